"""Property-based fuzzing of what a user can pass in: configs, actions, seeds and the physics API.

Every input either works (finite results, fields stored in their canonical type) or raises ValueError/TypeError
whose message names the parameter, quickly: each example has a deadline, so an input that makes the code
allocate gigabytes or loop for minutes fails the test instead of hanging it. Example counts are bounded so the
module runs in well under a minute; ``TRACKENV_FUZZ_EXAMPLES=1000`` runs more (and random) examples per test.
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
import warnings
from collections.abc import Callable
from functools import partial
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

import trackenv as te
from trackenv.envs.choices import INTERVENTIONS
from trackenv.envs.line import TampingLine
from trackenv.envs.line_config import LineConfig, scenario
from trackenv.envs.network import NetworkConfig
from trackenv.envs.network_env import TampingNetwork
from trackenv.envs.tamping import TampingEnv
from trackenv.envs.vector import TampingVectorEnv
from trackenv.physics._checks import SERVICE_SPEED_M_PER_S
from trackenv.physics.dynamics import OVERLOAD_FACTOR
from trackenv.physics.settlement import LAWS, make_law
from trackenv.physics.tamping import TampingModel

EXAMPLES = int(os.environ.get("TRACKENV_FUZZ_EXAMPLES", "0"))
FUZZ = settings(
    max_examples=EXAMPLES or 40,
    deadline=10_000,  # ms per example (examples take < 0.2 s): a hang or a huge allocation fails here
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
    derandomize=not EXAMPLES,  # in CI the same examples every run: a failure reproduces
)

# Anything a user might type: numbers of every size and sign, non-finite values, bools, numeric and other
# strings, None, containers.
junk = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(min_value=-1e3, max_value=1e3),
    st.integers(min_value=-(10**12), max_value=10**12),
    st.integers(min_value=-3, max_value=70),
    st.booleans(),
    st.sampled_from(["1.5", "100", "x", "", "nan", "low", "wheelset", "shenton"]),
    st.none(),
    st.lists(st.floats(allow_nan=False, allow_infinity=False), max_size=3),
    st.sampled_from([np.float32(1.5), np.int64(3), np.array(2.0), np.nan, complex(1, 1)]),
)



def mostly(valid: st.SearchStrategy, junk_share: int = 4) -> st.SearchStrategy:
    """``valid`` but one draw in ``junk_share`` from :data:`junk` (``st.one_of`` would flatten junk's many
    branches and draw almost only junk)."""
    return st.integers(0, junk_share - 1).flatmap(lambda k: junk if k == 0 else valid)


CONFIG_FIELDS = [f.name for f in dataclasses.fields(LineConfig)]


def _assert_names(err: Exception, names) -> None:
    msg = str(err)
    event("refused")
    assert any(n in msg for n in names), f"error does not name any of {sorted(names)}: {msg!r}"


def _fast(t0: float, what: str) -> None:
    assert time.perf_counter() - t0 < 1.0, f"{what} took more than a second to refuse"


def _refuses_or_stores_canonical_values(make: Callable[..., Any], kw: dict, kind: type = LineConfig) -> Any:
    """``make(**kw)`` refuses quickly, naming a field it was given (a bound may follow another given field), or
    stores every given numeric field of the config class ``kind`` in the type of its default, finite; the config
    made, or None where refused."""
    typed = {f.name: type(f.default) for f in dataclasses.fields(kind)}
    t0 = time.perf_counter()
    try:
        cfg = make(**kw)
    except (ValueError, TypeError) as e:
        _fast(t0, kind.__name__)
        _assert_names(e, kw)
        return None
    for name in kw:
        value = getattr(cfg, name)
        if typed[name] in (float, int):
            assert type(value) is typed[name], (name, value)
            assert math.isfinite(value)
    return cfg


@FUZZ
@given(st.dictionaries(st.sampled_from(CONFIG_FIELDS), mostly(st.one_of(st.floats(0, 100), st.integers(0, 60)), 2),
                       min_size=1, max_size=3))
def test_track60_config_refuses_or_stores_canonical_values(kw: dict) -> None:
    """The 60 m track's preset with fields changed: a segment of several sections ties its length, its sections'
    length and their number together, and a refusal names one of the fields given."""
    _refuses_or_stores_canonical_values(partial(scenario, "track60"), kw)


@FUZZ
@given(st.dictionaries(st.sampled_from(CONFIG_FIELDS), mostly(st.one_of(st.floats(0, 300), st.integers(0, 300)), 2),
                       min_size=1, max_size=3))
def test_line_config_refuses_or_stores_canonical_values(kw: dict) -> None:
    _refuses_or_stores_canonical_values(LineConfig, kw)


# the 60 m track cut to 30 m (51 sleepers) in 3 sections of 10 m, 2 steps
ENV_CFG = scenario("track60", n_sections=3, segment_length_m=30.0, sections_per_segment=3, capacity=3,
                   horizon_years=0.5)
valid_action = st.lists(st.integers(0, 1), min_size=3, max_size=3)
actions = st.one_of(
    mostly(st.one_of(valid_action, valid_action.map(np.array)), 3),
    st.lists(st.integers(-1, 2), min_size=0, max_size=4),
    st.lists(st.sampled_from([0, 1, 0.5, np.nan, True]), min_size=3, max_size=3),
    st.integers(0, 1).map(lambda b: np.full(3, b, dtype=np.int8)),
)


def _reset(env, seed) -> None:
    """Reset ``env`` with a fuzzed seed; a refused one must name "seed", and then seed 0 resets it."""
    try:
        env.reset(seed=seed)
    except (ValueError, TypeError) as e:
        _assert_names(e, ["seed"])
        env.reset(seed=0)


def _reset_and_step(env, seed, action, name: str):
    """Reset ``env`` with a fuzzed seed (a refused one must name "seed"; then seed 0) and step it with a fuzzed
    action: (observation, reward) when it is accepted, None when it is refused quickly with an error naming
    "action"."""
    _reset(env, seed)
    t0 = time.perf_counter()
    try:
        obs, reward, _, _, _ = env.step(action)
    except (ValueError, TypeError) as e:
        _fast(t0, name)
        _assert_names(e, ["action"])
        return None
    return obs, reward


def _steps_within_its_space(env, seed, action, name: str) -> None:
    """:func:`_reset_and_step`, and an accepted step's observation finite and in the env's observation space."""
    out = _reset_and_step(env, seed, action, name)
    if out is not None:
        _assert_finite(*out)
        assert env.observation_space.contains(out[0])


def _assert_finite(obs: dict, reward) -> None:
    """A step's reward(s) and every observed value are finite numbers."""
    assert np.all(np.isfinite(reward))
    assert all(np.all(np.isfinite(v)) for v in obs.values())


