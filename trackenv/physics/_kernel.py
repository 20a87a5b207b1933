"""The compiled time-stepping kernel behind :func:`trackenv.physics.dynamics.simulate_passes`.

Newmark average acceleration (β = 1/4, γ = 1/2: implicit, unconditionally stable, no numerical damping) on the
linear track and the linear vehicle, coupled by the non-linear contact law, which is solved by Newton's method
every step. Only the contact forces couple the two, so each step is: predict both without contact, solve the
small contact problem through the two flexibilities at the wheels, correct both.

Speed comes from a window of the standing track that follows each group of axles. The supports are heavily
damped and the rail's deflection decays like e^{-βx} (β ≈ 1.6 1/m), so beyond a few sleeper bays the track
hardly moves: inside the window the track is integrated in full, outside it is at rest. The window is a
contiguous block of the banded matrices (DOFs are numbered along the track) and moves by whole bays; the DOFs it
leaves behind are set back to rest. Every quantity the caller sees (contact force, rail deflection, peak sleeper
forces) is taken where the window is. With the window as long as the track this is the full model.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

B = 4  # half-bandwidth of the track matrices (see track.DofLayout)


@njit(cache=True, fastmath=True)
def _factor(keff, lo, m, L, inv_diag):
    """Banded Cholesky of keff[lo:lo+m] (lower band storage); L[i, k] = L(i, i-k)."""
    for i in range(m):
        kmax = min(i, B)
        for k in range(kmax, 0, -1):
            j = i - k
            s = keff[lo + i, k]
            for c in range(max(i - B, 0), j):
                s -= L[i, i - c] * L[j, j - c]
            L[i, k] = s * inv_diag[j]
        s = keff[lo + i, 0]
        for c in range(max(i - B, 0), i):
            s -= L[i, i - c] * L[i, i - c]
        L[i, 0] = np.sqrt(s)
        inv_diag[i] = 1.0 / L[i, 0]


@njit(cache=True, fastmath=True)
def _scale(L, inv_diag, m, fw, bw):
    """Pre-scaled triangular factors for :func:`_solve`: fw[i, k] = L(i, i-k)/L(i, i), bw[i, k] = L(i+k, i)/L(i, i).

    With them each unknown of the forward and backward sweeps hangs on its neighbour through one fused
    multiply-add, which keeps the sequential sweeps short."""
    for i in range(m):
        for k in range(1, B + 1):
            fw[i, k] = L[i, k] * inv_diag[i] if k <= i else 0.0
            bw[i, k] = L[i + k, k] * inv_diag[i] if i + k < m else 0.0


@njit(cache=True, fastmath=True)
def _solve(fw, bw, inv_diag, m, x):
    """Solve (L Lᵀ) y = x in place for the first m entries of x (factors from :func:`_scale`)."""
    for i in range(min(m, B)):
        s = x[i] * inv_diag[i]
        for k in range(i, 0, -1):
            s -= fw[i, k] * x[i - k]
        x[i] = s
    for i in range(B, m):
        x[i] = (
            x[i] * inv_diag[i] - fw[i, 4] * x[i - 4] - fw[i, 3] * x[i - 3] - fw[i, 2] * x[i - 2] - (fw[i, 1] * x[i - 1])
        )
    for i in range(m - 1, max(m - 1 - B, -1), -1):
        s = x[i] * inv_diag[i]
        for k in range(m - 1 - i, 0, -1):
            s -= bw[i, k] * x[i + k]
        x[i] = s
    for i in range(m - 1 - B, -1, -1):
        x[i] = (
            x[i] * inv_diag[i] - bw[i, 4] * x[i + 4] - bw[i, 3] * x[i + 3] - bw[i, 2] * x[i + 2] - (bw[i, 1] * x[i + 1])
        )


@njit(cache=True, fastmath=True)
def _mass_times(mfull, x, out, lo, hi):
    """out[:hi-lo] = M x restricted to the window [lo, hi) (the track outside it is at rest)."""
    for i in range(lo, min(lo + B, hi)):
        s = 0.0
        for d in range(2 * B + 1):
            j = i + d - B
            if lo <= j < hi:
                s += mfull[i, d] * x[j]
        out[i - lo] = s
    for i in range(lo + B, hi - B):
        out[i - lo] = (
            mfull[i, 0] * x[i - 4]
            + mfull[i, 1] * x[i - 3]
            + mfull[i, 2] * x[i - 2]
            + mfull[i, 3] * x[i - 1]
            + mfull[i, 4] * x[i]
            + mfull[i, 5] * x[i + 1]
            + mfull[i, 6] * x[i + 2]
            + mfull[i, 7] * x[i + 3]
            + mfull[i, 8] * x[i + 4]
        )
    for i in range(max(hi - B, lo + B), hi):
        s = 0.0
        for d in range(2 * B + 1):
            j = i + d - B
            if lo <= j < hi:
                s += mfull[i, d] * x[j]
        out[i - lo] = s


@njit(cache=True, fastmath=True)
def _contact(law, param, d):
    """Force and tangent stiffness of the contact law at compression d (0 when d <= 0)."""
    if d <= 0.0:
        return 0.0, 0.0
    if law == 0:
        r = d / param
        sr = np.sqrt(r)
        return r * sr, 1.5 * sr / param
    return param * d, param


@njit(cache=True, fastmath=True)
def _run_one(
    mb,
    cb,
    keff,
    node_w,
    sleeper_dof,
    sleeper_node,
    pad_k,
    pad_c,
    bal_k,
    bal_c,
    elem_len,
    epb,
    spacing,
    n_sleepers,
    mv,
    cv,
    kv_inv,
    fv,
    wheel_dofs,
    cluster_of_axle,
    n_clusters,
    margin_bays,
    x_axle,
    z_axle,
    law,
    param,
    consts,
    u,
    v,
    a,
    q,
    qd,
    qdd,
    out_force,
    out_rail,
    out_wheel,
    peak_ballast,
    peak_total,
):
    n_steps = x_axle.shape[0] - 1
    n_axles = x_axle.shape[1]
    n = u.shape[0]
    nv = q.shape[0]
    a0, a1, a2, a3, a4, a5, a6, a7 = consts
    m_max = n
    Ls = np.zeros((n_clusters, m_max, B + 1))
    Fw = np.zeros((n_clusters, m_max, B + 1))
    Bw = np.zeros((n_clusters, m_max, B + 1))
    invd = np.zeros((n_clusters, m_max))
    lo_c = np.full(n_clusters, -1, dtype=np.int64)
    hi_c = np.full(n_clusters, -1, dtype=np.int64)
    s_lo_c = np.zeros(n_clusters, dtype=np.int64)
    s_hi_c = np.zeros(n_clusters, dtype=np.int64)
    # the mass matrix as 2B+1 full diagonals: mfull[i, d] = M[i, i + d - B]
    mfull = np.zeros((n, 2 * B + 1))
    for i in range(n):
        for k in range(B + 1):
            if i - k >= 0:
                mfull[i, B - k] = mb[i, k]
                mfull[i - k, B + k] = mb[i, k]
    bay_cache = np.full(n_axles, -1, dtype=np.int64)
    ncol = 2 * (epb + 1)
    cols = np.zeros((n_axles, ncol, m_max))
    rhs = np.zeros(n)
    pred = np.zeros(n)
    qdamp = np.zeros(n)
    rv = np.zeros(nv)
    qpred = np.zeros(nv)
    tmp = np.zeros(m_max)
    shape = np.zeros((n_axles, 4))
    edofs = np.zeros((n_axles, 4), dtype=np.int64)
    elem_of = np.zeros(n_axles, dtype=np.int64)
    wpred = np.zeros(n_axles)
    ypred = np.zeros(n_axles)
    H = np.zeros((n_axles, n_axles))
    J = np.zeros((n_axles, n_axles))
    delta = np.zeros(n_axles)
    force = out_force[0].copy()
    res = np.zeros(n_axles)
    fprime = np.zeros(n_axles)
    for j in range(n_axles):  # compression that carries the initial force
        if law == 0:
            delta[j] = param * force[j] ** (2.0 / 3.0)
        else:
            delta[j] = force[j] / param

    for step in range(1, n_steps + 1):
        # ---- element, shape functions and window of every axle at t_{n+1}
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
                for i in range(lo_c[c], min(lo, hi_c[c])):
                    u[i] = 0.0
                    v[i] = 0.0
                    a[i] = 0.0
            lo_c[c] = lo
            hi_c[c] = hi
            s_lo_c[c] = s_lo
            s_hi_c[c] = s_hi
            m = hi - lo
            _factor(keff, lo, m, Ls[c], invd[c])
            _scale(Ls[c], invd[c], m, Fw[c], Bw[c])
            for j in range(n_axles):
                if cluster_of_axle[j] != c:
                    continue
                bay = elem_of[j] // epb  # the bay of the axle's element, so element and bay always agree
                bay_cache[j] = bay
                for k in range(ncol):
                    # the bay's rail DOFs: (w, θ) of its epb+1 nodes; the sleeper DOF after node 0 is skipped
                    node = k // 2
                    dof = node_w[sleeper_node[bay] + node] + (k % 2)
                    for i in range(m):
                        tmp[i] = 0.0
                    tmp[dof - lo] = 1.0
                    _solve(Fw[c], Bw[c], invd[c], m, tmp)
                    for i in range(m):
                        cols[j, k, i] = tmp[i]

        # ---- track predictor (no contact force) in every window: K_eff u = M p + C q
        for c in range(n_clusters):
            lo = lo_c[c]
            hi = hi_c[c]
            m = hi - lo
            for i in range(lo, hi):
                rhs[i] = a0 * u[i] + a2 * v[i] + a3 * a[i]
                qdamp[i] = a1 * u[i] + a4 * v[i] + a5 * a[i]
            window = pred[lo:hi]
            _mass_times(mfull, rhs, window, lo, hi)
            # damping sits only in the pads and the ballast
            for s_ in range(s_lo_c[c], s_hi_c[c] + 1):
                d = sleeper_dof[s_]
                w = node_w[sleeper_node[s_]]
                fp = pad_c[s_] * (qdamp[w] - qdamp[d])
                pred[w] += fp
                pred[d] += bal_c[s_] * qdamp[d] - fp
            _solve(Fw[c], Bw[c], invd[c], m, window)

        # ---- vehicle predictor
        for i in range(nv):
            rv[i] = 0.0
        for i in range(nv):
            s = fv[i]
            for k in range(nv):
                s += mv[i, k] * (a0 * q[k] + a2 * qd[k] + a3 * qdd[k]) + cv[i, k] * (
                    a1 * q[k] + a4 * qd[k] + a5 * qdd[k]
                )
            rv[i] = s
        for i in range(nv):
            s = 0.0
            for k in range(nv):
                s += kv_inv[i, k] * rv[k]
            qpred[i] = s

        # ---- flexibilities at the wheels and contact predictor
        for j in range(n_axles):
            c = cluster_of_axle[j]
            lo = lo_c[c]
            s = 0.0
            for k in range(4):
                s += shape[j, k] * pred[edofs[j, k]]
            wpred[j] = s
            ypred[j] = qpred[wheel_dofs[j]]
            for i in range(n_axles):
                hv = kv_inv[wheel_dofs[j], wheel_dofs[i]]
                ht = 0.0
                if cluster_of_axle[i] == c:
                    basei = node_w[sleeper_node[bay_cache[i]]]
                    for k in range(4):
                        # column of axle i's DOF k evaluated at axle j's DOFs
                        lk = _local(edofs[i, k], basei, epb)
                        if lk < 0:
                            continue
                        acc = 0.0
                        for kk in range(4):
                            acc += shape[j, kk] * cols[i, lk, edofs[j, kk] - lo]
                        ht += shape[i, k] * acc
                H[j, i] = hv + ht
        # ---- Newton on the compressions: d = d_pred - H f(d)
        for j in range(n_axles):
            dp = ypred[j] - wpred[j] - z_axle[step, j]
            res[j] = dp
        for j in range(n_axles):
            delta[j] = res[j] if force[j] <= 0.0 else delta[j]
        for _it in range(60):
            for j in range(n_axles):
                force[j], fprime[j] = _contact(law, param, delta[j])
            err = 0.0
            for j in range(n_axles):
                r = delta[j] - res[j]
                for i in range(n_axles):
                    r += H[j, i] * force[i]
                tmp[j] = -r
                for i in range(n_axles):
                    J[j, i] = H[j, i] * fprime[i] + (1.0 if i == j else 0.0)
                err = max(err, abs(r))
            if err < 1e-15:
                break
            if n_axles == 1:
                delta[0] += tmp[0] / J[0, 0]
            else:
                dx = np.linalg.solve(J, tmp[:n_axles])
                for j in range(n_axles):
                    delta[j] += dx[j]
        for j in range(n_axles):
            force[j], fprime[j] = _contact(law, param, delta[j])

        # ---- correct the track: u = pred + Σ F_j K⁻¹ N_j
        for c in range(n_clusters):
            lo = lo_c[c]
            hi = hi_c[c]
            loaded = 0
            last = -1
            for j in range(n_axles):
                if cluster_of_axle[j] == c and force[j] != 0.0:
                    loaded += 1
                    last = j
            if loaded == 1:  # one loaded wheel in this window (a wheelset): correction and update in one sweep
                j = last
                basej = node_w[sleeper_node[bay_cache[j]]]
                c0 = cols[j, _local(edofs[j, 0], basej, epb)]
                c1 = cols[j, _local(edofs[j, 1], basej, epb)]
                c2 = cols[j, _local(edofs[j, 2], basej, epb)]
                c3 = cols[j, _local(edofs[j, 3], basej, epb)]
                f0 = force[j] * shape[j, 0]
                f1 = force[j] * shape[j, 1]
                f2 = force[j] * shape[j, 2]
                f3 = force[j] * shape[j, 3]
                for i in range(hi - lo):
                    k = lo + i
                    un = pred[k] + f0 * c0[i] + f1 * c1[i] + f2 * c2[i] + f3 * c3[i]
                    an = a0 * (un - u[k]) - a2 * v[k] - a3 * a[k]
                    v[k] += a6 * a[k] + a7 * an
                    a[k] = an
                    u[k] = un
                loaded = -1  # done
            for j in range(n_axles):
                if loaded < 0 or cluster_of_axle[j] != c or force[j] == 0.0:
                    continue
                basej = node_w[sleeper_node[bay_cache[j]]]
                l0 = _local(edofs[j, 0], basej, epb)
                l1 = _local(edofs[j, 1], basej, epb)
                l2 = _local(edofs[j, 2], basej, epb)
                l3 = _local(edofs[j, 3], basej, epb)
                f0 = force[j] * shape[j, 0]
                f1 = force[j] * shape[j, 1]
                f2 = force[j] * shape[j, 2]
                f3 = force[j] * shape[j, 3]
                for i in range(hi - lo):
                    pred[lo + i] += (
                        f0 * cols[j, l0, i] + f1 * cols[j, l1, i] + f2 * cols[j, l2, i] + f3 * cols[j, l3, i]
                    )
            for i in range(lo, hi):
                if loaded < 0:
                    break
                an = a0 * (pred[i] - u[i]) - a2 * v[i] - a3 * a[i]
                v[i] += a6 * a[i] + a7 * an
                a[i] = an
                u[i] = pred[i]
            # peak sleeper forces in the window
            for s_ in range(s_lo_c[c], s_hi_c[c] + 1):
                d = sleeper_dof[s_]
                w = node_w[sleeper_node[s_]]
                fb = bal_k[s_] * u[d] + bal_c[s_] * v[d]
                fp = pad_k[s_] * (u[w] - u[d]) + pad_c[s_] * (v[w] - v[d])
                if fb > peak_ballast[s_]:
                    peak_ballast[s_] = fb
                if fb + fp > peak_total[s_]:
                    peak_total[s_] = fb + fp

        # ---- correct the vehicle
        for i in range(nv):
            s = qpred[i]
            for j in range(n_axles):
                s -= kv_inv[i, wheel_dofs[j]] * force[j]
            an = a0 * (s - q[i]) - a2 * qd[i] - a3 * qdd[i]
            qd[i] += a6 * qdd[i] + a7 * an
            qdd[i] = an
            q[i] = s

        for j in range(n_axles):
            out_force[step, j] = force[j]
            w = 0.0
            for k in range(4):
                w += shape[j, k] * u[edofs[j, k]]
            out_rail[step, j] = w
            out_wheel[step, j] = q[wheel_dofs[j]]


@njit(cache=True, inline="always")
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


@njit(cache=True)
def _run_row(args, b):
    """Row ``b`` of a batch packed as in :func:`run_batch`: per-row arrays are indexed, shared ones passed on."""
    (
        mb,
        cb,
        keff,
        node_w,
        sleeper_dof,
        sleeper_node,
        pad_k,
        pad_c,
        bal_k,
        bal_c,
        elem_len,
        epb,
        spacing,
        n_sleepers,
        mv,
        cv,
        kv_inv,
        fv,
        wheel_dofs,
        cluster_of_axle,
        n_clusters,
        margin_bays,
        x_axle,
        z_axle,
        law,
        param,
        consts,
        u,
        v,
        a,
        q,
        qd,
        qdd,
        out_force,
        out_rail,
        out_wheel,
        peak_ballast,
        peak_total,
    ) = args
    _run_one(
        mb[b],
        cb[b],
        keff[b],
        node_w,
        sleeper_dof,
        sleeper_node,
        pad_k[b],
        pad_c[b],
        bal_k[b],
        bal_c[b],
        elem_len,
        epb,
        spacing,
        n_sleepers,
        mv,
        cv,
        kv_inv,
        fv,
        wheel_dofs,
        cluster_of_axle,
        n_clusters,
        margin_bays,
        x_axle,
        z_axle[b],
        law,
        param,
        consts,
        u[b],
        v[b],
        a[b],
        q[b],
        qd[b],
        qdd[b],
        out_force[b],
        out_rail[b],
        out_wheel[b],
        peak_ballast[b],
        peak_total[b],
    )


@njit(parallel=True, cache=True)
def run_batch(args):
    """Run every row of the batch (leading axis of the per-row arrays in ``args``, the argument list of
    :func:`_run_one`) in parallel; arrays are filled in place."""
    for b in prange(args[0].shape[0]):
        _run_row(args, b)


@njit(cache=True)
def run_serial(args):
    """:func:`run_batch` on one thread (a batch of one gains nothing from starting threads)."""
    for b in range(args[0].shape[0]):
        _run_row(args, b)
