"""TampingVectorEnv: many tamping episodes stepped together, their passes in one batched call of the dynamics.

The rules of a step are those of :mod:`trackenv.envs.episode` (shared with :class:`TampingEnv`); only the
vehicle passes are gathered into one :func:`trackenv.physics.dynamics.simulate_passes` call, which the compiled
kernel spreads over the CPU cores.

Both of Gymnasium's autoreset modes, with the results of ``gymnasium.vector.SyncVectorEnv`` over
:class:`TampingEnv` in the same mode (observations, rewards, flags and infos, with its ``_key`` masks):

* ``SAME_STEP`` (default): an episode resets in the step it ends; the returned observation and info are the
  new episode's first, ``infos["final_obs"]`` (an object array) and ``infos["final_info"]`` (a dict of arrays)
  hold the last of the old one;
* ``NEXT_STEP`` (Gymnasium's and RLlib's convention): the step that ends an episode returns its last
  observation and info; the next step resets that env (its action is ignored, reward 0, both flags False).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space, concatenate, create_empty_array

from ..degradation import simulate_batch
from ..physics._checks import check_int
from . import episode as E
from ._seeding import vector_rngs
from .config import TampingEnvConfig
from .tamping import action_space, check_reset_arguments, decode_action, observation_space


class TampingVectorEnv(VectorEnv):
    """``num_envs`` independent :class:`TampingEnv` episodes with batched physics (same config).

    ``autoreset_mode``: ``AutoresetMode.SAME_STEP`` (default) or ``NEXT_STEP`` (or their values, "SameStep",
    "NextStep"; see the module docstring); ``render_mode="rgb_array"``: :meth:`render` draws the first env.
    Seeds: ``reset(seed=s)`` seeds env ``i`` with ``s + i``, or give a list of one seed per env."""

    metadata = {"render_modes": ["rgb_array"], "autoreset_mode": AutoresetMode.SAME_STEP}

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
        num_envs = check_int("num_envs", num_envs, low=1, high=4096)
        modes = (AutoresetMode.SAME_STEP, AutoresetMode.NEXT_STEP)
        try:
            mode = AutoresetMode(autoreset_mode)
        except ValueError:
            mode = None
        if mode not in modes:
            raise ValueError(f"autoreset_mode must be one of {[m.value for m in modes]}, got {autoreset_mode!r}")
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        self.autoreset_mode = mode
        self.metadata = {**type(self).metadata, "autoreset_mode": mode}
        self.render_mode = render_mode
        overrides.pop("max_episode_steps", None)
        config = TampingEnvConfig.coerce(config)
        if overrides:
            config = config.replace(**overrides)
        self.config = config
        self.num_envs = int(num_envs)
        self.action_type = action_type
        self.single_observation_space = observation_space(config)
        self.single_action_space = action_space(config, action_type)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.episodes: list[E.Episode] = []
        self._rngs: list[np.random.Generator] = []
        self._autoreset = np.zeros(self.num_envs, dtype=bool)  # NEXT_STEP: envs to reset at the next step
        self._first_info: dict = {}  # the first env's last info, for render()

    def _observations(self) -> dict:
        out = create_empty_array(self.single_observation_space, self.num_envs)
        # gymnasium types concatenate's result as any space's; for a Dict space it is the dict ``out``
        return concatenate(self.single_observation_space, [E.observation(ep) for ep in self.episodes], out)  # type: ignore[return-value]

    def _new_episodes(self, idx: list[int], others: Sequence[E.Episode] = ()) -> list:
        """Start new episodes in envs ``idx`` (a traffic-free pass each); the passes of ``others`` (episodes
        about to take their traffic step) run in the same batched call, and their results are returned."""
        eps = [E.new_episode(self.config, self._rngs[i]) for i in idx]
        results = simulate_batch([ep.sim for ep in others] + [ep.sim for ep in eps])
        for i, ep, res in zip(idx, eps, results[len(others):]):
            ep.contact_force = ep.sim.evaluated(res.contact_force_profile())
            self.episodes[i] = ep
        return results[:len(others)]

    def _reset_info(self, i: int) -> dict:
        zero = dict.fromkeys(E.COST_KEYS, 0.0)
        return E.info(self.episodes[i], zero, np.zeros(self.config.n_sections, dtype=bool))

    def reset(self, *, seed: int | list[int] | None = None, options: dict | None = None):
        check_reset_arguments(None, options)
        self._rngs = vector_rngs(seed, self.num_envs)
        self.episodes = [None] * self.num_envs  # type: ignore[list-item]
        self._new_episodes(list(range(self.num_envs)))
        self._autoreset[:] = False
        infos: dict = {}
        for i in range(self.num_envs):
            infos = self._add_info(infos, self._reset_info(i), i)  # Gymnasium's vector infos, with masks
        self._first_info = self._reset_info(0)
        return self._observations(), infos

    def step(self, actions):
        if not self.episodes:
            raise RuntimeError("call reset() before step()")
        try:
            arr = np.asarray(actions)
        except ValueError:  # ragged nested sequences
            arr = np.empty(0)
        want = (self.num_envs,) + self.single_action_space.shape
        if arr.shape != want:
            raise ValueError(
                f"actions must have shape {want} (one action per env), got shape {arr.shape} ({actions!r:.60})"
            )
        actions = arr
        n = self.num_envs
        resetting = np.flatnonzero(self._autoreset).tolist()  # NEXT_STEP only: their actions are ignored
        stepping = [i for i in range(n) if not self._autoreset[i]]
        wants = {i: decode_action(actions[i], self.action_type, self.config.n_sections) for i in stepping}
        tamping = {i: E.apply_tamping(self.episodes[i], wants[i], self._rngs[i]) for i in stepping}
        results = self._new_episodes(resetting, [self.episodes[i] for i in stepping])
        if stepping:
            E.traffic_batch([self.episodes[i] for i in stepping], results)
        rewards = np.zeros(n)
        truncated = np.zeros(n, dtype=bool)
        step_infos: dict[int, dict] = {}
        for i in stepping:
            ep = self.episodes[i]
            cost, tamped = tamping[i]
            parts = E.costs(ep, cost)
            rewards[i] = -sum(parts.values())
            truncated[i] = ep.step_count >= self.config.horizon_steps
            step_infos[i] = E.info(ep, parts, tamped)
        done = np.flatnonzero(truncated).tolist()
        infos: dict = {}
        if self.autoreset_mode == AutoresetMode.SAME_STEP and done:
            for i in done:
                final = {"final_obs": E.observation(self.episodes[i]), "final_info": step_infos[i]}
                infos = self._add_info(infos, final, i)
            self._new_episodes(done)
            resetting = done
        elif self.autoreset_mode == AutoresetMode.NEXT_STEP:
            self._autoreset = truncated.copy()  # reset these at the next step
        for i in resetting:
            step_infos[i] = self._reset_info(i)
        for i in range(n):
            infos = self._add_info(infos, step_infos[i], i)
        self._first_info = step_infos[0]
        return self._observations(), rewards, np.zeros(n, dtype=bool), truncated, infos

    def render(self):
        """The first env's current state as an RGB array (``render_mode="rgb_array"``), else None."""
        if self.render_mode != "rgb_array" or not self.episodes:
            return None
        from ..render import episode_frame

        return episode_frame(self.episodes[0], self._first_info)

    def action_masks(self) -> np.ndarray:
        """(num_envs, ...) masks as :meth:`TampingEnv.action_masks` gives them for one env."""
        return np.array([E.action_mask(ep, self.action_type, self.config.n_sections) for ep in self.episodes])

