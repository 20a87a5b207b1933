"""Training settings: frozen, validated dataclasses, one per trainer.

* :class:`AlgoSettings` — the algorithm's constructor arguments (stable-baselines3's PPO, sb3-contrib's
  MaskablePPO); the defaults are theirs (a test keeps them equal);
* :class:`TampingSettings` — what :func:`~trackenv_agents.learning.tamping.train` reads (the 60 m track): the
  algorithm's arguments and the trainer's own options;
* :class:`LineSettings` — what :func:`~trackenv_agents.learning.line.train_line` reads (TampingLine).

The shipped values are the RL Zoo entries of ``agents/learning/hyperparams/ppo.yml`` (read flat by
:func:`~trackenv_agents.learning.tamping.load_hyperparams`); the defaults below fill what an entry leaves out.
Every field is checked when a settings object is made: a value of the wrong type or out of its range raises
ValueError naming the field and its range (:meth:`TrainingSettings.ranges` lists them), and so does a key
that is no field (:meth:`TrainingSettings.from_dict`, :meth:`TrainingSettings.updated`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np

__all__ = ["AlgoSettings", "LineSettings", "TampingSettings", "TrainingSettings"]

ALGOS = ("ppo", "maskable_ppo")


@dataclass(frozen=True)
class _Range:
    """A closed (or, with ``open_low``, half-open) interval of numbers; ``integer``: whole numbers only."""

    low: float
    high: float = math.inf
    integer: bool = False
    open_low: bool = False

    def __str__(self) -> str:
        def num(x: float) -> str:
            return "inf" if x == math.inf else f"{x:g}"

        kind = "an integer" if self.integer else "a number"
        left, right = "(" if self.open_low else "[", ")" if self.high == math.inf else "]"
        return f"{kind} in {left}{num(self.low)}, {num(self.high)}{right}"

    def check(self, value: Any) -> bool:
        if self.integer:
            ok = isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))
        else:
            ok = (isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))
                  and math.isfinite(value))
        return ok and (self.low < value if self.open_low else self.low <= value) and value <= self.high


def _num(default: float | None, low: float, high: float = math.inf, *, integer: bool = False,
         open_low: bool = False, optional: bool = False, doc: str = "") -> Any:
    return field(default=default, metadata={"range": _Range(low, high, integer, open_low), "optional": optional,
                                            "doc": doc})


def _choice(default: str | None, choices: str, *, optional: bool = False, doc: str = "") -> Any:
    """``choices``: the name of the class attribute (a tuple, or a callable returning one) listing the values."""
    return field(default=default, metadata={"choices": choices, "optional": optional, "doc": doc})


def _flag(default: bool, doc: str = "") -> Any:
    return field(default=default, metadata={"bool": True, "doc": doc})


def _layers(default: tuple[int, ...], doc: str = "") -> Any:
    return field(default=default, metadata={"layers": True, "doc": doc})


def _params(doc: str = "") -> Any:
    return field(default=None, metadata={"params": True, "doc": doc})


@dataclass(frozen=True)
class TrainingSettings:
    """The checks every settings class shares: see the module docstring."""

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            meta = f.metadata
            if value is None and (meta.get("optional") or meta.get("params")):
                continue
            where = f"{type(self).__name__}.{f.name}"
            if "range" in meta:
                rng: _Range = meta["range"]
                if not rng.check(value):
                    extra = " or None" if meta.get("optional") else ""
                    raise ValueError(f"{where} must be {rng}{extra}, got {value!r}")
                value = int(value) if rng.integer else float(value)
            elif "choices" in meta:
                choices = getattr(self, meta["choices"])
                choices = tuple(choices() if callable(choices) else choices)
                if value not in choices:
                    extra = " or None" if meta.get("optional") else ""
                    raise ValueError(f"{where} must be one of {list(choices)}{extra}, got {value!r}")
            elif meta.get("bool"):
                if not isinstance(value, (bool, np.bool_)):
                    raise ValueError(f"{where} must be true or false, got {value!r}")
                value = bool(value)
            elif meta.get("layers"):
                layers = _Range(1, 65_536, integer=True)
                if isinstance(value, (str, bytes)) or not hasattr(value, "__iter__") or \
                        not all(layers.check(v) for v in value):
                    raise ValueError(f"{where} must be a list of layer widths, each {layers}, got {value!r}")
                value = tuple(int(v) for v in value)
            elif meta.get("params"):
                if not isinstance(value, Mapping) or not all(isinstance(k, str) for k in value):
                    raise ValueError(f"{where} must be a mapping of parameter names to values or None, "
                                     f"got {value!r}")
                value = MappingProxyType(dict(value))
            object.__setattr__(self, f.name, value)

    @classmethod
    def field_names(cls) -> tuple[str, ...]:
        return tuple(f.name for f in dataclasses.fields(cls))

    @classmethod
    def ranges(cls) -> dict[str, str]:
        """Each field's allowed values, in words (what the errors say)."""
        out = {}
        for f in dataclasses.fields(cls):
            meta = f.metadata
            if "range" in meta:
                out[f.name] = str(meta["range"])
            elif "choices" in meta:
                choices = getattr(cls, meta["choices"])
                out[f.name] = f"one of {list(choices() if callable(choices) else choices)}"
            elif meta.get("bool"):
                out[f.name] = "true or false"
            elif meta.get("layers"):
                out[f.name] = "a list of layer widths"
            else:
                out[f.name] = "a mapping of parameter names to values"
            if meta.get("optional") or meta.get("params"):
                out[f.name] += " or None"
        return out

    @classmethod
    def _unknown(cls, keys: Any) -> None:
        unknown = sorted(set(keys) - set(cls.field_names()))
        if unknown:
            raise ValueError(f"unknown hyper-parameter(s) {unknown} for {cls.__name__} "
                             f"(known: {', '.join(sorted(cls.field_names()))})")

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> Any:
        """Settings from flat hyper-parameters (the defaults for what ``values`` leaves out); a key that is no
        field raises ValueError."""
        cls._unknown(values)
        return cls(**values)

    def updated(self, values: Mapping[str, Any]) -> Any:
        """A copy with ``values`` replacing fields key by key (checked again); a key that is no field raises."""
        self._unknown(values)
        return dataclasses.replace(self, **values)

    def to_dict(self) -> dict[str, Any]:
        """The flat hyper-parameters, JSON-ready (lists, plain dicts), as :meth:`from_dict` reads them."""
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if isinstance(value, tuple):
                value = list(value)
            elif isinstance(value, Mapping):
                value = dict(value)
            out[f.name] = value
        return out


