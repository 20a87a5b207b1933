"""Agent-side action parameterisations: the names the training code uses for what a learning agent chooses.

The env speaks ``MultiBinary(n_sections)`` (Tamping-v1) or ``Discrete(n_sections + 1)`` (TampingDiscrete-v1).
Agents may also learn in the **ranked** parameterisation, ``Discrete(n_sections + 1)``: action ``k`` tamps the
``k`` sections with the largest SD of the D1 level (0 = nothing, ``n_sections`` = a full campaign). Why, and
the decoding itself, live with the Gymnasium wrappers any library can use
(:mod:`trackenv.envs.wrappers`: :class:`~trackenv.envs.wrappers.RankedActions`,
:func:`~trackenv.envs.wrappers.ranked_to_sections`); this module only maps the agent's action type to the
env's and to the space the agent learns in.
"""

from __future__ import annotations

from gymnasium import spaces

from trackenv.envs.common import action_space
from trackenv.envs.line_config import LineConfig
from trackenv.envs.wrappers import ranked_to_sections

RANKED = "ranked"
ACTION_TYPES = ("multibinary", "discrete", RANKED)

__all__ = ["ACTION_TYPES", "RANKED", "agent_action_space", "check_action_type", "env_action_type",
           "ranked_to_sections"]


def check_action_type(action_type: str) -> str:
    if action_type not in ACTION_TYPES:
        raise ValueError(f"action_type must be one of {ACTION_TYPES}, got {action_type!r}")
    return action_type


def env_action_type(action_type: str) -> str:
    """The env's action type under an agent's action type (ranked agents drive the MultiBinary env)."""
    return "multibinary" if check_action_type(action_type) == RANKED else action_type


def agent_action_space(config: LineConfig, action_type: str) -> spaces.Space:
    """The action space the agent learns in."""
    if check_action_type(action_type) == RANKED:
        return spaces.Discrete(config.n_sections + 1)
    return action_space(config, action_type)
