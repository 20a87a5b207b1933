"""The learners' wrappers: ranked actions, section-level and flat observations, MultiDiscrete actions, masks
in the observation; single and vector forms agree; masks reachable the way sb3-contrib looks for them."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces

import trackenv.envs  # noqa: F401  (registers the ids)
from trackenv.envs import TampingEnv, scenario
from trackenv.envs.wrappers import (
    ActionMaskObservation,
    MultiDiscreteActions,
    RankedActions,
    SectionObservation,
    make_ranked,
    make_ranked_vector,
    n_sections_of,
    ranked_to_sections,
    section_keys,
)

# 30 m (51 sleepers) in 3 sections of 10 m, 4 steps
CFG = scenario("track60", n_sections=3, segment_length_m=30.0, sections_per_segment=3, capacity=3, horizon_years=1.0)
# the section-level keys (the space's order): the per-sleeper profiles level and contact_force, of shape
# (1, 51) on this one segment, are dropped
SECTION_KEYS = ["budget_left", "measurement_age", "register", "section_peak", "section_sd", "tampings",
                "tampings_since_renewal", "time", "years_since_tamping"]
FLAT_SIZE = 3 + 6 * 3  # the 3 keys of shape (1,) and the 6 of shape (n_sections,)


def test_ranked_tamps_the_k_worst_sections() -> None:
    sd = np.array([[1.0, 3.0, 2.0, 0.5], [2.0, 2.0, 1.0, 4.0]])
    out = ranked_to_sections(np.array([2, 1]), sd)
    assert out.dtype == np.int8
    np.testing.assert_array_equal(out, [[0, 1, 1, 0], [0, 0, 0, 1]])
    np.testing.assert_array_equal(ranked_to_sections(np.array([0, 4]), sd), [[0, 0, 0, 0], [1, 1, 1, 1]])
    # ties go to the lower index; an unbatched observation gives an unbatched action
    np.testing.assert_array_equal(ranked_to_sections(1, np.array([2.0, 2.0, 1.0])), [1, 0, 0])


@pytest.mark.parametrize("k", [-1, 5, 1.5])
def test_ranked_rejects_counts_out_of_range(k) -> None:
    with pytest.raises(ValueError, match=r"\[0, 4\]"):
        ranked_to_sections(np.array([k]), np.ones((1, 4)))


@pytest.mark.parametrize("env_id, action", [
    ("trackenv/TampingDiscrete-v1", "3"), ("trackenv/TampingDiscrete-v1", {"a": 1}),
    ("trackenv/TampingDiscrete-v1", None), ("trackenv/Tamping-v1", ["1"] * 6),
    ("trackenv/Tamping-v1", np.ones(6, complex)), ("trackenv/Tamping-v1", [[0, 1], [0]]),
    ("trackenv/TampingRanked-v1", None), ("trackenv/TampingRanked-v1", "000000"),
    ("trackenv/TampingRanked-v1", {"a": 1}),
])
def test_actions_that_are_no_numbers_are_refused_naming_the_action(env_id, action) -> None:
    """Text, a dict, None, complex numbers or a ragged list: one ValueError saying what an action is (numpy
    would take "3" as 3, or fail deep inside on a dict)."""
    env = gym.make(env_id, disable_env_checker=True)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"^action must be "):
        env.step(action)


def test_the_flat_ranked_vector_env_refuses_same_step() -> None:
    with pytest.raises(ValueError, match=r"^autoreset_mode must be NEXT_STEP with flat=True"):
        gym.make_vec("trackenv/TampingRankedFlat-v1", num_envs=2, vectorization_mode="vector_entry_point",
                     autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)


def test_section_keys_and_n_sections_are_generic() -> None:
    env = TampingEnv(CFG)
    assert n_sections_of(gym.wrappers.RecordEpisodeStatistics(env)) == 3
    assert section_keys(env.observation_space, 3) == SECTION_KEYS
    # any Dict observation with per-section keys: e.g. a line env with 50 sections and per-sleeper arrays, of
    # the whole line or of one segment
    space = spaces.Dict({"level": spaces.Box(0, 1, (334,)), "profile": spaces.Box(0, 1, (1, 334)),
                         "section_sd": spaces.Box(0, 1, (50,)), "speed_band": spaces.Box(0, 1, (50, 2)),
                         "time": spaces.Box(0, 1, (1,))})
    assert section_keys(space, 50) == ["section_sd", "speed_band", "time"]


def test_ranked_wrapper_is_the_env_driven_by_ranked_to_sections() -> None:
    ranked = RankedActions(TampingEnv(CFG))
    base = TampingEnv(CFG)
    assert ranked.action_space == spaces.Discrete(4)
    obs_r, _ = ranked.reset(seed=5)
    obs_b, _ = base.reset(seed=5)
    for k in (1, 0, 3, 2):
        action = ranked_to_sections(k, obs_b["section_sd"])
        obs_r, r_r, _, tr_r, info_r = ranked.step(k)
        obs_b, r_b, _, tr_b, info_b = base.step(action)
        assert r_r == r_b and tr_r == tr_b
        np.testing.assert_array_equal(info_r["tamped_sections"], info_b["tamped_sections"])
        for key in obs_b:
            np.testing.assert_array_equal(obs_r[key], obs_b[key])
    assert ranked.action_masks().tolist() == [True] * 4
    with pytest.raises(TypeError, match="MultiBinary"):
        RankedActions(TampingEnv(CFG, action_type="discrete"))
    with pytest.raises(ValueError):
        ranked.step(7)


def test_registered_ranked_ids_and_masks_through_gym_make() -> None:
    env = gym.make("trackenv/TampingRanked-v1", config=CFG)
    assert env.action_space == spaces.Discrete(4)
    assert list(env.observation_space.spaces) == SECTION_KEYS
    env.reset(seed=0)
    # gym.make's own wrappers forward no methods: get_wrapper_attr finds the nearest action_masks
    assert env.get_wrapper_attr("action_masks")().tolist() == [True] * 4
    flat = gym.make("trackenv/TampingRankedFlat-v1", config=CFG)
    assert isinstance(flat.observation_space, spaces.Box) and flat.observation_space.shape == (FLAT_SIZE,)
    obs, _ = flat.reset(seed=0)
    assert flat.observation_space.contains(obs)
    obs, reward, *_ = flat.step(3)
    assert flat.observation_space.contains(obs) and reward < 0
    base = gym.make("trackenv/Tamping-v1", config=CFG)
    base.reset(seed=0)
    assert base.get_wrapper_attr("action_masks")().shape == (6,)


def test_sb3_contrib_finds_the_masks_through_the_wrappers() -> None:
    pytest.importorskip("sb3_contrib")
    from sb3_contrib.common.maskable.utils import get_action_masks
    from stable_baselines3.common.vec_env import DummyVecEnv

    venv = DummyVecEnv([lambda: gym.make("trackenv/TampingRanked-v1", config=CFG)] * 2)
    venv.reset()
    assert get_action_masks(venv).shape == (2, 4)
    venv = DummyVecEnv([lambda: MultiDiscreteActions(SectionObservation(TampingEnv(CFG)))])
    venv.seed(1)  # an episode whose sections were last tamped 2 steps or more before its start: none masked
    venv.reset()
    venv.step(np.array([[1, 0, 0]]))
    np.testing.assert_array_equal(get_action_masks(venv)[0].reshape(3, 2), [[1, 0], [1, 1], [1, 1]])


def test_multidiscrete_and_mask_observation() -> None:
    env = ActionMaskObservation(MultiDiscreteActions(TampingEnv(CFG)))
    assert env.action_space == spaces.MultiDiscrete([2, 2, 2])
    assert env.observation_space["action_mask"].shape == (6,)
    obs, _ = env.reset(seed=1)
    assert env.observation_space.contains(obs) and obs["action_mask"].all()
    obs, *_ = env.step(np.array([0, 1, 0]))
    assert env.observation_space.contains(obs)
    assert obs["action_mask"].tolist() == [1, 1, 1, 0, 1, 1]  # section 2 was just tamped
    assert env.action_masks().tolist() == [True, True, True, False, True, True]


def test_vector_ranked_env_matches_the_single_wrapped_envs() -> None:
    seeds = [3, 4]
    venv = gym.make_vec("trackenv/TampingRanked-v1", num_envs=2, vectorization_mode="vector_entry_point",
                        config=CFG)
    singles = [make_ranked(config=CFG) for _ in seeds]
    assert venv.single_action_space == singles[0].action_space
    assert venv.single_observation_space == singles[0].observation_space
    obs, _ = venv.reset(seed=seeds)
    for e, s in zip(singles, seeds):
        e.reset(seed=s)
    for t, ks in enumerate([(1, 3), (0, 2), (2, 0), (3, 1)]):
        obs, rewards, _, truncated, infos = venv.step(np.array(ks))
        for i, (e, k) in enumerate(zip(singles, ks)):
            o, r, _, tr, info = e.step(k)
            np.testing.assert_allclose(rewards[i], r, rtol=1e-9)
            assert truncated[i] == tr
            src = infos["final_info"] if tr else infos
            np.testing.assert_array_equal(src["tamped_sections"][i], info["tamped_sections"])
            final = infos["final_obs"][i] if tr else {k: v[i] for k, v in obs.items()}
            assert list(final) == SECTION_KEYS, t
            np.testing.assert_allclose(final["section_sd"], o["section_sd"], rtol=1e-5)
    assert venv.action_masks().shape == (2, 4)


def _same_step_only(num_envs: int, **kwargs):
    """A batched env that knows only the SAME_STEP autoreset mode (unknown keywords raise ValueError)."""
    from trackenv.envs.vector import TampingVectorEnv

    if "autoreset_mode" in kwargs:
        raise ValueError("unknown LineConfig key(s) ['autoreset_mode']")
    return TampingVectorEnv(num_envs, **kwargs)


@pytest.mark.parametrize("vector_entry_point", [None, _same_step_only])
def test_ranked_flat_vector_falls_back_to_sync_vector_env(vector_entry_point) -> None:
    """An env following the conventions but with no batched form, or one without the NEXT_STEP mode that the
    flat observation needs (as a new env may start), gets Gymnasium's SyncVectorEnv under the same wrappers."""
    env_id = f"trackenv_test/TampingVector{'None' if vector_entry_point is None else 'SameStep'}-v0"
    if env_id not in gym.registry:
        gym.register(env_id, entry_point="trackenv.envs.tamping:TampingEnv", vector_entry_point=vector_entry_point)

    venv = make_ranked_vector(2, env_id=env_id, flat=True, config=CFG)
    assert isinstance(venv.unwrapped, gym.vector.SyncVectorEnv)
    assert venv.metadata["autoreset_mode"] == gym.vector.AutoresetMode.NEXT_STEP
    obs, _ = venv.reset(seed=[0, 1])
    assert obs.shape == (2, FLAT_SIZE)
    obs, rewards, *_ = venv.step(np.array([3, 0]))
    assert venv.observation_space.contains(obs) and np.all(rewards < 0)