@dataclass(frozen=True)
class AlgoSettings(TrainingSettings):
    """The algorithm's constructor arguments; defaults: stable-baselines3's PPO (the same in MaskablePPO)."""

    #: the keys that go to the algorithm's constructor (the others configure the trainer)
    ALGO_KEYS: ClassVar[tuple[str, ...]] = ("n_steps", "batch_size", "n_epochs", "gamma", "gae_lambda",
                                            "learning_rate", "ent_coef", "clip_range", "vf_coef", "max_grad_norm",
                                            "target_kl", "normalize_advantage")

    n_steps: int = _num(2048, 1, 10**7, integer=True, doc="steps per env and roll-out")
    batch_size: int = _num(64, 1, 10**7, integer=True, doc="minibatch size")
    n_epochs: int = _num(10, 1, 10**5, integer=True, doc="passes over each roll-out")
    gamma: float = _num(0.99, 0.0, 1.0, doc="discount factor (also VecNormalize's, for the reward scale)")
    gae_lambda: float = _num(0.95, 0.0, 1.0, doc="GAE's bias-variance trade-off")
    learning_rate: float = _num(3e-4, 0.0, 1.0, doc="Adam's step size (0: the network stays as it starts)")
    ent_coef: float = _num(0.0, 0.0, doc="entropy bonus")
    clip_range: float = _num(0.2, 0.0, open_low=True, doc="PPO's clipping of the probability ratio")
    vf_coef: float = _num(0.5, 0.0, doc="weight of the value loss")
    max_grad_norm: float = _num(0.5, 0.0, open_low=True, doc="gradient clipping")
    target_kl: float | None = _num(None, 0.0, open_low=True, optional=True,
                                   doc="stop an update's epochs past this KL divergence (None: never)")
    normalize_advantage: bool = _flag(True, "normalise the advantages per minibatch")

    def algo_kwargs(self) -> dict[str, Any]:
        """The algorithm's constructor arguments."""
        return {k: getattr(self, k) for k in self.ALGO_KEYS}


def _action_types() -> tuple[str, ...]:
    from .actions import ACTION_TYPES

    return tuple(ACTION_TYPES)


def _rules() -> tuple[str, ...]:
    from ..rules.problems import advisor_rules

    return tuple(sorted(advisor_rules()))


