"""Independent batches of passes run side by side on the cores: a batch of a few rows cannot fill the cores on
its own (its rows run as one chunk per core, and a batch of one row runs on one core), so two such batches, e.g.
the passes of a line's two vehicle types, run at once in two threads, each kernel on one core.

Only the compiled kernel runs concurrently. Everything in Python around it (the arguments' checks, the kept
factors and steady states, the set-up and the results) runs under one lock, :func:`python_side`, which a thread
releases only while its kernel runs (:func:`kernel_outside`; the kernel's entries release the GIL). So the
caches of :mod:`trackenv.physics.dynamics` see one thread at a time, as in a plain call, and a row's result is
the same, bit for bit, whether its batch runs alone or beside another. The one thing two running kernels could
share is the store in which a one-row pass keeps its window factors for the next pass over its track: a store in
use by a running kernel is marked (:func:`kernel_outside`, read by :func:`store_in_use`), and a second pass over
it meanwhile computes its factors afresh (the same arithmetic: the same numbers).
"""

from __future__ import annotations

import contextlib
import os
import threading
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

Job = TypeVar("Job")
Result = TypeVar("Result")

#: batches of at most this many rows run side by side; a larger one fills the cores on its own and runs alone,
#: with every thread (measured on the default line's passes: batches of up to 8 rows gain side by side)
SIDE_BY_SIDE_MAX_ROWS = 8

_LOCK = threading.Lock()
_HELD = threading.local()
_STORES_IN_USE: set[int] = set()
_POOLS: dict[int, ThreadPoolExecutor] = {}  # workers -> this process's pool


def _reset_in_forked_child() -> None:
    """A forked child has none of its parent's pool threads, and a lock one of them held would never be freed."""
    global _LOCK, _HELD
    _LOCK, _HELD = threading.Lock(), threading.local()
    _STORES_IN_USE.clear()
    _POOLS.clear()


os.register_at_fork(after_in_child=_reset_in_forked_child)


def _holds() -> bool:
    return getattr(_HELD, "held", False)


@contextlib.contextmanager
def python_side() -> Iterator[None]:
    """Hold the lock of the Python side of the passes (re-entrant within a thread: a pass that reruns some rows
    calls the public function again)."""
    if _holds():
        yield
        return
    with _LOCK:
        _HELD.held = True
        try:
            yield
        finally:
            _HELD.held = False


@contextlib.contextmanager
def kernel_outside(store) -> Iterator[None]:
    """Let other threads' Python side run while this thread's kernel runs (``store``: the store of kept factors
    the kernel is handed, marked in use meanwhile), then take the lock back."""
    if not _holds():
        yield
        return
    key = id(store)
    _STORES_IN_USE.add(key)
    _HELD.held = False
    _LOCK.release()
    try:
        yield
    finally:
        _LOCK.acquire()
        _HELD.held = True
        _STORES_IN_USE.discard(key)


def store_in_use(store) -> bool:
    """Whether a running kernel of another thread writes ``store`` now (read under :func:`python_side`)."""
    return id(store) in _STORES_IN_USE


def _pool(workers: int) -> ThreadPoolExecutor:
    """This process's pool of ``workers`` threads, started on first use."""
    if workers not in _POOLS:
        _POOLS[workers] = ThreadPoolExecutor(workers, thread_name_prefix="trackenv-passes")
    return _POOLS[workers]


def run_side_by_side(jobs: Sequence[Job], run: Callable[[Job], Result], rows: Callable[[Job], int],
                     threads: int) -> list[Result]:
    """``[run(job) for job in jobs]``, the jobs of at most :data:`SIDE_BY_SIDE_MAX_ROWS` rows (``rows(job)``)
    side by side on ``threads`` cores (each in a pool thread with its share of numba's threads), the larger ones
    first, one at a time with every thread. With fewer than two small jobs or two threads, in order here."""
    import numba

    fits = [threads >= 2 and len(jobs) >= 2 and rows(job) <= SIDE_BY_SIDE_MAX_ROWS for job in jobs]
    small = [i for i, fit in enumerate(fits) if fit]
    if len(small) < 2:
        return [run(job) for job in jobs]
    results: list = [run(job) if not fit else None for job, fit in zip(jobs, fits, strict=True)]  # the large ones
    workers = min(threads, len(small))
    share = max(1, threads // workers)

    def in_pool_thread(job: Job) -> Result:
        numba.set_num_threads(share)  # this thread's share (numba's thread count is per thread)
        return run(job)

    futures = [_pool(workers).submit(in_pool_thread, jobs[i]) for i in small]
    for i, future in zip(small, futures, strict=True):
        results[i] = future.result()
    return results
