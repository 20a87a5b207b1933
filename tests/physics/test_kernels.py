"""The compiled kernel's entries: what is compiled can be asked cheaply, built up front with progress, and the
on-disk cache follows every kernel module's source."""

from __future__ import annotations

import ast
from pathlib import Path

import numba
import numpy as np
import pytest

from trackenv.physics import _kernel, _pipeline, kernels
from trackenv.physics.dynamics import simulate_pass
from trackenv.physics.kernels import CompileProgress, KernelEntry
from trackenv.physics.track import Track
from trackenv.physics.vehicle import Wheelset

PHYSICS = Path(_pipeline.__file__).parent


def test_every_reachable_entry_is_compiled_after_the_session_warm_up():
    """The session fixture builds every entry: none is missing, every width reports compiled, and building again
    compiles nothing and reports nothing."""
    assert kernels.missing_kernels() == []
    assert all(kernels.kernel_is_compiled(w) for w in kernels.WIDTHS)
    events = []
    assert kernels.compile_kernels(progress=events.append) == []
    assert events == []


def test_the_queried_signature_is_the_one_a_pass_compiles():
    """The query asks about the argument types a pass gives the kernel: after a one-row pass, the serial one-row
    entry holds code for exactly that signature (so a query cannot say compiled while a call would compile)."""
    simulate_pass(Track.seed(), Wheelset.seed(), 20.0, x_start=10.0, x_end=10.5)
    assert kernels._signature() in _kernel._RUNNERS[(False, 1)].overloads
    assert kernels.is_compiled(KernelEntry(False, 1))


def test_entries_and_progress():
    assert [e.width for e in kernels.kernel_entries([6])] == [6] * (2 if numba.config.NUMBA_NUM_THREADS >= 2 else 1)
    assert kernels.entry_for_rows(1) == KernelEntry(False, 1)
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        assert kernels.entry_for_rows(12) == KernelEntry(False, 16)
    finally:
        numba.set_num_threads(threads)
    with pytest.raises(ValueError, match="width"):
        KernelEntry(False, 3)
    with pytest.raises(ValueError, match="n_rows"):
        kernels.entry_for_rows(0)
    start = CompileProgress(KernelEntry(True, 6), 2, 5, from_cache=False)
    assert str(start) == "[2/5] compiling the pass kernel for parallel chunks of 6 rows"
    done = CompileProgress(KernelEntry(False, 1), 1, 1, from_cache=True, seconds=0.42)
    assert str(done) == "[1/1] loading the pass kernel for serial chunks of 1 row done in 0.4 s"


def test_loading_reports_each_entry_it_loads(monkeypatch):
    """With ``load`` an entry on disk but not in this process is loaded, with a start and a done event, and is not
    counted as compiled."""
    entry = KernelEntry(False, 4)
    monkeypatch.setattr(_kernel, "is_loaded", lambda key, sig: key != (entry.parallel, entry.width))
    monkeypatch.setattr(_kernel, "is_cached", lambda key, sig: True)
    built = []
    monkeypatch.setattr(_kernel, "build", lambda key, sig: built.append(key))
    events = []
    assert kernels.compile_kernels([4], progress=events.append, load=True) == []
    assert built == [(False, 4)] and [e.seconds is None for e in events] == [True, False]
    assert all(e.from_cache and e.entry == entry for e in events)
    assert kernels.compile_kernels([4], progress=events.append) == [] and len(events) == 2  # not loaded without load


def test_the_cache_stamp_covers_every_kernel_module():
    """numba's cache checks only a function's own file; the kernel's functions are stamped with the digest of all
    its modules, so that a change in one module invalidates the entries that inline it. Every module that
    compiles kernel code (kernel_jit or a lane intrinsic) is among them, and the digest is that of their source."""
    compiling = {
        path.name
        for path in PHYSICS.glob("*.py")
        if any(isinstance(node, ast.Name) and node.id in ("kernel_jit", "intrinsic") for node in
               ast.walk(ast.parse(path.read_text())))
    }
    assert compiling <= set(_pipeline.KERNEL_MODULES) and "_implicit.py" not in _pipeline.KERNEL_MODULES
    assert _pipeline.SOURCE_DIGEST == _pipeline._source_digest()
    for dispatcher in _kernel._RUNNERS.values():
        stamp = dispatcher._cache._impl.locator.get_source_stamp()
        assert isinstance(dispatcher._cache, _pipeline._KernelCache) and stamp[1] == _pipeline.SOURCE_DIGEST


