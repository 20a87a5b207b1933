"""Agent-side action parameterisations: the names the training code uses for what a learning agent chooses.

The env speaks ``MultiBinary(n_sections)`` (Tamping-v1), ``Discrete(n_sections + 1)`` (TampingDiscrete-v1) or
the choices, ``MultiDiscrete([7] * n_sections)`` (``action_type="choices"``). Agents may also learn in the
**ranked** parameterisation, ``Discrete(n_sections + 1)``: action ``k`` tamps the ``k`` sections with the
largest SD of the D1 level (0 = nothing, ``n_sections`` = a full campaign), or, over the choices,
**ranked_choices**, ``MultiDiscrete([n_sections + 1] * len(config.choices))``: one such count per enabled
intervention. Why, and the decoding itself, live with the Gymnasium wrappers any library can use
(:mod:`trackenv.envs.wrappers`: :class:`~trackenv.envs.wrappers.RankedActions`,
:func:`~trackenv.envs.wrappers.ranked_to_sections`, :func:`~trackenv.envs.wrappers.ranked_to_choices`); this
module only maps the agent's action type to the env's and to the space the agent learns in.

:data:`ACTION_TYPES` are those of the 60 m track's trainer; :data:`VEC_ACTION_TYPES` those the SB3 vector
adapter (:class:`~trackenv_agents.learning.sb3_vec.TampingSB3VecEnv`) takes, the choices' two included.
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from trackenv.envs.common import action_space
from trackenv.envs.line_config import LineConfig
from trackenv.envs.wrappers import ranked_to_choices, ranked_to_sections

RANKED = "ranked"
RANKED_CHOICES = "ranked_choices"
ACTION_TYPES = ("multibinary", "discrete", RANKED)
VEC_ACTION_TYPES = (*ACTION_TYPES, "choices", RANKED_CHOICES)
#: the env's action type under each ranked one (the others are the env's own)
_ENV_ACTION_TYPE = {RANKED: "multibinary", RANKED_CHOICES: "choices"}

__all__ = ["ACTION_TYPES", "RANKED", "RANKED_CHOICES", "VEC_ACTION_TYPES", "agent_action_space",
           "check_action_type", "decode_ranked_choices", "env_action_type", "ranked_to_choices", "ranked_to_sections"]


def check_action_type(action_type: str, allowed: tuple[str, ...] = VEC_ACTION_TYPES) -> str:
    if action_type not in allowed:
        raise ValueError(f"action_type must be one of {allowed}, got {action_type!r}")
    return action_type


def env_action_type(action_type: str) -> str:
    """The env's action type under an agent's action type (ranked agents drive the MultiBinary env, ranked
    choices the env with the choices)."""
    return _ENV_ACTION_TYPE.get(check_action_type(action_type), action_type)


def agent_action_space(config: LineConfig, action_type: str) -> spaces.Space:
    """The action space the agent learns in."""
    if check_action_type(action_type) == RANKED:
        return spaces.Discrete(config.n_sections + 1)
    if action_type == RANKED_CHOICES:
        return spaces.MultiDiscrete([config.n_sections + 1] * len(config.choices))
    return action_space(config, action_type)


def decode_ranked_choices(name: str, counts, observation, masks, heads) -> np.ndarray:
    """The env's choice codes of a trained policy's ranked ``counts`` of the choices ``heads``
    (:func:`ranked_to_choices` on its ``observation``), which decode on the env's action ``masks``: without them,
    ValueError naming the policy ``name`` and how to give them."""
    if masks is None:
        raise ValueError(f"policy {name!r} answers in ranked counts of the choices, which decode on the env's action "
                         "masks: predict(observation, action_masks=env.action_masks())")
    return ranked_to_choices(counts, observation, masks, heads)