@pytest.fixture(scope="module")
def env() -> TampingEnv:
    return TampingEnv(ENV_CFG)


@FUZZ
@given(seed=mostly(st.one_of(st.integers(0, 2**32), st.none())), action=actions)
def test_env_seed_and_action(env: TampingEnv, seed, action) -> None:
    out = _reset_and_step(env, seed, action, "TampingEnv.step")
    if out is not None:
        _assert_finite(*out)


@pytest.fixture(scope="module")
def venv() -> TampingVectorEnv:
    return TampingVectorEnv(2, ENV_CFG)


@settings(FUZZ, max_examples=EXAMPLES or 25)
@given(
    seed=mostly(st.one_of(st.integers(0, 2**32), st.lists(st.integers(0, 99), min_size=2, max_size=2))),
    action=st.one_of(st.lists(valid_action, min_size=2, max_size=2), st.lists(actions, max_size=3), actions),
)
def test_vector_env_seed_and_actions(venv: TampingVectorEnv, seed, action) -> None:
    out = _reset_and_step(venv, seed, action, "TampingVectorEnv.step")
    if out is not None:
        _assert_finite(*out)


# a section's own length, speed and traffic (``per_section``): any names, any values, any count
per_section_values = st.dictionaries(
    st.sampled_from(["section_length_m", "speed_kmh", "annual_mgt", "freight_share", "axle_load_t"]),
    mostly(st.lists(mostly(st.floats(0, 400), 6), min_size=2, max_size=4), 4), max_size=3)


