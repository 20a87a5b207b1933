"""Which compiled kernel entries this process has, and building them up front.

Every pass runs on one compiled entry of the time-stepping kernel: serial or parallel, for chunks of ``width`` rows
(one of :data:`WIDTHS`; :func:`entry_for_rows` says which a batch takes). numba compiles an entry the first time
it is called and keeps the machine code in its on-disk cache (next to the package's sources), from which later
processes load it in a fraction of a second. Compiling one takes tens of seconds of one core, so a first call
would block silently. This module lets the layers above ask, cheaply, what is missing
(:func:`missing_kernels`, :func:`kernel_is_compiled`) and build it up front with progress
(:func:`compile_kernels`), so that they can say so before anything blocks. It prints nothing.

    from trackenv.physics.kernels import compile_kernels, missing_kernels
    todo = missing_kernels()
    if todo:
        print(f"compiling {len(todo)} kernel entries (once per install)...")
        compile_kernels(progress=lambda p: print(p))
"""

from __future__ import annotations

import functools
import time
import warnings
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numba
import numpy as np

from . import _kernel

WIDTHS: tuple[int, ...] = _kernel.WIDTHS
"""Rows per chunk the kernel is compiled for."""


@dataclass(frozen=True, order=True)
class KernelEntry:
    """One compiled entry: ``parallel`` (chunks spread over numba's threads) and ``width`` (rows per chunk)."""

    parallel: bool
    width: int

    def __post_init__(self) -> None:
        if self.width not in WIDTHS:
            raise ValueError(f"width must be one of {WIDTHS}, got {self.width!r}")

    def __str__(self) -> str:
        return f"{'parallel' if self.parallel else 'serial'} chunks of {self.width} row{'s' * (self.width > 1)}"


@dataclass(frozen=True)
class CompileProgress:
    """What :func:`compile_kernels` reports: ``entry`` is the ``index``-th (from 1) of ``total`` it builds;
    ``seconds`` is None as it starts and the time it took when it is done; ``from_cache``: whether it is being
    loaded from numba's on-disk cache rather than compiled."""

    entry: KernelEntry
    index: int
    total: int
    from_cache: bool
    seconds: float | None = None

    def __str__(self) -> str:
        verb = "loading" if self.from_cache else "compiling"
        done = "" if self.seconds is None else f" done in {self.seconds:.1f} s"
        return f"[{self.index}/{self.total}] {verb} the pass kernel for {self.entry}{done}"


class KernelCompileWarning(UserWarning):
    """A pass is about to compile an entry of the kernel (tens of seconds, once per install and processor):
    raised so that the wait is never silent; ``trackenv compile`` (``make setup``) builds every entry up front."""


#: The entries a pass has found loaded or cached in this process (checking again would hash the signature's
#: numba types at every pass).
_ANNOUNCED: set[tuple[bool, int]] = set()


def announce_compile(parallel: bool, width: int) -> None:
    """Warn (:class:`KernelCompileWarning`) if the entry a pass is about to run on must be compiled, neither in
    this process nor in numba's on-disk cache; a set lookup once it was found (or announced)."""
    key = (bool(parallel), int(width))
    if key in _ANNOUNCED:
        return
    _ANNOUNCED.add(key)
    signature = _signature()
    if _kernel.is_loaded(key, signature) or _kernel.is_cached(key, signature):
        return
    warnings.warn(f"trackenv: compiling the physics kernel for {KernelEntry(*key)} first (once per install, about "
                  "15-30 s); `trackenv compile` (run by `make setup`) builds every entry up front",
                  KernelCompileWarning, stacklevel=2)


def kernel_entries(widths: Iterable[int] | None = None) -> list[KernelEntry]:
    """The entries for ``widths`` (default: all) that this process can reach: parallel ones only where numba may
    run two threads or more (``NUMBA_NUM_THREADS``)."""
    widths = WIDTHS if widths is None else tuple(widths)
    parallel = (False, True) if numba.config.NUMBA_NUM_THREADS >= 2 else (False,)  # type: ignore[attr-defined]
    return [KernelEntry(p, w) for w in widths for p in parallel]


def entry_for_rows(n_rows: int) -> KernelEntry:
    """The entry a batch of ``n_rows`` rows runs on with numba's current number of threads."""
    from .dynamics import _chunking

    if isinstance(n_rows, bool) or not isinstance(n_rows, (int, np.integer)) or n_rows < 1:
        raise ValueError(f"n_rows must be an integer >= 1, got {n_rows!r}")
    n_chunks, width = _chunking(int(n_rows))
    return KernelEntry(n_chunks > 1, width)


def is_compiled(entry: KernelEntry) -> bool:
    """Whether a call on ``entry`` would not compile: its code is loaded in this process or in numba's on-disk
    cache for this kernel's source and this processor (reads the cache's index; loads nothing)."""
    key, signature = (entry.parallel, entry.width), _signature()
    return _kernel.is_loaded(key, signature) or _kernel.is_cached(key, signature)


def missing_kernels(widths: Iterable[int] | None = None) -> list[KernelEntry]:
    """The reachable entries for ``widths`` (default: all) that a call would have to compile."""
    return [e for e in kernel_entries(widths) if not is_compiled(e)]


def kernel_is_compiled(width: int) -> bool:
    """Whether every reachable entry of ``width`` rows per chunk is compiled (see :func:`is_compiled`)."""
    return not missing_kernels([width])


