"""Static window ends (``window_ends="static"``): the track beyond each end of the moving window carries its static
stiffness and its damping, condensed onto the end node, and the bays the window takes in start as the static
extension of its end.

Checked from the closed form up: the condensed stiffness, damping and extension are the dense Schur complement,
Tᵀ C T with T = −K_aa⁻¹ K_ab, and T; the static start with static ends is the whole track's static deflection at
any margin (clamped ends are stiffer); where the window covers the track nothing changes; and at the margin
recommended for static ends, 3 decay lengths, a pass stays within the fast path's 1 % of the whole-track model
across the soft/stiff sweep."""

from __future__ import annotations

import numpy as np
import pytest

from trackenv.physics import dynamics
from trackenv.physics.dynamics import simulate_pass, simulate_passes, window_margin
from trackenv.physics.track import PER_SLEEPER_FIELDS, Track
from trackenv.physics.vehicle import Wheelset
from trackenv.physics.window_ends import outside_damping, outside_stiffness, outside_transfer, static_ends

V80 = 80 / 3.6
LOADED = Wheelset(mass=1800.0, static_load=100e3)
STATIC_ENDS_DECAY_LENGTHS = 3.0  # the margin recommended for static ends (experiments/physics_window_ends.py)
TOLERANCE = 0.01  # the fast path's tolerance against the whole track (tests/physics/test_dynamics.py)


def varied_track(elements_per_bay: int = 2) -> Track:
    """A short track whose supports change from sleeper to sleeper: a voided sleeper, a soft stretch, graded pads."""
    seed = Track.seed(elements_per_bay=elements_per_bay)
    t = seed.replace(**{f: getattr(seed, f)[:24] for f in PER_SLEEPER_FIELDS})
    t = t.with_voided_sleeper(6).scaled(ballast_stiffness=0.3, from_sleeper=15)
    return t.replace(pad_stiffness=np.linspace(1e8, 5e8, 24), pad_damping=np.linspace(1e4, 5e4, 24))


@pytest.mark.parametrize("elements_per_bay", [2, 3])
def test_condensed_stiffness_and_extension_are_the_dense_schur_complement(elements_per_bay):
    t = varied_track(elements_per_bay)
    _, c_dense, k_dense = (m.toarray() for m in t.matrices())
    lay, n = t.dof_layout, t.n_dof
    stiffness = outside_stiffness(t.banded_matrices()[2], lay)
    damping = outside_damping(t)
    transfer = outside_transfer(t.banded_matrices()[2], lay)
    bay_dofs = int(lay.sleeper[1] - lay.sleeper[0])
    for s in (0, 1, 2, 5, 6, 7, 14, 15, 16, 21, 22, 23):  # the ends, around the voided sleeper and the step
        w = int(lay.node_w[lay.sleeper_node[s]])
        node = [w, w + 1]
        for outside, columns in ((np.arange(0, w), slice(0, 3)), (np.arange(w + 3, n), slice(3, 6))):
            schur, guyan = np.zeros((2, 2)), np.zeros((2, 2))  # the window reaches the track's end: nothing beyond
            if outside.size:
                shape = -np.linalg.solve(k_dense[np.ix_(outside, outside)], k_dense[np.ix_(outside, node)])
                schur = k_dense[np.ix_(node, outside)] @ shape
                guyan = shape.T @ c_dense[np.ix_(outside, outside)] @ shape
            np.testing.assert_allclose(stiffness[s, columns], [schur[0, 0], schur[1, 0], schur[1, 1]],
                                       rtol=0, atol=1e-12 * np.abs(stiffness).max())
            np.testing.assert_allclose(damping[s, columns], [guyan[0, 0], guyan[1, 0], guyan[1, 1]],
                                       rtol=0, atol=1e-12 * np.abs(damping).max())
            assert schur[0, 0] < 0 or not outside.size  # softer than a clamped end
        beyond = np.arange(w + 3, n)
        if beyond.size:
            extension = -np.linalg.solve(k_dense[np.ix_(beyond, beyond)], k_dense[np.ix_(beyond, node)])[:bay_dofs]
            np.testing.assert_allclose(transfer[s], extension, rtol=0, atol=1e-12)
        else:
            assert not transfer[s].any()


