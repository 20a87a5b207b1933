"""Warm start by behaviour cloning: the cloned policy acts like its teacher rule."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from trackenv.envs.vector import TampingVectorEnv  # noqa: E402
from trackenv_agents.evaluation.harness import evaluate_one  # noqa: E402
from trackenv_agents.learning.imitation import (  # noqa: E402
    fit_choices,
    teacher_policy,
    teacher_to_agent_actions,
)
from trackenv_agents.learning.tamping import load_trained, train  # noqa: E402
from trackenv_agents.rules import tuned_params_for  # noqa: E402
from trackenv_agents.rules.line import UniformPeriodic  # noqa: E402


def test_teacher_actions_in_agent_terms():
    sections = np.array([[1, 1, 1], [0, 0, 0], [0, 1, 0]], dtype=np.int8)
    assert teacher_to_agent_actions(sections, "ranked").tolist() == [3, 0, 1]
    assert teacher_to_agent_actions(sections, "multibinary").tolist() == sections.tolist()
    with pytest.raises(ValueError, match="action_type"):
        teacher_to_agent_actions(sections, "discrete")


def test_teacher_policy_defaults_to_tuned_parameters_and_rejects_unknown_rules(small_coarse_config):
    tuned = tuned_params_for(small_coarse_config)["uniform-periodic"]
    teacher = teacher_policy("uniform-periodic", small_coarse_config)
    assert isinstance(teacher, UniformPeriodic) and teacher.params == tuned and tuned["interval_years"] > 0
    assert teacher.horizon_steps == small_coarse_config.horizon_steps
    assert teacher.capacity == small_coarse_config.capacity
    given = teacher_policy("uniform-periodic", small_coarse_config, {"interval_years": 0.5})
    assert given.params == {"interval_years": 0.5, "offset_years": 0.0}
    for unknown in ("oracle", "periodic"):
        with pytest.raises(ValueError, match="warm_start_rule"):
            teacher_policy(unknown, small_coarse_config)


@pytest.mark.parametrize("key, value", [("warm_start_episodes", 0), ("warm_start_epochs", 0),
                                        ("warm_start_label_smoothing", 1.0)])
def test_warm_start_rejects_bad_settings(tmp_path, key, value, small_coarse_config):
    hp = {"action_type": "ranked", "keep_per_sleeper": False, "warm_start_rule": "uniform-periodic", key: value}
    with pytest.raises(ValueError, match=key):
        train("ppo", small_coarse_config, total_timesteps=8, n_envs=2, out_dir=tmp_path, hyperparams=hp, progress=False,
              eval_seeds=None, verbose=0)


@pytest.mark.parametrize("action_type", ["ranked", "multibinary"])
def test_warm_started_policy_acts_like_its_teacher(tmp_path, action_type, small_coarse_config):
    # the whole track at steps 2 and 5 of the 8: from step 2 on, no section is within min_steps_between_tampings
    # of a tamping before the episode, so the env applies every campaign the teacher calls
    params = {"interval_years": 0.75, "offset_years": 0.5}
    hp = {"action_type": action_type, "keep_per_sleeper": False, "n_steps": 8, "batch_size": 16, "n_epochs": 1,
          "learning_rate": 0.0, "warm_start_rule": "uniform-periodic", "warm_start_params": params,
          "warm_start_episodes": 64, "warm_start_epochs": 300,  # the shipped amounts: fewer episodes let the
          "warm_start_label_smoothing": 0.1}  # clone read the tracks' random features (register, age) as cues
    path = train("ppo", small_coarse_config, total_timesteps=16, n_envs=2, seed=0, out_dir=tmp_path / "run",
                 hyperparams=hp,
                 progress=False, eval_seeds=[5, 6], eval_freq=1000, checkpoint_every_s=0, verbose=0)
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    warm = summary["warm_start"]
    assert warm["episodes"] >= 64 and warm["accuracy"] == 1.0
    assert 0.5 < warm["teacher_probability"] < 0.99  # label smoothing leaves room to explore
    assert summary["evaluations"][0]["timesteps"] == 0  # the clone itself is evaluated before PPO starts
    # on unseen seeds the clone's deterministic actions are the teacher's, step by step
    clone, teacher = load_trained(path), UniformPeriodic(**params).bind(small_coarse_config)
    venv = TampingVectorEnv(3, small_coarse_config)
    obs, _ = venv.reset(seed=[101, 102, 103])
    tamped = []
    for _ in range(small_coarse_config.horizon_steps):
        expected, _ = teacher.predict(obs)
        tamped.append(bool(expected.any()))
        got, _ = clone.predict(obs)
        np.testing.assert_array_equal(got, expected)
        obs, *_ = venv.step(expected)
    assert tamped == [False, False, True, False, False, True, False, False]
    np.testing.assert_allclose(evaluate_one(clone, small_coarse_config, [7, 8]).cost,
                               evaluate_one(teacher, small_coarse_config, [7, 8]).cost)


def test_line_teacher_is_the_tuned_line_rule():
    from trackenv.envs.line_config import scenario
    from trackenv_agents.rules.line import GroupedThreshold, line_tuned_params

    cfg = scenario("small", horizon_years=1.0, segment_length_m=12.0)
    teacher = teacher_policy("grouped-threshold", cfg)
    assert isinstance(teacher, GroupedThreshold) and teacher.capacity == cfg.capacity
    assert teacher.params == line_tuned_params()["grouped-threshold"]


def test_fit_choices_learns_the_cheaper_choice_and_keeps_its_own_where_it_does_not_matter():
    """Priced choices: tamping is cheaper where feature 0 > 0.5 (by 1-2 k€), waiting elsewhere, except where
    the two differ by less than the margin: there the target is the choice the data's policy made, which the
    policy can read (feature 2, as the advisor's choice is a feature of the line policy). The fitted policy
    makes the cheaper choice where it is clear and the choice made elsewhere."""
    import torch
    from gymnasium import spaces
    from sb3_contrib import MaskablePPO
    from stable_baselines3.common.env_util import DummyVecEnv

    class Box(__import__("gymnasium").Env):
        observation_space = spaces.Box(0.0, 1.0, (3,), np.float32)
        action_space = spaces.Discrete(2)

    model = MaskablePPO("MlpPolicy", DummyVecEnv([Box]), seed=0, device="cpu", policy_kwargs={"net_arch": [32, 32]})
    rng = np.random.default_rng(0)
    x = rng.random((800, 3)).astype(np.float32)
    x[:, 2] = np.rint(x[:, 2])
    acted = x[:, 2] > 0.5
    stake = rng.uniform(1.0, 2.0, 800)
    tamp = x[:, 0] > 0.5
    q_tamp = np.where(tamp, 50.0, 50.0 + stake)
    q_wait = np.where(tamp, 50.0 + stake, 50.0)
    tiny = x[:, 1] > 0.7  # differences below the margin, either way
    q_tamp[tiny] = 50.0 + rng.uniform(-0.4, 0.4, tiny.sum())
    q_wait[tiny] = 50.0
    samples = {"features": x, "q_do": q_tamp, "q_skip": q_wait, "did": acted, "weight": np.ones(800)}
    fit = fit_choices(model, samples, reward_scale=20.0, epochs=100, margin=1.0, batch_size=64)
    assert fit["weighted_target_share"] > 0.9 and fit["samples"] == 800
    chosen = model.policy.get_distribution(torch.as_tensor(x)).mode().numpy().astype(bool)
    away = np.abs(x[:, 0] - 0.5) > 0.1  # the learnt boundary is as sharp as the samples near it allow
    assert (chosen[~tiny & away] == tamp[~tiny & away]).mean() > 0.95
    assert (chosen[tiny] == acted[tiny]).mean() > 0.8
    with pytest.raises(ValueError, match="margin"):
        fit_choices(model, samples, reward_scale=20.0, margin=-1.0)
    flat = {**samples, "q_do": q_wait.copy()}
    with pytest.raises(ValueError, match="no cost difference"):
        fit_choices(model, flat, reward_scale=20.0, margin=0.0)
