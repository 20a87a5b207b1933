"""The compiled time-stepping kernel behind :func:`trackenv.physics.dynamics.simulate_passes`.

Newmark average acceleration (β = 1/4, γ = 1/2: implicit, unconditionally stable, no numerical damping) on the
linear track and the linear vehicle, coupled by the non-linear contact law, which is solved by Newton's method
every step. Only the contact forces couple the two, so each step is: predict both without contact, solve the
small contact problem through the two flexibilities at the wheels, correct both.

Speed comes from a window of the standing track that follows each group of axles. The supports are damped and
the rail's deflection decays like e^{-βx}, so beyond a few decay lengths the track hardly moves: inside the
window the track is integrated in full, outside it is at rest. The window is a contiguous block of the banded
matrices (DOFs are numbered along the track) and moves by whole bays; the DOFs it leaves behind are set back to
rest. Every quantity the caller sees (contact force, rail deflection, peak sleeper forces) is taken where the
window is. With the window as long as the track this is the full model. (The caller sizes the window from the
track's decay length: see ``dynamics.window_margin``.)

Lockstep batch. The rows of a batch share the mesh, the vehicle, the speed and dt, so their windows move together;
only the supports, the irregularity and the state differ. Every per-row array carries the batch axis *last*
(innermost), and the track's state vectors are used flat, DOF i of row b at i*W + b, with the chunk width W a
compile-time constant. For one row (W = 1) the hot loops run along the track as unit-stride loops, which compile to
SIMD. For several rows, each DOF's (or sleeper's) work across the chunk's rows is written in LLVM's IR with the rows
as the lanes of one vector (:func:`_mass_lanes`, :func:`_correct_lanes`, :func:`_damp_lanes`,
:func:`_peak_lanes`): a loop over 4, 6 or 8 rows is too short for LLVM's loop vectoriser, which unrolled it and
then left it scalar or vectorised it along the track with gathers and scatters (the 8-row kernel took 1 250 cycles
per row and step, against 860 with the lane code; the 16-row one 820 against 790). The Newmark update and the
predictor's right-hand side are one loop over the flat window at any width. The triangular sweeps are chains along
the track of fused multiply-adds, the chain's last four DOFs in registers: one row's as scalars, several rows' as the
lanes of one vector (:func:`_sweep_lanes`). Loops index
views from 0 wherever they can: numba wraps negative indices, and the check it emits where it cannot prove an index
non-negative blocks vectorisation (it cost the single pass half its time). Where an index has to be computed (the
sleepers of a window, the rows of a column sweep) it is cast to unsigned, for which numba emits no wrap-around: the
one-row sleeper loops ran twice as fast that way. The comment lines ``# ---- <name>`` of the time-step loop mark its
sections: ``experiments/kernel_profile.py`` counts the processor cycles spent in each (sampling profilers see
nothing inside the compiled functions). The track's predictor and corrector on a window are functions of their own
(:func:`_predict_window`, :func:`_correct_window`, their arrays gathered in ``Window``); for several rows they, and
the triangular sweeps, are compiled apart with the promise that their arrays do not overlap
(:class:`_NoAliasCompiler`), which lets LLVM drop the overlap checks it put around every loop across the rows. The
rail's mass band is stored once (``Mesh.rail_mass``), not per row. The batch is cut into chunks of rows (``Chunks``
arrays have a leading chunk axis), and the chunks run on the cores in parallel. The kernel is compiled without
reassociating fast-math: every row's arithmetic is the same IEEE sequence whatever its SIMD lane, chunk width or
thread, so a row's result does not depend on the batch it runs in (bit-identical; tested). The single pass is a
batch of one.

The arguments are five typed structures (namedtuples of arrays, which numba accepts), defined once here:
``Mesh`` and ``Drive`` (shared by all rows), ``Rows`` (per-row inputs and state, updated in place), ``Peaks``
(per-row outputs) and ``Reuse`` (window factors and bay columns a one-row pass keeps for the next pass over its
track; empty for batches).
"""

from __future__ import annotations

from collections import namedtuple

import llvmlite.binding as ll
import numpy as np
from llvmlite import ir
from numba import literally, njit, prange
from numba.core import cgutils, types
from numba.core import config as numba_config
from numba.core.compiler import CompilerBase, DefaultPassBuilder
from numba.core.compiler_machinery import register_pass
from numba.core.lowering import Lower
from numba.core.typed_passes import NativeLowering
from numba.extending import intrinsic

B = 4  # half-bandwidth of the track matrices (see track.DofLayout)
# Floating-point freedoms that do not make a row depend on its SIMD lane, width or compiled copy: no NaN/inf/-0
# bookkeeping only. Never reassociation or approximate reciprocals, and no fused multiply-adds left to the compiler
# ("contract"): LLVM fuses where it chooses, differently in each compiled copy (a chunk of 16 rows moved by ~1e-13
# between the serial and the parallel entry), which broke the bit-identity of a row across batch sizes. Where a
# fused multiply-add pays, the kernel writes it out (:func:`_fma`), the same in every path.
FASTMATH = {"nnan", "ninf", "nsz"}
# rows per chunk the kernel is compiled for (each a constant in its own compiled copy); 6: the line env's 12
# segments on two threads run as two chunks of 6 (as chunks of 8, a quarter of the lanes were padding: the line step
# took ~14 % longer)
WIDTHS = (1, 4, 6, 8, 16)

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

Rows = namedtuple("Rows", "mass_diag keff pad_k pad_c bal_k bal_c z sag u v a q qd qdd")
Rows.__doc__ = """Per-row inputs and state, chunk axis first and batch axis last: the diagonal of the track's
mass matrix (chunks, n_dof, W) [kg] (rail and sleepers; ``Mesh.rail_mass`` holds the rest), effective stiffness
in lower band storage (chunks, n_dof, B+1, W), pad and ballast stiffness and damping (chunks, n_sleepers, W), rail
level under each wheel (chunks, n_steps+1, n_axles, W) [m] to which the kernel adds the static sag ``sag``
(chunks, n_dof, W) of settled supports, and the track and vehicle state u, v, a (chunks, n_dof, W), q, qd, qdd
(chunks, nv, W), all updated in place."""

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


