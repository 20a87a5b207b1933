"""SB3 ``VecEnv`` s over the native vector envs: :class:`TampingSB3VecEnv` over
:class:`trackenv.envs.vector.TampingVectorEnv` (Tamping-v1) and :class:`trackenv.envs.line.TampingLineVectorEnv`
(TampingLine; chosen by a :class:`~trackenv.envs.line_config.LineConfig` or a scenario name as ``config``), and
:class:`SectionAgentsVecEnv`, the sections of TampingLine lines as agents of their own.

One physics implementation: the batched vector env steps all episodes in one call of the dynamics; this
adapter only translates conventions:

* Gymnasium's SAME_STEP autoreset (``infos["final_obs"]`` and ``infos["final_info"]`` at done envs, infos as
  a dict of arrays) becomes SB3's (a list of per-env info dicts, the episode's last info with
  ``info["terminal_observation"]`` and ``info["TimeLimit.truncated"]`` at done envs, the returned observation
  already the next episode's first);
* ``env_method("action_masks")`` / :meth:`action_masks` give the masks sb3-contrib's MaskablePPO asks for;
* seeds set by :meth:`seed` (SB3's convention: ``seed + i`` for env ``i``) are used at the next :meth:`reset`;
* ``action_type="ranked"``: the agent picks how many of the worst sections to tamp (``Discrete(n_sections +
  1)``), and ``"ranked_choices"`` (a line with the choices, ``LineConfig.choices``) how many sections get each
  enabled intervention (``MultiDiscrete([n_sections + 1] * len(choices))``), through the same vector wrapper any
  library gets (:class:`trackenv.envs.wrappers.RankedVectorActions`);
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

from collections.abc import Mapping, Sequence
from functools import partial
from typing import Any

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper

from trackenv.envs.line_config import LineConfig
from trackenv.envs.network import NetworkConfig
from trackenv.envs.problems import make_vector_env, problem_config
from trackenv.envs.sharded import native_or_sharded
from trackenv.envs.wrappers import RankedVectorActions, SectionVectorObservation, section_keys

from .actions import RANKED, RANKED_CHOICES, env_action_type
from .line_policy import FEATURE_CLIP, n_features, section_features


def observation_keys(space: spaces.Dict, keep_per_sleeper: bool = True, n_sections: int | None = None) -> list[str]:
    """The observation keys kept by the adapter, in the env's order (the section-level ones of
    :func:`trackenv.envs.wrappers.section_keys` unless ``keep_per_sleeper``)."""
    if keep_per_sleeper:
        return list(space.spaces)
    if n_sections is None:
        section_sd = space.spaces["section_sd"]
        assert isinstance(section_sd, spaces.Box)  # every problem's observation is a Dict of Boxes
        n_sections = section_sd.shape[0]
    return section_keys(space, n_sections)


def filter_observation(obs: dict, keys: Sequence[str]) -> dict:
    """The kept keys of an observation dict (single or batched), other keys dropped."""
    return {k: obs[k] for k in keys}


class _OneObjectVecEnv(VecEnv):
    """SB3's attribute and method access for a VecEnv whose envs are one object (a batched env): every index
    gets the same attribute; a method returning one row per env (like ``action_masks``) is split by index."""

    def _indices(self, indices) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        if isinstance(indices, (int, np.integer)):
            return [int(indices)]
        return [int(i) for i in indices]

    def _target(self, name: str):
        return getattr(self, name)

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
        idx = self._indices(indices)
        result = self._target(method_name)(*method_args, **method_kwargs)
        if isinstance(result, np.ndarray) and result.ndim >= 1 and result.shape[0] == self.num_envs:
            return [result[i] for i in idx]
        return [result for _ in idx]

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        return [False for _ in self._indices(indices)]

    def get_images(self) -> Sequence[np.ndarray | None]:
        return [None for _ in range(self.num_envs)]


class TampingSB3VecEnv(_OneObjectVecEnv):
    """SB3 VecEnv of ``num_envs`` tamping episodes with batched physics (see the module docstring).

    ``config`` is a :class:`LineConfig`, a preset name ("small", "default", "hard", "track60"), a dict of its
    fields, None (the 60 m track) or a :class:`~trackenv.envs.network.NetworkConfig`; ``action_type`` is
    "multibinary", "discrete", "ranked", "choices" or "ranked_choices" (:mod:`~trackenv_agents.learning.actions`;
    those the config's ``agent_action_types`` offer: the network's own only); ``seed``
    (optional) seeds the first reset (env ``i`` gets ``seed + i``); ``workers`` > 1 splits the envs over that
    many processes (:class:`~trackenv.envs.sharded.ShardedVectorEnv`: the same results, the Python of the steps
    in parallel; call :meth:`close` when done).
    """

    def __init__(self, num_envs: int = 8, config: LineConfig | NetworkConfig | dict | str | None = None, *,
                 action_type: str = "multibinary", keep_per_sleeper: bool = True,
                 bootstrap_at_horizon: bool = False, seed: int | None = None, workers: int = 1) -> None:
        venv: Any
        problem = problem_config(config)
        if action_type not in problem.agent_action_types:
            raise ValueError(f"action_type must be one of {problem.agent_action_types} on "
                             f"{type(problem).__name__}, got {action_type!r}")
        make = partial(make_vector_env, problem, action_type=env_action_type(action_type))
        venv = native_or_sharded(make, num_envs, workers)
        self.config = venv.config
        if action_type in (RANKED, RANKED_CHOICES):
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
        every count is valid; a masked section among the worst is simply not tamped by the env; ranked choices:
        :func:`trackenv.envs.wrappers.ranked_choice_masks`)."""
        return self.venv.action_masks()

    def _target(self, name: str):
        if hasattr(self, name):
            return getattr(self, name)
        return getattr(self.venv, name)  # raises AttributeError if neither has it

    # --- checkpoints ---
    def get_state(self) -> dict[str, Any] | None:
        """What a checkpoint needs to continue these envs exactly: each env's snapshot (its episode, generator
        and last info; :mod:`trackenv.envs.state`; the ranked actions decode on the restored observation). None
        where the envs live in worker processes (``workers`` > 1), out of reach of the planning state API. Call
        after :meth:`reset`."""
        base = self.venv.unwrapped
        if not hasattr(base, "get_state"):
            return None
        return {"envs": [base.get_state(i) for i in range(self.num_envs)]}

    def set_state(self, state: dict[str, Any]) -> None:
        """Continue the envs from :meth:`get_state`'s ``state`` (taken from envs of the same config and
        count): every env resumes its episode where it was, and draws its later episodes from its restored
        generator. (A checkpoint written before the ranked wrapper read the env's observation also holds its
        copy of the last observation, ``ranked_obs``: the restored envs give the same.)"""
        if len(state["envs"]) != self.num_envs:
            raise ValueError(f"the state holds {len(state['envs'])} envs, this adapter {self.num_envs}")
        self.venv.reset()  # the rows and their generators exist; their episodes are replaced below
        base = self.venv.unwrapped
        for i, env_state in enumerate(state["envs"]):
            base.set_state(i, env_state)
        self._reset_seeds()  # a seed set before would reseed the restored generators at the next reset


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