def test_tamping_only_ranked_wrappers_are_the_k_worst_by_a_plain_sort() -> None:
    """The tamp-or-wait ranked wrappers, single and vector, against the line env driven by a reference decoding
    written out here (a stable sort of the observed SDs): the same rewards and tampings, bit for bit (the ranked
    form of the choices shares their code and must leave them as they were)."""
    env_id, kwargs, seeds = "trackenv/TampingLineSmall-v0", {"n_sections": 4, "horizon_years": 1.0}, [5, 6]
    single = RankedActions(gym.make(env_id, **kwargs))
    venv = make_ranked_vector(2, env_id=env_id, **kwargs)
    bases = [gym.make(env_id, **kwargs) for _ in seeds]
    single.reset(seed=seeds[0])
    venv.reset(seed=seeds)
    observations = [base.reset(seed=s)[0] for base, s in zip(bases, seeds)]
    for counts in [(2, 4), (0, 1), (3, 3), (1, 0)]:
        _, rewards, _, _, infos = venv.step(np.array(counts))
        _, reward, *_, info = single.step(counts[0])
        for i, (base, k) in enumerate(zip(bases, counts)):
            action = np.zeros(4, dtype=np.int8)
            action[np.argsort(-observations[i]["section_sd"], kind="stable")[:k]] = 1
            observations[i], base_reward, *_, base_info = base.step(action)
            assert rewards[i] == base_reward
            np.testing.assert_array_equal(infos["tamped_sections"][i], base_info["tamped_sections"])
            if i == 0:
                assert reward == base_reward
                np.testing.assert_array_equal(info["tamped_sections"], base_info["tamped_sections"])


@pytest.mark.parametrize("wrap", [
    RankedActions,
    SectionObservation,
    MultiDiscreteActions,
    lambda env: ActionMaskObservation(MultiDiscreteActions(env)),
], ids=["ranked", "section", "multidiscrete", "mask"])
@pytest.mark.filterwarnings("ignore:.*is different from the unwrapped version")  # the checker's note on any wrapper
def test_gymnasiums_env_checker_passes_on_every_wrapper(wrap) -> None:
    """Gymnasium's own checker on each learner wrapper over a registered id: it asks each wrapper to record its
    constructor's arguments (so that a spec can rebuild the stack) and checks spaces, seeding and determinism."""
    from gymnasium.utils.env_checker import check_env

    env = wrap(gym.make("trackenv/Tamping-v1", config=CFG).unwrapped)
    check_env(env, skip_render_check=True)
    assert [w.name for w in env.spec.additional_wrappers][-1] == type(env).__name__
