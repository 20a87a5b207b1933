"""The planning state API (get_state / set_state): a restored state replays bit for bit, in the env it came
from, in a fresh env of the same config and in a row of the native vector env; snapshots are independent of
the env, picklable, and refused by an env of another config."""

from __future__ import annotations

import pickle

import gymnasium as gym
import numpy as np
import pytest
from same_results import assert_same

import trackenv  # noqa: F401  (registers the ids)
from trackenv.envs.state import EnvState

SHORT = {
    "trackenv/TampingLineSmall-v0": {"horizon_years": 2.0},
    "trackenv/Tamping-v1": {"horizon_years": 2.0, "transition_probability": 1.0, "voided_sleepers_mean": 2.0},
}
IDS = sorted(SHORT)


def _actions(env, n: int, seed: int) -> list[np.ndarray]:
    """A fixed, tamping-heavy sequence of actions (so restored tamping residuals and counts matter)."""
    rng = np.random.default_rng(seed)
    shape = env.action_space.shape
    return [(rng.random(shape) < 0.4).astype(np.int8) for _ in range(n)]


def _play(env, actions) -> list:
    return [env.step(a)[:4] + (env.unwrapped.get_state().last_info,) for a in actions]


@pytest.mark.parametrize("env_id", IDS)
def test_restored_state_replays_bit_for_bit(env_id):
    env = gym.make(env_id, **SHORT[env_id])
    env.reset(seed=3)
    for a in _actions(env, 2, 0):
        env.step(a)
    state = env.unwrapped.get_state()
    future = _actions(env, 4, 1)
    first = _play(env, future)
    env.unwrapped.set_state(state)
    assert_same(tuple(first), tuple(_play(env, future)))
    # another env of the same config, on another episode, continues the same way (through a pickle)
    other = gym.make(env_id, **SHORT[env_id])
    other.reset(seed=99)
    other.unwrapped.set_state(pickle.loads(pickle.dumps(state)))
    assert_same(tuple(first), tuple(_play(other, future)))
    # and so does a bare env object that was never reset
    bare = type(env.unwrapped)(config=env.unwrapped.config)
    bare.set_state(state)
    assert_same(tuple(first), tuple(_play(bare, future)))
    # and the snapshot was not changed by either replay: a third restore gives the same again
    env.unwrapped.set_state(state)
    assert_same(tuple(first), tuple(_play(env, future)))


@pytest.mark.parametrize("env_id", IDS)
def test_other_actions_from_a_state_differ_and_the_generator_continues(env_id):
    env = gym.make(env_id, **SHORT[env_id])
    env.reset(seed=5)
    state = env.unwrapped.get_state()
    tamp_all = np.ones(env.action_space.shape, dtype=np.int8)
    r_tamp = env.step(tamp_all)[1]
    env.unwrapped.set_state(state)
    r_wait = env.step(np.zeros_like(tamp_all))[1]
    assert r_tamp != r_wait  # the state is a branching point, not a recording
    # the generator's state travels with the snapshot: the next unseeded episode is the same
    env.unwrapped.set_state(state)
    obs_a, _ = env.reset()
    env.unwrapped.set_state(state)
    obs_b, _ = env.reset()
    assert_same(obs_a, obs_b)


@pytest.mark.parametrize("env_id", IDS)
def test_vector_rows_take_single_env_states(env_id):
    env = gym.make(env_id, **SHORT[env_id])
    env.reset(seed=7)
    env.step(np.ones(env.action_space.shape, dtype=np.int8))
    state = env.unwrapped.get_state()
    future = _actions(env, 3, 2)
    single = [env.step(a)[:4] for a in future]
    vec = gym.make_vec(env_id, num_envs=3, vectorization_mode="vector_entry_point", **SHORT[env_id])
    vec.reset(seed=100)
    vec.unwrapped.set_state(1, state)
    zero = np.zeros(env.action_space.shape, dtype=np.int8)
    for t, a in enumerate(future):
        obs, rew, term, trunc, _ = vec.step(np.stack([zero, a, zero]))
        s_obs, s_rew, s_term, s_trunc = single[t]
        assert_same({k: v[1] for k, v in obs.items()}, s_obs)
        assert rew[1] == s_rew and term[1] == s_term and trunc[1] == s_trunc
    # and back: the row's snapshot continues in a single env exactly as in the row
    row = vec.unwrapped.get_state(1)
    again = gym.make(env_id, **SHORT[env_id])
    again.unwrapped.set_state(row)
    assert_same(again.unwrapped.get_state().last_info, row.last_info)
    vec.close()


