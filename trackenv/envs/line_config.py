"""The configuration of the TampingLine environment and its scenario suite (small, default, hard).

Every default carries its source, or says **[assumption]**. The sources (the documentation's line-problem
page lists them with their figures): EN 13848-5/-6 (200 m SD sections, limits), Andrade & Teixeira 2011 (J. Transp. Eng.
137:193; lognormal rates between sections, spatially correlated), Wang & Markine 2018 (Proc. IMechE F,
doi 10.1177/0954409717748789; transition zones need 4-8x the maintenance of open track), GB figures for
switches and crossings (~5x per length), ÖBB / TU Graz (recording cars 2-4 times a year), tamper output
0.5-2.2 km per working hour (Railway Gazette), cost orders of magnitude (5-20 k€ per call-out, a few to
~15 €/m of tamping) **[unverified]**.
"""

from __future__ import annotations

import math
import os
import warnings
from dataclasses import dataclass, fields
from functools import partial
from typing import TYPE_CHECKING, Any

import numpy as np

from ..physics._checks import (
    check_bool,
    check_choice,
    check_field,
    check_int_field,
    check_scalar,
    check_time_steps,
)
from ..physics.contact import HertzContact
from ..physics.engine import ENGINES
from ..physics.timestep import DT_REFERENCE_S, auto_time_step, check_dt_option
from ..physics.track import Track
from ..physics.vehicle import GRAVITY, Car, Wheelset
from .choices import COST_KEY, INTERVENTIONS
from .config import ConfigBase, bounded_by, check_range_field

if TYPE_CHECKING:
    from .line_file import LineDescription

SLEEPER_SPACING_M = 0.6
#: sleepers of the approach (and of the exit) zone added to each end of a segment in its passes (the classic
#: engine's; the fast engine's may be longer: :attr:`LineConfig.approach_sleepers`)
APPROACH_SLEEPERS = 10
#: the engines a line's passes can run with (``LineConfig.engine``; :mod:`trackenv.physics.engine`)
LINE_ENGINES = tuple(ENGINES)
#: the shortest segment of track [m] whose passes a line computes (``segment_length_m``; 20 sleepers at 0.6 m)
MIN_SEGMENT_LENGTH_M = 12.0
#: the longest ``LineConfig.horizon_years`` [years] (the shortest is one step)
MAX_HORIZON_YEARS = 100.0
#: the largest ``LineConfig.pass_reuse_tolerance_m`` [m] (1 mm is the largest whose episode costs stay within 0.1 %
#: of computing every pass)
MAX_PASS_REUSE_TOLERANCE_M = 2e-3
#: the fast engine's approach is sized for a segment whose softest five supports have this share of the line's
#: ballast stiffness (about nine log-SDs below the mean of the default field) [assumption]; a softer segment's
#: passes start from static equilibrium instead (:meth:`~trackenv.physics.engine.PassEngine.options_for`)
SOFTEST_BALLAST_SHARE = 0.25
REGISTER_CLASSES = ("plain", "transition", "switch_or_crossing")
OVER_CAPACITY = ("clip", "raise")
#: How a local defect's rate factor meets a known zone's (transition, switch or crossing) on its sleepers:
#: "multiply" (the two factors multiply) or "faster" (the patch settles ``local_defect_rate_factor`` times the
#: plain track's rate, or at the zone's where that is faster).
LOCAL_DEFECT_IN_ZONE = ("multiply", "faster")
#: The line's fields that may also be given per section (``per_section``), with their bounds: the one range of
#: each, read by the line's value and by every section's.
PER_SECTION_BOUNDS: dict[str, tuple[float, float]] = {
    "section_length_m": (5.0, 1000.0), "speed_kmh": (5.0, 300.0), "annual_mgt": (0.1, 200.0),
    "freight_share": (0.0, 1.0)}
#: The fields a line file sets (``line``): its number of sections, their length, the line's traffic and what
#: differs per section (and, where it gives them, its costs, capacity, and with known short defects
#: :data:`KNOWN_DEFECT_NEAR_M` and :data:`KNOWN_DEFECT_IN_ZONE`: :func:`file_fields`).
LINE_FILE_FIELDS = ("n_sections", "section_length_m", "speed_kmh", "annual_mgt", "freight_share",
                    "freight_axle_load_t", "per_section")
#: The ``local_defect_near_m`` [m] of a line file that gives known short defects (its ``defects`` column): each
#: section counts its local defects once in its length, as the short-defect preset does (its value: 3 m either
#: side hold about 95 % of a 2.4 m dip's D1 energy), not once every 30 m segment (about seven times over in a
#: 200 m section's SD).
KNOWN_DEFECT_NEAR_M = 3.0
#: The ``local_defect_in_zone`` of a line file that gives known short defects: a defect on a zone's sleepers
#: settles at the faster of its own rate and the zone's, as on the short-defect preset; multiplied (4 × 2.5 on a
#: switch) four on a 60 km/h switch ran past the engine's validity within a quarter.
KNOWN_DEFECT_IN_ZONE = "faster"


def check_horizon(name: str, years: Any, steps_per_year: int) -> float:
    """``years`` as a float horizon of whole steps of ``1 / steps_per_year`` years, from one step to
    ``MAX_HORIZON_YEARS``; ValueError naming ``name`` with the two horizons of whole steps around it otherwise (an
    episode is whole steps: a horizon between two is refused, not rounded)."""
    years = check_scalar(name, years, low=1.0 / steps_per_year, high=MAX_HORIZON_YEARS)
    steps = years * steps_per_year
    if abs(steps - round(steps)) > 1e-6 * max(1.0, steps):
        step = 1.0 / steps_per_year
        raise ValueError(f"{name} must be a whole number of steps of {step:g} years (steps_per_year = "
                         f"{steps_per_year}), got {years:g} ({steps:.3g} steps): {math.floor(steps) * step:g} or "
                         f"{math.ceil(steps) * step:g}")
    return years


#: The most sections a line has (its sections' statics and the observation grow with them; a longer line is a
#: network of lines).
MAX_SECTIONS = 256


