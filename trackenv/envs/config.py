"""What the environment configuration builds on: :class:`ConfigBase` (the dict round trip and the physics objects
built from the fields) and the checks of fields whose range depends on another field. The configuration itself
is :class:`~trackenv.envs.line_config.LineConfig`, one frozen, validated dataclass with named presets."""

from __future__ import annotations

import difflib
from dataclasses import asdict, fields
from functools import cached_property
from typing import Any, ClassVar, TypeVar

from ..physics._checks import check_choice, check_scalar
from ..physics.geometry import QualityLimits
from ..physics.settlement import LAWS, make_law
from ..physics.tamping import TampingModel

_C = TypeVar("_C", bound="ConfigBase")


class ConfigBase:
    """What the frozen env config (``LineConfig``) is built on: the dict round trip
    (``from_dict`` refuses unknown keys by name, ``replace`` validates the changed copy, ``to_dict`` writes the
    mapping fields, stored as sorted item tuples so the config stays hashable, back as dicts) and the physics
    objects built from the fields both have (the settlement law, the tamping model, the quality limits). The
    derived objects are built once per config (it is frozen, so they cannot go stale), not once per step."""

    _MAPPING_FIELDS: tuple[str, ...] = ("law_params", "tamping", "limits")
    #: the action parameterisations a learner may use on this problem: the env's own action types, and
    #: "ranked" (tamp the k worst sections by measured SD: ``trackenv.envs.wrappers``) where it is offered
    agent_action_types: ClassVar[tuple[str, ...]] = ("multibinary",)
    #: the cost parts of a step that interventions make, in the order of ``info["costs"]``
    _INTERVENTION_COST_KEYS: ClassVar[tuple[str, ...]] = ()
    #: the config field of the fixed cost of a campaign (a step with any intervention)
    _CAMPAIGN_COST_FIELD: ClassVar[str] = ""
    #: (cost part, quality class, config field of its cost per section and step) for each class that costs
    _CLASS_COST_FIELDS: ClassVar[tuple[tuple[str, int, str], ...]] = ()
    speed_kmh: float
    law: str
    law_params: tuple
    tamping: tuple
    limits: tuple

    @classmethod
    def from_dict(cls: type[_C], d: dict[str, Any]) -> _C:
        """Build from a dict; an unknown key raises ValueError naming it."""
        known = {f.name for f in fields(cls)}  # type: ignore[arg-type]
        unknown = set(d) - known
        if unknown:
            close = {k: difflib.get_close_matches(str(k), sorted(known), n=1) for k in sorted(unknown, key=str)}
            hint = "; ".join(f"did you mean {m[0]!r} for {k!r}?" for k, m in close.items() if m)
            raise ValueError(f"unknown {cls.__name__} key(s) {sorted(unknown)}; {hint + ' ' if hint else ''}"
                             f"known: {sorted(known)}")
        return cls(**d)

    def replace(self: _C, **changes: Any) -> _C:
        """A copy with some fields changed (validated; unknown keys raise ValueError)."""
        return self.from_dict({**self.to_dict(), **changes})

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)  # type: ignore[call-overload]
        for k in self._MAPPING_FIELDS:
            d[k] = dict(getattr(self, k))
        return d

    def _check_models(self) -> None:
        """Check the fields that build the physics objects both problems have (the settlement law and its
        parameters, the tamping model, the quality limits at the config's speed), storing the mappings as
        sorted item tuples; each model's own validation names the field at fault."""
        check_choice("law", self.law, sorted(LAWS))
        for name in self._MAPPING_FIELDS:
            object.__setattr__(self, name, _as_items(name, getattr(self, name)))
        _ = self.settlement_law  # validates law_params
        _ = self.tamping_model
        self.quality_limits.for_speed(self.speed)

    @classmethod
    def cost_keys(cls) -> tuple[str, ...]:
        """The names of a step's cost parts (``info["costs"]``), in order: the interventions', the geometry, the
        quality classes'."""
        return cls._INTERVENTION_COST_KEYS + ("geometry",) + tuple(name for name, _, _ in cls._CLASS_COST_FIELDS)

    @property
    def campaign_cost(self) -> float:
        """The fixed cost of a step with any intervention (k€: the mobilisation of the machine, the possession of
        the line), which belongs to the campaign rather than to any section."""
        return getattr(self, self._CAMPAIGN_COST_FIELD)

    @property
    def class_costs(self) -> dict[str, tuple[int, float]]:
        """Cost part name -> (quality class, cost per section and step in k€), for
        :func:`~trackenv.envs.costs.section_quality_costs`."""
        return {name: (cls, getattr(self, field)) for name, cls, field in self._CLASS_COST_FIELDS}

    @property
    def speed(self) -> float:
        """``speed_kmh`` in m/s."""
        return self.speed_kmh / 3.6

    @cached_property
    def settlement_law(self):
        return make_law(self.law, **dict(self.law_params))

    @cached_property
    def tamping_model(self) -> TampingModel:
        return TampingModel.from_dict(dict(self.tamping))

    @cached_property
    def quality_limits(self) -> QualityLimits:
        return QualityLimits.from_dict(dict(self.limits)) if self.limits else QualityLimits.en13848()


def check_range_field(obj: object, name: str, *, low: float, high: float, strict: bool = False) -> tuple[float, float]:
    """Check the field ``name`` of a frozen config as a range (lower, upper) of real numbers with ``low <= lower
    <= upper <= high`` (``lower < upper`` if ``strict``) and store it as a tuple of floats; else ValueError naming
    the field and what is allowed."""
    value = getattr(obj, name)
    rel = "<" if strict else "<="
    allowed = f"two numbers (lower, upper) with {low:g} <= lower {rel} upper <= {high:g}"
    try:
        if isinstance(value, str):
            raise TypeError
        lower, upper = (check_scalar(name, v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be {allowed}, got {value!r}") from None
    if not (low <= lower <= upper <= high) or (strict and lower == upper):
        raise ValueError(f"{name} must be {allowed}, got {value!r}")
    object.__setattr__(obj, name, (lower, upper))
    return lower, upper


def bounded_by(obj: object, other: str, check: Any, name: str, **limits: Any) -> Any:
    """``check(name, **limits)`` for a field whose range depends on the field ``other``: a refusal names both
    (the user may have changed either)."""
    try:
        return check(name, **limits)
    except ValueError as e:
        raise ValueError(f"{e} (its bound follows {other} = {getattr(obj, other)!r})") from None


def _as_items(name: str, value) -> tuple:
    """Mappings are stored as sorted (key, value) tuples so the config stays hashable and frozen."""
    if isinstance(value, dict):
        value = tuple(sorted(value.items()))
    try:
        items = tuple((str(k), v) for k, v in value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a mapping of parameter names to values") from None
    return items
