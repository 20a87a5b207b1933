"""One time step of the kernel, and the integration of a chunk of rows over a pass.

Newmark average acceleration (β = 1/4, γ = 1/2: implicit, unconditionally stable, no numerical damping) on the
linear track and the linear vehicle, coupled by the non-linear contact law, which is solved by Newton's method
every step. Only the contact forces couple the two, so each step is: predict both without contact, solve the
small contact problem through the two flexibilities at the wheels, correct both.

The track is integrated in a window of the standing track that follows each group of axles. The supports are
damped and the rail's deflection decays like e^{-βx}, so beyond a few decay lengths the track hardly moves: inside
the window the track is integrated in full, outside it is at rest. The window is a contiguous block of the banded
matrices (DOFs are numbered along the track) and moves by whole bays; the DOFs it leaves behind are set back to
rest. Every quantity the caller sees (contact force, rail deflection, peak sleeper forces) is taken where the
window is. With the window as long as the track this is the full model (the caller sizes the window from the
track's decay length: ``dynamics.window_margin``). The window's ends are clamped (the first rail node beyond is
at rest), or, with static ends, each end's rail node carries the static stiffness of the track beyond it and its
damping condensed through the static shape (in the window's factor and, the damping, in the predictor's right-hand
side), and the bays the window takes in at its leading end start as the static extension of its end node
(:mod:`trackenv.physics.window_ends`): the deflection basin then continues across the ends, and a shorter window
keeps the long one's accuracy.

Lockstep rows. The rows of a batch share the mesh, the vehicle, the speed and dt, so their windows move together;
only the supports, the irregularity and the state differ. Every per-row array carries the rows *last*, and the
track's state vectors are used flat, DOF i of row b at i*W + b, with the chunk width W a compile-time constant.
For one row (W = 1) the hot loops run along the track as unit-stride loops, which compile to SIMD; for several
rows each DOF's work across the rows is one vector operation (:mod:`trackenv.physics._lanes`). Every row's
arithmetic is the same IEEE sequence whatever its lane, chunk width or thread (no reassociation, fused
multiply-adds only where written out), so a row's result does not depend on the batch it runs in (tested).

Loops index views from 0 wherever they can: numba wraps negative indices, and the check it emits where it cannot
prove an index non-negative blocks vectorisation. Where an index has to be computed it is cast to unsigned, for
which numba emits no wrap-around. The comment lines ``# ---- <name>`` of the time-step loop in :func:`_run_chunk`
mark its sections: ``experiments/kernel_profile.py`` counts the processor cycles spent in each.

The kernel's arguments are five namedtuples of arrays (numba accepts them), defined here: ``Mesh`` and ``Drive``
(shared by all rows), ``Rows`` (per-row inputs and state, updated in place), ``Peaks`` (per-row outputs) and
``Reuse`` (window factors and bay columns a one-row pass keeps for the next pass over its track; empty for
batches).
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import literally, njit

from ._lanes import correct_lanes, damp_lanes, fma, mass_lanes, peak_lanes, sweep_lanes
from ._pipeline import FASTMATH, _CalledCompiler, _InlineCompiler, _NoAliasCompiler, _NoAliasInlineCompiler, kernel_jit
from .track import HALF_BANDWIDTH

B = HALF_BANDWIDTH  # half-bandwidth of the track matrices (see track.DofLayout)


Mesh = namedtuple("Mesh", "node_w sleeper_dof sleeper_node elem_len epb n_sleepers margin_bays rail_mass")
Mesh.__doc__ = """The rail mesh, shared by every row: DOF of each node's deflection, DOF and node of each sleeper
(int64 arrays), element length [m], elements per bay, number of sleepers, window margin in bays, and the bare
rail's consistent mass matrix as its 2B+1 full diagonals, rail_mass[d, i] = M_rail[i, i + d - B] (2B+1, n_dof)
[kg]: the rail is the same in every row, so its mass is stored once; the kernel reads its off-diagonals (the
diagonal, with the sleepers' masses, is per row)."""

Drive = namedtuple("Drive", "x_axle consts law param mass damping kv_inv force wheel_dofs cluster_of_axle n_clusters")
Drive.__doc__ = """What moves over the track, shared by every row: axle positions (n_steps+1, n_axles) [m],
Newmark constants a0..a7, contact law code and parameter, the vehicle's M, C, K_eff⁻¹ (nv, nv), its constant
forces (nv,), the DOF of each wheel, the window group of each axle and the number of groups."""

Rows = namedtuple("Rows", "mass_diag keff pad_k pad_c bal_k bal_c z sag u v a q qd qdd ends", defaults=(None,))
Rows.__doc__ = """Per-row inputs and state, chunk axis first and batch axis last: the diagonal of the track's
mass matrix (chunks, n_dof, W) [kg] (rail and sleepers; ``Mesh.rail_mass`` holds the rest), effective stiffness
in lower band storage (chunks, n_dof, B+1, W), pad and ballast stiffness and damping (chunks, n_sleepers, W), rail
level under each wheel (chunks, n_steps+1, n_axles, W) [m] to which the kernel adds the static sag ``sag``
(chunks, n_dof, W) of settled supports, and the track and vehicle state u, v, a (chunks, n_dof, W), q, qd, qdd
(chunks, nv, W), all updated in place; ``ends`` (chunks, n_sleepers, 6, W): what the track beyond a window's
end adds to the window's effective stiffness where the window starts (columns 0-2) or ends (3-5) at each sleeper,
the (w, w), (θ, w), (θ, θ) entries of its end node (zeros, or None for :func:`trackenv.physics._kernel.run` to
fill with zeros: clamped ends); for static ends (chunks, n_sleepers, 12 + 2 bay_dofs, W): columns 0-5 the
outside's static stiffness plus a1 times its condensed damping, 6-11 that damping, which also enters the
predictor's right-hand side (:func:`_end_damping`), and from 12 the static extension of each sleeper's rail node
onto the bay after it, which a window's leading end takes in (:mod:`trackenv.physics.window_ends`)."""

Reuse = namedtuple("Reuse", "factor factor_window columns columns_window")
Reuse.__doc__ = """Window factors and bay columns kept from pass to pass over one track at one dt (the effective
stiffness, and so every window's factor and every bay's columns, is the same in each; one-row passes only): the
pre-scaled factor of the window of the axle group whose first axle is in bay s (near the track's ends several
such windows start or end at the same sleeper), factor[s] = (fw[0..B], bw[0..B], inv_diag) (n_sleepers, 2B+3,
m_cap), stored for the window [lo, hi) = factor_window[s] (n_sleepers, 2) (-1: none yet); the
solved columns of bay s, columns[s] (n_sleepers, 2(epb+1), m_cap), for the window columns_window[s]. A window of
more than m_cap DOFs is not kept. Filled by the kernel as it goes; arrays of zero sleepers keep nothing (batches
of several rows, whose chunks' rows change from pass to pass)."""

Peaks = namedtuple("Peaks", "force rail wheel ballast total")
Peaks.__doc__ = """Per-row outputs (chunks, ..., W): contact force, rail and wheel displacement under each wheel
(n_steps+1, n_axles), peak ballast force and peak pad + ballast force per sleeper (n_sleepers,)."""


@njit(inline="always", fastmath=FASTMATH)
def _factor(keff, end_lo, end_hi, lo, m, L, inv_diag, s, W):
    """Banded Cholesky of keff[lo:lo+m] (lower band storage) for every row, with the outside track's stiffness
    added at the window's end nodes (``end_lo``, ``end_hi``: (6, W), see :func:`_end_entry`); L[i, k] = L(i, i-k)
    and inv_diag[i*W + b] = 1 / L(i, i) (flat)."""
    for i in range(m):
        kmax = min(i, B)
        for k in range(kmax, 0, -1):
            j = i - k
            for b in range(W):
                s[b] = keff[lo + i, k, b]
            _add_end_entry(s, end_lo, end_hi, i, k, m, W)
            for c in range(max(i - B, 0), j):
                for b in range(W):
                    s[b] -= L[i, i - c, b] * L[j, j - c, b]
            for b in range(W):
                L[i, k, b] = s[b] * inv_diag[j * W + b]
        for b in range(W):
            s[b] = keff[lo + i, 0, b]
        _add_end_entry(s, end_lo, end_hi, i, 0, m, W)
        for c in range(max(i - B, 0), i):
            for b in range(W):
                s[b] -= L[i, i - c, b] * L[i, i - c, b]
        for b in range(W):
            L[i, 0, b] = np.sqrt(s[b])
            inv_diag[i * W + b] = 1.0 / L[i, 0, b]


@njit(inline="always", fastmath=FASTMATH)
def _end_entry(i, k, m):
    """Which entry of the ends' stiffness adds to the window's entry (i, i-k): 0-2 the first rail node's (w, w),
    (θ, w), (θ, θ) (the window starts with its w, θ), 3-5 the last rail node's (the window ends with its w, θ and
    its sleeper); -1 none."""
    if i == 0:
        return 0
    if i == 1:
        return 2 - k if k <= 1 else -1
    if i == m - 3 and k == 0:
        return 3
    if i == m - 2 and k <= 1:
        return 5 - k
    return -1


@njit(inline="always", fastmath=FASTMATH)
def _add_end_entry(s, end_lo, end_hi, i, k, m, W):
    """s[b] += the ends' stiffness at the window's entry (i, i-k), for every row (exact where it is zero)."""
    e = _end_entry(i, k, m)
    if e >= 3:
        for b in range(W):
            s[b] += end_hi[e, b]
    elif e >= 0:
        for b in range(W):
            s[b] += end_lo[e, b]


@njit(inline="always", fastmath=FASTMATH)
def _scale(L, inv_diag, m, fw, bw, W):
    """Pre-scaled triangular factors for :func:`_solve`, flat: fw[k, i*W + b] = L(i, i-k)/L(i, i),
    bw[k, i*W + b] = L(i+k, i)/L(i, i)."""
    for i in range(m):
        for k in range(1, B + 1):
            for b in range(W):
                f = i * W + b
                fw[k, f] = L[i, k, b] * inv_diag[f] if k <= i else 0.0
                bw[k, f] = L[i + k, k, b] * inv_diag[f] if i + k < m else 0.0


@njit(inline="always", fastmath=FASTMATH)
def _chain_step(x, inv_diag, g4, g3, g2, g1, f, x4, x3, x2, x1):
    """One DOF of a triangular sweep for one row: x[f] / L(i, i) less the terms of the sweep's four previous DOFs
    x4..x1 (g: the pre-scaled factors), in the one order of operations every path of :func:`_solve` uses. The
    terms are fused multiply-adds: the chain from one DOF to the next is then one FMA's latency instead of a
    multiply's and a subtraction's."""
    return fma(-g1[f], x1, fma(-g2[f], x2, fma(-g3[f], x3, fma(-g4[f], x4, x[f] * inv_diag[f]))))


@njit(inline="always", fastmath=FASTMATH)
def _solve(fw, bw, inv_diag, m, x, W):
    """Solve (L Lᵀ) y = x in place for the m DOFs of the flat vector x, every row (factors from :func:`_scale`;
    DOF i of row b at x[i*W + b]). Every index is written so that the compiler sees it is >= 0: numba wraps
    negative indices, and the check it would emit otherwise costs more than the arithmetic. Each sweep is a chain
    along the track per row, its last four DOFs kept in registers: one row as scalars, several rows as the lanes of
    one vector (:func:`sweep_lanes`). Every path does a row's arithmetic in the same order (:func:`_chain_step`),
    so a row's result does not depend on its chunk's width."""
    fw1, fw2, fw3, fw4 = fw[1], fw[2], fw[3], fw[4]
    bw1, bw2, bw3, bw4 = bw[1], bw[2], bw[3], bw[4]
    for i in range(min(m, B)):
        for b in range(W):
            f = i * W + b
            s = x[f] * inv_diag[f]
            for k in range(i, 0, -1):
                s -= fw[k, f] * x[f - k * W]
            x[f] = s
    if W == 1:  # one row: the sweep is a chain of dependent steps; keep its last four values in registers
        x4, x3, x2, x1 = x[0], x[1], x[2], x[3]
        for i in range(B, m):
            x0 = _chain_step(x, inv_diag, fw4, fw3, fw2, fw1, i, x4, x3, x2, x1)
            x[i] = x0
            x4, x3, x2, x1 = x3, x2, x1, x0
    else:  # several rows: the rows as the lanes of one vector, chained in registers
        sweep_lanes(x, inv_diag, fw1, fw2, fw3, fw4, m, True, W)
    for r in range(min(m, B)):
        i = m - 1 - r
        for b in range(W):
            f = i * W + b
            s = x[f] * inv_diag[f]
            for k in range(r, 0, -1):
                s -= bw[k, f] * x[f + k * W]
            x[f] = s
    if W == 1:
        x4, x3, x2, x1 = x[m - 1], x[m - 2], x[m - 3], x[m - 4]
        for r in range(m - B):
            i = m - 1 - B - r
            x0 = _chain_step(x, inv_diag, bw4, bw3, bw2, bw1, i, x4, x3, x2, x1)
            x[i] = x0
            x4, x3, x2, x1 = x3, x2, x1, x0
    else:
        sweep_lanes(x, inv_diag, bw1, bw2, bw3, bw4, m, False, W)


@kernel_jit(fastmath=FASTMATH, pipeline_class=_NoAliasCompiler)
def _solve_rows(fw, bw, inv_diag, m, x, W):
    """:func:`_solve` compiled on its own (``W`` a literal) with distinct arrays (:class:`_NoAliasCompiler`).
    For several rows its loops then run without overlap checks; one row has none to drop and calls it as well."""
    literally(W)
    _solve(fw, bw, inv_diag, m, x, W)


@njit(inline="always", fastmath=FASTMATH)
def _solve_columns_one(fw, bw, inv_diag, m, cols_t, ncol):
    """One row (W = 1): :func:`_solve` for the ``ncol`` columns of ``cols_t`` (m, ncol) side by side, in place.
    One column's sweep is a chain of dependent steps; the columns are independent chains, so sweeping them
    together keeps the processor busy instead of waiting on each step. Each column's arithmetic is exactly
    :func:`_solve`'s (bit-identical). Row indices are unsigned: no negative-index wrap-around check."""
    for i in range(min(m, B)):
        row, d = cols_t[i], inv_diag[i]
        for k in range(ncol):
            row[k] = row[k] * d
        for kk in range(i, 0, -1):
            f, prev = fw[kk, i], cols_t[np.uint64(i - kk)]
            for k in range(ncol):
                row[k] -= f * prev[k]
    for i in range(B, m):
        row, d = cols_t[i], inv_diag[i]
        p4, p3 = cols_t[np.uint64(i - 4)], cols_t[np.uint64(i - 3)]
        p2, p1 = cols_t[np.uint64(i - 2)], cols_t[np.uint64(i - 1)]
        f4, f3, f2, f1 = fw[4, i], fw[3, i], fw[2, i], fw[1, i]
        for k in range(ncol):  # :func:`_chain_step`'s arithmetic
            row[k] = fma(-f1, p1[k], fma(-f2, p2[k], fma(-f3, p3[k], fma(-f4, p4[k], row[k] * d))))
    for r in range(min(m, B)):
        i = np.uint64(m - 1 - r)
        row, d = cols_t[i], inv_diag[i]
        for k in range(ncol):
            row[k] = row[k] * d
        for kk in range(r, 0, -1):
            f, nxt = bw[kk, i], cols_t[i + np.uint64(kk)]
            for k in range(ncol):
                row[k] -= f * nxt[k]
    for r in range(m - B):
        i = np.uint64(m - 1 - B - r)
        row, d = cols_t[i], inv_diag[i]
        n4, n3 = cols_t[i + np.uint64(4)], cols_t[i + np.uint64(3)]
        n2, n1 = cols_t[i + np.uint64(2)], cols_t[i + np.uint64(1)]
        g4, g3, g2, g1 = bw[4, i], bw[3, i], bw[2, i], bw[1, i]
        for k in range(ncol):  # :func:`_chain_step`'s arithmetic
            row[k] = fma(-g1, n1[k], fma(-g2, n2[k], fma(-g3, n3[k], fma(-g4, n4[k], row[k] * d))))


@njit(inline="always", fastmath=FASTMATH)
def _mass_times(rail_mass, mass_diag, xpad, out, lo, hi, W):
    """out = M x on the DOFs of the window [lo, hi) (the track outside it is at rest), every row: flat vectors
    (DOF i of row b at i*W + b), x padded by B DOFs on each side (DOF i at xpad[(i + B)*W + b]) whose B DOFs
    either side of the window the caller has set to zero, so that the whole window is one band loop (a zero term
    adds exactly nothing). M's off-diagonals are the rail's (``Mesh.rail_mass``, shared by the rows), its
    diagonal ``mass_diag`` is per row (the sleepers' masses differ). The nine terms are summed in band order by
    fused multiply-adds (:func:`fma`), in both loops alike: 17 instructions per DOF and vector become 9.
    For one row the loop indexes views from 0, which the compiler vectorises along the track (numba wraps
    negative indices, and a check it cannot drop blocks SIMD); for several rows each DOF is one
    :func:`mass_lanes`, the rows as vector lanes."""
    if W == 1:
        o = out[lo:hi]
        x0, x1, x2 = xpad[lo:], xpad[lo + 1 :], xpad[lo + 2 :]
        x3, x4, x5 = xpad[lo + 3 :], xpad[lo + 4 :], xpad[lo + 5 :]
        x6, x7, x8 = xpad[lo + 6 :], xpad[lo + 7 :], xpad[lo + 8 :]
        m0, m1, m2 = rail_mass[0, lo:], rail_mass[1, lo:], rail_mass[2, lo:]
        m3, m4, m5 = rail_mass[3, lo:], mass_diag[lo:], rail_mass[5, lo:]
        m6, m7, m8 = rail_mass[6, lo:], rail_mass[7, lo:], rail_mass[8, lo:]
        for g in range(hi - lo):
            s = fma(m3[g], x3[g], fma(m2[g], x2[g], fma(m1[g], x1[g], m0[g] * x0[g])))
            s = fma(m7[g], x7[g], fma(m6[g], x6[g], fma(m5[g], x5[g], fma(m4[g], x4[g], s))))
            o[g] = fma(m8[g], x8[g], s)
    else:
        for i in range(lo, hi):  # the one-row loop's arithmetic, term by term, the rows as vector lanes
            mass_lanes(xpad, mass_diag, out, i, rail_mass[0, i], rail_mass[1, i], rail_mass[2, i], rail_mass[3, i],
                        rail_mass[5, i], rail_mass[6, i], rail_mass[7, i], rail_mass[8, i], W)


@kernel_jit(fastmath=FASTMATH)
def _contact(law, param, d):
    """Force and tangent stiffness of the contact law at compression d (0 when d <= 0): :func:`_contact_lane`,
    called (not inlined) where one row at a time needs it."""
    return _contact_lane(law, param, d)


@njit(inline="always", fastmath=FASTMATH)
def _contact_lane(law, param, d):
    """Force and tangent stiffness of the contact law at compression d (0 when d <= 0), written without branches
    so that it runs as SIMD across the rows: where d <= 0 the arithmetic runs on 0 and the result is replaced by
    0."""
    pos = d > 0.0
    dd = d if pos else 0.0
    if law == 0:
        r = dd / param
        sr = np.sqrt(r)
        f, fp = r * sr, 1.5 * sr / param
    else:
        f, fp = param * dd, param
    return (f if pos else 0.0), (fp if pos else 0.0)


@njit(inline="always", fastmath=FASTMATH)
def _copy(src, dst, m):
    """dst[:m] = src[:m] for 1-D views (indexed from 0: no negative-index check, so the loop vectorises)."""
    for i in range(m):
        dst[i] = src[i]


@njit(inline="always", fastmath=FASTMATH)
def _bay_dof(node_w, sleeper_node, bay, k):
    """DOF of the bay's k-th cached column: (w, θ) of its epb+1 rail nodes in turn (the sleeper DOF after the
    first node is skipped; see :func:`_local`)."""
    return node_w[sleeper_node[bay] + k // 2] + (k % 2)


@njit(inline="always", fastmath=FASTMATH)
def _local(dof, base, epb):
    """Index of a rail DOF among the cached columns of its bay (w, θ per node; the sleeper DOF after the first
    node shifts the later nodes by one)."""
    off = dof - base
    if off < 2:
        return off
    if off == 2:
        return -1
    off -= 1  # skip the sleeper DOF that follows the bay's first node
    if off >= 2 * (epb + 1):
        return -1
    return off


Window = namedtuple("Window",
                    "u v a pred rhs qdamp mass_diag pad_k pad_c bal_k bal_c peak_ballast peak_total ends")
Window.__doc__ = """One chunk's track arrays as the window steps see them: state u, v, a and the predictor pred, flat
(n_dof*W); the padded right-hand side rhs ((n_dof + 2B)*W, see :func:`_mass_times`), the damping term qdamp and
the mass diagonal, flat; pads, ballast and peak sleeper forces (n_sleepers, W); the window ends (see
:class:`Rows`). Each a distinct array (see :class:`_NoAliasCompiler`)."""


@njit(inline="always", fastmath=FASTMATH)
def _end_damping(end_lo, end_hi, pred, qdamp, lo, hi, W):
    """The damping the track beyond the window's ends puts on its end nodes, in the predictor's right-hand side:
    pred += C_end (a1 u + a4 v + a5 a) at the first rail node's (w, θ) (``end_lo[6:9]``: (w, w), (θ, w), (θ, θ))
    and the last one's (``end_hi[9:12]``), every row (see :class:`Rows`)."""
    for b in range(W):
        w, t = lo * W + b, (lo + 1) * W + b
        qw, qt = qdamp[w], qdamp[t]
        pred[w] += end_lo[6, b] * qw + end_lo[7, b] * qt
        pred[t] += end_lo[7, b] * qw + end_lo[8, b] * qt
        w, t = (hi - 3) * W + b, (hi - 2) * W + b
        qw, qt = qdamp[w], qdamp[t]
        pred[w] += end_hi[9, b] * qw + end_hi[10, b] * qt
        pred[t] += end_hi[10, b] * qw + end_hi[11, b] * qt


@njit(inline="always", fastmath=FASTMATH)
def _predict_window(win, mesh, drive, fw, bw, inv_diag, lo, hi, s_lo, s_hi, bay_dofs, sleeper_shift, W):
    """Track predictor on the window [lo, hi) (no contact force): K_eff pred = M p + C q for every row, with
    p = a0 u + a2 v + a3 a and q = a1 u + a4 v + a5 a; the window's sleepers are s_lo..s_hi (sleeper g of the
    window has its rail node's deflection at DOF lo + g*bay_dofs and its own DOF sleeper_shift after it)."""
    consts = drive.consts
    a0, a1, a2, a3, a4, a5 = consts[0], consts[1], consts[2], consts[3], consts[4], consts[5]
    u, v, a, rhs, qdamp, pred = win.u, win.v, win.a, win.rhs, win.qdamp, win.pred
    m = hi - lo
    uw, vw, aw = u[lo * W : hi * W], v[lo * W : hi * W], a[lo * W : hi * W]
    rw, qw = rhs[(lo + B) * W : (hi + B) * W], qdamp[lo * W : hi * W]
    for g in range(m * W):
        rw[g] = fma(a3, aw[g], fma(a2, vw[g], a0 * uw[g]))
        qw[g] = fma(a5, aw[g], fma(a4, vw[g], a1 * uw[g]))
    before, after = rhs[lo * W : (lo + B) * W], rhs[(hi + B) * W : (hi + 2 * B) * W]
    for g in range(B * W):
        before[g] = 0.0
        after[g] = 0.0
    # mass product
    _mass_times(mesh.rail_mass, win.mass_diag, rhs, pred, lo, hi, W)
    # damping (only in the pads and the ballast)
    qw, qs = qdamp[lo * W :], qdamp[(lo + sleeper_shift) * W :]
    pw, ps = pred[lo * W :], pred[(lo + sleeper_shift) * W :]
    cp, cb = win.pad_c[s_lo:], win.bal_c[s_lo:]
    if W == 1:
        for g in range(s_hi + 1 - s_lo):
            f = np.uint64(g * bay_dofs)  # unsigned: no negative-index wrap-around check
            fp = cp[g, 0] * (qw[f] - qs[f])
            pw[f] += fp
            ps[f] += fma(cb[g, 0], qs[f], -fp)
    else:  # the same arithmetic, the rows as vector lanes
        for g in range(s_hi + 1 - s_lo):
            w_at = (lo + g * bay_dofs) * W
            damp_lanes(win.pred, win.qdamp, cp[g], cb[g], w_at, w_at + sleeper_shift * W, W)
    if win.ends.shape[1] > 6:  # static ends: the outside's damping on the end nodes
        _end_damping(win.ends[s_lo], win.ends[s_hi], pred, qdamp, lo, hi, W)
    # triangular sweeps
    _solve_rows(fw, bw, inv_diag, m, pred[lo * W : hi * W], W)


@kernel_jit(fastmath=FASTMATH, pipeline_class=_NoAliasInlineCompiler)
def _predict_window_rows(win, mesh, drive, fw, bw, inv_diag, lo, hi, s_lo, s_hi, bay_dofs, sleeper_shift, W):
    """:func:`_predict_window` compiled for a literal width with distinct arrays
    (:class:`_pipeline._NoAliasInlineCompiler`: no overlap checks around its loops across a chunk's rows), inlined
    by LLVM. One row inlines :func:`_predict_window` directly, which measured faster."""
    literally(W)
    _predict_window(win, mesh, drive, fw, bw, inv_diag, lo, hi, s_lo, s_hi, bay_dofs, sleeper_shift, W)


@kernel_jit(fastmath=FASTMATH, pipeline_class=_NoAliasInlineCompiler)
def _correct_window(win, drive, cols, fsh, loc, c, lo, hi, s_lo, s_hi, bay_dofs, sleeper_shift, W):
    """Correct the track on the window [lo, hi) of axle group c, u = pred + Σ_j F_j K⁻¹ N_j (cols[j, loc[j, k]]:
    the solved column of axle j's element DOF k, fsh[j, k]: its contact force times shape function), then its
    Newmark update and the peak sleeper forces of the window's sleepers s_lo..s_hi (indexed as in
    :func:`_predict_window`)."""
    consts, cluster_of_axle = drive.consts, drive.cluster_of_axle
    a0, a2, a3, a6, a7 = consts[0], consts[2], consts[3], consts[6], consts[7]
    m = hi - lo
    u, v, a = win.u, win.v, win.a
    pw, uw, vw, aw = win.pred[lo * W : hi * W], u[lo * W : hi * W], v[lo * W : hi * W], a[lo * W : hi * W]
    for j in range(cluster_of_axle.shape[0]):
        if cluster_of_axle[j] != c:
            continue
        c0 = cols[j, loc[j, 0]]
        c1 = cols[j, loc[j, 1]]
        c2 = cols[j, loc[j, 2]]
        c3 = cols[j, loc[j, 3]]
        f0 = fsh[j, 0]
        f1 = fsh[j, 1]
        f2 = fsh[j, 2]
        f3 = fsh[j, 3]
        if W == 1:
            for i in range(m):
                # products and sums, not fused multiply-adds: written as a chain of fma, LLVM vectorises the
                # lane loop along the track with gathers and scatters
                pw[i] += f0[0] * c0[i] + f1[0] * c1[i] + f2[0] * c2[i] + f3[0] * c3[i]
        else:
            for i in range(m):  # the same products and sums, the rows as vector lanes
                correct_lanes(pw, c0, c1, c2, c3, f0, f1, f2, f3, i, W)
    # Newmark update of the track
    for g in range(m * W):
        an = fma(-a3, aw[g], fma(-a2, vw[g], a0 * (pw[g] - uw[g])))
        vw[g] = fma(a7, an, fma(a6, aw[g], vw[g]))
        aw[g] = an
        uw[g] = pw[g]
    # peak sleeper forces in the window
    uw, us, vw, vs = u[lo * W :], u[(lo + sleeper_shift) * W :], v[lo * W :], v[(lo + sleeper_shift) * W :]
    kp, cp, kb, cb = win.pad_k[s_lo:], win.pad_c[s_lo:], win.bal_k[s_lo:], win.bal_c[s_lo:]
    pb, pt = win.peak_ballast[s_lo:], win.peak_total[s_lo:]
    if W == 1:
        for g in range(s_hi + 1 - s_lo):
            f = np.uint64(g * bay_dofs)
            fb = fma(cb[g, 0], vs[f], kb[g, 0] * us[f])
            fp = fma(cp[g, 0], vw[f] - vs[f], kp[g, 0] * (uw[f] - us[f]))
            pb[g, 0] = max(pb[g, 0], fb)
            pt[g, 0] = max(pt[g, 0], fb + fp)
    else:  # the same arithmetic, the rows as vector lanes
        for g in range(s_hi + 1 - s_lo):
            w_at = (lo + g * bay_dofs) * W
            peak_lanes(u, v, kp[g], cp[g], kb[g], cb[g], pb[g], pt[g], w_at, w_at + sleeper_shift * W, W)


Work = namedtuple(
    "Work",
    "Ls Fw Bw invd lo_c hi_c s_lo_c s_hi_c bay_cache cols tmp cols_t scratch shape edofs elem_of loc wpred ypred "
    "H J rj delta force fprime res fsh rv qpred res_w done_w",
)
Work.__doc__ = """One chunk's workspaces over a pass (each its own allocation; see :func:`_workspaces`)."""


@njit(inline="always", fastmath=FASTMATH)
def _workspaces(n, nv, n_axles, n_clusters, epb, W):
    """The workspaces of a chunk: per window group, the factor being built (Ls), its pre-scaled factors and inverse
    diagonal, window DOFs [lo, hi) and sleepers [s_lo, s_hi]; per axle, its bay, its bay's solved columns, shape
    functions, element DOFs and where they sit among the columns; the contact problem's arrays; the vehicle's
    right-hand side and predictor. A window spans at most the whole track (n DOFs)."""
    ncol = 2 * (epb + 1)
    return Work(
        np.zeros((n, B + 1, W)),
        np.zeros((n_clusters, B + 1, n * W)),
        np.zeros((n_clusters, B + 1, n * W)),
        np.zeros((n_clusters, n * W)),
        np.full(n_clusters, -1, dtype=np.int64),
        np.full(n_clusters, -1, dtype=np.int64),
        np.zeros(n_clusters, dtype=np.int64),
        np.zeros(n_clusters, dtype=np.int64),
        np.full(n_axles, -1, dtype=np.int64),
        np.zeros((n_axles, ncol, n * W)),
        np.zeros(n * W),
        np.zeros((n, ncol)),  # one row: a bay's columns side by side (see _solve_columns_one)
        np.zeros(W),
        np.zeros((n_axles, 4)),
        np.zeros((n_axles, 4), dtype=np.int64),
        np.zeros(n_axles, dtype=np.int64),
        np.zeros((n_axles, 4), dtype=np.int64),
        np.zeros((n_axles, W)),
        np.zeros((n_axles, W)),
        np.zeros((n_axles, n_axles, W)),
        np.zeros((n_axles, n_axles)),
        np.zeros(n_axles),
        np.zeros((n_axles, W)),
        np.zeros((n_axles, W)),
        np.zeros(n_axles),
        np.zeros(n_axles),
        np.zeros((n_axles, 4, W)),
        np.zeros((nv, W)),
        np.zeros((nv, W)),
        np.zeros(W),  # one axle, several rows: the Newton's right-hand sides and converged flags per row
        np.zeros(W),
    )


@kernel_jit(fastmath=FASTMATH, pipeline_class=_InlineCompiler)
def _place_axles(x_axle, step, node_w, elem_len, z_axle, sag, elem_of, shape, edofs, W):
    """Element, Hermite shape functions and element DOFs of every axle at step ``step`` (shared by the rows), and
    the static sag of settled supports added to each row's rail level under the wheel."""
    literally(W)
    for j in range(x_axle.shape[1]):
        x = x_axle[step, j]
        e = int(x / elem_len)
        if e > node_w.shape[0] - 2:
            e = node_w.shape[0] - 2
        if e < 0:
            e = 0
        xi = x / elem_len - e
        elem_of[j] = e
        xi2 = xi * xi
        xi3 = xi2 * xi
        shape[j, 0] = 1.0 - 3.0 * xi2 + 2.0 * xi3
        shape[j, 1] = elem_len * (xi - 2.0 * xi2 + xi3)
        shape[j, 2] = 3.0 * xi2 - 2.0 * xi3
        shape[j, 3] = elem_len * (xi3 - xi2)
        edofs[j, 0] = node_w[e]
        edofs[j, 1] = node_w[e] + 1
        edofs[j, 2] = node_w[e + 1]
        edofs[j, 3] = node_w[e + 1] + 1
        for b in range(W):
            z_axle[step, j, b] += (
                shape[j, 0] * sag[edofs[j, 0], b]
                + shape[j, 1] * sag[edofs[j, 1], b]
                + shape[j, 2] * sag[edofs[j, 2], b]
                + shape[j, 3] * sag[edofs[j, 3], b]
            )


@njit(inline="always", fastmath=FASTMATH)
def _window_factor(keff, end_lo, end_hi, reuse, wk, c, lo, hi, bay_min, keep, W):
    """The pre-scaled factor of group ``c``'s window [lo, hi), its ends' stiffness ``end_lo``, ``end_hi`` added
    (see :func:`_factor`): read back from ``reuse`` where a one-row pass kept it (``keep``) for this window, else
    factored, and kept where ``keep``."""
    m = hi - lo
    Fw, Bw, invd = wk.Fw[c], wk.Bw[c], wk.invd[c]
    if keep and reuse.factor_window[bay_min, 0] == lo and reuse.factor_window[bay_min, 1] == hi:
        kept = reuse.factor[bay_min]
        for k in range(1, B + 1):  # (row 0 of fw and bw is not used)
            _copy(kept[k], Fw[k], m)
            _copy(kept[B + 1 + k], Bw[k], m)
        _copy(kept[2 * B + 2], invd, m)
        return
    _factor(keff, end_lo, end_hi, lo, m, wk.Ls, invd, wk.scratch, W)
    _scale(wk.Ls, invd, m, Fw, Bw, W)
    if keep:
        kept = reuse.factor[bay_min]
        for k in range(1, B + 1):
            _copy(Fw[k], kept[k], m)
            _copy(Bw[k], kept[B + 1 + k], m)
        _copy(invd, kept[2 * B + 2], m)
        reuse.factor_window[bay_min, 0] = lo
        reuse.factor_window[bay_min, 1] = hi


@njit(inline="always", fastmath=FASTMATH)
def _bay_columns_one(mesh, reuse, wk, c, j, bay, lo, hi, keep):
    """One row: K_eff⁻¹ of the unit loads on the rail DOFs of axle j's bay on group ``c``'s window [lo, hi),
    solved in one sweep side by side, or read back where a one-row pass kept them (``keep``)."""
    m = hi - lo
    ncol = wk.cols.shape[1]
    cols, cols_t = wk.cols, wk.cols_t
    if keep and reuse.columns_window[bay, 0] == lo and reuse.columns_window[bay, 1] == hi:
        kept = reuse.columns[bay]
        for k in range(ncol):
            _copy(kept[k], cols[j, k], m)
        return
    for i in range(m):
        for k in range(ncol):
            cols_t[i, k] = 0.0
    for k in range(ncol):
        cols_t[_bay_dof(mesh.node_w, mesh.sleeper_node, bay, k) - lo, k] = 1.0
    _solve_columns_one(wk.Fw[c], wk.Bw[c], wk.invd[c], m, cols_t, ncol)
    for k in range(ncol):
        colk = cols[j, k]
        for i in range(m):
            colk[i] = cols_t[i, k]
    if keep:
        kept = reuse.columns[bay]
        for k in range(ncol):
            _copy(cols[j, k], kept[k], m)
        reuse.columns_window[bay, 0] = lo
        reuse.columns_window[bay, 1] = hi


@njit(inline="always", fastmath=FASTMATH)
def _bay_columns_rows(mesh, wk, c, j, bay, lo, hi, W):
    """Several rows: K_eff⁻¹ of the unit loads on the rail DOFs of axle j's bay on group ``c``'s window [lo, hi),
    one column at a time for every row."""
    m = hi - lo
    tmp = wk.tmp
    for k in range(wk.cols.shape[1]):
        dof = _bay_dof(mesh.node_w, mesh.sleeper_node, bay, k)
        for f in range(m * W):
            tmp[f] = 0.0
        for b in range(W):
            tmp[(dof - lo) * W + b] = 1.0
        _solve_rows(wk.Fw[c], wk.Bw[c], wk.invd[c], m, tmp, W)
        colk = wk.cols[j, k]
        for f in range(m * W):
            colk[f] = tmp[f]


@njit(inline="always", fastmath=FASTMATH)
def _take_in(ends, u, v, a, node_w, sleeper_node, s_from, s_to, W):
    """The state of the bays a window's leading end takes in, after sleepers s_from .. s_to - 1, for every row:
    each bay's DOFs (those after its first sleeper, up to the next sleeper's) are the static extension of its
    first rail node's w and θ (``ends[s, 12 + 2d + 0/1]``, see :func:`trackenv.physics.window_ends.outside_transfer`),
    in u, v and a, bay after bay (each from the node the bay before it set). A bay's DOFs follow its first node's
    w, θ and sleeper (:class:`trackenv.physics.track.DofLayout`)."""
    bay_dofs = (ends.shape[1] - 12) // 2
    for s in range(s_from, s_to):
        node = node_w[sleeper_node[s]]
        t = ends[s]
        for d in range(bay_dofs):
            f = (node + 3 + d) * W
            for b in range(W):
                tw, tt = t[12 + 2 * d, b], t[13 + 2 * d, b]
                u[f + b] = tw * u[node * W + b] + tt * u[(node + 1) * W + b]
                v[f + b] = tw * v[node * W + b] + tt * v[(node + 1) * W + b]
                a[f + b] = tw * a[node * W + b] + tt * a[(node + 1) * W + b]


@kernel_jit(fastmath=FASTMATH, pipeline_class=_CalledCompiler)
def _move_window(mesh, drive, keff, ends, reuse, u, v, a, m_cap, wk, c, bay_min, bay_max, W):
    """Move group ``c``'s window to span ``margin_bays`` sleepers beyond its bays [bay_min, bay_max]: the DOFs
    left behind come to rest, and the new window's factor and its axles' bay columns are built (or read back).
    Runs only when a group enters a new bay: called, not inlined, so that the step loop stays small."""
    literally(W)
    node_w, sleeper_dof, sleeper_node = mesh.node_w, mesh.sleeper_dof, mesh.sleeper_node
    n_sleepers, margin_bays, epb = mesh.n_sleepers, mesh.margin_bays, mesh.epb
    cluster_of_axle, lo_c, hi_c = drive.cluster_of_axle, wk.lo_c, wk.hi_c
    s_lo = max(0, bay_min - margin_bays)
    s_hi = min(n_sleepers - 1, bay_max + 1 + margin_bays)
    lo = node_w[sleeper_node[s_lo]]
    hi = sleeper_dof[s_hi] + 1
    if ends.shape[1] > 12 and hi_c[c] >= 0:  # static ends: the bays taken in continue the end's static basin
        _take_in(ends, u, v, a, node_w, sleeper_node, wk.s_hi_c[c], s_hi, W)
    if lo_c[c] >= 0:  # DOFs left behind come to rest
        for f in range(lo_c[c] * W, min(lo, hi_c[c]) * W):
            u[f] = 0.0
            v[f] = 0.0
            a[f] = 0.0
    lo_c[c] = lo
    hi_c[c] = hi
    wk.s_lo_c[c] = s_lo
    wk.s_hi_c[c] = s_hi
    keep = W == 1 and hi - lo <= m_cap  # one row: this window's factor and columns are kept across passes
    _window_factor(keff, ends[s_lo], ends[s_hi], reuse, wk, c, lo, hi, bay_min, keep, W)
    for j in range(cluster_of_axle.shape[0]):
        if cluster_of_axle[j] != c:
            continue
        bay = wk.elem_of[j] // epb
        wk.bay_cache[j] = bay
        if W == 1:
            _bay_columns_one(mesh, reuse, wk, c, j, bay, lo, hi, keep)
        else:
            _bay_columns_rows(mesh, wk, c, j, bay, lo, hi, W)


@kernel_jit(fastmath=FASTMATH, pipeline_class=_InlineCompiler)
def _predict_vehicle(consts, mv, cv, kv_inv, fv, q, qd, qdd, rv, qpred, W):
    """Vehicle predictor (no contact force): K_eff q = f + M p + C r with p = a0 q + a2 qd + a3 qdd and
    r = a1 q + a4 qd + a5 qdd, through the vehicle's K_eff⁻¹."""
    literally(W)
    a0, a1, a2, a3, a4, a5 = consts[0], consts[1], consts[2], consts[3], consts[4], consts[5]
    nv = q.shape[0]
    for i in range(nv):
        for b in range(W):
            rv[i, b] = fv[i]
        for k in range(nv):
            mik = mv[i, k]
            cik = cv[i, k]
            for b in range(W):
                rv[i, b] += mik * (a0 * q[k, b] + a2 * qd[k, b] + a3 * qdd[k, b]) + cik * (
                    a1 * q[k, b] + a4 * qd[k, b] + a5 * qdd[k, b]
                )
    for i in range(nv):
        for b in range(W):
            qpred[i, b] = 0.0
        for k in range(nv):
            kik = kv_inv[i, k]
            for b in range(W):
                qpred[i, b] += kik * rv[k, b]


@kernel_jit(fastmath=FASTMATH, pipeline_class=_InlineCompiler)
def _wheel_flexibilities(cluster_of_axle, wheel_dofs, kv_inv, lo_c, pred, qpred, shape, edofs, loc, cols, wpred,
                         ypred, H, W):
    """The predicted rail and wheel under each wheel, and the flexibility H[j, i] of wheel j to a unit contact
    force at wheel i: the vehicle's (K_eff⁻¹ at the wheels) plus the track's where both axles share a window."""
    literally(W)
    n_axles = shape.shape[0]
    for j in range(n_axles):
        c = cluster_of_axle[j]
        lo = lo_c[c]
        for b in range(W):
            wpred[j, b] = (
                shape[j, 0] * pred[edofs[j, 0] * W + b]
                + shape[j, 1] * pred[edofs[j, 1] * W + b]
                + shape[j, 2] * pred[edofs[j, 2] * W + b]
                + shape[j, 3] * pred[edofs[j, 3] * W + b]
            )
            ypred[j, b] = qpred[wheel_dofs[j], b]
        for i in range(n_axles):
            hv = kv_inv[wheel_dofs[j], wheel_dofs[i]]
            for b in range(W):
                H[j, i, b] = hv
            if cluster_of_axle[i] != c:
                continue
            for k in range(4):
                # column of axle i's DOF k evaluated at axle j's DOFs
                lk = loc[i, k]
                if lk < 0:
                    continue
                col = cols[i, lk]
                for b in range(W):
                    acc = (
                        shape[j, 0] * col[(edofs[j, 0] - lo) * W + b]
                        + shape[j, 1] * col[(edofs[j, 1] - lo) * W + b]
                        + shape[j, 2] * col[(edofs[j, 2] - lo) * W + b]
                        + shape[j, 3] * col[(edofs[j, 3] - lo) * W + b]
                    )
                    H[j, i, b] += shape[i, k] * acc


@kernel_jit(fastmath=FASTMATH, pipeline_class=_InlineCompiler)
def _newton_one_axle(law, param, z_axle, step, wpred, ypred, H, delta, force, shape, fsh, res_w, done_w, W):
    """One axle, several rows: the rows' scalar Newton iterations on the compression d = d_pred - H f(d) side by
    side (SIMD); a row that has converged keeps its compression while the others go on, so each row takes exactly
    the steps it takes alone. Leaves the contact force and its shape-function loads (``fsh``)."""
    literally(W)
    d0, f0, h0, z0 = delta[0], force[0], H[0, 0], z_axle[step, 0]
    for b in range(W):
        res_w[b] = ypred[0, b] - wpred[0, b] - z0[b]
        if f0[b] <= 0.0:
            d0[b] = res_w[b]
        done_w[b] = 0.0
    for _it in range(60):
        alive = 0.0
        for b in range(W):
            fb, fpb = _contact_lane(law, param, d0[b])
            r = d0[b] - res_w[b]
            r += h0[b] * fb
            stop = done_w[b] > 0.0 or abs(r) < 1e-15
            step_b = -r / (h0[b] * fpb + 1.0)
            d0[b] = d0[b] if stop else d0[b] + step_b
            done_w[b] = 1.0 if stop else 0.0
            alive += 0.0 if stop else 1.0
        if alive == 0.0:
            break
    for b in range(W):
        f0[b], fpb = _contact_lane(law, param, d0[b])
        for k in range(4):
            fsh[0, k, b] = f0[b] * shape[0, k]


@kernel_jit(fastmath=FASTMATH, pipeline_class=_InlineCompiler)
def _correct_vehicle(consts, kv_inv, wheel_dofs, q, qd, qdd, qpred, rv, force, W):
    """Vehicle corrector: q = q_pred - K_eff⁻¹ Σ_j F_j e_wheel(j), then its Newmark update."""
    literally(W)
    a0, a2, a3, a6, a7 = consts[0], consts[2], consts[3], consts[6], consts[7]
    for i in range(q.shape[0]):
        for b in range(W):
            rv[i, b] = qpred[i, b]
        for j in range(wheel_dofs.shape[0]):
            kij = kv_inv[i, wheel_dofs[j]]
            for b in range(W):
                rv[i, b] -= kij * force[j, b]
        for b in range(W):
            an = a0 * (rv[i, b] - q[i, b]) - a2 * qd[i, b] - a3 * qdd[i, b]
            qd[i, b] += a6 * qdd[i, b] + a7 * an
            qdd[i, b] = an
            q[i, b] = rv[i, b]


@kernel_jit(fastmath=FASTMATH, pipeline_class=_InlineCompiler)
def _record(step, u, q, wheel_dofs, shape, edofs, force, out_force, out_rail, out_wheel, W):
    """Contact force, rail and wheel displacement under each wheel at step ``step``."""
    literally(W)
    for j in range(shape.shape[0]):
        for b in range(W):
            out_force[step, j, b] = force[j, b]
            out_rail[step, j, b] = (
                shape[j, 0] * u[edofs[j, 0] * W + b]
                + shape[j, 1] * u[edofs[j, 1] * W + b]
                + shape[j, 2] * u[edofs[j, 2] * W + b]
                + shape[j, 3] * u[edofs[j, 3] * W + b]
            )
            out_wheel[step, j, b] = q[wheel_dofs[j], b]


@njit(inline="always", fastmath=FASTMATH)
def _initial_compressions(law, param, force_history, force, delta, W):
    """The contact forces at the start (step 0 of ``force_history``) and the compressions that carry them."""
    for j in range(force.shape[0]):
        for b in range(W):
            force[j, b] = force_history[0, j, b]
            if law == 0:
                delta[j, b] = param * force[j, b] ** (2.0 / 3.0)
            else:
                delta[j, b] = force[j, b] / param


@njit(inline="always", fastmath=FASTMATH)
def _run_chunk(mesh, drive, rows, peaks, reuse, ch, W):
    """Integrate chunk ``ch`` of the batch (its rows in lockstep) over the whole pass, in place, from the state in
    ``rows`` and the contact forces in ``peaks.force[ch, 0]``.

    The track's state vectors are used flat, DOF i of row b at i*W + b (W a compile-time constant): loops over a
    whole window's DOFs and rows are one unit-stride loop at any width. The step's sections are functions compiled
    apart and inlined by LLVM (:class:`_pipeline._InlineCompiler`); their arrays are taken out of the argument
    tuples once, here, so that the step loop updates no reference count."""
    n = rows.u.shape[1]
    u, v, a = rows.u[ch].reshape(n * W), rows.v[ch].reshape(n * W), rows.a[ch].reshape(n * W)
    q, qd, qdd = rows.q[ch], rows.qd[ch], rows.qdd[ch]
    z_axle, sag, keff, ends = rows.z[ch], rows.sag[ch], rows.keff[ch], rows.ends[ch]
    out_force, out_rail, out_wheel = peaks.force[ch], peaks.rail[ch], peaks.wheel[ch]
    win = Window(u, v, a, np.zeros(n * W), np.zeros((n + 2 * B) * W), np.zeros(n * W),
                 rows.mass_diag[ch].reshape(n * W), rows.pad_k[ch], rows.pad_c[ch], rows.bal_k[ch], rows.bal_c[ch],
                 peaks.ballast[ch], peaks.total[ch], ends)  # rhs padded by B DOFs each side (see _mass_times)
    node_w, sleeper_node, epb = mesh.node_w, mesh.sleeper_node, mesh.epb
    n_sleepers, elem_len = mesh.n_sleepers, mesh.elem_len
    x_axle, consts, law, param, n_clusters = drive.x_axle, drive.consts, drive.law, drive.param, drive.n_clusters
    cluster_of_axle, wheel_dofs, kv_inv = drive.cluster_of_axle, drive.wheel_dofs, drive.kv_inv
    mv, cv, fv = drive.mass, drive.damping, drive.force
    n_axles = x_axle.shape[1]
    wk = _workspaces(n, q.shape[0], n_axles, n_clusters, epb, W)
    Fw, Bw, invd, lo_c, hi_c, s_lo_c, s_hi_c = wk.Fw, wk.Bw, wk.invd, wk.lo_c, wk.hi_c, wk.s_lo_c, wk.s_hi_c
    bay_cache, cols, shape, edofs, elem_of, loc = wk.bay_cache, wk.cols, wk.shape, wk.edofs, wk.elem_of, wk.loc
    wpred, ypred, H, delta, force, fsh = wk.wpred, wk.ypred, wk.H, wk.delta, wk.force, wk.fsh
    rv, qpred, fprime, res, rj, J, res_w, done_w = wk.rv, wk.qpred, wk.fprime, wk.res, wk.rj, wk.J, wk.res_w, wk.done_w
    pred = win.pred
    # the DOF layout is regular (track.DofLayout): a bay is bay_dofs DOFs, and a sleeper's DOF follows its rail
    # node's deflection by sleeper_shift; a window starts at a sleeper's rail node
    bay_dofs = mesh.sleeper_dof[1] - mesh.sleeper_dof[0]
    sleeper_shift = mesh.sleeper_dof[0] - node_w[mesh.sleeper_node[0]]
    m_cap = reuse.factor.shape[2] if reuse.factor.shape[0] == mesh.n_sleepers else 0  # no sleepers kept: 0
    _initial_compressions(law, param, out_force, force, delta, W)

    for step in range(1, x_axle.shape[0]):
        # ---- element, shape functions and window of every axle at t_{n+1} (shared by the rows)
        _place_axles(x_axle, step, node_w, elem_len, z_axle, sag, elem_of, shape, edofs, W)
        # ---- move the window of every axle group that has entered a new bay: factor, columns of its bay
        for c in range(n_clusters):
            changed, bay_min, bay_max = False, n_sleepers, -1
            for j in range(n_axles):
                if cluster_of_axle[j] == c:  # the bay of the axle's element, so element and bay always agree
                    bay = elem_of[j] // epb
                    changed = changed or bay != bay_cache[j]
                    bay_min, bay_max = min(bay_min, bay), max(bay_max, bay)
            if changed:
                _move_window(mesh, drive, keff, ends, reuse, u, v, a, m_cap, wk, c, bay_min, bay_max, W)
        # ---- where the axles' element DOFs sit among their bay's columns
        for j in range(n_axles):
            basej = node_w[sleeper_node[bay_cache[j]]]
            for k in range(4):
                loc[j, k] = _local(edofs[j, k], basej, epb)
        # ---- track predictor (no contact force) in every window: K_eff u = M p + C q
        for c in range(n_clusters):
            lo, hi, s_lo, s_hi = lo_c[c], hi_c[c], s_lo_c[c], s_hi_c[c]
            if W == 1:
                _predict_window(win, mesh, drive, Fw[c], Bw[c], invd[c], lo, hi, s_lo, s_hi, bay_dofs, sleeper_shift,
                                W)
            else:
                _predict_window_rows(win, mesh, drive, Fw[c], Bw[c], invd[c], lo, hi, s_lo, s_hi, bay_dofs,
                                     sleeper_shift, W)
        # ---- vehicle predictor
        _predict_vehicle(consts, mv, cv, kv_inv, fv, q, qd, qdd, rv, qpred, W)
        # ---- flexibilities at the wheels and contact predictor
        _wheel_flexibilities(cluster_of_axle, wheel_dofs, kv_inv, lo_c, pred, qpred, shape, edofs, loc, cols, wpred,
                             ypred, H, W)
        # ---- Newton on the compressions, row by row: d = d_pred - H f(d)
        # (a wheel off the rail starts from its free compression; written out: as a function the pass was slower)
        if W > 1 and n_axles == 1:  # compile-time W: the one-row entry has only the general loop
            _newton_one_axle(law, param, z_axle, step, wpred, ypred, H, delta, force, shape, fsh, res_w, done_w, W)
        else:
            for b in range(W):
                for j in range(n_axles):
                    res[j] = ypred[j, b] - wpred[j, b] - z_axle[step, j, b]
                    if force[j, b] <= 0.0:
                        delta[j, b] = res[j]
                for _it in range(60):
                    for j in range(n_axles):
                        force[j, b], fprime[j] = _contact(law, param, delta[j, b])
                    err = 0.0
                    for j in range(n_axles):
                        r = delta[j, b] - res[j]
                        for i in range(n_axles):
                            r += H[j, i, b] * force[i, b]
                        rj[j] = -r
                        for i in range(n_axles):
                            J[j, i] = H[j, i, b] * fprime[i] + (1.0 if i == j else 0.0)
                        err = max(err, abs(r))
                    if err < 1e-15:
                        break
                    if n_axles == 1:
                        delta[0, b] += rj[0] / J[0, 0]
                    else:
                        dx = np.linalg.solve(J, rj)
                        for j in range(n_axles):
                            delta[j, b] += dx[j]
                for j in range(n_axles):
                    force[j, b], fprime[j] = _contact(law, param, delta[j, b])
                for j in range(n_axles):
                    for k in range(4):
                        fsh[j, k, b] = force[j, b] * shape[j, k]
        # ---- correct the track, u = pred + Σ_j F_j K⁻¹ N_j, its Newmark update and peak sleeper forces
        for c in range(n_clusters):
            lo, hi, s_lo, s_hi = lo_c[c], hi_c[c], s_lo_c[c], s_hi_c[c]
            _correct_window(win, drive, cols, fsh, loc, c, lo, hi, s_lo, s_hi, bay_dofs, sleeper_shift, W)
        # ---- correct the vehicle
        _correct_vehicle(consts, kv_inv, wheel_dofs, q, qd, qdd, qpred, rv, force, W)
        # ---- outputs under the wheels
        _record(step, u, q, wheel_dofs, shape, edofs, force, out_force, out_rail, out_wheel, W)
