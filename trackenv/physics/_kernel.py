"""The kernel's compiled entries, one per (serial or parallel, chunk width), and the call that picks one.

A batch is cut into chunks of ``width`` rows (one of :data:`WIDTHS`), and each chunk is integrated over the pass
by :func:`trackenv.physics._step._run_chunk`. The width is a compile-time constant in each entry, so that the loops
over a chunk's rows have a known trip count; the serial entries run the chunks on the calling thread, the parallel
ones spread them over numba's threads. The entries are written out, not generated, so that numba's on-disk cache
keeps each one (:func:`trackenv.physics._pipeline.kernel_jit`).

The serial one-row entry, the single pass, inlines the chunk integrator; every other entry calls the copy of its
width (:func:`_run_chunk_shared`), compiled once per width and process through the wide-vector pipeline, so that a
width's serial and parallel entries share its compile time. That copy is linked into each entry's cached code and
is not cached on its own: its copies of all widths would share one cache index, which processes compiling
different widths at once (``trackenv compile``'s workers) would each rewrite; the entries' own caches are one per
entry and never shared.
"""

from __future__ import annotations

import numpy as np
from numba import literally, njit, prange

from ._pipeline import FASTMATH, _WideCompiler, kernel_jit
from ._step import _run_chunk

# rows per chunk the kernel is compiled for; 6: the line env's 12 segments on two threads run as two chunks of 6
WIDTHS = (1, 4, 6, 8, 16)


@njit(fastmath=FASTMATH, pipeline_class=_WideCompiler)  # not cached on its own: see the module's docstring
def _run_chunk_shared(mesh, drive, rows, peaks, reuse, ch, W):
    """:func:`_run_chunk` compiled once per width ``W`` (a literal, so a compile-time constant in each compiled
    copy) and called by both the serial and the parallel entry of that width. ``ch`` is int64 from either entry
    (prange's index is unsigned), so that both share one compiled copy."""
    literally(W)
    _run_chunk(mesh, drive, rows, peaks, reuse, ch, W)


@kernel_jit(fastmath=FASTMATH, nogil=True)
def _serial_1(mesh, drive, rows, peaks, reuse):
    for ch in range(rows.u.shape[0]):
        _run_chunk(mesh, drive, rows, peaks, reuse, ch, 1)


@kernel_jit(fastmath=FASTMATH, nogil=True)
def _serial_4(mesh, drive, rows, peaks, reuse):
    for ch in range(rows.u.shape[0]):
        _run_chunk_shared(mesh, drive, rows, peaks, reuse, ch, 4)


@kernel_jit(fastmath=FASTMATH, nogil=True)
def _serial_6(mesh, drive, rows, peaks, reuse):
    for ch in range(rows.u.shape[0]):
        _run_chunk_shared(mesh, drive, rows, peaks, reuse, ch, 6)


@kernel_jit(fastmath=FASTMATH, nogil=True)
def _serial_8(mesh, drive, rows, peaks, reuse):
    for ch in range(rows.u.shape[0]):
        _run_chunk_shared(mesh, drive, rows, peaks, reuse, ch, 8)


@kernel_jit(fastmath=FASTMATH, nogil=True)
def _serial_16(mesh, drive, rows, peaks, reuse):
    for ch in range(rows.u.shape[0]):
        _run_chunk_shared(mesh, drive, rows, peaks, reuse, ch, 16)


@kernel_jit(parallel=True, fastmath=FASTMATH, nogil=True)
def _parallel_1(mesh, drive, rows, peaks, reuse):
    for ch in prange(rows.u.shape[0]):
        _run_chunk_shared(mesh, drive, rows, peaks, reuse, np.int64(ch), 1)


@kernel_jit(parallel=True, fastmath=FASTMATH, nogil=True)
def _parallel_4(mesh, drive, rows, peaks, reuse):
    for ch in prange(rows.u.shape[0]):
        _run_chunk_shared(mesh, drive, rows, peaks, reuse, np.int64(ch), 4)


@kernel_jit(parallel=True, fastmath=FASTMATH, nogil=True)
def _parallel_6(mesh, drive, rows, peaks, reuse):
    for ch in prange(rows.u.shape[0]):
        _run_chunk_shared(mesh, drive, rows, peaks, reuse, np.int64(ch), 6)


@kernel_jit(parallel=True, fastmath=FASTMATH, nogil=True)
def _parallel_8(mesh, drive, rows, peaks, reuse):
    for ch in prange(rows.u.shape[0]):
        _run_chunk_shared(mesh, drive, rows, peaks, reuse, np.int64(ch), 8)


@kernel_jit(parallel=True, fastmath=FASTMATH, nogil=True)
def _parallel_16(mesh, drive, rows, peaks, reuse):
    for ch in prange(rows.u.shape[0]):
        _run_chunk_shared(mesh, drive, rows, peaks, reuse, np.int64(ch), 16)


_RUNNERS = {
    (False, 1): _serial_1,
    (False, 4): _serial_4,
    (False, 6): _serial_6,
    (False, 8): _serial_8,
    (False, 16): _serial_16,
    (True, 1): _parallel_1,
    (True, 4): _parallel_4,
    (True, 6): _parallel_6,
    (True, 8): _parallel_8,
    (True, 16): _parallel_16,
}


def run(mesh, drive, rows, peaks, reuse, width: int) -> None:
    """Integrate every chunk of the batch (``width`` rows each, one of :data:`WIDTHS`), filling the arrays in
    place: on the calling thread for one chunk, else the chunks spread over numba's threads. Rows without
    ``ends`` (None) get clamped ends (zeros)."""
    if rows.ends is None:
        n_sleepers = rows.pad_k.shape[1]
        rows = rows._replace(ends=np.zeros((rows.u.shape[0], n_sleepers, 6, width)))
    _RUNNERS[(rows.u.shape[0] > 1, width)](mesh, drive, rows, peaks, reuse)


def is_loaded(entry: tuple[bool, int], signature: tuple) -> bool:
    """Whether ``entry`` holds machine code for ``signature`` in this process."""
    return tuple(signature) in _RUNNERS[entry].overloads


def is_cached(entry: tuple[bool, int], signature: tuple) -> bool:
    """Whether numba's on-disk cache holds ``entry`` for ``signature``, this kernel's source and this processor
    (reads the entry's cache index only; loads nothing)."""
    dispatcher = _RUNNERS[entry]
    cache = dispatcher._cache
    key = cache._index_key(tuple(signature), dispatcher.targetctx.codegen())
    return key in cache._cache_file._load_index()


def build(entry: tuple[bool, int], signature: tuple) -> None:
    """Compile ``entry`` for ``signature``, or load it from numba's on-disk cache where it is there."""
    _RUNNERS[entry].compile(tuple(signature))
