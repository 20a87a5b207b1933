"""The torch backend of the pass on a GPU: equivalence with the numba kernel, and passes per second.

Two halves, on two machines. Here, with the package installed (numba compiles the kernel):

    python experiments/gpu_passes.py --make-reference REF.npz    # the kernel's inputs and outputs, ~2 MB
    python experiments/gpu_passes.py --cpu-timing --rows 1000      # the numba kernel's passes/s on this CPU

On the device machine (torch, numpy; neither numba nor the package is needed: the torch backend is loaded from
its file alone):

    PYTHONPATH=. python3 experiments/gpu_passes.py --reference REF.npz --out OUT.json [--quick]

The reference holds the kernel's prepared arguments (the packed arrays ``simulate_passes`` hands the kernel) and
the kernel's outputs for a set of cases: the benchmark batch (8 rows of the 60 m track of the environment, 60 m
with 10 sleepers either side, ballast fields and settled supports per row, a 20 t wheelset at 100 km/h,
dt 4e-4 s) and short cases of stiff and soft pads, a voided sleeper, a wheel that leaves the rail, a freight car on
settled supports and a steady start. The device run (a) integrates every case with the torch backend and reports
the largest error against the kernel, relative to each field's largest value; (b) times batches of 1 000, 3 000
and 10 000 rows made by repeating the benchmark rows with a random long-wave rail level added to each (warm-up
first, the median of three); (c) writes the figures, the device and the torch version as JSON and prints a
table. ``--budget-s`` bounds the run: a measurement that would not fit is skipped and says so.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import statistics
import sys
import time
import types
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
MESH = ("node_w", "sleeper_dof", "sleeper_node", "elem_len", "epb", "n_sleepers", "margin_bays", "rail_mass")
DRIVE = ("x_axle", "consts", "law", "param", "mass", "damping", "kv_inv", "force", "wheel_dofs", "cluster_of_axle",
         "n_clusters")
ROWS = ("mass_diag", "keff", "pad_k", "pad_c", "bal_k", "bal_c", "z", "sag", "u", "v", "a", "q", "qd", "qdd")
PEAKS = ("force", "rail", "wheel", "ballast", "total")
BENCH = "bench_60m"
BENCH_ROWS = (1000, 3000, 10000)
LEVEL_AMPLITUDE_M = 3e-4  # the random rail level added to each repeated benchmark row


def load_torch_pass():
    """``trackenv/physics/torch_pass.py`` loaded from its file, without importing the package (whose kernel needs
    numba and whose environments need gymnasium)."""
    path = ROOT / "trackenv" / "physics" / "torch_pass.py"
    spec = importlib.util.spec_from_file_location("trackenv_torch_pass", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # (its dataclasses look their module up)
    spec.loader.exec_module(module)
    return module


# ------------------------------------------------------------------------------------ here: the reference
def reference_cases() -> dict:
    """name -> (tracks, vehicle, speed, irregularities, options) of ``simulate_passes``."""
    from trackenv.physics.track import Track
    from trackenv.physics.vehicle import Car, Wheelset

    g = 9.81
    wheel = Wheelset(mass=1800.0, static_load=20e3 * g / 2 - 900.0 * g)
    loaded = Wheelset(mass=1800.0, static_load=100e3)
    rng = np.random.default_rng(0)
    base = Track.realistic(60.0)
    fields = np.exp(0.1 * rng.standard_normal((8, base.n_sleepers)))
    bench = [base.replace(ballast_stiffness=base.ballast_stiffness * f).extended(10, 10) for f in fields]
    levels = np.abs(1e-3 * np.cumsum(rng.standard_normal((8, bench[0].n_sleepers)), axis=1) / 10)
    short = Track.realistic(36.0)
    rough = 2e-4 * np.sin(np.arange(short.n_sleepers) * 0.9)

    def dip(x, x0=15.0, depth=5e-3, length=1.0):
        s = (np.asarray(x, dtype=float) - x0) / length
        return np.where((s >= 0) & (s <= 1), 0.5 * depth * (1 - np.cos(2 * np.pi * s)), 0.0)

    n = short.n_sleepers
    pads = [short, short.replace(pad_stiffness=np.full(n, 1e9)), short.replace(pad_stiffness=np.full(n, 6e7))]
    return {
        BENCH: (bench, wheel, 100 / 3.6, None, dict(support_settlement=levels, dt=4e-4)),
        "stiff_soft_pads": (pads, loaded, 30.0, rough, dict(x_start=12.0, x_end=16.0, dt=2e-4)),
        "voided_sleeper": (short.with_voided_sleeper(24), loaded, 30.0, rough, dict(x_start=12.0, x_end=16.0,
                                                                                    dt=2e-4)),
        "loses_contact": (short, loaded, 120 / 3.6, dip, dict(x_start=13.0, x_end=17.0)),
        "car_settled": (Track.realistic(30.0), Car.freight_wagon(), 100 / 3.6, None,
                        dict(x_end=24.0, dt=4e-4, support_settlement=np.linspace(0.0, 2e-3, 51))),
        "steady_start": (short, loaded, 30.0, rough, dict(start="steady", x_end=9.0, dt=2e-4)),
    }


def capture_kernel_calls(run_case) -> list[dict]:
    """The kernel's calls during ``run_case()``: each one's arguments before and its outputs after, as arrays."""
    from trackenv.physics import _kernel

    calls: list[dict] = []
    real = _kernel.run

    def recording(mesh, drive, rows, peaks, reuse, width):
        call = {f"mesh/{k}": np.asarray(getattr(mesh, k)) for k in MESH}
        call.update({f"drive/{k}": np.asarray(getattr(drive, k)) for k in DRIVE})
        call.update({f"rows_in/{k}": np.array(getattr(rows, k)) for k in ROWS})
        call.update({f"peaks_in/{k}": np.array(getattr(peaks, k)) for k in PEAKS})
        real(mesh, drive, rows, peaks, reuse, width)
        call.update({f"rows_out/{k}": np.array(getattr(rows, k)) for k in ("z", "u", "v", "a", "q", "qd", "qdd")})
        call.update({f"peaks_out/{k}": np.array(getattr(peaks, k)) for k in PEAKS})
        calls.append(call)

    _kernel.run = recording
    try:
        run_case()
    finally:
        _kernel.run = real
    return calls


def make_reference(path: Path) -> None:
    """Every case's kernel calls, in one .npz (keys ``case/call/part/field``)."""
    from trackenv.physics.dynamics import simulate_passes

    arrays = {}
    for name, (tracks, vehicle, speed, irr, options) in reference_cases().items():
        calls = capture_kernel_calls(lambda: simulate_passes(tracks, vehicle, speed, irr, **options))  # noqa: B023
        if name == BENCH and len(calls) != 1:
            raise RuntimeError(f"the benchmark batch must be one kernel call, got {len(calls)}")
        for i, call in enumerate(calls):
            arrays.update({f"{name}/{i}/{key}": value for key, value in call.items()})
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, **arrays)
    print(f"wrote {path} ({path.stat().st_size / 2**20:.1f} MB, {len(arrays)} arrays)")


