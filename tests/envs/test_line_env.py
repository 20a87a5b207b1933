"""TampingLine: the API checks, determinism, pickling, reward parts, and one cost/limit test per class."""

import pickle

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import trackenv  # noqa: F401  (registers the ids)
from trackenv.envs.line import TampingLine, TampingLineVectorEnv
from trackenv.envs.line_config import SCENARIOS, LineConfig, scenario

SHORT = {"horizon_years": 0.75}  # 3 steps


@pytest.mark.parametrize("env_id", ["trackenv/TampingLineSmall-v0", "trackenv/TampingLine-v0",
                                    "trackenv/TampingLineHard-v0"])
def test_checkers(env_id):
    from stable_baselines3.common.env_checker import check_env as sb3_check

    env = gym.make(env_id, **SHORT)
    check_env(env.unwrapped, skip_render_check=True)
    sb3_check(TampingLine(scenario=env_id_scenario(env_id), **SHORT), warn=False)


def env_id_scenario(env_id):
    return {"trackenv/TampingLineSmall-v0": "small", "trackenv/TampingLine-v0": "default",
            "trackenv/TampingLineHard-v0": "hard"}[env_id]


def _rollout(env, seed, actions):
    obs, _ = env.reset(seed=seed)
    out = [obs]
    for a in actions:
        obs, r, _, _, info = env.step(a)
        out.append((obs, r, info["section_sd_m"]))
    return out


def _same(a, b):
    for x, y in zip(a, b):
        if isinstance(x, dict):
            assert all(np.array_equal(x[k], y[k]) for k in x)
        else:
            assert all(np.array_equal(x[0][k], y[0][k]) for k in x[0])
            assert x[1] == y[1]
            assert np.allclose(x[2], y[2], rtol=0, atol=1e-12)


def test_same_seed_same_rollout_single_sync_native():
    actions = [np.array([1, 0, 1, 0, 0, 0]), np.zeros(6, int), np.array([0, 1, 0, 0, 0, 1])]
    a = _rollout(TampingLine(scenario="small", **SHORT), 7, actions)
    b = _rollout(TampingLine(scenario="small", **SHORT), 7, actions)
    _same(a, b)
    vec = TampingLineVectorEnv(2, scenario="small", **SHORT)
    obs, _ = vec.reset(seed=7)
    assert np.array_equal(obs["section_sd"][0], a[0]["section_sd"])
    sync = gym.vector.SyncVectorEnv([lambda: TampingLine(scenario="small", **SHORT)] * 2)
    sobs, _ = sync.reset(seed=7)
    assert np.array_equal(sobs["section_sd"], obs["section_sd"])
    for i, act in enumerate(actions[:2]):
        batch = np.stack([act, act])
        obs, r, _, _, _ = vec.step(batch)
        sobs, sr, _, _, _ = sync.step(batch)
        assert r[0] == pytest.approx(a[i + 1][1], abs=1e-9)
        assert np.allclose(r, sr, atol=1e-9)
        assert np.allclose(obs["section_sd"], sobs["section_sd"], atol=1e-6)


def test_pickle_round_trip_mid_episode():
    env = TampingLine(scenario="small", **SHORT)
    env.reset(seed=3)
    env.step(np.array([1, 1, 0, 0, 0, 0]))
    clone = pickle.loads(pickle.dumps(env))
    a = env.step(np.array([0, 0, 1, 0, 0, 0]))
    b = clone.step(np.array([0, 0, 1, 0, 0, 0]))
    assert a[1] == b[1]
    assert np.array_equal(a[0]["section_sd"], b[0]["section_sd"])


def test_reward_is_minus_sum_of_parts_and_vector_autoreset():
    vec = TampingLineVectorEnv(2, scenario="small", horizon_years=0.5)
    vec.reset(seed=0)
    for a in ([np.ones(6, int)] * 2, [np.zeros(6, int)] * 2):
        obs, r, term, trunc, info = vec.step(np.stack(a))
        parts = sum(info["costs"].values())
        assert np.allclose(r, -parts)
    assert trunc.all() and "final_info" in info
    assert obs["time"].max() == 0.0  # reset in the same step


def test_transition_zone_degrades_faster_than_plain_track():
    cfg = {"transition_probability": 0.5, "switch_probability": 0.0, "wet_spot_probability": 0.0,
           "horizon_years": 1.0}
    growth = {0: [], 1: []}
    vec = TampingLineVectorEnv(3, scenario="small", **cfg)
    obs0, info0 = vec.reset(seed=11)
    reg = obs0["register"].astype(int)
    for _ in range(4):
        _, _, _, _, info = vec.step(np.zeros((3, 6), int))
    d = info["final_info"] if "final_info" in info else None
    sd1 = np.stack([f["section_sd_m"] for f in d])
    g = sd1 - info0["section_sd_m"]
    for k in (0, 1):
        growth[k] = g[reg == k]
    assert len(growth[1]) and len(growth[0])
    assert np.median(growth[1]) > 2 * np.median(growth[0])


def test_hidden_wet_spot_appears_and_is_seen_only_through_measurement():
    env = TampingLine(scenario="small", wet_spot_probability=1.0, transition_probability=0.0,
                      switch_probability=0.0, horizon_years=2.0, measurement_interval=2)
    obs, info = env.reset(seed=5)
    assert not info["wet_spot_active"].any()
    assert np.all(obs["register"] == 0)  # wet spots are in no register
    seen_active, prev_obs = False, obs
    for _ in range(8):
        obs, _, _, _, info = env.step(np.zeros(6, int))
        seen_active |= info["wet_spot_active"].any()
        assert np.all(obs["register"] == 0)
        if obs["measurement_age"][0] > 0:  # no recording run this step: the observation did not change
            assert np.array_equal(obs["section_sd"], prev_obs["section_sd"])
            assert not np.array_equal(info["section_sd_m"] * 1e3, obs["section_sd"])
        prev_obs = obs
    assert seen_active
    assert info["rate_factor"].max() > 1.5 * np.median(info["rate_factor"])


def test_over_capacity_refused_or_clipped():
    env = TampingLine(scenario="small", over_capacity="raise", **SHORT)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="capacity"):
        env.step(np.ones(6, int))
    env = TampingLine(scenario="small", **SHORT)
    obs, _ = env.reset(seed=0)
    _, _, _, _, info = env.step(np.ones(6, int))
    assert info["clipped"] and info["tamped_sections"].sum() == env.config.capacity
    worst = np.argsort(-obs["section_sd"])[: env.config.capacity]
    assert set(np.flatnonzero(info["tamped_sections"])) == set(worst)
    # a section tamped last step is masked and dropped
    mask = env.action_masks().reshape(6, 2)[:, 1]
    assert not mask[info["tamped_sections"]].any()


def test_config_validation_and_scenarios():
    with pytest.raises(ValueError, match="unknown LineConfig"):
        LineConfig.from_dict({"n_sectoins": 3})
    with pytest.raises(ValueError, match="capacity"):
        LineConfig(n_sections=4, capacity=5)
    with pytest.raises(ValueError, match="scenario"):
        scenario("nope")
    assert set(SCENARIOS) == {"small", "default", "hard"}
    with pytest.raises(ValueError, match="shape"):
        env = TampingLine(scenario="small", **SHORT)
        env.reset(seed=0)
        env.step(np.ones(5, int))
