"""The SB3 adapter, learning smoke tests and a trained policy's answers."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from trackenv.envs.line_config import LineConfig  # noqa: E402
from trackenv.envs.tamping import TampingEnv  # noqa: E402
from trackenv_agents.evaluation.harness import evaluate_one  # noqa: E402
from trackenv_agents.learning.sb3_vec import TampingSB3VecEnv  # noqa: E402
from trackenv_agents.learning.tamping import load_trained, stats_path, train  # noqa: E402
from trackenv_agents.rules.base import RandomPolicy  # noqa: E402


@pytest.mark.parametrize("bootstrap_at_horizon", [False, True])
def test_adapter_reset_step_and_terminal_observation(bootstrap_at_horizon, small_config):
    env = TampingSB3VecEnv(2, small_config, seed=3, bootstrap_at_horizon=bootstrap_at_horizon)
    obs = env.reset()
    n, s = small_config.n_sleepers, small_config.n_sections
    assert set(obs) == set(env.observation_space.spaces)
    assert obs["level"].shape == (2, 1, n) and obs["contact_force"].shape == (2, 1, n)  # one segment of n sleepers
    assert obs["section_sd"].shape == (2, s) and obs["time"].shape == (2, 1)
    assert env.observation_space.contains({k: v[0] for k, v in obs.items()})
    masks = np.stack(env.env_method("action_masks")).reshape(2, s, 2)  # [may wait, may tamp] per section
    assert env.has_attr("action_masks")
    assert masks[..., 0].all()
    # a section tamped within min_steps_between_tampings steps (here: just before the episode) may not be tamped
    recent = small_config.min_steps_between_tampings / small_config.steps_per_year
    np.testing.assert_array_equal(masks[..., 1], obs["years_since_tamping"] > recent)
    assert masks[..., 1].any()
    i, j = np.argwhere(masks[..., 1])[0]
    for t in range(small_config.horizon_steps):
        action = np.zeros((2, s), dtype=np.int8)
        if t == 0:
            action[i, j] = 1
        obs, rewards, dones, infos = env.step(action)
        assert rewards.shape == (2,) and np.all(rewards <= 0) and len(infos) == 2
        assert isinstance(infos[0], dict) and "cost" in infos[0] and "costs" in infos[0]
        if t == 0:
            assert infos[i]["tamped_sections"].tolist() == [k == j for k in range(s)]
            assert env.env_method("action_masks")[i].reshape(s, 2)[j].tolist() == [True, False]
        if t < small_config.horizon_steps - 1:
            assert not dones.any() and "terminal_observation" not in infos[0]
    assert dones.all()
    for info in infos:
        # the horizon ends the problem (no bootstrapping past it) unless asked to treat it as a time limit
        assert info["TimeLimit.truncated"] is bootstrap_at_horizon
        term = info["terminal_observation"]
        assert term["time"][0] == pytest.approx(1.0) and term["level"].shape == (1, n)
    assert np.all(obs["time"] == 0.0)  # already the next episode's first observation
    env.close()


def test_adapter_over_the_line_env_and_fixed_reward_scale():
    """TampingLine through the same adapter: its final infos (an array of per-line dicts) become SB3's, masks
    are the line's [may-not, may] pairs, and VecScaleReward divides the rewards by a fixed scale."""
    from trackenv.envs.line_config import scenario
    from trackenv_agents.learning.sb3_vec import VecScaleReward

    cfg = scenario("small", horizon_years=0.5, segment_length_m=12.0)  # 2 steps
    raw = TampingSB3VecEnv(2, cfg, seed=4)
    env = VecScaleReward(raw, 10.0)
    obs = env.reset()
    assert obs["section_sd"].shape == (2, 6) and obs["time"].shape == (2, 1)
    assert env.env_method("action_masks")[0].shape == (12,) and env.action_masks().shape == (2, 12)
    action = np.zeros((2, 6), dtype=np.int8)
    action[1, :2] = 1
    obs, rewards, dones, infos = env.step(action)
    raw_rewards = env.get_original_reward()
    np.testing.assert_allclose(rewards, raw_rewards / 10.0, rtol=1e-6)
    assert raw_rewards[1] <= -15.0 and not dones.any()  # a campaign: possession + two sections
    assert raw.action_masks().reshape(2, 6, 2)[1, :2, 1].tolist() == [False, False]  # just tamped: masked
    obs, rewards, dones, infos = env.step(np.zeros((2, 6), dtype=np.int8))
    assert dones.all() and np.all(obs["time"] == 0.0)
    for info in infos:
        assert info["terminal_observation"]["time"][0] == pytest.approx(1.0)
        assert info["TimeLimit.truncated"] is False and "costs" in info
    with pytest.raises(ValueError, match="action_type must be one of"):
        TampingSB3VecEnv(2, cfg, action_type="campaign")
    with pytest.raises(ValueError, match="scale"):
        VecScaleReward(raw, 0.0)


