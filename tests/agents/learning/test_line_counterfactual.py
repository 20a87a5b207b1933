"""Counterfactual pricing of one section's choice: each fork is what the env gives for that section when it
makes the other choice and the policy goes on deciding for it, the other sections as they were."""

import numpy as np
import pytest
from fork_replays import SHARED, line_cost_to_go, line_cost_to_go_remembering

from trackenv.envs.line import TampingLine
from trackenv.envs.line_config import scenario
from trackenv_agents.evaluation.harness import bind_policy
from trackenv_agents.learning.line_counterfactual import line_forks, section_counterfactuals
from trackenv_agents.rules.line import GroupedThreshold
from trackenv_agents.rules.model_predictive import ModelPredictive

CFG = scenario("small", horizon_years=2.0)


def _section_cost_to_go(cfg, seed, policy, others, j, t, first):
    """Section j's cost from step t (its own costs plus the possession where it tamps alone) in the env, when the
    other sections replay ``others`` (H, S) and section j follows ``policy`` except ``first`` at step t."""
    env = TampingLine(cfg)
    obs, _ = env.reset(seed=seed)
    cost = 0.0
    for step in range(cfg.horizon_steps):
        a = others[step].astype(np.int8).copy()
        a[j] = first if step == t else policy.predict(obs)[0][j]
        obs, _, _, _, info = env.step(a)
        if step >= t:
            tamped = info["tamped_sections"]
            alone = tamped[j] and tamped.sum() == 1
            cost += info["section_costs"][j] + cfg.possession_cost * alone
    return cost


def test_forks_are_the_envs_section_costs_under_the_other_choice():
    rule = bind_policy(GroupedThreshold(trigger_mm=1.5, include_mm=1.0), CFG)
    seeds = [3, 4]
    data = section_counterfactuals(CFG, seeds, rule, focus_rate=0.3, other_rate=0.05, seed=1)
    n = len(data["q_do"])
    assert n > 5 and data["features"].shape[0] == n and (data["weight"] >= 1.0).all()
    assert set(np.unique(data["weight"])) <= {1 / 0.3, 1 / 0.05}
    # the policy's own run, as the env records it
    plans = {}
    for s in seeds:
        env, plan = TampingLine(CFG), []
        obs, _ = env.reset(seed=s)
        for _ in range(CFG.horizon_steps):
            obs, *_, info = env.step(rule.predict(obs)[0])
            plan.append(info["tamped_sections"])
        plans[s] = np.array(plan)
    rng = np.random.default_rng(0)
    for k in rng.choice(n, size=4, replace=False):
        s, t, j, acted = int(data["seed"][k]), int(data["step"][k]), int(data["section"][k]), bool(data["did"][k])
        assert plans[s][t, j] == acted
        other = _section_cost_to_go(CFG, s, rule, plans[s], j, t, int(not acted))
        own = _section_cost_to_go(CFG, s, rule, plans[s], j, t, int(acted))
        q_other, q_own = (data["q_skip"][k], data["q_do"][k]) if acted else (data["q_do"][k], data["q_skip"][k])
        assert q_other == pytest.approx(other, rel=1e-9) and q_own == pytest.approx(own, rel=1e-9)
    with pytest.raises(ValueError, match="focus_rate"):
        section_counterfactuals(CFG, seeds, rule, focus_rate=0.0)




def _own_and_flipped(steps, section, n_sections, flipped_at):
    """A ``choose`` for :func:`line_forks`: every line forked at each of ``steps`` twice, once with the policy's
    codes and once with ``section``'s flipped (kept in ``flipped_at[t]``); no fork at other steps."""

    def choose(t, obs, codes, allowed):
        if t not in steps:
            return np.zeros(0, dtype=np.int64), np.zeros((0, n_sections), dtype=np.int64)
        flipped = codes.copy()
        flipped[:, section] = 1 - flipped[:, section]
        flipped_at[t] = flipped
        lines = np.arange(len(codes))
        return np.concatenate([lines, lines]), np.concatenate([codes, flipped])

    return choose


def test_a_whole_line_fork_of_the_policys_own_choice_is_its_run_and_another_choice_is_not():
    rule = bind_policy(GroupedThreshold(trigger_mm=1.5, include_mm=1.0), SHARED)
    picked = {}
    run = line_forks(SHARED, [3, 4], rule, _own_and_flipped((2, 5), 1, SHARED.n_sections, picked))
    assert run["line"].tolist() == [0, 1, 0, 1, 0, 1, 0, 1] and run["step"].tolist() == [2] * 4 + [5] * 4
    own = run["to_go"][run["step"], run["line"]]
    same, other = np.array([0, 1, 4, 5]), np.array([2, 3, 6, 7])
    np.testing.assert_array_equal(run["cost"][same], own[same])  # exactly: the same episode, copied
    assert (run["cost"][other] != own[other]).all()
    for k in other:  # the other choice, as the env prices it when the line replays it
        t, line = int(run["step"][k]), int(run["line"][k])
        assert run["cost"][k] == pytest.approx(line_cost_to_go(SHARED, [3, 4][line], rule, t, picked[t][line]),
                                               rel=1e-9)
    np.testing.assert_array_equal(run["applied"][other], np.concatenate([picked[2], picked[5]]))


