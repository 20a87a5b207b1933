"""TampingEnv (the 60 m track, the preset "track60" of the one engine): the Gymnasium and stable-baselines3 API
contracts, determinism, the reward and episode rules, actions and masks, and the behaviour the physics must show
(tamping helps, neglect hurts, ballast damage, stiffness transitions)."""

from __future__ import annotations

import copy
import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest

import trackenv as te
import trackenv.envs  # noqa: F401  (registers the ids)
from trackenv.envs import TampingEnv, scenario
from trackenv.envs.line_episode import line_observation_bounds
from trackenv.physics.tamping import TampingModel

IDS = ("trackenv/Tamping-v1", "trackenv/TampingDiscrete-v1")
# the Tamping family with the learners' wrapped ids (the TampingLine ids are checked in test_line_env.py, the
# network in test_network.py)
ALL_IDS = tuple(sorted(i for i in gym.registry if i.startswith("trackenv/Tamping")
                       and "TampingLine" not in i and "TampingNetwork" not in i))
COST_KEYS = ("possession", "tamping", "renewal", "spot_tamping", "drainage", "inspection", "survey", "geometry",
             "alert", "speed_restriction", "immediate_action")
# the keywords of small_config: 30 m (51 sleepers) in 3 sections of 10 m, 2 years of quarters
SMALL = {"n_sections": 3, "segment_length_m": 30.0, "sections_per_segment": 3, "capacity": 3, "horizon_years": 2.0}


def one_hot(k: int | None, n: int = 3) -> np.ndarray:
    a = np.zeros(n, dtype=np.int8)
    if k is not None:
        a[k] = 1
    return a


def rollout(env: gym.Env, seed: int, actions) -> tuple:
    obs0, info0 = env.reset(seed=seed)
    steps = [env.step(a) for a in actions]
    return obs0, info0, steps


# Actions that tamp something now and then (MultiBinary, small_config).
ACTIONS_MB = [one_hot(None), one_hot(1), np.array([1, 0, 1], dtype=np.int8), one_hot(None), one_hot(0)]


# ------------------------------------------------------------------------------------------- API checkers
def _significant(caught: list[warnings.WarningMessage]) -> list[str]:
    """The warnings that fail a checker test: everything except deprecation notices raised from outside
    trackenv (e.g. torch or gymnasium internals announcing API changes), which say nothing about the env."""
    bad = []
    for w in caught:
        housekeeping = issubclass(w.category, (DeprecationWarning, PendingDeprecationWarning, FutureWarning))
        if housekeeping and "trackenv" not in str(w.filename):
            continue
        bad.append(f"{w.category.__name__}: {w.message} ({w.filename}:{w.lineno})")
    return bad


@pytest.mark.slow
@pytest.mark.parametrize("env_id", ALL_IDS)
def test_gymnasium_env_checker(small_config, env_id: str) -> None:
    """Gymnasium's checker: spaces, reset/step signatures, obs in space with the right dtype, seeding
    determinism of reset and step. No warning is tolerated (bar unrelated deprecation notices). An id made of
    wrappers is checked with its wrappers (the checker's advice to check ``env.unwrapped`` instead is the one
    warning let through there: the wrappers are what is under test)."""
    from gymnasium.utils.env_checker import check_env

    env = gym.make(env_id, config=small_config)
    wrapped = env_id not in IDS
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env if wrapped else env.unwrapped)
    bad = [w for w in _significant(caught) if not (wrapped and "different from the unwrapped version" in w)]
    assert not bad, bad


@pytest.mark.slow
@pytest.mark.parametrize("env_id", ALL_IDS)
def test_stable_baselines3_env_checker(env_id: str) -> None:
    """stable-baselines3's checker (Dict observation of Boxes, MultiBinary/Discrete actions). No warning is
    tolerated (bar unrelated deprecation notices): e.g. its warnings about unbounded or non-symmetric Box
    bounds, non-float32 observations or missing reset seeding would all fail this test. The one note let
    through is on the per-sleeper profiles of the unwrapped ids: they are observed per segment, shape
    (n_segments, n_sleepers) = (1, 51), which SB3 calls an unconventional shape (its extractors flatten it);
    the learners' ranked ids observe no profiles and get no such note."""
    sb3_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    env = gym.make(env_id, **SMALL)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sb3_checker.check_env(env, warn=True)
    profiles = [f"observation {key} has an unconventional shape" for key in ("level", "contact_force")]
    bad = [w for w in _significant(caught) if not (env_id in IDS and any(p in w for p in profiles))]
    assert not bad, bad


