"""What a line file knows, applied to its episodes; and each section's settlement rate conditioned on its measured
history.

:func:`line_overrides` turns a config's line file (:class:`~trackenv.envs.line_file.LineDescription`) into
per-section arrays that the line engine applies over an episode's draws (``LineBatch._apply_line_file``): the
register, the known wet zones (and the suspected ones, whose hidden wet spot is likelier), the known number of
short local defects, years since tamping and tampings since renewal, the rate factor where the file
gives one, the posterior of the rate where the history gives one, and the SD the section starts from (a
section's own length, speed and traffic come with the config: ``LineConfig.per_section``). Everything else (the
within-section fields, hidden wet spots, the rates of sections without history) is drawn per episode as on a line
without a file.

**The history fit** (:func:`history_fit`). After its last tamping a section's D1 level is its post-tamping
shape plus the settlement since. The shape does not change; the settlement grows with a fixed pattern (the
section's per-sleeper rates and stiffness) in proportion to its rate, so with a, b the D1 of the shape and of
the settlement,

    SD(t)² = SD₀² + 2ρ·SD₀·κ·φ(t) + κ²·φ(t)²,    κ = k·(1 + damage_per_tamping)^(tampings since renewal − 1),

where t is the time since the last tamping, SD₀ the SD right after it, ρ the correlation of a and b, φ(t) the SD
of b for k = 1 and k the section's *effective* rate factor: its factor times how unevenly its hidden field
makes it settle (:func:`roughness`, over the typical one of its class). φ(t) and the spread of ρ are the
engine's own: short simulations of a section of the same class (register, known wet zone, traffic), one
tamping since renewal, :data:`FIT_DRAWS` draws of it settled for :data:`FIT_PREVIOUS_CYCLE_YEARS`, tamped by the
engine's tamping and run without tamping for the span needed; each class is simulated alone (a line of that one
section, the same seeds on every line) and ρ's spread is taken over the section's own span since its tamping,
so that a section's fit depends on its own data and class only, never on another section's history or years
since tamping (a simulation's first steps do not depend on how many follow). Checked on those simulations: φ
scales with k within 10 % for k from 0.5 to 4, ρ of a section stays within a few hundredths over three years,
and the log of the settlement's D1 SD correlates at 0.97 with that of the rate field's roughness.

The measurements after the last tamping (t_i, SD_i) then condition k by Bayes' rule on a grid of (k, ρ, SD₀):
the prior of k is the engine's own (lognormal with log-SD ``rate_sigma``, widened by the spread of the
roughness between draws), that of ρ the simulations' spread, SD₀ flat; the likelihood Gaussian with the
recording car's error ``sd_noise_mm`` and a model error of :data:`FIT_MODEL_ERROR_MM`. Why a posterior and not
a least-squares value: while the settlement is small against the post-tamping shape, the series fixes ρ·k (the
first-order slope) much better than k itself, and a least-squares k then runs to its bounds; the posterior says
how much the history tells and falls back on the prior where it tells little. The fit reports per section the
posterior median of k and its 10-90 % interval, the most probable (k, ρ, SD₀), the RMS residual of its curve
against the measured SD, and that curve's SD at ``as_of``, where the section starts (its drawn shape scaled to
SD₀ and its settlement to the start SD: :func:`start_levels`).

In an episode a fitted section's effective rate is a draw from its posterior, made from the episode's own draw
of the section's factor (its quantile under the prior is taken to the same quantile of the posterior), so
nothing more is drawn and neighbouring sections keep their correlation; the section's rates are then scaled so
that the drawn field's roughness gives that effective rate (:func:`rate_multipliers`). The fit needs two
measurements after the last tamping; with one, that measurement sets the start SD and the rate is drawn as
without a file. With a ``rate_factor`` in the file, k is given (the drawn field's roughness then varies as
usual) and only ρ and SD₀ are fitted. How well the fit recovers rates the engine generated histories with is on
the documentation's page "Lines from files" (``python experiments/line_example.py``).

With local defects counted once in a section's length (``local_defect_near_m``), every SD above is the
section's as the engine measures it (:func:`sd_weights`: the drawn defects' neighbourhoods weighted by their
length over the section's), and the classes are simulated without local defects (a defect's settlement runs
away on some draws, which would make the class's curve follow those draws): the fit is the same as without
defects, and an episode's draw, its defects included, is scaled to it. A file's known defects (its ``defects``
column, which sets ``local_defect_near_m``) are placed with the drawn ones, before the file's values are
applied, and take the same path: a section with known defects fits as its class does and starts at the SD its
history gives.

A fitted section's simulated growth in an episode scatters around its measured one by what remains: the
posterior's spread, the rest of the hidden field (its stiffness, the pattern beyond its roughness) and the
dynamics.

Where a section's file contradicts its history, :func:`history_fit` warns (:class:`FitWarning`) and notes it in
the table: a given ``rate_factor`` whose curve's residual exceeds the fitted factor's by more than
:data:`FIT_CONFLICT_ERRORS` times the fit's error, an SD that does not drop across the stated last tamping
(:data:`FIT_NO_DROP_SHARE`), an SD that drops after it (a tamping the file does not state,
:data:`FIT_DROP_ERRORS`), a fitted curve that misses its runs by far (:data:`FIT_POOR_ERRORS`), or a history
whose every SD is below what tamped track measures (:data:`FIT_LOW_SD_MM`: an SD in cm), or a last tamping more
than :data:`FIT_LONG_UNTAMPED_YEARS` ago (months given as years?). The file's values are used either way.
"""

