"""How the time-stepping kernel is compiled: numba's nopython pipeline with two changes, and its on-disk cache.

* :class:`_WideCompiler` lowers a function with LLVM's preference for 512-bit vectors where the processor has
  them (:class:`_WideLower`): the loops across a chunk's rows then issue half the instructions.
* :class:`_NoAliasCompiler` marks the pointers among a function's arguments ``noalias``: LLVM may then drop the
  run-time overlap checks it puts around every short loop across a chunk's rows.
* :class:`_InlineCompiler` marks a function ``alwaysinline``: the time step's sections are functions of their
  own, inlined by LLVM, without the reference counting that numba's own inlining adds.

Neither changes the arithmetic (see :data:`FASTMATH`). :func:`kernel_jit` compiles a kernel function with numba's
on-disk cache keyed by the source of *every* kernel module, not only the function's own file: numba's cache
checks only the file that defines a function, so an entry in one module that inlines code from another would
otherwise load stale machine code after that other module changed.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import llvmlite.binding as ll
from numba import njit
from numba.core import config as numba_config
from numba.core import types
from numba.core.caching import CompileResultCacheImpl, FunctionCache
from numba.core.compiler import CompilerBase, DefaultPassBuilder
from numba.core.compiler_machinery import register_pass
from numba.core.lowering import Lower
from numba.core.typed_passes import NativeLowering

# Floating-point freedoms that do not make a row depend on its SIMD lane, width or compiled copy: no NaN/inf/-0
# bookkeeping only. Never reassociation or approximate reciprocals, and no fused multiply-adds left to the compiler
# ("contract"): LLVM would fuse where it chooses, differently in each compiled copy, and a row's result would
# depend on the batch it runs in. Where a fused multiply-add pays, the kernel writes it out (``_lanes._fma``).
FASTMATH = {"nnan", "ninf", "nsz"}

# Intel's first AVX-512 server cores (and the Xeon Phi), whose clock drops under sustained 512-bit arithmetic
_NARROW_CPUS = frozenset({"skylake-avx512", "cascadelake", "cooperlake", "knl", "knm"})
# the processor numba compiles for (NUMBA_CPU_NAME overrides the host)
_HOST_CPU = getattr(numba_config, "CPU_NAME", None) or ll.get_host_cpu_name()

# the kernel's modules: a change to any of them invalidates every cached kernel function
KERNEL_MODULES = ("_pipeline.py", "_lanes.py", "_step.py", "_kernel.py")


def _source_digest() -> bytes:
    here = Path(__file__).resolve().parent
    digest = hashlib.sha256()
    for name in KERNEL_MODULES:
        digest.update(name.encode())
        digest.update((here / name).read_bytes())
    return digest.digest()


SOURCE_DIGEST = _source_digest()


class _WideLower(Lower):
    """numba's lowering, with the function marked for LLVM to prefer vectors of 512 bits where the processor has
    them (function attribute ``prefer-vector-width``). LLVM's tuning for Intel processors with AVX-512 prefers
    256-bit vectors; the kernel's loops across a chunk's 16 rows are then four instructions per operation instead
    of two. Lanes do the same IEEE operations at any vector width, so results do not change. A function whose last
    argument is the chunk width W = 1 is left as LLVM tunes it (one row's loops run along a short window, where
    512-bit vectors are slower), and so is every function on the processors whose clock drops under sustained
    512-bit arithmetic (:data:`_NARROW_CPUS`), the reason for LLVM's preference."""

    def lower_normal_function(self, fndesc):
        super().lower_normal_function(fndesc)
        width = fndesc.argtypes[-1] if fndesc.argtypes else None
        if _HOST_CPU in _NARROW_CPUS or (isinstance(width, types.IntegerLiteral) and width.literal_value == 1):
            return
        # llvmlite's attribute set accepts only LLVM's keyword attributes; a string attribute is written as is
        set.add(self.function.attributes, '"prefer-vector-width"="512"')


@register_pass(mutates_CFG=True, analysis_only=False)
class _WideNativeLowering(NativeLowering):
    """numba's lowering pass, through :class:`_WideLower`."""

    _name = "trackenv_wide_native_lowering"

    @property
    def lowering_class(self):
        return _WideLower


def _wide_pipeline(state):
    """numba's nopython pipeline with its lowering pass replaced by :class:`_WideNativeLowering`."""
    pm = DefaultPassBuilder.define_nopython_pipeline(state)
    pm.passes = [(_WideNativeLowering if p is NativeLowering else p, d) for p, d in pm.passes]
    return pm


class _WideCompiler(CompilerBase):
    """numba's nopython pipeline, lowered by :class:`_WideLower`."""

    def define_pipelines(self):
        return [_wide_pipeline(self.state)]


