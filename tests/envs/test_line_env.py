"""TampingLine: the API checks, determinism, pickling, reward parts, the vector env against Gymnasium's
SyncVectorEnv in both autoreset modes, rendering, and one cost/limit test per class."""

import pickle

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.vector import AutoresetMode
from same_results import assert_same

import trackenv  # noqa: F401  (registers the ids)
from trackenv.envs.line import TampingLine, TampingLineVectorEnv
from trackenv.envs.line_config import SCENARIOS, LineConfig, scenario
from trackenv.envs.line_episode import COST_KEYS

SHORT = {"horizon_years": 0.75}  # 3 steps


@pytest.mark.parametrize("env_id", ["trackenv/TampingLineSmall-v0", "trackenv/TampingLine-v0",
                                    "trackenv/TampingLineHard-v0", "trackenv/Tamping-v1"])
def test_checkers(env_id):
    from stable_baselines3.common.env_checker import check_env as sb3_check

    env = gym.make(env_id, **SHORT)
    check_env(env.unwrapped, skip_render_check=True)
    sb3_check(TampingLine(scenario=env_id_scenario(env_id), **SHORT), warn=False)


def env_id_scenario(env_id):
    return {"trackenv/TampingLineSmall-v0": "small", "trackenv/TampingLine-v0": "default",
            "trackenv/TampingLineHard-v0": "hard", "trackenv/Tamping-v1": "track60"}[env_id]


def _rollout(env, seed, actions):
    obs, _ = env.reset(seed=seed)
    out = [obs]
    for a in actions:
        obs, r, _, _, info = env.step(a)
        out.append((obs, r, info["section_sd_m"]))
    return out


def _same(a, b):
    for x, y in zip(a, b):
        if isinstance(x, dict):
            assert all(np.array_equal(x[k], y[k]) for k in x)
        else:
            assert all(np.array_equal(x[0][k], y[0][k]) for k in x[0])
            assert x[1] == y[1]
            assert np.allclose(x[2], y[2], rtol=0, atol=1e-12)


def test_same_seed_same_rollout_single_sync_native():
    actions = [np.array([1, 0, 1, 0, 0, 0]), np.zeros(6, int), np.array([0, 1, 0, 0, 0, 1])]
    a = _rollout(TampingLine(scenario="small", **SHORT), 7, actions)
    b = _rollout(TampingLine(scenario="small", **SHORT), 7, actions)
    _same(a, b)
    # 3 lines: 18 segments, more than one chunk of the kernel's widest SIMD width (a single line runs narrower)
    vec = TampingLineVectorEnv(3, scenario="small", **SHORT)
    obs, _ = vec.reset(seed=7)
    assert np.array_equal(obs["section_sd"][0], a[0]["section_sd"])
    sync = gym.vector.SyncVectorEnv([lambda: TampingLine(scenario="small", **SHORT)] * 3)
    sobs, _ = sync.reset(seed=7)
    assert np.array_equal(sobs["section_sd"], obs["section_sd"])
    for i, act in enumerate(actions[:2]):
        batch = np.stack([act] * 3)
        obs, r, _, _, _ = vec.step(batch)
        sobs, sr, _, _, _ = sync.step(batch)
        assert r[0] == a[i + 1][1]  # bit-identical: a line's numbers do not depend on its batch
        assert np.array_equal(r, sr)
        assert np.array_equal(obs["section_sd"], sobs["section_sd"])


def test_pickle_round_trip_mid_episode():
    env = TampingLine(scenario="small", **SHORT)
    env.reset(seed=3)
    env.step(np.array([1, 1, 0, 0, 0, 0]))
    clone = pickle.loads(pickle.dumps(env))
    a = env.step(np.array([0, 0, 1, 0, 0, 0]))
    b = clone.step(np.array([0, 0, 1, 0, 0, 0]))
    assert a[1] == b[1]
    assert np.array_equal(a[0]["section_sd"], b[0]["section_sd"])


def test_reward_is_minus_sum_of_parts_and_vector_autoreset():
    vec = TampingLineVectorEnv(2, scenario="small", horizon_years=0.5)
    vec.reset(seed=0)
    for a in ([np.ones(6, int)] * 2, [np.zeros(6, int)] * 2):
        obs, r, term, trunc, info = vec.step(np.stack(a))
    assert trunc.all() and info["_final_info"].all() and info["_final_obs"].all()
    last = info["final_info"]  # SAME_STEP (default): the ended step's info, as a dict of arrays with masks
    assert np.allclose(r, -sum(last["costs"][k] for k in COST_KEYS), rtol=1e-12, atol=0)
    assert np.array_equal(last["cost"], -r)
    assert obs["time"].max() == 0.0  # reset in the same step
    assert info["year"].tolist() == [0.0, 0.0] and info["cost"].tolist() == [0.0, 0.0]  # the new episodes' first


