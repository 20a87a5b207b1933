"""What a line file knows, applied to its episodes; and each section's settlement rate fitted to its measured
history.

:func:`line_overrides` turns a config's line file (:class:`~trackenv.envs.line_file.LineDescription`) into
per-section arrays that the line engine applies over an episode's draws (``LineBatch._apply_line_file``): the
register, the known wet zones, the traffic factor, years since tamping and tampings since renewal, a rate
factor where the file gives one or the history fits one, and the SD the section starts from where its history
tells it. Everything else (the within-section fields, hidden wet spots, the rates of sections without
history) is drawn per episode as on a line without a file.

**The history fit** (:func:`history_fit`). A section's D1 level after its last tamping is its post-tamping
shape plus the settlement since, and the settlement grows with the section's rate factor k while the shape
does not; the two are independent at first order, so its SD obeys

    SD(t)² ≈ SD₀² + k_eff²·G²(t),    k_eff = k·(1 + damage_per_tamping)^(tampings since renewal − 1),

with t the time since the last tamping, SD₀ the SD right after it, and G²(t) the engine's own mean growth of
SD² of a section of the same class (register, known wet zone, traffic) with k = 1 and one tamping since
renewal. G² comes from a few short simulations in the engine itself: :data:`FIT_DRAWS` draws of such a
section, tamped by the engine's tamping and run without tamping for the span needed (the draws' mean of
SD²(t) − SD²(0)). Per section, the measurements since its last tamping (t_i, SD_i) give SD₀² and k_eff² by
least squares on SD_i² = SD₀² + k_eff²·G²(t_i) (both non-negative), so the fitted rate makes the engine's
expected SD growth reproduce the measured series; the fit reports k, SD₀, the residual (RMS of the fitted
SD against the measured, mm) and the SD the fitted curve gives at ``as_of``, which the section starts from
(its drawn post-tamping shape scaled to it). The fit needs two measurements since the last tamping; with one,
that measurement sets the start SD and the rate is drawn. With a ``rate_factor`` in the file, k is given and
only SD₀ is fitted. How well the fit recovers a known rate from histories the engine generated is on the
documentation's page "Lines from files" (``python experiments/line_example.py``).

A section's simulated growth in an episode still scatters around the fitted one: its within-section fields
(per-sleeper rate and stiffness) are hidden and drawn per episode, and a segment is a 30 m sample of them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from ..physics.geometry import d1_filter
from .line_config import SLEEPER_SPACING_M, LineConfig
from .line_file import LineDescription, Section

#: Draws of each class's section in the growth simulations of the fit, and their seeds ([FIT_SEED, i]).
FIT_DRAWS = 8
FIT_SEED = 38
#: The fit's window: a section last tamped longer ago than this is not fitted (the simulations run this long
#: at most).
FIT_MAX_YEARS = 10.0
#: The range a fitted rate factor is clipped to (as the file's ``rate_factor`` column allows more: a fit
#: beyond this says more about the data than the section).
FIT_RATE_RANGE = (0.05, 20.0)


@dataclass(frozen=True)
class SectionFit:
    """One section's fit (:func:`history_fit`): ``status`` says what was done ("fitted", "given": the file's
    rate factor with SD₀ fitted, "start SD only": one measurement since the last tamping, "not fitted": none
    since, or last tamped more than :data:`FIT_MAX_YEARS` ago, "no history"); ``points`` the measurements
    used; ``rate_factor`` k; ``sd_after_tamping_mm`` SD₀; ``residual_mm`` the RMS of the fitted SD against the
    measured; ``start_sd_mm`` the SD the section starts from at ``as_of`` (NaN where drawn)."""

    section: str
    status: str
    points: int = 0
    rate_factor: float = math.nan
    sd_after_tamping_mm: float = math.nan
    residual_mm: float = math.nan
    start_sd_mm: float = math.nan


@dataclass(frozen=True)
class HistoryFit:
    """The fit of a line's measured history, one :class:`SectionFit` per section in line order."""

    sections: tuple[SectionFit, ...]

    @property
    def fitted(self) -> tuple[SectionFit, ...]:
        return tuple(s for s in self.sections if s.status == "fitted")

    def to_dict(self) -> dict:
        """JSON-ready: per section its fit, and the median residual of the fitted sections."""
        fitted = self.fitted
        return {"sections": [vars(s) for s in self.sections], "fitted": len(fitted),
                "median_residual_mm": float(np.median([s.residual_mm for s in fitted])) if fitted else None}

    def table(self) -> str:
        """A text table of the sections with a history."""
        lines = [f"{'section':<10} {'status':<15} {'points':>6} {'rate':>6} {'SD0 mm':>7} {'resid mm':>8} "
                 f"{'start SD mm':>11}"]
        for s in self.sections:
            if s.status != "no history":
                lines.append(f"{s.section:<10} {s.status:<15} {s.points:>6d} {s.rate_factor:>6.2f} "
                             f"{s.sd_after_tamping_mm:>7.2f} {s.residual_mm:>8.3f} {s.start_sd_mm:>11.2f}")
        return "\n".join(lines)


