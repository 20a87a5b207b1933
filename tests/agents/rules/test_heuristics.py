"""The heuristics: valid actions for single and batched observations, and the rules they state."""

from __future__ import annotations

import numpy as np
import pytest

from trackenv.envs.config import TampingEnvConfig
from trackenv.envs.tamping import observation_space
from trackenv_agents.rules.tamping import (
    HEURISTICS,
    Campaign,
    DefectThreshold,
    NoMaintenance,
    Periodic,
    RandomPolicy,
    SDThreshold,
    WorstFirst,
    make_policy,
)

CFG = TampingEnvConfig(track_length_m=30.0, n_sections=3, horizon_years=2.0)  # 8 steps


def obs_at(step: int, sd, peak=None, tampings=None, cfg=CFG, n_envs: int | None = None):
    """A (possibly batched) observation at ``step`` with given section SD/peak [mm]."""
    space = observation_space(cfg)
    o = {k: np.zeros(v.shape, np.float32) for k, v in space.spaces.items()}
    s = cfg.n_sections
    o["section_sd"] = np.asarray(sd, np.float32)
    o["section_peak"] = np.asarray(peak if peak is not None else np.zeros(s), np.float32)
    o["tampings"] = np.asarray(tampings if tampings is not None else np.zeros(s), np.float32)
    o["time"] = np.array([step / cfg.horizon_steps], np.float32)
    if n_envs is not None:
        o = {k: np.repeat(v[None], n_envs, axis=0) for k, v in o.items()}
    return o


def all_policies():
    out = [cls(**cls.param_grid()[0]).bind(CFG) for cls in HEURISTICS.values()]
    out.append(Periodic(1.0, sections="worst", n_worst=1).bind(CFG))
    return out


@pytest.mark.parametrize("policy", all_policies(), ids=lambda p: repr(p))
def test_valid_actions_single_and_batched(policy):
    space = observation_space(CFG)
    space.seed(0)
    rng = np.random.default_rng(0)
    single = space.sample()
    action, state = policy.predict(single, deterministic=True)
    assert action.shape == (CFG.n_sections,) and state is None
    assert set(np.unique(action)) <= {0, 1}
    batch = {k: np.stack([space.sample()[k] for _ in range(5)]) for k in space.spaces}
    batch["time"] = rng.integers(0, CFG.horizon_steps, (5, 1)).astype(np.float32) / CFG.horizon_steps
    action, _ = policy.predict(batch, state=None, episode_start=np.ones(5, bool))
    assert action.shape == (5, CFG.n_sections)
    assert set(np.unique(action)) <= {0, 1}


def test_batched_equals_rowwise():
    sd = np.array([[0.5, 2.0, 1.1], [3.0, 0.1, 1.5], [1.0, 1.0, 1.0]])
    for policy in (SDThreshold(1.0), WorstFirst(4.0, 1.2).bind(CFG), Periodic(1.0, "worst", 2).bind(CFG)):
        batch = obs_at(4, sd[0], n_envs=3)
        batch["section_sd"] = sd.astype(np.float32)
        a, _ = policy.predict(batch)
        for i in range(3):
            ai, _ = policy.predict(obs_at(4, sd[i]))
            np.testing.assert_array_equal(a[i], ai)


def test_no_maintenance_never_tamps():
    p = NoMaintenance()
    for step in range(CFG.horizon_steps):
        a, _ = p.predict(obs_at(step, [50, 50, 50], [100, 100, 100]))
        assert not a.any()


def test_sd_threshold_tamps_exactly_above():
    a, _ = SDThreshold(1.5).predict(obs_at(3, [1.49, 1.5, 2.7]))
    np.testing.assert_array_equal(a, [0, 1, 1])
    a, _ = SDThreshold(1.5).predict(obs_at(3, [1.49, 1.5, 2.7], n_envs=2))
    np.testing.assert_array_equal(a, [[0, 1, 1]] * 2)


def test_defect_threshold_uses_peak():
    a, _ = DefectThreshold(8.0).predict(obs_at(3, [9, 9, 9], [7.9, 8.0, 20.0]))
    np.testing.assert_array_equal(a, [0, 1, 1])