@FUZZ
@given(per_section=mostly(per_section_values, 4), n_sections=st.integers(2, 4))
def test_per_section_config_refuses_or_stores_canonical_values(per_section, n_sections) -> None:
    """A config refuses per-section values naming per_section (or a field whose bound they set), or stores them
    as floats in range, one per section."""
    kw = {"per_section": per_section, "n_sections": n_sections, "capacity": 1, "segment_length_m": 12.0}
    _refuses_or_stores_canonical_values(LineConfig, kw)
    try:
        cfg = LineConfig(**kw)
    except ValueError:
        return
    for name, values in cfg.per_section:
        assert len(values) == n_sections and all(type(v) is float and math.isfinite(v) for v in values), name
        assert (cfg.section_values(name) == values).all()


# a line's cells from Python: junk, and the words, dates and numbers a file holds
cell = mostly(st.one_of(st.floats(-10, 300), st.integers(-5, 300), st.sampled_from(
    ["yes", "no", "Y", "maybe", "Suspected", "plain", "Plain", "transition", "switch_or_crossing", "S&C", "2025-06-01",
     "01/06/2025", "1,5", " 2 ", "1e3", "inf", "-0", "K1", ""])), 2)


@settings(FUZZ, max_examples=EXAMPLES or 60)
@given(section=st.dictionaries(st.sampled_from(["section", "length_m", "register", "wet", "annual_mgt", "speed_kmh",
                                                "freight_share", "years_since_tamping", "tampings_since_renewal",
                                                "rate_factor", "km", "chainage", "defects"]), cell, max_size=3),
       run=st.dictionaries(st.sampled_from(["section", "date", "sd_mm", "peak_mm"]), cell, max_size=2),
       key=st.sampled_from(["as_of", "name", "traffic", "costs", None]), value=cell)
def test_a_line_dict_with_any_values_loads_or_is_refused_in_one_error(section, run, key, value) -> None:
    """A line given from Python (``LineDescription.from_dict``: a file's keys, a row of its sections, incl. the
    ``km`` and ``defects`` columns and a suspected wet zone, and one of its history) with values of any type, not
    only the text of a file (:func:`test_a_line_file_loads_or_is_refused_in_one_line`), loads, or is refused with
    one LineFileError (a ValueError naming its place), quickly; a line that loads makes a config or is refused
    naming a field, never a crash deep inside the loader or NaN in the line."""
    from trackenv.envs.line_file import LineDescription, LineFileError

    second = {"section": "K2", "length_m": 200, "register": "plain", "years_since_tamping": 1,
              "tampings_since_renewal": 0}
    first = {**second, "section": "K1", **section}
    d: dict[str, Any] = {"name": "fuzz", "as_of": "2026-01-01",
                         "traffic": {"annual_mgt": 15, "speed_kmh": 100, "freight_share": 0.3},
                         "sections": [first, second],
                         "history": [{"section": "K1", "date": "2025-06-01", "sd_mm": 1.2, **run}]}
    if key is not None:
        d[key] = value
    t0 = time.perf_counter()
    try:
        line = LineDescription.from_dict(d, source="fuzz.yaml")
    except LineFileError as e:
        _assert_names(e, ["fuzz.yaml"])
        _fast(t0, "the loader")
        return
    event("loaded")
    assert all(math.isfinite(s.length_m) and math.isfinite(s.years_since_tamping) for s in line.sections)
    assert all(math.isfinite(m.sd_mm) for m in line.history)
    try:
        LineConfig(line=line)
    except ValueError as e:
        _assert_names(e, CONFIG_FIELDS + ["line"])