@pytest.mark.parametrize("env_id", IDS)
def test_registration(env_id: str) -> None:
    spec = gym.spec(env_id)
    assert spec.max_episode_steps is None  # the env truncates itself at its configured horizon
    assert spec.vector_entry_point == "trackenv.envs.sharded:tamping_vector_env"  # TampingVectorEnv, or sharded
    env = gym.make(env_id)
    assert type(env.unwrapped) is TampingEnv and env.unwrapped.config == scenario("track60")
    expected = gym.spaces.MultiBinary(6) if env_id.endswith("Tamping-v1") else gym.spaces.Discrete(7)
    assert env.action_space == expected
    obs_space = env.observation_space
    assert set(obs_space.spaces) == {"level", "contact_force", "section_sd", "section_peak", "measurement_age",
                                     "register", "tampings", "tampings_since_renewal", "years_since_tamping", "time",
                                     "budget_left"}
    assert obs_space["level"].shape == obs_space["contact_force"].shape == (1, 101)  # one segment of 101 sleepers
    assert obs_space["section_sd"].shape == (6,)
    assert all(s.dtype == np.float32 and np.all(np.isfinite(s.low)) and np.all(np.isfinite(s.high))
               for s in obs_space.values())


def test_registered_env_runs_a_longer_configured_horizon_to_its_end(small_config) -> None:
    env = gym.make("trackenv/Tamping-v1", config=small_config.replace(horizon_years=12.0, dt=2e-4))
    horizon = env.unwrapped.config.horizon_steps
    assert horizon == 48 > scenario("track60").horizon_steps
    env.reset(seed=0)
    truncated_at = [t for t in range(1, horizon + 1) if env.step(np.zeros(3, dtype=np.int8))[3]]
    assert truncated_at == [horizon]


# ------------------------------------------------------------------------------ determinism
def test_same_seed_same_rollout_different_seed_differs(small_config) -> None:
    cfg = small_config
    a = rollout(TampingEnv(cfg), 7, ACTIONS_MB)
    b = rollout(gym.make("trackenv/Tamping-v1", config=cfg), 7, ACTIONS_MB)  # fresh env, via the registry
    np.testing.assert_equal(a, b)  # observations, infos, rewards, flags: all identical
    c = rollout(TampingEnv(cfg), 8, ACTIONS_MB[:2])
    assert not np.array_equal(a[0]["level"], c[0]["level"])
    assert a[2][1][1] != c[2][1][1]  # rewards differ too


def test_reset_reseeds_the_same_env(small_config) -> None:
    env = TampingEnv(small_config)
    first = rollout(env, 3, ACTIONS_MB[:3])
    rollout(env, 4, ACTIONS_MB[:1])
    again = rollout(env, 3, ACTIONS_MB[:3])
    np.testing.assert_equal(first, again)


def test_env_pickles_mid_episode_and_both_copies_continue_identically(small_config) -> None:
    env = TampingEnv(small_config)
    env.reset(seed=11)
    for a in ACTIONS_MB[:3]:
        env.step(a)
    clone = pickle.loads(pickle.dumps(env))
    rest = [one_hot(None), one_hot(2), one_hot(0)]  # tamps with the residuals drawn at the reset
    np.testing.assert_equal([env.step(a) for a in rest], [clone.step(a) for a in rest])
    # the registered, wrapped env pickles too
    wrapped = gym.make("trackenv/Tamping-v1", config=small_config)
    wrapped.reset(seed=1)
    wrapped.step(one_hot(1))
    wclone = pickle.loads(pickle.dumps(wrapped))
    np.testing.assert_equal(wrapped.step(one_hot(0)), wclone.step(one_hot(0)))


