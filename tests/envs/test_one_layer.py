"""The 60 m track and the line (presets of LineConfig) run through the one Gymnasium layer (TrackEnv,
TrackVectorEnv) and the functions they share: the same info keys from one builder, costs whose named parts are
the reward and whose per-section parts add up with the campaign's fixed cost, the shared observation bounds,
one mask convention, one dispatch by config."""

from __future__ import annotations

import numpy as np
import pytest

from trackenv.envs import LineConfig, NetworkConfig, scenario
from trackenv.envs.common import SHARED_BOUNDS
from trackenv.envs.env import TrackEnv, TrackVectorEnv
from trackenv.envs.info import step_info
from trackenv.envs.problems import make_vector_env, problem_config, problem_of

CONFIGS = {
    "60 m track": scenario("track60", n_sections=3, segment_length_m=30.0, sections_per_segment=3, capacity=3,
                           horizon_years=1.0),
    "line": scenario("small", horizon_years=1.0),
}
SHARED_INFO_KEYS = set(step_info({}, np.zeros(1, bool), np.zeros(1), np.zeros(1), np.zeros(1, int), 0.0, 0.0))


@pytest.mark.parametrize("name", sorted(CONFIGS))
def test_each_problem_steps_through_the_one_layer_and_the_shared_functions(name):
    config = CONFIGS[name]
    env = TrackEnv(config)
    obs, info = env.reset(seed=1)
    assert SHARED_INFO_KEYS <= set(info) and "section_costs" in info
    for key, bounds in SHARED_BOUNDS.items():
        if key in env.observation_space.spaces:
            space = env.observation_space[key]
            assert (space.low.min(), space.high.max()) == bounds, key
    S = config.n_sections
    for action in (np.ones(S, np.int8), np.zeros(S, np.int8)):
        obs, reward, terminated, truncated, info = env.step(action)
        assert env.observation_space.contains(obs)
        assert tuple(info["costs"]) == type(config).cost_keys()
        assert -reward == pytest.approx(sum(info["costs"].values()), rel=1e-12)
        campaign = config.campaign_cost * bool(info["tamped_sections"].any())
        assert info["section_costs"].sum() + campaign == pytest.approx(info["cost"], rel=1e-9)
        assert env.action_masks().shape == (2 * S,)


@pytest.mark.parametrize("name", sorted(CONFIGS))
def test_the_vector_env_of_each_problem_is_the_one_vector_layer(name):
    config = CONFIGS[name]
    vec = make_vector_env(config, 2)
    assert type(vec) is TrackVectorEnv and type(vec.engine) is type(None)
    vec.reset(seed=1)
    assert type(vec.engine) is problem_of(config).engine
    single = TrackEnv(config)
    single.reset(seed=2)  # row 1 of the vector env is seeded 1 + 1
    action = np.ones(config.n_sections, np.int8)
    obs, rew, _, _, _ = vec.step(np.stack([action, action]))
    s_obs, s_rew, _, _, _ = single.step(action)
    assert rew[1] == s_rew and all(np.array_equal(obs[k][1], s_obs[k]) for k in s_obs)


def test_dispatch_by_config_type():
    assert problem_config("small") == scenario("small")
    assert problem_config("track60") == scenario("track60")
    assert problem_config(None) == scenario("track60")  # the default of the harnesses that take no env
    assert problem_config({"n_sections": 3, "capacity": 3}) == LineConfig(n_sections=3, capacity=3)
    network = {"line_config": ["small", {"n_sections": 4, "capacity": 2}]}  # a network's dict is a network's
    assert problem_config(network) == NetworkConfig(**network) and problem_config({"n_lines": 2}).n_lines == 2
    with pytest.raises(ValueError, match="scenario"):
        problem_config("tiny")
    with pytest.raises(ValueError, match="config must be one of"):
        problem_of({"n_sections": 3})
    for config in CONFIGS.values():  # every preset takes every action type
        assert problem_of(config).action_types == ("multibinary", "discrete", "choices")
        with pytest.raises(ValueError, match="action_type"):
            TrackEnv(config, action_type="continuous")
