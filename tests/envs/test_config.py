"""The 60 m track's config: the preset "track60" of LineConfig, frozen, validated, round-trips through dicts and
reaches the env as an object, a dict or keywords; bad input raises ValueError naming the field. (What every
LineConfig shares with the line presets is in test_line_env.py; a segment of several sections in
test_one_engine.py.)"""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np
import pytest

import trackenv.envs  # noqa: F401  (registers the ids)
from trackenv.envs import LineConfig, TampingEnv, scenario
from trackenv.envs.env import TrackEnv

# the keywords of small_config: 30 m (51 sleepers) in 3 sections of 10 m, 2 years of quarters
SMALL = {"n_sections": 3, "segment_length_m": 30.0, "sections_per_segment": 3, "capacity": 3, "horizon_years": 2.0}


def test_defaults_and_derived_quantities(small_config) -> None:
    c = scenario("track60")
    assert c.n_sleepers == 101 and c.n_segments == 1  # one 60 m segment at 0.6 m
    assert c.n_sections == 6 and c.section_length_m == 10.0
    assert c.horizon_steps == 40  # 10 years of quarters
    np.testing.assert_allclose(c.axle_passes_per_step(), [0.0, 500_000])  # 2 million 20 t axles a year
    assert c.speed == pytest.approx(100 / 3.6)
    assert small_config.n_sleepers == 51 and small_config.n_segments == 1
    assert small_config.horizon_steps == 8


def test_frozen_hashable_and_round_trip() -> None:
    c = scenario("track60", **SMALL, tamping={"damage_per_tamping": 0.2}, law_params={"force_exponent": 1.5})
    with pytest.raises(dataclasses.FrozenInstanceError):
        c.n_sections = 4  # type: ignore[misc]
    assert hash(c) == hash(LineConfig.from_dict(c.to_dict()))
    assert LineConfig.from_dict(c.to_dict()) == c
    d = c.to_dict()
    assert d["tamping"] == {"damage_per_tamping": 0.2}
    assert d["law_params"] == {"force_exponent": 1.5}
    assert c.tamping_model.damage_per_tamping == 0.2
    r = c.replace(horizon_years=3.0)
    assert r.horizon_steps == 12 and c.horizon_steps == 8
    assert r.replace(horizon_years=2.0) == c


def test_config_reaches_the_env_by_object_dict_or_keywords() -> None:
    """TampingEnv's default is the preset "track60": keywords override its fields, a dict is a whole LineConfig
    (as ``to_dict`` writes it)."""
    cfg = scenario("track60", **SMALL)
    assert TampingEnv(cfg).config == cfg
    assert TampingEnv(cfg.to_dict()).config == cfg
    assert TampingEnv(**SMALL).config == cfg
    assert TampingEnv(scenario("track60"), **SMALL).config == cfg
    assert TampingEnv().config == scenario("track60")
    for kwargs in ({"config": cfg}, {"config": cfg.to_dict()}, dict(SMALL)):
        env = gym.make("trackenv/Tamping-v1", **kwargs)
        assert env.unwrapped.config == cfg
        env.close()
    with pytest.raises(ValueError, match="config"):
        TampingEnv(config=42)  # type: ignore[arg-type]


def test_a_misspelt_key_gets_the_closest_field() -> None:
    with pytest.raises(ValueError, match=r"unknown LineConfig key\(s\) \['capacty'\]; did you mean 'capacity' for "
                                         r"'capacty'\? known: \["):
        scenario("default", capacty=4)


@pytest.mark.parametrize("key", ["no_such_field", "horizon", "sections"])
def test_unknown_key_raises_naming_it(key: str) -> None:
    named = rf"unknown LineConfig key\(s\) \['{key}'\]"
    with pytest.raises(ValueError, match=named):
        scenario("track60", **SMALL).replace(**{key: 1})
    with pytest.raises(ValueError, match=named):
        TampingEnv(**SMALL, **{key: 1})
    with pytest.raises(ValueError, match=named):
        gym.make("trackenv/Tamping-v1", **SMALL, **{key: 1})
    with pytest.raises(ValueError, match=named):  # the preset by name too (was Python's TypeError)
        scenario("track60", **{key: 1})


