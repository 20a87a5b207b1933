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
) -> list[KernelEntry]:
    """Build every reachable entry for ``widths`` (default: all) that a call would compile, and return them.

    With ``load`` the entries already in numba's on-disk cache are loaded into this process too (cheap), so that
    no later call in it pays even that. ``progress`` is called with a :class:`CompileProgress` as each entry starts
    and as it is done. Compiling every entry takes several minutes of one core on a fresh install; entries of one
    width share most of it (the parallel entry reuses the serial one's chunk integrator)."""
    return build_entries(kernel_entries(widths), progress, load=load)


def build_entries(
    entries: Iterable[KernelEntry],
    progress: Callable[[CompileProgress], None] | None = None,
    *,
    load: bool = False,
) -> list[KernelEntry]:
    """:func:`compile_kernels` for a list of entries."""
    signature = _signature()
    todo = [(e, _kernel.is_cached((e.parallel, e.width), signature)) for e in entries
            if not _kernel.is_loaded((e.parallel, e.width), signature)]
    if not load:
        todo = [(e, cached) for e, cached in todo if not cached]
    for index, (entry, cached) in enumerate(todo, start=1):
        if progress is not None:
            progress(CompileProgress(entry, index, len(todo), cached))
        began = time.perf_counter()
        _kernel.build((entry.parallel, entry.width), signature)
        if progress is not None:
            progress(CompileProgress(entry, index, len(todo), cached, time.perf_counter() - began))
    return [e for e, cached in todo if not cached]


@functools.lru_cache(maxsize=1)
def _signature() -> tuple:
    """The argument types of every entry (the same for all widths): those of a pass's kernel arguments."""
    from .dynamics import kernel_arguments

    return tuple(numba.typeof(x) for x in kernel_arguments())
