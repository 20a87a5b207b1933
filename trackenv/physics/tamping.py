"""Tamping: what a tamping machine does to the per-sleeper rail level and to later settlement.

Model (all coefficients are parameters of :class:`TampingModel`; defaults are assumptions, see there):

* **Partial restoration with ballast memory.** A tamping machine lifts the rail towards a reference line and
  packs ballast under the sleepers, but the result depends on the geometry before: Audley & Andrews (2013) fit
  ``SD_after = alpha + beta * SD_before`` with ``beta < 1`` to UK recording-car data, and RTRI reports that
  the irregularity "gradually returns to its original shape after tamping" (ballast memory). We keep a
  fraction ``beta = residual_fraction`` of the old shape about the reference line ``f`` and add an independent
  random residual of SD ``alpha = residual_sd_m`` (the machine's own error)::

      reference="smoothing":  target_i = f_i + beta * (z_i - f_i) + alpha * e_i,   e_i ~ N(0, 1)
      reference="design":     target_i =       beta * (z_i - f_i) + alpha * e_i

  where ``z`` is the level before (m, downward positive, relative to the design line). In ``"smoothing"``
  mode (default) the machine's long reference chord rests on the untamped track beyond the run, as in
  maintenance tamping of a short site, so ``f`` is the straight line through the two untamped neighbours
  (through the one neighbour with least-squares slope if the run reaches an end of the array; the
  least-squares line if the whole array is tamped) and the run stays at that line: the irregularity is
  reduced, but a uniformly settled track is not lifted back to the design level, and no lift step appears
  at the ends of the run. In ``"design"`` mode ``f`` is the least-squares straight line through ``z`` over
  each contiguous tamped run, and the run is lifted back to the design line (level 0) in mean and slope, by
  at most ``max_lift_m`` per pass (``target_i = f_i - min(f_i, max_lift_m) + ...``);
  where the neighbours have settled by ``s`` this leaves a lift step of ``s`` at each end of the run,
  spread over the run-out (a 10 mm step over 3 run-out sleepers reads as about 4 mm in the D1 signal).
  Why smoothing is the default: in the env (30 m track, three 10 m sections, 2 years untamped, SD of the
  D1 level at the end of the step, 6 seeds x 3 sections) design-mode tamping raised the tamped section's SD
  in 11 of 18 cases (mean ratio tamped/untamped 1.38), smoothing in 7 of 18 (mean ratio 0.90; the rest is
  the residual and the restarted consolidation on already good sections, which Audley & Andrews'
  ``alpha + beta * SD`` form also predicts for ``SD < alpha/(1 - beta)``).
  Levels are relative to the design line; the extra overall lift a real machine adds so that it never has
  to push a sleeper down (it can only raise the track) is a constant offset, which the vehicle does not
  feel, and is not modelled. That holds where the whole array is tamped (every section of the envs); a run
  shorter than the array keeps its untamped neighbours' level in ``"smoothing"`` mode and then, its
  consolidation restarted, settles below them (an evenly settled track tamped over sleepers 25-35 of 51:
  3.8 mm before, 7.9 mm after the next 1e5 cycles, a dip a real site's overlift would not leave): model such
  a site with ``reference="design"`` (lifted to the design line, the ends ramped).
* **Run-out ramp.** Real tampers ramp the lift in and out at the ends of a work site instead of leaving a
  step. Inside each tamped run, the ``runout_sleepers`` sleepers next to an *untamped* neighbour receive a
  linearly growing fraction of the full lift: ``new_i = (1 - w_i) * z_i + w_i * target_i`` with
  ``w_i = min(1, d_i / (runout_sleepers + 1))`` and ``d_i`` the distance in sleepers to the nearest untamped
  neighbour (1 for the first tamped sleeper). Runs that reach the ends of the array are not ramped there
  (the track beyond is not modelled). Untamped sleepers are never changed.
* **Consolidation restarts.** Tamping loosens the ballast bed, so the settlement law restarts its fast
  initial phase on the tamped sleepers (``restarted_mask``; the settlement model acts on it).
* **Ballast damage.** Tamping breaks ballast (aggregate degradation and fouling up to ~40 % reported by SNCF),
  so each tamping makes later settlement faster. Assumed geometric growth: the settlement-rate factor is
  ``(1 + damage_per_tamping) ** n`` after ``n`` tampings since renewal **[assumption]**. When a sleeper due
  for tamping has already had ``max_tampings_before_renewal`` tampings (default 8, in the 5-10 range of
  practice **[assumption]**) and ``renewal_resets`` is true, the intervention is a ballast renewal instead:
  the count and the rate factor reset (0 and 1) and, since fresh ballast has no memory, the old shape is not
  kept (``beta = 0`` for those sleepers).

Tamping machines work at about 0.5-2.2 km/h (Railway Gazette and manufacturers' figures);
:meth:`TampingModel.duration_s` converts a tamped length to machine time with ``machine_speed_m_per_s``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from trackenv.physics._checks import (
    check_array,
    check_bool,
    check_choice,
    check_field,
    check_int_field,
    check_scalar,
    dataclass_from_dict,
)

__all__ = ["TampingModel", "TampingResult", "tamp", "restored_level", "sd_after_tamping", "tamped_runs"]


@dataclass(frozen=True)
class TampingModel:
    """Parameters of the tamping model (see the module docstring for the equations).

    Attributes
    ----------
    residual_fraction : float
        ``beta`` in [0, 1]: fraction of the pre-tamping shape (about the reference line ``f``) left after
        tamping.
        Default 0.3 **[assumption]**, within the 0.2-0.5 suggested by ballast-memory observations (RTRI) and
        of the order of the Audley & Andrews (2013) slope **[unverified]**.
    residual_sd_m : float
        ``alpha`` [m], >= 0: SD of the machine's random, sleeper-to-sleeper independent residual error.
        Default 0.5 mm **[assumption]** (Audley & Andrews' intercept is of this order **[unverified]**).
    damage_per_tamping : float
        >= 0: each tamping multiplies the tamped sleepers' settlement rate by ``1 + damage_per_tamping``.
        Default 0.15 **[assumption]** (ballast breakage per tamping; SNCF reports fouling up to 40 %).
    max_tampings_before_renewal : int
        >= 1: tampings a sleeper takes before the next intervention is a renewal. Default 8 **[assumption]**,
        practice is about 5-10.
    renewal_resets : bool
        Whether renewal happens (resets count, rate factor and memory). Default True.
    runout_sleepers : int
        >= 0: length of the lift ramp at the ends of a tamped run next to untamped track. Default 3
        **[assumption]** (real run-out ramps are set by a maximum lift gradient; 0 disables the ramp).
    machine_speed_m_per_s : float
        > 0: working speed of the tamping machine. Default 1 km/h = 0.2778 m/s, within the 0.5-2.2 km/h of
        practice (Railway Gazette and manufacturers' figures).
    reference : {"smoothing", "design"}
        Line the machine restores (module docstring). Default "smoothing": the chord through the untamped
        neighbours (no lift step against settled neighbours); "design": lift to the design line (level 0),
        leaving a ramped lift step where the neighbours have settled.
    max_lift_m : float
        > 0 [m]: largest lift of the reference line toward the design line in one pass ("design" reference).
        Ballast packed under a sleeper lifted by more than a few centimetres at once is unstable and settles
        back quickly, so machines lift large settlements in several passes. Default ``inf`` (no limit: the
        line is lifted to the design level in one pass, as before this field existed); 0.05 m is a typical
        working maximum per pass **[assumption]**.
    """

    residual_fraction: float = 0.3
    residual_sd_m: float = 0.5e-3
    damage_per_tamping: float = 0.15
    max_tampings_before_renewal: int = 8
    renewal_resets: bool = True
    runout_sleepers: int = 3
    machine_speed_m_per_s: float = 1.0 / 3.6
    reference: str = "smoothing"
    max_lift_m: float = math.inf

    def __post_init__(self) -> None:
        check_field(self, "residual_fraction", low=0.0, high=1.0)
        check_field(self, "residual_sd_m", low=0.0, high=0.1)
        check_field(self, "damage_per_tamping", low=0.0, high=10.0)
        check_int_field(self, "max_tampings_before_renewal", low=1, high=1000)
        check_int_field(self, "runout_sleepers", low=0, high=1000)
        object.__setattr__(self, "renewal_resets", check_bool("renewal_resets", self.renewal_resets))
        check_field(self, "machine_speed_m_per_s", low=0.0, high=10.0, low_inclusive=False)
        check_choice("reference", self.reference, ("smoothing", "design"))
        if self.max_lift_m != math.inf:
            check_field(self, "max_lift_m", low=0.0, high=1.0, low_inclusive=False)

    @classmethod
    def from_dict(cls, d: Mapping) -> TampingModel:
        """Build from a mapping of field names to values; an unknown key raises ValueError naming it."""
        return dataclass_from_dict(cls, d)

    def rate_factor(self, tampings) -> np.ndarray:
        """Settlement-rate factor ``(1 + damage_per_tamping) ** tampings`` for tamping counts ``tampings``."""
        t = _check_counts("tampings", tampings, None)
        return (1.0 + self.damage_per_tamping) ** t

    def duration_s(self, length_m: float) -> float:
        """Machine time [s] to tamp ``length_m`` metres of track at ``machine_speed_m_per_s``."""
        return check_scalar("length_m", length_m, low=0.0) / self.machine_speed_m_per_s


@dataclass(frozen=True, eq=False)
class TampingResult:
    """Outcome of :func:`tamp` (fresh arrays, shape (n,), safe to modify).

    Attributes
    ----------
    level : float array [m]
        Rail level after tamping (downward positive, relative to the design line).
    rate_factor : float array
        Settlement-rate multiplier per sleeper, ``(1 + damage_per_tamping) ** tampings``.
    tampings : int array
        Tampings since the last renewal per sleeper.
    restarted_mask : bool array
        Sleepers whose consolidation restarts (the tamped ones).
    renewed_mask : bool array
        Sleepers whose ballast was renewed instead of tamped.
    lift : float array [m]
        ``level_before - level_after`` (positive = raised), 0 on untamped sleepers. Tells a settlement model
        with ballast memory where, and how much, the old shape was removed.
    """

    level: np.ndarray
    rate_factor: np.ndarray
    tampings: np.ndarray
    restarted_mask: np.ndarray
    renewed_mask: np.ndarray
    lift: np.ndarray


def _check_counts(name: str, value, shape) -> np.ndarray:
    arr = np.asarray(value)
    if arr.dtype == np.bool_:
        raise ValueError(f"{name} must be an array of integers >= 0, got booleans")
    if arr.dtype.kind in "iu" and (shape is None or arr.shape == shape):  # integers: only the sign to check
        if arr.size and arr.min() < 0:
            raise ValueError(f"{name} must be >= 0 everywhere, got min {arr.min()}")
        return arr.astype(np.int64)
    f = check_array(name, arr, shape=shape, low=0.0)
    if np.any(f != np.round(f)):
        raise ValueError(f"{name} must hold integers >= 0")
    return f.astype(np.int64)


def tamped_runs(mask) -> np.ndarray:
    """Contiguous runs of True in a 1-D bool ``mask`` as an (m, 2) int array of [start, stop) pairs."""
    m = np.asarray(mask, dtype=bool)
    padded = np.zeros(m.size + 2, dtype=np.int8)
    padded[1:-1] = m
    edges = np.flatnonzero(np.diff(padded))  # starts and stops alternate
    return edges.reshape(-1, 2).astype(np.int64)


def line_fit_rows(z: np.ndarray) -> np.ndarray:
    """Least-squares straight line of each row of ``z`` (..., n) against the sample index, row by row (a matrix
    product's rounding would depend on the number of rows, and a row's numbers must not depend on its batch)."""
    n = z.shape[-1]
    t = np.arange(n, dtype=np.float64) - 0.5 * (n - 1)
    slope = (z * t).sum(axis=-1) / float(t @ t)
    return z.mean(axis=-1, keepdims=True) + slope[..., None] * t


def _line_fit(y: np.ndarray) -> np.ndarray:
    """Least-squares straight line through ``y`` against its index (the mean when fewer than 2 points)."""
    if y.size < 2:
        return np.full_like(y, y.mean())
    return line_fit_rows(y)


def _anchored_line(z: np.ndarray, start: int, stop: int) -> np.ndarray:
    """Reference line over ``z[start:stop]`` resting on the untamped neighbours ``start - 1`` and ``stop``."""
    n = z.size
    i = np.arange(start, stop, dtype=np.float64)
    left, right = start > 0, stop < n
    if left and right:
        a, b = start - 1, stop
        return z[a] + (z[b] - z[a]) * (i - a) / (b - a)
    if not (left or right):
        return _line_fit(z[start:stop])
    a = start - 1 if left else stop
    t = i - a
    slope = float(t @ (z[start:stop] - z[a])) / float(t @ t)
    return z[a] + slope * t


def restored_level(level: np.ndarray, mask: np.ndarray, model: TampingModel, noise: np.ndarray,
                   renewed: np.ndarray) -> np.ndarray:
    """The level after tamping, row by row: the model of the module docstring on each row of ``level`` (rows, n)
    [m] for the sleepers in ``mask`` (rows, n) bool, with the machine's residual ``model.residual_sd_m * noise``
    (``noise`` (rows, n): standard normals, given so that a caller can draw them in advance) and no memory of
    the old shape where ``renewed`` (rows, n). The one implementation of the restoration (:func:`tamp` and the
    episode engine call it). Rows tamped over their whole length (the reference line is the least-squares line
    of the row, no run-out) are computed together; the others run by run. Inputs are trusted (callers check)."""
    beta = np.where(renewed, 0.0, model.residual_fraction)
    new = np.array(level, dtype=np.float64, copy=True)
    full = mask.all(axis=1)
    if full.any():
        z = level[full]
        ref = line_fit_rows(z) if z.shape[1] >= 2 else z.copy()
        base = ref - np.minimum(ref, model.max_lift_m) if model.reference == "design" else ref
        new[full] = base + beta[full] * (z - ref) + model.residual_sd_m * noise[full]
    r = model.runout_sleepers
    n = level.shape[1]
    for b in np.flatnonzero(~full & mask.any(axis=1)):
        z, row = level[b], new[b]
        for start, stop in tamped_runs(mask[b]).tolist():
            seg = z[start:stop]
            base_b: float | np.ndarray
            if model.reference == "design":
                # the line is lifted to the design level (0), by at most max_lift_m where it lies below it
                ref = _line_fit(seg)
                base_b = ref - np.minimum(ref, model.max_lift_m)
            else:
                ref = _anchored_line(z, start, stop)
                base_b = ref
            target = base_b + beta[b, start:stop] * (seg - ref) + model.residual_sd_m * noise[b, start:stop]
            k = np.arange(stop - start, dtype=np.float64)
            d_left = k + 1.0 if start > 0 else np.full_like(k, math.inf)
            d_right = (stop - start) - k if stop < n else np.full_like(k, math.inf)
            w = np.minimum(1.0, np.minimum(d_left, d_right) / (r + 1.0))
            row[start:stop] = (1.0 - w) * seg + w * target
    return new


def tamp(level, mask, model: TampingModel, rng: np.random.Generator, tampings) -> TampingResult:
    """Tamp the sleepers in ``mask``; a pure function of its inputs and ``rng``'s state.

    Parameters
    ----------
    level : array_like, shape (n,)
        Rail level [m] per sleeper before tamping, downward positive, relative to the design line; finite.
    mask : array_like of bool, shape (n,)
        Sleepers being tamped.
    model : TampingModel
    rng : numpy.random.Generator
        Draws exactly ``n`` standard normals (the residual ``e``), whatever the mask, so later draws do not
        depend on how many sleepers were tamped.
    tampings : array_like of int, shape (n,)
        Tampings since renewal per sleeper, before this one.

    Returns
    -------
    TampingResult
        Per tamped sleeper (see module docstring): ``target = [f +] beta_i * (z - f) + alpha * e`` with
        ``beta_i = residual_fraction`` (0 where renewed), ramped over ``runout_sleepers`` next to untamped
        neighbours; ``tampings + 1`` (0 where renewed); rate factor ``(1 + damage) ** tampings``. Untamped
        sleepers keep level and count.
    """
    if not isinstance(model, TampingModel):
        raise ValueError(f"model must be a TampingModel, got {type(model).__name__}")
    if not isinstance(rng, np.random.Generator):
        raise TypeError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    z = check_array("level", level)
    if z.ndim != 1 or z.size == 0:
        raise ValueError(f"level must be a non-empty 1-D array, got shape {z.shape}")
    n = z.size
    m = np.asarray(mask)
    if m.shape != (n,):
        raise ValueError(f"mask must have shape {(n,)} like level, got {m.shape}")
    if m.dtype != np.bool_:
        raise ValueError(f"mask must be a boolean array, got dtype {m.dtype}")
    count = _check_counts("tampings", tampings, (n,))

    noise = rng.standard_normal(n)

    renewed = m & (count >= model.max_tampings_before_renewal) if model.renewal_resets else np.zeros(n, bool)
    new = restored_level(z[None], m[None], model, noise[None], renewed[None])[0]

    count_after = np.where(m, count + 1, count)
    count_after = np.where(renewed, 0, count_after).astype(np.int64)
    return TampingResult(
        level=new,
        rate_factor=(1.0 + model.damage_per_tamping) ** count_after,
        tampings=count_after,
        restarted_mask=m.copy(),
        renewed_mask=renewed,
        lift=z - new,
    )


def sd_after_tamping(sd_before, model: TampingModel, *, linear: bool = False) -> np.ndarray:
    """Expected SD [m] of the level over a tamped run after tamping, given the SD before (about its fit).

    Default: the RMS expectation of :func:`tamp` away from the run-out ramps, where the kept shape and the
    independent residual add in variance: ``SD_after = sqrt(alpha^2 + (beta * SD_before)^2)``.
    ``linear=True`` gives Audley & Andrews' (2013) empirical form ``SD_after = alpha + beta * SD_before``
    with the same ``alpha = residual_sd_m``, ``beta = residual_fraction`` (an upper bound of the former; both
    agree for ``SD_before = 0`` and for ``SD_before >> alpha / beta``). ``SD_before`` is measured about the
    reference line of the run, as in :func:`tamp`; renewal (beta = 0) is not included.
    """
    if not isinstance(model, TampingModel):
        raise ValueError(f"model must be a TampingModel, got {type(model).__name__}")
    s = check_array("sd_before", sd_before, low=0.0)
    a, b = model.residual_sd_m, model.residual_fraction
    return a + b * s if linear else np.sqrt(a * a + (b * s) ** 2)