@pytest.mark.parametrize("elements_per_bay", [2, 3])
def test_static_ends_of_a_batch_are_each_tracks_own_bit_for_bit(elements_per_bay):
    """The batch's ends (every step vectorised over its tracks) are, track by track, the outside's stiffness,
    damping and extension that each track has alone, bit for bit: the tracks differ in every support property."""
    base = varied_track(elements_per_bay)
    rng = np.random.default_rng(5)
    tracks = [base.replace(**{f: getattr(base, f) * rng.uniform(0.3, 3.0, base.n_sleepers) for f in PER_SLEEPER_FIELDS})
              for _ in range(3)] + [base]
    ends = static_ends(tracks, np.stack([t.banded_matrices()[2] for t in tracks]))
    lay = base.dof_layout
    for row, t in zip(ends, tracks, strict=True):
        k = t.banded_matrices()[2]
        alone = np.concatenate([outside_stiffness(k, lay), outside_damping(t),
                                outside_transfer(k, lay).reshape(t.n_sleepers, -1)], axis=1)
        np.testing.assert_array_equal(row, alone)
    assert not np.array_equal(ends[0], ends[1])


def test_static_ends_give_the_whole_tracks_static_deflection_at_any_margin():
    """The static start solves the window with the outside condensed onto its ends: exact statics."""
    t = Track.realistic(40.0)
    full = simulate_pass(t, LOADED, V80, window_bays=None, x_start=20.0, x_end=20.5)
    for margin in (2, 3):
        static = simulate_pass(t, LOADED, V80, window_bays=margin, window_ends="static", x_start=20.0, x_end=20.5)
        clamped = simulate_pass(t, LOADED, V80, window_bays=margin, x_start=20.0, x_end=20.5)
        w0 = full.rail_displacement[0, 0]
        assert static.rail_displacement[0, 0] == pytest.approx(w0, rel=1e-9)
        assert abs(clamped.rail_displacement[0, 0] / w0 - 1) > 1e-3  # clamped ends are stiffer


def test_static_ends_change_nothing_where_the_window_covers_the_track():
    t = varied_track()
    for window_bays in (None, 60):
        rest = simulate_pass(t, LOADED, V80, window_bays=window_bays, x_start=3.0, x_end=12.0)
        static = simulate_pass(t, LOADED, V80, window_bays=window_bays, window_ends="static", x_start=3.0, x_end=12.0)
        np.testing.assert_array_equal(static.contact_force, rest.contact_force)
        np.testing.assert_array_equal(static.ballast_force, rest.ballast_force)


SWEEP = {
    "ballast_1e+07": Track.seed().replace(ballast_stiffness=np.full(51, 1e7)),
    "ballast_1e+09": Track.seed().replace(ballast_stiffness=np.full(51, 1e9)),
    "pad_1e+07": Track.seed().replace(pad_stiffness=np.full(51, 1e7)),
    "voided_sleeper": Track.seed().with_voided_sleeper(25, residual_support=0.05),
    "transition_soft_x4": Track.seed().scaled(ballast_stiffness=0.25, from_sleeper=25),
    "ballast_1e+07_60m": Track.realistic(60.0).replace(ballast_stiffness=np.full(101, 1e7)),
}


@pytest.mark.parametrize("name", SWEEP)
def test_static_ends_keep_the_fast_paths_tolerance_with_a_shorter_window(name):
    """At 3 decay lengths (6.5 with clamped ends), per-sleeper peak forces, the contact force, rail and wheel
    displacement over the evaluated track (every axle 8 sleepers or more from the rail's free ends, past the
    start's transient) are within 1 % of the whole track; clamped ends at the same margin are not everywhere."""
    t = SWEEP[name]
    margin = window_margin(t, STATIC_ENDS_DECAY_LENGTHS)
    today = window_margin(t)
    assert margin is not None and (today is None or margin < today)  # a shorter window than today's default
    full = simulate_pass(t, LOADED, V80, window_bays=None)
    static = simulate_pass(t, LOADED, V80, window_bays=margin, window_ends="static")
    assert evaluated_error(static, full, t) < TOLERANCE
    if name in ("ballast_1e+07", "pad_1e+07", "ballast_1e+07_60m"):
        assert evaluated_error(simulate_pass(t, LOADED, V80, window_bays=margin), full, t) > TOLERANCE


