"""Checkpoints of a training run: what a run killed at any moment resumes from.

A run's folder holds ``train_meta.json`` (what the run was started with: trainer, env, settings, config, seeds;
written when it starts) and ``checkpoint.zip``, the run's state at its last checkpoint, replaced whole each
time. ``checkpoint.zip`` is a zip archive (stored, not compressed) of

* ``checkpoint.json`` — what the checkpoint is (:data:`FORMAT_VERSION`, the trainer, its phase, the work done
  and the total asked for, whether the run is finished, when it was written);
* ``model.zip`` — the stable-baselines3 model in its own format (network, optimiser, step counter, last
  observation, learning-rate progress);
* ``state.pkl`` — the rest, pickled: the random generators (Python's ``random``, numpy's global one, torch's),
  the envs' states where they are reachable (each row's episode and generator, see
  :meth:`~trackenv_agents.learning.sb3_vec.TampingSB3VecEnv.get_state`), the wrappers' running statistics
  (VecNormalize, VecMonitor) and the trainer's bookkeeping (best evaluation, its history, the policy
  iteration's data).

Why one file replaced atomically: a SIGKILL can land at any instant, also while a checkpoint is being written.
:func:`write_checkpoint` writes the archive to a temporary file in the same folder, flushes it to disk, then
``os.replace``-s it over ``checkpoint.zip`` (atomic on POSIX and Windows within one file system): a reader sees
the previous checkpoint or the new one, never a torn one. The state is pickled: read checkpoints only from run
folders you trust, as with stable-baselines3's own files.

Why the stable-baselines3 trainers checkpoint at the start of a roll-out (:func:`make_checkpoint_callback`):
the roll-out buffer is empty then, and the model, the envs and the statistics are exactly what the next
roll-out starts from, so a resumed run takes the same steps as a run that was never interrupted (where the
envs' states are reachable).
"""

from __future__ import annotations

import copy
import io
import json
import os
import pickle
import random
import time
import zipfile
from collections.abc import Callable
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["CHECKPOINT_FILE", "FORMAT_VERSION", "META_FILE", "Checkpoint", "capture_random_states",
           "finished_run", "make_checkpoint_callback", "read_checkpoint", "read_checkpoint_info", "read_run_meta",
           "refuse_on_resume", "restore_random_states", "restore_vec_env_state", "resume_folder",
           "save_model_atomic", "start_run_folder", "vec_env_state", "write_checkpoint", "write_json_atomic"]

CHECKPOINT_FILE = "checkpoint.zip"
META_FILE = "train_meta.json"
#: the layout of checkpoint.zip; a reader refuses another (a checkpoint is for resuming with the code that wrote it)
FORMAT_VERSION = 1
_INFO, _MODEL, _STATE = "checkpoint.json", "model.zip", "state.pkl"


class Checkpoint:
    """A checkpoint as read back: ``info`` (checkpoint.json), ``state`` (the unpickled state) and ``model``
    (the stable-baselines3 model's bytes, or None); :meth:`model_file` gives them to ``Algorithm.load``."""

    def __init__(self, info: dict[str, Any], state: dict[str, Any], model: bytes | None) -> None:
        self.info = info
        self.state = state
        self.model = model

    def model_file(self) -> io.BytesIO:
        """The model as a file object for ``PPO.load`` / ``MaskablePPO.load``."""
        if self.model is None:
            raise ValueError("this checkpoint holds no model")
        return io.BytesIO(self.model)


def _fsync_dir(folder: Path) -> None:
    """Flush the folder's entry of a replaced file to disk (where the platform allows opening a folder)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:  # pragma: no cover - Windows cannot open a folder
        return
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _replace_atomically(path: Path, write: Callable[[Any], None], mode: str = "wb") -> None:
    """Write ``path`` through ``write(file)`` into a temporary file beside it, then ``os.replace`` it over
    ``path``: a process killed at any point leaves the old ``path`` or the new one, never a part-written file."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, mode) as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    finally:
        if tmp.exists():  # an error before the replace: no stray temporary file
            tmp.unlink()
    _fsync_dir(path.parent)


