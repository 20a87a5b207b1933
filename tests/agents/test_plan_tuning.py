"""``trackenv plan --tune N``: the plan's rule tuned on the line itself (:mod:`trackenv_agents.plan_tuning`)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from trackenv_agents.cli import main
from trackenv_agents.evaluation.harness import evaluate_many
from trackenv_agents.plan_tuning import TUNE_YEARS, tune_plan_rule
from trackenv_agents.planning import line_policy, plan_config, plan_line
from trackenv_agents.rules.line import GroupedThreshold

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "envs"))
from test_line_file import LINE, write  # noqa: E402  (the loader's test line: four sections with a history)

FAST = {"engine": "fast", "pass_reuse_tolerance_m": 1e-3}
#: one candidate besides the shipped parameters (3.5 / 1.75 mm): a low trigger that tamps far more often
LOW = {"trigger_mm": 1.0, "include_mm": 0.5}


@pytest.fixture
def small_grid(monkeypatch):
    """The grouped threshold's grid cut to one candidate, so that a tuning runs a few episodes."""
    monkeypatch.setattr(GroupedThreshold, "param_grid", classmethod(lambda cls: [dict(LOW)]))


def test_the_tuning_scores_the_grid_and_the_shipped_parameters_on_ten_year_training_futures(tmp_path, small_grid):
    """Each candidate's cost is its mean over the training futures (seeds 1000, 1001) of ten years from the
    line's state, as the harness scores it; the cheaper is chosen."""
    cfg = plan_config(write(tmp_path), years=0.5, **FAST)
    rule = line_policy("grouped-threshold", cfg)
    tuning = tune_plan_rule(rule, cfg, 2)
    assert tuning.candidates == 2 and tuning.shipped_params == {"trigger_mm": 3.5, "include_mm": 1.75}
    runs = evaluate_many([GroupedThreshold(**tuning.shipped_params), GroupedThreshold(**LOW)],
                         cfg.replace(horizon_years=TUNE_YEARS), [1000, 1001])
    shipped, low = (float(r.cost.mean()) for r in runs)
    assert tuning.shipped_cost_keur == pytest.approx(shipped, rel=1e-12)
    assert tuning.cost_keur == pytest.approx(min(shipped, low), rel=1e-12)
    assert tuning.params == (LOW if low < shipped else tuning.shipped_params)
    assert tuning.to_dict()["seeds"] == [1000, 1001] and tuning.to_dict()["years"] == TUNE_YEARS
    assert tuning.searched == {"trigger_mm": [1.0, 3.5], "include_mm": [0.5, 1.75]} and tuning.at_edge() == []


def test_a_choice_rule_tunes_its_campaign_first_then_its_choices_around_the_best(tmp_path, small_grid,
                                                                                   monkeypatch):
    """A choice rule's campaign triggers are searched first (the grouped threshold's grid, the choices as
    shipped), then its choice grid around the best campaign; every candidate once, the cheapest of all chosen."""
    from trackenv_agents import plan_tuning
    from trackenv_agents.rules.choices import ChoiceThresholdSpotOnly

    bases = []

    def choice_grid(cls, base):
        bases.append(dict(base))
        return [{**base, "spot_peak_mm": 9.0}]

    monkeypatch.setattr(plan_tuning, "choice_grid", choice_grid)
    cfg = plan_config(write(tmp_path), "defects", years=0.5, **FAST)
    rule = line_policy("choice-threshold-spot-only", cfg, "defects")
    shipped = dict(rule.params)
    tuning = tune_plan_rule(rule, cfg, 2)
    campaign = {**shipped, **LOW}
    assert [name for name, _ in plan_tuning.tuning_stages(ChoiceThresholdSpotOnly)] == [
        "campaign's triggers", "choices around the best campaign"]
    runs = evaluate_many([ChoiceThresholdSpotOnly(**shipped), ChoiceThresholdSpotOnly(**campaign)],
                         cfg.replace(horizon_years=TUNE_YEARS), [1000, 1001], action_type="choices")
    costs = {"shipped": float(runs[0].cost.mean()), "low": float(runs[1].cost.mean())}
    best_campaign = campaign if costs["low"] < costs["shipped"] else shipped
    assert bases == [{k: best_campaign[k] for k in ("trigger_mm", "include_mm")}]
    spot = {**best_campaign, "spot_peak_mm": 9.0}
    costs["spot"] = float(evaluate_many([ChoiceThresholdSpotOnly(**spot)], cfg.replace(horizon_years=TUNE_YEARS),
                                        [1000, 1001], action_type="choices")[0].cost.mean())
    assert tuning.shipped_cost_keur == pytest.approx(costs["shipped"], rel=1e-12)
    assert tuning.cost_keur == pytest.approx(min(costs.values()), rel=1e-12)
    assert tuning.params == {"shipped": shipped, "low": campaign, "spot": spot}[min(costs, key=costs.get)]
    assert tuning.candidates == 3 and set(tuning.searched) == {"trigger_mm", "include_mm", "spot_peak_mm"}
    assert tuning.to_dict()["stages"] == [{"name": "campaign's triggers", "candidates": 2},
                                          {"name": "choices around the best campaign", "candidates": 1}]
    assert tuning.lines("choice-threshold-spot-only")[1].startswith(
        "  searched 3 candidates in 2 stages (2 for the campaign's triggers, then 1 for the choices around the best "
        "campaign; combinations of a grid, not every one) with ")


