"""ShardedVectorEnv: a native vector env split over worker processes, so that the Python of one shard's step
runs while another shard's physics does.

A native vector env (:class:`~trackenv.envs.vector.TampingVectorEnv`,
:class:`~trackenv.envs.line.TampingLineVectorEnv`) runs its batched physics on every core, but the rest of its
step (tamping, settlement, costs, observations: about 40 % of a 32-env step) runs in one Python thread while the
other cores wait. Here each of ``workers`` processes holds a shard of the envs, a native vector env of its own
whose physics runs on ``threads_per_worker`` numba threads; a step sends every shard its rows of the actions and
gathers the shards' results, so the shards' Python and physics overlap across the cores.

The results are those of the one-process native vector env of ``num_envs`` envs with the same seeds, bit for
bit (``tests/envs/test_sharded.py``): ``reset(seed=s)`` seeds env ``i`` with ``s + i`` whatever its shard, every
row of the physics depends on its own row only, and the infos are merged into Gymnasium's vector layout (each
key with its ``_key`` mask) exactly as the one-process env builds them. Warnings raised in a worker are raised
again in the caller; an exception in a worker is raised again in the caller with the worker's traceback; a
worker that died raises RuntimeError instead of hanging.

Workers start with the ``spawn`` method by default (safe with numba's threads): as with any multiprocessing
code, a script that builds this env at import time must guard it with ``if __name__ == "__main__":``.
"""

from __future__ import annotations

import multiprocessing as mp
import pickle
import traceback
import warnings
from collections.abc import Callable
from functools import partial
from typing import Any

import numpy as np
from gymnasium.vector import VectorEnv
from gymnasium.vector.utils import batch_space

from ..physics._checks import check_choice, check_int
from ..physics.kernels import usable_cores
from ._seeding import vector_seeds
from .batched import BatchedVectorEnv, check_vector_actions

__all__ = ["ShardedVectorEnv", "line_vector_env", "native_or_sharded", "shard_sizes", "tamping_vector_env"]

_REPLY_TIMEOUT_S = 1.0  # how often a wait for a worker checks that the worker is still alive


def shard_sizes(num_envs: int, workers: int) -> list[int]:
    """Envs per shard: ``num_envs`` split over ``workers`` shards as evenly as possible, the larger first."""
    return [num_envs // workers + (i < num_envs % workers) for i in range(workers)]


def _worker(conn, make_shard: Callable[[int], BatchedVectorEnv], num_envs: int, threads: int) -> None:
    """A shard's process: build the shard, then answer commands until "close" (or the pipe closes)."""
    import numba

    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))  # type: ignore[attr-defined]
    env = None
    try:
        env, caught = _recorded(make_shard, num_envs)
        conn.send(("ok", None, caught))
        while True:
            try:
                command, arg = conn.recv()
            except EOFError:
                return
            if command == "close":
                return
            try:
                conn.send(("ok", *_recorded(_command, env, command, arg)))
            except Exception as exc:  # the caller raises it again
                conn.send(("error", _error_report(exc), []))
    except Exception as exc:  # building the shard failed
        conn.send(("error", _error_report(exc), []))
    finally:
        if env is not None:
            env.close()
        conn.close()


def _command(env: BatchedVectorEnv, command: str, arg: Any) -> Any:
    """What a worker's shard answers to ``command``."""
    if command == "reset":
        return env.reset(seed=arg[0], options=arg[1])
    if command == "step":
        return env.step(arg)
    if command == "action_masks":
        return env.action_masks()  # type: ignore[attr-defined]
    if command == "render":
        return env.render()
    if command == "current_observations":
        return env.current_observations()
    if command == "get_state":
        return env.get_state(arg)  # type: ignore[attr-defined]
    if command == "set_state":
        return env.set_state(*arg)  # type: ignore[attr-defined]
    raise ValueError(f"unknown command {command!r}")  # pragma: no cover (the parent sends only the above)


