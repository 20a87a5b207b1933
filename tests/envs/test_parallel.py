"""The multi-agent interface (trackenv.envs.line_parallel_env): PettingZoo's parallel API and seed tests, the
agents' rewards against the line env's reward, the same rollout as the line env for the same joint actions, the
masks, the errors, and the documentation page's example."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import trackenv  # noqa: F401  (registers the ids)
from trackenv.envs import line_parallel_env

pytest.importorskip("pettingzoo")

from pettingzoo.test import parallel_api_test, parallel_seed_test  # noqa: E402

from trackenv.envs.choices import CHOICES, IS_TRACK_WORK  # noqa: E402
from trackenv.envs.parallel import LineParallelEnv, agent_name, possession_shares  # noqa: E402

SMALL = "trackenv/TampingLineSmall-v0"  # 6 sections, capacity 3, a tamped section masked for 1 step
SHORT = {"horizon_years": 1.5}  # 6 steps
N = 6
AGENTS = [f"section_{j}" for j in range(N)]
#: joint actions over 6 steps: a campaign of 3, a request of a section tamped last step (masked), none, 6
#: requests for a capacity of 3 (clipped to the 3 worst), then single requests
JOINT = [np.array(a) for a in ([1, 1, 1, 0, 0, 0], [1, 0, 0, 0, 0, 0], [0, 0, 0, 0, 0, 0], [1, 1, 1, 1, 1, 1],
                               [0, 0, 0, 1, 0, 0], [0, 1, 0, 0, 0, 1])]


def _pair(seed: int, **kwargs):
    """The line env and the parallel env over its twin, reset with the same seed."""
    single = gym.make(SMALL, **SHORT, **kwargs)
    parallel = line_parallel_env(SMALL, **SHORT, **kwargs)
    return single, single.reset(seed=seed), parallel, parallel.reset(seed=seed)


def _actions(joint) -> dict[str, int]:
    return {agent: int(a) for agent, a in zip(AGENTS, joint)}


@pytest.mark.filterwarnings("error")  # PettingZoo's tests report what they doubt as warnings
def test_pettingzoo_parallel_api_and_seed_tests():
    env = line_parallel_env(SMALL, horizon_years=0.75)
    parallel_api_test(env, num_cycles=100)
    assert env.agents == []  # the last cycle ran to the horizon
    parallel_seed_test(lambda: line_parallel_env(SMALL, horizon_years=0.75))


def test_agents_and_spaces():
    env = line_parallel_env(SMALL, **SHORT)
    assert env.possible_agents == AGENTS and env.agents == []
    spaces = [env.observation_space(agent) for agent in AGENTS]
    assert all(space == spaces[0] for space in spaces)  # homogeneous: one shared policy can serve every agent
    assert env.observation_space("section_2") is env.observation_space("section_2")
    assert env.action_space("section_2") is env.action_space("section_2")
    assert env.action_space("section_0") == gym.spaces.Discrete(2)
    assert env.feature_names == ("register", "section_peak", "section_sd", "tampings", "tampings_since_renewal",
                                 "years_since_tamping", "budget_left", "measurement_age", "time")
    assert spaces[0]["observation"].shape == (len(env.feature_names),)
    line_space = env.env.observation_space
    assert spaces[0]["observation"].high[env.feature_names.index("section_sd")] == line_space["section_sd"].high[0]


def test_possession_shares_rule():
    tamped = np.array([True, False, True, False])
    assert possession_shares(15.0, tamped).tolist() == [7.5, 0.0, 7.5, 0.0]
    assert possession_shares(0.0, np.zeros(4, bool)).tolist() == [0.0] * 4
    assert possession_shares(4.0, np.zeros(4, bool)).sum() == 4.0  # no payer: still adds up


def test_rewards_add_up_to_the_line_reward_and_follow_the_split_rule():
    single, _, parallel, _ = _pair(seed=2)  # every section may be tamped at the start
    possession = single.unwrapped.config.possession_cost
    campaigns = []
    for joint in JOINT:
        _, reward, _, _, info = single.step(joint)
        _, rewards, _, _, infos = parallel.step(_actions(joint))
        assert sum(rewards.values()) == pytest.approx(reward, rel=1e-12, abs=1e-9)
        tamped = info["tamped_sections"]
        campaigns.append((int(tamped.sum()), info["clipped"]))
        for j, agent in enumerate(AGENTS):
            share = possession / tamped.sum() if tamped[j] else 0.0
            assert infos[agent]["possession_share"] == pytest.approx(share, rel=1e-12)
            assert rewards[agent] == pytest.approx(-(info["section_costs"][j] + share), rel=1e-12, abs=1e-12)
            assert infos[agent]["cost"] == -rewards[agent]
    # the schedule exercised the rule: a campaign of 3, a masked request (no campaign), none, clipped to 3
    assert campaigns[:4] == [(3, False), (0, False), (0, False), (3, True)]


def _line_entry(obs: dict, feature: str, section: int) -> float:
    """The line env's value of an agent's ``feature`` (``key`` or ``key[i]``): the section's or the line's."""
    key, _, index = feature.partition("[")
    value = obs[key][section] if obs[key].shape[0] == N else obs[key]
    return value[int(index[:-1])] if index else value.item()


@pytest.mark.parametrize("kwargs", [{}, {"profiles": True}], ids=["default", "profiles"])
def test_same_rollout_as_the_line_env(kwargs):
    single, (obs, info), parallel, (observations, infos) = _pair(seed=11, **kwargs)
    if kwargs:  # the measured level of each sleeper of the agent's section joins its features
        assert sum(name.startswith("level[") for name in parallel.feature_names) == obs["level"].shape[1]
    for step, joint in enumerate([*JOINT, None]):
        for j, agent in enumerate(AGENTS):
            assert parallel.observation_space(agent).contains(observations[agent])
            row = observations[agent]["observation"]
            for name, value in zip(parallel.feature_names, row, strict=True):
                assert value == _line_entry(obs, name, j), (step, agent, name)
            assert infos[agent]["tamped_sections"] == info["tamped_sections"][j]
            assert infos[agent]["section_sd_mm"] == info["section_sd_mm"][j]
        np.testing.assert_array_equal(parallel.state(), gym.spaces.flatten(single.observation_space, obs))
        if joint is None:
            break
        obs, _, terminated, truncated, info = single.step(joint)
        observations, _, terminations, truncations, infos = parallel.step(_actions(joint))
        assert terminations == dict.fromkeys(AGENTS, terminated)
        assert truncations == dict.fromkeys(AGENTS, truncated)
        assert parallel.line_info["cost"] == info["cost"]
    assert truncated and parallel.agents == []  # all truncated together at the horizon
    with pytest.raises(RuntimeError, match="call reset"):
        parallel.step(_actions(JOINT[0]))


def test_masks_forbid_what_the_line_env_forbids():
    single, _, parallel, (observations, _) = _pair(seed=4)  # sections 2 and 3 are masked at the start
    masked_requests = 0
    for joint in JOINT:
        line_mask = single.unwrapped.action_masks().reshape(N, 2)
        masks = np.stack([observations[agent]["action_mask"] for agent in AGENTS])
        np.testing.assert_array_equal(masks, line_mask)
        assert masks.dtype == np.int8 and masks[:, 0].all()  # waiting is always allowed
        single.step(joint)
        observations, _, _, _, infos = parallel.step(_actions(joint))
        for j, agent in enumerate(AGENTS):
            if joint[j] and not masks[j, 1]:  # asked to tamp a masked section: not tamped, pays nothing
                masked_requests += 1
                assert not infos[agent]["tamped_sections"] and infos[agent]["possession_share"] == 0.0
    assert masked_requests >= 2  # section 2 at the start, section 0 the step after its tamping


def test_an_agent_sees_its_request_dropped_and_the_line_clipped():
    """Six requests for a capacity of 3 (the fourth joint action): the three sections not tamped say ``dropped``,
    every agent ``clipped`` (the line env's flag); a masked request is dropped without clipping; a section that
    waits is never dropped."""
    _, _, parallel, _ = _pair(seed=11)
    for joint in JOINT:
        observations, _, _, _, infos = parallel.step(_actions(joint))
        line = parallel.line_info
        tamped = np.array([infos[agent]["tamped_sections"] for agent in AGENTS])
        dropped = np.array([infos[agent]["dropped"] for agent in AGENTS])
        np.testing.assert_array_equal(dropped, (joint == 1) & ~tamped)
        assert all(infos[agent]["clipped"] == line["clipped"] for agent in AGENTS)
    _, _, parallel, _ = _pair(seed=11)
    parallel.step(_actions(JOINT[0]))
    infos = parallel.step(_actions(JOINT[1]))[4]  # section 0 again, tamped last step: masked
    assert infos["section_0"]["dropped"] and not infos["section_0"]["clipped"]
    infos = parallel.step(_actions(JOINT[2]))[4]
    infos = parallel.step(_actions(JOINT[3]))[4]  # six for three
    assert sum(infos[agent]["dropped"] for agent in AGENTS) == 3 and infos["section_0"]["clipped"]


def test_get_state_and_set_state_continue_the_episode_bit_for_bit():
    """A snapshot after two steps, restored after the episode ended (every agent truncated), makes the agents live
    again with the observations, infos and global state of that moment, and the same joint actions then give the
    same rewards and observations; a second restore into another PettingZoo env of the config too."""
    _, _, parallel, _ = _pair(seed=5)
    for joint in JOINT[:2]:
        observations, _, _, _, infos = parallel.step(_actions(joint))
    snap, state = parallel.get_state(), parallel.state()
    rest = [parallel.step(_actions(joint)) for joint in JOINT[2:]]
    assert parallel.agents == []
    for target in (parallel, line_parallel_env(SMALL, **SHORT)):
        if target is not parallel:
            target.reset(seed=0)  # another episode, then the snapshot
        again_obs, again_infos = target.set_state(snap)
        assert target.agents == AGENTS
        np.testing.assert_array_equal(target.state(), state)
        for agent in AGENTS:
            np.testing.assert_array_equal(again_obs[agent]["observation"], observations[agent]["observation"])
            np.testing.assert_array_equal(again_obs[agent]["action_mask"], observations[agent]["action_mask"])
            assert again_infos[agent]["cost"] == infos[agent]["cost"]
        for joint, (obs, rewards, _, truncations, _) in zip(JOINT[2:], rest, strict=True):
            obs2, rewards2, _, truncations2, _ = target.step(_actions(joint))
            assert rewards2 == rewards and truncations2 == truncations
            for agent in AGENTS:
                np.testing.assert_array_equal(obs2[agent]["observation"], obs[agent]["observation"])
    with pytest.raises(RuntimeError, match="call reset"):
        line_parallel_env(SMALL, **SHORT).get_state()


CHOICE_IDS = ("trackenv/TampingLine-v1", "trackenv/TampingLineWet-v0")
CHOICE_SMALL = {"n_sections": 4, "capacity": 3, "horizon_years": 0.75}  # 3 steps


@pytest.mark.filterwarnings("error")
@pytest.mark.parametrize("env_id", CHOICE_IDS)
def test_pettingzoo_api_and_seed_tests_on_the_choices(env_id):
    env = line_parallel_env(env_id, **CHOICE_SMALL)
    assert env.action_space("section_0") == gym.spaces.Discrete(len(CHOICES))
    assert env.observation_space("section_0")["action_mask"].shape == (len(CHOICES),)
    assert {"section_measurement_age", "section_survey"} <= set(env.feature_names)
    parallel_api_test(env, num_cycles=100)
    parallel_seed_test(lambda: line_parallel_env(env_id, **CHOICE_SMALL))


def test_choices_split_the_possession_among_the_sections_with_track_work():
    """Random choices drawn within each agent's mask, on the wet line under a budget small enough to mask:
    the masks are the line env's, the agents' rewards add up to the line's, and the possession is shared by the
    sections with track work only (an inspection or a survey pays none of it)."""
    kwargs = {**CHOICE_SMALL, "horizon_years": 2.0, "annual_budget": 80.0}
    single = gym.make("trackenv/TampingLineWet-v0", **kwargs)
    parallel = line_parallel_env("trackenv/TampingLineWet-v0", **kwargs)
    single.reset(seed=3)
    observations, _ = parallel.reset(seed=3)
    agents = parallel.possible_agents
    rng = np.random.default_rng(0)
    kinds = set()
    while parallel.agents:
        masks = np.stack([observations[agent]["action_mask"] for agent in agents])
        np.testing.assert_array_equal(masks, single.unwrapped.action_masks().reshape(len(agents), len(CHOICES)))
        joint = np.array([rng.choice(np.flatnonzero(row)) for row in masks])
        _, reward, _, _, info = single.step(joint)
        observations, rewards, _, _, infos = parallel.step(dict(zip(agents, joint.tolist())))
        assert sum(rewards.values()) == pytest.approx(reward, rel=1e-12, abs=1e-9)
        worked = IS_TRACK_WORK[info["section_choices"]]
        possession = info["costs"]["possession"]
        assert (possession > 0) == worked.any()
        for j, agent in enumerate(agents):
            share = possession / worked.sum() if worked[j] else 0.0
            assert infos[agent]["possession_share"] == pytest.approx(share, rel=1e-12)
            assert infos[agent]["section_choices"] == info["section_choices"][j]
            assert rewards[agent] == pytest.approx(-(info["section_costs"][j] + share), rel=1e-12, abs=1e-12)
        kinds |= {CHOICES[c] for c in info["section_choices"]}
    assert {"inspect", "survey"} & kinds and {"spot_tamp", "drainage", "renew"} & kinds  # the rule was exercised
    with pytest.raises(ValueError, match=r"must be a choice code in \[0, 6\] \(an integer\), got 7"):
        parallel.reset(seed=0)
        parallel.step({**dict.fromkeys(agents, 0), "section_1": 7})


def test_render_passes_through():
    single, _, parallel, _ = _pair(seed=0, render_mode="rgb_array")
    single.step(JOINT[0])
    parallel.step(_actions(JOINT[0]))
    frame = parallel.render()
    assert frame.ndim == 3 and frame.shape[2] == 3
    np.testing.assert_array_equal(frame, single.render())
    without = line_parallel_env(SMALL, **SHORT)
    without.reset(seed=0)
    assert without.render() is None


def test_every_listed_id_is_a_parallel_env_and_the_list_is_the_documented_one():
    """The ids the messages name are those the multi-agent page lists, and each builds a parallel env whose agents
    are its sections (the 60 m track's six included)."""
    from trackenv.envs.parallel import _line_env_ids

    ids = _line_env_ids()
    assert ids == sorted(["trackenv/Tamping-v1", "trackenv/TampingLine-v0", "trackenv/TampingLine-v1",
                          "trackenv/TampingLineDefects-v0", "trackenv/TampingLineHard-v0",
                          "trackenv/TampingLineLong-v0", "trackenv/TampingLineSmall-v0", "trackenv/TampingLineWet-v0"])
    page = (Path(__file__).resolve().parents[2] / "docs" / "environments" / "multi-agent.md").read_text()
    assert all(f"`{env_id}`" in page for env_id in ids)
    env = line_parallel_env("trackenv/Tamping-v1")
    assert env.possible_agents == [agent_name(i) for i in range(6)]


def test_errors():
    with pytest.raises(ValueError, match=r"env_id must name a TampingLine env \(one of .*TampingLineSmall-v0"):
        line_parallel_env("CartPole-v1")
    # a TampingLine (the 60 m track), but Discrete actions: the ids that act in their own space are named
    with pytest.raises(ValueError, match=r"'trackenv/TampingDiscrete-v1' acts in Discrete\(7\): one agent per section "
                                         r"needs the line env's own actions.*as on trackenv/Tamping-v1, "):
        line_parallel_env("trackenv/TampingDiscrete-v1")
    with pytest.raises(ValueError, match=r"got 'trackenv/TampingNetwork-v0' \(TampingNetwork\)"):
        line_parallel_env("trackenv/TampingNetwork-v0")
    env = line_parallel_env(SMALL, **SHORT)
    with pytest.raises(RuntimeError, match="call reset"):
        env.step(_actions(JOINT[0]))
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"missing \['section_5'\]"):
        env.step({agent: 0 for agent in AGENTS[:5]})
    with pytest.raises(ValueError, match=r"unknown \['section_9'\]"):
        env.step({**_actions(JOINT[1]), "section_9": 0})
    for wrong in (2, 1.0, True, np.array([1]), "1", None):  # as the line env, only an integer of the space
        with pytest.raises(ValueError, match=r"actions\['section_1'\] must be 0 \(wait\) or 1 \(tamp\) "
                                             r"\(an integer\), got "):
            env.step({**_actions(JOINT[1]), "section_1": wrong})
    assert env.agents == AGENTS  # a refused step changes nothing
    with pytest.raises(ValueError, match="agent must be one of"):
        env.observation_space("section_6")
    with pytest.raises(ValueError, match="options must be a dict"):
        env.reset(options=[1])
    assert agent_name(4) == "section_4" and isinstance(env, LineParallelEnv)


def test_missing_pettingzoo_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "pettingzoo", None)  # import pettingzoo now raises ImportError
    with pytest.raises(ImportError, match=re.escape('pip install "trackenv[multiagent]"')):
        line_parallel_env(SMALL)


def test_the_library_imports_without_loading_pettingzoo():
    code = "import sys, trackenv, trackenv.envs; print('pettingzoo' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"


def test_documentation_example_runs(capsys):
    """The page's example (every python block, in order) runs and prints the returns it promises."""
    page = Path(__file__).resolve().parents[2] / "docs" / "environments" / "multi-agent.md"
    blocks = re.findall(r"```python\n(.*?)```", page.read_text(), flags=re.S)
    assert blocks
    namespace: dict = {}
    for block in blocks:
        exec(compile(block, str(page), "exec"), namespace)
    out = capsys.readouterr().out
    assert re.search(r"greedy: -\d+\.\d k€", out) and re.search(r"random: -\d+\.\d k€", out)
