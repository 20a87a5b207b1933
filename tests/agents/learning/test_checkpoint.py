"""Checkpoints and resuming: the file is replaced atomically, the envs' states restore exactly, and a training
run killed with SIGKILL resumes from its last checkpoint to the very model an uninterrupted run makes (both
trainers, through the command line)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("sb3_contrib")

from trackenv_agents.learning.checkpoint import (  # noqa: E402
    CHECKPOINT_FILE,
    META_FILE,
    capture_random_states,
    make_checkpoint_callback,
    read_checkpoint,
    read_checkpoint_info,
    restore_random_states,
    start_run_folder,
    write_checkpoint,
)

CLI = [sys.executable, "-m", "trackenv_agents"]


# --- the file ---
def test_checkpoint_round_trip_and_what_it_refuses(tmp_path):
    state = {"data": [np.arange(3)], "best": -1.5}
    path = write_checkpoint(tmp_path, {"unit": "iterations", "done": 2, "total": 5, "finished": False}, state)
    assert path == tmp_path / CHECKPOINT_FILE
    ckpt = read_checkpoint(tmp_path)
    assert ckpt.info["done"] == 2 and ckpt.info["format"] == 1 and ckpt.model is None
    np.testing.assert_array_equal(ckpt.state["data"][0], np.arange(3))
    with pytest.raises(FileNotFoundError, match=f"no {CHECKPOINT_FILE}"):
        read_checkpoint_info(tmp_path / "elsewhere")
    with zipfile.ZipFile(path, "w") as archive:  # a checkpoint of another layout
        archive.writestr("checkpoint.json", json.dumps({"format": 99}))
    with pytest.raises(ValueError, match="format 99"):
        read_checkpoint_info(tmp_path)


def test_a_write_cut_short_leaves_the_previous_checkpoint_whole(tmp_path, monkeypatch):
    """What a SIGKILL during a write leaves: a temporary file, never a torn checkpoint.zip. Here the write
    stops with an error after the archive's first entry is in the temporary file: the old checkpoint still
    reads. A temporary file that a killed writer left behind (no error handler ran) is cleared by the next
    write."""
    write_checkpoint(tmp_path, {"done": 1, "total": 2, "finished": False}, {"n": 1})
    before = (tmp_path / CHECKPOINT_FILE).read_bytes()
    writestr = zipfile.ZipFile.writestr

    def cut_short(self, name, data, *args, **kwargs):
        if name == "state.pkl":
            raise OSError("disk full")
        return writestr(self, name, data, *args, **kwargs)

    with monkeypatch.context() as m:
        m.setattr(zipfile.ZipFile, "writestr", cut_short)
        with pytest.raises(OSError, match="disk full"):
            write_checkpoint(tmp_path, {"done": 2, "total": 2, "finished": False}, {"n": 2})
    assert (tmp_path / CHECKPOINT_FILE).read_bytes() == before and read_checkpoint(tmp_path).state == {"n": 1}
    assert not list(tmp_path.glob(".*.tmp"))
    stale = tmp_path / f".{CHECKPOINT_FILE}.999999999.tmp"  # a killed writer's half-written file
    stale.write_bytes(b"torn")
    write_checkpoint(tmp_path, {"done": 2, "total": 2, "finished": True}, {"n": 2})
    assert not stale.exists() and read_checkpoint(tmp_path).state == {"n": 2}


def test_a_new_run_never_overwrites_an_unfinished_one(tmp_path):
    write_checkpoint(tmp_path, {"unit": "timesteps", "done": 64, "total": 128, "finished": False}, {})
    with pytest.raises(ValueError, match=r"unfinished run \(checkpoint at 64 of 128 timesteps\).*--resume"):
        start_run_folder(tmp_path)
    write_checkpoint(tmp_path, {"unit": "timesteps", "done": 128, "total": 128, "finished": True}, {})
    start_run_folder(tmp_path)  # a finished run's checkpoint makes way for the new run's
    assert not (tmp_path / CHECKPOINT_FILE).exists()


def test_checkpoint_interval_must_be_positive():
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="checkpoint_every_s must be a number of seconds > 0"):
            make_checkpoint_callback(bad, lambda model: None)


def test_random_states_round_trip():
    import random

    import torch

    states = capture_random_states()
    first = (random.random(), np.random.random(), torch.rand(1).item())  # noqa: NPY002 - the global one, on purpose
    restore_random_states(states)
    assert (random.random(), np.random.random(), torch.rand(1).item()) == first  # noqa: NPY002


# --- the envs' states ---
@pytest.mark.parametrize("action_type", ["multibinary", "ranked"])
def test_adapter_state_continues_the_envs_exactly(small_coarse_config, action_type):
    """A fresh adapter given another's state steps on exactly as the other does, through an episode's end (its
    next episode comes from the restored generator) and, ranked, with the wrapper's section SDs."""
    from trackenv_agents.learning.sb3_vec import TampingSB3VecEnv

    kw = {"action_type": action_type, "keep_per_sleeper": False}
    a = TampingSB3VecEnv(2, small_coarse_config, seed=5, **kw)
    a.reset()
    rng = np.random.default_rng(0)

    def actions() -> np.ndarray:
        if action_type == "ranked":
            return rng.integers(0, 4, size=2)
        return rng.integers(0, 2, size=(2, 3)).astype(np.int8)

    a.step(actions())
    for _ in range(2):  # no tamping just before the state is taken: every section may be tamped next
        a.step(np.zeros(2, dtype=np.int64) if action_type == "ranked" else np.zeros((2, 3), dtype=np.int8))
    b = TampingSB3VecEnv(2, small_coarse_config, seed=99, **kw)  # other seeds: nothing of its own survives
    b.set_state(a.get_state())
    for t in range(small_coarse_config.horizon_steps + 2):  # past the end of the episode
        # first, tamp each line's worst section: ranked, which one that is comes from the restored SDs
        act = actions() if t else (np.ones(2, dtype=np.int64) if action_type == "ranked" else
                                   np.eye(3, dtype=np.int8)[[0, 2]])
        (obs_a, rew_a, done_a, _), (obs_b, rew_b, done_b, _) = a.step(act), b.step(act)
        np.testing.assert_array_equal(rew_a, rew_b)
        np.testing.assert_array_equal(done_a, done_b)
        for k in obs_a:
            np.testing.assert_array_equal(obs_a[k], obs_b[k])
    with pytest.raises(ValueError, match="holds 2 envs"):
        TampingSB3VecEnv(3, small_coarse_config, **kw).set_state(a.get_state())


