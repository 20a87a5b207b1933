"""Gymnasium wrappers that learners need, usable by any RL library (SB3, RLlib, CleanRL, TorchRL).

They are generic over any trackenv env whose observation is a ``Dict`` with per-section keys (``section_sd``
and others of shape ``(n_sections,)``) and whose unwrapped env has ``n_sections`` (or ``config.n_sections``):
the tamping env and the line env follow that convention.

* :class:`RankedActions` — ``Discrete(n_sections + 1)``: action ``k`` tamps the ``k`` sections with the
  largest observed section SD (0 = nothing, ``n_sections`` = a full campaign). With a mobilisation cost per
  campaign, good schedules tamp many sections at once, rarely; under ``MultiBinary`` a policy must switch its
  independent Bernoulli heads on in the same rare step, which per-section exploration almost never finds;
  ranked, a campaign is one choice among ``n_sections + 1``. The order of preference (worst first) is fixed;
  when and how much to tamp is learnt. Over an env with the choices (``action_type="choices"``) the same idea
  per intervention: ``MultiDiscrete([n_sections + 1] * len(config.choices))``, one count per enabled choice
  (how many of the worst sections by SD to tamp, by peak to spot-tamp, ...), each with its fixed order of
  preference (:mod:`trackenv.envs.ranking` has the scores and the precedence between them).
* :class:`SectionObservation` — drops the per-sleeper arrays (``level``, ``contact_force``): keeps the keys of
  shape ``(n_sections, ...)`` and the scalar ones (``time``). Small, and independent of the track's length.
* :class:`MultiDiscreteActions` — ``MultiBinary(n)`` as ``MultiDiscrete([2] * n)`` (what RLlib accepts); the
  choices, already ``MultiDiscrete``, pass through.
* :class:`ActionMaskObservation` — ``Dict(action_mask=..., observations=...)``, the form RLlib's action-masking
  RLModule reads the mask from (RLlib has no ``action_masks()`` method convention).
* a flat ``Box`` observation: Gymnasium's ``FlattenObservation`` over any of these (see :func:`make_ranked`).

**What each supports.** Every wrapper here takes the tamp-or-wait envs (``MultiBinary``) and the line's
choices (``action_type="choices"``, ``MultiDiscrete([7] * n_sections)``, the masks ``(n_sections · 7,)``);
the action wrappers refuse any other action space (``Discrete``) with a TypeError.

**Action masks.** Every wrapper here defines ``action_masks()`` in the wrapped action space's terms, so the
mask is reachable the way sb3-contrib looks for it (``env.get_wrapper_attr("action_masks")``, which its vector
envs' ``env_method("action_masks")`` calls). Gymnasium's own wrappers (those ``gym.make`` adds) do not forward
methods: call ``env.get_wrapper_attr("action_masks")()`` or ``env.unwrapped.action_masks()``.

The ranked decoding is batched (:func:`ranked_to_sections`, :func:`ranked_to_choices`) and exists as vector wrappers
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

from .batched import check_autoreset_mode
from .choices import CHOICES, code, work_on_sections, work_per_code
from .common import numeric_action
from .ranking import rank_mask, ranked_choice_masks, ranked_to_choices, ranked_to_sections, score_keys

__all__ = [
    "ActionMaskObservation", "MultiDiscreteActions", "RankedActions", "RankedVectorActions",
    "SectionObservation", "SectionVectorObservation", "choices_of", "config_of", "make_ranked", "make_ranked_vector",
    "n_sections_of", "rank_mask", "ranked_choice_masks", "ranked_fit", "ranked_to_choices", "ranked_to_sections",
    "section_keys",
]

SD_KEY = "section_sd"
SURVEY_KEY = "section_survey"


# --- what the wrappers read of an env ---
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


def config_of(env: gym.Env | VectorEnv) -> Any:
    """The config of a (wrapped) trackenv env or vector env (over Gymnasium's SyncVectorEnv, its first env's); None
    for an env without one."""
    base = env.unwrapped
    if getattr(base, "config", None) is None and getattr(base, "envs", None):  # SyncVectorEnv: its first env's
        return config_of(base.envs[0])  # type: ignore[union-attr]
    return getattr(base, "config", None)


def choices_of(env: gym.Env | VectorEnv) -> tuple[str, ...]:
    """The enabled interventions of a (wrapped) trackenv env, in the order of the action codes:
    ``config.choices`` (``("tamp",)`` for an env without it)."""
    return tuple(getattr(config_of(env), "choices", ("tamp",)))


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
    """:func:`_masks` for vector envs (Gymnasium's vector wrappers have no ``get_wrapper_attr``); over
    Gymnasium's SyncVectorEnv, its envs' masks stacked."""
    while not hasattr(type(env), "action_masks"):
        if isinstance(env, gym.vector.SyncVectorEnv):
            return np.stack(env.call("action_masks"))
        if not hasattr(env, "env"):
            raise AttributeError(f"no layer of {env} defines action_masks")
        env = env.env
    return np.asarray(env.action_masks())


def ranked_fit(config: Any, heads: tuple[str, ...], n_sections: int) -> tuple[np.ndarray, float]:
    """What caps the ranked choices' counts (:func:`ranked_choice_masks`' ``fit``): per head of ``heads``, each of
    the ``n_sections`` sections' work in the possession for that choice, and the possession's capacity, from a
    line ``config``."""
    per_code = work_per_code(config.choice_work)
    return (np.stack([work_on_sections(per_code, np.full(n_sections, code(h)), config.length_factors)
                      for h in heads]), float(config.capacity))


class _RankedForm:
    """What a ranked wrapper decodes, batched: over a tamp-or-wait env (``MultiBinary(n)``), one count
    (``Discrete(n + 1)``, :func:`ranked_to_sections`, every count valid); over an env with the choices
    (``MultiDiscrete([7] * n)``), one count per enabled intervention (``MultiDiscrete([n + 1] * heads)``,
    :func:`ranked_to_choices`, masked by :func:`ranked_choice_masks`). TypeError for any other env."""

    def __init__(self, owner: str, action_space: spaces.Space, observation_space: spaces.Space, n_sections: int,
                 choices: tuple[str, ...], config: Any = None) -> None:
        if action_space == spaces.MultiBinary(n_sections):
            self.heads: tuple[str, ...] | None = None
            keys: tuple[str, ...] = (SD_KEY,)
            self.space: spaces.Space = spaces.Discrete(n_sections + 1)
        elif action_space == spaces.MultiDiscrete([len(CHOICES)] * n_sections):
            self.heads = tuple(choices)
            keys = score_keys(self.heads)
            self.space = spaces.MultiDiscrete([n_sections + 1] * len(self.heads))
        else:
            raise TypeError(f"{owner} needs a MultiBinary({n_sections}) env or one with the choices "
                            f"(MultiDiscrete([{len(CHOICES)}] * {n_sections})), got {action_space}")
        if not isinstance(observation_space, spaces.Dict) or not set(keys) <= set(observation_space.spaces):
            raise TypeError(f"{owner} needs a Dict observation with {list(keys)}")
        if self.heads is not None and SURVEY_KEY in observation_space.spaces:
            keys += (SURVEY_KEY,)  # drainage ranks by what a survey found where the observation says it
        self.keys = tuple(dict.fromkeys(keys))
        self.n_sections = n_sections
        #: per head, each section's work in the possession, and the possession's capacity (the counts' masks stop
        #: where the head's eligible sections, least work first, no longer fit); None: no cap (no config)
        self.fit: tuple[np.ndarray, float] | None = None
        if self.heads is not None and config is not None and hasattr(config, "choice_work"):
            self.fit = ranked_fit(config, self.heads, n_sections)

    @property
    def width(self) -> int:
        """How many counts one action holds."""
        return 1 if self.heads is None else len(self.heads)

    def kept(self, observation: dict) -> dict[str, np.ndarray]:
        """The keys of ``observation`` the decoding reads, copied."""
        return {k: np.asarray(observation[k], dtype=float).copy() for k in self.keys}

    def decode(self, counts: np.ndarray, observation: dict[str, np.ndarray], env_masks) -> np.ndarray:
        """The env's actions (rows, n) of ``counts`` (rows, width) on the batched ``observation``;
        ``env_masks()`` gives the env's masks (read only for the choices)."""
        if self.heads is None:
            return ranked_to_sections(counts.reshape(-1), observation[SD_KEY])
        masks = np.asarray(env_masks()).reshape(counts.shape[0], -1)
        return ranked_to_choices(counts, observation, masks, self.heads)

    def masks(self, rows: int, env_masks) -> np.ndarray:
        """(rows, mask size) the valid ranked actions."""
        if self.heads is None:
            return np.ones((rows, self.n_sections + 1), dtype=bool)
        return np.asarray(ranked_choice_masks(env_masks(), self.heads, self.fit)).reshape(rows, -1)


