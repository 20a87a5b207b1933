"""The line comparison's report: the agents' headlines against the best tuned rule; a user's own policy."""

import numpy as np
import pytest

from trackenv_agents.evaluation.line_compare import (
    MAX_EPISODES,
    MAX_SEED,
    format_line_table,
    line_comparison,
    parse_seeds,
)


def test_agent_headline_pairs_the_agent_with_the_best_rule_whichever_policy_is_best():
    """The headline of an agent against the best tuned rule, from each episode's costs, also where a third
    policy (the model-predictive planner on the 60 m track) is the best of the table."""
    from trackenv_agents.evaluation.line_compare import agent_headline

    rows = [{"policy": "planner", "mean_cost": 90.0, "episode_costs": [80.0, 100.0], "vs_best": None},
            {"policy": "rule", "mean_cost": 100.0, "episode_costs": [95.0, 105.0], "vs_best": {}},
            {"policy": "agent", "mean_cost": 110.0, "episode_costs": [105.0, 115.0], "vs_best": {}}]
    payload = {"results": rows, "best_rule": "rule", "seeds": [0, 1]}
    line = agent_headline(payload, "agent")
    assert line is not None and line.startswith("agent vs the best tuned rule (rule), paired over 2 episodes: +10.0")
    assert line.endswith("+10.0 %")
    assert "-10.0 k€" in agent_headline(payload, "planner") and agent_headline(payload, "rule") is None


def test_a_users_own_policy_is_scored_as_the_agents_page_shows(tmp_path, monkeypatch):
    """The page's example: a class with SB3's predict on a batch, scored against a tuned rule with the seeds as a
    range (they failed when the JSON was written), its row named by its key in ``extra`` (as run_leaderboard names
    its agents; it was the policy's ``name``) and labelled by its params; a key that names a scored rule is
    refused before anything runs."""
    class TampAbove:
        name = "tamp-above-2.5mm"
        params = {"threshold_mm": 2.5}

        def predict(self, obs, state=None, episode_start=None, deterministic=True):
            return (obs["section_sd"] >= 2.5).astype(np.int8), state

    from matplotlib.axes import Axes

    titles: list[str] = []
    set_title = Axes.set_title
    monkeypatch.setattr(Axes, "set_title", lambda ax, text, *a, **k: titles.append(text) or set_title(ax, text, *a,
                                                                                                       **k))
    result = line_comparison("trackenv/TampingLineSmall-v0", seeds=range(2), rules=["grouped-threshold"],
                             extra={"mine": TampAbove()}, progress=False, out_dir=str(tmp_path), horizon_years=1.0)
    assert result["seeds"] == [0, 1] and result["extra"] == ["mine"]
    # the episode figure names each panel as its row is named (it used the policy's own name)
    panels = [t.split(" on ")[0] for t in titles if " sections, seed 0" in t]
    assert panels == ["grouped-threshold", "mine"]
    assert {r["policy"] for r in result["results"]} == {"mine", "grouped-threshold"}
    mine = next(r for r in result["results"] if r["policy"] == "mine")
    assert mine["params"] == {"threshold_mm": 2.5} and mine["n_episodes"] == 2
    assert (tmp_path / "line_compare.json").exists()
    with pytest.raises(ValueError, match="extra names grouped-threshold as a rule scored here"):
        line_comparison("trackenv/TampingLineSmall-v0", seeds=[0], rules=["grouped-threshold"],
                        extra={"grouped-threshold": TampAbove()}, progress=False, out_dir=str(tmp_path))


def test_the_network_episode_figure_draws_lines_of_their_own(tmp_path):
    """Each line's panel draws that line's own sections (lines of 6, 4 and 8 sections)."""
    from trackenv.envs.network import NetworkConfig
    from trackenv_agents.evaluation.line_compare import plot_network_episode
    from trackenv_agents.rules import NetworkRule, SectionThreshold

    config = NetworkConfig.coerce(None, line_config=["small", {"n_sections": 4, "capacity": 2},
                                                     {"n_sections": 8, "capacity": 3}], horizon_years=0.5)
    out = plot_network_episode(NetworkRule(SectionThreshold(threshold_mm=0.5)), config, 0, str(tmp_path / "n.png"))
    import matplotlib.image

    assert matplotlib.image.imread(out).ndim == 3