# ------------------------------------------------------------------------------------ reading the reference
def read_calls(path: Path) -> dict:
    """case -> list of calls, each a dict part -> SimpleNamespace of its fields."""
    data = np.load(path)
    cases: dict = {}
    for key in data.files:
        case, call, part, field = key.split("/")
        calls = cases.setdefault(case, {})
        calls.setdefault(int(call), {}).setdefault(part, {})[field] = data[key]
    return {case: [{part: types.SimpleNamespace(**f) for part, f in calls[i].items()} for i in sorted(calls)]
            for case, calls in cases.items()}


def unpack(x: np.ndarray) -> np.ndarray:
    """(chunks, ..., width) -> (rows, ...)."""
    x = np.moveaxis(x, -1, 1)
    return x.reshape((-1,) + x.shape[2:])


def row_tensors(torch, call: dict, device, rows: np.ndarray | None = None) -> dict:
    """The torch backend's state of a call's rows (all, or the indices ``rows``) on ``device``."""
    pick = (lambda x: x) if rows is None else (lambda x: x[rows])
    st = {k: torch.as_tensor(pick(unpack(getattr(call["rows_in"], k))), device=device) for k in ROWS}
    st.update({f"out_{k}": torch.as_tensor(pick(unpack(getattr(call["peaks_in"], k))), device=device)
               for k in PEAKS})
    return st


