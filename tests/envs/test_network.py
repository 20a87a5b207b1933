"""TampingNetwork: the API checkers, the vector env against the single env, seeds, the shared machine's rules
(moving costs a step and the move cost, then works; ties; capacity over the network), the one-line network
against the plain line, the state API and bad configs."""

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import trackenv  # noqa: F401  (registers the ids)
from trackenv.envs.line import TampingLine
from trackenv.envs.network import NetworkConfig, line_seeds
from trackenv.envs.network_env import TampingNetwork, TampingNetworkVectorEnv

SMALL = {"line_config": "small", "n_lines": 2, "horizon_years": 0.75}  # 2 lines of 6 sections, 3 steps
S = 6


def _network(**kw):
    return TampingNetwork(**{**SMALL, **kw})


def _ask(line_sections: dict[int, list[int]], n_lines: int = 2) -> np.ndarray:
    a = np.zeros(n_lines * S, dtype=np.int8)
    for line, sections in line_sections.items():
        a[[line * S + j for j in sections]] = 1
    return a


def _unmasked(env) -> np.ndarray:
    return env.action_masks().reshape(-1, 2)[:, 1]


def _pick(env, line: int, k: int) -> list[int]:
    """The first ``k`` unmasked sections of ``line`` (a section tamped just before the start is masked)."""
    free = np.flatnonzero(_unmasked(env).reshape(env.config.n_lines, S)[line])
    assert free.size >= k
    return free[:k].tolist()


def test_checkers():
    """Gymnasium's and SB3's checkers, with no warning of either (bar deprecation notices from outside trackenv)."""
    from stable_baselines3.common.env_checker import check_env as sb3_check

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(gym.make("trackenv/TampingNetwork-v0", **SMALL).unwrapped, skip_render_check=True)
        sb3_check(_network(), warn=True)
    bad = [f"{w.category.__name__}: {w.message}" for w in caught
           if not (issubclass(w.category, (DeprecationWarning, PendingDeprecationWarning, FutureWarning))
                   and "trackenv" not in str(w.filename))]
    assert not bad, bad


def test_spaces_and_the_stacked_observation():
    env = _network(n_lines=3)
    obs, info = env.reset(seed=2)
    assert env.action_space == gym.spaces.MultiBinary(3 * S)
    assert obs["section_sd"].shape == (3 * S,) and obs["budget_left"].shape == (3,) and obs["time"].shape == (1,)
    assert np.array_equal(obs["machine_line"], [1, 0, 0])
    assert env.action_masks().shape == (2 * 3 * S,)
    assert info["cost"] == 0.0 and not info["moved"] and info["tamped_sections"].shape == (3 * S,)
    # each line draws its own episode: the lines differ
    sd = obs["section_sd"].reshape(3, S)
    assert not np.array_equal(sd[0], sd[1]) and not np.array_equal(sd[1], sd[2])


def test_a_request_on_another_line_moves_the_machine_then_works():
    env = _network(move_cost=7.0)
    env.reset(seed=4)
    there = _pick(env, 1, 2)
    state = env.get_state()
    _, idle, *_ = env.step(np.zeros(2 * S, dtype=np.int8))
    env.set_state(state)
    obs, moving, _, _, info = env.step(_ask({1: there}))
    assert info["moved"] and info["machine_line"] == 1 and np.array_equal(obs["machine_line"], [0, 1])
    assert not info["tamped_sections"].any() and info["costs"]["move"] == 7.0
    assert list(info["dropped_requests"]) == [0, 2] and list(info["requested_sections"]) == [0, 2]
    assert moving == pytest.approx(idle - 7.0, rel=1e-12)  # the lines' costs are an idle step's, plus the move
    obs, _, _, _, info = env.step(_ask({1: there}))
    assert not info["moved"] and info["costs"]["move"] == 0.0
    assert np.array_equal(np.flatnonzero(info["tamped_sections"]), [S + j for j in there])
    assert list(info["dropped_requests"]) == [0, 0]


