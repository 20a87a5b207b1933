"""The per-section policy of TampingLine: its features, the line agent's predict, and the SB3 VecEnv of
section agents."""

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
pytest.importorskip("sb3_contrib")

from trackenv.envs.line import TampingLine, TampingLineVectorEnv  # noqa: E402
from trackenv.envs.line_config import scenario  # noqa: E402
from trackenv_agents.learning.line_policy import (  # noqa: E402
    FEATURE_CLIP,
    FEATURES,
    FRESH_SD_MM,
    LineAgent,
    section_features,
)
from trackenv_agents.learning.sb3_vec import SectionAgentsVecEnv  # noqa: E402

CFG = scenario("small", horizon_years=1.0)
NAMES = [n for n, _ in FEATURES]


def _col(name: str) -> int:
    return NAMES.index(name)


def test_features_follow_the_measurement_calendar_and_the_line():
    """Measured values over their scales; a section tamped after the recording run is stale (its measurement
    predates the tamping) and projected at the fresh SD; otherwise the growth since its last tamping projects
    the SD to now; the line context is the other sections' worst and the line's mean."""
    obs = {"section_sd": np.array([[3.0, 3.0, 0.5, 2.9]]), "section_peak": np.array([[8.0, 8.0, 2.0, 6.0]]),
           "years_since_tamping": np.array([[0.25, 2.25, 1.0, 0.5]]), "measurement_age": np.array([[0.25]]),
           "tampings": np.array([[1.0, 0.0, 0.0, 1.0]]), "tampings_since_renewal": np.array([[8.0, 2.0, 0.0, 1.0]]),
           "register": np.array([[1.0, 0.0, 2.0, 0.0]]), "time": np.array([[0.5]]), "budget_left": np.array([[1.0]])}
    x = section_features(obs)[0]
    assert x.shape == (4, len(FEATURES)) and x.dtype == np.float32
    np.testing.assert_array_equal(x[:, _col("stale")], [1, 0, 0, 0])
    growth = [0.0, (3.0 - FRESH_SD_MM) / 2.0, 0.0, (2.9 - FRESH_SD_MM) / 0.25]
    np.testing.assert_allclose(x[:, _col("growth_mm_per_year")], np.minimum(growth, FEATURE_CLIP), rtol=1e-6)
    projected = np.array([FRESH_SD_MM, 3.0 + growth[1] * 0.25, 0.5, 2.9 + growth[3] * 0.25])
    np.testing.assert_allclose(x[:, _col("projected_sd_mm")], projected / 2.0, rtol=1e-6)
    np.testing.assert_allclose(x[:, _col("line_max_other_projected_sd_mm")],
                               [projected[3], projected[3], projected[3], projected[1]] / np.float64(2.0), rtol=1e-6)
    np.testing.assert_array_equal(x[:, _col("renewal_due")], [1, 0, 0, 0])
    np.testing.assert_array_equal(x[:, [_col("plain"), _col("transition"), _col("switch_or_crossing")]].argmax(1),
                                  [1, 0, 2, 0])
    assert x.min() >= 0.0 and x.max() <= FEATURE_CLIP
    # permuting the sections permutes the features
    perm = np.array([2, 0, 3, 1])
    np.testing.assert_array_equal(section_features({k: (v[:, perm] if v.shape[1] == 4 else v)
                                                    for k, v in obs.items()})[0], x[perm])


def test_section_rewards_add_up_to_the_line_reward_and_episodes_end_together():
    env = SectionAgentsVecEnv(2, CFG, seed=5, reward_scale=10.0)
    lines = TampingLineVectorEnv(2, CFG)
    lines.reset(seed=5)
    obs = env.reset()
    assert obs.shape == (12, len(FEATURES)) and env.action_space.n == 2
    def may_tamp():  # the line env's masks, pairs per section
        return lines.action_masks().reshape(2, 6, 2)[:, :, 1].ravel()

    np.testing.assert_array_equal(env.action_masks(), np.stack([np.ones(12, bool), may_tamp()], axis=1))
    j = 6 + int(np.flatnonzero(may_tamp()[6:])[0])  # a section of line 1 that may be tamped now
    for t in range(CFG.horizon_steps):
        a = np.zeros(12, dtype=np.int8)
        a[:2] = t == 1
        a[j] = t in (0, 1)  # asked again one step after its tamping: masked, dropped
        a = a.reshape(2, 6)
        obs, r, done, infos = env.step(a.ravel())
        _, line_r, _, _, _ = lines.step(a)
        np.testing.assert_allclose(r.reshape(2, 6).sum(axis=1) * 10.0, line_r, rtol=1e-5)
        np.testing.assert_array_equal(env.action_masks()[:, 1], may_tamp())
        if t == 0:  # the section tamped at step 0 may not be tamped at step 1, and paid the whole possession
            assert not may_tamp()[j] and r[j] < -CFG.possession_cost / 10.0
    assert done.all() and all("terminal_observation" in i and not i["TimeLimit.truncated"] for i in infos)
    assert infos[0]["terminal_observation"].shape == (len(FEATURES),)
    assert (obs[:, NAMES.index("time")] == 0.0).all()  # the next episodes started in the same step
    with pytest.raises(ValueError, match="reward_scale"):
        SectionAgentsVecEnv(1, CFG, reward_scale=0.0)


class _Fixed:
    """A stand-in SB3 policy: probability of tamping = projected SD / 4 mm (a function of the features)."""

    device = "cpu"

    def set_training_mode(self, mode):
        pass

    def get_distribution(self, x):
        import torch

        p = (x[:, _col("projected_sd_mm")] * 2.0 / 4.0).clamp(0, 1)

        class D:
            distribution = torch.distributions.Categorical(probs=torch.stack([1 - p, p], dim=-1))

        return D()


