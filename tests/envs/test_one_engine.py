"""The 60 m track is a preset of the one episode engine: a segment that carries several sections. These tests
run it and a line through the same engine and check what a segment of several sections adds: tamping acts on
the chosen sections' sleepers only, the sections' quality and contact force come from their own sleepers, and
the 60 m preset is measured without error after every step."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from trackenv.envs import scenario
from trackenv.envs.env import TrackEnv, TrackVectorEnv
from trackenv.envs.line_episode import LineBatch
from trackenv.physics.geometry import d1_filter, section_peak, section_sd

TRACK = scenario("track60", horizon_years=2.0)


def _engine(config, seed: int = 0) -> LineBatch:
    env = TrackEnv(config)
    env.reset(seed=seed)
    return env.engine


def test_the_60_m_track_and_a_line_step_through_the_same_engine():
    for config in (TRACK, scenario("small", horizon_years=1.0)):
        env = TrackEnv(config)
        env.reset(seed=3)
        assert type(env.engine) is LineBatch
        obs, reward, _, _, info = env.step(np.ones(config.n_sections, np.int8))
        assert env.observation_space.contains(obs)
        assert -reward == pytest.approx(info["cost"], rel=1e-12)
    env = gym.make("trackenv/Tamping-v1")
    assert env.unwrapped.config == scenario("track60")


def test_tamping_a_section_of_a_longer_segment_changes_its_sleepers_only():
    engine = _engine(TRACK, seed=1)
    env_steps = 3
    for _ in range(env_steps):  # let the track settle so that a tamping has something to do
        engine.advance(np.zeros((1, 6), bool), [0], [np.random.default_rng(0)])
    level, u = engine.level.copy(), engine.u.copy()
    assert (u[0] > 0).all()
    want = np.zeros((1, 6), bool)
    want[0, 2] = True
    engine.apply(want)
    changed = np.flatnonzero(engine.level[0] != level[0])
    inside = np.flatnonzero(engine.section_of_sleeper == 2)
    assert set(changed) <= set(inside) and len(changed) >= len(inside) - 2
    assert (engine.u[0, inside] == 0).all() and (engine.u[0, ~np.isin(np.arange(101), inside)] > 0).all()
    assert engine.tampings[:6].tolist() == [0, 0, 1, 0, 0, 0]
    d1 = d1_filter(engine.level[:1], 0.6)
    sd_after = section_sd(d1, engine.section_of_sleeper, 6)[0]
    assert engine.sd_after_tamping[2] == pytest.approx(sd_after[2], rel=1e-12)
    assert engine.sd_after_tamping[[0, 1, 3, 4, 5]].tolist() == [0.0] * 5


def test_the_sections_quality_and_contact_force_come_from_their_own_sleepers():
    env = TrackEnv(TRACK)
    obs, info = env.reset(seed=4)
    obs, _, _, _, info = env.step(np.zeros(6, np.int8))
    engine = env.engine
    d1 = d1_filter(engine.level[:1], 0.6)
    np.testing.assert_allclose(info["section_sd_m"], section_sd(d1, engine.section_of_sleeper, 6)[0], rtol=1e-12)
    np.testing.assert_allclose(info["section_peak_m"], section_peak(d1, engine.section_of_sleeper, 6)[0], rtol=1e-12)
    # the 60 m preset is measured without error after every step: what it observes is the true state
    np.testing.assert_allclose(obs["section_sd"], info["section_sd_mm"].astype(np.float32))
    assert obs["measurement_age"][0] == 0.0
    profile = obs["contact_force"][0]  # kN per sleeper bay
    assert profile.shape == (101,) and 60.0 < profile.mean() < 200.0  # about the static wheel load, 98 kN
    per_section = [profile[engine.section_of_sleeper == k].max() for k in range(6)]
    np.testing.assert_allclose(engine.contact_force[:6] / 1e3, per_section, rtol=1e-6)


def test_a_vector_row_of_the_60_m_track_is_the_single_env():
    vec = TrackVectorEnv(2, TRACK)
    vec.reset(seed=5)
    single = TrackEnv(TRACK)
    single.reset(seed=6)
    for k in range(3):
        action = np.eye(6, dtype=np.int8)[k]
        obs, rew, _, _, _ = vec.step(np.stack([action, action]))
        s_obs, s_rew, _, _, _ = single.step(action)
        assert rew[1] == s_rew and all(np.array_equal(obs[key][1], s_obs[key]) for key in s_obs)


@pytest.mark.parametrize(("changes", "message"), [
    ({"segment_length_m": 50.0}, "segment_length_m must be sections_per_segment x section_length_m"),
    ({"n_sections": 4}, "n_sections must be a multiple of sections_per_segment"),
    ({"sections_per_segment": 0}, "sections_per_segment"),
])
def test_a_segment_of_several_sections_is_checked(changes, message):
    with pytest.raises(ValueError, match=message):
        scenario("track60", **changes)


def test_forking_single_sections_needs_one_section_per_segment():
    engine = _engine(TRACK)
    with pytest.raises(ValueError, match="one section per segment"):
        engine.copy_rows(np.array([0]), engine, np.array([1]))