@njit(cache=True, inline="always", fastmath=FASTMATH)
def _factor(keff, lo, m, L, inv_diag, s, W):
    """Banded Cholesky of keff[lo:lo+m] (lower band storage) for every row; L[i, k] = L(i, i-k) and
    inv_diag[i*W + b] = 1 / L(i, i) (flat)."""
    for i in range(m):
        kmax = min(i, B)
        for k in range(kmax, 0, -1):
            j = i - k
            for b in range(W):
                s[b] = keff[lo + i, k, b]
            for c in range(max(i - B, 0), j):
                for b in range(W):
                    s[b] -= L[i, i - c, b] * L[j, j - c, b]
            for b in range(W):
                L[i, k, b] = s[b] * inv_diag[j * W + b]
        for b in range(W):
            s[b] = keff[lo + i, 0, b]
        for c in range(max(i - B, 0), i):
            for b in range(W):
                s[b] -= L[i, i - c, b] * L[i, i - c, b]
        for b in range(W):
            L[i, 0, b] = np.sqrt(s[b])
            inv_diag[i * W + b] = 1.0 / L[i, 0, b]


@njit(cache=True, inline="always", fastmath=FASTMATH)
def _scale(L, inv_diag, m, fw, bw, W):
    """Pre-scaled triangular factors for :func:`_solve`, flat: fw[k, i*W + b] = L(i, i-k)/L(i, i),
    bw[k, i*W + b] = L(i+k, i)/L(i, i)."""
    for i in range(m):
        for k in range(1, B + 1):
            for b in range(W):
                f = i * W + b
                fw[k, f] = L[i, k, b] * inv_diag[f] if k <= i else 0.0
                bw[k, f] = L[i + k, k, b] * inv_diag[f] if i + k < m else 0.0


@intrinsic
def _fma(typingctx, a, b, c):
    """a·b + c rounded once: LLVM's ``llvm.fma`` intrinsic, one instruction on a processor with FMA (a correctly
    rounded library call on one without, same result). Written out where the kernel wants it, never left to the
    compiler (see FASTMATH), so that every compiled copy fuses the same operations."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        f64 = ir.DoubleType()
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(f64, [f64, f64, f64]), "llvm.fma.f64")
        return builder.call(fn, args)

    return sig, codegen


@njit(cache=True, inline="always", fastmath=FASTMATH)
def _chain_step(x, inv_diag, g4, g3, g2, g1, f, x4, x3, x2, x1):
    """One DOF of a triangular sweep for one row: x[f] / L(i, i) less the terms of the sweep's four previous DOFs
    x4..x1 (g: the pre-scaled factors), in the one order of operations every path of :func:`_solve` uses. The
    terms are fused multiply-adds: the chain from one DOF to the next is then one FMA (4 cycles) instead of a
    multiply and a subtraction (8), which halves a one-row sweep (a micro-benchmark on 68 DOFs: 6.3 -> 3.5
    cycles per DOF at the nominal clock)."""
    return _fma(-g1[f], x1, _fma(-g2[f], x2, _fma(-g3[f], x3, _fma(-g4[f], x4, x[f] * inv_diag[f]))))


def _lane_arrays(arrays) -> bool:
    """Whether every one of ``arrays`` is a contiguous 1-D float64 array (what the lane intrinsics index)."""
    return all(isinstance(a, types.Array) and a.ndim == 1 and a.layout == "C" and a.dtype == types.float64
               for a in arrays)


def _lanes(context, builder, signature, args, n_arrays, W):
    """The pieces every lane intrinsic's code needs, as (i64, vec, ptrs, load, store, splat, fma): the 64-bit
    integer and W-lane vector types, the data pointers of its first ``n_arrays`` arguments, ``load(p, start)`` and
    ``store(v, p, start)`` of the W lanes from flat index ``start``, ``splat`` (a scalar in every lane) and the
    vector fused multiply-add."""
    i64, f64 = ir.IntType(64), ir.DoubleType()
    vec = ir.VectorType(f64, W)
    ptrs = [context.make_array(ty)(context, builder, val).data
            for ty, val in zip(signature.args[:n_arrays], args[:n_arrays])]

    def at(p, start):
        return builder.bitcast(builder.gep(p, [start]), vec.as_pointer())

    def load(p, start):
        return builder.load(at(p, start), align=8)

    def store(v, p, start):
        builder.store(v, at(p, start), align=8)

    def splat(x):
        undef, i32 = ir.Constant(vec, ir.Undefined), ir.IntType(32)
        one = builder.insert_element(undef, x, ir.Constant(i32, 0))
        return builder.shuffle_vector(one, undef, ir.Constant(ir.VectorType(i32, W), [0] * W))

    fma = cgutils.get_or_insert_function(builder.module, ir.FunctionType(vec, [vec, vec, vec]), f"llvm.fma.v{W}f64")
    return i64, vec, ptrs, load, store, splat, fma


@intrinsic
def _sweep_lanes(typingctx, x, inv_diag, g1, g2, g3, g4, m, forward, width):
    """The chain part of a triangular sweep for a chunk of ``width`` rows: DOFs B..m-1 (``forward``) or m-1-B..0
    (backward) of the flat vector x (DOF i of row b at i*W + b), the rows as the lanes of one LLVM vector whose
    sweep's four previous DOFs stay in registers, each lane doing :func:`_chain_step`'s arithmetic (so a row's
    result is the one-row path's, bit for bit). numba has no vector type and its loop vectoriser does not see
    through the chain, so the loop is written here in LLVM's IR: a micro-benchmark (TSC cycles per DOF and sweep,
    90 DOFs) gave 13 against 21 for blocks of four register chains at 8 rows, and 26 against 40 for the loop
    across the lanes at 16. Every array must be contiguous (checked when the caller is compiled)."""
    if not isinstance(width, types.IntegerLiteral) or not _lane_arrays((x, inv_diag, g1, g2, g3, g4)):
        return None
    W = width.literal_value
    sig = types.none(x, inv_diag, g1, g2, g3, g4, m, forward, width)

    def codegen(context, builder, signature, args):
        i64, vec, ptrs, load_flat, store_flat, _, vfma = _lanes(context, builder, signature, args, 6, W)
        xp, dp, p1, p2, p3, p4 = ptrs
        m_, fwd = args[6], builder.icmp_unsigned("!=", args[7], ir.Constant(args[7].type, 0))

        def load(p, dof):  # the W lanes of DOF ``dof``
            return load_flat(p, builder.mul(dof, ir.Constant(i64, W)))

        count = builder.sub(m_, ir.Constant(i64, B))  # the chain's DOFs
        step = builder.select(fwd, ir.Constant(i64, 1), ir.Constant(i64, -1))
        first = builder.select(fwd, ir.Constant(i64, B), builder.sub(m_, ir.Constant(i64, B + 1)))
        with builder.if_then(builder.icmp_signed(">", count, ir.Constant(i64, 0))):
            # the four DOFs before the first, as the sweep runs: first - 4*step .. first - step
            prev = [load(xp, builder.sub(first, builder.mul(step, ir.Constant(i64, k)))) for k in (4, 3, 2, 1)]
            entry = builder.block
            loop = builder.append_basic_block("sweep_lanes")
            done = builder.append_basic_block("sweep_lanes_done")
            builder.branch(loop)
            builder.position_at_end(loop)
            k, i = builder.phi(i64), builder.phi(i64)
            v = [builder.phi(vec) for _ in range(4)]  # x4, x3, x2, x1
            k.add_incoming(ir.Constant(i64, 0), entry)
            i.add_incoming(first, entry)
            for phi, val in zip(v, prev):
                phi.add_incoming(val, entry)
            t = builder.fmul(load(xp, i), load(dp, i))
            for g, xv in zip((p4, p3, p2, p1), v):
                t = builder.call(vfma, [builder.fneg(load(g, i)), xv, t])
            store_flat(t, xp, builder.mul(i, ir.Constant(i64, W)))
            k_next, i_next = builder.add(k, ir.Constant(i64, 1)), builder.add(i, step)
            body = builder.block
            k.add_incoming(k_next, body)
            i.add_incoming(i_next, body)
            for phi, val in zip(v, (v[1], v[2], v[3], t)):
                phi.add_incoming(val, body)
            builder.cbranch(builder.icmp_signed("<", k_next, count), loop, done)
            builder.position_at_end(done)
        return context.get_dummy_value()

    return sig, codegen


@intrinsic
def _mass_lanes(typingctx, xpad, mass_diag, out, i, r0, r1, r2, r3, r5, r6, r7, r8, width):
    """One DOF i of :func:`_mass_times` for a chunk of ``width`` rows, the rows as the lanes of one LLVM vector:
    out[i*W + b] = Σ_k M(i, i + k - B) xpad[(i + k)*W + b], the same fused multiply-adds in the same order as
    the one-row loop (a row's result is the one-row path's, bit for bit). Written in LLVM's IR because a loop
    over 4, 6 or 8 rows is too short for LLVM's loop vectoriser (it unrolls it first, then vectorises it badly
    or not at all: the 8-row mass product took longer than the 16-row one)."""
    if not isinstance(width, types.IntegerLiteral) or not _lane_arrays((xpad, mass_diag, out)):
        return None
    W = width.literal_value
    sig = types.none(xpad, mass_diag, out, i, r0, r1, r2, r3, r5, r6, r7, r8, width)

    def codegen(context, builder, signature, args):
        i64, vec, (xp, mp, op), load, store, splat, fma = _lanes(context, builder, signature, args, 3, W)
        base = builder.mul(args[3], ir.Constant(i64, W))
        x = [load(xp, builder.add(base, ir.Constant(i64, k * W))) for k in range(2 * B + 1)]
        r = [splat(v) for v in args[4:12]]  # r0 r1 r2 r3 r5 r6 r7 r8
        s = builder.fmul(r[0], x[0])
        for c, xv in ((r[1], x[1]), (r[2], x[2]), (r[3], x[3]), (load(mp, base), x[4]), (r[4], x[5]), (r[5], x[6]),
                      (r[6], x[7]), (r[7], x[8])):
            s = builder.call(fma, [c, xv, s])
        store(s, op, base)
        return context.get_dummy_value()

    return sig, codegen


@intrinsic
def _correct_lanes(typingctx, pred, c0, c1, c2, c3, f0, f1, f2, f3, i, width):
    """One DOF i of the correction in :func:`_correct_window` for a chunk of ``width`` rows (the rows as the
    lanes of one LLVM vector): pred[i*W + b] += f0[b]*c0[i*W + b] + f1[b]*c1[…] + f2[b]*c2[…] + f3[b]*c3[…],
    products and sums in the one-row path's order (bit for bit its result). See :func:`_mass_lanes` for why."""
    if not isinstance(width, types.IntegerLiteral) or not _lane_arrays((pred, c0, c1, c2, c3, f0, f1, f2, f3)):
        return None
    W = width.literal_value
    sig = types.none(pred, c0, c1, c2, c3, f0, f1, f2, f3, i, width)

    def codegen(context, builder, signature, args):
        i64, vec, ptrs, load, store, splat, fma = _lanes(context, builder, signature, args, 9, W)
        pp, cp, fp = ptrs[0], ptrs[1:5], ptrs[5:9]
        base = builder.mul(args[9], ir.Constant(i64, W))
        zero = ir.Constant(i64, 0)
        t = [builder.fmul(load(f, zero), load(c, base)) for f, c in zip(fp, cp)]
        s = builder.fadd(builder.fadd(builder.fadd(t[0], t[1]), t[2]), t[3])
        store(builder.fadd(load(pp, base), s), pp, base)
        return context.get_dummy_value()

    return sig, codegen