from __future__ import annotations

import datetime as dt
import math
import warnings
from dataclasses import dataclass, replace
from functools import lru_cache
from typing import Any

import numpy as np
from scipy.special import ndtr

from ..physics.geometry import d1_filter
from .line_config import SLEEPER_SPACING_M, LineConfig
from .line_file import DAYS_PER_YEAR, LineDescription, Section

#: Draws of each class's section in the simulations of the fit, and their seeds ([FIT_SEED, i]).
FIT_DRAWS = 8
FIT_SEED = 38
#: How long the simulated sections had settled before the tamping they are followed from [years]: a tamping
#: keeps part of the old shape, and where that shape is the section's own settlement it grows again with it
#: (ρ > 0), so the simulated sections start one cycle into their life, as track in service is **[assumption:
#: a 3-year cycle; the engine's sections start up to 3 years after their last tamping]**.
FIT_PREVIOUS_CYCLE_YEARS = 3.0
#: A recording-car run this many days or fewer after a section's last tamping counts as before it.
FIT_SAME_DAYS = 15
#: The fit's window: a section last tamped longer ago than this is not fitted (the simulations run this long
#: at most).
FIT_MAX_YEARS = 10.0
#: The model error of the fit's SD curve [mm], added in quadrature to the recording car's error **[assumption:
#: the curve fits the engine's own noise-free series within ~0.01-0.03 mm; 0.05 mm leaves room]**.
FIT_MODEL_ERROR_MM = 0.05
#: A file's ``rate_factor`` contradicts a section's history where the RMS residual of its curve exceeds that of
#: the fitted factor's by more than this many times the fit's error (the car's ``sd_noise_mm`` and
#: :data:`FIT_MODEL_ERROR_MM` in quadrature: 0.11 mm by default, so 0.22 mm): a warning, and a note in the table.
FIT_CONFLICT_ERRORS = 2.0
#: A history shows no drop across a section's stated last tamping where its SD rose over its last two runs
#: before it and rose on across it at least this share of that rate (per year): a warning naming the section.
FIT_NO_DROP_SHARE = 0.5
#: A drop of a section's SD between two runs after its stated last tamping, larger than this many times the fit's
#: error and than :data:`FIT_DROP_SHARE` of the SD before it, is a tamping the file does not state (the SD of
#: settling track does not fall; the car's error moves it by ~0.15 mm between two runs, the example line's largest
#: such drop is 0.32 mm, a tamping takes ~1-3 mm off): a warning naming the runs.
FIT_DROP_ERRORS = 5.0
FIT_DROP_SHARE = 0.3
#: A fitted curve that misses its runs by more than this many times the fit's error (RMS) follows no one
#: settlement curve (the example line's worst is 1.5 times): a warning.
FIT_POOR_ERRORS = 3.0
#: A section whose every run measures an SD below this [mm] measures less than tamped track does (about 0.5 mm
#: and more; the engine's tamping leaves ~0.14 mm plus a quarter of the SD before plus its residual shape):
#: most likely an SD in cm, a warning **[assumption]**.
FIT_LOW_SD_MM = 0.3
#: A section last tamped longer ago than this [year] is noted: track under traffic is tamped every few years (a
#: quiet branch's cycle ~10-15 years), so such a value is more often months given as years; the file's value is
#: used **[assumption]**.
FIT_LONG_UNTAMPED_YEARS = 20.0
#: The grid of the rate factor's posterior (log-spaced), of ρ and the number of SD₀ values.
RATE_GRID = np.exp(np.linspace(math.log(0.02), math.log(50.0), 81))
RHO_GRID = np.linspace(-1.0, 1.0, 25)
SD0_POINTS = 40


class FitWarning(UserWarning):
    """A section's file contradicts its measured history (:func:`history_fit`): a given ``rate_factor`` the
    history does not bear out, or an SD that does not drop across the stated last tamping."""


@dataclass(frozen=True)
class SectionFit:
    """One section's fit (:func:`history_fit`): ``status`` says what was done ("fitted"; "given": the file's
    rate factor, ρ and SD₀ fitted; "start SD only": one measurement since the last tamping; "not fitted": none
    since, or last tamped more than :data:`FIT_MAX_YEARS` ago; "no history"); ``points`` the measurements
    used; ``rate_factor`` the posterior median of k (the file's where given) and ``rate_p10`` / ``rate_p90``
    its 10-90 % interval; ``rho`` and ``sd_after_tamping_mm`` (SD₀) of the most probable curve,
    ``residual_mm`` the RMS of that curve against the measured SD, ``start_sd_mm`` its SD at ``as_of``, where
    the section starts (NaN where drawn). Where the factor is given, ``fitted_rate_factor`` and
    ``fitted_residual_mm`` are those the history alone gives (NaN otherwise), to compare. ``note``: where the
    file contradicts the history, what (the text of the :class:`FitWarning`; "" otherwise)."""

    section: str
    status: str
    points: int = 0
    rate_factor: float = math.nan
    rate_p10: float = math.nan
    rate_p90: float = math.nan
    rho: float = math.nan
    sd_after_tamping_mm: float = math.nan
    residual_mm: float = math.nan
    start_sd_mm: float = math.nan
    fitted_rate_factor: float = math.nan
    fitted_residual_mm: float = math.nan
    note: str = ""