@dataclass(frozen=True)
class LineConfig(ConfigBase):
    """Everything that defines a TampingLine problem. SI units unless the name says otherwise; costs in k€.

    **Line.** ``n_sections`` sections of ``section_length_m`` (200 m: the EN 13848-6 / Trafikverket / Network
    Rail decision unit), each represented in the physics by a *segment* of ``segment_length_m`` of standing
    track (UIC60 on concrete sleepers at 0.6 m, ``Track.realistic``) that carries the section's properties.
    Why 30 m: ``experiments/segment_error.py`` compares the SD growth of a segment with that of the full 200 m
    section (the documentation's line-problem page gives the figures).

    **Traffic.** ``annual_mgt`` million gross tonnes a year at ``speed_kmh``; ``freight_share`` of the tonnage
    is freight at ``freight_axle_load_t`` (22.5 t: EN 15528 line category D), the rest passenger coaches
    (the Manchester benchmark coach of :class:`~trackenv.physics.vehicle.Car`, 11.1 t per axle). Each
    vehicle type is one loaded wheelset (its static wheel load and unsprung mass) per pass **[assumption:
    the car bodies' own dynamics are left out for speed; the sleeper forces come from the wheel loads]**.
    The settlement of a step is advanced over the mix by the equivalent force of the law's force exponent p,
    ``F_eq = (Σ_v n_v F_v^p / Σ_v n_v)^(1/p)`` per sleeper for ``Σ_v n_v`` axle passes (exact for a law
    linear in N, Miner's rule for load spectra otherwise).

    **Time.** ``steps_per_year`` planning periods (default quarters), ``horizon_years`` (truncation).
    A recording car measures every ``measurement_interval`` steps (default 4 = once a year: Trafikverket
    records track geometry 1-6 times a year by inspection class, BVF 807.2; ÖBB 2-4 times a year on its main
    lines; twice a year, the first design, left the best rule within ~5 % of the hindsight bound) with
    Gaussian noise ``sd_noise_mm`` on the SD and ``peak_noise_mm`` on the mean-to-peak **[assumption:
    repeatability of a recording car]**.

    **Heterogeneity.** Plain-track settlement-rate factor per section lognormal with log-SD ``rate_sigma``, AR(1)
    correlated along the line with correlation length ``rate_correlation_m`` (Andrade & Teixeira 2011: lognormal;
    the figures are **[assumption]**); inside a segment per-sleeper factors with CV ``sleeper_rate_cv`` correlated
    over ``sleeper_rate_correlation_m`` and ballast stiffness CV ``ballast_stiffness_cv`` (correlated over 2
    sleepers, 1.2 m **[assumption]**) around ``ballast_stiffness_factor`` times the realistic track's 160 MN/m (1
    by default; other values are for robustness studies: the calibration was run at 1). Known zones, in the
    register: a **transition** (probability ``transition_probability`` per section; ballast
    ``transition_stiffness_ratio`` times stiffer from the middle of the segment on, as at a bridge, plus
    ``transition_rate_factor`` on the soft side: the physics alone gives too little, see the calibration) and a
    **switch or level crossing** (``switch_probability``; ``switch_rate_factor`` on the segment and a stiff 3 m
    patch: ballast twice as stiff **[assumption]**: a crossing nose or a level-crossing slab). **Hanging
    sleepers**: a Poisson number per segment, mean ``voided_sleepers_mean`` (0 on the line, 0.3 on the 60 m
    track), each resting on ``voided_residual_support`` (0.05) of its ballast stiffness **[assumption]**: a gap
    under the sleeper that the first millimetres of deflection close. **Hidden wet spots**: with probability
    ``wet_spot_probability`` per section and episode a ``wet_spot_length_m`` patch starts to settle
    ``wet_spot_rate_factor`` times faster at a step drawn uniformly in the horizon; it is in no register. On a
    line file's sections whose ``wet`` column says ``suspected``, with probability ``suspected_wet_probability``
    instead (0.5 **[assumption]**: a suspicion, e.g. from mud spots or a drainage record, is taken as an even
    chance; set it to what your surveys find), from the same uniform draw.
    ``rate_scale`` multiplies all settlement (calibrated to the published SD growth, see ``trackenv calibrate``).
    ``initial_age_years``: each section was last tamped up to this long before the start (uniform), with up to
    ``initial_max_tampings`` tampings since renewal; its initial level is the German low-disturbance PSD scaled
    by a factor uniform in ``initial_scale``.

    **Settlement law** (``law``, ``law_params``: a name of :data:`~trackenv.physics.settlement.LAWS` and fields
    of that law). Shenton's power-plus-linear law with K1 = 0.05 mm (a third of
    :class:`~trackenv.physics.settlement.ShentonLaw`'s own default: less early consolidation), K2 = 1 mm per
    million cycles at 50 kN, and Hettler's force exponent 1.6 **[assumption]**: the form keeps growing after
    consolidation as track does, and ``rate_scale`` calibrates the whole to the published SD growth.

    **Tamping** (``tamping``: :class:`TampingModel` fields). A tamped section is lifted to the least-squares
    line of its segment keeping ``residual_fraction`` of its old shape plus a random residual (so the SD after
    rises with the SD before, Audley & Andrews' form), consolidation restarts, and the settlement rate grows
    by ``damage_per_tamping`` per tamping until, at ``max_tampings_before_renewal``, the intervention is a
    ballast renewal (rate and count reset, no memory; cost ``renewal_cost_per_m``).

    **Economics (k€).** ``possession_cost`` per campaign (a step with any tamping on the line: call-out, night
    possession; 5-20 k€ **[unverified]**), ``tamping_cost_per_m`` × section length per tamped section (10 €/m:
    a few to ~15 €/m **[unverified]**), ``renewal_cost_per_m`` (150 €/m **[assumption]**),
    ``geometry_cost_per_section_year`` × (SD/SD_alert)² (poor ride, faster wear of track and vehicles: 4 k€
    per section-year at the alert SD, against ÖBB's ~35 k€ per km-year, i.e. ~7 k€ per section-year, of
    total track cost **[assumption]**), ``speed_restriction_cost`` per section-step at or above the
    intervention limit of the D1 mean-to-peak (a temporary speed restriction: Railtrack's ~650 TSRs cost
    ~2 000 delay-minutes a day, ~3 min a day each; at ~75 € per delay-minute **[assumption]** that is
    ~80 k€ a year, 20 k€ a quarter),
    ``immediate_action_cost`` per section-step at the immediate-action limit (closure) **[assumption]**,
    ``alert_cost`` per section-step in the alert class (0: the geometry cost already prices the SD; 0.5 k€ on the
    60 m track **[assumption]**). ``limits``: the quality limits as ``QualityLimits`` fields (empty, the
    default: ``QualityLimits.en13848()``, the EN 13848-5 limits of each speed band).
    **Constraints**: ``capacity`` sections per campaign (a possession covers ``capacity`` × 200 m: one night
    at a tamper's 0.5-2.2 km/h); ``annual_budget`` (0: none) for the cost of each calendar year's work
    (possession, tamping, renewal and the other choices);
    ``over_capacity``: "clip" (keep the allowed sections with the worst measured SD, documented in the env)
    or "raise" (ValueError). ``min_steps_between_tampings``: a section tamped in the last k steps is masked.
    ``profiles``: also observe the measured per-sleeper level and wheel/rail force of every segment.
    ``contact_sensor``: also observe, every step, each section's wheel/rail force as an instrumented in-service
    vehicle reads it (axle-box accelerations): the peak of the step's passes and its dynamic share above the
    static wheel load, with a relative error of SD ``contact_sensor_noise`` (default 5 % **[assumption]**: the
    order of force estimates from axle-box accelerations), drawn at the reset like every other error.
    **Choices** (``action_type="choices"``; the documentation's page "What a track manager decides" has the
    table with sources). ``choices``: the enabled choices besides "nothing" (names of
    :data:`~trackenv.envs.choices.CHOICES`; default ``("tamp",)``: the tamping-only problem, drawn and scored as
    before). ``spot_tamping_length_m`` (6 m lifted around the worst sleeper), ``spot_tamping_cost`` (0.5 k€ per
    site), ``drainage_cost`` (25 k€ per site), ``inspection_cost`` (0.3 k€ per section) with the trolley's errors
    ``inspection_sd_noise_mm`` (0.05) and ``inspection_peak_noise_mm`` (0.2), ``survey_cost`` (0.4 k€ per
    section) **[assumption]** all; a renewal by choice costs a tamping and ``renewal_cost_per_m``. The work of
    each, in tamping-section equivalents of ``capacity`` (:attr:`choice_work`): tamp 1, ``spot_tamping_work``
    0.2, ``drainage_work`` 2, ``renewal_work`` 3 **[assumption]**, inspect and survey 0 (a choice whose work
    exceeds ``capacity`` is always masked). ``spot_possession_share`` (1): the share of ``possession_cost`` a step
    pays whose only track work is spot tamping (a short possession for a small tamper or a gang with hand-held
    tampers instead of a night's for a tamping machine **[assumption]**). ``surveyed_share``: the share of
    sections surveyed before the start (needs "survey"). Drawn only where set (else nothing is drawn for them):
    ``wet_spot_active_share``, the share of wet spots working from the first step; ``local_defects_mean`` short
    local defects per segment (Poisson; a joint, a weld, a failed sleeper), each a ``local_defect_length_m`` patch
    (2.4 m) settling ``local_defect_rate_factor`` (2.5) times faster **[assumption]** (on a line file's section
    with a known count, its ``defects`` column, that count in place of the draw, whatever the mean, apart at
    drawn positions, at most :meth:`known_defects_fit`); such a short patch lies
    mostly below the D1 band of 3-25 m, so it shows little in the measured level. ``local_defect_near_m`` (0:
    off) makes a section
    of ``section_length_m`` carry its segment's local defects once, instead of once every segment length: its SD
    (true and measured, and whatever reads it) is the length-weighted combination of the D1 variance over the
    sleepers within ``local_defect_near_m`` of a local defect and the variance over the rest of the segment,
    which stands for the rest of the section, ``SD² = (w·var_near + (L − w)·var_far) / L`` (w the length of the
    defects' neighbourhoods, L the section's length); its mean-to-peak stays the segment's. At 3 m either side
    the neighbourhood holds about 95 % of a 2.4 m dip's D1 energy **[assumption]**. Needs
    ``sections_per_segment`` = 1. ``local_defect_in_zone`` ("multiply", the default, or "faster"): on the sleepers
    of a transition or switch zone, a local defect's factor multiplies the zone's, or the patch settles at the
    factor times the plain track's rate unless the zone's is faster **[assumption]**: the zone's fast settlement
    comes from the same dynamic loads, and multiplied factors (up to 50x on a transition's soft side) can run a
    never-maintained section past the model's validity.
    ``dt``: time step of the passes [s] or "auto" (default: per vehicle type and speed, the coarsest step that
    keeps the peak forces within 0.5 % of dt = 1e-4 s, the contract of :mod:`trackenv.physics.timestep`; 4e-4 s
    for the coach wheelset and 3.2e-4 s for the freight wheelset at 100 km/h). ``engine`` (one of
    :data:`LINE_ENGINES`): how the passes run (:mod:`trackenv.physics.engine`). "classic" (the default, which
    every saved result used): static equilibrium at the start of a :data:`APPROACH_SLEEPERS`-sleeper approach
    zone, windows of 6.5 decay lengths with clamped ends, each pass running to the end of the exit zone. "fast":
    the periodic steady state 3 bays before the segment, windows of 3 decay lengths whose ends carry the static
    stiffness of the track beyond them, and each pass ending 3 bays after the segment (as
    :class:`~trackenv.degradation.TrackDegradation`'s); its approach zone (:attr:`approach_sleepers`) is sized
    for the softest segment the line is taken to draw (:data:`SOFTEST_BALLAST_SHARE`). Its line steps run about
    1.5 times as fast, with sleeper forces closer to a converged approach's; an episode's cost moves by a few
    hundredths of a percent (the physics-engine page of the documentation gives the figures).
    ``pass_reuse_tolerance_m`` [m] (0, the default: off, every segment's passes run every step): a segment's
    pass results are those of its last computed pass while its level differs from the level of that pass by less
    than this, once the mean of the difference is removed (a uniform shift moves the rail with its supports,
    approach and exit zones included, and changes no force); a tamping, spot tamping or renewal, and a new
    episode, compute the next pass afresh. The kept sleeper forces (per vehicle type) are corrected by the static
    redistribution of the level change since (the segment's support influence times the change), the contact
    force and profile are kept as computed. The change is measured against the computed pass, not the previous
    step, so the reused pass's level is at most the tolerance off. In [0, 2e-3]; 1e-3 is the largest tolerance
    whose episode costs stay within 0.1 % of computing every pass (the physics-engine page of the documentation
    gives its accuracy and speed).

    **Per section** (``per_section``: a mapping of some of :data:`PER_SECTION_BOUNDS` to one value per section;
    a field left out is the line's everywhere; needs ``sections_per_segment`` = 1, as each section then has a
    pass of its own). ``speed_kmh``: the section's passes run at its speed (so do its time steps with
    dt="auto"), and its quality limits are those of its speed band. ``freight_share``: the mix of its axle
    passes (its equivalent force and, as freight axles carry more tonnes, how many there are) and the static
    wheel load its contact sensor reads the dynamic share above. ``annual_mgt``: its axle passes scale with its
    tonnage. ``section_length_m``: the section is still represented by a segment of ``segment_length_m`` (a
    sample of its track: at most the shortest section), so its length changes what is counted per metre: its
    tamping and renewal cost, the possession work of tamping or renewing it (in sections of the line's
    ``section_length_m``, what ``capacity`` counts), its geometry cost, and the correlation of its settlement
    rate with its neighbours' (over the distance between their centres). It does not change its dynamics, its
    SD and mean-to-peak (those of its segment), the per-site choices (spot tamping, drainage) or the
    per-section ones (inspection, survey, the costs of a quality class). The line's own fields stay the
    reference: ``section_length_m`` is the unit of ``capacity``, ``speed_kmh`` the band of ``LineBatch.limits``
    (a section's own: :meth:`~trackenv.envs.line_episode.LineBatch.section_limits`).

    **A line from a file** (``line``: the path of a line file, or a
    :class:`~trackenv.envs.line_file.LineDescription`; the documentation's page "Lines from files"): the file
    sets :data:`LINE_FILE_FIELDS` (the number of sections, the line's section length, speed and traffic, and
    ``per_section``: the lengths, speeds, tonnages and freight shares that differ between its sections), the
    costs its ``costs`` mapping gives (:func:`file_fields`), and, per section, the register, known (and
    suspected) wet zones, years since tamping, tampings since renewal and the number of known short local defects.
    A file that gives known defects (a count in its ``defects`` column) also sets ``local_defect_near_m`` to
    :data:`KNOWN_DEFECT_NEAR_M` (3 m) and ``local_defect_in_zone`` to :data:`KNOWN_DEFECT_IN_ZONE` ("faster"),
    the short-defect preset's, so that a section's defects, known and drawn, count once in its length and one on a
    zone does not run away; a section may give at most :meth:`known_defects_fit` (3). Giving one of those fields
    as well is an error unless it equals the file's (:meth:`from_dict`, ``scenario``; :meth:`replace`, which the
    envs' keywords go through, refuses any; a config built directly cannot tell a value equal to the field's
    default from leaving it out, and the file's is taken).
    Where the file gives a measured history the section's
    rate factor is fitted to it (:mod:`trackenv.envs.line_fit`). What
    the file does not know is drawn per episode as without one. ``capacity`` is at most the file's number of
    sections (a larger one, the default 6 on a file of 4 sections or any other, is cut to it).
    """

    n_sections: int = 12
    section_length_m: float = 200.0
    segment_length_m: float = 30.0
    sections_per_segment: int = 1
    speed_kmh: float = 100.0
    annual_mgt: float = 15.0
    freight_share: float = 0.4
    freight_axle_load_t: float = 22.5
    steps_per_year: int = 4
    horizon_years: float = 10.0
    measurement_interval: int = 4
    sd_noise_mm: float = 0.1
    peak_noise_mm: float = 0.5
    rate_sigma: float = 0.5
    rate_correlation_m: float = 600.0
    sleeper_rate_cv: float = 0.35
    sleeper_rate_correlation_m: float = 3.0
    ballast_stiffness_cv: float = 0.15
    ballast_stiffness_factor: float = 1.0
    transition_probability: float = 0.12
    transition_stiffness_ratio: float = 3.0
    transition_rate_factor: float = 6.0
    switch_probability: float = 0.08
    switch_rate_factor: float = 4.0
    wet_spot_probability: float = 0.1
    suspected_wet_probability: float = 0.5
    wet_spot_rate_factor: float = 5.0
    wet_spot_length_m: float = 6.0
    voided_sleepers_mean: float = 0.0
    voided_residual_support: float = 0.05
    rate_scale: float = 1.0
    initial_age_years: float = 3.0
    initial_max_tampings: int = 4
    initial_scale: tuple = (0.4, 1.2)
    law: str = "shenton"
    law_params: tuple = (("K1", 0.5e-4), ("force_exponent", 1.6))
    tamping: tuple = ()
    possession_cost: float = 15.0
    tamping_cost_per_m: float = 0.01
    renewal_cost_per_m: float = 0.15
    geometry_cost_per_section_year: float = 4.0
    alert_cost: float = 0.0
    speed_restriction_cost: float = 20.0
    immediate_action_cost: float = 50.0
    capacity: int = 6
    annual_budget: float = 0.0
    over_capacity: str = "clip"
    min_steps_between_tampings: int = 1
    profiles: bool = False
    contact_sensor: bool = False
    contact_sensor_noise: float = 0.05
    choices: tuple = ("tamp",)
    spot_tamping_length_m: float = 6.0
    spot_tamping_cost: float = 0.5
    spot_tamping_work: float = 0.2
    spot_possession_share: float = 1.0
    drainage_cost: float = 25.0
    drainage_work: float = 2.0
    renewal_work: float = 3.0
    inspection_cost: float = 0.3
    inspection_sd_noise_mm: float = 0.05
    inspection_peak_noise_mm: float = 0.2
    survey_cost: float = 0.4
    surveyed_share: float = 0.0
    wet_spot_active_share: float = 0.0
    local_defects_mean: float = 0.0
    local_defect_length_m: float = 2.4
    local_defect_rate_factor: float = 2.5
    local_defect_near_m: float = 0.0
    local_defect_in_zone: str = "multiply"
    limits: tuple = ()
    dt: float | str = "auto"
    engine: str = "classic"
    pass_reuse_tolerance_m: float = 0.0
    per_section: tuple = ()
    line: LineDescription | None = None

    agent_action_types = ("multibinary", "discrete", "ranked", "choices", "ranked_choices")
    _INTERVENTION_COST_KEYS = ("possession", "tamping", "renewal", *COST_KEY.values())
    _CAMPAIGN_COST_FIELD = "possession_cost"
    _CLASS_COST_FIELDS = (("alert", 1, "alert_cost"), ("speed_restriction", 2, "speed_restriction_cost"),
                          ("immediate_action", 3, "immediate_action_cost"))

    def __post_init__(self) -> None:
        self._take_line()
        # each check stores the value back in its canonical type
        c, ci = partial(check_field, self), partial(check_int_field, self)
        ci("n_sections", low=1, high=MAX_SECTIONS)
        lo, hi = PER_SECTION_BOUNDS["section_length_m"]
        c("section_length_m", low=lo, high=hi)
        ci("sections_per_segment", low=1, high=64)
        self._check_per_section()
        K = self.sections_per_segment
        if K == 1:
            if self.section_length_m < MIN_SEGMENT_LENGTH_M:  # [MIN, section_length_m] below would be empty
                raise ValueError(f"section_length_m = {self.section_length_m:g} with sections_per_segment = 1: a "
                                 f"section is then represented by a segment of its own track, at least "
                                 f"{MIN_SEGMENT_LENGTH_M:g} m long (segment_length_m): lengthen the sections to "
                                 f">= {MIN_SEGMENT_LENGTH_M:g} m or carry several on a segment "
                                 f"(sections_per_segment > 1)")
            bounded_by(self, "section_length_m", c, "segment_length_m", low=MIN_SEGMENT_LENGTH_M,
                       high=self.section_length_m)
            lengths = self.section_values("section_length_m")
            if (lengths < self.segment_length_m).any():  # a section is represented by a segment of its track
                j = int(np.argmin(lengths))
                raise ValueError(f"per_section['section_length_m'][{j}] must lie in [segment_length_m = "
                                 f"{self.segment_length_m:g}, {PER_SECTION_BOUNDS['section_length_m'][1]:g}] (a "
                                 f"section is represented by a segment of its track), got {lengths[j]:g}")
        else:  # the segment is its sections, end to end
            c("segment_length_m", low=MIN_SEGMENT_LENGTH_M, high=2000.0)
            if abs(self.segment_length_m - K * self.section_length_m) > 1e-9 * self.segment_length_m:
                raise ValueError(f"segment_length_m must be sections_per_segment x section_length_m = "
                                 f"{K * self.section_length_m:g} when a segment carries several sections, "
                                 f"got {self.segment_length_m:g}")
            if self.n_sections % K:
                raise ValueError(f"n_sections must be a multiple of sections_per_segment = {K}, "
                                 f"got {self.n_sections}")
            # every section holds at least 8 sleepers: section_length_m >= 5 m at 0.6 m spacing
        for name in ("speed_kmh", "annual_mgt", "freight_share"):
            lo, hi = PER_SECTION_BOUNDS[name]
            c(name, low=lo, high=hi)
        c("freight_axle_load_t", low=5.0, high=40.0)
        ci("steps_per_year", low=1, high=52)
        object.__setattr__(self, "horizon_years", check_horizon("horizon_years", self.horizon_years,
                                                                self.steps_per_year))
        ci("measurement_interval", low=1, high=1000)
        c("sd_noise_mm", low=0.0, high=10.0)
        c("peak_noise_mm", low=0.0, high=50.0)
        c("rate_sigma", low=0.0, high=3.0)
        c("rate_correlation_m", low=0.0, high=1e5)
        c("sleeper_rate_cv", low=0.0, high=2.0)
        c("sleeper_rate_correlation_m", low=0.0, high=100.0)
        c("ballast_stiffness_cv", low=0.0, high=1.0)
        c("ballast_stiffness_factor", low=0.25, high=4.0)
        for name in ("transition_probability", "switch_probability", "wet_spot_probability",
                     "suspected_wet_probability"):
            c(name, low=0.0, high=1.0)
        c("transition_stiffness_ratio", low=0.2, high=10.0)
        for name in ("transition_rate_factor", "switch_rate_factor", "wet_spot_rate_factor"):
            c(name, low=0.1, high=100.0)
        bounded_by(self, "segment_length_m", c, "wet_spot_length_m", low=0.6, high=self.segment_length_m)
        c("voided_sleepers_mean", low=0.0, high=10.0)
        c("voided_residual_support", low=0.0, high=1.0)
        c("rate_scale", low=1e-3, high=1e3)
        c("initial_age_years", low=0.0, high=50.0)
        ci("initial_max_tampings", low=0, high=100)
        check_range_field(self, "initial_scale", low=0.0, high=10.0)
        self._check_models()
        for name in ("possession_cost", "tamping_cost_per_m", "renewal_cost_per_m", "geometry_cost_per_section_year",
                     "alert_cost", "speed_restriction_cost", "immediate_action_cost", "annual_budget"):
            c(name, low=0.0, high=1e9)
        self._check_capacity(ci)
        check_choice("over_capacity", self.over_capacity, OVER_CAPACITY)
        ci("min_steps_between_tampings", low=0, high=100)
        object.__setattr__(self, "profiles", check_bool("profiles", self.profiles))
        object.__setattr__(self, "contact_sensor", check_bool("contact_sensor", self.contact_sensor))
        c("contact_sensor_noise", low=0.0, high=1.0)
        self._check_choices()
        object.__setattr__(self, "dt", check_dt_option(self.dt))
        check_choice("engine", self.engine, LINE_ENGINES)
        c("pass_reuse_tolerance_m", low=0.0, high=MAX_PASS_REUSE_TOLERANCE_M)
        self._check_pass_time_steps()

    def _check_per_section(self) -> None:
        """``per_section``: a mapping of names of :data:`PER_SECTION_BOUNDS` to one number per section, each in
        the range of the line's field; stored as sorted (name, tuple of floats) items. Needs one section per
        segment (the sections of a segment share their pass)."""
        value = self.per_section
        if isinstance(value, dict):
            value = tuple(value.items())
        allowed = f"a mapping of {list(PER_SECTION_BOUNDS)} to {self.n_sections} numbers each (one per section)"
        try:
            items = dict((str(k), v) for k, v in value)
        except (TypeError, ValueError):
            raise ValueError(f"per_section must be {allowed}, got {self.per_section!r}") from None
        out = []
        for name in sorted(items):
            if name not in PER_SECTION_BOUNDS:
                raise ValueError(f"per_section: unknown field {name!r}; allowed: {list(PER_SECTION_BOUNDS)}")
            values = items[name]
            if isinstance(values, (str, bytes)) or not hasattr(values, "__len__") \
                    or getattr(values, "ndim", 1) != 1 or len(values) != self.n_sections:
                raise ValueError(f"per_section[{name!r}] must be {self.n_sections} numbers (n_sections), got "
                                 f"{values!r}")
            lo, hi = PER_SECTION_BOUNDS[name]
            out.append((name, tuple(check_scalar(f"per_section[{name!r}][{j}]", v, low=lo, high=hi)
                                    for j, v in enumerate(values))))
        object.__setattr__(self, "per_section", tuple(out))
        if out and self.sections_per_segment != 1:
            raise ValueError(f"per_section needs sections_per_segment = 1 (each section a pass of its own; the "
                             f"sections of a segment share one), got sections_per_segment = "
                             f"{self.sections_per_segment}")

    def _check_choices(self) -> None:
        """The enabled choices (stored as a tuple in the order of :data:`~trackenv.envs.choices.CHOICES`), their
        costs, work and noise, and the draws that only make sense with them."""
        value = self.choices
        allowed = f"a non-empty list of distinct names from {list(INTERVENTIONS)}"
        if isinstance(value, str) or not isinstance(value, (tuple, list)):
            raise ValueError(f"choices must be {allowed}, got {value!r}")
        unknown = [v for v in value if not isinstance(v, str) or v not in INTERVENTIONS]
        if unknown or not value or len(set(value)) != len(value):
            raise ValueError(f"choices must be {allowed}, got {list(value)!r}")
        object.__setattr__(self, "choices", tuple(name for name in INTERVENTIONS if name in value))
        c = partial(check_field, self)
        bounded_by(self, "segment_length_m", c, "spot_tamping_length_m", low=SLEEPER_SPACING_M,
                   high=self.segment_length_m)
        for name in ("spot_tamping_cost", "drainage_cost", "inspection_cost", "survey_cost"):
            c(name, low=0.0, high=1e9)
        c("spot_possession_share", low=0.0, high=1.0)
        for name in ("spot_tamping_work", "drainage_work", "renewal_work"):  # more than capacity: always masked
            c(name, low=0.0, high=100.0)
        c("inspection_sd_noise_mm", low=0.0, high=10.0)
        c("inspection_peak_noise_mm", low=0.0, high=50.0)
        c("surveyed_share", low=0.0, high=1.0)
        if self.surveyed_share > 0 and "survey" not in self.choices:
            raise ValueError(f"surveyed_share = {self.surveyed_share:g} needs 'survey' in choices (the observation "
                             f"shows what a survey found), got choices = {list(self.choices)}")
        c("wet_spot_active_share", low=0.0, high=1.0)
        c("local_defects_mean", low=0.0, high=10.0)
        bounded_by(self, "segment_length_m", c, "local_defect_length_m", low=SLEEPER_SPACING_M,
                   high=self.segment_length_m)
        c("local_defect_rate_factor", low=0.1, high=100.0)
        if self.local_defect_in_zone not in LOCAL_DEFECT_IN_ZONE:
            raise ValueError(f"local_defect_in_zone must be one of {list(LOCAL_DEFECT_IN_ZONE)}, got "
                             f"{self.local_defect_in_zone!r}")
        bounded_by(self, "segment_length_m", c, "local_defect_near_m", low=0.0, high=self.segment_length_m / 2)
        if self.local_defect_near_m > 0 and self.sections_per_segment != 1:
            raise ValueError(f"local_defect_near_m = {self.local_defect_near_m:g} needs sections_per_segment = 1 "
                             f"(a section represented by a segment of its own), got sections_per_segment = "
                             f"{self.sections_per_segment}")
        self._check_known_defects()
        self._check_suspected_wet()

    def _check_pass_time_steps(self) -> None:
        """The dynamics' own bound on the time steps of a pass (``MAX_TIME_STEPS``), read here so that the config
        refuses what a step could not simulate: each vehicle type's pass over a segment runs from the vehicle's
        span to the end of the modelled track (:meth:`pass_length_m`); with dt="auto" a pass that loses contact
        is rerun at the reference step, so the finer of the two counts."""
        track = Track.realistic(30.0)  # the sleeper spacing and supports the auto step reads
        speeds = sorted({self.speed_kmh, *self.section_values("speed_kmh")})
        for speed_kmh in speeds:
            speed = speed_kmh / 3.6
            try:
                self.quality_limits.for_speed(speed)
            except ValueError as e:
                raise ValueError(f"per_section['speed_kmh'] and limits: {e}") from None
            for vehicle in self.vehicles():
                system = vehicle.system()
                finest = (min(auto_time_step(track, system, speed, HertzContact()), DT_REFERENCE_S)
                          if isinstance(self.dt, str) else self.dt)
                try:
                    check_time_steps(self.pass_length_m(system.span), speed, finest)
                except ValueError as e:
                    where = "speed_kmh" if speed_kmh == self.speed_kmh else "per_section['speed_kmh']"
                    raise ValueError(f"segment_length_m, {where} and dt: {e}") from None

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> LineConfig:
        """Build from a dict (an unknown key raises ValueError naming it); with a ``line``, a field the file sets
        (:func:`file_fields`: its traffic and sections, its own costs) that ``d`` gives must be the file's, even
        where it is the field's default
        (the file's 50 km/h is not overridden by a given 100, the default speed, silently)."""
        config = super().from_dict(d)
        if config.line is not None:
            for name in file_fields(config.line):
                if name in d:
                    _check_file_field(name, d[name], config.line)
        return config

    @classmethod
    def coerce(cls, config: LineConfig | dict | str | None) -> LineConfig:
        """A config from None (defaults), a scenario name, a dict (validated) or a config."""
        if config is None:
            return cls()
        if isinstance(config, str):
            return scenario(config)
        if isinstance(config, dict):
            return cls.from_dict(config)
        if not isinstance(config, cls):
            raise ValueError(f"config must be a LineConfig, dict or scenario name, got {type(config).__name__}")
        return config

    def to_dict(self) -> dict[str, Any]:
        d = super().to_dict()
        d["initial_scale"] = tuple(self.initial_scale)
        d["per_section"] = dict(self.per_section)
        d["line"] = None if self.line is None else self.line.to_dict()
        return d

    def replace(self, **changes: Any) -> LineConfig:
        """A copy with some fields changed (validated; unknown keys raise ValueError). With a line file, the
        fields it sets (:func:`file_fields`) are the file's: changing one is an error, and a new ``line``
        replaces them all."""
        line = changes.get("line", self.line)
        owned = file_fields(line) if hasattr(line, "costs") else dict.fromkeys(LINE_FILE_FIELDS)
        given = [name for name in owned if name in changes]
        if line is not None and given:
            source = line if isinstance(line, (str, os.PathLike)) else getattr(line, "source", "given")
            raise ValueError(f"{', '.join(given)} come(s) from the line file {source}: change the file, or leave "
                             f"{'them' if len(given) > 1 else 'it'} out")
        base = {**self.to_dict(), "line": self.line}  # the description itself: its source, no second check
        if "line" in changes:  # the old line's values (or the scenario's, the defaults) give way to the new file's
            new = line_description(changes["line"])
            changes = {**changes, "line": new}
            old = LINE_FILE_FIELDS if self.line is None else file_fields(self.line)
            for name in {*old, *(file_fields(new) if new is not None else ())}:
                base.pop(name, None)
        return self.from_dict({**base, **changes})

    def _check_capacity(self, ci: Any) -> None:
        """``capacity`` within [1, n_sections]; the default's refusal on a shorter line says that it is the
        default, which the user never set, and what to set."""
        default = next(f.default for f in fields(self) if f.name == "capacity")
        n = self.n_sections
        if type(self.capacity) is int and self.capacity == default and isinstance(n, int) and 1 <= n < default:
            raise ValueError(f"capacity must be in [1, {n}] on a line of {n} sections, got {default} (the default "
                             f"where capacity is not given): set capacity")
        bounded_by(self, "n_sections", ci, "capacity", low=1, high=self.n_sections)

    def known_defects_fit(self) -> int:
        """The most known short local defects that the segment standing for a section holds apart: each a
        ``local_defect_length_m`` patch with ``local_defect_near_m`` of neighbourhood either side (3 with the
        defaults: 30 m / (2.4 + 2 · 3) m). More would overlap and fill the segment, and the section's SD would no
        longer count each once in its length (a fuller segment settles more evenly: a smoother section)."""
        return max(int(self.segment_length_m // (self.local_defect_length_m + 2 * self.local_defect_near_m)), 1)

    def _check_known_defects(self) -> None:
        """ValueError naming the first section of the line file whose known short defects do not fit its segment
        (:meth:`known_defects_fit`), and how to describe it instead."""
        if self.line is None or not self.line.defects_known:
            return
        most = self.known_defects_fit()
        for s in self.line.sections:
            if s.defects is not None and s.defects > most:
                raise ValueError(
                    f"line file {self.line.label}: section {s.id} gives {s.defects} known short defects; the "
                    f"{self.segment_length_m:g} m segment that stands for a section in the model holds at most "
                    f"{most} apart (each {self.local_defect_length_m:g} m with {self.local_defect_near_m:g} m "
                    f"either side): split the section in the file into shorter ones (each is a segment of its "
                    f"own, whatever its length), each with its own defects")

    def _check_suspected_wet(self) -> None:
        """A warning where the line file's suspected wet zones are less likely wet than its other sections
        (``suspected_wet_probability`` below ``wet_spot_probability``): a suspicion that lowers the chance."""
        if self.line is None or not any(s.wet_suspected for s in self.line.sections):
            return
        if self.suspected_wet_probability < self.wet_spot_probability:
            warnings.warn(f"suspected_wet_probability = {self.suspected_wet_probability:g} is below "
                          f"wet_spot_probability = {self.wet_spot_probability:g}: the line file's suspected wet "
                          f"zones are less likely wet than its other sections", UserWarning, stacklevel=3)

    def _take_line(self) -> None:
        """Read ``line`` (a path, a dict of a line's keys, or a description) and set the fields it owns."""
        line = line_description(self.line)
        if line is None:
            return
        object.__setattr__(self, "line", line)
        if self.sections_per_segment != 1:
            raise ValueError(f"sections_per_segment must be 1 with a line file (each of its sections is a segment of "
                             f"its own), got {self.sections_per_segment!r}")
        defaults = {f.name: f.default for f in fields(self)}
        for name, theirs in file_fields(line).items():
            value = getattr(self, name)
            if value != defaults[name]:  # a default: not given (from_dict also checks one given as the default)
                _check_file_field(name, value, line)
            object.__setattr__(self, name, theirs)
        if isinstance(self.capacity, int) and not isinstance(self.capacity, bool):
            object.__setattr__(self, "capacity", min(self.capacity, line.n_sections))

    # ------------------------------------------------------------------ derived
    @property
    def n_sleepers(self) -> int:
        """Sleepers per segment."""
        return int(round(self.segment_length_m / SLEEPER_SPACING_M)) + 1

    @property
    def n_segments(self) -> int:
        """Physics segments per line (``n_sections / sections_per_segment``)."""
        return self.n_sections // self.sections_per_segment

    @property
    def horizon_steps(self) -> int:
        return int(round(self.horizon_years * self.steps_per_year))

    def pass_length_m(self, span_m: float = 0.0) -> float:
        """How far the leading axle of a vehicle of axle span ``span_m`` [m] travels in a pass over a segment [m]
        at most: from the span to the end of the modelled track, the segment with :attr:`approach_sleepers`
        sleepers more at each end (a wheelset has no span; the fast engine's passes run less of it)."""
        return (self.n_sleepers - 1 + 2 * self.approach_sleepers) * SLEEPER_SPACING_M - span_m

    @property
    def approach_sleepers(self) -> int:
        """Sleepers of the approach (and of the exit) zone added to each end of a segment for its passes:
        :data:`APPROACH_SLEEPERS` with the classic engine; with the fast engine at least that, and as many as
        its steady start needs on a segment softened to :data:`SOFTEST_BALLAST_SHARE` of its ballast stiffness
        (the same for every segment, so that a batch's model tracks share their length)."""
        engine = ENGINES[self.engine]
        if engine.start != "steady":
            return APPROACH_SLEEPERS
        track = Track.realistic(self.segment_length_m)
        softest = track.replace(ballast_stiffness=track.ballast_stiffness * (self.ballast_stiffness_factor
                                                                             * SOFTEST_BALLAST_SHARE))
        return max(APPROACH_SLEEPERS, *(engine.approach_sleepers(softest, v) for v in self.vehicles()))

    def section_values(self, name: str) -> np.ndarray:
        """(n_sections,) the value of the line field ``name`` (one of :data:`PER_SECTION_BOUNDS`) on each
        section: its ``per_section`` values, or the line's everywhere."""
        if name not in PER_SECTION_BOUNDS:
            raise ValueError(f"name must be one of {list(PER_SECTION_BOUNDS)}, got {name!r}")
        given = dict(self.per_section).get(name)
        return np.array(given, dtype=float) if given is not None else np.full(self.n_sections, getattr(self, name))

    @property
    def length_factors(self) -> np.ndarray:
        """(n_sections,) each section's length over the line's ``section_length_m``: what its costs and work per
        metre are multiplied by (1 everywhere without per-section lengths)."""
        return self.section_values("section_length_m") / self.section_length_m

    @property
    def traffic_factors(self) -> np.ndarray:
        """(n_sections,) each section's annual tonnage over the line's: what its axle passes are multiplied by."""
        return self.section_values("annual_mgt") / self.annual_mgt

    @property
    def section_tamping_cost(self) -> float:
        """The tamping cost of a section of the line's ``section_length_m`` (k€)."""
        return self.tamping_cost_per_m * self.section_length_m

    @property
    def section_renewal_cost(self) -> float:
        return self.renewal_cost_per_m * self.section_length_m

    @property
    def choice_work(self) -> dict[str, float]:
        """The possession each choice takes, in tamping-section equivalents (what ``capacity`` counts): tamping
        a section 1, the other track work its ``*_work`` field, looking (inspect, survey) nothing."""
        return {"tamp": 1.0, "spot_tamp": self.spot_tamping_work, "drainage": self.drainage_work,
                "renew": self.renewal_work, "inspect": 0.0, "survey": 0.0}

    def vehicles(self) -> tuple[Wheelset, Wheelset]:
        """(passenger, freight) loaded wheelsets (static wheel load on the modelled rail)."""
        coach = Car.manchester_coach()
        passenger = Wheelset(mass=coach.wheelset_mass, static_load=coach.wheel_load - coach.wheelset_mass / 2 * GRAVITY)
        wheel = self.freight_axle_load_t * 1000.0 * GRAVITY / 2
        freight = Wheelset(mass=1400.0, static_load=wheel - 700.0 * GRAVITY)
        return passenger, freight

    def axle_passes_per_step(self, freight_share: float | None = None) -> np.ndarray:
        """(passenger, freight) axle passes per step of the line's tonnage, with the line's freight share or
        ``freight_share`` (a section's: :meth:`section_axle_passes`)."""
        p, f = self.vehicles()
        share_f = self.freight_share if freight_share is None else freight_share
        tonnes = self.annual_mgt * 1e6 / self.steps_per_year
        axle_t = np.array([p.wheel_load, f.wheel_load]) * 2 / GRAVITY / 1000.0
        share = np.array([1.0 - share_f, share_f])
        return tonnes * share / axle_t

    def section_axle_passes(self) -> np.ndarray:
        """(n_sections, 2) (passenger, freight) axle passes per step on each section: the line's tonnage with the
        section's freight share (:meth:`axle_passes_per_step`: the mix), times its :attr:`traffic_factors` (its
        own tonnage)."""
        shares = self.section_values("freight_share")
        return np.stack([self.axle_passes_per_step(share) for share in shares]) * self.traffic_factors[:, None]


def line_description(line: Any) -> LineDescription | None:
    """``line`` (the path of a line file, a dict of a line's keys, a description or None) as a description (None
    for None); ValueError for anything else."""
    from .line_file import LineDescription, load_line

    if line is None or isinstance(line, LineDescription):
        return line
    if isinstance(line, (str, os.PathLike)):
        return load_line(line)
    if isinstance(line, dict):
        return LineDescription.from_dict(line)
    raise ValueError(f"line must be the path of a line file, a LineDescription or a dict, got {type(line).__name__}")


def file_fields(line: Any) -> dict[str, Any]:
    """The fields of a config that the line file ``line`` (a description) sets, with its values: those of
    :data:`LINE_FILE_FIELDS`, the costs it gives (its ``costs`` mapping), its ``capacity`` where it gives one, and
    ``local_defect_near_m`` (:data:`KNOWN_DEFECT_NEAR_M`) and ``local_defect_in_zone``
    (:data:`KNOWN_DEFECT_IN_ZONE`) where it gives known short defects (a count in its ``defects`` column): a
    section's known defects then count once in its length, and one on a zone settles at the faster rate."""
    own: dict[str, Any] = {"capacity": line.capacity} if getattr(line, "capacity", None) is not None else {}
    if getattr(line, "defects_known", False):
        own["local_defect_near_m"] = KNOWN_DEFECT_NEAR_M
        own["local_defect_in_zone"] = KNOWN_DEFECT_IN_ZONE
    return {**{name: getattr(line, name) for name in LINE_FILE_FIELDS}, **dict(line.costs), **own}


def _check_file_field(name: str, value: Any, line: Any) -> None:
    """ValueError where ``value`` given for the field ``name`` differs from the line file's (``line``, a
    description), which sets it."""
    theirs = file_fields(line)[name]
    if (_items(value) if name == "per_section" else value) != theirs:  # per_section: in its stored form
        raise ValueError(f"{name}={value!r} conflicts with the line file {line.source}, which sets it to "
                         f"{theirs!r}: leave it out")


def _items(value: Any) -> Any:
    """``per_section`` as it is stored (sorted (name, tuple) items), for comparing a given value with a line
    file's; a value that is no mapping is returned as it is (its check refuses it)."""
    try:
        items = dict(value.items() if isinstance(value, dict) else value)
        return tuple(sorted((str(k), tuple(float(x) for x in v)) for k, v in items.items()))
    except (TypeError, ValueError):
        return value


#: The scenario suite (documented in the TampingLine docstring and on the documentation's environment pages).
SCENARIOS: dict[str, dict[str, Any]] = {
    "small": {"n_sections": 6, "capacity": 3},
    "default": {},
    "hard": {"n_sections": 24, "capacity": 4, "wet_spot_probability": 0.25, "transition_probability": 0.2,
             "switch_probability": 0.12, "annual_budget": 60.0},
    # 50 km: 250 sections of 200 m; a quarter's possessions cover 25 sections (5 km, e.g. a few nights at a
    # tamper's 0.5-2.2 km/h) [assumption]; otherwise the default line's distributions and economics
    "long": {"n_sections": 250, "capacity": 25},
    # the 60 m track (trackenv/Tamping-v1): one 60 m segment of six 10 m sections, one wheelset type (20 t
    # axles, 2 million axle passes a year), measured without error after every step, with the level and the
    # wheel/rail force per sleeper in the observation; its costs per 10 m section [assumption]: a 10 m site's
    # tamping (2 k€) is mostly the machine's set-up, not the line's per-metre price, and each class cost is
    # scaled so that the six short sections' costs stay comparable to the possession
    "track60": {"n_sections": 6, "section_length_m": 10.0, "segment_length_m": 60.0, "sections_per_segment": 6,
                "annual_mgt": 40.0, "freight_share": 1.0, "freight_axle_load_t": 20.0,
                "measurement_interval": 1, "sd_noise_mm": 0.0, "peak_noise_mm": 0.0, "rate_sigma": 0.0,
                "transition_probability": 0.3, "transition_stiffness_ratio": 2.0, "transition_rate_factor": 1.0,
                "switch_probability": 0.0, "wet_spot_probability": 0.0, "voided_sleepers_mean": 0.3,
                "initial_age_years": 2.0, "initial_max_tampings": 0, "initial_scale": (1.0, 1.0),
                "possession_cost": 10.0, "tamping_cost_per_m": 0.2, "alert_cost": 0.5,
                "speed_restriction_cost": 3.0, "capacity": 6, "profiles": True},
    # the default line with the full decision (trackenv/TampingLine-v1): every choice, and the contact sensor
    "choices": {"choices": INTERVENTIONS, "contact_sensor": True},
    # a wet, poorly drained line (trackenv/TampingLineWet-v0): a wet spot on ~35 % of the sections, 40 % of them
    # working from the start, half the sections surveyed before it [assumption]; the full decision
    "wet": {"choices": INTERVENTIONS, "contact_sensor": True, "wet_spot_probability": 0.35,
            "wet_spot_active_share": 0.4, "surveyed_share": 0.5},
    # a line of many short defects (trackenv/TampingLineDefects-v0): more switches and crossings, on average
    # one short defect per section (a joint, a weld, a failed sleeper: 2.4 m settling 5x faster than plain track,
    # a zone's rate kept where faster; the section's SD counts it once in its 200 m), and spot tamping alone in a
    # short possession at a fifth of a tamping possession's cost [assumption]; the full decision
    "defects": {"choices": INTERVENTIONS, "contact_sensor": True, "switch_probability": 0.2,
                "local_defects_mean": 1.0, "local_defect_rate_factor": 5.0, "local_defect_in_zone": "faster",
                "local_defect_near_m": KNOWN_DEFECT_NEAR_M, "spot_possession_share": 0.2},
}


def scenario(name: str, **overrides: Any) -> LineConfig:
    """The named scenario's config, with ``overrides`` (fields of :class:`LineConfig`: an unknown one is a
    ValueError naming the known ones, as the env's is, not Python's TypeError)."""
    if name not in SCENARIOS:
        raise ValueError(f"unknown scenario {name!r}; known: {sorted(SCENARIOS)}")
    return LineConfig.from_dict({**SCENARIOS[name], **overrides})
