"""Rendering: render_mode="rgb_array" gives an (H, W, 3) uint8 picture of the episode."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.passive_env_checker import env_render_passive_checker

import trackenv.envs  # noqa: F401  (registers the ids)
from trackenv.envs import TampingEnv


def _check_frame(frame) -> None:
    assert isinstance(frame, np.ndarray)
    assert frame.ndim == 3 and frame.shape[2] == 3
    assert frame.shape[0] >= 100 and frame.shape[1] >= 100
    assert frame.dtype == np.uint8
    assert len(np.unique(frame.reshape(-1, 3), axis=0)) > 10  # a picture, not a blank canvas


@pytest.mark.parametrize("env_id", ["trackenv/Tamping-v0", "trackenv/TampingDiscrete-v0"])
def test_rgb_array_after_reset_and_after_steps(env_id: str, small_config) -> None:
    env = gym.make(env_id, config=small_config, render_mode="rgb_array")
    assert "rgb_array" in env.metadata["render_modes"]
    assert env.render_mode == "rgb_array"
    env.reset(seed=0)
    first = env.render()
    _check_frame(first)
    env.step(env.action_space.sample() * 0)  # no tamping
    second = env.render()
    _check_frame(second)
    assert second.shape == first.shape
    assert not np.array_equal(first, second)  # the year and the profiles moved on
    tamp = 1 if env_id.endswith("Discrete-v0") else np.array([1, 0, 0], dtype=np.int8)
    env.step(tamp)
    third = env.render()
    _check_frame(third)
    assert third.shape == first.shape
    env.close()


def test_render_passes_gymnasiums_passive_checker(small_config) -> None:
    env = TampingEnv(small_config, render_mode="rgb_array")
    env.reset(seed=1)
    env_render_passive_checker(env)


def test_no_render_mode_or_no_episode_renders_nothing(small_config) -> None:
    assert TampingEnv(small_config, render_mode="rgb_array").render() is None  # before reset
    env = TampingEnv(small_config)
    env.reset(seed=0)
    assert env.render() is None
    with pytest.raises(ValueError, match="render_mode"):
        TampingEnv(small_config, render_mode="human")