def compile_kernels(
    widths: Iterable[int] | None = None,
    progress: Callable[[CompileProgress], None] | None = None,
    *,
    load: bool = False,
    jobs: int = 1,
) -> list[KernelEntry]:
    """Build every reachable entry for ``widths`` (default: all) that a call would compile, and return them.

    With ``load`` the entries already in numba's on-disk cache are loaded into this process too (cheap), so that
    no later call in it pays even that. ``progress`` is called with a :class:`CompileProgress` as each entry starts
    and as it is done. Compiling every entry takes several minutes of one core on a fresh install; entries of one
    width share most of it (the parallel entry reuses the serial one's chunk integrator). ``jobs`` > 1 compiles
    the widths in up to that many worker processes at once (:func:`usable_cores` is what the machine offers);
    the code they leave in the cache is the code one process compiles. The workers are started by
    multiprocessing's "spawn", which imports the calling script again: in a script, call it under
    ``if __name__ == "__main__":``."""
    return build_entries(kernel_entries(widths), progress, load=load, jobs=jobs)


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity where the system reports it)."""
    import os

    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def build_entries(
    entries: Iterable[KernelEntry],
    progress: Callable[[CompileProgress], None] | None = None,
    *,
    load: bool = False,
    jobs: int = 1,
) -> list[KernelEntry]:
    """:func:`compile_kernels` for a list of entries."""
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
        raise ValueError(f"jobs must be an integer >= 1, got {jobs!r}")
    entries, signature = list(entries), _signature()
    todo = _to_build(entries, signature, load)
    to_compile = [e for e, cached in todo if not cached]
    groups = _width_groups(to_compile)
    first, total = 1, len(todo)
    if jobs > 1 and len(groups) > 1:  # compiled by worker processes; with ``load`` then loaded here, from the cache
        todo = [(e, True) for e, _ in todo] if load else []
        first, total = len(to_compile) + 1, len(to_compile) + len(todo)
        try:
            _compile_in_workers(groups, min(jobs, len(groups)), total, progress)
        except RuntimeError as error:  # a worker that could not start or died: what it left, compiled here
            warnings.warn(f"{error}; compiling what is missing in this process", RuntimeWarning, stacklevel=3)
            todo = _to_build(entries, signature, load)
            first, total = 1, len(todo)
    for index, (entry, cached) in enumerate(todo, start=first):
        if progress is not None:
            progress(CompileProgress(entry, index, total, cached))
        began = time.perf_counter()
        _kernel.build((entry.parallel, entry.width), signature)
        if progress is not None:
            progress(CompileProgress(entry, index, total, cached, time.perf_counter() - began))
    return to_compile


def _to_build(entries: list[KernelEntry], signature: tuple, load: bool) -> list[tuple[KernelEntry, bool]]:
    """The ``entries`` this process lacks, each with whether numba's on-disk cache holds it; those only cached
    are left out unless ``load``."""
    todo = [(e, _kernel.is_cached((e.parallel, e.width), signature)) for e in entries
            if not _kernel.is_loaded((e.parallel, e.width), signature)]
    return todo if load else [(e, cached) for e, cached in todo if not cached]


def _width_groups(entries: list[KernelEntry]) -> list[list[KernelEntry]]:
    """``entries`` by width, the longest to compile first: one row (its serial entry inlines the chunk integrator,
    so the width compiles it twice), then the widest; serial before parallel within a width (the parallel entry
    reuses the chunk integrator the serial one compiled)."""
    widths = sorted({e.width for e in entries}, key=lambda w: (w != 1, -w))
    return [sorted(e for e in entries if e.width == w) for w in widths]


def _compile_in_workers(groups: list[list[KernelEntry]], jobs: int, total: int,
                        progress: Callable[[CompileProgress], None] | None) -> None:
    """Compile each group of entries (one width) in a worker process, ``jobs`` at a time, into numba's on-disk
    cache (each entry's cache is its own: no two workers write the same file); ``progress`` hears each entry start
    as its group is handed to a worker and end when the group is done."""
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

    numbered, index = [], 1
    for group in groups:
        numbered.append([(index + i, e) for i, e in enumerate(group)])
        index += len(group)
    pending = list(reversed(numbered))
    with ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context("spawn")) as pool:
        running: dict = {}

        def submit() -> None:
            group = pending.pop()
            for i, e in group:
                if progress is not None:
                    progress(CompileProgress(e, i, total, False))
            running[pool.submit(_compile_group, [(e.parallel, e.width) for _, e in group])] = group

        while pending and len(running) < jobs:
            submit()
        while running:
            done, _ = wait(running, return_when=FIRST_COMPLETED)
            for future in done:
                group = running.pop(future)
                try:
                    seconds = future.result()
                except Exception as error:  # a worker that died or failed: say which entries
                    raise RuntimeError(f"compiling the pass kernel for {', '.join(str(e) for _, e in group)} in a "
                                       f"worker process failed: {error!r}") from error
                for (i, e), s in zip(group, seconds, strict=True):
                    if progress is not None:
                        progress(CompileProgress(e, i, total, False, s))
                if pending:
                    submit()


def _compile_group(keys: list[tuple[bool, int]]) -> list[float]:
    """In a worker process: compile each entry (parallel, width) in order into numba's on-disk cache; the
    seconds each took."""
    signature, seconds = _signature(), []
    for key in keys:
        began = time.perf_counter()
        _kernel.build(key, signature)
        seconds.append(time.perf_counter() - began)
    return seconds


@functools.lru_cache(maxsize=1)
def _signature() -> tuple:
    """The argument types of every entry (the same for all widths): those of a pass's kernel arguments."""
    from .dynamics import kernel_arguments

    return tuple(numba.typeof(x) for x in kernel_arguments())