def test_shared_segment_counterfactuals_price_the_whole_line():
    rule = bind_policy(GroupedThreshold(trigger_mm=1.5, include_mm=1.0), SHARED)
    seeds = [3, 4, 5]
    data = section_counterfactuals(SHARED, seeds, rule, focus_rate=0.5, other_rate=0.3, seed=1)
    n = len(data["q_do"])
    assert n > 5 and data["features"].shape[0] == n and (data["weight"] >= 1.0).all()
    assert not np.allclose(data["q_do"], data["q_skip"])
    for k in np.random.default_rng(0).choice(n, size=3, replace=False):
        s, t, j, acted = int(data["seed"][k]), int(data["step"][k]), int(data["section"][k]), bool(data["did"][k])
        env = TampingLine(SHARED)
        obs, _ = env.reset(seed=s)
        for _ in range(t):
            obs, *_ = env.step(rule.predict(obs)[0])
        codes = np.asarray(rule.predict(obs)[0], dtype=np.int64)
        assert bool(codes[j]) == acted
        flipped = codes.copy()
        flipped[j] = 1 - flipped[j]
        q_own, q_other = (data["q_do"][k], data["q_skip"][k]) if acted else (data["q_skip"][k], data["q_do"][k])
        assert q_own == pytest.approx(line_cost_to_go(SHARED, s, rule, t, codes), rel=1e-9)
        assert q_other == pytest.approx(line_cost_to_go(SHARED, s, rule, t, flipped), rel=1e-9)


class _RemembersTheLine:
    """A policy whose recurrent state is one record per line (a tuple): single-section forks refuse it."""

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        n, S = np.shape(obs["section_sd"])
        return np.zeros((n, S), dtype=np.int8), (np.zeros((n, 2, S)), np.zeros((n, S)))


class _Remembers:
    """A policy with a recurrent state: whole-line forks refuse it."""

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        n = len(obs["section_sd"])
        return np.zeros((n, SHARED.n_sections), dtype=np.int8), np.zeros((n, 1, SHARED.n_sections))


def test_whole_line_forks_carry_on_a_state_that_records_what_the_policy_was_shown():
    """The model-predictive planner forecasts from the SD history it has seen (its recurrent state): a fork takes
    its line's state as the run left it and carries it on, so it prices a flip as the env does when the line
    replays the planner with its history."""
    cheap = scenario("track60", n_sections=3, segment_length_m=30.0, sections_per_segment=3, capacity=3,
                     horizon_years=2.0, possession_cost=0.3, tamping_cost_per_m=0.01)  # so that it tamps
    # without its history: no growth seen, and no slope learnt from a section's own tamping
    planner = ModelPredictive(prior_growth_mm_per_step=0.0, own_slope_weight=0.5).bind(cheap)
    flips = {}
    run = line_forks(cheap, [3, 4], planner, _own_and_flipped((1, 3), 0, cheap.n_sections, flips))
    own = run["to_go"][run["step"], run["line"]]
    same, other = np.array([0, 1, 4, 5]), np.array([2, 3, 6, 7])
    np.testing.assert_array_equal(run["cost"][same], own[same])
    for k in other:
        t, line = int(run["step"][k]), int(run["line"][k])
        assert run["cost"][k] == pytest.approx(
            line_cost_to_go_remembering(cheap, [3, 4][line], planner, t, flips[t][line]), rel=1e-9)
    # without its history the planner decides otherwise on some of these forks: the state matters here
    stateless = [line_cost_to_go(cheap, [3, 4][int(run["line"][k])], planner, int(run["step"][k]),
                                 flips[int(run["step"][k])][int(run["line"][k])]) for k in other]
    assert not np.allclose(stateless, run["cost"][other], rtol=1e-9)


def test_whole_line_forks_refuse_what_they_cannot_price():
    with pytest.raises(ValueError, match="recurrent state"):
        section_counterfactuals(SHARED, [3], _Remembers())
    with pytest.raises(ValueError, match="forks of single sections"):  # a whole line's state, not a section's
        section_counterfactuals(CFG, [3], _RemembersTheLine())
    rule = bind_policy(GroupedThreshold(trigger_mm=1.5, include_mm=1.0), SHARED)
    with pytest.raises(ValueError, match="2 lines and 1 rows"):
        line_forks(SHARED, [3], rule, lambda t, obs, codes, allowed: (np.zeros(2, dtype=np.int64), codes))
    with pytest.raises(ValueError, match="copy_rows forks single sections"):
        from trackenv.envs.line_episode import LineBatch

        LineBatch(SHARED, 2).copy_rows(np.array([0]), LineBatch(SHARED, 1), np.array([0]))
