"""The pass engine (:mod:`trackenv.physics.engine`): bad values are refused naming the field; the classic engine's
options are the passes' defaults, bit for bit; the fast engine's steady start sits its lead bays before the
evaluated track and falls back to the static start where its window does not fit the approach; the settlement
loop runs with either."""

from __future__ import annotations

import numpy as np
import pytest

from trackenv.degradation import TrackDegradation
from trackenv.physics.dynamics import simulate_passes
from trackenv.physics.engine import CLASSIC_ENGINE, ENGINES, FAST_ENGINE, PassEngine, check_engine
from trackenv.physics.track import Track
from trackenv.physics.vehicle import Wheelset

WHEEL = Wheelset(mass=1400.0, static_load=100e3)
SPEED = 100 / 3.6


@pytest.mark.parametrize("field, value", [("start", "moving"), ("window_ends", "absorbing"),
                                          ("decay_lengths", 0.1), ("decay_lengths", 1e3), ("lead_bays", -1.0)])
def test_bad_values_are_refused_naming_the_field(field, value):
    with pytest.raises(ValueError, match=field):
        PassEngine(**{field: value})


def test_engines_by_name():
    assert check_engine("classic") is CLASSIC_ENGINE and check_engine("fast") is FAST_ENGINE
    assert check_engine(FAST_ENGINE) is FAST_ENGINE and set(ENGINES) == {"classic", "fast"}
    with pytest.raises(ValueError, match="engine"):
        check_engine("quick")
    with pytest.raises(ValueError, match="window_decay_lengths"):
        simulate_passes(Track.realistic(12.0), WHEEL, SPEED, window_decay_lengths=0.0)


def test_the_classic_engine_is_the_passes_defaults():
    track = Track.realistic(18.0).extended(10, 10)
    level = np.abs(np.sin(np.arange(track.n_sleepers) * 0.7)) * 1e-3
    default = simulate_passes(track, WHEEL, SPEED, None, support_settlement=level, dt="auto")[0]
    classic = simulate_passes(track, WHEEL, SPEED, None, support_settlement=level, dt="auto",
                              **CLASSIC_ENGINE.options_for(track, WHEEL, 10))[0]
    assert np.array_equal(default.sleeper_force, classic.sleeper_force)
    assert np.array_equal(default.contact_force, classic.contact_force)


def test_the_steady_start_sits_its_lead_bays_before_the_evaluated_track_or_falls_back():
    track = Track.realistic(18.0).extended(10, 10)
    options = FAST_ENGINE.options_for(track, WHEEL, 10)
    assert options["start"] == "steady"
    assert options["x_start"] == pytest.approx((10 - FAST_ENGINE.lead_bays) * track.sleeper_spacing)
    assert FAST_ENGINE.approach_sleepers(track, WHEEL) <= 10 and CLASSIC_ENGINE.approach_sleepers(track, WHEEL) == 0
    soft = track.replace(ballast_stiffness=track.ballast_stiffness * 0.02)  # its window needs more approach
    assert FAST_ENGINE.options_for(soft, WHEEL, 10)["start"] == "static"
    assert FAST_ENGINE.approach_sleepers(soft, WHEEL) > 10


def test_the_options_of_a_track_are_kept_and_each_caller_gets_its_own_dict():
    track = Track.realistic(18.0).extended(10, 10)
    options = FAST_ENGINE.options_for(track, WHEEL, 10)
    options["start"] = "rest"  # a caller's change stays its own
    assert FAST_ENGINE.options_for(track, WHEEL, 10) == {**options, "start": "steady"}
    assert FAST_ENGINE.options_for(track, WHEEL, 12)["x_start"] > FAST_ENGINE.options_for(track, WHEEL, 10)["x_start"]
    assert CLASSIC_ENGINE.options_for(track, WHEEL, 10) == CLASSIC_ENGINE.pass_options


def test_the_settlement_loop_runs_with_the_fast_engine():
    track = Track.realistic(12.0)
    level = 1e-3 * np.cos(np.arange(track.n_sleepers) * 0.9)
    sims = {name: TrackDegradation(track, WHEEL, feedback="support", initial_level=level, engine=name, dt="auto")
            for name in ENGINES}
    forces = {name: sim.evaluated(sim.simulate().sleeper_force) for name, sim in sims.items()}
    assert not np.array_equal(forces["fast"], forces["classic"])
    np.testing.assert_allclose(forces["fast"], forces["classic"], rtol=0.01)
    with pytest.raises(ValueError, match="engine"):
        TrackDegradation(track, WHEEL, engine="quick")