def test_a_horizon_between_whole_steps_is_refused_not_rounded() -> None:
    """An episode is whole steps: 0.3 years of quarterly steps was 1 step (0.25 years) without a word; now the two
    horizons of whole steps around it are named."""
    with pytest.raises(ValueError, match=r"^horizon_years must be a whole number of steps of 0.25 years "
                                         r"\(steps_per_year = 4\), got 0.3 \(1.2 steps\): 0.25 or 0.5$"):
        LineConfig(horizon_years=0.3)
    assert LineConfig(horizon_years=2.5).horizon_steps == 10
    assert LineConfig(horizon_years=1 / 3, steps_per_year=3).horizon_steps == 1


@pytest.mark.parametrize("field, value", [
    ("segment_length_m", float("nan")),
    ("segment_length_m", "long"),
    ("section_length_m", 4.0),  # fewer than the 3 sleepers a section needs (D1 SD, peak)
    ("n_sections", 0),
    ("n_sections", 257),
    ("sections_per_segment", 65),
    ("ballast_stiffness_cv", -0.1),
    ("transition_probability", 1.5),
    ("transition_stiffness_ratio", 20.0),
    ("voided_sleepers_mean", float("inf")),
    ("voided_residual_support", 1.5),
    ("freight_axle_load_t", 0.0),
    ("freight_share", 1.5),
    ("speed_kmh", 1000.0),
    ("annual_mgt", -1.0),
    ("steps_per_year", 0),
    ("steps_per_year", 4.0),
    ("horizon_years", 0.0),
    ("initial_age_years", -1.0),
    ("law", "no_law"),
    ("possession_cost", -1.0),
    ("immediate_action_cost", float("nan")),
    ("capacity", 7),
    ("min_steps_between_tampings", -1),
    ("dt", 1.0),
    ("dt", "fine"),
])
def test_out_of_range_value_raises_naming_the_field(field: str, value) -> None:
    with pytest.raises(ValueError, match=field):
        scenario("track60", **{field: value})
    with pytest.raises(ValueError, match=field):
        scenario("track60").replace(**{field: value})


@pytest.mark.parametrize("field, value, match", [
    ("tamping", {"no_such_param": 1.0}, "no_such_param"),
    ("law_params", {"no_such_param": 1.0}, "no_such_param"),
    ("limits", {"no_such_param": 1.0}, "no_such_param"),
    ("tamping", 3.0, "tamping"),
    ("law_params", "force_exponent", "law_params"),
])
def test_nested_mappings_are_validated(field: str, value, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        scenario("track60", **SMALL, **{field: value})


def test_bad_action_type(small_config) -> None:
    with pytest.raises(ValueError, match="action_type"):
        TampingEnv(small_config, action_type="continuous")


def test_the_numbers_that_draw_a_track_reach_its_model(small_config) -> None:
    """The transition's stiffness ratio (from the middle of the segment on), the voided sleepers and their
    residual support are config fields that reach the track the passes run on (ballast stiffness CV 0: the
    supports are otherwise uniform)."""
    cfg = small_config.replace(ballast_stiffness_cv=0.0, transition_probability=1.0, transition_stiffness_ratio=2.5,
                               voided_sleepers_mean=3.0, voided_residual_support=0.2)
    n, mid, extra = cfg.n_sleepers, cfg.n_sleepers // 2, 10  # the engine's approach sleepers at each end
    voided = 0
    for seed in range(4):
        env = TrackEnv(cfg)
        env.reset(seed=seed)
        kb = env.engine.model_tracks[0].ballast_stiffness[extra : extra + n]
        plain = np.where(np.arange(n) < mid, 1.0, 2.5) * kb[0]
        ratio = kb / plain
        hanging = ~np.isclose(ratio, 1.0, rtol=1e-12)
        assert not hanging[:2].any() and not hanging[-2:].any()  # never the two sleepers at either end
        # a sleeper drawn twice hangs twice (0.2 of 0.2)
        assert np.all(np.isclose(ratio[hanging], 0.2, rtol=1e-12) | np.isclose(ratio[hanging], 0.04, rtol=1e-12))
        voided += int(hanging.sum())
    assert voided > 0
