"""Gymnasium wrappers that learners need, usable by any RL library (SB3, RLlib, CleanRL, TorchRL).

They are generic over any trackenv env whose observation is a ``Dict`` with per-section keys (``section_sd``
and others of shape ``(n_sections,)``) and whose unwrapped env has ``n_sections`` (or ``config.n_sections``):
the tamping env and the line env follow that convention.

* :class:`RankedActions` — ``Discrete(n_sections + 1)``: action ``k`` tamps the ``k`` sections with the
  largest observed section SD (0 = nothing, ``n_sections`` = a full campaign). With a mobilisation cost per
  campaign, good schedules tamp many sections at once, rarely; under ``MultiBinary`` a policy must switch its
  independent Bernoulli heads on in the same rare step, which per-section exploration almost never finds;
  ranked, a campaign is one choice among ``n_sections + 1``. The order of preference (worst first) is fixed;
  when and how much to tamp is learnt.
* :class:`SectionObservation` — drops the per-sleeper arrays (``level``, ``contact_force``): keeps the keys of
  shape ``(n_sections, ...)`` and the scalar ones (``time``). Small, and independent of the track's length.
* :class:`MultiDiscreteActions` — ``MultiBinary(n)`` as ``MultiDiscrete([2] * n)`` (what RLlib accepts).
* :class:`ActionMaskObservation` — ``Dict(action_mask=..., observations=...)``, the form RLlib's action-masking
  RLModule reads the mask from (RLlib has no ``action_masks()`` method convention).
* a flat ``Box`` observation: Gymnasium's ``FlattenObservation`` over any of these (see :func:`make_ranked`).

**What each supports.** :class:`SectionObservation`, :class:`SectionVectorObservation`,
:class:`ActionMaskObservation` and ``FlattenObservation`` take any action space, the line's choices
(``action_type="choices"``, ``MultiDiscrete([7] * n_sections)``, the masks ``(n_sections · 7,)``) included;
:class:`RankedActions`, :class:`RankedVectorActions` and :class:`MultiDiscreteActions` turn tamp-or-wait
(``MultiBinary``) actions into other forms and refuse any other action space with a TypeError.

**Action masks.** Every wrapper here defines ``action_masks()`` in the wrapped action space's terms, so the
mask is reachable the way sb3-contrib looks for it (``env.get_wrapper_attr("action_masks")``, which its vector
envs' ``env_method("action_masks")`` calls). Gymnasium's own wrappers (those ``gym.make`` adds) do not forward
methods: call ``env.get_wrapper_attr("action_masks")()`` or ``env.unwrapped.action_masks()``.

The ranked decoding is also batched (:func:`ranked_to_sections`) and exists as vector wrappers
(:class:`RankedVectorActions`, :class:`SectionVectorObservation`) over the native vector env, which the SB3
adapter in ``trackenv_agents.learning.sb3_vec`` uses: one implementation for every library.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorActionWrapper, VectorEnv, VectorWrapper
from gymnasium.vector.utils import batch_space

__all__ = [
    "ActionMaskObservation", "MultiDiscreteActions", "RankedActions", "RankedVectorActions",
    "SectionObservation", "SectionVectorObservation", "make_ranked", "make_ranked_vector", "n_sections_of",
    "rank_mask", "ranked_to_sections", "section_keys",
]

SD_KEY = "section_sd"


# --- the logic, as functions (batched) ---
def rank_mask(score: np.ndarray, eligible: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Per row, True for the ``k[row]`` highest-``score`` entries among ``eligible`` (ties: lower index)."""
    s = np.where(eligible, score, -np.inf)
    order = np.argsort(-s, axis=1, kind="stable")
    ranks = np.empty_like(order)
    np.put_along_axis(ranks, order, np.arange(s.shape[1])[None, :].repeat(s.shape[0], 0), axis=1)
    return eligible & (ranks < np.asarray(k).reshape(-1, 1))


