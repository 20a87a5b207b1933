"""TampingVectorEnv: many episodes of the 60 m track stepped together, their passes in one batched call of the
dynamics, which the compiled kernel spreads over the CPU cores.

It is :class:`~trackenv.envs.env.TrackVectorEnv` (the one vector env of every problem) over the 60 m track's
engine (:class:`~trackenv.envs.episode.TrackEpisodes`): seeding, both of Gymnasium's autoreset modes
(``SAME_STEP``, the default, and ``NEXT_STEP``) with the results of ``gymnasium.vector.SyncVectorEnv`` over
:class:`~trackenv.envs.tamping.TampingEnv` in the same mode, rendering and the state API come from there.
"""

from __future__ import annotations

from typing import Any

from gymnasium.vector import AutoresetMode

from .config import TampingEnvConfig
from .env import TrackVectorEnv
from .episode import Episode


class TampingVectorEnv(TrackVectorEnv):
    """``num_envs`` independent :class:`~trackenv.envs.tamping.TampingEnv` episodes with batched physics (same
    config: a :class:`TampingEnvConfig`, a dict, or its fields as keywords).

    ``autoreset_mode``: ``AutoresetMode.SAME_STEP`` (default) or ``NEXT_STEP`` (or their values, "SameStep",
    "NextStep"; see :mod:`trackenv.envs.batched`); ``render_mode="rgb_array"``: :meth:`render` draws the first env.
    Seeds: ``reset(seed=s)`` seeds env ``i`` with ``s + i``, or give a list of one seed per env."""

    def __init__(
        self,
        num_envs: int = 8,
        config: TampingEnvConfig | dict | None = None,
        *,
        action_type: str = "multibinary",
        autoreset_mode: AutoresetMode | str = AutoresetMode.SAME_STEP,
        render_mode: str | None = None,
        **overrides: Any,
    ) -> None:
        overrides.pop("max_episode_steps", None)
        config = TampingEnvConfig.coerce(config)
        super().__init__(num_envs, config.replace(**overrides) if overrides else config, action_type=action_type,
                         autoreset_mode=autoreset_mode, render_mode=render_mode)

    @property
    def episodes(self) -> list[Episode]:
        """The current episode of each env (empty before the first reset)."""
        return [] if self.engine is None else self.engine.episodes
