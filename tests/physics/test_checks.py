"""Tests of trackenv.physics._checks, the one argument-check mechanism, and of the inputs issue 13 found."""

from __future__ import annotations

import time
import warnings

import numpy as np
import pytest

import trackenv as te
from trackenv.envs.line_config import LineConfig, scenario
from trackenv.physics._checks import MAX_TIME_STEPS, check_array, check_int, check_scalar, check_time_steps


@pytest.mark.parametrize("value", ["1.5", True, np.bool_(False), None, [1.0], 1 + 1j, float("nan"), float("inf")])
def test_check_scalar_refuses_what_is_not_a_finite_real(value) -> None:
    with pytest.raises(ValueError, match=r"^speed must .*\[0, 10\]"):
        check_scalar("speed", value, low=0.0, high=10.0)


@pytest.mark.parametrize("value", [3, 3.0, np.float32(3.0), np.int64(3), np.array(3.0)])
def test_check_scalar_returns_a_python_float(value) -> None:
    out = check_scalar("x", value, low=0.0)
    assert type(out) is float and out == 3.0


@pytest.mark.parametrize("value", [True, 2.0, "2", np.float64(2.0), None])
def test_check_int_refuses_bools_floats_and_strings(value) -> None:
    with pytest.raises(ValueError, match=r"^n must be an integer in \[1, 5\]"):
        check_int("n", value, low=1, high=5)


def test_check_int_accepts_numpy_integers() -> None:
    assert type(check_int("n", np.int32(4), low=1)) is int


def test_check_array_refuses_strings_and_bools() -> None:
    for bad in ("x", ["1", "2"], np.array([True, False])):
        with pytest.raises(ValueError, match="^a must be an array of real numbers"):
            check_array("a", bad)


def test_time_step_bound_is_checked_before_allocating() -> None:
    with pytest.raises(ValueError, match="MAX_TIME_STEPS"):
        check_time_steps(30.0, 30.0 / (MAX_TIME_STEPS + 10) / 1e-4, 1e-4)
    assert check_time_steps(30.0, 30.0 / MAX_TIME_STEPS / 1e-4 * 1.001, 1e-4) <= MAX_TIME_STEPS
    with pytest.raises(ValueError, match="MAX_PASS_SAMPLES"):
        check_time_steps(30.0, 20.0, 1e-4, rows=4096, axles=16)


@pytest.mark.parametrize("speed", [1e-3, 1e-9])
def test_a_crawling_pass_is_refused_within_a_second(speed) -> None:
    t0 = time.perf_counter()
    with pytest.raises(ValueError, match="speed"):
        te.simulate_pass(te.Track.seed(), te.Wheelset.seed(), speed=speed)
    assert time.perf_counter() - t0 < 1.0


SUPPORTS = dict(pad_stiffness=200e6, pad_damping=30e3, sleeper_mass=157.4, ballast_stiffness=160e6,
                ballast_damping=500e3)


@pytest.mark.parametrize(
    ("change", "name"),
    [({"rail_bending_stiffness": 1e300}, "rail_bending_stiffness"), ({"sleeper_mass": "x"}, "sleeper_mass"),
     ({"ballast_stiffness": 1e300}, "ballast_stiffness")],
)
def test_track_uniform_names_the_bad_parameter(change, name) -> None:
    with pytest.raises(ValueError, match=f"^{name} must"):
        te.Track.uniform(51, **{**SUPPORTS, **change})


def test_the_stiffest_allowed_rail_still_solves() -> None:
    track = te.Track.uniform(51, **SUPPORTS, rail_bending_stiffness=1e10)
    assert np.isfinite(te.static_deflection(track, 100e3))


@pytest.mark.parametrize(
    ("field", "value"),
    [("tamping_cost_per_m", "1.5"), ("speed_kmh", "100"), ("voided_sleepers_mean", "1.5"),
     ("steps_per_year", True), ("n_sections", True), ("min_steps_between_tampings", 1.0)],
)
def test_config_refuses_strings_and_bools_at_construction(field, value) -> None:
    with pytest.raises(ValueError, match=f"^{field} must"):
        LineConfig(**{field: value})


@pytest.mark.parametrize("changes", [
    {"speed_kmh": 5.0, "dt": 1e-6},  # a 42 m pass: 30 million steps
    {"speed_kmh": 10.0, "section_length_m": 1000.0, "segment_length_m": 1000.0},  # dt "auto": 1e-4 s at most
])
def test_config_reads_the_dynamics_time_step_bound(changes) -> None:
    """A config the env would accept and then fail on at its first pass is refused at once, naming the fields
    that set the pass's time steps."""
    with pytest.raises(ValueError, match="segment_length_m, speed_kmh and dt.*MAX_TIME_STEPS"):
        scenario("small", **changes)
    scenario("small", **{**changes, "speed_kmh": 100.0})  # fast enough


