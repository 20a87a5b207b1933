"""The line agent that learns spot tamping and drainage besides the tamping: the flips the forks price, the
marginal possession (a spot-only step pays its share), the forks of the new choices against the env, the agent's
codes under the env's masks, and a training smoke test."""

from __future__ import annotations

import numpy as np
import pytest
from fork_replays import rule_plans, section_cost

from trackenv.envs.choices import DRAINAGE, INSPECT, NOTHING, RENEW, SPOT_TAMP, SURVEY, TAMP
from trackenv.envs.line import TampingLine
from trackenv.envs.line_config import scenario
from trackenv_agents.evaluation.harness import bind_policy
from trackenv_agents.learning.line_counterfactual import (
    flipped_choices,
    marginal_possession,
    section_counterfactuals,
)
from trackenv_agents.learning.line_policy import (
    ADVISOR_FEATURES,
    CHOICE_FEATURES,
    FEATURES,
    LEARNABLE_CHOICES,
    LineAgent,
    compose_choices,
)
from trackenv_agents.rules.choices import ChoiceThreshold

#: a short line of short defects: spot tamping pays a share of the possession there
DEFECTS = scenario("defects", n_sections=6, capacity=3, horizon_years=2.0, segment_length_m=12.0)
#: a short wet line: wet spots that surveys find
WET = scenario("wet", n_sections=6, capacity=3, horizon_years=2.0, segment_length_m=12.0)
#: a rule that tamps, spot-tamps and surveys every section but drains nothing: a drainage is then the forks' to find
NO_DRAIN = ChoiceThreshold(trigger_mm=1.5, include_mm=1.0, spot_peak_mm=4.0, drain_surveyed=False, survey_all=True)
NAMES = [n for n, _ in FEATURES] + list(ADVISOR_FEATURES) + list(CHOICE_FEATURES)


def test_flipped_choices_turn_one_decision_and_keep_the_rest():
    codes = np.array([NOTHING, TAMP, SPOT_TAMP, DRAINAGE, RENEW, INSPECT, NOTHING])
    advice = np.array([NOTHING, SPOT_TAMP, SPOT_TAMP, DRAINAGE, RENEW, INSPECT, SURVEY])
    # the tamping: a tamped section waits (the rule's spot tamping stands), a waiting one is tamped; drained: as is
    np.testing.assert_array_equal(flipped_choices("tamp", codes, advice),
                                  [TAMP, SPOT_TAMP, TAMP, DRAINAGE, NOTHING, TAMP, TAMP])
    # spot tamping: only where the section is neither tamped nor drained; off, the rule's looks stand
    np.testing.assert_array_equal(flipped_choices("spot_tamp", codes, advice),
                                  [SPOT_TAMP, TAMP, NOTHING, DRAINAGE, RENEW, SPOT_TAMP, SPOT_TAMP])
    # drainage: on anything (it comes first); off, the section waits
    np.testing.assert_array_equal(flipped_choices("drainage", codes, advice),
                                  [DRAINAGE, DRAINAGE, DRAINAGE, NOTHING, DRAINAGE, DRAINAGE, DRAINAGE])
    np.testing.assert_array_equal(flipped_choices("tamp", codes[:2], None), [TAMP, NOTHING])
    with pytest.raises(ValueError, match="choice must be"):
        flipped_choices("survey", codes, advice)


def test_compose_choices_with_the_policys_own_spot_tamping_and_drainage():
    advice = np.array([NOTHING, SPOT_TAMP, DRAINAGE, INSPECT, RENEW])
    no, yes = np.zeros(5, bool), np.ones(5, bool)
    np.testing.assert_array_equal(compose_choices(no, advice, spot=no, drain=no),
                                  [NOTHING, NOTHING, NOTHING, INSPECT, NOTHING])
    np.testing.assert_array_equal(compose_choices(no, advice, spot=yes, drain=no), [SPOT_TAMP] * 5)
    np.testing.assert_array_equal(compose_choices(yes, advice, spot=yes, drain=no), [TAMP, TAMP, TAMP, TAMP, RENEW])
    np.testing.assert_array_equal(compose_choices(yes, advice, spot=no, drain=yes), [DRAINAGE] * 5)


