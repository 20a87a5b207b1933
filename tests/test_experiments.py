"""Pieces of the experiment scripts that carry logic of their own."""

from __future__ import annotations

import argparse
import importlib.util
from pathlib import Path

import numpy as np
import pytest


def _script(name: str):
    path = Path(__file__).resolve().parents[1] / "experiments" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(f"{name}_script", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_room_summary_takes_each_episodes_cheapest_search_and_never_more_than_the_rule():
    summ = _script("line_room_summary")
    room = {"test_seeds": [0, 1, 2], "best_rule": "r", "episode_costs": {"r": [100.0, 200.0, 50.0]},
            "hindsight": {"episodes": [{"seed": 0, "hindsight": 90.0}]}}
    searches = summ._searches(room) + [{"seed": 0, "hindsight": 80.0}, {"seed": 1, "hindsight": 210.0},
                                       {"seed": 7, "hindsight": 1.0}]  # seed 7 is not a room episode
    out = summ.summarise(room, searches)
    assert out["seeds"] == [0, 1] and out["n_episodes"] == 2
    np.testing.assert_allclose(out["per_episode_relative"], [-0.2, 0.0])
    np.testing.assert_allclose(out["relative"], -10.0 / 150.0)
    assert out["ci_low"] <= out["mean_difference"] <= out["ci_high"]


def test_choices_room_pairs_the_bound_with_a_rule_or_given_costs(tmp_path):
    import json

    mod = _script("choices_room")
    out = mod.room(np.array([100.0, 200.0, 300.0]), np.array([80.0, 150.0, 300.0]))
    assert out["difference"] == pytest.approx(-70.0 / 3) and out["relative"] == pytest.approx(-70.0 / 600)
    assert out["difference_ci"][0] <= out["difference"] <= out["difference_ci"][1] <= 0
    board = {"seeds": {"e": [3, 4]}, "results": [{"env": "e", "policy": "p", "episode_costs": [1.0, 2.0]}]}
    (tmp_path / "board.json").write_text(json.dumps(board))
    (tmp_path / "costs.json").write_text(json.dumps({"3": 5.0}))
    assert mod.given_costs(tmp_path / "board.json", "e", "p") == {3: 1.0, 4: 2.0}
    assert mod.given_costs(tmp_path / "costs.json", "e", None) == {3: 5.0}
    with pytest.raises(SystemExit, match="no row"):
        mod.given_costs(tmp_path / "board.json", "e", "q")
    text = mod.table([{**out, "env": "e", "rule": "p"}, {"env": "f", "rule": "p", "n_episodes": 2, "rule_mean": 1.0,
                                                          "rule_ci": [0.5, 1.5], "bound_unavailable": "a budget"}])
    assert "-11.7 %" in text and "a budget" in text


def test_kernel_profile_counts_every_section_of_the_kernels_time_step():
    kp = _script("kernel_profile")
    source = kp.KERNEL.read_text()
    text, names = kp.instrument(source)
    compile(text, "instrumented_kernel.py", "exec")  # valid Python
    headers = [line.split("# ---- ", 1)[1].strip() for line in source.splitlines() if "        # ---- " in line]
    assert names[1:] == headers and len(headers) >= 8  # one section per header, plus the step's start
    assert "Newton on the compressions" in " ".join(names) and "track predictor" in " ".join(names)
    # a counter read at every header and once at the end of the step, each closing one section
    assert [f"prof[{k}] +=" in text for k in range(len(names))] == [True] * len(names)
    assert text.count("_cycles(); prof[") == len(names)
    assert "cache=True" not in text and "def _run_chunk(mesh, drive, rows, peaks, reuse, ch, W, prof):" in text
    try:
        kp.instrument(source.replace("# ---- ", "# "))
    except ValueError as e:
        assert "section headers" in str(e)
    else:
        raise AssertionError("a kernel without section headers must be refused")


def test_ab_speed_alternates_the_versions_and_summarises_the_pairs():
    ab = _script("ab_speed")
    runs = ab.order(3)
    assert runs == ["base", "new", "new", "base", "base", "new"]
    assert runs.count("base") == runs.count("new") == 3
    assert ab.rounds(("a", "b", "c"), 2) == ["a", "b", "c", "c", "b", "a"]  # the engine and window A/Bs' order
    rep = ab.summary([100.0, 110.0, 90.0], [105.0, 99.0, 99.0])
    assert rep["median_base"] == 100.0 and rep["median_new"] == 99.0
    np.testing.assert_allclose(rep["ratios"], [1.05, 0.9, 1.1])
    assert rep["median_ratio"] == rep["ratios"][0] and rep["new_faster"] == 2 and rep["pairs"] == 3
    with pytest.raises(ValueError, match="pairs"):
        ab.order(0)
    with pytest.raises(ValueError, match="equal, non-empty"):
        ab.summary([1.0], [])


def test_ab_speed_timed_runs_collect_each_variants_records_in_the_alternating_order(capsys):
    import sys

    ab = _script("ab_speed")
    code = "import json, sys; print('noise'); print(json.dumps({'v': sys.argv[1], 'load': float(sys.argv[2])}))"
    loads = iter([1.0, 3.0, 2.0, 0.5])
    runs = ab.timed_runs(("a", "b"), 2, lambda v: [sys.executable, "-c", code, v, str(next(loads))],
                         lambda v, rec: f"{v}:{rec['load']}")
    assert runs == {"a": [{"v": "a", "load": 1.0}, {"v": "a", "load": 0.5}],
                    "b": [{"v": "b", "load": 3.0}, {"v": "b", "load": 2.0}]}  # run order a b b a
    assert capsys.readouterr().out.split() == ["a:1.0", "b:3.0", "b:2.0", "a:0.5"]
    assert ab.load_range(runs) == [0.5, 3.0]


def test_ab_speed_gives_the_new_version_its_env_keywords_and_refuses_bad_ones(capsys):
    ab = _script("ab_speed")
    parser = argparse.ArgumentParser()
    assert ab._keyword_arguments('{"engine": "fast"}', "line", parser) == {"engine": "fast"}
    code = ab._SNIPPETS["line_vector"].format(envs=8, steps=2, workers=1, kwargs=", engine='fast'")
    assert "TampingLineVectorEnv(8, scenario=\"default\", engine='fast')" in code
    code = ab._SNIPPETS["env"].format(envs=1, steps=2, workers=1, env_id="trackenv/Tamping-v0", kwargs="")
    assert 'gym.make("trackenv/Tamping-v0")' in code
    for text, figure in (("[1]", "line"), ("{not json", "line"), ('{"engine": "fast"}', "seed"),
                         ('{"1x": 2}', "line")):
        with pytest.raises(SystemExit):
            ab._keyword_arguments(text, figure, parser)
    with pytest.raises(SystemExit):
        ab._keyword_arguments("[1]", "line", parser, "--base-kwargs")
    assert "--base-kwargs must be a JSON object" in capsys.readouterr().err
    with pytest.raises(ValueError, match="equal, non-empty"):
        ab.summary([], [])


def test_ab_speed_gives_each_version_its_own_env_id_and_keywords():
    ab = _script("ab_speed")
    codes = ab.figure_codes("env", {"base": "trackenv/Tamping-v0", "new": "trackenv/Tamping-v1"},
                            {"base": {"engine": "classic"}, "new": {"engine": "fast"}}, steps=2, envs=1, workers=1)
    assert 'gym.make("trackenv/Tamping-v0", engine=\'classic\')' in codes["base"]
    assert 'gym.make("trackenv/Tamping-v1", engine=\'fast\')' in codes["new"]
    codes = ab.figure_codes("line", {"base": "", "new": ""}, {"base": {"engine": "fast"}, "new": {}}, steps=2,
                            envs=1, workers=1)
    assert "engine='fast'" in codes["base"] and "engine=" not in codes["new"]



def test_robustness_conditions_each_move_one_field_of_their_scenario_and_are_valid():
    from trackenv.envs.line_config import scenario

    mod = _script("robustness")
    for name, (conditions, others) in mod.SCENARIOS.items():
        nominal = scenario(name).to_dict()
        assert conditions[0] == ("nominal", {}) and others[0] == mod.AGENT
        for label, overrides in conditions[1:]:
            moved = scenario(name, **overrides).to_dict()  # validated at construction
            assert {k for k in nominal if nominal[k] != moved[k]} == set(overrides), (name, label)
    assert [p.name for p in mod.policies("track60")][:3] == [mod.AGENT, "cpi-track60-agent", "model-predictive"]


def test_robustness_table_pairs_each_policy_with_the_best_rule_also_from_a_saved_run_of_the_agent_alone():
    mod = _script("robustness")
    diff = {"mean_difference": -5.0, "ci_low": -8.0, "ci_high": -2.0}
    costs = {p: {"mean_cost": c} for p, c in (("cpi-agent", 95.0), ("model-predictive", 90.0),
                                              ("grouped-threshold", 100.0), ("uniform-periodic", 120.0))}
    row = {"condition": "nominal", "costs": costs, "best_rule": "grouped-threshold",
           "agent_minus_best_rule": diff, "agent_vs_best_rule_relative": -0.05,
           "vs_best_rule": {"cpi-agent": {**diff, "relative": -0.05},
                            "model-predictive": {**diff, "mean_difference": -10.0, "relative": -0.1}}}
    text = mod.table([row])
    assert "model-predictive − best rule" in text and "-10.0 [-8.0, -2.0] (-10.0 % vs grouped-threshold)" in text
    saved = {k: v for k, v in row.items() if k != "vs_best_rule"}  # a row written before the planner's column
    assert "| nominal | 95.0 | 100.0 | 120.0 | -5.0 [-8.0, -2.0] (-5.0 % vs grouped-threshold) |" in mod.table([saved])


def test_choice_agent_script_loads_every_shipped_agent_and_an_agent_with_another_advisor():
    """``experiments/choice_agent.py`` names its policies as the commands do: each shipped agent by its name (the
    shipped files), ``AGENT@RULE`` with another advisor, and a rule with the scenario's tuned parameters."""
    from trackenv.envs.problems import problem_config
    from trackenv_agents.shipped import SHIPPED_AGENTS

    mod = _script("choice_agent")
    config = problem_config("wet")
    for name in SHIPPED_AGENTS:
        assert mod._policy(name, config).name == name
    mixed = mod._policy("cpi-agent@choice-threshold", config)
    assert mixed.name == "cpi-agent@choice-threshold" and mixed.advisor.name == "choice-threshold"
    assert mod._policy("choice-threshold", config).name == "choice-threshold"


def test_network_agent_script_builds_network_policies_and_pairs_them_with_the_best_rule(tmp_path):
    """``experiments/network_agent.py``: each name a NetworkRule over the rule (the line's tuned parameters) or
    the shipped agent; the report pairs every policy with the cheapest rule on the seeds all of them have, and
    never takes an agent as the reference."""
    import json

    from trackenv.envs.network import NetworkConfig
    from trackenv_agents.rules import NetworkRule, tuned_params_for

    mod = _script("network_agent")
    built = mod.network_policies(NetworkConfig(), ["grouped-threshold", "cpi-agent"])
    assert list(built) == ["network(grouped-threshold)", "network(cpi-agent)"]
    assert all(isinstance(p, NetworkRule) for p in built.values())
    tuned = tuned_params_for(NetworkConfig().line_config)["grouped-threshold"]
    assert built["network(grouped-threshold)"].line_rule.params == tuned
    with pytest.raises(SystemExit, match="unknown"):
        mod.network_policies(NetworkConfig(), ["no-such-policy"])
    costs = {"network(grouped-threshold)": [100.0, 200.0, 300.0], "network(section-threshold)": [110.0, 190.0, 330.0],
             "network(cpi-agent)": [90.0, 150.0, 250.0]}  # the agent cheapest, the grouped threshold the best rule
    for name, values in costs.items():
        seeds = range(len(values) + (name == "network(cpi-agent)"))  # one seed more: left out of the pairing
        extra = [999.0] if name == "network(cpi-agent)" else []
        (tmp_path / f"{name}.json").write_text(json.dumps({
            "policy": name, "costs": {str(s): c for s, c in zip(seeds, values + extra, strict=True)},
            "runs": [{"policies": list(costs), "seeds": [0, 2], "wall_s": 1.0, "cpu_s": 2.0}]}))
    payload = mod.report(tmp_path)
    assert payload["best_rule"] == "network(grouped-threshold)" and payload["n_episodes"] == 3
    rows = {r["policy"]: r for r in payload["results"]}
    assert rows["network(cpi-agent)"]["vs_best_rule"]["mean_difference"] == pytest.approx(-110.0 / 3)
    assert rows["network(cpi-agent)"]["relative_to_best_rule"] == pytest.approx(-110.0 / 600)
    assert rows["network(section-threshold)"]["better_fraction"] == pytest.approx(1 / 3)
    assert payload["wall_s"] == 1.0 and payload["cpu_s"] == 2.0  # one run, kept in every policy's file
    assert json.loads((tmp_path / "report.json").read_text()) == payload


def test_train_line_trains_on_the_60_m_track(tmp_path, capsys):
    """``train_line.py --scenario track60``: the 60 m track's sections share a segment, so its decisions are priced
    by whole-line forks; one short iteration runs, scored on held-out episodes against the 60 m track's rule, and
    the saved policy says it was trained on trackenv/Tamping-v1."""
    import json

    _script("train_line").main(["--scenario", "track60", "--horizon-years", "1", "--iterations", "1", "--episodes",
                                "2", "--eval-seeds", "10000:10002", "--out", str(tmp_path), "--no-progress"])
    summary = json.loads((tmp_path / "summary.json").read_text())
    (it,) = summary["iterations"]
    assert it["samples"] > 0 and summary["fork_segment_steps"] > 0
    assert summary["baseline"]["policy"] == "grouped-threshold" and summary["baseline"]["params"] == {
        "trigger_mm": 3.0, "include_mm": 1.0}  # the 60 m track's tuned rule
    meta = json.loads((tmp_path / "model_meta.json").read_text())
    assert meta["env_id"] == "trackenv/Tamping-v1" and meta["config"]["sections_per_segment"] == 6
    assert "iteration 0: held-out" in capsys.readouterr().out


def test_network_agent_script_scores_the_value_dispatch_and_pairs_against_a_chosen_reference(tmp_path):
    """``--dispatch value`` names each policy ``network-by-value(<policy>)``; the shipped agent by value is never
    the reference; ``--against`` pairs every policy with the reference named, and an unknown one is refused."""
    import json

    from trackenv.envs.network import NetworkConfig
    from trackenv_agents.rules.dispatch import ValueDispatch

    mod = _script("network_agent")
    built = mod.network_policies(NetworkConfig(), ["grouped-threshold", "cpi-agent"], ("requests", "value"))
    assert list(built) == ["network(grouped-threshold)", "network(cpi-agent)", "network-by-value(grouped-threshold)",
                           "network-by-value(cpi-agent)"]
    assert built["network-by-value(cpi-agent)"].dispatch == ValueDispatch()
    costs = {"network(grouped-threshold)": [100.0, 200.0], "network-by-value(grouped-threshold)": [90.0, 200.0],
             "network-by-value(cpi-agent)": [50.0, 60.0]}
    for name, values in costs.items():
        (tmp_path / f"{name}.json").write_text(json.dumps({
            "policy": name, "costs": {str(s): c for s, c in enumerate(values)},
            "runs": [{"policies": list(costs), "seeds": [0, 1], "wall_s": 1.0, "cpu_s": 2.0}]}))
    assert mod.report(tmp_path)["best_rule"] == "network-by-value(grouped-threshold)"
    payload = mod.report(tmp_path, against="network(grouped-threshold)")
    rows = {r["policy"]: r for r in payload["results"]}
    assert payload["best_rule"] == "network(grouped-threshold)"
    assert rows["network-by-value(cpi-agent)"]["vs_best_rule"]["mean_difference"] == pytest.approx(-95.0)
    assert json.loads((tmp_path / "report-vs-network(grouped-threshold).json").read_text()) == payload
    assert mod.report(tmp_path)["best_rule"] == "network-by-value(grouped-threshold)"  # the saved reports not read
    with pytest.raises(SystemExit, match="--against"):
        mod.report(tmp_path, against="network(no-such-policy)")


def test_engine_switch_scores_like_the_leaderboard_and_finds_each_shipped_bound():
    """The normalised score is the paired sums' ratio (the leaderboard's), the relative changes are of the means,
    and every scenario it compares has exactly one shipped bound file."""
    mod = _script("engine_switch")
    rows = {"rule": np.array([100.0, 200.0]), "agent": np.array([90.0, 200.0]), "bound": np.array([80.0, 150.0]),
            "evaluation_s": 1.5}
    s = mod.summary(rows)
    assert s["normalised_score"] == pytest.approx(10.0 / 70.0)
    assert s["agent_vs_rule"] == pytest.approx(290.0 / 300.0 - 1) and s["bound_vs_rule"] == pytest.approx(-70.0 / 300)
    for name in mod.SCENARIOS:
        assert mod.bound_file(name).name.startswith(f"{name}_")


def test_bound_parts_replays_split_each_episodes_cost_into_its_parts_and_count_the_choices():
    """The replayed parts of a schedule sum to what the env charges it (replay_schedules), and the choice counts
    are the schedule's."""
    from trackenv.envs.choices import CHOICES
    from trackenv.envs.line_config import scenario
    from trackenv_agents.evaluation.line_hindsight import replay_schedules

    mod = _script("bound_parts")
    config = scenario("wet", horizon_years=1.0)
    seeds = [3, 4]
    plans = np.random.default_rng(0).choice([0, 1, 3], size=(2, config.horizon_steps, config.n_sections),
                                            p=[0.8, 0.1, 0.1]).astype(np.int8)
    plans[:, 1:] = np.where(plans[:, :-1] != 0, 0, plans[:, 1:])  # no work on a section two steps running
    parts, counts = mod.replay_parts(config, seeds, plans)
    assert not any(k.startswith("_") for k in parts) and "drainage" in parts
    np.testing.assert_allclose(sum(parts.values()), replay_schedules(config, seeds, list(plans)), rtol=1e-9)
    assert counts.shape == (2, len(CHOICES) - 1)
    assert counts[:, CHOICES.index("tamp") - 1].tolist() == (plans == 1).sum(axis=(1, 2)).tolist()
    assert counts[:, CHOICES.index("drainage") - 1].tolist() == (plans == 3).sum(axis=(1, 2)).tolist()


def test_track60_room_replays_a_schedule_exactly_and_its_end_stop_does_no_late_work():
    from trackenv.envs.line_config import scenario
    from trackenv_agents.evaluation.harness import evaluate_many
    from trackenv_agents.rules.line import GroupedThreshold

    mod = _script("track60_room")
    config = scenario("track60", horizon_years=3.0)
    seeds = [3000, 3003]
    rule = GroupedThreshold(trigger_mm=1.0, include_mm=0.5)  # a low trigger: work within these 3 years
    own = evaluate_many([rule], config, seeds, batch_size=2)[0]
    assert own.tamped[:, :-6].any() and own.tamped[:, -6:].any()  # work before the stop and within it
    stop = 6
    played, ended = evaluate_many([mod.SchedulePlayer(list(own.tamped), config.horizon_steps),
                                   mod.EndStop(rule.params["trigger_mm"], rule.params["include_mm"], stop)],
                                  config, seeds, batch_size=2)
    np.testing.assert_allclose(played.cost, own.cost, rtol=0, atol=1e-9)  # the rule's own schedule, replayed
    assert not ended.tamped[:, -stop:].any()
    np.testing.assert_array_equal(ended.tamped[:, :-stop], own.tamped[:, :-stop])  # the same rule before that
    row = mod.summary(own)
    assert row["sections_tamped"] == own.tamped.sum() / 2 and row["mean_cost"] == pytest.approx(own.cost.mean())
    with pytest.raises(ValueError, match="one batch"):
        evaluate_many([mod.SchedulePlayer(list(own.tamped), config.horizon_steps)], config, seeds, batch_size=1)


def test_line_information_designs_change_what_is_seen_not_the_track():
    """Each recording design changes only the measurement fields: the same seed gives the same true state under
    every design (so the designs are paired with each other and with the bound), while what the observation
    shows differs; the scores are the leaderboard's (paired sums) and the bound file is the default line's."""
    from trackenv.envs.line import TampingLine
    from trackenv.envs.line_config import scenario

    mod = _script("line_information")
    assert all(set(f) <= {"measurement_interval", "sd_noise_mm", "peak_noise_mm"} for f in mod.DESIGNS.values())
    assert all(g["include_mm"] < g["trigger_mm"] for g in mod.GRID)
    seeds, plans = mod.bound_schedules()
    assert len(seeds) == len(plans) >= 16
    base = scenario("default", horizon_years=1.0)
    true, seen = [], []
    for fields in mod.DESIGNS.values():
        env = TampingLine(base.replace(**fields))
        obs, info = env.reset(seed=5)
        for t in range(3):
            obs, _, _, _, info = env.step(np.eye(base.n_sections, dtype=np.int8)[t])
        true.append(info["section_sd_m"])
        seen.append(obs["section_sd"])
    for t in true[1:]:
        np.testing.assert_array_equal(t, true[0])
    assert not np.allclose(seen[0], seen[-1])  # once a year with error against every step without
    s = mod.score(np.array([90.0, 200.0]), np.array([100.0, 200.0]), np.array([80.0, 150.0]))
    assert s["normalised_score"] == pytest.approx(10.0 / 70.0) and s["mean_keur"] == pytest.approx(145.0)
    assert s["vs_reference"]["mean"] == pytest.approx(-5.0) and s["vs_reference"]["relative"] == pytest.approx(-5 / 150)
