"""The line comparison's report: the agents' headlines against the best tuned rule."""


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
