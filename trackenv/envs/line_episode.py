"""The episode engine of every trackenv problem: the state and the rules of its episodes, batched over lines,
as plain arrays with a leading axis of physics *segments* (``n_lines × n_segments`` rows) or of decision
*sections* (``n_lines × n_sections``), so a step is array code and one batched pass per vehicle type.

A segment carries ``sections_per_segment`` sections: one on the line presets (each 200 m section is
represented by a 30 m segment of its own), several on the 60 m track (one 60 m segment of six 10 m sections,
so the sections share one pass and feel each other through the rail).

Everything random in an episode is drawn at its reset from the line's own generator (track, rates, register,
wet spots with their onset step, every tamping residual and every measurement error, indexed by step and
section): an episode is a deterministic function of its seed and its actions, so policies meet common random
numbers and a hindsight search can replay the future of any schedule.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from functools import partial
from typing import TYPE_CHECKING

import numpy as np
from gymnasium import spaces

from ..degradation import INFLUENCE_BAND, TrackDegradation
from ..physics.dynamics import simulate_pass_batches
from ..physics.engine import CLASSIC_ENGINE, ENGINES
from ..physics.geometry import (
    classify,
    d1_filter,
    german_psd,
    section_index,
    section_peak,
    section_sd,
    synthesize_profile,
)
from ..physics.settlement import implicit_settlement_step
from ..physics.tamping import restored_level
from ..physics.track import Track
from .choices import (
    CHOICES,
    COST_KEY,
    DRAINAGE,
    INSPECT,
    IS_TRACK_WORK,
    NOTHING,
    RENEW,
    SPOT_TAMP,
    SURVEY,
    TAMP,
    choice_counts,
    code,
    enabled_codes,
    step_possession,
    work_on_sections,
    work_per_code,
)
from .common import SHARED_BOUNDS, clip_observation, clipped_values
from .common import observation_space as common_observation_space
from .costs import section_quality_costs
from .info import step_info
from .line_config import REGISTER_CLASSES, SLEEPER_SPACING_M, LineConfig

if TYPE_CHECKING:  # line_fit builds its fit on this module's engine: each imports the other where used
    from .line_fit import LineOverrides

COST_KEYS = LineConfig.cost_keys()
#: The largest wheel/rail force the model is taken to represent, in static wheel loads: impact forces at dipped
#: joints and crossings reach about 2-3 times the static load in the field; the engine's lines stay below 1.3
#: even at 130 mm of mean-to-peak without maintenance [assumption: a validity guard, not a design limit].
VALID_CONTACT_FACTOR = 3.0
#: The largest D1 mean-to-peak [m] the settlement law is taken to represent: about ten times the default line's
#: immediate-action limit (26 mm), beyond any track in service; the shipped lines reach about 140 mm when never
#: maintained [assumption: a validity guard].
VALID_PEAK_M = 0.25


def _correlated_normal(rng: np.random.Generator, shape: tuple[int, ...], corr: float) -> np.ndarray:
    """Standard normal fields along the last axis, Gaussian-correlated over ``corr`` samples, unit SD."""
    n = shape[-1]
    pad = int(3 * corr) + 2
    z = rng.standard_normal(shape[:-1] + (n + 2 * pad,))
    if corr > 0:
        from scipy.ndimage import gaussian_filter1d  # here, not at import: ~0.15 s of `import trackenv`

        z = gaussian_filter1d(z, corr, axis=-1, mode="wrap")
    z = z[..., pad : pad + n]
    return (z - z.mean(axis=-1, keepdims=True)) / (z.std(axis=-1, keepdims=True) + 1e-12)


def _lognormal(z: np.ndarray, cv: float) -> np.ndarray:
    sigma = np.sqrt(np.log1p(cv * cv))
    return np.exp(sigma * z - sigma * sigma / 2)


#: The arrays of :class:`LineBatch` with a leading axis of segments, and those indexed (step, segment).
_SEGMENT_FIELDS = ("influence", "offset", "u", "cyc", "base_rate", "wet_onset", "wet_mask", "wet_active",
                   "measured_level", "contact_profile", "d1", "traffic_factor", "pass_speed", "axle_mix",
                   "defect_near", "computed_level", "computed_force", "computed_contact", "computed_bays")
_SEGMENT_NOISE = ("tamp_noise",)
#: The arrays with a leading axis of sections, and those indexed (step, section).
_SECTION_FIELDS = ("count", "tampings", "register", "last_tamped", "measured_sd", "measured_peak", "contact_force",
                   "sd", "peak", "sd_after_tamping", "last_work", "measured_at", "survey", "length_factor",
                   "static_wheel_load", "band")
_SECTION_NOISE = ("meas_noise", "sensor_noise", "inspect_noise")


@dataclass(frozen=True, eq=False)
class LineState:
    """One line's episode, copied out of a :class:`LineBatch` (:meth:`LineBatch.get_state`): its segments' and
    sections' arrays (``rows``: name -> (segments or sections, ...); ``noise``: name -> (H + 1, ...), the
    pre-drawn residuals and measurement errors), its segments' model tracks (shared: immutable), and the line's
    step, last recording run and remaining annual budget."""

    rows: dict[str, np.ndarray]
    noise: dict[str, np.ndarray]
    model_tracks: tuple
    step: int
    last_measured: int
    budget_left: float


def file_run_age_years(config: LineConfig) -> float:
    """How long before ``as_of`` the oldest of the line file's last runs that the first observation shows was
    [years] (:func:`~trackenv.envs.line_fit.last_runs`; 0 without a file or without such a run): the measurement
    ages reach that far beyond the horizon's."""
    if config.line is None:
        return 0.0
    from .line_fit import last_runs

    ages = last_runs(config.line)["last_run_age_years"]
    return float(np.max(ages[~np.isnan(ages)], initial=0.0))


def line_observation_bounds(config: LineConfig) -> dict[str, tuple[float, float]]:
    """Bounds of each key of TampingLine's observation (its space is built from these and the observation is
    clipped to them, so the two cannot drift apart); ``level`` and ``contact_force`` only with ``profiles``."""
    shared = SHARED_BOUNDS
    bounds = {
        "section_sd": shared["section_sd"],
        "section_peak": shared["section_peak"],
        "measurement_age": (0.0, config.horizon_years + 1.0 + file_run_age_years(config)),
        "register": (0.0, float(len(REGISTER_CLASSES) - 1)),
        "tampings": shared["tampings"],
        "tampings_since_renewal": shared["tampings"],
        "years_since_tamping": (0.0, 100.0),
        "time": shared["time"],
        "budget_left": (0.0, 1.0),
    }
    if config.profiles:
        bounds["level"] = shared["level"]
        bounds["contact_force"] = shared["contact_force"]
    if config.contact_sensor:
        bounds["section_contact_peak"] = shared["contact_force"]
        bounds["section_dynamic_share"] = (-1.0, 20.0)
    if "inspect" in config.choices:
        bounds["section_measurement_age"] = (0.0, config.horizon_years + 1.0 + file_run_age_years(config))
    if "survey" in config.choices:
        bounds["section_survey"] = (-1.0, 1.0)
    return bounds


def line_observation_space(config: LineConfig) -> spaces.Dict:
    """The Dict space of TampingLine's observation table (its bounds: :func:`line_observation_bounds`)."""
    bounds = line_observation_bounds(config)
    profile = (config.n_segments, config.n_sleepers)
    per_line = {"measurement_age": (1,), "time": (1,), "budget_left": (1,), "level": profile,
                "contact_force": profile}
    return common_observation_space(bounds, {key: per_line.get(key, (config.n_sections,)) for key in bounds})