def _recorded(fn: Callable, *args: Any) -> tuple[Any, list[tuple[type, str]]]:
    """``fn(*args)`` and the warnings it raised, as (category, message) pairs for the caller to raise again."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = fn(*args)
    return out, [(w.category, str(w.message)) for w in caught]


def _error_report(exc: Exception) -> tuple[type, str, str]:
    """What the caller needs to raise a worker's exception again: its class (RuntimeError where the class cannot
    be pickled), message and traceback."""
    kind: type = type(exc)
    try:
        pickle.dumps(kind)
    except Exception:
        kind = RuntimeError
    return kind, str(exc), traceback.format_exc()


def _raised_again(kind: type, message: str) -> Exception:
    """The caller's copy of a worker's exception: its class with ``message``, or RuntimeError where the class
    does not take a single message."""
    try:
        err = kind(message)
    except Exception:
        return RuntimeError(message)
    return err if isinstance(err, Exception) else RuntimeError(message)


def _blank(like: np.ndarray, n: int) -> np.ndarray:
    """The entries of a vector info key for ``n`` envs that did not report it: what Gymnasium's ``_add_info``
    leaves there (zeros of the key's dtype, None in object arrays)."""
    if like.dtype == object:
        return np.full((n,) + like.shape[1:], None, dtype=object)
    return np.zeros((n,) + like.shape[1:], dtype=like.dtype)


def merge_infos(parts: list[dict], sizes: list[int]) -> dict:
    """The vector infos of consecutive shards (``sizes`` envs each) as one vector info dict of ``sum(sizes)``
    envs: every key's arrays concatenated, nested dicts merged alike, blanks where a shard lacks a key."""
    keys: dict = {}
    for part in parts:
        keys.update(dict.fromkeys(part))
    out: dict = {}
    for key in keys:
        values = [part.get(key) for part in parts]
        ref = next(v for v in values if v is not None)
        if isinstance(ref, dict):
            out[key] = merge_infos([{} if v is None else v for v in values], sizes)
        else:
            out[key] = np.concatenate([_blank(ref, n) if v is None else v for v, n in zip(values, sizes)])
    return out


class ShardedVectorEnv(VectorEnv):
    """``num_envs`` envs of a native vector env in ``workers`` processes (see the module docstring).

    ``make_shard``: a picklable callable that builds a shard of ``n`` envs, ``make_shard(n)`` (e.g.
    ``functools.partial(TampingVectorEnv, config=cfg)``); ``workers`` in [1, num_envs];
    ``threads_per_worker``: numba threads of each shard's physics (default: the cores this process may run
    on, :func:`~trackenv.physics.kernels.usable_cores`, shared out, at least 1); ``context``: the
    multiprocessing start method, "spawn" or "forkserver" ("fork" is refused: a child forked from a process
    whose numba threads have run aborts).
    The spaces, ``config``, autoreset mode and render mode are those of the shards. Use :meth:`close` (or
    ``with``) to stop the workers."""

    def __init__(self, make_shard: Callable[[int], BatchedVectorEnv], num_envs: int, workers: int = 2, *,
                 threads_per_worker: int | None = None, context: str = "spawn") -> None:
        self.closed = True  # until the workers start (a failed construction has nothing to close)
        self._conns: list = []
        self._procs: list = []
        if not callable(make_shard):
            raise ValueError(f"make_shard must be a callable that builds a shard of n envs, got {make_shard!r}")
        self.num_envs = check_int("num_envs", num_envs, low=1, high=4096)
        self.workers = check_int("workers", workers, low=1, high=self.num_envs)
        cores = usable_cores()
        threads = max(1, cores // self.workers) if threads_per_worker is None else threads_per_worker
        self.threads_per_worker = check_int("threads_per_worker", threads, low=1, high=1024)
        # not "fork": a child forked from a process whose numba threads have run (OpenMP) aborts
        check_choice("context", context, ("spawn", "forkserver"))
        template = make_shard(1)  # spaces and config, without episodes (no physics runs here)
        if not isinstance(template, BatchedVectorEnv):
            raise ValueError(f"make_shard must build a native vector env, got {type(template).__name__}")
        self.config = getattr(template, "config", None)
        self.autoreset_mode = template.autoreset_mode
        self.render_mode = template.render_mode
        self.metadata = dict(template.metadata)
        self.single_observation_space = template.single_observation_space
        self.single_action_space = template.single_action_space
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._obs_keys = list(getattr(self.single_observation_space, "spaces", {}))
        template.close()
        self.sizes = shard_sizes(self.num_envs, self.workers)
        self._bounds = np.cumsum([0] + self.sizes)
        ctx: Any = mp.get_context(context)
        self.closed = False
        try:
            for n in self.sizes:
                parent, child = ctx.Pipe()
                proc = ctx.Process(target=_worker, args=(child, make_shard, n, self.threads_per_worker),
                                   daemon=True)
                try:
                    proc.start()
                except (pickle.PicklingError, AttributeError) as exc:  # spawn and forkserver pickle make_shard
                    raise ValueError(
                        f"make_shard must be picklable for the {context!r} start method (a class, or a "
                        f"functools.partial of one, from an importable module), got {make_shard!r}: {exc}"
                    ) from exc
                child.close()
                self._conns.append(parent)
                self._procs.append(proc)
            self._gather(range(self.workers))  # each shard built (or its error raised)
        except BaseException:
            self.close()
            raise

    # ------------------------------------------------------------------ talking to the workers
    def _receive(self, k: int) -> Any:
        conn, proc = self._conns[k], self._procs[k]
        while not conn.poll(_REPLY_TIMEOUT_S):
            if not proc.is_alive():
                raise self._died(k)
        try:
            status, out, caught = conn.recv()
        except EOFError:
            raise self._died(k) from None
        for category, message in caught:
            warnings.warn(message, category, stacklevel=4)
        if status == "error":
            kind, message, trace = out
            raise _raised_again(kind, f"{message}\n(raised in worker {k} of the sharded vector env:\n{trace})")
        return out

    def _died(self, k: int) -> RuntimeError:
        self._procs[k].join(timeout=1.0)  # its exit code
        return RuntimeError(f"worker {k} of the sharded vector env died (exit code {self._procs[k].exitcode}); "
                            "close this env and make a new one")

    def _gather(self, shards) -> list:
        """Every shard's reply, in order; the first error (after all replies are read, so no pipe is left with
        an unread reply) is raised again."""
        replies, error = [], None
        for k in shards:
            try:
                replies.append(self._receive(k))
            except Exception as exc:
                replies.append(None)
                if error is None:
                    error = exc
        if error is not None:
            raise error
        return replies

    def _send(self, k: int, command: str, arg: Any) -> None:
        if self.closed:
            raise RuntimeError("the sharded vector env is closed")
        try:
            self._conns[k].send((command, arg))
        except (BrokenPipeError, OSError):
            raise self._died(k) from None

    def _send_all(self, command: str, args: list) -> list:
        for k, arg in enumerate(args):
            self._send(k, command, arg)
        return self._gather(range(self.workers))

    def _rows(self, x: np.ndarray) -> list[np.ndarray]:
        return [x[a:b] for a, b in zip(self._bounds[:-1], self._bounds[1:])]

    def _observations(self, parts: list[dict]) -> dict:
        return {k: np.concatenate([p[k] for p in parts]) for k in self._obs_keys}

    # ------------------------------------------------------------------ the Gymnasium API
    def reset(self, *, seed: int | list[int] | None = None,
              options: dict | None = None) -> tuple[dict, dict[str, Any]]:
        seeds = vector_seeds(seed, self.num_envs)
        replies = self._send_all("reset", [(list(s), options) for s in self._rows(np.array(seeds, dtype=object))])
        return (self._observations([r[0] for r in replies]),
                merge_infos([r[1] for r in replies], self.sizes))

    def step(self, actions: Any) -> tuple[dict, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        actions = check_vector_actions(actions, self.num_envs, self.single_action_space)
        replies = self._send_all("step", self._rows(actions))
        obs = self._observations([r[0] for r in replies])
        rewards, terminated, truncated = (np.concatenate([r[i] for r in replies]) for i in (1, 2, 3))
        return obs, rewards, terminated, truncated, merge_infos([r[4] for r in replies], self.sizes)

    def action_masks(self) -> np.ndarray:
        """(num_envs, ...) action masks of the shards, in env order."""
        return np.concatenate(self._send_all("action_masks", [None] * self.workers))

    def current_observations(self) -> dict:
        """The shards' observations as they stand (:meth:`BatchedVectorEnv.current_observations`), in env order."""
        return self._observations(self._send_all("current_observations", [None] * self.workers))

    def get_state(self, index: int) -> Any:
        """A snapshot of env ``index`` from the worker that holds it: the native vector env's
        (:mod:`trackenv.envs.state`), restorable in any row, here or in a native or single env of this config."""
        k, i = self._shard_of(index)
        self._send(k, "get_state", i)
        return self._gather([k])[0]

    def set_state(self, index: int, state: Any) -> None:
        """Continue env ``index`` from ``state`` (a snapshot of this config), in the worker that holds it."""
        k, i = self._shard_of(index)
        self._send(k, "set_state", (i, state))
        self._gather([k])

    def _shard_of(self, index: int) -> tuple[int, int]:
        """The worker holding env ``index`` (checked) and the env's row in its shard."""
        index = check_int("index", index, low=0, high=self.num_envs - 1)
        k = int(np.searchsorted(self._bounds, index, side="right")) - 1
        return k, index - int(self._bounds[k])

    def render(self):  # one frame, as the native vector env draws it
        """The first env's state as an RGB array (``render_mode="rgb_array"``), else None."""
        if self.render_mode != "rgb_array":
            return None
        self._send(0, "render", None)
        return self._gather([0])[0]

    def close_extras(self, **kwargs: Any) -> None:
        """Stop the workers (:meth:`close` calls this once)."""
        for conn in self._conns:
            try:
                conn.send(("close", None))
            except (BrokenPipeError, OSError):
                pass
        for proc in self._procs:
            proc.join(timeout=10.0)
            if proc.is_alive():  # pragma: no cover (a worker stuck in a command)
                proc.terminate()
                proc.join(timeout=5.0)
        for conn in self._conns:
            conn.close()

    def __enter__(self) -> ShardedVectorEnv:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def native_or_sharded(make_shard: Callable[[int], BatchedVectorEnv], num_envs: int, workers: int = 1) -> VectorEnv:
    """``make_shard(num_envs)`` itself for ``workers`` = 1, else the same envs in that many processes
    (:class:`ShardedVectorEnv`): the one choice every entry point (make_vec, the SB3 adapter, the benchmark)
    makes."""
    workers = check_int("workers", workers, low=1, high=4096)
    if workers == 1:
        return make_shard(num_envs)
    return ShardedVectorEnv(make_shard, num_envs, workers)


def tamping_vector_env(num_envs: int = 8, *, workers: int = 1, **kwargs: Any) -> VectorEnv:
    """The vector entry point of the Tamping ids (``gym.make_vec(..., vectorization_mode="vector_entry_point")``):
    :class:`~trackenv.envs.vector.TampingVectorEnv` of ``num_envs`` envs with ``kwargs``, or with ``workers`` > 1
    the same envs in that many processes (:class:`ShardedVectorEnv`)."""
    from .vector import TampingVectorEnv

    return native_or_sharded(partial(TampingVectorEnv, **kwargs), num_envs, workers)


def line_vector_env(num_envs: int = 4, *, workers: int = 1, **kwargs: Any) -> VectorEnv:
    """The vector entry point of the TampingLine ids: :class:`~trackenv.envs.line.TampingLineVectorEnv`, or with
    ``workers`` > 1 the same lines in that many processes (:class:`ShardedVectorEnv`)."""
    from .line import TampingLineVectorEnv

    return native_or_sharded(partial(TampingLineVectorEnv, **kwargs), num_envs, workers)

