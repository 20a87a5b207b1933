"""The value dispatch of the network's machine: a section's value is the line's quality cost of its projected
state, a line's the sum over its requests, and the machine goes to the line whose requests are worth most, with a
margin before it leaves work on its own line."""

import numpy as np
import pytest

from trackenv.envs.costs import section_quality_costs
from trackenv.envs.line_config import LineConfig
from trackenv.envs.network import NetworkConfig
from trackenv_agents.rules import NetworkRule, SectionThreshold
from trackenv_agents.rules.dispatch import ValueDispatch, section_cost_rates

S = 4


def _line_obs(sd_mm, peak_mm, years_since=1.0, age=0.0) -> dict[str, np.ndarray]:
    """A batched line observation (one line per row) of sections never tamped in the episode."""
    sd = np.atleast_2d(np.asarray(sd_mm, dtype=np.float32))
    zeros = np.zeros_like(sd)
    n = sd.shape[0]
    return {"section_sd": sd, "section_peak": np.atleast_2d(np.asarray(peak_mm, dtype=np.float32)),
            "register": zeros, "tampings": zeros, "tampings_since_renewal": zeros,
            "years_since_tamping": zeros + years_since, "measurement_age": np.full((n, 1), age, np.float32),
            "budget_left": np.ones((n, 1), np.float32), "time": np.zeros((n, 1), np.float32)}


def _network_obs(sd_mm, peak_mm, machine: int) -> dict[str, np.ndarray]:
    """A batched network observation of len(sd_mm) // S lines, measured just now, never tamped."""
    n_lines = len(sd_mm) // S
    line = _line_obs(np.reshape(sd_mm, (n_lines, S)), np.reshape(peak_mm, (n_lines, S)))
    out = {k: v.reshape(1, -1) for k, v in line.items() if k != "time"}
    return {**out, "time": np.zeros((1, 1), np.float32),
            "machine_line": (np.arange(n_lines) == machine).astype(np.float32)[None]}


def test_a_sections_rate_is_the_lines_quality_cost_of_its_measured_state():
    """Measured now (no projection), the rate is the env's own quality cost of that state: the geometry cost and
    the cost of the class of the peak against the line's limits (below alert, at intervention, at immediate
    action)."""
    config = LineConfig(n_sections=S, capacity=3)
    limits = config.quality_limits.for_speed(config.speed)
    peaks_mm = [0.5 * limits.alert_m * 1e3, limits.intervention_m * 1e3, limits.immediate_action_m * 1e3 + 1, 1.0]
    sd_mm = [1.0, 2.0, 3.0, 4.0]
    rates = section_cost_rates(_line_obs(sd_mm, peaks_mm), config)
    geometry = config.geometry_cost_per_section_year / config.steps_per_year * (np.array(sd_mm) * 1e-3
                                                                                / limits.sd_alert_m) ** 2
    expected = geometry + [0.0, config.speed_restriction_cost, config.immediate_action_cost, config.alert_cost]
    assert rates.shape == (1, S) and np.allclose(rates[0], expected, rtol=1e-5)
    env_parts = section_quality_costs(np.array(sd_mm) * 1e-3, np.array([0, 2, 3, 0]), sd_alert_m=limits.sd_alert_m,
                                      geometry_cost_per_section_year=config.geometry_cost_per_section_year,
                                      steps_per_year=config.steps_per_year, class_costs=config.class_costs)
    assert np.allclose(rates[0], sum(env_parts.values()), rtol=1e-5)


def test_the_rate_projects_a_growing_section_past_the_limit():
    """A section measured a year after its last tamping just below the intervention limit crosses it when
    carried on a half year at its growth: the speed restriction is priced with a lead, not without."""
    config = LineConfig(n_sections=S, capacity=3)
    limit_mm = config.quality_limits.for_speed(config.speed).intervention_m * 1e3
    obs = _line_obs([2.0] * S, [0.95 * limit_mm] * S)
    now, ahead = section_cost_rates(obs, config), section_cost_rates(obs, config, lead_years=0.5)
    assert (ahead - now > config.speed_restriction_cost - 1.0).all()


def test_the_machine_goes_to_the_line_whose_requests_are_worth_most():
    """Line 1 asks for three sections of little value, line 2 for two at the immediate-action limit: by requests
    the machine goes to line 1 (the most sections), by value (the default dispatch) to line 2, and only line 2's
    requests are passed on. The machine on line 0 with one low-value request of its own leaves it for line 2
    too, whose requests are worth more by the margin."""
    config = NetworkConfig(n_lines=3, line_config={"n_sections": S, "capacity": 3})
    ial_mm = config.line_config.quality_limits.for_speed(config.line_config.speed).immediate_action_m * 1e3
    sd = np.array([0.5, 0.5, 0.5, 0.5, 2.5, 2.5, 2.5, 0.5, 0.5, 0.5, 3.0, 3.0])
    peak = np.where(np.arange(3 * S) >= 2 * S + 2, ial_mm + 1.0, 2.0)
    rule = SectionThreshold(threshold_mm=2.0)
    by_count = NetworkRule(rule).bind(config)
    by_value = NetworkRule(rule, dispatch="value").bind(config)
    assert 2 * config.line_config.immediate_action_cost > by_value.dispatch.switch_margin
    counted = by_count.predict(_network_obs(sd, peak, machine=0))[0][0]
    assert counted.reshape(3, S).sum(axis=1).tolist() == [0, 3, 2]  # every line's: the env goes to line 1
    urgent = [2 * S + 2, 2 * S + 3]
    assert np.flatnonzero(by_value.predict(_network_obs(sd, peak, machine=0))[0][0]).tolist() == urgent
    sd[0] = 2.5  # the machine's line asks for one plain section
    assert np.flatnonzero(by_count.predict(_network_obs(sd, peak, machine=0))[0][0]).tolist() == [0]
    assert np.flatnonzero(by_value.predict(_network_obs(sd, peak, machine=0))[0][0]).tolist() == urgent