@dataclass(frozen=True)
class TampingSettings(AlgoSettings):
    """What :func:`~trackenv_agents.learning.tamping.train` reads: the algorithm's arguments and these."""

    ALGOS: ClassVar[tuple[str, ...]] = ALGOS
    ACTION_TYPES: ClassVar[Any] = staticmethod(_action_types)
    RULES: ClassVar[Any] = staticmethod(_rules)

    algo: str = _choice("ppo", "ALGOS", doc="ppo (stable-baselines3) or maskable_ppo (sb3-contrib)")
    action_type: str = _choice("multibinary", "ACTION_TYPES", doc="the agent's action parameterisation")
    keep_per_sleeper: bool = _flag(True, "keep the per-sleeper arrays in the observation")
    n_envs: int = _num(8, 1, 4096, integer=True, doc="envs stepped together")
    total_timesteps: int = _num(8000, 1, 10**12, integer=True, doc="env steps to train for")
    net_arch: tuple[int, ...] = _layers((64, 64), "hidden layers of the policy and value networks")
    clip_obs: float = _num(10.0, 0.0, open_low=True, doc="VecNormalize's clipping of the normalised observation")
    eval_freq: int = _num(0, 0, 10**12, integer=True, doc="env steps between held-out evaluations (0: none)")
    checkpoint_every_s: float = _num(300.0, 0.0, 10**7, doc="seconds of wall clock between checkpoints, taken at "
                                                            "a roll-out's start (0: none; see checkpoint.py)")
    initial_tamp_logit: float | None = _num(None, -50.0, 50.0, optional=True,
                                            doc="initial log-odds of tamping (None: the network's own)")
    warm_start_rule: str | None = _choice(None, "RULES", optional=True,
                                          doc="the rule cloned before PPO (None: no warm start)")
    warm_start_episodes: int = _num(64, 1, 10**6, integer=True, doc="episodes of the rule cloned")
    warm_start_epochs: int = _num(300, 1, 10**6, integer=True, doc="epochs of the cloning")
    warm_start_label_smoothing: float = _num(0.02, 0.0, 0.5, doc="label smoothing of the cloning")
    warm_start_params: Mapping[str, Any] | None = _params("the rule's parameters (None: its tuned ones)")
    bootstrap_at_horizon: bool = _flag(False, "bootstrap the value at the horizon instead of ending there")


@dataclass(frozen=True)
class LineSettings(AlgoSettings):
    """What :func:`~trackenv_agents.learning.line.train_line` reads: the algorithm's arguments (for the
    MaskablePPO stage) and these."""

    ALGOS: ClassVar[tuple[str, ...]] = ALGOS
    RULES: ClassVar[Any] = staticmethod(_rules)

    algo: str = _choice("maskable_ppo", "ALGOS", doc="the algorithm of the PPO stage")
    n_envs: int = _num(4, 1, 4096, integer=True, doc="lines of the PPO batch")
    total_timesteps: int = _num(0, 0, 10**9, integer=True, doc="line-steps of PPO after the policy iteration")
    net_arch: tuple[int, ...] = _layers((64, 64), "hidden layers of the per-section network")
    reward_scale: float = _num(20.0, 1e-6, 1e9, doc="k€ per section: the value head's and PPO's reward unit")
    eval_freq: int = _num(0, 0, 10**9, integer=True, doc="line-steps between PPO's held-out evaluations")
    checkpoint_every_s: float = _num(300.0, 0.0, 10**7,
                                     doc="the policy iteration's checkpoint follows each iteration; the PPO "
                                         "stage's comes every this many seconds of wall clock (0: none at all)")
    advisor: str = _choice("grouped-threshold", "RULES", doc="the rule the policy starts from (its choice is a "
                                                             "feature; a choice rule: the policy answers in choice "
                                                             "codes, the rule's other choices with its tamping)")
    advisor_params: Mapping[str, Any] | None = _params("the advisor's parameters (None: its tuned ones)")
    iterations: int = _num(6, 0, 1000, integer=True, doc="counterfactual policy iterations")
    episodes_per_iteration: int = _num(16, 1, 4096, integer=True, doc="new training episodes per iteration")
    focus_rate: float = _num(0.5, 1e-6, 1.0, doc="share of the decisions in question that are priced")
    other_rate: float = _num(0.1, 1e-6, 1.0, doc="share of the other decisions that are priced")
    fit_epochs: int = _num(40, 1, 100_000, integer=True, doc="epochs of each fit")
    fit_margin: float = _num(1.0, 0.0, 1e9, doc="k€: below it the policy keeps its own choice")
    learn_choices: bool = _flag(False, doc="the network also decides spot tamping and drainage, priced in the "
                                           "forks (with a choice rule as advisor, on a line that enables them)")
    campaign_forks: bool = _flag(False, doc="price whole campaigns instead of single sections' other choices (where "
                                            "sections share a segment: line_campaigns.campaign_counterfactuals)")