class _NoAliasCompiler(CompilerBase):
    """numba's nopython pipeline with its ``noalias`` flag on: every pointer among the function's arguments (an
    array's data, a namedtuple's arrays) is marked ``noalias`` for LLVM, the promise that memory written through
    one argument is not read or written through another during the call. numba cannot know this of arrays, and
    without it LLVM guards each short loop across a chunk's rows with run-time overlap checks (more instructions
    per DOF than the DOF's arithmetic at 4 to 16 rows). The functions compiled with it are called with distinct
    arrays only: the kernel's inputs, outputs and workspaces are each their own allocation (tested). numba has
    no decorator option for the flag, so it is set through its custom-pipeline hook (``pipeline_class``). It
    changes what LLVM may assume, not the arithmetic. Lowered by :class:`_WideLower`."""

    def define_pipelines(self):
        self.state.flags.noalias = True
        return [_wide_pipeline(self.state)]


class _InlineLower(_WideLower):
    """:class:`_WideLower`, with the function marked ``alwaysinline`` for LLVM: the caller's machine code is then
    the same as with the function's body written out in it. numba's own inlining (``inline="always"``) works on its
    IR, where each array handed to the inlined function is a new reference: atomic reference-count updates at every
    call, which in the time-step loop cost more than the arithmetic. A call between compiled functions borrows its
    array arguments (no update), and LLVM then removes the call itself."""

    def lower_normal_function(self, fndesc):
        super().lower_normal_function(fndesc)
        self.function.attributes.add("alwaysinline")


@register_pass(mutates_CFG=True, analysis_only=False)
class _InlineNativeLowering(NativeLowering):
    """numba's lowering pass, through :class:`_InlineLower`."""

    _name = "trackenv_inline_native_lowering"

    @property
    def lowering_class(self):
        return _InlineLower


def _inline_pipeline(state):
    """numba's nopython pipeline with its lowering pass replaced by :class:`_InlineNativeLowering`."""
    pm = DefaultPassBuilder.define_nopython_pipeline(state)
    pm.passes = [(_InlineNativeLowering if p is NativeLowering else p, d) for p, d in pm.passes]
    return pm


class _InlineCompiler(CompilerBase):
    """numba's nopython pipeline, lowered by :class:`_InlineLower`: for the time step's sections, compiled apart
    (each for a literal width) and inlined by LLVM into the chunk integrator."""

    def define_pipelines(self):
        return [_inline_pipeline(self.state)]


class _NoAliasInlineCompiler(CompilerBase):
    """:class:`_NoAliasCompiler`'s promise of distinct arrays, lowered by :class:`_InlineLower` (LLVM keeps the
    promise as alias metadata where it inlines the function)."""

    def define_pipelines(self):
        self.state.flags.noalias = True
        return [_inline_pipeline(self.state)]


class _CalledLower(_WideLower):
    """:class:`_WideLower`, with the function marked ``noinline``: for code that runs rarely, kept out of the time
    step's loop (LLVM inlines a function called from one place, which enlarged the loop and slowed every step)."""

    def lower_normal_function(self, fndesc):
        super().lower_normal_function(fndesc)
        self.function.attributes.add("noinline")


@register_pass(mutates_CFG=True, analysis_only=False)
class _CalledNativeLowering(NativeLowering):
    """numba's lowering pass, through :class:`_CalledLower`."""

    _name = "trackenv_called_native_lowering"

    @property
    def lowering_class(self):
        return _CalledLower


class _CalledCompiler(CompilerBase):
    """numba's nopython pipeline, lowered by :class:`_CalledLower`."""

    def define_pipelines(self):
        pm = DefaultPassBuilder.define_nopython_pipeline(self.state)
        pm.passes = [(_CalledNativeLowering if p is NativeLowering else p, d) for p, d in pm.passes]
        return [pm]


class _KernelStamp:
    """A cache locator whose source stamp is that of every kernel module (:data:`SOURCE_DIGEST`)."""

    def get_source_stamp(self):
        return (super().get_source_stamp(), SOURCE_DIGEST)


class _KernelCacheImpl(CompileResultCacheImpl):
    _locator_classes: list = [type(f"_Kernel{c.__name__}", (_KernelStamp, c), {})
                              for c in CompileResultCacheImpl._locator_classes]


class _KernelCache(FunctionCache):
    """numba's on-disk function cache, stamped with the source of every kernel module."""

    _impl_class = _KernelCacheImpl


def kernel_jit(**options):
    """``numba.njit(**options)`` with numba's on-disk cache stamped by every kernel module's source (see the
    module's docstring). For the functions that are compiled on their own; those inlined into them need no cache."""

    def decorate(fn):
        dispatcher = njit(**options)(fn)
        dispatcher._cache = _KernelCache(dispatcher.py_func)  # what njit(cache=True) sets, with our stamp
        return dispatcher

    return decorate
