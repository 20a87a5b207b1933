"""Static window ends (``window_ends="static"``) against clamped ones: accuracy against the whole-track model at
shorter margins, and what a shorter window buys on the line's passes.

    python experiments/physics_window_ends.py accuracy          # the table, saved to experiments/saved/
    python experiments/physics_window_ends.py ab --pairs 4      # line-steps/s, alternating processes
    python experiments/physics_window_ends.py time --layout c3  # one process's figure (what ab runs)
    python experiments/physics_window_ends.py env-ab --pairs 3  # the envs' steps/s, today against w3

``accuracy``: every case runs with the window's margin at 2, 3, 4, 5 and 6.5 decay lengths (``window_margin(track,
decay_lengths)`` bays either side) with clamped ("rest") and static ends, against ``window_bays=None``. Cases: the
soft/stiff sweep of ``tests/physics/test_dynamics.py`` (pads and ballast 1e6-1e9 N/m, a voided sleeper, a soft
transition, 80 km/h, a 100 kN wheel) and the line's segment kinds of ``tests/physics/test_steady_start.py``
(plain, transition, switch patch, wet spot, voided sleeper; the line's wheelsets at 100 km/h, dt "auto", the
level as settled supports, 10 sleepers of approach and exit). Figures: the largest relative error of the
per-sleeper peak ballast forces (each floored at a tenth of the largest) over the evaluated sleepers, of the peak
contact force, the histories over the evaluated track (``history``: the largest of contact force, rail and wheel
displacement while every axle is over the evaluated sleepers, and sleeper force, normalised by the static load,
the static deflection and the largest sleeper force) and the same over the whole pass (``test``, the measure of
``assert_close_to_reference``, which includes the static start's transient at the rail's free end). "whole"
where the margin covers the track (the window does not move).

``ab``: the line's passes of one ``TampingLine-v0`` step (12 segments of 30 m, both wheelsets, as
``experiments/physics_steady_start.py`` builds them) in four layouts, each in its own process, A B C D D C B A ...:
``a`` today (10 sleepers of approach and exit, static start, auto window, clamped ends); ``b`` the steady start
with 3 bays of exit; ``c<d>`` ``b`` with static ends and a margin of ``<d>`` decay lengths (``c3``: the margin
recommended for static ends; the approach shortened to the shorter window). Each process reports line-steps/s
(wall) and the CPU seconds of a step (all threads).

``env-ab``: ``TampingLine-v0`` and its 8-line vector env, random actions, as ``trackenv bench`` measures them
(``experiments/studies/bench.py``), today (``a``) against ``w3``: the env's passes with static ends at 3 decay
lengths (its static start and 10-sleeper zones unchanged: the steady start is not wired into the env).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import math
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from ab_speed import load_range, timed_runs  # experiments/ab_speed.py: the scripts run from experiments/

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "experiments" / "saved" / "physics_window_ends.json"
DECAY_LENGTHS = (2.0, 3.0, 4.0, 5.0, 6.5)
ENDS = ("rest", "static")
LAYOUTS = ("a", "b", "c4", "c3")


def _module(name: str, path: Path):
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.path.insert(0, str(path.parent))  # (the test modules import their neighbours)
    spec.loader.exec_module(module)
    return module


def _cases() -> dict:
    """name -> (model track, vehicle, speed, irregularity, options, evaluated sleepers)."""
    dyn = _module("_ends_dynamics_cases", ROOT / "tests" / "physics" / "test_dynamics.py")
    st = _module("_ends_steady_cases", ROOT / "tests" / "physics" / "test_steady_start.py")
    cases = {}
    for name, track in dyn.SOFT_AND_STIFF.items():
        cases[name] = (track, dyn.LOADED, dyn.V80, None, {}, slice(8, track.n_sleepers - 8))
    for name, (track, vehicle, speed, irr, options) in st.LINE.items():
        pad = st.EXIT_SLEEPERS
        model = track.extended(pad, pad)
        options = dict(options, dt="auto")
        if "support_settlement" in options:
            options["support_settlement"] = st.held(options["support_settlement"], track, pad, pad)
        cases[f"line_{name}"] = (model, vehicle, speed, st.held(irr, track, pad, pad), options,
                                 slice(pad, pad + track.n_sleepers))
    return cases


def _measures(res, ref, ev: slice) -> dict:
    f, g = res.ballast_force[ev], ref.ballast_force[ev]
    sleeper = float(np.max(np.abs(f - g) / np.maximum(np.abs(g), 0.1 * g.max())))
    contact = float(abs(res.max_contact_force / ref.max_contact_force - 1))
    w0 = np.abs(ref.rail_displacement[0])
    p0 = res.static_wheel_load
    test = max(np.max(np.abs(res.contact_force - ref.contact_force) / p0),
               np.max(np.abs(res.rail_displacement - ref.rail_displacement) / w0),
               np.max(np.abs(res.ballast_force - ref.ballast_force)) / ref.ballast_force.max(),
               np.max(np.abs(res.wheel_displacement - ref.wheel_displacement) / w0))
    # the same over the evaluated track only: every axle over it (the start's transient left out)
    x = res.wheel_position
    s = res.sleeper_positions[1]
    span = (x.min(axis=1) >= ev.start * s) & (x.max(axis=1) <= (ev.stop - 1) * s)
    evaluated = max(np.max(np.abs(res.contact_force - ref.contact_force)[span] / p0),
                    np.max(np.abs(res.rail_displacement - ref.rail_displacement)[span] / w0),
                    np.max(np.abs(res.ballast_force - ref.ballast_force)[ev]) / ref.ballast_force.max(),
                    np.max(np.abs(res.wheel_displacement - ref.wheel_displacement)[span] / w0))
    return {"sleeper": sleeper, "contact": contact, "history": float(evaluated), "test": float(test)}


def accuracy() -> dict:
    from trackenv.physics.dynamics import simulate_pass, window_margin

    out: dict = {}
    for name, (track, vehicle, speed, irr, options, ev) in _cases().items():
        ref = simulate_pass(track, vehicle, speed, irr, window_bays=None, **options)
        row: dict = {}
        for decay in DECAY_LENGTHS:
            margin = window_margin(track, decay)
            for ends in ENDS:
                key = f"{decay:g}/{ends}"
                if margin is None:
                    row[key] = {"margin": None}
                    continue
                res = simulate_pass(track, vehicle, speed, irr, window_bays=margin, window_ends=ends, **options)
                row[key] = {"margin": margin, **_measures(res, ref, ev)}
        out[name] = row
        print(f"{name:28s} " + " ".join(_cell(row[f"{d:g}/{e}"]) for d in DECAY_LENGTHS for e in ENDS), flush=True)
    worst = {}
    for d in DECAY_LENGTHS:
        for e in ENDS:
            cells = [r[f"{d:g}/{e}"] for r in out.values() if r[f"{d:g}/{e}"]["margin"] is not None]
            worst[f"{d:g}/{e}"] = {k: max(c[k] for c in cells) for k in ("sleeper", "contact", "history", "test")}
    print("worst:", json.dumps({k: {m: round(100 * x, 3) for m, x in v.items()} for k, v in worst.items()}))
    return {"cases": out, "worst": worst, "decay_lengths": DECAY_LENGTHS, "ends": ENDS}


def _cell(c: dict) -> str:
    if c["margin"] is None:
        return f"{'whole':>17s}"
    return f"{c['margin']:2d}:{100 * c['sleeper']:4.2f}/{100 * c['contact']:4.2f}/{100 * c['history']:4.2f}"


# ------------------------------------------------------------------------------------------ speed
def line_workload(layout: str):
    """The line's passes of one step in ``layout`` (see the module's docstring): a function running both
    vehicles' batched passes."""
    from trackenv.physics import dynamics

    steady = _module("_ends_steady_start", ROOT / "experiments" / "physics_steady_start.py")
    if layout == "a":
        return steady.line_workload("today")
    if layout == "b":
        return steady.line_workload("steady_exit3")
    decay_lengths = float(layout[1:])
    original = dynamics.simulate_passes
    tracks_seen: list = []

    def call(tracks, *args, **kwargs):
        margin = max(dynamics.window_margin(t, decay_lengths) for t in tracks)
        return original(tracks, *args, **{**kwargs, "window_bays": margin, "window_ends": "static"})

    # the approach: the vehicle's span, the shorter window and 1.5 bays behind it, 3 lead bays
    def approach(segments, vehicle, lead):
        tracks_seen.extend(segments)
        margin = max(dynamics.window_margin(t.extended(20, 20), decay_lengths) for t in segments)
        span = dynamics._vehicle_system(vehicle).span
        return math.ceil(span / segments[0].sleeper_spacing + margin + 1.5 + lead - 1e-9)

    dynamics.simulate_passes, saved_approach = call, dynamics.steady_approach_sleepers
    dynamics.steady_approach_sleepers = approach
    try:
        return steady.line_workload("steady_exit3")
    finally:
        dynamics.simulate_passes, dynamics.steady_approach_sleepers = original, saved_approach