def test_section_costs_add_up_to_the_lines_cost_with_the_possession():
    """info["section_costs"]: each section's own costs of the step (tamping or renewal, geometry, restrictions);
    with the line's possession they are the step's cost, and a tamped section pays its tamping or its renewal."""
    cfg = scenario("small", horizon_years=1.0)
    vec = TampingLineVectorEnv(2, cfg)
    vec.reset(seed=3)
    vec.batch.count[1] = cfg.tamping_model.max_tampings_before_renewal  # line 0, section 1: its renewal is due
    vec.batch.last_work[[1, 2, 6, 11]] = -8  # last worked on two years before: none of the asked is masked
    steps = []
    for a in ([[0, 1, 1, 0, 0, 0], [0, 0, 0, 0, 0, 0]], [[0, 0, 0, 0, 0, 0], [1, 0, 0, 0, 0, 1]]):
        _, r, _, _, info = vec.step(np.array(a, dtype=np.int8))
        sec, tamped = info["section_costs"], info["tamped_sections"]
        assert sec.shape == (2, 6) and (sec > 0).all()
        np.testing.assert_allclose(sec.sum(axis=1) + info["costs"]["possession"], -r, rtol=1e-12)
        assert sec[~tamped].max() < cfg.section_tamping_cost < sec[tamped].min()
        steps.append(sec)
    assert vec.batch.count[1] == 0  # renewed in the first step, and charged for it; section 2 was tamped
    assert steps[0][0, 1] > cfg.section_renewal_cost > steps[0][0, 2]
    reset_info = vec.reset(seed=3)[1]
    np.testing.assert_array_equal(reset_info["section_costs"], np.zeros((2, 6)))


SEEDS = [7, 8]
H = 4  # steps of the episodes compared with SyncVectorEnv (horizon_years=1.0)
# (steps, lines, sections): a different pattern per line, over capacity (clipped to 3) and masked repeats
# included, into the next episode
ACTIONS = np.zeros((H + 2, 2, 6), dtype=np.int8)
ACTIONS[0, 0] = [1, 1, 1, 1, 0, 0]  # over capacity: clipped
ACTIONS[1, 0] = [1, 0, 0, 0, 0, 0]  # tamped last step: masked
ACTIONS[1, 1] = [0, 1, 0, 0, 1, 0]
ACTIONS[3, 1] = [1, 1, 1, 1, 1, 1]
ACTIONS[4] = [[0, 0, 1, 0, 0, 0], [1, 0, 0, 0, 0, 1]]  # SAME_STEP: new episodes; NEXT_STEP: ignored (reset)
ACTIONS[5, 0] = [0, 0, 0, 0, 0, 1]


@pytest.mark.slow
@pytest.mark.parametrize("mode", [AutoresetMode.SAME_STEP, AutoresetMode.NEXT_STEP])
def test_autoreset_modes_match_sync_vector_env(mode):
    """gym.make_vec reaches the native vector env through the registered vector entry point; over one episode
    and into the next it gives, bit for bit, what SyncVectorEnv over gym.make gives in the same autoreset mode:
    observations, rewards, flags, infos with their masks (final_obs and final_info in SAME_STEP)."""
    kw = {"horizon_years": 1.0}
    native = gym.make_vec("trackenv/TampingLineSmall-v0", num_envs=2, vectorization_mode="vector_entry_point",
                          autoreset_mode=mode, **kw)
    assert isinstance(native.unwrapped, TampingLineVectorEnv)
    assert native.metadata["autoreset_mode"] == mode and native.unwrapped.config == scenario("small", **kw)
    sync = gym.vector.SyncVectorEnv([lambda: gym.make("trackenv/TampingLineSmall-v0", **kw) for _ in SEEDS],
                                    autoreset_mode=mode)
    assert_same(native.reset(seed=SEEDS), sync.reset(seed=SEEDS), "reset")
    ended = []
    for t in range(H + 2):
        got, want = native.step(ACTIONS[t]), sync.step(ACTIONS[t])
        for name, a, b in zip(("obs", "reward", "terminated", "truncated", "info"), got, want):
            assert_same(a, b, f"step {t} {name}")
        ended.append(bool(got[3].all()))
        if t == 0:
            assert got[4]["clipped"].tolist() == [True, False]
        if t == 1:
            assert not got[4]["tamped_sections"][0].any()  # the masked repeat was dropped
    assert ended == [t == H - 1 for t in range(H + 2)]
    years = got[4]["year"].tolist()  # SAME_STEP: two steps into the new episodes; NEXT_STEP: one (a reset between)
    assert years == [0.5 if mode == AutoresetMode.SAME_STEP else 0.25] * 2


