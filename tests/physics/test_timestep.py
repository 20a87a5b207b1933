"""The accuracy contract of dt="auto" (trackenv.physics.timestep): on a matrix of cases with short-wave features
the auto step keeps the per-sleeper peak forces and the peak contact force within 0.5 % of dt = 1e-4 s, and one
set of dt bounds holds in every layer."""

from __future__ import annotations

from functools import partial

import numpy as np
import pytest

import trackenv as te
from trackenv.envs.line_config import LineConfig
from trackenv.physics.dynamics import simulate_pass
from trackenv.physics.geometry import german_psd, synthesize_profile
from trackenv.physics.timestep import (
    CONTRACT_TOLERANCE,
    DT_MAX_S,
    DT_REFERENCE_S,
    LADDER_S,
    MAX_SLOPE_CHANGE_PER_STEP,
    auto_time_step,
    slope_change_per_step,
)
from trackenv.physics.track import Track
from trackenv.physics.vehicle import Car, Wheelset

GRAVITY = 9.81
WHEEL_20T = Wheelset(mass=1800.0, static_load=20e3 * GRAVITY / 2 - 900.0 * GRAVITY)  # the env's default
LOADED = Wheelset(mass=1800.0, static_load=100e3)
TRACK = Track.realistic(30.0)
PSD = synthesize_profile(TRACK.sleeper_positions, partial(german_psd, quality="low"), np.random.default_rng(3))
TAMPING_STEP = np.where(np.arange(TRACK.n_sleepers) >= 25, 2e-3, 0.0)  # a fresh 2 mm step at a section end


def dip(x, x0=14.0, depth=2e-3, length=1.0):
    """A 1 m cosine dip of ``depth`` [m] (downward positive)."""
    s = (np.asarray(x, dtype=float) - x0) / length
    return np.where((s >= 0) & (s <= 1), 0.5 * depth * (1 - np.cos(2 * np.pi * s)), 0.0)


# name: (track, vehicle, speed [m/s], irregularity, options)
MATRIX = {
    "psd_100": (TRACK, WHEEL_20T, 100 / 3.6, PSD, {}),
    "tamping_step": (TRACK, WHEEL_20T, 100 / 3.6, TAMPING_STEP, {}),
    "voided_sleeper": (TRACK.with_voided_sleeper(25, residual_support=0.05), WHEEL_20T, 100 / 3.6, PSD, {}),
    "transition_x4": (TRACK.scaled(ballast_stiffness=4.0, from_sleeper=25), WHEEL_20T, 100 / 3.6, PSD, {}),
    "dip_1m": (TRACK, WHEEL_20T, 100 / 3.6, dip, {}),
    "psd_200": (TRACK, WHEEL_20T, 200 / 3.6, PSD, {}),
    "freight_car": (Track.realistic(40.0), Car.freight_wagon(), 100 / 3.6, None, {}),
    "from_rest": (Track.seed(), LOADED, 80 / 3.6, None, {"start": "rest"}),
    "settled_supports": (TRACK, WHEEL_20T, 100 / 3.6, None, {"support_settlement": np.abs(PSD)}),
}


def errors(res, ref) -> tuple[float, float]:
    """Largest relative error of the peak sleeper forces (each against its own reference value, floored at a
    tenth of the largest, sleepers between the two end sleepers) and of the peak contact force."""
    f, g = res.sleeper_force[1:-1], ref.sleeper_force[1:-1]
    sleeper = np.max(np.abs(f - g) / np.maximum(g, 0.1 * g.max()))
    return float(sleeper), abs(res.max_contact_force / ref.max_contact_force - 1)


@pytest.mark.parametrize("name", MATRIX)
def test_auto_step_keeps_peak_forces_within_contract(name):
    track, vehicle, speed, irr, opts = MATRIX[name]
    auto = simulate_pass(track, vehicle, speed, irr, dt="auto", **opts)
    ref = simulate_pass(track, vehicle, speed, irr, dt=DT_REFERENCE_S, **opts)
    assert auto.dt > DT_REFERENCE_S or np.any(auto.contact_force[1:] <= 0)  # the contract buys time
    sleeper, contact = errors(auto, ref)
    assert sleeper <= CONTRACT_TOLERANCE, f"{name}: sleeper forces {100 * sleeper:.2f} % off at dt={auto.dt:g}"
    assert contact <= CONTRACT_TOLERANCE, f"{name}: contact force {100 * contact:.2f} % off at dt={auto.dt:g}"