def time_layout(layout: str, repeats: int) -> dict:
    step = line_workload(layout)
    began = time.perf_counter()
    step()  # the steady states are computed here
    first = time.perf_counter() - began
    step()
    cpu0, began = time.process_time(), time.perf_counter()
    for _ in range(repeats):
        step()
    wall, cpu = time.perf_counter() - began, time.process_time() - cpu0
    return {"layout": layout, "line_steps_per_s": repeats / wall, "cpu_s_per_step": cpu / repeats,
            "first_step_ms": 1e3 * first, "load": os.getloadavg()[0]}


def ab(pairs: int, repeats: int) -> dict:
    runs = timed_runs(LAYOUTS, pairs,
                      lambda layout: [sys.executable, __file__, "time", "--layout", layout, "--repeats", str(repeats)],
                      lambda layout, rec: f"{layout} {rec['line_steps_per_s']:7.2f} line-steps/s  cpu "
                                          f"{1e3 * rec['cpu_s_per_step']:6.1f} ms/step  first "
                                          f"{rec['first_step_ms']:6.0f} ms  load {rec['load']:.2f}")
    med = {k: statistics.median(r["line_steps_per_s"] for r in v) for k, v in runs.items()}
    cpu = {k: statistics.median(r["cpu_s_per_step"] for r in v) for k, v in runs.items()}
    summary = {"median_line_steps_per_s": med, "ratio_to_a": {k: med[k] / med["a"] for k in LAYOUTS},
               "median_cpu_s_per_step": cpu, "cpu_ratio_to_a": {k: cpu["a"] / cpu[k] for k in LAYOUTS},
               "load_range": load_range(runs), "pairs": pairs, "repeats": repeats, "runs": runs}
    print(json.dumps({k: summary[k] for k in ("median_line_steps_per_s", "ratio_to_a", "median_cpu_s_per_step",
                                              "cpu_ratio_to_a", "load_range")}))
    return summary


