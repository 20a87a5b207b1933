"""Training on TampingLine: hyper-parameters, saving and loading, and a learning smoke test of the counterfactual
policy iteration (and MaskablePPO on the sections as agents)."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("sb3_contrib")

from trackenv.envs.line import TampingLine  # noqa: E402
from trackenv.envs.line_config import scenario  # noqa: E402
from trackenv_agents.learning.line import (  # noqa: E402
    DEFAULT_LINE_PRETRAINED,
    LINE_ENV_ID,
    LINE_ZOO,
    _save_line_policy,
    line_meta_path,
    load_line_trained,
    train_line,
)
from trackenv_agents.learning.tamping import from_zoo, load_hyperparams  # noqa: E402


@pytest.fixture(scope="module")
def fast_line():
    """The small line (6 sections) over 2 years (8 steps) on 12 m segments (21 sleepers, ~3x faster physics):
    for tests of the learner, not of the line's calibration."""
    return scenario("small", horizon_years=2.0, segment_length_m=12.0)


def test_line_hyperparams_entry_and_its_schema(tmp_path):
    hp = load_hyperparams(env_id=LINE_ENV_ID, schema=LINE_ZOO)
    assert hp["algo"] == "maskable_ppo" and hp["advisor"] == "grouped-threshold" and hp["iterations"] >= 1
    assert hp["net_arch"] == [64, 64] and "clip_obs" not in hp
    with pytest.raises(ValueError, match="normalize"):
        from_zoo({"policy": "MlpPolicy", "normalize": True}, LINE_ZOO)
    with pytest.raises(ValueError, match="policy_kwargs"):
        from_zoo({"policy": "MlpPolicy", "policy_kwargs": {"activation_fn": "relu"}}, LINE_ZOO)
    with pytest.raises(ValueError, match="policy must be MlpPolicy"):
        from_zoo({"policy": "MultiInputPolicy"}, LINE_ZOO)
    with pytest.raises(ValueError, match="clip_obs"):
        train_line("small", hyperparams={"clip_obs": 5.0}, out_dir=tmp_path, progress=False, verbose=0)
    for key, value in (("reward_scale", 0.0), ("iterations", -1), ("focus_rate", 1.5), ("fit_margin", -1.0)):
        with pytest.raises(ValueError, match=key):
            train_line("small", hyperparams={key: value}, out_dir=tmp_path, progress=False, verbose=0)
    with pytest.raises(ValueError, match="advisor must be one of"):
        train_line("small", hyperparams={"advisor": "oracle"}, out_dir=tmp_path, progress=False, verbose=0)
    # the planner may advise, where it can plan, and not the PPO stage (its section agents ask without a history)
    with pytest.raises(ValueError, match="measured every step"):
        train_line("small", hyperparams={"advisor": "model-predictive"}, out_dir=tmp_path, progress=False, verbose=0)
    with pytest.raises(ValueError, match="total_timesteps must be 0"):
        train_line("track60", total_timesteps=8, hyperparams={"advisor": "model-predictive"}, out_dir=tmp_path,
                   progress=False, verbose=0)


def test_a_run_says_first_how_much_it_will_train(tmp_path, capsys):
    """A new run's first line says its policy iterations and PPO line-steps, and what sets them (a small
    ``--timesteps`` does not make a short run)."""
    train_line("small", iterations=0, total_timesteps=0, n_envs=1, out_dir=tmp_path, eval_seeds=None,
               progress=False, verbose=1)
    first = capsys.readouterr().out.splitlines()[0]
    assert first == ("[start] 0 policy iterations of 16 training episodes each (minutes each on two cores), then 0 "
                     "line-steps of maskable_ppo: iterations and total_timesteps (--iterations, --timesteps) set them")


