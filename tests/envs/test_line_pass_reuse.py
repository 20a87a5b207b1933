"""Pass reuse (``LineConfig.pass_reuse_tolerance_m``): off (the default) every segment's passes run every step
and nothing is kept; on, a segment whose level stays within the tolerance of its last computed pass's (its mean
change removed) takes that pass's results, its sleeper forces corrected by the static redistribution of the level
change, a worked segment is computed afresh, and the kept results are episode state (restored, forked and batched
exactly); a bad tolerance is refused naming the field."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from same_results import assert_same

import trackenv  # noqa: F401  (registers the envs)
from trackenv.envs.choices import DRAINAGE, NOTHING, RENEW, SPOT_TAMP, TAMP
from trackenv.envs.line import TampingLine, TampingLineVectorEnv
from trackenv.envs.line_config import LineConfig
from trackenv.envs.line_episode import LineBatch

#: plain track, whose segments' shapes change by about 0.1 mm a step: some passes reused, some computed
TOLERANCE_M = 3e-4
BASE = dict(n_sections=4, capacity=4, segment_length_m=18.0, transition_probability=0.0, switch_probability=0.0,
            wet_spot_probability=0.0, horizon_years=2.0, engine="fast")


def started(tolerance_m: float, seed: int = 3) -> LineBatch:
    batch = LineBatch(LineConfig(**BASE, pass_reuse_tolerance_m=tolerance_m), 1)
    batch.start([0], [np.random.default_rng(seed)])
    return batch


def computed_segments(batch: LineBatch, monkeypatch) -> list[np.ndarray]:
    """The segments of each computed pass of ``batch`` from now on (recorded around ``_vehicle_passes``)."""
    calls: list[np.ndarray] = []
    compute = batch._vehicle_passes

    def recorded(segs):
        calls.append(np.array(segs))
        return compute(segs)

    monkeypatch.setattr(batch, "_vehicle_passes", recorded)
    return calls


def rollout(env, actions, seed: int = 5) -> tuple:
    obs, _ = env.reset(seed=seed)
    out = [obs]
    for action in actions:
        obs, reward, *_, info = env.step(action)
        out += [obs, reward, info["costs"]]
    return tuple(out)


def tamping_actions(n: int, sections: int = 4, seed: int = 0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [(rng.random(sections) < 0.3).astype(np.int8) for _ in range(n)]


def test_off_runs_every_pass_every_step_and_keeps_nothing(monkeypatch):
    assert LineConfig().pass_reuse_tolerance_m == 0.0
    env = TampingLine(LineConfig(**BASE))
    env.reset(seed=5)
    calls = computed_segments(env.engine, monkeypatch)
    actions = tamping_actions(3)
    for action in actions:
        env.step(action)
    assert [c.tolist() for c in calls] == [[0, 1, 2, 3]] * 3
    assert np.isnan(env.engine.computed_level).all()  # the cache is never filled
    assert_same(rollout(TampingLine(LineConfig(**BASE)), actions),
                rollout(TampingLine(LineConfig(**BASE, pass_reuse_tolerance_m=0.0)), actions))


def test_a_uniform_shift_of_a_segments_level_moves_none_of_its_forces():
    """What the tolerance's measure leaves out: the approach and exit zones repeat the end levels, so the whole
    modelled track moves and the pass sees the same shape."""
    batch = started(0.0)
    segs = np.arange(batch.config.n_segments)
    before = batch._computed_passes(segs)
    batch.offset[segs] += 2e-3
    after = batch._computed_passes(segs)
    for a, b in zip(before, after, strict=True):
        np.testing.assert_allclose(b, a, rtol=1e-9)


def test_on_a_pass_is_reused_within_the_tolerance_and_a_tamped_segment_is_computed(monkeypatch):
    batch = started(1e-3)  # the largest tolerance: quiet segments are reused at once
    assert not np.isnan(batch.computed_level).any()  # the reset's pass was kept
    kept = batch.computed_force.copy()
    calls = computed_segments(batch, monkeypatch)
    force, contact, _ = batch._passes(np.arange(4))
    assert calls == []  # nothing has moved since the reset's pass: every segment reused
    np.testing.assert_array_equal(force, batch._equivalent(kept.transpose(1, 0, 2), batch.axle_mix))
    np.testing.assert_array_equal(contact, batch.computed_contact)
    level = batch.computed_level.copy()
    want = np.zeros((1, 4), bool)
    want[0, 2] = True
    batch.apply(want)
    assert np.isnan(batch.computed_level[2]).all()
    np.testing.assert_array_equal(batch.computed_level[[0, 1, 3]], level[[0, 1, 3]])
    batch.traffic()
    assert [c.tolist() for c in calls] == [[2]]  # the tamped segment alone


def test_the_kept_passes_are_those_computed_per_vehicle_type():
    """The reset's pass is kept per vehicle type: its equivalent force is that of a pass computed now, exactly."""
    batch = started(1e-3)
    segs = np.arange(4)
    forces, contact, bays = batch._vehicle_passes(segs)
    np.testing.assert_array_equal(batch.computed_force, forces.transpose(1, 0, 2))
    assert_same(batch._passes(segs), batch._computed_passes(segs))


