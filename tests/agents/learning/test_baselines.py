"""The baselines' adapters (agents/learning/baselines.py): each kind of trained policy loads from what its trainer
writes and acts through the evaluation harness on one episode of the small line cut to one year (4 steps); a
path that holds no trained policy is refused naming what one holds; a baseline is scored on its own line only.

The RLlib kinds are RLModules of RLlib's default PPO network, built and saved where experiments/train_rllib.py's
checkpoint keeps them (no Ray runtime: the adapters need none); tests/test_experiments_ray.py loads the modules
of real training runs."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from trackenv.envs.line_config import LineConfig, scenario
from trackenv_agents.evaluation.harness import evaluate_one
from trackenv_agents.evaluation.leaderboard import format_leaderboard, run_leaderboard
from trackenv_agents.learning.baselines import (
    RLLIB_SUMMARY,
    baseline_kind,
    load_baseline,
    rllib_module_dir,
    saved_baselines,
)

SMALL = "trackenv/TampingLineSmall-v0"
SHORT = {"horizon_years": 1.0}  # 4 steps


def _assert_acts(policy, config) -> None:
    """One episode through the harness: finite costs, every tamping one the env allowed, and the policy's
    actions on a batch of raw observations are 0/1 per section."""
    result = evaluate_one(policy, config, [3])
    assert np.isfinite(result.cost).all() and result.cost[0] > 0
    assert 0 <= result.section_tampings[0] <= config.n_sections * config.horizon_steps
    from trackenv.envs.problems import make_vector_env

    env = make_vector_env(config, 2)
    obs, _ = env.reset(seed=[0, 1])
    action, _ = policy.predict(obs, deterministic=False)
    assert action.shape == (2, config.n_sections) and set(np.unique(action)) <= {0, 1}
    env.close()


@pytest.fixture(scope="module")
def sb3_model(tmp_path_factory) -> Path:
    """A MaskablePPO of the ranked view trained for 16 line-steps on the short small line."""
    pytest.importorskip("sb3_contrib")
    from trackenv_agents.learning.tamping import train

    out = tmp_path_factory.mktemp("maskable")
    hp = {"algo": "maskable_ppo", "action_type": "ranked", "keep_per_sleeper": False, "warm_start_rule": None,
          "n_steps": 8, "batch_size": 8, "n_epochs": 1}
    return train(config=scenario("small", **SHORT), total_timesteps=16, n_envs=2, out_dir=out, hyperparams=hp,
                 progress=False, eval_seeds=None, checkpoint_every_s=0, verbose=0)


def test_sb3_model_loads_and_acts_on_its_own_line_only(sb3_model) -> None:
    assert baseline_kind(sb3_model) == "sb3"
    policy = load_baseline(sb3_model, name="maskable")
    config = scenario("small", **SHORT)
    assert policy.name == "maskable" and policy.params["kind"] == "sb3"
    assert policy.unfit_for(config) is None
    assert "horizon_years 1.0 (here 10.0)" in policy.unfit_for(scenario("small"))
    assert "n_sections 6 (here 12)" in policy.unfit_for(scenario("default", **SHORT))
    _assert_acts(policy, config)


def test_leaderboard_scores_a_baseline_on_its_line_and_says_where_it_does_not(sb3_model, tmp_path) -> None:
    policy = load_baseline(sb3_model, name="maskable")
    payload = run_leaderboard([SMALL, "trackenv/TampingLine-v0"], rules=["grouped-threshold"],
                              agents={"maskable": policy}, seeds=[0], bound=False, out_dir=tmp_path, **SHORT)
    assert [(r["env"], r["policy"]) for r in payload["results"] if r["policy"] == "maskable"] == [(SMALL, "maskable")]
    assert payload["not_scored"][SMALL] == {}
    assert "n_sections" in payload["not_scored"]["trackenv/TampingLine-v0"]["maskable"]
    assert "Not scored here (each sees the observation of the line it was trained on): maskable." in (
        format_leaderboard(payload))


def test_a_baseline_of_a_line_file_is_refused_naming_the_file_and_how_to_score_it_there(tmp_path):
    """Trained on a line file, refused elsewhere by the file's path and ``--set line=PATH``, not by the whole line
    (kilobytes) and the fields its file sets, also from the config its files saved; fit for the same line read
    from another path; a line given as data is named by its name."""
    from trackenv.envs.line_file import LineDescription
    from trackenv.lines import EXAMPLE
    from trackenv_agents.learning.baselines import TrainedPolicy

    trained = scenario("default", line=str(EXAMPLE), horizon_years=2.0)
    message = TrainedPolicy(None, trained, "run", "sb3", "run.zip").unfit_for(scenario("default"))
    assert message == (f"trained on another line: line {EXAMPLE} (here none), horizon_years 2.0 (here 10.0); score "
                       f"it on its line with --set line={EXAMPLE}")
    saved = LineConfig.coerce(json.loads(json.dumps(trained.to_dict())))  # the config a model's files keep
    assert TrainedPolicy(None, saved, "run", "sb3", "run.zip").unfit_for(scenario("default")) == message
    copy = shutil.copytree(EXAMPLE.parent, tmp_path / "lines") / EXAMPLE.name  # the same line, another path
    assert TrainedPolicy(None, saved, "run", "sb3", "run.zip").unfit_for(
        scenario("default", line=str(copy), horizon_years=2.0)) is None
    unnamed = {k: v for k, v in trained.line.to_dict().items() if k != "source"}
    as_data = trained.replace(line=LineDescription.from_dict(unnamed))
    message = TrainedPolicy(None, as_data, "run", "sb3", "run.zip").unfit_for(scenario("default"))
    assert "line 'Example Valley Line (synthetic)' (here none)" in message
    assert message.endswith("--set line=PATH (the file of 'Example Valley Line (synthetic)')")
    assert len(message) < 300


def _rllib_run(folder: Path, multi_agent: bool) -> Path:
    """A folder as experiments/train_rllib.py writes it, with an untrained RLModule of RLlib's default PPO."""
    pytest.importorskip("ray.rllib")
    from gymnasium import spaces
    from ray.rllib.algorithms.ppo.torch.default_ppo_torch_rl_module import DefaultPPOTorchRLModule
    from ray.rllib.core.rl_module.default_model_config import DefaultModelConfig
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec

    env_config = {"env_id": SMALL, **SHORT, **({"multi_agent": True} if multi_agent else {})}
    if multi_agent:
        from trackenv.envs.multiagent import line_parallel_env

        penv = line_parallel_env(SMALL, **SHORT)
        obs_space = spaces.flatten_space(penv.observation_space("section_0"))
        act_space = penv.action_space("section_0")
    else:
        from trackenv.envs.wrappers import make_ranked

        env = make_ranked(SMALL, flat=True, **SHORT)
        obs_space, act_space = env.observation_space, env.action_space
    spec = RLModuleSpec(module_class=DefaultPPOTorchRLModule, observation_space=obs_space, action_space=act_space,
                        model_config=DefaultModelConfig(fcnet_hiddens=[8]))
    spec.build().save_to_path(str(rllib_module_dir(folder, multi_agent)))
    (folder / RLLIB_SUMMARY).write_text(json.dumps({"env_config": env_config, "history": []}))
    return folder


