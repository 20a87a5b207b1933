"""TampingVectorEnv: many tamping episodes stepped together, their passes in one batched call of the dynamics.

The rules of a step are those of :mod:`trackenv.envs.episode` (shared with :class:`TampingEnv`); only the
vehicle passes are gathered into one :func:`trackenv.physics.dynamics.simulate_passes` call, which the compiled
kernel spreads over the CPU cores. Episodes reset in the same step they end (Gymnasium's SAME_STEP autoreset):
the returned observation is the new episode's first, and ``infos["final_obs"]`` / ``infos["final_info"]`` hold
the last of the old one.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space, concatenate, create_empty_array

from ..degradation import simulate_batch
from ..physics._checks import check_int
from . import episode as E
from .config import TampingEnvConfig
from .tamping import action_space, check_reset_arguments, decode_action, observation_space


class TampingVectorEnv(VectorEnv):
    """``num_envs`` independent :class:`TampingEnv` episodes with batched physics (same config)."""

    metadata = {"render_modes": [], "autoreset_mode": AutoresetMode.SAME_STEP}

    def __init__(
        self,
        num_envs: int = 8,
        config: TampingEnvConfig | dict | None = None,
        *,
        action_type: str = "multibinary",
        **overrides: Any,
    ) -> None:
        num_envs = check_int("num_envs", num_envs, low=1, high=4096)
        overrides.pop("render_mode", None)
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

    def _observations(self) -> dict:
        out = create_empty_array(self.single_observation_space, self.num_envs)
        # gymnasium types concatenate's result as any space's; for a Dict space it is the dict ``out``
        return concatenate(self.single_observation_space, [E.observation(ep) for ep in self.episodes], out)  # type: ignore[return-value]

    def _new_episodes(self, idx: list[int]) -> None:
        eps = [E.new_episode(self.config, self._rngs[i]) for i in idx]
        results = simulate_batch([ep.sim for ep in eps])
        for i, ep, res in zip(idx, eps, results):
            ep.contact_force = ep.sim.evaluated(res.contact_force_profile())
            self.episodes[i] = ep

    def reset(self, *, seed: int | list[int] | None = None, options: dict | None = None):
        seeds: list[int | None]
        if seed is None:
            seeds = [None] * self.num_envs
        elif isinstance(seed, (list, tuple)) or (isinstance(seed, np.ndarray) and seed.ndim == 1):
            if len(seed) != self.num_envs:
                raise ValueError(f"seed must be an int or a list of {self.num_envs} seeds, got {len(seed)}")
            seeds = [None if s is None else check_int("seed", s, low=0) for s in seed]
        else:
            seeds = [check_int("seed", seed, low=0) + i for i in range(self.num_envs)]
        check_reset_arguments(None, options)
        self._rngs = [np.random.default_rng(s) for s in seeds]
        self.episodes = [None] * self.num_envs  # type: ignore[list-item]
        self._new_episodes(list(range(self.num_envs)))
        zero = dict.fromkeys(E.COST_KEYS, 0.0)
        infos = [E.info(ep, zero, np.zeros(self.config.n_sections, dtype=bool)) for ep in self.episodes]
        return self._observations(), _stack_infos(infos)

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
        wants = [decode_action(a, self.action_type, self.config.n_sections) for a in actions]
        tamping = [E.apply_tamping(ep, w, rng) for ep, w, rng in zip(self.episodes, wants, self._rngs)]
        E.traffic_batch(self.episodes, simulate_batch([ep.sim for ep in self.episodes]))
        rewards = np.zeros(self.num_envs)
        truncated = np.zeros(self.num_envs, dtype=bool)
        infos = []
        for i, (ep, (cost, tamped)) in enumerate(zip(self.episodes, tamping)):
            parts = E.costs(ep, cost)
            rewards[i] = -sum(parts.values())
            truncated[i] = ep.step_count >= self.config.horizon_steps
            infos.append(E.info(ep, parts, tamped))
        done = np.flatnonzero(truncated).tolist()
        info = _stack_infos(infos)
        if done:
            final_obs = [E.observation(self.episodes[i]) if i in done else None for i in range(self.num_envs)]
            self._new_episodes(done)
            info["final_obs"] = np.array(final_obs, dtype=object)
            info["final_info"] = np.array(
                [infos[i] if i in done else None for i in range(self.num_envs)], dtype=object
            )
            info["_final_obs"] = truncated.copy()
            info["_final_info"] = truncated.copy()
        return self._observations(), rewards, np.zeros(self.num_envs, dtype=bool), truncated, info

    def action_masks(self) -> np.ndarray:
        """(num_envs, ...) masks as :meth:`TampingEnv.action_masks` gives them for one env."""
        return np.array([E.action_mask(ep, self.action_type, self.config.n_sections) for ep in self.episodes])


def _stack_infos(infos: list[dict]) -> dict:
    """Per-env info dicts as one dict of arrays (Gymnasium's vector convention)."""
    out: dict[str, Any] = {}
    for key in infos[0]:
        vals = [inf[key] for inf in infos]
        if key == "costs":
            out[key] = {k: np.array([v[k] for v in vals]) for k in vals[0]}
        else:
            out[key] = np.array(vals)
        out["_" + key] = np.ones(len(infos), dtype=bool)
    return out