def test_marginal_possession_follows_the_envs_spot_rule():
    c = DEFECTS
    full, spot = c.possession_cost, c.spot_possession_share * c.possession_cost
    codes = np.array([[SPOT_TAMP, NOTHING, INSPECT, 0, 0, 0],     # spot tamping alone
                      [SPOT_TAMP, TAMP, NOTHING, 0, 0, 0],        # a tamping beside a spot tamping
                      [TAMP, TAMP, NOTHING, 0, 0, 0],             # a campaign of two
                      [NOTHING, INSPECT, SURVEY, 0, 0, 0]])       # no track work
    lines, sections = np.array([0, 0, 1, 1, 2, 3, 3]), np.array([0, 2, 1, 0, 0, 0, 1])
    own = codes[lines, sections]
    got = marginal_possession(c, codes, lines, sections, own)
    np.testing.assert_allclose(got, [spot, 0.0, full - spot, 0.0, 0.0, 0.0, 0.0])
    # the other choice of a fork: a tamping where the line spot-tamps alone pays what the spot step did not
    np.testing.assert_allclose(marginal_possession(c, codes, np.array([0, 3]), np.array([1, 0]),
                                                   np.array([TAMP, SPOT_TAMP])), [full - spot, spot])


SPOTS = ChoiceThreshold(trigger_mm=1.5, include_mm=1.0, spot_peak_mm=4.0, survey_all=True)


@pytest.mark.parametrize("cfg, rule, choices", [(DEFECTS, SPOTS, ("tamp", "spot_tamp")),
                                                (WET, NO_DRAIN, LEARNABLE_CHOICES)])
def test_forks_of_spot_tamping_and_drainage_are_the_envs_section_costs(cfg, rule, choices):
    """A spot-only step pays its share of the possession on the defects line; the recording car's runs date the
    forks' measurements as the env's do (the rule reads their age); a fork asks for no work over capacity."""
    rule = bind_policy(rule, cfg)
    seeds = [3, 4]
    data = section_counterfactuals(cfg, seeds, rule, advisor=rule, focus_rate=0.5, other_rate=0.2, seed=1,
                                   choices=choices)
    n = len(data["q_do"])
    assert data["features"].shape == (n, len(NAMES))
    plans, states = rule_plans(cfg, rule, seeds)
    rng = np.random.default_rng(0)
    for i, choice in enumerate(choices):
        rows = np.flatnonzero(data["choice"] == i)
        assert rows.size > 0, choice
        # the features ask about the choice priced
        asked = data["features"][rows][:, [NAMES.index("asks_spot_tamp"), NAMES.index("asks_drainage")]]
        np.testing.assert_array_equal(asked, np.broadcast_to([choice == "spot_tamp", choice == "drainage"],
                                                             asked.shape))
        for k in rng.choice(rows, size=min(3, rows.size), replace=False):
            s, t, j = int(data["seed"][k]), int(data["step"][k]), int(data["section"][k])
            code = plans[s][t, j]
            other = flipped_choices(choice, np.array([code]), np.array([code]))[0]  # the rule's code is its advice
            assert other != code
            q_own = section_cost(cfg, s, rule, plans[s], states[s], j, t, int(code))
            q_other = section_cost(cfg, s, rule, plans[s], states[s], j, t, int(other))
            did = bool(data["did"][k])
            assert (data["q_do"][k], data["q_skip"][k]) == pytest.approx((q_own, q_other) if did else (q_other, q_own),
                                                                         rel=1e-9)


def test_the_forks_find_the_drainage_of_a_wet_section():
    """The rule surveys every section but drains none: over four years, draining some sections the survey found
    wet saves what their wet spots cost when left to work (hundreds of k€ where the settlement runs away), and the
    forks ask about drainage only where a survey found the section wet (the rule drains nothing)."""
    cfg = scenario("wet", n_sections=4, capacity=3, horizon_years=4.0, segment_length_m=12.0)
    rule = bind_policy(NO_DRAIN, cfg)
    data = section_counterfactuals(cfg, [3, 4, 5, 6], rule, advisor=rule, focus_rate=1.0, other_rate=0.5, seed=2,
                                   choices=("drainage",))
    assert (data["features"][:, NAMES.index("surveyed_wet")] == 1).all() and not data["did"].any()
    saved = data["q_skip"] - data["q_do"]
    assert (saved > 100.0).sum() >= 3  # the priced drainage wins where it should
    assert (saved < 0).any()  # and not everywhere: a spot that starts late is not worth draining early


def test_tamping_alone_priced_with_the_choice_features():
    """A network with the choice features on a line where only the tamping is learnt: its samples carry them."""
    rule = bind_policy(SPOTS, WET)
    data = section_counterfactuals(WET, [3], rule, advisor=rule, seed=1, choice_features=True)
    assert data["features"].shape == (len(data["q_do"]), len(NAMES)) and (data["choice"] == 0).all()
    assert (data["features"][:, -2:] == 0).all()  # asked about the tamping
    with pytest.raises(ValueError, match="choice rule as advisor"):
        section_counterfactuals(WET, [3], rule, choice_features=True)