# three values each, mostly in the ranges of the fields (a share, a speed, a length or a tonnage)
three_values = st.lists(st.one_of(st.floats(0, 1), st.floats(12, 300), st.floats(0, 400)), min_size=3, max_size=3)


@settings(FUZZ, max_examples=EXAMPLES or 12)
@given(per_section=st.dictionaries(st.sampled_from(["section_length_m", "speed_kmh", "annual_mgt", "freight_share"]),
                                   three_values, max_size=3), seed=st.integers(0, 2**16))
def test_a_line_with_per_section_values_refuses_or_steps_finitely(per_section, seed) -> None:
    """A three-section line with fuzzed per-section values is refused naming per_section, or resets and steps
    with finite observations and reward."""
    kw = {"n_sections": 3, "capacity": 3, "segment_length_m": 12.0, "horizon_years": 0.5}
    try:
        env = TampingLine(LineConfig(**kw, per_section=per_section))
    except ValueError as e:
        _assert_names(e, ["per_section", "segment_length_m"])
        return
    event("stepped")
    env.reset(seed=seed)
    _assert_finite(*env.step(np.array([1, 0, 1], dtype=np.int8))[:2])


# the choices: config fields and actions, on the same short track (a segment of three sections) with wet spots,
# short defects and a survey before the start, so that every choice acts
choice_names = st.lists(st.sampled_from([*INTERVENTIONS, "grind", ""]), max_size=7)
CHOICE_FIELDS = ["surveyed_share", "wet_spot_active_share", "local_defects_mean", "local_defect_length_m",
                 "local_defect_rate_factor", "local_defect_near_m", "spot_tamping_length_m", "spot_tamping_work",
                 "spot_possession_share", "drainage_work", "renewal_work", "inspection_sd_noise_mm", "survey_cost",
                 "suspected_wet_probability"]


@FUZZ
@given(choices=mostly(st.one_of(choice_names, choice_names.map(tuple)), 3),
       kw=st.dictionaries(st.sampled_from(CHOICE_FIELDS), mostly(st.one_of(st.floats(0, 40), st.integers(0, 40)), 2),
                          max_size=3))
def test_choice_config_refuses_or_stores_canonical_values(choices, kw: dict) -> None:
    _refuses_or_stores_canonical_values(LineConfig, {"choices": choices, **kw})


CHOICE_CFG = ENV_CFG.replace(choices=INTERVENTIONS, wet_spot_probability=0.6, wet_spot_active_share=0.5,
                             surveyed_share=0.5, local_defects_mean=1.0, annual_budget=40.0)
valid_choices = st.lists(st.integers(0, len(INTERVENTIONS)), min_size=3, max_size=3)
choice_actions = st.one_of(
    mostly(st.one_of(valid_choices, valid_choices.map(np.array)), 3),
    st.lists(st.integers(-1, 8), min_size=0, max_size=4),
    st.lists(st.sampled_from([0, 3, 2.5, np.nan, True, 7]), min_size=3, max_size=3),
)


@pytest.fixture(scope="module")
def choice_env() -> TampingLine:
    return TampingLine(CHOICE_CFG, action_type="choices")


@FUZZ
@given(seed=mostly(st.one_of(st.integers(0, 2**32), st.none())), action=choice_actions)
def test_choice_env_seed_and_action(choice_env: TampingLine, seed, action) -> None:
    _steps_within_its_space(choice_env, seed, action, "TampingLine.step (choices)")


@pytest.fixture(scope="module")
def reuse_env() -> TampingLine:
    """The choice line on the fast engine with pass reuse at its largest tolerance, so that most steps reuse."""
    return TampingLine(CHOICE_CFG.replace(engine="fast", pass_reuse_tolerance_m=2e-3), action_type="choices")