def _remove_stale_temporaries(folder: Path, name: str) -> None:
    """Temporary files of ``name`` left by a process killed while writing (the pid in their name is not ours)."""
    for stale in folder.glob(f".{name}.*.tmp"):
        if stale.name != f".{name}.{os.getpid()}.tmp":
            stale.unlink(missing_ok=True)


def write_json_atomic(path: str | Path, payload: Any) -> None:
    """``payload`` as indented JSON at ``path``, replaced atomically (see :func:`_replace_atomically`)."""
    text = json.dumps(payload, indent=1, default=str)
    _replace_atomically(Path(path), lambda f: f.write(text), mode="w")


def save_model_atomic(model: Any, path: str | Path, exclude: list[str] | None = None) -> Path:
    """``model.save`` to ``path``, replaced atomically (see :func:`_replace_atomically`): a run killed while
    saving its best or final model leaves the previous file whole."""
    buffer = io.BytesIO()
    model.save(buffer, exclude=exclude)
    path = Path(path)
    _replace_atomically(path, lambda f: f.write(buffer.getvalue()))
    return path


def write_checkpoint(run_dir: str | Path, info: dict[str, Any], state: dict[str, Any],
                     model: Any = None) -> Path:
    """Replace ``run_dir/checkpoint.zip`` atomically with ``info``, ``state`` (picklable) and ``model`` (a
    stable-baselines3 algorithm, saved whole, or None); return its path. ``info`` gets the format version and
    the time of writing."""
    run_dir = Path(run_dir)
    info = {"format": FORMAT_VERSION, **info, "written": datetime.now(timezone.utc).isoformat(timespec="seconds")}
    parts: list[tuple[str, bytes]] = [(_INFO, json.dumps(info, indent=1, default=str).encode())]
    if model is not None:
        buffer = io.BytesIO()
        model.save(buffer)
        parts.append((_MODEL, buffer.getvalue()))
    parts.append((_STATE, pickle.dumps(state, protocol=pickle.HIGHEST_PROTOCOL)))

    def write(f: Any) -> None:
        with zipfile.ZipFile(f, "w", compression=zipfile.ZIP_STORED) as archive:
            for name, data in parts:
                archive.writestr(name, data)

    _remove_stale_temporaries(run_dir, CHECKPOINT_FILE)
    path = run_dir / CHECKPOINT_FILE
    _replace_atomically(path, write)
    return path


def _missing(run_dir: Path, name: str, why: str) -> FileNotFoundError:
    return FileNotFoundError(f"{run_dir} has no {name} ({why})")


def read_run_meta(run_dir: str | Path) -> dict[str, Any]:
    """``run_dir/train_meta.json``: what the run was started with. FileNotFoundError naming the file if the
    folder holds none (it is no training run's folder)."""
    run_dir = Path(run_dir)
    path = run_dir / META_FILE
    if not path.is_file():
        raise _missing(run_dir, META_FILE, "not the folder of a training run")
    return json.loads(path.read_text())


def read_checkpoint_info(run_dir: str | Path) -> dict[str, Any]:
    """The ``checkpoint.json`` of ``run_dir/checkpoint.zip`` (cheap: the state and model stay unread).
    FileNotFoundError naming the file if there is no checkpoint; ValueError if it is of another format."""
    run_dir = Path(run_dir)
    path = run_dir / CHECKPOINT_FILE
    if not path.is_file():
        raise _missing(run_dir, CHECKPOINT_FILE, "the run kept no checkpoint: was it started with "
                                                 "--checkpoint-every 0, or killed before its first one?")
    with zipfile.ZipFile(path) as archive:
        info = json.loads(archive.read(_INFO))
    if info.get("format") != FORMAT_VERSION:
        raise ValueError(f"{path} is of checkpoint format {info.get('format')!r}; this version reads format "
                         f"{FORMAT_VERSION}")
    return info


