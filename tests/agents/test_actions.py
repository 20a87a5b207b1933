"""The ranked action parameterisation and its use through the SB3 adapter."""

from __future__ import annotations

import numpy as np
import pytest
from gymnasium import spaces

from trackenv_agents.actions import agent_action_space, env_action_type, ranked_to_sections


def test_ranked_tamps_the_k_worst_sections():
    sd = np.array([[1.0, 3.0, 2.0, 0.5], [2.0, 2.0, 1.0, 4.0]])
    out = ranked_to_sections(np.array([2, 1]), sd)
    assert out.dtype == np.int8
    np.testing.assert_array_equal(out, [[0, 1, 1, 0], [0, 0, 0, 1]])
    np.testing.assert_array_equal(ranked_to_sections(np.array([0, 4]), sd), [[0, 0, 0, 0], [1, 1, 1, 1]])
    # ties go to the lower index; an unbatched observation gives an unbatched action
    np.testing.assert_array_equal(ranked_to_sections(1, np.array([2.0, 2.0, 1.0])), [1, 0, 0])


@pytest.mark.parametrize("k", [-1, 5])
def test_ranked_rejects_counts_out_of_range(k):
    with pytest.raises(ValueError, match=r"\[0, 4\]"):
        ranked_to_sections(np.array([k]), np.ones((1, 4)))


def test_action_types(small_coarse_config):
    assert env_action_type("ranked") == "multibinary"
    assert env_action_type("discrete") == "discrete"
    assert agent_action_space(small_coarse_config, "ranked") == spaces.Discrete(small_coarse_config.n_sections + 1)
    with pytest.raises(ValueError, match="action_type"):
        env_action_type("campaign")


def test_adapter_translates_ranked_actions_on_the_last_observation(small_coarse_config):
    pytest.importorskip("stable_baselines3")
    from trackenv_agents.sb3_vec import TampingSB3VecEnv

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
