"""The steady start of a pass (``start="steady"``): its accuracy against a long approach, and what it saves on the
line's passes.

    python experiments/physics_steady_start.py accuracy             # errors against a 40-sleeper approach
    python experiments/physics_steady_start.py ab --pairs 6          # line passes per second, alternating processes
    python experiments/physics_steady_start.py time --layout steady  # one process's figure (what ab runs)

``accuracy``: on every case of ``tests/physics/test_steady_start.py`` (the short-wave matrix of the time-step
contract and line-like segments), the largest relative error of the evaluated per-sleeper peak forces and of the
peak contact force, for today's approach (10 sleepers from static equilibrium) and for the steady start with the
leading axle 1, 2 or 3 bays before the evaluated track, each against 40 sleepers of approach.

``ab``: the line's passes (12 segments of 30 m in one batch, the passenger and the freight wheelset at
100 km/h, dt "auto", the level as settled supports), as ``TampingLine-v0`` runs them at each step, per layout:

* ``today``: 10 sleepers of approach and of exit, from static equilibrium, over the whole model track;
* ``steady``: the steady start's approach (``steady_approach_sleepers``, 3 lead bays), the same exit;
* ``steady_exit3``: the steady start, ending 3 bays after the evaluated track (as the degradation loop's passes);
* ``today_exit3``: today's approach, ending there too.

Each layout runs in its own process, in the order A B B A ..., and reports line-steps per second (both vehicles'
passes) after a warm-up that also computes the steady states (once per episode in the env: reported apart as
``first_step_ms``). The machine's load average is printed with every figure.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
LAYOUTS = ("today", "steady", "steady_exit3", "today_exit3")
TODAY_APPROACH = 10
EXIT_RUN_OUT = 3
LEAD = 3


def _cases():
    """The test module of the steady start (its cases and helpers)."""
    path = ROOT / "tests" / "physics" / "test_steady_start.py"
    spec = importlib.util.spec_from_file_location("_steady_start_cases", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def accuracy() -> dict:
    from trackenv.physics.dynamics import steady_approach_sleepers

    m = _cases()
    out = {}
    print(f"{'case':26s} {'10 from static':>16s} " + " ".join(f"{'steady, lead ' + str(k):>16s}" for k in (1, 2, 3)))
    for name, case in m.CASES.items():
        track, vehicle = case[0], case[1]
        span_bays = int(np.ceil(m.dynamics._vehicle_system(vehicle).span / track.sleeper_spacing))
        f_ref, c_ref, _ = m.run_case(case, m.REFERENCE_APPROACH + span_bays, "static")
        row = {}
        f, c, _ = m.run_case(case, TODAY_APPROACH + span_bays, "static")
        row["today"] = _errors(f, c, f_ref, c_ref)
        for lead in (1, 2, 3):
            f, c, _ = m.run_case(case, steady_approach_sleepers(track, vehicle, lead), "steady")
            row[f"steady_lead{lead}"] = _errors(f, c, f_ref, c_ref)
        out[name] = row
        print(f"{name:26s} " + " ".join(f"{100 * s:7.3f} {100 * k:7.3f}%" for s, k in row.values()), flush=True)
    worst = {k: [max(r[k][0] for r in out.values()), max(r[k][1] for r in out.values())] for k in out[name]}
    print("worst (sleeper %, contact %):", {k: [round(100 * x, 3) for x in v] for k, v in worst.items()})
    return {"cases": out, "worst": worst}


def _errors(f, c, f_ref, c_ref) -> tuple[float, float]:
    sleeper = float(np.max(np.abs(f - f_ref) / np.maximum(np.abs(f_ref), 0.1 * f_ref.max())))
    return sleeper, float(abs(c.max() / c_ref.max() - 1))


def line_workload(layout: str):
    """The line's passes for one step in ``layout``: a function running both vehicles' batched passes."""
    from functools import partial

    from trackenv.physics.dynamics import simulate_passes, steady_approach_sleepers
    from trackenv.physics.geometry import german_psd, synthesize_profile

    m = _cases()
    rng = np.random.default_rng(0)
    segments = [m._segment(m._ballast_field(seed)) for seed in range(12)]
    x = segments[0].sleeper_positions
    levels = [np.abs(synthesize_profile(x, partial(german_psd, quality="low"), rng)) * 2 for _ in segments]
    vehicles = (m.WHEEL_20T, m.FREIGHT_25T)
    steady = layout.startswith("steady")
    approach = steady_approach_sleepers(segments, vehicles[1], LEAD) if steady else TODAY_APPROACH
    n = segments[0].n_sleepers
    models = [t.extended(approach, TODAY_APPROACH) for t in segments]
    settlement = np.stack([m.held(lv, segments[0], approach, TODAY_APPROACH) for lv in levels])
    s = segments[0].sleeper_spacing
    x_end = (approach + n - 1 + EXIT_RUN_OUT) * s if layout.endswith("exit3") else None

    def step():
        for v in vehicles:
            simulate_passes(models, v, m.V100, None, support_settlement=settlement, dt="auto",
                            start="steady" if steady else "static", x_end=x_end)

    return step


def time_layout(layout: str, repeats: int) -> dict:
    step = line_workload(layout)
    began = time.perf_counter()
    step()  # compiles nothing (warm cache); the steady start computes its states here
    first = time.perf_counter() - began
    step()
    began = time.perf_counter()
    for _ in range(repeats):
        step()
    rate = repeats / (time.perf_counter() - began)
    return {"layout": layout, "line_steps_per_s": rate, "first_step_ms": 1e3 * first, "load": os.getloadavg()[0]}


def ab(base: str, new: str, pairs: int, repeats: int) -> dict:
    order = []
    for i in range(pairs):
        order += [base, new] if i % 2 == 0 else [new, base]
    runs: dict[str, list] = {base: [], new: []}
    for layout in order:
        out = subprocess.run([sys.executable, __file__, "time", "--layout", layout, "--repeats", str(repeats)],
                             check=True, capture_output=True, text=True).stdout
        rec = json.loads(out.strip().splitlines()[-1])
        runs[layout].append(rec)
        print(f"{layout:14s} {rec['line_steps_per_s']:7.2f} line-steps/s  first step {rec['first_step_ms']:6.0f} ms"
              f"  load {rec['load']:.2f}", flush=True)
    ratios = [n["line_steps_per_s"] / b["line_steps_per_s"] for b, n in zip(runs[base], runs[new])]
    summary = {
        "base": base, "new": new, "pairs": pairs,
        "median_base": statistics.median(r["line_steps_per_s"] for r in runs[base]),
        "median_new": statistics.median(r["line_steps_per_s"] for r in runs[new]),
        "median_ratio": statistics.median(ratios), "ratios": ratios,
        "load": [r["load"] for r in runs[base] + runs[new]],
    }
    print(json.dumps({k: v for k, v in summary.items() if k != "load"}))
    print(f"load average during the runs: {min(summary['load']):.2f}-{max(summary['load']):.2f}")
    return summary


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("accuracy")
    t = sub.add_parser("time")
    t.add_argument("--layout", choices=LAYOUTS, required=True)
    t.add_argument("--repeats", type=int, default=10)
    a = sub.add_parser("ab")
    a.add_argument("--base", choices=LAYOUTS, default="today")
    a.add_argument("--new", choices=LAYOUTS, default="steady")
    a.add_argument("--pairs", type=int, default=6)
    a.add_argument("--repeats", type=int, default=10)
    args = parser.parse_args(argv)
    if args.command == "accuracy":
        accuracy()
    elif args.command == "time":
        print(json.dumps(time_layout(args.layout, args.repeats)))
    else:
        ab(args.base, args.new, args.pairs, args.repeats)


if __name__ == "__main__":
    main()
