"""The kernel's lane intrinsics: its per-DOF work across a chunk's rows, written in LLVM's IR.

For a chunk of several rows the kernel keeps each per-row quantity with the rows innermost (DOF i of row b at
flat index i*W + b, W the chunk width), so that one DOF's W values are adjacent. Each function here does one DOF's
(or one sleeper's) work for all W rows as the lanes of one LLVM vector, with the same IEEE operations in the same
order as the kernel's one-row loop: a row's result is the one-row path's, bit for bit. They are written in the IR
because numba has no vector type and LLVM's loop vectoriser does not serve these loops: a loop over 4, 6 or 8 rows
is too short for it (it unrolls the loop first, then leaves it scalar or vectorises it along the track with
gathers and scatters), and it does not see through a triangular sweep's chain of dependent steps.

Each intrinsic is typed only for a literal width and contiguous 1-D float64 arrays (checked when the caller is
compiled) and returns None, as numba's ``@intrinsic`` functions do where they cannot type their arguments.
"""

from __future__ import annotations

from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

from .track import HALF_BANDWIDTH as B


@intrinsic
def fma(typingctx, a, b, c):
    """a·b + c rounded once: LLVM's ``llvm.fma`` intrinsic, one instruction on a processor with FMA (a correctly
    rounded library call on one without, same result). Written out where the kernel wants it, never left to the
    compiler (see ``_pipeline.FASTMATH``), so that every compiled copy fuses the same operations."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        f64 = ir.DoubleType()
        fn = cgutils.get_or_insert_function(builder.module, ir.FunctionType(f64, [f64, f64, f64]), "llvm.fma.f64")
        return builder.call(fn, args)

    return sig, codegen


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
def sweep_lanes(typingctx, x, inv_diag, g1, g2, g3, g4, m, forward, width):
    """The chain part of a triangular sweep for a chunk of ``width`` rows: DOFs B..m-1 (``forward``) or m-1-B..0
    (backward) of the flat vector x (DOF i of row b at i*W + b), the rows as the lanes of one LLVM vector whose
    sweep's four previous DOFs stay in registers, each lane doing ``_step.chain_step``'s arithmetic (so a row's
    result is the one-row path's, bit for bit). The loop itself is written here, with the four previous DOFs
    as loop-carried vectors: LLVM's vectoriser does not see through the chain."""
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
def mass_lanes(typingctx, xpad, mass_diag, out, i, r0, r1, r2, r3, r5, r6, r7, r8, width):
    """One DOF i of ``_step.mass_times`` for a chunk of ``width`` rows, the rows as the lanes of one LLVM vector:
    out[i*W + b] = Σ_k M(i, i + k - B) xpad[(i + k)*W + b], the same fused multiply-adds in the same order as
    the one-row loop (a row's result is the one-row path's, bit for bit)."""
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
def correct_lanes(typingctx, pred, c0, c1, c2, c3, f0, f1, f2, f3, i, width):
    """One DOF i of the correction in ``_step.correct_window`` for a chunk of ``width`` rows (the rows as the
    lanes of one LLVM vector): pred[i*W + b] += f0[b]*c0[i*W + b] + f1[b]*c1[…] + f2[b]*c2[…] + f3[b]*c3[…],
    products and sums in the one-row path's order (bit for bit its result)."""
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
def damp_lanes(typingctx, pred, qdamp, pad_c, bal_c, w_at, s_at, width):
    """The damping of one sleeper in ``_step.predict_window`` for a chunk of ``width`` rows (the rows as the
    lanes of one LLVM vector): with the pad's force fp = c_pad (q_rail − q_sleeper), pred[rail] += fp and
    pred[sleeper] += c_ballast q_sleeper − fp (a fused multiply-add, as in the one-row path); ``w_at`` and
    ``s_at`` are the flat indices of the rail node's and the sleeper's lanes."""
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
def peak_lanes(typingctx, u, v, pad_k, pad_c, bal_k, bal_c, peak_ballast, peak_total, w_at, s_at, width):
    """The peak forces of one sleeper in ``_step.correct_window`` for a chunk of ``width`` rows (the rows as the
    lanes of one LLVM vector): ballast force fb = c_b v_s + k_b u_s and pad force c_p (v_w − v_s) + k_p (u_w − u_s)
    (fused multiply-adds, as in the one-row path), peak_ballast = max(peak_ballast, fb) and peak_total =
    max(peak_total, fb + fp) as numba's ``max`` selects (the new value where it is greater)."""
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