def test_loss_of_contact_falls_back_to_reference_step():
    """A 2 mm, 1 m dip at 200 km/h throws the wheel off the rail; the impact's peak is not within the contract
    at any coarser step, so that row runs at the reference step (and only that row)."""
    with pytest.warns(te.OverloadWarning, match="row 0 of 2:"):  # (the impact: the batch names its row)
        both = te.simulate_passes(TRACK, WHEEL_20T, 200 / 3.6, [dip, np.zeros(TRACK.n_sleepers)], dt="auto")
    assert both[0].dt == DT_REFERENCE_S and both[1].dt > DT_REFERENCE_S
    ref = simulate_pass(TRACK, WHEEL_20T, 200 / 3.6, dip, on_overload="ignore")
    np.testing.assert_array_equal(both[0].contact_force, ref.contact_force)


def vee(x, x0=14.3, change=4e-3, half_length=0.5):
    """A V-shaped dip (a dipped joint) whose slope changes by ``change`` [rad] at its bottom (half of it at each
    end), ``half_length`` [m] each side."""
    return np.clip(change / 2 * (half_length - np.abs(np.asarray(x, dtype=float) - x0)), 0.0, None)


def test_a_kink_in_the_rail_falls_back_to_reference_step():
    """A dipped joint whose slope changes by 4 mrad rings the wheel on the rail faster than the auto step
    resolves (its contact peak 1.3 % off at 4e-4 s, 100 km/h): that row runs at the reference step and gives
    its results, the smooth rows beside it keep the auto step (a dip given as a smooth function, and the V given as
    an array: a spline, which cannot kink, is not checked), and a step the caller chose is kept."""
    sampled = vee(TRACK.sleeper_positions)  # the same dip as an array: a cubic spline through it, not checked
    both = te.simulate_passes(TRACK, WHEEL_20T, 100 / 3.6, [vee, dip, sampled], dt="auto")
    assert both[0].dt == DT_REFERENCE_S and both[1].dt > DT_REFERENCE_S and both[2].dt > DT_REFERENCE_S
    ref = simulate_pass(TRACK, WHEEL_20T, 100 / 3.6, vee, dt=DT_REFERENCE_S)
    np.testing.assert_array_equal(both[0].contact_force, ref.contact_force)
    coarse = simulate_pass(TRACK, WHEEL_20T, 100 / 3.6, vee, dt=4e-4)
    assert coarse.dt == 4e-4  # what the rule avoids:
    assert abs(coarse.max_contact_force / ref.max_contact_force - 1) > CONTRACT_TOLERANCE


def test_slope_change_per_step_counts_a_kink_whole_and_a_curve_by_its_curvature():
    x = np.linspace(10.0, 12.0, 201)[:, None] + np.array([0.0, -0.013])  # two wheels, steps of 1 cm
    for x0 in (11.0, 11.003, 11.0071):  # wherever the kink lies within a step
        assert slope_change_per_step(x, vee(x, x0=x0, change=3e-3, half_length=5.0)) == pytest.approx(3e-3)
    assert slope_change_per_step(x, 0.01 * (x - 11.0) ** 2) == pytest.approx(2 * 0.02 * 0.01)  # 2 z'' h
    standing = np.vstack([x, np.repeat(x[-1:], 5, axis=0)])  # the wheels stop at the track's end: no kink there
    assert slope_change_per_step(standing, 1e-3 * standing) == pytest.approx(0.0, abs=1e-12)
    assert MAX_SLOPE_CHANGE_PER_STEP == pytest.approx(1e-3)


def test_auto_step_values():
    law = te.HertzContact()
    assert auto_time_step(TRACK, WHEEL_20T.system(), 100 / 3.6, law) == pytest.approx(4e-4)
    assert auto_time_step(TRACK, WHEEL_20T.system(), 200 / 3.6, law) == pytest.approx(2.5e-4)
    assert auto_time_step(TRACK, WHEEL_20T.system(), 20 / 3.6, law) == pytest.approx(4e-4)  # contact-bound
    assert auto_time_step(TRACK, WHEEL_20T.system(), 300 / 3.6, law) == pytest.approx(2e-4)
    assert set(LADDER_S) >= {DT_REFERENCE_S, DT_MAX_S}


def test_one_set_of_dt_bounds_in_every_layer():
    """A step the env accepts, the loop and the dynamics accept; one beyond the bound all three refuse."""
    ok, too_big = DT_MAX_S, DT_MAX_S * 1.01
    LineConfig(dt=ok)
    te.TrackDegradation(TRACK, WHEEL_20T, dt=ok)
    simulate_pass(TRACK, WHEEL_20T, 100 / 3.6, dt=ok, x_start=5.0, x_end=6.0)
    for make in (
        lambda: LineConfig(dt=too_big),
        lambda: te.TrackDegradation(TRACK, WHEEL_20T, dt=too_big),
        lambda: simulate_pass(TRACK, WHEEL_20T, 100 / 3.6, dt=too_big),
        lambda: LineConfig(dt="fine"),
    ):
        with pytest.raises(ValueError, match="dt"):
            make()
    assert LineConfig().dt == "auto" and te.TrackDegradation(TRACK, WHEEL_20T).pass_options["dt"] == "auto"