def test_the_margin_keeps_the_machine_on_its_line_while_it_asks():
    """Another line worth more by less than the margin does not take the machine from work on its own line; a
    line that asks for nothing is left for the best line that asks; no request anywhere: nothing asked."""
    dispatch = ValueDispatch(switch_margin=20.0)
    values = np.array([[10.0, 25.0, 0.0], [10.0, 31.0, 0.0], [0.0, 3.0, 5.0], [0.0, 0.0, 0.0]])
    asked = np.array([[True, True, False], [True, True, False], [False, True, True], [False, False, False]])
    here = np.array([0, 0, 0, 1])
    assert dispatch.target(values, asked, here).tolist() == [0, 1, 2, 1]
    # a move dearer than the margin is weighed instead: from a line that asks, and from one that does not
    assert dispatch.target(values, asked, here, move_cost=10.0).tolist() == [0, 1, 2, 1]
    assert dispatch.target(values, asked, here, move_cost=25.0).tolist() == [0, 0, 0, 1]


def test_a_bound_value_rule_weighs_the_networks_move_cost():
    """On a network whose move costs 1000 k€, the value rule without a margin never takes the machine from a line
    that asks (with the move free it does)."""
    from trackenv.envs.network_env import TampingNetwork
    from trackenv_agents.rules import NetworkRule, SectionThreshold

    def moves_from_asking_lines(move_cost: float) -> int:
        env = TampingNetwork(line_config="small", n_lines=3, horizon_years=2.0, move_cost=move_cost)
        rule = NetworkRule(SectionThreshold(threshold_mm=0.5), ValueDispatch(switch_margin=0.0)).bind(env.config)
        obs, _ = env.reset(seed=1)
        moves = 0
        for _ in range(env.config.horizon_steps):
            action, _ = rule.predict(obs)
            asks_here = rule.last_requests.reshape(3, 6)[int(obs["machine_line"].argmax())].any()
            obs, _, _, _, info = env.step(action)
            moves += bool(info["moved"] and asks_here)
        return moves

    assert moves_from_asking_lines(1000.0) == 0 and moves_from_asking_lines(0.0) > 0


def test_the_value_dispatch_plays_the_env_and_the_harness_and_the_default_is_unchanged():
    """By value on a small network: valid actions, one line's requests at a time; by requests (the default),
    the same actions as the rule always gave (the machine's line while it asks, else every line's), and the same
    name and params."""
    from trackenv.envs.network_env import TampingNetwork
    from trackenv_agents.evaluation.harness import evaluate_many
    from trackenv_agents.rules.network import line_view

    env = TampingNetwork(line_config="small", n_lines=3, horizon_years=3.0)
    line = SectionThreshold(threshold_mm=1.5).bind(env.config.line_config)
    default = NetworkRule(SectionThreshold(threshold_mm=1.5)).bind(env.config)
    by_value = NetworkRule(SectionThreshold(threshold_mm=1.5), dispatch="value").bind(env.config)
    assert default.name == "network(section-threshold)" and "dispatch" not in default.params
    assert by_value.name == "network-by-value(section-threshold)"
    assert by_value.params["dispatch"] == "value" and by_value.params["switch_margin"] == ValueDispatch().switch_margin
    obs, _ = env.reset(seed=3)
    served = 0
    for _ in range(env.config.horizon_steps):
        own = line.predict(line_view({k: v[None] for k, v in obs.items()}, 3))[0].astype(bool)
        here = int(obs["machine_line"].argmax())
        expected = np.zeros_like(own)
        if own[here].any():
            expected[here] = own[here]
        else:
            expected[:] = own
        assert np.array_equal(default.predict(obs)[0].reshape(3, -1).astype(bool), expected)
        act, _ = by_value.predict(obs)
        per_line = act.reshape(3, -1).astype(bool)
        assert env.action_space.contains(act) and (per_line <= own).all() and per_line.any(axis=1).sum() <= 1
        served += int(act.sum())
        obs, *_ = env.step(act)
    assert served > 0
    config = NetworkConfig.coerce(None, line_config="small", n_lines=2, horizon_years=1.0)
    (result,) = evaluate_many([NetworkRule(dispatch="value")], config, seeds=[0, 1], batch_size=2)
    assert result.policy == "network-by-value(section-threshold)" and (result.cost > 0).all()


def test_bad_dispatches_are_refused():
    with pytest.raises(ValueError, match="dispatch must be one of"):
        NetworkRule(dispatch="nearest")
    with pytest.raises(ValueError, match="switch_margin"):
        ValueDispatch(switch_margin=-1.0)
    obs = _network_obs(np.full(2 * S, 3.0), np.full(2 * S, 1.0), machine=0)
    with pytest.raises(ValueError, match="bind it"):
        NetworkRule(dispatch="value").predict(obs)
