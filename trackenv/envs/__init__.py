"""Gymnasium environments of trackenv, registered on import (safe to import twice)."""

from gymnasium.envs.registration import register, registry

from .config import TampingEnvConfig
from .tamping import TampingEnv

DEFAULT_HORIZON_STEPS = TampingEnvConfig().horizon_steps

for _id, _kwargs in (
    ("trackenv/Tamping-v0", {"action_type": "multibinary"}),
    ("trackenv/TampingDiscrete-v0", {"action_type": "discrete"}),
):
    if _id not in registry:
        register(
            id=_id,
            entry_point="trackenv.envs.tamping:TampingEnv",
            kwargs=_kwargs,
            max_episode_steps=DEFAULT_HORIZON_STEPS,
            vector_entry_point="trackenv.envs.vector:TampingVectorEnv",
        )

__all__ = ["TampingEnv", "TampingEnvConfig"]
