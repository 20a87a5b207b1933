"""NetworkRule: the line rule on every line, the machine kept on its line while there is work there, else sent
where the most is; its actions through the network env and the evaluation harness."""

import numpy as np
import pytest

from trackenv.envs.network import NetworkConfig
from trackenv.envs.network_env import TampingNetwork
from trackenv_agents.evaluation.harness import evaluate_many
from trackenv_agents.rules import NetworkRule, SectionThreshold
from trackenv_agents.rules.network import line_view

S = 4


def _obs(sd_mm: np.ndarray, machine: int) -> dict[str, np.ndarray]:
    """A batched network observation of one network of len(sd_mm) // S lines, never tamped in the episode."""
    n_lines = sd_mm.size // S
    zeros = np.zeros((1, sd_mm.size), dtype=np.float32)
    return {"section_sd": sd_mm[None].astype(np.float32), "section_peak": zeros, "register": zeros,
            "tampings": zeros, "tampings_since_renewal": zeros, "years_since_tamping": zeros + 1.0,
            "measurement_age": np.zeros((1, n_lines), np.float32), "budget_left": np.ones((1, n_lines), np.float32),
            "time": np.zeros((1, 1), np.float32),
            "machine_line": (np.arange(n_lines) == machine).astype(np.float32)[None]}


def test_stays_while_its_line_has_work_else_asks_for_all():
    rule = NetworkRule(SectionThreshold(threshold_mm=2.0, capacity=2))
    sd = np.array([3.0, 1.0, 1.0, 1.0,  3.0, 3.0, 3.0, 1.0,  1.0, 1.0, 1.0, 1.0])
    act, _ = rule.predict(_obs(sd, machine=0))
    assert act.shape == (1, 3 * S) and np.flatnonzero(act[0]).tolist() == [0]  # its own line's one section
    sd[0] = 1.0
    act, _ = rule.predict(_obs(sd, machine=0))
    assert np.flatnonzero(act[0]).tolist() == [S + 0, S + 1]  # the line rule's two worst (capacity 2) on line 1


def test_runs_on_the_env_and_the_harness():
    env = TampingNetwork(line_config="small", n_lines=2, horizon_years=0.5)
    rule = NetworkRule(SectionThreshold(threshold_mm=0.0)).bind(env.config)
    obs, _ = env.reset(seed=0)
    act, _ = rule.predict(obs)
    assert act.shape == (2 * 6,) and not act[6:].any() and act[:6].sum() <= env.config.capacity
    config = NetworkConfig.coerce(None, line_config="small", n_lines=2, horizon_years=0.5)
    (result,) = evaluate_many([NetworkRule()], config, seeds=[0, 1], batch_size=2)
    assert result.cost.shape == (2,) and (result.cost > 0).all()
    assert np.allclose(result.cost, -result.sum_rewards, rtol=1e-12, atol=0)
    assert set(result.cost_parts) == set(NetworkConfig.cost_keys())


def _shipped_agent():
    pytest.importorskip("stable_baselines3")
    from trackenv_agents.learning.line import DEFAULT_LINE_PRETRAINED, load_line_trained

    return load_line_trained(DEFAULT_LINE_PRETRAINED, name="cpi-agent")


def test_the_shipped_line_agent_plays_the_network_with_valid_actions():
    """The tamp-or-wait agent on every line of three: its actions are the network's MultiBinary, each line's
    requests are the agent's own on that line (never more than the line's capacity), and while the machine's
    line has requests no other line's are asked for."""
    agent = _shipped_agent()
    env = TampingNetwork(line_config="small", n_lines=3, horizon_years=4.0)
    rule = NetworkRule(agent).bind(env.config)
    assert rule.name == "network(cpi-agent)" and rule.params == {"line_rule": "cpi-agent"}
    line = agent.bind(env.config.line_config)
    obs, _ = env.reset(seed=4)
    asked = 0
    for _ in range(env.config.horizon_steps):
        act, _ = rule.predict(obs)
        assert act.dtype == np.int8 and env.action_space.contains(act)
        own = line.predict(line_view({k: v[None] for k, v in obs.items()}, 3))[0]  # (3 lines, 6 sections)
        per_line = act.reshape(3, 6)
        assert (per_line <= own).all() and (per_line.sum(axis=1) <= env.config.capacity).all()
        here = int(obs["machine_line"].argmax())
        if own[here].any():
            assert np.array_equal(per_line[here], own[here]) and per_line.sum() == own[here].sum()
        else:
            assert np.array_equal(per_line, own)
        asked += int(act.sum())
        obs, *_ = env.step(act)
    assert asked > 0  # the agent asked for work on this episode: the checks above saw requests


