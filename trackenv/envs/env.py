"""The Gymnasium layer of every trackenv problem, written once: :class:`TrackEnv` (one episode) and
:class:`TrackVectorEnv` (many, stepped together), both thin layers over the problem's episode engine.

The engine (:class:`~trackenv.envs.line_episode.LineBatch`, which :func:`~trackenv.envs.problems.problem_of`
names for the config) holds the episodes of its rows and knows the rules of a step; the env layer owns what
Gymnasium asks: spaces, seeding, decoding and checking actions, masks, the episode's end, rendering and the
planning state API. The single env is an engine of one row driven by the env's own generator; the vector env
(:class:`~trackenv.envs.batched.BatchedVectorEnv`'s conventions: both autoreset modes, Gymnasium's info layout)
one row per env, its physics in one batched call. So a row of the vector env gives bit for bit what the single
env gives for the same seed and actions, whatever the problem.

The registered ids use the named subclasses, which carry the spec in their docstrings:
:class:`~trackenv.envs.line.TampingLine` and :class:`~trackenv.envs.line.TampingLineVectorEnv` (the line and
every preset), :class:`~trackenv.envs.tamping.TampingEnv` and :class:`~trackenv.envs.vector.TampingVectorEnv`
(the 60 m track), :class:`~trackenv.envs.network_env.TampingNetwork` and
:class:`~trackenv.envs.network_env.TampingNetworkVectorEnv` (lines that share a machine, whose engine
:class:`~trackenv.envs.network.NetworkBatch` holds its lines as rows of the line's engine).
"""

from __future__ import annotations

import copy
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode

from .batched import BatchedVectorEnv
from .choices import CHOICES, TAMP, enabled_codes, work_on_sections, work_per_code
from .common import action_mask, action_space, check_render_mode, check_reset_arguments, decode_action
from .line_config import LineConfig
from .problems import EnvConfig, problem_of
from .state import EnvState, checked, snapshot


def _checked_action_type(config: EnvConfig, action_type: str) -> str:
    allowed = problem_of(config).action_types
    if action_type not in allowed:
        raise ValueError(f"action_type must be one of {list(allowed)} for {type(config).__name__}, "
                         f"got {action_type!r}")
    return action_type


def _masks(engine: Any, config: EnvConfig, n_rows: int, action_type: str) -> np.ndarray:
    """(n_rows, mask size) the action masks of ``engine``'s rows (before the first reset: what the config
    allows, every section free)."""
    if action_type == "choices":
        if not isinstance(config, LineConfig):  # the network takes tamp requests only (its action types)
            raise ValueError(f"action_type='choices' needs a line config, got {type(config).__name__}")
        if engine is None:
            every = np.broadcast_to(np.arange(len(CHOICES)), (config.n_sections, len(CHOICES)))
            work = work_on_sections(work_per_code(config.choice_work), every, config.length_factors[:, None])
            free = enabled_codes(config.choices) & (work <= config.capacity + 1e-9)
            return action_mask(np.broadcast_to(free, (n_rows, config.n_sections, len(CHOICES))), action_type)
        return action_mask(engine.choice_mask(), action_type)
    if engine is None:
        allowed = np.ones((n_rows, config.n_sections), bool)
    elif isinstance(config, LineConfig):  # a tamping the env would apply alone: its gap, capacity and budget
        allowed = engine.choice_mask()[..., TAMP]
    else:
        allowed = engine.allowed()
    return action_mask(allowed, action_type)


