"""Argument checks: the one mechanism every parameter of trackenv goes through.

Each check returns the value converted to its canonical type (float, int, float64 array) or raises ValueError
naming the parameter and its allowed range, so callers store what the check returns and a parameter never stays
a string or a bool. Frozen dataclasses call :func:`check_field` / :func:`check_int_field` in ``__post_init__``,
right below their fields, so a field's bound is written once, next to the field; a layer that passes a value on
(the env's config to the dynamics) reads the bound of the layer below (e.g. :data:`MAX_TIME_STEPS`) instead of
writing its own.

Not to be confused with :mod:`trackenv_studies.validation` (``trackenv validate``), which checks the *physics*
against closed forms.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from collections.abc import Mapping
from typing import Any

import numpy as np

#: Upper bound on the time steps of one vehicle pass (length / (speed · dt)). A pass stores a few arrays of
#: (time steps × axles) per row; 2 million steps (a 60 m track at 1 m/s with dt = 3e-5 s, or 2 km at 100 km/h
#: with dt = 1e-4 s) is about 16 MB per array and axle: a slower pass or a finer step is refused before anything
#: is allocated, instead of running out of memory (1 mm/s would need 4 GB per array).
MAX_TIME_STEPS = 2_000_000
#: Upper bound on time steps × axles × rows of one batched pass (about 0.4 GB per stored array).
MAX_PASS_SAMPLES = 50_000_000
#: Upper bound of a pass's speed [m/s] (720 km/h: beyond any railway; the model has no aerodynamics or
#: critical-velocity checks), read by the dynamics, the settlement loop and the paper's reproduction.
MAX_SPEED_M_PER_S = 200.0
#: Above this speed [m/s] (350 km/h: the fastest ballasted lines run at 300-320 km/h) a pass warns: the model has
#: no ballast flight or ground-wave (critical velocity) effects, and a speed in km/h given as m/s lands here.
SERVICE_SPEED_M_PER_S = 350.0 / 3.6


def _describe(value) -> str:
    return f"{value!r} ({type(value).__name__})"


def _range_text(low, high, low_inclusive=True, high_inclusive=True) -> str:
    lb = "(-inf" if low is None else ("[" if low_inclusive else "(") + f"{low:g}"
    hb = "inf)" if high is None else f"{high:g}" + ("]" if high_inclusive else ")")
    return f"{lb}, {hb}"


def check_scalar(
    name: str,
    value,
    *,
    low: float | None = None,
    high: float | None = None,
    low_inclusive: bool = True,
    high_inclusive: bool = True,
) -> float:
    """Return ``value`` as float, or raise ValueError naming ``name`` and the allowed range.

    Accepts Python and numpy real numbers (and 0-d arrays of them); refuses strings (``"1.5"`` is not converted:
    a config read as text must be parsed where it is read), bools (``True`` is not 1.0) and complex numbers. A
    Python float, the common case (the passes check several per call), skips the type tests; the range's text is
    written only for an error."""
    if type(value) is float:
        v = value
    else:
        if isinstance(value, np.ndarray) and value.ndim == 0:
            value = value[()]
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
            rng = _range_text(low, high, low_inclusive, high_inclusive)
            raise ValueError(f"{name} must be a real number in {rng}, got {_describe(value)}")
        v = float(value)
    if not math.isfinite(v):
        rng = _range_text(low, high, low_inclusive, high_inclusive)
        raise ValueError(f"{name} must be a finite number in {rng}, got {value!r}")
    lo_ok = low is None or (v >= low if low_inclusive else v > low)
    hi_ok = high is None or (v <= high if high_inclusive else v < high)
    if not (lo_ok and hi_ok):
        raise ValueError(f"{name} must lie in {_range_text(low, high, low_inclusive, high_inclusive)}, got {v:g}")
    return v


def check_int(name: str, value, *, low: int | None = None, high: int | None = None) -> int:
    """Return ``value`` as int, or raise ValueError naming ``name`` and the allowed range.

    Accepts Python and numpy integers; refuses bools (``True`` is not 1), floats (even 2.0) and strings."""
    rng = _range_text(low, high)
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value[()]
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
        raise ValueError(f"{name} must be an integer in {rng}, got {_describe(value)}")
    v = int(value)
    if (low is not None and v < low) or (high is not None and v > high):
        raise ValueError(f"{name} must be an integer in {rng}, got {v}")
    return v


def check_choice(name: str, value, choices) -> str:
    """Return ``value`` if it is one of ``choices`` (compared as strings), else raise ValueError naming them."""
    if not isinstance(value, str) or value not in choices:
        raise ValueError(f"{name} must be one of {tuple(choices)}, got {value!r}")
    return value


def check_bool(name: str, value) -> bool:
    """Return ``value`` as bool if it is a Python or numpy bool, else raise ValueError naming ``name``."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be True or False, got {_describe(value)}")
    return bool(value)


def check_instance(name: str, value, cls: type | tuple[type, ...]):
    """Return ``value`` if it is an instance of ``cls``, else raise ValueError naming ``name`` and the type."""
    if not isinstance(value, cls):
        want = " or ".join(c.__name__ for c in (cls if isinstance(cls, tuple) else (cls,)))
        raise ValueError(f"{name} must be a {want}, got {type(value).__name__}")
    return value


def check_field(obj: object, name: str, **limits) -> float:
    """Check the real field ``name`` of a frozen dataclass with :func:`check_scalar` and store it as float."""
    v = check_scalar(name, getattr(obj, name), **limits)
    object.__setattr__(obj, name, v)
    return v


