"""The test suite's warning filter (pyproject.toml, [tool.pytest.ini_options]): what Gymnasium's and
stable-baselines3's env checkers warn about fails a test; other warnings keep pytest's default."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces


class _Doubtful(gym.Env):
    """A valid env the checkers doubt: its render gives a float picture, its action space is not [-1, 1]."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 4}
    observation_space = spaces.Box(-1.0, 1.0, (2,), np.float32)
    action_space = spaces.Box(0.0, 10.0, (1,), np.float32)

    def __init__(self, render_mode: str | None = None) -> None:
        self.render_mode = render_mode

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return np.zeros(2, np.float32), {}

    def step(self, action):
        return np.zeros(2, np.float32), 0.0, False, False, {}

    def render(self):
        return np.zeros((8, 8, 3))


def test_gymnasiums_passive_checker_warnings_fail_a_test():
    from gymnasium.utils.passive_env_checker import env_render_passive_checker

    with pytest.raises(UserWarning, match="uint8"):
        env_render_passive_checker(_Doubtful("rgb_array"))


def test_stable_baselines3s_checker_warnings_fail_a_test():
    env_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    with pytest.raises(UserWarning, match="symmetric and normalized Box action space"):
        env_checker.check_env(_Doubtful(), warn=True, skip_render_check=True)


def test_other_warnings_are_no_errors():
    with pytest.warns(UserWarning, match="elsewhere"):
        warnings.warn("elsewhere", UserWarning, stacklevel=1)
