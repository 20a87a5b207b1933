"""Line heuristics: valid actions within capacity, their calendars, the harness on the line, the hindsight search."""

import numpy as np
import pytest

from trackenv.envs.line import TampingLine
from trackenv.envs.line_config import scenario
from trackenv_agents.evaluation.harness import bind_policy, evaluate_many
from trackenv_agents.evaluation.line_compare import SECTION_CLASSES, class_breakdown, parse_seeds, scenario_of
from trackenv_agents.evaluation.line_hindsight import (
    TrueStateRule,
    _select,
    _total,
    _variants,
    hindsight_bound,
    hindsight_bounds,
    recorded_rule_schedules,
    replay,
    replay_sections,
    saved_schedules,
    schedule_from_rows,
    schedule_rows,
)
from trackenv_agents.rules.line import (
    LINE_HEURISTICS,
    GroupedThreshold,
    RegisterPeriodic,
    SectionThreshold,
    UniformPeriodic,
    planner_view,
    stale_measurement,
)

CFG = scenario("small", horizon_years=1.0)


def _obs(n_envs=3, S=6, seed=0):
    rng = np.random.default_rng(seed)
    return {"section_sd": rng.uniform(0.5, 4.0, (n_envs, S)).astype(np.float32),
            "register": rng.integers(0, 3, (n_envs, S)).astype(np.float32),
            "time": np.full((n_envs, 1), 0.25, np.float32),
            "years_since_tamping": np.ones((n_envs, S), np.float32),
            "measurement_age": np.full((n_envs, 1), 0.5, np.float32),
            "tampings": np.ones((n_envs, S), np.float32)}


@pytest.mark.parametrize("name", sorted(LINE_HEURISTICS))
def test_actions_are_binary_and_within_capacity(name):
    cls = LINE_HEURISTICS[name]
    for params in cls.param_grid():
        pol = bind_policy(cls(**params), CFG)
        a, state = pol.predict(_obs())
        assert a.shape == (3, 6) and set(np.unique(a)) <= {0, 1} and state is None
        assert (a.sum(axis=1) <= CFG.capacity).all()
        single, _ = pol.predict({k: v[0] for k, v in _obs().items()})
        assert single.shape == (6,)


def test_rules_read_a_section_tamped_since_the_recording_run_as_fresh():
    """The measured SD of a section tamped after the last recording run is the SD before that tamping: no rule
    tamps it again on that measurement, nor calls a campaign for it."""
    obs = _obs(1)
    obs["section_sd"][:] = [[3.5, 1.0, 1.0, 1.0, 1.0, 1.0]]
    obs["years_since_tamping"][:] = [[0.5, 2.0, 2.0, 2.0, 2.0, 2.0]]  # section 0 tamped after the run (age 0.5)
    for name, params in (("section-threshold", {"threshold_mm": 2.0}),
                         ("grouped-threshold", {"trigger_mm": 3.0, "include_mm": 0.5}),
                         ("budgeted-worst-first", {"every_years": 0.25, "n_worst": 2, "min_sd_mm": 0.5})):
        pol = bind_policy(LINE_HEURISTICS[name](**params), CFG)
        assert pol.predict(obs)[0][0, 0] == 0
        if name == "grouped-threshold":
            assert not pol.predict(obs)[0].any()  # nothing else triggers a campaign
    fresh = planner_view(obs)
    assert fresh["section_sd"][0, 0] == 0.0 and fresh["section_sd"][0, 1] == 1.0
    untouched = {**obs, "tampings": np.zeros_like(obs["tampings"])}  # not tamped in the episode: not stale
    assert not stale_measurement(untouched).any()
    # in the env: every tamping of the best rule is of a section not tamped since its last measurement
    cfg = scenario("small", horizon_years=2.0)
    res = evaluate_many([GroupedThreshold(trigger_mm=1.5, include_mm=1.0)], cfg, seeds=[1, 2], batch_size=2)[0]
    assert res.tamped.sum() >= 4
    for tamped in res.tamped:  # (steps, sections); a run closes steps 3, 7, ...: it sees tampings of steps 0-3, ...
        for j in range(6):
            steps = np.flatnonzero(tamped[:, j])
            assert all(b // cfg.measurement_interval > a // cfg.measurement_interval
                       for a, b in zip(steps[:-1], steps[1:]))