def test_saved_policy_loads_with_its_advisor_and_acts_the_same(tmp_path, fast_line):
    from sb3_contrib import MaskablePPO

    from trackenv_agents.learning.imitation import teacher_policy
    from trackenv_agents.learning.line import _feature_names
    from trackenv_agents.learning.line_policy import LineAgent
    from trackenv_agents.learning.sb3_vec import SectionAgentsVecEnv

    rule = teacher_policy("grouped-threshold", fast_line)
    model = MaskablePPO("MlpPolicy", SectionAgentsVecEnv(1, fast_line, advisor=rule), seed=0, device="cpu")
    meta = {"features": _feature_names(True), "advisor": rule.name, "advisor_params": rule.params}
    path = _save_line_policy(model, tmp_path / "line.zip", meta)
    assert json.loads(line_meta_path(path).read_text())["algo"] == "maskable_ppo"
    assert path.stat().st_size < 128 * 1024  # ships in the repository
    loaded = load_line_trained(path)
    assert loaded.advisor.params == rule.params
    default = scenario("default")
    obs, _ = TampingLine(default).reset(seed=5)  # any line length
    batched = {k: v[None] for k, v in obs.items()}
    np.testing.assert_allclose(loaded.bind(default).tamp_probability(batched),
                               LineAgent(model.policy, advisor=rule).bind(default).tamp_probability(batched), rtol=1e-6)
    meta["features"] = meta["features"][:-1]
    line_meta_path(path).write_text(json.dumps({"algo": "maskable_ppo", **meta}))
    with pytest.raises(ValueError, match="features"):
        load_line_trained(path)
    with pytest.raises(FileNotFoundError, match="no trained line policy"):
        load_line_trained(tmp_path / "missing.zip")


@pytest.mark.slow
def test_policy_iteration_improves_over_its_start(tmp_path, fast_line, capsys):
    """The advisor, and so the first policy, is a bad rule: tamp every section whenever allowed (a section
    threshold of 0 mm), with tamping at 10 k€ a section. One iteration of counterfactual forks finds that most
    of those tampings cost more than they save: the learnt policy's cost on held-out episodes falls below half
    the rule's, paired on the same episodes. Then a few MaskablePPO updates on the section agents run from it,
    with the same evaluation."""
    cfg = fast_line.replace(tamping_cost_per_m=0.05)
    hp = {"advisor": "section-threshold", "advisor_params": {"threshold_mm": 0.0}, "episodes_per_iteration": 6,
          "fit_epochs": 30, "net_arch": [32, 32], "n_steps": 8, "batch_size": 48, "n_epochs": 1, "eval_freq": 16}
    path = train_line(cfg, iterations=1, total_timesteps=12, n_envs=1, seed=20_000, out_dir=tmp_path / "run",
                      hyperparams=hp, progress=True, eval_seeds=list(range(100, 106)), verbose=1)
    # 12 line-steps of 6 section agents, in roll-outs of 8 steps of the 6: two whole roll-outs, said so
    assert "total_timesteps=12 line-steps run as 2 roll-outs, 16 line-steps" in capsys.readouterr().out
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    (it,) = summary["iterations"]
    start, learnt = summary["baseline"]["mean_cost"], it["evaluation"]["mean_cost"]
    assert it["samples"] > 20 and it["other_choice_cheaper"] > 0.3
    assert learnt < 0.5 * start, (start, learnt)
    assert it["evaluation"]["vs_baseline"]["ci_high"] < 0
    assert summary["line_steps_per_second"] > 0 and summary["ppo"]["line_steps"] == 12
    assert summary["ppo"]["line_steps_run"] == 16
    assert summary["ppo"]["evaluations"] and (tmp_path / "run" / "best_model.zip").exists()
    assert (tmp_path / "run" / "checkpoints" / "iteration_0.zip").exists()
    assert list((tmp_path / "run" / "policy_iteration").glob("events.out.tfevents*"))  # TensorBoard
    agent = load_line_trained(path).bind(cfg)
    obs, _ = TampingLine(cfg).reset(seed=7)
    assert agent.predict(obs)[0].shape == (6,)