def test_the_episode_plots_hand_predict_a_batch_as_the_harness_does(tmp_path):
    """A policy written for the harness's contract (``predict`` gets a batch of observations, one row per env) draws
    the line's and the network's episode figures: both plots call it with a batch of one (a probe's policy met one
    env's unbatched observation there and failed, after its scores had run)."""
    from trackenv.envs.line_config import LineConfig
    from trackenv.envs.network import NetworkConfig
    from trackenv_agents.evaluation.line_compare import plot_line_episode, plot_network_episode

    class BatchOnly:
        name = "batch-only"
        calls = 0

        def predict(self, obs, state=None, episode_start=None, deterministic=True):
            sd = obs["section_sd"]
            assert sd.ndim == 2 and obs["time"].ndim == 2, "one env's observation, not a batch"
            BatchOnly.calls += 1
            return (sd >= 1.0).astype(np.int8), state

    line = LineConfig(n_sections=6, capacity=3, horizon_years=0.5)
    plot_line_episode([BatchOnly()], line, 0, str(tmp_path / "l.png"))
    network = NetworkConfig.coerce(None, line_config=["small", "small"], horizon_years=0.5)
    plot_network_episode([BatchOnly()], network, 0, str(tmp_path / "n.png"))
    assert BatchOnly.calls == line.horizon_steps + network.horizon_steps


def test_a_line_file_is_named_by_its_path_in_what_changed():
    """A table's "changed:" names a line file by its path, not by the whole line (100 kB for the example) nor the
    fields and per-section values the file sets; the JSON's "config" keeps the line itself."""
    from trackenv.lines import EXAMPLE
    from trackenv_agents.evaluation.line_compare import changes_note, config_changes, env_config

    config = env_config("trackenv/TampingLine-v0", line=str(EXAMPLE), horizon_years=1.0)
    changes = config_changes("trackenv/TampingLine-v0", config)
    assert changes == {"horizon_years": 1.0, "line": str(EXAMPLE)}
    assert changes_note(changes) == f"; changed: horizon_years=1.0, line={EXAMPLE}"


def test_parse_seeds_counts_the_episodes_before_it_builds_them():
    """A range of 10^13 seeds died in MemoryError building the list: refused first, naming --seeds and the most
    episodes; the most is taken, and seeds up to the harness's int64, never below zero."""
    with pytest.raises(ValueError, match=f"^--seeds gives 10000000000000 episodes: at most {MAX_EPISODES} are "):
        parse_seeds("0:10000000000000")
    assert len(parse_seeds(f"5:{5 + MAX_EPISODES}")) == MAX_EPISODES
    with pytest.raises(ValueError, match=f"at most {MAX_EPISODES} are allowed"):
        parse_seeds(",".join(map(str, range(MAX_EPISODES + 1))))
    assert parse_seeds(f"{MAX_SEED - 1}:{MAX_SEED + 1}") == [MAX_SEED - 1, MAX_SEED]
    with pytest.raises(ValueError, match=f"^--seeds must be at most {MAX_SEED}"):
        parse_seeds(f"{MAX_SEED},{MAX_SEED + 1}")
    for text in ("-1:3", "-3,2", "2,-1"):
        with pytest.raises(ValueError, match="^--seeds must be whole numbers >= 0"):
            parse_seeds(text)


def _table_payload(seeds: list[int], low: float, high: float) -> dict:
    rows = [{"policy": "model-predictive", "params": {}, "mean_cost": 124.1, "ci_low": low - 14, "ci_high": high - 14,
             "vs_best": None},
            {"policy": "grouped-threshold", "params": {}, "mean_cost": 138.0, "ci_low": low, "ci_high": high,
             "vs_best": {"mean_difference": 13.9, "ci_low": 11.8, "ci_high": 16.2, "n_episodes": len(seeds)}}]
    return {"env": "trackenv/Tamping-v1", "scenario": "track60", "seeds": seeds, "tuned_from": "shipped",
            "best_rule": "grouped-threshold", "extra": [], "results": rows}


def test_the_table_says_what_it_pairs_with_and_gives_no_ci_on_one_episode():
    """The column pairs each row with the table's cheapest policy (the planner here, not the best rule): its head
    says "vs cheapest"; on one episode a CI of zero width ("198.1 [198.1, 198.1]") is "n/a", and the count is
    singular."""
    two = format_line_table(_table_payload([0, 1], 131.4, 144.6)).splitlines()
    assert two[0].startswith("trackenv/Tamping-v1 (track60), 2 held-out episodes, ")
    assert "vs cheapest (paired, 95% CI)" in two[1] and "vs best" not in two[1]
    assert two[3].split()[1:6] == ["138.0", "[131.4,", "144.6]", "+13.9", "[+11.8,"]
    one = format_line_table(_table_payload([0], 138.0, 138.0)).splitlines()
    assert one[0].startswith("trackenv/Tamping-v1 (track60), 1 held-out episode, ")
    assert "[" not in one[3] and one[3].split()[1:4] == ["138.0", "n/a", "+13.9"]