def test_ties_keep_the_machine_and_other_lines_go_to_the_first():
    env = _network(n_lines=3)
    env.reset(seed=5)
    mine = _pick(env, 0, 1)
    _, _, _, _, info = env.step(_ask({0: mine, 1: _pick(env, 1, 1)}, 3))  # 1 each: the machine's line wins
    assert not info["moved"] and np.array_equal(np.flatnonzero(info["tamped_sections"]), mine)
    assert list(info["dropped_requests"]) == [0, 1, 0]
    _, _, _, _, info = env.step(_ask({1: _pick(env, 1, 2), 2: _pick(env, 2, 2)}, 3))  # 2 each: the lower index
    assert info["moved"] and info["machine_line"] == 1


def test_capacity_is_over_the_network():
    env = _network(capacity=2)
    obs, _ = env.reset(seed=6)
    assert env.config.line_config.capacity == 2
    mine = _pick(env, 0, 4)
    _, _, _, _, info = env.step(_ask({0: mine, 1: _pick(env, 1, 2)}))
    tamped = info["tamped_sections"]
    assert tamped.sum() == 2 and not tamped[S:].any() and info["clipped"]
    sd = obs["section_sd"][mine]
    worst = np.asarray(mine)[np.argsort(-sd, kind="stable")[:2]]  # the line's rule: worst measured SD kept
    assert set(np.flatnonzero(tamped)) == set(worst)
    assert list(info["dropped_requests"]) == [2, 2]


def test_masked_sections_are_not_counted_and_not_worked():
    env = _network()
    env.reset(seed=7)
    mine = _pick(env, 0, 3)
    env.step(_ask({0: mine}))  # tamped: masked in the next step (min_steps_between_tampings = 1)
    assert not _unmasked(env)[mine].any()
    _, _, _, _, info = env.step(_ask({0: mine, 1: _pick(env, 1, 1)}))  # three masked requests lose to one
    assert info["moved"] and list(info["requested_sections"]) == [0, 1]


def test_reward_is_the_sum_of_the_lines_and_the_move():
    """... and exactly minus info["cost"], as on a line (it differed in the last digit: a probe's exact check)."""
    env = _network()
    env.reset(seed=8)
    for action in (_ask({0: [0]}), _ask({1: [1, 2]}), _ask({1: [1, 2]})):
        _, reward, _, _, info = env.step(action)
        assert reward == -info["cost"]
        assert info["cost"] == pytest.approx(info["line_costs"].sum() + info["costs"]["move"], rel=1e-12)
        assert info["cost"] == pytest.approx(sum(info["costs"].values()), rel=1e-12)
        for part, per_line in info["line_cost_parts"].items():
            assert info["costs"][part] == pytest.approx(per_line.sum(), rel=1e-12)


def test_same_seed_same_rollout_and_seeds_differ():
    actions = [_ask({0: [0, 3]}), _ask({1: [2]}), _ask({1: [2, 4]})]

    def rollout(seed):
        env = _network()
        out = [env.reset(seed=seed)[0]["section_sd"]]
        out += [env.step(a)[1] for a in actions]
        return out

    a, b, c = rollout(11), rollout(11), rollout(12)
    assert np.array_equal(a[0], b[0]) and a[1:] == b[1:]
    assert not np.array_equal(a[0], c[0])


def test_one_line_network_is_the_plain_line():
    seed = 3
    line_seed = line_seeds(np.random.default_rng(seed), 1)[0]
    net = TampingNetwork(line_config="small", n_lines=1, horizon_years=0.75)
    line = TampingLine(scenario="small", horizon_years=0.75)
    nobs, _ = net.reset(seed=seed)
    lobs, _ = line.reset(seed=line_seed)
    assert all(np.array_equal(nobs[k], lobs[k]) for k in lobs)
    for action in (np.array([1, 0, 1, 0, 0, 1]), np.zeros(6, int), np.array([0, 1, 0, 1, 1, 0])):
        nobs, nr, _, ntr, ninfo = net.step(action)
        lobs, lr, _, ltr, linfo = line.step(action)
        assert nr == lr and ntr == ltr  # bit for bit
        assert all(np.array_equal(nobs[k], lobs[k]) for k in lobs)
        assert np.array_equal(ninfo["tamped_sections"], linfo["tamped_sections"])


