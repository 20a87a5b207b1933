"""The rules (one family for every preset) on the 60 m track's observation: valid actions for single and batched
observations, the rules they state, the random baseline, the registry and the tuned parameters per preset."""

from __future__ import annotations

import json

import numpy as np
import pytest

from trackenv.envs.line_config import scenario
from trackenv.envs.line_episode import line_observation_space
from trackenv_agents.rules import problems
from trackenv_agents.rules.base import RandomPolicy
from trackenv_agents.rules.line import (
    LINE_HEURISTICS,
    LINE_TUNED_FILE,
    BudgetedWorstFirst,
    GroupedThreshold,
    LineNoMaintenance,
    RegisterPeriodic,
    SectionThreshold,
    UniformPeriodic,
)

# the 60 m track cut to 30 m in 3 sections over 2 years of quarters (8 steps), as tests/conftest.py's small_config
CFG = scenario("track60", n_sections=3, segment_length_m=30.0, sections_per_segment=3, capacity=3,
               horizon_years=2.0)


def obs_at(step: int, sd, peak=None, tampings=None, cfg=CFG, n_envs: int | None = None):
    """A (possibly batched) observation at ``step`` with given section SD/peak [mm]; every section last tamped a
    year ago, before the episode unless ``tampings`` says otherwise (so no measurement is stale)."""
    space = line_observation_space(cfg)
    o = {k: np.zeros(v.shape, np.float32) for k, v in space.spaces.items()}
    s = cfg.n_sections
    o["section_sd"] = np.asarray(sd, np.float32)
    o["section_peak"] = np.asarray(peak if peak is not None else np.zeros(s), np.float32)
    o["tampings"] = np.asarray(tampings if tampings is not None else np.zeros(s), np.float32)
    o["years_since_tamping"] = np.ones(s, np.float32)
    o["time"] = np.array([step / cfg.horizon_steps], np.float32)
    if n_envs is not None:
        o = {k: np.repeat(v[None], n_envs, axis=0) for k, v in o.items()}
    return o


def all_policies(cfg):
    return [cls(**cls.param_grid()[0]).bind(cfg) for cls in LINE_HEURISTICS.values()]


CAPPED = CFG.replace(capacity=2)  # the possession takes two of the three sections


@pytest.mark.parametrize("policy", [*all_policies(CAPPED), RandomPolicy(0.5)], ids=lambda p: repr(p))
def test_valid_actions_single_and_batched(policy):
    space = line_observation_space(CAPPED)
    space.seed(0)
    rng = np.random.default_rng(0)
    single = space.sample()
    action, state = policy.predict(single, deterministic=True)
    assert action.shape == (CAPPED.n_sections,) and action.dtype == np.int8 and state is None
    assert set(np.unique(action)) <= {0, 1}
    batch = {k: np.stack([space.sample()[k] for _ in range(5)]) for k in space.spaces}
    batch["time"] = rng.integers(0, CAPPED.horizon_steps, (5, 1)).astype(np.float32) / CAPPED.horizon_steps
    action, _ = policy.predict(batch, state=None, episode_start=np.ones(5, bool))
    assert action.shape == (5, CAPPED.n_sections)
    assert set(np.unique(action)) <= {0, 1}
    if not isinstance(policy, RandomPolicy):  # the rules respect the capacity themselves; the env clips the rest
        assert (action.sum(axis=1) <= CAPPED.capacity).all()


def test_batched_equals_rowwise():
    sd = np.array([[0.5, 2.0, 1.1], [3.0, 0.1, 1.5], [1.0, 1.0, 1.0]])
    steps = [4, 5, 6]
    one = CFG.replace(capacity=1)
    for policy in (SectionThreshold(threshold_mm=1.0).bind(CFG), SectionThreshold(threshold_mm=1.0).bind(one),
                   GroupedThreshold(trigger_mm=2.5, include_mm=1.0).bind(CFG),
                   BudgetedWorstFirst(every_years=0.5, n_worst=2, min_sd_mm=1.0).bind(CFG),
                   UniformPeriodic(interval_years=0.75).bind(one)):
        batch = obs_at(0, sd[0], n_envs=3)
        batch["section_sd"] = sd.astype(np.float32)
        batch["time"] = np.array([[k / CFG.horizon_steps] for k in steps], np.float32)
        a, _ = policy.predict(batch)
        assert a.any(), policy  # something to compare
        for i in range(3):
            ai, _ = policy.predict(obs_at(steps[i], sd[i]))
            np.testing.assert_array_equal(a[i], ai)