@intrinsic
def _damp_lanes(typingctx, pred, qdamp, pad_c, bal_c, w_at, s_at, width):
    """The damping of one sleeper in :func:`_predict_window` for a chunk of ``width`` rows (the rows as the
    lanes of one LLVM vector): with the pad's force fp = c_pad (q_rail − q_sleeper), pred[rail] += fp and
    pred[sleeper] += c_ballast q_sleeper − fp (a fused multiply-add, as in the one-row path); ``w_at`` and
    ``s_at`` are the flat indices of the rail node's and the sleeper's lanes. See :func:`_mass_lanes` for why."""
    if not isinstance(width, types.IntegerLiteral) or not _lane_arrays((pred, qdamp, pad_c, bal_c)):
        return None
    W = width.literal_value
    sig = types.none(pred, qdamp, pad_c, bal_c, w_at, s_at, width)

    def codegen(context, builder, signature, args):
        i64, vec, (pp, qp, cpp, cbp), load, store, splat, fma = _lanes(context, builder, signature, args, 4, W)
        w_at, s_at, zero = args[4], args[5], ir.Constant(i64, 0)
        qs = load(qp, s_at)
        fp = builder.fmul(load(cpp, zero), builder.fsub(load(qp, w_at), qs))
        store(builder.fadd(load(pp, w_at), fp), pp, w_at)
        store(builder.fadd(load(pp, s_at), builder.call(fma, [load(cbp, zero), qs, builder.fneg(fp)])), pp, s_at)
        return context.get_dummy_value()

    return sig, codegen


