"""Compiled inverse of the settlement laws' growth functions that have no closed form (Sato, Shenton).

One numba entry, :func:`growth_inverse`, runs the safeguarded Newton solve of
:func:`trackenv.physics.settlement` element by element: the same iteration, the same bracket updates and the
same stopping rules as the vectorised numpy solve it replaces (kept as the reference in
``tests/physics/settlement_reference.py``), without the masked array bookkeeping that dominated its cost. Each element's
iterates depend on that element only, so a row gives the same numbers in any batch.

The upper brackets of the solve (:func:`upper_bracket`) are written once here, for the laws' inverses and for
the compiled implicit step alike. The growth functions g(N) and their slopes are those of
:class:`~trackenv.physics.settlement.SatoLaw` and :class:`~trackenv.physics.settlement.ShentonLaw`;
``tests/physics/test_settlement.py`` checks that the compiled g and the laws' ``_growth`` agree and that the
inverse matches the numpy reference.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["SATO", "SHENTON", "growth_inverse", "inverse_one", "upper_bracket", "upper_brackets"]

SATO = 0  # g(N) = -gamma·expm1(-alpha·N) + beta·N, params (alpha, beta, gamma)
SHENTON = 1  # g(N) = K1·N^0.2 + K2·N, params (K1, K2)

_EPS = float(np.finfo(np.float64).eps)


@njit(cache=True, inline="always")
def _growth(kind: int, p: np.ndarray, n: float) -> float:
    if kind == SATO:
        return -p[2] * math.expm1(-p[0] * n) + p[1] * n
    return p[0] * n**0.2 + p[1] * n


@njit(cache=True, inline="always")
def _slope(kind: int, p: np.ndarray, n: float) -> float:
    if kind == SATO:
        return p[2] * p[0] * math.exp(-p[0] * n) + p[1]
    return 0.2 * p[0] * n ** (0.2 - 1.0) + p[1]


@njit(cache=True, inline="always", error_model="numpy")
def upper_bracket(kind: int, p: np.ndarray, y: float) -> float:
    """An upper bound of the N with g(N) = y, +inf where none is known (the law may be bounded below y).

    Sato: g(N) >= beta·N, so N <= y/beta; g(N) >= gamma·(1 − e^(−alpha·N)), so N <= −ln(1 − y/gamma)/alpha for
    y < gamma. Shenton: g(N) >= K2·N and g(N) >= K1·N^0.2."""
    hi = np.inf
    if kind == SATO:
        alpha, beta, gamma = p[0], p[1], p[2]
        if beta > 0.0:
            hi = y / beta
        if gamma > 0.0:
            h2 = -math.log1p(-min(y / gamma, 1.0)) / alpha if y < gamma else np.inf
            hi = min(hi, h2)
    else:
        if p[1] > 0.0:
            hi = y / p[1]
        if p[0] > 0.0:
            hi = min(hi, (y / p[0]) ** (1.0 / 0.2))
    return hi


@njit(cache=True, error_model="numpy")
def upper_brackets(kind: int, p: np.ndarray, y: np.ndarray) -> np.ndarray:
    """:func:`upper_bracket` of every element of ``y``."""
    out = np.empty(y.shape[0])
    for i in range(y.shape[0]):
        out[i] = upper_bracket(kind, p, y[i])
    return out


@njit(cache=True, inline="always", error_model="numpy")
def inverse_one(kind: int, p: np.ndarray, t: float, h: float, max_iter: int) -> float:
    """N >= 1 with g(N) = t (t > g(1)); +inf where the upper bracket ``h`` is not finite.

    Safeguarded Newton on the bracket [1, max(h, 1)], from its upper end: the Newton step where it stays
    inside the bracket, the geometric midpoint otherwise; stops at a residual at the rounding level of t, or a
    step or bracket of a few ulps (see the numpy reference for the reasoning). Both growth functions are
    concave and their upper brackets are their dominant terms' inverses, so the first step from the bracket
    lands just left of the root and the rest climb to it: 3.5 (Sato) and 4.3 (Shenton) iterations on average
    over y = g(1)·e^[0, 8], against 4.3 and 6.8 from the bracket's geometric midpoint.
    """
    if not np.isfinite(h):
        return np.inf
    lo = 1.0
    h = max(h, 1.0)
    x = h
    for _ in range(max_iter):
        f = _growth(kind, p, x) - t
        if f < 0.0:
            lo = x
        else:
            h = x
        step = x - f / _slope(kind, p, x)
        if np.isfinite(step) and step >= lo and step <= h:
            new = step
        else:
            new = math.sqrt(lo * h)
        at_root = abs(f) <= 4.0 * _EPS * abs(t)
        if at_root:
            new = x
        done = at_root or abs(new - x) <= 8.0 * _EPS * x or h - lo <= 8.0 * _EPS * h
        x = new
        if done:
            break
    return x


@njit(cache=True, error_model="numpy")
def growth_inverse(kind: int, p: np.ndarray, y: np.ndarray, hi: np.ndarray, max_iter: int) -> np.ndarray:
    """:func:`inverse_one` of every element of ``y`` with its upper bracket ``hi``."""
    out = np.empty(y.shape[0])
    for i in range(y.shape[0]):
        out[i] = inverse_one(kind, p, y[i], hi[i], max_iter)
    return out