def test_vector_env_arguments():
    with pytest.raises(ValueError, match="autoreset_mode"):
        TampingLineVectorEnv(2, scenario="small", autoreset_mode=AutoresetMode.DISABLED)
    with pytest.raises(ValueError, match="render_mode"):
        TampingLineVectorEnv(2, scenario="small", render_mode="human")
    with pytest.raises(ValueError, match="num_envs"):
        TampingLineVectorEnv(0, scenario="small")
    vec = TampingLineVectorEnv(2, scenario="small", autoreset_mode="NextStep", **SHORT)
    assert vec.autoreset_mode == AutoresetMode.NEXT_STEP
    with pytest.raises(RuntimeError, match="reset"):
        vec.step(np.zeros((2, 6), dtype=np.int8))
    vec.reset(seed=0)
    with pytest.raises(ValueError, match=r"^actions must have shape \(2, 6\)"):
        vec.step(np.zeros((3, 6), dtype=np.int8))
    with pytest.raises(ValueError, match="0 or 1"):
        vec.step(np.full((2, 6), 2, dtype=np.int8))


def test_transition_zone_degrades_faster_than_plain_track():
    cfg = {"transition_probability": 0.5, "switch_probability": 0.0, "wet_spot_probability": 0.0,
           "horizon_years": 1.0}
    growth = {0: [], 1: []}
    vec = TampingLineVectorEnv(3, scenario="small", **cfg)
    obs0, info0 = vec.reset(seed=11)
    reg = obs0["register"].astype(int)
    for _ in range(4):
        _, _, _, _, info = vec.step(np.zeros((3, 6), int))
    sd1 = info["final_info"]["section_sd_m"]
    g = sd1 - info0["section_sd_m"]
    for k in (0, 1):
        growth[k] = g[reg == k]
    assert len(growth[1]) and len(growth[0])
    assert np.median(growth[1]) > 2 * np.median(growth[0])


def test_hidden_wet_spot_appears_and_is_seen_only_through_measurement():
    env = TampingLine(scenario="small", wet_spot_probability=1.0, transition_probability=0.0,
                      switch_probability=0.0, horizon_years=2.0, measurement_interval=2)
    obs, info = env.reset(seed=5)
    assert not info["wet_spot_active"].any()
    assert np.all(obs["register"] == 0)  # wet spots are in no register
    seen_active, prev_obs = False, obs
    for _ in range(8):
        obs, _, _, _, info = env.step(np.zeros(6, int))
        seen_active |= info["wet_spot_active"].any()
        assert np.all(obs["register"] == 0)
        if obs["measurement_age"][0] > 0:  # no recording run this step: the observation did not change
            assert np.array_equal(obs["section_sd"], prev_obs["section_sd"])
            assert not np.array_equal(info["section_sd_m"] * 1e3, obs["section_sd"])
        prev_obs = obs
    assert seen_active
    assert info["rate_factor"].max() > 1.5 * np.median(info["rate_factor"])


def test_over_capacity_refused_or_clipped():
    env = TampingLine(scenario="small", over_capacity="raise", **SHORT)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="capacity"):
        env.step(np.ones(6, int))
    env = TampingLine(scenario="small", **SHORT)
    obs, _ = env.reset(seed=0)
    _, _, _, _, info = env.step(np.ones(6, int))
    assert info["clipped"] and info["tamped_sections"].sum() == env.config.capacity
    worst = np.argsort(-obs["section_sd"])[: env.config.capacity]
    assert set(np.flatnonzero(info["tamped_sections"])) == set(worst)
    # a section tamped last step is masked and dropped
    mask = env.action_masks().reshape(6, 2)[:, 1]
    assert not mask[info["tamped_sections"]].any()


def test_config_validation_and_scenarios():
    with pytest.raises(ValueError, match="unknown LineConfig"):
        LineConfig.from_dict({"n_sectoins": 3})
    with pytest.raises(ValueError, match="capacity"):
        LineConfig(n_sections=4, capacity=5)
    with pytest.raises(ValueError, match="scenario"):
        scenario("nope")
    assert set(SCENARIOS) == {"small", "default", "hard", "long", "track60", "choices", "wet", "defects"}
    with pytest.raises(ValueError, match="shape"):
        env = TampingLine(scenario="small", **SHORT)
        env.reset(seed=0)
        env.step(np.ones(5, int))


