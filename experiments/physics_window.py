"""What a shorter window would buy: the line's passes against the window's margin, and the error of a plain
shorter window against the whole-track model.

    python experiments/physics_window.py              # both tables (one thread; ~2 min on 2 vCPUs)

The window integrates ``margin`` sleeper bays either side of each axle group ("auto": 6.5 decay lengths, 7-8
bays on the line's segments); outside it the track is held at rest, so the window's ends are clamped. Absorbing
(non-reflecting) ends would let a shorter window keep the accuracy of the long one; the most they could buy is the
speed of a plain short window, measured here, and the error they would have to remove is that of the plain short
window, measured against ``window_bays=None`` (the whole track) on the soft/stiff sweep.

Speed: the line's passes with the steady start (``experiments/physics_steady_start.py``'s ``steady`` layout),
margins run round-robin in one process, one thread, the median of 10 rounds; the load average is printed.
"""

from __future__ import annotations

import importlib.util
import os
import statistics
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
MARGINS = (3, 4, 5, 6, "auto")


def _module(name: str, path: Path):
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def speed() -> None:
    import numba

    from trackenv.physics import dynamics

    numba.set_num_threads(1)
    steady = _module("_physics_steady_start", ROOT / "experiments" / "physics_steady_start.py")
    original = dynamics.simulate_passes
    steps = {}
    try:
        for margin in MARGINS:  # each workload binds simulate_passes with its window when it is built
            dynamics.simulate_passes = _with(original, margin)
            steps[margin] = steady.line_workload("steady")
    finally:
        dynamics.simulate_passes = original
    for step in steps.values():  # warm-up (and the steady states of each window)
        step()
    times: dict = {m: [] for m in MARGINS}
    for _ in range(10):
        for margin, step in steps.items():
            began = time.perf_counter()
            step()
            times[margin].append(time.perf_counter() - began)
    base = statistics.median(times["auto"])
    print(f"line passes, one thread, load {os.getloadavg()[0]:.2f}")
    for margin in MARGINS:
        t = statistics.median(times[margin])
        print(f"  window_bays={margin!s:5s} {1e3 * t:6.1f} ms per line step  x{base / t:.2f} against auto")


def _with(original, margin):
    def call(*args, **kwargs):
        return original(*args, **{**kwargs, "window_bays": margin})

    return call


def accuracy() -> None:
    from trackenv.physics.dynamics import simulate_pass, window_margin
    from trackenv.physics.track import Track
    from trackenv.physics.vehicle import Wheelset

    wheel = Wheelset(mass=1800.0, static_load=20e3 * 9.81 / 2 - 900.0 * 9.81)
    base = Track.realistic(30.0)
    cases = {
        "realistic": base,
        "ballast 1e8": base.replace(ballast_stiffness=np.full(base.n_sleepers, 1e8)),
        "ballast 2e7": base.replace(ballast_stiffness=np.full(base.n_sleepers, 2e7)),
        "pads 1e9": base.replace(pad_stiffness=np.full(base.n_sleepers, 1e9)),
        "voided sleeper": base.with_voided_sleeper(25, residual_support=0.05),
        "soft transition x0.3": base.scaled(ballast_stiffness=0.3, from_sleeper=25),
    }
    level = 5e-4 * np.abs(np.sin(np.arange(base.n_sleepers) / 3.0))
    print("largest error against the whole track (per-sleeper peak %, contact peak %)")
    for name, track in cases.items():
        kw = dict(support_settlement=level, dt="auto", x_start=3.0, x_end=27.0)
        ref = simulate_pass(track, wheel, 100 / 3.6, window_bays=None, **kw)
        row = []
        for margin in MARGINS:
            res = simulate_pass(track, wheel, 100 / 3.6, window_bays=margin, **kw)
            ev = slice(8, track.n_sleepers - 8)
            f, g = res.sleeper_force[ev], ref.sleeper_force[ev]
            s = np.max(np.abs(f - g) / np.maximum(np.abs(g), 0.1 * g.max()))
            c = abs(res.max_contact_force / ref.max_contact_force - 1)
            row.append(f"{margin!s:>4s}: {100 * s:5.2f} {100 * c:5.2f}")
        print(f"  {name:22s} (auto = {window_margin(track)})  " + " | ".join(row))


if __name__ == "__main__":
    import argparse

    argparse.ArgumentParser(description=__doc__.split("\n\n")[0] + " Prints both tables; writes nothing.").parse_args()
    accuracy()
    speed()