# ------------------------------------------------------------------------------------ the device: equivalence
def equivalence(tp, torch, cases: dict, device, solver: str) -> dict:
    """Each case through the torch backend against the kernel: the largest error of each output, relative to that
    output's largest value, and the steps whose contact state differs."""
    out: dict = {}
    for name, calls in cases.items():
        errs: dict = {}
        flips = 0
        t0 = time.perf_counter()
        for call in calls:
            st = tp.integrate(call["mesh"], call["drive"], row_tensors(torch, call, device), solver=solver)
            for k in PEAKS:
                want = unpack(getattr(call["peaks_out"], k))
                got = st[f"out_{k}"].cpu().numpy()
                errs[k] = max(errs.get(k, 0.0), float(np.max(np.abs(got - want)) / np.max(np.abs(want))))
                if k == "force":
                    flips += int(np.sum((got[:, 1:] <= 0.0) != (want[:, 1:] <= 0.0)))
            for k in ("u", "q"):
                want = unpack(getattr(call["rows_out"], k))
                got = st[k].cpu().numpy()
                errs[f"final_{k}"] = max(errs.get(f"final_{k}", 0.0),
                                         float(np.max(np.abs(got - want)) / np.max(np.abs(want))))
        out[name] = {"max_rel_error": errs, "contact_state_differs_steps": flips,
                     "rows": int(sum(unpack(c["rows_in"].u).shape[0] for c in calls)),
                     "seconds": time.perf_counter() - t0}
    return out


# ------------------------------------------------------------------------------------ the device: timing
def bench_batch(torch, base: dict, x_axle: np.ndarray, n_rows: int, n_steps: int, device, seed: int = 0) -> dict:
    """``n_rows`` rows repeating the benchmark's rows (``base``: their state on the device), a random long-wave
    rail level added to each, over the first ``n_steps`` steps of the pass."""
    pick = torch.arange(n_rows, device=device) % base["u"].shape[0]
    st = {k: v[pick] for k, v in base.items() if not k.startswith("out_") and k != "z"}
    st["z"] = base["z"][pick, : n_steps + 1].clone()
    for key in ("out_force", "out_rail", "out_wheel"):
        st[key] = torch.zeros_like(base[key][pick, : n_steps + 1])
        st[key][:, 0] = base[key][pick, 0]
    for key in ("out_ballast", "out_total"):
        st[key] = base[key][pick]
    gen = torch.Generator(device=device).manual_seed(seed)
    wavelength = 3.0 + 22.0 * torch.rand((n_rows, 1, 1), generator=gen, device=device, dtype=torch.float64)
    phase = 2 * np.pi * torch.rand((n_rows, 1, 1), generator=gen, device=device, dtype=torch.float64)
    x = torch.as_tensor(x_axle[: n_steps + 1], device=device).unsqueeze(0)
    st["z"] += LEVEL_AMPLITUDE_M * torch.sin(2 * np.pi * x / wavelength + phase)
    return st


def synchronize(torch, device) -> None:
    if torch.device(device).type == "cuda":
        torch.cuda.synchronize()


def time_batch(tp, torch, call: dict, base: dict, n_rows: int, n_steps: int, device, solver: str,
               repeats: int) -> dict:
    """Seconds per batch of ``n_rows`` rows over ``n_steps`` steps (median of ``repeats``) and the rates that
    follow; passes/s counts passes of the benchmark's full length."""
    drive = types.SimpleNamespace(**{**vars(call["drive"]), "x_axle": call["drive"].x_axle[: n_steps + 1]})
    seconds = []
    for _ in range(repeats):
        st = bench_batch(torch, base, call["drive"].x_axle, n_rows, n_steps, device)
        synchronize(torch, device)
        t0 = time.perf_counter()
        tp.integrate(call["mesh"], drive, st, solver=solver)
        synchronize(torch, device)
        seconds.append(time.perf_counter() - t0)
        del st
    full = call["drive"].x_axle.shape[0] - 1
    median = statistics.median(seconds)
    return {"rows": n_rows, "steps": n_steps, "seconds": seconds, "median_s": median,
            "row_steps_per_s": n_rows * n_steps / median, "full_passes_per_s": n_rows * n_steps / median / full}