def check_int_field(obj: object, name: str, **limits) -> int:
    """Check the integer field ``name`` of a frozen dataclass with :func:`check_int` and store it as int."""
    v = check_int(name, getattr(obj, name), **limits)
    object.__setattr__(obj, name, v)
    return v


def check_array(
    name: str,
    value,
    *,
    shape: tuple[int, ...] | None = None,
    low: float | None = None,
    high: float | None = None,
    low_inclusive: bool = True,
) -> np.ndarray:
    """Return ``value`` as a float64 array; raise ValueError naming ``name`` on NaN, bad shape or range.

    Refuses strings, bools and objects that are not real numbers, like :func:`check_scalar`."""
    arr = np.asarray(value) if not isinstance(value, str) else np.asarray([value])
    if arr.dtype.kind not in "iuf":
        raise ValueError(f"{name} must be an array of real numbers, got dtype {arr.dtype} ({value!r:.60})")
    arr = arr.astype(np.float64)
    if shape is not None and arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {arr.shape}")
    if arr.size == 0:
        return arr
    # two reductions answer every check (a NaN propagates into both, an inf shows in one): on the short arrays
    # of an env step this is several times cheaper than an element-wise test per condition
    lo, hi = float(arr.min()), float(arr.max())
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise ValueError(f"{name} must be finite (no NaN or inf)")
    if low is not None and (lo < low if low_inclusive else lo <= low):
        op = ">=" if low_inclusive else ">"
        raise ValueError(f"{name} must be {op} {low:g} everywhere, got min {lo:g}")
    if high is not None and hi > high:
        raise ValueError(f"{name} must be <= {high:g} everywhere, got max {hi:g}")
    return arr


def caller_stacklevel() -> int:
    """The ``stacklevel`` that makes a warning issued by the calling function name the first frame outside the
    trackenv package (the user's call), however deep inside it the warning is raised."""
    import os
    import sys

    package = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    frame: Any = sys._getframe(1)
    level = 1
    while frame is not None and os.path.abspath(frame.f_code.co_filename).startswith(package + os.sep):
        frame, level = frame.f_back, level + 1
    return level


def check_speed(speed, name: str = "speed") -> float:
    """A vehicle's speed [m/s] in (0, :data:`MAX_SPEED_M_PER_S`]; a warning above :data:`SERVICE_SPEED_M_PER_S`
    (outside the model's validity, or km/h given as m/s)."""
    try:
        v = check_scalar(name, speed, low=0.0, high=MAX_SPEED_M_PER_S, low_inclusive=False)
    except ValueError as error:  # the range is in m/s: say so where a speed in km/h is the likely slip
        raise ValueError(f"{error} (m/s: {MAX_SPEED_M_PER_S:g} m/s is {MAX_SPEED_M_PER_S * 3.6:g} km/h; a speed in "
                         f"km/h divided by 3.6)") from None
    if v > SERVICE_SPEED_M_PER_S:
        import warnings

        warnings.warn(f"{name} {v:g} m/s is {v * 3.6:.4g} km/h, above the 350 km/h of any ballasted line: the "
                      f"model has no ballast flight or critical-velocity effects there. The speed is in m/s (a "
                      f"speed in km/h divided by 3.6)", UserWarning, stacklevel=caller_stacklevel())
    return v


def check_time_steps(length_m: float, speed_m_per_s: float, dt_s: float, rows: int = 1, axles: int = 1) -> int:
    """Time steps of a pass over ``length_m`` at ``speed_m_per_s`` with step ``dt_s``; raise ValueError naming
    speed and dt when they exceed :data:`MAX_TIME_STEPS` (or the batch :data:`MAX_PASS_SAMPLES`), before
    anything is allocated."""
    steps = length_m / (speed_m_per_s * dt_s)
    if not steps <= MAX_TIME_STEPS:
        raise ValueError(
            f"a pass of {length_m:g} m at speed {speed_m_per_s:g} m/s with dt {dt_s:g} s needs {steps:.3g} time "
            f"steps, more than the {MAX_TIME_STEPS:,} allowed (MAX_TIME_STEPS): raise speed or dt, or shorten "
            f"the pass (speed >= {length_m / (MAX_TIME_STEPS * dt_s):.3g} m/s at this dt)"
        )
    n = int(math.ceil(steps - 1e-9))
    samples = (n + 1) * rows * axles
    if samples > MAX_PASS_SAMPLES:
        raise ValueError(
            f"a batched pass of {rows} rows × {axles} axles × {n + 1} time steps stores {samples:.3g} samples per "
            f"array, more than the {MAX_PASS_SAMPLES:,} allowed (MAX_PASS_SAMPLES): split the batch or raise "
            "speed or dt"
        )
    return n


def dataclass_from_dict(cls, d):
    """``cls(**d)`` for a frozen parameter dataclass, raising ValueError naming any unknown key."""
    if not isinstance(d, Mapping):
        raise ValueError(f"{cls.__name__}.from_dict expects a mapping, got {type(d).__name__}")
    known = sorted(f.name for f in dataclasses.fields(cls))
    unknown = sorted(str(k) for k in d if k not in known)
    if unknown:
        raise ValueError(f"unknown {cls.__name__} key(s) {unknown}; allowed: {known}")
    return cls(**dict(d))


def readonly_array(arr) -> np.ndarray:
    """A float64 copy of ``arr`` that cannot be written to: what a frozen dataclass stores, so neither the
    caller's array nor a later in-place write can change a frozen value."""
    out = np.array(arr, dtype=np.float64, copy=True)
    out.flags.writeable = False
    return out
