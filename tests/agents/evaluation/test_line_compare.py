"""The line comparison's report: the agents' headlines against the best tuned rule; a user's own policy."""

import numpy as np

from trackenv_agents.evaluation.line_compare import line_comparison


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


def test_a_users_own_policy_is_scored_as_the_agents_page_shows(tmp_path):
    """The page's example: a class with SB3's predict on a batch, scored against a tuned rule with the seeds as a
    range (they failed when the JSON was written), its row named by its name and labelled by its params."""
    class TampAbove:
        name = "tamp-above-2.5mm"
        params = {"threshold_mm": 2.5}

        def predict(self, obs, state=None, episode_start=None, deterministic=True):
            return (obs["section_sd"] >= 2.5).astype(np.int8), state

    result = line_comparison("trackenv/TampingLineSmall-v0", seeds=range(2), rules=["grouped-threshold"],
                             extra={"mine": TampAbove()}, progress=False, out_dir=str(tmp_path), horizon_years=1.0)
    assert result["seeds"] == [0, 1] and result["extra"] == ["tamp-above-2.5mm"]
    mine = next(r for r in result["results"] if r["policy"] == "tamp-above-2.5mm")
    assert mine["params"] == {"threshold_mm": 2.5} and mine["n_episodes"] == 2
    assert (tmp_path / "line_compare.json").exists()


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


def test_a_line_file_is_named_by_its_path_in_what_changed():
    """A table's "changed:" names a line file by its path, not by the whole line (100 kB for the example) nor the
    fields and per-section values the file sets; the JSON's "config" keeps the line itself."""
    from trackenv.lines import EXAMPLE
    from trackenv_agents.evaluation.line_compare import changes_note, config_changes, env_config

    config = env_config("trackenv/TampingLine-v0", line=str(EXAMPLE), horizon_years=1.0)
    changes = config_changes("trackenv/TampingLine-v0", config)
    assert changes == {"horizon_years": 1.0, "line": str(EXAMPLE)}
    assert changes_note(changes) == f"; changed: horizon_years=1.0, line={EXAMPLE}"
