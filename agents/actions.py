"""Agent-side action parameterisations: what a learning agent chooses, translated to the env's actions.

The env speaks ``MultiBinary(n_sections)`` (Tamping-v0) or ``Discrete(n_sections + 1)`` (TampingDiscrete-v0).
Agents may also learn in the **ranked** parameterisation, ``Discrete(n_sections + 1)``: action ``k`` tamps the
``k`` sections with the largest SD of the D1 level (0 = nothing, ``n_sections`` = a full campaign).

Why: with a mobilisation cost per campaign, good schedules tamp many sections at once, rarely. Under
``MultiBinary`` a policy must learn to switch all its independent Bernoulli heads on in the same rare step,
which per-section exploration almost never finds; under ``ranked`` a campaign is one choice among
``n_sections + 1``, and choosing *which* sections reduces to choosing *how many* of the worst. The agent still
decides when and how much to tamp from the state; only the order of preference (worst first) is fixed.
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from trackenv.envs.config import TampingEnvConfig
from trackenv.envs.tamping import action_space

from .heuristics import _rank_mask

RANKED = "ranked"
ACTION_TYPES = ("multibinary", "discrete", RANKED)


def check_action_type(action_type: str) -> str:
    if action_type not in ACTION_TYPES:
        raise ValueError(f"action_type must be one of {ACTION_TYPES}, got {action_type!r}")
    return action_type


def env_action_type(action_type: str) -> str:
    """The env's action type under an agent's action type (ranked agents drive the MultiBinary env)."""
    return "multibinary" if check_action_type(action_type) == RANKED else action_type


def agent_action_space(config: TampingEnvConfig, action_type: str) -> spaces.Space:
    """The action space the agent learns in."""
    if check_action_type(action_type) == RANKED:
        return spaces.Discrete(config.n_sections + 1)
    return action_space(config, action_type)


def ranked_to_sections(k, section_sd) -> np.ndarray:
    """MultiBinary actions (int8, ``section_sd``'s shape) tamping the ``k`` worst sections by SD per row.

    ``k``: one count per row (or a scalar for a single unbatched observation); ``section_sd``: (n_sections,)
    or (n_envs, n_sections). Ties go to the lower section index.
    """
    sd = np.asarray(section_sd, dtype=float)
    single = sd.ndim == 1
    sd2 = sd[None] if single else sd
    counts = np.asarray(k).reshape(-1)
    if counts.size != sd2.shape[0]:
        raise ValueError(f"need one ranked action per row of section_sd ({sd2.shape[0]}), got {counts.size}")
    if not np.all((counts >= 0) & (counts <= sd2.shape[1])):
        raise ValueError(f"ranked actions must be integers in [0, {sd2.shape[1]}], got {counts.tolist()}")
    out = _rank_mask(sd2, np.ones(sd2.shape, dtype=bool), counts.astype(int)).astype(np.int8)
    return out[0] if single else out