@dataclass(frozen=True, eq=False)
class HistoryFit:
    """The fit of a line's measured history: one :class:`SectionFit` per section in line order, and per
    section the posterior CDF of its rate factor on :data:`RATE_GRID` (``rate_cdf``, (S, grid); NaN rows where
    the rate is not fitted) and the typical roughness of its class's rate field (``roughness``, (S,))."""

    sections: tuple[SectionFit, ...]
    rate_cdf: np.ndarray
    roughness: np.ndarray

    @property
    def fitted(self) -> tuple[SectionFit, ...]:
        return tuple(s for s in self.sections if s.status == "fitted")

    def to_dict(self) -> dict:
        """JSON-ready: per section its fit, and the median residual of the fitted sections."""
        fitted = self.fitted
        return {"sections": [vars(s) for s in self.sections], "fitted": len(fitted),
                "median_residual_mm": float(np.median([s.residual_mm for s in fitted])) if fitted else None}

    def table(self) -> str:
        """A text table of the sections with a history: per section its fit, and a note where the file
        contradicts the history (a given rate factor's "fitted" column is the history's own factor)."""
        lines = [f"{'section':<10} {'status':<14} {'points':>6} {'rate':>5} {'10-90 %':>11} {'fitted':>6} "
                 f"{'SD0 mm':>6} {'resid mm':>8} {'start SD mm':>11}  note"]
        for s in self.sections:
            if s.status != "no history":
                fitted = "" if math.isnan(s.fitted_rate_factor) else f"{s.fitted_rate_factor:.2f}"
                lines.append(f"{s.section:<10} {s.status:<14} {s.points:>6d} {s.rate_factor:>5.2f} "
                             f"{s.rate_p10:>5.2f}-{s.rate_p90:<5.2f} {fitted:>6} "
                             f"{s.sd_after_tamping_mm:>6.2f} {s.residual_mm:>8.3f} {s.start_sd_mm:>11.2f}  "
                             f"{s.note}".rstrip())
        return "\n".join(lines)


@dataclass(frozen=True, eq=False)
class LineOverrides:
    """Per section (line order), what the line file sets over an episode's draws: ``register`` (codes),
    ``wet`` (known wet zones), ``wet_suspected`` (suspected ones: their hidden wet spot drawn with the config's
    ``suspected_wet_probability``), ``defects`` (the number of known short local defects; −1: not known, drawn),
    ``years_since_tamping``,
    ``tampings_since_renewal``, ``rate_factor`` (the file's; NaN: none), ``rate_cdf`` (the posterior CDF of a
    fitted rate on :data:`RATE_GRID`; NaN rows: not fitted), ``start_sd_m`` (the SD at the start; NaN: as
    drawn), ``sd_after_tamping_m`` (the fitted SD right after the last tamping; NaN: as drawn), and the
    section's last recording-car run as the episode's first observation reads it (:func:`last_runs`):
    ``last_sd_m``, ``last_peak_m`` (NaN: the model's own reading at the start) and ``last_run_age_years``."""

    register: np.ndarray
    wet: np.ndarray
    wet_suspected: np.ndarray
    defects: np.ndarray
    years_since_tamping: np.ndarray
    tampings_since_renewal: np.ndarray
    rate_factor: np.ndarray
    rate_cdf: np.ndarray
    roughness: np.ndarray
    start_sd_m: np.ndarray
    sd_after_tamping_m: np.ndarray
    last_sd_m: np.ndarray
    last_peak_m: np.ndarray
    last_run_age_years: np.ndarray


@lru_cache(maxsize=16)
def line_overrides(config: LineConfig) -> LineOverrides:
    """What ``config.line`` sets over each episode's draws (cached per config: the fit runs once)."""
    line = _line(config)
    fit = history_fit(config)
    secs = line.sections
    arrays = LineOverrides(
        register=np.array([s.register_index for s in secs], dtype=np.int64),
        wet=np.array([s.wet for s in secs], dtype=bool),
        wet_suspected=np.array([s.wet_suspected for s in secs], dtype=bool),
        defects=np.array([-1 if s.defects is None else s.defects for s in secs], dtype=np.int64),
        years_since_tamping=np.array([s.years_since_tamping for s in secs]),
        tampings_since_renewal=np.array([s.tampings_since_renewal for s in secs], dtype=np.int64),
        rate_factor=np.array([math.nan if s.rate_factor is None else s.rate_factor for s in secs]),
        rate_cdf=fit.rate_cdf,
        roughness=fit.roughness,
        start_sd_m=np.array([f.start_sd_mm * 1e-3 for f in fit.sections]),
        sd_after_tamping_m=np.array([f.sd_after_tamping_mm * 1e-3 for f in fit.sections]),
        **last_runs(line),
    )
    for a in vars(arrays).values():
        a.flags.writeable = False
    return arrays


def last_runs(line: LineDescription) -> dict[str, np.ndarray]:
    """Per section, its last recording-car run, which a planner knows at ``as_of`` and the episode's first
    observation shows in place of a run of the model's own: ``last_sd_m``, ``last_peak_m`` [m] and
    ``last_run_age_years`` (years before ``as_of``, whatever the horizon: the observation's bounds take the
    oldest, ``line_episode.file_run_age_years``). NaN where the section has no run or where its last run comes
    before its last tamping (:func:`_after_tamping`: the tamping's result is not measured yet); the peak NaN
    where the run gives none. There the model's own reading at the start stands."""
    sd, peak, age = (np.full(line.n_sections, math.nan) for _ in range(3))
    for j, s in enumerate(line.sections):
        ms = line.measurements(s.id)
        if not ms:
            continue
        last = ms[-1]
        years = line.years_before(last.date)
        if not _after_tamping(line, s, last):
            continue
        sd[j], age[j] = last.sd_m, years
        peak[j] = math.nan if last.peak_mm is None else last.peak_mm * 1e-3
    return {"last_sd_m": sd, "last_peak_m": peak, "last_run_age_years": age}


