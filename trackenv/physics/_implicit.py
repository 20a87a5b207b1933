"""Compiled settlement kernels for the laws of :mod:`trackenv.physics.settlement`: the root-solved inverse of
Sato's and Shenton's growth functions, and the whole implicit settlement step.

**The root-solved inverse.** Sato's and Shenton's g(N) have no closed-form inverse. :func:`growth_inverse` runs
the safeguarded Newton solve of :func:`trackenv.physics.settlement` element by element: the same iteration, the
same bracket updates and the same stopping rules as the vectorised numpy solve it replaced (kept as the
reference in ``tests/physics/settlement_reference.py``), without the masked array bookkeeping that dominated its
cost. Each element's iterates depend on that element only, so a row gives the same numbers in any batch. The
upper brackets of the solve (:func:`upper_bracket`) are written once here, for the laws' inverses and for the
implicit step alike. ``tests/physics/test_settlement.py`` checks that the compiled g and the laws' ``_growth``
agree and that the inverse matches the numpy reference.

**The implicit step.** :func:`trackenv.physics.settlement.implicit_settlement_step` solves, row by row,
Δ = u(F0 + S·Δ, N + ΔN) − u_now by Newton's method. Each iteration evaluates the law (with curve shifting) on
every sleeper twice and solves a banded system: in numpy that is ~40 calls on arrays of a hundred numbers, 4.1 ms
per 60 m track step against 0.8 ms compiled. Here the whole step runs compiled, the rows of a batch spread
over numba's threads, with the same iteration: the same forward-difference Jacobian, the same banded S, the same
stopping rule, the same clipping.

Every law of the module is separable with an amplitude of one form, A(F) = c·(F / F0)^p, and a growth function
g(N) of four kinds (the ramp g(1)·N below N = 1 as in the module's convention):

* ``SATO`` and ``SHENTON``: no closed-form inverse, the safeguarded Newton solve above;
* ``LOG``: g = a + b·ln N (Hettler, Alva-Hurtado & Selig with b = C / ln 10, Indraratna), params (a, b);
* ``POWER``: g = N^β (Selig & Waters), params (β,).

A law describes itself by ``_compiled_form()`` (amplitude (c, F0, p), kind, growth params); the numbers agree
with the law's numpy methods to the last bits of pow/log/exp (tested in ``tests/physics/test_settlement.py``,
against the numpy step which stays the path of any other law). Each row's numbers depend on that row only,
so a row gives the same result in any batch.

Both live in this one file on purpose: numba's on-disk cache checks only the file of the function it compiled,
so a compiled step that inlined a solve from another file would keep running the old solve after that file
changed (seen: an edit of the solve's start was invisible to the cached step until its cache was deleted).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

__all__ = ["LOG", "POWER", "SATO", "SHENTON", "growth_inverse", "implicit_rows", "inverse_one", "upper_bracket",
           "upper_brackets"]

SATO = 0  # g(N) = -gamma·expm1(-alpha·N) + beta·N, params (alpha, beta, gamma)
SHENTON = 1  # g(N) = K1·N^0.2 + K2·N, params (K1, K2)

_EPS = float(np.finfo(np.float64).eps)


@njit(cache=True, inline="always")
def _root_growth(kind: int, p: np.ndarray, n: float) -> float:
    """g(N) of the root-solved kinds (Sato, Shenton)."""
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
        f = _root_growth(kind, p, x) - t
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


LOG = 2  # g(N) = a + b·ln N, params (a, b)
POWER = 3  # g(N) = N^beta, params (beta,)
_MAX_NEWTON = 200  # iterations of the root-solved inverse (as the numpy laws)
_DF = 1e-3  # [N] forward-difference step of the force (as the numpy step)


@njit(cache=True, inline="always")
def _growth(kind: int, p: np.ndarray, n: float) -> float:
    """g(N) for N >= 1."""
    if kind == LOG:
        return p[0] + p[1] * math.log(n)
    if kind == POWER:
        return n ** p[0]
    return _root_growth(kind, p, n)


@njit(cache=True, inline="always", error_model="numpy")
def _growth_inverse(kind: int, p: np.ndarray, y: float) -> float:
    """N > 1 with g(N) = y for y > g(1); +inf where the law can never reach y."""
    if kind == LOG:
        if p[1] == 0.0:
            return np.inf
        return math.exp((y - p[0]) / p[1])
    if kind == POWER:
        return y ** (1.0 / p[0])
    return inverse_one(kind, p, y, upper_bracket(kind, p, y), _MAX_NEWTON)


@njit(cache=True, inline="always", error_model="numpy")
def _advance(amp: np.ndarray, kind: int, p: np.ndarray, g1: float, u: float, c: float, r: float, f: float,
             dn: float) -> tuple[float, float]:
    """Curve shifting of one sleeper (see ``SettlementState.advance``): the new (settlement, cycles)."""
    if not (f > 0.0 and dn > 0.0):
        return u, c
    a = amp[0] * (f / amp[1]) ** amp[2]
    y = u / r
    if y > 0.0:
        if a > 0.0:
            ya = y / a
            n_eq = ya / g1 if ya <= g1 else _growth_inverse(kind, p, ya)
        else:
            n_eq = np.inf
    else:
        n_eq = 0.0
    if not np.isfinite(n_eq):
        return u, np.inf
    n = n_eq + dn
    g = n * g1 if n < 1.0 else _growth(kind, p, n)
    return max(r * (a * g), u), n


@njit(cache=True, error_model="numpy")
def _banded_solve(jac: np.ndarray, rhs: np.ndarray, band: int, out: np.ndarray) -> bool:
    """Solve jac·x = rhs in place (jac dense (n, n) but zero beyond ``band`` diagonals) by Gaussian
    elimination with partial pivoting within the band (what LAPACK's gbsv does); False if singular."""
    n = rhs.shape[0]
    for k in range(n):
        last = min(k + band, n - 1)
        piv = k
        for i in range(k + 1, last + 1):
            if abs(jac[i, k]) > abs(jac[piv, k]):
                piv = i
        if jac[piv, k] == 0.0:
            return False
        right = min(k + 2 * band, n - 1)  # fill-in of the row swaps reaches 2·band
        if piv != k:
            for j in range(k, right + 1):
                jac[k, j], jac[piv, j] = jac[piv, j], jac[k, j]
            rhs[k], rhs[piv] = rhs[piv], rhs[k]
        for i in range(k + 1, last + 1):
            m = jac[i, k] / jac[k, k]
            if m != 0.0:
                for j in range(k + 1, right + 1):
                    jac[i, j] -= m * jac[k, j]
                rhs[i] -= m * rhs[k]
    for k in range(n - 1, -1, -1):
        s = rhs[k]
        for j in range(k + 1, min(k + 2 * band, n - 1) + 1):
            s -= jac[k, j] * out[j]
        out[k] = s / jac[k, k]
    return True


@njit(cache=True, error_model="numpy")
def _implicit_row(amp, kind, p, g1, u_now, c_now, rate, f0, s, dn, band, tol, max_iter, u_out, c_out):
    """The implicit step of one row (arrays (n,), ``s`` (n, n)): fills ``u_out``, ``c_out``; returns 0
    (converged), 1 (not converged within ``max_iter``) or 2 (singular Jacobian)."""
    n = u_now.shape[0]
    delta = np.zeros(n)
    f = np.zeros(n)
    uf = np.zeros(n)
    cf = np.zeros(n)
    r = np.zeros(n)
    step = np.zeros(n)
    jac = np.zeros((n, n))
    flag = 1
    for _ in range(max_iter):
        err = 0.0
        for i in range(n):
            acc = f0[i]
            for j in range(n):
                acc += s[i, j] * delta[j]
            f[i] = max(acc, 0.0)
            uf[i], cf[i] = _advance(amp, kind, p, g1, u_now[i], c_now[i], rate[i], f[i], dn)
            r[i] = delta[i] - (uf[i] - u_now[i])
            err = max(err, abs(r[i]))
        if err < tol:
            flag = 0
            break
        jac[:, :] = 0.0  # I − diag(∂u/∂F)·S·[F > 0] within the band
        for i in range(n):
            ufd = _advance(amp, kind, p, g1, u_now[i], c_now[i], rate[i], f[i] + _DF, dn)[0]
            slope = (ufd - uf[i]) / _DF if f[i] > 0.0 else 0.0
            for j in range(max(i - band, 0), min(i + band, n - 1) + 1):
                jac[i, j] = (1.0 if i == j else 0.0) - slope * s[i, j]
        if not _banded_solve(jac, r, band, step):
            flag = 2
            break
        for i in range(n):
            delta[i] = max(delta[i] - step[i], 0.0)
    if flag == 0:  # converged: the last evaluation was at the final increment (the forces and the law as below)
        for i in range(n):
            u_out[i], c_out[i] = uf[i], cf[i]
        return flag
    for i in range(n):
        acc = f0[i]
        for j in range(n):
            acc += s[i, j] * delta[j]
        u_out[i], c_out[i] = _advance(amp, kind, p, g1, u_now[i], c_now[i], rate[i], max(acc, 0.0), dn)
    return flag


@njit(cache=True, parallel=True, error_model="numpy")
def implicit_rows(amp, kind, p, u_now, c_now, rate, f0, s_mat, dn, band, tol, max_iter):
    """The implicit step of every row, the rows spread over numba's threads: ``u_now``, ``c_now``, ``rate``,
    ``f0`` (nb, n), ``s_mat`` (1 or nb, n, n), ``dn`` (nb,); returns the new settlement and cycles (nb, n) and
    a flag per row (0 converged, 1 not converged within ``max_iter``, 2 singular Jacobian). A row's numbers do
    not depend on its thread."""
    nb, n = u_now.shape
    u_out = np.empty((nb, n))
    c_out = np.empty((nb, n))
    flag = np.zeros(nb, dtype=np.int64)
    g1 = _growth(kind, p, 1.0)
    shared = s_mat.shape[0] == 1
    for b in prange(nb):
        s = s_mat[0] if shared else s_mat[b]
        flag[b] = _implicit_row(amp, kind, p, g1, u_now[b], c_now[b], rate[b], f0[b], s, dn[b], band, tol,
                                max_iter, u_out[b], c_out[b])
    return u_out, c_out, flag
