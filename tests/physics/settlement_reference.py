"""The vectorised numpy safeguarded Newton solve that inverted the Sato and Shenton growth functions before
the compiled one (:mod:`trackenv.physics._implicit`): kept as the reference the compiled solve is tested
against."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

_EPS = np.finfo(np.float64).eps


def solve_increasing(
    func: Callable[[np.ndarray], np.ndarray],
    deriv: Callable[[np.ndarray], np.ndarray],
    target: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    max_iter: int = 200,
) -> np.ndarray:
    """Solve ``func(x) = target`` elementwise, ``func`` increasing, ``func(lo) <= target <= func(hi)``."""
    lo = np.array(lo, dtype=np.float64, copy=True)
    hi = np.array(hi, dtype=np.float64, copy=True)
    x = hi.copy()  # from the upper end of the bracket, as the compiled solve
    active = np.ones(x.shape, dtype=bool)
    for _ in range(max_iter):
        xa = x[active]
        f = func(xa) - target[active]
        below = f < 0.0
        lo_a = np.where(below, xa, lo[active])
        hi_a = np.where(below, hi[active], xa)
        with np.errstate(divide="ignore", invalid="ignore"):
            step = xa - f / deriv(xa)
        inside = np.isfinite(step) & (step >= lo_a) & (step <= hi_a)
        new = np.where(inside, step, np.sqrt(lo_a * hi_a))
        at_root = np.abs(f) <= 4.0 * _EPS * np.abs(target[active])
        new = np.where(at_root, xa, new)
        done = at_root | (np.abs(new - xa) <= 8.0 * _EPS * xa) | (hi_a - lo_a <= 8.0 * _EPS * hi_a)
        x[active] = new
        lo[active] = lo_a
        hi[active] = hi_a
        idx = np.flatnonzero(active)
        active[idx[done]] = False
        if not active.any():
            break
    return x


def solve_bracketed(func, deriv, y: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """N >= 1 with func(N) = y, for y > func(1); +inf where no finite upper bracket ``hi`` exists."""
    out = np.full(y.shape, np.inf)
    ok = np.isfinite(hi)
    if ok.any():
        hi_ok = np.maximum(hi[ok], 1.0)
        out[ok] = solve_increasing(func, deriv, y[ok], np.ones_like(hi_ok), hi_ok)
    return out