# ---------------------------------------------------------------------- reward, episode end
@pytest.mark.parametrize("env_id, actions", [
    ("trackenv/Tamping-v1", [one_hot(None), one_hot(0), np.array([0, 1, 1]), one_hot(None), one_hot(None),
                             np.array([1, 1, 1]), one_hot(None), one_hot(None)]),
    ("trackenv/TampingDiscrete-v1", [0, 1, 3, 0, 0, 2, 0, 0]),
])
def test_reward_costs_and_truncation_over_a_whole_episode(small_config, env_id: str, actions) -> None:
    cfg = small_config
    env = gym.make(env_id, config=cfg)
    obs, info = env.reset(seed=5)
    assert env.observation_space.contains(obs)
    assert info["costs"] == dict.fromkeys(COST_KEYS, 0.0)
    assert cfg.horizon_steps == len(actions) == 8
    for t, a in enumerate(actions, start=1):
        obs, reward, terminated, truncated, info = env.step(a)
        assert env.observation_space.contains(obs)
        assert tuple(info["costs"]) == COST_KEYS
        parts = info["costs"]
        assert all(np.isfinite(v) and v >= 0 for v in parts.values())
        assert isinstance(reward, float)
        assert reward == pytest.approx(-sum(parts.values()), rel=1e-12, abs=1e-12)
        assert info["cost"] == pytest.approx(sum(parts.values()), rel=1e-12, abs=1e-12)
        n_tamped = int(np.sum(info["tamped_sections"]))
        assert parts["possession"] == (cfg.possession_cost if n_tamped else 0.0)
        assert parts["tamping"] == pytest.approx(cfg.section_tamping_cost * n_tamped)
        assert parts["renewal"] == 0.0  # no section reaches its renewal within 8 steps
        assert parts["geometry"] > 0
        assert terminated is False
        assert truncated is (t == cfg.horizon_steps), t
        assert obs["time"][0] == pytest.approx(t / cfg.horizon_steps)
        assert info["year"] == pytest.approx(t / cfg.steps_per_year)


# ------------------------------------------------------------------------ actions and masks
def test_invalid_multibinary_actions_raise_and_change_nothing(small_config) -> None:
    env = TampingEnv(small_config)
    with pytest.raises(RuntimeError, match="reset"):
        env.step(one_hot(None))
    env.reset(seed=0)
    before = env.engine.level.copy()
    bad = [np.zeros(2), np.zeros(4), np.zeros((3, 1)), 0, np.array([0, 2, 0]), np.array([0.5, 0, 0]),
           np.array([np.nan, 0, 0]), np.array([-1, 0, 0]), np.array([0, np.inf, 0]), ["a", "b", "c"], None]
    for a in bad:
        with pytest.raises(ValueError):
            env.step(a)
    assert env.engine.step_count(0) == 0
    np.testing.assert_array_equal(env.engine.level, before)
    for ok in ([0, 1, 0], np.array([True, False, False]), np.array([0.0, 0.0, 1.0])):
        env.step(ok)
    assert env.engine.step_count(0) == 3


def test_invalid_discrete_actions_raise(small_config) -> None:
    env = TampingEnv(small_config, action_type="discrete")
    env.reset(seed=0)
    for a in (-1, 4, 100, np.nan, 1.5, np.array([1, 2]), np.inf):
        with pytest.raises(ValueError):
            env.step(a)
    assert env.engine.step_count(0) == 0
    for ok in (0, np.int64(3), np.array(2), np.array([1])):
        env.step(ok)
    assert env.engine.step_count(0) == 4


@pytest.mark.parametrize("action_type", ["multibinary", "discrete"])
def test_action_masks_block_a_section_tamped_last_step(small_config, action_type: str) -> None:
    env = TampingEnv(small_config.replace(min_steps_between_tampings=1), action_type=action_type)
    discrete = action_type == "discrete"
    env.reset(seed=2)  # its sections were last tamped 2 steps before the start: none masked
    mask = env.action_masks()
    assert mask.dtype == bool
    assert mask.shape == ((4,) if discrete else (6,))
    assert mask.all()
    tamp_1 = 2 if discrete else one_hot(1)  # section index 1
    _, _, _, _, info = env.step(tamp_1)
    assert info["tamped_sections"].tolist() == [False, True, False]
    assert info["costs"]["tamping"] > 0
    mask = env.action_masks()
    if discrete:
        assert mask.tolist() == [True, True, False, True]
    else:  # [may-not-tamp, may-tamp] per section
        assert mask.tolist() == [True, True, True, False, True, True]
    # the masked request is ignored: nothing tamped, nothing paid, the count unchanged
    obs, _, _, _, info = env.step(tamp_1)
    assert info["tamped_sections"].tolist() == [False, False, False]
    assert info["costs"]["tamping"] == 0.0
    assert obs["tampings"].tolist() == [0.0, 1.0, 0.0]
    # the period has passed: allowed again
    assert env.action_masks().all()
    _, _, _, _, info = env.step(tamp_1)
    assert info["tamped_sections"].tolist() == [False, True, False]