@intrinsic
def _peak_lanes(typingctx, u, v, pad_k, pad_c, bal_k, bal_c, peak_ballast, peak_total, w_at, s_at, width):
    """The peak forces of one sleeper in :func:`_correct_window` for a chunk of ``width`` rows (the rows as the
    lanes of one LLVM vector): ballast force fb = c_b v_s + k_b u_s and pad force c_p (v_w − v_s) + k_p (u_w − u_s)
    (fused multiply-adds, as in the one-row path), peak_ballast = max(peak_ballast, fb) and peak_total =
    max(peak_total, fb + fp) as numba's ``max`` selects (the new value where it is greater). See
    :func:`_mass_lanes` for why."""
    arrays = (u, v, pad_k, pad_c, bal_k, bal_c, peak_ballast, peak_total)
    if not isinstance(width, types.IntegerLiteral) or not _lane_arrays(arrays):
        return None
    W = width.literal_value
    sig = types.none(u, v, pad_k, pad_c, bal_k, bal_c, peak_ballast, peak_total, w_at, s_at, width)

    def codegen(context, builder, signature, args):
        i64, vec, ptrs, load, store, splat, fma = _lanes(context, builder, signature, args, 8, W)
        up, vp, kpp, cpp, kbp, cbp, pbp, ptp = ptrs
        w_at, s_at, zero = args[8], args[9], ir.Constant(i64, 0)
        us, vs = load(up, s_at), load(vp, s_at)
        fb = builder.call(fma, [load(cbp, zero), vs, builder.fmul(load(kbp, zero), us)])
        pad = builder.fmul(load(kpp, zero), builder.fsub(load(up, w_at), us))
        fp = builder.call(fma, [load(cpp, zero), builder.fsub(load(vp, w_at), vs), pad])
        total = builder.fadd(fb, fp)
        for peak, new in ((pbp, fb), (ptp, total)):
            old = load(peak, zero)
            store(builder.select(builder.fcmp_ordered(">", new, old), new, old), peak, zero)
        return context.get_dummy_value()

    return sig, codegen


@njit(cache=True, inline="always", fastmath=FASTMATH)
def _solve(fw, bw, inv_diag, m, x, W):
    """Solve (L Lᵀ) y = x in place for the m DOFs of the flat vector x, every row (factors from :func:`_scale`;
    DOF i of row b at x[i*W + b]). Every index is written so that the compiler sees it is >= 0: numba wraps
    negative indices, and the check it would emit otherwise costs more than the arithmetic. Each sweep is a chain
    along the track per row, its last four DOFs kept in registers: one row as scalars, several rows as the lanes of
    one vector (:func:`_sweep_lanes`). Every path does a row's arithmetic in the same order (:func:`_chain_step`),
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
        _sweep_lanes(x, inv_diag, fw1, fw2, fw3, fw4, m, True, W)
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
        _sweep_lanes(x, inv_diag, bw1, bw2, bw3, bw4, m, False, W)


# Intel's first AVX-512 server cores (and the Xeon Phi), whose clock drops under sustained 512-bit arithmetic
_NARROW_CPUS = frozenset({"skylake-avx512", "cascadelake", "cooperlake", "knl", "knm"})
# the processor numba compiles for (NUMBA_CPU_NAME overrides the host)
_HOST_CPU = getattr(numba_config, "CPU_NAME", None) or ll.get_host_cpu_name()


class _WideLower(Lower):
    """numba's lowering, with the function marked for LLVM to prefer vectors of 512 bits where the processor has
    them (function attribute ``prefer-vector-width``). LLVM's tuning for Intel processors with AVX-512 prefers
    256-bit vectors; the kernel's loops across a chunk's 16 rows are then four instructions per operation
    instead of two, and the step's time follows the instructions it issues. Lanes do the same IEEE operations at
    any vector width (no reassociation; see FASTMATH), so results do not change. Without AVX-512 the attribute
    has no effect. A function whose last argument is the chunk width W = 1 is left as LLVM tunes it: one row's
    loops run along a window of ~90 DOFs, where 512-bit vectors made the pass ~7 % slower. So are all functions
    on the processors whose clock drops under sustained 512-bit arithmetic (:data:`_NARROW_CPUS`), the reason for
    LLVM's preference: the gain measured here (~3.5 % of the 16-row kernel, on a processor without that drop)
    would not survive it."""

    def lower_normal_function(self, fndesc):
        super().lower_normal_function(fndesc)
        width = fndesc.argtypes[-1] if fndesc.argtypes else None
        if _HOST_CPU in _NARROW_CPUS or (isinstance(width, types.IntegerLiteral) and width.literal_value == 1):
            return
        # llvmlite's attribute set accepts only LLVM's keyword attributes; a string attribute is written as is
        set.add(self.function.attributes, '"prefer-vector-width"="512"')


@register_pass(mutates_CFG=True, analysis_only=False)
class _WideNativeLowering(NativeLowering):
    """numba's lowering pass, through :class:`_WideLower`."""

    _name = "trackenv_wide_native_lowering"

    @property
    def lowering_class(self):
        return _WideLower


def _wide_pipeline(state):
    """numba's nopython pipeline with its lowering pass replaced by :class:`_WideNativeLowering`."""
    pm = DefaultPassBuilder.define_nopython_pipeline(state)
    pm.passes = [(_WideNativeLowering if p is NativeLowering else p, d) for p, d in pm.passes]
    return pm


class _WideCompiler(CompilerBase):
    """numba's nopython pipeline, lowered by :class:`_WideLower`."""

    def define_pipelines(self):
        return [_wide_pipeline(self.state)]


class _NoAliasCompiler(CompilerBase):
    """numba's nopython pipeline with its ``noalias`` flag on: every pointer among the function's arguments (an
    array's data, a namedtuple's arrays) is marked ``noalias`` for LLVM, the promise that memory written through
    one argument is not read or written through another during the call. numba cannot know this of arrays, and
    without it LLVM guards each short loop across a chunk's rows with run-time overlap checks (~80 instructions
    per DOF, more than the DOF's arithmetic at 4 to 16 rows). The functions compiled with it are called with
    distinct arrays only: the kernel's inputs, outputs and workspaces are each their own allocation. numba sets
    the same flag on its parallel loop bodies when it finds no aliasing; it has no decorator option for it, so it
    is set here through numba's custom-pipeline hook (``pipeline_class``). It changes what LLVM may assume, not
    the arithmetic: results are bit-identical. Lowered by :class:`_WideLower`."""

    def define_pipelines(self):
        self.state.flags.noalias = True
        return [_wide_pipeline(self.state)]


