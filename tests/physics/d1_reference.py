"""The D1 filter written with scipy (sosfilt, solve_toeplitz, lfilter), as :func:`trackenv.physics.geometry.d1_filter`
ran before its core was compiled (:mod:`trackenv.physics._d1`): the reference the compiled filter is tested
against. Same method: least-squares line removed, Yule-Walker AR end extension, forward-backward band-pass."""

from __future__ import annotations

import math

import numpy as np
from scipy import linalg, signal

from trackenv.physics.geometry import _bandpass_sos


def _filtfilt(sos: np.ndarray, zi: np.ndarray, x: np.ndarray) -> np.ndarray:
    zi = zi[:, None, :]
    y, _ = signal.sosfilt(sos, x, axis=-1, zi=zi * x[None, :, :1])
    y = y[:, ::-1]
    y, _ = signal.sosfilt(sos, y, axis=-1, zi=zi * y[None, :, :1])
    return y[:, ::-1]


def _ar_extension(y: np.ndarray, order: int, n_pad: int) -> tuple[np.ndarray, np.ndarray]:
    n = y.size
    r = np.correlate(y, y, mode="full")[n - 1 : n + order] / n
    if order < 1 or not r[0] > 0.0:
        return np.zeros(n_pad), np.zeros(n_pad)
    col = r[:order].copy()
    col[0] *= 1.0 + 1e-9
    coef = linalg.solve_toeplitz(col, r[1 : order + 1])
    den = np.concatenate(([1.0], -coef))
    state = linalg.hankel(coef)  # transposed direct form state of the all-pole recursion
    zeros = np.zeros(n_pad)
    fwd = signal.lfilter([1.0], den, zeros, zi=state @ y[::-1][:order])[0]
    bwd = signal.lfilter([1.0], den, zeros, zi=state @ y[:order])[0]
    return bwd[::-1], fwd


def d1_reference(z: np.ndarray, spacing: float, band=(3.0, 25.0), order: int = 4, pad_wavelengths: float = 3.0,
                 ar_order: int = 20) -> np.ndarray:
    sos, zi = _bandpass_sos(spacing, band[0], band[1], order)
    shape = z.shape
    n = shape[-1]
    rows = z.reshape(-1, n)
    t = np.arange(n, dtype=np.float64) - 0.5 * (n - 1)
    slope = (rows * t).sum(axis=1) / float(t @ t)
    resid = rows - rows.mean(axis=1, keepdims=True) - slope[:, None] * t
    pad = math.ceil(pad_wavelengths * band[1] / spacing)
    if pad > 0:
        p_eff = min(ar_order, (n - 1) // 3)
        ext = np.empty((rows.shape[0], n + 2 * pad))
        for i, y in enumerate(resid):
            ext[i, :pad], ext[i, pad + n :] = _ar_extension(y, p_eff, pad)
        ext[:, pad : pad + n] = resid
    else:
        ext = resid
    return np.ascontiguousarray(_filtfilt(sos.copy(), zi, ext)[:, pad : pad + n]).reshape(shape)