def test_uniform_periodic_covers_the_line_once_per_interval():
    cfg = scenario("small", horizon_years=4.0)
    pol = bind_policy(UniformPeriodic(interval_years=2.0), cfg)
    obs = _obs(1)
    counts = np.zeros(6, int)
    for t in range(cfg.horizon_steps):
        obs["time"][:] = t / cfg.horizon_steps
        counts += pol.predict(obs)[0][0]
    assert (counts == 2).all()


def test_register_periodic_tamps_zones_more_often():
    cfg = scenario("small", horizon_years=6.0)
    pol = bind_policy(RegisterPeriodic(plain_years=6.0, zone_years=1.5), cfg)
    obs = _obs(1)
    obs["register"][:] = [[0, 1, 0, 2, 0, 0]]
    counts = np.zeros(6, int)
    for t in range(cfg.horizon_steps):
        obs["time"][:] = t / cfg.horizon_steps
        counts += pol.predict(obs)[0][0]
    assert counts[[1, 3]].min() > counts[[0, 2, 4, 5]].max()


def test_harness_scores_line_heuristics_with_cost_parts():
    cfg = scenario("small", horizon_years=0.5)
    res = evaluate_many([LINE_HEURISTICS["no-maintenance"](), UniformPeriodic(interval_years=2.0)], cfg,
                        seeds=[0, 1], batch_size=4)
    assert [r.policy for r in res] == ["no-maintenance", "uniform-periodic"]
    for r in res:
        assert np.allclose(r.cost, -r.sum_rewards)
        assert set(r.cost_parts) >= {"possession", "speed_restriction"}
    assert res[1].cost_parts["possession"].min() > 0
    for r in res:  # the evaluation records what was tamped, step by step
        assert r.tamped.shape == (2, cfg.horizon_steps, 6)
        np.testing.assert_array_equal(r.tamped.sum(axis=(1, 2)), r.section_tampings)
    # where the costs fall: the classes' own costs and the possessions add up to the episodes' costs
    for r in res:
        cl = class_breakdown(r)
        assert sum(cl[c]["sections_per_episode"] for c in SECTION_CLASSES) == 6
        own = sum((cl[c]["cost_per_section"] or 0.0) * cl[c]["sections_per_episode"] for c in SECTION_CLASSES)
        assert own + cl["line"]["possession_per_episode"] == pytest.approx(r.cost.mean(), rel=1e-9)
        assert all(cl[c]["cost_per_section"] is None for c in SECTION_CLASSES if cl[c]["sections_per_episode"] == 0)
    assert class_breakdown(res[0])["line"]["campaigns_per_episode"] == 0
    assert class_breakdown(res[1])["line"]["campaigns_per_episode"] > 0


#: pass reuse (fast engine) keeps results as episode state: forks and replays must carry them
@pytest.mark.parametrize("passes", [{}, {"engine": "fast", "pass_reuse_tolerance_m": 1e-4}])
def test_hindsight_search_is_exact_and_no_worse_than_its_start(passes):
    cfg = scenario("small", horizon_years=1.0, **passes)
    plan = np.zeros((cfg.horizon_steps, 6), bool)
    plan[0, :3] = True
    env = TampingLine(cfg)
    env.reset(seed=4)
    start = -sum(env.step(plan[t].astype(np.int8))[1] for t in range(cfg.horizon_steps))
    h = hindsight_bound(cfg, 4, plan, rounds=1, sd_thresholds_mm=(1.5,), peak_fractions=(np.inf,),
                        stop_steps=(0,))
    assert h["start_cost"] == pytest.approx(start, rel=1e-9)  # the per-section pricing of the start is exact
    assert h["cost"] == pytest.approx(h["replayed_cost"], rel=1e-9)  # ... and of the result
    assert h["cost"] <= start + 1e-9 and h["search"] == sorted(h["search"], reverse=True)
    assert (h["schedule"].sum(axis=1) <= cfg.capacity).all()


