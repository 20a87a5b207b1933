"""A plain reference integrator for one vehicle pass, written independently of the numba kernel.

The whole track is integrated (every DOF, scipy sparse M, C, K from ``Track.matrices()``) together with the
vehicle's full matrices, by Newmark's average-acceleration scheme (β = 1/4, γ = 1/2) in its textbook form.
The contact couples them: every step the track and the vehicle are predicted without contact force, and the
contact compressions δ_j = y_j − (w_j + z_j) solve

    δ = δ_pred − (H_vehicle + H_track) F(δ)

by Newton's method, where H are the flexibilities of the effective (Newmark) systems at the wheels. The
track's effective stiffness is constant, so it is LU-factorised once and solved every step for the predictor
and for one unit load under each wheel.

Conventions as in :mod:`trackenv.physics`: downward positive, the contact pushes the rail down and the wheel
up, the track's dead weight is not modelled, the irregularity z lowers the rail level. Slow but simple.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.interpolate
import scipy.sparse
import scipy.sparse.linalg

from trackenv.physics.contact import HertzContact


@dataclass
class ReferenceResult:
    time: np.ndarray  # (n_steps + 1,)
    wheel_position: np.ndarray  # (n_steps + 1, n_axles)
    contact_force: np.ndarray  # (n_steps + 1, n_axles)
    rail_displacement: np.ndarray  # (n_steps + 1, n_axles)
    wheel_displacement: np.ndarray  # (n_steps + 1, n_axles)
    ballast_force: np.ndarray  # (n_sleepers,) peak of k_b u_s + c_b v_s over the pass, static value included
    static_wheel_load: np.ndarray  # (n_axles,)


def shape_functions(xi: float, le: float) -> np.ndarray:
    """Hermite cubics of a beam element of length le at local coordinate xi ∈ [0, 1] (w1, θ1, w2, θ2)."""
    return np.array(
        [
            1.0 - 3.0 * xi**2 + 2.0 * xi**3,
            le * xi * (1.0 - xi) ** 2,
            xi**2 * (3.0 - 2.0 * xi),
            le * xi**2 * (xi - 1.0),
        ]
    )


def load_vector(track, x: float) -> np.ndarray:
    """Global vector N(x): N·u is the rail deflection at x, N the consistent nodal load of a unit force."""
    le = track.element_length
    e = min(max(int(np.floor(x / le)), 0), track.n_nodes - 2)
    lay = track.dof_layout
    n = np.zeros(track.n_dof)
    dofs = [lay.node_w[e], lay.node_theta[e], lay.node_w[e + 1], lay.node_theta[e + 1]]
    n[dofs] = shape_functions(x / le - e, le)
    return n


def rail_level(track, irregularity, x: np.ndarray) -> np.ndarray:
    """Irregularity z at positions x: None, a callable, or values per sleeper / per rail node (natural cubic
    spline through them)."""
    if irregularity is None:
        return np.zeros_like(x)
    if callable(irregularity):
        return np.asarray(irregularity(x), dtype=float)
    values = np.asarray(irregularity, dtype=float)
    grid = track.sleeper_positions if values.size == track.n_sleepers else track.node_positions
    assert values.size == grid.size
    return scipy.interpolate.CubicSpline(grid, values, bc_type="natural")(np.clip(x, 0.0, track.length))


def newton_compressions(delta_pred, flexibility, law, delta0, tol=1e-16, max_iter=100) -> np.ndarray:
    """Solve g(δ) = δ − δ_pred + H F(δ) = 0 for δ by Newton's method (scalar when there is one wheel)."""
    delta = np.array(delta0, dtype=float)
    eye = np.eye(delta.size)
    for _ in range(max_iter):
        force = law.force(delta)
        g = delta - delta_pred + flexibility @ force
        if np.max(np.abs(g)) < tol:
            break
        jac = eye + flexibility * law.stiffness(force)[None, :]
        if delta.size == 1:
            delta = delta - g / jac[0, 0]
        else:
            delta = delta - np.linalg.solve(jac, g)
    return delta


