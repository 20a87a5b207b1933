"""The hindsight search with the choices: priced exactly, below its own candidates and doing nothing, drainage
found where a wet spot makes repeated tamping dear, never a look (inspect, survey), and on a tamping-only config
the numbers of the tamping-only search."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from trackenv.envs.choices import INTERVENTIONS, code, work_per_code
from trackenv.envs.line_config import scenario
from trackenv_agents.evaluation.line_hindsight import (
    TrueStateRule,
    _select,
    _total,
    choice_rules,
    hindsight_bound,
    hindsight_bounds,
    replay,
    schedule_from_rows,
    schedule_rows,
)

TAMP, SPOT, DRAIN, RENEW, INSPECT, SURVEY = (code(n) for n in INTERVENTIONS)
REFERENCE = Path(__file__).parent / "data" / "hindsight_tamping_reference.json"
SEARCH = {"rounds": 1, "sd_thresholds_mm": (2.0,), "peak_fractions": (0.8,), "stop_steps": (0,)}


#: how far a cost of the reference may lie from this machine's: the reference was written on an AVX-512 Xeon;
#: numpy's elementwise functions are dispatched per instruction set and the pass kernel is compiled for the host
#: processor, so another processor may round the last bits otherwise (an AVX2 AMD EPYC: up to 3e-14 relative,
#: measured 2026-12-07); the search's decisions are compared exactly
CROSS_CPU_REL = 1e-12


def test_tamping_only_configs_give_the_tamping_only_search():
    """The reference was written by the search before it knew the choices (same config, plans and settings): the
    same schedules and options, bit for bit, and the same costs (the episode's, and after each round of the search)
    to the last digits a processor may round otherwise (:data:`CROSS_CPU_REL`; on the processor that wrote it,
    exactly)."""
    ref = json.loads(REFERENCE.read_text())
    cfg = scenario(ref["config"]["scenario"], horizon_years=ref["config"]["horizon_years"],
                   initial_scale=tuple(ref["config"]["initial_scale"]))
    plan, extra = schedule_from_rows(ref["plan"]), schedule_from_rows(ref["extra"])
    search = {k: tuple(v) if isinstance(v, list) else v for k, v in ref["search"].items()}
    found = hindsight_bounds(cfg, [(4, plan.astype(bool), (extra.astype(bool),)), (9, plan.astype(bool), ())],
                             **search)
    for h, r in zip(found, ref["episodes"], strict=True):
        assert h["seed"] == r["seed"]
        for key in ("cost", "replayed_cost", "start_cost"):
            assert h[key] == pytest.approx(r[key], rel=CROSS_CPU_REL, abs=0.0), key
        assert h["search"] == pytest.approx(r["search"], rel=CROSS_CPU_REL, abs=0.0)  # the cost after each round
        assert h["options"] == r["options"] and schedule_rows(h["schedule"]) == r["schedule"]


def test_a_tamping_only_config_gets_no_choice_rules():
    rules = [TrueStateRule(2.0, 0.8, 0)]
    assert choice_rules(scenario("small"), rules) == rules
    every = choice_rules(scenario("small", choices=INTERVENTIONS), rules)
    # drainage (first, onset); spot tamping alone and with each drainage timing; renewal
    assert every[0] == rules[0] and len(every) == 1 + 2 + 3 + 1
    assert not any(r.tamping_only for r in every[1:])
    assert choice_rules(scenario("small", choices=("tamp", "drainage")), rules)[1:] == [
        TrueStateRule(2.0, 0.8, 0, drainage="first"), TrueStateRule(2.0, 0.8, 0, drainage="onset")]
    with pytest.raises(ValueError, match="drainage"):
        TrueStateRule(drainage="later")


def test_the_choice_bound_is_exact_below_its_start_and_doing_nothing_and_never_looks():
    cfg = scenario("small", choices=INTERVENTIONS, horizon_years=2.0, initial_scale=(1.2, 2.0),
                   wet_spot_probability=0.5, wet_spot_active_share=0.5, local_defects_mean=1.0)
    H, S = cfg.horizon_steps, cfg.n_sections
    plan = np.zeros((H, S), dtype=np.int8)
    plan[1, :2], plan[1, 2], plan[3, 3:] = TAMP, SPOT, TAMP
    plan[0, 4], plan[2, 5] = INSPECT, SURVEY  # looks, which the bound never needs
    _, start = replay(cfg, 2, plan)
    _, nothing = replay(cfg, 2, np.zeros((H, S), dtype=np.int8))
    h = hindsight_bound(cfg, 2, plan, **SEARCH)
    assert h["start_cost"] == pytest.approx(start, rel=1e-9)  # the per-section pricing of a schedule of choices
    assert h["cost"] == pytest.approx(h["replayed_cost"], rel=1e-9)  # ... and of the result, in the env
    assert h["cost"] <= min(start, nothing) + 1e-9 and h["search"] == sorted(h["search"], reverse=True)
    sched = h["schedule"]
    assert not np.isin(sched, (INSPECT, SURVEY)).any()
    assert (work_per_code(cfg.choice_work)[sched].sum(axis=1) <= cfg.capacity + 1e-9).all()
    assert _total(sched, np.zeros(S), cfg) == pytest.approx(
        cfg.possession_cost * np.isin(sched, (TAMP, SPOT, DRAIN, RENEW)).any(axis=1).sum())


def test_a_spot_possession_is_priced_as_the_env_prices_it():
    # a step whose only track work is spot tamping pays spot_possession_share of the possession, in the search's
    # pricing, in its selection and in the env (the search's result is replayed there)
    cfg = scenario("small", choices=INTERVENTIONS, horizon_years=2.0, initial_scale=(1.2, 2.0),
                   local_defects_mean=1.0, spot_possession_share=0.2)
    H, S = cfg.horizon_steps, cfg.n_sections
    plan = np.zeros((H, S), dtype=np.int8)
    plan[1, :2], plan[3, :2], plan[3, 3], plan[5, 0] = SPOT, TAMP, SPOT, INSPECT
    assert _total(plan, np.zeros(S), cfg) == pytest.approx(cfg.possession_cost * (1 + 0.2))
    _, start = replay(cfg, 2, plan)
    h = hindsight_bound(cfg, 2, plan, **SEARCH)
    assert h["start_cost"] == pytest.approx(start, rel=1e-9)
    assert h["cost"] == pytest.approx(h["replayed_cost"], rel=1e-9) and h["cost"] <= start + 1e-9
    options = [[(np.where(np.arange(H) == 0, SPOT, 0).astype(np.int8), 1.0), (np.zeros(H, dtype=np.int8), 10.0)]
               for _ in range(S)]
    choice, total = _select(options, cfg)
    assert (choice == 0).all() and total == pytest.approx(S * 1.0 + 0.2 * cfg.possession_cost)
    choice, total = _select(options, cfg.replace(spot_possession_share=1.0))
    assert (choice == 0).all() and total == pytest.approx(S * 1.0 + cfg.possession_cost)


def test_the_search_drains_a_wet_spot_rather_than_tamp_it_again_and_again():
    """Every section has a wet spot working from the start: tamping alone must come back to it, draining once
    returns it to the plain rate. Same episodes with and without drainage (the draws do not depend on it)."""
    wet = scenario("small", horizon_years=2.5, wet_spot_probability=1.0, wet_spot_active_share=1.0,
                   wet_spot_rate_factor=20.0, initial_scale=(1.0, 1.5))
    plan = np.zeros((wet.horizon_steps, wet.n_sections), dtype=np.int8)
    closed_loop = {**SEARCH, "rounds": 0}  # the candidates alone: a drainage rule against tamping rules
    tamping = hindsight_bound(wet, 1, plan, **closed_loop)
    drained = hindsight_bound(wet.replace(choices=("tamp", "drainage")), 1, plan, **closed_loop)
    assert drained["cost"] < tamping["cost"] and (drained["schedule"] == DRAIN).any()
    assert drained["cost"] == pytest.approx(drained["replayed_cost"], rel=1e-9)
    per_section = (drained["schedule"] == DRAIN).any(axis=0)
    assert (tamping["schedule"][:, per_section] == TAMP).sum() > (drained["schedule"][:, per_section] == TAMP).sum()
