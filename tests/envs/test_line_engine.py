"""The line's pass engine (``LineConfig.engine``): the default is the classic engine, whose passes are those of
the plain ``simulate_passes`` call the line ran before the option existed, bit for bit; the fast engine's sleeper
forces of a line step are within the steady start's tolerance of an approach of 40 sleepers (closer than the
classic engine's); a bad engine is refused naming the field."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import trackenv  # noqa: F401  (registers the envs)
from trackenv.envs.line import TampingLine, TampingLineVectorEnv
from trackenv.envs.line_config import LineConfig
from trackenv.envs.line_episode import LineBatch
from trackenv.physics.dynamics import simulate_passes

TOLERANCE = 0.002  # relative: the steady start's contract (tests/physics/test_steady_start.py)
REFERENCE_APPROACH = 40  # sleepers of approach from static equilibrium: converged
BASE = dict(n_sections=4, capacity=4, segment_length_m=18.0, transition_probability=0.5, switch_probability=0.0,
            wet_spot_probability=0.0, horizon_years=1.0)


def started(engine: str) -> LineBatch:
    batch = LineBatch(LineConfig(**BASE, engine=engine), 1)
    batch.start([0], [np.random.default_rng(3)])
    return batch


def line_forces(batch: LineBatch, vehicle, approach: int, **options) -> np.ndarray:
    """(segments, n) the sleeper forces of one pass of ``vehicle`` over each segment of ``batch``'s line, its
    model tracks with ``approach`` sleepers of approach (the engine's, or more: copies of the first)."""
    n, ne = batch.config.n_sleepers, batch.n_extra
    level = batch.level[batch.segments(0)]
    profile = np.concatenate([np.repeat(level[:, :1], approach, 1), level, np.repeat(level[:, -1:], ne, 1)], axis=1)
    tracks = [t.extended(approach - ne, 0) for t in batch.model_tracks[batch.segments(0)]]
    results = simulate_passes(tracks, vehicle, float(batch.pass_speed[0]), None, support_settlement=profile,
                              dt=batch.config.dt, **options)
    return np.stack([r.sleeper_force[approach : approach + n] for r in results])


def rollout(env_id: str, **overrides) -> list:
    env = gym.make(env_id, **overrides)
    obs, _ = env.reset(seed=5)
    env.action_space.seed(1)
    out = [obs]
    for _ in range(2):
        obs, reward, *_, info = env.step(env.action_space.sample())
        out += [obs, reward, info["costs"]]
    return out


def assert_same(a, b) -> None:
    if isinstance(a, dict):
        assert a.keys() == b.keys()
        for key in a:
            assert_same(a[key], b[key])
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b)
        for x, y in zip(a, b):
            assert_same(x, y)
    else:
        assert np.array_equal(np.asarray(a), np.asarray(b))


def test_the_default_engine_runs_the_lines_passes_as_before():
    batch = started(LineConfig().engine)
    assert batch.config.engine == "classic" and batch.n_extra == 10
    segs = np.arange(batch.config.n_segments)
    force, *_ = batch._passes(segs)
    before = [line_forces(batch, v, batch.n_extra) for v in batch.vehicles]  # the call the line made before
    assert np.array_equal(force, batch._equivalent(np.stack(before), batch.axle_mix[segs]))


@pytest.mark.parametrize("env_id", ["trackenv/TampingLine-v0", "trackenv/Tamping-v1"])
def test_the_default_env_is_the_classic_engine(env_id):
    default, fast = rollout(env_id), rollout(env_id, engine="fast")
    assert_same(default, rollout(env_id, engine="classic"))
    assert not np.array_equal(default[-2], fast[-2])  # the fast engine's costs move (a little)
    assert fast[-2] == pytest.approx(default[-2], rel=0.01)


def test_the_fast_engines_forces_are_those_of_a_converged_approach():
    fast, classic = started("fast"), started("classic")
    for vehicle in fast.vehicles:
        groups = fast._pass_groups(np.arange(fast.config.n_segments), np.ones(fast.config.n_segments, bool), vehicle)
        assert len(groups) == 1 and groups[0][1]["start"] == "steady"  # no segment falls back to the static start
        reference = line_forces(classic, vehicle, REFERENCE_APPROACH)
        # relative to each segment's largest sleeper force: a sleeper hanging in the rail carries little
        scale = reference.max(axis=1, keepdims=True)
        error = {name: np.max(np.abs(line_forces(b, vehicle, b.n_extra, **options) - reference) / scale)
                 for name, b, options in (("fast", fast, groups[0][1]), ("classic", classic, {}))}
        assert error["fast"] < TOLERANCE
        assert error["fast"] < error["classic"]


def test_a_vector_row_with_the_fast_engine_is_the_single_env():
    """Each segment's options (and steady state) are its own track's: a line's numbers do not depend on the other
    lines of its batch."""
    config = LineConfig(**BASE, engine="fast")
    vec, single = TampingLineVectorEnv(2, config), TampingLine(config)
    vec.reset(seed=5)
    single.reset(seed=6)
    for k in range(2):
        action = np.eye(4, dtype=np.int8)[k]
        obs, reward, *_ = vec.step(np.stack([action, action]))
        s_obs, s_reward, *_ = single.step(action)
        assert reward[1] == s_reward and all(np.array_equal(obs[key][1], s_obs[key]) for key in s_obs)


def test_a_bad_engine_is_refused_naming_the_field():
    with pytest.raises(ValueError, match="engine"):
        LineConfig(engine="quick")