@pytest.mark.parametrize("name", ["small", "track60"])
def test_config_counts_the_time_steps_of_the_pass_the_env_runs(name, monkeypatch) -> None:
    """The config's check of MAX_TIME_STEPS measures the passes the env's dynamics integrate (each vehicle type
    over a segment with its approach and exit zones)."""
    from trackenv.envs import line_episode
    from trackenv.envs.env import TrackEnv

    cfg = scenario(name, speed_kmh=120.0, dt=2e-4)
    if name == "track60":  # a segment of 30 m, as the line's
        cfg = cfg.replace(n_sections=3, segment_length_m=30.0, sections_per_segment=3, capacity=3)
    counted = []
    original = line_episode.simulate_pass_batches

    def recording(batches):
        results = original(batches)
        counted.extend((b["vehicle"].system().span, {r.time.size - 1 for r in res}) for b, res in zip(batches, results))
        return results

    monkeypatch.setattr(line_episode, "simulate_pass_batches", recording)
    TrackEnv(cfg).reset(seed=0)
    assert len(counted) == (cfg.axle_passes_per_step() > 0).sum()  # one pass per vehicle type with traffic
    for span, steps in counted:
        assert steps == {check_time_steps(cfg.pass_length_m(span), cfg.speed, cfg.dt)}


@pytest.mark.parametrize("fn", [te.static_deflection, te.receptance])
def test_static_and_harmonic_responses_check_their_track(fn) -> None:
    with pytest.raises(ValueError, match="^track must be a Track"):
        fn("not a track")


def test_receptance_bounds_its_frequencies() -> None:
    with pytest.raises(ValueError, match="^frequencies must be <= 100000"):
        te.receptance(te.Track.seed(), frequencies=[10.0, 1e300])


@pytest.mark.parametrize("index", [None, "3", 2.0, -1, 51])
def test_voided_sleeper_index_is_checked_first(index) -> None:
    with pytest.raises(ValueError, match=r"^index must be an integer in \[0, 50\]"):
        te.Track.seed().with_voided_sleeper(index)


@pytest.mark.parametrize(("kw", "name"), [({"tracks": None}, "track"), ({"tracks": 3.0}, "track"),
                                          ({"irregularities": 0.5}, "irregularities"),
                                          ({"irregularities": True}, "irregularities")])
def test_simulate_passes_names_malformed_rows(kw, name) -> None:
    args = {"tracks": te.Track.seed(), "vehicle": te.Wheelset.seed(), "speed": 20.0, **kw}
    with pytest.raises(ValueError, match=name):
        te.simulate_passes(**args)


@pytest.mark.parametrize("profile", ["x", [1 + 1j] * 51, [object()] * 51])
def test_simulate_pass_refuses_a_profile_that_is_not_numbers(profile) -> None:
    with pytest.raises(ValueError, match="^irregularity must be an array of real numbers"):
        te.simulate_pass(te.Track.seed(), te.Wheelset.seed(), 20.0, profile)


@pytest.mark.parametrize("speed", [250.0, -10.0, 0.0])
def test_a_speed_out_of_range_says_its_unit(speed) -> None:
    """250 meant as km/h: the range is in m/s, and the message says so and how to convert."""
    with pytest.raises(ValueError, match=r"^speed must lie in \(0, 200\], got .* \(m/s: 200 m/s is 720 km/h; a speed "
                                         r"in km/h divided by 3\.6\)$"):
        te.simulate_pass(te.Track.seed(), te.Wheelset.seed(), speed=speed)


def test_a_track_in_kilonewtons_per_metre_is_named_even_far_from_the_rails_ends() -> None:
    """Pads and ballast entered in kN/m (60e3 and 100e3): a pass kept clear of the rail's ends gives no overload
    (106 kN against 100 static) while the rail sinks 178 mm; the static deflection names the unit, warned or
    raised as the overload is, and a soft real track (1 MN/m pads and ballast, 25 mm) passes without a word."""
    wheel = te.Wheelset(mass=1800.0, static_load=100e3 - 900.0 * 9.81)

    def track(pad, ballast):
        return te.Track.uniform(61, pad_stiffness=pad, pad_damping=30e3, sleeper_mass=157.4,
                                ballast_stiffness=ballast, ballast_damping=60e3, rail_bending_stiffness=6.42e6,
                                rail_mass=60.2)

    with pytest.warns(te.OverloadWarning, match=r"^the track: the rail would deflect 177\.7 mm under the static "
                                                r"wheel load of 100 kN .* Check the units \(stiffness N/m, not kN/m"):
        te.simulate_pass(track(60e3, 100e3), wheel, speed=100 / 3.6, x_start=15.0, x_end=20.0)
    with pytest.raises(te.OverloadError, match="would deflect"):
        te.simulate_pass(track(60e3, 100e3), wheel, speed=100 / 3.6, x_start=15.0, x_end=20.0, on_overload="raise")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        te.simulate_pass(track(60e3, 100e3), wheel, speed=100 / 3.6, x_start=15.0, x_end=20.0, on_overload="ignore")
        te.simulate_pass(track(1e6, 1e6), wheel, speed=100 / 3.6, x_start=15.0, x_end=20.0)
    with pytest.warns(te.OverloadWarning, match=r"^the track: the rail would deflect 177\.7 mm"):
        te.TrackDegradation(track(60e3, 100e3), wheel, law=te.HettlerLaw(), speed=100 / 3.6)
