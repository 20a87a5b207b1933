"""The command line as a person meets it: help, version, refused input, what each command prints."""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from trackenv_agents.cli import main

HERE = Path(__file__).resolve().parent


@pytest.mark.slow
def test_evaluate_on_the_60m_track_prints_one_json_object(tmp_path, capsys):
    """`trackenv evaluate --env trackenv/Tamping-v1`: two rules with their shipped parameters and the 60 m track's
    shipped agent on two held-out episodes of the 60 m track, paired."""
    argv = ["evaluate", "--env", "trackenv/Tamping-v1", "--seeds", "0:2", "--rules", "uniform-periodic,no-maintenance",
            "--batch-size", "6", "--json", "--out", str(tmp_path)]
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["env"] == "trackenv/Tamping-v1" and out["scenario"] == "track60" and out["seeds"] == [0, 1]
    rows = out["results"]
    # with the model-predictive planner: the 60 m track measures every step without error
    assert {row["policy"] for row in rows} == {"uniform-periodic", "no-maintenance", "cpi-track60-agent",
                                              "model-predictive"}
    for row in rows:
        assert row["n_episodes"] == 2 and row["ci_low"] <= row["mean_cost"] <= row["ci_high"]
    costs = [row["mean_cost"] for row in rows]
    assert costs == sorted(costs)
    assert out["extra"] == ["cpi-track60-agent", "model-predictive"]
    assert out["best_rule"] in {"uniform-periodic", "no-maintenance"}
    for name in ("line_compare.json", "line_compare.png", "line_episode.png"):
        assert (tmp_path / name).exists(), name


BASELINE = Path(__file__).resolve().parents[1] / "experiments" / "saved" / "baselines" / "maskable-ppo-ranked.zip"


def test_evaluate_scores_a_model_of_the_standard_libraries_and_refuses_it_on_another_line(tmp_path, capsys):
    """`--model` takes what `trackenv train` writes (an SB3 .zip with its observation statistics), not only a
    per-section policy: scored on the line it was trained on, named by its folder and file; refused in one line
    naming the fields that differ on another line, or by `trackenv plan` on a line file."""
    pytest.importorskip("sb3_contrib")
    argv = ["evaluate", "--env", "trackenv/TampingLine-v0", "--model", str(BASELINE), "--policy", "agent",
            "--seeds", "0:1", "--rules", "grouped-threshold", "--json", "--out", str(tmp_path)]
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["extra"] == ["baselines/maskable-ppo-ranked"]
    assert {row["policy"] for row in out["results"]} == {"grouped-threshold", "baselines/maskable-ppo-ranked"}
    argv[2] = "trackenv/TampingLineSmall-v0"
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"trackenv evaluate: --model {BASELINE} cannot be scored on trackenv/TampingLineSmall-v0: "
                          "trained on another line: ") and err.count("\n") == 1
    line = Path(__file__).resolve().parents[1] / "trackenv" / "lines" / "example.yaml"
    assert main(["plan", str(line), "--policy", str(BASELINE), "--years", "0.5", "--out", str(tmp_path)]) == 2
    assert "cannot run on this line: trained on another line" in capsys.readouterr().err


def test_evaluate_prints_the_table_and_where_the_plots_are(tmp_path, capsys, monkeypatch):
    """The comparison itself is stubbed (it runs end to end in the test above): the printing is under test, and
    what reaches the comparison (the default env is the default line)."""
    import trackenv_agents.evaluation.line_compare as lc
    from trackenv.envs.line_config import scenario
    from trackenv_agents.rules.line import UniformPeriodic

    params = UniformPeriodic(interval_years=3.5).bind(scenario("track60")).params
    row = {"policy": "uniform-periodic", "params": params, "n_episodes": 2, "mean_cost": 10.0, "ci_low": 9.0,
           "ci_high": 11.0, "immediate_action_exceedances": 0, "vs_best": None}
    seen = {}

    def fake(env_id, out_dir, **kw):
        seen.update(env_id=env_id, out_dir=out_dir, **kw)
        return {"env": env_id, "scenario": "track60", "seeds": [0, 1], "tuned_from": "shipped",
                "best_rule": "uniform-periodic", "extra": [], "results": [row],
                "plot": f"{out_dir}/line_compare.png", "episode_plot": f"{out_dir}/line_episode.png"}

    monkeypatch.setattr(lc, "line_comparison", fake)
    assert main(["evaluate", "--env", "trackenv/Tamping-v1", "--policy", "rules", "--out", str(tmp_path)]) == 0
    assert seen["env_id"] == "trackenv/Tamping-v1" and seen["out_dir"] == str(tmp_path) and seen["extra"] == {}
    assert seen["seeds"] is None and seen["rules"] is None and not seen["retune"]
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("trackenv/Tamping-v1 (track60), 2 held-out episodes")
    shown = next(line for line in out if line.startswith("uniform-periodic"))
    assert shown.endswith("interval_years=3.5, offset_years=0.0")  # its parameters, not the calendar it is bound to
    assert out[-1].startswith(f"plots: {tmp_path}/line_compare.png, {tmp_path}/line_episode.png (episode 0 under "
                              "uniform-periodic")
    assert main(["evaluate", "--policy", "rules", "--out", str(tmp_path)]) == 0
    assert seen["env_id"] == "trackenv/TampingLine-v0"


def test_train_seed_default_is_the_training_seed_of_agents_train():
    pytest.importorskip("stable_baselines3")
    from trackenv_agents.cli import build_parser
    from trackenv_agents.learning.tamping import DEFAULT_TRAIN_SEED

    assert build_parser().parse_args(["train"]).seed == DEFAULT_TRAIN_SEED


def test_train_json_prints_one_json_object(tmp_path, capsys):
    """``trackenv train --json``: exactly one JSON object on stdout (the training log and the progress bar stay
    off it), naming the saved model."""
    hp = tmp_path / "hp.json"
    hp.write_text(json.dumps({"n_steps": 8, "batch_size": 16, "n_epochs": 1, "net_arch": [16],
                              "warm_start_rule": None}))
    assert main(["train", "--json", "--timesteps", "16", "--n-envs", "2", "--hyperparams", str(hp),
                 "--out", str(tmp_path / "run")]) == 0
    payload = json.loads(capsys.readouterr().out)
    assert payload["model"].endswith("model.zip") and (tmp_path / "run" / "model.zip").exists()


def test_train_line_options_are_refused_where_they_do_not_apply(capsys):
    for env in ([], ["--env", "trackenv/Tamping-v1"]):  # the 60 m track's trainer has no policy iteration
        assert main(["train", *env, "--iterations", "2"]) == 2
        assert "--iterations" in capsys.readouterr().err
    assert main(["train", "--env", "trackenv/TampingLineSmall-v0", "--algo", "ppo"]) == 2
    assert "hyper-parameter file" in capsys.readouterr().err
    assert main(["train", "--env", "trackenv/Tamping-v9"]) == 2  # not a registered id
    # the network's policy is a line's: trained on the line, played on every line of the network
    assert main(["train", "--env", "trackenv/TampingNetwork-v0", "--iterations", "1"]) == 2
    assert "train it on the network's line (--env trackenv/TampingLine-v0)" in capsys.readouterr().err


