"""The calibration's runs of the line: per step the true state of each episode, its last step included."""

import numpy as np

from trackenv.envs.line import TampingLine
from trackenv.envs.line_config import scenario
from trackenv_studies.calibration import run_line


def test_run_line_records_every_step_of_each_episode_to_its_end():
    cfg = scenario("small", horizon_years=0.5)  # 2 steps
    out = run_line(cfg, [4, 9], threshold_mm=0.0)  # tamp whatever the capacity allows
    assert out["sd"].shape == (3, 2, 6) and out["tamped"].shape == (2, 2, 6)
    env = TampingLine(cfg)
    obs, info = env.reset(seed=9)
    sd, tamped = [info["section_sd_m"]], []
    for _ in range(cfg.horizon_steps):
        obs, _, _, _, info = env.step((obs["section_sd"] >= 0.0).astype(np.int8))
        sd.append(info["section_sd_m"])
        tamped.append(info["tamped_sections"])
    np.testing.assert_array_equal(out["sd"][:, 1], np.array(sd))  # the last step too, not a new episode's first
    np.testing.assert_array_equal(out["tamped"][:, 1], np.array(tamped))
    assert out["tamped"].any()


def test_calibrate_refuses_a_threshold_that_is_no_sd():
    """A threshold at or below zero (every section tamped every step) is no calibration rule: an error naming it,
    before any episode runs."""
    import pytest

    from trackenv_studies.calibration import calibrate

    for bad in (-1.0, 0.0, float("nan")):
        with pytest.raises(ValueError, match="threshold_mm must"):
            calibrate(scenario("small", horizon_years=0.5), [1], threshold_mm=bad)