@pytest.mark.parametrize("multi_agent", [False, True], ids=["flat-ranked", "parameter-shared"])
def test_rllib_module_loads_and_acts(multi_agent, tmp_path, monkeypatch) -> None:
    if multi_agent:
        pytest.importorskip("pettingzoo")
    run = _rllib_run(tmp_path / "run", multi_agent)
    assert baseline_kind(run) == "rllib"
    monkeypatch.chdir(tmp_path)
    policy = load_baseline(Path("run"))  # a relative path, as the command line gives it
    assert policy.name == "run" and policy.params["kind"] == "rllib"
    assert type(policy.policy).__name__ == ("RLlibSectionPolicy" if multi_agent else "RLlibRankedPolicy")
    config = scenario("small", **SHORT)
    assert policy.unfit_for(config) is None and policy.unfit_for(scenario("small")) is not None
    _assert_acts(policy, config)
    assert saved_baselines(tmp_path) == [run]
    assert policy.policy.name == "run" and policy.params["path"] == "run"


def test_paths_without_a_trained_policy_are_refused(tmp_path) -> None:
    with pytest.raises(FileNotFoundError, match="no trained policy at"):
        baseline_kind(tmp_path / "missing.zip")
    with pytest.raises(ValueError, match=f"must hold {RLLIB_SUMMARY}"):
        baseline_kind(tmp_path)
    (tmp_path / "model.zip").write_bytes(b"")
    with pytest.raises(ValueError, match="needs model_obs_stats.json .*save_sb3_policy.* or model_meta.json"):
        baseline_kind(tmp_path / "model.zip")
    (tmp_path / "notes.txt").write_text("")
    with pytest.raises(ValueError, match="a .zip .* or a folder"):
        baseline_kind(tmp_path / "notes.txt")
    # the folder of a trackenv train run (its model.zip inside, no RLlib summary): its .zip is the model
    with pytest.raises(ValueError, match=f"a trained model is its .zip, not the run's folder: give {tmp_path}/model"):
        baseline_kind(tmp_path)
    assert saved_baselines(tmp_path) == [] and saved_baselines(tmp_path / "none") == []