def test_selection_is_the_exact_optimum_over_the_options():
    """The integer program picks the cheapest option per section with shared possessions and the capacity:
    equal to brute force on random instances, and it empties a campaign by moving two sections at once, which a
    one-section-at-a-time descent from the incumbent cannot."""
    import itertools

    cfg = scenario("small", horizon_years=1.5, capacity=2)  # H = 6 steps, 6 sections
    H, S = cfg.horizon_steps, cfg.n_sections
    rng = np.random.default_rng(0)
    for _ in range(5):
        options = [[(rng.random(H) < 0.3, float(rng.uniform(0, 30))) for _ in range(3)] for _ in range(S)]
        brute = min(_total(np.stack([options[j][c[j]][0] for j in range(S)], axis=1),
                           np.array([options[j][c[j]][1] for j in range(S)]), cfg)
                    for c in itertools.product(range(3), repeat=S))
        choice, total = _select(options, cfg)
        assert total == pytest.approx(brute, rel=1e-12)
    # two sections tamp at step 1; moving either alone to step 3 (where two others tamp) saves nothing, as the
    # campaign at step 1 stays; moving both saves a possession (15 k€) for 2 × 1 k€ more
    at = {t: np.eye(H, dtype=bool)[t] for t in range(H)}
    options = [[(at[1], 10.0), (at[3], 11.0)], [(at[1], 10.0), (at[3], 11.0)], [(at[3], 10.0)], [(at[4], 10.0)],
               [(np.zeros(H, bool), 0.0)], [(np.zeros(H, bool), 0.0)]]
    cfg4 = cfg.replace(capacity=4)
    choice, total = _select(options, cfg4, incumbent=np.zeros(S, dtype=int))
    assert list(choice[:2]) == [1, 1] and total == pytest.approx(42.0 + 2 * cfg4.possession_cost)
    # over capacity (2): steps 1 and 3 can hold two sections each
    _, total2 = _select(options, cfg, incumbent=np.zeros(S, dtype=int))
    assert total2 == pytest.approx(40.0 + 3 * cfg.possession_cost)
    with pytest.raises(ValueError, match="annual_budget"):  # sections priced alone cannot share a budget
        hindsight_bound(cfg.replace(annual_budget=50.0), 0, np.zeros((H, S), bool))


def test_forked_section_replays_equal_replays_from_the_start_and_the_env():
    """Candidates share their common past (forked where they part) and many episodes share a batch: the numbers
    are bit for bit those of replaying every candidate from the first step, and an open-loop schedule of every
    section priced per section (plus the possession per campaign step) is what the env charges."""
    cfg = scenario("small", horizon_years=1.5)
    H, S = cfg.horizon_steps, cfg.n_sections
    rng = np.random.default_rng(2)
    plans = {seed: rng.random((3, H, S)) < 0.25 for seed in (4, 9)}
    cands, first = [], {}
    for seed, ps in plans.items():
        for j in range(S):
            first.setdefault(seed, []).append(len(cands))  # the row of section j under the seed's first plan
            cands += [(seed, j, p[:, j]) for p in ps]
            cands += [(seed, j, TrueStateRule(1.5, 0.8, 0)), (seed, j, TrueStateRule(1.5, 0.8, 2)),
                      (seed, j, TrueStateRule(1.0, np.inf, 0))]
            late = ps[0][:, j].copy()
            late[-1] = not late[-1]  # parts from its parent only at the last step
            cands.append((seed, j, late))
    shared = replay_sections(cfg, cands)
    alone = replay_sections(cfg, cands, share_prefixes=False)
    for a, b in zip(shared, alone, strict=True):
        np.testing.assert_array_equal(a, b)
    cost, sched = shared[0], shared[1]
    for seed, ps in plans.items():
        rows = first[seed]
        applied = sched[rows].T  # (H, S) as the env applies it
        _, env_cost = replay(cfg, seed, ps[0])
        assert cost[rows].sum() + cfg.possession_cost * applied.any(axis=1).sum() == pytest.approx(env_cost, rel=1e-12)
    with pytest.raises(ValueError, match="sections"):
        replay_sections(cfg, [(4, S, np.zeros(H, bool))])