def rate_multipliers(overrides: LineOverrides, drawn: np.ndarray, rate: np.ndarray,
                     config: LineConfig, weights: np.ndarray | None = None) -> np.ndarray:
    """(S,) what each section's drawn per-sleeper rates (S, n) (its register's and known wet zone's factors in,
    tamping damage out) are multiplied by, given the section factors ``drawn`` of the episode's draw: the
    file's factor over the drawn one where the file gives one; where the history is fitted, a draw from the
    posterior (the quantile of the drawn factor under the prior, lognormal with log-SD ``rate_sigma``, taken to
    the same quantile of the posterior) times the class's typical rate-field roughness over this draw's, so
    that the draw's settlement grows as the history says whatever its hidden field (its local defects
    included: the roughness weighs the sleepers as the section's SD does, ``weights`` of :func:`sd_weights`;
    None: the segment's own); else 1."""
    o = overrides
    out = np.where(np.isnan(o.rate_factor), 1.0, o.rate_factor / drawn)
    fitted = np.flatnonzero(~np.isnan(o.rate_cdf[:, 0]))
    if fitted.size:
        sigma = config.rate_sigma
        z = (np.log(drawn[fitted]) + sigma**2 / 2) / sigma if sigma > 0 else np.zeros(fitted.size)
        k = np.array([math.exp(float(np.interp(ndtr(zj), o.rate_cdf[j], np.log(RATE_GRID))))
                      for zj, j in zip(z, fitted, strict=True)])
        w = None if weights is None else weights[fitted]
        out[fitted] = k * o.roughness[fitted] / roughness(rate[fitted], w)
    return out