def _rollout_costs(model, env, seeds, masked: bool) -> list[float]:
    """Each seed's episode cost (k€, minus the summed rewards) of ``model`` acting deterministically in ``env``
    (``masked``: with the env's action masks, as MaskablePPO trains)."""
    costs = []
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        total, done = 0.0, False
        while not done:
            extra = {"action_masks": env.get_wrapper_attr("action_masks")()} if masked else {}
            action, _ = model.predict(obs, deterministic=True, **extra)
            obs, reward, terminated, truncated, _ = env.step(action)
            total -= float(reward)
            done = terminated or truncated
        costs.append(total)
    return costs


@pytest.mark.parametrize("env_id, pipeline, algo", [
    (SMALL, "ranked", "ppo"), (SMALL, "env", "ppo"), (SMALL, "multidiscrete", "maskable_ppo"),
    ("trackenv/TampingLineWet-v0", "env", "ppo"), ("trackenv/TampingLineWet-v0", "ranked", "maskable_ppo")])
def test_a_model_trained_in_ones_own_script_is_scored_as_it_acts_in_its_env(env_id, pipeline, algo, tmp_path) -> None:
    """A model trained with SB3 directly (ranked counts on the section-level observation, the env's own actions,
    MultiDiscrete pairs, the choice codes of the wet line, ranked counts of each choice), saved with
    save_sb3_policy: load_baseline scores it on its line with the costs it gets acting in its own env (a
    MaskablePPO with its masks there, as in training), episode by episode, and on no other line."""
    import gymnasium as gym

    from trackenv.envs.wrappers import MultiDiscreteActions, make_ranked
    from trackenv_agents.learning.baselines import save_sb3_policy
    from trackenv_agents.learning.tamping import _algo_class

    env = {"ranked": lambda: make_ranked(env_id, **SHORT), "env": lambda: gym.make(env_id, **SHORT),
           "multidiscrete": lambda: MultiDiscreteActions(gym.make(env_id, **SHORT))}[pipeline]()
    model = _algo_class(algo)("MultiInputPolicy", env, n_steps=8, batch_size=8, n_epochs=1, seed=0, device="cpu")
    model.learn(8)
    path = save_sb3_policy(model, env, tmp_path / "mine.zip")
    assert baseline_kind(path) == "sb3"
    policy = load_baseline(path, name="mine")
    config = env.unwrapped.config
    assert policy.unfit_for(config) is None and "horizon_years" in policy.unfit_for(config.replace(horizon_years=2.0))
    result = evaluate_one(policy, config, [0, 1])
    np.testing.assert_allclose(result.cost, _rollout_costs(model, env, [0, 1], algo == "maskable_ppo"), rtol=1e-9)
    if policy.policy.action_type == "ranked_choices":  # its counts decode on the env's masks: asked for by name
        obs, _ = gym.make(env_id, **SHORT).reset(seed=0)
        with pytest.raises(ValueError, match="policy 'mine' answers in ranked counts of the choices, which decode "
                                             "on the env's action masks"):
            policy.predict(obs)


