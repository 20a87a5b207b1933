"""The time step of a pass: its bounds (one set, read by every layer) and the accuracy contract of ``dt="auto"``.

The integrator (Newmark average acceleration) is unconditionally stable, so dt is a matter of accuracy only. The
reference is ``DT_REFERENCE_S`` = 1e-4 s (validation and the paper's reproduction run there). The contract of
:func:`auto_time_step`: the coarsest step of a fixed ladder whose per-sleeper peak forces and peak contact force
stay within 0.5 % of the reference, for a pass that keeps contact. Two time scales bound it:

* the sleeper-passing period s/v: the track's response is periodic in it and its peaks must be sampled
  (dt ≤ s / (v · STEPS_PER_SLEEPER_PASSING));
* the contact period T_c = 2π √(m_w / k_H), the wheel's unsprung mass on the linearised Hertz spring at three
  times the static wheel load (the highest natural frequency the wheel excites; a drop from rest or an impact
  rings at it): dt ≤ T_c / STEPS_PER_CONTACT_PERIOD.

The constants are calibrated on a convergence matrix (smooth track, PSD irregularity, a fresh 2 mm tamping step,
a voided sleeper, a 4x transition zone, a 1 m dip, 100 and 200 km/h, a freight car, the drop from rest, settled
supports), which ``tests/physics/test_timestep.py`` checks: at the auto step every case stays within 0.5 % on
the sleepers between the two end sleepers (the first and the last sleeper depend on where the last step falls).
A wheel that loses contact hits the rail again: the impact is short and its peak converges much more slowly in
dt (a 2 mm, 1 m dip at 200 km/h is 1.7 % off at dt = 2e-4), so :func:`trackenv.physics.dynamics.simulate_passes`
reruns a row that lost contact at the reference step.

A kink in the rail level (a dipped joint, a weld, the edge of a V-shaped dip: a change of slope over a length
shorter than a step of the wheel) is an impact too: it rings the wheel and the rail on the contact spring at a
frequency well above T_c's, which the auto step does not resolve, and the contact peak it gives is off (a
V-shaped dip whose slope changes by 3 mrad: 0.45-1.7 % at 20-160 km/h, by 2 mrad at 160 km/h: 0.54 %, by 20 mrad
at 100 km/h: 13 %; the sleeper forces up to 1.1 % at 10 mrad). So a row whose rail level, given as a function of
x (the only form that can kink: an array is a natural cubic spline, smooth in slope and curvature), changes slope
by more than :data:`MAX_SLOPE_CHANGE_PER_STEP` within a step (:func:`slope_change_per_step`) is rerun at the
reference step as well. The threshold is half the smallest such
kink found off the contract (2 mrad at 160 km/h; 3 mrad at 40-100 km/h). The contract matrix stays below 0.9 mrad
(its dip is a function), and the envs' rows are arrays, or settled supports (below 0.5 mrad on every line id and
the 60 m track, two episodes each of 40 steps without maintenance): neither reruns.

Known limits: a lone 1-3 mm spike at one sleeper of an array, at 160 km/h, puts one sleeper's force 2-3 % off at
the auto step (3.2e-4 s). The matrix uses the German PSD of low disturbance (the env's default initial quality); checked
over 8 seeds it stays within 0.38 %. On the high-disturbance PSD (8 seeds) the sleeper forces stay within
0.52 % but the peak contact force is up to 0.9 % off (not monotone in dt between 2.5e-4 and 4e-4): on rough
track use dt = DT_REFERENCE_S, or make the rule aware of the irregularity (not done).
"""

from __future__ import annotations

import numpy as np

from ._checks import check_scalar, check_speed