def test_the_table_says_what_was_searched_and_a_choice_at_the_grids_edge():
    """A parameter the grid did not vary is not in ``searched`` (a choice rule's grid may leave the triggers
    alone), and a choice at the smallest or largest value searched is flagged."""
    from trackenv_agents.plan_tuning import RuleTuning, _searched

    grid = [{"trigger_mm": t, "include_mm": 1.0, "spot_peak_mm": 9.0} for t in (2.0, 3.0, 3.5)]
    searched = _searched(grid)
    assert searched == {"trigger_mm": [2.0, 3.0, 3.5]}
    edge = RuleTuning(dict(grid[0]), dict(grid[2]), 90.0, 100.0, 1, 1000, 3, searched)
    text = "\n".join(edge.lines("grouped-threshold"))
    assert "chose trigger_mm 2 (shipped 3.5);" in text and "over 1 training future (seed 1000, in-sample)" in text
    assert "searched 3 candidates (combinations of a grid, not every one) with trigger_mm from 2 to 3.5" in text
    assert "at the grid's edge: trigger_mm 2: the line's best may lie beyond it" in text
    assert edge.to_dict()["at_edge"] == ["trigger_mm"]
    spots = _searched([{"spot_peak_mm": p, "drain_surveyed": d} for p in (0.0, 7.0, 9.0, 12.0) for d in (False, True)])
    off = RuleTuning({"spot_peak_mm": 0.0, "drain_surveyed": True}, {"spot_peak_mm": 9.0, "drain_surveyed": False},
                     90.0, 100.0, 1, 1000, 8, spots)
    assert off.at_edge() == []  # 0 switches spot tamping off: no end of a range of peaks
    assert "chose spot_peak_mm 0 (shipped 9), drain_surveyed on (shipped off)" in off.lines("choice-threshold")[0]
    assert RuleTuning({"spot_peak_mm": 12.0}, {}, 90.0, 100.0, 1, 1000, 8, spots).at_edge() == ["spot_peak_mm"]
    inside = RuleTuning(dict(grid[1]), dict(grid[2]), 90.0, 100.0, 2, 1000, 3, searched, alone=True)
    assert inside.at_edge() == [] and "grid's edge" not in "\n".join(inside.lines("x"))
    assert inside.lines("x")[0].startswith("tuned on this line alone (as if it had a machine of its own)")
    assert "stopped after" not in "\n".join(inside.lines("x")) and inside.to_dict()["dropped"] == []
    raced = RuleTuning(dict(grid[1]), dict(grid[2]), 90.0, 100.0, 8, 1000, 3, searched,
                       dropped=({"params": dict(grid[0]), "futures": 4, "mean_cost": 120.0},))
    assert ("  1 of them stopped after 4 of the 8 futures: dearer than the best so far by more than 2 %, "
            "significantly (paired t-test, one-sided 2.5 %)") in raced.lines("x")
    assert raced.to_dict()["dropped"] == [{"params": grid[0], "futures": 4, "mean_cost": 120.0}]


def test_the_plan_runs_the_tuned_rule_and_says_so(tmp_path, small_grid):
    """The plan's rule is the tuned one (its parameters in the plan), and the table and JSON say what the tuning
    found; without ``tune`` nothing is tuned."""
    line = write(tmp_path)
    plan = plan_line(line, years=0.5, futures=2, tune=2, **FAST)
    assert plan.tuning is not None and plan.policy_params == plan.tuning.params
    assert plan.to_dict()["tuning"]["candidates"] == 2
    assert "tuned on this line: grouped-threshold" in plan.table()
    assert "in-sample" in plan.table()
    plain = plan_line(line, years=0.5, futures=2, **FAST)
    assert plain.tuning is None and plain.to_dict()["tuning"] is None and "tuned on this line" not in plain.table()
    assert ("parameters: the shipped ones (trigger_mm 3.5, include_mm 1.75), tuned on the default preset's line; "
            "--tune 8") in plain.table()
    if plan.policy_params == plain.policy_params:  # the same rule: the same plan
        np.testing.assert_array_equal(plan.costs, plain.costs)