@pytest.mark.parametrize("command", [["evaluate", "--seeds", "0:1"], ["leaderboard"], ["train"]])
def test_a_line_or_network_file_as_env_says_what_to_give_instead(command, capsys, tmp_path):
    """``--env FILE.yaml`` is no env id: a line file is refused in one line giving the id and ``--set line=PATH``
    (was: "not a registered env id"), a network file naming the plan and NetworkRule instead."""
    from trackenv.lines import EXAMPLE, EXAMPLE_NETWORK

    name, *rest = command
    assert main([name, "--env", str(EXAMPLE), *rest, "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is a line file, not an env id" in err
    assert f"--env trackenv/TampingLine-v0 --set line={EXAMPLE}" in err and f"trackenv plan {EXAMPLE}" in err
    assert main([name, "--env", str(EXAMPLE_NETWORK), *rest, "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is a network file, not an env id" in err
    assert f"trackenv plan {EXAMPLE_NETWORK}" in err and "NetworkRule(...).bind(config)" in err


@pytest.mark.parametrize("env", [[], ["--env", "trackenv/TampingLine-v0"]])
@pytest.mark.parametrize("field", ["bogus", "n_lines"])
def test_train_refuses_an_unknown_set_field_as_evaluate_does(env, field, capsys):
    """``trackenv train --set FIELD=...`` with no such field of the line's config: evaluate's one line naming it
    and the known fields, exit status 2 (was Python's TypeError traceback)."""
    assert main(["train", *env, "--set", f"{field}=2"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"trackenv train: unknown LineConfig key(s) ['{field}']; ") and err.count("\n") == 1
    assert " known: ['alert_cost'" in err


def test_evaluate_ray_options_parse():
    from trackenv_agents.cli import build_parser

    args = build_parser().parse_args(["evaluate", "--ray-address", "ray://head:10001", "--batch-size", "8"])
    assert args.ray_address == "ray://head:10001" and args.batch_size == 8 and not args.ray
    assert build_parser().parse_args(["evaluate", "--ray"]).ray


def test_evaluate_ray_reaches_the_line_comparison(monkeypatch, capsys):
    """`--ray` hands the line's comparison (not only the tamping one) a Ray executor, closed after; Ray itself is
    not started (the stub runs nothing): the same results over Ray are tested in tests/agents/test_distributed.py."""
    import trackenv_agents.evaluation.line_compare as lc
    from trackenv_agents.evaluation.distributed import RayExecutor

    seen = {}

    def fake(env_id, **kw):
        seen.update(kw)
        return {"env": env_id, "scenario": "small", "seeds": [0, 1], "tuned_from": "-", "results": []}

    monkeypatch.setattr(lc, "line_comparison", fake)
    closed = []
    monkeypatch.setattr(RayExecutor, "close", lambda self: closed.append(self))
    assert main(["evaluate", "--env", "trackenv/TampingLineSmall-v0", "--seeds", "0:2", "--ray", "--json"]) == 0
    assert isinstance(seen["executor"], RayExecutor) and closed == [seen["executor"]]
    assert json.loads(capsys.readouterr().out)["ray"] == "local"
    assert main(["evaluate", "--env", "trackenv/TampingLineSmall-v0", "--seeds", "0:2", "--json"]) == 0
    assert seen["executor"] is None and json.loads(capsys.readouterr().out)["ray"] is None


def test_a_trained_agent_scored_at_another_horizon_is_noted(tmp_path, capsys):
    """``--set horizon_years=1`` scores the shipped agent, trained on 10-year episodes, in 1-year ones: stderr says
    so (its time feature runs 10 times as fast); at the preset's horizon, nothing."""
    argv = ["evaluate", "--env", "trackenv/TampingLineSmall-v0", "--seeds", "0:1", "--rules", "grouped-threshold",
            "--out", str(tmp_path)]
    assert main([*argv, "--set", "horizon_years=1"]) == 0
    assert ("trackenv evaluate: note: cpi-agent was trained on 10-year episodes and is scored here on 1-year ones of "
            "trackenv/TampingLineSmall-v0 (--set horizon_years): its time feature, the share of the episode gone, now "
            "runs 10 times as fast as it learnt it") in capsys.readouterr().err
    assert main([*argv, "--set", "horizon_years=10"]) == 0
    assert "note:" not in capsys.readouterr().err


def test_a_capacity_above_a_line_files_sections_is_noted(tmp_path, capsys):
    """``--set capacity=50`` on the 30-section branch: the config cuts it to 30 (documented), and evaluate says so
    on stderr (plan refuses it); within the sections, nothing."""
    from trackenv.lines import EXAMPLE

    branch = str(Path(EXAMPLE).parent / "example_branch.yaml")
    argv = ["evaluate", "--env", "trackenv/TampingLine-v0", "--set", f"line={branch}", "--set", "horizon_years=0.5",
            "--seeds", "0:1", "--rules", "grouped-threshold", "--policy", "rules", "--out", str(tmp_path)]
    assert main([*argv, "--set", "capacity=50"]) == 0
    assert ("trackenv evaluate: note: --set capacity=50 is more than the line file's 30 sections: the line's "
            "capacity is 30") in capsys.readouterr().err
    assert main([*argv, "--set", "capacity=8"]) == 0
    assert "note:" not in capsys.readouterr().err


def test_set_changes_a_field_of_the_scenario_and_the_table_says_so(tmp_path, capsys):
    """``--set FIELD=VALUE`` scores a variant of the preset from the command line (it had no way to): the JSON
    records the config and what changed, the table's first line names the changes; a misspelt field or a value out
    of range is one line naming it."""
    argv = ["evaluate", "--env", "trackenv/TampingLineSmall-v0", "--seeds", "0:1", "--rules", "grouped-threshold",
            "--set", "horizon_years=1", "--out", str(tmp_path)]
    assert main([*argv, "--json"]) == 0
    base = json.loads(capsys.readouterr().out)
    assert main([*argv, "--set", "annual_mgt=30", "--json"]) == 0
    heavy = json.loads(capsys.readouterr().out)
    assert heavy["config"]["annual_mgt"] == 30 and base["config"]["annual_mgt"] != 30
    assert heavy["config_changes"] == {"annual_mgt": 30.0, "horizon_years": 1.0}
    cost = {r["policy"]: r["mean_cost"] for r in base["results"]}
    assert all(r["mean_cost"] != cost[r["policy"]] for r in heavy["results"])
    assert main([*argv, "--set", "annual_mgt=30"]) == 0
    assert capsys.readouterr().out.splitlines()[0].endswith("; changed: annual_mgt=30.0, horizon_years=1.0")
    for bad, message in (("annual_mgtt=30", "unknown LineConfig key(s) ['annual_mgtt']"),
                         ("annual_mgt=-3", "annual_mgt must lie in [0.1, 200], got -3")):
        assert main([*argv, "--set", bad]) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1
    with pytest.raises(SystemExit):
        main([*argv, "--set", "annual_mgt"])
    assert "--set: expected FIELD=VALUE (e.g. annual_mgt=30), got 'annual_mgt'" in capsys.readouterr().err
    for extra, message in ((["--set", "annual_mgt=30", "--set", "annual_mgt=40"],
                            "--set annual_mgt: given more than once"),
                           (["--set", "engine=classic", "--engine", "fast"], "--set engine and --engine: give one"),
                           (["--set", "pass_reuse_tolerance_m=0", "--pass-reuse-mm", "1"],
                            "--set pass_reuse_tolerance_m and --pass-reuse-mm: give one")):
        assert main([*argv, *extra]) == 2 and message in capsys.readouterr().err
    assert main([*argv, "--set", "pass_reuse_tolerance_m=1e-3", "--json"]) == 0  # (YAML 1.1 read 1e-3 as text)
    assert json.loads(capsys.readouterr().out)["config"]["pass_reuse_tolerance_m"] == 1e-3


def test_set_takes_a_networks_line_fields_as_the_output_names_them(tmp_path, capsys):
    """On the network a line field is reported as line_config.FIELD; --set takes that name back."""
    argv = ["evaluate", "--env", "trackenv/TampingNetwork-v0", "--seeds", "0:1", "--rules", "grouped-threshold",
            "--policy", "rules", "--set", "line_config.horizon_years=0.5", "--set", "n_lines=2", "--json",
            "--out", str(tmp_path)]
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["config_changes"] == {"n_lines": 2, "line_config.horizon_years": 0.5}


def test_plan_takes_set_and_says_what_changed(tmp_path, capsys):
    """``trackenv plan --set capacity=3`` plans with three sections a possession and says so; a field the line file
    sets is refused naming the file's value."""
    from trackenv.lines import EXAMPLE

    argv = ["plan", str(EXAMPLE), "--years", "0.25", "--futures", "1", "--engine", "fast", "--pass-reuse-mm", "1",
            "--out", str(tmp_path)]
    assert main([*argv, "--set", "capacity=3", "--json"]) == 0
    payload = json.loads(capsys.readouterr().out)
    assert payload["config_changes"] == {"capacity": 3}
    assert all(len(q["tamp"]) <= 3 for q in payload["quarters"])
    assert main([*argv, "--set", "annual_mgt=3"]) == 2
    assert "annual_mgt=3 conflicts with the line file" in capsys.readouterr().err
    for field, own in (("line=other.yaml", "the line file argument"), ("horizon_years=3", "--years")):
        assert main([*argv, "--set", field]) == 2
        assert f"the plan takes it from {own}" in capsys.readouterr().err  # (line= was a TypeError traceback)


def test_engine_options_reach_the_comparison_and_the_trainers_and_are_checked(monkeypatch, capsys, tmp_path):
    """``--engine`` and ``--pass-reuse-mm`` (mm on the command line, metres in the config) reach `evaluate`'s
    comparison as config overrides and the table's first line names them; `train` builds the line's config (and
    the 60 m track's) with them; none given: no override (the presets' classic engine, every saved result's).
    Out of range or with --resume: one line and exit status 2. (The two engines' costs are compared in
    tests/envs/test_line_engine.py and tests/envs/test_line_pass_reuse.py.)"""
    import trackenv_agents.evaluation.line_compare as lc
    import trackenv_agents.learning.line as line_learning
    import trackenv_agents.learning.tamping as tamping
    from trackenv.envs.line_config import LINE_ENGINES, MAX_PASS_REUSE_TOLERANCE_M
    from trackenv_agents import cli

    assert cli.ENGINES == LINE_ENGINES and cli.MAX_PASS_REUSE_MM == MAX_PASS_REUSE_TOLERANCE_M * 1e3
    seen = {}

    def fake(env_id, **kw):
        seen.clear()
        seen.update(kw)
        config = lc.env_config(env_id, **{k: v for k, v in kw.items() if k in
                                          ("engine", "pass_reuse_tolerance_m")}).to_dict()
        return {"env": env_id, "scenario": "small", "seeds": [0], "tuned_from": "shipped", "results": [],
                "config": config}

    monkeypatch.setattr(lc, "line_comparison", fake)
    argv = ["evaluate", "--env", "trackenv/TampingLineSmall-v0", "--policy", "rules"]
    assert main([*argv, "--engine", "fast", "--pass-reuse-mm", "1"]) == 0
    assert seen["engine"] == "fast" and seen["pass_reuse_tolerance_m"] == pytest.approx(1e-3)
    assert capsys.readouterr().out.splitlines()[0].endswith("parameters shipped, engine fast, pass reuse 1 mm")
    assert main(argv) == 0
    assert "engine" not in seen and "pass_reuse_tolerance_m" not in seen
    assert capsys.readouterr().out.splitlines()[0].endswith("parameters shipped")
    assert main([*argv, "--pass-reuse-mm", "2.5"]) == 2
    assert "--pass-reuse-mm must be in [0, 2] mm, got 2.5" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_:  # argparse's own choice check
        main([*argv, "--engine", "quick"])
    assert exit_.value.code == 2 and "--engine: invalid choice: 'quick'" in capsys.readouterr().err

    configs = []
    monkeypatch.setattr(line_learning, "train_line", lambda config, **kw: configs.append(config) or tmp_path / "m.zip")
    monkeypatch.setattr(cli, "_line_payload", lambda path, wall, out, note="": ({}, ""))
    assert main(["train", "--env", "trackenv/TampingLineSmall-v0", "--engine", "fast", "--pass-reuse-mm", "0.5"]) == 0
    assert configs[-1].engine == "fast" and configs[-1].pass_reuse_tolerance_m == pytest.approx(5e-4)
    assert configs[-1].n_sections == lc.env_config("trackenv/TampingLineSmall-v0").n_sections
    assert main(["train", "--env", "trackenv/TampingLineSmall-v0"]) == 0
    assert configs[-1] == "small"  # no override: the preset by name, as before
    monkeypatch.setattr(tamping, "train", lambda **kw: configs.append(kw["config"]) or tmp_path / "m.zip")
    assert main(["train", "--engine", "fast"]) == 0
    assert configs[-1].engine == "fast" and configs[-1].sections_per_segment == 6  # the 60 m track
    assert main(["train", "--resume", str(tmp_path), "--engine", "fast"]) == 2
    assert "a resumed run keeps the config it was started with" in capsys.readouterr().err
    capsys.readouterr()
    assert main(["train", "--set", "capacity=3", "--json"]) == 0  # the JSON says what --set changed
    assert configs[-1].capacity == 3 and json.loads(capsys.readouterr().out)["config_changes"] == {"capacity": 3}


def test_evaluate_line_rules_option(monkeypatch, capsys):
    """`--rules a,b` reaches the comparison as a list, on any preset; an unknown rule name is refused by the
    comparison, naming the rules there are, and an id without per-section actions in one line."""
    import trackenv_agents.evaluation.line_compare as lc

    seen = {}
    real = lc.line_comparison

    def fake(env_id, **kw):
        seen.update(kw)
        return {"env": env_id, "scenario": "small", "seeds": [0, 1], "tuned_from": "-", "results": []}

    monkeypatch.setattr(lc, "line_comparison", fake)
    args = ["evaluate", "--env", "trackenv/TampingLineSmall-v0", "--seeds", "0:2", "--json", "--policy", "rules"]
    assert main(args + ["--rules", "grouped-threshold, uniform-periodic"]) == 0
    assert seen["rules"] == ["grouped-threshold", "uniform-periodic"]
    assert main(args) == 0 and seen["rules"] is None
    assert main(["evaluate", "--env", "trackenv/Tamping-v1", "--policy", "rules", "--json",
                 "--rules", "section-threshold"]) == 0
    assert seen["rules"] == ["section-threshold"]
    capsys.readouterr()
    with pytest.raises(ValueError, match="rules must name line rules among"):
        real("trackenv/TampingLineSmall-v0", rules=["grouped", "uniform-periodic"])
    monkeypatch.setattr(lc, "line_comparison", real)
    assert main(["evaluate", "--env", "trackenv/TampingDiscrete-v1", "--policy", "rules"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "per-section actions" in err


def test_evaluate_scores_the_shipped_agent_of_the_id(monkeypatch, capsys, tmp_path):
    """`trackenv evaluate` scores the agent of the lines with every choice on an id with every choice, the 60 m
    track's agent there, the tamp-or-wait agent elsewhere (the network's lines are tamp-or-wait), and a
    ``--model`` by its folder and file, the shipped agent's file by its name."""
    pytest.importorskip("stable_baselines3")
    import trackenv_agents.evaluation.line_compare as lc
    from trackenv_agents.cli import shipped_agent_for
    from trackenv_agents.learning.line import DEFAULT_LINE_PRETRAINED

    assert {env: shipped_agent_for(env) for env in ("trackenv/TampingLine-v0", "trackenv/Tamping-v1",
                                                    "trackenv/TampingNetwork-v0", "trackenv/TampingLine-v1",
                                                    "trackenv/TampingLineWet-v0", "trackenv/TampingLineDefects-v0")} \
        == {"trackenv/TampingLine-v0": "cpi-agent", "trackenv/Tamping-v1": "cpi-track60-agent",
            "trackenv/TampingNetwork-v0": "cpi-agent", "trackenv/TampingLine-v1": "cpi-choice-agent",
            "trackenv/TampingLineWet-v0": "cpi-choice-agent", "trackenv/TampingLineDefects-v0": "cpi-choice-agent"}
    seen = {}

    def fake(env_id, **kw):
        seen.update(kw)
        return {"env": env_id, "scenario": "wet", "seeds": [0], "tuned_from": "-", "results": []}

    monkeypatch.setattr(lc, "line_comparison", fake)
    assert main(["evaluate", "--env", "trackenv/TampingLineWet-v0", "--seeds", "0:1", "--json"]) == 0
    (name, agent), = seen["extra"].items()
    assert name == "cpi-choice-agent" and agent.name == name and agent.choices  # a choice rule as its advisor
    assert main(["evaluate", "--env", "trackenv/TampingLine-v0", "--seeds", "0:1", "--json"]) == 0
    (name, agent), = seen["extra"].items()
    assert name == "cpi-agent" and not agent.choices
    assert main(["evaluate", "--env", "trackenv/TampingLineWet-v0", "--seeds", "0:1", "--json",
                 "--model", str(DEFAULT_LINE_PRETRAINED)]) == 0
    assert list(seen["extra"]) == ["cpi-agent"]  # a shipped agent's file: the agent's name
    own = tmp_path / "run" / "best_model.zip"  # any other: its folder and file
    own.parent.mkdir()
    shutil.copy(DEFAULT_LINE_PRETRAINED, own)
    shutil.copy(DEFAULT_LINE_PRETRAINED.with_name(DEFAULT_LINE_PRETRAINED.stem + "_meta.json"),
                own.with_name("best_model_meta.json"))
    assert main(["evaluate", "--env", "trackenv/TampingLine-v0", "--seeds", "0:1", "--json", "--model", str(own)]) == 0
    assert list(seen["extra"]) == ["run/best_model"]
    assert main(["evaluate", "--env", "trackenv/Tamping-v1", "--seeds", "0:1", "--json"]) == 0
    (name, agent), *planner = seen["extra"].items()
    assert name == "cpi-track60-agent" and agent.advisor.name == "model-predictive" and agent.observation_state
    assert [n for n, _ in planner] == ["model-predictive"]  # and the planner itself, where it can plan
    capsys.readouterr()


def test_hyperparams_file_is_the_one_agents_train_reads():
    pytest.importorskip("stable_baselines3")
    from trackenv_agents.cli import HYPERPARAMS_FILE
    from trackenv_agents.learning.tamping import DEFAULT_HYPERPARAMS

    assert HYPERPARAMS_FILE == DEFAULT_HYPERPARAMS


def test_help_imports_neither_the_physics_nor_torch():
    """`trackenv --help` must answer at once: the parser is built without importing numba, trackenv or torch."""
    code = ("import sys; from trackenv_agents.cli import build_parser; build_parser(); "
            "heavy = [m for m in ('trackenv', 'numba', 'torch', 'gymnasium', 'scipy') if m in sys.modules]; "
            "print(heavy)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_version_is_the_installed_distribution_version(capsys):
    import importlib.metadata

    import trackenv

    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    expected = importlib.metadata.version("trackenv")
    assert capsys.readouterr().out.strip() == f"trackenv {expected}"
    assert trackenv.__version__ == expected


@pytest.mark.parametrize("command", ["validate", "paper", "bench", "evaluate", "train", "leaderboard"])
def test_every_option_has_help_text(command):
    from trackenv_agents.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices[command]
    for action in sub._actions:
        assert action.help, f"{command} {action.option_strings} has no help text"
    text = " ".join(sub.format_help().split())
    if command == "train":
        assert "(default: 20000)" in text and "hyper-parameter file's, 8" in text
    if command == "paper":
        assert "(default: 6)" in text and "(default: 50000)" in text
    if command == "evaluate":  # --policy agent scores the rules as well: its comparison is with the best of them
        assert "agent, the trained agent (refused where there is none) and the tuned rules it is compared with" in text


@pytest.mark.parametrize("argv", [["train", "--timesteps", "-5"], ["train", "--n-envs", "0"],
                                  ["train", "--timesteps", "1.5"], ["paper", "--iterations", "0"],
                                  ["paper", "--cycles", "nan"], ["evaluate", "--n-train", "-1"],
                                  ["evaluate", "--batch-size", "0"],
                                  ["train", "--seed", "-1"]])
def test_non_positive_counts_are_refused(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "error: argument" in err and "Traceback" not in err
    assert err.count("\n") == 1 and "usage:" not in err  # one line, as every other refusal


def test_a_line_file_on_the_60_m_track_says_how_to_train_on_it(capsys):
    assert main(["train", "--set", "line=my.yaml", "--timesteps", "64"]) == 2
    assert capsys.readouterr().err == (
        "trackenv train: --set line: a line file trains as a line: --env trackenv/TampingLine-v0 --set line=my.yaml "
        "(the default --env, trackenv/Tamping-v1, is the 60 m track: one segment of six sections)\n")


def test_an_unknown_option_is_named_by_its_command(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["plan", "line.yaml", "--bogus", "2"])
    assert exc.value.code == 2
    assert capsys.readouterr().err == ("trackenv plan: error: unrecognized arguments: --bogus 2 (see `trackenv plan "
                                       "--help`)\n")


def test_large_counts_may_be_written_in_exponent_form():
    from trackenv_agents.cli import build_parser

    assert build_parser().parse_args(["train", "--timesteps", "1e5"]).timesteps == 100_000


@pytest.mark.parametrize("argv, message", [
    (["train", "--hyperparams", "/missing.json"], "trackenv train: --hyperparams: no such file: /missing.json"),
    (["train", "--resume", "/missing"], "trackenv train: --resume: no such folder: /missing"),
    (["evaluate", "--model", "/missing.zip"], "trackenv evaluate: --model: no such file: /missing.zip"),
])
def test_missing_paths_give_one_line_not_a_traceback(argv, message, capsys):
    assert main(argv) == 2
    assert capsys.readouterr().err == message + "\n"


def test_broken_hyperparams_file_gives_one_line(tmp_path, capsys):
    pytest.importorskip("stable_baselines3")
    bad = tmp_path / "hp.json"
    bad.write_text('{"n_steps": 8, "no_such_key": 1}')
    assert main(["train", "--hyperparams", str(bad), "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no_such_key" in err


@pytest.mark.parametrize("text, suffix, message", [
    ("root:x:0:0:root:/root:/bin/bash\n", ".json", "not a JSON object of hyper-parameters"),
    ("a: [\n", ".yml", "not a YAML file"),
    ("just words\n", ".yaml", "a mapping of env ids to entries, got str"),
    ("trackenv/Tamping-v1: 3\n", ".yml", "the entry for 'trackenv/Tamping-v1' must be a mapping of settings"),
])
def test_a_hyperparams_file_that_is_not_one_is_refused_naming_it(tmp_path, capsys, text, suffix, message):
    """A file of another kind, broken YAML, or YAML of the wrong shape: one line naming the file, exit 2."""
    pytest.importorskip("stable_baselines3")
    bad = tmp_path / f"hp{suffix}"
    bad.write_text(text)
    assert main(["train", "--hyperparams", str(bad), "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(bad) in err and message in err, err


@pytest.mark.parametrize("command", [["evaluate", "--seeds", "0:1"], ["calibrate"], ["paper"], ["validate"],
                                     ["leaderboard", "--seeds", "0:1"], ["train"]])
def test_an_out_folder_that_cannot_be_made_is_refused_before_the_work(command, tmp_path, capsys, monkeypatch):
    """--out under a file: one line naming the folder, exit 2, and no command ran (it would have failed only when
    it came to write)."""
    import trackenv_agents.cli as cli

    ran = []
    for name in [n for n in vars(cli) if n.startswith("cmd_")]:
        monkeypatch.setattr(cli, name, lambda args, name=name: ran.append(name) or 0)
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    out = blocker / "results"
    assert main([*command, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err == f"trackenv {command[0]}: --out {out}: cannot create the folder (Not a directory)\n"
    assert not ran


def test_the_out_folder_check_leaves_nothing_behind(tmp_path, monkeypatch, capsys):
    """The check makes the missing folders and removes them again: a command that then writes nothing (refused
    for another reason) leaves no folder; an --out that is a file is refused by name."""
    import trackenv_agents.cli as cli

    seen = []
    monkeypatch.setattr(cli, "cmd_calibrate", lambda args: seen.append(Path(args.out).parent.is_dir()) or 0)
    out = tmp_path / "deep" / "er"
    assert main(["calibrate", "--out", str(out)]) == 0
    assert seen == [False] and not (tmp_path / "deep").exists()
    (tmp_path / "f").write_text("")
    assert main(["calibrate", "--out", str(tmp_path / "f")]) == 2
    assert capsys.readouterr().err == f"trackenv calibrate: --out {tmp_path / 'f'}: a file, not a folder\n"


def test_validate_prints_pass_fail_per_check_and_where_it_wrote(tmp_path, capsys, monkeypatch):
    """The heavy passes are stubbed: the command's printing is under test, not the physics."""
    import trackenv_studies.validation as val

    monkeypatch.setattr(val, "_receptance_summary", lambda track: ({
        "static_limit_max_abs_rel_error": 1e-4, "pinned_pinned_rel_error": 0.25}, {}))
    monkeypatch.setattr(val, "_loaded_pass_summary", lambda: ({"sleeper_passing_hz": 37.037}, {}))
    monkeypatch.setattr(val, "_rest_pass_summary", lambda: ({}, ()))
    assert main(["validate", "--no-plots", "--out", str(tmp_path)]) == 1  # one check fails: exit status 1
    out = capsys.readouterr().out
    lines = out.splitlines()
    assert any(line.strip().startswith("PASS  static deflection at x = 15.0 m") for line in lines)
    fail = next(line for line in lines if line.strip().startswith("FAIL"))
    assert "pinned-pinned" in fail and "+25.00 %" in fail
    assert "3 of 4 checks pass" in out
    assert f"wrote summary.json to {tmp_path}" in out
    assert "148148148.148" not in out  # numbers are rounded


def test_compile_builds_what_is_missing_and_then_has_nothing_to_do(capsys):
    """`trackenv compile` (run by `make setup`) leaves no entry of the asked widths to compile; a second run
    builds nothing; a width the kernel has no entry for is refused in one line."""
    from trackenv.physics.kernels import missing_kernels

    assert main(["compile", "--widths", "1", "--json"]) == 0
    first = json.loads(capsys.readouterr().out)
    assert first["missing_after"] == [] and missing_kernels([1]) == []
    assert main(["compile", "--widths", "1", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["compiled"] == []
    assert main(["compile", "--widths", "7"]) == 2
    assert "width must be one of" in capsys.readouterr().err


def test_leaderboard_writes_its_files_and_one_json_object(tmp_path, capsys):
    """The whole command on one short episode of the small line without the bound: one JSON object on stdout, the
    JSON and Markdown files under --out, null scores and the reason in the table, the command as given."""
    argv = ["leaderboard", "--env", "trackenv/TampingLineSmall-v0", "--seeds", "3:4", "--policies",
            "grouped-threshold,uniform-periodic", "--no-bound", "--json", "--out", str(tmp_path)]
    assert main(argv) == 0
    payload = json.loads(capsys.readouterr().out)
    saved = json.loads((tmp_path / "leaderboard.json").read_text())
    assert saved["results"] == payload["results"] and saved["command"] == "trackenv leaderboard " + " ".join(argv[1:])
    assert [r["policy"] for r in payload["results"]][0] == payload["best_rule"]["trackenv/TampingLineSmall-v0"]
    assert {r["policy"] for r in payload["results"]} == {"grouped-threshold", "uniform-periodic"}
    assert all(r["normalised_score"] is None and r["normalised_score_ci"] is None for r in payload["results"])
    assert payload["seeds"] == {"trackenv/TampingLineSmall-v0": [3]}
    table = (tmp_path / "leaderboard.md").read_text()
    assert "No normalised score: not computed (--no-bound)." in table and "| uniform-periodic |" in table


@pytest.mark.parametrize("argv, message", [
    (["--env", "trackenv/Nope-v0"], "leaderboard: --env: 'trackenv/Nope-v0' is not a registered env id"),
    (["--env", "trackenv/TampingLine-v0,"], "--env 'trackenv/TampingLine-v0,': an empty item (a comma too many?)"),
    (["--env", "trackenv/TampingLineSmall-v0, trackenv/TampingLineSmall-v0"],
     "--env trackenv/TampingLineSmall-v0: given more than once"),
    (["--env", "CartPole-v1"], "(the TampingLine ids, trackenv/Tamping-v1, trackenv/TampingNetwork-v0)"),
    (["--seeds", "0:10000000000000"], "--seeds gives 10000000000000 episodes: at most 100000 are allowed"),
    (["--seeds", "0:99999999999999999999"], "--seeds must be at most 9223372036854775807"),
    (["--seeds", "-1:3"], "--seeds must be whole numbers >= 0 (Gymnasium's seeds), got '-1:3'"),
    (["--seeds", "5:2"], "--seeds A:B needs B > A"),
    (["--seeds", "a:b"], "--seeds must be A:B with B > A, or a,b,c: whole numbers >= 0, each once; got 'a:b'"),
    (["--seeds", "1,2,1"], "--seeds must be A:B with B > A"),
    (["--seeds", ","], "--seeds must be A:B with B > A"),
    (["--seeds=-3:2"], "--seeds must be whole numbers >= 0"),
    (["--seeds", "-3,2"], "--seeds must be whole numbers >= 0"),
    (["--policies", "rules,no-such-agent"], "--policies: unknown policy 'no-such-agent'"),
    (["--policies", "cpi-agent"], "--policies names no rule"),
    (["--env", "trackenv/TampingLineSmall-v0", "--policies", "choice-threshold"],
     "--policies: rules must name some of trackenv/TampingLineSmall-v0's rules ['budgeted-worst-first',"),
    (["--policies", "rules,grouped-threshold,grouped-threshold"], "--policies grouped-threshold: given more than "
     "once"),
    (["--policies", "rules,/missing.zip"], "--policies: no trained policy at /missing.zip"),
    (["--policies", f"rules,{HERE}"], f"--policies: {HERE}: a folder of a trained policy must hold rllib_summary.json"),
    (["--policies", f"rules,{HERE / 'conftest.py'}"],
     "conftest.py: the command takes trained policies by path (.zip, or a folder of experiments/train_rllib.py), "
     "not Python code; score a policy object from Python with "
     "trackenv_agents.evaluation.leaderboard.run_leaderboard(agents={'name': policy})"),
    (["--policies", "rules,,no-such-agent"], "--policies 'rules,,no-such-agent': an empty item"),
    (["--policies", "rules,no-such-agent"], "'baselines' or the path of a trained policy"),
    (["--env", "TampingLineSmall-v0"], "did you mean 'trackenv/TampingLineSmall-v0'?"),
    (["--pass-reuse-mm", "3"], "--pass-reuse-mm must be in [0, 2] mm, got 3"),
])
def test_leaderboard_bad_input_is_one_line_and_status_2(argv, message, capsys, tmp_path):
    assert main(["leaderboard", *argv, "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("trackenv leaderboard: ") and message in err and err.count("\n") == 1
    assert not (tmp_path / "leaderboard.json").exists()


@pytest.mark.parametrize("argv, message", [
    (["--threshold", "-1"], "argument --threshold: must be a number > 0, got -1"),
    (["--horizon-years", "0"], "argument --horizon-years: must be a number > 0, got 0"),
    (["--seeds", "3"], None),  # a valid list of one seed is no error: checked below with a short horizon
])
def test_calibrate_bad_input_is_refused_by_name(argv, message, capsys, tmp_path):
    """A threshold or horizon at or below zero is refused by argparse (exit status 2, the option named) instead of
    running a degenerate rule or silently keeping the scenario's horizon; a horizon shorter than a step by the
    config, naming its field."""
    if message is None:
        assert main(["calibrate", *argv, "--horizon-years", "0.1", "--out", str(tmp_path)]) == 2
        assert "horizon_years must lie in [0.25, 100], got 0.1" in capsys.readouterr().err
        return
    with pytest.raises(SystemExit) as exit_:
        main(["calibrate", *argv, "--out", str(tmp_path)])
    assert exit_.value.code == 2 and message in capsys.readouterr().err


def test_leaderboard_ray_reaches_the_leaderboard(monkeypatch, capsys, tmp_path):
    """`--ray` hands the leaderboard a Ray executor (closed after) and the suite defaults to the four scenarios;
    Ray itself is not started (the stub runs nothing): the same numbers over Ray are tested in
    tests/agents/evaluation/test_leaderboard.py."""
    import trackenv_agents.evaluation.leaderboard as lb
    from trackenv_agents.evaluation.distributed import RayExecutor

    seen = {}

    def fake(envs, **kw):
        seen.update(kw, envs=envs)
        return {"results": [], "bound": {}, "seeds": {}, "best_rule": {}}

    monkeypatch.setattr(lb, "run_leaderboard", fake)
    monkeypatch.setattr(RayExecutor, "close", lambda self: None)
    assert main(["leaderboard", "--ray", "--policies", "rules", "--json", "--out", str(tmp_path)]) == 0
    assert isinstance(seen["executor"], RayExecutor) and seen["envs"] == list(lb.DEFAULT_SUITE)
    assert seen["agents"] == {} and seen["rules"] is None and seen["bound"] is True
    assert "engine" not in seen and "pass_reuse_tolerance_m" not in seen  # the presets' passes unless asked
    assert json.loads(capsys.readouterr().out)["ray"] == "local"


def test_leaderboard_engine_options_reach_every_scenarios_config(monkeypatch, capsys, tmp_path):
    """`--engine fast --pass-reuse-mm 1` are config overrides of every scenario (what they do to the bound:
    tests/agents/evaluation/test_leaderboard.py)."""
    import trackenv_agents.evaluation.leaderboard as lb

    seen = {}

    def fake(envs, **kw):
        seen.update(kw)
        return {"results": [], "bound": {}, "seeds": {}, "best_rule": {}}

    monkeypatch.setattr(lb, "run_leaderboard", fake)
    argv = ["leaderboard", "--engine", "fast", "--pass-reuse-mm", "1", "--json", "--out", str(tmp_path)]
    assert main(argv) == 0
    assert seen["engine"] == "fast" and seen["pass_reuse_tolerance_m"] == pytest.approx(1e-3)


def test_leaderboard_policies_baselines_names_the_committed_ones(monkeypatch):
    """`--policies rules,baselines`: every rule and each trained policy of experiments/saved/baselines/ by its
    name, its path relative to the working directory."""
    from trackenv_agents.cli import _leaderboard_policies
    from trackenv_agents.learning.baselines import SAVED_BASELINES, saved_baselines

    monkeypatch.chdir(SAVED_BASELINES.parents[2])
    rules, agents = _leaderboard_policies("rules,baselines", ["grouped-threshold"])
    assert rules is None
    assert agents == {p.stem: str(p.relative_to(SAVED_BASELINES.parents[2])) for p in saved_baselines()}
    assert sorted(agents) == ["maskable-ppo-ranked", "rllib-ppo-ranked", "rllib-shared-ppo"]


def test_leaderboard_names_trained_files_by_their_run_as_evaluate_does(tmp_path, monkeypatch):
    """Two runs' model.zip were named "model" and "/path/run2/model.zip": now "run1/model" and "run2/model", as
    trackenv evaluate names them, however the path is written (relative, absolute, ./model.zip in the run's
    folder); another run's file of the same name is named by its absolute path."""
    from trackenv_agents.cli import _leaderboard_policies, model_label

    files = [tmp_path / run / "model.zip" for run in ("run1", "run2", "other/run2")]
    for f in files:
        f.parent.mkdir(parents=True)
        f.write_bytes(b"")
        (f.parent / "model_obs_stats.json").write_text("{}")
    monkeypatch.chdir(tmp_path)
    rules, agents = _leaderboard_policies(f"rules,run1/model.zip,{files[1]},{files[2]}", ["grouped-threshold"])
    assert agents == {"run1/model": "run1/model.zip", "run2/model": str(files[1]), str(files[2]): str(files[2])}
    monkeypatch.chdir(tmp_path / "run1")
    assert model_label(Path("model.zip")) == model_label(files[0]) == "run1/model"


@pytest.mark.parametrize("given", [["{0}", "{0}"], ["run1/model.zip", "{0}"], ["{0}", "run1/../run1/model.zip"]])
def test_leaderboard_refuses_one_policy_given_twice(given, tmp_path, monkeypatch, capsys):
    """The same model twice (as written, or by another relative or absolute path) was scored twice under two
    names: one line naming --policies and the repeated item, exit status 2, before anything runs."""
    model = tmp_path / "run1" / "model.zip"
    model.parent.mkdir()
    model.write_bytes(b"")
    (model.parent / "model_obs_stats.json").write_text("{}")
    monkeypatch.chdir(tmp_path)
    items = [g.format(model) for g in given]
    assert main(["leaderboard", "--policies", ",".join(["grouped-threshold", *items]), "--out",
                 str(tmp_path / "lb")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("trackenv leaderboard: --policies ")
    assert (f"{items[1]}: given more than once" if items[0] == items[1]
            else f"--policies {items[1]}: the same policy as {items[0]}") in err


def test_a_run_folder_as_model_names_its_zip(tmp_path, capsys):
    """`--model DIR` on the folder of a trackenv train run (model.zip, best_model.zip, no rllib_summary.json) says
    that a trained model is the .zip, naming those there, instead of asking for rllib_summary.json."""
    for name in ("model.zip", "best_model.zip"):
        (tmp_path / name).write_bytes(b"")
    assert main(["evaluate", "--env", "trackenv/TampingLineSmall-v0", "--model", str(tmp_path), "--seeds", "0:1",
                 "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"trackenv evaluate: --model: {tmp_path}: a trained model is its "
                                                  f".zip, not the run's folder: give {tmp_path / 'model.zip'} or "
                                                  f"{tmp_path / 'best_model.zip'}")


@pytest.mark.parametrize("argv, message", [
    (["--seeds", "0:1000000000000"], "--seeds gives 1000000000000 episodes: at most 100000 are allowed"),
    (["--seeds", "-1:3"], "--seeds must be whole numbers >= 0"),
    (["--rules", "foo"], "--rules: rules must name line rules among ['budgeted-worst-first',"),
    (["--rules", "grouped-threshold,"], "--rules 'grouped-threshold,': an empty item"),
    (["--rules", "grouped-threshold, grouped-threshold"], "--rules grouped-threshold: given more than once"),
    (["--env", "trackenv/Nope-v0"], "evaluate: --env: 'trackenv/Nope-v0' is not a registered env id"),
])
def test_evaluate_bad_input_is_one_line_naming_the_option(argv, message, capsys, tmp_path):
    assert main(["evaluate", "--policy", "rules", *argv, "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("trackenv evaluate: ") and message in err and err.count("\n") == 1


def test_the_most_episodes_of_the_help_are_those_parse_seeds_takes():
    """cli.MAX_EPISODES is written out (importing it would load the physics for `trackenv --help`): the same
    number as parse_seeds's."""
    from trackenv_agents import cli
    from trackenv_agents.evaluation.line_compare import MAX_EPISODES

    assert cli.MAX_EPISODES == MAX_EPISODES


def test_a_line_run_dearer_than_its_advisor_ends_with_a_warning(tmp_path):
    """A run whose best held-out iteration costs more than the advisor rule (the CI above zero) ends its summary
    with one warning line (the JSON's "warning"); a run level with the rule ends without one."""
    from trackenv_agents.cli import _line_payload

    def summary(low: float, high: float) -> None:
        d = {"b": "grouped-threshold", "n_episodes": 16, "mean_difference": (low + high) / 2, "ci_low": low,
             "ci_high": high}
        (tmp_path / "summary.json").write_text(json.dumps({"iterations": [
            {"iteration": 0, "evaluation": {"mean_cost": 500.0, "vs_baseline": d}}]}))

    summary(38.6, 642.6)
    payload, human = _line_payload(tmp_path / "model.zip", 1.0, tmp_path, "; changed: capacity=3")
    lines = human.splitlines()
    assert lines[1].endswith("(best_model.zip; export it with experiments/train_line.py --export); changed: capacity=3")
    assert lines[-1] == payload["warning"] and lines[-1].startswith(
        "warning: the best held-out iteration costs +340.6 k€ [+38.6, +642.6] per episode more than its advisor "
        "grouped-threshold: the rule stays the better policy")
    summary(-5.0, 3.0)
    payload, human = _line_payload(tmp_path / "model.zip", 1.0, tmp_path)
    assert payload["warning"] is None and "warning" not in human


def test_a_line_run_with_a_ppo_stage_reports_the_stages_best_model(tmp_path):
    """After a PPO stage, best_model.zip is the best of the stage's own evaluations (its first: the best
    iteration's policy), not the best iteration: the summary names that evaluation (a probe's run said 103.6 k€,
    the iteration's, where best_model.zip cost 89.1)."""
    from trackenv_agents.cli import _line_payload

    def vs(diff: float) -> dict:
        return {"b": "grouped-threshold", "n_episodes": 2, "mean_difference": diff, "ci_low": diff - 30.0,
                "ci_high": diff + 40.0}

    (tmp_path / "summary.json").write_text(json.dumps({
        "iterations": [{"iteration": 0, "evaluation": {"mean_cost": 103.6, "vs_baseline": vs(28.9)}}],
        "ppo": {"evaluations": [{"timesteps": 0, "mean_return": -103.6, "vs_baseline": vs(28.9)},
                                {"timesteps": 62400, "mean_return": -89.1, "vs_baseline": vs(14.4)}]}}))
    _, human = _line_payload(tmp_path / "model.zip", 1.0, tmp_path)
    assert human.splitlines()[1].startswith("best held-out evaluation of the PPO stage (after 62400 section-steps): "
                                            "89.1 k€, vs grouped-threshold +14.4 k€")


def test_leaderboard_policies_name_both_shipped_line_agents():
    """`--policies cpi-agent,cpi-choice-agent`: the two shipped line policies by name, each a per-section policy
    whose metadata names its advisor (the choice rule for the agent of the lines with every choice)."""
    import json

    from trackenv_agents import cli
    from trackenv_agents.learning.line import DEFAULT_CHOICE_PRETRAINED, DEFAULT_LINE_PRETRAINED, line_meta_path

    rules, agents = cli._leaderboard_policies("grouped-threshold,cpi-agent,cpi-choice-agent", ["grouped-threshold"])
    assert rules == ["grouped-threshold"]
    assert agents == {"cpi-agent": str(DEFAULT_LINE_PRETRAINED), "cpi-choice-agent": str(DEFAULT_CHOICE_PRETRAINED)}
    assert all(Path(path).is_file() for path in agents.values())
    assert json.loads(line_meta_path(DEFAULT_CHOICE_PRETRAINED).read_text())["advisor"] == "choice-threshold"


def test_leaderboard_policies_name_the_planner_and_it_is_scored_only_where_it_fits():
    """`--policies rules,model-predictive`: the model-predictive planner, scored on a scenario that measures every
    step without error (the 60 m track) and listed as not scored elsewhere, with the reason."""
    from trackenv.envs.line_config import scenario
    from trackenv_agents import cli
    from trackenv_agents.evaluation.leaderboard import fitting_agents
    from trackenv_agents.rules.model_predictive import ModelPredictive

    rules, agents = cli._leaderboard_policies("rules,model-predictive", ["grouped-threshold"])
    assert rules is None and agents == {"model-predictive": "model-predictive"}
    # every tuned rule and a named one: both reach the leaderboard, which lists the named one where it is no rule
    assert cli._leaderboard_policies("rules,choice-threshold", ["choice-threshold"]) == (
        ["rules", "choice-threshold"], {})
    planner = {"model-predictive": ModelPredictive()}
    assert list(fitting_agents(planner, scenario("track60"))[0]) == ["model-predictive"]
    here, unfit = fitting_agents(planner, scenario("default"))
    assert here == {} and "measurement_interval must be 1" in unfit["model-predictive"]


def test_the_leaderboard_says_why_each_policy_is_not_scored_grouped_by_reason():
    from trackenv_agents.evaluation.leaderboard import format_leaderboard

    payload = {"results": [], "bound": {"x": {"available": False, "reason": "none here"}}, "seeds": {"x": [0]},
               "command": "c", "best_rule": {"x": "grouped-threshold"},
               "not_scored": {"x": {"b": "trained on another line: n_sections 12 (here 6)", "a": "trained on another "
                                    "line: capacity 6 (here 3)", "model-predictive": "needs an SD measured every "
                                    "step without error: this config measures every 4 steps"}}}
    table = format_leaderboard(payload)
    assert "Not scored here (each sees the observation of the line it was trained on): a, b." in table
    assert "Not scored here (needs an SD measured every step without error): model-predictive." in table


def test_leaderboard_horizon_notes_name_only_the_scenarios_where_the_agent_is_scored(monkeypatch, capsys, tmp_path):
    """`--set horizon_years=2` with the 60 m track's agent on the 60 m track and a line: the note on its time
    feature is said for the 60 m track, where it is scored, and not for the line, where it is not."""
    import trackenv_agents.evaluation.leaderboard as lb

    monkeypatch.setattr(lb, "run_leaderboard", lambda envs, **kw: {"results": [], "bound": {}, "seeds": {},
                                                                    "best_rule": {}})
    argv = ["leaderboard", "--env", "trackenv/Tamping-v1,trackenv/TampingLineSmall-v0", "--policies",
            "rules,cpi-track60-agent", "--set", "horizon_years=2", "--no-bound", "--json", "--out", str(tmp_path)]
    assert main(argv) == 0
    notes = [line for line in capsys.readouterr().err.splitlines() if "trackenv leaderboard: note:" in line]
    assert len(notes) == 1 and "cpi-track60-agent was trained on" in notes[0], notes
    assert "ones of trackenv/Tamping-v1 (--set horizon_years)" in notes[0]


def test_leaderboard_says_why_a_policy_asked_for_is_scored_nowhere(monkeypatch, capsys, tmp_path):
    """A model saved from a script of one's own on 1-year episodes, asked for on the 10-year small line: the page
    only groups it as not scored; stderr says why (its horizon), as the JSON's not_scored does."""
    import gymnasium as gym
    from stable_baselines3 import PPO

    import trackenv_agents.evaluation.leaderboard as lb
    from trackenv_agents.learning.baselines import save_sb3_policy

    env = gym.make("trackenv/TampingLineSmall-v0", horizon_years=1.0)
    path = save_sb3_policy(PPO("MultiInputPolicy", env, n_steps=8, batch_size=8, device="cpu"), env,
                           tmp_path / "mine.zip")
    monkeypatch.setattr(lb, "run_leaderboard", lambda envs, **kw: {"results": [], "bound": {}, "seeds": {},
                                                                    "best_rule": {}})
    argv = ["leaderboard", "--env", "trackenv/TampingLineSmall-v0", "--policies", f"grouped-threshold,{path}",
            "--no-bound", "--json", "--out", str(tmp_path / "lb")]
    assert main(argv) == 0
    err = capsys.readouterr().err
    assert (f"trackenv leaderboard: note: {tmp_path.name}/mine is scored on none of the scenarios given "
            "(trackenv/TampingLineSmall-v0: trained on another line: horizon_years 1.0 (here 10.0))") in err


def test_leaderboard_policies_name_a_path_as_name_equals_path(tmp_path, monkeypatch):
    """`--policies rules,mine=run1/model.zip`: the row is named "mine"; a name taken by a rule, a shipped agent or
    another item is refused, and the path is checked as any path is."""
    from trackenv_agents.cli import UsageError, _leaderboard_policies

    for run in ("run1", "run2"):
        model = tmp_path / run / "model.zip"
        model.parent.mkdir()
        model.write_bytes(b"")
        (model.parent / "model_obs_stats.json").write_text("{}")
    monkeypatch.chdir(tmp_path)
    assert _leaderboard_policies("rules,mine=run1/model.zip", ["grouped-threshold"]) == (
        None, {"mine": "run1/model.zip"})
    for taken in ("grouped-threshold=run1/model.zip", "cpi-agent=run1/model.zip",
                  "mine=run1/model.zip,mine=run2/model.zip"):
        with pytest.raises(UsageError, match="is taken .* give each policy a name of its own"):
            _leaderboard_policies(f"rules,{taken}", ["grouped-threshold"])
    with pytest.raises(UsageError, match="no trained policy at nope.zip"):
        _leaderboard_policies("rules,mine=nope.zip", ["grouped-threshold"])