def ranked_to_sections(k, section_sd) -> np.ndarray:
    """MultiBinary actions (int8, ``section_sd``'s shape) tamping the ``k`` worst sections by SD per row.

    ``k``: one count per row (or a scalar for a single unbatched observation); ``section_sd``: (n_sections,)
    or (n_envs, n_sections). Ties go to the lower section index. A count outside [0, n_sections] raises.
    """
    sd = np.asarray(section_sd, dtype=float)
    single = sd.ndim == 1
    sd2 = sd[None] if single else sd
    counts = np.asarray(k).reshape(-1)
    if counts.size != sd2.shape[0]:
        raise ValueError(f"need one ranked action per row of section_sd ({sd2.shape[0]}), got {counts.size}")
    if not np.all((counts >= 0) & (counts <= sd2.shape[1]) & (counts == np.round(counts))):
        raise ValueError(f"ranked actions must be integers in [0, {sd2.shape[1]}], got {counts.tolist()}")
    out = rank_mask(sd2, np.ones(sd2.shape, dtype=bool), counts.astype(int)).astype(np.int8)
    return out[0] if single else out


def n_sections_of(env: gym.Env | VectorEnv) -> int:
    """The number of tamping sections of a (wrapped) trackenv env: ``n_sections`` or ``config.n_sections``."""
    base = env.unwrapped
    n = getattr(base, "n_sections", None)
    if n is None:
        n = getattr(getattr(base, "config", None), "n_sections", None)
    if n is None and getattr(base, "envs", None):  # Gymnasium's SyncVectorEnv: its first env's
        return n_sections_of(base.envs[0])  # type: ignore[union-attr]
    if n is None:
        raise TypeError(f"{type(base).__name__} has neither n_sections nor config.n_sections")
    return int(n)


def section_keys(space: spaces.Space, n_sections: int) -> list[str]:
    """The keys of a Dict observation space that describe sections (shape ``(n_sections, ...)``) or the whole
    problem (shape ``(1,)``, e.g. ``time``), in the space's order; per-sleeper arrays are left out, also those of
    one segment that carries every section (``level`` of the 60 m track, shape ``(1, n_sleepers)``)."""
    if not isinstance(space, spaces.Dict):
        raise TypeError(f"need a Dict observation space, got {space}")
    return [k for k, s in space.spaces.items() if s.shape and (s.shape[0] == n_sections or s.shape == (1,))]


def _masks(env) -> np.ndarray:
    """The action masks of the nearest layer (wrapper or env) that defines ``action_masks``."""
    return np.asarray(env.get_wrapper_attr("action_masks")())


def _vector_masks(env) -> np.ndarray:
    """:func:`_masks` for vector envs (Gymnasium's vector wrappers have no ``get_wrapper_attr``)."""
    while not hasattr(type(env), "action_masks"):
        if not hasattr(env, "env"):
            raise AttributeError(f"no layer of {env} defines action_masks")
        env = env.env
    return np.asarray(env.action_masks())


