"""The race of :mod:`trackenv_agents.evaluation.tuning`: a grid search that stops running clearly dearer
candidates, and whose survivors' costs are the full search's."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from trackenv_agents.evaluation import tuning
from trackenv_agents.evaluation.tuning import RACE_MARGIN, race, race_rounds, tune
from trackenv_agents.rules.line import SectionThreshold


def test_a_race_looks_once_after_half_of_the_futures():
    assert race_rounds(1) == [1] and race_rounds(3) == [3] and race_rounds(4) == [2, 4]
    assert race_rounds(8) == [4, 8] and race_rounds(9) == [4, 9]


class Offset:
    """A stand-in policy whose cost in future ``s`` is ``base[s] + offset + wobble * (-1) ** s`` k€."""

    name = "offset"
    base = {1000 + s: 500.0 + 37.0 * s for s in range(8)}

    def __init__(self, offset: float, wobble: float = 0.0):
        self.offset, self.wobble = offset, wobble


@pytest.fixture
def runs(monkeypatch):
    """The harness replaced by :class:`Offset`'s costs; records each call's (offsets, seeds)."""
    calls = []

    def evaluate_many(policies, cfg, seeds, **kw):
        calls.append(([p.offset for p in policies], list(seeds)))
        return [SimpleNamespace(cost=np.array([Offset.base[s] + p.offset + p.wobble * (-1) ** s for s in seeds]),
                                tampings_per_km_year=np.zeros(len(seeds))) for p in policies]

    monkeypatch.setattr(tuning, "evaluate_many", evaluate_many)
    monkeypatch.setattr(tuning, "problem_config", lambda config: config)
    return calls


def test_clearly_dearer_candidates_stop_and_the_rest_run_every_future(runs):
    """Over 8 futures (a look after 4): a candidate dearer by more than the margin with no spread stops after
    the first four futures; one dearer by less than the margin, or by more but not significantly (its paired
    differences alternate by ±40 k€), runs on; a kept candidate runs every future however dear; the cheapest
    wins."""
    leader = 557.0  # the leader's mean cost over the first four futures: base 500 + 37 * 1.5, offset 1.5
    grid = [{"offset": 1.5}, {"offset": 1.5 + 0.5 * RACE_MARGIN * leader}, {"offset": 1.5 + 3 * RACE_MARGIN * leader},
            {"offset": 1.5 + 3 * RACE_MARGIN * leader, "wobble": 40.0}, {"offset": 300.0}]
    out = race(Offset, None, list(range(1000, 1008)), grid, keep=[{"offset": 300.0}])
    assert [d["params"] for d in out["dropped"]] == [grid[2]] and out["dropped"][0]["futures"] == 4
    assert out["dropped"][0]["mean_cost"] == pytest.approx(555.5 + grid[2]["offset"])
    assert [r["params"] for r in out["table"]] == [grid[0], grid[1], grid[3], grid[4]]
    assert out["best_params"] == grid[0] and out["best_mean_cost"] == out["table"][0]["mean_cost"]
    for row in out["table"]:
        assert len(row["episode_costs"]) == 8
    assert [seeds for _, seeds in runs] == [[1000, 1001, 1002, 1003], [1004, 1005, 1006, 1007]]
    assert len(runs[0][0]) == 5 and len(runs[1][0]) == 4


def test_a_race_of_three_futures_runs_every_candidate_on_each(runs):
    grid = [{"offset": 0.0}, {"offset": 1e4}]
    out = race(Offset, None, [1000, 1001, 1002], grid)
    assert out["dropped"] == [] and len(out["table"]) == 2 and runs == [([0.0, 1e4], [1000, 1001, 1002])]


def test_an_empty_grid_is_refused():
    with pytest.raises(ValueError, match="empty parameter grid"):
        race(SectionThreshold, None, [1000, 1001], [])


@pytest.mark.slow
def test_the_survivors_rows_are_the_full_searchs(small_config):
    """On the harness itself: each survivor's per-future costs and mean equal :func:`tune`'s on the same seeds
    (an episode does not depend on its batch), and a dropped candidate is dearer there than the best."""
    grid = [{"threshold_mm": 0.8}, {"threshold_mm": 2.0}, {"threshold_mm": 50.0}]
    seeds = [10, 11, 12, 13]
    full = {repr(r["params"]): r for r in tune(SectionThreshold, small_config, seeds, grid=grid)["table"]}
    raced = race(SectionThreshold, small_config, seeds, grid, batch_size=5)
    for row in raced["table"]:
        assert row["episode_costs"] == pytest.approx(full[repr(row["params"])]["episode_costs"], rel=1e-12)
    assert raced["best_params"] == min(full.values(), key=lambda r: r["mean_cost"])["params"]
    for d in raced["dropped"]:
        assert full[repr(d["params"])]["mean_cost"] > raced["best_mean_cost"]