# --- single-env wrappers ---
class RankedActions(gym.ActionWrapper, gym.utils.RecordConstructorArgs):
    """Ranked actions over a ``MultiBinary(n_sections)`` env or one with the choices (see the module docstring).

    Tamp-or-wait: ``Discrete(n_sections + 1)``, ``k`` tamps the ``k`` sections with the largest ``section_sd``
    of the observation the action was chosen on; a masked section among the ``k`` worst is not tamped (the env
    ignores it), so every count is valid: :meth:`action_masks` is all True.

    The choices (``action_type="choices"``): ``MultiDiscrete([n_sections + 1] * len(heads))``, one count per
    enabled intervention (:attr:`heads`, the env's ``config.choices``), each marking the sections that rank first
    by the head's score among those the env's mask lets get it (:func:`ranked_to_choices`); :meth:`action_masks`
    allows a count up to the number of such sections that fit the possession together (:func:`ranked_choice_masks`:
    a larger count of that choice alone would always be clipped).

    Wrap the env's own Dict observation (apply observation wrappers outside this one)."""

    def __init__(self, env: gym.Env) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.ActionWrapper.__init__(self, env)
        n = n_sections_of(env)
        self.n_sections = n
        self._form = _RankedForm("RankedActions", env.action_space, env.observation_space, n, choices_of(env),
                                 config_of(env))
        self.heads = self._form.heads
        """The interventions counted by the action, in order (None over a tamp-or-wait env)."""
        self.action_space = self._form.space

    def action(self, action) -> np.ndarray:
        a = numeric_action(action, f"{self._form.width} integer(s) in [0, {self.n_sections}] (a ranked action)")
        if a.size != self._form.width:
            raise ValueError(f"a ranked action is {self._form.width} integer(s) in [0, {self.n_sections}], got "
                             f"{action!r}")
        # the env's observation as it stands (a state restored through env.unwrapped.set_state included)
        now = self.env.unwrapped.current_observation()  # type: ignore[attr-defined]
        rows = {k: v[None] for k, v in self._form.kept(now).items()}
        return self._form.decode(a.reshape(1, -1), rows, lambda: _masks(self.env))[0]

    def action_masks(self) -> np.ndarray:
        return self._form.masks(1, lambda: _masks(self.env))[0]


