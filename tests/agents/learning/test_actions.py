"""The agent's action types and the ranked parameterisation through the SB3 adapter (the decoding itself is
tested with the wrappers, tests/envs/test_wrappers.py)."""

from __future__ import annotations

import numpy as np
import pytest
from gymnasium import spaces

from trackenv_agents.learning.actions import agent_action_space, env_action_type


def test_action_types(small_coarse_config):
    assert env_action_type("ranked") == "multibinary"
    assert env_action_type("discrete") == "discrete"
    assert agent_action_space(small_coarse_config, "ranked") == spaces.Discrete(small_coarse_config.n_sections + 1)
    with pytest.raises(ValueError, match="action_type"):
        env_action_type("campaign")


def test_adapter_translates_ranked_actions_on_the_last_observation(small_coarse_config):
    pytest.importorskip("stable_baselines3")
    from trackenv_agents.learning.sb3_vec import TampingSB3VecEnv

    env = TampingSB3VecEnv(2, small_coarse_config, action_type="ranked", keep_per_sleeper=False, seed=1)
    assert env.action_space == spaces.Discrete(small_coarse_config.n_sections + 1)
    obs = env.reset()
    assert env.action_masks().shape == (2, small_coarse_config.n_sections + 1)
    worst = np.argmax(obs["section_sd"][0])
    _, _, _, infos = env.step(np.array([1, small_coarse_config.n_sections]))
    expected = np.zeros(small_coarse_config.n_sections, dtype=bool)
    expected[worst] = True
    np.testing.assert_array_equal(infos[0]["tamped_sections"], expected)
    assert infos[1]["tamped_sections"].all()
    env.close()


def test_adapter_takes_ranked_choices_and_continues_them_from_a_checkpoint():
    pytest.importorskip("stable_baselines3")
    from trackenv.envs.choices import CHOICES, INTERVENTIONS
    from trackenv.envs.line_config import scenario
    from trackenv_agents.learning.sb3_vec import TampingSB3VecEnv

    config = scenario("wet", n_sections=4, capacity=3, horizon_years=1.0)
    assert env_action_type("ranked_choices") == env_action_type("choices") == "choices"
    space = agent_action_space(config, "ranked_choices")
    assert space == spaces.MultiDiscrete([5] * len(INTERVENTIONS))
    env = TampingSB3VecEnv(2, config, action_type="ranked_choices", keep_per_sleeper=False, seed=1)
    assert env.action_space == space
    env.reset()
    assert env.action_masks().shape == (2, len(INTERVENTIONS) * 5)
    state = env.get_state()
    tamp_worst = np.array([[1, 0, 0, 0, 0, 0], [0, 0, 0, 0, 0, 4]])  # the worst section tamped; every one surveyed
    first = env.step(tamp_worst)
    env.set_state(state)
    again = env.step(tamp_worst)
    np.testing.assert_array_equal(first[1], again[1])
    assert (first[3][0]["section_choices"] == CHOICES.index("tamp")).sum() == 1
    assert first[3][1]["choices"]["survey"] == 4
    env.close()