class _Asks:
    """A stand-in for a trained SB3 policy with the choice features: says yes to the choices in ``yes`` (read from
    the features' one-hot of the choice asked about), no to the others."""

    device = "cpu"

    def __init__(self, yes):
        self.yes = set(yes)

    def set_training_mode(self, mode):
        pass

    def get_distribution(self, x):
        import torch

        spot, drain = x[:, NAMES.index("asks_spot_tamp")], x[:, NAMES.index("asks_drainage")]
        tamp = 1 - spot - drain
        p = (tamp * ("tamp" in self.yes) + spot * ("spot_tamp" in self.yes) + drain * ("drainage" in self.yes))

        class D:
            distribution = torch.distributions.Categorical(probs=torch.stack([1 - p, p], dim=-1))

        return D()


@pytest.mark.parametrize("yes, made", [({"spot_tamp"}, SPOT_TAMP), ({"drainage"}, DRAINAGE), ({"tamp"}, TAMP)])
def test_a_learned_choice_agent_answers_codes_the_env_applies(yes, made):
    rule = ChoiceThreshold(trigger_mm=1.5, include_mm=1.0, spot_peak_mm=4.0, drain_surveyed=True, survey_all=True)
    with pytest.raises(ValueError, match="choice_features"):
        LineAgent(_Asks(yes), advisor=rule, learned=LEARNABLE_CHOICES)
    agent = LineAgent(_Asks(yes), advisor=rule, choice_features=True, learned=LEARNABLE_CHOICES).bind(WET)
    env = TampingLine(WET, action_type="choices")
    seen = []
    for seed in (3, 4):  # with wet sections known from the start
        obs, _ = env.reset(seed=seed)
        state = None
        for t in range(WET.horizon_steps):
            codes, state = agent.predict(obs, state=state, episode_start=np.array([t == 0]))
            mask = env.action_masks().reshape(WET.n_sections, -1)
            assert mask[np.arange(WET.n_sections), codes].all()
            if made == DRAINAGE:  # drainage only where a survey found the section wet (or the rule drains it)
                assert (obs["section_survey"][codes == DRAINAGE] == 1).all()
            obs, _, _, _, info = env.step(codes)
            np.testing.assert_array_equal(info["section_choices"], codes)  # applied as asked
            seen.append(codes)
    seen = np.array(seen)
    work = {TAMP, RENEW} if made == TAMP else {made}  # a tamping is a renewal where the rule renews
    assert (seen == made).any() and not np.isin(seen, list({TAMP, RENEW, SPOT_TAMP, DRAINAGE} - work)).any()


def test_widened_inputs_keep_the_saved_networks_answers():
    import torch

    from trackenv_agents.learning.line import _widened_inputs

    torch.manual_seed(0)
    old, new = torch.nn.Linear(3, 4), torch.nn.Linear(5, 4)
    new.load_state_dict(_widened_inputs(old.state_dict(), new.state_dict()))
    x = torch.rand(7, 5)
    torch.testing.assert_close(new(x), old(x[:, :3]))
    with pytest.raises(ValueError, match="does not widen"):
        _widened_inputs(new.state_dict(), old.state_dict())


def test_training_the_choices_saves_an_agent_that_decides_them(tmp_path):
    pytest.importorskip("sb3_contrib")
    import json

    from trackenv_agents.learning.line import DEFAULT_CHOICE_PRETRAINED, line_meta_path, load_line_trained, train_line

    cfg = scenario("defects", n_sections=4, capacity=2, horizon_years=1.0, segment_length_m=12.0)
    with pytest.raises(ValueError, match="learn_choices needs a choice rule"):
        train_line(cfg, out_dir=tmp_path / "rule", hyperparams={"learn_choices": True}, iterations=1,
                   progress=False, verbose=0)
    path = train_line(cfg, out_dir=tmp_path / "run", iterations=1, episodes_per_iteration=2, eval_seeds=[10000],
                      hyperparams={"advisor": "choice-threshold", "learn_choices": True, "fit_epochs": 2},
                      progress=False, verbose=0, init_policy=DEFAULT_CHOICE_PRETRAINED)
    meta = json.loads(line_meta_path(path).read_text())
    assert meta["learned"] == list(LEARNABLE_CHOICES) and meta["features"] == NAMES
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert set(summary["iterations"][0]["samples_per_choice"]) == set(LEARNABLE_CHOICES)
    agent = load_line_trained(path).bind(cfg)
    assert agent.learned == LEARNABLE_CHOICES and agent.choice_features
    env = TampingLine(cfg, action_type="choices")
    obs, _ = env.reset(seed=5)
    codes, _ = agent.predict(obs, episode_start=np.array([True]))
    assert env.action_masks().reshape(4, -1)[np.arange(4), codes].all()