@settings(FUZZ, max_examples=EXAMPLES or 15)
@given(seed=st.integers(0, 2**32), actions=st.lists(mostly(valid_choices, 6), min_size=2, max_size=4))
def test_pass_reuse_env_steps_finitely(reuse_env: TampingLine, seed, actions) -> None:
    """Several steps of fuzzed choices (waits, which reuse the kept passes, between tampings, spot tampings,
    drainage, renewals and inspections, which compute afresh) with pass reuse on: each step refuses a bad action
    naming it, or gives finite observations, reward and kept forces."""
    reuse_env.reset(seed=seed)
    for action in actions:
        t0 = time.perf_counter()
        try:
            obs, reward, terminated, truncated, _ = reuse_env.step(action)
        except (ValueError, TypeError) as e:
            _fast(t0, "TampingLine.step (pass reuse)")
            _assert_names(e, ["action"])
            continue
        _assert_finite(obs, reward)
        assert reuse_env.observation_space.contains(obs)
        if terminated or truncated:
            break
    batch = reuse_env.unwrapped.batch
    kept = ~np.isnan(batch.computed_level).any(axis=-1)
    assert np.isfinite(batch.computed_force[kept]).all()


# the network: its config, and the env's seeds and actions on two lines of the short track (6 sections)
NETWORK_FIELDS = [f.name for f in dataclasses.fields(NetworkConfig)]
line_configs = st.sampled_from(["default", "small", "nowhere", {"n_sections": 2}, {"n_sections": 2, "capacity": 2},
                                {"bogus": 1}, ENV_CFG,
                                # lines of their own: good, empty, one bad, another calendar, other observation keys
                                ["small", {"n_sections": 4, "capacity": 2}], [], ["small", "nowhere"],
                                ["small", {"steps_per_year": 2}], ["small", {"contact_sensor": True}],
                                ("small", "small", {"n_sections": 8, "capacity": 8})])


@FUZZ
@given(st.dictionaries(st.sampled_from(NETWORK_FIELDS),
                       mostly(st.one_of(st.integers(0, 20), st.floats(0, 100), line_configs), 2),
                       min_size=1, max_size=3))
def test_network_config_refuses_or_stores_canonical_values(kw: dict) -> None:
    """A network config refuses naming a field it was given (a line config's own refusal is prefixed with
    line_config; capacity's bound follows the lines' sections; a list's length is the number of lines), or stores
    its counts as int, its move cost as a finite float, one line config per line each with a capacity within its
    sections (the network's cut to them)."""
    cfg = _refuses_or_stores_canonical_values(NetworkConfig, kw, NetworkConfig)
    if cfg is not None:
        assert type(cfg.n_lines) is int and len(cfg.line_configs) == cfg.n_lines == len(cfg.line_sections)
        assert all(1 <= line.capacity <= line.n_sections for line in cfg.line_configs)
        if cfg.capacity is not None:
            assert type(cfg.capacity) is int and 1 <= cfg.capacity <= max(cfg.line_sections)
            assert all(line.capacity == min(cfg.capacity, line.n_sections) for line in cfg.line_configs)
        assert cfg.mixed or cfg.capacity is not None


valid_network_action = st.lists(st.integers(0, 1), min_size=6, max_size=6)
network_actions = st.one_of(
    mostly(st.one_of(valid_network_action, valid_network_action.map(np.array)), 3),
    st.lists(st.integers(-1, 2), max_size=7),
    st.lists(st.sampled_from([0, 1, 0.5, np.nan, True, "1", None]), min_size=6, max_size=6),
)


@pytest.fixture(scope="module")
def network_env() -> TampingNetwork:
    return TampingNetwork(NetworkConfig(n_lines=2, line_config=ENV_CFG))


@settings(FUZZ, max_examples=EXAMPLES or 25)
@given(seed=mostly(st.one_of(st.integers(0, 2**32), st.none())), action=network_actions)
def test_network_env_seed_and_action(network_env: TampingNetwork, seed, action) -> None:
    _steps_within_its_space(network_env, seed, action, "TampingNetwork.step")