class SectionObservation(gym.ObservationWrapper, gym.utils.RecordConstructorArgs):
    """The section-level observation: the keys of :func:`section_keys` (per-sleeper arrays dropped)."""

    def __init__(self, env: gym.Env) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.ObservationWrapper.__init__(self, env)
        self.keys = section_keys(env.observation_space, n_sections_of(env))
        self.observation_space = spaces.Dict({k: env.observation_space[k] for k in self.keys})  # type: ignore[index]

    def observation(self, observation: dict) -> dict:
        return {k: observation[k] for k in self.keys}

    def action_masks(self) -> np.ndarray:
        return _masks(self.env)


class MultiDiscreteActions(gym.ActionWrapper, gym.utils.RecordConstructorArgs):
    """``MultiBinary(n)`` actions as ``MultiDiscrete([2] * n)`` (same meaning; the masks are the same pairs
    [may-not-tamp, may-tamp] per section that sb3-contrib expects for MultiDiscrete). An env whose actions are
    already ``MultiDiscrete`` (the choices) passes through unchanged, so one pipeline of wrappers serves both;
    any other action space raises TypeError."""

    def __init__(self, env: gym.Env) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.ActionWrapper.__init__(self, env)
        space = env.action_space
        if isinstance(space, spaces.MultiDiscrete) and len(space.shape) == 1:
            self.action_space = space
            self._dtype = space.dtype
        elif isinstance(space, spaces.MultiBinary) and len(space.shape) == 1:
            self.action_space = spaces.MultiDiscrete([2] * space.n)
            self._dtype = np.dtype(np.int8)
        else:
            raise TypeError(f"MultiDiscreteActions needs a 1-D MultiBinary or MultiDiscrete env, got {space}")

    def action(self, action) -> np.ndarray:
        return np.asarray(action, dtype=self._dtype)

    def action_masks(self) -> np.ndarray:
        return _masks(self.env)


