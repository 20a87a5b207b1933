"""The pass integration of :mod:`trackenv.physics._step` in torch, batched over rows, on any torch device.

The same time-stepping algorithm as the numba kernel — Newmark average acceleration on the linear track and
vehicle, the contact solved by Newton's method every step, the track integrated in a window that moves with each
group of axles by whole bays — with the rows on the leading axis of every tensor, so that one step of all rows is
a few dozen tensor operations (a GPU runs them over thousands of rows at once). It takes the kernel's own
arguments (``Mesh``, ``Drive``, ``Rows``, ``Peaks`` of :mod:`trackenv.physics._step`, in their layout: chunks,
..., width) and fills their outputs and final state in place as the kernel does, so that
``simulate_passes(..., backend="torch")`` shares all of the pass's preparation and results.

What differs from the kernel is the linear algebra of a window. The kernel factors the window's banded effective
stiffness once per move and sweeps its triangular factors along the track every step; a sweep is a chain of
dependent steps, one tensor operation each, which a GPU would run one launch at a time. Here the window's matrix
(tens to a few hundred DOFs) is factored densely for all rows at once when the window moves, and each step's
solve is one batched product with its inverse (``solver="inverse"``) or one batched pair of triangular solves
(``solver="cholesky"``). The solves' rounding therefore differs from the kernel's, by far less than the
integration's own error (see ``tests/physics/test_torch_pass.py``).

Where the window is, which element each axle is on and its shape functions depend only on the axles' positions,
shared by the rows, so they are worked out on the host once per pass; the loop over time steps runs on the host
and launches the rows' work. The Newton iteration runs on every row with masks: a row that has converged keeps
its compression while the others go on, so each row takes the steps it would take alone.

This module imports numpy and torch only (not numba, not the rest of the package), so that it can be loaded on
its own on a machine where the kernel cannot be compiled.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass

import numpy as np
import torch

B = 4  # half-bandwidth of the track matrices (track.HALF_BANDWIDTH)
NEWTON_MAX_ITERATIONS = 60  # as the kernel
NEWTON_TOLERANCE_M = 1e-15  # as the kernel: the largest residual of a row's compressions [m]
NEWTON_UNCHECKED = 3  # iterations run before the first check of convergence (a check waits for the device)
SOLVERS = ("inverse", "cholesky")


def torch_device(device=None) -> torch.device:
    """``device`` (None: the CPU) as a torch device, checked to be usable here."""
    try:
        dev = torch.device("cpu" if device is None else device)
    except (RuntimeError, TypeError) as err:
        raise ValueError(f"device must be a torch device such as 'cpu' or 'cuda', got {device!r}") from err
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise ValueError(f"device {device!r}: torch finds no CUDA device here")
    return dev


@contextlib.contextmanager
def one_thread_on_cpu(dev: torch.device):
    """On the CPU, torch's intra-op threads set to one for the pass and restored after it: a pass is thousands of
    operations on small tensors, for which waking threads costs more than the arithmetic (a 153 × 153 product took
    ~1 000 times as long with two threads as with one on a busy two-core machine)."""
    if dev.type != "cpu":
        yield
        return
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)


# ------------------------------------------------------------------------------------ the kernel's layout
def unpack(x: np.ndarray) -> np.ndarray:
    """(chunks, ..., width) -> (chunks * width, ...): the kernel's layout as rows first."""
    x = np.moveaxis(x, -1, 1)
    return x.reshape((-1,) + x.shape[2:])


def pack_into(out: np.ndarray, rows: np.ndarray) -> None:
    """Write ``rows`` (chunks * width, ...) into ``out`` in the kernel's layout (chunks, ..., width)."""
    n_chunks, width = out.shape[0], out.shape[-1]
    out[...] = np.moveaxis(rows.reshape((n_chunks, width) + rows.shape[1:]), 1, -1)