def test_no_maintenance_never_tamps():
    p = LineNoMaintenance().bind(CFG)
    for step in range(CFG.horizon_steps):
        a, _ = p.predict(obs_at(step, [50, 50, 50], [100, 100, 100]))
        assert not a.any()


def test_section_threshold_tamps_at_and_above_the_threshold_worst_first():
    p = SectionThreshold(threshold_mm=1.5).bind(CFG)
    a, _ = p.predict(obs_at(3, [1.49, 1.5, 2.7]))
    np.testing.assert_array_equal(a, [0, 1, 1])
    a, _ = p.predict(obs_at(3, [1.49, 1.5, 2.7], n_envs=2))
    np.testing.assert_array_equal(a, [[0, 1, 1]] * 2)
    a, _ = SectionThreshold(threshold_mm=1.5).bind(CFG.replace(capacity=1)).predict(obs_at(3, [1.49, 1.5, 2.7]))
    np.testing.assert_array_equal(a, [0, 0, 1])  # the capacity keeps the worst


def test_uniform_periodic_schedule():
    p = UniformPeriodic(interval_years=1.0).bind(CFG)  # 4 steps a year; the whole track in one campaign
    due = [bool(p.predict(obs_at(k, [1, 1, 1]))[0].all()) for k in range(CFG.horizon_steps)]
    assert due == [True, False, False, False, True, False, False, False]
    assert not any(p.predict(obs_at(k, [1, 1, 1]))[0].any() and not due[k] for k in range(CFG.horizon_steps))
    # an offset of half a year: the first campaign at year 0.5 (step 2), then every year
    p = UniformPeriodic(interval_years=1.0, offset_years=0.5).bind(CFG)
    due = [bool(p.predict(obs_at(k, [1, 1, 1]))[0].any()) for k in range(CFG.horizon_steps)]
    assert due == [False, False, True, False, False, False, True, False]
    # one section per possession: the cycle's campaigns on consecutive steps, section by section
    p = UniformPeriodic(interval_years=1.0).bind(CFG.replace(capacity=1))
    acts = [p.predict(obs_at(k, [1.0, 3.0, 2.0]))[0] for k in range(CFG.horizon_steps)]
    np.testing.assert_array_equal(acts, [[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 0]] * 2)
    # batched: envs at different times
    b = obs_at(0, [1, 1, 1], n_envs=3)
    b["time"] = np.array([[0.0], [4 / 8], [5 / 8]], np.float32)
    a, _ = UniformPeriodic(interval_years=1.0).bind(CFG).predict(b)
    np.testing.assert_array_equal(a.all(axis=1), [True, True, False])


def test_register_periodic_tamps_known_zones_on_their_own_calendar():
    p = RegisterPeriodic(plain_years=2.0, zone_years=0.5).bind(CFG)
    counts = np.zeros(3, int)
    for k in range(CFG.horizon_steps):
        o = obs_at(k, [1, 1, 1])
        o["register"][:] = [0, 1, 0]
        counts += p.predict(o)[0]
    np.testing.assert_array_equal(counts, [1, 4, 1])  # plain: once in 2 years; the zone: every half year


def test_budgeted_worst_first_budget():
    p = BudgetedWorstFirst(every_years=0.5, n_worst=1, min_sd_mm=1.0).bind(CFG)  # a campaign every second step
    np.testing.assert_array_equal(p.predict(obs_at(0, [1.2, 3.0, 0.5]))[0], [0, 1, 0])
    assert not p.predict(obs_at(1, [1.2, 3.0, 2.0]))[0].any()  # not a campaign step
    np.testing.assert_array_equal(p.predict(obs_at(2, [1.2, 3.0, 2.0]))[0], [0, 1, 0])
    assert not p.predict(obs_at(4, [0.2, 0.3, 0.5]))[0].any()  # nothing above min_sd_mm
    p = BudgetedWorstFirst(every_years=0.25, n_worst=3, min_sd_mm=1.0)
    np.testing.assert_array_equal(p.bind(CFG).predict(obs_at(1, [1.2, 3.0, 0.5]))[0], [1, 1, 0])
    np.testing.assert_array_equal(p.bind(CFG.replace(capacity=1)).predict(obs_at(1, [1.2, 3.0, 2.0]))[0], [0, 1, 0])