DT_REFERENCE_S = 1e-4  # [s] the reference step: validation, the paper, and the auto step's yardstick
DT_MIN_S = 1e-6  # [s] smallest step any layer accepts
DT_MAX_S = 5e-4  # [s] largest step any layer accepts (the largest the contract matrix covers)
STEPS_PER_SLEEPER_PASSING = 36
STEPS_PER_CONTACT_PERIOD = 10
MIN_STEPS_PER_CONTACT_PERIOD = 8  # below this Newmark's period error at the contact frequency exceeds 5 %
LADDER_S = DT_REFERENCE_S * np.array([1.0, 1.25, 1.6, 2.0, 2.5, 3.2, 4.0, 5.0])  # steps the auto rule picks from
CONTRACT_TOLERANCE = 0.005  # relative error of peak forces the auto step keeps against the reference
#: [rad] the largest change of the rail level's slope within a step of the wheel that the auto step resolves
#: (a kink above it, a dipped joint or a weld, runs at the reference step: the module docstring)
MAX_SLOPE_CHANGE_PER_STEP = 1.0e-3


def contact_period(system, law) -> float:
    """T_c [s]: the lightest wheel's mass on the contact spring linearised at three times the largest static wheel
    load (``system``: a :class:`~trackenv.physics.vehicle.VehicleSystem`; ``law``: a contact law)."""
    k_contact = float(np.max(law.stiffness(max(float(system.static_wheel_loads.max()), 1.0) * 3.0)))
    m_wheel = float(np.min(np.diag(system.mass)[system.wheel_dofs]))
    return 2 * np.pi * np.sqrt(m_wheel / k_contact)


def check_time_step(dt, period: float | None = None) -> float:
    """``dt`` [s] validated against the one set of bounds, [DT_MIN_S, DT_MAX_S], and, given the contact period
    ``period`` [s], against the contact resolution (at least MIN_STEPS_PER_CONTACT_PERIOD steps per period)."""
    dt = check_scalar("dt", dt, low=DT_MIN_S, high=DT_MAX_S)
    if period is not None and dt > period / MIN_STEPS_PER_CONTACT_PERIOD:
        raise ValueError(
            f"dt must be <= {period / MIN_STEPS_PER_CONTACT_PERIOD:.3g} s to resolve the wheel-on-contact-spring "
            f"vibration (period {period:.3g} s), got {dt:g}"
        )
    return dt


def check_dt_option(dt) -> float | str:
    """A ``dt`` option as the env, the loop and the dynamics take it: "auto" or a step within the bounds."""
    if isinstance(dt, str):
        if dt != "auto":
            raise ValueError(f"dt must be 'auto' or a number of seconds in [{DT_MIN_S}, {DT_MAX_S}], got {dt!r}")
        return dt
    return check_time_step(dt)


def auto_time_step(track, system, speed: float, law) -> float:
    """The step ``dt="auto"`` uses for a pass of ``system`` (a VehicleSystem) at ``speed`` [m/s] over ``track``
    with contact ``law``: the largest ladder step within both bounds of the module docstring (or the bound
    itself where it is below the reference step)."""
    speed = check_speed(speed)
    bound = min(
        DT_MAX_S,
        track.sleeper_spacing / speed / STEPS_PER_SLEEPER_PASSING,
        contact_period(system, law) / STEPS_PER_CONTACT_PERIOD,
    )
    if bound < DT_REFERENCE_S:
        return float(max(bound, DT_MIN_S))
    return float(LADDER_S[LADDER_S <= bound * (1 + 1e-12)].max())


def slope_change_per_step(positions: np.ndarray, levels: np.ndarray) -> float:
    """The largest change [rad] of the rail level's slope under a wheel between the step before and the step after
    any one step of a pass: ``positions`` and ``levels`` (n_steps + 1, n_axles) are each wheel's position [m] and
    the rail level under it [m] at each step. A kink within a step counts whole wherever in the step it lies; a
    smooth level of curvature z'' gives about 2 · z'' · the step's length. Steps where a wheel does not move (at
    the end of the track) have no slope and are left out."""
    dx = np.diff(np.asarray(positions, dtype=float), axis=0)
    dz = np.diff(np.asarray(levels, dtype=float), axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        slope = np.where(dx > 0.0, dz / dx, np.nan)
    if len(slope) < 3:
        return 0.0
    change = np.abs(slope[2:] - slope[:-2])
    return float(np.nanmax(change)) if np.isfinite(change).any() else 0.0
