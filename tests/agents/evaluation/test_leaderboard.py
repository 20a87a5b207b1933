"""The leaderboard (`trackenv leaderboard`): the normalised score's definition (0 for the best rule, 1 for the
bound's own schedule), the payload's schema, the bound's cache and saved-search reuse, where the bound does not
apply, and Ray giving the single-process numbers. Every scenario is the small line cut to two years (8 steps) and
two seeds."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pytest

from trackenv.envs.line_config import scenario
from trackenv.envs.network import NetworkConfig
from trackenv_agents.evaluation.leaderboard import (
    bound_unavailable,
    format_leaderboard,
    normalised_score,
    run_leaderboard,
)
from trackenv_agents.evaluation.line_hindsight import schedule_from_rows

ENV = "trackenv/TampingLineSmall-v0"
SEEDS = [0, 1]
RULES = ["grouped-threshold", "section-threshold"]
TINY = {"horizon_years": 2.0}  # 8 steps: on seed 1 the bound is below the best rule


class ReplaySchedules:
    """Tamps what the given (H, S) schedules say, one per env of the batch in seed order: the harness hands one
    policy's envs over in the order of the seeds, all in one batch here."""

    name = "replay-bound"

    def __init__(self, plans: list[np.ndarray]) -> None:
        self.plans = np.stack(plans)
        self.t = 0

    def predict(self, obs: dict, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[np.ndarray, Any]:
        if episode_start is not None and np.all(episode_start):
            self.t = 0
        action = self.plans[:, self.t].astype(np.int8)
        self.t += 1
        return action, state


def test_score_is_a_ratio_of_paired_sums() -> None:
    rule = np.array([100.0, 200.0, 300.0])
    bound = np.array([90.0, 150.0, 290.0])  # gaps 10, 50, 10: Σ 70
    policy = np.array([95.0, 180.0, 310.0])  # gains 5, 20, -10: Σ 15
    s = normalised_score(rule, policy, bound)
    assert s["score"] == pytest.approx(15 / 70)  # not the mean of the per-episode ratios (0.5, 0.4, -1)
    lo, hi = s["ci"]
    assert lo <= s["score"] <= hi
    assert normalised_score(rule, rule, bound)["score"] == 0.0
    assert normalised_score(rule, bound, bound)["score"] == 1.0
    assert normalised_score(rule, rule - 100, bound)["score"] > 1  # beating the bound: a search, not the optimum


def test_score_is_null_without_a_gap_and_refuses_unpaired_costs() -> None:
    rule = np.array([100.0, 200.0])
    assert normalised_score(rule, rule - 1, rule) == {"score": None, "ci": None, "gap_mean": 0.0}
    with pytest.raises(ValueError, match="equal"):
        normalised_score(rule, rule[:1], rule)


def test_bound_applies_where_sections_or_whole_lines_are_priced() -> None:
    assert bound_unavailable(scenario("small")) is None
    assert bound_unavailable(scenario("default")) is None
    assert bound_unavailable(scenario("track60")) is None  # the whole-line search
    assert "annual budget" in bound_unavailable(scenario("hard"))
    assert "share one tamping machine" in bound_unavailable(NetworkConfig())


def test_the_scenarios_with_choices_have_a_bound_searched_over_their_choices(tmp_path) -> None:
    """The bound applies to the ids with choices, with the choices' search settings in its cache key; a cache
    written before the config gained fields (at their defaults) is still this config's."""
    from trackenv_agents.evaluation.leaderboard import CHOICE_SEARCH, _cache_path, _config_key, _search_settings

    wet = scenario("wet")
    assert bound_unavailable(wet) is None and _search_settings(wet)["choice_search"] == CHOICE_SEARCH
    assert "choice_search" not in _search_settings(scenario("small"))
    small = scenario("small")
    older = {k: v for k, v in small.to_dict().items() if k not in ("choices", "contact_sensor", "drainage_cost")}
    (tmp_path / "small_0123456789ab.json").write_text(json.dumps(
        {"scenario": "small", "config": older, "search": _search_settings(small), "episodes": {}}, default=str))
    assert _cache_path(small, "small", tmp_path).name == "small_0123456789ab.json"
    other = small.replace(capacity=2)
    assert _cache_path(other, "small", tmp_path) == tmp_path / f"{_config_key(other, 'small')}.json"


@pytest.fixture(scope="module")
def first(tmp_path_factory) -> tuple[dict, Any]:
    """The tiny leaderboard of two rules, with the bound searched and cached."""
    out = tmp_path_factory.mktemp("board")
    return run_leaderboard([ENV], rules=RULES, seeds=SEEDS, out_dir=out, searches=None, **TINY), out


def test_best_rule_scores_zero_and_the_bound_search_is_cached(first) -> None:
    payload, out = first
    rows = payload["results"]
    best = payload["best_rule"][ENV]
    assert rows[0]["policy"] == best and {r["policy"] for r in rows} == set(RULES)
    assert rows[0]["normalised_score"] == 0.0 and rows[0]["vs_best_rule"]["mean_difference"] == 0.0
    bound = payload["bound"][ENV]
    assert bound["available"] and bound["reason"] is None
    assert bound["sources"] == {"cache": 0, "saved": 0, "replayed": 0, "search": len(SEEDS)}
    assert bound["search_seconds_per_episode"] > 0
    assert np.all(np.array(bound["episode_costs"]) <= np.array(rows[0]["episode_costs"]))
    assert len(list((out / "bounds").glob("small_*.json"))) == 1


def test_replaying_the_bound_scores_one(first) -> None:
    """A policy that tamps the bound's own schedules closes the whole gap; the second run reads the cached bound."""
    payload, out = first
    cache = json.loads(next((out / "bounds").glob("small_*.json")).read_text())
    plans = [schedule_from_rows(cache["episodes"][str(s)]["schedule"]) for s in SEEDS]
    again = run_leaderboard([ENV], rules=RULES, agents={"replay-bound": ReplaySchedules(plans)}, seeds=SEEDS,
                        out_dir=out, searches=None, **TINY)
    assert again["bound"][ENV]["sources"] == {"cache": len(SEEDS), "saved": 0, "replayed": 0, "search": 0}
    assert again["bound"][ENV]["episode_costs"] == payload["bound"][ENV]["episode_costs"]
    row = next(r for r in again["results"] if r["policy"] == "replay-bound")
    assert again["bound"][ENV]["vs_best_rule"]["mean_difference"] < 0  # a gap to close
    assert row["normalised_score"] == pytest.approx(1.0, abs=1e-9)
    np.testing.assert_allclose(row["episode_costs"], again["bound"][ENV]["episode_costs"], rtol=1e-12)


def test_saved_searches_are_reused_where_they_replay(first, tmp_path) -> None:
    """A search file of the scenario (the form of experiments/searches/) stands in for the search when its
    schedules replay at their saved costs; one whose cost no longer matches is searched again."""
    payload, out = first
    cache = json.loads(next((out / "bounds").glob("small_*.json")).read_text())["episodes"]
    episodes = [{"seed": s, "schedule": cache[str(s)]["schedule"], "replayed": cache[str(s)]["cost"]} for s in SEEDS]
    episodes[1]["replayed"] += 1.0  # as if saved by another engine version
    searches = tmp_path / "searches"
    searches.mkdir()
    (searches / "room.json").write_text(json.dumps({"scenario": "small", "hindsight": {"episodes": episodes}}))
    again = run_leaderboard([ENV], rules=RULES, seeds=SEEDS, out_dir=tmp_path / "board", searches=searches, **TINY)
    assert again["bound"][ENV]["sources"] == {"cache": 0, "saved": 1, "replayed": 0, "search": 1}
    assert again["bound"][ENV]["episode_costs"] == pytest.approx(payload["bound"][ENV]["episode_costs"])


def test_a_fresh_output_folder_reads_the_committed_bound_cache(first, tmp_path) -> None:
    """The committed bound cache (here the first run's) serves a fresh output folder for the same config and
    search settings, as its own cache would: no search; another config finds nothing there and searches."""
    payload, out = first
    again = run_leaderboard([ENV], rules=RULES, seeds=SEEDS, out_dir=tmp_path / "fresh", searches=None,
                            shipped_bounds=out / "bounds", **TINY)
    assert again["bound"][ENV]["sources"] == {"cache": len(SEEDS), "saved": 0, "replayed": 0, "search": 0}
    assert again["bound"][ENV]["episode_costs"] == payload["bound"][ENV]["episode_costs"]
    other = run_leaderboard([ENV], rules=RULES, seeds=SEEDS[:1], out_dir=tmp_path / "other", searches=None,
                            shipped_bounds=out / "bounds", horizon_years=1.0)
    assert other["bound"][ENV]["sources"]["search"] == 1


def test_faster_options_replay_the_classic_engines_bound(first, tmp_path) -> None:
    """With the fast engine and pass reuse the bound is the classic search's schedules replayed under them (no new
    search), capped at the best rule, cached under the faster config's own key; the table says so."""
    from trackenv_agents.evaluation.line_hindsight import replay_schedules

    payload, out = first
    board = tmp_path / "board"
    (board / "bounds").mkdir(parents=True)
    for path in (out / "bounds").glob("small_*.json"):  # the classic run's cache, left as the fixture wrote it
        (board / "bounds" / path.name).write_text(path.read_text())
    fast = {"engine": "fast", "pass_reuse_tolerance_m": 1e-3}
    again = run_leaderboard([ENV], rules=RULES, seeds=SEEDS, out_dir=board, searches=None, **TINY, **fast)
    bound = again["bound"][ENV]
    assert bound["sources"] == {"cache": 0, "saved": 0, "replayed": len(SEEDS), "search": 0}
    cache = json.loads(next((out / "bounds").glob("small_*.json")).read_text())["episodes"]
    plans = [schedule_from_rows(cache[str(s)]["schedule"]) for s in SEEDS]
    replayed = replay_schedules(scenario("small", **TINY, **fast), SEEDS, plans)
    best = next(r for r in again["results"] if r["policy"] == again["best_rule"][ENV])
    np.testing.assert_allclose(bound["episode_costs"], np.minimum(replayed, best["episode_costs"]), rtol=1e-12)
    assert not np.allclose(best["episode_costs"], payload["results"][0]["episode_costs"], rtol=1e-9, atol=0)
    table = format_leaderboard(again)
    assert "engine fast, pass reuse 1 mm" in table and f"{len(SEEDS)} replayed" in table
    assert len(list((board / "bounds").glob("small_*.json"))) == 2  # the faster config's own cache beside
    third = run_leaderboard([ENV], rules=RULES, seeds=SEEDS, out_dir=board, searches=None, **TINY, **fast)
    assert third["bound"][ENV]["sources"]["cache"] == len(SEEDS)


def test_payload_schema_and_table(first) -> None:
    payload, _ = first
    assert set(payload) >= {"results", "bound", "seeds", "best_rule"}
    assert payload["seeds"] == {ENV: SEEDS}
    for row in payload["results"]:
        assert set(row) >= {"env", "policy", "mean_cost", "ci", "vs_best_rule", "normalised_score",
                            "normalised_score_ci", "immediate_action", "interventions_per_class"}
        assert row["env"] == ENV and row["ci"][0] <= row["mean_cost"] <= row["ci"][1]
        assert set(row["vs_best_rule"]) == {"mean_difference", "ci_low", "ci_high"}
        assert set(row["interventions_per_class"]) == {"plain", "transition", "switch_or_crossing",
                                                       "hidden_wet_spot"}
    json.dumps(payload)  # plain JSON
    table = format_leaderboard({**payload, "command": "trackenv leaderboard --env " + ENV})
    assert f"### {ENV}" in table and "Hindsight bound:" in table
    assert table.count(f"| {RULES[0]} |") == 1 and "Written by `trackenv leaderboard --env" in table
    assert [r["episodes_beyond_validity"] for r in payload["results"]] == [0] * len(payload["results"])
    assert "Beyond the model's validity" not in table


def test_the_page_warns_where_episodes_left_the_models_validity(first) -> None:
    """A row with episodes beyond the model's validity (its costs not physical from there on) is named under its
    scenario's table, with the count."""
    payload, _ = first
    row = {**payload["results"][-1], "episodes_beyond_validity": 2}
    table = format_leaderboard({**payload, "results": [*payload["results"][:-1], row]})
    assert (f"**Beyond the model's validity** (a section's settlement ran away) in some episodes of {row['policy']} "
            f"(2 of {row['n_episodes']}): their costs from there on are not physical.") in table


def test_no_bound_gives_null_scores_and_says_why(tmp_path) -> None:
    """Without the bound the scores are null and the table says why; on one episode the table gives no CI (one
    of zero width claimed a certainty) and counts "1 held-out episode"."""
    payload = run_leaderboard([ENV], rules=RULES[:1], seeds=SEEDS[:1], bound=False, out_dir=tmp_path, **TINY)
    assert [r["normalised_score"] for r in payload["results"]] == [None]
    assert payload["bound"][ENV] == {"available": False, "reason": "not computed (--no-bound)"}
    table = format_leaderboard(payload)
    assert "No normalised score: not computed (--no-bound)." in table
    assert "1 held-out episode (seeds 0); best tuned rule" in table
    (row,) = [line for line in table.splitlines() if line.startswith(f"| {RULES[0]} |")]
    assert row.startswith(f"| {RULES[0]} | {payload['results'][0]['mean_cost']:.1f} n/a | — | n/a |")
    assert not (tmp_path / "bounds").exists()


def test_from_python_it_writes_the_commands_files_and_takes_its_seed_text(tmp_path) -> None:
    """run_leaderboard writes leaderboard.json and the page into out_dir as the command does (a caller found none),
    and takes one id alone and the command's "A:B" seeds; seeds that are no sequence are named."""
    payload = run_leaderboard(ENV, rules=RULES[:1], seeds="0:1", bound=False, out_dir=tmp_path / "lb", **TINY)
    files = [str(tmp_path / "lb" / "leaderboard.json"), str(tmp_path / "lb" / "leaderboard.md")]
    assert payload["files"] == files and payload["seeds"] == {ENV: [0]}
    saved = json.loads((tmp_path / "lb" / "leaderboard.json").read_text())
    assert saved["results"] == json.loads(json.dumps(payload["results"])) and saved["files"] == files
    assert (tmp_path / "lb" / "leaderboard.md").read_text() == format_leaderboard(payload)
    assert not run_leaderboard([ENV], rules=RULES[:1], seeds=[0], bound=False, out_dir=tmp_path / "no",
                               write=False, **TINY).get("files") and not (tmp_path / "no").exists()
    with pytest.raises(ValueError, match="seeds must be whole numbers"):
        run_leaderboard([ENV], rules=RULES[:1], seeds=2, bound=False, out_dir=tmp_path, **TINY)


def test_an_id_registered_over_a_preset_is_scored_with_its_own_arguments(tmp_path) -> None:
    """An id registered with gym.register over a preset's entry point, with a field changed, is scored on that
    config (it was scored on the preset: the same cost as the id it was made from)."""
    import gymnasium as gym

    variant = "trackenv_tests/HeavySmallLine-v0"
    if variant not in gym.registry:
        spec = gym.spec(ENV)
        gym.register(variant, entry_point=spec.entry_point, kwargs={**spec.kwargs, "annual_mgt": 30.0})
    try:
        cost = {env_id: run_leaderboard([env_id], rules=RULES[:1], seeds=[0], bound=False, write=False,
                                        out_dir=tmp_path, **TINY)["results"][0]["mean_cost"]
                for env_id in (ENV, variant)}
        heavier = run_leaderboard([ENV], rules=RULES[:1], seeds=[0], bound=False, write=False, out_dir=tmp_path,
                                  annual_mgt=30.0, **TINY)["results"][0]["mean_cost"]
    finally:
        del gym.registry[variant]
    assert cost[variant] == heavier != cost[ENV]


def test_unknown_rule_is_refused(tmp_path) -> None:
    with pytest.raises(ValueError, match="rules must be among .*got unknown \\['no-such-rule'\\]"):
        run_leaderboard([ENV], rules=["grouped-threshold", "no-such-rule"], seeds=SEEDS, out_dir=tmp_path, **TINY)


def test_a_scenario_scores_the_named_rules_of_its_family(tmp_path) -> None:
    """The rules of the choices apply only where a config enables them: named with a tamping rule (or with every
    tuned rule, "rules"), a tamping-only scenario scores the tamping rules and lists the other as not scored, with
    the reason, as an agent that does not fit (it was dropped silently); named alone there, the scenario is refused
    by its id."""
    from trackenv_agents.rules.problems import tuned_params_for

    payload = run_leaderboard([ENV], rules=["choice-threshold", "grouped-threshold"], seeds=SEEDS[:1], bound=False,
                              out_dir=tmp_path, **TINY)
    assert [r["policy"] for r in payload["results"]] == ["grouped-threshold"]
    assert list(payload["not_scored"][ENV]) == ["choice-threshold"]
    assert payload["not_scored"][ENV]["choice-threshold"].startswith(
        "no such rule on this scenario: its rules are budgeted-worst-first, grouped-threshold, ")
    assert "Not scored here (no such rule on this scenario): choice-threshold." in format_leaderboard(payload)
    every = run_leaderboard([ENV], rules=["rules", "choice-threshold"], seeds=SEEDS[:1], bound=False,
                            out_dir=tmp_path, **TINY)  # (--policies rules,choice-threshold)
    assert {r["policy"] for r in every["results"]} == set(tuned_params_for(scenario("small")))
    assert list(every["not_scored"][ENV]) == ["choice-threshold"]
    with pytest.raises(ValueError, match=f"rules must name some of {ENV}'s rules"):
        run_leaderboard([ENV], rules=["choice-threshold"], seeds=SEEDS[:1], bound=False, out_dir=tmp_path, **TINY)


def test_a_scenario_given_twice_is_refused(tmp_path) -> None:
    """The same id twice wrote two identical tables: refused, naming it."""
    with pytest.raises(ValueError, match=f"^envs name {ENV} more than once"):
        run_leaderboard([ENV, ENV], rules=RULES[:1], seeds=SEEDS[:1], bound=False, out_dir=tmp_path, **TINY)


def test_agents_are_a_dict_named_apart_from_the_rules_and_a_failing_one_names_its_scenario(tmp_path) -> None:
    """A probe's slips from Python: agents as a list (an AttributeError deep inside), an agent named as a rule
    scored there (two rows of that name, neither compared), a policy whose predict fails (a raw error that named
    neither the policy nor the scenario)."""
    def wait(obs):
        return np.zeros_like(obs["section_sd"], dtype=np.int8)

    with pytest.raises(ValueError, match="^agents must be a dict of name -> policy, got list"):
        run_leaderboard([ENV], rules=RULES[:1], agents=[wait], seeds=SEEDS[:1], bound=False, out_dir=tmp_path, **TINY)
    with pytest.raises(ValueError, match=f"^agents name {RULES[0]} as a rule scored on {ENV}: give each policy a "
                                         "name of its own"):
        run_leaderboard([ENV], rules=RULES[:1], agents={RULES[0]: wait}, seeds=SEEDS[:1], bound=False,
                        out_dir=tmp_path, **TINY)

    class Broken:
        name = "broken"

        def predict(self, obs, state=None, episode_start=None, deterministic=True):
            raise RuntimeError("Sizes of tensors must match")

    with pytest.raises(RuntimeError, match="Sizes of tensors") as caught:
        run_leaderboard([ENV], rules=RULES[:1], agents={"mine": Broken()}, seeds=SEEDS[:1], bound=False,
                        out_dir=tmp_path, **TINY)
    notes = " ".join(caught.value.__notes__)
    assert "predict of policy 'broken'" in notes and f"while scoring {ENV}" in notes and "unfit_for" in notes


def test_the_network_scores_its_lines_policies_on_every_line_without_a_bound(tmp_path) -> None:
    """On the network every rule and agent runs on every line through NetworkRule (dispatched by value, named
    network-by-value(...)), the
    best of its rules is the reference, an agent's row is its NetworkRule's episodes, and there is no bound."""
    from trackenv_agents.evaluation.harness import CallablePolicy, evaluate_many
    from trackenv_agents.evaluation.leaderboard import DEFAULT_SEEDS, DEFAULT_SUITE
    from trackenv_agents.rules import GroupedThreshold, NetworkRule

    net = "trackenv/TampingNetwork-v0"
    assert net in DEFAULT_SUITE and len(DEFAULT_SEEDS[net]) >= 8
    tiny = {"line_config": "small", "n_lines": 2, "horizon_years": 1.5}
    class Eager(GroupedThreshold):  # a line policy that is no tuned rule
        name = "eager"

    def above_two(obs):  # a plain function of the batch is a policy too, named by its key
        return (obs["section_sd"] >= 2.0).astype(int)

    agent = Eager(trigger_mm=1.0, include_mm=0.5)
    payload = run_leaderboard([net], rules=RULES, agents={"eager": agent, "mine": above_two}, seeds=SEEDS,
                              out_dir=tmp_path, **tiny)
    rows = {r["policy"]: r for r in payload["results"]}
    assert set(rows) == {"network-by-value(grouped-threshold)", "network-by-value(section-threshold)",
                         "network-by-value(eager)", "network-by-value(mine)"}
    assert payload["best_rule"][net] == min(("network-by-value(grouped-threshold)",
                                             "network-by-value(section-threshold)"),
                                            key=lambda name: rows[name]["mean_cost"])
    assert all(r["normalised_score"] is None and r["normalised_score_ci"] is None for r in rows.values())
    bound = payload["bound"][net]
    assert bound["available"] is False and "share one tamping machine" in bound["reason"]
    config = NetworkConfig.coerce(None, **tiny)
    direct, mine = evaluate_many([NetworkRule(agent, "value").bind(config),
                                  NetworkRule(CallablePolicy(above_two), "value").bind(config)], config, SEEDS)
    assert rows["network-by-value(eager)"]["episode_costs"] == direct.cost.tolist()
    assert rows["network-by-value(mine)"]["episode_costs"] == mine.cost.tolist()
    assert rows["network-by-value(eager)"]["params"]["line_rule"] == "eager"
    assert "No normalised score: 2 lines share one tamping machine" in format_leaderboard(payload)
    assert not (tmp_path / "bounds").exists()


@pytest.mark.slow
@pytest.mark.xdist_group("ray")  # one local Ray at a time (tests/test_experiments_ray.py)
def test_ray_gives_the_single_process_leaderboard(first, tmp_path) -> None:
    """Episodes and searches as Ray tasks (a local Ray, 2 CPUs): the same rows and bound as in one process."""
    pytest.importorskip("ray")
    from trackenv_agents.evaluation.distributed import RayExecutor

    payload, _ = first
    with RayExecutor(num_cpus=2) as executor:
        there = run_leaderboard([ENV], rules=RULES, seeds=SEEDS, out_dir=tmp_path, searches=None, executor=executor,
                            batch_size=1, **TINY)
    assert there["results"] == payload["results"]
    drop = ("seconds", "search_seconds_per_episode")
    assert ({k: v for k, v in there["bound"][ENV].items() if k not in drop}
            == {k: v for k, v in payload["bound"][ENV].items() if k not in drop})


def test_the_committed_leaderboard_is_the_default_commands_output() -> None:
    """The documentation's tables are the committed leaderboard.md, which is the command's rendering of the
    committed leaderboard.json: its command, its default seeds and suite, every committed baseline scored on the
    default line (where they were trained) and listed as not scored elsewhere, the model-predictive planner and the
    60 m track's agent (the planner its advisor) scored on the 60 m track only (the one scenario measured every
    step without error), and the page that includes it."""
    from pathlib import Path

    from trackenv_agents.evaluation.leaderboard import DEFAULT_SEEDS, DEFAULT_SUITE

    root = Path(__file__).resolve().parents[3]
    folder = root / "experiments" / "saved" / "leaderboard"
    saved = json.loads((folder / "leaderboard.json").read_text())
    command = ("trackenv leaderboard --out experiments/saved/leaderboard "
               "--policies rules,cpi-agent,cpi-choice-agent,cpi-track60-agent,model-predictive,baselines")
    assert saved["command"] == command
    assert saved["seeds"] == {env: list(DEFAULT_SEEDS[env]) for env in DEFAULT_SUITE}
    baselines = {p.stem for p in (root / "experiments" / "saved" / "baselines").iterdir()
                 if p.suffix == ".zip" or p.is_dir()}
    assert len(baselines) == 3
    line = "trackenv/TampingLine-v0"
    assert baselines <= {r["policy"] for r in saved["results"] if r["env"] == line}
    # the network's lines are the default line: the baselines play each of its lines
    here = (line, "trackenv/TampingNetwork-v0")
    planner, track60 = {"model-predictive", "cpi-track60-agent"}, "trackenv/Tamping-v1"
    assert all(set(saved["not_scored"][env]) == (set() if env in here else baselines) | (
        set() if env == track60 else planner) for env in DEFAULT_SUITE)
    for name in planner:
        assert {r["env"] for r in saved["results"] if r["policy"] == name} == {track60}
    assert (folder / "leaderboard.md").read_text() == format_leaderboard(saved)
    page = (root / "docs" / "leaderboard.md").read_text()
    assert command in page and '--8<-- "experiments/saved/leaderboard/leaderboard.md"' in page


def test_the_network_rows_name_the_dispatch_their_policies_play() -> None:
    """``on_network`` and ``policy_label`` give the network's rows the NetworkRule of a dispatch and its name: by
    requests ``network(<policy>)``, by value (the default) ``network-by-value(<policy>)``; on a line, the
    policy."""
    from trackenv_agents.evaluation.leaderboard import NETWORK_DISPATCH, on_network, policy_label
    from trackenv_agents.rules import GroupedThreshold

    net, line = NetworkConfig(), scenario("default")
    rule = GroupedThreshold()
    assert NETWORK_DISPATCH == "value"
    by_requests = on_network(rule, net, "requests")
    assert by_requests.name == policy_label("grouped-threshold", net, "requests") == "network(grouped-threshold)"
    by_value = on_network(rule, net)
    assert by_value.name == policy_label("grouped-threshold", net) == "network-by-value(grouped-threshold)"
    assert on_network(rule, line, "value") is rule and policy_label("grouped-threshold", line) == "grouped-threshold"


def test_a_trained_agent_plays_the_network_eager() -> None:
    """On the network a trained line agent plays eager where the machine stays (``eager_for``), and its row is
    named so; a rule does not."""
    pytest.importorskip("stable_baselines3")
    from trackenv_agents.evaluation.leaderboard import on_network, policy_label
    from trackenv_agents.learning.line import DEFAULT_LINE_PRETRAINED, load_line_trained
    from trackenv_agents.rules import GroupedThreshold
    from trackenv_agents.rules.network import NETWORK_EAGER_PROBABILITY

    agent = load_line_trained(DEFAULT_LINE_PRETRAINED, name="cpi-agent")
    net, line = NetworkConfig(), scenario("default")
    played = on_network(agent, net)
    assert played.eager_probability == NETWORK_EAGER_PROBABILITY
    assert played.name == policy_label("cpi-agent", net, policy=agent) == (
        f"network-by-value(cpi-agent, eager {NETWORK_EAGER_PROBABILITY:g})")
    assert on_network(GroupedThreshold(), net).eager_probability is None
    assert on_network(agent, line) is agent and policy_label("cpi-agent", line, policy=agent) == "cpi-agent"
