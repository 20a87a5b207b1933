"""ShardedVectorEnv: the native vector envs split over worker processes give the one-process results, bit for bit."""

from __future__ import annotations

import os
import signal
import warnings
from functools import partial

import numpy as np
import pytest
from gymnasium.vector import AutoresetMode
from same_results import assert_same

from trackenv.envs.line import TampingLineVectorEnv
from trackenv.envs.sharded import ShardedVectorEnv, merge_infos, shard_sizes
from trackenv.envs.vector import TampingVectorEnv

# the 60 m track cut to 30 m (51 sleepers) in 3 sections of 10 m
SMALL = {"n_sections": 3, "segment_length_m": 30.0, "sections_per_segment": 3, "capacity": 3}
SHORT = {**SMALL, "horizon_years": 1.5}  # 6 steps an episode: both autoreset modes reset within the rollout


def _rollout(env, steps: int, seed: int, n_sections: int) -> list:
    out = [env.reset(seed=seed)]
    rng = np.random.default_rng(seed)
    for _ in range(steps):
        out.append(env.step(rng.integers(0, 2, size=(env.num_envs, n_sections))))
    out.append(env.action_masks())
    return out


@pytest.mark.parametrize("mode", [AutoresetMode.SAME_STEP, AutoresetMode.NEXT_STEP])
def test_sharded_tamping_env_is_the_native_vector_env_bit_for_bit(mode) -> None:
    """5 envs in shards of 3 and 2 against one process of 5: observations, rewards, flags, infos (with their
    masks, final observations and infos across the resets at the horizon) and action masks."""
    make = partial(TampingVectorEnv, autoreset_mode=mode, **SHORT)
    one = make(5)
    want = _rollout(one, 8, 11, one.config.n_sections)
    with ShardedVectorEnv(make, 5, workers=2) as env:
        assert env.sizes == [3, 2] and env.autoreset_mode == mode and env.config == one.config
        assert env.single_observation_space == one.single_observation_space
        assert env.action_space == one.action_space
        got = _rollout(env, 8, 11, one.config.n_sections)
    assert any(np.any(step[3]) for step in want[1:-1])  # episodes did end (truncated at the horizon)
    for i, (a, b) in enumerate(zip(want, got)):
        assert_same(a, b, f"step {i}")


def test_sharded_line_env_is_the_native_vector_env_bit_for_bit() -> None:
    make = partial(TampingLineVectorEnv, config="small")
    one = make(3)
    want = _rollout(one, 2, 4, one.config.n_sections)
    with ShardedVectorEnv(make, 3, workers=2) as env:
        got = _rollout(env, 2, 4, one.config.n_sections)
    for i, (a, b) in enumerate(zip(want, got)):
        assert_same(a, b, f"step {i}")


def test_sharded_env_moves_states_between_its_workers_and_the_native_env() -> None:
    """get_state / set_state by env index reach the worker that holds the env: a snapshot of env 4 (the second
    worker) restored into env 0 (the first) and into a native vector env continues as env 4 does; a bad index is
    refused by name."""
    make = partial(TampingVectorEnv, **SHORT)
    actions = np.ones((5, 3), dtype=np.int8)
    with ShardedVectorEnv(make, 5, workers=2) as env:
        env.reset(seed=3)
        env.step(actions)
        state = env.get_state(4)
        want = env.step(actions)
        env.set_state(0, state)
        got = env.step(actions)
        with pytest.raises(ValueError, match=r"index must be an integer in \[0, 4\]"):
            env.get_state(5)
    native = make(5)
    native.reset(seed=9)
    native.set_state(2, state)
    again = native.step(actions)
    for name, i in (("worker", 0), ("native", 2)):
        back = got if name == "worker" else again
        assert_same({k: v[4] for k, v in want[0].items()}, {k: v[i] for k, v in back[0].items()}, name)
        assert want[1][4] == back[1][i], name


def test_sharded_env_renders_the_first_env_and_raises_worker_errors_as_theirs() -> None:
    make = partial(TampingVectorEnv, render_mode="rgb_array", **SMALL)
    one = make(2)
    one.reset(seed=2)
    with ShardedVectorEnv(make, 2, workers=2) as env:
        env.reset(seed=2)
        np.testing.assert_array_equal(env.render(), one.render())
        with pytest.raises(ValueError, match="seed must be an int or a list of 2 seeds"):  # checked here
            env.reset(seed=[1, 2, 3])