def device_run(args) -> None:
    started = time.perf_counter()
    import torch

    tp = load_torch_pass()
    device = tp.torch_device(args.device)
    cases = read_calls(args.reference)
    report: dict = {"device": torch.cuda.get_device_name(device) if device.type == "cuda" else "cpu",
                    "torch": torch.__version__, "cuda": torch.version.cuda, "solver": args.solver,
                    "quick": args.quick, "budget_s": args.budget_s, "skipped": []}

    def save():
        report["elapsed_s"] = time.perf_counter() - started
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(report, indent=1))

    equiv_cases = {k: v for k, v in cases.items() if not (args.quick and k == BENCH)}
    report["equivalence"] = equivalence(tp, torch, equiv_cases, device, args.solver)
    worst = max(max(c["max_rel_error"].values()) for c in report["equivalence"].values())
    report["equivalence_max_rel_error"] = worst
    save()
    print(f"equivalence: largest relative error {worst:.2e} over {len(equiv_cases)} cases")
    for name, c in report["equivalence"].items():
        e = c["max_rel_error"]
        print(f"  {name:16s} rows {c['rows']:3d}  sleeper peaks {max(e['ballast'], e['total']):.1e}  "
              f"contact {e['force']:.1e}  contact state differs at {c['contact_state_differs_steps']} steps  "
              f"({c['seconds']:.1f} s)")

    call = cases[BENCH][0]
    base = row_tensors(torch, call, device)
    full = call["drive"].x_axle.shape[0] - 1
    n_steps = min(args.quick_steps, full) if args.quick else full
    repeats = 1 if args.quick else 3
    report["timing"] = []
    t0 = time.perf_counter()
    warm = time_batch(tp, torch, call, base, args.rows[0], min(200, full), device, args.solver, 1)
    report["warmup_s"] = time.perf_counter() - t0
    print(f"warm-up: {warm['steps']} steps of {warm['rows']} rows in {warm['median_s']:.1f} s")
    print(f"{'solver':>8s} {'rows':>6s} {'steps':>6s} {'median s':>9s} {'passes/s':>9s} {'row-steps/s':>12s}")
    last = warm
    for solver, n_rows in [(args.solver, n) for n in args.rows] + [(s, args.rows[-1]) for s in args.also_solvers]:
        # a step's time grows at most in proportion to the rows (it is launch-bound until the device is full)
        guess = repeats * n_steps * last["median_s"] / last["steps"] * max(1.0, n_rows / last["rows"])
        left = args.budget_s - (time.perf_counter() - started)
        if guess > left:
            report["skipped"].append(f"{solver} {n_rows} rows: ~{guess:.0f} s expected, {left:.0f} s left")
            print(f"skipped {solver} {n_rows} rows (~{guess:.0f} s expected, {left:.0f} s left)")
            continue
        if device.type == "cuda":
            torch.cuda.reset_peak_memory_stats(device)
        row = time_batch(tp, torch, call, base, n_rows, n_steps, device, solver, repeats)
        row["solver"] = solver
        if device.type == "cuda":
            row["peak_memory_gib"] = torch.cuda.max_memory_allocated(device) / 2**30
        report["timing"].append(row)
        last = row
        save()
        print(f"{solver:>8s} {n_rows:6d} {row['steps']:6d} {row['median_s']:9.2f} {row['full_passes_per_s']:9.1f} "
              f"{row['row_steps_per_s']:12.3e}")
    save()
    print(f"wrote {args.out} ({time.perf_counter() - started:.0f} s)")


