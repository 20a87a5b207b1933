"""Tests of trackenv.physics.dynamics: a vehicle pass over the track, from the smooth-track statics to dips,
loss of contact, batching, and the moving-window fast path against the plain full-model reference
(tests/physics/reference.py)."""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pytest
import scipy.signal
from reference import load_vector, reference_pass

from trackenv.physics import dynamics
from trackenv.physics.contact import LinearContact
from trackenv.physics.dynamics import (
    OverloadError,
    OverloadWarning,
    batched_bands,
    newmark_constants,
    simulate_pass,
    simulate_passes,
    static_deflection,
)
from trackenv.physics.track import Track
from trackenv.physics.vehicle import Car, Train, Wheelset

V80 = 80 / 3.6  # [m/s]
V120 = 120 / 3.6
LOADED = Wheelset(mass=1800.0, static_load=100e3)
SLEEPER_PASSING = V80 / 0.6  # 37.04 Hz


def central(n: int) -> slice:
    """The middle half of a pass of n samples."""
    return slice(n // 4, 3 * n // 4)


def central_sleepers(track: Track) -> np.ndarray:
    x = track.sleeper_positions
    return (x > 0.25 * track.length) & (x < 0.75 * track.length)


def cosine_dip(depth: float, length: float = 1.0, x0: float = 15.0):
    """An isolated dip (downward positive): depth/2·(1 − cos 2π(x − x0)/length) on [x0, x0 + length]."""

    def z(x):
        s = (np.asarray(x, dtype=float) - x0) / length
        return np.where((s >= 0.0) & (s <= 1.0), 0.5 * depth * (1.0 - np.cos(2.0 * np.pi * s)), 0.0)

    return z


def amplitude_spectrum(signal: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Single-sided amplitude spectrum of the linearly detrended, Hann-windowed signal."""
    y = scipy.signal.detrend(signal)
    w = np.hanning(y.size)
    return np.fft.rfftfreq(y.size, dt), 2.0 * np.abs(np.fft.rfft(y * w)) / w.sum()


@functools.cache
def smooth_pass(dt: float = 1e-4, elements_per_bay: int = 2, window_bays: int | str | None = "auto"):
    return simulate_pass(Track.seed(elements_per_bay=elements_per_bay), LOADED, V80, dt=dt, window_bays=window_bays)


# ------------------------------------------------------------------------------------------ helpers
def test_newmark_constants_average_acceleration():
    dt = 1e-4
    a = newmark_constants(dt)
    np.testing.assert_allclose(a, [4 / dt**2, 2 / dt, 4 / dt, 1.0, 1.0, 0.0, dt / 2, dt / 2], rtol=1e-14)


def test_static_deflection_matches_full_sparse_solve():
    t = Track.seed()
    _, _, k = t.matrices()
    for x in (0.0, 7.13, 15.0, 15.3, 30.0):
        n = load_vector(t, x)
        u = np.linalg.solve(k.toarray(), 100e3 * n)
        assert static_deflection(t, 100e3, x) == pytest.approx(n @ u, rel=1e-10)


# ------------------------------------------------------------------------------------------ smooth track
def test_batched_bands_are_each_tracks_own_bands():
    """A batch's bands (the rail assembled once, every track's supports added at once) are, row by row, each
    track's own ``banded_matrices``, bit for bit: the tracks differ in every support property."""
    base = Track.realistic(30.0)
    rng = np.random.default_rng(3)
    names = ("pad_stiffness", "pad_damping", "sleeper_mass", "ballast_stiffness", "ballast_damping")
    tracks = [base.replace(**{n: getattr(base, n) * rng.uniform(0.5, 1.5, base.n_sleepers) for n in names})
              for _ in range(3)]
    tracks.append(base.with_voided_sleeper(7, residual_support=0.05))
    batch = batched_bands(tracks)
    for r, track in enumerate(tracks):
        for rows, own in zip(batch, track.banded_matrices(), strict=True):
            np.testing.assert_array_equal(rows[r], own)
    assert not np.array_equal(batch[2][0], batch[2][1])


def _kept_track_arrays() -> list[np.ndarray]:
    """Every array of the one batch of track arrays the set-up keeps."""
    (kept,) = dynamics._TRACK_ROWS.values()
    return [getattr(kept, field.name) for field in dataclasses.fields(kept)]


def test_a_batchs_kept_track_arrays_give_the_passes_of_a_fresh_process():
    """The set-up keeps a batch's track arrays in the kernel's layout, its tracks' window ends and margins: passes
    that find them kept are bit for bit those that build them, and the kernel leaves the kept arrays as they were."""
    base = Track.realistic(30.0)
    tracks = [base.scaled(ballast_stiffness=f) for f in (0.6, 1.0, 1.7)]
    level = 1e-3 * np.cos(np.arange(base.n_sleepers) * 0.9)
    kw = dict(window_ends="static", window_decay_lengths=3.0, support_settlement=level)

    def passes():
        return simulate_passes(tracks, LOADED, V80, **kw)

    dynamics._TRACK_ROWS.clear()
    dynamics._ROW_ARRAYS.clear()
    dynamics._STATIC_ENDS.clear()
    first = passes()
    kept = [x.copy() for x in _kept_track_arrays()]
    again = passes()
    for a, b in zip(first, again, strict=True):
        np.testing.assert_array_equal(a.contact_force, b.contact_force)
        np.testing.assert_array_equal(a.sleeper_force, b.sleeper_force)
    for before, now in zip(kept, _kept_track_arrays(), strict=True):
        np.testing.assert_array_equal(before, now)
    dynamics._TRACK_ROWS.clear()
    dynamics._ROW_ARRAYS.clear()
    dynamics._STATIC_ENDS.clear()
    fresh = passes()
    np.testing.assert_array_equal(fresh[2].contact_force, first[2].contact_force)


def test_a_batch_of_other_composition_assembles_kept_rows_bit_for_bit():
    """Each track's kernel rows are kept per track: a batch of another composition (a subset, in another order, as
    pass reuse leaves it) assembles its arrays from those kept, and its passes are bit for bit those of the same
    batch built afresh; the kept rows are read-only and the cache stays within its bound."""
    base = Track.realistic(30.0)
    tracks = [base.scaled(ballast_stiffness=f) for f in (0.6, 1.0, 1.7, 1.3)]
    level = 1e-3 * np.cos(np.arange(base.n_sleepers) * 0.9)
    kw = dict(window_ends="static", window_decay_lengths=3.0, support_settlement=level)
    simulate_passes(tracks, LOADED, V80, **kw)  # every track's rows kept
    subset = [tracks[3], tracks[0]]
    kept = simulate_passes(subset, LOADED, V80, **kw)
    assert all(not row.flags.writeable for row in dynamics._ROW_ARRAYS.values())
    assert len(dynamics._ROW_ARRAYS) <= dynamics._ROW_ARRAYS_CACHE_SIZE
    dynamics._TRACK_ROWS.clear()
    dynamics._ROW_ARRAYS.clear()
    dynamics._STATIC_ENDS.clear()
    fresh = simulate_passes(subset, LOADED, V80, **kw)
    for a, b in zip(kept, fresh, strict=True):
        for name in ("contact_force", "rail_displacement", "sleeper_force", "pad_plus_ballast_force"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


def test_result_shapes_and_time_grid():
    res = smooth_pass()
    t = Track.seed()
    n_steps = int(np.ceil(t.length / (V80 * 1e-4) - 1e-9))
    assert res.time.shape == (n_steps + 1,)
    np.testing.assert_allclose(res.time, 1e-4 * np.arange(n_steps + 1))
    for a in (
        res.contact_force,
        res.rail_displacement,
        res.wheel_displacement,
        res.irregularity,
        res.wheel_position,
    ):
        assert a.shape == (n_steps + 1, 1)
    np.testing.assert_allclose(res.wheel_position[:, 0], np.minimum(V80 * res.time, t.length))
    assert res.sleeper_force.shape == (51,)
    np.testing.assert_array_equal(res.sleeper_force, res.ballast_force)
    assert res.static_wheel_load[0] == pytest.approx(LOADED.wheel_load)
    assert res.max_contact_force == res.contact_force.max()
    assert res.contact_force_profile().shape == (51,)
    assert res.contact_force_profile().max() == pytest.approx(res.max_contact_force)


def test_contact_force_profile_is_the_peak_of_every_axle_over_each_bay():
    """The batch finds each row's bay peaks in the kernel's layout (PassResult.bay_contact_force); they are the
    maxima over every (time step, axle) whose wheel lies within ±s/2 of the sleeper, as computed here element by
    element, for every row of a batch of several chunks and a four-axle car; the same from the general path
    (positions given)."""
    t = Track.realistic(48.0)  # longer than the coach's span and its bogies' gap: every bay under some wheel
    rng = np.random.default_rng(3)
    irr = 1e-3 * rng.standard_normal((5, t.n_sleepers))
    for res in simulate_passes(t, Car.manchester_coach(), 30.0, irr, dt="auto", on_overload="ignore"):
        idx = np.clip(np.rint(res.wheel_position / t.sleeper_spacing).astype(int), 0, t.n_sleepers - 1)
        want = np.zeros(t.n_sleepers)
        for step, axle in np.ndindex(idx.shape):
            want[idx[step, axle]] = max(want[idx[step, axle]], res.contact_force[step, axle])
        np.testing.assert_array_equal(res.contact_force_profile(), want)
        np.testing.assert_array_equal(res.contact_force_profile(t.sleeper_positions), want)
        assert want.max() == res.max_contact_force


def test_smooth_mean_contact_force_is_static_load():
    res = smooth_pass()
    f = res.contact_force[central(res.time.size), 0]
    assert f.mean() == pytest.approx(LOADED.wheel_load, rel=0.01)
    assert f.min() > 0.97 * LOADED.wheel_load and f.max() < 1.03 * LOADED.wheel_load


def test_smooth_rail_deflection_is_static_deflection():
    t = Track.seed()
    res = smooth_pass()
    c = central(res.time.size)
    w = res.rail_displacement[c, 0]
    assert w.mean() == pytest.approx(t.winkler_deflection(LOADED.wheel_load), rel=0.05)
    # the quasi-static pass stays between the over-sleeper and mid-span static deflections (± 2 %)
    w_lo = static_deflection(t, LOADED.wheel_load, 15.0)
    w_hi = static_deflection(t, LOADED.wheel_load, 15.3)
    assert 0.98 * w_lo < w.min() and w.max() < 1.02 * w_hi


def test_smooth_sleeper_forces_share_the_load():
    """On a uniform track the peak ballast force under a passing wheel is its static share: the Winkler
    beam puts β·s/2 of the load on the sleeper under it (support reaction k_s·w0 out of P = 2 k_f w0/β)."""
    t = Track.seed()
    res = smooth_pass()
    f = res.sleeper_force[central_sleepers(t)]
    share = t.support_stiffness[0] * t.winkler_deflection(LOADED.wheel_load)
    assert np.ptp(f) < 1e-3 * f.mean()
    assert f.mean() == pytest.approx(share, rel=0.05)


def test_sleeper_passing_frequency_in_spectrum():
    f_sl = SLEEPER_PASSING
    for epb in (2, 4):
        res = smooth_pass(elements_per_bay=epb)
        freq, amp = amplitude_spectrum(res.contact_force[central(res.time.size), 0], res.dt)
        above = freq > 10.0
        i = int(np.argmin(np.abs(freq - f_sl)))
        # v/0.6 is a spectral peak standing far above the median amplitude
        assert amp[i] > amp[i - 1] and amp[i] > amp[i + 1]
        assert amp[i] > 5.0 * np.median(amp[above])
        assert abs(freq[i] - f_sl) < 1.5
    # with 4 elements per bay it is the largest peak above 10 Hz; with 2 the element-passing component at
    # 2·v/0.6 (74 Hz) is larger, a discretisation effect that shrinks as the mesh is refined
    assert abs(freq[np.argmax(np.where(above, amp, 0.0))] - f_sl) < 1.5


def test_smooth_pass_converges_in_dt():
    t = Track.seed()
    r1, r2 = smooth_pass(1e-4), smooth_pass(5e-5)
    p1 = r1.contact_force[central(r1.time.size), 0].max()
    p2 = r2.contact_force[central(r2.time.size), 0].max()
    assert abs(p2 / p1 - 1) < 0.01
    sel = central_sleepers(t)
    np.testing.assert_allclose(r2.sleeper_force[sel], r1.sleeper_force[sel], rtol=0.01)


def test_static_start_is_equilibrium():
    """Starting from statics, the first steps of the contact force stay near the static load (over a uniform
    stretch of track, away from the rail end)."""
    t = Track.seed()
    res = simulate_pass(t, LOADED, V80, x_start=10.0, x_end=12.0)
    assert res.contact_force[0, 0] == pytest.approx(LOADED.wheel_load, rel=1e-12)
    assert res.rail_displacement[0, 0] == pytest.approx(static_deflection(t, LOADED.wheel_load, 10.0), rel=1e-3)
    assert np.max(np.abs(res.contact_force[:, 0] / LOADED.wheel_load - 1)) < 0.02


def test_start_from_rest_settles_to_static_load():
    res = simulate_pass(Track.seed(), Wheelset.seed(), V80, start="rest")
    f = res.contact_force[:, 0]
    assert f[0] == 0.0
    assert f.max() > 1.2 * Wheelset.seed().wheel_load  # the wheel drops onto the track
    assert f[central(f.size)].mean() == pytest.approx(Wheelset.seed().wheel_load, rel=0.01)
    assert f.min() >= 0.0


def test_linear_contact_option():
    t = Track.seed()
    res = simulate_pass(t, LOADED, V80, contact=LinearContact(1.43e9), x_start=5.0, x_end=25.0)
    f = res.contact_force[:, 0]
    assert f.mean() == pytest.approx(LOADED.wheel_load, rel=0.01)
    assert res.wheel_displacement[0, 0] - res.rail_displacement[0, 0] == pytest.approx(
        LOADED.wheel_load / 1.43e9, rel=1e-9
    )


def test_pad_plus_ballast_measure():
    t = Track.seed()
    res = simulate_pass(t, LOADED, V80, sleeper_force_measure="pad_plus_ballast", x_start=5.0, x_end=25.0)
    np.testing.assert_array_equal(res.sleeper_force, res.pad_plus_ballast_force)
    sel = (t.sleeper_positions > 8) & (t.sleeper_positions < 22)
    assert np.all(res.pad_plus_ballast_force[sel] > res.ballast_force[sel])


# ------------------------------------------------------------------------------------------ fast vs plain
def assert_close_to_reference(res, ref, tol: float) -> dict:
    p0 = res.static_wheel_load
    d_force = np.max(np.abs(res.contact_force - ref.contact_force) / p0)
    w0 = np.abs(ref.rail_displacement[0])
    d_rail = np.max(np.abs(res.rail_displacement - ref.rail_displacement) / w0)
    d_sleeper = np.max(np.abs(res.ballast_force - ref.ballast_force)) / ref.ballast_force.max()
    d_wheel = np.max(np.abs(res.wheel_displacement - ref.wheel_displacement) / w0)
    diffs = {"force": d_force, "rail": d_rail, "sleeper": d_sleeper, "wheel": d_wheel}
    assert max(diffs.values()) < tol, diffs
    return diffs


@pytest.mark.slow
def test_fast_path_matches_reference_on_seed_pass():
    t = Track.seed()
    ref = reference_pass(t, LOADED, V80)
    np.testing.assert_allclose(ref.time, smooth_pass().time, rtol=0, atol=1e-15)
    # the whole-track window is the same model: agreement to round-off
    assert_close_to_reference(smooth_pass(window_bays=None), ref, 1e-8)
    # the default window: within 1 % on every output
    assert_close_to_reference(smooth_pass(), ref, 0.01)


@pytest.mark.slow
def test_fast_path_matches_reference_for_a_car():
    """Four axles in two windows (one per bogie), vector Newton on the contacts."""
    t = Track.realistic(40.0)
    car = Car.manchester_coach()
    ref = reference_pass(t, car, 100 / 3.6)
    assert_close_to_reference(simulate_pass(t, car, 100 / 3.6, window_bays=None), ref, 1e-8)
    assert_close_to_reference(simulate_pass(t, car, 100 / 3.6), ref, 0.01)


SOFT_AND_STIFF = {
    **{f"ballast_{k:.0e}": Track.seed().replace(ballast_stiffness=np.full(51, k)) for k in (1e6, 1e7, 3e7, 1e8, 1e9)},
    **{f"pad_{k:.0e}": Track.seed().replace(pad_stiffness=np.full(51, k)) for k in (1e6, 1e7, 1e8, 1e9)},
    "voided_sleeper": Track.seed().with_voided_sleeper(25, residual_support=0.05),
    "transition_soft_x4": Track.seed().scaled(ballast_stiffness=0.25, from_sleeper=25),
    "ballast_1e+07_60m": Track.realistic(60.0).replace(ballast_stiffness=np.full(101, 1e7)),
    "ballast_1e+06_60m": Track.realistic(60.0).replace(ballast_stiffness=np.full(101, 1e6)),
}


@pytest.mark.parametrize("name", SOFT_AND_STIFF)
def test_auto_window_follows_the_track_stiffness(name):
    """The default window is sized from the track's decay length: from 1e6 to 1e9 N/m pads and ballast, with a
    voided sleeper and a transition, it stays within the fast path's 1 % of the full model (a fixed 6-bay window
    gave 6 850 kN instead of 281 kN peak contact force on 1e6 N/m ballast)."""
    t = SOFT_AND_STIFF[name]
    full = simulate_pass(t, LOADED, V80, window_bays=None)
    assert_close_to_reference(simulate_pass(t, LOADED, V80), full, 0.01)


def test_auto_window_sizes():
    from trackenv.physics.dynamics import window_margin

    assert window_margin(Track.seed()) == 7  # stiff track: a small window
    assert window_margin(SOFT_AND_STIFF["ballast_1e+07_60m"]) == 13
    assert window_margin(SOFT_AND_STIFF["ballast_1e+06_60m"]) is None  # softer: the whole track moves
    # one voided sleeper widens the window by at most a bay, a soft transition by more
    assert window_margin(SOFT_AND_STIFF["voided_sleeper"]) <= 8 < window_margin(SOFT_AND_STIFF["transition_soft_x4"])


# ------------------------------------------------------------------------------------------ dips
def test_dip_raises_peak_force():
    t = Track.seed()
    smooth = smooth_pass()
    x = smooth.wheel_position[:, 0]
    near = (x > 10.0) & (x < 22.0)
    peak_smooth = smooth.contact_force[near, 0].max()
    dip = cosine_dip(1e-3)
    # the exact shape, and its samples at the rail nodes (natural cubic spline through them, which rings a
    # little before the dip, hence the looser check there)
    for irregularity, x_before, rtol in ((dip, 14.5, 1e-12), (dip(t.node_positions), 13.0, 1e-3)):
        res = simulate_pass(t, LOADED, V80, irregularity)
        assert res.contact_force[near, 0].max() > 1.05 * peak_smooth
        assert res.contact_force[near, 0].min() < 0.95 * smooth.contact_force[near, 0].min()
        assert res.contact_force.min() > 0.0
        # before the wheel reaches the dip nothing changes
        before = x < x_before
        np.testing.assert_allclose(res.contact_force[before], smooth.contact_force[before], rtol=rtol)


def test_dip_as_callable_and_as_node_profile_agree_on_the_rail_level():
    t = Track.seed(elements_per_bay=8)  # 7.5 cm nodes resolve the 1 m dip
    dip = cosine_dip(1e-3)
    r1 = simulate_pass(t, LOADED, V80, dip, x_start=12.0, x_end=18.0)
    r2 = simulate_pass(t, LOADED, V80, dip(t.node_positions), x_start=12.0, x_end=18.0)
    np.testing.assert_allclose(r1.irregularity, dip(r1.wheel_position), atol=1e-12)
    np.testing.assert_allclose(r2.irregularity, r1.irregularity, atol=2e-5)
    assert r2.max_contact_force == pytest.approx(r1.max_contact_force, rel=0.02)


def test_loss_of_contact_force_is_zero_never_negative():
    t = Track.seed()
    res = simulate_pass(t, LOADED, V120, cosine_dip(5e-3), x_start=10.0, x_end=25.0)
    f = res.contact_force[:, 0]
    x = res.wheel_position[:, 0]
    assert np.all(f >= 0.0)
    lost = f == 0.0
    assert lost.sum() >= 5
    assert np.all((x[lost] > 15.0) & (x[lost] < 16.5))  # only over the dip
    assert f[-1] > 0.0  # the wheel lands and stays on the rail
    assert f.max() > 1.5 * LOADED.wheel_load  # with an impact
    # while in the air the wheel is above the rail
    gap = res.wheel_displacement[lost, 0] - res.rail_displacement[lost, 0] - res.irregularity[lost, 0]
    assert np.all(gap <= 0.0)


def test_bare_wheelset_leaves_the_rail():
    """A 5 mm dip at 120 km/h throws a bare wheelset off the rail; its landing, 30 times its static load, is far
    beyond what track in service gives, so the pass warns (an impact study passes on_overload="ignore")."""
    with pytest.warns(OverloadWarning, match=r"row 0 of 1: peak contact force .* times the static wheel load"):
        res = simulate_pass(Track.seed(), Wheelset.seed(), V120, cosine_dip(5e-3), x_start=10.0, x_end=20.0)
    f = res.contact_force[:, 0]
    assert np.any(f == 0.0) and np.all(f >= 0.0)
    with pytest.raises(OverloadError, match="on_overload='ignore'"):
        simulate_pass(Track.seed(), Wheelset.seed(), V120, cosine_dip(5e-3), x_start=10.0, x_end=20.0,
                      on_overload="raise")
    again = simulate_pass(Track.seed(), Wheelset.seed(), V120, cosine_dip(5e-3), x_start=10.0, x_end=20.0,
                          on_overload="ignore")
    np.testing.assert_array_equal(again.contact_force, res.contact_force)


def test_a_car_on_a_track_barely_longer_than_itself_warns_of_the_unloaded_stretch():
    """A coach (axles up to 15.6 m apart) over the 30 m seed track by default: its leading axle runs 9.6 m, so no
    wheel crosses 12-18 m and a dip there changes nothing; the pass says so. On 72 m it does not."""
    import warnings

    with pytest.warns(dynamics.UnloadedTrackWarning, match=r"the pass leaves 12-18 m of the track under no wheel") \
            as caught:
        simulate_pass(Track.seed(), Car.zhai_coach(), 160 / 3.6)
    assert caught[0].filename == __file__  # the warning names the caller's line, not the library's
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        simulate_pass(Track.realistic(72.0), Car.zhai_coach(), 160 / 3.6)


def test_wrong_unit_stiffness_warns():
    """Pads and ballast given in kN/m where N/m is meant (1000 times too soft): the pass's contact force reaches
    3 times the static wheel load and the pass says to check the units; the same track in N/m stays near 1."""
    wheel = Wheelset(mass=1800.0, static_load=100e3)
    assert simulate_pass(Track.seed(), wheel, V80).max_contact_force < 1.5 * wheel.wheel_load
    soft = Track.seed().scaled(pad_stiffness=1e-3, ballast_stiffness=1e-3)
    with pytest.warns(OverloadWarning, match="Check the units") as caught:
        simulate_pass(soft, wheel, V80)
    assert caught[0].filename == __file__
    with pytest.raises(ValueError, match="on_overload"):
        simulate_pass(Track.seed(), wheel, V80, on_overload="quiet")


@pytest.mark.slow
def test_loss_of_contact_matches_reference():
    t = Track.seed()
    kw = dict(x_start=12.0, x_end=19.0)
    ref = reference_pass(t, LOADED, V120, cosine_dip(5e-3), **kw)
    res = simulate_pass(t, LOADED, V120, cosine_dip(5e-3), window_bays=None, on_overload="ignore", **kw)
    np.testing.assert_array_equal(res.contact_force == 0.0, ref.contact_force == 0.0)
    np.testing.assert_allclose(res.contact_force, ref.contact_force, rtol=0, atol=1e-8 * LOADED.wheel_load)


# ------------------------------------------------------------------------------------------ bad input
@pytest.mark.parametrize("speed", [0.0, -10.0, float("nan")])
def test_bad_speed(speed):
    with pytest.raises(ValueError, match="speed"):
        simulate_pass(Track.seed(), LOADED, speed)


def test_a_speed_beyond_ballasted_lines_warns_with_its_km_h():
    """120 given for 120 km/h is taken as 120 m/s = 432 km/h: a warning names both units; 300 km/h does not warn."""
    import warnings

    with pytest.warns(UserWarning, match=r"speed 120 m/s is 432 km/h, above the 350 km/h") as caught:
        simulate_pass(Track.seed(), LOADED, 120.0, x_start=5.0, x_end=6.0)
    assert caught[0].filename == __file__
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        simulate_pass(Track.seed(), LOADED, 300 / 3.6, x_start=5.0, x_end=6.0)


def test_dt_too_large_to_resolve_contact():
    with pytest.raises(ValueError, match="dt"):
        simulate_pass(Track.seed(), LOADED, V80, dt=1e-2)
    with pytest.raises(ValueError, match="dt"):
        simulate_pass(Track.seed(), LOADED, V80, dt=-1e-4)


@pytest.mark.parametrize("n", [10, 52, 100])
def test_irregularity_of_wrong_length(n):
    with pytest.raises(ValueError, match="irregularity"):
        simulate_pass(Track.seed(), LOADED, V80, np.zeros(n))


def test_irregularity_nan_or_bad_callable():
    z = np.zeros(51)
    z[3] = np.nan
    with pytest.raises(ValueError, match="irregularity"):
        simulate_pass(Track.seed(), LOADED, V80, z)
    with pytest.raises(ValueError, match="irregularity"):
        simulate_pass(Track.seed(), LOADED, V80, lambda x: np.zeros(3))


def test_vehicle_longer_than_track():
    with pytest.raises(ValueError, match="vehicle"):
        simulate_pass(Track.seed(), Train.of(Car.manchester_coach(), 2), V80)


def test_other_bad_options():
    t = Track.seed()
    with pytest.raises(ValueError, match="start"):
        simulate_pass(t, LOADED, V80, start="moving")
    with pytest.raises(ValueError, match="sleeper_force_measure"):
        simulate_pass(t, LOADED, V80, sleeper_force_measure="pad")
    with pytest.raises(ValueError, match="window_bays"):
        simulate_pass(t, LOADED, V80, window_bays=1)
    with pytest.raises(ValueError, match="x_end"):
        simulate_pass(t, LOADED, V80, x_start=10.0, x_end=5.0)
    with pytest.raises(ValueError, match="vehicle"):
        simulate_pass(t, "wheelset", V80)
    with pytest.raises(ValueError, match="contact"):
        simulate_pass(t, LOADED, V80, contact="hertz")


# ------------------------------------------------------------------------------------------ batches
def test_batch_of_irregularities_equals_single_passes():
    t = Track.seed()
    rng = np.random.default_rng(1)
    rows = [1e-3 * rng.standard_normal(51), cosine_dip(2e-3, x0=12.0)(t.sleeper_positions), np.zeros(51)]
    kw = dict(x_start=3.0, x_end=27.0, dt=1e-4)
    batch = simulate_passes(t, LOADED, V80, rows, **kw)
    assert len(batch) == 3
    for b, z in zip(batch, rows, strict=True):
        single = simulate_pass(t, LOADED, V80, z, **kw)
        for name in (
            "contact_force",
            "rail_displacement",
            "wheel_displacement",
            "sleeper_force",
            "pad_plus_ballast_force",
            "irregularity",
        ):
            got, want = getattr(b, name), getattr(single, name)
            np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-10 * np.abs(want).max(), err_msg=name)
    assert not np.allclose(batch[0].contact_force, batch[2].contact_force)


def test_batch_interpolates_its_profiles_together_as_one_row_at_a_time():
    """The rows' profiles are interpolated by one spline through all of them: each row's rail level and forces are
    bit for bit those of its pass alone, whatever else is in the batch (per-sleeper and per-node profiles, a
    callable, None, one profile object in two rows)."""
    t = Track.seed()
    rng = np.random.default_rng(7)
    sleeper_a, sleeper_b = 1e-3 * rng.standard_normal(t.n_sleepers), 1e-3 * rng.standard_normal(t.n_sleepers)
    node = 5e-4 * np.sin(t.node_positions)
    rows = [sleeper_a, None, node, cosine_dip(2e-3, x0=12.0), sleeper_b, sleeper_a]
    kw = dict(x_start=3.0, x_end=27.0, dt=1e-4)
    batch = simulate_passes(t, LOADED, V80, rows, **kw)
    for b, z in zip(batch, rows, strict=True):
        single = simulate_pass(t, LOADED, V80, z, **kw)
        for name in ("irregularity", "contact_force", "sleeper_force"):
            assert np.array_equal(getattr(b, name), getattr(single, name)), name
    assert np.array_equal(batch[0].contact_force, batch[5].contact_force)
    assert not np.array_equal(batch[0].contact_force, batch[4].contact_force)


def test_batch_of_tracks_with_different_ballast():
    seed = Track.seed()
    tracks = [seed, seed.scaled(ballast_stiffness=1.1, from_sleeper=40), seed.scaled(ballast_stiffness=0.5)]
    batch = simulate_passes(tracks, LOADED, V80)
    for b, t in zip(batch, tracks, strict=True):
        single = simulate_pass(t, LOADED, V80)
        np.testing.assert_allclose(b.contact_force, single.contact_force, rtol=1e-10)
        np.testing.assert_allclose(b.sleeper_force, single.sleeper_force, rtol=1e-10)
    c = central(batch[0].time.size)
    # the softer ballast: more deflection, as the Winkler beam says (w0 ∝ k_f^{-3/4})
    w_seed, w_soft = (b.rail_displacement[c, 0].mean() for b in (batch[0], batch[2]))
    assert w_soft / w_seed == pytest.approx(tracks[2].winkler_deflection(1.0) / seed.winkler_deflection(1.0), rel=0.03)
    # the stiffer ballast from sleeper 40 on takes more of the load there
    np.testing.assert_allclose(batch[1].sleeper_force[10:30], batch[0].sleeper_force[10:30], rtol=1e-9)
    assert np.all(batch[1].sleeper_force[42:48] > batch[0].sleeper_force[42:48])


def test_batch_of_mismatched_tracks_rejected():
    with pytest.raises(ValueError, match="tracks"):
        simulate_passes([Track.seed(), Track.realistic(30.0)], LOADED, V80)
    with pytest.raises(ValueError, match="irregularities"):
        simulate_passes([Track.seed()] * 2, LOADED, V80, [np.zeros(51)] * 3)


def test_multi_car_train_runs():
    t = Track.realistic(80.0)
    train = Train.of(Car.freight_wagon(), 2)
    res = simulate_pass(t, train, 100 / 3.6)
    assert res.contact_force.shape[1] == 8
    c = central(res.time.size)
    np.testing.assert_allclose(res.contact_force[c].mean(axis=0), res.static_wheel_load, rtol=0.02)
    assert np.all(res.contact_force >= 0.0)


def test_lockstep_rows_do_not_depend_on_batch_size_or_threads():
    """The kernel runs the rows of a batch in lockstep, cut into chunks over the threads: a row's result is
    bit-identical whatever batch it runs in, however the batch is cut and on however many threads. The rows'
    ballast and sleeper masses differ (the rail's mass band is shared by the rows, the mass diagonal is not)."""
    import numba

    t = Track.seed()
    rng = np.random.default_rng(7)
    rows = 5e-4 * rng.standard_normal((17, t.n_sleepers))
    tracks = [
        t.scaled(ballast_stiffness=f, sleeper_mass=g, from_sleeper=int(k))
        for f, g, k in zip(rng.uniform(0.5, 2.0, 17), rng.uniform(0.7, 1.5, 17), rng.integers(0, 20, 17))
    ]
    kw = dict(x_start=6.0, x_end=12.0, support_settlement=np.abs(rows), start="rest")
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one_thread = simulate_passes(tracks, LOADED, V80, rows, **kw)  # chunks of 16 rows
        eight = simulate_passes(  # one chunk of 8 rows
            tracks[:8], LOADED, V80, rows[:8], **{**kw, "support_settlement": kw["support_settlement"][:8]}
        )
    finally:
        numba.set_num_threads(threads)
    all_threads = simulate_passes(tracks, LOADED, V80, rows, **kw)
    five = simulate_passes(  # two chunks of 4 rows
        tracks[3:8], LOADED, V80, rows[3:8], **{**kw, "support_settlement": kw["support_settlement"][3:8]}
    )
    eleven = simulate_passes(  # two chunks of 6 rows
        tracks[3:14], LOADED, V80, rows[3:14], **{**kw, "support_settlement": kw["support_settlement"][3:14]}
    )
    for b in (0, 3, 7, 13, 16):
        single = simulate_pass(
            tracks[b], LOADED, V80, rows[b], **{**kw, "support_settlement": kw["support_settlement"][b]}
        )
        others = [one_thread[b], all_threads[b]] + ([five[b - 3]] if 3 <= b < 8 else []) + ([eight[b]] if b < 8 else [])
        others += [eleven[b - 3]] if 3 <= b < 14 else []
        for other in others:
            for name in ("contact_force", "rail_displacement", "wheel_displacement", "sleeper_force", "irregularity"):
                np.testing.assert_array_equal(getattr(other, name), getattr(single, name), err_msg=name)


@pytest.mark.parametrize("width", dynamics._kernel.WIDTHS)
def test_every_chunk_width_gives_each_rows_own_pass(width):
    """Each width the kernel is compiled for runs a batch of that many rows as one chunk (one thread) or as chunks
    of fewer rows (all threads), the last padded: every row is bit for bit its own pass run alone."""
    import numba

    t = Track.seed()
    rng = np.random.default_rng(width)
    rows = 5e-4 * rng.standard_normal((width, t.n_sleepers))
    tracks = [t.scaled(ballast_stiffness=f, from_sleeper=int(k))
              for f, k in zip(rng.uniform(0.5, 2.0, width), rng.integers(0, 20, width))]
    kw = dict(x_start=6.0, x_end=9.0, support_settlement=np.abs(rows), start="rest")
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        assert dynamics._chunking(width) == (1, width)
        one_chunk = simulate_passes(tracks, LOADED, V80, rows, **kw)
    finally:
        numba.set_num_threads(threads)
    spread = simulate_passes(tracks, LOADED, V80, rows, **kw)
    for b in range(width):
        single = simulate_pass(tracks[b], LOADED, V80, rows[b], **{**kw, "support_settlement": np.abs(rows[b])})
        for other in (one_chunk[b], spread[b]):
            for name in ("contact_force", "rail_displacement", "wheel_displacement", "sleeper_force"):
                np.testing.assert_array_equal(getattr(other, name), getattr(single, name), err_msg=name)


def test_sleeper_mass_of_a_row_enters_its_pass():
    """The mass diagonal is per row: heavier sleepers in one row of a batch change that row's pass and no other,
    and the row equals the same track run alone."""
    t = Track.seed()
    heavy = t.scaled(sleeper_mass=3.0, from_sleeper=20, to_sleeper=30)
    kw = dict(x_start=6.0, x_end=24.0, dt=1e-4)
    plain, loaded, plain_again = simulate_passes([t, heavy, t], LOADED, V80, **kw)
    alone = simulate_pass(heavy, LOADED, V80, **kw)
    np.testing.assert_array_equal(plain.contact_force, plain_again.contact_force)
    np.testing.assert_array_equal(loaded.contact_force, alone.contact_force)
    np.testing.assert_array_equal(loaded.sleeper_force, alone.sleeper_force)
    changed = np.abs(loaded.sleeper_force - plain.sleeper_force) / plain.sleeper_force.max()
    assert changed[20:30].max() > 1e-3  # the heavier sleepers move their own peak forces


def test_warm_kernel_reaches_every_compiled_entry():
    """warm_kernel loads (or compiles) every entry: each must then hold its compiled code in this process (a batch
    that warm_kernel sizes wrongly would leave an entry to compile inside a test), and bad entries are refused."""
    import numba

    from trackenv.physics import _kernel
    from trackenv.physics.dynamics import KERNEL_ENTRIES, warm_kernel

    warm_kernel()  # loaded from the cache by now: cheap
    reachable = [e for e in KERNEL_ENTRIES if not e[0] or numba.config.NUMBA_NUM_THREADS >= 2]
    assert len(reachable) >= len(_kernel.WIDTHS)
    for entry in reachable:
        assert _kernel._RUNNERS[entry].signatures, entry
    with pytest.raises(ValueError, match="entries must be among"):
        warm_kernel([(False, 3)])


def test_a_vehicles_system_is_assembled_once_and_cannot_be_changed_by_a_pass():
    """Passes of one vehicle share its assembled system (its statics, which the static start and the auto time
    step read every pass, are computed once): an equal vehicle gives the same system, another vehicle its own,
    and the shared arrays are read-only, so that no caller can change the vehicle of later passes."""
    from trackenv.physics.dynamics import _vehicle_system

    system = _vehicle_system(Wheelset(mass=1800.0, static_load=50e3))
    assert _vehicle_system(Wheelset(mass=1800.0, static_load=50e3)) is system
    assert _vehicle_system(Wheelset(mass=1500.0, static_load=50e3)) is not system
    for arr in (system.mass, system.damping, system.stiffness, system.force, system.wheel_dofs, system.axle_offsets):
        with pytest.raises(ValueError, match="read-only"):
            arr[...] = 0
    car = _vehicle_system(Car.manchester_coach())
    np.testing.assert_allclose(car.static_wheel_loads, Car.manchester_coach().system().static_wheel_loads, rtol=0)


@pytest.mark.parametrize("n_rows", [1, 3, 17])
def test_the_kernel_gets_arrays_that_do_not_overlap(monkeypatch, n_rows):
    """The kernel's window functions are compiled with the promise that their arrays do not overlap
    (``_pipeline._NoAliasCompiler``): no two of a pass's per-row arrays (inputs, state, outputs) may share memory,
    nor any of them with the shared mesh and vehicle arrays, at any chunk width and for a train of several axles."""
    from trackenv.physics import _kernel

    seen = []
    run = _kernel.run

    def recording_run(mesh, drive, rows, peaks, reuse, width):
        seen.append((mesh, drive, rows, peaks, reuse))
        return run(mesh, drive, rows, peaks, reuse, width)

    monkeypatch.setattr(_kernel, "run", recording_run)
    for t, vehicle in ((Track.seed(), LOADED), (Track.realistic(40.0), Car.manchester_coach())):
        rows = 5e-4 * np.random.default_rng(3).standard_normal((n_rows, t.n_sleepers))
        simulate_passes(t, vehicle, V80, rows, support_settlement=np.abs(rows), dt="auto")
    assert len(seen) == 2
    for mesh, drive, rows_, peaks, reuse in seen:
        shared = [x for x in (*mesh, *drive) if isinstance(x, np.ndarray)]
        per_row = [*rows_, *peaks, *reuse]
        for i, x in enumerate(per_row):
            for y in per_row[i + 1 :] + shared:
                assert not np.may_share_memory(x, y), (rows_._fields + peaks._fields + reuse._fields)[i]


@pytest.mark.parametrize("case", ["wheelset", "coach"])
def test_one_row_passes_keep_their_window_factors_bit_identically(monkeypatch, case):
    """A one-row pass keeps each window's factor and each bay's columns for the next pass over the same track at
    the same dt (the effective stiffness is the same): the next pass reads them back and its results are bit for
    bit the first pass's, a batch's (which keeps nothing) and those of a pass over a new, equal track; another dt
    or window size is kept apart. Corrupting what was kept changes the next pass: it is read, not recomputed."""
    from trackenv.physics import dynamics

    kept_factors = dynamics._kept_factors
    kept_factors.cache_clear()
    stores = []
    monkeypatch.setattr(dynamics, "_kept_factors", lambda *a: stores.append(kept_factors(*a)) or stores[-1])
    if case == "wheelset":
        make, vehicle = Track.seed, LOADED
    else:
        make, vehicle = (lambda: Track.realistic(40.0)), Car.manchester_coach()
    t = make()
    z = 5e-4 * np.random.default_rng(11).standard_normal(t.n_sleepers)
    kw = dict(dt=4e-4, support_settlement=np.abs(z))
    first = simulate_pass(t, vehicle, V80, z, **kw)
    store = stores[0]
    assert (store.factor_window[:, 0] >= 0).sum() > 10 and (store.columns_window[:, 0] >= 0).sum() > 10
    if case == "wheelset":  # one window per bay the wheel passed, each kept (none overwritten near the ends)
        assert (store.factor_window[:, 0] >= 0).sum() == (store.columns_window[:, 0] >= 0).sum()
    second = simulate_pass(t, vehicle, V80, z, **kw)
    assert stores[1] is store and kept_factors.cache_info().hits == 1
    fresh = simulate_pass(make(), vehicle, V80, z, **kw)
    batch = simulate_passes(t, vehicle, V80, [z, 0.5 * z], support_settlement=np.abs(np.stack([z, z])), dt=4e-4)
    assert len(stores) == 3  # the batch keeps nothing
    for name in ("contact_force", "rail_displacement", "sleeper_force", "pad_plus_ballast_force"):
        want = getattr(first, name)
        for other in (second, fresh, batch[0]):
            assert np.array_equal(getattr(other, name), want), name
    for options in (dict(dt=2e-4, support_settlement=np.abs(z)), dict(window_bays=12, **kw)):
        alone = simulate_pass(t, vehicle, V80, z, **options)
        assert stores[-1] is not store
        assert np.array_equal(simulate_pass(t, vehicle, V80, z, **options).contact_force, alone.contact_force)
    store.columns[...] *= 1.01
    assert not np.array_equal(simulate_pass(t, vehicle, V80, z, **kw).contact_force, first.contact_force)
    kept_factors.cache_clear()


def test_long_tracks_keep_no_window_factors(monkeypatch):
    """A one-row pass over a track whose store would exceed its bound (600 m: ~12 MB) keeps nothing, so that the
    lru of stores cannot hold hundreds of MB; the pass is the same as a batch's."""
    from trackenv.physics import dynamics

    calls = []
    monkeypatch.setattr(dynamics, "_kept_factors", lambda *a: calls.append(a))
    t = Track.realistic(600.0)
    alone = simulate_pass(t, LOADED, V80, dt=4e-4, x_end=60.0)
    assert calls == []
    batch = simulate_passes(t, LOADED, V80, [None, None], dt=4e-4, x_end=60.0)
    assert np.array_equal(alone.contact_force, batch[0].contact_force)
