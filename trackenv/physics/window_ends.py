"""The static stiffness of the track beyond a window's ends, condensed onto the end nodes.

The kernel integrates the track in a window that follows each axle group; outside it the track is held at rest.
With ``window_ends="rest"`` the window's ends are clamped: the first rail node beyond each end does not move, so
the window is stiffer than the track it stands for, and the deflection basin is cut short where the margin is
short. With ``window_ends="static"`` each end's rail node carries instead the exact static stiffness of all the
track beyond it (the rail's bending and, per sleeper, the pad and the ballast in series), condensed onto the end
node's deflection and rotation: the outside track answers the end node's motion as it would in equilibrium. The
mass and damping beyond the end are left out (the outside is a massless static spring).

The condensation is a Schur complement. With the stiffness K split into the outside DOFs a and the end node's
(w, θ) b, the outside adds −K_ba K_aa⁻¹ K_ab to the window's block K_bb (the window's matrix already holds K_bb,
the stiffness the clamped end has). The DOFs are numbered along the track, so eliminating everything before a
node is the leading part of the banded Cholesky factor K = L Lᵀ: K_ba K_aa⁻¹ K_ab = L_ba L_baᵀ, with L_ba the rows
of b in the columns of a, which the band limits to four. The factor of the track read from its start gives every
left end at once; the factor of the reversed track every right end. This is the bay-by-bay Riccati recursion of
the outside's stiffness, carried out by LAPACK.

In Newmark's effective form only the effective stiffness changes: the step solves
(K + a0 M + a1 C) u_{n+1} = F + M(a0 u + a2 u' + a3 u'') + C(a1 u + a4 u' + a5 u''), whose right-hand side has
no K term, so a static spring at the end enters the window's factor and nothing else.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from .track import HALF_BANDWIDTH, DofLayout

WINDOW_ENDS = ("rest", "static")
"""What a window's ends stand on: "rest" (the track beyond is held at rest: clamped ends) or "static" (the track
beyond carries its static stiffness, condensed onto the end nodes)."""

_PBTRF = scipy.linalg.get_lapack_funcs("pbtrf", (np.zeros(1),))


def outside_stiffness(k_band: np.ndarray, layout: DofLayout) -> np.ndarray:
    """The outside track's static stiffness at each possible window end, as what it adds to the window's
    stiffness (n_sleepers, 6): columns 0-2 for a window that starts at sleeper s (its first rail node's
    (w, w), (θ, w), (θ, θ) entries), columns 3-5 for one that ends at sleeper s (its last rail node's).

    ``k_band``: the track's stiffness in lower band storage (n_dof, B+1) (:meth:`Track.banded_matrices`). The
    entries are ≤ 0 on the diagonal (the outside is softer than a clamped end); where the window reaches the
    track's end there is no outside and they are zero."""
    n = k_band.shape[0]
    w = layout.node_w[layout.sleeper_node]  # each sleeper's rail node: (w, θ) at (w, w + 1), its sleeper after
    out = np.zeros((w.size, 6))
    # left ends: the DOFs before the node, eliminated first
    out[:, 0:3] = _condensed(_band_factor(k_band), w, w + 1, w)
    # right ends: the DOFs after the node's sleeper, eliminated first in the reversed numbering, in which the
    # node's sleeper comes first, then θ, then w
    reversed_w = n - 1 - w
    out[:, 3:6] = _condensed(_band_factor(_reversed_band(k_band)), reversed_w, reversed_w - 1, reversed_w - 2)
    return out


def outside_transfer(k_band: np.ndarray, layout: DofLayout) -> np.ndarray:
    """The static extension of a window's last rail node onto the bay beyond it (n_sleepers, bay_dofs, 2): the
    displacements of the DOFs of the bay after sleeper s (its inner rail nodes' w, θ, then the next sleeper's
    rail node and the sleeper) when the track beyond sleeper s's rail node is in equilibrium with that node's
    deflection (column 0) or rotation (column 1), u_a = −K_aa⁻¹ K_ab u_b. A window that moves on takes its new
    bay's state from it, so the static end's deflection basin continues into the track it takes in. Zero for the
    last sleeper (no bay beyond).

    With the reversed numbering's factor L (outside DOFs first, L_aa Lᵀ_aa = K_aa): u_a = −L_aa⁻ᵀ L_baᵀ u_b, a back
    substitution that starts next to the node and reaches the bay's DOFs in ``bay_dofs`` steps."""
    n = k_band.shape[0]
    w = layout.node_w[layout.sleeper_node]
    bay_dofs = int(layout.sleeper[1] - layout.sleeper[0])
    ab = _band_factor(_reversed_band(k_band))
    outside = n - (w + 3)  # the outside's size; its DOFs are reversed 0 .. outside - 1 (the nearest last)
    out = np.zeros((w.size, bay_dofs, 2))
    inner = outside >= bay_dofs  # every sleeper but the last

    def factor(row: np.ndarray, col: np.ndarray) -> np.ndarray:
        ok = inner & (col >= 0) & (col <= row) & (row - col <= HALF_BANDWIDTH)
        return np.where(ok, ab[np.where(ok, row - col, 0), np.where(ok, col, 0)], 0.0)

    for unit, node_row in ((0, outside + 2), (1, outside + 1)):  # the end node's w, then its θ (reversed rows)
        x = np.zeros((w.size, bay_dofs))
        for d in range(bay_dofs):
            j = outside - 1 - d
            y = factor(node_row, j)  # (L_baᵀ u_b)[j] for the unit displacement
            for k in range(1, HALF_BANDWIDTH + 1):
                if d - k >= 0:
                    y = y - factor(j + k, j) * x[:, d - k]
            diag = factor(j, j)
            x[:, d] = np.where(inner, y / np.where(inner, diag, 1.0), 0.0)
        out[:, :, unit] = -x
    return out


def _condensed(ab: np.ndarray, rows_w: np.ndarray, rows_t: np.ndarray, outside_end: np.ndarray) -> np.ndarray:
    """−L_ba L_baᵀ for each end (columns (w, w), (θ, w), (θ, θ)): ``ab`` the factor in LAPACK's lower band
    storage (ab[k, j] = L[j + k, j]), ``rows_w``/``rows_t`` the factor's rows of the end node's w and θ, and the
    outside the columns below ``outside_end``."""
    def entries(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        cols = rows[:, None] - np.arange(1, HALF_BANDWIDTH + 1)[None, :]  # the band left of the diagonal
        keep = (cols >= 0) & (cols < outside_end[:, None])
        safe = np.where(keep, cols, 0)
        return np.where(keep, ab[np.where(keep, rows[:, None] - safe, 0), safe], 0.0), safe, keep

    lw, cw, kw = entries(rows_w)
    lt, ct, kt = entries(rows_t)
    # the two rows' entries in the same outside column: pair them by column
    cross = np.zeros(rows_w.size)
    for i in range(HALF_BANDWIDTH):
        for j in range(HALF_BANDWIDTH):
            same = kw[:, i] & kt[:, j] & (cw[:, i] == ct[:, j])
            cross += np.where(same, lw[:, i] * lt[:, j], 0.0)
    return -np.stack([(lw * lw).sum(axis=1), cross, (lt * lt).sum(axis=1)], axis=1)


def _band_factor(k_band: np.ndarray) -> np.ndarray:
    """The banded Cholesky factor of a symmetric positive definite band (LAPACK pbtrf), in LAPACK's storage."""
    n, b1 = k_band.shape
    ab = np.zeros((b1, n))
    for k in range(b1):
        ab[k, : n - k] = k_band[k:, k]
    factor, info = _PBTRF(ab, lower=1)
    if info != 0:
        raise np.linalg.LinAlgError(f"pbtrf: the track's stiffness is not positive definite (info {info})")
    return factor


def _reversed_band(k_band: np.ndarray) -> np.ndarray:
    """The band of the matrix with its DOFs numbered from the other end: R[i, i - k] = K[n-1-i+k, n-1-i]."""
    n, b1 = k_band.shape
    out = np.zeros_like(k_band)
    for k in range(b1):
        out[k:, k] = k_band[k:, k][::-1]
    return out


def check_window_ends(window_ends: str) -> str:
    """``window_ends`` validated: one of :data:`WINDOW_ENDS`."""
    if not isinstance(window_ends, str) or window_ends not in WINDOW_ENDS:
        raise ValueError(f"window_ends must be one of {WINDOW_ENDS}, got {window_ends!r}")
    return window_ends