def test_hindsight_of_several_episodes_at_once_is_each_episodes_own():
    cfg = scenario("small", horizon_years=1.0)
    H, S = cfg.horizon_steps, cfg.n_sections
    plan = np.zeros((H, S), bool)
    plan[1, :2] = True
    kw = dict(rounds=1, sd_thresholds_mm=(2.0,), peak_fractions=(np.inf,), stop_steps=(0,))
    both = hindsight_bounds(cfg, [(4, plan, ()), (6, plan, ())], **kw)
    for h in both:
        one = hindsight_bound(cfg, h["seed"], plan, **kw)
        assert one["cost"] == h["cost"] and np.array_equal(one["schedule"], h["schedule"])
    with pytest.raises(ValueError, match="distinct seeds"):
        hindsight_bounds(cfg, [(4, plan, ()), (4, plan, ())], **kw)


def test_recorded_rule_schedules_are_the_rules_own_under_another_recording_and_candidates():
    cfg = scenario("small", horizon_years=1.5, measurement_interval=4)
    exact = {"measurement_interval": 1, "sd_noise_mm": 0.0, "peak_noise_mm": 0.0}
    rule = SectionThreshold(threshold_mm=1.0)
    ((sched,),) = recorded_rule_schedules(cfg, [3], [rule], designs=(exact, {"measurement_interval": 4}))
    own, _ = replay(cfg.replace(**exact), 3, bind_policy(rule, cfg.replace(**exact)))
    assert sched.shape == (cfg.horizon_steps, 6) and sched.any() and np.array_equal(sched, own)  # cfg's design skipped
    _, sched_cost = replay(cfg, 3, sched.astype(bool))  # the same schedule is feasible on the episode as cfg records it
    h = hindsight_bound(cfg, 3, np.zeros_like(sched, bool), rounds=0, sd_thresholds_mm=(), peak_fractions=(np.inf,),
                        stop_steps=(0,), extra_schedules=(sched,))
    assert h["cost"] <= sched_cost + 1e-9
    with pytest.raises(ValueError, match="designs may change only"):
        recorded_rule_schedules(cfg, [3], [rule], designs=({"possession_cost": 1.0},))


def test_a_schedules_cost_does_not_depend_on_the_recording_design():
    # why a hindsight schedule found under one recording design bounds every other: the costs see the true state
    cfg = scenario("small", horizon_years=1.5)
    plan = np.zeros((cfg.horizon_steps, 6), bool)
    plan[[1, 3], :3] = True
    plan[4, 3:] = True
    costs = {replay(cfg.replace(**d), 5, plan)[1]
             for d in ({}, {"measurement_interval": 1, "sd_noise_mm": 0.0, "peak_noise_mm": 0.0},
                       {"measurement_interval": 2}, {"measurement_interval": 3, "sd_noise_mm": 0.5})}
    assert len(costs) == 1


def test_hindsight_variants_move_drop_and_add_one_tamping():
    col = np.zeros(10, bool)
    col[[2, 6]] = True
    restricted = np.zeros(10, bool)
    restricted[8:] = True
    var = _variants(col, restricted)
    assert all(v.sum() in (1, 2, 3) for v in var)
    keys = {tuple(np.flatnonzero(v)) for v in var}
    assert {(0, 6), (3, 6), (6,), (2,), (2, 4), (2, 8), (2, 6, 7)} <= keys and (2, 6) not in keys
    campaigns = np.zeros(10, bool)
    campaigns[[5, 9]] = True  # the plan tamps other sections at steps 5 and 9
    joined = {tuple(np.flatnonzero(v)) for v in _variants(col, restricted, campaigns)}
    assert keys < joined and {(5, 6), (2, 5), (2, 9), (2, 5, 6)} <= joined and (2, 6) not in joined


