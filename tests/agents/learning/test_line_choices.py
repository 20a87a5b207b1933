"""The per-section agent on the lines with every choice: its tamping from the network, the other choices from the
choice rule (composition, masks, memory), the counterfactual forks with the choices, and a training smoke test
with a choice rule as advisor."""

from __future__ import annotations

import numpy as np
import pytest
from fork_replays import rule_plans, section_cost

from trackenv.envs.choices import DRAINAGE, INSPECT, NOTHING, RENEW, SPOT_TAMP, SURVEY, TAMP
from trackenv.envs.line import TampingLine
from trackenv.envs.line_config import scenario
from trackenv.envs.problems import problem_config
from trackenv_agents.evaluation.harness import bind_policy
from trackenv_agents.learning.line_counterfactual import section_counterfactuals
from trackenv_agents.learning.line_policy import (
    FEATURES,
    LineAgent,
    compose_choices,
    section_features,
    tamping_codes,
)
from trackenv_agents.rules import tuned_params_for
from trackenv_agents.rules.choices import ChoiceThreshold

#: a small wet line over 2 years on short segments: fast, with wet spots, surveys and drainage to decide
CFG = scenario("wet", n_sections=6, capacity=3, horizon_years=2.0, segment_length_m=12.0)
#: a choice rule that uses every choice on CFG within two years
RULE = ChoiceThreshold(trigger_mm=1.5, include_mm=1.0, spot_peak_mm=4.0, drain_surveyed=True, survey_all=True,
                       check_peak_mm=4.0)


def _col(name: str) -> int:
    return [n for n, _ in FEATURES].index(name)


class _ByProjectedSD:
    """A stand-in for a trained SB3 policy: tamps with probability projected SD / 2 mm (clipped)."""

    device = "cpu"

    def set_training_mode(self, mode):
        pass

    def get_distribution(self, x):
        import torch

        p = (x[:, _col("projected_sd_mm")] * 2.0 / 2.0).clamp(0, 1)

        class D:
            distribution = torch.distributions.Categorical(probs=torch.stack([1 - p, p], dim=-1))

        return D()


def test_compose_choices_follows_the_rules_precedence():
    advice = np.array([NOTHING, TAMP, SPOT_TAMP, DRAINAGE, RENEW, INSPECT, SURVEY])
    tamped = compose_choices(np.ones(7, dtype=bool), advice)
    waiting = compose_choices(np.zeros(7, dtype=bool), advice)
    # tamping: the rule's drainage and renewal stand, its looks and spot tamping give way to the tamping
    np.testing.assert_array_equal(tamped, [TAMP, TAMP, TAMP, DRAINAGE, RENEW, TAMP, TAMP])
    # waiting: the rule's tamping and renewal lapse, the rest stands
    np.testing.assert_array_equal(waiting, [NOTHING, NOTHING, SPOT_TAMP, DRAINAGE, NOTHING, INSPECT, SURVEY])
    np.testing.assert_array_equal(tamping_codes(advice), [0, 1, 0, 0, 1, 0, 0])


def test_choice_agent_answers_codes_the_env_applies_as_asked():
    agent = LineAgent(_ByProjectedSD(), advisor=RULE)
    bound = agent.bind(CFG)
    assert bound.choices and bound.advisor.name == "choice-threshold"
    wet = problem_config("wet")
    assert agent.bind(wet).advisor.params.items() >= tuned_params_for(wet)["choice-threshold"].items()
    env = TampingLine(CFG, action_type="choices")
    seen = set()
    for seed in (0, 1):
        obs, _ = env.reset(seed=seed)
        state = None
        for t in range(CFG.horizon_steps):
            mask = env.action_masks().reshape(CFG.n_sections, -1)
            start = np.array([t == 0])
            before = state
            codes, state = bound.predict(obs, state=before, episode_start=start)
            assert codes.dtype == np.int8 and codes.shape == (CFG.n_sections,) and state.shape == (1, 3, 6)
            assert mask[np.arange(CFG.n_sections), codes].all()
            # the network decides the tamping where it may tamp and the rule does not drain
            batched = {k: v[None] for k, v in obs.items()}
            advice = bound.advisor.predict(batched, state=before, episode_start=start)[0][0]
            p = bound.tamp_probability(batched, advice[None])[0]
            free = (advice != DRAINAGE) & mask[:, TAMP]
            np.testing.assert_array_equal(tamping_codes(codes)[free], (p > 0.5)[free])
            obs, _, _, _, info = env.step(codes)
            np.testing.assert_array_equal(info["section_choices"], codes)  # applied as asked
            seen |= set(codes.tolist())
    assert {TAMP, DRAINAGE} <= seen


