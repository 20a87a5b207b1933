"""Independent batches of passes side by side (:func:`~trackenv.physics.dynamics.simulate_pass_batches`): each
batch's results are those of its call alone, bit for bit; the kernels run at once while the Python side stays
one thread at a time; a one-row store of kept factors is never written by two kernels at once."""

from __future__ import annotations

import threading

import numba
import numpy as np
import pytest

from trackenv.physics import _side_by_side, dynamics
from trackenv.physics.dynamics import simulate_pass_batches, simulate_passes
from trackenv.physics.track import Track
from trackenv.physics.vehicle import Wheelset

V80, V120 = 80 / 3.6, 120 / 3.6
LOADED = Wheelset(mass=1800.0, static_load=100e3)
LIGHT = Wheelset(mass=1500.0, static_load=70e3)
FIELDS = ("contact_force", "rail_displacement", "sleeper_force", "pad_plus_ballast_force", "bay_contact_force")


def _level(seed: int, n: int) -> np.ndarray:
    return 5e-4 * np.random.default_rng(seed).standard_normal(n)


def _batches() -> list[dict]:
    """Three small batches (two vehicles, two speeds, one and three rows) and one of more rows than run side by
    side."""
    t = Track.seed()
    soft = [t.scaled(ballast_stiffness=f) for f in (0.5, 0.8, 1.2)]  # other windows: groups of their own
    n = t.n_sleepers
    return [
        dict(tracks=soft, vehicle=LOADED, speed=V80, support_settlement=np.abs(np.stack([_level(s, n) for s in
                                                                                          range(3)])), dt=4e-4),
        dict(tracks=t, vehicle=LIGHT, speed=V120, irregularities=[_level(7, n)], dt=4e-4),
        dict(tracks=soft[:2], vehicle=LIGHT, speed=V80, irregularities=[_level(8, n), _level(9, n)], dt=4e-4),
        dict(tracks=[t] * (_side_by_side.SIDE_BY_SIDE_MAX_ROWS + 2), vehicle=LOADED, speed=V80, dt=4e-4,
             support_settlement=np.abs(np.stack([_level(10 + s, n) for s in range(10)]))),
    ]


def _assert_same(got: list, want: list) -> None:
    assert len(got) == len(want)
    for g, w in zip(got, want, strict=True):
        for name in FIELDS:
            assert np.array_equal(getattr(g, name), getattr(w, name)), name


def test_each_batch_gives_its_own_calls_results_bit_for_bit():
    batches = _batches()
    alone = [simulate_passes(**b) for b in batches]
    for _ in range(3):  # the kept factors and track arrays are warm from the second round on
        side_by_side = simulate_pass_batches(batches)
        for got, want in zip(side_by_side, alone, strict=True):
            _assert_same(got, want)


def test_small_batches_run_in_pool_threads_on_their_share_of_the_cores_the_large_ones_alone():
    seen = []

    def run(job):
        seen.append((job, threading.current_thread().name, numba.get_num_threads()))
        return job

    jobs = [3, 12, 1, 8]
    assert _side_by_side.run_side_by_side(jobs, run, rows=lambda job: job, threads=2) == jobs
    where = {job: (name, threads) for job, name, threads in seen}
    assert where[12] == (threading.current_thread().name, numba.get_num_threads())  # alone, every thread
    for job in (3, 1, 8):
        assert where[job][0].startswith("trackenv-passes") and where[job][1] == 1
    seen.clear()
    assert _side_by_side.run_side_by_side(jobs, run, rows=lambda job: job, threads=1) == jobs
    assert [job for job, _, _ in seen] == jobs and {name for _, name, _ in seen} == {threading.current_thread().name}


def test_the_kernels_run_at_once_and_a_one_row_store_is_never_shared(monkeypatch):
    """Two one-row passes over one track at one dt would keep their window factors in one store. Side by side,
    each thread's kernel waits at a barrier for the other's: both reach it only if the Python side lets the
    second thread set up while the first one's kernel runs. Exactly one of them gets the store; the other
    computes its factors afresh, and both give their sequential results."""
    if numba.get_num_threads() < 2:
        pytest.skip("side by side needs two numba threads")
    t = Track.seed()
    batches = [dict(tracks=t, vehicle=LOADED, speed=V80, irregularities=[_level(s, t.n_sleepers)], dt=4e-4)
               for s in (1, 2)]
    dynamics._kept_factors.cache_clear()
    want = [simulate_passes(**b) for b in batches]
    store = dynamics._one_row_reuse(t, 4e-4, np.zeros(1), np.zeros(1, dtype=np.int64), dynamics.window_margin(t))
    assert store is not dynamics._NO_REUSE
    real_run, barrier, handed = dynamics._kernel.run, threading.Barrier(2, timeout=60), []

    def run_at_once(mesh, drive, rows, peaks, reuse, width):
        handed.append(reuse)
        barrier.wait()  # BrokenBarrierError if the other thread cannot reach its kernel meanwhile
        real_run(mesh, drive, rows, peaks, reuse, width)

    monkeypatch.setattr(dynamics._kernel, "run", run_at_once)
    got = simulate_pass_batches(batches)
    assert sorted(r is store for r in handed) == [False, True]
    assert not _side_by_side._STORES_IN_USE
    for g, w in zip(got, want, strict=True):
        _assert_same(g, w)


def test_a_bad_batch_raises_its_own_error():
    batches = _batches()[:3]
    batches[1] = {**batches[1], "speed": -1.0}
    with pytest.raises(ValueError, match="speed"):
        simulate_pass_batches(batches)


def test_the_python_side_is_reentrant_within_a_thread():
    done = threading.Event()

    def nested():
        with _side_by_side.python_side(), _side_by_side.python_side():
            pass
        with _side_by_side.python_side():
            done.set()

    worker = threading.Thread(target=nested)
    worker.start()
    worker.join(timeout=30)
    assert done.is_set() and not _side_by_side._LOCK.locked()


def _in_child(batches, queue) -> None:
    queue.put([[r.sleeper_force for r in res] for res in simulate_pass_batches(batches)])


def test_a_forked_child_runs_batches_side_by_side_with_pool_threads_of_its_own():
    """The parent's pool threads are not in a forked child (and a lock one held there would stay held): the child
    starts its own and gets the parent's numbers."""
    import multiprocessing

    batches = _batches()[1:3]
    want = [[r.sleeper_force for r in res] for res in simulate_pass_batches(batches)]  # the parent's pool is up
    context = multiprocessing.get_context("fork")
    queue = context.Queue()
    child = context.Process(target=_in_child, args=(batches, queue))
    child.start()
    got = queue.get(timeout=120)
    child.join(timeout=60)
    assert child.exitcode == 0
    for g, w in zip(got, want, strict=True):
        assert all(np.array_equal(a, b) for a, b in zip(g, w, strict=True))