@pytest.fixture(scope="module")
def mixed_network_env() -> TampingNetwork:
    """Lines of their own: the short track's 3 sections and a track of 6 such sections, capacity 2 (9 entries in the
    action)."""
    return TampingNetwork(NetworkConfig(line_config=[ENV_CFG, ENV_CFG.replace(n_sections=6, capacity=2)]))


mixed_network_actions = st.one_of(
    mostly(st.lists(st.integers(0, 1), min_size=9, max_size=9), 3),
    st.lists(st.integers(-1, 2), max_size=10),
    st.lists(st.sampled_from([0, 1, 0.5, np.nan, None]), min_size=9, max_size=9),
)


@settings(FUZZ, max_examples=EXAMPLES or 25)
@given(seed=mostly(st.one_of(st.integers(0, 2**32), st.none())), action=mixed_network_actions)
def test_mixed_network_env_seed_and_action(mixed_network_env: TampingNetwork, seed, action) -> None:
    _steps_within_its_space(mixed_network_env, seed, action, "TampingNetwork.step")


@pytest.fixture(scope="module")
def parallel_env():
    pytest.importorskip("pettingzoo")
    from trackenv.envs.multiagent import line_parallel_env

    return line_parallel_env("trackenv/TampingLineSmall-v0", horizon_years=0.5)


AGENTS = [f"section_{i}" for i in range(6)]  # the small line's sections
joint_actions = st.one_of(
    st.fixed_dictionaries({a: st.integers(0, 1) for a in AGENTS}),
    st.dictionaries(st.sampled_from([*AGENTS, "section_99", "x"]), mostly(st.integers(-1, 3), 3)),
    st.fixed_dictionaries({a: st.sampled_from([0, 1, np.int64(1), 1.0, 0.5, np.nan, True, None, "1", np.array(1)])
                           for a in AGENTS}),
    junk,
)


@settings(FUZZ, max_examples=EXAMPLES or 25)
@given(seed=mostly(st.one_of(st.integers(0, 2**32), st.none())), actions=joint_actions)
def test_parallel_env_seed_and_joint_action(parallel_env, seed, actions) -> None:
    """The PettingZoo interface: a joint action is taken (finite rewards, observations in their spaces) or
    refused quickly naming the action or an agent."""
    assert parallel_env.possible_agents == AGENTS
    _reset(parallel_env, seed)
    t0 = time.perf_counter()
    try:
        obs, rewards, _, _, _ = parallel_env.step(actions)
    except (ValueError, TypeError, KeyError) as e:
        _fast(t0, "LineParallelEnv.step")
        _assert_names(e, ["action", "agent"])
        return
    assert all(np.isfinite(r) for r in rewards.values())
    assert all(parallel_env.observation_space(a).contains(o) for a, o in obs.items())


TRACK_KEYS = ["pad_stiffness", "pad_damping", "sleeper_mass", "ballast_stiffness", "ballast_damping"]
SCALAR_KEYS = ["sleeper_spacing", "rail_bending_stiffness", "rail_mass", "elements_per_bay"]
positive = mostly(st.one_of(st.floats(min_value=1e2, max_value=1e9), st.floats(min_value=1e-3, max_value=1e13)), 10)


@FUZZ
@given(
    n=mostly(st.integers(-2, 30)),
    supports=st.fixed_dictionaries({k: positive for k in TRACK_KEYS}),
    scalars=st.dictionaries(
        st.sampled_from(SCALAR_KEYS), mostly(st.one_of(st.floats(1e-3, 1e11), st.integers(0, 80))), max_size=1
    ),
)
def test_track_refuses_or_builds_a_solvable_track(n, supports, scalars) -> None:
    t0 = time.perf_counter()
    try:
        track = te.Track.uniform(n, **supports, **scalars)
    except (ValueError, TypeError) as e:
        _fast(t0, "Track.uniform")
        _assert_names(e, ["n_sleepers", *TRACK_KEYS, *SCALAR_KEYS])
        return
    w = te.static_deflection(track, load=100e3)
    assert math.isfinite(w)


