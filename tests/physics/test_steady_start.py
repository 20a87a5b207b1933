"""The steady start (``start="steady"``): a pass that starts in the periodic steady state of its track's entry
gives the peak forces of a long approach from rest, with a short approach.

The yardstick is the converged approach: the evaluated track behind 40 sleepers of approach (copies of its first
sleeper at its first sleeper's level, as the degradation loop builds its model track), the pass starting there in
static equilibrium (or from rest, for that case). The steady start runs the same evaluated track behind an
approach just long enough for its windows and 3 bays of lead (``steady_approach_sleepers``). Per-sleeper peak
forces and the peak contact force over the evaluated track agree within ``TOLERANCE`` on the short-wave matrix of
the time-step contract and on line-like segments (ballast varying from sleeper to sleeper, a transition, a
switch's stiff patch, a wet spot, a voided sleeper and a transition just after the start)."""

from __future__ import annotations

import math
from functools import partial

import numpy as np
import pytest

from trackenv.physics import dynamics
from trackenv.physics.dynamics import simulate_pass, simulate_passes, steady_approach_sleepers, window_margin
from trackenv.physics.geometry import german_psd, synthesize_profile
from trackenv.physics.track import Track
from trackenv.physics.vehicle import Car, Wheelset

TOLERANCE = 0.002  # relative, the converged start's contract
REFERENCE_APPROACH = 40  # sleepers of approach of the yardstick
EXIT_SLEEPERS = 10  # after the evaluated track, in both

GRAVITY = 9.81
WHEEL_20T = Wheelset(mass=1800.0, static_load=20e3 * GRAVITY / 2 - 900.0 * GRAVITY)
FREIGHT_25T = Wheelset(mass=1400.0, static_load=25e3 * GRAVITY / 2 - 700.0 * GRAVITY)
LOADED = Wheelset(mass=1800.0, static_load=100e3)
V100, V200, V80 = 100 / 3.6, 200 / 3.6, 80 / 3.6
TRACK = Track.realistic(30.0)
N = TRACK.n_sleepers
PSD = synthesize_profile(TRACK.sleeper_positions, partial(german_psd, quality="low"), np.random.default_rng(3))


def dip(x, x0=14.0, depth=2e-3, length=1.0):
    """A 1 m cosine dip of ``depth`` [m] (downward positive)."""
    s = (np.asarray(x, dtype=float) - x0) / length
    return np.where((s >= 0) & (s <= 1), 0.5 * depth * (1 - np.cos(2 * np.pi * s)), 0.0)


def _ballast_field(seed: int) -> np.ndarray:
    """A line segment's ballast stiffness factors: lognormal (cv 0.15), correlated over ~3 sleepers."""
    rng = np.random.default_rng(seed)
    z = np.convolve(rng.standard_normal(N + 12), np.exp(-0.5 * (np.arange(-6, 7) / 3.0) ** 2), mode="valid")
    z /= z.std()
    return np.exp(0.15 * z - 0.15**2 / 2)


def _segment(factor: np.ndarray) -> Track:
    return TRACK.replace(ballast_stiffness=TRACK.ballast_stiffness * factor)


FIELD = _ballast_field(5)
MID = N // 2
WET = np.where(np.abs(np.arange(N) - 8) <= 5, 3e-3 * np.cos(np.pi * (np.arange(N) - 8) / 12) ** 2, 0.0)
LEVEL = 1.5 * np.abs(PSD)

# name: (evaluated track, vehicle, speed [m/s], irregularity, options) on the evaluated track
MATRIX = {
    "psd_100": (TRACK, WHEEL_20T, V100, PSD, {}),
    "tamping_step": (TRACK, WHEEL_20T, V100, np.where(np.arange(N) >= 25, 2e-3, 0.0), {}),
    "voided_sleeper": (TRACK.with_voided_sleeper(25, residual_support=0.05), WHEEL_20T, V100, PSD, {}),
    "transition_x4": (TRACK.scaled(ballast_stiffness=4.0, from_sleeper=25), WHEEL_20T, V100, PSD, {}),
    "dip_1m": (TRACK, WHEEL_20T, V100, dip, {}),
    "psd_200": (TRACK, WHEEL_20T, V200, PSD, {}),
    "freight_car": (Track.realistic(40.0), Car.freight_wagon(), V100, None, {}),
    "from_rest": (Track.seed(), LOADED, V80, None, {"start": "rest"}),
    "settled_supports": (TRACK, WHEEL_20T, V100, None, {"support_settlement": np.abs(PSD)}),
}
LINE = {  # the line's segments: its two wheelsets at 100 km/h, dt auto, the level as settled supports
    "plain": (_segment(FIELD), WHEEL_20T, V100, None, {"support_settlement": LEVEL}),
    "plain_freight": (_segment(FIELD), FREIGHT_25T, V100, None, {"support_settlement": LEVEL}),
    "transition": (_segment(FIELD * np.where(np.arange(N) >= MID, 3.0, 1.0)), FREIGHT_25T, V100, None,
                   {"support_settlement": LEVEL}),
    "switch_patch": (_segment(FIELD * np.where(np.abs(np.arange(N) - MID) <= 2, 2.0, 1.0)), WHEEL_20T, V100, None,
                     {"support_settlement": LEVEL}),
    "wet_spot_at_start": (_segment(FIELD), FREIGHT_25T, V100, None, {"support_settlement": LEVEL + WET}),
    "voided_sleeper_at_start": (_segment(FIELD).with_voided_sleeper(2, residual_support=0.05), WHEEL_20T, V100,
                                None, {"support_settlement": LEVEL}),
    "transition_at_start": (_segment(FIELD * np.where(np.arange(N) >= 3, 3.0, 1.0)), FREIGHT_25T, V100, None,
                            {"support_settlement": LEVEL}),
}
CASES = {**MATRIX, **LINE}