ROW_FIELDS = ("mass_diag", "keff", "pad_k", "pad_c", "bal_k", "bal_c", "z", "sag", "u", "v", "a", "q", "qd", "qdd")
STATE_FIELDS = ("u", "v", "a", "q", "qd", "qdd", "z")
PEAK_FIELDS = ("force", "rail", "wheel", "ballast", "total")


def run(mesh, drive, rows, peaks, reuse=None, width=None, *, device=None, solver: str = "inverse") -> None:
    """Integrate every row of the kernel's arguments over the pass, filling ``peaks`` and the final state in
    ``rows`` in place as :func:`trackenv.physics._kernel.run` does (``reuse`` and ``width`` are accepted for the
    same call and not used: the rows' layout gives the width)."""
    dev = torch_device(device)
    tensors = {name: torch.as_tensor(unpack(getattr(rows, name)), device=dev) for name in ROW_FIELDS}
    tensors.update({f"out_{name}": torch.as_tensor(unpack(getattr(peaks, name)), device=dev) for name in PEAK_FIELDS})
    out = integrate(mesh, drive, tensors, solver=solver)
    for name in STATE_FIELDS:
        pack_into(getattr(rows, name), out[name].cpu().numpy())
    for name in PEAK_FIELDS:
        pack_into(getattr(peaks, name), out[f"out_{name}"].cpu().numpy())


# ------------------------------------------------------------------------------------ the host's schedule
@dataclass(frozen=True)
class Schedule:
    """What the axles' positions decide, shared by the rows, for every step: each axle's element, its Hermite
    shape functions (steps, axles, 4) and element DOFs (steps, axles, 4), and its bay."""

    shape: np.ndarray
    edofs: np.ndarray
    bay: np.ndarray