class SectionAgentsVecEnv(_OneObjectVecEnv):
    """SB3 ``VecEnv`` of the sections of ``n_lines`` TampingLine episodes as ``n_lines × S`` agents (env
    ``b·S + j`` is section j of line b), over one native line vector env (:class:`TampingSB3VecEnv`): one
    physics batch, and any SB3 algorithm for ``Discrete`` actions learns the per-section policy of
    :mod:`trackenv_agents.learning.line_policy`.

    Why: almost all of a section's costs are its own (the sections are physically independent; only the
    possession of a campaign is shared). A learner paid the line's total for every section's choice has to find
    the effect of one tamping under the noise of the other sections; paid the section's own costs, the credit is
    where it belongs (the reward decomposition of cooperative multi-agent RL, with the possession split equally
    between the sections of a campaign so that the sections' rewards add up to the line's).

    Observation: ``Box`` of :func:`section_features`. Action: ``Discrete(2)`` (1 = ask to tamp; the line env
    resolves the campaign: masked sections dropped, at most ``capacity``). Reward: minus the section's own costs
    of the step (``info["section_costs"]``) and, where it was tamped, an equal share of the campaign's
    possession, over ``reward_scale`` k€; the sections' rewards add up to the line's. Episodes end together at
    the horizon, reported as terminal (the life-cycle cost ends there; see :mod:`trackenv_agents.learning.sb3_vec`), and
    restart in the same step (SB3's convention, ``terminal_observation`` in the info). ``seed``: line ``i`` of
    the first reset gets ``seed + i``; later resets continue each line's generator. ``advisor``: a rule whose
    choice is a feature (:func:`~trackenv_agents.learning.line_policy.section_features`); ``choice_features``:
    with the choice features too, asking about the tamping (a choice rule as advisor)."""

    def __init__(self, n_lines: int, config: LineConfig | str | dict | None = None, *, seed: int | None = None,
                 reward_scale: float = 20.0, advisor: Any = None, choice_features: bool = False) -> None:
        if not (np.isfinite(reward_scale) and reward_scale > 0):
            raise ValueError(f"reward_scale must be a number > 0 (k€), got {reward_scale!r}")
        self.lines = TampingSB3VecEnv(int(n_lines), LineConfig.coerce(config), seed=seed)
        self.config = self.lines.config
        self.n_lines, self.S = self.lines.num_envs, self.config.n_sections
        self.reward_scale = float(reward_scale)
        self.advisor = None if advisor is None else advisor.bind(self.config)
        self.ask = "tamp" if choice_features else None
        space = spaces.Box(0.0, FEATURE_CLIP, (n_features(advisor, choice_features),), np.float32)
        self.render_mode = None
        super().__init__(self.n_lines * self.S, space, spaces.Discrete(2))
        self._actions: np.ndarray | None = None
        self.line_obs: dict[str, np.ndarray] = {}  # the lines' last raw observation (a rule acting on it: cloning)

    def _features(self, line_obs: Mapping[str, np.ndarray]) -> np.ndarray:
        return section_features(line_obs, self.advisor, ask=self.ask).reshape(self.num_envs, -1)

    def reset(self):
        obs = self.line_obs = self.lines.reset()
        self.reset_infos = [{} for _ in range(self.num_envs)]
        return self._features(obs)

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions).reshape(self.n_lines, self.S)

    def step_wait(self):
        if self._actions is None:
            raise RuntimeError("step_async() must be called before step_wait()")
        want, self._actions = self._actions.astype(np.int8), None
        obs, _, dones, infos = self.lines.step(want)
        self.line_obs = obs
        rewards = np.empty((self.n_lines, self.S))
        section_infos: list[dict] = []
        for b, info in enumerate(infos):  # the step's own info (the ended episode's last one where done)
            tamped = np.asarray(info["tamped_sections"], dtype=bool)
            share = info["costs"]["possession"] / max(int(tamped.sum()), 1)
            rewards[b] = -(np.asarray(info["section_costs"]) + share * tamped) / self.reward_scale
            terminal = section_features({k: v[None] for k, v in info["terminal_observation"].items()},
                                        self.advisor, ask=self.ask)[0] if dones[b] else None
            for j in range(self.S):
                d: dict[str, Any] = {"tamped": bool(tamped[j])}
                if terminal is not None:
                    d["terminal_observation"] = terminal[j]
                    d["TimeLimit.truncated"] = False
                section_infos.append(d)
        return (self._features(obs), rewards.ravel().astype(np.float32), np.repeat(dones, self.S),
                section_infos)

    def action_masks(self) -> np.ndarray:
        """(num_envs, 2): [may leave, may tamp] per section (a section tamped within the env's
        ``min_steps_between_tampings`` may not be tamped)."""
        may = np.asarray(self.lines.action_masks()).reshape(self.n_lines, self.S, 2)[:, :, 1]
        return np.stack([np.ones_like(may), may], axis=-1).reshape(self.num_envs, 2)

    def close(self) -> None:
        self.lines.close()

    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        self.lines.seed(seed)
        return [seed]

    def get_state(self) -> dict[str, Any] | None:
        """The lines' state (:meth:`TampingSB3VecEnv.get_state`) and their last observation, for a checkpoint;
        None where the lines' state is out of reach."""
        lines = self.lines.get_state()
        if lines is None:
            return None
        return {"lines": lines, "line_obs": {k: np.array(v, copy=True) for k, v in self.line_obs.items()}}

    def set_state(self, state: dict[str, Any]) -> None:
        """Continue the lines from :meth:`get_state`'s ``state``."""
        self.lines.set_state(state["lines"])
        self.line_obs = {k: np.array(v, copy=True) for k, v in state["line_obs"].items()}


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


def make_vec_env(num_envs: int = 8, config: LineConfig | dict | str | None = None, *,
                 seed: int | None = None, action_type: str = "multibinary",
                 keep_per_sleeper: bool = True) -> TampingSB3VecEnv:
    """Convenience constructor (same arguments as :class:`TampingSB3VecEnv`)."""
    return TampingSB3VecEnv(num_envs, config, action_type=action_type, keep_per_sleeper=keep_per_sleeper,
                            seed=seed)


__all__ = ["SectionAgentsVecEnv", "TampingSB3VecEnv", "VecScaleReward", "make_vec_env", "observation_keys",
           "filter_observation"]