@FUZZ
@given(
    speed=mostly(
        st.one_of(
            st.floats(min_value=1e-12, max_value=0.1),  # far too slow: must be refused at once, not allocated
            st.floats(min_value=10.0, max_value=120.0),  # valid: at most 60 000 time steps below
        )
    ),
    dt=mostly(st.one_of(st.floats(min_value=1e-9, max_value=1e-3), st.floats(min_value=5e-5, max_value=1e-4))),
    mass=mostly(st.floats(min_value=100.0, max_value=5000.0), 8),
    load=mostly(st.floats(min_value=0.0, max_value=200e3), 8),
)
def test_simulate_pass_refuses_or_is_finite(speed, dt, mass, load) -> None:
    track = te.Track.seed()
    t0 = time.perf_counter()
    try:
        wheel = te.Wheelset(mass=mass, static_load=load)
    except (ValueError, TypeError) as e:
        _assert_names(e, ["mass", "static_load"])
        return
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            res = te.simulate_pass(track, wheel, speed=speed, dt=dt)
    except (ValueError, TypeError) as e:
        _fast(t0, "simulate_pass")
        _assert_names(e, ["speed", "dt"])
        return
    assert np.all(np.isfinite(res.contact_force))
    assert np.all(np.isfinite(res.sleeper_force))
    # a speed beyond ballasted lines says so with its km/h; a contact force beyond 3 times the static load as well
    fast = [w for w in caught if "km/h, above the 350 km/h" in str(w.message)]
    assert bool(fast) == (speed > SERVICE_SPEED_M_PER_S)
    overload = res.max_contact_force > OVERLOAD_FACTOR * float(np.max(res.static_wheel_load))
    assert overload == any(issubclass(w.category, te.OverloadWarning) for w in caught)
    assert len(caught) == len(fast) + overload


@FUZZ
@given(
    law=st.sampled_from(sorted(LAWS)),
    params=st.dictionaries(st.sampled_from(["K1", "K2", "C", "s", "a", "alpha", "beta", "gamma", "force_exponent",
                                            "reference_force", "epsilon_1", "porosity", "b"]),
                           mostly(st.floats(0.0, 10.0)), max_size=2),
    force=mostly(st.floats(min_value=0.0, max_value=500e3)),
    cycles=mostly(st.floats(min_value=0.0, max_value=1e8)),
)
def test_settlement_law_refuses_or_is_finite(law, params, force, cycles) -> None:
    t0 = time.perf_counter()
    try:
        m = make_law(law, **params)
    except (ValueError, TypeError) as e:
        _fast(t0, "make_law")
        _assert_names(e, list(params) or [law])
        return
    try:
        u = m.settlement(force, cycles)
    except (ValueError, TypeError) as e:
        _assert_names(e, ["force", "cycles"])
        return
    assert np.all(np.isfinite(u))


@FUZZ
@given(
    st.dictionaries(
        st.sampled_from([f.name for f in dataclasses.fields(TampingModel)]),
        mostly(st.one_of(st.floats(0, 2), st.integers(0, 10), st.booleans(), st.sampled_from(["design", "smoothing"]))),
        max_size=3,
    )
)
def test_tamping_model_refuses_or_stores_canonical_values(kw) -> None:
    t0 = time.perf_counter()
    try:
        m = TampingModel(**kw)
    except (ValueError, TypeError) as e:
        _fast(t0, "TampingModel")
        _assert_names(e, kw)
        return
    for name in kw:
        stored = getattr(m, name)
        assert not isinstance(stored, str) or name == "reference"
        if isinstance(stored, float):
            assert math.isfinite(stored)