@dataclass(frozen=True, eq=False)
class LineOverrides:
    """Per section (line order), what the line file sets over an episode's draws: ``register`` (codes),
    ``wet`` (known wet zones), ``traffic_factor`` (on the axle passes), ``years_since_tamping``,
    ``tampings_since_renewal``, ``rate_factor`` (NaN: drawn), ``start_sd_m`` (the SD at the start; NaN: as
    drawn) and ``sd_after_tamping_m`` (the fitted SD right after the last tamping; NaN: as drawn)."""

    register: np.ndarray
    wet: np.ndarray
    traffic_factor: np.ndarray
    years_since_tamping: np.ndarray
    tampings_since_renewal: np.ndarray
    rate_factor: np.ndarray
    start_sd_m: np.ndarray
    sd_after_tamping_m: np.ndarray


@lru_cache(maxsize=16)
def line_overrides(config: LineConfig) -> LineOverrides:
    """What ``config.line`` sets over each episode's draws (cached per config: the fit runs once)."""
    line = _line(config)
    fit = history_fit(config)
    secs = line.sections
    arrays = LineOverrides(
        register=np.array([s.register_index for s in secs], dtype=np.int64),
        wet=np.array([s.wet for s in secs], dtype=bool),
        traffic_factor=np.array(line.traffic_factors()),
        years_since_tamping=np.array([s.years_since_tamping for s in secs]),
        tampings_since_renewal=np.array([s.tampings_since_renewal for s in secs], dtype=np.int64),
        rate_factor=np.array([f.rate_factor if f.status in ("fitted", "given") else
                              (s.rate_factor if s.rate_factor is not None else math.nan)
                              for s, f in zip(secs, fit.sections, strict=True)]),
        start_sd_m=np.array([f.start_sd_mm * 1e-3 for f in fit.sections]),
        sd_after_tamping_m=np.array([f.sd_after_tamping_mm * 1e-3 for f in fit.sections]),
    )
    for a in vars(arrays).values():
        a.flags.writeable = False
    return arrays


def _line(config: LineConfig) -> LineDescription:
    if config.line is None:
        raise ValueError("the config has no line file (LineConfig(line=...))")
    return config.line


# ---------------------------------------------------------------------- the fit
@lru_cache(maxsize=16)
def history_fit(config: LineConfig) -> HistoryFit:
    """Each section's rate factor fitted to its measured history (see the module docstring); cached per
    config. A line without history gives every section the status "no history" and runs nothing."""
    line = _line(config)
    damage = 1.0 + config.tamping_model.damage_per_tamping
    plans = {s.id: _points(line, s) for s in line.sections}
    need = {s.id for s in line.sections if s.years_since_tamping <= FIT_MAX_YEARS
            and (len(plans[s.id][1]) >= 2 or (len(plans[s.id][1]) == 1 and s.rate_factor is not None))}
    classes = sorted({_class_of(line, s) for s in line.sections if s.id in need})
    years = max((s.years_since_tamping for s in line.sections if s.id in need), default=0.0)
    growth = _growth(config, tuple(classes), years) if classes else None
    out = []
    for s in line.sections:
        t, sd = plans[s.id]
        if not line.measurements(s.id):
            out.append(SectionFit(s.id, "no history"))
        elif s.id in need and growth is not None:
            g = growth[classes.index(_class_of(line, s))]
            out.append(_fit_section(s, t, sd, g, config.steps_per_year, damage))
        elif len(sd) >= 1:
            out.append(SectionFit(s.id, "start SD only", points=1, start_sd_mm=float(sd[-1]) * 1e3))
        else:
            out.append(SectionFit(s.id, "not fitted"))
    return HistoryFit(tuple(out))


def _points(line: LineDescription, s: Section) -> tuple[np.ndarray, np.ndarray]:
    """A section's measurements since its last tamping: (years since that tamping, SD [m])."""
    ms = line.measurements(s.id)
    t = np.array([s.years_since_tamping - line.years_before(m.date) for m in ms])
    sd = np.array([m.sd_m for m in ms])
    keep = t >= -1e-9
    return np.maximum(t[keep], 0.0), sd[keep]


