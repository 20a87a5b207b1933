"""The per-section actor-critic: features, one policy on every line length, permutation equivariance."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("sb3_contrib")

import torch  # noqa: E402
from gymnasium import spaces  # noqa: E402

from trackenv.envs.line import TampingLine, line_observation_space  # noqa: E402
from trackenv.envs.line_config import scenario  # noqa: E402
from trackenv_agents.line_policy import (  # noqa: E402
    FEATURE_CLIP,
    FEATURE_SCALES,
    N_FEATURES,
    LineAgent,
    MaskableSectionActorCritic,
    SectionActorCritic,
    section_features,
    section_policy_class,
)

CLASSES = [SectionActorCritic, MaskableSectionActorCritic]


def _policy(cls, n_sections: int = 6, hidden: int = 16, seed: int = 0):
    torch.manual_seed(seed)
    cfg = scenario("small").replace(n_sections=n_sections, capacity=3)
    return cls(line_observation_space(cfg), spaces.MultiBinary(n_sections), lambda _: 1e-3, hidden=hidden)


def _batch(n_sections: int, n: int = 5, seed: int = 0) -> dict[str, torch.Tensor]:
    """Random but valid observations (the space's bounds, registers 0-2), batched."""
    space = line_observation_space(scenario("small").replace(n_sections=n_sections, capacity=3))
    space.seed(seed)
    obs = [space.sample() for _ in range(n)]
    out = {k: torch.as_tensor(np.stack([o[k] for o in obs])) for k in obs[0]}
    out["register"] = out["register"].round()
    out["section_sd"] = out["section_sd"] / 20.0  # the sampled range (0-100 mm) dwarfs real SDs; keep some variety
    return out


def test_features_are_the_observation_over_fixed_scales():
    env = TampingLine(scenario("small"))
    obs, _ = env.reset(seed=3)
    x = section_features({k: torch.as_tensor(v)[None] for k, v in obs.items()}).numpy()
    assert x.shape == (1, 6, N_FEATURES)
    np.testing.assert_allclose(x[0, :, 0], obs["section_sd"] / FEATURE_SCALES["section_sd"], rtol=1e-6)
    np.testing.assert_allclose(x[0, :, 4], obs["years_since_tamping"] / FEATURE_SCALES["years_since_tamping"],
                               rtol=1e-6)
    register = x[0, :, 5:8]
    assert np.all(register.sum(axis=1) == 1) and np.all(register.argmax(axis=1) == obs["register"])
    np.testing.assert_allclose(x[0, :, 9], obs["time"][0])  # globals broadcast to every section
    np.testing.assert_allclose(x[0, :, 11], obs["section_sd"].max() / FEATURE_SCALES["section_sd"], rtol=1e-6)
    np.testing.assert_allclose(x[0, :, 12], obs["section_sd"].mean() / FEATURE_SCALES["section_sd"], rtol=1e-6)


def test_extreme_observations_are_clipped_to_the_training_range():
    obs, _ = TampingLine(scenario("small")).reset(seed=3)
    obs = {k: torch.as_tensor(v)[None] for k, v in obs.items()}
    wild = {**obs, "section_sd": obs["section_sd"].clone(), "years_since_tamping": obs["years_since_tamping"] + 50}
    wild["section_sd"][0, 2] = 19.0  # mm: a hidden wet spot gone wild
    x = section_features(wild).numpy()
    assert x.max() == FEATURE_CLIP and x[0, 2, 0] == FEATURE_CLIP and np.all(x[0, :, 11] == FEATURE_CLIP)
    assert np.all(x[0, :, 4] == FEATURE_CLIP)


@pytest.mark.parametrize("cls", CLASSES)
def test_one_policy_runs_on_every_scenario(cls):
    """Weights are shared over sections: a policy built for 6 sections scores 6, 12 and 24."""
    agent = LineAgent(_policy(cls, n_sections=6))
    for name, S in (("small", 6), ("default", 12), ("hard", 24)):
        env = TampingLine(scenario(name))
        obs, _ = env.reset(seed=1)
        action, state = agent.predict(obs)
        assert state is None and action.shape == (S,) and env.action_space.contains(action)
        batched = {k: np.stack([v, v, v]) for k, v in obs.items()}
        actions, _ = agent.predict(batched)
        assert actions.shape == (3, S)
        np.testing.assert_array_equal(actions[1], action)
        assert agent.section_logits(batched).shape == (3, S)
        value = agent.policy.section_value({k: torch.as_tensor(v) for k, v in batched.items()})
        assert value.shape == (3,)


@pytest.mark.parametrize("cls", CLASSES)
@pytest.mark.parametrize("n_sections", [6, 12])
def test_permuting_sections_permutes_logits_and_keeps_the_value(cls, n_sections):
    policy = _policy(cls, n_sections=n_sections, seed=2)
    with torch.no_grad():  # the encoder's weights are not tiny, so the logits carry the sections' differences
        policy.action_net.linear.weight.mul_(100.0)
    obs = _batch(n_sections)
    perm = torch.as_tensor(np.random.default_rng(0).permutation(n_sections))
    shuffled = {k: (v[:, perm] if v.shape[1] == n_sections else v) for k, v in obs.items()}
    with torch.no_grad():
        logits, logits_p = policy.section_logits(obs), policy.section_logits(shuffled)
        value, value_p = policy.section_value(obs), policy.section_value(shuffled)
    assert logits.std(dim=1).min() > 1e-3  # sections are scored differently: the check below means something
    torch.testing.assert_close(logits_p, logits[:, perm], rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(value_p, value, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("cls", CLASSES)
def test_the_action_distribution_is_one_bernoulli_per_section(cls):
    policy = _policy(cls, seed=4)
    with torch.no_grad():
        policy.action_net.linear.weight.mul_(100.0)
    obs = _batch(6)
    with torch.no_grad():
        logits = policy.section_logits(obs)
        dist = policy.get_distribution(obs)
        ones = torch.ones_like(logits)
        # log P(tamp every section) = Σ log σ(logit): the same under SB3's Bernoulli and contrib's masked pairs
        torch.testing.assert_close(dist.log_prob(ones), torch.nn.functional.logsigmoid(logits).sum(dim=1))
        np.testing.assert_array_equal(dist.mode().numpy().astype(bool), (logits > 0).numpy())


def test_initial_logit_is_settable_and_bad_arguments_name_the_parameter():
    from trackenv_agents.train import _set_initial_tamp_logit

    class Model:
        policy = _policy(MaskableSectionActorCritic)

    _set_initial_tamp_logit(Model, -3.0, "multibinary")
    logits = Model.policy.section_logits(_batch(6))
    assert torch.all((logits - -3.0).abs() < 0.1)  # the head starts with a small gain: the bias dominates
    with pytest.raises(ValueError, match="hidden"):
        _policy(SectionActorCritic, hidden=0)
    with pytest.raises(ValueError, match="feature_scales"):
        SectionActorCritic(line_observation_space(scenario("small")), spaces.MultiBinary(6), lambda _: 1e-3,
                           feature_scales={"section_sd": 2.0})
    with pytest.raises(ValueError, match="feature_scales"):
        SectionActorCritic(line_observation_space(scenario("small")), spaces.MultiBinary(6), lambda _: 1e-3,
                           feature_scales={**FEATURE_SCALES, "time": 0.0})
    with pytest.raises(ValueError, match="algo"):
        section_policy_class("a2c")
    with pytest.raises(ValueError, match="MultiBinary"):
        SectionActorCritic(line_observation_space(scenario("small")), spaces.Discrete(7), lambda _: 1e-3)
