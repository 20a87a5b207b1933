"""The problems trackenv poses, known by their config type: the one place that says which episode engine, which
observation space and which action types a config's problem has. The env layer (:mod:`trackenv.envs.env`) and
every harness (evaluation, training, search) ask here and run every problem the same way, without switching on
which one they have.

Two families: :class:`~trackenv.envs.line_config.LineConfig` (the lines and the 60 m track are its presets) over
the one engine :class:`~trackenv.envs.line_episode.LineBatch`, and :class:`~trackenv.envs.network.NetworkConfig`
(lines that share one tamping machine) over :class:`~trackenv.envs.network.NetworkBatch`, a thin layer whose
lines are rows of that same engine.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from gymnasium import spaces
from gymnasium.vector import AutoresetMode

from .line_config import SCENARIOS, LineConfig
from .line_episode import LineBatch, line_observation_space
from .network import NetworkBatch, NetworkConfig, network_observation_space

if TYPE_CHECKING:
    from .env import TrackVectorEnv

#: the config of any env of trackenv: a line (every preset) or a network of lines
EnvConfig = LineConfig | NetworkConfig
#: the config of a problem the harnesses run (evaluation, training, search): any env's
ProblemConfig = EnvConfig


@dataclass(frozen=True)
class Problem:
    """What the env layer needs of a problem family: its episode ``engine`` (built as ``engine(config,
    n_rows)``), its ``observation_space(config)`` and the env's ``action_types``."""

    engine: Callable[[Any, int], Any]
    observation_space: Callable[[Any], spaces.Dict]
    action_types: tuple[str, ...]


_PROBLEMS: dict[type, Problem] = {
    LineConfig: Problem(LineBatch, line_observation_space, ("multibinary", "discrete", "choices")),
    NetworkConfig: Problem(NetworkBatch, network_observation_space, ("multibinary",)),
}


def problem_of(config: Any) -> Problem:
    """The :class:`Problem` that ``config`` poses; ValueError for anything but a config of a known family."""
    try:
        return _PROBLEMS[type(config)]
    except KeyError:
        known = [t.__name__ for t in _PROBLEMS]
        raise ValueError(f"config must be one of {known}, got {type(config).__name__}") from None


def problem_config(value: Any = None) -> ProblemConfig:
    """A problem's config from a config (returned as is), a preset name (``"small"``, ``"default"``, ``"hard"``,
    ``"track60"``), a dict of :class:`~trackenv.envs.line_config.LineConfig` fields (or, with ``line_config`` or
    ``n_lines`` among its keys, of :class:`~trackenv.envs.network.NetworkConfig` fields), or None (the 60 m track,
    ``"track60"``: the default of the trainers and harnesses that take no env)."""
    if type(value) in _PROBLEMS:
        return value
    if isinstance(value, str):
        if value not in SCENARIOS:
            hint = (" (an env id: give its preset, e.g. 'small' for trackenv/TampingLineSmall-v0, or its config, "
                    "gym.make(id).unwrapped.config)") if "/" in value else ""
            raise ValueError(f"unknown scenario {value!r}; known: {sorted(SCENARIOS)}{hint}")
        return LineConfig.coerce(value)
    if value is None:
        return LineConfig.coerce("track60")
    if isinstance(value, dict) and {"line_config", "n_lines"} & set(value):
        return NetworkConfig.from_dict(value)
    return LineConfig.coerce(value)


def make_vector_env(config: ProblemConfig, num_envs: int, *, action_type: str = "multibinary",
                    autoreset_mode: AutoresetMode | str = AutoresetMode.SAME_STEP,
                    render_mode: str | None = None) -> TrackVectorEnv:
    """The native vector env of ``config``'s problem with ``num_envs`` envs."""
    from .env import TrackVectorEnv

    return TrackVectorEnv(num_envs, config, action_type=action_type, autoreset_mode=autoreset_mode,
                          render_mode=render_mode)