def test_on_a_one_line_network_the_agent_is_the_line_agent():
    """With one line the machine never leaves it, so the network policy asks what the line agent asks, and its
    episode costs what the line agent's costs on the same line, bit for bit."""
    from trackenv.envs.line_config import scenario
    from trackenv.envs.network import line_seeds

    agent = _shipped_agent()
    config = NetworkConfig.coerce(None, line_config="small", n_lines=1, horizon_years=1.5)
    env = TampingNetwork(config)
    rule, line = NetworkRule(agent).bind(config), agent.bind(config.line_config)
    obs, _ = env.reset(seed=5)
    for _ in range(config.horizon_steps):
        act, _ = rule.predict(obs)
        assert np.array_equal(act, line.predict({k: v for k, v in obs.items() if k != "machine_line"})[0])
        obs, *_ = env.step(act)
    seeds = [5, 6]
    (on_network,) = evaluate_many([NetworkRule(agent)], config, seeds=seeds, batch_size=2)
    line_cfg = scenario("small", horizon_years=1.5)
    (alone,) = evaluate_many([agent], line_cfg, seeds=[line_seeds(np.random.default_rng(s), 1)[0] for s in seeds])
    assert np.array_equal(on_network.cost, alone.cost) and on_network.section_tampings.sum() > 0


def test_eager_needs_an_agent_and_a_probability_in_range():
    with pytest.raises(ValueError, match="eager_probability needs a line policy"):
        NetworkRule(SectionThreshold(), eager_probability=0.2)
    agent = _shipped_agent()
    for bad in (0.0, 0.6, float("nan")):
        with pytest.raises(ValueError, match="eager_probability"):
            NetworkRule(agent, "value", eager_probability=bad)
    rule = NetworkRule(agent, "value", eager_probability=0.15)
    assert rule.name == "network-by-value(cpi-agent, eager 0.15)" and rule.params["eager_probability"] == 0.15
    bound = rule.bind(NetworkConfig.coerce(None, line_config="small", n_lines=2, horizon_years=1.0))
    assert bound.eager_probability == 0.15 and bound.name == rule.name


def test_eager_for_gives_the_agents_their_probability_and_the_rules_none():
    from trackenv_agents.rules.network import NETWORK_EAGER_PROBABILITY, eager_for

    assert eager_for(SectionThreshold()) is None
    assert eager_for(_shipped_agent()) == NETWORK_EAGER_PROBABILITY


def test_agent_requests_from_a_probability():
    """``LineAgent.requests``: from one half it asks what ``predict`` asks; from a lower probability a superset
    (up to the capacity), never a section the env would drop."""
    from trackenv.envs.line import TampingLine
    from trackenv.envs.line_config import scenario
    from trackenv_agents.learning.line_policy import may_tamp

    config = scenario("small")
    agent = _shipped_agent().bind(config)
    env = TampingLine(config)
    obs, _ = env.reset(seed=3)
    grew = False
    for _ in range(12):
        batch = {k: np.asarray(v)[None] for k, v in obs.items()}
        half = agent.requests(batch, 0.5)[0]
        low = agent.requests(batch, 0.1)[0]
        assert np.array_equal(half, agent.predict(obs)[0].astype(bool))
        assert low.sum() <= config.capacity and (low >= half).all() and not (low & ~may_tamp(batch, config)[0]).any()
        grew |= bool(low.sum() > half.sum())
        obs, *_ = env.step(agent.predict(obs)[0])
    assert grew  # the lower probability asked for more somewhere
    with pytest.raises(ValueError, match="probability"):
        agent.requests({k: np.asarray(v)[None] for k, v in obs.items()}, 0.0)


