"""Rendering: render_mode="rgb_array" gives an (H, W, 3) uint8 picture of the episode: the profiles along the
60 m track (a segment of several sections) and the sections of a line."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.utils.passive_env_checker import env_render_passive_checker

import trackenv.envs  # noqa: F401  (registers the ids)
from trackenv.envs import TampingEnv
from trackenv.envs.line import TampingLine, TampingLineVectorEnv


def _check_frame(frame) -> None:
    assert isinstance(frame, np.ndarray)
    assert frame.ndim == 3 and frame.shape[2] == 3
    assert frame.shape[0] >= 100 and frame.shape[1] >= 100
    assert frame.dtype == np.uint8
    assert len(np.unique(frame.reshape(-1, 3), axis=0)) > 10  # a picture, not a blank canvas


def _checked_render(env) -> np.ndarray:
    """``env.render()`` through Gymnasium's passive render checker, whose findings are warnings: any warning it
    gives fails here, and what it checks is asserted too (declared modes and fps, an rgb_array frame)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        frame = env_render_passive_checker(env)
    assert [str(w.message) for w in caught] == []
    modes = env.metadata["render_modes"]
    assert isinstance(modes, (list, tuple)) and all(isinstance(m, str) for m in modes) and "rgb_array" in modes
    fps = env.metadata["render_fps"]
    assert isinstance(fps, (int, float)) and not isinstance(fps, bool) and fps > 0
    assert env.render_mode == "rgb_array"
    _check_frame(frame)
    return frame


class _FloatFrames(gym.Env):
    """Renders a float picture: what the checker must flag."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 4}
    render_mode = "rgb_array"

    def render(self):
        return np.random.default_rng(0).random((120, 120, 3))


def test_the_render_check_can_fail() -> None:
    with pytest.raises(AssertionError, match="uint8"):
        _checked_render(_FloatFrames())


@pytest.mark.parametrize("env_id", ["trackenv/Tamping-v1", "trackenv/TampingDiscrete-v1"])
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
    tamp = 1 if env_id.endswith("Discrete-v1") else np.array([1, 0, 0], dtype=np.int8)
    env.step(tamp)
    third = env.render()
    _check_frame(third)
    assert third.shape == first.shape
    env.close()


def test_render_passes_gymnasiums_passive_checker(small_config) -> None:
    env = TampingEnv(small_config, render_mode="rgb_array")
    env.reset(seed=1)
    first = _checked_render(env)
    env.step(np.array([1, 0, 0], dtype=np.int8))
    assert _checked_render(env).shape == first.shape
    wrapped = gym.make("trackenv/Tamping-v1", config=small_config, render_mode="rgb_array")  # through the wrappers
    wrapped.reset(seed=1)
    np.testing.assert_array_equal(_checked_render(wrapped), first)


def test_no_render_mode_or_no_episode_renders_nothing(small_config) -> None:
    assert TampingEnv(small_config, render_mode="rgb_array").render() is None  # before reset
    env = TampingEnv(small_config)
    env.reset(seed=0)
    assert env.render() is None
    with pytest.raises(ValueError, match="render_mode"):
        TampingEnv(small_config, render_mode="human")


LINE_SHORT = {"horizon_years": 0.75}  # 3 steps


def test_line_rgb_array_shows_the_step() -> None:
    env = gym.make("trackenv/TampingLineSmall-v0", render_mode="rgb_array", **LINE_SHORT)
    assert "rgb_array" in env.metadata["render_modes"] and env.render_mode == "rgb_array"
    env.reset(seed=0)
    first = env.render()
    _check_frame(first)
    env.step(np.array([1, 0, 1, 0, 0, 0], dtype=np.int8))
    second = env.render()
    _check_frame(second)
    assert second.shape == first.shape
    assert not np.array_equal(first, second)  # the year, the true SD and the tamped sections moved on
    assert TampingLine(scenario="small", render_mode="rgb_array", **LINE_SHORT).render() is None  # before reset
    plain = TampingLine(scenario="small", **LINE_SHORT)
    plain.reset(seed=0)
    assert plain.render() is None
    with pytest.raises(ValueError, match="render_mode"):
        TampingLine(scenario="small", render_mode="human")


def test_line_render_passes_gymnasiums_checkers() -> None:
    """check_env without skip_render_check: the passive render check, and each declared render mode made from
    the spec, reset and rendered."""
    env = gym.make("trackenv/TampingLineSmall-v0", render_mode="rgb_array", **LINE_SHORT)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped)  # fails by assertion where it must, warns where it doubts
    assert [str(w.message) for w in caught] == []
    env.reset(seed=0)
    _checked_render(env.unwrapped)


def test_line_vector_env_renders_the_first_line() -> None:
    venv = TampingLineVectorEnv(2, scenario="small", render_mode="rgb_array", **LINE_SHORT)
    assert venv.render() is None  # nothing to draw before reset
    venv.reset(seed=[0, 5])
    frame = venv.render()
    _check_frame(frame)
    single = TampingLine(scenario="small", render_mode="rgb_array", **LINE_SHORT)
    single.reset(seed=0)
    np.testing.assert_array_equal(frame, single.render())  # line 0 of the vector env is the single env's line
    assert TampingLineVectorEnv(2, scenario="small", **LINE_SHORT).render() is None