def test_masked_section_is_ignored_but_others_in_the_same_action_are_tamped(small_config) -> None:
    env = TampingEnv(small_config.replace(min_steps_between_tampings=1))
    env.reset(seed=2)
    env.step(one_hot(0))
    _, _, _, _, info = env.step(np.array([1, 0, 1]))
    assert info["tamped_sections"].tolist() == [False, False, True]
    cfg = env.config
    assert info["costs"]["possession"] == cfg.possession_cost
    assert info["costs"]["tamping"] == pytest.approx(cfg.section_tamping_cost)


# -------------------------------------------------------------------------------- behaviour
SEEDS = (0, 1, 2)


@pytest.fixture(scope="module")
def neglect(small_config) -> dict:
    """Episodes of 4 years (16 steps) without any tamping on the tiny track, for three seeds; the state after
    8 steps is kept (deep copies) to branch from."""
    cfg = small_config.replace(horizon_years=4.0)
    out = {"sd": [], "cost": [], "obs": [], "branch": []}
    for seed in SEEDS:
        env = TampingEnv(cfg)
        env.reset(seed=seed)
        sd, cost, obs = [], [], []
        for t in range(cfg.horizon_steps):
            if t == 8:
                out["branch"].append(copy.deepcopy(env))
            o, r, _, _, _ = env.step(one_hot(None))
            sd.append(float(np.mean(o["section_sd"])))
            cost.append(-r)
            obs.append(o)
        out["sd"].append(sd)
        out["cost"].append(cost)
        out["obs"].append(obs)
    return out


@pytest.fixture(scope="module")
def branches(neglect: dict) -> list:
    """From the state after 2 years without tamping (seeds 0 and 1): the step's observation without tamping
    and, for each section, with that section tamped."""
    out = []
    for branch, obs in zip(neglect["branch"][:2], neglect["obs"][:2]):
        untamped = copy.deepcopy(branch).step(one_hot(None))[0]
        np.testing.assert_equal(untamped, obs[8])  # the branch continues the recorded episode
        out.append((untamped, [copy.deepcopy(branch).step(one_hot(s)) for s in range(3)]))
    return out


@pytest.mark.slow
def test_tamping_a_section_is_recorded_in_the_step(small_config, branches: list) -> None:
    cfg = small_config
    for _, tamped in branches:
        for s, (o, r, _, _, info) in enumerate(tamped):
            assert info["tamped_sections"].tolist() == one_hot(s).astype(bool).tolist()
            assert info["costs"]["possession"] == cfg.possession_cost
            assert info["costs"]["tamping"] == pytest.approx(cfg.section_tamping_cost)
            assert o["tampings"].tolist() == one_hot(s).tolist()
            assert o["years_since_tamping"][s] == pytest.approx(0.25)
            assert r == pytest.approx(-sum(info["costs"].values()))


@pytest.mark.slow
def test_tamping_a_section_lowers_its_sd_at_once(branches: list) -> None:
    """The issue's must-hold: the step's section SD with the section tamped is below that without."""
    worse = [(seed, s, float(o["section_sd"][s]), float(untamped["section_sd"][s]))
             for seed, (untamped, tamped) in zip(SEEDS, branches)
             for s, (o, *_) in enumerate(tamped) if not o["section_sd"][s] < untamped["section_sd"][s]]
    assert not worse, f"(seed, section, SD tamped, SD untamped) [mm]: {worse}"


@pytest.mark.slow
def test_without_tamping_the_track_and_the_cost_get_worse(neglect: dict) -> None:
    sd = np.array(neglect["sd"])  # (seeds, steps)
    cost = np.array(neglect["cost"])
    q = sd.shape[1] // 4
    assert sd[:, -q:].mean() > 1.1 * sd[:, :q].mean(), sd
    assert cost[:, -q:].mean() > 1.1 * cost[:, :q].mean(), cost
    # every seed: mean SD keeps growing (the level only settles, nothing is restored)
    assert np.all(sd[:, -1] > sd[:, 0]), sd