def test_save_sb3_policy_keeps_the_vecnormalize_statistics(tmp_path) -> None:
    """Trained in a VecNormalize, the saved policy normalises a raw observation with its statistics, as the model
    saw it in training."""
    import gymnasium as gym
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from trackenv_agents.learning.baselines import save_sb3_policy

    venv = VecNormalize(DummyVecEnv([lambda: gym.make(SMALL, **SHORT)]), norm_reward=False)
    model = PPO("MultiInputPolicy", venv, n_steps=8, batch_size=8, n_epochs=1, seed=0, device="cpu")
    model.learn(8)
    policy = load_baseline(save_sb3_policy(model, venv, tmp_path / "normed.zip"))
    raw = venv.get_original_obs()
    theirs = venv.normalize_obs(raw)
    ours = policy.policy.normalize(raw)
    for key, value in theirs.items():
        np.testing.assert_allclose(ours[key], value, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("normalise", [{"norm_obs": False}, {"norm_obs_keys": ["section_sd"]}])
def test_save_sb3_policy_reads_a_vecnormalize_of_some_keys_or_none(normalise, tmp_path) -> None:
    """A VecNormalize of the rewards only, or of some observation keys (a probe's AttributeError and KeyError):
    the saved policy normalises as the model saw in training, the other keys passed as the env gives them."""
    import gymnasium as gym
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from trackenv_agents.learning.baselines import save_sb3_policy

    venv = VecNormalize(DummyVecEnv([lambda: gym.make(SMALL, **SHORT)]), **normalise)
    model = PPO("MultiInputPolicy", venv, n_steps=8, batch_size=8, n_epochs=1, seed=0, device="cpu")
    model.learn(8)
    policy = load_baseline(save_sb3_policy(model, venv, tmp_path / "some.zip"))
    raw = venv.get_original_obs()
    theirs, ours = venv.normalize_obs(raw), policy.policy.normalize(raw)
    for key, value in theirs.items():
        np.testing.assert_allclose(ours[key], value, rtol=1e-6, atol=1e-6)


def test_a_ranked_choices_model_plays_its_episode_plot_with_the_envs_masks(tmp_path) -> None:
    """`trackenv evaluate --model` of a model in ranked counts of the choices failed after its table: the episode
    plot called predict without the env's masks. The plot now calls every policy as the harness does."""
    from sb3_contrib import MaskablePPO

    from trackenv.envs.wrappers import make_ranked
    from trackenv_agents.evaluation.line_compare import plot_line_episode
    from trackenv_agents.learning.baselines import save_sb3_policy

    env = make_ranked("trackenv/TampingLineWet-v0", **SHORT)
    model = MaskablePPO("MultiInputPolicy", env, n_steps=8, batch_size=8, n_epochs=1, seed=0, device="cpu")
    policy = load_baseline(save_sb3_policy(model, env, tmp_path / "ranked.zip"))
    out = plot_line_episode(policy, env.unwrapped.config, 0, str(tmp_path / "episode.png"), action_type="choices")
    assert (tmp_path / "episode.png").stat().st_size > 0 and out.endswith("episode.png")


def test_save_sb3_policy_refuses_what_the_harness_cannot_undo(tmp_path) -> None:
    import gymnasium as gym
    from stable_baselines3 import PPO

    from trackenv.envs.wrappers import make_ranked
    from trackenv_agents.learning.baselines import save_sb3_policy

    flat = make_ranked(SMALL, flat=True, **SHORT)
    with pytest.raises(ValueError, match="trained through FlattenObservation > SectionObservation > RankedActions "
                                         "cannot be scored"):
        save_sb3_policy(PPO("MlpPolicy", flat, n_steps=8, batch_size=8, device="cpu"), flat, tmp_path / "x.zip")
    with pytest.raises(ValueError, match="model must be one of .*got str"):
        save_sb3_policy("model", gym.make(SMALL), tmp_path / "x.zip")
    env = gym.make(SMALL, **SHORT)
    with pytest.raises(ValueError, match="the model's spaces are not env's: it was trained on another env"):
        save_sb3_policy(PPO("MultiInputPolicy", make_ranked(SMALL, **SHORT), n_steps=8, batch_size=8, device="cpu"),
                        env, tmp_path / "x.zip")
    with pytest.raises(ValueError, match="give one env built the same way .*make_ranked"):
        save_sb3_policy(PPO("MultiInputPolicy", env, n_steps=8, batch_size=8, device="cpu"), object(),
                        tmp_path / "x.zip")
    with pytest.raises(ValueError, match="path must end in .zip"):
        save_sb3_policy(PPO("MultiInputPolicy", env, n_steps=8, batch_size=8, device="cpu"), env, tmp_path / "x")
    assert not list(tmp_path.iterdir())  # nothing written by a refusal


class _FixedLogits:
    """An RLModule stand-in: the same action logits for every row of the batch."""

    def __init__(self, logits: np.ndarray) -> None:
        self.logits = np.asarray(logits, dtype=np.float32)

    def forward_inference(self, batch):
        import torch

        return {"action_dist_inputs": torch.as_tensor(np.tile(self.logits, (len(batch["obs"]), 1)))}


def test_a_flat_rllib_run_on_the_choices_decodes_one_count_per_choice() -> None:
    """An RLlib module trained on the flat ranked view of the wet line answers one block of logits per choice: it
    was read as one tamping count (a probe's run scored 33 % below the rule, against twice the rule's cost in its
    own env). Each block's count is now decoded on the env's masks, as the wrapper did in training; without the
    masks it is refused by name. A multi-agent run on the choices is refused, not misread."""
    from trackenv.envs.multiagent import line_parallel_env
    from trackenv.envs.wrappers import make_ranked, ranked_to_choices
    from trackenv_agents.learning.baselines import RLlibRankedPolicy, RLlibSectionPolicy

    env = make_ranked("trackenv/TampingLineWet-v0", flat=True, **SHORT)
    env.reset(seed=0)
    heads = env.get_wrapper_attr("heads")
    line = env.unwrapped
    s = line.config.n_sections
    logits = np.random.default_rng(1).normal(size=len(heads) * (s + 1))
    counts = logits.reshape(len(heads), s + 1).argmax(axis=1)
    keys = list(env.get_wrapper_attr("keys"))
    policy = RLlibRankedPolicy(_FixedLogits(logits), keys, "flat", heads=heads)
    obs, masks = line.current_observation(), line.action_masks()
    batch = {k: np.asarray(v)[None] for k, v in obs.items()}
    action, _ = policy.predict(batch, action_masks=masks[None])
    np.testing.assert_array_equal(action[0], ranked_to_choices(counts, obs, masks, heads))
    with pytest.raises(ValueError, match="'flat' answers in ranked counts of the choices"):
        policy.predict(batch)
    with pytest.raises(ValueError, match="on a line with the choices .* cannot be scored yet"):
        RLlibSectionPolicy(_FixedLogits(np.zeros(7)), line_parallel_env("trackenv/TampingLineWet-v0", **SHORT),
                           line.config, "shared")