class TrackEnv(gym.Env):
    """One episode of the problem that ``config`` poses (see the module docstring); ``action_type`` one of the
    problem's, ``render_mode`` None or "rgb_array"."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 4}

    def __init__(self, config: EnvConfig, *, action_type: str = "multibinary",
                 render_mode: str | None = None) -> None:
        self.config = config
        self.action_type = _checked_action_type(config, action_type)
        self.render_mode = check_render_mode(render_mode)
        self.observation_space = problem_of(config).observation_space(config)
        self.action_space = action_space(config, action_type)
        self.engine: Any = None  # the problem's engine with one row, made by reset() or set_state()
        self._last_info: dict = {}

    def _engine(self) -> Any:
        if self.engine is None:
            raise RuntimeError("call reset() before step()")
        return self.engine

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=check_reset_arguments(seed, options))
        if self.engine is None:
            self.engine = problem_of(self.config).engine(self.config, 1)
        self.engine.start([0], [self.np_random])  # drawn from this env's generator (reset() continues it)
        self._last_info = self.engine.reset_info(0)
        return self.engine.observation(0), self._last_info

    def step(self, action):
        engine = self._engine()
        c = self.config
        if engine.step_count(0) >= c.horizon_steps:
            raise RuntimeError(
                f"the episode was truncated at its horizon ({c.horizon_steps} steps, {c.horizon_years:g} years): "
                "call reset() before step()")
        want = decode_action(action, self.action_type, self.config.n_sections)[None, :]
        rewards, truncated, infos = engine.advance(want, [0], [self.np_random])
        self._last_info = infos[0]
        return engine.observation(0), float(rewards[0]), False, bool(truncated[0]), self._last_info

    def action_masks(self) -> np.ndarray:
        """Valid actions for masked algorithms (sb3-contrib's MaskablePPO): MultiBinary, (2·n_sections,) pairs
        [may-not-tamp, may-tamp] per section; Discrete, (n_sections + 1,); choices (MultiDiscrete),
        (n_sections · len(CHOICES),), each section's choices in turn (:meth:`LineBatch.choice_mask`). A section
        tamped (or worked on) within the last ``min_steps_between_tampings`` steps may not be tamped; on a line,
        neither may one whose tamping alone is more work than the possession's capacity or, with an annual
        budget, costs (with the possession) more than is left of it (the tamping column of the choice masks)."""
        return _masks(self.engine, self.config, 1, self.action_type)[0]

    def current_observation(self) -> dict[str, np.ndarray]:
        """The observation of the episode as it stands: what the last reset or step returned, or the restored
        moment's after :meth:`set_state` (the ranked wrappers decode their counts on it)."""
        if self.engine is None:
            raise RuntimeError("call reset() before current_observation()")
        return self.engine.observation(0)

    def get_state(self) -> EnvState:
        """A snapshot of the episode (:mod:`trackenv.envs.state`): ``set_state`` on this env, on any env of the
        same config or on a row of its vector env continues it bit for bit."""
        if self.engine is None:
            raise RuntimeError("call reset() before get_state()")
        return snapshot(self.config, self.engine.get_state(0), self.np_random, self._last_info)

    def set_state(self, state: EnvState) -> None:
        """Continue from ``state`` (from ``get_state`` of an env of this config); the snapshot is not changed, so
        it can be restored again."""
        state = checked(state, self.config)
        if self.engine is None:
            self.engine = problem_of(self.config).engine(self.config, 1)
        self.engine.set_state(0, state.episode)
        self.np_random.bit_generator.state = copy.deepcopy(state.rng_state)
        self._last_info = copy.deepcopy(state.last_info)

    def render(self):
        """The episode's state as an RGB array (``render_mode="rgb_array"``), else None."""
        if self.render_mode != "rgb_array" or self.engine is None:
            return None
        return self.engine.frame(0, self._last_info)


class TrackVectorEnv(BatchedVectorEnv):
    """``num_envs`` episodes of the problem that ``config`` poses, stepped together: one row of the problem's
    engine per env, the physics of all of them in one batched call (see the module docstring and
    :class:`~trackenv.envs.batched.BatchedVectorEnv` for the Gymnasium conventions)."""

    def __init__(self, num_envs: int, config: EnvConfig, *, action_type: str = "multibinary",
                 autoreset_mode: AutoresetMode | str = AutoresetMode.SAME_STEP,
                 render_mode: str | None = None) -> None:
        self.config = config
        self.action_type = _checked_action_type(config, action_type)
        obs_space = problem_of(config).observation_space(config)
        self._observation_keys = list(obs_space.spaces)
        super().__init__(num_envs, obs_space, action_space(config, action_type),
                         autoreset_mode=autoreset_mode, render_mode=render_mode)
        self.engine: Any = None  # the problem's engine with num_envs rows, made by the first reset()

    def _rows(self) -> Any:
        if self.engine is None:
            raise RuntimeError("call reset() before step()")
        return self.engine

    def reset(self, *, seed: int | list[int] | None = None, options: dict | None = None):
        check_reset_arguments(None, options)
        if self.engine is None:
            self.engine = problem_of(self.config).engine(self.config, self.num_envs)
        return super().reset(seed=seed, options=options)

    def _start(self, idx: list[int]) -> None:
        self._rows().start(idx, self._rngs)

    def _step_envs(self, actions: np.ndarray, stepping: list[int],
                   resetting: list[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[int, dict]]:
        n_sections = self.config.n_sections
        want = np.zeros((self.num_envs, n_sections), dtype=np.int64)
        for i in stepping:
            try:
                want[i] = decode_action(actions[i], self.action_type, n_sections)
            except ValueError as exc:  # say which env's action
                raise ValueError(f"actions[{i}]: {exc}") from None
        rewards, truncated, infos = self._rows().advance(want, stepping, self._rngs, resetting)
        return rewards, np.zeros(self.num_envs, dtype=bool), truncated, infos

    def _observation(self, i: int) -> dict[str, np.ndarray]:
        return self._rows().observation(i)

    def _observations(self) -> dict:
        return self._rows().observations(self._observation_keys)

    def _reset_info(self, i: int) -> dict:
        return self._rows().reset_info(i)

    def _frame(self, info: dict) -> np.ndarray:
        return self._rows().frame(0, info)

    def action_masks(self) -> np.ndarray:
        """(num_envs, ...) the masks of :meth:`TrackEnv.action_masks`, one row per env."""
        return _masks(self.engine, self.config, self.num_envs, self.action_type)

    def get_state(self, index: int) -> EnvState:
        """A snapshot of env ``index`` (:mod:`trackenv.envs.state`), the same as :meth:`TrackEnv.get_state`
        gives: it can be restored here, in another row, or in a single env of this config."""
        i = self._env_index(index)
        return snapshot(self.config, self._rows().get_state(i), self._rngs[i], self._infos[i])

    def set_state(self, index: int, state: EnvState) -> None:
        """Continue env ``index`` from ``state`` (a snapshot of this config); a pending NEXT_STEP reset of that
        env is dropped."""
        i = self._env_index(index)
        state = checked(state, self.config)
        self._rows().set_state(i, state.episode)
        self._restore_row(i, state)
