"""TampingEnvConfig: frozen, validated, round-trips through dicts; bad input raises ValueError naming it."""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np
import pytest

import trackenv.envs  # noqa: F401  (registers the ids)
from trackenv.envs import TampingEnv, TampingEnvConfig

TINY = {"track_length_m": 30.0, "n_sections": 3, "horizon_years": 2.0}


def test_defaults_and_derived_quantities(small_config) -> None:
    c = TampingEnvConfig()
    assert c.n_sleepers == 101  # 60 m at 0.6 m
    assert c.horizon_steps == 40  # 10 years of quarters
    assert c.cycles_per_step == pytest.approx(500_000)
    assert c.speed == pytest.approx(100 / 3.6)
    assert small_config.n_sleepers == 51
    assert small_config.horizon_steps == 8


def test_frozen_hashable_and_round_trip() -> None:
    c = TampingEnvConfig(**TINY, tamping={"damage_per_tamping": 0.2}, law_params={"force_exponent": 1.5})
    with pytest.raises(dataclasses.FrozenInstanceError):
        c.n_sections = 4  # type: ignore[misc]
    assert hash(c) == hash(TampingEnvConfig.from_dict(c.to_dict()))
    assert TampingEnvConfig.from_dict(c.to_dict()) == c
    d = c.to_dict()
    assert d["tamping"] == {"damage_per_tamping": 0.2}
    assert d["law_params"] == {"force_exponent": 1.5}
    assert c.tamping_model.damage_per_tamping == 0.2
    r = c.replace(n_sections=5)
    assert r.n_sections == 5 and c.n_sections == 3
    assert r.replace(n_sections=3) == c


def test_config_reaches_the_env_by_object_dict_or_keywords() -> None:
    cfg = TampingEnvConfig(**TINY)  # the keywords of small_config, to reach the env as a dict and as keywords
    assert TampingEnv(cfg).config == cfg
    assert TampingEnv(dict(TINY)).config == cfg
    assert TampingEnv(**TINY).config == cfg
    assert TampingEnv(TampingEnvConfig(), **TINY).config == cfg
    for kwargs in ({"config": cfg}, {"config": dict(TINY)}, dict(TINY)):
        env = gym.make("trackenv/Tamping-v0", **kwargs)
        assert env.unwrapped.config == cfg
        env.close()
    with pytest.raises(ValueError, match="config"):
        TampingEnv(config=42)  # type: ignore[arg-type]


@pytest.mark.parametrize("key", ["no_such_field", "horizon", "sections"])
def test_unknown_key_raises_naming_it(key: str) -> None:
    with pytest.raises(ValueError, match=key):
        TampingEnvConfig.from_dict({**TINY, key: 1})
    with pytest.raises(ValueError, match=key):
        TampingEnvConfig(**TINY).replace(**{key: 1})
    with pytest.raises(ValueError, match=key):
        TampingEnv(**TINY, **{key: 1})
    with pytest.raises(ValueError, match=key):
        gym.make("trackenv/Tamping-v0", **TINY, **{key: 1})


@pytest.mark.parametrize("field, value", [
    ("track_length_m", 10.0),
    ("track_length_m", float("nan")),
    ("track_length_m", "long"),
    ("n_sections", 0),
    ("n_sections", 2.5),
    ("n_sections", 65),
    ("ballast_stiffness_cv", -0.1),
    ("transition_probability", 1.5),
    ("voided_sleepers_mean", float("inf")),
    ("initial_quality", "medium"),
    ("vehicle", "tram"),
    ("axle_load_t", 0.0),
    ("speed_kmh", 1000.0),
    ("axle_passes_per_year", -1.0),
    ("steps_per_year", 0),
    ("steps_per_year", 4.0),
    ("horizon_years", 0.0),
    ("law", "no_law"),
    ("mobilisation_cost", -1.0),
    ("immediate_action_cost", float("nan")),
    ("min_steps_between_tampings", -1),
    ("dt", 1.0),
])
def test_out_of_range_value_raises_naming_the_field(field: str, value) -> None:
    with pytest.raises(ValueError, match=field):
        TampingEnvConfig(**{**TINY, field: value})
    with pytest.raises(ValueError, match=field):
        TampingEnvConfig.from_dict({**TINY, field: value})


def test_too_many_sections_for_the_track() -> None:
    # 30 m = 51 sleepers: 17 sections of 3 sleepers fit, 18 do not
    TampingEnvConfig(track_length_m=30.0, n_sections=17)
    with pytest.raises(ValueError, match="n_sections"):
        TampingEnvConfig(track_length_m=30.0, n_sections=18)


@pytest.mark.parametrize("field, value, match", [
    ("tamping", {"no_such_param": 1.0}, "no_such_param"),
    ("law_params", {"no_such_param": 1.0}, "no_such_param"),
    ("limits", {"no_such_param": 1.0}, "no_such_param"),
    ("tamping", 3.0, "tamping"),
    ("law_params", "force_exponent", "law_params"),
])
def test_nested_mappings_are_validated(field: str, value, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        TampingEnvConfig(**{**TINY, field: value})


def test_bad_env_arguments(small_config) -> None:
    with pytest.raises(ValueError, match="action_type"):
        TampingEnv(small_config, action_type="continuous")
    with pytest.raises(ValueError, match="render_mode"):
        TampingEnv(small_config, render_mode="human")


def test_the_numbers_that_draw_a_track_are_fields(small_config) -> None:
    """Sleeper spacing, ballast correlation, transition placement and voided support are config fields that
    reach the track (defaults: the values the episode used to hard-code)."""
    from trackenv.envs.episode import new_episode
    from trackenv.physics.track import Track

    c = small_config
    assert (c.sleeper_spacing_m, c.ballast_stiffness_correlation_m) == (0.6, 1.2)
    assert (c.transition_position, c.voided_residual_support) == ((0.2, 0.8), 0.05)
    wide = TampingEnvConfig(**TINY, sleeper_spacing_m=0.75, transition_probability=1.0,
                            transition_position=[0.5, 0.6])
    assert wide.transition_position == (0.5, 0.6)
    assert wide.n_sleepers == Track.realistic(30.0, sleeper_spacing=0.75).n_sleepers == 41
    for seed in range(5):
        ep = new_episode(wide, np.random.default_rng(seed))
        assert ep.sim.track.sleeper_spacing == 0.75
        assert int(0.5 * 41) <= ep.transition_sleeper < int(0.6 * 41)
    assert TampingEnvConfig.from_dict(wide.to_dict()) == wide


@pytest.mark.parametrize("field, value", [
    ("sleeper_spacing_m", 0.1), ("ballast_stiffness_correlation_m", -1.0), ("voided_residual_support", 1.5),
    ("transition_position", (0.8, 0.2)), ("transition_position", (0.1,)), ("transition_position", "middle"),
])
def test_track_drawing_fields_are_checked(field: str, value) -> None:
    with pytest.raises(ValueError, match=field):
        TampingEnvConfig(**TINY, **{field: value})