def test_state_of_another_config_or_kind_is_refused():
    env = gym.make("trackenv/TampingLineSmall-v0", horizon_years=1.0)
    with pytest.raises(RuntimeError, match="reset"):
        env.unwrapped.get_state()
    env.reset(seed=0)
    state = env.unwrapped.get_state()
    assert isinstance(state, EnvState)
    with pytest.raises(ValueError, match="another config"):
        gym.make("trackenv/TampingLine-v0", horizon_years=1.0).unwrapped.set_state(state)
    with pytest.raises(ValueError, match="EnvState"):
        env.unwrapped.set_state({"step": 0})
    vec = gym.make_vec("trackenv/TampingLineSmall-v0", num_envs=2, vectorization_mode="vector_entry_point",
                       horizon_years=1.0)
    with pytest.raises(RuntimeError, match="reset"):
        vec.unwrapped.get_state(0)
    vec.reset(seed=0)
    with pytest.raises(ValueError, match="index"):
        vec.unwrapped.get_state(2)
    vec.close()


def test_set_state_drops_a_pending_next_step_reset():
    """In NEXT_STEP autoreset, an env whose episode just ended is reset at its next step; restoring a state into
    it first continues the restored episode instead (and its action is no longer ignored)."""
    from gymnasium.vector import AutoresetMode

    kwargs = {"horizon_years": 0.5}  # 2 steps
    single = gym.make("trackenv/TampingLineSmall-v0", **kwargs)
    single.reset(seed=11)
    state = single.unwrapped.get_state()
    tamp = np.ones(6, dtype=np.int8)
    expected = single.step(tamp)[1]
    vec = gym.make_vec("trackenv/TampingLineSmall-v0", num_envs=2, vectorization_mode="vector_entry_point",
                       autoreset_mode=AutoresetMode.NEXT_STEP, **kwargs)
    vec.reset(seed=0)
    zero = np.zeros((2, 6), dtype=np.int8)
    for _ in range(2):
        *_, trunc, _ = vec.step(zero)
    assert trunc.all()  # both ended: the next step would reset them and ignore the actions
    vec.unwrapped.set_state(0, state)
    _, rew, _, trunc, _ = vec.step(np.stack([tamp, np.zeros(6, dtype=np.int8)]))
    assert rew[0] == expected and not trunc[0]  # row 0 stepped the restored episode with its action
    assert rew[1] == 0.0  # row 1 was reset, as NEXT_STEP does
    vec.close()


@pytest.mark.parametrize("vector", [False, True])
def test_ranked_actions_decode_on_a_restored_state(vector):
    """The ranked ids rank the sections on the env's observation as it stands, so a state restored through
    ``.unwrapped`` replays the same tamping (they once ranked on a copy of the last observation returned, so the
    restored episode tamped the sections that ranked worst in the abandoned one)."""
    cfg = {"horizon_years": 3.0}
    if vector:
        env = gym.make_vec("trackenv/TampingRanked-v1", num_envs=2, vectorization_mode="vector_entry_point", **cfg)
        get, put, wait, tamp_one = (lambda: env.unwrapped.get_state(1), lambda s: env.unwrapped.set_state(1, s),
                                    np.zeros(2, int), np.ones(2, int))
        detour = [np.zeros(2, int), np.zeros(2, int), np.array([0, 3])]
    else:
        env = gym.make("trackenv/TampingRanked-v1", **cfg)
        get, put, wait, tamp_one, detour = env.unwrapped.get_state, env.unwrapped.set_state, 0, 1, [0, 0, 3]
    replayed = 0
    for seed in range(6):  # row 1 of the vector env: seeds 1 to 6; the old copy tamped other sections at 1 and 4
        env.reset(seed=seed)
        for _ in range(4):
            env.step(wait)
        state = get()
        first = env.step(tamp_one)
        for a in detour:  # another moment of the episode: its worst sections differ
            env.step(a)
        put(state)
        again = env.step(tamp_one)
        row = (lambda x: x[1]) if vector else (lambda x: x)
        assert row(first[1]) == row(again[1])
        np.testing.assert_array_equal(row(first[4]["tamped_sections"]), row(again[4]["tamped_sections"]))
        replayed += 1
    assert replayed == 6