def read_checkpoint(run_dir: str | Path) -> Checkpoint:
    """The whole checkpoint of ``run_dir`` (see :func:`read_checkpoint_info` for the errors)."""
    info = read_checkpoint_info(run_dir)
    with zipfile.ZipFile(Path(run_dir) / CHECKPOINT_FILE) as archive:
        names = set(archive.namelist())
        model = archive.read(_MODEL) if _MODEL in names else None
        state = pickle.loads(archive.read(_STATE))
    return Checkpoint(info, state, model)


# --- run folders ---
def refuse_on_resume(run_dir: Path, **given: Any) -> None:
    """A resumed run keeps the settings it was started with: ValueError naming the first of ``given`` (argument
    name → value) that is not None."""
    for name, value in given.items():
        if value is not None:
            raise ValueError(f"resume continues {run_dir} with the settings it was started with ({run_dir / META_FILE}"
                             f"); {name} cannot be given (got {value!r})")


def resume_folder(resume: str | Path, out_dir: str | Path | None) -> Path:
    """The folder a resumed run continues in: ``resume`` itself (``out_dir`` must be None or the same)."""
    run_dir = Path(resume)
    if out_dir is not None and Path(out_dir).resolve() != run_dir.resolve():
        raise ValueError(f"resume continues the run in its own folder {run_dir}; out_dir must be None or that folder, "
                         f"got {out_dir}")
    if not run_dir.is_dir():
        raise FileNotFoundError(f"resume: no such folder: {run_dir}")
    return run_dir


def start_run_folder(run_dir: Path) -> None:
    """Make ``run_dir`` for a new run. An unfinished run's checkpoint there is never overwritten (ValueError
    saying how to continue it or start over); a finished run's is removed (the new run writes its own)."""
    run_dir.mkdir(parents=True, exist_ok=True)
    if not (run_dir / CHECKPOINT_FILE).exists():
        return
    info = read_checkpoint_info(run_dir)
    if not info.get("finished"):
        raise ValueError(f"{run_dir} holds an unfinished run (checkpoint at {info.get('done')} of "
                         f"{info.get('total')} {info.get('unit', 'steps')}): continue it with --resume {run_dir} "
                         f"(resume= in Python), or delete {run_dir / CHECKPOINT_FILE} to start over")
    (run_dir / CHECKPOINT_FILE).unlink()


def finished_run(run_dir: Path, info: dict[str, Any], total: int) -> Path | None:
    """The final model of a run whose checkpoint says it is finished with at least ``total`` units of work done
    (a resume with nothing left to do), else None."""
    if not (info.get("finished") and info["done"] >= total):
        return None
    path = run_dir / "model.zip"
    if not path.exists():
        raise FileNotFoundError(f"{run_dir} is finished ({info['done']} of {total} {info['unit']}) but its "
                                f"model.zip is gone")
    return path


# --- random generators ---
def capture_random_states() -> dict[str, Any]:
    """The process-wide generators a trainer draws from: Python's ``random``, numpy's global generator (the
    roll-out buffer's minibatch shuffles) and torch's (the policy's sampled actions)."""
    import torch

    # numpy's legacy global generator, because that is the one stable-baselines3 shuffles with
    return {"python": random.getstate(), "numpy": np.random.get_state(),  # noqa: NPY002
            "torch": torch.get_rng_state()}


def restore_random_states(states: dict[str, Any]) -> None:
    """Put back what :func:`capture_random_states` took. Global state, on purpose: resuming a run means the
    process continues as the killed one would have (the trainers seed these same generators when they start)."""
    import torch

    random.setstate(states["python"])
    np.random.set_state(states["numpy"])  # noqa: NPY002 (see capture_random_states)
    torch.set_rng_state(states["torch"])


# --- the stable-baselines3 vector env chain ---
def _chain(env: Any) -> list[Any]:
    """The stable-baselines3 VecEnv and the VecEnvs it wraps, outermost first (down to the first that is no
    VecEnvWrapper: the adapter over the native envs)."""
    from stable_baselines3.common.vec_env import VecEnvWrapper

    out = [env]
    while isinstance(out[-1], VecEnvWrapper):
        out.append(out[-1].venv)
    return out


