"""Compiled core of :func:`trackenv.physics.geometry.d1_filter`: end extension and zero-phase band-pass, row by row.

The filter is applied to every env's level after every step; done with scipy (sosfilt twice, solve_toeplitz,
lfilter twice, per row) the calls' overhead was ~1 ms per row against a few µs of arithmetic. This runs the same
method compiled: the residual of each row continued beyond both ends by linear prediction from a Yule-Walker
AR model of the row (Levinson's recursion for the Toeplitz system), then the Butterworth second-order sections
forwards and backwards, each pass started in the steady state of its first sample (as ``sosfiltfilt`` with
``padtype=None``). It agrees with the scipy implementation (kept as the reference in
``tests/physics/d1_reference.py``, compared in ``tests/physics/test_geometry.py``) to rounding; each row's
numbers depend on that row only.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["d1_rows"]


@njit(cache=True)
def _levinson(t: np.ndarray, b: np.ndarray) -> np.ndarray:
    """x with T x = b for the symmetric positive definite Toeplitz T[i, j] = t[|i − j|] (Levinson's
    recursion: the forward vector grown one order at a time, the solution updated along it)."""
    p = b.size
    f = np.zeros(p)
    x = np.zeros(p)
    f_new = np.zeros(p)
    f[0] = 1.0 / t[0]
    x[0] = b[0] / t[0]
    for n in range(1, p):
        ef = 0.0
        ex = 0.0
        for i in range(n):
            ef += t[n - i] * f[i]
            ex += t[n - i] * x[i]
        scale = 1.0 / (1.0 - ef * ef)
        for i in range(n + 1):
            fi = f[i] if i < n else 0.0
            bi = f[n - 1 - (i - 1)] if i >= 1 else 0.0  # the backward vector: f reversed, shifted by one
            f_new[i] = (fi - ef * bi) * scale
        for i in range(n + 1):
            f[i] = f_new[i]
        gap = b[n] - ex
        for i in range(n + 1):
            x[i] += gap * f[n - i]
    return x


@njit(cache=True)
def _extend(y: np.ndarray, order: int, ext: np.ndarray, pad: int) -> None:
    """``ext`` = [backward prediction (pad), y, forward prediction (pad)] from an AR(``order``) model of y
    fitted by Yule-Walker to its biased autocorrelation (stable: the prediction decays to zero)."""
    n = y.size
    for i in range(n):
        ext[pad + i] = y[i]
    r = np.zeros(order + 1)
    for k in range(order + 1):
        acc = 0.0
        for i in range(n - k):
            acc += y[i] * y[i + k]
        r[k] = acc / n
    if order < 1 or not r[0] > 0.0:  # too short a record for a model, or a zero row: nothing to continue
        for i in range(pad):
            ext[i] = 0.0
            ext[pad + n + i] = 0.0
        return
    col = r[:order].copy()
    col[0] *= 1.0 + 1e-9  # guard against round-off making the Toeplitz matrix singular
    coef = _levinson(col, r[1 : order + 1])
    for i in range(pad):  # forwards: y[t] = Σ_k coef[k-1]·y[t-k]
        t = pad + n + i
        acc = 0.0
        for k in range(1, order + 1):
            acc += coef[k - 1] * ext[t - k]
        ext[t] = acc
    for i in range(pad):  # backwards with the same coefficients (the autocorrelation is symmetric in time)
        t = pad - 1 - i
        acc = 0.0
        for k in range(1, order + 1):
            acc += coef[k - 1] * ext[t + k]
        ext[t] = acc


@njit(cache=True)
def _sos_pass(sos: np.ndarray, zi: np.ndarray, x: np.ndarray, reverse: bool) -> None:
    """One pass of the second-order sections over x in place (transposed direct form II), forwards or
    backwards, each section's state started at zi scaled by the pass's first sample."""
    n_sec = sos.shape[0]
    n = x.size
    z = np.empty((n_sec, 2))
    first = x[n - 1] if reverse else x[0]
    for s in range(n_sec):
        z[s, 0] = zi[s, 0] * first
        z[s, 1] = zi[s, 1] * first
    for k in range(n):
        i = n - 1 - k if reverse else k
        v = x[i]
        for s in range(n_sec):
            out = sos[s, 0] * v + z[s, 0]
            z[s, 0] = sos[s, 1] * v - sos[s, 4] * out + z[s, 1]
            z[s, 1] = sos[s, 2] * v - sos[s, 5] * out
            v = out
        x[i] = v


@njit(cache=True)
def d1_rows(rows: np.ndarray, sos: np.ndarray, zi: np.ndarray, order: int, pad: int) -> np.ndarray:
    """The D1 signal of every row of ``rows`` (k, n): the least-squares line removed, the residual extended by
    ``pad`` predicted samples each side (AR ``order``; none if pad = 0), band-passed forwards and backwards by
    ``sos`` (normalised second-order sections, a0 = 1, with step steady states ``zi``), the pad cut off."""
    k, n = rows.shape
    out = np.empty((k, n))
    t = np.empty(n)
    tt = 0.0
    for i in range(n):
        t[i] = i - 0.5 * (n - 1)
        tt += t[i] * t[i]
    resid = np.empty(n)
    ext = np.empty(n + 2 * pad)
    for b in range(k):
        row = rows[b]
        st = 0.0
        mean = 0.0
        for i in range(n):
            st += row[i] * t[i]
            mean += row[i]
        slope = st / tt
        mean /= n
        for i in range(n):
            resid[i] = row[i] - mean - slope * t[i]
        if pad > 0:
            _extend(resid, order, ext, pad)
        else:
            ext[:] = resid
        _sos_pass(sos, zi, ext, False)
        _sos_pass(sos, zi, ext, True)
        out[b] = ext[pad : pad + n]
    return out