def test_cli_scores_the_given_line_policy_and_skips_a_missing_shipped_one(tmp_path, monkeypatch):
    import argparse

    import trackenv_agents.cli as cli

    assert cli.SHIPPED_AGENTS["cpi-agent"] == DEFAULT_LINE_PRETRAINED
    monkeypatch.setitem(cli.SHIPPED_AGENTS, "cpi-agent", tmp_path / "none.zip")
    monkeypatch.setitem(cli.SHIPPED_AGENTS, "cpi-track60-agent", tmp_path / "none.zip")
    line = "trackenv/TampingLine-v0"
    args = argparse.Namespace(policy="all", model=None, env=line)
    assert cli._line_policies(args) == {}
    with pytest.raises(cli.UsageError, match="no trained line policy"):
        cli._line_policies(argparse.Namespace(policy="agent", model=None, env=line))
    assert cli._line_policies(argparse.Namespace(policy="rules", model="whatever.zip", env=line)) == {}
    # the 60 m track measures every step without error: the model-predictive planner joins the rules there
    track60 = "trackenv/Tamping-v1"
    assert list(cli._line_policies(argparse.Namespace(policy="all", model=None, env=track60))) == ["model-predictive"]
    only_agent = argparse.Namespace(policy="agent", model=str(DEFAULT_LINE_PRETRAINED), env=track60)
    # a model is named by its folder and file (the shipped agent's file by the agent's name, patched away here)
    assert list(cli._line_policies(only_agent)) == ["pretrained/ppo_tamping_line"]


@pytest.mark.parametrize("name", ["small", "default", "hard"])
def test_shipped_line_policy_loads_and_acts_within_the_lines_rules(name):
    """The shipped policy (one network for every section) runs on every scenario: its actions are one 0/1 per
    section, within the campaign's capacity, never on a section the env masks."""
    assert DEFAULT_LINE_PRETRAINED.exists()
    cfg = scenario(name)
    agent = load_line_trained().bind(cfg)
    assert agent.advisor is not None and agent.advisor.name == "grouped-threshold"
    env = TampingLine(cfg)
    obs, _ = env.reset(seed=3)
    for _ in range(3):
        action, _ = agent.predict(obs)
        assert action.shape == (cfg.n_sections,) and set(np.unique(action)) <= {0, 1}
        assert action.sum() <= cfg.capacity and not (action.astype(bool) & ~env.action_masks()[1::2]).any()
        obs, _, _, _, info = env.step(action)
        assert not info["clipped"]


def test_shipped_60m_agent_plays_with_its_planner_advisor():
    """The shipped agent of the 60 m track: the network with the model-predictive planner as advisor, whose SD
    history is its recurrent state; it runs where the planner can plan (a line measured every step)."""
    from trackenv_agents.shipped import TRACK60_AGENT_NAME, TRACK60_PRETRAINED_FILE

    agent = load_line_trained(TRACK60_PRETRAINED_FILE, name=TRACK60_AGENT_NAME)
    assert agent.advisor.name == "model-predictive" and agent.observation_state
    assert agent.unfit_for(scenario("default")) is not None
    cfg = scenario("track60")
    assert agent.unfit_for(cfg) is None
    agent = agent.bind(cfg)
    env = TampingLine(cfg)
    obs, _ = env.reset(seed=3)
    state = None
    for t in range(3):
        action, state = agent.predict({k: v[None] for k, v in obs.items()}, state=state,
                                      episode_start=np.array([t == 0]))
        assert action.shape == (1, cfg.n_sections) and state[0].shape[1] == t + 1  # the SD seen so far
        obs, *_ = env.step(action[0])


def test_a_best_iteration_dearer_than_the_advisor_is_warned_of():
    """The probe's one-iteration run saved a policy that never tamps, +269.8 k€ [+38.6, +642.6] against its
    advisor, and said nothing: one warning line where the CI lies above zero; none where it reaches zero or below,
    nor on one episode (no CI)."""
    from trackenv_agents.learning.line import dearer_than_advisor

    def evaluation(mean: float, low: float, high: float, n: int = 16) -> dict:
        return {"mean_cost": 900.0, "vs_baseline": {"b": "grouped-threshold", "n_episodes": n,
                                                    "mean_difference": mean, "ci_low": low, "ci_high": high}}

    warning = dearer_than_advisor(evaluation(269.8, 38.6, 642.6))
    assert warning is not None and "\n" not in warning
    assert warning.startswith("warning: the best held-out iteration costs +269.8 k€ [+38.6, +642.6] per episode "
                              "more than its advisor grouped-threshold: the rule stays the better policy; more "
                              "iterations (--iterations) or training episodes")
    assert dearer_than_advisor(evaluation(20.0, 0.0, 40.0)) is None
    assert dearer_than_advisor(evaluation(-13.7, -15.8, -11.6)) is None
    assert dearer_than_advisor(evaluation(269.8, 269.8, 269.8, n=1)) is None
