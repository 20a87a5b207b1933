"""Campaign forks where sections share a segment: each branch is what the env gives the whole line under that
campaign at the step and the policy afterwards, and each section's two prices are the cheapest branches with and
without it."""

import itertools

import numpy as np
import pytest
from fork_replays import SHARED, line_cost_to_go

from trackenv.envs.line import TampingLine
from trackenv.envs.line_config import scenario
from trackenv_agents.evaluation.harness import bind_policy
from trackenv_agents.learning.line_campaigns import campaign_candidates, campaign_counterfactuals
from trackenv_agents.rules.line import GroupedThreshold


def test_candidates_are_none_the_marginal_sections_and_the_grouped_campaign_within_capacity():
    tamped = np.array([False, True, False, False, True])
    allowed = np.array([True, True, False, True, True])
    sd = np.array([1.2, 2.0, 9.0, 0.5, 3.0])  # section 2 is the worst but may not be tamped

    def campaigns(capacity, include_mm=1.0):
        got = campaign_candidates(tamped, allowed, sd, np.ones(5), capacity, include_mm)
        assert all(not (c == tamped).all() for c in got)  # the policy's own is its run, not a fork
        return [tuple(np.nonzero(c)[0].tolist()) for c in got]

    # none; + the worst left out (0); - the least worst taken (1); the grouped campaign (SD >= 1 mm: 0, 1, 4)
    assert campaigns(5.0) == [(), (0, 1, 4), (4,)]  # the grouped campaign is the first one's repeat
    assert campaigns(5.0, include_mm=2.5) == [(), (0, 1, 4), (4,)]  # grouped: (4,), a repeat
    assert campaigns(2.0) == [(), (4,)]  # three sections are over capacity
    nothing = campaign_candidates(np.zeros(5, bool), allowed, sd, np.ones(5), 5.0, 5.0)
    assert [tuple(np.nonzero(c)[0].tolist()) for c in nothing] == [(4,)]  # the worst allowed, whatever its SD


def test_campaign_prices_are_the_cheapest_env_replays_with_and_without_the_section():
    rule = bind_policy(GroupedThreshold(trigger_mm=1.5, include_mm=1.0), SHARED)
    seeds = [3, 4, 5]
    data = campaign_counterfactuals(SHARED, seeds, rule, focus_rate=0.6, other_rate=0.3, seed=1, alternatives=None)
    n = len(data["q_do"])
    assert n > 5 and data["features"].shape[0] == n and (data["branches"] >= 2).all()
    steps = data["seed"] * 1000 + data["step"]  # the sections a line-step moves share its weight, 1 / its rate
    per_step = np.array([data["weight"][steps == k].sum() for k in np.unique(steps)])
    assert (data["weight"] > 0).all() and (per_step >= 1.0 - 1e-12).all() and (per_step <= 1 / 0.3 + 1e-12).all()
    assert (data["choice"] == 0).all() and not np.allclose(data["q_do"], data["q_skip"])
    S = SHARED.n_sections
    for k in np.random.default_rng(0).choice(n, size=3, replace=False):
        s, t, j = int(data["seed"][k]), int(data["step"][k]), int(data["section"][k])
        env = TampingLine(SHARED)
        obs, _ = env.reset(seed=s)
        for _ in range(t):
            obs, *_ = env.step(rule.predict(obs)[0])
        own = np.asarray(rule.predict(obs)[0], dtype=np.int64)
        assert bool(own[j]) == bool(data["did"][k])
        every = {c: line_cost_to_go(SHARED, s, rule, t, c) for c in itertools.product((0, 1), repeat=S)}
        with_j = [v for c, v in every.items() if c[j]]
        without_j = [v for c, v in every.items() if not c[j]]
        # each price is one campaign's exact replay, no cheaper than the best campaign on its side
        assert min(abs(np.array(with_j) - data["q_do"][k])) <= 1e-9 * data["q_do"][k]
        assert min(abs(np.array(without_j) - data["q_skip"][k])) <= 1e-9 * data["q_skip"][k]
        assert data["q_do"][k] >= min(with_j) - 1e-9 and data["q_skip"][k] >= min(without_j) - 1e-9
        # the policy's own campaign is a branch: the section's price on its side is at most its run's
        mine = data["q_do"][k] if own[j] else data["q_skip"][k]
        assert mine <= every[tuple(own)] + 1e-9 * every[tuple(own)]


def test_one_alternative_a_step_pairs_the_policys_run_with_one_campaign():
    rule = bind_policy(GroupedThreshold(trigger_mm=1.5, include_mm=1.0), SHARED)
    data = campaign_counterfactuals(SHARED, [3, 4, 5], rule, focus_rate=0.6, other_rate=0.3, seed=1)
    assert len(data["q_do"]) > 3 and (data["branches"] == 2).all()
    k = int(np.argmax(np.abs(data["q_do"] - data["q_skip"])))
    s, t = int(data["seed"][k]), int(data["step"][k])
    env = TampingLine(SHARED)
    obs, _ = env.reset(seed=s)
    for _ in range(t):
        obs, *_ = env.step(rule.predict(obs)[0])
    own = rule.predict(obs)[0]
    mine, other = (data["q_do"][k], data["q_skip"][k]) if data["did"][k] else (data["q_skip"][k], data["q_do"][k])
    assert mine == pytest.approx(line_cost_to_go(SHARED, s, rule, t, own), rel=1e-9)
    same_step = (data["seed"] == s) & (data["step"] == t)  # every section that differs shares the one other branch
    assert np.allclose(np.where(data["did"], data["q_skip"], data["q_do"])[same_step], other, rtol=0, atol=0)


def test_campaign_forks_refuse_choice_codes_and_bad_rates():
    rule = GroupedThreshold(trigger_mm=1.5, include_mm=1.0)
    with pytest.raises(ValueError, match="focus_rate"):
        campaign_counterfactuals(SHARED, [3], rule, focus_rate=0.0)
    with pytest.raises(ValueError, match="alternatives"):
        campaign_counterfactuals(SHARED, [3], rule, alternatives=0)
    with pytest.raises(ValueError, match="choice codes"):
        campaign_counterfactuals(scenario("wet"), [3], rule)


def test_policy_iteration_prices_campaigns_where_sections_share_a_segment(tmp_path):
    pytest.importorskip("sb3_contrib")
    import json

    from trackenv_agents.learning.line import train_line

    hp = {"campaign_forks": True, "episodes_per_iteration": 3, "fit_epochs": 2, "net_arch": [16, 16]}
    with pytest.raises(ValueError, match="campaign_forks"):
        train_line("small", hyperparams=hp, out_dir=tmp_path / "no", progress=False, verbose=0)
    train_line(SHARED, iterations=1, total_timesteps=0, n_envs=1, seed=20_000, out_dir=tmp_path / "run",
               hyperparams=hp, progress=False, eval_seeds=[100, 101], verbose=0)
    (it,) = json.loads((tmp_path / "run" / "summary.json").read_text())["iterations"]
    assert it["samples"] > 0 and "evaluation" in it