def test_grouped_threshold_calls_a_campaign_on_the_trigger_and_takes_every_section_above_include():
    p = GroupedThreshold(trigger_mm=2.0, include_mm=1.0).bind(CFG)
    assert not p.predict(obs_at(0, [1.5, 1.9, 0.5]))[0].any()
    np.testing.assert_array_equal(p.predict(obs_at(0, [1.5, 2.1, 0.5]))[0], [1, 1, 0])
    np.testing.assert_array_equal(p.predict(obs_at(0, [1.5, 2.0, 1.0]))[0], [1, 1, 1])  # both bounds included
    # include above the trigger: the campaign takes the sections at the trigger, never fewer than its cause
    p = GroupedThreshold(trigger_mm=2.0, include_mm=3.0).bind(CFG)
    np.testing.assert_array_equal(p.predict(obs_at(0, [1.5, 2.1, 2.9]))[0], [0, 1, 1])


def test_random_policy_reproducible():
    p = RandomPolicy(0.5, seed=3)
    a1 = [p.predict(obs_at(0, [1, 1, 1]))[0] for _ in range(5)]
    p.reset()
    a2 = [p.predict(obs_at(0, [1, 1, 1]))[0] for _ in range(5)]
    np.testing.assert_array_equal(a1, a2)
    assert len({tuple(a) for a in a1}) > 1  # a generator, not a constant
    assert not RandomPolicy(0.0).predict(obs_at(0, [1, 1, 1]))[0].any()
    assert RandomPolicy(1.0).predict(obs_at(0, [1, 1, 1]))[0].all()
    with pytest.raises(ValueError, match="p must be in"):
        RandomPolicy(1.5)


def test_registry_grids_and_binding():
    assert set(LINE_HEURISTICS) == {"no-maintenance", "uniform-periodic", "section-threshold", "grouped-threshold",
                                    "register-periodic", "budgeted-worst-first"}
    assert problems.rules_for(CFG) is LINE_HEURISTICS
    for name, cls in LINE_HEURISTICS.items():
        assert cls.name == name
        grid = cls.param_grid()
        assert 1 <= len(grid) <= 25 and len({json.dumps(p, sort_keys=True) for p in grid}) == len(grid)
        for params in grid:
            p = cls(**params).bind(CFG)
            assert p.name == name and p.params == params  # the calendar is not a parameter
            assert (p.steps_per_year, p.horizon_steps, p.capacity) == (4, CFG.horizon_steps, CFG.capacity)
            assert repr(p).startswith(f"{cls.__name__}(")
    with pytest.raises(ValueError, match="LineConfig"):
        problems.rules_for({"n_sections": 3})


def test_tuned_parameters_are_those_of_the_preset_at_any_horizon_else_the_default_lines(tmp_path, monkeypatch):
    default_line = json.loads(LINE_TUNED_FILE.read_text())["params"]
    mine = tmp_path / "track60.json"
    mine.write_text(json.dumps({"params": {"section-threshold": {"threshold_mm": 2.5}}}))
    monkeypatch.setitem(problems.TUNED_FILES, "track60", mine)
    assert problems.tuned_params_for(scenario("track60")) == {"section-threshold": {"threshold_mm": 2.5}}
    assert problems.tuned_params_for(scenario("track60", horizon_years=2.0))["section-threshold"] == {
        "threshold_mm": 2.5}
    assert problems.tuned_params_for(CFG) == default_line  # a cut of the preset is no shipped preset
    assert problems.tuned_params_for(scenario("small")) == default_line
    monkeypatch.setitem(problems.TUNED_FILES, "track60", tmp_path / "missing.json")
    assert problems.tuned_params_for(scenario("track60")) == default_line


def test_tuned_rule_is_the_rule_with_its_shipped_parameters_and_names_what_is_missing(tmp_path, monkeypatch):
    mine = tmp_path / "track60.json"
    mine.write_text(json.dumps({"params": {"section-threshold": {"threshold_mm": 2.5}}}))
    monkeypatch.setitem(problems.TUNED_FILES, "track60", mine)
    rule = problems.tuned_rule(scenario("track60"), "section-threshold", require_tuned=True)
    assert isinstance(rule, SectionThreshold) and rule.params == {"threshold_mm": 2.5}
    # none ship for this rule here: its own defaults, or a clear error where the tuned rule is required
    assert problems.tuned_rule(scenario("track60"), "grouped-threshold").params == GroupedThreshold().params
    with pytest.raises(ValueError, match="no tuned parameters ship.*section-threshold"):
        problems.tuned_rule(scenario("track60"), "grouped-threshold", require_tuned=True)
    # a choice rule is no rule of a tamp-only line; on a line with choices it is, with that line's parameters
    with pytest.raises(ValueError, match="rule must be one of .*'grouped-threshold'.*got 'choice-threshold'"):
        problems.tuned_rule(scenario("default"), "choice-threshold")
    shipped = problems.tuned_params_for(scenario("defects"))["choice-threshold"]
    assert problems.tuned_rule(scenario("defects"), "choice-threshold").params == shipped