def test_line_agent_tamps_the_likely_sections_within_capacity_and_masks():
    env = TampingLine(CFG)
    obs, _ = env.reset(seed=2)
    obs = {k: v.copy() for k, v in obs.items()}
    obs["section_sd"][:] = [3.0, 3.5, 1.0, 2.5, 3.9, 3.2]  # capacity 3: sections 4, 1 and 5
    obs["years_since_tamping"][:] = 2.0
    agent = LineAgent(_Fixed()).bind(CFG)
    a, state = agent.predict(obs)
    assert state is None and a.dtype == np.int8
    np.testing.assert_array_equal(a, [0, 1, 0, 0, 1, 1])
    obs["years_since_tamping"][4] = 0.25  # tamped last step: masked, the next most probable takes its place
    np.testing.assert_array_equal(agent.predict(obs)[0], [1, 1, 0, 0, 0, 1])
    batched = {k: np.stack([v, v]) for k, v in obs.items()}
    assert agent.predict(batched)[0].shape == (2, 6)
    sampled = LineAgent(_Fixed(), rng=np.random.default_rng(0)).bind(CFG).predict(batched, deterministic=False)[0]
    assert sampled.shape == (2, 6) and sampled.sum(axis=1).max() <= CFG.capacity


class _FollowsTheAdvisor(_Fixed):
    """A stand-in SB3 policy that tamps exactly where the advisor does (its feature after the section's own)."""

    def get_distribution(self, x):
        import torch

        p = x[:, len(NAMES)].clamp(0, 1)

        class D:
            distribution = torch.distributions.Categorical(probs=torch.stack([1 - p, p], dim=-1))

        return D()


def test_a_planner_advisor_keeps_its_history_as_the_agents_state():
    """With the model-predictive planner as advisor the agent's recurrent state is the planner's record of the SD
    history, fed every step's observation: a network that follows its advisor plays the planner's episode, state
    for state; the agent is unfit where the planner cannot plan."""
    from trackenv_agents.rules.model_predictive import ModelPredictive

    track60 = scenario("track60")
    planner = ModelPredictive().bind(track60)
    agent = LineAgent(_FollowsTheAdvisor(), advisor=ModelPredictive()).bind(track60)
    assert agent.observation_state and agent.unfit_for(track60) is None
    assert "measured every step" in agent.unfit_for(scenario("default"))
    assert not LineAgent(_Fixed(), advisor=None).observation_state and LineAgent(_Fixed()).unfit_for(CFG) is None
    env = TampingLine(track60)
    obs, _ = env.reset(seed=5)
    mine = theirs = None
    tamped = 0
    for t in range(track60.horizon_steps):
        batch = {k: v[None] for k, v in obs.items()}
        start = np.array([t == 0])
        act, mine = agent.predict(batch, state=mine, episode_start=start)
        want, theirs = planner.predict(batch, state=theirs, episode_start=start)
        np.testing.assert_array_equal(act, want)
        for a, b in zip(mine, theirs, strict=True):
            np.testing.assert_array_equal(a, b)
        tamped += int(act.sum())
        obs, *_ = env.step(act[0])
    assert mine[0].shape[1] == 5 and tamped > 0  # a full window of history, and the planner tamped


def test_the_choice_agent_plays_its_presets_network_where_one_ships(tmp_path):
    """The shipped choice agent's metadata names a network for the short-defect line (``preset_weights``): bound
    to that preset (any horizon or engine) it plays it, bound to any other line the default one, and a bound agent
    bound again to another line changes back. A preset network of other features or advisor, or an unknown
    preset, is refused by name."""
    import json
    import shutil

    from trackenv_agents.learning.line import line_meta_path, load_line_trained
    from trackenv_agents.shipped import CHOICE_PRETRAINED_FILE, LINE_PRETRAINED_FILE

    agent = load_line_trained(CHOICE_PRETRAINED_FILE, name="cpi-choice-agent")
    assert set(agent.preset_policies) == {"defects"}
    defects = agent.bind(scenario("defects", horizon_years=1.0, engine="fast"))
    assert defects.policy is agent.preset_policies["defects"] and defects.name == "cpi-choice-agent"
    assert agent.bind(scenario("wet")).policy is agent.default_policy
    assert defects.bind(scenario("choices")).policy is agent.default_policy
    obs, _ = TampingLineVectorEnv(2, scenario("defects", horizon_years=1.0), action_type="choices").reset(seed=[0, 1])
    p_defects = defects.tamp_probability(obs)
    p_default = agent.bind(scenario("defects").replace(annual_mgt=30.0)).tamp_probability(obs)  # no preset
    assert not np.allclose(p_defects, p_default)  # two networks

    for file, preset, why in ((LINE_PRETRAINED_FILE, "defects", "same features, advisor"),
                              (CHOICE_PRETRAINED_FILE, "no-such-line", "a preset's")):
        folder = tmp_path / why.split()[0]
        folder.mkdir()
        shutil.copy(CHOICE_PRETRAINED_FILE, folder / "agent.zip")
        shutil.copy(file, folder / "other.zip")
        shutil.copy(line_meta_path(file), line_meta_path(folder / "other.zip"))
        meta = json.loads(line_meta_path(CHOICE_PRETRAINED_FILE).read_text())
        meta["preset_weights"] = {preset: "other.zip"}
        line_meta_path(folder / "agent.zip").write_text(json.dumps(meta))
        with pytest.raises(ValueError, match=f"preset_weights '{preset}'.*{why}"):
            load_line_trained(folder / "agent.zip")
