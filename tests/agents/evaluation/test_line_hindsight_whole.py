"""The whole-line hindsight search of lines whose sections share a segment: exact replays (forked or from the
start, and in the env), never above its start, the exhaustive optimum on a tiny track, its neighbourhood."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from trackenv.envs.choices import TAMP
from trackenv.envs.line_config import scenario
from trackenv_agents.evaluation.line_hindsight import hindsight_bounds, replay_schedules
from trackenv_agents.evaluation.line_hindsight_whole import (
    TrueStateCampaignRule,
    campaign_variants,
    replay_lines,
    whole_line_bounds,
)

#: a 20 m track of two 10 m sections on one segment, five quarters, worn (so that tamping pays on some seeds):
#: 2^10 schedules, few enough to replay every one
TINY = scenario("track60", n_sections=2, segment_length_m=20.0, sections_per_segment=2, capacity=2,
                horizon_years=1.25, initial_scale=(4.0, 4.0))
#: no closed-loop candidates: the local search alone
NO_RULES = {"sd_thresholds_mm": (), "peak_fractions": (np.inf,), "stop_steps": (0,)}


#: pass reuse (fast engine) keeps results as episode state: forks and replays must carry them
@pytest.mark.parametrize("passes", [{}, {"engine": "fast", "pass_reuse_tolerance_m": 1e-4}])
def test_forked_whole_line_replays_equal_replays_from_the_start_and_the_env(passes):
    cfg = TINY.replace(**passes)
    H, S = cfg.horizon_steps, cfg.n_sections
    rng = np.random.default_rng(0)
    cands = [(s, rng.random((H, S)) < 0.3) for s in (3, 5) for _ in range(3)]
    cands += [(s, TrueStateCampaignRule(1.5, 1.0, 0.8, 1)) for s in (3, 5)] + [(3, TrueStateCampaignRule(1.0))]
    late = cands[0][1].copy()
    late[-1, 0] = not late[-1, 0]  # parts from its parent only at the last step
    cands.append((3, late))
    shared = replay_lines(cfg, cands)
    alone = replay_lines(cfg, cands, share_prefixes=False)
    for a, b in zip(shared, alone, strict=True):
        np.testing.assert_array_equal(a, b)
    env = replay_schedules(cfg, [s for s, _ in cands], list(shared[1]))
    np.testing.assert_allclose(shared[0], env, rtol=0, atol=1e-9)
    with pytest.raises(ValueError, match="shape"):
        replay_lines(cfg, [(3, np.zeros((H, S + 1)))])


def test_the_search_finds_the_exhaustive_optimum_of_a_tiny_track():
    """Every one of the 2^10 schedules replayed: the local search alone, from one late campaign of one section,
    ends at the cheapest (on episodes where tamping pays); the full search's schedule replays in the env at the
    cost it reports."""
    cfg = TINY
    H, S = cfg.horizon_steps, cfg.n_sections
    plans = [np.array(bits, dtype=np.int8).reshape(H, S) * TAMP for bits in itertools.product((0, 1), repeat=H * S)]
    late = np.zeros((H, S), bool)
    late[3, 1] = True
    for seed in (5, 7):
        every = replay_lines(cfg, [(seed, p) for p in plans])[0]
        assert every.min() < every[0] - 1.0  # tamping pays here: no trivial optimum
        local = whole_line_bounds(cfg, [(seed, late, ())], rounds=4, **NO_RULES)[0]
        assert local["cost"] == pytest.approx(every.min(), rel=1e-12)
        full = whole_line_bounds(cfg, [(seed, np.zeros((H, S)), ())], rounds=1)[0]
        assert full["cost"] == pytest.approx(full["replayed_cost"], rel=0, abs=1e-9)
        assert every.min() - 1e-9 <= full["cost"] <= every[0]


def test_the_bound_is_never_above_its_start_and_replays_exactly_on_the_60_m_track():
    cfg = scenario("track60", horizon_years=1.5)
    H, S = cfg.horizon_steps, cfg.n_sections
    plan = np.zeros((H, S), bool)
    plan[2] = True
    other = np.zeros((H, S), bool)
    other[4, :3] = True
    found = hindsight_bounds(cfg, [(1, plan, (other,)), (2, plan, ())], rounds=1, sd_thresholds_mm=(2.0,),
                             peak_fractions=(np.inf,), stop_steps=(0,))
    start = replay_schedules(cfg, [1, 2], [plan, plan])
    for h, s in zip(found, start, strict=True):
        assert h["start_cost"] == pytest.approx(s, rel=0, abs=1e-9)
        assert h["cost"] <= s + 1e-12 and h["search"] == sorted(h["search"], reverse=True)
        assert h["cost"] == pytest.approx(h["replayed_cost"], rel=0, abs=1e-9)
        assert h["schedule"].shape == (H, S)
    with pytest.raises(ValueError, match="tamping only"):
        hindsight_bounds(cfg, [(1, plan, ())], choice_search={})
    with pytest.raises(ValueError, match="tamping only"):
        whole_line_bounds(scenario("track60", choices=("tamp", "drainage")), [(1, plan, ())])
    with pytest.raises(ValueError, match="distinct seeds"):
        whole_line_bounds(cfg, [(1, plan, ()), (1, plan, ())])


def test_campaign_rule_tamps_the_line_over_its_inclusion_threshold_once_triggered():
    rule = TrueStateCampaignRule(trigger_mm=2.0, include_mm=1.0, stop_steps=2)
    limit = np.full(3, 1e-2)
    sd = np.array([0.5, 1.2, 2.1]) * 1e-3
    assert rule.decide(0, 10, sd, np.zeros(3), limit).tolist() == [0, TAMP, TAMP]
    assert rule.decide(8, 10, sd, np.zeros(3), limit).tolist() == [0, 0, 0]  # the last stop_steps steps
    assert rule.decide(0, 10, sd * 0.9, np.zeros(3), limit).tolist() == [0, 0, 0]  # not triggered
    guard = TrueStateCampaignRule(trigger_mm=np.inf, include_mm=np.inf, peak_fraction=0.8)
    assert guard.decide(0, 10, sd, np.array([0.0, 9e-3, 0.0]), limit).tolist() == [0, TAMP, 0]
    with pytest.raises(ValueError, match="stop_steps"):
        TrueStateCampaignRule(2.0, stop_steps=-1)


def test_campaign_variants_move_drop_merge_campaigns_and_vary_sections():
    H, S = 8, 3
    plan = np.zeros((H, S), np.int8)
    plan[2, :2] = TAMP
    plan[5, 2] = TAMP
    restricted = np.zeros((H, S), bool)
    restricted[4:, 2] = True
    variants = campaign_variants(plan, restricted)
    keys = {v.tobytes() for v in variants}
    assert plan.tobytes() not in keys and len(keys) == len(variants)

    def has(rows: dict[int, list[int]]) -> bool:
        v = np.zeros((H, S), np.int8)
        for t, js in rows.items():
            v[t, js] = TAMP
        return v.tobytes() in keys

    assert has({3: [0, 1], 5: [2]}) and has({0: [0, 1], 5: [2]})  # a campaign moved
    assert has({5: [2]}) and has({2: [0, 1]})  # dropped
    assert has({2: [0, 1, 2]}) and has({5: [0, 1, 2]})  # merged with the next, at either step
    assert has({2: [0], 5: [2]}) and has({2: [0, 1], 5: [1, 2]})  # a section left out of or joined to one
    assert has({2: [0, 1], 3: [2], 5: [2]}) and has({2: [0, 1], 4: [2], 5: [2]})  # where a restriction starts
    assert has({2: [0, 1, 2], 5: [2]}) and has({2: [0, 1], 4: [0, 1, 2], 5: [2]})  # ... or of the whole line