def reference_pass(
    track, vehicle, speed, irregularity=None, *, dt=1e-4, contact=None, x_start=None, x_end=None
) -> ReferenceResult:
    """One pass of ``vehicle`` over the whole ``track`` from static equilibrium (see the module docstring)."""
    law = HertzContact() if contact is None else contact
    veh = vehicle.system()
    n_axles = veh.n_axles
    offsets = veh.axle_offsets
    wheels = veh.wheel_dofs
    x_start = veh.span if x_start is None else float(x_start)
    x_end = track.length if x_end is None else float(x_end)

    # time grid, axle positions and the rail level under each wheel
    n_steps = int(np.ceil((x_end - x_start) / (speed * dt) - 1e-9))
    time = dt * np.arange(n_steps + 1)
    x_lead = np.minimum(x_start + speed * time, track.length)
    x_axle = x_lead[:, None] - offsets[None, :]
    z = rail_level(track, irregularity, x_axle)

    # matrices
    M, C, K = (m.tocsc() for m in track.matrices())
    Mv, Cv, Kv, fv = veh.mass, veh.damping, veh.stiffness, veh.force
    lay = track.dof_layout
    kb, cb = track.ballast_stiffness, track.ballast_damping
    s_dof = lay.sleeper

    # Newmark average acceleration: u_{n+1} = u_n + dt v_n + dt²/4 (a_n + a_{n+1}),
    # v_{n+1} = v_n + dt/2 (a_n + a_{n+1}); in terms of u_{n+1}:
    # a_{n+1} = 4/dt² (u_{n+1} − u_n) − 4/dt v_n − a_n and v_{n+1} = 2/dt (u_{n+1} − u_n) − v_n.
    c_m, c_c = 4.0 / dt**2, 2.0 / dt
    lu_track = scipy.sparse.linalg.splu((K + c_m * M + c_c * C).tocsc())
    kv_eff_inv = np.linalg.inv(Kv + c_m * Mv + c_c * Cv)

    # static equilibrium at the start: loads on the compliant rail by a few fixed-point sweeps (one for a
    # statically determinate vehicle), track from K u = Σ P_j N_j, wheels at w + z + δ(P)
    lu_static = scipy.sparse.linalg.splu(K.tocsc())
    loads = veh.static_wheel_loads.copy()
    N0 = np.stack([load_vector(track, x) for x in x_axle[0]], axis=1)
    for _ in range(10):
        u = lu_static.solve(N0 @ loads)
        w = N0.T @ u
        q = veh.static_displacements(w + z[0] + law.compression(loads))
        new_loads = fv[wheels] - Kv[wheels] @ q
        done = np.allclose(new_loads, loads, rtol=1e-13, atol=1e-9)
        loads = new_loads
        if done:
            break
    v, a = np.zeros_like(u), np.zeros_like(u)
    qd, qdd = np.zeros_like(q), np.zeros_like(q)

    force = np.zeros((n_steps + 1, n_axles))
    rail = np.zeros_like(force)
    wheel = np.zeros_like(force)
    force[0], rail[0], wheel[0] = loads, w, q[wheels]
    peak_ballast = kb * u[s_dof] + cb * v[s_dof]
    delta = law.compression(loads)

    for step in range(1, n_steps + 1):
        N = np.stack([load_vector(track, x) for x in x_axle[step]], axis=1)  # (n_dof, n_axles)
        # predictors without contact force
        rhs = M @ (c_m * u + 2.0 * c_c * v + a) + C @ (c_c * u + v)
        sol = lu_track.solve(np.column_stack([rhs, N]))
        u_pred, g_track = sol[:, 0], sol[:, 1:]
        rhs_v = fv + Mv @ (c_m * q + 2.0 * c_c * qd + qdd) + Cv @ (c_c * q + qd)
        q_pred = kv_eff_inv @ rhs_v
        # contact
        flex = N.T @ g_track + kv_eff_inv[np.ix_(wheels, wheels)]
        delta_pred = q_pred[wheels] - N.T @ u_pred - z[step]
        start = np.where(delta > 0.0, delta, delta_pred)
        delta = newton_compressions(delta_pred, flex, law, start)
        f = law.force(delta)
        # corrected states
        u_new = u_pred + g_track @ f
        q_new = q_pred - kv_eff_inv[:, wheels] @ f
        a_new = c_m * (u_new - u) - 2.0 * c_c * v - a
        v = c_c * (u_new - u) - v
        a, u = a_new, u_new
        qdd_new = c_m * (q_new - q) - 2.0 * c_c * qd - qdd
        qd = c_c * (q_new - q) - qd
        qdd, q = qdd_new, q_new

        force[step], rail[step], wheel[step] = f, N.T @ u, q[wheels]
        np.maximum(peak_ballast, kb * u[s_dof] + cb * v[s_dof], out=peak_ballast)

    return ReferenceResult(time, x_axle, force, rail, wheel, peak_ballast, veh.static_wheel_loads.copy())