def test_make_vec_with_workers_gives_the_sharded_env() -> None:
    """gym.make_vec(..., vectorization_mode="vector_entry_point", workers=2): the same envs in two processes;
    without workers the native vector env itself (tests/envs/test_vector_env.py)."""
    import gymnasium as gym

    kwargs = {"vectorization_mode": "vector_entry_point", **SMALL}
    one = gym.make_vec("trackenv/Tamping-v1", num_envs=3, **kwargs)
    assert isinstance(one, TampingVectorEnv)
    want = _rollout(one, 2, 5, 3)
    with gym.make_vec("trackenv/Tamping-v1", num_envs=3, workers=2, **kwargs) as env:
        assert isinstance(env, ShardedVectorEnv) and env.sizes == [2, 1]
        got = _rollout(env, 2, 5, 3)
    for i, (a, b) in enumerate(zip(want, got)):
        assert_same(a, b, f"step {i}")
    with pytest.raises(ValueError, match="workers"):
        gym.make_vec("trackenv/TampingLineSmall-v0", num_envs=2, vectorization_mode="vector_entry_point", workers=0)


def test_shard_sizes_and_info_merge() -> None:
    assert shard_sizes(5, 2) == [3, 2] and shard_sizes(32, 3) == [11, 11, 10] and shard_sizes(4, 4) == [1] * 4
    # a key only the second shard reported: blanks (zeros, None in object arrays) and False masks in the first
    a = {"x": np.array([1, 2]), "_x": np.array([True, True])}
    b = {"x": np.array([3]), "_x": np.array([True]), "y": np.array(["s"], dtype=object), "_y": np.array([True]),
         "final_info": {"z": np.array([0.5]), "_z": np.array([True])}}
    m = merge_infos([a, b], [2, 1])
    np.testing.assert_array_equal(m["x"], [1, 2, 3])
    assert m["y"].dtype == object and list(m["y"]) == [None, None, "s"]
    np.testing.assert_array_equal(m["_y"], [False, False, True])
    np.testing.assert_array_equal(m["final_info"]["z"], [0.0, 0.0, 0.5])
    np.testing.assert_array_equal(m["final_info"]["_z"], [False, False, True])


def _warning_shard(n: int) -> TampingVectorEnv:
    warnings.warn("built a shard", UserWarning, stacklevel=1)
    return TampingVectorEnv(n, **SMALL)


def test_sharded_env_errors_reach_the_caller() -> None:
    with pytest.raises(ValueError, match="workers"):
        ShardedVectorEnv(TampingVectorEnv, 2, workers=3)
    with pytest.raises(ValueError, match="make_shard"):
        ShardedVectorEnv(lambda n: object(), 2, workers=1)  # type: ignore[arg-type,return-value]
    with pytest.raises(ValueError, match="make_shard must be picklable"):
        ShardedVectorEnv(lambda n: TampingVectorEnv(n), 2, workers=2)
    for context in ("threads", "fork"):  # fork: unsafe once numba's threads have run in the parent
        with pytest.raises(ValueError, match="context"):
            ShardedVectorEnv(TampingVectorEnv, 2, workers=1, context=context)
    with pytest.warns(UserWarning, match="built a shard"):  # raised in a worker, raised again here
        env = ShardedVectorEnv(_warning_shard, 2, workers=2)
    try:
        env.reset(seed=0)
        with pytest.raises(ValueError, match="actions must have shape"):
            env.step(np.zeros((3, 3), dtype=int))
        with pytest.raises(ValueError, match="(?s)unknown reset option.*raised in worker 0"):  # the worker's own error
            env.reset(seed=0, options={"bad": 1})
        obs, _ = env.reset(seed=0)  # still usable after a worker's error
        assert obs["level"].shape[0] == 2
        os.kill(env._procs[1].pid, signal.SIGKILL)
        env._procs[1].join(timeout=10)
        with pytest.raises(RuntimeError, match="worker 1 .* died"):
            env.step(np.zeros((2, 3), dtype=int))
    finally:
        env.close()
    env.close()  # idempotent
    with pytest.raises(RuntimeError, match="closed"):
        env.reset()


def test_default_threads_share_the_cores_this_process_may_run_on(monkeypatch) -> None:
    import trackenv.envs.sharded as sharded

    monkeypatch.setattr(os, "cpu_count", lambda: 1)  # the machine's count is not what this process may use
    monkeypatch.setattr(sharded, "usable_cores", lambda: 4)
    with ShardedVectorEnv(partial(TampingVectorEnv, **SMALL), 2, workers=2) as env:
        assert env.threads_per_worker == 2