# ------------------------------------------------------------------------------------ here: the CPU kernel
def cpu_timing(args) -> None:
    """The numba kernel's passes/s on the benchmark rows repeated to each row count (the same rail levels added
    as on the device; numba's threads, chunks of 16 rows), median of ``repeats``."""
    import numba

    from trackenv.physics import _kernel
    from trackenv.physics._step import Peaks, Rows
    from trackenv.physics.dynamics import _NO_REUSE, _chunking, _pack

    call = read_calls(args.reference)[BENCH][0]
    base = unpack(call["rows_in"].u).shape[0]
    rng = np.random.default_rng(0)
    mesh, drive = _mesh_tuple(call), _drive_tuple(call)
    x, steps = call["drive"].x_axle, call["drive"].x_axle.shape[0] - 1
    for n_rows in args.rows:
        rows = np.arange(n_rows) % base
        n_chunks, width = _chunking(n_rows)
        level = LEVEL_AMPLITUDE_M * np.sin(2 * np.pi * x[None] / rng.uniform(3, 25, (n_rows, 1, 1))
                                           + rng.uniform(0, 2 * np.pi, (n_rows, 1, 1)))
        seconds = []
        for _ in range(args.repeats):
            fields = {k: unpack(getattr(call["rows_in"], k))[rows] for k in ROWS}
            fields["z"] = fields["z"] + level
            packed = Rows(*(_pack(fields[k], n_chunks, width) for k in ROWS))
            peaks = Peaks(*(_pack(unpack(getattr(call["peaks_in"], k))[rows], n_chunks, width) for k in PEAKS))
            t0 = time.perf_counter()
            _kernel.run(mesh, drive, packed, peaks, _NO_REUSE, width)
            seconds.append(time.perf_counter() - t0)
        median = statistics.median(seconds)
        print(json.dumps({"rows": n_rows, "steps": steps, "seconds": seconds, "passes_per_s": n_rows / median,
                          "row_steps_per_s": n_rows * steps / median, "numba_threads": numba.get_num_threads(),
                          "load_average": os.getloadavg()}))


def _mesh_tuple(call: dict):
    from trackenv.physics._step import Mesh

    m = call["mesh"]
    return Mesh(m.node_w, m.sleeper_dof, m.sleeper_node, float(m.elem_len), int(m.epb), int(m.n_sleepers),
                int(m.margin_bays), m.rail_mass)


def _drive_tuple(call: dict):
    from trackenv.physics._step import Drive

    d = call["drive"]
    return Drive(np.ascontiguousarray(d.x_axle), d.consts, int(d.law), float(d.param), d.mass, d.damping, d.kv_inv,
                 d.force, d.wheel_dofs, d.cluster_of_axle, int(d.n_clusters))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--make-reference", type=Path, help="write the reference .npz here (needs the package)")
    parser.add_argument("--cpu-timing", action="store_true", help="time the numba kernel on the reference's batch")
    parser.add_argument("--reference", type=Path, default=ROOT / "experiments" / "saved" / "gpu" / "reference.npz")
    parser.add_argument("--out", type=Path, default=Path("gpu_passes.json"))
    parser.add_argument("--device", default="cuda")
    parser.add_argument("--solver", default="inverse", choices=("inverse", "cholesky"))
    parser.add_argument("--also-solvers", default="cholesky",
                        help="solvers also timed on the largest batch, comma-separated ('' for none)")
    parser.add_argument("--rows", default=",".join(map(str, BENCH_ROWS)), help="batch sizes, comma-separated")
    parser.add_argument("--repeats", type=int, default=3, help="--cpu-timing: runs per batch size")
    parser.add_argument("--quick", action="store_true", help="the benchmark over its first --quick-steps steps, once")
    parser.add_argument("--quick-steps", type=int, default=600)
    parser.add_argument("--budget-s", type=float, default=210.0, help="skip measurements that would end later")
    args = parser.parse_args(argv)
    args.rows = [int(r) for r in args.rows.split(",") if r]
    args.also_solvers = [s for s in args.also_solvers.split(",") if s]
    if args.make_reference:
        make_reference(args.make_reference)
    elif args.cpu_timing:
        cpu_timing(args)
    else:
        device_run(args)


if __name__ == "__main__":
    main()