def test_a_section_tamped_often_settles_faster_in_the_env(small_config) -> None:
    """Ballast damage in the env: the same step from the same state, the middle section tamped for the 4th time
    since renewal instead of the 1st (no tamping residual: the same level after tamping), settles about
    (1 + damage_per_tamping)^3 times as much over the next period, and its neighbours as before."""
    cfg = small_config.replace(tamping={"residual_fraction": 0.0, "residual_sd_m": 0.0})
    env = TampingEnv(cfg)
    env.reset(seed=0)
    env.step(one_hot(None))
    inside = env.engine.section_of_sleeper == 1
    growth = {}
    for count in (0, 3):
        branch = copy.deepcopy(env)
        branch.engine.count[1] = count  # tampings since renewal before this one
        branch.step(one_hot(1))
        assert branch.engine.count[:3].tolist() == [0, count + 1, 0]
        u = branch.engine.u.copy()
        branch.step(one_hot(None))
        growth[count] = (branch.engine.u - u)[0]
    assert np.all(growth[0] > 0)
    expected = (1 + cfg.tamping_model.damage_per_tamping) ** 3
    ratio = growth[3][inside].mean() / growth[0][inside].mean()
    assert ratio > 1.2 and ratio == pytest.approx(expected, rel=0.15)
    far = np.flatnonzero(~inside)[[0, -1]]  # the end sleepers of the other sections
    np.testing.assert_allclose(growth[3][far], growth[0][far], rtol=0.05)


def test_often_tamped_ballast_settles_faster_afterwards() -> None:
    """Ballast damage: the same section tamped 4 times vs once (on a track with uniform properties, no
    tamping residual, so the level after tamping is the same) settles more over the next period."""
    track = te.Track.realistic(30.0)
    assert np.ptp(track.ballast_stiffness) == 0
    model = TampingModel(residual_fraction=0.0, residual_sd_m=0.0)
    sim = te.TrackDegradation(track, te.Wheelset(mass=1800.0, static_load=100e3),
                              cycles_per_iteration=500_000, speed=100 / 3.6, feedback="support")
    sim.advance()
    mask = np.zeros(track.n_sleepers, dtype=bool)
    mask[15:36] = True
    once, often = copy.deepcopy(sim), copy.deepcopy(sim)
    once.tamp(mask, model)
    for _ in range(4):
        often.tamp(mask, model)
    assert np.all(often.tampings[mask] == 4) and np.all(once.tampings[mask] == 1)
    core = slice(20, 31)  # away from the run-out ramps (repeated tamping ramps the run-out further)
    np.testing.assert_allclose(often.level[core], once.level[core], atol=1e-12)
    l_once, l_often = once.level.copy(), often.level.copy()
    once.advance()
    often.advance()
    d_once = (once.level - l_once)[core].mean()
    d_often = (often.level - l_often)[core].mean()
    assert d_once > 0
    expected = (1 + model.damage_per_tamping) ** 3  # rate factor (1+d)^4 vs (1+d)^1
    assert d_often > 1.2 * d_once
    assert d_often / d_once == pytest.approx(expected, rel=0.15)


def test_stiffer_ballast_next_to_softer_degrades_faster_at_the_joint() -> None:
    track = te.Track.realistic(30.0).scaled(ballast_stiffness=2.0, from_sleeper=25)
    sim = te.TrackDegradation(track, te.Wheelset(mass=1800.0, static_load=100e3), cycles_per_iteration=50_000,
                              speed=80 / 3.6, feedback="support")
    u = sim.run(4).settlement
    diff = np.abs(np.diff(u, axis=1))  # (iterations, bays): bay i lies between sleepers i and i+1
    near = diff[:, 21:28].max(axis=1)  # bays around sleeper 25
    # elsewhere: the rest of the track, leaving out 6 sleepers at each end
    elsewhere = np.concatenate([diff[:, 6:19], diff[:, 31:44]], axis=1).max(axis=1)
    assert np.all(near > 3 * elsewhere), (near, elsewhere)
    assert np.all(np.diff(near) > 0), near  # and it grows
    assert 21 <= diff[-1].argmax() <= 27 or diff[-1, 21:28].max() >= 0.9 * diff[-1].max()