def test_plan_tune_from_the_command_line(tmp_path, capsys, small_grid):
    line = write(tmp_path)
    assert main(["plan", str(line), "--years", "0.5", "--futures", "1", "--tune", "1", "--engine", "fast",
                 "--json", "--out", str(tmp_path / "plan")]) == 0
    out = capsys.readouterr()
    payload = json.loads(out.out)
    assert payload["tuning"]["futures"] == 1 and payload["policy_params"] == payload["tuning"]["params"]
    assert "tuning grouped-threshold on 1 ten-year future of the line first" in out.err  # --json: no bars


class _InTurn:
    """An executor with ``map`` that runs here, in turn, counting the batches it is given."""

    def __init__(self) -> None:
        self.batches = 0

    def map(self, fn, items):
        items = list(items)
        self.batches += len(items)
        return [fn(item) for item in items]


def test_an_executor_runs_the_tunings_batches_with_the_same_result(tmp_path, small_grid):
    """``executor`` (Ray's, on a cluster) runs the races' batches of ``batch_size`` episodes: the same tuning as
    in one process, in as many batches as the episodes ask."""
    cfg = plan_config(write(tmp_path), years=0.5, **FAST)
    rule = line_policy("grouped-threshold", cfg)
    here = tune_plan_rule(rule, cfg, 2)
    executor = _InTurn()
    there = tune_plan_rule(rule, cfg, 2, executor=executor, batch_size=1)
    assert executor.batches == 4  # two candidates, two futures each, one episode a batch
    assert (there.params, there.cost_keur, there.shipped_cost_keur) == (here.params, here.cost_keur,
                                                                         here.shipped_cost_keur)


def test_plan_ray_hands_the_tuning_a_ray_executor_and_closes_it(tmp_path, capsys, small_grid, monkeypatch):
    """``plan --tune N --ray`` tunes through a RayExecutor (Ray itself not started here: the stub runs the tuning
    in this process), closed after; ``--ray``, ``--ray-address`` or ``--batch-size`` without ``--tune`` are
    refused, one line each."""
    from trackenv_agents import plan_tuning
    from trackenv_agents.evaluation.distributed import RayExecutor

    seen, real = {}, plan_tuning.tune_plan_rule

    def tune(rule, cfg, futures, progress=False, desc=None, executor=None, batch_size=32):
        seen.update(executor=executor, batch_size=batch_size)
        return real(rule, cfg, futures, progress, desc)

    monkeypatch.setattr(plan_tuning, "tune_plan_rule", tune)
    closed = []
    monkeypatch.setattr(RayExecutor, "close", lambda self: closed.append(self))
    line = str(write(tmp_path))
    assert main(["plan", line, "--years", "0.25", "--futures", "1", "--tune", "1", "--engine", "fast", "--ray",
                 "--batch-size", "4", "--json", "--out", str(tmp_path / "plan")]) == 0
    assert isinstance(seen["executor"], RayExecutor) and closed == [seen["executor"]] and seen["batch_size"] == 4
    assert json.loads(capsys.readouterr().out)["ray"] == "local"
    for option in (["--ray"], ["--ray-address", "auto"], ["--batch-size", "8"]):
        assert main(["plan", line, *option]) == 2
        assert f"{option[0]} is for --tune's episodes: give --tune N" in capsys.readouterr().err


def test_the_tunings_limits_are_checked_before_the_plan_starts(tmp_path, capsys):
    """What cannot be tuned, a number of futures out of range and a plan's futures among the training futures
    are one line each, exit status 2, before the fit and the futures run."""
    from trackenv_agents.cli import MAX_TUNE_FUTURES
    from trackenv_agents.evaluation.harness import TRAIN_SEEDS

    assert MAX_TUNE_FUTURES == len(TRAIN_SEEDS)
    line = str(write(tmp_path))
    with pytest.raises(SystemExit) as exit_:
        main(["plan", line, "--tune", "101"])
    assert exit_.value.code == 2 and "argument --tune: must be at most 100, got 101" in capsys.readouterr().err
    for args, says in ((["--tune", "2", "--policy", "no-maintenance"], "tune: 'no-maintenance' has no parameters"),
                       (["--tune", "2", "--seed", "995", "--futures", "8"],
                        "seed: the plan's futures (seeds 995-1002) overlap the tuning's training futures (seeds "
                        "1000-1001): its forecast would be in-sample; choose a seed below 993 or above 1001")):
        assert main(["plan", line, *args]) == 2
        err = capsys.readouterr().err
        assert says in err and "plan: starting" not in err, err


def test_what_cannot_be_tuned_is_refused_naming_why(tmp_path, capsys):
    cfg = plan_config(write(tmp_path), years=0.5)
    with pytest.raises(ValueError, match=r"^tune: 'no-maintenance' has no parameters to tune"):
        tune_plan_rule(line_policy("no-maintenance", cfg), cfg, 2)
    rule = line_policy("grouped-threshold", cfg)
    for bad in (0, 101, 2.5, True):
        with pytest.raises(ValueError, match=r"^tune must be an integer in \[1, 100\]"):
            tune_plan_rule(rule, cfg, bad)


