"""TampingVectorEnv: many tamping episodes stepped together, their passes in one batched call of the dynamics.

The rules of a step are those of :mod:`trackenv.envs.episode` (shared with :class:`TampingEnv`); only the
vehicle passes are gathered into one :func:`trackenv.physics.dynamics.simulate_passes` call, which the compiled
kernel spreads over the CPU cores. Seeding, both of Gymnasium's autoreset modes (``SAME_STEP``, the default, and
``NEXT_STEP``) with the results of ``gymnasium.vector.SyncVectorEnv`` over :class:`TampingEnv` in the same mode,
and rendering come from :class:`~trackenv.envs.batched.BatchedVectorEnv`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode

from ..degradation import simulate_batch
from . import episode as E
from .batched import BatchedVectorEnv
from .common import action_mask, action_space, check_reset_arguments, decode_action
from .config import TampingEnvConfig
from .state import EnvState, checked, snapshot
from .tamping import observation_space


class TampingVectorEnv(BatchedVectorEnv):
    """``num_envs`` independent :class:`TampingEnv` episodes with batched physics (same config).

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
        if overrides:
            config = config.replace(**overrides)
        self.config = config
        self.action_type = action_type
        obs_space = observation_space(config)
        self._observation_keys = list(obs_space.spaces)
        super().__init__(num_envs, obs_space, action_space(config, action_type),
                         autoreset_mode=autoreset_mode, render_mode=render_mode)
        self.episodes: list[E.Episode] = [None] * self.num_envs  # type: ignore[list-item]  # filled by reset()

    def _new_episodes(self, idx: list[int], others: Sequence[E.Episode] = ()) -> list:
        """Start new episodes in envs ``idx`` (a traffic-free pass each); the passes of ``others`` (episodes
        about to take their traffic step) run in the same batched call, and their results are returned."""
        eps = [E.new_episode(self.config, self._rngs[i]) for i in idx]
        results = simulate_batch([ep.sim for ep in others] + [ep.sim for ep in eps])
        for i, ep, res in zip(idx, eps, results[len(others):]):
            ep.contact_force = ep.sim.evaluated(res.contact_force_profile())
            self.episodes[i] = ep
        return results[:len(others)]

    def _start(self, idx: list[int]) -> None:
        self._new_episodes(idx)
        E.refresh_geometry([self.episodes[i] for i in idx])

    def _observation(self, i: int) -> dict[str, np.ndarray]:
        return E.observation(self.episodes[i])

    def _observations(self) -> dict:
        return E.observations(self.episodes, self._observation_keys)

    def _reset_info(self, i: int) -> dict:
        zero = dict.fromkeys(E.COST_KEYS, 0.0)
        return E.info(self.episodes[i], zero, np.zeros(self.config.n_sections, dtype=bool))

    def reset(self, *, seed: int | list[int] | None = None, options: dict | None = None):
        check_reset_arguments(None, options)
        return super().reset(seed=seed, options=options)

    def _step_envs(self, actions: np.ndarray, stepping: list[int],
                   resetting: list[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[int, dict]]:
        n = self.num_envs
        wants = {i: decode_action(actions[i], self.action_type, self.config.n_sections) for i in stepping}
        tamping = {i: E.apply_tamping(self.episodes[i], wants[i], self._rngs[i]) for i in stepping}
        results = self._new_episodes(resetting, [self.episodes[i] for i in stepping])
        if stepping:
            E.traffic_batch([self.episodes[i] for i in stepping], results)
        E.refresh_geometry(self.episodes)  # the new levels' D1 (stepped and new episodes), for costs, info, obs
        rewards = np.zeros(n)
        truncated = np.zeros(n, dtype=bool)
        infos: dict[int, dict] = {}
        for i in stepping:
            ep = self.episodes[i]
            cost, tamped = tamping[i]
            parts, section_costs = E.costs(ep, cost, tamped)
            rewards[i] = -sum(parts.values())
            truncated[i] = ep.step_count >= self.config.horizon_steps
            infos[i] = E.info(ep, parts, tamped, section_costs)
        return rewards, np.zeros(n, dtype=bool), truncated, infos

    def _frame(self, info: dict) -> np.ndarray:
        from ..render import episode_frame

        return episode_frame(self.episodes[0], info)

    def get_state(self, index: int) -> EnvState:
        """A snapshot of env ``index`` (:mod:`trackenv.envs.state`), the same as :meth:`TampingEnv.get_state`
        gives: it can be restored here, in another row, or in a single env of this config."""
        i = self._env_index(index)
        return snapshot(self.config, E.copy_episode(self.episodes[i]), self._rngs[i], self._infos[i])

    def set_state(self, index: int, state: EnvState) -> None:
        """Continue env ``index`` from ``state`` (a snapshot of this config); a pending NEXT_STEP reset of that
        env is dropped."""
        i = self._env_index(index)
        state = checked(state, self.config)
        self.episodes[i] = E.copy_episode(state.episode)
        self._restore_row(i, state)

    def action_masks(self) -> np.ndarray:
        """(num_envs, ...) masks as :meth:`TampingEnv.action_masks` gives them for one env."""
        return action_mask(np.array([ep.mask() for ep in self.episodes]), self.action_type)