def test_a_short_line_is_told_that_the_capacity_it_exceeds_is_the_default():
    """A line of fewer sections than the default capacity, given none, is told that 6 is the default and what to
    set (it said "capacity must be in [1, 4], got 6", a 6 the user never wrote); a capacity given is refused as
    before, and one that fits is taken."""
    with pytest.raises(ValueError, match=r"^capacity must be in \[1, 4\] on a line of 4 sections, got 6 \(the "
                                         r"default where capacity is not given\): set capacity$"):
        LineConfig(n_sections=4)
    with pytest.raises(ValueError, match=r"^capacity must be an integer in \[1, 4\], got 5"):
        LineConfig(n_sections=4, capacity=5)
    assert LineConfig(n_sections=4, capacity=4).capacity == 4


@pytest.mark.parametrize(("field", "value", "message"), [
    ("n_sections", 2.0, r"n_sections must be an integer in \[1, 256\]"),
    ("annual_mgt", "15", r"annual_mgt must be a real number"),
    ("initial_scale", "wide", r"initial_scale must be two numbers \(lower, upper\) with 0 <= lower <= upper <= 10"),
    ("initial_scale", (1.2, 0.4), r"initial_scale must be two numbers"),
    ("initial_scale", (0.4,), r"initial_scale must be two numbers"),
    ("over_capacity", "drop", r"over_capacity must be one of \('clip', 'raise'\)"),
    ("profiles", 1, r"profiles must be True or False"),
    ("law", "linear", r"law must be one of"),
])
def test_line_config_refuses_bad_values_by_name(field, value, message):
    """LineConfig checks its fields with the one mechanism of trackenv.physics._checks: one line naming the field
    and what is allowed."""
    with pytest.raises(ValueError, match=message):
        LineConfig(**{field: value})


def test_line_config_stores_fields_in_their_canonical_types():
    c = LineConfig(n_sections=np.int64(6), capacity=3, annual_mgt=15, initial_scale=[0.5, 1],
                   speed_kmh=np.float32(80.0))
    assert type(c.n_sections) is int and type(c.annual_mgt) is float and c.initial_scale == (0.5, 1.0)
    assert type(c.speed_kmh) is float and c.speed_kmh == 80.0


def test_episode_end_and_reset_arguments_are_enforced():
    env = TampingLine(scenario="small", horizon_years=0.25)  # one step
    env.reset(seed=3)
    _, _, _, truncated, _ = env.step(np.zeros(6, dtype=np.int8))
    assert truncated
    with pytest.raises(RuntimeError, match="horizon"):
        env.step(np.zeros(6, dtype=np.int8))
    with pytest.raises(ValueError, match="unknown reset option"):
        env.reset(seed=3, options={"level": 1})
    with pytest.raises(ValueError, match="seed"):
        env.reset(seed=-1)
    env.reset(seed=3)  # a valid reset starts a new episode
    env.step(np.zeros(6, dtype=np.int8))


@pytest.mark.slow
def test_the_50_km_line_runs_a_step():
    """trackenv/TampingLineLong-v0: 250 sections of 200 m, capacity 25, one step on one machine (the scale the
    planning of a real line needs; experiments/scale.py times it)."""
    env = gym.make("trackenv/TampingLineLong-v0", horizon_years=0.5)
    obs, _ = env.reset(seed=0)
    assert obs["section_sd"].shape == (250,) and env.unwrapped.config.capacity == 25
    action = np.zeros(250, np.int8)
    action[:40] = 1  # over capacity: the 25 worst measured of the allowed ones are kept
    obs, reward, _, _, info = env.step(action)
    assert info["tamped_sections"].sum() <= 25 and info["clipped"]
    assert -reward == pytest.approx(info["cost"]) and np.isfinite(obs["section_sd"]).all()


@pytest.mark.parametrize("env_id", ["trackenv/TampingLineSmall-v0", "trackenv/TampingLine-v1", "trackenv/Tamping-v1"])
def test_every_info_key_and_cost_part_is_documented(env_id):
    """The environments page lists every key of a step's info and every part of its costs (a key added to the
    env and not to the page fails here)."""
    from pathlib import Path

    page = (Path(__file__).resolve().parents[2] / "docs" / "environments" / "index.md").read_text()
    env = gym.make(env_id)
    env.reset(seed=0)
    info = env.step(env.action_space.sample())[-1]
    missing = [key for key in [*info, *info["costs"]] if f"`{key}`" not in page]
    assert not missing, f"not on docs/environments/index.md: {missing}"
