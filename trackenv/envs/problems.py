"""The problems trackenv poses, known by their config type: a harness (evaluation, training, search) asks here
for a problem's config, its vector env and its cost parts, and runs every problem the same way, without
switching on which one it has.

Today there are two families: the 60 m track (:class:`~trackenv.envs.config.TampingEnvConfig`,
``trackenv/Tamping-v0``) and the line (:class:`~trackenv.envs.line_config.LineConfig`, ``trackenv/TampingLine*``).
"""

from __future__ import annotations

from typing import Any

from gymnasium.vector import AutoresetMode

from .batched import BatchedVectorEnv
from .config import TampingEnvConfig
from .line_config import SCENARIOS, LineConfig

ProblemConfig = TampingEnvConfig | LineConfig


def problem_config(value: Any = None) -> ProblemConfig:
    """A problem's config from a config of either family (returned as is), a line scenario name (``"small"``,
    ``"default"``, ``"hard"``), a dict of :class:`TampingEnvConfig` fields, or None (the 60 m default)."""
    if isinstance(value, (TampingEnvConfig, LineConfig)):
        return value
    if isinstance(value, str):
        if value not in SCENARIOS:
            raise ValueError(f"unknown scenario {value!r}; known: {sorted(SCENARIOS)}")
        return LineConfig.coerce(value)
    return TampingEnvConfig.coerce(value)


def make_vector_env(config: ProblemConfig, num_envs: int, *, action_type: str = "multibinary",
                    autoreset_mode: AutoresetMode | str = AutoresetMode.SAME_STEP,
                    render_mode: str | None = None) -> BatchedVectorEnv:
    """The native vector env of ``config``'s problem with ``num_envs`` envs (``action_type`` applies to the 60 m
    track; the line's action is MultiBinary)."""
    from .line import TampingLineVectorEnv
    from .vector import TampingVectorEnv

    if isinstance(config, LineConfig):
        if action_type != "multibinary":
            raise ValueError(f"action_type must be 'multibinary' for a line, got {action_type!r}")
        return TampingLineVectorEnv(num_envs, config, autoreset_mode=autoreset_mode, render_mode=render_mode)
    return TampingVectorEnv(num_envs, config, action_type=action_type, autoreset_mode=autoreset_mode,
                            render_mode=render_mode)