@njit(cache=True, fastmath=FASTMATH, pipeline_class=_NoAliasCompiler)
def _solve_rows(fw, bw, inv_diag, m, x, W):
    """:func:`_solve` compiled on its own (``W`` a literal) with distinct arrays (:class:`_NoAliasCompiler`).
    With it, the kernel's time on the env's pass fell ~15 % at 32 rows (chunks of 16; interleaved A/B); one row
    has no overlap checks to drop and calls it as well (no measurable difference from the inlined sweeps)."""
    literally(W)
    _solve(fw, bw, inv_diag, m, x, W)


@njit(cache=True, inline="always", fastmath=FASTMATH)
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
            row[k] = _fma(-f1, p1[k], _fma(-f2, p2[k], _fma(-f3, p3[k], _fma(-f4, p4[k], row[k] * d))))
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
            row[k] = _fma(-g1, n1[k], _fma(-g2, n2[k], _fma(-g3, n3[k], _fma(-g4, n4[k], row[k] * d))))


@njit(cache=True, inline="always", fastmath=FASTMATH)
def _mass_times(rail_mass, mass_diag, xpad, out, lo, hi, W):
    """out = M x on the DOFs of the window [lo, hi) (the track outside it is at rest), every row: flat vectors
    (DOF i of row b at i*W + b), x padded by B DOFs on each side (DOF i at xpad[(i + B)*W + b]) whose B DOFs
    either side of the window the caller has set to zero, so that the whole window is one band loop (a zero term
    adds exactly nothing). M's off-diagonals are the rail's (``Mesh.rail_mass``, shared by the rows), its
    diagonal ``mass_diag`` is per row (the sleepers' masses differ). The nine terms are summed in band order by
    fused multiply-adds (:func:`_fma`), in both loops alike: 17 instructions per DOF and vector become 9.
    For one row the loop indexes views from 0, which the compiler vectorises along the track (numba wraps
    negative indices, and a check it cannot drop blocks SIMD); for several rows each DOF is one
    :func:`_mass_lanes`, the rows as vector lanes."""
    if W == 1:
        o = out[lo:hi]
        x0, x1, x2 = xpad[lo:], xpad[lo + 1 :], xpad[lo + 2 :]
        x3, x4, x5 = xpad[lo + 3 :], xpad[lo + 4 :], xpad[lo + 5 :]
        x6, x7, x8 = xpad[lo + 6 :], xpad[lo + 7 :], xpad[lo + 8 :]
        m0, m1, m2 = rail_mass[0, lo:], rail_mass[1, lo:], rail_mass[2, lo:]
        m3, m4, m5 = rail_mass[3, lo:], mass_diag[lo:], rail_mass[5, lo:]
        m6, m7, m8 = rail_mass[6, lo:], rail_mass[7, lo:], rail_mass[8, lo:]
        for g in range(hi - lo):
            s = _fma(m3[g], x3[g], _fma(m2[g], x2[g], _fma(m1[g], x1[g], m0[g] * x0[g])))
            s = _fma(m7[g], x7[g], _fma(m6[g], x6[g], _fma(m5[g], x5[g], _fma(m4[g], x4[g], s))))
            o[g] = _fma(m8[g], x8[g], s)
    else:
        for i in range(lo, hi):  # the one-row loop's arithmetic, term by term, the rows as vector lanes
            _mass_lanes(xpad, mass_diag, out, i, rail_mass[0, i], rail_mass[1, i], rail_mass[2, i], rail_mass[3, i],
                        rail_mass[5, i], rail_mass[6, i], rail_mass[7, i], rail_mass[8, i], W)


@njit(cache=True, fastmath=FASTMATH)
def _contact(law, param, d):
    """Force and tangent stiffness of the contact law at compression d (0 when d <= 0): :func:`_contact_lane`,
    called (not inlined) where one row at a time needs it."""
    return _contact_lane(law, param, d)


@njit(cache=True, inline="always", fastmath=FASTMATH)
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


@njit(cache=True, inline="always", fastmath=FASTMATH)
def _copy(src, dst, m):
    """dst[:m] = src[:m] for 1-D views (indexed from 0: no negative-index check, so the loop vectorises)."""
    for i in range(m):
        dst[i] = src[i]