def test_uniform_track_with_support_feedback_settles_uniformly_to_its_ends() -> None:
    sim = te.TrackDegradation(te.Track.realistic(30.0), te.Wheelset(mass=1800.0, static_load=100e3),
                              cycles_per_iteration=50_000, speed=80 / 3.6, feedback="support")
    u = sim.run(2).settlement[-1]
    assert (u.max() - u.min()) / u.mean() < 0.02, u


# ------------------------------------------------------------------------ episode end and reset arguments
def test_step_after_the_horizon_raises_until_reset(small_config) -> None:
    env = TampingEnv(small_config.replace(horizon_years=0.5))  # 2 steps
    env.reset(seed=0)
    assert [env.step(np.zeros(3, dtype=np.int8))[3] for _ in range(2)] == [False, True]
    level = env.engine.level.copy()
    with pytest.raises(RuntimeError, match="horizon.*reset"):
        env.step(np.zeros(3, dtype=np.int8))
    np.testing.assert_array_equal(env.engine.level, level)  # nothing simulated, nothing charged
    env.reset(seed=0)
    env.step(np.zeros(3, dtype=np.int8))


@pytest.mark.parametrize("seed", [1.5, -1, True, "1", np.float64(2.0)])
def test_reset_refuses_seeds_that_are_not_non_negative_integers(small_config, seed) -> None:
    with pytest.raises(ValueError, match="^seed must be an integer"):
        TampingEnv(small_config).reset(seed=seed)


def test_reset_accepts_numpy_integer_seeds_and_refuses_unknown_options(small_config) -> None:
    env = TampingEnv(small_config)
    a, _ = env.reset(seed=np.int64(7))
    b, _ = env.reset(seed=7, options={})
    np.testing.assert_array_equal(a["level"], b["level"])
    with pytest.raises(ValueError, match=r"unknown reset option\(s\) \['initial_level'\]"):
        env.reset(options={"initial_level": 0.0})


# ------------------------------------------------------------------------ observation bounds
def test_observation_space_and_clipping_share_one_table_of_bounds(small_config) -> None:
    cfg = small_config
    space = TampingEnv(cfg).observation_space
    bounds = line_observation_bounds(cfg)
    assert set(bounds) == set(space.spaces)
    for key, (low, high) in bounds.items():
        assert float(space[key].low.min()) == low and float(space[key].high.max()) == high


def test_clipped_observations_are_reported_in_info(small_config) -> None:
    env = TampingEnv(small_config)
    _, info = env.reset(seed=0)
    assert info["observation_clipped"] == 0
    n = small_config.n_sleepers
    engine = env.engine
    engine.measured_level += 0.25  # 250 mm of settlement everywhere: past the 200 mm bound of "level"
    assert np.all(engine.observation(0)["level"] == 200.0)
    assert engine.reset_info(0)["observation_clipped"] == n
    engine.offset += 0.25  # and on the track itself: the next recording run sees it
    obs, _, _, _, info = env.step(np.zeros(3, dtype=np.int8))
    assert np.all(obs["level"] == 200.0)
    assert info["observation_clipped"] >= n


def test_section_classes_follow_the_geometry_and_the_info_owns_its_copy(small_config) -> None:
    """The quality classes are computed once per geometry (with the D1 level) and used by the costs and the
    info: every step's ``section_class`` is the classification of that step's section peaks, through tamping
    and settlement, and writing into one info's array changes neither the episode nor the next info."""
    from trackenv.physics.geometry import classify

    env = TampingEnv(small_config)
    _, info = env.reset(seed=4)
    limits = env.engine.limits
    assert limits == small_config.quality_limits.for_speed(small_config.speed)
    rng = np.random.default_rng(4)
    for _ in range(small_config.horizon_steps):
        expected = classify(info["section_peak_m"], limits)
        np.testing.assert_array_equal(info["section_class"], expected)
        assert info["immediate_action_exceedances"] == int(np.sum(expected == 3))
        info["section_class"][:] = 3  # the caller's copy
        _, _, _, truncated, info = env.step(rng.integers(0, 2, small_config.n_sections))
        if truncated:
            break
    np.testing.assert_array_equal(classify(env.engine.true_quality()[1], limits),
                                  classify(info["section_peak_m"], limits))
