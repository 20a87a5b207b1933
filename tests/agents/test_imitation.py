"""Warm start by behaviour cloning: the cloned policy acts like its teacher rule."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from trackenv.envs.vector import TampingVectorEnv  # noqa: E402
from trackenv_agents.evaluation import evaluate_one  # noqa: E402
from trackenv_agents.heuristics import Periodic  # noqa: E402
from trackenv_agents.imitation import (  # noqa: E402
    agreement,
    relabel,
    teacher_policy,
    teacher_to_agent_actions,
    warm_start,
)
from trackenv_agents.train import load_trained, train  # noqa: E402


def test_teacher_actions_in_agent_terms():
    sections = np.array([[1, 1, 1], [0, 0, 0], [0, 1, 0]], dtype=np.int8)
    assert teacher_to_agent_actions(sections, "ranked").tolist() == [3, 0, 1]
    assert teacher_to_agent_actions(sections, "multibinary").tolist() == sections.tolist()
    with pytest.raises(ValueError, match="action_type"):
        teacher_to_agent_actions(sections, "discrete")


def test_teacher_policy_defaults_to_tuned_parameters_and_rejects_unknown_rules(small_coarse_config):
    tuned = json.loads(open("agents/tuned_heuristics.json").read())["best_params"]["periodic"]
    teacher = teacher_policy("periodic", small_coarse_config)
    assert isinstance(teacher, Periodic) and teacher.params["interval_years"] == tuned["interval_years"]
    assert teacher.horizon_years == small_coarse_config.horizon_years
    with pytest.raises(ValueError, match="warm_start_rule"):
        teacher_policy("oracle", small_coarse_config)


@pytest.mark.parametrize("key, value", [("warm_start_episodes", 0), ("warm_start_epochs", 0),
                                        ("warm_start_label_smoothing", 1.0)])
def test_warm_start_rejects_bad_settings(tmp_path, key, value, small_coarse_config):
    hp = {"action_type": "ranked", "keep_per_sleeper": False, "warm_start_rule": "periodic", key: value}
    with pytest.raises(ValueError, match=key):
        train("ppo", small_coarse_config, total_timesteps=8, n_envs=2, out_dir=tmp_path, hyperparams=hp, progress=False,
              eval_seeds=None, verbose=0)


@pytest.mark.parametrize("action_type", ["ranked", "multibinary"])
def test_warm_started_policy_acts_like_its_teacher(tmp_path, action_type, small_coarse_config):
    params = {"interval_years": 0.75, "sections": "all"}  # tamps at steps 3 and 6 of the 8
    hp = {"action_type": action_type, "keep_per_sleeper": False, "n_steps": 8, "batch_size": 16, "n_epochs": 1,
          "learning_rate": 0.0, "warm_start_rule": "periodic", "warm_start_params": params,
          "warm_start_episodes": 8, "warm_start_epochs": 200,
          "warm_start_label_smoothing": 0.1}
    path = train("ppo", small_coarse_config, total_timesteps=16, n_envs=2, seed=0, out_dir=tmp_path / "run",
                 hyperparams=hp,
                 progress=False, eval_seeds=[5, 6], eval_freq=1000, checkpoint_every=0, verbose=0)
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    warm = summary["warm_start"]
    assert warm["episodes"] >= 8 and warm["accuracy"] == 1.0
    assert 0.5 < warm["teacher_probability"] < 0.99  # label smoothing leaves room to explore
    assert summary["evaluations"][0]["timesteps"] == 0  # the clone itself is evaluated before PPO starts
    # on unseen seeds the clone's deterministic actions are the teacher's, step by step
    clone, teacher = load_trained(path), Periodic(**params).bind(small_coarse_config)
    venv = TampingVectorEnv(3, small_coarse_config)
    obs, _ = venv.reset(seed=[101, 102, 103])
    for _ in range(small_coarse_config.horizon_steps):
        expected, _ = teacher.predict(obs)
        got, _ = clone.predict(obs)
        np.testing.assert_array_equal(got, expected)
        obs, *_ = venv.step(expected)
    np.testing.assert_allclose(evaluate_one(clone, small_coarse_config, [7, 8]).cost,
                               evaluate_one(teacher, small_coarse_config, [7, 8]).cost)


def test_line_teacher_is_the_tuned_line_rule_and_agrees_with_itself():
    from trackenv.envs.line_config import scenario
    from trackenv_agents.line_heuristics import GroupedThreshold, line_tuned_params

    cfg = scenario("small", horizon_years=1.0, segment_length_m=12.0)
    teacher = teacher_policy("grouped-threshold", cfg)
    assert isinstance(teacher, GroupedThreshold) and teacher.capacity == cfg.capacity
    assert teacher.params == line_tuned_params()["grouped-threshold"]
    with pytest.raises(ValueError, match="warm_start_rule"):
        teacher_policy("periodic", cfg)  # a Tamping-v0 rule, not a line rule
    same = agreement(teacher, teacher, cfg, [5, 6])
    assert same["state"] == same["section"] == 1.0 and same["states"] == 2 * cfg.horizon_steps
    never = agreement(teacher_policy("no-maintenance", cfg), teacher, cfg, [5, 6])
    assert never["state"] <= 1.0 and never["sections"] == same["sections"]


def test_relabelled_copies_carry_the_teachers_labels():
    from trackenv.envs.line import line_observation_space
    from trackenv.envs.line_config import scenario

    cfg = scenario("small")
    space = line_observation_space(cfg)
    space.seed(0)
    obs = [space.sample() for _ in range(20)]
    demo_obs = {k: np.stack([o[k] for o in obs]) for k in obs[0]}
    demo_obs["section_sd"] = demo_obs["section_sd"] / 25.0  # 0-4 mm: around the rule's thresholds
    teacher = teacher_policy("grouped-threshold", cfg)
    demos = {"obs": demo_obs, "actions": teacher.predict(demo_obs)[0], "returns": np.arange(20.0), "episodes": 1}
    assert relabel(demos, teacher, "multibinary", 0, 0.2, np.random.default_rng(0)) is demos
    out = relabel(demos, teacher, "multibinary", 3, 0.2, np.random.default_rng(0))
    assert out["actions"].shape == (80, 6) and out["returns"].shape == (80,) and out["episodes"] == 1
    np.testing.assert_array_equal(out["obs"]["section_sd"][:20], demo_obs["section_sd"])  # the originals stay
    np.testing.assert_array_equal(out["returns"][20:40], demos["returns"])
    jitter = out["obs"]["section_sd"][20:] - np.tile(demo_obs["section_sd"], (3, 1))
    assert 0.1 < jitter.std() < 0.3 and np.all(out["obs"]["section_sd"] >= 0)
    np.testing.assert_array_equal(out["actions"], teacher.predict(out["obs"])[0])
    assert not np.array_equal(out["actions"][20:40], demos["actions"])  # some labels moved with the SD
    np.testing.assert_array_equal(out["obs"]["register"][40:60], demo_obs["register"])


@pytest.mark.parametrize("key, value", [("relabel_copies", -1), ("relabel_copies", 1.5), ("relabel_sd_mm", -0.1)])
def test_warm_start_rejects_bad_relabel_settings(key, value):
    from trackenv.envs.line_config import scenario

    with pytest.raises(ValueError, match=f"warm_start_{key}"):
        warm_start(None, None, scenario("small"), "multibinary", "grouped-threshold", **{key: value})