DEGRADATION_KEYS = ["cycles_per_iteration", "speed", "approach_sleepers", "adaptive", "max_increment",
                    "max_passes_per_iteration", "initial_level", "rate_factor", "feedback", "on_runaway",
                    "interpolation", "dt", "sleeper_force_measure", "window_bays", "contact", "law"]
degradation_values = mostly(
    st.one_of(
        st.floats(min_value=1.0, max_value=1e5),
        st.integers(2, 20),
        st.booleans(),
        st.sampled_from(["irregularity", "support", "warn", "ignore", "linear", "cubic", "ballast", 1e-4]),
        st.lists(st.floats(min_value=0.0, max_value=1e-2), min_size=51, max_size=51),
    ),
    3,
)


@FUZZ
@given(
    kw=st.dictionaries(st.sampled_from(DEGRADATION_KEYS), degradation_values, max_size=3),
    cycles=mostly(st.floats(min_value=0.0, max_value=1e5)),
)
def test_track_degradation_refuses_or_advances_finitely(kw: dict, cycles) -> None:
    t0 = time.perf_counter()
    try:
        sim = te.TrackDegradation(te.Track.seed(), te.Wheelset.seed(), **kw)
    except (ValueError, TypeError) as e:
        _fast(t0, "TrackDegradation")
        _assert_names(e, [*kw, "option"])
        return
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", te.RunawayWarning)
            rec = sim.advance(cycles)
    except (ValueError, TypeError) as e:
        _assert_names(e, ["cycles", "dt", *kw])
        return
    assert np.all(np.isfinite(rec.settlement)) and math.isfinite(rec.max_contact_force)


# --- line files: cells and values a user might type into the example line's files ---
LINE_FILE_TEXT = ["", " ", "nan", "inf", "-1", "0", "1e308", "1e400", "abc", "yes", "no", "2026-13-45", "2026-02-30",
                  "1,5", "null", "[]", "{}", "true", "S001", "plain", "2020-01-01", "3000-01-01", "12 mm", "007"]


@settings(FUZZ, max_examples=EXAMPLES or 100)  # ~15 ms an example
@given(
    edits=st.lists(st.tuples(st.sampled_from(["line", "sections", "history"]), st.integers(0, 10_000),
                             st.integers(0, 20), st.sampled_from(LINE_FILE_TEXT)), min_size=1, max_size=3),
)
def test_a_line_file_loads_or_is_refused_in_one_line(edits) -> None:
    """Any cell of the example line's CSV files, or any value of its YAML file, replaced by text a user might
    type: the line loads and makes a config, or the loader refuses in one line naming the file (a config refusal
    is a ValueError naming its field), never an error from inside yaml, csv or datetime."""
    import tempfile
    from pathlib import Path

    from trackenv.envs.line_file import LineFileError, load_line
    from trackenv.lines import EXAMPLE

    texts = {"line": EXAMPLE.read_text(), "sections": (EXAMPLE.parent / "example_sections.csv").read_text(),
             "history": (EXAMPLE.parent / "example_history.csv").read_text()}
    for which, row, col, value in edits:
        lines = texts[which].splitlines()
        r = row % len(lines)
        if which == "line":
            if ":" in lines[r] and not lines[r].lstrip().startswith("#"):
                lines[r] = lines[r].split(":", 1)[0] + ": " + value
        else:
            cells = lines[r].split(",")
            cells[col % len(cells)] = f'"{value}"' if "," in value else value
            lines[r] = ",".join(cells)
        texts[which] = "\n".join(lines) + "\n"
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "example.yaml"
        path.write_text(texts["line"])
        (Path(folder) / "example_sections.csv").write_text(texts["sections"])
        (Path(folder) / "example_history.csv").write_text(texts["history"])
        try:
            line = load_line(path)
        except LineFileError as e:
            event("refused")
            assert "\n" not in str(e) and str(e).startswith(str(Path(folder))), str(e)
            return
        try:
            scenario("default", line=line)
        except ValueError as e:
            event("config refused")
            assert str(e), "a refusal says why"