def test_section_agents_state_continues_the_lines_exactly():
    from trackenv.envs.line_config import scenario
    from trackenv_agents.learning.sb3_vec import SectionAgentsVecEnv

    cfg = scenario("small", horizon_years=1.0, segment_length_m=12.0)
    a, b = SectionAgentsVecEnv(1, cfg, seed=3), SectionAgentsVecEnv(1, cfg, seed=4)
    a.reset()
    act = np.zeros(a.num_envs, dtype=np.int64)
    act[0] = 1
    a.step(act)
    b.set_state(a.get_state())
    for _ in range(cfg.horizon_steps + 1):
        (obs_a, rew_a, _, _), (obs_b, rew_b, _, _) = a.step(act), b.step(act)
        np.testing.assert_array_equal(obs_a, obs_b)
        np.testing.assert_array_equal(rew_a, rew_b)


# --- the command line, without training ---
def test_resume_refuses_a_folder_without_a_checkpoint_naming_what_is_missing(tmp_path, capsys):
    from trackenv_agents.cli import main

    assert main(["train", "--resume", str(tmp_path)]) == 2
    assert capsys.readouterr().err == f"trackenv train: {tmp_path} has no {META_FILE} (not the folder of a training " \
                                      f"run)\n"
    (tmp_path / META_FILE).write_text(json.dumps({"trainer": "sb3"}))
    assert main(["train", "--resume", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{tmp_path} has no {CHECKPOINT_FILE}" in err and "--checkpoint-every 0" in err


@pytest.mark.parametrize("flag", [["--n-envs", "4"], ["--algo", "ppo"], ["--seed", "7"], ["--iterations", "2"],
                                  ["--env", "trackenv/TampingLine-v0"], ["--out", "elsewhere"]])
def test_resume_keeps_the_runs_own_settings(tmp_path, capsys, flag):
    from trackenv_agents.cli import main

    assert main(["train", "--resume", str(tmp_path), *flag]) == 2
    assert f"drop {flag[0]}" in capsys.readouterr().err


def test_checkpoint_every_is_checked():
    from trackenv_agents.cli import build_parser

    assert build_parser().parse_args(["train", "--checkpoint-every", "0"]).checkpoint_every == 0.0
    with pytest.raises(SystemExit):
        build_parser().parse_args(["train", "--checkpoint-every", "-1"])


# --- SIGKILL and resume ---
def _checkpoint_info(run_dir: Path) -> dict | None:
    try:
        return read_checkpoint_info(run_dir)
    except FileNotFoundError:
        return None


def _kill_at(proc: subprocess.Popen, run_dir: Path, ready: Callable[[dict], bool]) -> dict:
    """SIGKILL ``proc`` as soon as its checkpoint satisfies ``ready``; the checkpoint's info then. Fails if the
    run ends first (then it was never interrupted and the test would prove nothing)."""
    deadline = time.monotonic() + 900  # only against a hang: the run takes seconds
    while time.monotonic() < deadline:
        info = _checkpoint_info(run_dir)
        if info is not None and ready(info):
            proc.send_signal(signal.SIGKILL)
            proc.wait()
            if proc.returncode != -signal.SIGKILL:
                pytest.fail(f"the run ended (status {proc.returncode}) before it could be killed")
            return read_checkpoint_info(run_dir)  # the last one written before the kill
        if proc.poll() is not None:
            pytest.fail(f"the run ended (status {proc.returncode}) before its checkpoint was ready")
        time.sleep(0.02)
    proc.kill()
    pytest.fail("no checkpoint was ready in time: the run hung")


def _policy_parameters(path: Path) -> dict:
    from stable_baselines3.common.save_util import load_from_zip_file

    return load_from_zip_file(path, device="cpu")[1]["policy"]


def _assert_same_parameters(a: Path, b: Path) -> None:
    pa, pb = _policy_parameters(a), _policy_parameters(b)
    assert pa.keys() == pb.keys()
    for k in pa:
        assert pa[k].equal(pb[k]), k


def _without_timings(records: list[dict]) -> list[dict]:
    return [{k: v for k, v in r.items() if "seconds" not in k} for r in records]


@pytest.mark.slow
def test_sb3_run_killed_with_sigkill_resumes_from_its_checkpoint(tmp_path):
    """`trackenv train` on the 60 m track (Tamping-v1, 2 envs, a roll-out of 16 steps, a checkpoint at every
    roll-out's start, a held-out evaluation every 64 steps) is killed with SIGKILL once it has checkpointed past
    its first evaluation; `trackenv train --resume` continues from that checkpoint (not from 0) to the total
    and ends with the model, the evaluations and the best model of a run that was never interrupted (run
    alongside), bit for bit. A further resume says the run is finished."""
    hp = tmp_path / "hp.json"
    hp.write_text(json.dumps({"n_steps": 8, "batch_size": 16, "n_epochs": 1, "net_arch": [16],
                              "warm_start_rule": None, "eval_freq": 64}))
    args = ["train", "--timesteps", "160", "--n-envs", "2", "--checkpoint-every", "0.001", "--hyperparams", str(hp),
            "--json"]
    killed, whole = tmp_path / "killed", tmp_path / "whole"
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    reference = subprocess.Popen([*CLI, *args, "--out", str(whole)], **quiet)
    run = subprocess.Popen([*CLI, *args, "--out", str(killed)], **quiet)
    try:
        at = _kill_at(run, killed, lambda info: info["done"] >= 80)  # after the evaluation at 64 steps
    finally:
        reference.wait()
    assert reference.returncode == 0
    assert at["done"] >= 80 and not at["finished"]
    assert not (killed / "model.zip").exists() and not (killed / "summary.json").exists()

    out = subprocess.run([*CLI, "train", "--resume", str(killed), "--json"], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    resumed = json.loads(out.stdout)
    assert resumed["resumed_from_timesteps"] == at["done"]  # from the checkpoint, not from 0
    assert resumed["timesteps_this_run"] == 160 - at["done"] and resumed["timesteps"] == 160
    assert read_checkpoint_info(killed)["finished"]

    from trackenv_agents.learning.baselines import load_baseline
    from trackenv_agents.learning.tamping import load_trained, stats_path

    for name in ("model.zip", "best_model.zip"):
        load_trained(killed / name)
        _assert_same_parameters(killed / name, whole / name)
        # each says what it was trained on, so trackenv evaluate --model / leaderboard --policies can score it (the
        # best model's sidecar had no config: refused "no 'config' (the line it was trained on)")
        meta = json.loads(stats_path(killed / name).read_text())
        assert meta["config"] == json.loads(stats_path(killed / "model.zip").read_text())["config"]
        load_baseline(killed / name, name=name)
    assert (killed / "vecnormalize.pkl").exists()
    evaluations = json.loads((killed / "evaluations.json").read_text())
    assert [e["timesteps"] for e in evaluations] == [64, 128, 160]
    assert _without_timings(evaluations) == _without_timings(json.loads((whole / "evaluations.json").read_text()))

    again = subprocess.run([*CLI, "train", "--resume", str(killed)], capture_output=True, text=True)
    assert again.returncode == 0 and "is finished (160 of 160 timesteps); nothing to resume" in again.stdout


_LINE_RUN = """
import sys
from trackenv.envs.line_config import scenario
from trackenv_agents.learning.line import train_line
hp = {"episodes_per_iteration": 2, "fit_epochs": 5, "net_arch": [16, 16], "n_steps": 8, "batch_size": 48,
      "n_epochs": 1, "eval_freq": 8}
train_line(scenario("small", horizon_years=2.0, segment_length_m=12.0), iterations=3, total_timesteps=16, n_envs=1,
           out_dir=sys.argv[1], hyperparams=hp, eval_seeds=[100, 101], progress=False, verbose=0)
"""


@pytest.mark.slow
def test_line_run_killed_with_sigkill_resumes_from_its_last_iteration(tmp_path):
    """The line's policy iteration (small line over 2 years, 3 iterations of 2 episodes, then 16 line-steps of
    MaskablePPO), killed with SIGKILL after its first iteration's checkpoint, resumes through the command line
    from the last complete iteration: the iterations before the kill are not run again, and the run ends with
    the iterations, evaluations and model of a run that was never interrupted."""
    killed, whole = tmp_path / "killed", tmp_path / "whole"
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    reference = subprocess.Popen([sys.executable, "-c", _LINE_RUN, str(whole)], **quiet)
    run = subprocess.Popen([sys.executable, "-c", _LINE_RUN, str(killed)], **quiet)
    try:
        at = _kill_at(run, killed, lambda info: info["phase"] == "policy_iteration" and info["done"] >= 1)
    finally:
        reference.wait()
    assert reference.returncode == 0
    assert at["phase"] == "policy_iteration" and 1 <= at["done"] <= 3
    iteration_files = {p.name: p.stat().st_mtime_ns for p in (killed / "checkpoints").glob("*.zip")}

    out = subprocess.run([*CLI, "train", "--resume", str(killed), "--json"], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    summary = json.loads(out.stdout)
    assert [it["iteration"] for it in summary["iterations"]] == [0, 1, 2]
    for it in range(at["done"]):  # the iterations done before the kill were not run again
        name = f"iteration_{it}.zip"
        assert (killed / "checkpoints" / name).stat().st_mtime_ns == iteration_files[name]
    assert read_checkpoint_info(killed)["finished"] and summary["ppo"]["line_steps"] == 16

    from trackenv_agents.learning.line import load_line_trained

    load_line_trained(killed / "model.zip")
    _assert_same_parameters(killed / "model.zip", whole / "model.zip")
    reference_summary = json.loads((whole / "summary.json").read_text())

    def comparable(iterations: list[dict]) -> list[dict]:
        return [{"fit": it["fit"], "samples": it["samples"], "mean_cost": it["evaluation"]["mean_cost"]}
                for it in iterations]

    assert comparable(summary["iterations"]) == comparable(reference_summary["iterations"])
    assert _without_timings(summary["ppo"]["evaluations"]) == _without_timings(reference_summary["ppo"]["evaluations"])
    assert os.path.exists(killed / "best_model.zip")
