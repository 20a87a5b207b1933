"""Counterfactual pricing of one section's choice: each fork is what the env gives for that section when it
makes the other choice and the policy goes on deciding for it, the other sections as they were."""

import numpy as np
import pytest

from trackenv.envs.line import TampingLine
from trackenv.envs.line_config import scenario
from trackenv_agents.evaluation.harness import bind_policy
from trackenv_agents.learning.line_counterfactual import section_counterfactuals
from trackenv_agents.rules.line import GroupedThreshold

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
