"""The problems trackenv poses, known by their config type: the one place that says which episode engine, which
observation space and which action types a config's problem has. The env layer (:mod:`trackenv.envs.env`) and
every harness (evaluation, training, search) ask here and run every problem the same way, without switching on
which one they have.

Today there are two families: the 60 m track (:class:`~trackenv.envs.config.TampingEnvConfig`,
``trackenv/Tamping-v0``) and the line (:class:`~trackenv.envs.line_config.LineConfig`, ``trackenv/TampingLine*``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from gymnasium import spaces
from gymnasium.vector import AutoresetMode

from .config import TampingEnvConfig
from .episode import TrackEpisodes
from .episode import observation_space as track_observation_space
from .line_config import SCENARIOS, LineConfig
from .line_episode import LineBatch, line_observation_space

if TYPE_CHECKING:
    from .env import TrackVectorEnv

ProblemConfig = TampingEnvConfig | LineConfig


@dataclass(frozen=True)
class Problem:
    """What the env layer needs of a problem family: its episode ``engine`` (built as ``engine(config,
    n_rows)``), its ``observation_space(config)`` and the env's ``action_types``."""

    engine: Callable[[Any, int], Any]
    observation_space: Callable[[Any], spaces.Dict]
    action_types: tuple[str, ...]


_PROBLEMS: dict[type, Problem] = {
    TampingEnvConfig: Problem(TrackEpisodes, track_observation_space, ("multibinary", "discrete")),
    LineConfig: Problem(LineBatch, line_observation_space, ("multibinary",)),
}


def problem_of(config: Any) -> Problem:
    """The :class:`Problem` that ``config`` poses; ValueError for anything but a config of a known family."""
    try:
        return _PROBLEMS[type(config)]
    except KeyError:
        known = [t.__name__ for t in _PROBLEMS]
        raise ValueError(f"config must be one of {known}, got {type(config).__name__}") from None


def problem_config(value: Any = None) -> ProblemConfig:
    """A problem's config from a config of either family (returned as is), a line scenario name (``"small"``,
    ``"default"``, ``"hard"``), a dict of :class:`TampingEnvConfig` fields, or None (the 60 m default)."""
    if type(value) in _PROBLEMS:
        return value
    if isinstance(value, str):
        if value not in SCENARIOS:
            raise ValueError(f"unknown scenario {value!r}; known: {sorted(SCENARIOS)}")
        return LineConfig.coerce(value)
    return TampingEnvConfig.coerce(value)


def make_vector_env(config: ProblemConfig, num_envs: int, *, action_type: str = "multibinary",
                    autoreset_mode: AutoresetMode | str = AutoresetMode.SAME_STEP,
                    render_mode: str | None = None) -> TrackVectorEnv:
    """The native vector env of ``config``'s problem with ``num_envs`` envs."""
    from .env import TrackVectorEnv

    return TrackVectorEnv(num_envs, config, action_type=action_type, autoreset_mode=autoreset_mode,
                          render_mode=render_mode)
