"""TrackDegradation: the paper's iterative settlement loop (section 4) and its must-hold properties.

Scenario A is the seed track with uniform ballast (the paper's Fig. 10), scenario B the same with the ballast
10 % stiffer from sleeper 40 at 24 m (Fig. 11); both run 6 iterations of 50 000 cycles at 80 km/h with a
loaded wheelset (108.8 kN static wheel load).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import trackenv as te

SPEED = 80 / 3.6
ITERATIONS = 6
CYCLES = 50_000
CHANGE_SLEEPER = 40  # scenario B: ballast +10 % from this sleeper on
CHANGE_M = 24.0
NEAR_M = 1.8  # "around 24 m": within 3 sleeper spacings


def loaded_wheelset() -> te.Wheelset:
    return te.Wheelset(mass=1800.0, static_load=100e3)


def track_a() -> te.Track:
    return te.Track.seed()


def track_b() -> te.Track:
    return te.Track.seed().scaled(ballast_stiffness=1.10, from_sleeper=CHANGE_SLEEPER)


@pytest.fixture(scope="module")
def history_a() -> te.DegradationHistory:
    return te.TrackDegradation(track_a(), loaded_wheelset(), cycles_per_iteration=CYCLES, speed=SPEED).run(
        ITERATIONS)


@pytest.fixture(scope="module")
def history_b() -> te.DegradationHistory:
    return te.TrackDegradation(track_b(), loaded_wheelset(), cycles_per_iteration=CYCLES, speed=SPEED).run(
        ITERATIONS)


# ------------------------------------------------------------------------------------ the history itself
@pytest.mark.parametrize("name", ["history_a", "history_b"])
def test_history_shapes_and_monotone_settlement(name: str, request: pytest.FixtureRequest) -> None:
    h: te.DegradationHistory = request.getfixturevalue(name)
    n = te.Track.seed().n_sleepers
    assert h.settlement.shape == (ITERATIONS, n)
    assert h.sleeper_force.shape == (ITERATIONS, n)
    assert h.contact_force.shape == (ITERATIONS, n)
    assert h.max_contact_force.shape == (ITERATIONS,)
    assert h.cycles.shape == h.passes.shape == (ITERATIONS,)
    np.testing.assert_allclose(h.cycles, CYCLES * np.arange(1, ITERATIONS + 1))
    assert np.all(h.passes >= 1)
    np.testing.assert_allclose(h.sleeper_positions, 0.6 * np.arange(n))
    for arr in (h.settlement, h.sleeper_force, h.contact_force, h.max_contact_force):
        assert np.all(np.isfinite(arr))
    # settlement is downward positive, and never decreases on any sleeper from one iteration to the next
    assert np.all(h.settlement[0] > 0)
    assert np.all(np.diff(h.settlement, axis=0) >= 0)
    assert np.all(h.sleeper_force > 0)
    # the peak per iteration is the largest of its profile
    np.testing.assert_allclose(h.max_contact_force, h.contact_force.max(axis=1))
    d = json.loads(json.dumps(h.to_dict()))
    assert np.asarray(d["settlement_m"]).shape == (ITERATIONS, n)
    assert np.asarray(d["contact_force_N"]).shape == (ITERATIONS, n)
    assert set(d) >= {"sleeper_positions_m", "cycles", "settlement_m", "sleeper_force_N", "contact_force_N",
                      "max_contact_force_N", "passes"}


def test_progress_callback_and_level() -> None:
    seen = []
    sim = te.TrackDegradation(track_a(), loaded_wheelset())
    hist = sim.run(2, progress=lambda i, rec: seen.append((i, rec)))
    assert [i for i, _ in seen] == [0, 1]
    assert seen[-1][1] is hist.records[-1]
    np.testing.assert_array_equal(sim.level, hist.settlement[-1])
    assert sim.cycles == pytest.approx(2 * CYCLES)


def test_initial_level_is_kept_as_offset() -> None:
    n = te.Track.seed().n_sleepers
    lv0 = np.full(n, 0.5e-3)
    sim = te.TrackDegradation(track_a(), loaded_wheelset(), initial_level=lv0)
    np.testing.assert_allclose(sim.level, lv0)
    rec = sim.advance()
    assert np.all(rec.settlement > lv0)
    # an advance of zero cycles records a pass but does not move the level
    rec0 = sim.advance(0)
    np.testing.assert_array_equal(rec0.settlement, rec.settlement)


# ------------------------------------------------------------------------------------ scenario A (Fig. 10)
def test_scenario_a_settles_uniformly_away_from_the_ends(history_a: te.DegradationHistory) -> None:
    u = history_a.settlement[-1][3:48]  # sleepers 3..47
    spread = (u.max() - u.min()) / u.mean()
    assert spread < 0.02
    # and the contact force stays (nearly) the same along the track: "negligible variations"
    f = history_a.contact_force[-1][3:48]
    assert (f.max() - f.min()) / f.mean() < 0.01


# ------------------------------------------------------------------------------------ scenario B (Fig. 11)
def test_scenario_b_differential_settlement_localises_and_grows(history_b: te.DegradationHistory) -> None:
    x = history_b.sleeper_positions
    diff = np.abs(np.diff(history_b.settlement, axis=1))  # between neighbouring sleepers
    k = diff.argmax(axis=1)
    where = 0.5 * (x[k] + x[k + 1])
    assert np.all(np.abs(where - CHANGE_M) <= NEAR_M), where
    largest = diff.max(axis=1)
    assert np.all(np.diff(largest[1:]) > 0), largest  # grows over iterations 2..6 (at least)
    # the settlement is no longer uniform: the differential is far above scenario A's
    assert largest[-1] > 1e-5


def test_scenario_b_contact_force_increase_localises_and_grows(history_b: te.DegradationHistory) -> None:
    x = history_b.sleeper_positions
    inc = history_b.contact_force - history_b.contact_force[0]  # vs iteration 1's profile
    k = inc[1:].argmax(axis=1)
    assert np.all(np.abs(x[k] - CHANGE_M) <= NEAR_M), x[k]
    largest = inc.max(axis=1)
    assert np.all(largest[1:] > 0)
    assert np.all(np.diff(largest[1:]) > 0), largest  # grows over iterations 2..6
    assert np.all(np.diff(history_b.max_contact_force[1:]) > 0)


def test_scenario_b_stays_stable(history_b: te.DegradationHistory) -> None:
    p0 = loaded_wheelset().wheel_load
    assert p0 == pytest.approx(1800.0 / 2 * 9.81 + 100e3)
    assert np.all(np.abs(history_b.max_contact_force - p0) <= 0.3 * p0), history_b.max_contact_force
    # the wheel never leaves the rail
    assert np.all(history_b.contact_force > 0.5 * p0)


def test_scenario_b_matches_a_far_from_the_change(history_a: te.DegradationHistory,
                                                  history_b: te.DegradationHistory) -> None:
    """Far from the change (sleepers 3..30) both scenarios settle alike: the change acts locally."""
    np.testing.assert_allclose(history_b.settlement[-1][3:31], history_a.settlement[-1][3:31], rtol=1e-3)


# ------------------------------------------------------------------------------------ step size
def test_halving_delta_n_with_adaptive_stepping_hardly_changes_the_result() -> None:
    def final(cycles: float, iterations: int) -> np.ndarray:
        sim = te.TrackDegradation(track_b(), loaded_wheelset(), cycles_per_iteration=cycles, adaptive=True)
        return sim.run(iterations).settlement[-1]

    coarse = final(50_000, 6)
    fine = final(25_000, 12)
    assert np.max(np.abs(coarse - fine) / fine) < 0.02


def test_adaptive_stepping_splits_large_increments() -> None:
    sim = te.TrackDegradation(track_b(), loaded_wheelset(), adaptive=True, max_increment=0.02e-3)
    rec = sim.advance()
    assert rec.passes > 1
    assert rec.cycles == pytest.approx(CYCLES)
    plain = te.TrackDegradation(track_b(), loaded_wheelset()).advance()
    np.testing.assert_allclose(rec.settlement, plain.settlement, rtol=0.05)


# ------------------------------------------------------------------------------------ other vehicles
def test_car_on_realistic_track_runs_and_settles() -> None:
    track = te.Track.realistic(30.0)
    sim = te.TrackDegradation(track, te.Car.manchester_coach())
    h = sim.run(2)
    assert h.settlement.shape == (2, track.n_sleepers)
    assert np.all(np.isfinite(h.settlement))
    assert np.all(h.settlement[0] > 0)
    assert np.all(h.settlement[1] >= h.settlement[0])
    assert np.all(h.settlement[1] > h.settlement[0])
    wheel_load = te.Car.manchester_coach().wheel_load
    assert np.all(np.abs(h.max_contact_force - wheel_load) <= 0.3 * wheel_load)


# ------------------------------------------------------------------------------------ bad input
@pytest.fixture(scope="module")
def sim_a() -> te.TrackDegradation:
    return te.TrackDegradation(track_a(), loaded_wheelset())


@pytest.mark.parametrize("cycles", [-1, -1e-3, float("nan"), float("inf")])
def test_advance_rejects_bad_cycles(sim_a: te.TrackDegradation, cycles: float) -> None:
    with pytest.raises(ValueError, match="cycles"):
        sim_a.advance(cycles)


@pytest.mark.parametrize("iterations", [-1, 1.5, "3"])
def test_run_rejects_bad_iterations(sim_a: te.TrackDegradation, iterations) -> None:
    with pytest.raises(ValueError, match="iterations"):
        sim_a.run(iterations)


@pytest.mark.parametrize("kwargs, match", [
    ({"initial_level": np.full(51, np.nan)}, "initial_level"),
    ({"initial_level": np.zeros(50)}, "initial_level"),
    ({"initial_level": np.full(51, 2.0)}, r"initial_level must be <= 0.5 everywhere, got max 2"),  # mm as m
    ({"foo": 1}, "unknown option"),
    ({"windowbays": 4}, "unknown option"),
    ({"cycles_per_iteration": 0}, "cycles_per_iteration"),
    ({"cycles_per_iteration": float("nan")}, "cycles_per_iteration"),
    ({"speed": -1.0}, "speed"),
    ({"speed": 0.0}, "speed"),
    ({"approach_sleepers": 1}, "approach_sleepers"),
    ({"max_increment": 0.0}, "max_increment"),
    ({"law": object()}, "law"),
])
def test_constructor_rejects_bad_input(kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        te.TrackDegradation(track_a(), loaded_wheelset(), **kwargs)


def test_constructor_rejects_bad_track_and_vehicle() -> None:
    with pytest.raises(ValueError, match="track"):
        te.TrackDegradation("seed", loaded_wheelset())  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="vehicle"):
        te.TrackDegradation(track_a(), "wheelset")


def test_make_law_rejects_unknown_parameter_and_name() -> None:
    with pytest.raises(ValueError, match="foo"):
        te.make_law("hettler", foo=1)
    with pytest.raises(ValueError, match="unknown settlement law"):
        te.make_law("no-such-law")


def test_other_law_runs() -> None:
    sim = te.TrackDegradation(track_a(), loaded_wheelset(), law=te.make_law("selig_waters"))
    h = sim.run(2)
    assert np.all(h.settlement[1] > h.settlement[0])


@pytest.mark.parametrize("vehicle", ["wheelset", "car"])
def test_pass_ending_after_the_evaluated_zone_gives_the_full_pass_forces(vehicle: str) -> None:
    """A pass ends EXIT_RUN_OUT_BAYS bays after the last axle left the evaluated zone: every evaluated
    sleeper's peak force and the contact-force profile are those of a pass to the end of the track, bit for
    bit (rough, settled track with support feedback at the auto dt, and the paper's irregularity feedback)."""
    from trackenv.physics.dynamics import simulate_passes

    rng = np.random.default_rng(2)
    track = te.Track.realistic(30.0)
    veh = loaded_wheelset() if vehicle == "wheelset" else te.Car.manchester_coach()
    for feedback in ("support", "irregularity"):
        level = np.abs(2e-3 * rng.standard_normal(track.n_sleepers))
        sim = te.TrackDegradation(track, veh, initial_level=level, feedback=feedback)
        assert sim.pass_end < sim.model_track.length
        short = sim.simulate()
        z = sim.model_irregularity()
        if feedback == "support":
            full = simulate_passes(sim.model_track, veh, sim.speed, None, support_settlement=z[None], dt="auto")[0]
        else:
            full = simulate_passes(sim.model_track, veh, sim.speed, [sim.rail_level()], dt="auto")[0]
        assert full.time.size > short.time.size
        np.testing.assert_array_equal(sim.evaluated(short.sleeper_force), sim.evaluated(full.sleeper_force))
        np.testing.assert_array_equal(
            sim.evaluated(short.contact_force_profile()), sim.evaluated(full.contact_force_profile())
        )


# ------------------------------------------------------------------------------------ runaway feedback
def heavy_fast(**kwargs) -> te.TrackDegradation:
    """Scenario B under a 200 kN wheel load at 200 km/h: the irregularity feedback diverges."""
    return te.TrackDegradation(track_b(), te.Wheelset(mass=1800.0, static_load=200e3), speed=200 / 3.6, **kwargs)


def test_a_diverging_loop_warns_with_what_to_change() -> None:
    sim = heavy_fast(cycles_per_iteration=100_000)
    with pytest.warns(te.RunawayWarning, match="grow geometrically.*cycles_per_iteration.*adaptive.*support"):
        sim.run(4)
    d = np.diff(np.vstack([np.zeros(sim.track.n_sleepers), sim.history.settlement]), axis=0)
    spread = np.ptp(d, axis=1)
    assert spread[3] > 3 * spread[2] > 9 * spread[1]  # it does grow geometrically: the warning is due


def test_a_diverging_loop_raises_when_asked() -> None:
    sim = heavy_fast(cycles_per_iteration=100_000, on_runaway="raise")
    with pytest.raises(te.RunawayError, match="diverging"):
        sim.run(4)


def test_adaptive_stepping_that_runs_out_of_passes_is_reported() -> None:
    """... with advice that fits: adaptive stepping is on already, so its budget and tolerance are named."""
    sim = heavy_fast(cycles_per_iteration=1e6, adaptive=True, max_passes_per_iteration=4)
    with pytest.warns(te.RunawayWarning, match="ran out of passes.*raise max_passes_per_iteration \\(now 4\\) or "
                                               "max_increment") as caught:
        sim.advance()
    assert "use adaptive=True" not in str(caught[0].message)


def test_a_sleeper_force_beyond_the_laws_range_stops_the_loop_by_name() -> None:
    """A loop run away so far that a sleeper carries more than the laws take (1e7 N): a RunawayError that says
    so, whatever on_runaway says, not the law's range error from inside (a probe's adaptive run after a partial
    tamping)."""
    sim = te.TrackDegradation(track_a(), loaded_wheelset(), on_runaway="ignore")
    force = np.full(track_a().n_sleepers, 50e3)
    force[7] = 1.2e7
    with pytest.raises(te.RunawayError, match="sleeper 7 carries 1.2e\\+04 kN.*beyond the settlement laws' range"):
        sim.check_sleeper_forces(force)


class _OwnLaw:
    """A law of one's own by the protocol: u = answer(F, N) and its inverse on a log law."""

    name = "own"

    def __init__(self, sign: float = 1.0, nan: bool = False) -> None:
        self.sign, self.nan = sign, nan

    def settlement(self, force, cycles):
        u = self.sign * 1e-9 * np.asarray(force) * np.log10(1.0 + np.asarray(cycles))
        return np.full(np.shape(u), np.nan) if self.nan else u

    def equivalent_cycles(self, force, settlement):
        return 10.0 ** (np.abs(np.asarray(settlement)) / (1e-9 * np.maximum(np.asarray(force), 1.0))) - 1.0


@pytest.mark.parametrize("feedback", ["irregularity", "support"])
def test_a_law_of_ones_own_runs_and_one_that_answers_nonsense_is_named(feedback: str) -> None:
    """A law of one's own settles by its formula; one returning negative settlements settled as nothing, one
    returning NaN failed as the state's own error or as an unconverged Newton step: now both name the law; the
    class given for an instance is named too."""
    sim = te.TrackDegradation(track_a(), loaded_wheelset(), law=_OwnLaw(), feedback=feedback)
    sim.run(1)
    assert np.all(sim.level > 0.0)
    for bad in (_OwnLaw(sign=-1.0), _OwnLaw(nan=True)):
        with pytest.raises(ValueError, match="^law 'own': settlement\\(force, cycles\\) must return finite "
                                             "settlements >= 0"):
            te.TrackDegradation(track_a(), loaded_wheelset(), law=bad, feedback=feedback).run(1)
    with pytest.raises(ValueError, match="^law must be an instance, e.g. HettlerLaw\\(\\), got the class"):
        te.TrackDegradation(track_a(), loaded_wheelset(), law=te.HettlerLaw)
    with pytest.raises(ValueError, match="^law must be an instance"):
        te.SettlementState.zeros(3).advance(te.HettlerLaw, 5e4, 5e4)


def test_converging_loops_do_not_warn(recwarn: pytest.WarningsRecorder) -> None:
    te.TrackDegradation(track_b(), loaded_wheelset(), cycles_per_iteration=1e6, speed=SPEED).run(6)
    heavy_fast(cycles_per_iteration=1e6, feedback="support").run(4)
    assert not [w for w in recwarn if issubclass(w.category, te.RunawayWarning)]


def test_on_runaway_is_checked() -> None:
    with pytest.raises(ValueError, match="on_runaway must be one of"):
        heavy_fast(on_runaway="shout")


# ------------------------------------------------------------------------------------ interpolation
@pytest.fixture(scope="module")
def step_40_39() -> dict:
    """u40 - u39 [mm] after scenario B's 6 x 50 000 cycles, per (interpolation, elements per bay, dt)."""
    out = {}
    for interp, epb, dt in [("cubic", 2, 1e-4), ("cubic", 8, 1e-4), ("linear", 2, 1e-4), ("linear", 8, 1e-4),
                            ("linear", 16, 1e-4), ("linear", 8, 5e-5)]:
        track = te.Track.seed(elements_per_bay=epb).scaled(ballast_stiffness=1.10, from_sleeper=CHANGE_SLEEPER)
        sim = te.TrackDegradation(track, loaded_wheelset(), cycles_per_iteration=CYCLES, speed=SPEED,
                                  interpolation=interp, dt=dt)
        u = sim.run(ITERATIONS).settlement[-1]
        out[interp, epb, dt] = (u[40] - u[39]) * 1e3
    return out


def test_cubic_loop_is_mesh_converged_at_the_default_mesh(step_40_39: dict) -> None:
    assert step_40_39["cubic", 2, 1e-4] == pytest.approx(step_40_39["cubic", 8, 1e-4], rel=0.05)


def test_linear_loop_needs_eight_elements_per_bay(step_40_39: dict) -> None:
    fine = step_40_39["linear", 16, 1e-4]
    assert step_40_39["linear", 8, 1e-4] == pytest.approx(fine, rel=0.01)  # the paper's mesh: converged
    assert step_40_39["linear", 8, 5e-5] == pytest.approx(step_40_39["linear", 8, 1e-4], rel=0.01)  # and in dt
    assert step_40_39["linear", 2, 1e-4] > 1.25 * fine  # the default mesh is not, for a kinked profile
    assert step_40_39["linear", 8, 1e-4] > 1.2 * step_40_39["cubic", 8, 1e-4]  # the reading matters


def test_linear_interpolation_is_straight_between_sleepers() -> None:
    level = np.zeros(51)
    level[25] = 1e-3
    sim = te.TrackDegradation(track_a(), loaded_wheelset(), initial_level=level, interpolation="linear")
    res = sim.simulate()
    x = res.wheel_position[:, 0] - sim.n_extra * sim.track.sleeper_spacing
    between = (x > 14.4) & (x < 15.6)
    np.testing.assert_allclose(res.irregularity[between, 0], 1e-3 * (1 - np.abs(x[between] - 15.0) / 0.6), atol=1e-12)
    cubic = te.TrackDegradation(track_a(), loaded_wheelset(), initial_level=level).simulate()
    assert np.min(cubic.irregularity[:, 0]) < -1e-5  # the natural spline overshoots below zero next to the dip


def test_interpolation_is_checked() -> None:
    with pytest.raises(ValueError, match="interpolation must be one of"):
        te.TrackDegradation(track_a(), loaded_wheelset(), interpolation="quadratic")


def test_a_sudden_jump_of_the_increment_warns_at_once() -> None:
    """Realistic track, 250 kN at 200 km/h, 1e6 cycles per iteration: 15.7 → 22.0 → 107 mm; warned at the 2nd."""
    sim = te.TrackDegradation(te.Track.realistic(30.0), te.Wheelset(mass=1800.0, static_load=250e3),
                              cycles_per_iteration=1e6, speed=200 / 3.6, on_runaway="raise")
    sim.advance()
    with pytest.raises(te.RunawayError, match=r"grow geometrically \(x[0-9.]+ per iteration"):
        sim.advance()


def test_tamping_starts_a_new_series_of_increments(recwarn: pytest.WarningsRecorder) -> None:
    """The restarted consolidation after tamping makes the next increment jump: that is not a runaway."""
    rate = 1.0 + 0.03 * np.sin(np.arange(51) / 3.0)  # ballast condition varies a little along the track
    sim = te.TrackDegradation(te.Track.realistic(30.0), loaded_wheelset(), cycles_per_iteration=500_000,
                              speed=100 / 3.6, feedback="support", rate_factor=rate)
    sim.advance()
    assert sim._differential[-1] > 0.1 * te.degradation.RUNAWAY_FLOOR  # not a flat start
    mask = np.zeros(sim.track.n_sleepers, dtype=bool)
    mask[15:36] = True
    sim.tamp(mask)
    sim.advance()
    assert not [w for w in recwarn if issubclass(w.category, te.RunawayWarning)]


def test_sleeper_forces_beyond_the_models_validity_are_reported_when_settling() -> None:
    """The env settles without advance(): an impossible sleeper force is caught there too."""
    import dataclasses

    sim = te.TrackDegradation(track_a(), loaded_wheelset(), feedback="support")
    res = sim.simulate()
    assert sim.check_sleeper_forces(sim.evaluated(res.sleeper_force)) is None  # a sound pass: nothing to say
    static = float(sim.system.static_wheel_loads.max())
    scale = 3.5 * static / sim.evaluated(res.sleeper_force).max()
    forced = dataclasses.replace(res, sleeper_force=res.sleeper_force * scale)
    with pytest.warns(te.RunawayWarning, match=r"sleeper \d+ carries .* 3.5 times the static wheel load"):
        sim.settle(forced, 1000.0)
    strict = te.TrackDegradation(track_a(), loaded_wheelset(), feedback="support", on_runaway="raise")
    with pytest.raises(te.RunawayError, match="outside its validity"):
        strict.settle(forced, 1000.0)


def test_adaptive_stepping_takes_a_restart_it_cannot_split_whole() -> None:
    """After a partial tamping the restarted sleepers settle more than max_increment within one cycle (the law's
    initial settlement): adaptive stepping spent its 64 passes on one-cycle steps and left the rest of the
    iteration to one step on their forces, and three iterations later a probe's run stopped on the law's force
    range. The first iteration after the tamping is now taken whole, in one pass, as without adaptive stepping."""
    wheel = te.Wheelset(mass=1800.0, static_load=100e3)
    sim = te.TrackDegradation(te.Track.seed().scaled(ballast_stiffness=3.0, from_sleeper=30), wheel,
                              cycles_per_iteration=1e5, speed=100 / 3.6, adaptive=True)
    sim.run(2)
    tamped = np.zeros(sim.track.n_sleepers, dtype=bool)
    tamped[20:41] = True
    sim.tamp(tamped, te.TampingModel(), rng=np.random.default_rng(1))
    record = sim.advance()
    assert record.passes == 1 and np.isfinite(sim.level).all()
