"""Where a time step of the compiled kernel goes: processor cycles per section, from counters read inside the kernel.

Sampling profilers do not help here: the kernel is one JIT-compiled function with everything inlined, this VM
has no hardware performance counters, and ``perf`` sees the JIT code without symbols. So this script makes a copy
of ``trackenv/physics/_step.py`` (the time step) with a cycle counter (LLVM's ``readcyclecounter``, the x86 TSC) read at
every section header of the time-step loop — the comment lines ``# ---- <name>`` of ``_run_chunk`` — and adds up
the cycles between consecutive headers. The track's predictor and corrector on a window (mass product, damping,
triangular sweeps; correction, Newmark update, peak sleeper forces) are functions of their own, each one section.
Reading the counter costs a few cycles per section (the totals come out ~1-3 % above the plain kernel's); it does
not change the arithmetic, so the copy's results are the kernel's.

Give several time-step files (``--kernel A --kernel B``, e.g. an older commit's ``_step.py`` from ``git show``) to
compare them: their passes alternate in one process, so a drifting machine moves both alike, which is what makes
the comparison fair on a shared machine (whole-process timings of this VM drift by ±15 % within minutes).

    python experiments/kernel_profile.py                       # one row: the env's 60 m pass at the auto dt
    python experiments/kernel_profile.py --rows 16 --repeats 3  # a 16-row chunk in lockstep (per row)
    python experiments/kernel_profile.py --kernel old_step.py --kernel trackenv/physics/_step.py

Workload: the passes of the 60 m track's steps (``rows`` episodes of ``trackenv/Tamping-v1``: 60 m with
approach and exit zones, 100 km/h, dt 4e-4, one wheelset), on one thread. Cycles are TSC cycles, which tick at
the processor's nominal clock, not its actual one (2.0 GHz on the Zen 1 VM of the earlier rounds, 2.6 GHz on the
Xeon VM of the fifth): compare figures taken on one machine. Each copy compiles on its own (~40-60 s cold; no
on-disk cache). A copy is imported as a module of ``trackenv.physics``, so that its relative imports (the lane
intrinsics, the compile pipeline) resolve to this tree's.
"""

from __future__ import annotations

import argparse
import importlib.util
import re
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
KERNEL = ROOT / "trackenv" / "physics" / "_step.py"
HEADER = re.compile(r"^(\s+)# ---- (.*)$")
COUNTER = '''
from llvmlite import ir as _ir
from numba.core import cgutils as _cgutils
from numba.core import types as _types
from numba.extending import intrinsic as _intrinsic


@_intrinsic
def _cycles(typingctx):
    """The processor's cycle counter (x86: RDTSC)."""
    def codegen(context, builder, signature, args):
        fn = _cgutils.get_or_insert_function(builder.module, _ir.FunctionType(_ir.IntType(64), []),
                                             "llvm.readcyclecounter")
        return builder.call(fn, [])
    return _types.uint64(), codegen

'''


def instrument(source: str) -> tuple[str, list[str]]:
    """The kernel's source with a cycle counter at every section header of ``_run_chunk``'s time-step loop, and
    the sections' names (the first is the step's start, before the first header)."""
    lines = source.replace("cache=True", "cache=False").splitlines()
    start = next(i for i, s in enumerate(lines) if s.startswith("def _run_chunk("))
    lines[start] = lines[start].replace("ch, W):", "ch, W, prof):")
    loop = next(i for i in range(start, len(lines)) if lines[i].strip().startswith("for step in range("))
    indent = len(lines[loop]) - len(lines[loop].lstrip())
    def outside(line: str) -> bool:  # a non-blank line at or left of the loop's indentation ends its body
        return bool(line.strip()) and len(line) - len(line.lstrip()) <= indent

    end = next((i for i in range(loop + 1, len(lines)) if outside(lines[i])), len(lines))
    while not lines[end - 1].strip():
        end -= 1
    names = ["start of step (axle positions)"]
    out = lines[:loop] + [" " * indent + "_tp = _cycles()"]
    for i in range(loop, end):
        m = HEADER.match(lines[i])
        if m:
            out.append(f"{m.group(1)}_t = _cycles(); prof[{len(names) - 1}] += _t - _tp; _tp = _t")
            names.append(m.group(2).strip())
        out.append(lines[i])
    out.append(" " * (indent + 4) + f"_t = _cycles(); prof[{len(names) - 1}] += _t - _tp; _tp = _t")
    out += lines[end:]
    if len(names) == 1:
        raise ValueError("no '# ---- <name>' section headers found in _run_chunk's time-step loop")
    text = "\n".join(out) + "\n"
    first = text.index("\nB = ")  # the counter goes after the imports, before the module's constants
    return text[:first] + "\n" + COUNTER + text[first:], names


