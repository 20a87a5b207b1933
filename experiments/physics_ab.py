"""Interleaved A/B of the physics' pass speed between two source trees, in alternating processes.

    git archive main trackenv | tar -x -C /tmp/base               # a tree to compare against
    python experiments/physics_ab.py --base /tmp/base --pairs 6   # this tree (new) against it (base)

Each run is a fresh process with ``PYTHONPATH`` set to one tree, in the order A B B A A B ... (a drift of the
machine favours neither); it warms up (each tree compiles its kernel on its first run, untimed: run once before
timing a cold tree) and reports passes per second. Workloads (``--workload``):

* ``single``: the pass of the 60 m track (60 m of realistic track with 10 sleepers of approach and exit, a 20 t
  wheelset at 100 km/h, dt 4e-4, the level as settled supports), one row;
* ``line``: the line's passes for one step (12 segments of 30 m in one batch, the passenger and the freight
  wheelset at 100 km/h, dt "auto", settled supports): line-steps per second;
* ``seed``: the seed pass (the paper's track and wheelset, 80 km/h, dt 1e-4).

The load average is printed with every figure; figures from different machines or loads do not compare.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

_WORKLOAD = r"""
import json, os, sys, time
import numpy as np
from trackenv.physics.dynamics import simulate_pass, simulate_passes
from trackenv.physics.track import Track
from trackenv.physics.vehicle import Wheelset
workload, repeats = sys.argv[1], int(sys.argv[2])
g = 9.81
wheel = Wheelset(mass=1800.0, static_load=20e3 * g / 2 - 900.0 * g)
freight = Wheelset(mass=1400.0, static_load=25e3 * g / 2 - 700.0 * g)
rng = np.random.default_rng(0)
if workload == "single":
    track = Track.realistic(60.0).extended(10, 10)
    level = np.abs(1e-3 * np.cumsum(rng.standard_normal(track.n_sleepers)) / 10)
    run = lambda: simulate_pass(track, wheel, 100 / 3.6, support_settlement=level, dt=4e-4)
elif workload == "line":
    base = Track.realistic(30.0)
    fields = np.exp(0.15 * rng.standard_normal((12, base.n_sleepers)))
    tracks = [base.replace(ballast_stiffness=base.ballast_stiffness * f).extended(10, 10) for f in fields]
    levels = np.abs(1e-3 * np.cumsum(rng.standard_normal((12, tracks[0].n_sleepers)), axis=1) / 10)
    def run():
        for v in (wheel, freight):
            simulate_passes(tracks, v, 100 / 3.6, None, support_settlement=levels, dt="auto")
else:
    track = Track.seed()
    run = lambda: simulate_pass(track, Wheelset.seed(), 80 / 3.6, dt=1e-4)
run(); run()
t = time.perf_counter()
for _ in range(repeats):
    run()
print(json.dumps({"rate": repeats / (time.perf_counter() - t), "load": os.getloadavg()[0],
                  "tree": os.path.dirname(os.path.dirname(__import__("trackenv").__file__))}))
"""


def order(pairs: int) -> list[str]:
    """base new new base base new ...: each pair's order alternates."""
    if pairs < 1:
        raise ValueError(f"pairs must be >= 1, got {pairs}")
    out: list[str] = []
    for i in range(pairs):
        out += ["base", "new"] if i % 2 == 0 else ["new", "base"]
    return out


def measure(tree: Path, workload: str, repeats: int) -> dict:
    env = dict(os.environ, PYTHONPATH=str(tree))
    out = subprocess.run([sys.executable, "-c", _WORKLOAD, workload, str(repeats)], env=env, cwd="/",
                         check=True, capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--base", type=Path, required=True, help="a source tree holding trackenv/")
    parser.add_argument("--new", type=Path, default=ROOT, help="default: this tree")
    parser.add_argument("--workload", choices=("single", "line", "seed"), default="line")
    parser.add_argument("--pairs", type=int, default=6)
    parser.add_argument("--repeats", type=int, default=10)
    args = parser.parse_args(argv)
    trees = {"base": args.base.resolve(), "new": args.new.resolve()}
    runs: dict[str, list[dict]] = {"base": [], "new": []}
    for version in order(args.pairs):
        rec = measure(trees[version], args.workload, args.repeats)
        if Path(rec["tree"]) != trees[version]:
            raise SystemExit(f"{version} imported trackenv from {rec['tree']}, not {trees[version]}")
        runs[version].append(rec)
        print(f"{version:5s} {rec['rate']:8.2f} /s  load {rec['load']:.2f}", flush=True)
    ratios = [n["rate"] / b["rate"] for b, n in zip(runs["base"], runs["new"])]
    loads = [r["load"] for r in runs["base"] + runs["new"]]
    print(json.dumps({
        "workload": args.workload,
        "median_base": statistics.median(r["rate"] for r in runs["base"]),
        "median_new": statistics.median(r["rate"] for r in runs["new"]),
        "median_ratio_new_over_base": statistics.median(ratios),
        "ratios": [round(r, 3) for r in ratios],
        "load_average": [min(loads), max(loads)],
    }))


if __name__ == "__main__":
    main()