def test_periodic_schedule():
    p = Periodic(1.0).bind(CFG)  # 4 steps a year
    due = [bool(p.predict(obs_at(k, [1, 1, 1]))[0].all()) for k in range(CFG.horizon_steps)]
    assert due == [False, False, False, False, True, False, False, False]
    p = Periodic(0.5, sections="worst", n_worst=1).bind(CFG)
    acts = [p.predict(obs_at(k, [1.0, 3.0, 2.0]))[0] for k in range(CFG.horizon_steps)]
    for k, a in enumerate(acts):
        np.testing.assert_array_equal(a, [0, 1, 0] if k in (2, 4, 6) else [0, 0, 0])
    # batched: envs at different times
    b = obs_at(0, [1, 1, 1], n_envs=3)
    b["time"] = np.array([[0.0], [4 / 8], [5 / 8]], np.float32)
    a, _ = Periodic(1.0).bind(CFG).predict(b)
    np.testing.assert_array_equal(a.all(axis=1), [False, True, False])


def test_worst_first_budget():
    p = WorstFirst(4.0, threshold_mm=1.0).bind(CFG)  # one section a step
    a, _ = p.predict(obs_at(0, [1.2, 3.0, 0.5]))
    np.testing.assert_array_equal(a, [0, 1, 0])
    a, _ = p.predict(obs_at(1, [0.2, 0.3, 0.5], tampings=[0, 1, 0]))  # nothing above threshold
    assert not a.any()
    p = WorstFirst(2.0, threshold_mm=1.0).bind(CFG)  # one section every second step
    a, _ = p.predict(obs_at(0, [1.2, 3.0, 2.0]))
    assert not a.any()
    a, _ = p.predict(obs_at(1, [1.2, 3.0, 2.0]))
    np.testing.assert_array_equal(a, [0, 1, 0])
    a, _ = p.predict(obs_at(2, [1.2, 3.0, 2.0], tampings=[0, 1, 0]))  # budget used
    assert not a.any()


def test_campaign_triggers_on_the_worst_section_and_stops_before_the_horizon():
    p = Campaign(trigger_mm=2.0, include_mm=1.0, stop_years=0.5).bind(CFG)  # 8 steps of a quarter year
    assert not p.predict(obs_at(0, [1.5, 1.9, 0.5]))[0].any()
    np.testing.assert_array_equal(p.predict(obs_at(0, [1.5, 2.1, 0.5]))[0], [1, 1, 0])
    np.testing.assert_array_equal(Campaign(2.0).bind(CFG).predict(obs_at(0, [1.5, 2.1, 0.5]))[0], [1, 1, 1])
    assert p.predict(obs_at(5, [1.5, 2.1, 0.5]))[0].any()  # 0.75 years left
    assert not p.predict(obs_at(6, [1.5, 2.1, 0.5]))[0].any()  # 0.5 years left: too late
    with pytest.raises(ValueError, match="include_mm"):
        Campaign(trigger_mm=2.0, include_mm=3.0)


def test_random_policy_reproducible():
    p = RandomPolicy(0.5, seed=3)
    a1 = [p.predict(obs_at(0, [1, 1, 1]))[0] for _ in range(5)]
    p.reset()
    a2 = [p.predict(obs_at(0, [1, 1, 1]))[0] for _ in range(5)]
    np.testing.assert_array_equal(a1, a2)
    assert not RandomPolicy(0.0).predict(obs_at(0, [1, 1, 1]))[0].any()


def test_registry_and_grids():
    expected = {"no_maintenance", "periodic", "sd_threshold", "defect_threshold", "worst_first", "campaign"}
    assert set(HEURISTICS) >= expected
    for name, cls in HEURISTICS.items():
        assert cls.name == name
        grid = cls.param_grid()
        assert 1 <= len(grid) <= 12
        for params in grid:
            p = make_policy(name, **params)
            assert p.name == name
            for k, v in params.items():
                assert p.params[k] == v
    with pytest.raises(ValueError, match="unknown heuristic"):
        make_policy("nope")
    with pytest.raises(ValueError):
        Periodic(0.0)