def load(path: Path, tag: str, workdir: Path):
    """Import an instrumented copy of the kernel at ``path`` as module ``tag``; returns (module, names)."""
    text, names = instrument(path.read_text())
    copy = workdir / f"{tag}.py"
    copy.write_text(text)
    name = f"trackenv.physics.{tag}"  # a module of the package: its relative imports resolve
    spec = importlib.util.spec_from_file_location(name, copy)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module, names


def runner(module, width: int):
    """A compiled entry that runs every chunk of the batch through ``module``'s instrumented chunk integrator."""
    from numba import njit

    from trackenv.physics._pipeline import _WideCompiler

    chunk = module._run_chunk
    # compiled as the kernel compiles its chunk integrator: several rows through the kernel's wide-vector pipeline,
    # one row (the single pass's entry) by numba's default
    options = {"pipeline_class": getattr(module, "_WideCompiler", _WideCompiler)} if width > 1 else {}

    if hasattr(module, "Reuse"):  # a kernel that keeps window factors across passes

        @njit(fastmath=module.FASTMATH, **options)
        def run(mesh, drive, rows, peaks, reuse, prof):
            for ch in range(rows.u.shape[0]):
                chunk(mesh, drive, rows, peaks, reuse, ch, width, prof)

    else:  # an older kernel file

        @njit(fastmath=module.FASTMATH, **options)
        def run(mesh, drive, rows, peaks, reuse, prof):
            for ch in range(rows.u.shape[0]):
                chunk(mesh, drive, rows, peaks, ch, width, prof)

    return run


def own_store(reuse, stores: dict):
    """A kernel's own copy of the pass's store of kept window factors (empty at first), so that kernels compared
    in one process do not read each other's."""
    key = id(reuse)
    if key not in stores:
        stores[key] = type(reuse)(*(np.full_like(a, -1) if a.dtype.kind == "i" else np.zeros_like(a) for a in reuse))
    return stores[key]


def main(argv: list[str] | None = None) -> None:
    from trackenv.physics._kernel import WIDTHS  # the widths the kernel is compiled for

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--kernel", action="append", type=Path, help="kernel file(s) (default: this tree's)")
    parser.add_argument("--rows", type=int, default=1, choices=WIDTHS, help="rows in lockstep (a chunk)")
    parser.add_argument("--repeats", type=int, default=7, help="passes per kernel (alternating)")
    args = parser.parse_args(argv)
    if args.repeats < 1:
        parser.error(f"--repeats must be >= 1, got {args.repeats}")
    kernels = args.kernel or [KERNEL]

    import numba

    import trackenv.physics._kernel as K
    from trackenv.envs import scenario
    from trackenv.envs.line_episode import LineBatch

    numba.set_num_threads(1)
    with tempfile.TemporaryDirectory() as tmp:
        loaded = [load(p, f"_kernel_profile_{i}", Path(tmp)) for i, p in enumerate(kernels)]
        names = loaded[0][1]
        if any(n != names for _, n in loaded):
            raise SystemExit("the kernels' section headers differ; compare kernels with the same sections")
        runs = [runner(mod, args.rows) for mod, _ in loaded]
        counts = [np.zeros(len(names), dtype=np.uint64) for _ in kernels]
        stores: list[dict] = [{} for _ in kernels]
        steps = {}
        current = [0]

        def run(mesh, drive, rows, peaks, reuse, width):
            if width != args.rows:
                raise SystemExit(f"the batch ran at width {width}, not {args.rows}")
            steps["n"] = drive.x_axle.shape[0] - 1
            k = current[0]
            runs[k](mesh, drive, rows, peaks, own_store(reuse, stores[k]), counts[k])

        K.run = run  # simulate_passes calls _kernel.run at run time
        engine = LineBatch(scenario("track60"), args.rows)
        every = np.ones(args.rows * engine.config.n_sections, dtype=bool)
        for k in range(len(kernels)):  # compile, and the episodes' first passes (not counted)
            current[0] = k
            engine.start(list(range(args.rows)), [np.random.default_rng(i) for i in range(args.rows)])
            counts[k][:] = 0
        for _ in range(args.repeats):
            for k in range(len(kernels)):
                current[0] = k
                engine.traffic_rows(every, 0)  # a step's pass (and its settlement, which is not the kernel's)
    per = [c.astype(float) / (args.repeats * steps["n"] * args.rows) for c in counts]
    labels = [str(p) if len(str(p)) < 28 else "…" + str(p)[-27:] for p in kernels]
    print(f"cycles per time step and row, {args.rows} row(s) in lockstep, {steps['n']} steps per pass, "
          f"{args.repeats} passes per kernel (alternating)")
    print(f"{'section':52s}" + "".join(f"{s:>30s}" for s in labels))
    for i, name in enumerate(names):
        print(f"{name[:52]:52s}" + "".join(f"{p[i]:30.0f}" for p in per))
    print(f"{'total':52s}" + "".join(f"{p.sum():30.0f}" for p in per))


if __name__ == "__main__":
    main()
