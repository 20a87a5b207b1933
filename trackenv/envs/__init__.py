"""Gymnasium environments of trackenv, registered on import (safe to import twice).

No ``max_episode_steps``: the env truncates itself at its configured horizon, so a registered TimeLimit could
only cut a longer configured horizon short (``gym.make(..., horizon_years=20)`` runs its 80 steps)."""

from gymnasium.envs.registration import register, registry

from .config import TampingEnvConfig
from .tamping import TampingEnv

for _id, _kwargs in (
    ("trackenv/Tamping-v0", {"action_type": "multibinary"}),
    ("trackenv/TampingDiscrete-v0", {"action_type": "discrete"}),
):
    if _id not in registry:
        register(
            id=_id,
            entry_point="trackenv.envs.tamping:TampingEnv",
            kwargs=_kwargs,
            vector_entry_point="trackenv.envs.vector:TampingVectorEnv",
        )

__all__ = ["TampingEnv", "TampingEnvConfig"]

for _id, _scenario in (
    ("trackenv/TampingLine-v0", "default"),
    ("trackenv/TampingLineSmall-v0", "small"),
    ("trackenv/TampingLineHard-v0", "hard"),
):
    if _id not in registry:
        register(
            id=_id,
            entry_point="trackenv.envs.line:TampingLine",
            kwargs={"scenario": _scenario},
            vector_entry_point="trackenv.envs.line:TampingLineVectorEnv",
        )
