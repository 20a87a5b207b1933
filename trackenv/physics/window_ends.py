"""The track beyond a window's ends: its static stiffness and damping condensed onto the end nodes, its shape.

The kernel integrates the track in a window that follows each axle group; outside it the track is held at rest.
With ``window_ends="rest"`` the window's ends are clamped: the first rail node beyond each end does not move, so
the window is stiffer than the track it stands for, and the deflection basin is cut short where the margin is
short. With ``window_ends="static"`` each end's rail node carries instead the exact static stiffness of all the
track beyond it (the rail's bending and, per sleeper, the pad and the ballast in series), condensed onto the end
node's deflection and rotation: the outside track answers the end node's motion as it would in equilibrium. Its
damping is condensed the same way, through the static shape the outside takes under the end node (a Guyan
reduction): on soft, heavily damped ballast the outside's dampers carry much of its quasi-static motion. Its mass
is left out. The bays a window takes in at its leading end start as the static extension of its end node, so the
deflection basin continues across the end as the window moves (:func:`outside_transfer`).

The condensation is a Schur complement. With the stiffness K split into the outside DOFs a and the end node's
(w, θ) b, the outside adds −K_ba K_aa⁻¹ K_ab to the window's block K_bb (the window's matrix already holds K_bb,
the stiffness the clamped end has). The DOFs are numbered along the track, so eliminating everything before a
node is the leading part of the banded Cholesky factor K = L Lᵀ: K_ba K_aa⁻¹ K_ab = L_ba L_baᵀ, with L_ba the rows
of b in the columns of a, which the band limits to four. The factor of the track read from its start gives every
left end at once; the factor of the reversed track every right end. This is the bay-by-bay Riccati recursion of
the outside's stiffness, carried out by LAPACK.

In Newmark's effective form the step solves
(K + a0 M + a1 C) u_{n+1} = F + M(a0 u + a2 u' + a3 u'') + C(a1 u + a4 u' + a5 u''), whose right-hand side has
no K term: the outside's stiffness enters the window's factor and nothing else; its damping enters the factor
(times a1) and the right-hand side's C term at the end nodes.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.linalg

from .track import HALF_BANDWIDTH, PER_SLEEPER_FIELDS, DofLayout, Track, add_supports, rail_bands

WINDOW_ENDS = ("rest", "static")
"""What a window's ends stand on: "rest" (the track beyond is held at rest: clamped ends) or "static" (the track
beyond carries its static stiffness, condensed onto the end nodes)."""

_PBTRF = scipy.linalg.get_lapack_funcs("pbtrf", (np.zeros(1),))


def outside_stiffness(k_band: np.ndarray, layout: DofLayout) -> np.ndarray:
    """The outside track's static stiffness at each possible window end, as what it adds to the window's
    stiffness (..., n_sleepers, 6): columns 0-2 for a window that starts at sleeper s (its first rail node's
    (w, w), (θ, w), (θ, θ) entries), columns 3-5 for one that ends at sleeper s (its last rail node's).

    ``k_band``: the track's stiffness in lower band storage (..., n_dof, B+1) (:meth:`Track.banded_matrices`),
    with any leading axes (a batch of tracks on one mesh). The entries are ≤ 0 on the diagonal (the outside is
    softer than a clamped end); where the window reaches the track's end there is no outside and they are zero."""
    n = k_band.shape[-2]
    w = layout.node_w[layout.sleeper_node]  # each sleeper's rail node: (w, θ) at (w, w + 1), its sleeper after
    out = np.zeros(k_band.shape[:-2] + (w.size, 6))
    # left ends: the DOFs before the node, eliminated first
    out[..., 0:3] = _condensed(_band_factor(k_band), w, w + 1, w)
    # right ends: the DOFs after the node's sleeper, eliminated first in the reversed numbering, in which the
    # node's sleeper comes first, then θ, then w
    reversed_w = n - 1 - w
    out[..., 3:6] = _condensed(_band_factor(_reversed_band(k_band)), reversed_w, reversed_w - 1, reversed_w - 2)
    return out


def outside_transfer(k_band: np.ndarray, layout: DofLayout) -> np.ndarray:
    """The static extension of a window's last rail node onto the bay beyond it (..., n_sleepers, bay_dofs, 2): the
    displacements of the DOFs of the bay after sleeper s (its inner rail nodes' w, θ, then the next sleeper's
    rail node and the sleeper) when the track beyond sleeper s's rail node is in equilibrium with that node's
    deflection (column 0) or rotation (column 1), u_a = −K_aa⁻¹ K_ab u_b. A window that moves on takes its new
    bay's state from it, so the static end's deflection basin continues into the track it takes in. Zero for the
    last sleeper (no bay beyond). ``k_band`` (..., n_dof, B+1) as :func:`outside_stiffness` takes it.

    With the reversed numbering's factor L (outside DOFs first, L_aa Lᵀ_aa = K_aa): u_a = −L_aa⁻ᵀ L_baᵀ u_b, a back
    substitution that starts next to the node and reaches the bay's DOFs in ``bay_dofs`` steps."""
    n = k_band.shape[-2]
    w = layout.node_w[layout.sleeper_node]
    bay_dofs = int(layout.sleeper[1] - layout.sleeper[0])
    ab = _band_factor(_reversed_band(k_band))
    outside = n - (w + 3)  # the outside's size; its DOFs are reversed 0 .. outside - 1 (the nearest last)
    out = np.zeros(k_band.shape[:-2] + (w.size, bay_dofs, 2))
    inner = outside >= bay_dofs  # every sleeper but the last

    def factor(row: np.ndarray, col: np.ndarray) -> np.ndarray:
        ok = inner & (col >= 0) & (col <= row) & (row - col <= HALF_BANDWIDTH)
        return np.where(ok, ab[..., np.where(ok, row - col, 0), np.where(ok, col, 0)], 0.0)

    for unit, node_row in ((0, outside + 2), (1, outside + 1)):  # the end node's w, then its θ (reversed rows)
        x = np.zeros(k_band.shape[:-2] + (w.size, bay_dofs))
        for d in range(bay_dofs):
            j = outside - 1 - d
            y = factor(node_row, j)  # (L_baᵀ u_b)[j] for the unit displacement
            for k in range(1, HALF_BANDWIDTH + 1):
                if d - k >= 0:
                    y = y - factor(j + k, j) * x[..., d - k]
            diag = factor(j, j)
            x[..., d] = np.where(inner, y / np.where(inner, diag, 1.0), 0.0)
        out[..., unit] = -x
    return out


def outside_damping(track: Track) -> np.ndarray:
    """The damping of the track beyond each possible window end, condensed onto the end node through the static
    extension (a Guyan reduction: the outside moves as its static shape under the end node's motion), as what it
    adds to the window's damping (n_sleepers, 6), columns as :func:`outside_stiffness`'s.

    The outside's dampers are its pads and ballast; for the right end at sleeper s they are those of sleepers
    s+1, s+2, ... and the condensed matrix follows bay by bay from the track's far end:
    C_s = T_sᵀ D_{s+1} T_s + P_sᵀ C_{s+1} P_s, with T_s the extension onto the bay after s
    (:func:`outside_transfer`), D_{s+1} the quadratic form of sleeper s+1's pad and ballast dampers on that bay's
    DOFs and P_s the extension's rows of node s+1 (w, θ). The left ends are the right ends of the mirrored track
    (the rotation changes sign). A static end carries it where the track's damping makes the outside's quasi-static
    motion matter (soft, heavily damped ballast)."""
    return _damping([track], outside_transfer(track.banded_matrices()[2][None], track.dof_layout))[0]


def static_ends(tracks: Sequence[Track], k_bands: np.ndarray) -> np.ndarray:
    """The static ends of a batch of tracks on one mesh (len(tracks), n_sleepers, 12 + 2 bay_dofs), as the kernel
    reads them: the outside's stiffness (:func:`outside_stiffness`), its condensed damping
    (:func:`outside_damping`) and the static extension onto the next bay (:func:`outside_transfer`, flattened).
    ``k_bands``: the tracks' stiffness bands (len(tracks), n_dof, B+1). Every step is vectorised over the batch
    (the banded factorisations excepted, one LAPACK call per track), each track's numbers those it has alone."""
    layout = tracks[0].dof_layout
    transfer = outside_transfer(k_bands, layout)
    return np.concatenate([outside_stiffness(k_bands, layout), _damping(tracks, transfer),
                           transfer.reshape(transfer.shape[:2] + (-1,))], axis=-1)


def _damping(tracks: Sequence[Track], transfer: np.ndarray) -> np.ndarray:
    """:func:`outside_damping` of each track (len(tracks), n_sleepers, 6), given their extensions ``transfer``
    (:func:`outside_transfer`, (len(tracks), n_sleepers, bay_dofs, 2)): the right ends from them, the left ends
    as the right ends of the mirrored tracks."""
    pad, ballast = (np.stack([getattr(t, name) for t in tracks]) for name in ("pad_damping", "ballast_damping"))
    right = _right_damping(transfer, pad, ballast)
    mirrored = outside_transfer(_mirrored_stiffness(tracks), tracks[0].dof_layout)
    left = _right_damping(mirrored, pad[:, ::-1], ballast[:, ::-1])[:, ::-1] * np.array([1.0, -1.0, 1.0])  # θ → −θ
    return np.concatenate([left, right], axis=-1)


def _mirrored_stiffness(tracks: Sequence[Track]) -> np.ndarray:
    """The stiffness bands (len(tracks), n_dof, B+1) of the tracks with their sleepers in reverse order, assembled as
    :meth:`Track.banded_matrices` assembles the mirrored track's (the rail, then its supports: the same numbers)."""
    t0 = tracks[0]
    layout = t0.dof_layout
    m, c, k = (np.repeat(band[None], len(tracks), axis=0)
               for band in rail_bands(layout, t0.element_length, t0.rail_bending_stiffness, t0.rail_mass))
    add_supports(m, c, k, layout, *(np.stack([getattr(t, name)[::-1] for t in tracks]) for name in PER_SLEEPER_FIELDS))
    return k


def _right_damping(transfer: np.ndarray, pad: np.ndarray, ballast: np.ndarray) -> np.ndarray:
    """Columns 3-5 of :func:`outside_damping` ((w, w), (θ, w), (θ, θ) of the right end at each sleeper) of a batch
    of tracks (rows, n_sleepers, 3), from their extensions ``transfer`` (rows, n_sleepers, bay_dofs, 2) and their
    pad and ballast damping (rows, n_sleepers): the recursion runs over the sleepers, every row at once."""
    rows, n, bay_dofs = transfer.shape[:3]
    node = transfer[:, :, bay_dofs - 3]  # the next sleeper's rail node w (then θ, then the sleeper), per unit (w, θ)
    sleeper = transfer[:, :, bay_dofs - 1]
    out = np.zeros((rows, n, 2, 2))
    for s in range(n - 2, -1, -1):
        relative = node[:, s] - sleeper[:, s]
        d = (pad[:, s + 1, None, None] * (relative[:, :, None] * relative[:, None, :])
             + ballast[:, s + 1, None, None] * (sleeper[:, s, :, None] * sleeper[:, s, None, :]))
        p = transfer[:, s, bay_dofs - 3 : bay_dofs - 1]  # node s+1's (w, θ) per unit (w, θ) of node s
        out[:, s] = d + np.swapaxes(p, -1, -2) @ out[:, s + 1] @ p
    return np.stack([out[..., 0, 0], out[..., 1, 0], out[..., 1, 1]], axis=-1)


def _condensed(ab: np.ndarray, rows_w: np.ndarray, rows_t: np.ndarray, outside_end: np.ndarray) -> np.ndarray:
    """−L_ba L_baᵀ for each end (..., ends, 3) (columns (w, w), (θ, w), (θ, θ)): ``ab`` the factor in LAPACK's lower
    band storage (..., B+1, n) (ab[k, j] = L[j + k, j]), ``rows_w``/``rows_t`` the factor's rows of the end node's w
    and θ, and the outside the columns below ``outside_end``."""
    def entries(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        cols = rows[:, None] - np.arange(1, HALF_BANDWIDTH + 1)[None, :]  # the band left of the diagonal
        keep = (cols >= 0) & (cols < outside_end[:, None])
        safe = np.where(keep, cols, 0)
        return np.where(keep, ab[..., np.where(keep, rows[:, None] - safe, 0), safe], 0.0), safe, keep

    lw, cw, kw = entries(rows_w)
    lt, ct, kt = entries(rows_t)
    # the two rows' entries in the same outside column: pair them by column
    cross = np.zeros(lw.shape[:-1])
    for i in range(HALF_BANDWIDTH):
        for j in range(HALF_BANDWIDTH):
            same = kw[:, i] & kt[:, j] & (cw[:, i] == ct[:, j])
            cross += np.where(same, lw[..., i] * lt[..., j], 0.0)
    return -np.stack([(lw * lw).sum(axis=-1), cross, (lt * lt).sum(axis=-1)], axis=-1)


def _band_factor(k_band: np.ndarray) -> np.ndarray:
    """The banded Cholesky factor of a symmetric positive definite band (..., n, B+1) (LAPACK pbtrf, one call per
    band), in LAPACK's storage (..., B+1, n)."""
    n, b1 = k_band.shape[-2:]
    ab = np.zeros(k_band.shape[:-2] + (b1, n))
    for k in range(b1):
        ab[..., k, : n - k] = k_band[..., k:, k]
    out = np.empty_like(ab)
    for index in np.ndindex(k_band.shape[:-2]):
        factor, info = _PBTRF(ab[index], lower=1)
        if info != 0:
            raise np.linalg.LinAlgError(f"pbtrf: the track's stiffness is not positive definite (info {info})")
        out[index] = factor
    return out


def _reversed_band(k_band: np.ndarray) -> np.ndarray:
    """The band (..., n, B+1) of the matrix with its DOFs numbered from the other end:
    R[i, i - k] = K[n-1-i+k, n-1-i]."""
    b1 = k_band.shape[-1]
    out = np.zeros_like(k_band)
    for k in range(b1):
        out[..., k:, k] = k_band[..., k:, k][..., ::-1]
    return out


def check_window_ends(window_ends: str) -> str:
    """``window_ends`` validated: one of :data:`WINDOW_ENDS`."""
    if not isinstance(window_ends, str) or window_ends not in WINDOW_ENDS:
        raise ValueError(f"window_ends must be one of {WINDOW_ENDS}, got {window_ends!r}")
    return window_ends