ENV_LAYOUTS = ("a", "w3")


def time_env(layout: str, budget_s: float) -> dict:
    """The line env's and the 8-line vector env's steps/s in this process, in ``layout`` (see ``env-ab``)."""
    from trackenv.envs import line_episode
    from trackenv.physics import dynamics

    bench = _module("_ends_bench", ROOT / "experiments" / "studies" / "bench.py")
    if layout != "a":
        decay_lengths = float(layout[1:])

        def call(batches):
            return dynamics.simulate_pass_batches([
                {**b, "window_bays": max(dynamics.window_margin(t, decay_lengths) for t in b["tracks"]),
                 "window_ends": "static"} for b in batches])

        line_episode.simulate_pass_batches = call
    cpu0 = time.process_time()
    line = bench._bench_env(1000, budget_s, env_id="trackenv/TampingLine-v0")
    vector = bench._bench_vector_env(8, 1000, budget_s, line=True)
    return {"layout": layout, "line_env_steps_per_s": line.get("steps_per_s"), "pass_share": line.get("pass_share"),
            "line_vector_env_8_steps_per_s": vector.get("env_steps_per_s"), "cpu_s": time.process_time() - cpu0,
            "load": os.getloadavg()[0]}


def env_ab(pairs: int, budget_s: float) -> dict:
    runs = timed_runs(ENV_LAYOUTS, pairs,
                      lambda layout: [sys.executable, __file__, "time-env", "--layout", layout, "--budget",
                                      str(budget_s)])
    keys = ("line_env_steps_per_s", "line_vector_env_8_steps_per_s")
    med = {k: {m: statistics.median(r[m] for r in v) for m in keys} for k, v in runs.items()}
    new = ENV_LAYOUTS[1]
    summary = {"median": med, "ratio": {m: med[new][m] / med["a"][m] for m in keys},
               "load_range": load_range(runs), "pairs": pairs, "runs": runs}
    print(json.dumps({k: summary[k] for k in ("median", "ratio", "load_range")}))
    return summary


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("what", choices=("accuracy", "ab", "time", "env-ab", "time-env"))
    parser.add_argument("--layout", default="c3", help=f"one of {LAYOUTS} (or c<decay lengths>, w<decay lengths>)")
    parser.add_argument("--pairs", type=int, default=4)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--budget", type=float, default=15.0, help="seconds per env figure (env-ab)")
    args = parser.parse_args()
    if args.what == "accuracy":
        record = accuracy()
        saved = json.loads(OUT.read_text()) if OUT.exists() else {}
        OUT.write_text(json.dumps({**saved, "accuracy": record}, indent=1) + "\n")
    elif args.what == "ab":
        import numba

        record = ab(args.pairs, args.repeats)
        saved = json.loads(OUT.read_text()) if OUT.exists() else {}
        OUT.write_text(json.dumps({**saved, f"ab_threads{numba.get_num_threads()}": record}, indent=1) + "\n")
    elif args.what == "env-ab":
        record = env_ab(args.pairs, args.budget)
        saved = json.loads(OUT.read_text()) if OUT.exists() else {}
        OUT.write_text(json.dumps({**saved, "env_ab": record}, indent=1) + "\n")
    elif args.what == "time-env":
        print(json.dumps(time_env(args.layout, args.budget)))
    else:
        print(json.dumps(time_layout(args.layout, args.repeats)))


if __name__ == "__main__":
    main()
