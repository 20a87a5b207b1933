"""The state and the rules of TampingLine episodes, batched over lines: plain arrays with a leading axis of
segments (``n_lines × n_sections`` rows), so a step is array code and one batched pass per vehicle type.

Everything random in an episode is drawn at its reset from the line's own generator (track, rates, register,
wet spots with their onset step, every tamping residual and every measurement error, indexed by step and
section): an episode is a deterministic function of its seed and its actions, so policies meet common random
numbers and a hindsight search can replay the future of any schedule.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np
from gymnasium import spaces
from scipy.ndimage import gaussian_filter1d

from ..degradation import TrackDegradation
from ..physics.dynamics import simulate_passes
from ..physics.geometry import classify, d1_filter, german_psd, synthesize_profile
from ..physics.settlement import implicit_settlement_step
from ..physics.track import Track
from .common import SHARED_BOUNDS, clip_observation
from .common import observation_space as common_observation_space
from .costs import section_quality_costs
from .info import step_info
from .line_config import REGISTER_CLASSES, SLEEPER_SPACING_M, LineConfig

COST_KEYS = LineConfig.cost_keys()
APPROACH_SLEEPERS = 10


def _correlated_normal(rng: np.random.Generator, shape: tuple[int, ...], corr: float) -> np.ndarray:
    """Standard normal fields along the last axis, Gaussian-correlated over ``corr`` samples, unit SD."""
    n = shape[-1]
    pad = int(3 * corr) + 2
    z = rng.standard_normal(shape[:-1] + (n + 2 * pad,))
    if corr > 0:
        z = gaussian_filter1d(z, corr, axis=-1, mode="wrap")
    z = z[..., pad : pad + n]
    return (z - z.mean(axis=-1, keepdims=True)) / (z.std(axis=-1, keepdims=True) + 1e-12)


def _lognormal(z: np.ndarray, cv: float) -> np.ndarray:
    sigma = np.sqrt(np.log1p(cv * cv))
    return np.exp(sigma * z - sigma * sigma / 2)


def _lsq_line(z: np.ndarray) -> np.ndarray:
    """Least-squares straight line of each row of z (row by row: a matrix product's rounding depends on the
    number of rows, and a line's numbers must not depend on its batch)."""
    n = z.shape[-1]
    t = np.arange(n) - 0.5 * (n - 1)
    slope = (z * t).sum(axis=-1) / float(t @ t)
    return z.mean(axis=-1, keepdims=True) + slope[..., None] * t


#: The per-segment arrays of :class:`LineBatch` (leading axis: segment), and those indexed (step, segment).
_ROW_FIELDS = ("influence", "offset", "u", "cyc", "base_rate", "count", "tampings", "register", "wet_onset",
               "wet_mask", "wet_active", "last_tamped", "measured_sd", "measured_peak", "measured_level",
               "contact_force", "d1", "sd", "peak", "sd_after_tamping", "traffic_factor")
_ROW_NOISE = ("tamp_noise", "meas_noise")


@dataclass(frozen=True, eq=False)
class LineState:
    """One line's episode, copied out of a :class:`LineBatch` (:meth:`LineBatch.get_state`): its segments'
    arrays (``rows``: name -> (S, ...); ``noise``: name -> (H + 1, S, ...), the pre-drawn residuals and
    measurement errors), its segments' model tracks (shared: immutable), and the line's step, last recording
    run and remaining annual budget."""

    rows: dict[str, np.ndarray]
    noise: dict[str, np.ndarray]
    model_tracks: tuple
    step: int
    last_measured: int
    budget_left: float


def line_observation_bounds(config: LineConfig) -> dict[str, tuple[float, float]]:
    """Bounds of each key of TampingLine's observation (its space is built from these and the observation is
    clipped to them, so the two cannot drift apart); ``level`` only with ``profiles``."""
    shared = SHARED_BOUNDS
    bounds = {
        "section_sd": shared["section_sd"],
        "section_peak": shared["section_peak"],
        "measurement_age": (0.0, config.horizon_years + 1.0),
        "register": (0.0, float(len(REGISTER_CLASSES) - 1)),
        "tampings": shared["tampings"],
        "tampings_since_renewal": shared["tampings"],
        "years_since_tamping": (0.0, 100.0),
        "time": shared["time"],
        "budget_left": (0.0, 1.0),
    }
    if config.profiles:
        bounds["level"] = shared["level"]
    return bounds


def line_observation_space(config: LineConfig) -> spaces.Dict:
    """The Dict space of TampingLine's observation table (its bounds: :func:`line_observation_bounds`)."""
    bounds = line_observation_bounds(config)
    per_line = {"measurement_age": (1,), "time": (1,), "budget_left": (1,),
                "level": (config.n_sections, config.n_sleepers)}
    return common_observation_space(bounds, {key: per_line.get(key, (config.n_sections,)) for key in bounds})


class LineBatch:
    """``n_lines`` TampingLine episodes (same config), their segments stacked: row ``b·S + j`` is section j
    of line b. Per-line resets (:meth:`start`) leave the other lines untouched.

    **The engine's public API** (what envs, searches and planning code may call; everything else is internal):

    * lines: :meth:`start` (new episodes), :meth:`advance` (one step of the env), :meth:`observation`,
      :meth:`reset_info`, :meth:`allowed`, :meth:`step_count`, :meth:`get_state` / :meth:`set_state` (a line's
      episode, exactly);
    * rows (one section each), for searches that fork single sections, which evolve independently of each
      other but for the line's possession: :meth:`copy_rows` (fork), :meth:`allowed_rows`,
      :meth:`intervention_costs`, :meth:`tamp_rows`, :meth:`traffic_rows`, :meth:`measure_rows`,
      :meth:`section_costs`, :meth:`section_entries` (what a planner sees of a section), :meth:`true_quality`;
    * read-only: ``config``, ``n_lines``, ``limits`` (the quality limits of the line's speed band), ``step``
      (per line), ``register`` (per row).

    Rows of other lines and the arrays behind them are the engine's; code outside this module reads the state
    through the methods above."""

    def __init__(self, config: LineConfig, n_lines: int) -> None:
        self.config = c = config
        self.bounds = line_observation_bounds(c)
        self.n_lines = int(n_lines)
        S, n, H = c.n_sections, c.n_sleepers, c.horizon_steps
        G = self.n_lines * S
        self.law = c.settlement_law
        self.tm = c.tamping_model
        self.limits = c.quality_limits.for_speed(c.speed)
        self.vehicles = c.vehicles()
        self.passes = c.axle_passes_per_step()
        self.p_exp = float(dict(c.law_params).get("force_exponent", 1.0))
        self.model_tracks: list[Track | None] = [None] * G
        self.n_extra = APPROACH_SLEEPERS
        self.influence = np.zeros((G, n, n))
        self.offset = np.zeros((G, n))
        self.u = np.zeros((G, n))
        self.cyc = np.zeros((G, n))
        self.base_rate = np.ones((G, n))
        self.count = np.zeros(G, dtype=np.int64)  # tampings since renewal
        self.tampings = np.zeros(G, dtype=np.int64)  # tampings this episode
        self.register = np.zeros(G, dtype=np.int64)
        self.wet_onset = np.full(G, -1, dtype=np.int64)
        self.wet_mask = np.zeros((G, n), dtype=bool)
        self.wet_active = np.zeros(G, dtype=bool)
        self.last_tamped = np.zeros(G)  # step of the last tamping (negative: before the episode)
        self.tamp_noise = np.zeros((H + 1, G, n))
        self.meas_noise = np.zeros((H + 1, G, 2))
        self.step = np.zeros(self.n_lines, dtype=np.int64)
        self.last_measured = np.zeros(self.n_lines, dtype=np.int64)
        self.measured_sd = np.zeros(G)
        self.measured_peak = np.zeros(G)
        self.measured_level = np.zeros((G, n))
        self.budget_left = np.zeros(self.n_lines)
        self.contact_force = np.zeros(G)
        self.d1 = np.zeros((G, n))
        self.sd = np.zeros(G)
        self.peak = np.zeros(G)
        self.sd_after_tamping = np.zeros(G)  # true SD right after this step's tamping [m] (0: not tamped)
        self.traffic_factor = np.ones(G)  # factor on the axle passes per row (a line file's per-section traffic)

    # ------------------------------------------------------------------ helpers
    @property
    def S(self) -> int:
        return self.config.n_sections

    def rows(self, line: int) -> slice:
        return slice(line * self.S, (line + 1) * self.S)

    @property
    def level(self) -> np.ndarray:
        return self.offset + self.u

    def rate(self) -> np.ndarray:
        """Current settlement-rate factor per sleeper: base (section, zone, wet spot) × ballast damage."""
        return self.base_rate * (1.0 + self.tm.damage_per_tamping) ** self.count[:, None]

    def _quality(self, rows=slice(None)) -> None:
        self.d1[rows] = d1_filter(self.level[rows], SLEEPER_SPACING_M)
        self.sd[rows] = self.d1[rows].std(axis=1)
        self.peak[rows] = np.abs(self.d1[rows]).max(axis=1)

    def _measure(self, lines: np.ndarray) -> None:
        """A recording-car run on ``lines`` (bool over lines), with the pre-drawn errors of this step."""
        self.measure_rows(np.repeat(lines, self.S), np.repeat(self.step, self.S))
        self.last_measured = np.where(lines, self.step, self.last_measured)

    def measure_rows(self, seg: np.ndarray, seg_step: np.ndarray | int) -> None:
        """A recording-car run on the segments ``seg`` (segments,) bool at their step ``seg_step`` (per segment or
        one), with the pre-drawn errors of that step: the measured SD, mean-to-peak and level. No calendar:
        :meth:`_measure` is the line-level run; a per-section fork is measured through this directly."""
        c = self.config
        step = np.broadcast_to(np.asarray(seg_step), seg.shape)
        e = self.meas_noise[np.minimum(step, c.horizon_steps), np.arange(seg.size)]
        sd = np.maximum(self.sd + c.sd_noise_mm * 1e-3 * e[:, 0], 0.0)
        pk = np.maximum(self.peak + c.peak_noise_mm * 1e-3 * e[:, 1], 0.0)
        self.measured_sd = np.where(seg, sd, self.measured_sd)
        self.measured_peak = np.where(seg, pk, self.measured_peak)
        self.measured_level[seg] = self.level[seg]

    # ------------------------------------------------------------------ reset
    def start(self, lines: list[int], rngs: list[np.random.Generator]) -> None:
        """Draw new episodes for ``lines`` from their generators and run their traffic-free first pass."""
        for b in lines:
            self._draw(b, rngs[b])
        rows = np.concatenate([np.arange(self.rows(b).start, self.rows(b).stop) for b in lines])
        self._quality(rows)
        mask = np.zeros(self.n_lines, dtype=bool)
        mask[lines] = True
        self._measure(mask)
        forces = self._passes(rows)[1]
        self.contact_force[rows] = forces

    def _draw(self, b: int, rng: np.random.Generator) -> None:
        c = self.config
        S, n, H = c.n_sections, c.n_sleepers, c.horizon_steps
        r = self.rows(b)
        # section rate factors: lognormal, AR(1) along the line
        rho = np.exp(-c.section_length_m / c.rate_correlation_m) if c.rate_correlation_m > 0 else 0.0
        e = rng.standard_normal(S)
        z = np.empty(S)
        z[0] = e[0]
        for j in range(1, S):  # the AR(1) recursion (drawn once per episode, at reset)
            z[j] = rho * z[j - 1] + np.sqrt(1 - rho * rho) * e[j]
        section_rate = np.exp(c.rate_sigma * z - c.rate_sigma**2 / 2)
        # register: transition zones and switches/crossings
        u = rng.random(S)
        p_t, p_s = c.transition_probability, c.switch_probability
        reg = np.where(u < p_t, 1, np.where(u < p_t + p_s, 2, 0))
        sleeper_rate = _lognormal(_correlated_normal(rng, (S, n), c.sleeper_rate_correlation_m / SLEEPER_SPACING_M),
                                  c.sleeper_rate_cv)
        kfield = _lognormal(_correlated_normal(rng, (S, n), 2.0), c.ballast_stiffness_cv)
        rate = c.rate_scale * section_rate[:, None] * sleeper_rate
        mid = n // 2
        soft = np.arange(n) < mid
        rate[reg == 1] *= np.where(soft, c.transition_rate_factor, 1.0)
        kfield[reg == 1] *= np.where(soft, 1.0, c.transition_stiffness_ratio)
        patch = np.abs(np.arange(n) - mid) <= 2  # a stiff 3 m patch (crossing nose, level-crossing slab)
        rate[reg == 2] *= c.switch_rate_factor
        kfield[reg == 2] *= np.where(patch, 2.0, 1.0)
        # hidden wet spots
        wet = rng.random(S) < c.wet_spot_probability
        onset = rng.integers(1, max(H, 2), size=S)
        wl = max(int(round(c.wet_spot_length_m / SLEEPER_SPACING_M)), 1)
        start = rng.integers(0, n - wl + 1, size=S)
        wmask = (np.arange(n)[None, :] >= start[:, None]) & (np.arange(n)[None, :] < (start + wl)[:, None])
        # initial state: level from the PSD, scaled; age and tampings since renewal
        scale = rng.uniform(c.initial_scale[0], c.initial_scale[1], size=S)
        base = Track.realistic(c.segment_length_m)
        x = base.sleeper_positions
        level = np.stack([synthesize_profile(x, partial(german_psd, quality="low"), rng) for _ in range(S)])
        level *= scale[:, None]
        age = rng.uniform(0.0, c.initial_age_years, size=S)
        count = rng.integers(0, c.initial_max_tampings + 1, size=S)
        self.tamp_noise[:, r] = rng.standard_normal((H + 1, S, n))
        self.meas_noise[:, r] = rng.standard_normal((H + 1, S, 2))
        self.sd_after_tamping[r] = 0.0
        self.base_rate[r] = rate
        self.register[r] = reg
        self.wet_onset[r] = np.where(wet, onset, -1)
        self.wet_mask[r] = wmask
        self.wet_active[r] = False
        self.offset[r] = level
        self.u[r] = 0.0
        self.cyc[r] = 0.0
        self.count[r] = count
        self.tampings[r] = 0
        self.last_tamped[r] = -np.round(age * c.steps_per_year)
        self.step[b] = 0
        self.budget_left[b] = c.annual_budget
        p_vehicle = self.vehicles[0]
        for j in range(S):  # per-segment track statics, once per episode
            track = base.replace(ballast_stiffness=base.ballast_stiffness * kfield[j])
            sim = TrackDegradation(track, p_vehicle, law=self.law, feedback="support",
                                   approach_sleepers=APPROACH_SLEEPERS, dt=c.dt)
            self.model_tracks[r.start + j] = sim.model_track
            self.influence[r.start + j] = sim.support_influence
        # the settlement since the last tamping: advance the fresh state over its age at the mean load
        cycles = age * c.steps_per_year * self.passes.sum()
        f0 = float(self._equivalent(0.45 * np.array([v.wheel_load for v in self.vehicles])))  # static, Winkler
        u0 = self.rate()[r] * self.law.settlement(f0, np.broadcast_to(cycles[:, None], (S, n)))
        self.u[r] = u0
        self.cyc[r] = np.broadcast_to(cycles[:, None], (S, n))
        self._apply_line_file(b)

    def _apply_line_file(self, b: int) -> None:
        """Line ``b``'s draws overridden by what the config's line file knows (nothing without one), in place of
        the drawn values (:func:`~trackenv.envs.line_fit.line_overrides`): the register, with its zones' rate
        and stiffness (the statics rebuilt where they change); known wet zones (the drawn patch, wet from the
        start instead of hidden); the per-section traffic factor, tampings since renewal and years since tamping
        with the settlement since (as above); the rate factor the file gives, or a draw from its posterior given
        the history (:func:`~trackenv.envs.line_fit.rate_multipliers`), in place of the drawn one; and the SD the
        history gives at the start (the drawn shape and settlement scaled to it:
        :func:`~trackenv.envs.line_fit.start_levels`).
        Everything is drawn first, as without a file, so the draws and their order do not change."""
        c = self.config
        if c.line is None:
            return
        from .line_fit import drawn_section_factor, line_overrides, rate_multipliers, start_levels, zone_factors

        o, r, S, n = line_overrides(c), self.rows(b), c.n_sections, c.n_sleepers
        old_rate, old_k = zone_factors(self.register[r], n, c)
        new_rate, new_k = zone_factors(o.register, n, c)
        drawn = drawn_section_factor(self.base_rate[r] / old_rate, c)
        rate = self.base_rate[r] / old_rate * new_rate
        rate[o.wet] *= np.where(self.wet_mask[r][o.wet], c.wet_spot_rate_factor, 1.0)
        self.base_rate[r] = rate * rate_multipliers(o, drawn, rate, c)[:, None]
        self.wet_onset[r] = np.where(o.wet, -1, self.wet_onset[r])
        self.wet_active[r] = o.wet
        base = Track.realistic(c.segment_length_m)
        for j in np.flatnonzero((old_k != new_k).any(axis=1)):
            model = self.model_tracks[r.start + j]
            first = (model.n_sleepers - n) // 2
            stiffness = model.ballast_stiffness[first : first + n] / old_k[j] * new_k[j]
            sim = TrackDegradation(base.replace(ballast_stiffness=stiffness), self.vehicles[0], law=self.law,
                                   feedback="support", approach_sleepers=APPROACH_SLEEPERS, dt=c.dt)
            self.model_tracks[r.start + j] = sim.model_track
            self.influence[r.start + j] = sim.support_influence
        self.register[r] = o.register
        self.traffic_factor[r] = o.traffic_factor
        self.count[r] = o.tampings_since_renewal
        self.last_tamped[r] = -np.round(o.years_since_tamping * c.steps_per_year)
        cycles = o.years_since_tamping * c.steps_per_year * self.passes.sum() * o.traffic_factor
        f0 = float(self._equivalent(0.45 * np.array([v.wheel_load for v in self.vehicles])))  # as above
        self.u[r] = self.rate()[r] * self.law.settlement(f0, np.broadcast_to(cycles[:, None], (S, n)))
        self.cyc[r] = np.broadcast_to(cycles[:, None], (S, n))
        known = np.flatnonzero(~np.isnan(o.start_sd_m))
        rows = r.start + known
        self.offset[rows], self.u[rows] = start_levels(self.offset[rows], self.u[rows],
                                                       o.sd_after_tamping_m[known], o.start_sd_m[known])

    def _equivalent(self, forces: np.ndarray) -> np.ndarray:
        """Equivalent force of the traffic mix: (Σ n_v F_v^p / Σ n_v)^(1/p); forces (2, ...)."""
        w = (self.passes / self.passes.sum()).reshape((2,) + (1,) * (forces.ndim - 1))
        return (np.sum(w * np.maximum(forces, 0.0) ** self.p_exp, axis=0)) ** (1.0 / self.p_exp)

    # ------------------------------------------------------------------ physics
    def _passes(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One batched pass per vehicle type over the segments ``rows``: the equivalent sleeper force (rows, n)
        and the largest contact force per segment [N]."""
        c = self.config
        n, ne = c.n_sleepers, self.n_extra
        lv = self.level[rows]
        prof = np.concatenate([np.repeat(lv[:, :1], ne, 1), lv, np.repeat(lv[:, -1:], ne, 1)], axis=1)
        tracks = [self.model_tracks[i] for i in rows]
        forces, contact = [], np.zeros(len(rows))
        for v in self.vehicles:
            res = simulate_passes(tracks, v, c.speed, None, support_settlement=prof, dt=c.dt)
            forces.append(np.stack([r.sleeper_force[ne : ne + n] for r in res]))
            contact = np.maximum(contact, [r.contact_force.max() for r in res])
        return self._equivalent(np.stack(forces)), contact

    def _advance(self, rows: np.ndarray, force: np.ndarray, cycles: float) -> None:
        """Advance the segments ``rows`` by ``cycles`` axle passes under the equivalent forces ``force`` (rows, n),
        with the static load redistribution taken implicitly (backward Euler, as TrackDegradation's support
        feedback): :func:`~trackenv.physics.settlement.implicit_settlement_step`, batched over the segments.

        Each segment iterates until its own residual is below 1e-9 m and then stops, so its settlement does not
        depend on the other segments of the batch: a line gives the same numbers alone (``TampingLine``) and
        among others (:class:`~trackenv.envs.line.TampingLineVectorEnv`), and a section's cost depends only on
        its own schedule (the hindsight search relies on that)."""
        self.u[rows], self.cyc[rows] = implicit_settlement_step(
            self.law, self.u[rows], self.cyc[rows], self.rate()[rows], force, self.influence[rows],
            cycles * self.traffic_factor[rows],
            band=force.shape[1],  # segments are short: the full Jacobian, as the line's calibration was run
        )

    # ------------------------------------------------------------------ a step
    def allowed(self) -> np.ndarray:
        """(n_lines, S) sections that may be tamped now (not within min_steps_between_tampings)."""
        return self.allowed_rows(np.repeat(self.step, self.S)).reshape(self.n_lines, self.S)

    def allowed_rows(self, seg_step: np.ndarray | int) -> np.ndarray:
        """(segments,) bool: the segments that may be tamped at their step ``seg_step`` (per segment or one)."""
        return (seg_step - self.last_tamped) > self.config.min_steps_between_tampings

    def renewing(self) -> np.ndarray:
        """(segments,) bool: whether a section's next intervention is a ballast renewal instead of a tamping (it
        has had ``max_tampings_before_renewal`` tampings and the model renews)."""
        return (self.count >= self.tm.max_tampings_before_renewal) & bool(self.tm.renewal_resets)

    def campaign_cost(self, want: np.ndarray) -> np.ndarray:
        """(n_lines,) tamping + possession + renewal cost of tamping ``want`` (n_lines, S)."""
        c = self.config
        renew = self.renewing().reshape(self.n_lines, self.S)
        k = want.sum(axis=1)
        return (k > 0) * c.possession_cost + c.section_tamping_cost * k + c.section_renewal_cost * (want & renew).sum(1)

    def resolve(self, want: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The sections actually tamped from requested ``want`` (n_lines, S) bool: masked sections dropped;
        over capacity (or over the remaining annual budget) the allowed sections with the worst measured SD are
        kept ("clip") or ValueError ("raise"). Returns (tamped, clipped-per-line)."""
        c = self.config
        want = want & self.allowed()
        clipped = np.zeros(self.n_lines, dtype=bool)
        over = want.sum(axis=1) > c.capacity
        if over.any():
            if c.over_capacity == "raise":
                b = int(np.flatnonzero(over)[0])
                raise ValueError(
                    f"line {b}: {int(want[b].sum())} sections requested in one campaign, capacity is {c.capacity} "
                    "(over_capacity='raise')")
            want = keep_worst(want, self.measured_sd.reshape(self.n_lines, self.S), c.capacity)
            clipped |= over
        if c.annual_budget > 0:
            for _ in range(self.S):  # drop the mildest section until each line fits its remaining budget
                too = self.campaign_cost(want) > self.budget_left + 1e-9
                if not too.any():
                    break
                if c.over_capacity == "raise":
                    b = int(np.flatnonzero(too)[0])
                    raise ValueError(f"line {b}: campaign costs more than the remaining annual budget "
                                     f"{self.budget_left[b]:.1f} k€ (over_capacity='raise')")
                keep = want.sum(axis=1) - too.astype(int)
                want = keep_worst(want, self.measured_sd.reshape(self.n_lines, self.S), keep)
                clipped |= too
        return want, clipped

    def apply(self, tamped: np.ndarray) -> np.ndarray:
        """Tamp the sections ``tamped`` (n_lines, S) at the start of the step; returns the cost parts of the
        campaign per line (possession, tamping, renewal)."""
        c = self.config
        t = tamped.ravel()
        renew = t & self.renewing()
        parts = np.stack([
            (tamped.sum(1) > 0) * c.possession_cost,
            c.section_tamping_cost * tamped.sum(1),
            c.section_renewal_cost * renew.reshape(self.n_lines, self.S).sum(1),
        ])
        self.tamp_rows(t, np.repeat(self.step, self.S))
        if t.any() and c.annual_budget > 0:
            self.budget_left -= parts.sum(axis=0)
        return parts

    def tamp_rows(self, t: np.ndarray, seg_step: np.ndarray | int) -> None:
        """Tamp (or renew, where due) the segments ``t`` (segments,) bool at their step ``seg_step`` (per
        segment or one): the level lifted to its least-squares line keeping the residual fraction of its shape
        plus the pre-drawn residual of that step, consolidation restarted. No costs, no budget: :meth:`apply`
        is the line-level step; a search over per-section schedules calls this directly."""
        c = self.config
        renew = t & self.renewing()
        self.sd_after_tamping[:] = 0.0
        if not t.any():
            return
        z = self.level[t]
        f = _lsq_line(z)
        beta = np.where(renew[t], 0.0, self.tm.residual_fraction)[:, None]
        step_t = np.broadcast_to(np.asarray(seg_step), t.shape)[t]
        e = self.tamp_noise[np.minimum(step_t, c.horizon_steps), np.flatnonzero(t)]
        self.offset[t] = f + beta * (z - f) + self.tm.residual_sd_m * e
        self.sd_after_tamping[t] = d1_filter(self.offset[t], SLEEPER_SPACING_M).std(axis=1)
        self.u[t] = 0.0
        self.cyc[t] = 0.0
        self.count[t] = np.where(renew[t], 0, self.count[t] + 1)
        self.tampings[t] += 1
        self.last_tamped[t] = step_t

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
        """The period's traffic on the segments ``seg`` (segments,) bool at their step ``seg_step`` (per segment
        or one): wet spots whose onset it is, one batched pass per vehicle type, the settlement, the true
        quality. No step count, no measurement: :meth:`traffic` is the line-level step."""
        c = self.config
        start = seg & (self.wet_onset == seg_step) & ~self.wet_active
        if start.any():
            factor = np.where(self.wet_mask[start], c.wet_spot_rate_factor, 1.0)
            self.base_rate[start] = self.base_rate[start] * factor
            self.wet_active |= start
        rows = np.flatnonzero(seg)
        force, contact = self._passes(rows)
        self.contact_force[rows] = contact
        self._advance(rows, force, float(self.passes.sum()))
        self._quality(rows)

    def copy_rows(self, dst: np.ndarray, source: LineBatch, src: np.ndarray) -> None:
        """Make segments ``dst`` of this batch exact copies of segments ``src`` of ``source`` (the same config):
        every per-segment array (state, statics, pre-drawn noise). A search forks a section's trajectory this
        way where two schedules part, instead of replaying their common past."""
        dst, src = np.atleast_1d(dst), np.atleast_1d(src)
        for name in _ROW_FIELDS:
            getattr(self, name)[dst] = getattr(source, name)[src]
        for name in _ROW_NOISE:
            getattr(self, name)[:, dst] = getattr(source, name)[:, src]
        for d, s_ in zip(dst, src, strict=True):
            self.model_tracks[d] = source.model_tracks[s_]

    def get_state(self, line: int) -> LineState:
        """A copy of line ``line``'s episode (every per-segment array, the pre-drawn noise, the line's step,
        recording-car calendar and budget): :meth:`set_state` restores it exactly, here or in another batch
        of the same config."""
        r = self.rows(line)
        return LineState(
            rows={name: getattr(self, name)[r].copy() for name in _ROW_FIELDS},
            noise={name: getattr(self, name)[:, r].copy() for name in _ROW_NOISE},
            model_tracks=tuple(self.model_tracks[r]),
            step=int(self.step[line]),
            last_measured=int(self.last_measured[line]),
            budget_left=float(self.budget_left[line]),
        )

    def set_state(self, line: int, state: LineState) -> None:
        """Make line ``line`` continue from ``state`` (:meth:`get_state` of a batch of this config); the state
        itself is not changed."""
        r = self.rows(line)
        for name in _ROW_FIELDS:
            getattr(self, name)[r] = state.rows[name]
        for name in _ROW_NOISE:
            getattr(self, name)[:, r] = state.noise[name]
        self.model_tracks[r] = list(state.model_tracks)
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
        return {"possession": campaign[0], "tamping": campaign[1], "renewal": campaign[2],
                **{k: v.reshape(shape).sum(1) for k, v in per_section.items()}}

    def _quality_costs(self) -> dict[str, np.ndarray]:
        """The step's quality costs per segment (:func:`~trackenv.envs.costs.section_quality_costs`)."""
        c = self.config
        return section_quality_costs(
            self.sd, classify(self.peak, self.limits), sd_alert_m=self.limits.sd_alert_m,
            geometry_cost_per_section_year=c.geometry_cost_per_section_year, steps_per_year=c.steps_per_year,
            class_costs=c.class_costs)

    def intervention_costs(self, t: np.ndarray) -> np.ndarray:
        """(segments,) what tamping the segments ``t`` (segments,) bool costs each (k€): the tamping, or the
        ballast renewal where one is due (:meth:`renewing`); possession excluded (it is the line's). Call it
        before the tamping (:meth:`tamp_rows` resets the count)."""
        c = self.config
        return t * c.section_tamping_cost + (t & self.renewing()) * c.section_renewal_cost

    def section_costs(self) -> np.ndarray:
        """(segments,) the step's geometry, speed-restriction and immediate-action cost of each section (k€):
        the parts of :meth:`costs` that belong to one section (for per-section search, e.g. hindsight)."""
        return sum(self._quality_costs().values(), np.zeros(self.sd.shape))

    def advance(self, want: np.ndarray, lines: list[int], rngs: list[np.random.Generator],
                resetting: list[int] = ()) -> tuple[np.ndarray, np.ndarray, dict[int, dict]]:  # type: ignore[assignment]
        """One step of ``lines``, which ask to tamp ``want`` (n_lines, S) bool (rows of other lines: ignored): the
        campaign resolved against masks, capacity and budget, the tamping, the period's traffic, the costs; then
        new episodes in ``resetting``, drawn from their generators ``rngs[b]`` (everything random in a line is
        drawn at its reset). Returns the rewards and truncation flags (n_lines,; 0 and False for lines not
        stepped) and the info of each stepped line. Other lines are left as they are. Every TampingLine env steps
        here."""
        stepped = np.zeros(self.n_lines, dtype=bool)
        stepped[lines] = True
        tamped, clipped = self.resolve(want & stepped[:, None])
        section = self.intervention_costs(tamped.ravel())
        campaign = self.apply(tamped)
        self.traffic(stepped)
        parts = self.costs(campaign)
        section += self.section_costs()
        rewards = np.where(stepped, -np.asarray(sum(parts.values()), dtype=float), 0.0)
        truncated = stepped & (self.step >= self.config.horizon_steps)
        infos = {b: self.info(b, {k: float(v[b]) for k, v in parts.items()}, tamped[b], clipped[b],
                              section[self.rows(b)]) for b in lines}
        if resetting:
            self.start(list(resetting), rngs)
        return rewards, truncated, infos

    def observations(self, keys) -> dict[str, np.ndarray]:
        """Every line's :meth:`observation`, stacked (n_lines, ...) under ``keys``."""
        obs = [self.observation(b) for b in range(self.n_lines)]
        return {k: np.stack([o[k] for o in obs]) for k in keys}

    def frame(self, b: int, last_info: dict) -> np.ndarray:
        """An RGB picture of line ``b`` (:func:`trackenv.render.line_frame`)."""
        from ..render import line_frame

        return line_frame(self, b, last_info)

    def reset_info(self, b: int) -> dict:
        """Line ``b``'s info at the start of its episode (no costs, nothing tamped)."""
        S = self.S
        return self.info(b, dict.fromkeys(COST_KEYS, 0.0), np.zeros(S, dtype=bool), False, np.zeros(S))

    def step_count(self, b: int) -> int:
        """Steps line ``b`` has taken in its episode."""
        return int(self.step[b])

    # ------------------------------------------------------------------ observation and info
    def section_entries(self, rows, step) -> dict[str, np.ndarray]:
        """The per-section keys of the observation for the segments ``rows`` (a slice or indices) at step
        ``step`` (per segment or one): what a planner sees of each section, float32."""
        years = (np.asarray(step) - self.last_tamped[rows]) / self.config.steps_per_year
        return clip_observation({
            "section_sd": self.measured_sd[rows] * 1e3,
            "section_peak": self.measured_peak[rows] * 1e3,
            "register": self.register[rows],
            "tampings": self.tampings[rows],
            "tampings_since_renewal": self.count[rows],
            "years_since_tamping": years,
        }, self.bounds)

    def observation(self, b: int) -> dict[str, np.ndarray]:
        """Line ``b``'s observation (the table of ``TampingLine``), clipped to :func:`line_observation_bounds`."""
        c = self.config
        r = self.rows(b)
        line = {
            "measurement_age": np.array([(self.step[b] - self.last_measured[b]) / c.steps_per_year]),
            "time": np.array([self.step[b] / c.horizon_steps]),
            "budget_left": np.array([self.budget_left[b] / c.annual_budget if c.annual_budget > 0 else 1.0]),
        }
        if c.profiles:
            line["level"] = self.measured_level[r] * 1e3
        return {**self.section_entries(r, self.step[b]), **clip_observation(line, self.bounds)}

    def info(self, b: int, parts: dict[str, float], tamped: np.ndarray, clipped: bool,
             section_costs: np.ndarray) -> dict:
        """Line ``b``'s step info: the cost parts (k€), and per section its own costs ``section_costs`` (k€:
        tamping or renewal, geometry, speed restriction, immediate action; the possession is the line's)."""
        r = self.rows(b)
        return step_info(
            parts, tamped, self.sd[r], self.peak[r], classify(self.peak[r], self.limits),
            self.step[b] / self.config.steps_per_year, self.contact_force[r].max(),
            section_costs=np.asarray(section_costs, dtype=float).copy(), clipped=bool(clipped),
            section_sd_after_tamping_m=self.sd_after_tamping[r].copy(), wet_spot_active=self.wet_active[r].copy(),
            rate_factor=self.rate()[r].mean(axis=1))


def keep_worst(want: np.ndarray, score: np.ndarray, k) -> np.ndarray:
    """(rows, S) bool: per row, keep at most k (scalar or per row) of the True entries of ``want``, highest
    ``score`` first."""
    k = np.broadcast_to(np.asarray(k), (want.shape[0],))
    s = np.where(want, score, -np.inf)
    order = np.argsort(-s, axis=1, kind="stable")
    rank = np.empty_like(order)
    np.put_along_axis(rank, order, np.arange(want.shape[1])[None, :].repeat(want.shape[0], 0), axis=1)
    return want & (rank < k[:, None])
