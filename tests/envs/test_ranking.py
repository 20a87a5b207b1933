"""Ranked actions over the choices (trackenv.envs.ranking and the ranked wrappers on ``action_type="choices"``):
the scores and the precedence on a hand-made line, the decoded codes always allowed by the env's masks (random
counts under a budget small enough to mask), the ranked masks against the env's, the vector form against the
single one, and sb3-contrib's MaskablePPO on the ranked choices."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces

import trackenv.envs  # noqa: F401  (registers the ids)
from trackenv.envs.choices import CHOICES, INTERVENTIONS, NOTHING, code, work_per_code
from trackenv.envs.ranking import PRECEDENCE, rank_mask, ranked_choice_masks, ranked_to_choices, score_keys
from trackenv.envs.wrappers import (
    MultiDiscreteActions,
    RankedActions,
    RankedVectorActions,
    make_ranked,
    make_ranked_vector,
)

TAMP, SPOT, DRAIN, RENEW, INSPECT, SURVEY = (code(n) for n in INTERVENTIONS)
SMALL = {"n_sections": 4, "capacity": 3, "horizon_years": 2.0}  # 8 steps
#: four sections: measured SD and peak (mm), tampings since renewal, years since tamping, measurement age
#: (years), what a survey found (-1 not surveyed, 0 nothing, 1 a wet cause)
OBS = {"section_sd": np.array([1.0, 3.0, 2.0, 0.5]), "section_peak": np.array([5.0, 1.0, 9.0, 2.0]),
       "tampings_since_renewal": np.array([0.0, 2.0, 2.0, 1.0]), "years_since_tamping": np.array([2.0, 2.0, 0.5, 4.0]),
       "section_measurement_age": np.array([0.1, 1.0, 0.5, 2.0]), "section_survey": np.array([-1.0, 1.0, 0.0, -1.0])}
ALL_ALLOWED = np.ones(4 * len(CHOICES), dtype=bool)


def _counts(**by_head: int) -> np.ndarray:
    return np.array([by_head.get(h, 0) for h in INTERVENTIONS])


def test_rank_mask_breaks_ties_with_the_next_score_then_the_index() -> None:
    first = np.array([[1.0, 2.0, 2.0, 2.0]])
    second = np.array([[9.0, 0.0, 5.0, 5.0]])
    eligible = np.array([[True, True, True, False]])
    np.testing.assert_array_equal(rank_mask((first, second), eligible, np.array([1])), [[0, 0, 1, 0]])
    np.testing.assert_array_equal(rank_mask((first, second), eligible, np.array([2])), [[0, 1, 1, 0]])
    # never an ineligible entry, whatever the count
    np.testing.assert_array_equal(rank_mask((first, second), eligible, np.array([4])), eligible)


def test_each_head_ranks_by_its_score() -> None:
    def alone(head: str, k: int = 1) -> np.ndarray:
        return ranked_to_choices(_counts(**{head: k}), OBS, ALL_ALLOWED, INTERVENTIONS)

    np.testing.assert_array_equal(alone("tamp"), [0, TAMP, 0, 0])  # largest SD
    np.testing.assert_array_equal(alone("spot_tamp"), [0, 0, SPOT, 0])  # largest peak
    np.testing.assert_array_equal(alone("drainage"), [0, DRAIN, 0, 0])  # the wet cause found
    # then the unsurveyed by growth (SD over at least a year since tamping): 1/2 against 0.5/4
    np.testing.assert_array_equal(alone("drainage", 2), [DRAIN, DRAIN, 0, 0])
    np.testing.assert_array_equal(alone("renew"), [0, RENEW, 0, 0])  # 2 tampings since renewal, the larger SD
    # age × growth: 0.05, 1.5, 0.5 · 2/1 = 1.0, 0.25
    np.testing.assert_array_equal(alone("inspect", 2), [0, INSPECT, INSPECT, 0])
    np.testing.assert_array_equal(alone("survey"), [SURVEY, 0, 0, 0])  # not surveyed, the faster growth


def test_a_section_marked_twice_gets_the_first_choice_in_precedence() -> None:
    counts = _counts(tamp=1, spot_tamp=1, drainage=1, inspect=1, survey=1)
    # tamp and drainage both mark section 1: drainage comes first, and the tamping is not moved elsewhere
    np.testing.assert_array_equal(ranked_to_choices(counts, OBS, ALL_ALLOWED, INTERVENTIONS), [SURVEY, DRAIN, SPOT, 0])
    assert PRECEDENCE.index("drainage") < PRECEDENCE.index("tamp") < PRECEDENCE.index("inspect")
    # drainage masked on section 1: it goes to the next in its order, and the tamping stays on section 1
    masks = ALL_ALLOWED.reshape(4, -1).copy()
    masks[1, DRAIN] = False
    np.testing.assert_array_equal(ranked_to_choices(counts, OBS, masks.ravel(), INTERVENTIONS), [DRAIN, TAMP, SPOT, 0])


def test_counts_batched_and_validated() -> None:
    rows = {k: np.stack([v, v[::-1]]) for k, v in OBS.items()}
    counts = np.stack([_counts(tamp=1), _counts(tamp=2)])
    out = ranked_to_choices(counts, rows, np.stack([ALL_ALLOWED, ALL_ALLOWED]), INTERVENTIONS)
    np.testing.assert_array_equal(out, [[0, TAMP, 0, 0], [0, TAMP, TAMP, 0]])
    with pytest.raises(ValueError, match=r"\[0, 4\]"):
        ranked_to_choices(_counts(tamp=5), OBS, ALL_ALLOWED, INTERVENTIONS)
    with pytest.raises(ValueError, match="ranked count"):
        ranked_to_choices(np.array([1, 2]), OBS, ALL_ALLOWED, INTERVENTIONS)
    with pytest.raises(ValueError, match="ranked heads"):
        score_keys(["nothing"])


def test_ranked_masks_allow_counts_up_to_the_sections_allowed() -> None:
    masks = ALL_ALLOWED.reshape(4, -1).copy()
    masks[:3, RENEW] = False  # one section may be renewed
    masks[:, SURVEY] = False  # none may be surveyed
    out = ranked_choice_masks(masks.ravel(), ("tamp", "renew", "survey")).reshape(3, 5)
    np.testing.assert_array_equal(out, [[1, 1, 1, 1, 1], [1, 1, 0, 0, 0], [1, 0, 0, 0, 0]])


def test_ranked_masks_stop_at_what_fits_the_possession() -> None:
    """With each section's work and the capacity, a head's count stops where its allowed sections no longer fit
    together, least work first (drainage of 2 each in a possession of 3: one; 0.5 and 2 and 2 in 3: two), and a
    choice of no work (survey) is not capped."""
    masks = ALL_ALLOWED.reshape(4, -1).copy()
    work = np.array([[2.0, 2.0, 2.0, 2.0], [2.0, 0.5, 2.0, 9.0], [0.0, 0.0, 0.0, 0.0]])
    masks[3, RENEW] = False  # the renewal of work 9 is not allowed: it counts for nothing
    out = ranked_choice_masks(masks.ravel(), ("drainage", "renew", "survey"), (work, 3.0)).reshape(3, 5)
    np.testing.assert_array_equal(out, [[1, 1, 0, 0, 0], [1, 1, 1, 0, 0], [1, 1, 1, 1, 1]])


def _masked_counts(rng: np.random.Generator, ranked_mask: np.ndarray) -> np.ndarray:
    """A count per head drawn among those the ranked mask allows."""
    return np.array([rng.choice(np.flatnonzero(row)) for row in ranked_mask])


@pytest.mark.parametrize("env_id", ["trackenv/TampingLineWet-v0", "trackenv/TampingLine-v1"])
def test_decoded_choices_are_always_allowed_by_the_env_masks(env_id) -> None:
    """Random counts, within the ranked masks and beyond them, under an annual budget small enough to mask
    choices: every decoded code is one the env's mask allows, the ranked masks are those the env's imply, and
    the env applies the decoded codes (or drops some to nothing for the joint capacity or budget)."""
    env = RankedActions(gym.make(env_id, **SMALL, annual_budget=60.0, min_steps_between_tampings=0))
    config = env.unwrapped.config
    assert env.heads == INTERVENTIONS
    assert env.action_space == spaces.MultiDiscrete([5] * len(INTERVENTIONS))
    rng = np.random.default_rng(0)
    masked_by_budget = 0
    for episode in range(3):
        env.reset(seed=episode)
        for step in range(8):
            env_mask = env.unwrapped.action_masks().reshape(4, len(CHOICES))
            ranked_mask = env.action_masks().reshape(len(INTERVENTIONS), 5)
            for j, name in enumerate(INTERVENTIONS):  # the sections allowed, as many as fit the possession
                allowed = env_mask[:, code(name)]
                work = np.full(4, float(work_per_code(config.choice_work)[code(name)]))  # one length: equal works
                fits = int((np.cumsum(work[allowed]) <= config.capacity + 1e-9).sum())
                np.testing.assert_array_equal(ranked_mask[j], np.arange(5) <= fits)
            masked_by_budget += int((~env_mask[:, 1:]).sum())
            counts = _masked_counts(rng, ranked_mask) if step % 2 else rng.integers(0, 5, len(INTERVENTIONS))
            codes = env.action(counts)
            assert env_mask[np.arange(4), codes].all(), (episode, step, counts, codes)
            *_, info = env.step(counts)
            applied = info["section_choices"]
            assert np.all((applied == codes) | (applied == NOTHING))
            assert info["clipped"] or np.array_equal(applied, codes)
    assert masked_by_budget > 0  # the budget (or the capacity) did mask some choices


def test_vector_ranked_choices_match_the_single_wrapped_envs() -> None:
    seeds = [3, 4]
    venv = make_ranked_vector(2, env_id="trackenv/TampingLine-v1", **SMALL)
    singles = [make_ranked("trackenv/TampingLine-v1", **SMALL) for _ in seeds]
    assert venv.single_action_space == singles[0].action_space
    venv.reset(seed=seeds)
    for e, s in zip(singles, seeds):
        e.reset(seed=s)
    rng = np.random.default_rng(1)
    for _ in range(6):
        masks = venv.action_masks()
        for i, e in enumerate(singles):
            np.testing.assert_array_equal(masks[i], e.get_wrapper_attr("action_masks")())
        counts = rng.integers(0, 5, (2, len(INTERVENTIONS)))
        _, rewards, _, _, infos = venv.step(counts)
        for i, e in enumerate(singles):
            _, reward, *_, info = e.step(counts[i])
            assert rewards[i] == reward
            np.testing.assert_array_equal(infos["section_choices"][i], info["section_choices"])


def test_ranked_choices_follow_the_enabled_choices_and_refuse_other_envs() -> None:
    env = RankedActions(gym.make("trackenv/TampingLineSmall-v0", **SMALL, choices=("tamp", "inspect"),
                                 action_type="choices"))
    assert env.heads == ("tamp", "inspect") and env.action_space == spaces.MultiDiscrete([5, 5])
    env.reset(seed=0)
    may_tamp = env.unwrapped.action_masks().reshape(4, len(CHOICES))[:, TAMP]
    assert may_tamp.any() and not may_tamp.all()  # sections tamped just before the start are masked
    # every section marked by both heads: tamping comes first where it is allowed, else the inspection
    np.testing.assert_array_equal(env.action(np.array([4, 4])), np.where(may_tamp, TAMP, INSPECT))
    with pytest.raises(ValueError, match="2 integer"):
        env.step(np.array([1]))
    with pytest.raises(TypeError, match="MultiBinary.*choices"):
        RankedActions(gym.make("trackenv/TampingDiscrete-v1"))


def test_multidiscrete_actions_pass_the_choices_through() -> None:
    env = MultiDiscreteActions(gym.make("trackenv/TampingLine-v1", **SMALL))
    assert env.action_space == env.env.action_space
    env.reset(seed=0)
    action = np.where(env.action_masks().reshape(4, len(CHOICES))[:, TAMP], TAMP, INSPECT)
    *_, info = env.step(action)
    np.testing.assert_array_equal(info["section_choices"], action)
    assert env.action_masks().shape == (4 * len(CHOICES),)


def test_maskable_ppo_learns_on_ranked_choices() -> None:
    """sb3-contrib's MaskablePPO reads the ranked masks (head after head) and trains a few steps on them."""
    pytest.importorskip("sb3_contrib")
    from sb3_contrib import MaskablePPO
    from sb3_contrib.common.maskable.utils import get_action_masks
    from stable_baselines3.common.logger import Logger
    from stable_baselines3.common.vec_env import DummyVecEnv

    venv = DummyVecEnv([lambda: make_ranked("trackenv/TampingLineWet-v0", flat=True, **SMALL)])
    venv.reset()
    assert get_action_masks(venv).shape == (1, len(INTERVENTIONS) * 5)
    model = MaskablePPO("MlpPolicy", venv, n_steps=8, batch_size=8, n_epochs=1, seed=0, device="cpu")
    model.set_logger(Logger(None, []))  # SB3's default logger makes a folder in the system's temp dir per learn()
    model.learn(16)
    obs = venv.reset()
    action, _ = model.predict(obs, action_masks=get_action_masks(venv), deterministic=True)
    assert get_action_masks(venv)[0].reshape(len(INTERVENTIONS), 5)[np.arange(len(INTERVENTIONS)), action[0]].all()


def test_ranked_choices_over_gymnasiums_sync_vector_env() -> None:
    """Over Gymnasium's SyncVectorEnv (an env without a batched form) the masks come from its envs, and the
    rollout is that of the native vector env."""
    native = make_ranked_vector(2, env_id="trackenv/TampingLine-v1", **SMALL)
    sync = RankedVectorActions(gym.make_vec("trackenv/TampingLine-v1", num_envs=2, vectorization_mode="sync",
                                            **SMALL))
    native.reset(seed=[7, 8])
    sync.reset(seed=[7, 8])
    rng = np.random.default_rng(2)
    for _ in range(4):
        np.testing.assert_array_equal(sync.action_masks(), native.action_masks())
        counts = rng.integers(0, 5, (2, len(INTERVENTIONS)))
        _, sync_rewards, *_, sync_infos = sync.step(counts)
        _, native_rewards, *_, native_infos = native.step(counts)
        np.testing.assert_array_equal(sync_rewards, native_rewards)
        np.testing.assert_array_equal(sync_infos["section_choices"], native_infos["section_choices"])