def test_cli_helpers():
    assert parse_seeds("3:6") == [3, 4, 5] and parse_seeds("1,4") == [1, 4] and parse_seeds(" 2, 0,") == [2, 0]
    for bad in ("1:2:3", "1.5:3", "a", "", ",", "-2:1", "-1", "4,4", "3:3"):
        with pytest.raises(ValueError, match="--seeds"):
            parse_seeds(bad)
    assert scenario_of("trackenv/TampingLineSmall-v0") == "small"
    assert scenario_of("trackenv/Tamping-v1") == "track60"  # the 60 m track is a preset of the one env
    for env_id in ("trackenv/TampingDiscrete-v1", "trackenv/TampingRanked-v1"):  # not per-section actions
        with pytest.raises(ValueError, match="per-section actions"):
            scenario_of(env_id)
    with pytest.raises(ValueError, match="not a registered env id"):
        scenario_of("trackenv/Tamping-v9")


def test_line_comparison_of_chosen_rules_keeps_episode_costs_and_classes(tmp_path):
    """`trackenv evaluate --env ... --rules`: only the chosen rules, each row with its per-episode costs (in the
    order of the seeds, for paired analyses afterwards) and its class breakdown; the table names the best rule."""
    import json

    from trackenv_agents.evaluation.line_compare import format_line_table, line_comparison

    out = line_comparison("trackenv/TampingLineSmall-v0", seeds=[0, 1], rules=["uniform-periodic", "no-maintenance"],
                          batch_size=2, progress=False, out_dir=str(tmp_path), horizon_years=0.5)
    assert sorted(r["policy"] for r in out["results"]) == ["no-maintenance", "uniform-periodic"]
    saved = json.loads((tmp_path / "line_compare.json").read_text())
    assert saved["best_rule"] == out["results"][0]["policy"] and saved["extra"] == []
    for r in saved["results"]:
        assert len(r["episode_costs"]) == 2 and np.mean(r["episode_costs"]) == pytest.approx(r["mean_cost"])
        assert set(r["classes"]) == {*SECTION_CLASSES, "line"}
    assert "IA" in format_line_table(out)


def test_saved_schedules_keep_the_cheapest_search_per_episode_and_check_the_scenario(tmp_path):
    rng = np.random.default_rng(3)
    plans = [rng.random((CFG.horizon_steps, CFG.n_sections)) < 0.2 for _ in range(3)]
    assert np.array_equal(schedule_from_rows(schedule_rows(plans[0])), plans[0])
    import json

    def search(name, episodes):
        path = tmp_path / name
        path.write_text(json.dumps({"hindsight": {"episodes": [
            {"seed": s, "replayed": c, "schedule": schedule_rows(p)} for s, c, p in episodes]}}))
        return path

    a = search("a.json", [(7, 100.0, plans[0]), (2, 50.0, plans[1])])
    b = search("b.json", [(7, 90.0, plans[2])])
    seeds, schedules, costs = saved_schedules([a, b], CFG)
    assert seeds == [2, 7] and costs == [50.0, 90.0]
    assert np.array_equal(schedules[1], plans[2]) and np.array_equal(schedules[0], plans[1])
    with pytest.raises(ValueError, match="shape"):
        saved_schedules([a], scenario("default"))
    with pytest.raises(ValueError, match="no hindsight schedule"):
        saved_schedules([search("c.json", [])], CFG)
    with pytest.raises(ValueError, match="choice codes"):
        schedule_from_rows(["01", "0x"])