def test_a_networks_lines_are_tuned_each_on_its_own_and_play_their_tuned_rules(tmp_path, small_grid, monkeypatch):
    """On a network of a 100 km/h line twice (two files of equal content) and a 160 km/h line, each line's rule is
    tuned on that line alone, lines of one config once, and each line plans with its own tuned parameters (its
    plan and table say so)."""
    from trackenv_agents import network_plan, plan_tuning
    from trackenv_agents.rules.network import NetworkRule

    for name, speed in (("slow", 100), ("slow_copy", 100), ("fast", 160)):
        folder = tmp_path / name
        folder.mkdir()
        write(folder, line=LINE.replace("speed_kmh: 100", f"speed_kmh: {speed}"))
    (tmp_path / "net.yaml").write_text("name: probe network\n"
                                       "lines: [slow/line.yaml, slow_copy/line.yaml, fast/line.yaml]\nmove_cost: 10\n")
    tuned, real = [], plan_tuning.tune_plan_rule

    def tune_plan_rule(rule, cfg, futures, progress=False, desc=None, **kw):
        tuning = real(rule, cfg, futures, progress, desc, **kw)
        tuned.append(cfg.speed_kmh)
        # the fast line keeps the shipped parameters, the slow one takes the low trigger: two rules on one network
        params = dict(LOW) if cfg.speed_kmh == 100 else dict(tuning.shipped_params)
        return plan_tuning.RuleTuning(params, tuning.shipped_params, tuning.cost_keur, tuning.shipped_cost_keur,
                                      futures, tuning.seed, tuning.candidates, tuning.searched)

    monkeypatch.setattr(plan_tuning, "tune_plan_rule", tune_plan_rule)
    bound = []
    real_bind = NetworkRule.bind
    monkeypatch.setattr(NetworkRule, "bind", lambda self, config, line_rules=None: bound.append(line_rules)
                        or real_bind(self, config, line_rules))
    plan = network_plan.plan_network(tmp_path / "net.yaml", years=0.5, futures=1, tune=1, **FAST)
    assert sorted(tuned) == [100.0, 160.0]  # the two slow lines share one tuning
    assert [p.policy_params for p in plan.lines] == [LOW, LOW, plan.lines[2].tuning.shipped_params]
    assert [dict(r.params) for r in bound[-1]] == [LOW, LOW, plan.lines[2].tuning.shipped_params]
    assert plan.table().count("tuned on this line alone (as if it had a machine of its own): grouped-threshold") == 3
    assert all(p.tuning.alone for p in plan.lines)


def test_line_rules_of_one_config_must_agree(tmp_path):
    from trackenv.envs.network import NetworkConfig
    from trackenv_agents.rules.network import NetworkRule

    net = NetworkConfig(n_lines=2)
    with pytest.raises(ValueError, match=r"^line_rules must have one line policy per line \(2\), got 1"):
        NetworkRule(GroupedThreshold()).bind(net, line_rules=[GroupedThreshold()])
    with pytest.raises(ValueError, match=r"^line_rules: lines \[0, 1\] share one config but not"):
        NetworkRule(GroupedThreshold()).bind(net, line_rules=[GroupedThreshold(), GroupedThreshold(**LOW)])


def test_each_stage_is_a_race_that_keeps_the_shipped_parameters(tmp_path, monkeypatch):
    """tune_plan_rule runs each stage as a race (:func:`~trackenv_agents.evaluation.tuning.race`) on the training
    futures, the shipped parameters kept to the end (their cost is reported), and gathers what stopped early."""
    from trackenv_agents import plan_tuning

    calls = []

    def race(cls, config, seeds, grid, keep=(), **kw):
        calls.append((list(seeds), list(keep)))
        table = [{"params": g, "mean_cost": 100.0 + i} for i, g in enumerate(grid)]
        stopped = [{"params": grid[-1], "futures": 4, "mean_cost": 150.0}]
        return {"best_params": grid[0], "best_mean_cost": 100.0, "table": table[:-1], "dropped": stopped}

    monkeypatch.setattr(plan_tuning, "race", race)
    cfg = plan_config(write(tmp_path), years=0.5, **FAST)
    tuning = tune_plan_rule(line_policy("grouped-threshold", cfg), cfg, 8)
    shipped = {"trigger_mm": 3.5, "include_mm": 1.75}
    assert calls == [(list(range(1000, 1008)), [shipped])]
    assert tuning.params == shipped and tuning.shipped_cost_keur == 100.0 and len(tuning.dropped) == 1