# --- single-env wrappers ---
class RankedActions(gym.ActionWrapper):
    """``Discrete(n_sections + 1)`` over a ``MultiBinary(n_sections)`` env: ``k`` tamps the ``k`` sections with
    the largest ``section_sd`` of the observation the action was chosen on (see the module docstring).

    Wrap the env's own Dict observation (apply observation wrappers outside this one). A masked section among
    the ``k`` worst is not tamped (the env ignores it), so every count is valid: :meth:`action_masks` is all
    True."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        n = n_sections_of(env)
        if env.action_space != spaces.MultiBinary(n):
            raise TypeError(f"RankedActions needs a MultiBinary({n}) env, got {env.action_space}")
        if not isinstance(env.observation_space, spaces.Dict) or SD_KEY not in env.observation_space.spaces:
            raise TypeError(f"RankedActions needs a Dict observation with {SD_KEY!r}")
        self.n_sections = n
        self.action_space = spaces.Discrete(n + 1)
        self._sd = np.zeros(n)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        obs, info = self.env.reset(seed=seed, options=options)
        self._sd = np.asarray(obs[SD_KEY], dtype=float).copy()
        return obs, info

    def step(self, action):
        obs, reward, terminated, truncated, info = super().step(action)
        self._sd = np.asarray(obs[SD_KEY], dtype=float).copy()
        return obs, reward, terminated, truncated, info

    def action(self, action) -> np.ndarray:
        a = np.asarray(action)
        if a.size != 1:
            raise ValueError(f"a ranked action is one integer in [0, {self.n_sections}], got {action!r}")
        return ranked_to_sections(a.reshape(()), self._sd)

    def action_masks(self) -> np.ndarray:
        return np.ones(self.n_sections + 1, dtype=bool)


class SectionObservation(gym.ObservationWrapper):
    """The section-level observation: the keys of :func:`section_keys` (per-sleeper arrays dropped)."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.keys = section_keys(env.observation_space, n_sections_of(env))
        self.observation_space = spaces.Dict({k: env.observation_space[k] for k in self.keys})  # type: ignore[index]

    def observation(self, observation: dict) -> dict:
        return {k: observation[k] for k in self.keys}

    def action_masks(self) -> np.ndarray:
        return _masks(self.env)


class MultiDiscreteActions(gym.ActionWrapper):
    """``MultiBinary(n)`` actions as ``MultiDiscrete([2] * n)`` (same meaning; the masks are the same pairs
    [may-not-tamp, may-tamp] per section that sb3-contrib expects for MultiDiscrete)."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        if not isinstance(env.action_space, spaces.MultiBinary) or len(env.action_space.shape) != 1:
            raise TypeError(f"MultiDiscreteActions needs a 1-D MultiBinary env, got {env.action_space}")
        self.action_space = spaces.MultiDiscrete([2] * env.action_space.n)

    def action(self, action) -> np.ndarray:
        return np.asarray(action, dtype=np.int8)

    def action_masks(self) -> np.ndarray:
        return _masks(self.env)


class ActionMaskObservation(gym.ObservationWrapper):
    """``Dict(action_mask=Box(0, 1, (mask size,)), observations=<the inner observation>)``: the mask as part of
    the observation, where RLlib's action-masking RLModule (``ActionMaskingTorchRLModule``) reads it."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        size = _mask_size(env.action_space)
        self.observation_space = spaces.Dict({
            "action_mask": spaces.Box(0.0, 1.0, (size,), np.float32),
            "observations": env.observation_space,
        })

    def observation(self, observation) -> dict:
        return {"action_mask": _masks(self.env).astype(np.float32), "observations": observation}

    def action_masks(self) -> np.ndarray:
        return _masks(self.env)


def _mask_size(space: spaces.Space) -> int:
    if isinstance(space, spaces.Discrete):
        return int(space.n)
    if isinstance(space, spaces.MultiBinary):
        return 2 * int(np.prod(space.shape))
    if isinstance(space, spaces.MultiDiscrete):
        return int(np.sum(space.nvec))
    raise TypeError(f"no action mask for {space}")


def make_ranked(env_id: str = "trackenv/Tamping-v1", *, flat: bool = False, **kwargs: Any) -> gym.Env:
    """A MultiBinary env (``gym.make(env_id, **kwargs)``, the tamping env by default) learnt in ranked actions
    on the section-level observation; ``flat=True`` flattens that to one ``Box`` (default encoders of RLlib
    and CleanRL). The entry point of ``trackenv/TampingRanked-v1`` and ``trackenv/TampingRankedFlat-v1``."""
    env = SectionObservation(RankedActions(gym.make(env_id, **kwargs)))
    return gym.wrappers.FlattenObservation(env) if flat else env