def roughness(rate: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """(rows,) the SD of the D1 of per-sleeper rate factors (rows, n): how unevenly a segment settles. The
    settlement's D1 SD in the engine follows it closely (its log correlates at 0.97 with the dynamic
    settlement's after three years over 48 draws of a plain section), so it carries a history's growth into an
    episode's draw of the hidden field. With ``weights`` (:func:`sd_weights`), the SD as the section's is taken
    (its local defects once in its length)."""
    return weighted_sd(_centred_d1(rate), weights)


def sd_weights(near: np.ndarray, length_m: np.ndarray, config: LineConfig) -> np.ndarray | None:
    """(rows, n) the weight of each sleeper's squared D1 deviation in the SD of the section a segment represents,
    as the engine takes it (``LineBatch._segment_sd``) with ``local_defect_near_m``: the sleepers within that
    reach of a local defect (``near``, (rows, n) bool) share w / L, the rest (L − w) / L, w their length and L
    the section's (``length_m``, (rows,)); a segment without a defect, or all near one, uniform. None where
    ``local_defect_near_m`` is 0: the segment's own SD (uniform weights), computed as before. Each row sums
    to 1."""
    if config.local_defect_near_m == 0:
        return None
    near = np.asarray(near, dtype=bool)
    n = near.shape[1]
    n_near = near.sum(axis=1)
    n_far = n - n_near
    share = np.minimum(n_near * SLEEPER_SPACING_M, length_m) / length_m
    split = (n_near > 0) & (n_far > 0)
    w_near = np.where(split, share / np.maximum(n_near, 1), 1.0 / n)
    w_far = np.where(split, (1.0 - share) / np.maximum(n_far, 1), 1.0 / n)
    return np.where(near, w_near[:, None], w_far[:, None])


def weighted_sd(d1: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """(rows,) the SD of ``d1`` (rows, n) about each row's mean, its squared deviations weighted by ``weights``
    (:func:`sd_weights`; None: uniform, ``d1.std(axis=1)``)."""
    if weights is None:
        return d1.std(axis=1)
    dev = d1 - d1.mean(axis=1, keepdims=True)
    return np.sqrt((weights * dev * dev).sum(axis=1))


def _line(config: LineConfig) -> LineDescription:
    if config.line is None:
        raise ValueError("the config has no line file (LineConfig(line=...))")
    return config.line


# ---------------------------------------------------------------------- the fit
@dataclass(frozen=True, eq=False)
class _Growth:
    """A class's growth from its simulations: φ(t) [m] on the step grid for the class's typical rate-field
    ``roughness`` (k = 1), the log-SD of that roughness between draws, and ρ per step and draw (steps, draws)."""

    phi: np.ndarray
    roughness: float
    roughness_sd: float
    rho: np.ndarray

    def rho_prior(self, years: float, steps_per_year: int) -> tuple[float, float]:
        """The mean and SD of ρ over the draws and the steps up to ``years`` after the tamping (a section's own
        span, so that its prior does not depend on how long another section of its class was simulated)."""
        n = min(max(int(math.ceil(years * steps_per_year - 1e-9)), 1), self.rho.shape[0])
        return float(self.rho[:n].mean()), float(self.rho[:n].std())


@lru_cache(maxsize=16)
def history_fit(config: LineConfig) -> HistoryFit:
    """Each section's rate factor conditioned on its measured history (see the module docstring); cached per
    config. A line without history gives every section the status "no history" and simulates nothing.

    A section's fit uses its own history and its own class's simulations only (each class simulated alone, ρ's
    prior over the section's own span), so editing one section's history or ``years_since_tamping`` moves no
    other section's fit or start. Warns (:class:`FitWarning`) where a section's file contradicts its history (the
    module docstring lists the checks); the table's ``note`` says the same."""
    line = _line(config)
    points = {s.id: _points(line, s) for s in line.sections}
    need = {s.id for s in line.sections if s.years_since_tamping <= FIT_MAX_YEARS
            and (len(points[s.id][1]) >= 2 or (len(points[s.id][1]) == 1 and s.rate_factor is not None))}
    spans: dict[tuple[str, bool, float, float, float], float] = {}
    for s in line.sections:
        if s.id in need:
            cls = _class_of(line, s)
            spans[cls] = max(spans.get(cls, 0.0), s.years_since_tamping)
    growth = {cls: _growth(config, cls, years) for cls, years in spans.items()}
    out, cdf = [], np.full((line.n_sections, RATE_GRID.size), np.nan)
    rough = np.full(line.n_sections, np.nan)
    for j, s in enumerate(line.sections):
        t, sd = points[s.id]
        drop = _drop_note(line, s, config)
        note = "; ".join(n for n in (_untamped_note(s), _tamping_note(line, s), drop, _low_sd_note(line, s)) if n)
        if not line.measurements(s.id):
            fit = SectionFit(s.id, "no history")
        elif s.id in need:
            g = growth[_class_of(line, s)]
            fit, cdf_j = _fit_section(s, t, sd, g, config)
            if cdf_j is not None:
                cdf[j], rough[j] = cdf_j, g.roughness
            poor = "" if drop else _poor_fit_note(fit, config)  # (a drop explains a poor fit: said once)
            note = "; ".join(n for n in (note, _given_note(s, fit, config), poor) if n)
        elif len(sd) >= 1:
            fit = SectionFit(s.id, "start SD only", points=1, start_sd_mm=float(sd[-1]) * 1e3)
        else:
            fit = SectionFit(s.id, "not fitted")
        if note:
            warnings.warn(f"{line.source}, section {s.id}: {note}", FitWarning, stacklevel=2)
            fit = replace(fit, note=note)
        out.append(fit)
    return HistoryFit(tuple(out), cdf, rough)


def _given_note(s: Section, fit: SectionFit, config: LineConfig) -> str:
    """Where the file's ``rate_factor`` contradicts the history: its curve's residual exceeds the fitted
    factor's by more than :data:`FIT_CONFLICT_ERRORS` times the fit's error (the car's and the model's), a
    sentence naming both factors and residuals; else ""."""
    if fit.status != "given" or math.isnan(fit.fitted_residual_mm):
        return ""
    error_mm = _fit_error_mm(config)
    if fit.residual_mm - fit.fitted_residual_mm <= FIT_CONFLICT_ERRORS * error_mm:
        return ""
    return (f"rate_factor {fit.rate_factor:g} contradicts the history: its curve misses the measured SD by "
            f"{fit.residual_mm:.3f} mm RMS, the fitted factor {fit.fitted_rate_factor:.2f} by "
            f"{fit.fitted_residual_mm:.3f} mm (more than {FIT_CONFLICT_ERRORS:g} x the fit's error of "
            f"{error_mm:.3f} mm apart); the given factor is used: check it or leave it blank to fit it")


def _untamped_note(s: Section) -> str:
    """Where the section was last tamped more than :data:`FIT_LONG_UNTAMPED_YEARS` before ``as_of``: a sentence
    asking for the unit; else ""."""
    if s.years_since_tamping <= FIT_LONG_UNTAMPED_YEARS:
        return ""
    return (f"years_since_tamping {s.years_since_tamping:g}: no tamping in more than "
            f"{FIT_LONG_UNTAMPED_YEARS:g} years is rare on track under traffic; is it given in months? (the "
            f"section starts settled by {s.years_since_tamping:g} years of its traffic)")


def _tamping_note(line: LineDescription, s: Section) -> str:
    """Where the history shows no drop across the section's last tamping (``years_since_tamping`` before
    ``as_of``): its SD rose over its last two runs before that date and rose on across it, by at least
    :data:`FIT_NO_DROP_SHARE` of that rate; a sentence naming the runs; else "". (A tamping lowers the SD or at
    least slows its growth; a run on the tamping's date counts as before it, as in the fit.)"""
    ms = line.measurements(s.id)
    after = [m for m in ms if _after_tamping(line, s, m)]
    before = ms[:len(ms) - len(after)]
    if len(before) < 2 or not after:
        return ""
    (b1, b2), a1 = before[-2:], after[0]
    rate_before = (b2.sd_mm - b1.sd_mm) / (line.years_before(b1.date) - line.years_before(b2.date))
    rate_across = (a1.sd_mm - b2.sd_mm) / (line.years_before(b2.date) - line.years_before(a1.date))
    if rate_before <= 0 or rate_across < FIT_NO_DROP_SHARE * rate_before:
        return ""
    tamped = _tamping_date(line, s)
    return (f"the history shows no drop across the last tamping that years_since_tamping "
            f"{s.years_since_tamping:g} puts on {tamped}: {b1.sd_mm:g}, {b2.sd_mm:g} mm before it "
            f"({b1.date}, {b2.date}), {a1.sd_mm:g} mm after ({a1.date}); check years_since_tamping (the fit "
            f"uses the runs after that date only)")


def _drop_note(line: LineDescription, s: Section, config: LineConfig) -> str:
    """Where the SD drops between two runs after the stated last tamping by more than :data:`FIT_DROP_ERRORS`
    times the fit's error and :data:`FIT_DROP_SHARE` of the SD before: a tamping the file does not state, a
    sentence naming the runs (the largest such drop); else ""."""
    ms = [m for m in line.measurements(s.id) if _after_tamping(line, s, m)]
    error_mm = _fit_error_mm(config)
    drops = [(a.sd_mm - b.sd_mm, a, b) for a, b in zip(ms[:-1], ms[1:], strict=True)
             if a.sd_mm - b.sd_mm > max(FIT_DROP_ERRORS * error_mm, FIT_DROP_SHARE * a.sd_mm)]
    if not drops:
        return ""
    _, a, b = max(drops, key=lambda d: d[0])
    tamped = _tamping_date(line, s)
    return (f"the SD drops from {a.sd_mm:g} to {b.sd_mm:g} mm between the runs of {a.date} and {b.date}, after "
            f"the last tamping that years_since_tamping {s.years_since_tamping:g} puts on {tamped}: a "
            f"tamping the file does not state? The fit runs one settlement curve through the drop; check "
            f"years_since_tamping")


def _poor_fit_note(fit: SectionFit, config: LineConfig) -> str:
    """Where the fitted curve misses the section's runs by more than :data:`FIT_POOR_ERRORS` times the fit's
    error (RMS): a sentence saying so; else ""."""
    error_mm = _fit_error_mm(config)
    if fit.status != "fitted" or not fit.residual_mm > FIT_POOR_ERRORS * error_mm:
        return ""
    return (f"the fitted curve misses the measured SD by {fit.residual_mm:.3f} mm RMS, more than "
            f"{FIT_POOR_ERRORS:g} x the fit's error of {error_mm:.3f} mm: the runs since the last tamping follow no "
            f"one settlement curve; check their dates and SDs and years_since_tamping")


def _low_sd_note(line: LineDescription, s: Section) -> str:
    """Where every run of the section measures an SD below :data:`FIT_LOW_SD_MM`: a sentence asking for the
    unit; else ""."""
    ms = line.measurements(s.id)
    if not ms or max(m.sd_mm for m in ms) >= FIT_LOW_SD_MM:
        return ""
    return (f"every run measures an SD below {FIT_LOW_SD_MM:g} mm (at most {max(m.sd_mm for m in ms):g} mm), less "
            f"than tamped track measures (about 0.5 mm and more): is sd_mm given in cm?")


def _fit_error_mm(config: LineConfig) -> float:
    """The fit's error of one SD reading [mm]: the recording car's ``sd_noise_mm`` and the model error
    :data:`FIT_MODEL_ERROR_MM` in quadrature (the likelihood's, and the scale of every check's threshold)."""
    return math.hypot(config.sd_noise_mm, FIT_MODEL_ERROR_MM)


def _tamping_date(line: LineDescription, s: Section) -> str:
    """The date (ISO) of section ``s``'s last tamping as its ``years_since_tamping`` puts it before ``as_of``."""
    as_of = dt.date.fromisoformat(line.as_of)
    return (as_of - dt.timedelta(days=round(s.years_since_tamping * DAYS_PER_YEAR))).isoformat()


def _after_tamping(line: LineDescription, s: Section, m: Any) -> bool:
    """Whether the run ``m`` of section ``s`` comes after its last tamping. A run less than
    :data:`FIT_SAME_DAYS` days after it counts as before it (the tamping may be that run's reason, and years
    since tamping are often rounded)."""
    return s.years_since_tamping - line.years_before(m.date) > FIT_SAME_DAYS / DAYS_PER_YEAR


def _points(line: LineDescription, s: Section) -> tuple[np.ndarray, np.ndarray]:
    """A section's measurements after its last tamping (:func:`_after_tamping`): (years since that tamping,
    SD [m])."""
    ms = [m for m in line.measurements(s.id) if _after_tamping(line, s, m)]
    t = np.array([s.years_since_tamping - line.years_before(m.date) for m in ms])
    sd = np.array([m.sd_m for m in ms])
    return t, sd


def _class_of(line: LineDescription, s: Section) -> tuple[str, bool, float, float, float]:
    """What the growth of a section's SD depends on besides its rate: register, known wet zone, traffic (its
    tonnage over the line's, its speed, its freight share)."""
    return (s.register, s.wet, s.annual_mgt / line.annual_mgt, s.speed_kmh, s.freight_share)


def _fit_section(s: Section, t: np.ndarray, sd: np.ndarray, growth: _Growth,
                 config: LineConfig) -> tuple[SectionFit, np.ndarray | None]:
    """The posterior of (k, ρ, SD₀) on the grid (k fixed where the file gives it, and fitted as well to compare):
    the section's fit and the CDF of k (None where k is given)."""
    grid_t = np.arange(growth.phi.size) / config.steps_per_year
    phi = np.interp(t, grid_t, growth.phi)
    phi_now = float(np.interp(s.years_since_tamping, grid_t, growth.phi))
    damage = (1.0 + config.tamping_model.damage_per_tamping) ** (s.tampings_since_renewal - 1)
    rho_mean, rho_sd = growth.rho_prior(s.years_since_tamping, config.steps_per_year)
    # the prior of k: the section factor's (lognormal) times the spread of the hidden field's roughness
    sigma_k = math.hypot(max(config.rate_sigma, 0.05), growth.roughness_sd)
    mean_k = -config.rate_sigma**2 / 2
    sigma_e = _fit_error_mm(config) * 1e-3
    sd0_grid = np.linspace(0.0, 1.5 * float(sd.max()), SD0_POINTS)

    def posterior(rates: np.ndarray) -> tuple[np.ndarray, dict[str, Any]]:
        """The log posterior on (rates, ρ, SD₀) and its most probable curve's fields of a SectionFit."""
        kappa = rates * damage
        log_prior = (-(np.log(rates) - mean_k) ** 2 / (2 * sigma_k**2))[:, None] \
            - ((RHO_GRID - rho_mean) ** 2 / (2 * max(rho_sd, 0.05) ** 2))[None, :]
        kp = kappa[:, None, None] * phi[None, None, :]  # (k, 1, points)
        rho = RHO_GRID[None, :, None]
        log_post = np.empty((rates.size, RHO_GRID.size, sd0_grid.size))
        for i, s0 in enumerate(sd0_grid):
            model = np.sqrt(np.maximum(s0 * s0 + 2 * rho * s0 * kp + kp * kp, 0.0))
            log_post[:, :, i] = log_prior - ((model - sd) ** 2).sum(axis=-1) / (2 * sigma_e**2)
        ik, ir, i0 = np.unravel_index(int(np.argmax(log_post)), log_post.shape)
        k_map, rho_map, s0 = kappa[ik], RHO_GRID[ir], sd0_grid[i0]
        curve = np.sqrt(np.maximum(s0 * s0 + 2 * rho_map * s0 * k_map * phi + (k_map * phi) ** 2, 0.0))
        start = math.sqrt(max(s0 * s0 + 2 * rho_map * s0 * k_map * phi_now + (k_map * phi_now) ** 2, 0.0))
        return log_post, {"points": len(sd), "rho": float(rho_map), "sd_after_tamping_mm": float(s0) * 1e3,
                          "residual_mm": float(np.sqrt(np.mean((curve - sd) ** 2))) * 1e3,
                          "start_sd_mm": start * 1e3}

    log_post, common = posterior(RATE_GRID)
    weight = np.exp(log_post - log_post.max()).sum(axis=(1, 2))
    cdf = np.cumsum(weight + 1e-12 * weight.sum())
    cdf /= cdf[-1]
    log_k = np.log(RATE_GRID)
    p10, p50, p90 = (math.exp(float(np.interp(q, cdf, log_k))) for q in (0.1, 0.5, 0.9))
    if s.rate_factor is None:
        return SectionFit(s.id, "fitted", rate_factor=p50, rate_p10=p10, rate_p90=p90, **common), cdf
    k = float(s.rate_factor)
    _, given = posterior(np.array([k]))
    return SectionFit(s.id, "given", rate_factor=k, rate_p10=k, rate_p90=k, fitted_rate_factor=p50,
                      fitted_residual_mm=common["residual_mm"], **given), None


def _growth(config: LineConfig, cls: tuple[str, bool, float, float, float], years: float) -> _Growth:
    """A class's :class:`_Growth` from the engine (k = 1, one tamping since renewal), every step from the
    tamping up to ``years``: a line of one section of the class, simulated alone, so that its draws are the same
    whichever other classes the line has (a simulation's first steps do not depend on how many follow)."""
    line = _line(config)
    steps = max(int(math.ceil(years * config.steps_per_year - 1e-9)), 1)
    reg, wet, factor, speed, share = cls
    proto_section = Section(id="class", length_m=line.section_length_m, register=reg, wet=wet,
                            annual_mgt=line.annual_mgt * factor, speed_kmh=speed, freight_share=share,
                            years_since_tamping=FIT_PREVIOUS_CYCLE_YEARS, tampings_since_renewal=0, rate_factor=1.0)
    proto_line = replace(line, sections=(proto_section,), history=(), source=f"{line.source} (fit)")
    # without local defects: a defect's settlement runs away on some draws (its dynamic force feeds it: 5-10 times
    # the settlement per roughness of the others, 30 mm SD in a year next to a transition's stiff half), so the
    # class's mean curve would follow those draws and no section's history; the fit is of the section's own
    # field, as without defects, and the episode's draw (its defects included) is scaled to it
    # (the same for a file's known defects: a section's SD weighs them as drawn ones, the proto keeps the reach;
    # the proto's section gives no count, so the file's reach, local_defect_near_m, is not the proto line's)
    proto = config.replace(line=proto_line, wet_spot_probability=0.0, horizon_years=steps / config.steps_per_year,
                           local_defects_mean=0.0, local_defect_near_m=config.local_defect_near_m)
    phi, rough, rough_sd, rho = _simulated_growth(proto, steps)
    return _Growth(phi[0], float(rough[0]), float(rough_sd[0]), rho[0])


@lru_cache(maxsize=64)
def _simulated_growth(proto: LineConfig, steps: int) -> tuple[np.ndarray, ...]:
    """Run :data:`FIT_DRAWS` lines of ``proto`` (one section per class): tamp every section, then ``steps`` steps
    of traffic. Per class: φ (classes, steps + 1) [m], the settlement's D1 SD per unit of the rate field's
    roughness averaged over the draws, times the draws' typical (geometric mean) roughness; the log-SD of the
    roughness; ρ (classes, steps, draws)."""
    from .line_episode import LineBatch  # the engine builds on this module's overrides

    S = proto.n_sections
    batch = LineBatch(proto, FIT_DRAWS)
    batch.start(list(range(FIT_DRAWS)), [np.random.default_rng([FIT_SEED, i]) for i in range(FIT_DRAWS)])
    every = np.ones(FIT_DRAWS * S, dtype=bool)
    batch.tamp_rows(every, 0)

    def rows(name: str) -> np.ndarray:
        return np.concatenate([batch.get_state(b).rows[name] for b in range(FIT_DRAWS)])

    # the SDs as the engine measures the section's (its local defects once in its length, where counted so)
    weights = sd_weights(rows("defect_near"), proto.section_length_m * rows("length_factor"), proto)
    shape, rough = _centred_d1(rows("offset")), roughness(rows("base_rate"), weights)
    shape_sd = weighted_sd(shape, weights)
    per_rough, rho = [np.zeros(FIT_DRAWS * S)], []
    for step in range(steps):
        batch.traffic_rows(every, step)
        settled = _centred_d1(rows("u"))
        sd = weighted_sd(settled, weights)
        per_rough.append(sd / rough)
        cov = (shape * settled).mean(axis=1) if weights is None else (weights * shape * settled).sum(axis=1)
        rho.append(cov / (shape_sd * sd + 1e-300))
    log_rough = np.log(rough).reshape(FIT_DRAWS, S)
    typical = np.exp(log_rough.mean(axis=0))
    phi = np.array(per_rough).reshape(steps + 1, FIT_DRAWS, S).mean(axis=1).T * typical[:, None]
    rho_all = np.array(rho).reshape(steps, FIT_DRAWS, S).transpose(2, 0, 1)
    return phi, typical, log_rough.std(axis=0), rho_all


def _centred_d1(level: np.ndarray) -> np.ndarray:
    d1 = d1_filter(level, SLEEPER_SPACING_M)
    return d1 - d1.mean(axis=1, keepdims=True)


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
                 start_sd: np.ndarray, weights: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """A section's post-tamping ``shape`` and its ``settled`` level since (rows, n) [m] scaled so that it starts
    at the SD its history gives, ``start_sd`` [m] per row: the shape to the fitted SD right after tamping
    ``sd_after_tamping`` (where fitted; NaN: as drawn), then the settlement to the start SD; where the shape
    is rougher than that on its own, the shape instead (with the settlement at its least rough scale). Each SD
    is the section's as the engine measures it: with ``weights`` (:func:`sd_weights`, (rows, n)), its local
    defects once in its length; None, the segment's own. Returns the new (shape, settled)."""
    shape, settled = shape.copy(), settled.copy()
    sd0 = np.asarray(sd_after_tamping, dtype=float)
    fitted = ~np.isnan(sd0)
    if fitted.any():  # the D1 filter is homogeneous (D1(s·z) = s·D1(z)): a ratio of SDs scales it exactly
        own = weighted_sd(d1_filter(shape[fitted], SLEEPER_SPACING_M), None if weights is None else weights[fitted])
        shape[fitted] *= (sd0[fitted] / np.maximum(own, 1e-12))[:, None]
    s, reached = scale_to(settled, shape, start_sd, weights)
    settled *= s[:, None]
    if not reached.all():
        rest = ~reached
        s_shape, _ = scale_to(shape[rest], settled[rest], np.asarray(start_sd)[rest],
                              None if weights is None else weights[rest])
        shape[rest] *= s_shape[:, None]
    return shape, settled


def scale_to(x: np.ndarray, y: np.ndarray, target_sd: np.ndarray,
             weights: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(rows,) the factor s ≥ 0 per row with SD of D1(s·x + y) = ``target_sd`` [m], and whether it was reached.
    Were the D1 filter linear, SD² = s²·var(a) + 2s·cov(a, b) + var(b) with a, b the D1 of x and y, a quadratic
    in s: its root starts a secant iteration on the filter itself (whose end padding is fitted to the record,
    so it is additive only nearly) to 0.1 % of the target. Where no s reaches the target, the s of the least
    SD. With ``weights`` (:func:`sd_weights`) the SD weighs the squared deviations by them (the section's SD
    with its local defects once), the same quadratic with weighted moments."""
    target = np.asarray(target_sd, dtype=float)
    a = d1_filter(x, SLEEPER_SPACING_M)
    b = d1_filter(y, SLEEPER_SPACING_M)
    a = a - a.mean(axis=1, keepdims=True)
    b = b - b.mean(axis=1, keepdims=True)
    if weights is None:
        va, cab, vb = (a * a).mean(axis=1), (a * b).mean(axis=1), (b * b).mean(axis=1)
    else:
        va, cab, vb = (weights * a * a).sum(axis=1), (weights * a * b).sum(axis=1), (weights * b * b).sum(axis=1)
    va = np.maximum(va, 1e-30)
    disc = cab * cab - va * (vb - target**2)
    s = np.maximum(np.where(disc >= 0, (-cab + np.sqrt(np.maximum(disc, 0.0))) / va, -cab / va), 0.0)

    def miss(scale: np.ndarray) -> np.ndarray:
        return weighted_sd(d1_filter(scale[:, None] * x + y, SLEEPER_SPACING_M), weights) - target

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