def _class_of(line: LineDescription, s: Section) -> tuple[str, bool, float]:
    """What the growth of a section's SD depends on besides its rate: register, known wet zone, traffic."""
    return (s.register, s.wet, s.annual_mgt / line.annual_mgt)


def _fit_section(s: Section, t: np.ndarray, sd: np.ndarray, growth: np.ndarray, steps_per_year: int,
                 damage: float) -> SectionFit:
    """Least squares of SD_i² = SD₀² + k_eff²·G²(t_i), both non-negative (k_eff given where the file gives k)."""
    grid = np.arange(growth.size) / steps_per_year
    x, y = np.interp(t, grid, growth), sd**2
    to_k = damage ** (1 - s.tampings_since_renewal)  # k = k_eff · to_k
    status = "given" if s.rate_factor is not None else "fitted"
    if s.rate_factor is not None:
        q = (s.rate_factor / to_k) ** 2
    elif np.ptp(x) > 0:
        q = float(np.cov(x, y, bias=True)[0, 1] / np.var(x))
        if y.mean() - q * x.mean() < 0:  # SD₀² would be negative: the line through the origin
            q = float(x @ y / (x @ x))
        q = min(max(q, (FIT_RATE_RANGE[0] / to_k) ** 2), (FIT_RATE_RANGE[1] / to_k) ** 2)
    else:  # all the points at one time since tamping: the rate cannot be told
        return SectionFit(s.id, "start SD only", points=len(sd), start_sd_mm=float(sd[-1]) * 1e3)
    a = max(float(np.mean(y - q * x)), 0.0)
    fitted_sd = np.sqrt(a + q * x)
    start = math.sqrt(a + q * float(np.interp(s.years_since_tamping, grid, growth)))
    return SectionFit(s.id, status, points=len(sd), rate_factor=math.sqrt(q) * to_k,
                      sd_after_tamping_mm=math.sqrt(a) * 1e3,
                      residual_mm=float(np.sqrt(np.mean((fitted_sd - sd) ** 2))) * 1e3, start_sd_mm=start * 1e3)


def _growth(config: LineConfig, classes: tuple[tuple[str, bool, float], ...], years: float) -> np.ndarray:
    """(classes, steps + 1): the engine's mean growth of SD² [m²] of each class's section (k = 1, one tamping
    since renewal) from its tamping, every step up to ``years``."""
    line = _line(config)
    steps = max(int(math.ceil(years * config.steps_per_year - 1e-9)), 1)
    protos = tuple(Section(id=f"class{i}", length_m=line.section_length_m, register=reg, wet=wet,
                           annual_mgt=line.annual_mgt * factor, speed_kmh=line.speed_kmh,
                           freight_share=line.freight_share, years_since_tamping=0.0, tampings_since_renewal=0,
                           rate_factor=1.0)
                   for i, (reg, wet, factor) in enumerate(classes))
    proto_line = replace(line, sections=protos, history=(), source=f"{line.source} (fit)")
    proto = config.replace(line=proto_line, wet_spot_probability=0.0, horizon_years=steps / config.steps_per_year)
    return _simulated_growth(proto, steps)


@lru_cache(maxsize=16)
def _simulated_growth(proto: LineConfig, steps: int) -> np.ndarray:
    from .line_episode import LineBatch  # the engine builds on this module's overrides

    batch = LineBatch(proto, FIT_DRAWS)
    batch.start(list(range(FIT_DRAWS)), [np.random.default_rng([FIT_SEED, i]) for i in range(FIT_DRAWS)])
    every = np.ones(FIT_DRAWS * proto.n_sections, dtype=bool)
    batch.tamp_rows(every, 0)
    sd = [batch.sd_after_tamping.copy()]
    for step in range(steps):
        batch.traffic_rows(every, step)
        sd.append(batch.true_quality()[0])
    sq = np.array(sd).reshape(steps + 1, FIT_DRAWS, proto.n_sections) ** 2
    return (sq - sq[:1]).mean(axis=1).T


# ---------------------------------------------------------------------- the engine's side
def zone_factors(register: np.ndarray, n: int, config: LineConfig) -> tuple[np.ndarray, np.ndarray]:
    """(rate, ballast stiffness) factors (S, n) that each section's register class puts on its segment of
    ``n`` sleepers, as the line engine draws them: a transition zone settles ``transition_rate_factor`` times
    faster on its soft half and is ``transition_stiffness_ratio`` times stiffer on the other; a switch or
    crossing settles ``switch_rate_factor`` times faster with a stiff 3 m patch (twice the stiffness) in the
    middle. (A test checks them against the engine's draws.)"""
    c = config
    register = np.asarray(register)
    mid = n // 2
    soft = np.arange(n) < mid
    patch = np.abs(np.arange(n) - mid) <= 2
    rate = np.ones((register.size, n))
    stiff = np.ones((register.size, n))
    rate[register == 1] = np.where(soft, c.transition_rate_factor, 1.0)
    stiff[register == 1] = np.where(soft, 1.0, c.transition_stiffness_ratio)
    rate[register == 2] = c.switch_rate_factor
    stiff[register == 2] = np.where(patch, 2.0, 1.0)
    return rate, stiff