def test_adapter_on_the_network_steps_as_the_network_env():
    """The network is a problem the adapter takes (its learners' flat route): its own action only, and each env
    of the adapter gives what the network env gives on the same seed and actions."""
    import gymnasium as gym

    from trackenv.envs.network import NetworkConfig

    cfg = NetworkConfig(line_config="small", n_lines=2)
    with pytest.raises(ValueError, match="action_type must be one of .'multibinary',. on NetworkConfig"):
        TampingSB3VecEnv(2, cfg, action_type="ranked")
    adapter = TampingSB3VecEnv(2, cfg, seed=11)
    single = gym.make("trackenv/TampingNetwork-v0", config=cfg)
    obs = adapter.reset()
    first, _ = single.reset(seed=12)  # the adapter's second env: seed + 1
    assert obs["machine_line"].shape == (2, 2)
    for key, value in first.items():
        np.testing.assert_array_equal(obs[key][1], value)
    n = adapter.action_space.shape[0]
    action = np.zeros((2, n), dtype=np.int8)
    action[:, n // 2] = 1  # a section of the second line: the machine moves there
    obs, rewards, _, infos = adapter.step(action)
    expected, reward, _, _, info = single.step(action[1])
    assert infos[1]["moved"] and info["moved"]
    assert rewards[1] == pytest.approx(reward)
    for key, value in expected.items():
        np.testing.assert_array_equal(obs[key][1], value)


def test_adapter_seeding_and_dropping_per_sleeper_keys(small_config):
    a = TampingSB3VecEnv(2, small_config, seed=7, keep_per_sleeper=False)
    b = TampingSB3VecEnv(2, small_config, keep_per_sleeper=False)
    b.seed(7)
    oa, ob = a.reset(), b.reset()
    assert "level" not in oa and "contact_force" not in oa and "section_sd" in oa
    for k in oa:
        np.testing.assert_array_equal(oa[k], ob[k])
    assert not np.array_equal(oa["section_sd"][0], oa["section_sd"][1])


@pytest.mark.parametrize("action_type", ["multibinary", "ranked"])
def test_adapter_over_worker_processes_gives_the_same_steps(action_type, small_config):
    """workers=2 (ShardedVectorEnv under the adapter, and under the ranked wrapper): the observations, rewards,
    dones and infos (terminal observations included) of one process, bit for bit, across an episode's end."""
    envs = [TampingSB3VecEnv(3, small_config, seed=5, action_type=action_type, workers=w) for w in (1, 2)]
    try:
        obs = [e.reset() for e in envs]
        rng = np.random.default_rng(0)
        ended = False
        for _ in range(small_config.horizon_steps + 1):
            for k in obs[0]:
                np.testing.assert_array_equal(obs[0][k], obs[1][k])
            if action_type == "ranked":
                action = rng.integers(0, small_config.n_sections + 1, size=3)
            else:
                action = rng.integers(0, 2, size=(3, small_config.n_sections))
            (obs0, r0, d0, i0), (obs1, r1, d1, i1) = (e.step(action) for e in envs)
            obs = [obs0, obs1]
            np.testing.assert_array_equal(r0, r1)
            np.testing.assert_array_equal(d0, d1)
            ended |= bool(d0.all())
            for a, b in zip(i0, i1):
                assert a.keys() == b.keys() and a["cost"] == b["cost"]
                if "terminal_observation" in a:
                    for k in a["terminal_observation"]:
                        np.testing.assert_array_equal(a["terminal_observation"][k], b["terminal_observation"][k])
        assert ended  # the episodes ended on the way
        np.testing.assert_array_equal(envs[0].action_masks(), envs[1].action_masks())
    finally:
        for e in envs:
            e.close()


def test_maskable_ppo_runs_on_adapter(tmp_path, small_config):
    pytest.importorskip("sb3_contrib")
    from sb3_contrib import MaskablePPO
    from sb3_contrib.common.maskable.utils import get_action_masks
    from stable_baselines3.common.logger import Logger

    env = TampingSB3VecEnv(2, small_config.replace(dt=2e-4), action_type="discrete", seed=0)
    env.reset()
    assert get_action_masks(env).shape == (2, small_config.n_sections + 1)
    model = MaskablePPO("MultiInputPolicy", env, n_steps=4, batch_size=8, n_epochs=1, seed=0, device="cpu")
    model.set_logger(Logger(None, []))  # SB3's default logger makes a folder in the system's temp dir per learn()
    model.learn(8)
    assert model.num_timesteps >= 8


@pytest.mark.slow
def test_ppo_learns_never_tamp_when_geometry_is_free(tmp_path, small_config):
    # Only tamping costs money: never tamping is optimal (return 0); a random policy tamps most steps.
    cfg = small_config.replace(geometry_cost_per_section_year=0.0, alert_cost=0.0, speed_restriction_cost=0.0,
                               immediate_action_cost=0.0, dt=2e-4)
    hp = {"n_steps": 8, "batch_size": 32, "n_epochs": 10, "learning_rate": 3e-3, "ent_coef": 0.0,
          "net_arch": [32, 32], "gamma": 0.5, "action_type": "discrete", "keep_per_sleeper": False,
          "warm_start_rule": None}  # learning from scratch, not from a rule
    path = train("ppo", cfg, total_timesteps=384, n_envs=8, seed=0, out_dir=tmp_path / "run", hyperparams=hp,
                 progress=False, eval_seeds=None, checkpoint_every_s=0, eval_freq=0, verbose=0)
    assert path.exists() and stats_path(path).exists()
    assert (tmp_path / "run" / "vecnormalize.pkl").exists()
    seeds = list(range(100, 108))
    trained = evaluate_one(load_trained(path), cfg, seeds, "discrete").sum_rewards.mean()
    # the random baseline tamps each section with probability 1/2 (in the discrete env: one section in 3/4
    # of the steps); returns are comparable across action types (same costs)
    random = evaluate_one(RandomPolicy(0.5, seed=1), cfg, seeds).sum_rewards.mean()
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["timesteps"] >= 384
    assert random < -30.0
    assert trained > random + 0.5 * abs(random), (trained, random)


def test_ranked_agent_trains_and_answers_in_env_actions(tmp_path, small_config, capsys):
    cfg = small_config.replace(dt=2e-4)
    hp = {"n_steps": 8, "batch_size": 16, "n_epochs": 1, "net_arch": [16], "action_type": "ranked",
          "keep_per_sleeper": False, "initial_tamp_logit": -2.0, "warm_start_rule": None}
    path = train("ppo", cfg, total_timesteps=16, n_envs=2, seed=0, out_dir=tmp_path / "run", hyperparams=hp,
                 progress=True, eval_seeds=[5], eval_freq=8, verbose=0)
    # the progress bar (tqdm; stable-baselines3's own needs rich, which is not installed) ran to its end
    assert "16/16" in capsys.readouterr().err
    policy = load_trained(path)
    assert policy.action_type == "ranked" and policy.name == "ppo"
    env = TampingEnv(cfg)
    obs, _ = env.reset(seed=0)
    action, state = policy.predict(obs, deterministic=True)
    assert state is None and action.shape == (cfg.n_sections,)
    assert env.action_space.contains(np.asarray(action, dtype=np.int8))
    # the initial bias makes "tamp nothing" the likeliest choice: the deterministic answer tamps nothing
    assert not np.any(action)
    # a batch of observations: one answer per row, each the single observation's
    batched = {k: np.stack([v, v]) for k, v in obs.items()}
    actions, _ = policy.predict(batched)
    assert actions.shape == (2, cfg.n_sections)
    np.testing.assert_array_equal(actions[0], action)
    assert path.stat().st_size < 5 * 2**20
    evaluations = json.loads((tmp_path / "run" / "evaluations.json").read_text())
    assert evaluations and evaluations[-1]["timesteps"] >= 16
    # the finished run goes on in place to a new total: same hyper-parameters, config and held-out seeds, the step
    # counter continues from the run's final checkpoint
    more = train(total_timesteps=32, progress=False, verbose=0, resume=tmp_path / "run")
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert more == path and summary["resumed_from_timesteps"] == 16
    assert summary["timesteps"] == 32 and summary["timesteps_this_run"] == 16
    assert [e["timesteps"] for e in json.loads((tmp_path / "run" / "evaluations.json").read_text())] == [8, 16, 24, 32]
    assert load_trained(more).action_type == "ranked"
    meta = json.loads((tmp_path / "run" / "train_meta.json").read_text())
    assert LineConfig.coerce(meta["config"]) == cfg and meta["hyperparams"]["n_steps"] == 8
    with pytest.raises(FileNotFoundError, match="resume"):
        train(total_timesteps=8, resume=tmp_path / "missing", progress=False)


def test_loading_a_missing_model_names_its_path(tmp_path):
    with pytest.raises(FileNotFoundError, match=re.escape(f"no trained model at {tmp_path / 'model.zip'}")):
        load_trained(tmp_path / "model.zip")


def test_hyperparams_in_rl_zoo_form(tmp_path):
    """agents/learning/hyperparams/ppo.yml holds the algorithm's arguments apart from train()'s own options; a user's
    YAML (Zoo form, keyed by env id) or flat JSON overrides it key by key."""
    from trackenv_agents.learning.tamping import _ALGO_KEYS, DEFAULT_HYPERPARAMS, from_zoo, load_hyperparams

    hp = load_hyperparams()
    assert DEFAULT_HYPERPARAMS.suffix == ".yml"
    assert hp["action_type"] == "ranked" and hp["total_timesteps"] == 40960 and hp["net_arch"] == [64, 64]
    assert {k for k in hp if k in _ALGO_KEYS} >= {"n_steps", "batch_size", "learning_rate", "gamma"}
    mine = tmp_path / "mine.yml"
    mine.write_text("trackenv/Tamping-v1:\n  learning_rate: 1.0e-4\n  n_timesteps: 512\n"
                    "  trackenv: {warm_start_rule: null}\n")
    assert load_hyperparams(mine) == {"learning_rate": 1e-4, "total_timesteps": 512, "warm_start_rule": None}
    with pytest.raises(ValueError, match="no entry"):
        load_hyperparams(mine, env_id="trackenv/TampingLine-v0")
    flat = tmp_path / "mine.json"
    flat.write_text(json.dumps({"learning_rate": 1e-4}))
    assert load_hyperparams(flat) == {"learning_rate": 1e-4}
    flat.write_text(json.dumps({"learning_rat": 1e-4}))
    with pytest.raises(ValueError, match="learning_rat"):
        load_hyperparams(flat)
    with pytest.raises(ValueError, match="normalis"):
        from_zoo({"normalize": False})
    with pytest.raises(ValueError, match="policy"):
        from_zoo({"policy": "MlpPolicy"})