def test_vector_env_equals_single_envs_across_an_episode_end():
    vec = TampingNetworkVectorEnv(2, **SMALL)
    vobs, _ = vec.reset(seed=20)
    singles = [_network() for _ in range(2)]
    for i, env in enumerate(singles):
        obs, _ = env.reset(seed=20 + i)
        assert all(np.array_equal(vobs[k][i], obs[k]) for k in obs)
    rng = np.random.default_rng(0)
    for step in range(4):  # the horizon is 3 steps: the 3rd ends the episodes (SAME_STEP autoreset)
        actions = (rng.random((2, 2 * S)) < 0.3).astype(np.int8)
        vobs, vr, _, vtr, _ = vec.step(actions)
        for i, env in enumerate(singles):
            obs, r, _, tr, _ = env.step(actions[i])
            assert vr[i] == r and vtr[i] == tr
            if tr:
                obs, _ = env.reset()  # the single env's generator continues, as the vector env's row's does
            assert all(np.array_equal(vobs[k][i], obs[k]) for k in obs), (step, i)


def test_make_vec_entry_point():
    vec = gym.make_vec("trackenv/TampingNetwork-v0", num_envs=2, vectorization_mode="vector_entry_point", **SMALL)
    assert isinstance(vec, TampingNetworkVectorEnv) and vec.single_action_space.n == 2 * S


def test_state_round_trip_and_into_a_vector_row():
    env = _network()
    env.reset(seed=9)
    env.step(_ask({1: [0]}))  # the machine moves: the state holds it
    state = env.get_state()
    after = [env.step(_ask({1: [0, 1]}))[1] for _ in range(2)]
    env.set_state(state)
    assert [env.step(_ask({1: [0, 1]}))[1] for _ in range(2)] == after
    vec = TampingNetworkVectorEnv(2, **SMALL)
    vec.reset(seed=0)
    vec.set_state(1, state)
    _, rewards, *_ = vec.step(np.stack([_ask({0: [0]}), _ask({1: [0, 1]})]))
    assert rewards[1] == after[0]


@pytest.mark.parametrize("bad, message", [
    ({"n_lines": 0}, "n_lines"),
    ({"n_lines": 2.0}, "n_lines"),
    ({"capacity": 7}, "capacity"),
    ({"capacity": 0}, "capacity"),
    ({"move_cost": -1.0}, "move_cost"),
    ({"start_line": 2}, "start_line"),
    ({"line_config": "nowhere"}, "^line_config: unknown scenario"),
    ({"line_config": {"n_sections": 2}}, r"^line_config: capacity must be in \[1, 2\] on a line of 2 sections, "
                                         r"got 6 \(the default where capacity is not given\)"),
    ({"line_config": {"bogus": 1}}, r"^line_config: unknown LineConfig key\(s\) \['bogus'\]"),
    ({"line_config": 3}, "line_config"),
    ({"no_such_field": 1}, "no_such_field"),
    ({"action_type": "discrete"}, r"^action_type: the network takes no action_type \(its action is MultiBinary"),
    ({"scenario": "wet"}, r"^scenario: the network takes no scenario \(its lines are given by line_config"),
])
def test_bad_config_raises_naming_the_field(bad, message):
    with pytest.raises(ValueError, match=message):
        TampingNetwork(**{**SMALL, **bad})


def test_config_round_trip():
    config = NetworkConfig(n_lines=2, line_config="small")
    assert config.capacity == 3 and config.n_sections == 12
    assert NetworkConfig.from_dict({"n_lines": 2, "line_config": config.line_config}) == config
    assert config.replace(line_config="default").capacity == 6
    with pytest.raises(ValueError, match="unknown NetworkConfig key"):
        NetworkConfig.from_dict({"lines": 2})


def test_render_draws_the_machines_line():
    env = _network(render_mode="rgb_array")
    env.reset(seed=1)
    first = env.render()
    env.step(_ask({1: _pick(env, 1, 1)}))  # the machine moves to line 1: the picture is line 1's
    assert first.ndim == 3 and first.dtype == np.uint8 and env.render().shape == first.shape
    assert not np.array_equal(env.render(), first)


