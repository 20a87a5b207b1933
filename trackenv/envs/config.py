"""The configuration of the tamping environment: one frozen, validated dataclass with documented defaults."""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from functools import cached_property, partial
from typing import Any, ClassVar, TypeVar

from ..degradation import TrackDegradation
from ..physics._checks import check_choice, check_field, check_int_field, check_scalar, check_time_steps
from ..physics.contact import HertzContact
from ..physics.geometry import QualityLimits
from ..physics.settlement import LAWS, make_law
from ..physics.tamping import TampingModel
from ..physics.timestep import DT_REFERENCE_S, auto_time_step, check_dt_option
from ..physics.track import Track
from ..physics.vehicle import GRAVITY, Car, Wheelset

VEHICLES = ("wheelset", "manchester_coach", "zhai_coach", "freight_wagon")


_C = TypeVar("_C", bound="ConfigBase")


class ConfigBase:
    """What the frozen env configs (:class:`TampingEnvConfig`, ``LineConfig``) share: the dict round trip
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
            raise ValueError(f"unknown {cls.__name__} key(s) {sorted(unknown)}; known: {sorted(known)}")
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


@dataclass(frozen=True)
class TampingEnvConfig(ConfigBase):
    """Everything that defines a tamping problem. SI units unless the name says otherwise.

    Track: ``track_length_m`` (>= 30; default 60 m = 101 sleepers ``sleeper_spacing_m`` = 0.6 m apart) split
    into ``n_sections`` equal tamping sections; supports from ``Track.realistic`` with per-sleeper ballast
    stiffness drawn lognormal with coefficient of variation ``ballast_stiffness_cv``, correlated over
    ``ballast_stiffness_correlation_m``; with probability ``transition_probability`` a transition zone (ballast
    ``transition_stiffness_ratio`` times stiffer from a sleeper on, e.g. a bridge approach, drawn uniformly
    within the fractions ``transition_position`` of the track, away from its ends);
    ``voided_sleepers_mean`` hanging sleepers on average (Poisson), each keeping ``voided_residual_support``
    of its ballast support. Ballast condition varies along the track: each sleeper's settlement rate is
    lognormal with CV ``settlement_rate_cv``, correlated over ``settlement_rate_correlation_m``. The initial
    level is drawn from the German vertical PSD of ``initial_quality`` ("low"/"high" disturbance).

    Traffic: wheel load ``axle_load_t``·g/2 (a wheelset carrying it, or one of the car models in
    ``vehicle``), ``speed_kmh``, ``axle_passes_per_year``, ``steps_per_year`` planning periods a year (each
    step runs one dynamic pass and advances the settlement by axle_passes_per_year/steps_per_year cycles),
    ``horizon_years`` (the episode is truncated there).

    Settlement: ``law`` and ``law_params`` (see :data:`trackenv.physics.settlement.LAWS`). Default: Shenton's
    power-plus-linear law with the force exponent of Hettler (1.6): a log law (the paper's) saturates and a
    track following it would need almost no maintenance within a planning horizon, while real track keeps
    degrading roughly linearly after consolidation; K1 = 0.05 mm (a third of the law's default) keeps the
    consolidation after tamping to about 0.7 mm in the first quarter at 50 kN, so that the ballast-condition
    variability does not rebuild a tamped section's irregularity within one period **[assumption]**.
    Tamping: ``tamping`` (a dict of :class:`TampingModel` fields); default reference "smoothing": the
    machine's chord rests on the neighbouring track, so a section is not lifted above its settled neighbours
    (lifting it back to the design line would leave steps at its ends, which the D1 measure sees).

    Costs (k€): ``mobilisation_cost`` per campaign (a step with any tamping), ``section_tamping_cost`` per
    section tamped, ``geometry_cost_per_section_year`` times (SD/SD_alert)² per section and year (poor ride,
    speed restrictions, faster wear), and per section and step at or above a limit ``alert_cost``,
    ``intervention_cost``, ``immediate_action_cost`` (a large penalty: the line must be closed or slowed).
    Quality limits: EN 13848-5 style table (``limits``, a dict of :class:`QualityLimits` fields, default
    :meth:`QualityLimits.en13848`) at ``speed_kmh``; the SD alert value applies to our short sections as is.

    ``min_steps_between_tampings``: a section tamped in the last k steps cannot be tamped again (masked).

    ``dt``: time step of the passes [s], or "auto" (default): the coarsest step that keeps peak forces within
    0.5 % of dt = 1e-4 s (the accuracy contract of :mod:`trackenv.physics.timestep`, whose bounds apply).
    """

    track_length_m: float = 60.0
    n_sections: int = 6
    sleeper_spacing_m: float = 0.6
    ballast_stiffness_cv: float = 0.15
    ballast_stiffness_correlation_m: float = 1.2
    transition_probability: float = 0.3
    transition_stiffness_ratio: float = 2.0
    transition_position: tuple = (0.2, 0.8)
    voided_sleepers_mean: float = 0.3
    voided_residual_support: float = 0.05
    settlement_rate_cv: float = 0.35
    settlement_rate_correlation_m: float = 3.0
    initial_quality: str = "low"
    vehicle: str = "wheelset"
    axle_load_t: float = 20.0
    speed_kmh: float = 100.0
    axle_passes_per_year: float = 2.0e6
    steps_per_year: int = 4
    horizon_years: float = 10.0
    law: str = "shenton"
    law_params: tuple = (("K1", 0.5e-4), ("force_exponent", 1.6))
    tamping: tuple = (("reference", "smoothing"),)
    mobilisation_cost: float = 10.0
    section_tamping_cost: float = 2.0
    geometry_cost_per_section_year: float = 4.0
    alert_cost: float = 0.5
    intervention_cost: float = 3.0
    immediate_action_cost: float = 50.0
    limits: tuple = ()
    min_steps_between_tampings: int = 1
    dt: float | str = "auto"

    agent_action_types = ("multibinary", "discrete", "ranked")
    _INTERVENTION_COST_KEYS = ("tamping",)
    _CAMPAIGN_COST_FIELD = "mobilisation_cost"
    _CLASS_COST_FIELDS = (("alert", 1, "alert_cost"), ("intervention", 2, "intervention_cost"),
                          ("immediate_action", 3, "immediate_action_cost"))

    def __post_init__(self) -> None:
        # Each check stores the value back in its canonical type (a numeric string or a bool is refused).
        c, ci = partial(check_field, self), partial(check_int_field, self)
        c("track_length_m", low=30.0, high=2000.0)
        # the sleeper spacings of ballasted track in service (the D1 filter and the sections assume one)
        c("sleeper_spacing_m", low=0.3, high=1.0)
        ci("n_sections", low=1, high=64)
        if self.n_sleepers < 3 * self.n_sections:
            raise ValueError("n_sections must leave at least 3 sleepers per section")
        c("ballast_stiffness_cv", low=0.0, high=1.0)
        c("ballast_stiffness_correlation_m", low=0.0, high=100.0)
        c("transition_probability", low=0.0, high=1.0)
        c("transition_stiffness_ratio", low=0.2, high=10.0)
        check_range_field(self, "transition_position", low=0.0, high=1.0, strict=True)
        c("voided_sleepers_mean", low=0.0, high=10.0)
        c("voided_residual_support", low=0.0, high=1.0)
        c("settlement_rate_cv", low=0.0, high=2.0)
        c("settlement_rate_correlation_m", low=0.0, high=100.0)
        check_choice("initial_quality", self.initial_quality, ("low", "high"))
        check_choice("vehicle", self.vehicle, VEHICLES)
        c("axle_load_t", low=1.0, high=40.0)
        c("speed_kmh", low=5.0, high=300.0)
        c("axle_passes_per_year", low=1.0, high=1e8)
        ci("steps_per_year", low=1, high=52)
        c("horizon_years", low=1.0 / self.steps_per_year, high=100.0)
        self._check_models()
        for name in (
            "mobilisation_cost",
            "section_tamping_cost",
            "geometry_cost_per_section_year",
            "alert_cost",
            "intervention_cost",
            "immediate_action_cost",
        ):
            c(name, low=0.0, high=1e9)
        ci("min_steps_between_tampings", low=0, high=100)
        dt = check_dt_option(self.dt)
        object.__setattr__(self, "dt", dt)
        # the dynamics' own bound on the time steps of a pass, read here so that the config refuses what a
        # step could not simulate: the leading axle runs from the vehicle's span through the approach zone
        # and the evaluated track to TrackDegradation.pass_end_position; with dt="auto" a pass that loses
        # contact is rerun at the reference step, so the finer of the two counts
        system = self.make_vehicle().system()
        track = Track.realistic(30.0)
        finest = (
            min(auto_time_step(track, system, self.speed, HertzContact()), DT_REFERENCE_S)
            if isinstance(dt, str)
            else dt
        )
        end = TrackDegradation.pass_end_position(self.track_length_m, track.sleeper_spacing, system.span)
        try:
            check_time_steps(end - system.span, self.speed, finest)
        except ValueError as e:
            raise ValueError(f"track_length_m, speed_kmh and dt: {e}") from None

    @classmethod
    def coerce(cls, config: TampingEnvConfig | dict | None) -> TampingEnvConfig:
        """A config from None (the defaults), a dict (validated) or a config; anything else raises."""
        if config is None:
            return cls()
        if isinstance(config, dict):
            return cls.from_dict(config)
        if not isinstance(config, cls):
            raise ValueError(f"config must be a TampingEnvConfig or dict, got {type(config).__name__}")
        return config

    # derived
    @property
    def n_sleepers(self) -> int:
        return int(round(self.track_length_m / self.sleeper_spacing_m)) + 1  # as Track.realistic counts them

    @property
    def horizon_steps(self) -> int:
        return int(round(self.horizon_years * self.steps_per_year))

    @property
    def cycles_per_step(self) -> float:
        return self.axle_passes_per_year / self.steps_per_year

    # Derived objects are built once per config (it is frozen, so they cannot go stale), not once per step.
    @cached_property
    def band_limits(self):
        """The quality limits of the speed band of ``speed_kmh``."""
        return self.quality_limits.for_speed(self.speed)

    def make_vehicle(self):
        wheel_load = self.axle_load_t * 1000.0 * GRAVITY / 2
        if self.vehicle == "wheelset":
            return Wheelset(mass=1800.0, static_load=max(wheel_load - 900.0 * GRAVITY, 0.0))
        return getattr(Car, self.vehicle)()


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