def test_a_reused_pass_is_corrected_by_the_static_redistribution():
    """After a small differential settlement (one sleeper 0.1 mm, its neighbour 0.05 mm), the kept forces
    corrected by S·(level change) are far closer to a fresh pass than the kept forces alone: the sign of the
    influence against that of the level (a settling sleeper sheds load) and its size."""
    batch = started(1e-3)
    segs, n = np.arange(4), batch.config.n_sleepers
    kept = batch._equivalent(batch.computed_force.transpose(1, 0, 2), batch.axle_mix)
    batch.u[:, n // 2] += 1e-4
    batch.u[:, n // 2 + 1] += 5e-5
    assert batch._reusable(segs, 1e-3).all()
    corrected, contact, _ = batch._passes(segs)
    fresh, fresh_contact, _ = batch._computed_passes(segs)
    scale = fresh.max(axis=1)
    before = np.abs(kept - fresh).max(axis=1) / scale
    after = np.abs(corrected - fresh).max(axis=1) / scale
    assert (before > 0.03).all()  # kilonewtons off without the correction
    assert (after < before / 20).all()
    assert (corrected[:, n // 2] < kept[:, n // 2] - 1e3).all()  # the settled sleeper carries kilonewtons less
    np.testing.assert_array_equal(contact, batch.computed_contact)  # the contact force is kept as computed


def test_a_uniform_settlement_leaves_the_corrected_forces_as_kept():
    """The correction of a uniform change is S·1 ≈ 0: the approach and exit zones settle with the end sleepers."""
    batch = started(1e-3)
    segs = np.arange(4)
    kept = batch._equivalent(batch.computed_force.transpose(1, 0, 2), batch.axle_mix)
    batch.u[segs] += 5e-4
    np.testing.assert_allclose(batch._passes(segs)[0], kept, rtol=1e-9)


@pytest.mark.parametrize(("work", "computed"), [(TAMP, [1]), (RENEW, [1]), (SPOT_TAMP, [1]), (DRAINAGE, []),
                                                (NOTHING, [])])
def test_work_on_the_track_computes_the_next_pass(monkeypatch, work, computed):
    """Tamping, renewal and spot tamping change the level: the next pass is computed whatever the tolerance;
    drainage changes the rates only, and keeps the kept pass."""
    batch = started(1e-3)
    calls = computed_segments(batch, monkeypatch)
    codes = np.full(4, NOTHING)
    codes[1] = work
    batch.work_rows(codes, 0)
    assert np.isnan(batch.computed_level[1]).all() == bool(computed)  # cleared, whatever the lift
    batch.traffic()
    assert [c.tolist() for c in calls] == ([computed] if computed else [])


def test_the_reused_level_is_that_of_the_last_computed_pass_not_the_previous_step(monkeypatch):
    """Each step's passes: a segment within the tolerance of its kept level (mean change removed) keeps it and
    its results, the others are computed at their level; a segment reused over several steps is compared with
    the level of its computed pass all along, so its drift builds up until it is computed again."""
    batch = started(TOLERANCE_M)
    passes, reused_runs = batch._passes, np.zeros(4, int)
    history: list[np.ndarray] = []

    def checked(segs):
        level, kept = batch.level[segs].copy(), batch.computed_level[segs].copy()
        change = level - kept
        reuse = np.abs(change - change.mean(axis=1, keepdims=True)).max(axis=1) < TOLERANCE_M
        result = passes(segs)
        np.testing.assert_array_equal(batch.computed_level[segs], np.where(reuse[:, None], kept, level))
        reused_runs[:] = np.where(reuse, reused_runs + 1, 0)
        history.append(reused_runs.copy())
        return result

    monkeypatch.setattr(batch, "_passes", checked)
    for _ in range(6):
        batch.traffic()
    runs = np.array(history)
    assert runs.max() >= 2  # reused on consecutive steps against one kept level
    assert ((runs[:-1] > 0) & (runs[1:] == 0)).any()  # ... until its drift passed the tolerance


def test_a_restored_state_with_reuse_replays_bit_for_bit(monkeypatch):
    env = TampingLine(LineConfig(**BASE, pass_reuse_tolerance_m=TOLERANCE_M))
    env.reset(seed=3)
    for action in tamping_actions(2, seed=1):
        env.step(action)
    state = env.get_state()
    future = tamping_actions(4, seed=2)
    calls = computed_segments(env.engine, monkeypatch)
    first = tuple(env.step(a)[:4] for a in future)
    assert sum(c.size for c in calls) < 4 * 4  # passes were reused
    env.set_state(state)
    assert_same(first, tuple(env.step(a)[:4] for a in future))
    other = TampingLine(LineConfig(**BASE, pass_reuse_tolerance_m=TOLERANCE_M))
    other.reset(seed=99)
    other.set_state(state)
    assert_same(first, tuple(other.step(a)[:4] for a in future))


def test_forked_sections_with_reuse_continue_as_their_source(monkeypatch):
    source = started(TOLERANCE_M, seed=4)
    for _ in range(2):
        source.traffic()
    fork = started(TOLERANCE_M, seed=8)
    fork.copy_rows(np.arange(4), source, np.array([3, 2, 1, 0]))
    calls = computed_segments(fork, monkeypatch)
    for _ in range(3):
        source.traffic_rows(np.ones(4, bool), source.step[0])
        fork.traffic_rows(np.ones(4, bool), source.step[0])
        source.step += 1
    np.testing.assert_array_equal(fork.level, source.level[::-1])
    np.testing.assert_array_equal(fork.contact_force, source.contact_force[::-1])
    np.testing.assert_array_equal(fork.computed_level, source.computed_level[::-1])
    assert sum(c.size for c in calls) < 3 * 4  # passes were reused


def test_a_vector_row_with_reuse_is_the_single_env(monkeypatch):
    """Other lines change which rows a batched pass computes, never a row's numbers."""
    config = LineConfig(**BASE, pass_reuse_tolerance_m=TOLERANCE_M)
    vec, single = TampingLineVectorEnv(2, config), TampingLine(config)
    vec.reset(seed=5)
    single.reset(seed=6)
    calls = computed_segments(single.engine, monkeypatch)
    for action in tamping_actions(4, seed=3):
        obs, reward, *_ = vec.step(np.stack([1 - action, action]))
        s_obs, s_reward, *_ = single.step(action)
        assert reward[1] == s_reward and all(np.array_equal(obs[key][1], s_obs[key]) for key in s_obs)
    assert sum(c.size for c in calls) < 4 * 4  # passes were reused


def test_the_env_takes_the_tolerance():
    env = gym.make("trackenv/TampingLineSmall-v0", engine="fast", pass_reuse_tolerance_m=5e-5)
    assert env.unwrapped.config.pass_reuse_tolerance_m == 5e-5


@pytest.mark.parametrize("value", [-1e-5, 2.5e-3, float("nan"), "0.1 mm"])
def test_a_bad_tolerance_is_refused_naming_the_field(value):
    with pytest.raises(ValueError, match="pass_reuse_tolerance_m"):
        LineConfig(pass_reuse_tolerance_m=value)
