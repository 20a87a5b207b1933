"""The training settings: frozen dataclasses that check every field, with the algorithm's defaults, the shipped
hyper-parameters as values and ValueError (naming the field and its range) for anything else."""

from __future__ import annotations

import dataclasses
import inspect
import json
import math

import pytest

from trackenv_agents.learning.settings import AlgoSettings, LineSettings, TampingSettings

pytest.importorskip("yaml")


@pytest.mark.parametrize("module, name", [("stable_baselines3", "PPO"), ("sb3_contrib", "MaskablePPO")])
def test_the_algorithms_defaults_are_the_algorithms_own(module, name):
    algo = getattr(pytest.importorskip(module), name)
    params = inspect.signature(algo.__init__).parameters
    for key, value in AlgoSettings().algo_kwargs().items():
        assert params[key].default == value, key


def test_the_shipped_entries_are_valid_settings():
    from trackenv_agents.learning.line import LINE_ENV_ID, LINE_ZOO
    from trackenv_agents.learning.tamping import load_hyperparams

    tamping = TampingSettings.from_dict(load_hyperparams())
    assert tamping.action_type == "ranked" and tamping.net_arch == (64, 64)
    assert tamping.warm_start_rule == "uniform-periodic"
    assert tamping.vf_coef == 0.5  # not in the file: the algorithm's default
    line = LineSettings.from_dict(load_hyperparams(env_id=LINE_ENV_ID, schema=LINE_ZOO))
    assert line.algo == "maskable_ppo" and line.advisor == "grouped-threshold" and line.iterations >= 1
    for s in (tamping, line):
        assert type(s).from_dict(s.to_dict()) == s
        json.dumps(s.to_dict())  # JSON-ready


def test_settings_are_frozen_and_updated_by_copy():
    s = TampingSettings()
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.n_envs = 2  # type: ignore[misc]
    t = s.updated({"n_envs": 2, "warm_start_params": {"interval_years": 1.0}})
    assert (s.n_envs, t.n_envs) == (8, 2) and t.warm_start_params == {"interval_years": 1.0}
    with pytest.raises(TypeError):
        t.warm_start_params["interval_years"] = 2.0  # type: ignore[index]
    assert t.to_dict()["warm_start_params"] == {"interval_years": 1.0}


def test_unknown_keys_name_themselves_and_the_known_ones():
    with pytest.raises(ValueError, match=r"unknown hyper-parameter\(s\) \['learning_rat'\].*learning_rate"):
        TampingSettings.from_dict({"learning_rat": 1e-4})
    with pytest.raises(ValueError, match="clip_obs"):  # the line trains without VecNormalize
        LineSettings().updated({"clip_obs": 5.0})


@pytest.mark.parametrize("cls", [TampingSettings, LineSettings])
def test_every_field_refuses_what_is_out_of_its_range(cls):
    ranges = cls.ranges()
    assert set(ranges) == set(cls.field_names())
    for f in dataclasses.fields(cls):
        meta = f.metadata
        if "range" in meta:
            rng = meta["range"]
            bad = [rng.low - 1 if rng.low > -math.inf else None, "1", True, math.nan]
            if rng.high < math.inf:
                bad.append(rng.high * 2 + 1)
            if rng.open_low:
                bad.append(rng.low)
            if rng.integer:
                bad.append(rng.low + 0.5)
            if meta["optional"]:
                cls(**{f.name: None})
            else:
                bad.append(None)
        elif "choices" in meta:
            bad = ["nothing", 3]
        elif meta.get("bool"):
            bad = [1, "yes", None]
        elif meta.get("layers"):
            bad = [64, [0], [64, 1.5], "64"]
        else:
            bad = [[1, 2], {1: 2}]
        for value in bad:
            with pytest.raises(ValueError, match=rf"{cls.__name__}\.{f.name} must be") as err:
                cls(**{f.name: value})
            assert ranges[f.name] in str(err.value)


def test_the_ranges_read_as_intervals():
    r = LineSettings.ranges()
    assert r["focus_rate"] == "a number in [1e-06, 1]"
    assert r["iterations"] == "an integer in [0, 1000]"
    assert TampingSettings.ranges()["clip_range"] == "a number in (0, inf)"
    assert TampingSettings.ranges()["target_kl"] == "a number in (0, inf) or None"
    assert "uniform-periodic" in TampingSettings.ranges()["warm_start_rule"]


def test_trainers_check_their_settings_before_any_work(tmp_path):
    pytest.importorskip("stable_baselines3")
    from trackenv_agents.learning.line import train_line
    from trackenv_agents.learning.tamping import load_hyperparams, train

    with pytest.raises(ValueError, match=r"TampingSettings\.n_steps must be an integer in \[1, "):
        train(hyperparams={"n_steps": 0}, out_dir=tmp_path / "a", progress=False)
    with pytest.raises(ValueError, match=r"TampingSettings\.n_envs"):
        train(n_envs=0, out_dir=tmp_path / "b", progress=False)
    with pytest.raises(ValueError, match=r"LineSettings\.iterations"):
        train_line("small", iterations=-1, out_dir=tmp_path / "c", progress=False, verbose=0)
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"gamma": 1.5}))
    with pytest.raises(ValueError, match=r"gamma must be a number in \[0, 1\], got 1.5"):
        load_hyperparams(bad)
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()
