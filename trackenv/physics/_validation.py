"""Input checks shared by the frozen parameter dataclasses: each raises ValueError naming the field and its range."""

from __future__ import annotations

import math

import numpy as np


def check_scalar(
    name: str,
    value: float,
    *,
    low: float | None = None,
    high: float | None = None,
    low_inclusive: bool = True,
    high_inclusive: bool = True,
) -> float:
    """Return ``value`` as float, or raise ValueError naming ``name`` and the allowed range."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a real number, got {value!r}") from None
    if not math.isfinite(v):
        raise ValueError(f"{name} must be finite, got {value!r}")
    lo_ok = low is None or (v >= low if low_inclusive else v > low)
    hi_ok = high is None or (v <= high if high_inclusive else v < high)
    if not (lo_ok and hi_ok):
        lb = "(-inf" if low is None else ("[" if low_inclusive else "(") + f"{low:g}"
        hb = "inf)" if high is None else f"{high:g}" + ("]" if high_inclusive else ")")
        raise ValueError(f"{name} must lie in {lb}, {hb}, got {v:g}")
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
    """Return ``value`` as a float64 array; raise ValueError naming ``name`` on NaN, bad shape or range."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be an array of real numbers") from None
    if shape is not None and arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite (no NaN or inf)")
    if low is not None:
        bad = arr < low if low_inclusive else arr <= low
        if np.any(bad):
            op = ">=" if low_inclusive else ">"
            raise ValueError(f"{name} must be {op} {low:g} everywhere, got min {arr.min():g}")
    if high is not None and np.any(arr > high):
        raise ValueError(f"{name} must be <= {high:g} everywhere, got max {arr.max():g}")
    return arr


def dataclass_from_dict(cls, d):
    """``cls(**d)`` for a frozen parameter dataclass, raising ValueError naming any unknown key."""
    import dataclasses
    from collections.abc import Mapping

    if not isinstance(d, Mapping):
        raise ValueError(f"{cls.__name__}.from_dict expects a mapping, got {type(d).__name__}")
    known = sorted(f.name for f in dataclasses.fields(cls))
    unknown = sorted(str(k) for k in d if k not in known)
    if unknown:
        raise ValueError(f"unknown {cls.__name__} key(s) {unknown}; allowed: {known}")
    return cls(**dict(d))