def test_the_picture_names_its_line_and_shows_that_lines_cost(monkeypatch):
    """The picture is of the machine's line only: its title says which line, and the step cost is that line's own
    (it showed the whole network's)."""
    env = _network(render_mode="rgb_array")
    env.reset(seed=1)
    *_, info = env.step(_ask({1: _pick(env, 1, 1)}))  # the machine moves to line 1
    *_, info = env.step(_ask({1: _pick(env, 1, 1)}))
    seen: dict = {}
    lines, _ = env.unwrapped.engine.row(0, 1)  # the line engine that draws the machine's line
    monkeypatch.setattr(lines, "frame", lambda row, part: seen.update(part) or np.zeros((2, 2, 3), np.uint8))
    env.render()
    n_lines = env.unwrapped.config.n_lines
    assert seen["frame_label"].startswith(f"line 1 (the machine's; lines 0-{n_lines - 1})")
    assert seen["cost"] == info["line_costs"][1] != info["cost"]


# ---------------------------------------------------------------- lines of their own (a list of line configs)
#: three lines of their own: 6 sections, 4 sections of 150 m at 80 km/h, 6 sections with twice the tonnage
MIXED = {"line_config": ["small", {"n_sections": 4, "section_length_m": 150.0, "speed_kmh": 80.0, "capacity": 2},
                         {"n_sections": 6, "capacity": 3, "annual_mgt": 30.0}],
         "horizon_years": 0.75}


def _mixed(**kw):
    return TampingNetwork(**{**MIXED, **kw})


def test_lines_of_their_own_each_run_as_their_plain_line():
    """Without requests, line ``l`` of a network of mixed lines is bit for bit the plain line of its config and
    seed: its slice of every per-section key, its per-line keys and its cost."""
    seed = 11
    env = _mixed()
    config = env.config
    assert config.mixed and config.line_sections == (6, 4, 6) and config.line_offsets == (0, 6, 10, 16)
    assert env.action_space == gym.spaces.MultiBinary(16) and config.capacity is None
    plain = [TampingLine(line) for line in config.line_configs]
    nobs, _ = env.reset(seed=seed)
    lobs = [line.reset(seed=s)[0] for line, s in zip(plain, line_seeds(np.random.default_rng(seed), 3), strict=True)]
    for _ in range(3):
        for line, (first, end) in enumerate(zip(config.line_offsets, config.line_offsets[1:])):
            for key, value in lobs[line].items():
                mine = nobs[key][line] if value.shape == (1,) and key != "time" else (
                    nobs[key] if key == "time" else nobs[key][first:end])
                assert np.array_equal(np.atleast_1d(mine), value), (line, key)
        nobs, _, _, _, info = env.step(np.zeros(16, dtype=np.int8))
        steps = [line.step(np.zeros(line.config.n_sections, dtype=np.int8)) for line in plain]
        lobs = [s[0] for s in steps]
        assert list(info["line_costs"]) == [s[4]["cost"] for s in steps]


def test_requests_on_a_line_of_its_own_tamp_its_sections_within_its_capacity():
    env = _mixed()
    env.reset(seed=12)
    free = np.flatnonzero(env.action_masks().reshape(-1, 2)[:, 1][6:10])
    ask = np.zeros(16, dtype=np.int8)
    ask[6 + free] = 1
    _, _, _, _, info = env.step(ask)  # the machine moves to line 1
    assert info["moved"] and info["machine_line"] == 1
    _, _, _, _, info = env.step(ask)
    tamped = np.flatnonzero(info["tamped_sections"])
    assert set(tamped) <= set(6 + free) and len(tamped) == min(2, free.size)  # line 1's own capacity, 2
    assert info["clipped"] == (free.size > 2)


def test_a_network_capacity_is_cut_to_each_lines_sections():
    config = NetworkConfig.coerce(None, **MIXED, capacity=5)
    assert [line.capacity for line in config.line_configs] == [5, 4, 5]
    with pytest.raises(ValueError, match=r"capacity must be an integer in \[1, 6\]"):
        NetworkConfig.coerce(None, **MIXED, capacity=7)


def test_a_list_of_equal_configs_is_the_one_config():
    listed = NetworkConfig(line_config=["small", "small"])
    assert not listed.mixed and listed == NetworkConfig(n_lines=2, line_config="small")