def evaluated_error(res, ref, track: Track, keep_out: int = 8) -> float:
    """The largest error over the evaluated track: contact force / static load, rail and wheel displacement /
    static deflection while every axle is ``keep_out`` sleepers or more from the ends; peak ballast forces of the
    sleepers there / the largest; the peak contact force."""
    x, s = res.wheel_position, track.sleeper_spacing
    on = (x.min(axis=1) >= keep_out * s) & (x.max(axis=1) <= track.length - keep_out * s)
    ev = slice(keep_out, track.n_sleepers - keep_out)
    w0, p0 = abs(ref.rail_displacement[0, 0]), res.static_wheel_load[0]
    return max(
        np.max(np.abs(res.contact_force - ref.contact_force)[on]) / p0,
        np.max(np.abs(res.rail_displacement - ref.rail_displacement)[on]) / w0,
        np.max(np.abs(res.wheel_displacement - ref.wheel_displacement)[on]) / w0,
        np.max(np.abs(res.ballast_force - ref.ballast_force)[ev]) / ref.ballast_force[ev].max(),
        abs(res.max_contact_force / ref.max_contact_force - 1),
    )


def test_a_rows_result_does_not_depend_on_its_batch_with_static_ends():
    tracks = [Track.seed(), SWEEP["voided_sleeper"], SWEEP["transition_soft_x4"]]
    kw = dict(window_bays=4, window_ends="static", x_start=4.0, x_end=20.0)
    batch = simulate_passes(tracks, LOADED, V80, **kw)
    for t, res in zip(tracks, batch):
        alone = simulate_pass(t, LOADED, V80, **kw)
        np.testing.assert_array_equal(res.contact_force, alone.contact_force)
        np.testing.assert_array_equal(res.ballast_force, alone.ballast_force)


def test_kept_window_factors_are_kept_apart_by_ends():
    """A one-row pass keeps its window factors for the next pass over its track: clamped and static ends keep
    their own (a static pass after a clamped one is the static pass of a fresh process)."""
    t = Track.realistic(30.0)
    kw = dict(window_bays=4, x_start=3.0, x_end=20.0)
    dynamics._kept_factors.cache_clear()
    first = simulate_pass(t, LOADED, V80, window_ends="static", **kw)
    simulate_pass(t, LOADED, V80, **kw)
    again = simulate_pass(t, LOADED, V80, window_ends="static", **kw)
    np.testing.assert_array_equal(again.contact_force, first.contact_force)
    assert not np.array_equal(simulate_pass(t, LOADED, V80, **kw).contact_force, first.contact_force)


def test_steady_start_with_static_ends_keeps_its_own_states():
    t = Track.realistic(30.0)
    kw = dict(window_bays=4, start="steady")
    static = simulate_pass(t, LOADED, V80, window_ends="static", **kw)
    rest = simulate_pass(t, LOADED, V80, **kw)
    keys = [k for k in dynamics._STEADY_STATES if k[-1] == "static"]
    assert keys and any(k[-1] == "rest" for k in dynamics._STEADY_STATES)
    assert not np.array_equal(static.contact_force, rest.contact_force)


def test_window_ends_are_validated():
    t = Track.seed()
    with pytest.raises(ValueError, match="window_ends must be one of"):
        simulate_pass(t, LOADED, V80, window_ends="absorbing")
    with pytest.raises(ValueError, match="window_ends='static' needs backend='numba'"):
        simulate_pass(t, LOADED, V80, window_ends="static", backend="torch")
    with pytest.raises(ValueError, match="decay_lengths"):
        window_margin(t, 0.1)
