"""TampingVectorEnv: built by gym.make_vec through the registered vector_entry_point; the same episodes as
TampingEnv for the same seeds and actions; both autoreset modes, each against Gymnasium's SyncVectorEnv."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from same_results import assert_same

import trackenv.envs  # noqa: F401  (registers the ids)
from trackenv.envs import TampingEnv, scenario
from trackenv.envs.vector import TampingVectorEnv

# small_config: 30 m (51 sleepers) in 3 sections of 10 m, 8 steps
SMALL = {"n_sections": 3, "segment_length_m": 30.0, "sections_per_segment": 3, "capacity": 3, "horizon_years": 2.0}
CFG = scenario("track60", **SMALL)
# seeds whose sections were last tamped 2 steps or more before the start (in the next episode too): none is
# masked at the first step
SEEDS = [2, 14, 15]
# (steps, envs, sections): a different tamping pattern per env; masked repeats included
ACTIONS = np.zeros((CFG.horizon_steps + 1, 3, 3), dtype=np.int8)
ACTIONS[1, 0] = [1, 0, 0]
ACTIONS[2, 0] = [1, 0, 0]  # masked (tamped last step): ignored
ACTIONS[2, 1] = [0, 1, 1]
ACTIONS[4, 2] = [1, 1, 1]
ACTIONS[7, 1] = [1, 0, 0]
ACTIONS[8, 0] = [0, 0, 1]  # first step of the new episodes


def make_vec(**kwargs) -> gym.vector.VectorEnv:
    return gym.make_vec("trackenv/Tamping-v1", num_envs=3, vectorization_mode="vector_entry_point", **kwargs)


@pytest.fixture(scope="module")
def runs() -> dict:
    """The vector env and three single envs driven with the same seeds and actions through one whole episode
    and the first step of the next (vector side only)."""
    venv = make_vec(config=CFG)
    singles = [TampingEnv(CFG) for _ in SEEDS]
    v = {"reset": venv.reset(seed=SEEDS), "steps": []}
    s = {"reset": [e.reset(seed=seed) for e, seed in zip(singles, SEEDS)], "steps": []}
    masks = []
    for t in range(CFG.horizon_steps + 1):
        masks.append(venv.unwrapped.action_masks())
        v["steps"].append(venv.step(ACTIONS[t]))
        if t < CFG.horizon_steps:
            s["steps"].append([e.step(ACTIONS[t, i]) for i, e in enumerate(singles)])
    return {"venv": venv, "v": v, "s": s, "masks": masks}


def test_make_vec_uses_the_vector_entry_point() -> None:
    venv = make_vec(config=CFG)
    assert isinstance(venv.unwrapped, TampingVectorEnv)
    assert venv.num_envs == 3
    assert venv.unwrapped.config == CFG
    single = TampingEnv(CFG)
    assert venv.single_observation_space == single.observation_space
    assert venv.single_action_space == single.action_space == gym.spaces.MultiBinary(3)
    assert venv.action_space.shape == (3, 3)
    assert venv.observation_space["level"].shape == (3, 1, CFG.n_sleepers)
    assert venv.metadata["autoreset_mode"] == gym.vector.AutoresetMode.SAME_STEP
    # keywords instead of a config object
    kw = make_vec(**SMALL)
    assert kw.unwrapped.config == CFG
    assert TampingVectorEnv(2).config == scenario("track60")


@pytest.mark.slow  # shares the 3 s module fixture
def test_reset_matches_single_envs(runs: dict) -> None:
    obs, infos = runs["v"]["reset"]
    assert runs["venv"].observation_space.contains(obs)
    for i, (o, info) in enumerate(runs["s"]["reset"]):
        for k in o:
            np.testing.assert_array_equal(obs[k][i], o[k], err_msg=k)
        np.testing.assert_array_equal(infos["section_sd_m"][i], info["section_sd_m"])
        assert infos["costs"]["tamping"][i] == 0.0


@pytest.mark.slow  # shares the 3 s module fixture
def test_steps_match_single_envs(runs: dict) -> None:
    venv = runs["venv"]
    for t, (vstep, ssteps) in enumerate(zip(runs["v"]["steps"], runs["s"]["steps"])):
        obs, rewards, terminated, truncated, infos = vstep
        assert venv.observation_space.contains(obs), t
        assert rewards.shape == (3,) and rewards.dtype == np.float64
        assert not terminated.any()
        for i, (o, r, te, tr, info) in enumerate(ssteps):
            np.testing.assert_allclose(rewards[i], r, rtol=1e-9, err_msg=f"step {t} env {i}")
            assert truncated[i] == tr and terminated[i] == te
            src = infos["final_info"] if tr else infos  # SAME_STEP: at the horizon, the new episode's info
            np.testing.assert_array_equal(src["tamped_sections"][i], info["tamped_sections"])
            for k in info["costs"]:
                np.testing.assert_allclose(src["costs"][k][i], info["costs"][k], rtol=1e-9, atol=1e-12)
            total = sum(src["costs"][k][i] for k in info["costs"])
            np.testing.assert_allclose(rewards[i], -total, rtol=1e-12)
            if not tr:  # at the horizon the vector env returns the next episode's first observation
                for k in o:
                    np.testing.assert_allclose(obs[k][i], o[k], rtol=1e-6, atol=1e-5, err_msg=f"{k} step {t}")


@pytest.mark.slow  # shares the 3 s module fixture
def test_masks_follow_the_tampings(runs: dict) -> None:
    masks = runs["masks"]
    assert masks[0].shape == (3, 6) and masks[0].all()
    # env 0 tamped section 0 at step index 1: masked at step index 2, and the request ignored
    assert masks[2][0].tolist() == [True, False, True, True, True, True]
    infos = runs["v"]["steps"][2][4]
    assert infos["tamped_sections"][0].tolist() == [False, False, False]
    assert infos["tamped_sections"][1].tolist() == [False, True, True]


@pytest.mark.slow  # shares the 3 s module fixture
def test_autoreset_at_the_horizon(runs: dict) -> None:
    h = CFG.horizon_steps
    for t in range(h - 1):
        obs, _, _, truncated, infos = runs["v"]["steps"][t]
        assert not truncated.any() and "final_obs" not in infos
    obs, _, _, truncated, infos = runs["v"]["steps"][h - 1]
    assert truncated.all()
    assert infos["_final_obs"].all() and infos["_final_info"].all()
    for i, (o, *_rest, info) in enumerate(runs["s"]["steps"][h - 1]):
        final = infos["final_obs"][i]
        for k in o:
            np.testing.assert_allclose(final[k], o[k], rtol=1e-6, atol=1e-5, err_msg=k)
        assert infos["final_info"]["year"][i] == pytest.approx(info["year"])
    assert infos["year"].tolist() == [0.0] * 3  # the new episodes' first info
    # new episodes: time 0, nothing tamped yet, a fresh track
    np.testing.assert_array_equal(obs["time"], 0.0)
    np.testing.assert_array_equal(obs["tampings"], 0.0)
    assert runs["venv"].observation_space.contains(obs)
    for i in range(3):
        assert not np.array_equal(obs["level"][i], runs["v"]["reset"][0]["level"][i])
    # and they go on: one step into the new episodes
    obs, rewards, terminated, truncated, infos = runs["v"]["steps"][h]
    np.testing.assert_allclose(obs["time"], 1.0 / h)
    assert not truncated.any() and not terminated.any() and "final_obs" not in infos
    assert np.all(np.isfinite(rewards)) and np.all(rewards < 0)
    assert infos["tamped_sections"][0].tolist() == [False, False, True]


def test_reset_seeding_and_bad_input() -> None:
    venv = make_vec(config=CFG)
    a, _ = venv.reset(seed=100)
    b, _ = venv.reset(seed=[100, 101, 102])
    for k in a:
        np.testing.assert_array_equal(a[k], b[k])
    with pytest.raises(ValueError, match="seed"):
        venv.reset(seed=[1, 2])
    with pytest.raises(ValueError):
        venv.step(np.zeros((2, 3), dtype=np.int8))
    with pytest.raises(ValueError):
        venv.step(np.full((3, 3), 2, dtype=np.int8))
    with pytest.raises(ValueError, match="num_envs"):
        TampingVectorEnv(num_envs=0, config=CFG)
    with pytest.raises(RuntimeError, match="reset"):
        TampingVectorEnv(num_envs=2, config=CFG).step(np.zeros((2, 3), dtype=np.int8))


def test_discrete_vector_env() -> None:
    venv = gym.make_vec("trackenv/TampingDiscrete-v1", num_envs=2, vectorization_mode="vector_entry_point",
                        config=CFG)
    assert venv.single_action_space == gym.spaces.Discrete(4)
    obs, _ = venv.reset(seed=[0, 1])
    assert venv.observation_space.contains(obs)
    assert venv.unwrapped.action_masks().shape == (2, 4)
    obs, rewards, terminated, truncated, infos = venv.step(np.array([0, 2]))
    assert venv.observation_space.contains(obs)
    assert infos["tamped_sections"].tolist() == [[False, False, False], [False, True, False]]
    assert venv.unwrapped.action_masks().tolist() == [[True] * 4, [True, True, False, True]]
    single = TampingEnv(CFG, action_type="discrete")
    single.reset(seed=1)
    np.testing.assert_allclose(rewards[1], single.step(2)[1], rtol=1e-9)
    with pytest.raises(ValueError):
        venv.step(np.array([0, 4]))


@pytest.mark.slow
@pytest.mark.parametrize("mode", [gym.vector.AutoresetMode.SAME_STEP, gym.vector.AutoresetMode.NEXT_STEP])
def test_autoreset_modes_match_sync_vector_env(mode) -> None:
    """Over one episode and into the next, the native vector env gives what Gymnasium's SyncVectorEnv over
    TampingEnv gives in the same autoreset mode: observations, rewards, flags, infos with their masks."""
    cfg = CFG.replace(horizon_years=1.0)  # 4 steps
    h = cfg.horizon_steps
    native = make_vec(config=cfg, autoreset_mode=mode)
    assert native.metadata["autoreset_mode"] == mode
    sync = gym.vector.SyncVectorEnv([lambda: TampingEnv(cfg) for _ in SEEDS], autoreset_mode=mode)
    assert_same(native.reset(seed=SEEDS), sync.reset(seed=SEEDS), "reset")
    for t in range(h + 2):
        actions = ACTIONS[t % ACTIONS.shape[0]]
        got, want = native.step(actions), sync.step(actions)
        for name, a, b in zip(("obs", "reward", "terminated", "truncated", "info"), got, want):
            assert_same(a, b, f"step {t} {name}")
        assert got[3].all() == (t == h - 1)  # NEXT_STEP: step h resets, step h + 1 is the new episodes' first


def test_render_mode_renders_the_first_env() -> None:
    venv = TampingVectorEnv(2, CFG, render_mode="rgb_array")
    assert venv.render() is None  # nothing to draw before reset
    venv.reset(seed=0)
    frame = venv.render()
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.dtype == np.uint8
    assert TampingVectorEnv(2, CFG).render() is None
    made = make_vec(config=CFG, render_mode="rgb_array")
    assert made.render_mode == "rgb_array"
    made.reset(seed=1)
    made.step(np.zeros((3, 3), dtype=np.int8))
    assert made.render().shape == frame.shape
    with pytest.raises(ValueError, match="render_mode"):
        TampingVectorEnv(2, CFG, render_mode="human")
    with pytest.raises(ValueError, match="autoreset_mode"):
        TampingVectorEnv(2, CFG, autoreset_mode=gym.vector.AutoresetMode.DISABLED)


@pytest.mark.parametrize("actions", [None, 5, np.zeros(3), np.zeros((2, 2)), [[0, 1, 0], [0, 1]]])
def test_malformed_vector_actions_name_the_expected_shape(actions) -> None:
    venv = TampingVectorEnv(num_envs=2, config=CFG)
    venv.reset(seed=0)
    with pytest.raises(ValueError, match=r"^actions must have shape \(2, 3\) \(one action per env\), got "
                                         r"(a ragged list|\w+ of shape)"):
        venv.step(actions)


def test_a_bad_value_in_a_vector_action_names_its_env() -> None:
    venv = TampingVectorEnv(num_envs=2, config=CFG)
    venv.reset(seed=0)
    with pytest.raises(ValueError, match=r"^actions\[1\]: action values must be 0 or 1"):
        venv.step(np.array([[0, 0, 0], [0, 2, 0]]))


@pytest.mark.parametrize("seed", [1.5, -1, True, [0, -1], [0, 1.5], np.array(2.5)])
def test_vector_reset_refuses_bad_seeds(seed) -> None:
    with pytest.raises(ValueError, match="seed must be an integer"):
        TampingVectorEnv(num_envs=2, config=CFG).reset(seed=seed)


def test_vector_reset_refuses_unknown_options() -> None:
    with pytest.raises(ValueError, match="unknown reset option"):
        TampingVectorEnv(num_envs=2, config=CFG).reset(seed=0, options={"x": 1})


@pytest.mark.parametrize("spelling, mode", [("NextStep", "NextStep"), ("next_step", "NextStep"),
                                            ("NEXT_STEP", "NextStep"), ("same_step", "SameStep")])
def test_autoreset_mode_takes_its_value_or_its_name_in_any_case(spelling, mode) -> None:
    from trackenv.envs.batched import check_autoreset_mode

    assert check_autoreset_mode(spelling).value == mode
    with pytest.raises(ValueError, match=r"autoreset_mode must be one of \['SameStep', 'NextStep'\], got 'Disabled'"):
        check_autoreset_mode("Disabled")


def test_a_harness_given_an_env_id_for_a_preset_is_told_the_preset() -> None:
    from trackenv.envs.problems import problem_config

    with pytest.raises(ValueError, match=r"unknown scenario 'trackenv/TampingLineSmall-v0'.*an env id: give"):
        problem_config("trackenv/TampingLineSmall-v0")


@pytest.mark.parametrize("seeds", [None, [None, None, None]])
def test_reset_without_a_seed_continues_each_envs_generator(seeds) -> None:
    """As Gymnasium's SyncVectorEnv (each single env's ``reset()`` continues its generator): after
    ``reset(seed=s)``, ``reset()`` draws the same next episodes every time, those the sync env draws."""
    firsts = []
    for _ in range(2):
        venv = make_vec(config=CFG)
        venv.reset(seed=7)
        firsts.append(venv.reset(seed=seeds)[0])
    sync = gym.make_vec("trackenv/Tamping-v1", num_envs=3, vectorization_mode="sync", config=CFG)
    sync.reset(seed=7)
    expected = sync.reset()[0]
    for k in expected:
        np.testing.assert_array_equal(firsts[0][k], firsts[1][k])
        np.testing.assert_array_equal(firsts[0][k], expected[k])
    venv = make_vec(config=CFG)
    venv.reset(seed=7)
    mixed = venv.reset(seed=[None, 100, None])[0]  # a None keeps that env's generator, a seed reseeds
    fresh = make_vec(config=CFG).reset(seed=[100, 101, 102])[0]
    for k in expected:
        np.testing.assert_array_equal(mixed[k][[0, 2]], expected[k][[0, 2]])
        np.testing.assert_array_equal(mixed[k][1], fresh[k][0])