def test_eager_asks_more_only_on_the_line_the_machine_stays_on():
    """Eager by value: where the dispatch keeps the machine on its line, that line asks for the agent's requests
    from the eager probability as well as its own; no other line's requests change; where the machine leaves,
    nothing is added."""
    agent = _shipped_agent()
    env = TampingNetwork(line_config="small", n_lines=3, horizon_years=4.0)
    plain = NetworkRule(agent, "value").bind(env.config)
    eager = NetworkRule(agent, "value", eager_probability=0.1).bind(env.config)
    line = agent.bind(env.config.line_config)
    obs, _ = env.reset(seed=4)
    added = 0
    for _ in range(env.config.horizon_steps):
        a_plain, _ = plain.predict(obs)
        a_eager, _ = eager.predict(obs)
        here = int(obs["machine_line"].argmax())
        p_lines, e_lines = a_plain.reshape(3, 6), a_eager.reshape(3, 6)
        others = np.arange(3) != here
        assert np.array_equal(p_lines[others], e_lines[others])
        soon = line.requests(line_view({k: v[None] for k, v in obs.items()}, 3), 0.1)[here]
        if p_lines[others].any():  # the dispatch sends the machine elsewhere: nothing added here
            assert np.array_equal(e_lines[here], p_lines[here])
        else:
            assert np.array_equal(e_lines[here], p_lines[here] | soon)
            added += int(e_lines[here].sum() - p_lines[here].sum())
        assert env.action_space.contains(a_eager)
        obs, *_ = env.step(a_eager)
    assert added > 0  # the eager policy asked for more on this episode


@pytest.mark.parametrize("dispatch", ["requests", "value"])
def test_lines_of_their_own_each_get_the_rule_bound_to_their_config(dispatch):
    """On a network of lines of their own the line rule is bound to each line's config (its capacity) and asked on
    that line's slice of the observation: each line's requests are the plain line rule's on that line."""
    lines = ["small", {"n_sections": 4, "section_length_m": 150.0, "capacity": 2}, {"n_sections": 8, "capacity": 3}]
    env = TampingNetwork(line_config=lines, horizon_years=1.0)
    config = env.config
    rule = NetworkRule(SectionThreshold(threshold_mm=0.5), dispatch).bind(config)
    plain = [SectionThreshold(threshold_mm=0.5).bind(line) for line in config.line_configs]
    obs, _ = env.reset(seed=5)
    offsets = config.line_offsets
    for _ in range(config.horizon_steps):
        act, _ = rule.predict(obs)
        assert env.action_space.contains(act) and act.shape == (18,)
        for line, own_rule in enumerate(plain):
            mine = {k: (v if k == "time" else v[[line]] if v.shape == (3,) else v[offsets[line]:offsets[line + 1]])
                    for k, v in obs.items() if k != "machine_line"}
            own = own_rule.predict({k: v[None] for k, v in mine.items()})[0][0]
            part = act[offsets[line]:offsets[line + 1]]
            assert (part <= own).all() and part.sum() <= config.line_configs[line].capacity
            if dispatch == "requests" and line == int(obs["machine_line"].argmax()) and own.any():
                assert np.array_equal(part, own)  # the machine's line asks: its requests are passed on whole
        obs, *_ = env.step(act)


def test_an_unbound_rule_on_lines_of_their_own_asks_to_be_bound():
    env = TampingNetwork(line_config=["small", {"n_sections": 4, "capacity": 2}, {"n_sections": 4, "capacity": 2}],
                         horizon_years=0.5)
    obs, _ = env.reset(seed=0)
    with pytest.raises(ValueError, match="bind the rule to the network's config first"):
        NetworkRule(SectionThreshold()).predict(obs)
    act, _ = NetworkRule(SectionThreshold()).bind(env.config).predict(obs)
    assert act.shape == (14,)


def test_evaluate_refuses_a_network_of_lines_of_their_own_naming_why(capsys):
    from trackenv_agents.cli import main

    lines = 'line_config=["small", {"n_sections": 4, "capacity": 2}]'
    assert main(["evaluate", "--env", "trackenv/TampingNetwork-v0", "--set", lines, "--seeds", "0:1"]) == 2
    assert "a network of lines of their own is not scored by evaluate" in capsys.readouterr().err
