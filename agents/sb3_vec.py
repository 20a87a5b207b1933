"""An SB3 ``VecEnv`` over the native vector envs: :class:`trackenv.envs.vector.TampingVectorEnv` (Tamping-v0)
and :class:`trackenv.envs.line.TampingLineVectorEnv` (TampingLine; chosen by a
:class:`~trackenv.envs.line_config.LineConfig` or a scenario name as ``config``).

One physics implementation: the batched vector env steps all episodes in one call of the dynamics; this
adapter only translates conventions:

* Gymnasium's SAME_STEP autoreset (``infos["final_obs"]`` and ``infos["final_info"]`` at done envs, infos as
  a dict of arrays) becomes SB3's (a list of per-env info dicts, the episode's last info with
  ``info["terminal_observation"]`` and ``info["TimeLimit.truncated"]`` at done envs, the returned observation
  already the next episode's first);
* ``env_method("action_masks")`` / :meth:`action_masks` give the masks sb3-contrib's MaskablePPO asks for;
* seeds set by :meth:`seed` (SB3's convention: ``seed + i`` for env ``i``) are used at the next :meth:`reset`;
* ``action_type="ranked"``: the agent picks how many of the worst sections to tamp (``Discrete(n_sections +
  1)``), through the same vector wrapper any library gets
  (:class:`trackenv.envs.wrappers.RankedVectorActions`);
* the planning horizon ends the problem: the life-cycle cost is summed over the horizon only and the
  observation carries the time, so by default done envs are reported as terminal and SB3 does not bootstrap
  past the horizon (``bootstrap_at_horizon=True`` marks them ``TimeLimit.truncated`` instead, as a Gymnasium
  time limit; a learner then values tamping in the last year for benefits that no evaluation counts);
* ``keep_per_sleeper=False`` drops the large per-sleeper arrays (``level``, ``contact_force``) from the
  observation, keeping only the per-section summaries and time
  (:class:`trackenv.envs.wrappers.SectionVectorObservation`).

:class:`VecScaleReward` divides the rewards by a fixed scale (the line's learner: values O(1) without running
statistics, so that a policy does not depend on the line it was trained on).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper

from trackenv.envs.config import TampingEnvConfig
from trackenv.envs.line import TampingLineVectorEnv
from trackenv.envs.line_config import LineConfig
from trackenv.envs.vector import TampingVectorEnv
from trackenv.envs.wrappers import RankedVectorActions, SectionVectorObservation, section_keys

from .actions import RANKED, env_action_type


def observation_keys(space: spaces.Dict, keep_per_sleeper: bool = True, n_sections: int | None = None) -> list[str]:
    """The observation keys kept by the adapter, in the env's order (the section-level ones of
    :func:`trackenv.envs.wrappers.section_keys` unless ``keep_per_sleeper``)."""
    if keep_per_sleeper:
        return list(space.spaces)
    if n_sections is None:
        n_sections = space.spaces["section_sd"].shape[0]
    return section_keys(space, n_sections)


def filter_observation(obs: dict, keys: Sequence[str]) -> dict:
    """The kept keys of an observation dict (single or batched), other keys dropped."""
    return {k: obs[k] for k in keys}


class TampingSB3VecEnv(VecEnv):
    """SB3 VecEnv of ``num_envs`` tamping episodes with batched physics (see the module docstring).

    ``config`` is a :class:`TampingEnvConfig`, a dict of its fields, or None (defaults), or a TampingLine
    :class:`LineConfig` or scenario name ("small", "default", "hard"); ``action_type`` is "multibinary",
    "discrete" or "ranked" (the line: "multibinary" only); ``seed`` (optional) seeds the first reset (env ``i``
    gets ``seed + i``).
    """

    def __init__(self, num_envs: int = 8, config: TampingEnvConfig | LineConfig | dict | str | None = None, *,
                 action_type: str = "multibinary", keep_per_sleeper: bool = True,
                 bootstrap_at_horizon: bool = False, seed: int | None = None) -> None:
        venv: Any
        if isinstance(config, (LineConfig, str)):
            if action_type != "multibinary":
                raise ValueError(f"action_type must be 'multibinary' on TampingLine, got {action_type!r}")
            venv = TampingLineVectorEnv(num_envs, LineConfig.coerce(config))
        else:
            venv = TampingVectorEnv(num_envs, config, action_type=env_action_type(action_type))
        self.config = venv.config
        if action_type == RANKED:
            venv = RankedVectorActions(venv)
        if not keep_per_sleeper:
            venv = SectionVectorObservation(venv)
        self.venv = venv
        self.action_type = action_type
        self.keep_per_sleeper = bool(keep_per_sleeper)
        self.bootstrap_at_horizon = bool(bootstrap_at_horizon)
        obs_space = venv.single_observation_space
        self.obs_keys = list(obs_space.spaces)
        self.render_mode = None
        super().__init__(num_envs, obs_space, venv.single_action_space)
        self._actions: np.ndarray | None = None
        if seed is not None:
            self.seed(seed)

    # --- core API ---
    def reset(self):
        seeds = list(self._seeds)
        if all(s is None for s in seeds):
            obs, infos = self.venv.reset()
        else:
            obs, infos = self.venv.reset(seed=[None if s is None else int(s) for s in seeds])
        self.reset_infos = _unstack_infos(infos, self.num_envs)
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions)

    def step_wait(self):
        if self._actions is None:
            raise RuntimeError("step_async() must be called before step_wait()")
        actions, self._actions = self._actions, None
        if self.action_type in ("discrete", RANKED):
            actions = actions.reshape(self.num_envs)
        obs, rewards, terminated, truncated, infos = self.venv.step(actions)
        dones = np.logical_or(terminated, truncated)
        info_list = _unstack_infos(infos, self.num_envs)
        if dones.any():
            last = _unstack_infos(infos["final_info"], self.num_envs)
            for i in np.flatnonzero(dones):
                info_list[i] = last[i]  # the episode's last info, not the next one's first
                info_list[i]["terminal_observation"] = infos["final_obs"][i]
                info_list[i]["TimeLimit.truncated"] = bool(self.bootstrap_at_horizon and truncated[i]
                                                           and not terminated[i])
        return obs, rewards.astype(np.float32), dones, info_list

    def close(self) -> None:
        self.venv.close()

    def action_masks(self) -> np.ndarray:
        """(num_envs, mask size) valid actions, as :meth:`TampingEnv.action_masks` gives them per env (ranked:
        every count is valid; a masked section among the worst is simply not tamped by the env)."""
        return self.venv.action_masks()

    # --- attribute / method access (all envs share this one object) ---
    def _indices(self, indices) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        if isinstance(indices, (int, np.integer)):
            return [int(indices)]
        return [int(i) for i in indices]

    def _target(self, name: str):
        if hasattr(self, name):
            return getattr(self, name)
        return getattr(self.venv, name)  # raises AttributeError if neither has it

    def get_attr(self, attr_name: str, indices=None) -> list[Any]:
        value = self._target(attr_name)
        return [value for _ in self._indices(indices)]

    def has_attr(self, attr_name: str) -> bool:
        try:
            self._target(attr_name)
            return True
        except AttributeError:
            return False

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        setattr(self, attr_name, value)

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs) -> list[Any]:
        """Call a method of the envs; a method returning one row per env (like ``action_masks``) is split, so
        each index gets its own row."""
        idx = self._indices(indices)
        result = self._target(method_name)(*method_args, **method_kwargs)
        if isinstance(result, np.ndarray) and result.ndim >= 1 and result.shape[0] == self.num_envs:
            return [result[i] for i in idx]
        return [result for _ in idx]

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        return [False for _ in self._indices(indices)]

    def get_images(self) -> Sequence[np.ndarray | None]:
        return [None for _ in range(self.num_envs)]


class VecScaleReward(VecEnvWrapper):
    """Rewards divided by a fixed ``scale`` (> 0) for the learner; :meth:`get_original_reward` gives the last
    raw ones (as VecNormalize does). A monitor below this wrapper records the raw returns."""

    def __init__(self, venv: VecEnv, scale: float) -> None:
        if not (np.isfinite(scale) and scale > 0):
            raise ValueError(f"reward scale must be finite and > 0, got {scale!r}")
        super().__init__(venv)
        self.reward_scale = float(scale)
        self._raw = np.zeros(self.num_envs)

    def reset(self):
        return self.venv.reset()

    def step_wait(self):
        obs, rewards, dones, infos = self.venv.step_wait()
        self._raw = np.asarray(rewards, dtype=np.float64).copy()
        return obs, (self._raw / self.reward_scale).astype(np.float32), dones, infos

    def get_original_reward(self) -> np.ndarray:
        return self._raw.copy()


def _unstack_infos(infos: dict, n: int) -> list[dict]:
    """Gymnasium's dict-of-arrays infos as a list of per-env dicts (``_`` masks and final_* dropped)."""
    out: list[dict] = [{} for _ in range(n)]
    for key, val in infos.items():
        if key.startswith("_") or key in ("final_obs", "final_info"):
            continue
        if isinstance(val, dict):
            for i in range(n):
                out[i][key] = {k: _item(v[i]) for k, v in val.items() if not k.startswith("_")}
        else:
            for i in range(n):
                out[i][key] = _item(val[i])
    return out


def _item(x):
    return x.item() if isinstance(x, np.generic) else x


def make_vec_env(num_envs: int = 8, config: TampingEnvConfig | LineConfig | dict | str | None = None, *,
                 seed: int | None = None, action_type: str = "multibinary",
                 keep_per_sleeper: bool = True) -> TampingSB3VecEnv:
    """Convenience constructor (same arguments as :class:`TampingSB3VecEnv`)."""
    return TampingSB3VecEnv(num_envs, config, action_type=action_type, keep_per_sleeper=keep_per_sleeper,
                            seed=seed)


__all__ = ["TampingSB3VecEnv", "VecScaleReward", "make_vec_env", "observation_keys", "filter_observation"]