class ActionMaskObservation(gym.ObservationWrapper, gym.utils.RecordConstructorArgs):
    """``Dict(action_mask=Box(0, 1, (mask size,)), observations=<the inner observation>)``: the mask as part of
    the observation, where RLlib's action-masking RLModule (``ActionMaskingTorchRLModule``) reads it."""

    def __init__(self, env: gym.Env) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.ObservationWrapper.__init__(self, env)
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
    """A MultiBinary env or one with the choices (``gym.make(env_id, **kwargs)``, the tamping env by default;
    e.g. ``trackenv/TampingLineWet-v0``) learnt in ranked actions
    on the section-level observation; ``flat=True`` flattens that to one ``Box`` (default encoders of RLlib
    and CleanRL). The entry point of ``trackenv/TampingRanked-v1`` and ``trackenv/TampingRankedFlat-v1``."""
    env = SectionObservation(RankedActions(gym.make(env_id, **kwargs)))
    return gym.wrappers.FlattenObservation(env) if flat else env


# --- vector wrappers (the same logic over a batched env) ---
class RankedVectorActions(VectorActionWrapper):
    """:class:`RankedActions` for a vector env of MultiBinary envs or envs with the choices: one row of counts
    per env, decoded per env on the observation last returned and the env's masks (in NEXT_STEP autoreset the
    counts given to an env that is being reset are ignored, as every action is then)."""

    def __init__(self, env: VectorEnv) -> None:
        super().__init__(env)
        n = n_sections_of(env)
        self.n_sections = n
        self._form = _RankedForm("RankedVectorActions", env.single_action_space, env.single_observation_space, n,
                                 choices_of(env), config_of(env))
        self.heads = self._form.heads
        self.single_action_space = self._form.space
        self.action_space = batch_space(self.single_action_space, env.num_envs)

    def actions(self, actions) -> np.ndarray:  # type: ignore[override]
        counts = np.asarray(actions).reshape(self.num_envs, self._form.width)
        observed = self._form.kept(_current_observations(self.env.unwrapped))
        return self._form.decode(counts, observed, lambda: _vector_masks(self.env))

    def action_masks(self) -> np.ndarray:
        return self._form.masks(self.num_envs, lambda: _vector_masks(self.env))


def _current_observations(env: VectorEnv) -> dict:
    """The batched observations of ``env``'s envs as they stand: a native vector env's own
    (``current_observations``), or each single env's (``current_observation``) under Gymnasium's SyncVectorEnv."""
    if hasattr(env, "current_observations"):
        return env.current_observations()
    if isinstance(env, gym.vector.SyncVectorEnv):
        rows = env.call("current_observation")
        return {k: np.stack([row[k] for row in rows]) for k in rows[0]}
    raise TypeError(f"{type(env).__name__} does not say its envs' current observations")


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
        if check_autoreset_mode(kwargs["autoreset_mode"]) != AutoresetMode.NEXT_STEP:
            raise ValueError(f"autoreset_mode must be NEXT_STEP with flat=True (trackenv/TampingRankedFlat-v1): "
                             f"Gymnasium's vector FlattenObservation works in that mode only, got "
                             f"{kwargs['autoreset_mode']!r}; take flat=False (trackenv/TampingRanked-v1) for "
                             f"SAME_STEP")
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