def held(irregularity, track: Track, before: int, after: int):
    """An irregularity of ``track`` on the model track with ``before`` and ``after`` sleepers added: per-sleeper
    profiles and settled supports hold their end values, a callable z(x) is shifted and holds its ends."""
    if irregularity is None:
        return None
    if callable(irregularity):
        offset = before * track.sleeper_spacing
        return lambda x: irregularity(np.clip(np.asarray(x) - offset, 0.0, track.length))
    p = np.asarray(irregularity)
    return np.concatenate([np.full(before, p[0]), p, np.full(after, p[-1])])


def run_case(case, approach: int, start: str, dt="auto", **extra):
    """One case behind ``approach`` sleepers: (sleeper forces, bay contact peaks) of the evaluated track."""
    track, vehicle, speed, irr, options = case
    options = dict(options, **extra)
    model = track.extended(approach, EXIT_SLEEPERS)
    if "support_settlement" in options:
        options["support_settlement"] = held(options["support_settlement"], track, approach, EXIT_SLEEPERS)
    if options.get("start", "static") != "rest" or start == "steady":
        options["start"] = start
    res = simulate_pass(model, vehicle, speed, held(irr, track, approach, EXIT_SLEEPERS), dt=dt, **options)
    ev = slice(approach, approach + track.n_sleepers)
    return res.sleeper_force[ev], res.contact_force_profile()[ev], res


def errors(case, lead_bays: int = 3, dt="auto") -> tuple[float, float]:
    """Largest relative error of the evaluated per-sleeper peak forces (floored at a tenth of the largest) and of
    the peak contact force over the evaluated track, steady start against the 40-sleeper approach."""
    track, vehicle = case[0], case[1]
    span_bays = math.ceil(dynamics._vehicle_system(vehicle).span / track.sleeper_spacing)
    f_ref, c_ref, _ = run_case(case, REFERENCE_APPROACH + span_bays, "static", dt)
    f, c, _ = run_case(case, steady_approach_sleepers(track, vehicle, lead_bays), "steady", dt)
    sleeper = np.max(np.abs(f - f_ref) / np.maximum(np.abs(f_ref), 0.1 * f_ref.max()))
    return float(sleeper), abs(c.max() / c_ref.max() - 1)


@pytest.mark.parametrize("name", CASES)
def test_steady_start_matches_a_long_approach(name):
    sleeper, contact = errors(CASES[name])
    assert sleeper <= TOLERANCE, f"{name}: sleeper forces {100 * sleeper:.3f} % off"
    assert contact <= TOLERANCE, f"{name}: contact peak {100 * contact:.3f} % off"


def test_the_short_approach_from_static_equilibrium_is_not_converged():
    """What the steady start is for: 10 sleepers of approach from static equilibrium are more than the tolerance
    off on the first evaluated sleepers of a plain segment."""
    case = LINE["plain_freight"]
    f_ref, _, _ = run_case(case, REFERENCE_APPROACH, "static")
    f10, _, _ = run_case(case, 10, "static")
    assert np.max(np.abs(f10 - f_ref) / f_ref)[()] > TOLERANCE


def test_steady_state_is_periodic():
    """On a uniform track the steady start's sleeper forces repeat from sleeper to sleeper from the first one the
    axle passes (the start is the periodic state), where the static start's ring down."""
    track = Track.realistic(30.0)
    steady = simulate_pass(track, WHEEL_20T, V100, start="steady", dt="auto", x_end=20.0)
    margin = window_margin(track)
    first = margin + 3  # the first sleeper whose peak the axle passes after the start
    forces = steady.sleeper_force[first : first + 15]
    assert np.ptp(forces) / forces.mean() < 2e-4
    static = simulate_pass(track, WHEEL_20T, V100, start="static", x_start=steady.wheel_position[0, 0], dt="auto",
                           x_end=20.0)
    forces = static.sleeper_force[first : first + 15]
    assert np.ptp(forces) / forces.mean() > 5 * 2e-4


def test_steady_states_are_kept_and_shared_by_rows_with_one_entry(monkeypatch):
    """A steady state is computed once per entry, vehicle, speed, dt and window; rows of a batch with the same
    entry share it, a row's result does not depend on its batch, and a later pass reads it back."""
    dynamics._STEADY_STATES.clear()
    runs = []
    integrate = dynamics._integrate_steady
    monkeypatch.setattr(dynamics, "_integrate_steady", lambda b, t: runs.append(len(t)) or integrate(b, t))
    a, b = _segment(FIELD), _segment(FIELD).scaled(ballast_stiffness=1.5)
    kw = dict(start="steady", dt="auto", x_end=15.0, window_bays=7)
    batch = simulate_passes([a, b, a], WHEEL_20T, V100, **kw)
    assert runs == [2]  # two entries, one batch
    alone = simulate_pass(b, WHEEL_20T, V100, **kw)
    assert runs == [2]  # kept
    np.testing.assert_array_equal(alone.contact_force, batch[1].contact_force)
    np.testing.assert_array_equal(batch[0].sleeper_force, batch[2].sleeper_force)
    simulate_pass(a, WHEEL_20T, V80, **kw)
    assert runs == [2, 1]  # another speed: its own


def test_steady_start_refuses_windows_outside_the_track():
    track = Track.realistic(30.0)
    with pytest.raises(ValueError, match="steady"):
        simulate_pass(track, WHEEL_20T, V100, start="steady", x_start=1.0)
    with pytest.raises(ValueError, match="steady"):
        simulate_pass(track, WHEEL_20T, V100, start="steady", window_bays=None)
    with pytest.raises(ValueError, match="start"):
        simulate_pass(track, WHEEL_20T, V100, start="periodic")