class LineBatch:
    """``n_lines`` episodes of one config, stacked: segment row ``b·R + i`` is segment i of line b (R =
    ``n_segments``), section row ``b·S + j`` section j (S = ``n_sections``); segment i carries sections
    ``i·K .. i·K + K − 1`` (K = ``sections_per_segment``; on the line presets K = 1 and the two coincide).
    Per-line resets (:meth:`start`) leave the other lines untouched.

    **The engine's public API** (what envs, searches and planning code may call; everything else is internal):

    * lines: :meth:`start` (new episodes), :meth:`advance` (one step of the env), :meth:`observation`,
      :meth:`reset_info`, :meth:`allowed`, :meth:`step_count`, :meth:`get_state` / :meth:`set_state` (a line's
      episode, exactly);
    * sections: :meth:`allowed_rows`, :meth:`choice_costs`, :meth:`tamp_rows`,
      :meth:`work_rows` (any choice), :meth:`traffic_rows`, :meth:`measure_rows`, :meth:`section_costs`,
      :meth:`section_entries` (what a planner sees of a section), :meth:`true_quality`, :meth:`wet_present`,
      :meth:`wet_working_rows`; the other choices (:mod:`~trackenv.envs.choices`): :meth:`choice_mask`,
      :meth:`code_costs`, :meth:`spot_tamp_rows`, :meth:`drain_rows`, :meth:`survey_rows`, :meth:`inspect_rows`;
      and, where every segment carries one section (so that sections evolve independently of each other but for
      the line's possession), :meth:`copy_rows` to fork single sections in a search;
    * read-only: ``config``, ``n_lines``, ``limits`` (the quality limits of the line's speed band; a section's
      own, of its speed band: :meth:`section_limits`, :meth:`classify_rows`), ``step`` (per line), ``register``
      (per section).

    Rows of other lines and the arrays behind them are the engine's; code outside this module reads the state
    through the methods above."""

    def __init__(self, config: LineConfig, n_lines: int) -> None:
        self.config = c = config
        self.bounds = line_observation_bounds(c)
        self.n_lines = int(n_lines)
        S, R, K, n, H = c.n_sections, c.n_segments, c.sections_per_segment, c.n_sleepers, c.horizon_steps
        G, GR = self.n_lines * S, self.n_lines * R
        self.K = K
        self.section_of_sleeper = section_index(n, K)  # (n,) section (within its segment) of each sleeper
        self.law = c.settlement_law
        self.tm = c.tamping_model
        self.limits = c.quality_limits.for_speed(c.speed)
        #: per action code: enabled by the config, track work, possession work (tamping-section equivalents)
        self.enabled = enabled_codes(c.choices)
        self.is_work = IS_TRACK_WORK
        self.work = work_per_code(c.choice_work)
        #: the price of each choice that costs the same on every section (k€; tamp and renew depend on the count)
        self.fixed_price = {"spot_tamp": c.spot_tamping_cost, "drainage": c.drainage_cost,
                            "inspect": c.inspection_cost, "survey": c.survey_cost}
        #: sleepers either side of the worst one that a spot tamping lifts
        self.spot_half = max(int(round(c.spot_tamping_length_m / SLEEPER_SPACING_M / 2)), 1)
        self.vehicles = c.vehicles()
        self.p_exp = float(dict(c.law_params).get("force_exponent", 1.0))
        self.model_tracks: list[Track | None] = [None] * GR
        #: how the passes run (``config.engine``), and the sleepers of approach and exit around each segment
        self.engine = ENGINES[c.engine]
        self.n_extra = c.approach_sleepers
        # per segment
        self.influence = np.zeros((GR, n, n))
        self.offset = np.zeros((GR, n))
        self.u = np.zeros((GR, n))
        self.cyc = np.zeros((GR, n))
        self.base_rate = np.ones((GR, n))
        self.wet_onset = np.full(GR, -1, dtype=np.int64)
        self.wet_mask = np.zeros((GR, n), dtype=bool)
        self.wet_active = np.zeros(GR, dtype=bool)
        #: the sleepers within ``local_defect_near_m`` of a local defect (used only where that field is set)
        self.defect_near = np.zeros((GR, n), dtype=bool)
        self.measured_level = np.zeros((GR, n))
        self.contact_profile = np.zeros((GR, n))  # largest wheel/rail force over each sleeper bay [N]
        self.d1 = np.zeros((GR, n))
        self.tamp_noise = np.zeros((H + 1, GR, n))
        #: each segment's last computed pass (``pass_reuse_tolerance_m``): its level (NaN: none to reuse), its
        #: sleeper forces per vehicle type [N], largest contact force [N] and contact force per sleeper bay [N]
        self.computed_level = np.full((GR, n), np.nan)
        self.computed_force = np.zeros((GR, len(self.vehicles), n))
        self.computed_contact = np.zeros(GR)
        self.computed_bays = np.zeros((GR, n))
        self._section_traffic(c, S, R)
        # per section
        self.count = np.zeros(G, dtype=np.int64)  # tampings since renewal
        self.tampings = np.zeros(G, dtype=np.int64)  # tampings this episode
        self.register = np.zeros(G, dtype=np.int64)
        self.last_tamped = np.zeros(G)  # step of the last tamping (negative: before the episode)
        self.measured_sd = np.zeros(G)
        self.measured_peak = np.zeros(G)
        self.contact_force = np.zeros(G)
        self._validity_warned = False  # :meth:`_check_validity` warns once per batch
        self.sd = np.zeros(G)
        self.peak = np.zeros(G)
        self.sd_after_tamping = np.zeros(G)  # true SD right after this step's tamping [m] (0: not tamped)
        self.last_work = np.zeros(G)  # step of the last track work (tamping, spot tamping, drainage, renewal)
        self.measured_at = np.zeros(G, dtype=np.int64)  # step of the last measurement (recording car or trolley)
        self.survey = np.full(G, -1, dtype=np.int64)  # what a survey found: -1 none yet, 0 no wet cause, 1 one
        self.meas_noise = np.zeros((H + 1, G, 2))
        self.sensor_noise = np.zeros((H + 1, G))  # the contact sensor's errors (``contact_sensor``), per step
        self.inspect_noise = np.zeros((H + 1, G, 2))  # the trolley's errors (SD, peak), per step (``inspect``)
        # per line
        self.step = np.zeros(self.n_lines, dtype=np.int64)
        self.last_measured = np.zeros(self.n_lines, dtype=np.int64)
        self.budget_left = np.zeros(self.n_lines)

    def _section_traffic(self, c: LineConfig, S: int, R: int) -> None:
        """What a section's own length, speed and traffic (``per_section``; the line's where not given) set, per
        segment and per section row: its speed [m/s], the mix of its axle passes (passenger, freight per step at
        the line's tonnage and its freight share) and the factor of its tonnage on them, its length over the
        line's, the largest static wheel load of its traffic and its speed band's limits. A segment of several
        sections has the line's (``per_section`` needs one section per segment)."""
        K, n_lines = self.K, self.n_lines
        per_segment = {name: c.section_values(name).reshape(R, K)[:, 0] for name in ("speed_kmh", "freight_share")}
        #: per segment: the speed of its passes [m/s], the (passenger, freight) axle passes per step of its mix at
        #: the line's tonnage, and the factor of its tonnage on them
        self.pass_speed = np.tile(per_segment["speed_kmh"] / 3.6, n_lines)
        mix = np.stack([c.axle_passes_per_step(share) for share in per_segment["freight_share"]])
        self.axle_mix = np.tile(mix, (n_lines, 1))
        self.traffic_factor = np.tile(c.traffic_factors.reshape(R, K)[:, 0], n_lines)
        #: per section: its length over the line's section length (its costs and work per metre scale with it)
        self.length_factor = np.tile(c.length_factors, n_lines)
        #: per section: the largest static wheel load of its traffic [N] (the contact sensor's dynamic share is
        #: above it)
        loads = np.array([v.wheel_load for v in self.vehicles])
        static = np.where(self.axle_mix > 0, loads, -np.inf).max(axis=1)
        self.static_wheel_load = np.repeat(static, K)
        #: the quality limits of the sections' speed bands, and each section's band (an index into them)
        speeds, of_speed = np.unique(np.tile(c.section_values("speed_kmh"), n_lines) / 3.6, return_inverse=True)
        limits = [c.quality_limits.for_speed(v) for v in speeds]
        self.bands = tuple(dict.fromkeys(limits))
        self.band = np.array([self.bands.index(b) for b in limits])[of_speed]

    # ------------------------------------------------------------------ helpers
    @property
    def S(self) -> int:
        return self.config.n_sections

    @property
    def R(self) -> int:
        return self.config.n_segments

    def rows(self, line: int) -> slice:
        """The section rows of line ``line``."""
        return slice(line * self.S, (line + 1) * self.S)

    def segments(self, line: int) -> slice:
        """The segment rows of line ``line``."""
        return slice(line * self.R, (line + 1) * self.R)

    @property
    def level(self) -> np.ndarray:
        return self.offset + self.u

    def _on_sleepers(self, per_section: np.ndarray) -> np.ndarray:
        """A per-section array (sections,) spread over the sleepers of their segments: (segments, n)."""
        return per_section.reshape(-1, self.K)[:, self.section_of_sleeper]

    def _segments_of(self, sections: np.ndarray) -> np.ndarray:
        """(segments,) bool: the segments that carry any of the sections ``sections`` (sections,) bool."""
        return np.asarray(sections.reshape(-1, self.K).any(axis=1))

    def _sections_of(self, segs: np.ndarray) -> np.ndarray:
        """The section rows (indices) of the segment rows ``segs`` (indices)."""
        return (np.asarray(segs)[:, None] * self.K + np.arange(self.K)).ravel()

    def _per_section(self, values: np.ndarray, reduce: str) -> np.ndarray:
        """Per-sleeper ``values`` (segments, n) reduced ("max" or "mean") over each section's sleepers:
        (segments · K,)."""
        if self.K == 1:
            return values.max(axis=1) if reduce == "max" else values.mean(axis=1)
        parts = [values[:, self.section_of_sleeper == k] for k in range(self.K)]
        out = [p.max(axis=1) if reduce == "max" else p.mean(axis=1) for p in parts]
        return np.stack(out, axis=1).ravel()

    def section_limits(self, name: str) -> np.ndarray:
        """(sections,) each section's limit ``name`` (a field of
        :class:`~trackenv.physics.geometry.BandLimits`: ``alert_m``, ``intervention_m``, ``immediate_action_m``,
        ``sd_alert_m``) in its speed band [m]."""
        return np.array([getattr(b, name) for b in self.bands])[self.band]

    def classify_rows(self, peak: np.ndarray, rows=slice(None)) -> np.ndarray:
        """The quality class of the sections ``rows`` (a slice or indices) whose D1 mean-to-peak is ``peak`` [m],
        each against the limits of its speed band (:func:`~trackenv.physics.geometry.classify`)."""
        if len(self.bands) == 1:
            return classify(peak, self.bands[0])
        band = self.band[rows]
        out = np.zeros(np.shape(peak), dtype=np.int64)
        for i, limits in enumerate(self.bands):
            out[band == i] = classify(np.asarray(peak)[band == i], limits)
        return out

    def _work(self, codes: np.ndarray) -> np.ndarray:
        """The possession work of the choices ``codes`` (sections, or (n_lines, S)) on their sections, in
        tamping-section equivalents (:func:`~trackenv.envs.choices.work_on_sections`: a tamping's and a
        renewal's scale with the section's length)."""
        return work_on_sections(self.work, codes, self.length_factor.reshape(np.shape(codes)))

    def rate(self) -> np.ndarray:
        """Current settlement-rate factor per sleeper (segments, n): base (section, zone, wet spot) × ballast
        damage of its section's tampings since renewal."""
        return self.base_rate * (1.0 + self.tm.damage_per_tamping) ** self._on_sleepers(self.count)

    def _quality(self, segs: np.ndarray) -> None:
        """The true D1 level of the segments ``segs`` (indices) and the SD and mean-to-peak of their sections."""
        self.d1[segs] = d1_filter(self.level[segs], SLEEPER_SPACING_M)
        d1 = self.d1[segs]
        secs = self._sections_of(segs)
        if self.K == 1:
            self.sd[secs] = self._segment_sd(d1, segs)
            self.peak[secs] = np.abs(d1).max(axis=1)
        else:
            self.sd[secs] = section_sd(d1, self.section_of_sleeper, self.K).ravel()
            self.peak[secs] = section_peak(d1, self.section_of_sleeper, self.K).ravel()

    def _measure(self, lines: np.ndarray) -> None:
        """A recording-car run on ``lines`` (bool over lines), with the pre-drawn errors of this step."""
        seg = np.repeat(lines, self.S)
        self.measure_rows(seg, np.repeat(self.step, self.S))
        self.last_measured = np.where(lines, self.step, self.last_measured)

    def measure_rows(self, seg: np.ndarray, seg_step: np.ndarray | int) -> None:
        """A measurement of the sections ``seg`` (sections,) bool at their step ``seg_step`` (per section or one),
        with the pre-drawn errors of that step: the measured SD and mean-to-peak, and the level of their
        segments, and their measurement dated ``seg_step``. No calendar: :meth:`_measure` is the line-level run; a
        per-section fork is measured through this directly."""
        c = self.config
        step = np.broadcast_to(np.asarray(seg_step), seg.shape)
        self._read(seg, step, self.meas_noise, c.sd_noise_mm, c.peak_noise_mm)
        self.measured_at = np.where(seg, step, self.measured_at)
        segs = self._segments_of(seg)
        self.measured_level[segs] = self.level[segs]

    def _read(self, rows: np.ndarray, step: np.ndarray, noise: np.ndarray, sd_noise_mm: float,
              peak_noise_mm: float) -> None:
        """The measured SD and mean-to-peak of the sections ``rows`` (sections,) bool: the truth plus the pre-drawn
        errors ``noise`` (steps + 1, sections, 2) of each section's ``step``, scaled by the instrument's error [mm]
        (the recording car's or the trolley's), never below 0."""
        e = noise[np.minimum(step, self.config.horizon_steps), np.arange(rows.size)]
        sd = np.maximum(self.sd + sd_noise_mm * 1e-3 * e[:, 0], 0.0)
        pk = np.maximum(self.peak + peak_noise_mm * 1e-3 * e[:, 1], 0.0)
        self.measured_sd = np.where(rows, sd, self.measured_sd)
        self.measured_peak = np.where(rows, pk, self.measured_peak)

    # ------------------------------------------------------------------ reset
    def start(self, lines: list[int], rngs: list[np.random.Generator]) -> None:
        """Draw new episodes for ``lines`` from their generators and run their traffic-free first pass."""
        for b in lines:
            self._draw(b, rngs[b])
        segs = np.concatenate([np.arange(self.segments(b).start, self.segments(b).stop) for b in lines])
        self.computed_level[segs] = np.nan  # new model tracks: nothing to reuse
        self._quality(segs)
        mask = np.zeros(self.n_lines, dtype=bool)
        mask[lines] = True
        self._measure(mask)
        for b in lines:
            self._file_readings(b)
        _, contact, bays = self._passes(segs)
        self._contact(segs, contact, bays)

    def _draw(self, b: int, rng: np.random.Generator) -> None:
        c = self.config
        S, R, n, H = c.n_sections, c.n_segments, c.n_sleepers, c.horizon_steps
        r, rs = self.rows(b), self.segments(b)
        # section rate factors: lognormal, AR(1) along the line
        rho = self._rate_correlation()
        e = rng.standard_normal(S)
        z = np.empty(S)
        z[0] = e[0]
        for j in range(1, S):  # the AR(1) recursion (drawn once per episode, at reset)
            z[j] = rho[j] * z[j - 1] + np.sqrt(1 - rho[j] * rho[j]) * e[j]
        section_rate = np.exp(c.rate_sigma * z - c.rate_sigma**2 / 2)
        # register (per segment): transition zones and switches/crossings, in the middle of the segment
        u = rng.random(R)
        p_t, p_s = c.transition_probability, c.switch_probability
        reg = np.where(u < p_t, 1, np.where(u < p_t + p_s, 2, 0))
        sleeper_rate = _lognormal(_correlated_normal(rng, (R, n), c.sleeper_rate_correlation_m / SLEEPER_SPACING_M),
                                  c.sleeper_rate_cv)
        kfield = c.ballast_stiffness_factor * _lognormal(_correlated_normal(rng, (R, n), 2.0), c.ballast_stiffness_cv)
        rate = c.rate_scale * section_rate.reshape(R, self.K)[:, self.section_of_sleeper] * sleeper_rate
        plain_rate = rate.copy()
        mid = n // 2
        soft = np.arange(n) < mid
        rate[reg == 1] *= np.where(soft, c.transition_rate_factor, 1.0)
        kfield[reg == 1] *= np.where(soft, 1.0, c.transition_stiffness_ratio)
        patch = np.abs(np.arange(n) - mid) <= 2  # a stiff 3 m patch (crossing nose, level-crossing slab)
        rate[reg == 2] *= c.switch_rate_factor
        kfield[reg == 2] *= np.where(patch, 2.0, 1.0)
        # hidden wet spots (likelier on a line file's suspected wet zones: the same uniform draw)
        wet = rng.random(R) < self._wet_spot_probability()
        onset = rng.integers(1, max(H, 2), size=R)
        wl = max(int(round(c.wet_spot_length_m / SLEEPER_SPACING_M)), 1)
        start = rng.integers(0, n - wl + 1, size=R)
        wmask = (np.arange(n)[None, :] >= start[:, None]) & (np.arange(n)[None, :] < (start + wl)[:, None])
        # initial state: level from the PSD, scaled; age and tampings since renewal
        scale = rng.uniform(c.initial_scale[0], c.initial_scale[1], size=R)
        base = Track.realistic(c.segment_length_m)
        x = base.sleeper_positions
        level = np.stack([synthesize_profile(x, partial(german_psd, quality="low"), rng) for _ in range(R)])
        level *= scale[:, None]
        age = rng.uniform(0.0, c.initial_age_years, size=R)
        count = rng.integers(0, c.initial_max_tampings + 1, size=R)
        self.tamp_noise[:, rs] = rng.standard_normal((H + 1, R, n))
        self.meas_noise[:, r] = rng.standard_normal((H + 1, S, 2))
        voided = self._voided_sleepers(rng, R, n)  # drawn last: configs without voids draw as before
        if c.contact_sensor:  # after that: configs without the sensor draw as before
            self.sensor_noise[:, r] = rng.standard_normal((H + 1, S))
        # then what only the configs with these fields draw (the others draw as before)
        if "inspect" in c.choices:
            self.inspect_noise[:, r] = rng.standard_normal((H + 1, S, 2))
        if c.wet_spot_active_share > 0:  # wet spots already working: they start in the first step
            onset = np.where(rng.random(R) < c.wet_spot_active_share, 0, onset)
        patches = self._local_defects(rng, rate, plain_rate)
        self.defect_near[rs] = self._near_defects(patches)
        surveyed = rng.random(S) < c.surveyed_share if c.surveyed_share > 0 else np.zeros(S, dtype=bool)
        self.sd_after_tamping[r] = 0.0
        # a segment's zone belongs to the sections over its middle (all of it where a segment is one section)
        zone = np.zeros(self.K, dtype=np.int64)
        zone[np.unique(self.section_of_sleeper[[max(mid - 1, 0), mid]])] = 1
        self.base_rate[rs] = rate
        self.register[r] = (reg[:, None] * zone).ravel()
        self.wet_onset[rs] = np.where(wet, onset, -1)
        self.wet_mask[rs] = wmask
        self.wet_active[rs] = False
        self.offset[rs] = level
        self.u[rs] = 0.0
        self.cyc[rs] = 0.0
        self.count[r] = np.repeat(count, self.K)
        self.tampings[r] = 0
        self.last_tamped[r] = np.repeat(-np.round(age * c.steps_per_year), self.K)
        self.step[b] = 0
        self.budget_left[b] = c.annual_budget
        p_vehicle = self.vehicles[0]
        for j in range(R):  # per-segment track statics, once per episode
            track = base.replace(ballast_stiffness=base.ballast_stiffness * kfield[j])
            for i in voided[j]:
                track = track.with_voided_sleeper(int(i), residual_support=c.voided_residual_support)
            sim = TrackDegradation(track, p_vehicle, law=self.law, feedback="support",
                                   approach_sleepers=self.n_extra, dt=c.dt)
            self.model_tracks[rs.start + j] = sim.model_track
            self.influence[rs.start + j] = sim.support_influence
        # the settlement since the last tamping: advance the fresh state over its age at the mean load
        self._settled_since(rs, age)
        self._apply_line_file(b, patches)
        self.last_work[r] = self.last_tamped[r]
        self.survey[r] = np.where(surveyed | self._known_wet(), self.wet_present()[r], -1)

    def _rate_correlation(self) -> np.ndarray:
        """(S,) the AR(1) correlation of each section's rate factor with the one before it: exp(−d / L) over the
        distance d between their centres (the line's section length where the sections have one length), L =
        ``rate_correlation_m`` (0: none); the first section's is unused."""
        c = self.config
        if c.rate_correlation_m <= 0:
            return np.zeros(c.n_sections)
        if "section_length_m" not in dict(c.per_section):
            return np.full(c.n_sections, np.exp(-c.section_length_m / c.rate_correlation_m))
        lengths = c.section_values("section_length_m")
        gaps = np.concatenate([[0.0], (lengths[1:] + lengths[:-1]) / 2])
        return np.exp(-gaps / c.rate_correlation_m)

    def _settled_since(self, rs: slice, years: np.ndarray) -> None:
        """The segments ``rs`` (one line's) settled from a fresh tamping over ``years`` (per segment) of their
        traffic at the static equivalent load (Winkler: 0.45 of each wheel load on the sleeper below it)."""
        n = self.config.n_sleepers
        cycles = years * self.config.steps_per_year * self.axle_mix[rs].sum(axis=1) * self.traffic_factor[rs]
        loads = 0.45 * np.array([v.wheel_load for v in self.vehicles])
        f0 = self._equivalent(np.broadcast_to(loads[:, None], (2, cycles.size)), self.axle_mix[rs])
        cyc = np.broadcast_to(cycles[:, None], (cycles.size, n))
        self.u[rs] = self.rate()[rs] * self.law.settlement(f0[:, None], cyc)
        self.cyc[rs] = cyc

    def _local_defects(self, rng: np.random.Generator, rate: np.ndarray, plain_rate: np.ndarray) -> np.ndarray:
        """Short local defects (joints, welds, crossing noses, a failed sleeper: a Poisson number per segment, mean
        ``local_defects_mean``; a line file's known count in place of the draw on its sections that give one,
        :meth:`_known_defects`, spread along the segment: each at a drawn position in its own k-th of it), each a
        ``local_defect_length_m`` patch at a drawn position settling
        ``local_defect_rate_factor`` times faster, into ``rate`` (segments, n, with the zones' factors) in place:
        multiplied, or, with ``local_defect_in_zone = "faster"``, the factor times ``plain_rate`` (the rate without
        the zones) where that is faster than ``rate``. The Poisson counts are drawn as without known ones (none
        when the mean is 0), then the known ones replace theirs, so a config or file without known counts draws as
        before; nothing is drawn without either. Returns the sleepers of the patches (segments, n) bool."""
        c = self.config
        patches = np.zeros(rate.shape, dtype=bool)
        known = self._known_defects()
        if c.local_defects_mean == 0 and not (known >= 0).any():
            return patches
        n = rate.shape[1]
        length = max(int(round(c.local_defect_length_m / SLEEPER_SPACING_M)), 1)
        drawn = (np.asarray(rng.poisson(c.local_defects_mean, size=rate.shape[0])) if c.local_defects_mean > 0
                 else np.zeros(rate.shape[0], dtype=np.int64))
        counts = np.where(known >= 0, known, drawn)
        for j in range(rate.shape[0]):
            k = int(counts[j])
            if known[j] > 0:  # known ones lie apart, as in their section: each in its own k-th of the segment
                starts = (np.arange(k) * n) // k + rng.integers(0, max(n // k - length, 0) + 1, size=k)
            else:
                starts = rng.integers(0, n - length + 1, size=k)
            for start in starts:
                patches[j, start : start + length] = True
                if c.local_defect_in_zone == "multiply":
                    rate[j, start : start + length] *= c.local_defect_rate_factor
        if c.local_defect_in_zone == "faster":
            rate[patches] = np.maximum(rate[patches], c.local_defect_rate_factor * plain_rate[patches])
        return patches

    def _near_defects(self, patches: np.ndarray) -> np.ndarray:
        """(segments, n) bool: the sleepers within ``local_defect_near_m`` of a sleeper of the local defects'
        ``patches`` (segments, n) bool; none where the field is 0 (off)."""
        reach = int(round(self.config.local_defect_near_m / SLEEPER_SPACING_M))
        if self.config.local_defect_near_m == 0 or not patches.any():
            return np.zeros(patches.shape, dtype=bool)
        near = patches.copy()
        for shift in range(1, reach + 1):
            near[:, shift:] |= patches[:, :-shift]
            near[:, :-shift] |= patches[:, shift:]
        return near

    def _segment_sd(self, d1: np.ndarray, segs: np.ndarray) -> np.ndarray:
        """(segs,) the SD of the sections represented by the segments ``segs`` (indices; one section each) whose
        D1 level is ``d1`` (segs, n): the segment's own; with ``local_defect_near_m``, the section of its own
        length with the segment's local defects once: the squared deviations from the segment's mean, averaged
        over the defects' neighbourhoods (:attr:`defect_near`, length w) and over the rest of the segment, and
        weighted w : (L − w) over the section's length L (a segment without a defect: its own SD)."""
        c = self.config
        if c.local_defect_near_m == 0:
            return d1.std(axis=1)
        near = self.defect_near[segs]
        dev2 = (d1 - d1.mean(axis=1, keepdims=True)) ** 2
        n_near = near.sum(axis=1)
        n_far = near.shape[1] - n_near
        var_near = (dev2 * near).sum(axis=1) / np.maximum(n_near, 1)
        var_far = np.where(n_far > 0, (dev2 * ~near).sum(axis=1) / np.maximum(n_far, 1), var_near)
        length = c.section_length_m * self.length_factor[self._sections_of(segs)]
        w = np.minimum(n_near * SLEEPER_SPACING_M, length)
        return np.sqrt((w * var_near + (length - w) * var_far) / length)

    def _voided_sleepers(self, rng: np.random.Generator, R: int, n: int) -> list[np.ndarray]:
        """Per segment, the sleepers that hang (a Poisson number, mean ``voided_sleepers_mean``, never the two at
        either end); nothing is drawn when the mean is 0."""
        mean = self.config.voided_sleepers_mean
        if mean == 0:
            return [np.zeros(0, dtype=np.int64)] * R
        return [rng.integers(2, n - 2, size=int(rng.poisson(mean))) for _ in range(R)]

    def _file(self) -> LineOverrides | None:
        """What the config's line file sets over the draws (:func:`~trackenv.envs.line_fit.line_overrides`, cached
        per config; its config has one section per segment), or None without a file."""
        if self.config.line is None:
            return None
        from .line_fit import line_overrides

        return line_overrides(self.config)

    def _known_defects(self) -> np.ndarray:
        """(segments of a line,) the number of known short local defects on each, from the config's line file;
        −1 where not known (drawn), everywhere without a file."""
        o = self._file()
        return np.full(self.R, -1, dtype=np.int64) if o is None else o.defects

    def _wet_spot_probability(self) -> float | np.ndarray:
        """The probability of a hidden wet spot: ``wet_spot_probability``, or per segment
        ``suspected_wet_probability`` on the line file's suspected wet zones."""
        c, o = self.config, self._file()
        return c.wet_spot_probability if o is None else np.where(o.wet_suspected, c.suspected_wet_probability,
                                                                 c.wet_spot_probability)

    def _known_wet(self) -> np.ndarray:
        """(S,) the sections whose wet zone the config's line file knows: their survey is known from the start
        (a survey would find it), so a policy reads it as surveyed, not as a section to survey."""
        o = self._file()
        return np.zeros(self.S, dtype=bool) if o is None else o.wet

    def _apply_line_file(self, b: int, patches: np.ndarray) -> None:
        """Line ``b``'s draws overridden by what the config's line file knows (nothing without one), in place of
        the drawn values (:func:`~trackenv.envs.line_fit.line_overrides`): the register, with its zones' rate
        and stiffness (the statics rebuilt where they change; on the sleepers of the local defects' ``patches``
        (segments, n) bool, with ``local_defect_in_zone = "faster"``, the faster of the defect's and the file's
        zone's rate, as the draw does against a drawn zone); known wet zones (the drawn patch, wet from the
        start instead of hidden); tampings since renewal and years since tamping with the settlement since (as
        above, at the section's own traffic); the rate factor the file gives, or a draw from its posterior given
        the history (:func:`~trackenv.envs.line_fit.rate_multipliers`), in place of the drawn one; and the SD the
        history gives at the start (the drawn shape and settlement scaled to it:
        :func:`~trackenv.envs.line_fit.start_levels`); every SD there is the section's as the engine measures
        it (with ``local_defect_near_m``, its drawn local defects once in its length:
        :func:`~trackenv.envs.line_fit.sd_weights`).
        Everything is drawn first, as without a file, so the draws and their order do not change."""
        c, o = self.config, self._file()
        if o is None:
            return
        from .line_fit import drawn_section_factor, rate_multipliers, sd_weights, start_levels, zone_factors

        # a line file's config has one section per segment (LineConfig refuses more): section j is segment j
        r, rs, n = self.rows(b), self.segments(b), c.n_sleepers
        # the SD of a section as measured (its local defects once in its length; None: the segment's own SD)
        weights = sd_weights(self.defect_near[rs], c.section_length_m * self.length_factor[r], c)
        old_rate, old_k = zone_factors(self.register[r], n, c)
        new_rate, new_k = zone_factors(o.register, n, c)
        drawn = drawn_section_factor(self.base_rate[rs] / old_rate, c)
        rate = self.base_rate[rs] / old_rate * new_rate
        if c.local_defect_in_zone == "faster" and patches.any():  # a short defect against the file's zone
            f = c.local_defect_rate_factor  # (drawn as max(drawn zone, f) × plain; multiplied ones swap as above)
            rate = np.where(patches, self.base_rate[rs] / np.maximum(old_rate, f) * np.maximum(new_rate, f), rate)
        rate[o.wet] *= np.where(self.wet_mask[rs][o.wet], c.wet_spot_rate_factor, 1.0)
        self.base_rate[rs] = rate * rate_multipliers(o, drawn, rate, c, weights)[:, None]
        self.wet_onset[rs] = np.where(o.wet, -1, self.wet_onset[rs])
        self.wet_active[rs] = o.wet
        base = Track.realistic(c.segment_length_m)
        for j in np.flatnonzero((old_k != new_k).any(axis=1)):
            model = self.model_tracks[rs.start + j]
            own = slice((model.n_sleepers - n) // 2, (model.n_sleepers - n) // 2 + n)  # voided sleepers kept
            track = base.replace(ballast_stiffness=model.ballast_stiffness[own] / old_k[j] * new_k[j],
                                 ballast_damping=model.ballast_damping[own])
            sim = TrackDegradation(track, self.vehicles[0], law=self.law, feedback="support",
                                   approach_sleepers=self.n_extra, dt=c.dt)
            self.model_tracks[rs.start + j] = sim.model_track
            self.influence[rs.start + j] = sim.support_influence
        self.register[r] = o.register
        self.count[r] = o.tampings_since_renewal
        self.last_tamped[r] = -np.round(o.years_since_tamping * c.steps_per_year)
        self._settled_since(rs, o.years_since_tamping)
        known = np.flatnonzero(~np.isnan(o.start_sd_m))
        rows = rs.start + known
        self.offset[rows], self.u[rows] = start_levels(self.offset[rows], self.u[rows],
                                                       o.sd_after_tamping_m[known], o.start_sd_m[known],
                                                       None if weights is None else weights[known])

    def _file_readings(self, b: int) -> None:
        """Line ``b``'s first observation as a planner knows it at ``as_of``: each section's last recording-car run
        in the line file, dated back to it (:func:`~trackenv.envs.line_fit.last_runs`), in place of the model's own
        run at the start; the line's last run the latest of them. Sections without a usable run (none, or one
        before their last tamping) keep the model's reading. Nothing is drawn, so the
        episode's draws do not change."""
        c, o = self.config, self._file()
        if o is None:
            return
        r = self.rows(b)
        known = np.flatnonzero(~np.isnan(o.last_sd_m))
        if not known.size:
            return
        at = r.start + known
        self.measured_sd[at] = o.last_sd_m[known]
        peak = ~np.isnan(o.last_peak_m[known])
        self.measured_peak[at[peak]] = o.last_peak_m[known][peak]
        self.measured_at[at] = self.step[b] - np.round(o.last_run_age_years[known] * c.steps_per_year)
        self.last_measured[b] = int(self.measured_at[r].max())

    def _equivalent(self, forces: np.ndarray, mix: np.ndarray) -> np.ndarray:
        """Equivalent force of each row's traffic mix: (Σ n_v F_v^p / Σ n_v)^(1/p); forces (2, rows, ...), mix
        (rows, 2) axle passes per vehicle type."""
        w = (mix / mix.sum(axis=1, keepdims=True)).T.reshape(mix.shape[::-1] + (1,) * (forces.ndim - 2))
        return (np.sum(w * np.maximum(forces, 0.0) ** self.p_exp, axis=0)) ** (1.0 / self.p_exp)

    # ------------------------------------------------------------------ physics
    @property
    def _profiles_needed(self) -> bool:
        """Whether a pass reports the contact force per sleeper bay (sections inside a segment, or observed)."""
        return self.K > 1 or self.config.profiles

    def _passes(self, segs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The passes over the segments ``segs`` (:meth:`_computed_passes`): with ``pass_reuse_tolerance_m`` > 0,
        those of a segment whose level is within the tolerance of its last computed pass's (:meth:`_reusable`)
        are that pass's results with its sleeper forces corrected for the settlement since (:meth:`_kept_forces`),
        the others are computed and kept for later steps."""
        tolerance = self.config.pass_reuse_tolerance_m
        if tolerance == 0.0:
            return self._computed_passes(segs)
        fresh = segs[~self._reusable(segs, tolerance)]
        if fresh.size:
            forces, contact, bays = self._vehicle_passes(fresh)
            self.computed_level[fresh] = self.level[fresh]
            self.computed_force[fresh] = forces.transpose(1, 0, 2)
            self.computed_contact[fresh], self.computed_bays[fresh] = contact, bays
        force = self._equivalent(self._kept_forces(segs), self.axle_mix[segs])
        return force, self.computed_contact[segs], self.computed_bays[segs]

    def _kept_forces(self, segs: np.ndarray) -> np.ndarray:
        """(vehicle types, segs, n) the sleeper forces of each segment's last computed pass [N], corrected by the
        static redistribution of the level change since: F + S·(level − kept level), S the segment's
        :attr:`influence`. A tenth of a millimetre of differential settlement moves a sleeper's support force by
        kilonewtons (the ballast's stiffness is ~1e8 N/m), which the kept pass alone misses; the track is linear,
        so the static change is the same under a wheel's peak, its dynamic part (and the contact force) aside. A
        uniform change moves none (S·1 ≈ 0: the approach and exit zones settle with the end sleepers). Exactly
        the kept forces for a segment computed this step (its change is zero)."""
        change = self.level[segs] - self.computed_level[segs]
        static = np.einsum("sij,sj->si", self.influence[segs], change)
        return self.computed_force[segs].transpose(1, 0, 2) + static[None]

    def _reusable(self, segs: np.ndarray, tolerance: float) -> np.ndarray:
        """(segs,) bool: the segments whose level differs from that of their last computed pass by less than
        ``tolerance`` [m] at every sleeper once the mean difference is removed. A uniform shift changes none of a
        pass's forces (the approach and exit zones repeat the end levels, so the whole modelled track moves); a
        tilt or any other shape does, even a straight one (it kinks against the level zones). A segment's model
        track, speed and traffic mix are those of its computed pass: the model track is replaced only by a new
        episode, which clears the level (NaN: never reusable), and the speed and mix are the config's, copied with
        the rows (:meth:`copy_rows`, :meth:`set_state`) as the kept results are. Tamping, spot tamping and renewal
        clear it too, so a worked segment's next pass is always computed."""
        change = self.level[segs] - self.computed_level[segs]
        change -= change.mean(axis=1, keepdims=True)
        return np.abs(change).max(axis=1) < tolerance

    def _computed_passes(self, segs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The passes over the segments ``segs`` computed now (:meth:`_vehicle_passes`), with the equivalent sleeper
        force of each segment's traffic mix (segs, n) [N]; reads the state, writes nothing."""
        forces, contact, bays = self._vehicle_passes(segs)
        return self._equivalent(forces, self.axle_mix[segs]), contact, bays

    def _vehicle_passes(self, segs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One batched pass per vehicle type and speed with traffic over the segments ``segs`` (each segment at
        its own speed): the sleeper forces per vehicle type (vehicle types, segs, n) [N] (zeros for a type without
        traffic on the segment), the largest contact force over each segment's own sleeper bays [N] and, where
        needed (:attr:`_profiles_needed`; else zeros), the largest over each sleeper bay (segs, n) [N]."""
        c = self.config
        n, ne = c.n_sleepers, self.n_extra
        lv = self.level[segs]
        prof = np.concatenate([np.repeat(lv[:, :1], ne, 1), lv, np.repeat(lv[:, -1:], ne, 1)], axis=1)
        speed, mix = self.pass_speed[segs], self.axle_mix[segs]
        forces, contact = np.zeros((len(self.vehicles), len(segs), n)), np.zeros(len(segs))
        bays = np.zeros((len(segs), n))
        jobs, batches = [], []
        for k, v in enumerate(self.vehicles):
            for pass_speed in np.unique(speed[mix[:, k] > 0]):  # none: no traffic of this type, no pass
                for rows, options in self._pass_groups(segs, (speed == pass_speed) & (mix[:, k] > 0), v):
                    jobs.append((k, rows))
                    # (the engine checks its own forces and says which fields to look at: no OverloadWarning)
                    batches.append(dict(tracks=[self.model_tracks[segs[i]] for i in rows], vehicle=v,
                                        speed=float(pass_speed), support_settlement=prof[rows], dt=c.dt,
                                        on_overload="ignore", **options))
        for (k, rows), res in zip(jobs, simulate_pass_batches(batches), strict=True):
            forces[k, rows] = np.stack([r.sleeper_force[ne : ne + n] for r in res])
            # over the segment's own bays: the approach and exit zones (and the pass's start, whose ringing is
            # larger than what a local defect adds) are not the section's
            bay = np.stack([r.contact_force_profile()[ne : ne + n] for r in res])
            contact[rows] = np.maximum(contact[rows], bay.max(axis=1))
            if self._profiles_needed:
                bays[rows] = np.maximum(bays[rows], bay)
        return forces, contact, bays

    def _pass_groups(self, segs: np.ndarray, selected: np.ndarray, vehicle) -> list[tuple[np.ndarray, dict]]:
        """The rows of ``segs`` ``selected`` (bool) for a pass of ``vehicle``, grouped by the engine's options
        for their model tracks (:meth:`~trackenv.physics.engine.PassEngine.options_for`; the classic engine's are
        its defaults, one group): (rows, options) per group, each row's options its own track's alone."""
        rows = np.flatnonzero(selected)
        if self.engine == CLASSIC_ENGINE:
            return [(rows, {})] if rows.size else []
        n, s = self.config.n_sleepers, SLEEPER_SPACING_M
        x_end = TrackDegradation.pass_end_position((n - 1) * s, s, vehicle.system().span, self.n_extra)
        groups: dict = {}
        for i in rows:
            options = self.engine.options_for(self.model_tracks[segs[i]], vehicle, self.n_extra)
            groups.setdefault(tuple(sorted(options.items())), []).append(i)
        return [(np.array(group), {**dict(key), "x_end": x_end}) for key, group in groups.items()]

    def _contact(self, segs: np.ndarray, contact: np.ndarray, bays: np.ndarray) -> None:
        """Keep the contact forces of a pass over ``segs``: per sleeper bay, and per section (the segment's largest
        where a segment is one section, else the largest over the section's sleeper bays) [N]."""
        self.contact_profile[segs] = bays
        secs = self._sections_of(segs)
        self.contact_force[secs] = contact if self.K == 1 else self._per_section(bays, "max")

    def _advance(self, segs: np.ndarray, force: np.ndarray) -> None:
        """Advance the segments ``segs`` by a step's axle passes (of their mix and tonnage) under the equivalent
        forces ``force`` (segs, n), with the static load redistribution taken implicitly (backward Euler, as
        TrackDegradation's support feedback): :func:`~trackenv.physics.settlement.implicit_settlement_step`,
        batched over the segments.

        Each segment iterates until its own residual is below 1e-9 m and then stops, so its settlement does not
        depend on the other segments of the batch: a line gives the same numbers alone (``TampingLine``) and
        among others (:class:`~trackenv.envs.line.TampingLineVectorEnv`), and a section's cost depends only on
        its own schedule (the hindsight search relies on that)."""
        self.u[segs], self.cyc[segs] = implicit_settlement_step(
            self.law, self.u[segs], self.cyc[segs], self.rate()[segs], force, self.influence[segs],
            self.axle_mix[segs].sum(axis=1) * self.traffic_factor[segs],
            # a line's segments are short: the full Jacobian, as the line's calibration was run; a longer segment
            # of several sections (the 60 m track): the band a support's settlement reaches, as TrackDegradation
            band=force.shape[1] if self.K == 1 else INFLUENCE_BAND,
        )

    # ------------------------------------------------------------------ a step
    def allowed(self) -> np.ndarray:
        """(n_lines, S) sections that may be tamped (or get any track work) now: not within
        min_steps_between_tampings of their last track work."""
        return self.allowed_rows(np.repeat(self.step, self.S)).reshape(self.n_lines, self.S)

    def allowed_rows(self, seg_step: np.ndarray | int) -> np.ndarray:
        """(sections,) bool: the sections that may be tamped (or get any track work) at their step ``seg_step``
        (per section or one)."""
        return (seg_step - self.last_work) > self.config.min_steps_between_tampings

    def choice_mask(self) -> np.ndarray:
        """(n_lines, S, len(CHOICES)) bool: the choices each section may get now. "nothing" always; a choice the
        config does not enable, never; track work not within ``min_steps_between_tampings`` of the section's last
        track work, and only if its work fits the possession's ``capacity``; with an annual budget, only a choice
        whose cost (with the possession, for track work) fits what is left of it. What fits alone may still not
        fit with the other choices of the step: :meth:`resolve` settles that."""
        c = self.config
        every = np.broadcast_to(np.arange(len(CHOICES)), (self.n_lines * self.S, len(CHOICES)))
        fits = work_on_sections(self.work, every, self.length_factor[:, None]) <= c.capacity + 1e-9
        mask = self.enabled & fits.reshape(self.n_lines, self.S, len(CHOICES))
        mask = mask & (~self.is_work | self.allowed()[..., None])
        if c.annual_budget > 0:
            spot = np.arange(len(CHOICES)) == SPOT_TAMP  # alone, in a spot possession
            possession = self.is_work * np.where(spot, c.spot_possession_share, 1.0) * c.possession_cost
            cost = self.code_costs().reshape(self.n_lines, self.S, -1) + possession
            mask &= cost <= self.budget_left[:, None, None] + 1e-9
        mask[..., NOTHING] = True
        return mask

    def wet_present(self) -> np.ndarray:
        """(sections,) bool: the sections where a wet spot is, working or still to start (on a segment of several
        sections, those whose sleepers it covers): what a survey finds and drainage removes."""
        return self._wet_on_sections((self.wet_onset >= 0) | self.wet_active)

    def wet_working_rows(self, seg_step: np.ndarray | int) -> np.ndarray:
        """(sections,) bool: the sections whose wet spot works in the traffic of their step ``seg_step`` (per
        section or one): already working, or starting with it. What a planner who knows the future drains at the
        latest before the spot costs anything."""
        step = np.broadcast_to(np.asarray(seg_step), self.sd.shape).reshape(-1, self.K)[:, 0]
        return self._wet_on_sections(self.wet_active | (self.wet_onset == step))

    def renewing(self) -> np.ndarray:
        """(sections,) bool: whether a section's next intervention is a ballast renewal instead of a tamping (it
        has had ``max_tampings_before_renewal`` tampings and the model renews)."""
        return (self.count >= self.tm.max_tampings_before_renewal) & bool(self.tm.renewal_resets)

    def code_costs(self) -> np.ndarray:
        """(sections, len(CHOICES)) what each choice would cost each section now (k€), possession excluded: a
        tamping (with the ballast renewal where one is due: :meth:`renewing`), a spot tamping, a drainage, a
        ballast renewal (with its tamping), an inspection, a survey. A tamping's and a renewal's scale with the
        section's length."""
        c, length = self.config, self.length_factor
        tamping = c.section_tamping_cost * length + self.renewing() * c.section_renewal_cost * length
        per_choice: dict[str, float | np.ndarray] = {
            "tamp": tamping, "renew": c.section_tamping_cost * length + c.section_renewal_cost * length,
            **self.fixed_price}
        out = np.zeros((self.sd.size, len(CHOICES)))
        for i, name in enumerate(CHOICES[1:], start=1):
            out[:, i] = per_choice[name]
        return out

    def choice_costs(self, codes: np.ndarray) -> np.ndarray:
        """(sections,) what the choices ``codes`` (sections,) cost each section (k€; :meth:`code_costs`). Call it
        before :meth:`apply` (a tamping resets the count that decides a renewal)."""
        return np.take_along_axis(self.code_costs(), np.asarray(codes, dtype=np.int64)[:, None], axis=1)[:, 0]

    def campaign_parts(self, codes: np.ndarray) -> np.ndarray:
        """(len(intervention cost keys), n_lines) the step's intervention cost parts per line for the choices
        ``codes`` (n_lines, S), in the order of ``LineConfig.cost_keys()``: the possession (any track work), the
        tampings (tamp and renew), the renewals (renew, and tamp where due), then one part per other choice."""
        c = self.config
        renewing = self.renewing().reshape(self.n_lines, self.S)
        length = self.length_factor.reshape(self.n_lines, self.S)  # counted in sections of the line's length
        tamped = (((codes == TAMP) | (codes == RENEW)) * length).sum(1)
        renewed = (((codes == TAMP) & renewing) * length).sum(1) + ((codes == RENEW) * length).sum(1)
        return np.stack([
            step_possession(c, codes),
            c.section_tamping_cost * tamped,
            c.section_renewal_cost * renewed,
            *(self.fixed_price[name] * (codes == code(name)).sum(1) for name in COST_KEY),
        ])

    def campaign_cost(self, codes: np.ndarray) -> np.ndarray:
        """(n_lines,) the intervention cost of the choices ``codes`` (n_lines, S; bool: tamp), possession
        included."""
        return self.campaign_parts(np.asarray(codes, dtype=np.int64)).sum(axis=0)

    def resolve(self, want: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The choices actually applied from requested ``want`` (n_lines, S): action codes (bool: tamp). Choices
        the config does not enable and track work on sections within ``min_steps_between_tampings`` of their last
        become "nothing"; over the possession's capacity (the work of the track work, in tamping-section
        equivalents) or over the remaining annual budget, the requested sections with the worst measured SD are
        kept, each while it still fits ("clip": the line's ``clipped``, also where what was dropped is a choice
        too large or too dear even alone, which the masks forbid), or ValueError ("raise": after every choice that
        the masks forbid alone, :meth:`choice_mask`, became "nothing", so that only what the masks allow, asked
        for together, raises). Returns (codes, clipped-per-line)."""
        c = self.config
        codes = np.asarray(want, dtype=np.int64)
        codes = np.where(self.enabled[codes], codes, NOTHING)
        codes = np.where(self.is_work[codes] & ~self.allowed(), NOTHING, codes)
        if c.over_capacity == "raise" and codes.any():
            codes = np.where(self._allowed_alone(codes), codes, NOTHING)
        sd = self.measured_sd.reshape(self.n_lines, self.S)
        clipped = np.zeros(self.n_lines, dtype=bool)
        work = self._work(codes)
        over = work.sum(axis=1) > c.capacity + 1e-9
        if over.any():
            if c.over_capacity == "raise":
                b = int(np.flatnonzero(over)[0])
                raise ValueError(
                    f"line {b}: track work of {work[b].sum():g} tamping sections requested in one "
                    f"possession, capacity is {c.capacity} (over_capacity='raise')")
            codes = np.where(fit_worst(work, sd, c.capacity), codes, NOTHING)
            clipped |= over
        if c.annual_budget > 0:
            for _ in range(self.S):  # drop the mildest requested section until each line fits its remaining budget
                too = self.campaign_cost(codes) > self.budget_left + 1e-9
                if not too.any():
                    break
                if c.over_capacity == "raise":
                    b = int(np.flatnonzero(too)[0])
                    raise ValueError(f"line {b}: the step's work costs more than the remaining annual budget "
                                     f"{self.budget_left[b]:.1f} k€ (over_capacity='raise')")
                want_any = codes != NOTHING
                keep = want_any.sum(axis=1) - too.astype(int)
                codes = np.where(keep_worst(want_any, sd, keep), codes, NOTHING)
                clipped |= too
        return codes, clipped

    def _allowed_alone(self, codes: np.ndarray) -> np.ndarray:
        """(n_lines, S) bool: whether the masks (:meth:`choice_mask`) allow each section's code of ``codes``
        (n_lines, S), taken alone."""
        return np.take_along_axis(self.choice_mask(), codes[..., None], axis=2)[..., 0]

    def apply(self, codes: np.ndarray) -> np.ndarray:
        """Apply the choices ``codes`` (n_lines, S; bool: tamp) at the start of the step (the measurements of
        ``inspect`` come at its end: :meth:`inspect_rows`); returns the intervention cost parts per line
        (:meth:`campaign_parts`)."""
        c = self.config
        codes = np.asarray(codes, dtype=np.int64)
        parts = self.campaign_parts(codes)
        flat = codes.ravel()
        self.work_rows(flat, np.repeat(self.step, self.S))
        if flat.any() and c.annual_budget > 0:
            self.budget_left -= parts.sum(axis=0)
        return parts

    def work_rows(self, codes: np.ndarray, seg_step: np.ndarray | int) -> None:
        """Apply the choices ``codes`` (sections,) action codes to their sections at their step ``seg_step`` (per
        section or one), each section on its own: tamping and renewal (:meth:`tamp_rows`), spot tamping
        (:meth:`spot_tamp_rows`), drainage (:meth:`drain_rows`), survey (:meth:`survey_rows`); inspections measure
        at the end of the step (:meth:`inspect_rows`). No masks, no costs, no budget: :meth:`apply` is the
        line-level step; a search over per-section schedules of choices calls this directly."""
        codes = np.asarray(codes, dtype=np.int64)
        self.tamp_rows((codes == TAMP) | (codes == RENEW), seg_step, renew=codes == RENEW)
        if codes.any() and not np.isin(codes, (NOTHING, TAMP)).all():
            self.spot_tamp_rows(codes == SPOT_TAMP, seg_step)
            self.drain_rows(codes == DRAINAGE, seg_step)
            self.survey_rows(codes == SURVEY)

    def tamp_rows(self, t: np.ndarray, seg_step: np.ndarray | int, renew: np.ndarray | None = None) -> None:
        """Tamp (or renew, where due or where ``renew`` (sections,) bool asks) the sections ``t`` (sections,) bool
        at their step ``seg_step`` (per section or one): :func:`~trackenv.physics.tamping.restored_level` with
        the pre-drawn residuals of that step (a segment tamped whole is lifted to its least-squares line;
        sections of a longer segment to the chord through their untamped neighbours, ramped in and out),
        consolidation restarted on the tamped sleepers; a renewal keeps nothing of the old shape and resets the
        tampings since renewal. No costs, no budget: :meth:`apply` is the line-level step; a search over
        per-section schedules calls this directly."""
        c = self.config
        renew = t & (self.renewing() if renew is None else self.renewing() | renew)
        self.sd_after_tamping[:] = 0.0
        if not t.any():
            return
        step_t = np.broadcast_to(np.asarray(seg_step), t.shape)
        segs = np.flatnonzero(self._segments_of(t))
        seg_step = step_t.reshape(-1, self.K)[segs, 0]  # the sections of a segment share their line's step
        sleepers = self._on_sleepers(t)[segs]
        e = self.tamp_noise[np.minimum(seg_step, c.horizon_steps), segs]
        new = restored_level(self.level[segs], sleepers, self.tm, e, self._on_sleepers(renew)[segs])
        self.computed_level[segs] = np.nan  # worked: the next pass is computed
        if self.K == 1:
            self.offset[segs] = new
            self.sd_after_tamping[segs] = self._segment_sd(d1_filter(new, SLEEPER_SPACING_M), segs)
            self.u[segs] = 0.0
            self.cyc[segs] = 0.0
        else:
            self.offset[segs] = np.where(sleepers, new, self.offset[segs])
            self.u[segs] = np.where(sleepers, 0.0, self.u[segs])
            self.cyc[segs] = np.where(sleepers, 0.0, self.cyc[segs])
            after = section_sd(d1_filter(self.level[segs], SLEEPER_SPACING_M), self.section_of_sleeper, self.K)
            secs = self._sections_of(segs)
            self.sd_after_tamping[secs] = np.where(t[secs], after.ravel(), 0.0)
        self.count[t] = np.where(renew[t], 0, self.count[t] + 1)
        self.tampings[t] += 1
        self.last_tamped[t] = step_t[t]
        self.last_work[t] = step_t[t]

    def spot_tamp_rows(self, t: np.ndarray, seg_step: np.ndarray | int) -> None:
        """Spot-tamp the sections ``t`` (sections,) bool at their step ``seg_step`` (per section or one): the
        sleepers within ``spot_tamping_length_m / 2`` of the section's worst sleeper (largest true |D1 level|: the
        crew finds the defect on site), inside the section, lifted to the chord through their untamped neighbours
        and ramped (:func:`~trackenv.physics.tamping.restored_level`, the pre-drawn residuals of that step),
        consolidation restarted on them only. The tampings since renewal do not change (a few metres of ballast
        are disturbed, not the section's)."""
        if not t.any():
            return
        c, n = self.config, self.config.n_sleepers
        step_t = np.broadcast_to(np.asarray(seg_step), t.shape)
        secs = np.flatnonzero(t)
        seg_of = secs // self.K
        in_section = self.section_of_sleeper[None, :] == (secs % self.K)[:, None]
        centre = np.where(in_section, np.abs(self.d1[seg_of]), -np.inf).argmax(axis=1)
        window = in_section & (np.abs(np.arange(n)[None, :] - centre[:, None]) <= self.spot_half)
        segs, first = np.unique(seg_of, return_index=True)
        sleepers = np.zeros((segs.size, n), dtype=bool)
        np.logical_or.at(sleepers, np.searchsorted(segs, seg_of), window)
        e = self.tamp_noise[np.minimum(step_t[secs[first]], c.horizon_steps), segs]
        new = restored_level(self.level[segs], sleepers, self.tm, e, np.zeros_like(sleepers))
        self.computed_level[segs] = np.nan  # worked: the next pass is computed
        self.offset[segs] = np.where(sleepers, new, self.offset[segs])
        self.u[segs] = np.where(sleepers, 0.0, self.u[segs])
        self.cyc[segs] = np.where(sleepers, 0.0, self.cyc[segs])
        self.last_work[t] = step_t[t]

    def drain_rows(self, t: np.ndarray, seg_step: np.ndarray | int) -> None:
        """Drainage or formation repair on the sections ``t`` (sections,) bool at their step ``seg_step``: where a
        wet spot is (:meth:`wet_present`, working or still to start), its patch settles at the plain rate again
        and it never starts later; elsewhere nothing changes (the work is done, and paid, all the same). A
        drained section's survey reads 0 (the formation was opened: no wet cause is left)."""
        if not t.any():
            return
        c = self.config
        wet = t & self.wet_present()
        segs = np.flatnonzero(self._segments_of(wet))
        factor = np.where(self.wet_mask[segs] & self.wet_active[segs, None], c.wet_spot_rate_factor, 1.0)
        self.base_rate[segs] = self.base_rate[segs] / factor
        self.wet_onset[segs] = -1
        self.wet_active[segs] = False
        self.survey[t] = 0
        self.last_work[t] = np.broadcast_to(np.asarray(seg_step), t.shape)[t]

    def survey_rows(self, t: np.ndarray) -> None:
        """Survey the sections ``t`` (sections,) bool (ground-penetrating radar): ``survey`` reads 1 where a wet
        spot is (working or still to start: :meth:`wet_present`), else 0."""
        self.survey = np.where(t, self.wet_present(), self.survey)

    def inspect_rows(self, t: np.ndarray, seg_step: np.ndarray | int) -> None:
        """An extra measurement (a track-geometry trolley) of the sections ``t`` (sections,) bool at their step
        ``seg_step``: the true SD and mean-to-peak with the trolley's pre-drawn errors of that step
        (``inspection_sd_noise_mm``, ``inspection_peak_noise_mm``), the measured level of their sleepers, and
        their measurement age reset."""
        if not t.any():
            return
        c = self.config
        step = np.broadcast_to(np.asarray(seg_step), t.shape)
        self._read(t, step, self.inspect_noise, c.inspection_sd_noise_mm, c.inspection_peak_noise_mm)
        self.measured_at = np.where(t, step, self.measured_at)
        self.measured_level = np.where(self._on_sleepers(t), self.level, self.measured_level)

    def traffic(self, lines: np.ndarray | None = None) -> None:
        """The period's traffic on ``lines`` (bool over lines; None: every line): wet spots that start now, the
        passes, the settlement. Other lines are left as they are (a vector env in NEXT_STEP autoreset does not
        step the lines it is about to reset)."""
        c = self.config
        lines = np.ones(self.n_lines, dtype=bool) if lines is None else np.asarray(lines, dtype=bool)
        if not lines.any():
            return
        self.traffic_rows(np.repeat(lines, self.S), np.repeat(self.step, self.S))
        self.step[lines] += 1
        year_start = self.step % c.steps_per_year == 0
        if c.annual_budget > 0:
            self.budget_left = np.where(lines & year_start, c.annual_budget, self.budget_left)
        self._measure(lines & (self.step % c.measurement_interval == 0))

    def traffic_rows(self, seg: np.ndarray, seg_step: np.ndarray | int) -> None:
        """The period's traffic on the segments of the sections ``seg`` (sections,) bool at their step
        ``seg_step`` (per section or one): wet spots whose onset it is, one batched pass per vehicle type, the
        settlement, the true quality. No step count, no measurement: :meth:`traffic` is the line-level step."""
        c = self.config
        on = self._segments_of(seg)
        step = np.broadcast_to(np.asarray(seg_step), seg.shape).reshape(-1, self.K)[:, 0]
        start = on & (self.wet_onset == step) & ~self.wet_active
        if start.any():
            factor = np.where(self.wet_mask[start], c.wet_spot_rate_factor, 1.0)
            self.base_rate[start] = self.base_rate[start] * factor
            self.wet_active |= start
        segs = np.flatnonzero(on)
        force, contact, bays = self._passes(segs)
        self._contact(segs, contact, bays)
        self._advance(segs, force)
        self._quality(segs)
        self._check_validity(self._sections_of(segs))

    def _beyond_validity(self, secs: slice | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(sections ``secs``,) bool each: a wheel/rail force above :data:`VALID_CONTACT_FACTOR` times the static
        wheel load, and a D1 mean-to-peak above :data:`VALID_PEAK_M`: where a section has left what the model
        represents."""
        force = self.contact_force[secs] > VALID_CONTACT_FACTOR * self.static_wheel_load[secs]
        return force, self.peak[secs] > VALID_PEAK_M

    def _check_validity(self, secs: np.ndarray) -> None:
        """Warn (once per batch) where a section has left what the model represents (:meth:`_beyond_validity`).
        A settlement rate that feeds on its own sleeper forces (a very fast, short defect) can run away to metres
        of settlement and meganewtons; such figures are not physical, and the costs that follow from them are not
        either. Each step's info says it per line too (``beyond_validity``)."""
        if self._validity_warned:
            return
        force, level = self._beyond_validity(secs)
        if force.any() or level.any():
            self._validity_warned = True
            at = int(np.asarray(secs)[np.flatnonzero(force | level)[0]])
            c = self.config
            ratio = self.contact_force[at] / self.static_wheel_load[at]
            warnings.warn(
                f"section {at % c.n_sections} of the line in row {at // c.n_sections} of the batch (the env of "
                f"that index in a vector env) has left the model's validity: "
                f"wheel/rail force {self.contact_force[at] / 1e3:.0f} kN ({ratio:.1f} x the static wheel load; "
                f"valid up to {VALID_CONTACT_FACTOR:g} x), D1 mean-to-peak "
                f"{self.peak[at] * 1e3:.0f} mm (valid up to {VALID_PEAK_M * 1e3:.0f} mm); its settlement has run "
                f"away (check local_defect_rate_factor={c.local_defect_rate_factor:g}, "
                f"local_defect_length_m={c.local_defect_length_m:g}, wet_spot_rate_factor={c.wet_spot_rate_factor:g}"
                f"): the figures from here on are not physical", RuntimeWarning, stacklevel=3)

    def copy_rows(self, dst: np.ndarray, source: LineBatch, src: np.ndarray) -> None:
        """Make sections ``dst`` of this batch exact copies of sections ``src`` of ``source`` (the same config, one
        section per segment): every per-section and per-segment array (state, statics, pre-drawn noise). A search
        forks a section's trajectory this way where two schedules part, instead of replaying their common past."""
        if self.K != 1:
            raise ValueError("copy_rows forks single sections: it needs one section per segment "
                             f"(sections_per_segment = 1, got {self.K})")
        dst, src = np.atleast_1d(dst), np.atleast_1d(src)
        for name in _SEGMENT_FIELDS + _SECTION_FIELDS:
            getattr(self, name)[dst] = getattr(source, name)[src]
        for name in _SEGMENT_NOISE + _SECTION_NOISE:
            getattr(self, name)[:, dst] = getattr(source, name)[:, src]
        for d, s_ in zip(dst, src, strict=True):
            self.model_tracks[d] = source.model_tracks[s_]

    def get_state(self, line: int) -> LineState:
        """A copy of line ``line``'s episode (every per-segment and per-section array, the pre-drawn noise, the
        line's step, recording-car calendar and budget): :meth:`set_state` restores it exactly, here or in
        another batch of the same config."""
        r, rs = self.rows(line), self.segments(line)
        return LineState(
            rows={**{name: getattr(self, name)[rs].copy() for name in _SEGMENT_FIELDS},
                  **{name: getattr(self, name)[r].copy() for name in _SECTION_FIELDS}},
            noise={**{name: getattr(self, name)[:, rs].copy() for name in _SEGMENT_NOISE},
                   **{name: getattr(self, name)[:, r].copy() for name in _SECTION_NOISE}},
            model_tracks=tuple(self.model_tracks[rs]),
            step=int(self.step[line]),
            last_measured=int(self.last_measured[line]),
            budget_left=float(self.budget_left[line]),
        )

    def set_state(self, line: int, state: LineState) -> None:
        """Make line ``line`` continue from ``state`` (:meth:`get_state` of a batch of this config); the state
        itself is not changed."""
        r, rs = self.rows(line), self.segments(line)
        for names, rows in ((_SEGMENT_FIELDS, rs), (_SECTION_FIELDS, r)):
            for name in names:
                getattr(self, name)[rows] = state.rows[name]
        for noise, rows in ((_SEGMENT_NOISE, rs), (_SECTION_NOISE, r)):
            for name in noise:
                getattr(self, name)[:, rows] = state.noise[name]
        self.model_tracks[rs] = list(state.model_tracks)
        self.step[line] = state.step
        self.last_measured[line] = state.last_measured
        self.budget_left[line] = state.budget_left

    def true_quality(self) -> tuple[np.ndarray, np.ndarray]:
        """(segments,) copies of the true SD and D1 mean-to-peak of every row [m] (what the recording car would
        measure without error)."""
        return self.sd.copy(), self.peak.copy()

    def costs(self, campaign: np.ndarray) -> dict[str, np.ndarray]:
        """The period's costs per line (k€) in named parts; reward = −Σ parts."""
        shape = (self.n_lines, self.S)
        per_section = self._quality_costs()
        return {**dict(zip(self.config._INTERVENTION_COST_KEYS, campaign, strict=True)),
                **{k: v.reshape(shape).sum(1) for k, v in per_section.items()}}

    def _quality_costs(self) -> dict[str, np.ndarray]:
        """The step's quality costs per section (:func:`~trackenv.envs.costs.section_quality_costs`): against the
        limits of its speed band, the geometry cost per metre of it."""
        c = self.config
        return section_quality_costs(
            self.sd, self.classify_rows(self.peak), sd_alert_m=self.section_limits("sd_alert_m"),
            geometry_cost_per_section_year=c.geometry_cost_per_section_year * self.length_factor,
            steps_per_year=c.steps_per_year, class_costs=c.class_costs)

    def section_costs(self) -> np.ndarray:
        """(segments,) the step's geometry, speed-restriction and immediate-action cost of each section (k€):
        the parts of :meth:`costs` that belong to one section (for per-section search, e.g. hindsight)."""
        return sum(self._quality_costs().values(), np.zeros(self.sd.shape))

    def advance(self, want: np.ndarray, lines: list[int], rngs: list[np.random.Generator],
                resetting: list[int] = ()) -> tuple[np.ndarray, np.ndarray, dict[int, dict]]:  # type: ignore[assignment]
        """One step of ``lines``, which ask for the choices ``want`` (n_lines, S) action codes (bool: tamp; rows of
        other lines: ignored): the step's work resolved against masks, capacity and budget (:meth:`resolve`), the
        work, the period's traffic, the inspections, the costs; then
        new episodes in ``resetting``, drawn from their generators ``rngs[b]`` (everything random in a line is
        drawn at its reset). Returns the rewards and truncation flags (n_lines,; 0 and False for lines not
        stepped) and the info of each stepped line. Other lines are left as they are. Every TampingLine env steps
        here."""
        stepped = np.zeros(self.n_lines, dtype=bool)
        stepped[lines] = True
        codes, clipped = self.resolve(np.where(stepped[:, None], np.asarray(want, dtype=np.int64), NOTHING))
        section = self.choice_costs(codes.ravel())
        campaign = self.apply(codes)
        self.traffic(stepped)
        self.inspect_rows(codes.ravel() == INSPECT, np.repeat(self.step, self.S))
        parts = self.costs(campaign)
        section += self.section_costs()
        rewards = np.where(stepped, -np.asarray(sum(parts.values()), dtype=float), 0.0)
        truncated = stepped & (self.step >= self.config.horizon_steps)
        infos = {b: self.info(b, {k: float(v[b]) for k, v in parts.items()}, codes[b], clipped[b],
                              section[self.rows(b)]) for b in lines}
        if resetting:
            self.start(list(resetting), rngs)
        return rewards, truncated, infos

    def observations(self, keys) -> dict[str, np.ndarray]:
        """Every line's :meth:`observation`, stacked (n_lines, ...) under ``keys``."""
        obs = [self.observation(b) for b in range(self.n_lines)]
        return {k: np.stack([o[k] for o in obs]) for k in keys}

    def frame(self, b: int, last_info: dict) -> np.ndarray:
        """An RGB picture of line ``b``: its sections (:func:`trackenv.render.line_frame`), or, where a segment
        carries several sections, the profiles along it (:func:`trackenv.render.segment_frame`)."""
        from ..render import line_frame, segment_frame

        return (segment_frame if self.K > 1 else line_frame)(self, b, last_info)

    def reset_info(self, b: int) -> dict:
        """Line ``b``'s info at the start of its episode (no costs, nothing tamped)."""
        S = self.S
        return self.info(b, dict.fromkeys(COST_KEYS, 0.0), np.zeros(S, dtype=np.int64), False, np.zeros(S))

    def step_count(self, b: int) -> int:
        """Steps line ``b`` has taken in its episode."""
        return int(self.step[b])

    # ------------------------------------------------------------------ observation and info
    def _section_values(self, rows, step) -> dict[str, np.ndarray]:
        """The per-section keys of the observation for the sections ``rows`` (a slice or indices) at step
        ``step`` (per section or one), unclipped."""
        c = self.config
        years = (np.asarray(step) - self.last_tamped[rows]) / c.steps_per_year
        sensed = {}
        if c.contact_sensor:
            e = self.sensor_noise[np.minimum(np.asarray(step), c.horizon_steps), np.arange(self.sd.size)[rows]]
            peak = np.maximum(self.contact_force[rows] * (1.0 + c.contact_sensor_noise * e), 0.0)
            sensed = {"section_contact_peak": peak / 1e3,
                      "section_dynamic_share": peak / self.static_wheel_load[rows] - 1.0}
        return {**sensed,
            "section_sd": self.measured_sd[rows] * 1e3,
            "section_peak": self.measured_peak[rows] * 1e3,
            "register": self.register[rows],
            "tampings": self.tampings[rows],
            "tampings_since_renewal": self.count[rows],
            "years_since_tamping": years,
            **self._choice_values(rows, step),
        }

    def _choice_values(self, rows, step) -> dict[str, np.ndarray]:
        """The per-section keys that come with the choices: the measurement age (with ``inspect``) and what a
        survey found (with ``survey``)."""
        c = self.config
        out = {}
        if "inspect" in c.choices:
            out["section_measurement_age"] = (np.asarray(step) - self.measured_at[rows]) / c.steps_per_year
        if "survey" in c.choices:
            out["section_survey"] = self.survey[rows]
        return out

    def section_entries(self, rows, step) -> dict[str, np.ndarray]:
        """The per-section keys of the observation for the segments ``rows`` (a slice or indices) at step
        ``step`` (per segment or one): what a planner sees of each section, float32."""
        return clip_observation(self._section_values(rows, step), self.bounds)

    def _observed(self, b: int) -> dict[str, np.ndarray]:
        """Line ``b``'s observed quantities, unclipped: :meth:`observation` clips them, :meth:`info` counts what
        lies beyond the bounds."""
        c = self.config
        line = {
            "measurement_age": np.array([(self.step[b] - self.last_measured[b]) / c.steps_per_year]),
            "time": np.array([self.step[b] / c.horizon_steps]),
            "budget_left": np.array([self.budget_left[b] / c.annual_budget if c.annual_budget > 0 else 1.0]),
        }
        if c.profiles:
            line["level"] = self.measured_level[self.segments(b)] * 1e3
            line["contact_force"] = self.contact_profile[self.segments(b)] / 1e3
        return {**self._section_values(self.rows(b), self.step[b]), **line}

    def observation(self, b: int) -> dict[str, np.ndarray]:
        """Line ``b``'s observation (the table of ``TampingLine``), clipped to :func:`line_observation_bounds`."""
        return clip_observation(self._observed(b), self.bounds)

    def info(self, b: int, parts: dict[str, float], codes: np.ndarray, clipped: bool,
             section_costs: np.ndarray) -> dict:
        """Line ``b``'s step info: the cost parts (k€), the choices applied (``codes`` (S,): per section in
        ``section_choices``, counted by name in ``choices``; ``tamped_sections``: tamp or renew), and per section
        its own costs ``section_costs`` (k€: its choice, geometry, speed restriction, immediate action; the
        possession is the line's), and ``beyond_validity``: whether a section of the line is beyond the model's
        validity after the step (:meth:`_beyond_validity`: the step's costs are then not physical)."""
        r = self.rows(b)
        codes = np.asarray(codes, dtype=np.int64)
        force, level = self._beyond_validity(r)
        return step_info(
            parts, (codes == TAMP) | (codes == RENEW), self.sd[r], self.peak[r], self.classify_rows(self.peak[r], r),
            self.step[b] / self.config.steps_per_year, self.contact_force[r].max(),
            section_costs=np.asarray(section_costs, dtype=float).copy(), clipped=bool(clipped),
            section_sd_after_tamping_m=self.sd_after_tamping[r].copy(),
            wet_spot_active=self._wet_sections(b), rate_factor=self._per_section(self.rate()[self.segments(b)], "mean"),
            observation_clipped=clipped_values(self._observed(b), self.bounds),
            choices=choice_counts(codes), section_choices=codes.copy(),
            beyond_validity=bool(force.any() or level.any()))

    def _wet_sections(self, b: int) -> np.ndarray:
        """(S,) bool: line ``b``'s sections with an active wet spot (on a segment of several sections, those
        whose sleepers it covers)."""
        return self._wet_on_sections(self.wet_active, self.segments(b))

    def _wet_on_sections(self, wet: np.ndarray, segs: slice = slice(None)) -> np.ndarray:
        """(sections of ``segs``,) bool: the sections of the segments ``segs`` whose wet spot has the flag ``wet``
        (every segment's, (segments,) bool; on a segment of several sections, the sections its patch covers)."""
        if self.K == 1:
            return wet[segs].copy()
        return self._per_section(self.wet_mask[segs] & wet[segs, None], "max").astype(bool)


def fit_worst(work: np.ndarray, score: np.ndarray, capacity: float) -> np.ndarray:
    """(rows, S) bool: per row, the entries with ``work`` > 0 (rows, S) kept in order of highest ``score`` first
    (ties: lower index), each while it still fits in ``capacity`` with those kept before it; entries without
    work are all kept. With unit work it keeps the ``capacity`` highest (:func:`keep_worst`)."""
    s = np.where(work > 0, score, -np.inf)
    order = np.argsort(-s, axis=1, kind="stable")
    keep = np.ones(work.shape, dtype=bool)
    used = np.zeros(work.shape[0])
    rows = np.arange(work.shape[0])
    for col in order.T:  # greedy in each row's order
        w = work[rows, col]
        fits = used + w <= capacity + 1e-9
        keep[rows, col] = fits | (w == 0)
        used += np.where(fits, w, 0.0)
    return keep


def keep_worst(want: np.ndarray, score: np.ndarray, k) -> np.ndarray:
    """(rows, S) bool: per row, keep at most k (scalar or per row) of the True entries of ``want``, highest
    ``score`` first."""
    k = np.broadcast_to(np.asarray(k), (want.shape[0],))
    s = np.where(want, score, -np.inf)
    order = np.argsort(-s, axis=1, kind="stable")
    rank = np.empty_like(order)
    np.put_along_axis(rank, order, np.arange(want.shape[1])[None, :].repeat(want.shape[0], 0), axis=1)
    return want & (rank < k[:, None])