def drawn_section_factor(plain_rate: np.ndarray, config: LineConfig) -> np.ndarray:
    """(S,) the section rate factors of an episode's draw from its per-sleeper rates without zone factors
    (S, n): the engine draws them as ``rate_scale × section factor × sleeper factor`` with log sleeper factors
    of mean exactly −σ²/2 along the segment (σ² = log(1 + sleeper_rate_cv²): a normalised field), so the
    section factor is the geometric mean divided by ``rate_scale`` and exp(−σ²/2)."""
    sigma2 = math.log1p(config.sleeper_rate_cv**2)
    return np.exp(np.log(plain_rate).mean(axis=1) + sigma2 / 2) / config.rate_scale


def start_levels(shape: np.ndarray, settled: np.ndarray, sd_after_tamping: np.ndarray,
                 start_sd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A section's post-tamping ``shape`` and its ``settled`` level since (rows, n) [m] scaled so that it starts
    at the SD its history gives, ``start_sd`` [m] per row: the shape to the fitted SD right after tamping
    ``sd_after_tamping`` (where fitted; NaN: as drawn), then the settlement to the start SD; where the shape
    is rougher than that on its own, the shape instead (with the settlement at its least rough scale).
    Returns the new (shape, settled)."""
    shape, settled = shape.copy(), settled.copy()
    sd0 = np.asarray(sd_after_tamping, dtype=float)
    fitted = ~np.isnan(sd0)
    if fitted.any():  # the D1 filter is homogeneous (D1(s·z) = s·D1(z)): a ratio of SDs scales it exactly
        own = d1_filter(shape[fitted], SLEEPER_SPACING_M).std(axis=1)
        shape[fitted] *= (sd0[fitted] / np.maximum(own, 1e-12))[:, None]
    s, reached = scale_to(settled, shape, start_sd)
    settled *= s[:, None]
    if not reached.all():
        rest = ~reached
        s_shape, _ = scale_to(shape[rest], settled[rest], np.asarray(start_sd)[rest])
        shape[rest] *= s_shape[:, None]
    return shape, settled


def scale_to(x: np.ndarray, y: np.ndarray, target_sd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(rows,) the factor s ≥ 0 per row with SD of D1(s·x + y) = ``target_sd`` [m], and whether it was reached.
    Were the D1 filter linear, SD² = s²·var(a) + 2s·cov(a, b) + var(b) with a, b the D1 of x and y, a quadratic
    in s: its root starts a secant iteration on the filter itself (whose end padding is fitted to the record,
    so it is additive only nearly) to 0.1 % of the target. Where no s reaches the target, the s of the least
    SD."""
    target = np.asarray(target_sd, dtype=float)
    a = d1_filter(x, SLEEPER_SPACING_M)
    b = d1_filter(y, SLEEPER_SPACING_M)
    a = a - a.mean(axis=1, keepdims=True)
    b = b - b.mean(axis=1, keepdims=True)
    va, cab, vb = (a * a).mean(axis=1), (a * b).mean(axis=1), (b * b).mean(axis=1)
    va = np.maximum(va, 1e-30)
    disc = cab * cab - va * (vb - target**2)
    s = np.maximum(np.where(disc >= 0, (-cab + np.sqrt(np.maximum(disc, 0.0))) / va, -cab / va), 0.0)

    def miss(scale: np.ndarray) -> np.ndarray:
        return d1_filter(scale[:, None] * x + y, SLEEPER_SPACING_M).std(axis=1) - target

    prev = s * 1.02 + 1e-3
    f_prev, f = miss(prev), miss(s)
    for _ in range(8):
        todo = (disc >= 0) & (np.abs(f) > 1e-3 * target)
        if not todo.any():
            break
        slope = (f - f_prev) / np.where(s != prev, s - prev, 1.0)
        new = np.where(todo & (slope > 0), np.maximum(s - f / np.where(slope > 0, slope, 1.0), 0.0), s)
        prev, f_prev, s = s, f, new
        f = np.where(todo, miss(s), f)
    return s, np.abs(f) <= 1e-3 * target