@njit(cache=True, inline="always", fastmath=FASTMATH)
def _bay_dof(node_w, sleeper_node, bay, k):
    """DOF of the bay's k-th cached column: (w, θ) of its epb+1 rail nodes in turn (the sleeper DOF after the
    first node is skipped; see :func:`_local`)."""
    return node_w[sleeper_node[bay] + k // 2] + (k % 2)


@njit(cache=True, inline="always", fastmath=FASTMATH)
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


Window = namedtuple("Window", "u v a pred rhs qdamp mass_diag pad_k pad_c bal_k bal_c peak_ballast peak_total")
Window.__doc__ = """One chunk's track arrays as the window steps see them: state u, v, a and the predictor pred, flat
(n_dof*W); the padded right-hand side rhs ((n_dof + 2B)*W, see :func:`_mass_times`), the damping term qdamp and
the mass diagonal, flat; pads, ballast and peak sleeper forces (n_sleepers, W). Each a distinct array (see
:class:`_NoAliasCompiler`)."""


@njit(cache=True, inline="always", fastmath=FASTMATH)
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
        rw[g] = _fma(a3, aw[g], _fma(a2, vw[g], a0 * uw[g]))
        qw[g] = _fma(a5, aw[g], _fma(a4, vw[g], a1 * uw[g]))
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
            ps[f] += _fma(cb[g, 0], qs[f], -fp)
    else:  # the same arithmetic, the rows as vector lanes
        for g in range(s_hi + 1 - s_lo):
            w_at = (lo + g * bay_dofs) * W
            _damp_lanes(win.pred, win.qdamp, cp[g], cb[g], w_at, w_at + sleeper_shift * W, W)
    # triangular sweeps
    _solve_rows(fw, bw, inv_diag, m, pred[lo * W : hi * W], W)


@njit(cache=True, inline="always", fastmath=FASTMATH)
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
                # products and sums, not fused multiply-adds: written as a chain of _fma, LLVM vectorised the
                # lane loop along the track with gathers and scatters (the correction took 1.8x as long at 16 rows)
                pw[i] += f0[0] * c0[i] + f1[0] * c1[i] + f2[0] * c2[i] + f3[0] * c3[i]
        else:
            for i in range(m):  # the same products and sums, the rows as vector lanes
                _correct_lanes(pw, c0, c1, c2, c3, f0, f1, f2, f3, i, W)
    # Newmark update of the track
    for g in range(m * W):
        an = _fma(-a3, aw[g], _fma(-a2, vw[g], a0 * (pw[g] - uw[g])))
        vw[g] = _fma(a7, an, _fma(a6, aw[g], vw[g]))
        aw[g] = an
        uw[g] = pw[g]
    # peak sleeper forces in the window
    uw, us, vw, vs = u[lo * W :], u[(lo + sleeper_shift) * W :], v[lo * W :], v[(lo + sleeper_shift) * W :]
    kp, cp, kb, cb = win.pad_k[s_lo:], win.pad_c[s_lo:], win.bal_k[s_lo:], win.bal_c[s_lo:]
    pb, pt = win.peak_ballast[s_lo:], win.peak_total[s_lo:]
    if W == 1:
        for g in range(s_hi + 1 - s_lo):
            f = np.uint64(g * bay_dofs)
            fb = _fma(cb[g, 0], vs[f], kb[g, 0] * us[f])
            fp = _fma(cp[g, 0], vw[f] - vs[f], kp[g, 0] * (uw[f] - us[f]))
            pb[g, 0] = max(pb[g, 0], fb)
            pt[g, 0] = max(pt[g, 0], fb + fp)
    else:  # the same arithmetic, the rows as vector lanes
        for g in range(s_hi + 1 - s_lo):
            w_at = (lo + g * bay_dofs) * W
            _peak_lanes(u, v, kp[g], cp[g], kb[g], cb[g], pb[g], pt[g], w_at, w_at + sleeper_shift * W, W)


@njit(cache=True, fastmath=FASTMATH, pipeline_class=_NoAliasCompiler)
def _predict_window_rows(win, mesh, drive, fw, bw, inv_diag, lo, hi, s_lo, s_hi, bay_dofs, sleeper_shift, W):
    """:func:`_predict_window` for a chunk of several rows, compiled on its own with distinct arrays
    (:class:`_NoAliasCompiler`): its loops across the rows then run without overlap checks. One row inlines
    :func:`_predict_window` instead: a call per step with the window's arrays costs its short loops more."""
    literally(W)
    _predict_window(win, mesh, drive, fw, bw, inv_diag, lo, hi, s_lo, s_hi, bay_dofs, sleeper_shift, W)


@njit(cache=True, fastmath=FASTMATH, pipeline_class=_NoAliasCompiler)
def _correct_window_rows(win, drive, cols, fsh, loc, c, lo, hi, s_lo, s_hi, bay_dofs, sleeper_shift, W):
    """:func:`_correct_window` for a chunk of several rows, compiled on its own with distinct arrays (as
    :func:`_predict_window_rows`)."""
    literally(W)
    _correct_window(win, drive, cols, fsh, loc, c, lo, hi, s_lo, s_hi, bay_dofs, sleeper_shift, W)


@njit(cache=True, inline="always", fastmath=FASTMATH)
def _run_chunk(mesh, drive, rows, peaks, reuse, ch, W):
    """Integrate chunk ``ch`` of the batch (its rows in lockstep) over the whole pass.

    The track's state vectors are used flat, DOF i of row b at i*W + b (W a compile-time constant): loops over
    a whole window's DOFs and rows are one unit-stride loop at any width, and for several rows each DOF's lanes
    are one vector (the lane intrinsics; see the module's docstring)."""
    node_w = mesh.node_w
    sleeper_dof = mesh.sleeper_dof
    sleeper_node = mesh.sleeper_node
    elem_len = mesh.elem_len
    epb = mesh.epb
    n_sleepers = mesh.n_sleepers
    margin_bays = mesh.margin_bays
    x_axle = drive.x_axle
    law = drive.law
    param = drive.param
    mv = drive.mass
    cv = drive.damping
    kv_inv = drive.kv_inv
    fv = drive.force
    wheel_dofs = drive.wheel_dofs
    cluster_of_axle = drive.cluster_of_axle
    n_clusters = drive.n_clusters
    a0, a1, a2, a3, a4, a5, a6, a7 = (
        drive.consts[0], drive.consts[1], drive.consts[2], drive.consts[3],
        drive.consts[4], drive.consts[5], drive.consts[6], drive.consts[7],
    )  # fmt: skip
    n = rows.u.shape[1]
    mass_diag = rows.mass_diag[ch].reshape(n * W)
    keff = rows.keff[ch]
    pad_k = rows.pad_k[ch]
    pad_c = rows.pad_c[ch]
    bal_k = rows.bal_k[ch]
    bal_c = rows.bal_c[ch]
    z_axle = rows.z[ch]
    sag = rows.sag[ch]
    u = rows.u[ch].reshape(n * W)
    v = rows.v[ch].reshape(n * W)
    a = rows.a[ch].reshape(n * W)
    q = rows.q[ch]
    qd = rows.qd[ch]
    qdd = rows.qdd[ch]
    out_force = peaks.force[ch]
    out_rail = peaks.rail[ch]
    out_wheel = peaks.wheel[ch]
    peak_ballast = peaks.ballast[ch]
    peak_total = peaks.total[ch]

    n_steps = x_axle.shape[0] - 1
    # the DOF layout is regular (track.DofLayout): a bay is bay_dofs DOFs, and a sleeper's DOF follows its rail
    # node's deflection by sleeper_shift; a window starts at a sleeper's rail node
    bay_dofs = sleeper_dof[1] - sleeper_dof[0]
    sleeper_shift = sleeper_dof[0] - node_w[sleeper_node[0]]
    n_axles = x_axle.shape[1]
    nv = q.shape[0]
    m_max = n
    m_cap = reuse.factor.shape[2] if reuse.factor.shape[0] == n_sleepers else 0  # no sleepers kept: 0
    Ls = np.zeros((m_max, B + 1, W))
    Fw = np.zeros((n_clusters, B + 1, m_max * W))
    Bw = np.zeros((n_clusters, B + 1, m_max * W))
    invd = np.zeros((n_clusters, m_max * W))
    lo_c = np.full(n_clusters, -1, dtype=np.int64)
    hi_c = np.full(n_clusters, -1, dtype=np.int64)
    s_lo_c = np.zeros(n_clusters, dtype=np.int64)
    s_hi_c = np.zeros(n_clusters, dtype=np.int64)
    bay_cache = np.full(n_axles, -1, dtype=np.int64)
    ncol = 2 * (epb + 1)
    cols = np.zeros((n_axles, ncol, m_max * W))
    rhs = np.zeros((n + 2 * B) * W)  # padded by B DOFs each side (see _mass_times)
    pred = np.zeros(n * W)
    qdamp = np.zeros(n * W)
    rv = np.zeros((nv, W))
    qpred = np.zeros((nv, W))
    tmp = np.zeros(m_max * W)
    cols_t = np.zeros((m_max, ncol))  # one row: a bay's columns side by side (see _solve_columns_one)
    scratch = np.zeros(W)
    shape = np.zeros((n_axles, 4))
    edofs = np.zeros((n_axles, 4), dtype=np.int64)
    elem_of = np.zeros(n_axles, dtype=np.int64)
    loc = np.zeros((n_axles, 4), dtype=np.int64)
    wpred = np.zeros((n_axles, W))
    ypred = np.zeros((n_axles, W))
    H = np.zeros((n_axles, n_axles, W))
    J = np.zeros((n_axles, n_axles))
    rj = np.zeros(n_axles)
    delta = np.zeros((n_axles, W))
    force = np.zeros((n_axles, W))
    fprime = np.zeros(n_axles)
    res = np.zeros(n_axles)
    fsh = np.zeros((n_axles, 4, W))
    win = Window(u, v, a, pred, rhs, qdamp, mass_diag, pad_k, pad_c, bal_k, bal_c, peak_ballast, peak_total)
    res_w = np.zeros(W)  # one axle, several rows: the Newton's right-hand sides and converged flags per row
    done_w = np.zeros(W)
    for j in range(n_axles):  # compression that carries the initial force
        for b in range(W):
            force[j, b] = out_force[0, j, b]
            if law == 0:
                delta[j, b] = param * force[j, b] ** (2.0 / 3.0)
            else:
                delta[j, b] = force[j, b] / param

    for step in range(1, n_steps + 1):
        # ---- element, shape functions and window of every axle at t_{n+1} (shared by the rows)
        for j in range(n_axles):
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
            # the static sag of settled supports is part of the rail level under the wheel
            for b in range(W):
                z_axle[step, j, b] += (
                    shape[j, 0] * sag[edofs[j, 0], b]
                    + shape[j, 1] * sag[edofs[j, 1], b]
                    + shape[j, 2] * sag[edofs[j, 2], b]
                    + shape[j, 3] * sag[edofs[j, 3], b]
                )
        # ---- move the window of every axle group that has entered a new bay: factor, columns of its bay
        for c in range(n_clusters):
            changed = False
            bay_min = n_sleepers
            bay_max = -1
            for j in range(n_axles):
                if cluster_of_axle[j] != c:
                    continue
                bay = elem_of[j] // epb  # the bay of the axle's element, so element and bay always agree
                if bay != bay_cache[j]:
                    changed = True
                bay_min = min(bay_min, bay)
                bay_max = max(bay_max, bay)
            if not changed:
                continue
            s_lo = max(0, bay_min - margin_bays)
            s_hi = min(n_sleepers - 1, bay_max + 1 + margin_bays)
            lo = node_w[sleeper_node[s_lo]]
            hi = sleeper_dof[s_hi] + 1
            # DOFs left behind come to rest
            if lo_c[c] >= 0:
                for f in range(lo_c[c] * W, min(lo, hi_c[c]) * W):
                    u[f] = 0.0
                    v[f] = 0.0
                    a[f] = 0.0
            lo_c[c] = lo
            hi_c[c] = hi
            s_lo_c[c] = s_lo
            s_hi_c[c] = s_hi
            m = hi - lo
            keep = W == 1 and m <= m_cap  # one row: this window's factor and columns are kept across passes
            if keep and reuse.factor_window[bay_min, 0] == lo and reuse.factor_window[bay_min, 1] == hi:
                kept = reuse.factor[bay_min]
                for k in range(1, B + 1):  # (row 0 of fw and bw is not used)
                    _copy(kept[k], Fw[c, k], m)
                    _copy(kept[B + 1 + k], Bw[c, k], m)
                _copy(kept[2 * B + 2], invd[c], m)
            else:
                _factor(keff, lo, m, Ls, invd[c], scratch, W)
                _scale(Ls, invd[c], m, Fw[c], Bw[c], W)
                if keep:
                    kept = reuse.factor[bay_min]
                    for k in range(1, B + 1):
                        _copy(Fw[c, k], kept[k], m)
                        _copy(Bw[c, k], kept[B + 1 + k], m)
                    _copy(invd[c], kept[2 * B + 2], m)
                    reuse.factor_window[bay_min, 0] = lo
                    reuse.factor_window[bay_min, 1] = hi
            for j in range(n_axles):
                if cluster_of_axle[j] != c:
                    continue
                bay = elem_of[j] // epb
                bay_cache[j] = bay
                if W == 1:  # one row: the bay's columns in one sweep, side by side
                    if keep and reuse.columns_window[bay, 0] == lo and reuse.columns_window[bay, 1] == hi:
                        kept = reuse.columns[bay]
                        for k in range(ncol):
                            _copy(kept[k], cols[j, k], m)
                        continue
                    for i in range(m):
                        for k in range(ncol):
                            cols_t[i, k] = 0.0
                    for k in range(ncol):
                        cols_t[_bay_dof(node_w, sleeper_node, bay, k) - lo, k] = 1.0
                    _solve_columns_one(Fw[c], Bw[c], invd[c], m, cols_t, ncol)
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
                    continue
                for k in range(ncol):
                    dof = _bay_dof(node_w, sleeper_node, bay, k)
                    for f in range(m * W):
                        tmp[f] = 0.0
                    for b in range(W):
                        tmp[(dof - lo) * W + b] = 1.0
                    _solve_rows(Fw[c], Bw[c], invd[c], m, tmp, W)
                    colk = cols[j, k]
                    for f in range(m * W):
                        colk[f] = tmp[f]
        # ---- where the axles' element DOFs sit among their bay's columns
        for j in range(n_axles):
            basej = node_w[sleeper_node[bay_cache[j]]]
            for k in range(4):
                loc[j, k] = _local(edofs[j, k], basej, epb)

        # ---- track predictor (no contact force) in every window: K_eff u = M p + C q
        for c in range(n_clusters):
            lo, hi, s_lo, s_hi = lo_c[c], hi_c[c], s_lo_c[c], s_hi_c[c]
            fw, bw, inv_diag = Fw[c], Bw[c], invd[c]
            if W == 1:  # one row: inlined (a call per step with the window's arrays costs the short loops more)
                _predict_window(win, mesh, drive, fw, bw, inv_diag, lo, hi, s_lo, s_hi, bay_dofs, sleeper_shift, W)
            else:
                _predict_window_rows(win, mesh, drive, fw, bw, inv_diag, lo, hi, s_lo, s_hi, bay_dofs, sleeper_shift, W)

        # ---- vehicle predictor
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

        # ---- flexibilities at the wheels and contact predictor
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

        # ---- Newton on the compressions, row by row: d = d_pred - H f(d)
        if W > 1 and n_axles == 1:  # compile-time W: the one-row entry has only the general loop below
            # one axle: the rows' scalar Newton iterations side by side (SIMD); a row that has converged keeps
            # its compression while the others go on, so each row takes exactly the steps it takes alone
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
            if W == 1:
                _correct_window(win, drive, cols, fsh, loc, c, lo, hi, s_lo, s_hi, bay_dofs, sleeper_shift, W)
            else:
                _correct_window_rows(win, drive, cols, fsh, loc, c, lo, hi, s_lo, s_hi, bay_dofs, sleeper_shift, W)

        # ---- correct the vehicle
        for i in range(nv):
            for b in range(W):
                rv[i, b] = qpred[i, b]
            for j in range(n_axles):
                kij = kv_inv[i, wheel_dofs[j]]
                for b in range(W):
                    rv[i, b] -= kij * force[j, b]
            for b in range(W):
                an = a0 * (rv[i, b] - q[i, b]) - a2 * qd[i, b] - a3 * qdd[i, b]
                qd[i, b] += a6 * qdd[i, b] + a7 * an
                qdd[i, b] = an
                q[i, b] = rv[i, b]

        # ---- outputs under the wheels
        for j in range(n_axles):
            for b in range(W):
                out_force[step, j, b] = force[j, b]
                out_rail[step, j, b] = (
                    shape[j, 0] * u[edofs[j, 0] * W + b]
                    + shape[j, 1] * u[edofs[j, 1] * W + b]
                    + shape[j, 2] * u[edofs[j, 2] * W + b]
                    + shape[j, 3] * u[edofs[j, 3] * W + b]
                )
                out_wheel[step, j, b] = q[wheel_dofs[j], b]


@njit(cache=True, fastmath=FASTMATH, pipeline_class=_WideCompiler)
def _run_chunk_shared(mesh, drive, rows, peaks, reuse, ch, W):
    """:func:`_run_chunk` compiled once per width ``W`` (a literal, so a compile-time constant in each compiled
    copy) and called by both the serial and the parallel entry of that width: the chunk integrator is most of the
    kernel's compile time, which each width of several rows then pays once instead of once per entry. ``ch`` is
    int64 from either entry (prange's index is unsigned), so that both share one compiled copy."""
    literally(W)
    _run_chunk(mesh, drive, rows, peaks, reuse, ch, W)


# One compiled entry per (threads, width): the width is a constant in each, so that the loops over the rows have
# a known trip count (a width read at run time costs the single pass 2.5x). The serial one-row entry, the single
# pass, inlines the chunk integrator (called, it looked 6-12 % slower on the env's pass in one comparison and not
# in another; inlined is the safe side); the others call the copy of their width (no measurable difference at 4 to
# 16 rows): a width of several rows compiles once for both entries, and a parallel entry around a call compiles
# in ~15 s instead of ~70-120 s around the inlined integrator. Written out, not generated, so that numba's on-disk
# cache keeps each one.
@njit(cache=True, fastmath=FASTMATH)
def _serial_1(mesh, drive, rows, peaks, reuse):
    for ch in range(rows.u.shape[0]):
        _run_chunk(mesh, drive, rows, peaks, reuse, ch, 1)


@njit(cache=True, fastmath=FASTMATH)
def _serial_4(mesh, drive, rows, peaks, reuse):
    for ch in range(rows.u.shape[0]):
        _run_chunk_shared(mesh, drive, rows, peaks, reuse, ch, 4)


@njit(cache=True, fastmath=FASTMATH)
def _serial_6(mesh, drive, rows, peaks, reuse):
    for ch in range(rows.u.shape[0]):
        _run_chunk_shared(mesh, drive, rows, peaks, reuse, ch, 6)


@njit(cache=True, fastmath=FASTMATH)
def _serial_8(mesh, drive, rows, peaks, reuse):
    for ch in range(rows.u.shape[0]):
        _run_chunk_shared(mesh, drive, rows, peaks, reuse, ch, 8)


@njit(cache=True, fastmath=FASTMATH)
def _serial_16(mesh, drive, rows, peaks, reuse):
    for ch in range(rows.u.shape[0]):
        _run_chunk_shared(mesh, drive, rows, peaks, reuse, ch, 16)


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _parallel_1(mesh, drive, rows, peaks, reuse):
    for ch in prange(rows.u.shape[0]):
        _run_chunk_shared(mesh, drive, rows, peaks, reuse, np.int64(ch), 1)


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _parallel_4(mesh, drive, rows, peaks, reuse):
    for ch in prange(rows.u.shape[0]):
        _run_chunk_shared(mesh, drive, rows, peaks, reuse, np.int64(ch), 4)


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _parallel_6(mesh, drive, rows, peaks, reuse):
    for ch in prange(rows.u.shape[0]):
        _run_chunk_shared(mesh, drive, rows, peaks, reuse, np.int64(ch), 6)


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _parallel_8(mesh, drive, rows, peaks, reuse):
    for ch in prange(rows.u.shape[0]):
        _run_chunk_shared(mesh, drive, rows, peaks, reuse, np.int64(ch), 8)


@njit(parallel=True, cache=True, fastmath=FASTMATH)
def _parallel_16(mesh, drive, rows, peaks, reuse):
    for ch in prange(rows.u.shape[0]):
        _run_chunk_shared(mesh, drive, rows, peaks, reuse, np.int64(ch), 16)


_RUNNERS = {
    (False, 1): _serial_1,
    (False, 4): _serial_4,
    (False, 6): _serial_6,
    (False, 8): _serial_8,
    (False, 16): _serial_16,
    (True, 1): _parallel_1,
    (True, 4): _parallel_4,
    (True, 6): _parallel_6,
    (True, 8): _parallel_8,
    (True, 16): _parallel_16,
}


def run(mesh, drive, rows, peaks, reuse, width: int) -> None:
    """Integrate every chunk of the batch (``width`` rows each, one of :data:`WIDTHS`), filling the arrays in
    place: on the calling thread for one chunk, else the chunks spread over numba's threads."""
    _RUNNERS[(rows.u.shape[0] > 1, width)](mesh, drive, rows, peaks, reuse)
