"""The instrumented in-service vehicle (``LineConfig.contact_sensor``): every step each section's peak wheel/rail
force of the step's passes and its dynamic share above the static wheel load, read with a relative error drawn
at the reset; off by default, and then nothing is drawn for it."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import trackenv  # noqa: F401  (registers the ids)
from trackenv.envs import scenario

SHORT = {"horizon_years": 2.0}


def _rollout(noise: float, seed: int = 2, steps: int = 8):
    env = gym.make("trackenv/TampingLineSmall-v0", contact_sensor=True, contact_sensor_noise=noise, **SHORT)
    obs, info = env.reset(seed=seed)
    out = [(obs, 0.0, info)]
    for k in range(steps):
        action = np.zeros(6, np.int8)
        action[k % 6] = 1
        obs, reward, _, _, info = env.step(action)
        out.append((obs, reward, info))
    return env, out


def test_the_sensor_is_off_by_default_and_its_keys_come_with_it():
    assert "section_contact_peak" not in gym.make("trackenv/TampingLineSmall-v0").observation_space.spaces
    space = gym.make("trackenv/TampingLineSmall-v0", contact_sensor=True).observation_space
    assert space["section_contact_peak"].shape == (6,) and space["section_dynamic_share"].shape == (6,)


def test_without_error_the_sensor_reads_the_passes_peak_and_its_dynamic_share():
    env, steps = _rollout(0.0)
    static = env.unwrapped.engine.static_wheel_load  # per section: the largest of its traffic's
    assert ((100e3 < static) & (static < 130e3)).all()  # the freight wheel of 22.5 t axles
    for obs, _, info in steps:
        peak = obs["section_contact_peak"].astype(float)
        assert peak.max() == pytest.approx(info["max_contact_force_N"] / 1e3, rel=1e-6)
        np.testing.assert_allclose(obs["section_dynamic_share"], peak * 1e3 / static - 1.0, rtol=1e-5, atol=1e-6)
        assert (obs["section_dynamic_share"] > 0).all()  # a pass over irregular track loads beyond the static


def test_without_error_the_sensor_follows_the_geometry_of_its_own_section():
    """The peak is taken over the section's own sleeper bays, not over the pass's approach, whose start from rest
    rings more than a local defect adds: without error, the sections with the larger true D1 peak read the larger
    dynamic share (left without maintenance on the short-defect line, the peaks spread)."""
    from scipy.stats import spearmanr

    env = gym.make("trackenv/TampingLineDefects-v0", contact_sensor_noise=0.0, **SHORT)
    env.reset(seed=3)
    share, peak = [], []
    for _ in range(8):
        obs, _, _, _, info = env.step(np.zeros(12, np.int64))
        share.append(obs["section_dynamic_share"].astype(float))
        peak.append(np.asarray(info["section_peak_mm"], dtype=float))
    assert spearmanr(np.concatenate(share), np.concatenate(peak)).statistic > 0.5


def test_the_sensor_error_has_its_configured_size_and_leaves_the_dynamics_alone():
    _, exact = _rollout(0.0)
    _, noisy = _rollout(0.05)
    assert [r for _, r, _ in exact] == [r for _, r, _ in noisy]  # the sensor observes; it changes nothing
    ratio = np.concatenate([n[0]["section_contact_peak"] / e[0]["section_contact_peak"] for e, n in zip(exact, noisy)])
    assert abs(ratio.mean() - 1.0) < 0.03 and 0.03 < ratio.std() < 0.075  # 54 readings of a 5 % error


def test_a_restored_state_reads_the_same_sensor_errors():
    env, _ = _rollout(0.05, steps=2)
    state = env.unwrapped.get_state()
    first = env.step(np.zeros(6, np.int8))[0]
    env.unwrapped.set_state(state)
    again = env.step(np.zeros(6, np.int8))[0]
    np.testing.assert_array_equal(first["section_contact_peak"], again["section_contact_peak"])


@pytest.mark.parametrize(("field", "value", "message"), [
    ("contact_sensor", 1, "contact_sensor must be True or False"),
    ("contact_sensor_noise", -0.1, "contact_sensor_noise"),
    ("contact_sensor_noise", 2.0, "contact_sensor_noise"),
])
def test_the_sensor_fields_are_checked(field, value, message):
    with pytest.raises(ValueError, match=message):
        scenario("small", **{field: value})


def test_a_settlement_that_runs_away_is_a_warning_not_silent_figures():
    """A short defect settling 5x faster than a switch (the two factors multiplied) feeds on its own sleeper forces
    until the settlement reaches metres and the forces meganewtons: the engine warns once that the line has left
    the model's validity, naming the fields to check; the shipped preset on the same episode does not warn."""
    import warnings

    def run(**fields):
        env = gym.make("trackenv/TampingLineDefects-v0", **fields)
        _, info = env.reset(seed=1000)
        beyond = [info["beyond_validity"]]
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            for _ in range(40):
                beyond.append(env.step(np.zeros(12, np.int64))[-1]["beyond_validity"])
        return [w for w in caught if issubclass(w.category, RuntimeWarning) and "validity" in str(w.message)], beyond

    runaway, beyond = run(local_defect_length_m=3.0, local_defect_rate_factor=5.0, local_defect_in_zone="multiply")
    assert len(runaway) == 1 and "local_defect_rate_factor=5" in str(runaway[0].message)
    assert "of the line in row 0 of the batch (the env of that index in a vector env)" in str(runaway[0].message)
    # each step's info says it too (here from the reset: the episode's start is already a runaway's), and an
    # unmaintained line does not come back
    assert all(beyond[beyond.index(True):])
    assert run() == ([], [False] * 41)
