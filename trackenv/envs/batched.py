"""BatchedVectorEnv: the Gymnasium side of trackenv's native vector envs, written once for every problem.

A native vector env (:class:`~trackenv.envs.env.TrackVectorEnv`, whatever the problem) steps all its envs in one
batched call of the physics. What it owes Gymnasium does not depend on the problem and lives here:

* seeding: ``reset(seed=s)`` seeds env ``i`` with ``s + i``, or give a list of one seed per env
  (:func:`~trackenv.envs._seeding.vector_rngs`); later episodes of env ``i`` draw from the same generator, and
  ``reset()`` without a seed continues every env's generator (a None in the list, that env's);
* both of Gymnasium's autoreset modes, with the results of ``gymnasium.vector.SyncVectorEnv`` over the problem's
  single env in the same mode (observations, rewards, flags and infos, each info key with its ``_key`` mask):

  - ``SAME_STEP`` (default): an episode resets in the step it ends; the returned
    observation and info are the new episode's first, ``infos["final_obs"]`` (an object array) and
    ``infos["final_info"]`` (a dict of arrays) hold the last of the old one;
  - ``NEXT_STEP`` (Gymnasium's own default, RLlib's convention): the step that ends an episode returns its last
    observation and info; the next step resets that env (its action is ignored, reward 0, both flags False);

* ``render_mode="rgb_array"``: :meth:`render` draws the first env;
* the planning state API's bookkeeping per row (each env's generator and last info).

The subclass (:class:`~trackenv.envs.env.TrackVectorEnv`) connects it to the problem's engine: :meth:`_start`
(new episodes), :meth:`_step_envs` (one batched step), :meth:`_observation`, :meth:`_reset_info` and
:meth:`_frame`.
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space, concatenate, create_empty_array

from ..physics._checks import check_int
from ._seeding import vector_rngs
from .common import check_render_mode
from .state import EnvState

AUTORESET_MODES = (AutoresetMode.SAME_STEP, AutoresetMode.NEXT_STEP)


def check_autoreset_mode(value: AutoresetMode | str) -> AutoresetMode:
    """``value`` as an AutoresetMode (the enum, its value "SameStep" or "NextStep", or its name in any case:
    "same_step", "NEXT_STEP"); any other raises ValueError naming the modes a native vector env supports."""
    if isinstance(value, str):
        spelled = {m.value.lower(): m for m in AUTORESET_MODES} | {m.name.lower(): m for m in AUTORESET_MODES}
        value = spelled.get(value.lower(), value)
    try:
        mode = AutoresetMode(value)
    except ValueError:
        mode = None
    if mode not in AUTORESET_MODES:
        raise ValueError(f"autoreset_mode must be one of {[m.value for m in AUTORESET_MODES]}, got {value!r}")
    return mode


def check_vector_actions(actions: Any, num_envs: int, single_action_space: spaces.Space) -> np.ndarray:
    """``actions`` as an array of one action per env, (num_envs, *action shape); else ValueError naming the
    shape expected."""
    want = (num_envs,) + tuple(single_action_space.shape or ())
    try:
        arr = np.asarray(actions)
    except ValueError:  # ragged nested sequences
        raise ValueError(f"actions must have shape {want} (one action per env), got a ragged "
                         f"{type(actions).__name__} (rows of different lengths)") from None
    if arr.shape != want:
        raise ValueError(f"actions must have shape {want} (one action per env), got {type(actions).__name__} "
                         f"of shape {arr.shape}")
    return arr


class BatchedVectorEnv(VectorEnv):
    """``num_envs`` episodes of one problem, stepped together (see the module docstring).

    The subclass sets its config, then calls ``super().__init__`` with its single spaces."""

    metadata: dict[str, Any] = {"render_modes": ["rgb_array"], "autoreset_mode": AutoresetMode.SAME_STEP}

    def __init__(self, num_envs: int, single_observation_space: spaces.Space, single_action_space: spaces.Space,
                 *, autoreset_mode: AutoresetMode | str = AutoresetMode.SAME_STEP,
                 render_mode: str | None = None) -> None:
        self.num_envs = check_int("num_envs", num_envs, low=1, high=4096)
        self.autoreset_mode = check_autoreset_mode(autoreset_mode)
        self.render_mode = check_render_mode(render_mode)
        self.metadata = {**type(self).metadata, "autoreset_mode": self.autoreset_mode}
        self.single_observation_space = single_observation_space
        self.single_action_space = single_action_space
        self.observation_space = batch_space(single_observation_space, self.num_envs)
        self.action_space = batch_space(single_action_space, self.num_envs)
        self._rngs: list[np.random.Generator] = []  # one per env, from reset(seed=...)
        self._autoreset = np.zeros(self.num_envs, dtype=bool)  # NEXT_STEP: envs to reset at the next step
        self._infos: list[dict] = []  # each env's last info (render() draws the first; snapshots keep theirs)

    # ------------------------------------------------------------------ what a problem supplies
    def _start(self, idx: list[int]) -> None:
        """Start new episodes in envs ``idx``, drawn from their generators ``self._rngs[i]``."""
        raise NotImplementedError

    def _step_envs(self, actions: np.ndarray, stepping: list[int],
                   resetting: list[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[int, dict]]:
        """Step the envs ``stepping`` with their rows of ``actions`` and start new episodes in ``resetting`` (NEXT_STEP:
        the envs that ended in the previous step), all in one batch; return rewards, terminated and truncated
        (num_envs,) (0 and False outside ``stepping``) and the info of each stepped env."""
        raise NotImplementedError

    def _observation(self, i: int) -> dict[str, np.ndarray]:
        """The current observation of env ``i``."""
        raise NotImplementedError

    def _reset_info(self, i: int) -> dict:
        """The info of env ``i``'s new episode, as the single env's ``reset`` gives it."""
        raise NotImplementedError

    def _frame(self, info: dict) -> np.ndarray:
        """An RGB array (H, W, 3) of the first env's state, ``info`` its last info."""
        raise NotImplementedError

    def current_observations(self) -> dict:
        """The observations of the envs as they stand, batched: what the last reset or step returned, or a row's
        restored moment after :meth:`set_state` (a NEXT_STEP env that is to reset at the next step: its last)."""
        return self._observations()

    # ------------------------------------------------------------------ the Gymnasium API
    def _observations(self) -> dict:
        out = create_empty_array(self.single_observation_space, self.num_envs)
        obs = [self._observation(i) for i in range(self.num_envs)]
        # gymnasium types concatenate's result as any space's; for a Dict space it is the dict ``out``
        return concatenate(self.single_observation_space, obs, out)  # type: ignore[return-value]

    def _checked_actions(self, actions: Any) -> np.ndarray:
        return check_vector_actions(actions, self.num_envs, self.single_action_space)

    def reset(self, *, seed: int | list[int] | None = None,
              options: dict | None = None) -> tuple[dict, dict[str, Any]]:
        self._rngs = vector_rngs(seed, self.num_envs, self._rngs)
        everyone = list(range(self.num_envs))
        self._start(everyone)
        self._autoreset[:] = False
        infos: dict = {}
        self._infos = [self._reset_info(i) for i in everyone]
        for i, info in enumerate(self._infos):
            infos = self._add_info(infos, info, i)  # Gymnasium's vector infos, with masks
        return self._observations(), infos

    def step(self, actions: Any) -> tuple[dict, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        if not self._rngs:
            raise RuntimeError("call reset() before step()")
        actions = self._checked_actions(actions)
        resetting = np.flatnonzero(self._autoreset).tolist()  # NEXT_STEP only: their actions are ignored
        stepping = np.flatnonzero(~self._autoreset).tolist()
        rewards, terminated, truncated, step_infos = self._step_envs(actions, stepping, resetting)
        ended = terminated | truncated
        infos: dict = {}
        if self.autoreset_mode == AutoresetMode.SAME_STEP:
            done = np.flatnonzero(ended).tolist()
            for i in done:
                infos = self._add_info(infos, {"final_obs": self._observation(i), "final_info": step_infos[i]}, i)
            if done:
                self._start(done)
            resetting = done
        else:
            self._autoreset = ended.copy()  # reset these at the next step
        for i in resetting:
            step_infos[i] = self._reset_info(i)
        for i in range(self.num_envs):
            infos = self._add_info(infos, step_infos[i], i)
        self._infos = [step_infos[i] for i in range(self.num_envs)]
        return self._observations(), rewards, terminated, truncated, infos

    def render(self):  # one frame, not the tuple of frames VectorEnv.render is typed with
        """The first env's current state as an RGB array (``render_mode="rgb_array"``), else None."""
        if self.render_mode != "rgb_array" or not self._rngs:
            return None
        return self._frame(self._infos[0])

    # ------------------------------------------------------------------ the planning state API, per row
    def _env_index(self, index: int) -> int:
        """``index`` checked as an env of this vector env that has been reset."""
        i = check_int("index", index, low=0, high=self.num_envs - 1)
        if not self._rngs:
            raise RuntimeError("call reset() before get_state() or set_state()")
        return i

    def _restore_row(self, i: int, state: EnvState) -> None:
        """The Gymnasium side of restoring env ``i`` from ``state``: its generator and last info; a pending
        NEXT_STEP reset is dropped (the env continues the restored episode)."""
        self._rngs[i].bit_generator.state = copy.deepcopy(state.rng_state)
        self._infos[i] = copy.deepcopy(state.last_info)
        self._autoreset[i] = False