# --- vector wrappers (the same logic over a batched env) ---
class RankedVectorActions(VectorActionWrapper):
    """:class:`RankedActions` for a vector env of MultiBinary envs: (num_envs,) counts, decoded per env on the
    section SD of the observation last returned (in NEXT_STEP autoreset the count given to an env that is
    being reset is ignored, as every action is then)."""

    def __init__(self, env: VectorEnv) -> None:
        super().__init__(env)
        n = n_sections_of(env)
        if env.single_action_space != spaces.MultiBinary(n):
            raise TypeError(f"RankedVectorActions needs MultiBinary({n}) envs, got {env.single_action_space}")
        self.n_sections = n
        self.single_action_space = spaces.Discrete(n + 1)
        self.action_space = batch_space(self.single_action_space, env.num_envs)
        self._sd = np.zeros((env.num_envs, n))

    def reset(self, *, seed=None, options=None):
        obs, info = self.env.reset(seed=seed, options=options)
        self._sd = np.asarray(obs[SD_KEY], dtype=float).copy()
        return obs, info

    def step(self, actions):
        obs, rewards, terminated, truncated, info = self.env.step(self.actions(actions))
        self._sd = np.asarray(obs[SD_KEY], dtype=float).copy()
        return obs, rewards, terminated, truncated, info

    def actions(self, actions) -> np.ndarray:  # type: ignore[override]
        return ranked_to_sections(np.asarray(actions).reshape(self.num_envs), self._sd)

    def action_masks(self) -> np.ndarray:
        return np.ones((self.num_envs, self.n_sections + 1), dtype=bool)


class SectionVectorObservation(VectorWrapper):
    """:class:`SectionObservation` for a vector env in either autoreset mode (``infos["final_obs"]`` of the
    SAME_STEP mode filtered the same way, which Gymnasium's ``VectorObservationWrapper`` refuses to do)."""

    def __init__(self, env: VectorEnv) -> None:
        super().__init__(env)
        self.keys = section_keys(env.single_observation_space, n_sections_of(env))
        self.single_observation_space = spaces.Dict({k: env.single_observation_space[k]  # type: ignore[index]
                                                     for k in self.keys})
        self.observation_space = batch_space(self.single_observation_space, env.num_envs)

    def observations(self, observations: dict) -> dict:
        return {k: observations[k] for k in self.keys}

    def reset(self, *, seed=None, options=None):
        obs, info = self.env.reset(seed=seed, options=options)
        return self.observations(obs), info

    def step(self, actions):
        obs, rewards, terminated, truncated, info = self.env.step(actions)
        obs = self.observations(obs)
        if "final_obs" in info:
            info["final_obs"] = np.array([None if o is None else self.observations(o) for o in info["final_obs"]],
                                         dtype=object)
        return obs, rewards, terminated, truncated, info

    def action_masks(self) -> np.ndarray:
        return _vector_masks(self.env)


def make_ranked_vector(num_envs: int = 8, *, env_id: str = "trackenv/Tamping-v1", flat: bool = False,
                       **kwargs: Any) -> VectorEnv:
    """The native vector env of ``env_id`` (batched physics; Gymnasium's SyncVectorEnv for an id without a
    vector entry point, or whose vector env does not take the ``autoreset_mode`` asked for) in ranked actions
    and section-level observations; the ``vector_entry_point`` of the ranked ids. ``flat=True`` adds
    Gymnasium's vector ``FlattenObservation``, which works in the NEXT_STEP autoreset mode only (so that is then
    the default ``autoreset_mode``)."""
    if flat:
        kwargs.setdefault("autoreset_mode", AutoresetMode.NEXT_STEP)
    venv = None
    if gym.spec(env_id).vector_entry_point is not None:
        try:
            venv = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", **kwargs)
        except (TypeError, ValueError):
            if "autoreset_mode" not in kwargs:
                raise  # a bad argument, not a batched env that lacks the autoreset mode asked for
    if venv is None:  # no batched form (in this mode): Gymnasium's SyncVectorEnv over the single envs
        mode = kwargs.pop("autoreset_mode", AutoresetMode.SAME_STEP)
        venv = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="sync",
                            vector_kwargs={"autoreset_mode": mode}, **kwargs)
    venv = SectionVectorObservation(RankedVectorActions(venv))
    return gym.wrappers.vector.FlattenObservation(venv) if flat else venv