@pytest.mark.parametrize("bad, message", [
    ({"n_lines": 2}, r"n_lines=2 but line_config lists 3 line configs"),
    ({"line_config": []}, "line_config: an empty list"),
    ({"line_config": ["small", "nowhere"]}, r"^line_config\[1\]: unknown scenario"),
    ({"line_config": ["small", {"steps_per_year": 2}]}, r"line_config\[1\]: steps_per_year=2 differs"),
    ({"line_config": ["small", {"horizon_years": 2.0}]}, r"line_config\[1\]: horizon_steps=8 differs"),
    ({"line_config": ["small", {"contact_sensor": True}]}, r"line_config\[1\]: its observation has other keys"),
    ({"line_config": [{"profiles": True}, {"profiles": True, "segment_length_m": 20.0}]},
     r"line_config\[1\]: segment_length_m=20.0 differs"),
])
def test_bad_lists_of_line_configs_raise_naming_the_line(bad, message):
    with pytest.raises(ValueError, match=message):
        NetworkConfig(**{"line_config": MIXED["line_config"], **bad})


def test_mixed_config_round_trip_and_line_overrides():
    config = NetworkConfig.coerce(None, **MIXED)
    assert NetworkConfig.from_dict(config.to_dict()) == config
    assert isinstance(config.to_dict()["line_config"], list)
    assert all(line.horizon_steps == 3 for line in config.line_configs)  # the override reached every line
    with pytest.raises(ValueError, match="line_sections"):
        _ = config.sections_per_line


def test_a_field_a_line_file_sets_given_to_every_line_names_the_line():
    """``n_sections`` given to a network whose second line is a line file is refused naming that line by its index,
    its name and its file (it named neither: which of several files sets it?)."""
    from trackenv.lines import EXAMPLE_NETWORK

    branch = EXAMPLE_NETWORK.parent / "example_branch.yaml"
    config = NetworkConfig(line_config=[{"n_sections": 30, "capacity": 3}, {"line": str(branch)}])
    with pytest.raises(ValueError, match=r"^line_config\[1\] \(Example Branch Line \(synthetic\)\): n_sections "
                                         r"come\(s\) from the line file .*example_branch\.yaml: change the file"):
        NetworkConfig.coerce(config, n_sections=5)
    assert NetworkConfig.coerce(config, horizon_years=0.5).horizon_steps == 2  # a field no file sets reaches both


def test_mixed_vector_env_equals_single_envs_and_the_state_round_trips():
    vec = TampingNetworkVectorEnv(2, **MIXED)
    vobs, _ = vec.reset(seed=30)
    singles = [_mixed() for _ in range(2)]
    for i, env in enumerate(singles):
        env.reset(seed=30 + i)
    rng = np.random.default_rng(1)
    for step in range(4):  # across the end of the 3-step episodes
        actions = (rng.random((2, 16)) < 0.3).astype(np.int8)
        vobs, vr, _, vtr, _ = vec.step(actions)
        for i, env in enumerate(singles):
            obs, r, _, tr, _ = env.step(actions[i])
            assert vr[i] == r and vtr[i] == tr
            if tr:
                obs, _ = env.reset()
            assert all(np.array_equal(vobs[k][i], obs[k]) for k in obs), (step, i)
    env = singles[0]
    state = env.get_state()
    after = [env.step(actions[0])[1] for _ in range(2)]
    env.set_state(state)
    assert [env.step(actions[0])[1] for _ in range(2)] == after


def test_mixed_checkers_and_picture():
    from stable_baselines3.common.env_checker import check_env as sb3_check

    check_env(gym.make("trackenv/TampingNetwork-v0", **MIXED).unwrapped, skip_render_check=True)
    sb3_check(_mixed(), warn=True)
    env = _mixed(render_mode="rgb_array")
    env.reset(seed=1)
    ask = np.zeros(16, dtype=np.int8)
    ask[6:10] = 1
    env.step(ask)
    assert env.render().ndim == 3


def test_per_section_engine_values_are_placed_at_each_lines_offsets():
    """``allowed`` and ``renewing`` of a network of lines of their own: each line's slice is its line engine's row."""
    env = _mixed()
    env.reset(seed=13)
    engine, config = env.unwrapped.engine, env.unwrapped.config
    for values, of_line in ((engine.allowed(), "allowed"), (engine.renewing(), "renewing")):
        assert values.shape == (1, 16)
        for line, (first, end) in enumerate(zip(config.line_offsets, config.line_offsets[1:])):
            batch, row = engine.row(0, line)
            own = np.asarray(getattr(batch, of_line)()).reshape(batch.n_lines, -1)[row]
            assert np.array_equal(values[0, first:end], own), (of_line, line)