def test_forks_with_choices_are_the_envs_section_costs_under_the_other_choice():
    rule = bind_policy(RULE, CFG)
    seeds = [3, 4]
    data = section_counterfactuals(CFG, seeds, rule, advisor=rule, focus_rate=0.4, other_rate=0.1, seed=1)
    n = len(data["q_do"])
    assert n > 5 and data["features"].shape == (n, len(FEATURES) + 2)
    plans, states = rule_plans(CFG, rule, seeds)
    rng = np.random.default_rng(0)
    for k in rng.choice(n, size=4, replace=False):
        s, t, j, acted = int(data["seed"][k]), int(data["step"][k]), int(data["section"][k]), bool(data["did"][k])
        code = int(plans[s][t, j])
        assert tamping_codes(code) == acted
        first = compose_choices(np.array(not acted), np.array(code))  # the rule's own code is its advice
        other = section_cost(CFG, s, rule, plans[s], states[s], j, t, int(first))
        own = section_cost(CFG, s, rule, plans[s], states[s], j, t, code)
        q_other, q_own = (data["q_skip"][k], data["q_do"][k]) if acted else (data["q_do"][k], data["q_skip"][k])
        assert q_own == pytest.approx(own, rel=1e-9) and q_other == pytest.approx(other, rel=1e-9)
    # the features carry the rule's tamping, not its other codes
    x = section_features({k: v[None] for k, v in TampingLine(CFG, action_type="choices").reset(seed=3)[0].items()},
                         rule, np.array([[DRAINAGE, TAMP, SURVEY, RENEW, NOTHING, INSPECT]]))
    np.testing.assert_array_equal(x[0, :, -2], [0, 1, 0, 1, 0, 0])
    assert (x[0, :, -1] == 1).all()


def test_training_with_a_choice_rule_as_advisor_saves_a_choice_agent(tmp_path):
    pytest.importorskip("sb3_contrib")
    import json

    from trackenv_agents.learning.line import (
        DEFAULT_LINE_PRETRAINED,
        _line_env_id,
        line_meta_path,
        load_line_trained,
        train_line,
    )

    cfg = scenario("wet", n_sections=4, capacity=2, horizon_years=1.0, segment_length_m=12.0)
    hp = {"advisor": "choice-threshold", "fit_epochs": 2}
    with pytest.raises(ValueError, match="init_policy"):  # another network
        train_line(cfg, out_dir=tmp_path / "other", hyperparams={**hp, "net_arch": [8]}, iterations=1,
                   init_policy=DEFAULT_LINE_PRETRAINED, progress=False, verbose=0)
    path = train_line(cfg, out_dir=tmp_path / "run", hyperparams=hp, iterations=1, episodes_per_iteration=2,
                      eval_seeds=[10000], progress=False, verbose=0, init_policy=DEFAULT_LINE_PRETRAINED)
    assert json.loads((tmp_path / "run" / "train_meta.json").read_text())["init_policy"] == str(DEFAULT_LINE_PRETRAINED)
    meta = json.loads(line_meta_path(path).read_text())
    assert meta["advisor"] == "choice-threshold" and meta["env_id"] == "trackenv/TampingLine-v0"  # not a preset
    assert _line_env_id(scenario("wet", horizon_years=2.0)) == "trackenv/TampingLineWet-v0"
    assert _line_env_id(scenario("wet", engine="fast", pass_reuse_tolerance_m=1e-3)) == "trackenv/TampingLineWet-v0"
    agent = load_line_trained(path).bind(cfg)
    assert agent.choices
    env = TampingLine(cfg, action_type="choices")
    obs, _ = env.reset(seed=5)
    codes, state = agent.predict(obs, episode_start=np.array([True]))
    assert state.shape == (1, 3, cfg.n_sections) and env.action_masks().reshape(4, -1)[np.arange(4), codes].all()
    assert train_line(resume=tmp_path / "run", progress=False, verbose=0) == path  # finished: returned at once