def vec_env_state(env: Any) -> list[dict[str, Any] | None]:
    """The state of each layer of a stable-baselines3 VecEnv chain that a resumed run needs: VecNormalize's
    running statistics and its discounted-return accumulator, VecMonitor's running episode returns and
    lengths, and the innermost env's own (its ``get_state()``, None where it has none or its envs are out of
    reach). Outermost first, one entry per layer."""
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    states: list[dict[str, Any] | None] = []
    for layer in _chain(env):
        if isinstance(layer, VecNormalize):
            states.append({"vecnormalize": copy.deepcopy({k: getattr(layer, k) for k in (
                "obs_rms", "ret_rms", "returns", "old_obs", "old_reward")})})
        elif isinstance(layer, VecMonitor):
            states.append({"vecmonitor": {"episode_returns": layer.episode_returns.copy(),
                                          "episode_lengths": layer.episode_lengths.copy(),
                                          "episode_count": layer.episode_count}})
        elif hasattr(layer, "get_state"):
            envs = layer.get_state()
            states.append(None if envs is None else {"envs": envs})
        else:
            states.append(None)
    return states


def restore_vec_env_state(env: Any, states: list[dict[str, Any] | None]) -> bool:
    """Put :func:`vec_env_state`'s ``states`` back into the same chain; True if the innermost envs were restored
    (their episodes continue), False if their state was out of reach when it was taken (the caller starts new
    episodes). ValueError if the chain is not the one the states came from."""
    layers = _chain(env)
    if len(layers) != len(states):
        raise ValueError(f"the checkpoint's env has {len(states)} layers, this one {len(layers)}")
    envs_restored = False
    for layer, state in zip(layers, states):
        if state is None:
            continue
        if "vecnormalize" in state:
            for key, value in copy.deepcopy(state["vecnormalize"]).items():
                setattr(layer, key, value)
        elif "vecmonitor" in state:
            mon = state["vecmonitor"]
            layer.episode_returns = mon["episode_returns"].copy()
            layer.episode_lengths = mon["episode_lengths"].copy()
            layer.episode_count = mon["episode_count"]
        elif "envs" in state:
            layer.set_state(state["envs"])
            envs_restored = True
    return envs_restored


# --- the periodic checkpoint during model.learn ---
def make_checkpoint_callback(every_s: float, save: Callable[[Any], None], at_start: bool = True) -> Any:
    """A stable-baselines3 callback that calls ``save(model)`` at the start of a roll-out once ``every_s``
    seconds of wall clock have passed since the last checkpoint (and, ``at_start``, when training starts: a run
    is resumable from its first minute). It counts the checkpoints and the seconds spent writing them
    (``count``, ``seconds``): the overhead, which ``summary.json`` reports.

    Why the start of a roll-out: see the module docstring. A run killed loses at most ``every_s`` seconds plus
    the roll-out and update under way."""
    from stable_baselines3.common.callbacks import BaseCallback

    if not (np.isfinite(every_s) and every_s > 0):
        raise ValueError(f"checkpoint_every_s must be a number of seconds > 0, got {every_s!r}")

    class PeriodicCheckpoint(BaseCallback):
        """Writes a checkpoint every ``every_s`` seconds, at a roll-out's start."""

        def __init__(self) -> None:
            super().__init__(0)
            self.count = 0
            self.seconds = 0.0
            self.last_time = time.monotonic()
            self.last_timesteps = -1

        def save_now(self) -> None:
            t0 = time.monotonic()
            save(self.model)
            self.last_time = time.monotonic()
            self.last_timesteps = self.model.num_timesteps
            self.count += 1
            self.seconds += self.last_time - t0

        def _on_training_start(self) -> None:
            self.last_time = time.monotonic()
            self.last_timesteps = self.model.num_timesteps
            if at_start:
                self.save_now()

        def _on_rollout_start(self) -> None:
            due = time.monotonic() - self.last_time >= every_s
            if due and self.model.num_timesteps != self.last_timesteps:
                self.save_now()

        def _on_step(self) -> bool:
            return True

    return PeriodicCheckpoint()