def test_no_cache_file_is_written_by_two_compiling_processes():
    """Processes that compile different widths at once write only their entries' caches, one per entry: the chunk
    integrator shared by a width's two entries, whose copies of every width would share one cache index, keeps
    none of its own (it is linked into each entry's cached code)."""
    from numba.core.caching import NullCache

    assert isinstance(_kernel._run_chunk_shared._cache, NullCache)
    paths = [runner._cache._cache_file._index_path for runner in _kernel._RUNNERS.values()]
    assert len(set(paths)) == len(_kernel._RUNNERS)


def test_jobs_send_each_width_to_a_worker_and_load_the_rest_here(monkeypatch):
    """With jobs > 1 the widths to compile go to the workers, one row first, then the widest, a width's serial
    entry before its parallel one; with ``load`` every entry this process lacks is then loaded here from the
    cache, numbered after the workers' entries."""
    missing = {(False, 4), (True, 4), (False, 8), (True, 1)}
    monkeypatch.setattr(_kernel, "is_loaded", lambda key, sig: key not in missing | {(False, 6)})
    monkeypatch.setattr(_kernel, "is_cached", lambda key, sig: key not in missing)
    loaded, sent = [], []
    monkeypatch.setattr(_kernel, "build", lambda key, sig: loaded.append(key))
    monkeypatch.setattr(kernels, "_compile_in_workers",
                        lambda groups, jobs, total, progress: sent.append((groups, jobs, total)))
    events = []
    built = kernels.compile_kernels([1, 4, 6, 8], progress=events.append, load=True, jobs=4)
    assert sorted(built) == sorted(KernelEntry(*k) for k in missing)
    assert loaded == [(True, 1), (False, 4), (True, 4), (False, 6), (False, 8)]
    groups = [[KernelEntry(True, 1)], [KernelEntry(False, 8)], [KernelEntry(False, 4), KernelEntry(True, 4)]]
    assert sent == [(groups, 3, 9)]
    assert [(e.index, e.total, e.from_cache) for e in events[::2]] == [(i, 9, True) for i in range(5, 10)]
    assert kernels.compile_kernels([1, 4, 6, 8], jobs=4) == sorted(built, key=lambda e: (e.width, e.parallel))
    assert len(sent) == 2 and len(loaded) == 5  # without load: nothing loaded here
    with pytest.raises(ValueError, match="jobs must be an integer >= 1"):
        kernels.compile_kernels([4], jobs=0)


def test_a_failed_worker_leaves_the_rest_to_this_process(monkeypatch):
    """A worker that cannot start or dies is no dead end: a warning says so, and what is still missing compiles
    in this process."""
    missing = {(False, 4), (False, 8)}
    monkeypatch.setattr(_kernel, "is_loaded", lambda key, sig: key not in missing)
    monkeypatch.setattr(_kernel, "is_cached", lambda key, sig: key not in missing)
    built = []

    def build(key, sig):
        built.append(key)
        missing.discard(key)

    def fail(groups, jobs, total, progress):
        build((False, 8), None)  # one worker finished its width before the other failed
        raise RuntimeError("compiling the pass kernel for serial chunks of 4 rows in a worker process failed")

    monkeypatch.setattr(_kernel, "build", build)
    monkeypatch.setattr(kernels, "_compile_in_workers", fail)
    with pytest.warns(RuntimeWarning, match="chunks of 4 rows in a worker process failed; compiling what is missing"):
        assert kernels.compile_kernels([4, 8], jobs=2) == [KernelEntry(False, 4), KernelEntry(False, 8)]
    assert built == [(False, 8), (False, 4)] and not missing


def test_workers_compile_or_load_in_their_own_processes():
    """The worker pool itself (spawned processes, each building its group; here entries already in the cache, so
    each worker only loads them): a start and an end for every entry, with the worker's time."""
    events = []
    groups = [[KernelEntry(False, 6)], [KernelEntry(False, 1)]]
    kernels._compile_in_workers(groups, 2, 2, events.append)
    starts = [(e.index, e.entry) for e in events if e.seconds is None]
    ends = [(e.index, e.entry) for e in events if e.seconds is not None]
    assert starts == [(1, KernelEntry(False, 6)), (2, KernelEntry(False, 1))] and sorted(ends) == starts
    assert all(e.total == 2 for e in events) and all(e.seconds >= 0 for e in events if e.seconds is not None)


def test_physics_compiles_without_printing(capsys):
    kernels.compile_kernels([1])
    kernels.missing_kernels()
    assert capsys.readouterr() == ("", "")
    assert np.isfinite(simulate_pass(Track.seed(), Wheelset.seed(), 20.0, x_start=10.0, x_end=10.5).contact_force).all()