def schedule(mesh, drive) -> Schedule:
    """Each axle's element, shape functions and element DOFs at every step, as the kernel places them."""
    node_w = np.asarray(mesh.node_w)
    le = float(mesh.elem_len)
    x = np.asarray(drive.x_axle, dtype=float)
    e = np.clip((x / le).astype(np.int64), 0, node_w.shape[0] - 2)
    xi = x / le - e
    xi2 = xi * xi
    xi3 = xi2 * xi
    shape = np.stack([1.0 - 3.0 * xi2 + 2.0 * xi3, le * (xi - 2.0 * xi2 + xi3), 3.0 * xi2 - 2.0 * xi3,
                      le * (xi3 - xi2)], axis=-1)
    edofs = np.stack([node_w[e], node_w[e] + 1, node_w[e + 1], node_w[e + 1] + 1], axis=-1)
    return Schedule(shape, edofs, e // int(mesh.epb))


def local_column(dof: np.ndarray, base, epb: int, missing: int) -> np.ndarray:
    """Index of rail DOFs among their bay's columns (w, θ of its epb+1 nodes; the sleeper DOF after the first
    node shifts the later ones by one), ``missing`` where a DOF is not among them (as the kernel's ``_local``)."""
    off = dof - base
    out = np.where(off < 2, off, off - 1)
    return np.where((off == 2) | (out >= 2 * (epb + 1)), missing, out)


# ------------------------------------------------------------------------------------ a window
@dataclass
class Window:
    """One axle group's window of track [lo, hi) (DOFs) over sleepers s_lo..s_hi, for every row: the inverse (or
    Cholesky factor) of its effective stiffness, its sleepers' DOFs relative to lo, its rail mass diagonals, and
    the solved unit-load columns of each of its axles' bays."""

    lo: int
    hi: int
    s_lo: int
    s_hi: int
    solve_with: torch.Tensor  # (rows, m, m): K_eff⁻¹, or its lower Cholesky factor
    w_at: torch.Tensor  # (sleepers,) each sleeper's rail DOF, relative to lo
    s_at: torch.Tensor  # (sleepers,) each sleeper's own DOF, relative to lo
    rail_mass: torch.Tensor  # (m, 2B+1) the rail's mass diagonals, the diagonal zeroed (it is per row)
    columns: torch.Tensor  # (rows, m, axles, ncol + 1): K_eff⁻¹ of the unit loads of each axle's bay, and zeros
    ballast: torch.Tensor  # (rows, sleepers, 2): the window's sleepers' ballast stiffness and damping
    pad: torch.Tensor  # (rows, sleepers, 2): their pads' stiffness and damping


def dense_window(keff: torch.Tensor, lo: int, hi: int) -> torch.Tensor:
    """The symmetric matrix of the lower band storage keff[:, i, k] = K[i, i-k] on DOFs [lo, hi): (rows, m, m)."""
    m = hi - lo
    dense = torch.zeros((keff.shape[0], m, m), dtype=keff.dtype, device=keff.device)
    for k in range(min(B, m - 1) + 1):
        i = torch.arange(k, m, device=keff.device)
        dense[:, i, i - k] = keff[:, lo + k : hi, k]
        dense[:, i - k, i] = keff[:, lo + k : hi, k]
    return dense


def solve_window(window: Window, rhs: torch.Tensor, solver: str) -> torch.Tensor:
    """K_eff x = rhs on the window for every row; rhs (rows, m) or (rows, m, k)."""
    vector = rhs.dim() == 2
    b = rhs.unsqueeze(-1) if vector else rhs
    x = window.solve_with @ b if solver == "inverse" else torch.cholesky_solve(b, window.solve_with)
    return x.squeeze(-1) if vector else x


def open_window(mesh, st: dict, rail_mass: torch.Tensor, s_lo: int, s_hi: int, bays: np.ndarray,
                solver: str) -> Window:
    """The window over sleepers s_lo..s_hi: its factor, and the solved unit loads on the rail DOFs of the bays
    ``bays`` of its axles (w, θ of each of the bay's nodes)."""
    keff = st["keff"]
    node_w, sleeper_node, sleeper_dof = np.asarray(mesh.node_w), np.asarray(mesh.sleeper_node), mesh.sleeper_dof
    lo, hi = int(node_w[sleeper_node[s_lo]]), int(sleeper_dof[s_hi]) + 1
    dev, m = keff.device, hi - lo
    factor = torch.linalg.cholesky(dense_window(keff, lo, hi))
    if solver == "inverse":  # K_eff⁻¹ by solving for the identity (batched on every device torch supports)
        solve_with = torch.cholesky_solve(torch.eye(m, dtype=keff.dtype, device=dev).expand(keff.shape[0], m, m),
                                          factor)
    else:
        solve_with = factor
    sleepers = np.arange(s_lo, s_hi + 1)
    w_at = torch.as_tensor(node_w[sleeper_node[sleepers]] - lo, device=dev)
    s_at = torch.as_tensor(np.asarray(sleeper_dof)[sleepers] - lo, device=dev)
    masses = rail_mass[:, lo:hi].T.clone()
    masses[:, B] = 0.0
    k = np.arange(2 * (int(mesh.epb) + 1))
    dofs = torch.as_tensor(node_w[sleeper_node[np.asarray(bays)][:, None] + k // 2] + k % 2 - lo, device=dev)
    if solver == "inverse":
        cols = solve_with[:, :, dofs]  # (rows, m, axles, ncol)
    else:
        unit = torch.zeros((m, dofs.numel()), dtype=keff.dtype, device=dev)
        unit[dofs.reshape(-1), torch.arange(dofs.numel(), device=dev)] = 1.0
        cols = torch.cholesky_solve(unit.expand(keff.shape[0], m, dofs.numel()), factor).reshape(
            keff.shape[0], m, *dofs.shape)
    columns = torch.cat([cols, torch.zeros_like(cols[..., :1])], dim=-1)
    s = slice(s_lo, s_hi + 1)
    ballast = torch.stack([st["bal_k"][:, s], st["bal_c"][:, s]], dim=-1)
    pad = torch.stack([st["pad_k"][:, s], st["pad_c"][:, s]], dim=-1)
    return Window(lo, hi, s_lo, s_hi, solve_with, w_at, s_at, masses, columns, ballast, pad)


def contact_law(law: int, param: float, d: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Force and tangent stiffness of the contact law at compression d, zero where d <= 0 (Hertz: law 0,
    f = (d/G)^{3/2} with G = param; linear: f = param·d)."""
    dd = d.clamp(min=0.0)  # (d <= 0 gives f = f' = 0 exactly below, as in the kernel)
    if law == 0:
        r = dd * (1.0 / param)
        sr = torch.sqrt(r)
        return r * sr, sr * (1.5 / param)
    return param * dd, (d > 0.0).to(d.dtype) * param


def track_maps(consts, dtype, device) -> dict:
    """The track's Newmark arithmetic per DOF as products with small matrices of its state [u, v, a]:

    * ``rhs``: p = a0 u + a2 v + a3 a and q = a1 u + a4 v + a5 a (the predictor's M p + C q), [u, v, a] · R;
    * ``update``: with d = u_new - u, a_new = a0 d - a2 v - a3 a and v_new = v + a6 a + a7 a_new,
      [d, v, a] · U = [v_new, a_new] (d, not u_new and u apart: a0 d is then exact where u_new ≈ u)."""
    a0, a1, a2, a3, a4, a5, a6, a7 = (float(c) for c in consts[:8])
    rhs = [[a0, a1], [a2, a4], [a3, a5]]
    update = [[a7 * a0, a0], [1.0 - a7 * a2, -a2], [a6 - a7 * a3, -a3]]
    return {"rhs": torch.tensor(rhs, dtype=dtype, device=device),
            "update": torch.tensor(update, dtype=dtype, device=device)}


def predict_track(win: Window, st: dict, maps: dict) -> torch.Tensor:
    """The track's predictor on the window (no contact force): K_eff pred = M p + C q, with p = a0 u + a2 v + a3 a
    and q = a1 u + a4 v + a5 a; M is the rail's band plus each row's diagonal, C the pads' and ballast's dampers.
    Returns the right-hand side (rows, m)."""
    lo, hi = win.lo, win.hi
    pq = st["uva"][:, lo:hi] @ maps["rhs"]  # (rows, m, 2): p and q
    p, qd = pq[..., 0], pq[..., 1]
    padded = torch.nn.functional.pad(p, (B, B))
    rhs = torch.addcmul((padded.unfold(1, 2 * B + 1, 1) * win.rail_mass).sum(-1), st["mass_diag"][:, lo:hi], p)
    q_w, q_s = qd[:, win.w_at], qd[:, win.s_at]
    f_pad = win.pad[..., 1] * (q_w - q_s)
    rhs[:, win.w_at] += f_pad
    rhs[:, win.s_at] += win.ballast[..., 1] * q_s - f_pad
    return rhs


def newton(law: int, param: float, H: torch.Tensor, res: torch.Tensor,
           delta: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Each row's compressions d solving d = res - H f(d) by Newton's method from ``delta``, and the contact
    forces f(d); a row stops when its largest residual is below the tolerance, as in the kernel, and keeps its
    compressions while others go on."""
    if H.shape[1] == 1:
        return newton_one_axle(law, param, H[:, :, 0], res, delta)
    eye = torch.eye(H.shape[1], dtype=H.dtype, device=H.device)
    done = torch.zeros(H.shape[0], dtype=torch.bool, device=H.device)
    for it in range(NEWTON_MAX_ITERATIONS):
        f, fp = contact_law(law, param, delta)
        r = delta - res + (H @ f.unsqueeze(-1)).squeeze(-1)
        done |= r.abs().amax(dim=1) < NEWTON_TOLERANCE_M
        if it + 1 >= NEWTON_UNCHECKED and bool(done.all()):
            return delta, f  # (every row kept its compressions in this iteration: f is their force)
        step = torch.linalg.solve(H * fp.unsqueeze(1) + eye, r)
        delta = torch.where(done.unsqueeze(1), delta, delta - step)
    return delta, contact_law(law, param, delta)[0]


def newton_one_axle(law: int, param: float, h: torch.Tensor, res: torch.Tensor,
                    delta: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`newton` for one axle (``h``: (rows, 1) its flexibility), the step a division, in as few operations
    as the arithmetic allows: each is a launch on a GPU."""
    one = torch.ones_like(h)
    done = torch.zeros_like(delta, dtype=torch.bool)
    for it in range(NEWTON_MAX_ITERATIONS):
        f, fp = contact_law(law, param, delta)
        r = torch.addcmul(delta - res, h, f)
        done |= r.abs() < NEWTON_TOLERANCE_M
        if it + 1 >= NEWTON_UNCHECKED and bool(done.all()):
            return delta, f
        delta = torch.where(done, delta, delta - r / torch.addcmul(one, h, fp))
    return delta, contact_law(law, param, delta)[0]


def correct_track(win: Window, st: dict, pred: torch.Tensor, flex: torch.Tensor, force: torch.Tensor,
                  maps: dict) -> None:
    """u = pred + Σ_j F_j K⁻¹ N_j on the window (``flex``: (rows, m, axles) the K⁻¹ N_j of its axles), the Newmark
    update (:func:`track_maps`), and the peak ballast and pad + ballast forces of the window's sleepers."""
    lo, hi = win.lo, win.hi
    uva = st["uva"][:, lo:hi]
    new_u = torch.baddbmm(pred.unsqueeze(-1), flex, force.unsqueeze(-1)).squeeze(-1)
    dva = torch.cat([(new_u - uva[..., 0]).unsqueeze(-1), uva[..., 1:]], dim=-1)
    uva[..., 1:] = dva @ maps["update"]
    uva[..., 0] = new_u
    s = slice(win.s_lo, win.s_hi + 1)
    at_s, at_w = uva[:, win.s_at, :2], uva[:, win.w_at, :2]  # (u, v) of each sleeper and of the rail above it
    fb = (at_s * win.ballast).sum(-1)
    total = fb + ((at_w - at_s) * win.pad).sum(-1)
    st["out_ballast"][:, s] = torch.maximum(st["out_ballast"][:, s], fb)
    st["out_total"][:, s] = torch.maximum(st["out_total"][:, s], total)


def vehicle_maps(drive, consts, wheel_dofs: np.ndarray, as_t) -> dict:
    """The vehicle's step as two linear maps of its state, composed once per pass (the vehicle is small: a
    step's vehicle work is then two products instead of a few dozen operations):

    * predictor, K_eff q_pred = f + M p + C r with p = a0 q + a2 q' + a3 q'', r = a1 q + a4 q' + a5 q'':
      q_pred = [q, q', q''] · P + K_eff⁻¹ f;
    * corrector, q_new = q_pred - K_eff⁻¹ Σ_j F_j e_wheel(j), then Newmark's a = a0 (q_new - q) - a2 q' - a3 q''
      and q' += a6 q'' + a7 a: [q_new - q, q', q''] = [q_pred - q, F, q', q''] · Q (differences, so that a0 times
      them is exact where q_new ≈ q)."""
    a0, a1, a2, a3, a4, a5, a6, a7 = (float(c) for c in consts[:8])
    mass, damping = np.asarray(drive.mass, dtype=float), np.asarray(drive.damping, dtype=float)
    kv_inv = np.asarray(drive.kv_inv, dtype=float)
    nv, n_axles = kv_inv.shape[0], wheel_dofs.size
    P = np.concatenate([(kv_inv @ (c0 * mass + c1 * damping)).T for c0, c1 in ((a0, a1), (a2, a4), (a3, a5))])
    eye, zero = np.eye(nv), np.zeros((nv, nv))
    step = np.concatenate([eye, -kv_inv[:, wheel_dofs].T, zero, zero])  # rows: q_pred - q, F, q', q''
    acc = a0 * step
    acc[n_axles + nv : n_axles + 2 * nv] -= a2 * eye
    acc[n_axles + 2 * nv :] -= a3 * eye
    vel = a7 * acc
    vel[n_axles + nv : n_axles + 2 * nv] += eye
    vel[n_axles + 2 * nv :] += a6 * eye
    return {"P": as_t(P), "f": as_t(kv_inv @ np.asarray(drive.force, dtype=float)),
            "Q": as_t(np.concatenate([step, vel, acc], axis=1))}


def predict_vehicle(st: dict, maps: dict) -> torch.Tensor:
    """The vehicle's predictor (no contact force), q_pred (rows, nv): see :func:`vehicle_maps`."""
    return torch.addmm(maps["f"], st["qstate"], maps["P"])


def correct_vehicle(st: dict, maps: dict, qpred: torch.Tensor, force: torch.Tensor) -> None:
    """The vehicle's corrector and Newmark update of its state (q, q', q'') in place: see :func:`vehicle_maps`."""
    state, nv = st["qstate"], qpred.shape[1]
    new = torch.cat([qpred - state[:, :nv], force, state[:, nv:]], dim=1) @ maps["Q"]
    state[:, :nv] += new[:, :nv]
    state[:, nv:] = new[:, nv:]


# ------------------------------------------------------------------------------------ the pass
def integrate(mesh, drive, st: dict, *, solver: str = "inverse") -> dict:
    """Integrate the rows of ``st`` over the pass, in place, and return ``st``.

    ``st`` holds torch tensors, rows first, on one device: the kernel's ``Rows`` fields (mass_diag, keff, pad_k,
    pad_c, bal_k, bal_c, z, sag, u, v, a, q, qd, qdd) and its ``Peaks`` as out_force, out_rail, out_wheel (step 0
    filled: the start) and out_ballast, out_total (the peaks so far). ``mesh`` and ``drive`` are the kernel's
    shared arguments (numpy arrays). The state is integrated as two tensors, ``st["uva"]`` (rows, n_dof, 3) and
    ``st["qstate"]`` (rows, 3 nv), added to ``st``; its u, v, a, q, qd, qdd become views of them."""
    if solver not in SOLVERS:
        raise ValueError(f"solver must be one of {SOLVERS}, got {solver!r}")
    with one_thread_on_cpu(st["u"].device):
        return _integrate(mesh, drive, st, solver)


def _integrate(mesh, drive, st: dict, solver: str) -> dict:
    """:func:`integrate`, its arguments checked."""
    dev, dtype = st["u"].device, st["u"].dtype
    plan = schedule(mesh, drive)
    consts = np.asarray(drive.consts, dtype=float)
    law, param = int(drive.law), float(drive.param)
    wheel_dofs = np.asarray(drive.wheel_dofs)
    cluster = np.asarray(drive.cluster_of_axle)
    n_rows, n_axles, n_clusters, epb = st["u"].shape[0], wheel_dofs.size, int(drive.n_clusters), int(mesh.epb)

    def as_t(x):
        return torch.as_tensor(np.asarray(x, dtype=float), dtype=dtype, device=dev)

    kv_inv = np.asarray(drive.kv_inv, dtype=float)
    maps = vehicle_maps(drive, consts, wheel_dofs, as_t)
    h_vehicle = as_t(kv_inv[np.ix_(wheel_dofs, wheel_dofs)])
    # the track's state as one tensor (u, v, a of each DOF side by side) and the vehicle's (q, q', q''), st's u,
    # v, a and q, qd, qdd views of them
    st["uva"] = torch.stack([st["u"], st["v"], st["a"]], dim=-1)
    st["u"], st["v"], st["a"] = (st["uva"][..., i] for i in range(3))
    tmaps = track_maps(consts, dtype, dev)
    nv = kv_inv.shape[0]
    st["qstate"] = torch.cat([st["q"], st["qd"], st["qdd"]], dim=1)
    st["q"], st["qd"], st["qdd"] = (st["qstate"][:, i * nv : (i + 1) * nv] for i in range(3))
    rail_mass = as_t(mesh.rail_mass)
    wheel_index = torch.as_tensor(wheel_dofs, device=dev)
    # the whole schedule on the device once: a step indexes it there, with no transfer
    base = np.asarray(mesh.node_w)[np.asarray(mesh.sleeper_node)[plan.bay]]
    loc = local_column(plan.edofs, base[..., None], epb, 2 * (epb + 1))
    shapes = as_t(plan.shape)
    edofs_all, loc_all = torch.as_tensor(plan.edofs, device=dev), torch.as_tensor(loc, device=dev)
    members = [np.flatnonzero(cluster == c) for c in range(n_clusters)]
    groups = [torch.as_tensor(axles, device=dev) for axles in members]

    force = st["out_force"][:, 0].clone()
    delta = param * force ** (2.0 / 3.0) if law == 0 else force / param
    windows: list[Window | None] = [None] * n_clusters
    bay_cache = np.full(n_axles, -1)
    for step in range(1, plan.shape.shape[0]):
        shape, edofs = shapes[step], edofs_all[step]
        # the settled supports' static sag joins each row's rail level under the wheels
        st["z"][:, step] += (st["sag"][:, edofs] * shape).sum(-1)
        for c, axles in enumerate(members):
            bays = plan.bay[step]
            if np.any(bays[axles] != bay_cache[axles]):
                windows[c] = move_window(mesh, st, rail_mass, windows[c], bays[axles], solver)
                bay_cache[axles] = bays[axles]
        qpred = predict_vehicle(st, maps)
        wpred = torch.empty((n_rows, n_axles), dtype=dtype, device=dev)
        H = h_vehicle.expand(n_rows, n_axles, n_axles).clone()
        preds, flexes = [], []
        for win, sel in zip(windows, groups):
            assert win is not None
            pred = solve_window(win, predict_track(win, st, tmaps), solver)
            flex = axle_flexibilities(win, loc_all[step, sel], shape[sel])
            at = edofs[sel] - win.lo
            wpred[:, sel] = (pred[:, at] * shape[sel]).sum(-1)
            # H[j, i] += N_j · (K⁻¹ N_i) for the axles of one window
            H[:, sel.unsqueeze(1), sel.unsqueeze(0)] += (flex[:, at, :] * shape[sel].unsqueeze(-1)).sum(2)
            preds.append(pred)
            flexes.append(flex)
        res = qpred[:, wheel_index] - wpred - st["z"][:, step]
        delta = torch.where(force <= 0.0, res, delta)
        delta, force = newton(law, param, H, res, delta)
        for win, sel, pred, flex in zip(windows, groups, preds, flexes):
            assert win is not None
            correct_track(win, st, pred, flex, force[:, sel], tmaps)
        correct_vehicle(st, maps, qpred, force)
        st["out_force"][:, step] = force
        st["out_rail"][:, step] = (st["u"][:, edofs] * shape).sum(-1)
        st["out_wheel"][:, step] = st["q"][:, wheel_index]
    return st


def axle_flexibilities(win: Window, loc: torch.Tensor, shape: torch.Tensor) -> torch.Tensor:
    """K_eff⁻¹ N_j on the window for each of its axles (rows, m, axles): their bays' columns at the axles' element
    DOFs (``loc``: (axles, 4) among the columns) weighted by the shape functions (axles, 4)."""
    axle = torch.arange(loc.shape[0], device=loc.device).unsqueeze(1)
    return (win.columns[:, :, axle, loc] * shape).sum(-1)


def move_window(mesh, st: dict, rail_mass: torch.Tensor, old: Window | None, bays: np.ndarray,
                solver: str) -> Window:
    """Move a group's window to span the margin's sleepers beyond its axles' ``bays``: the DOFs it leaves behind
    come to rest, and the new window is factored with its axles' bay columns."""
    s_lo = max(0, int(bays.min()) - int(mesh.margin_bays))
    s_hi = min(int(mesh.n_sleepers) - 1, int(bays.max()) + 1 + int(mesh.margin_bays))
    lo = int(mesh.node_w[mesh.sleeper_node[s_lo]])
    if old is not None:
        st["uva"][:, old.lo : min(lo, old.hi)] = 0.0
    return open_window(mesh, st, rail_mass, s_lo, s_hi, bays, solver)
