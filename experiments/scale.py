"""How the line scales with its length: line-steps per second and peak memory of one line of 12, 50 and 250
sections (the default line, a 10 km line and ``trackenv/TampingLineLong-v0``), random allowed actions.

Each size runs in a fresh process, so its peak resident memory (``ru_maxrss``) is its own: the library, the
compiled kernel and the episode together. Writes ``results/scale.json`` and prints a table::

    python experiments/scale.py                      # 12, 50, 250 sections, 8 steps each
    python experiments/scale.py --sizes 12 250 --steps 4
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

_ONE = r"""
import json, resource, sys, time
import gymnasium as gym
import numpy as np
import trackenv  # noqa: F401
n, steps = int(sys.argv[1]), int(sys.argv[2])
env = gym.make("trackenv/TampingLineLong-v0") if n == 250 else gym.make(
    "trackenv/TampingLine-v0", n_sections=n, capacity=max(1, n // 10) if n > 12 else 6)
t0 = time.perf_counter()
env.reset(seed=0)
reset_s = time.perf_counter() - t0
rng = np.random.default_rng(0)
t0 = time.perf_counter()
for _ in range(steps):
    mask = env.unwrapped.action_masks().reshape(-1, 2)[:, 1]
    env.step(((rng.random(n) < 0.1) & mask).astype(np.int8))
wall = time.perf_counter() - t0
print(json.dumps({"sections": n, "steps": steps, "reset_s": reset_s, "line_steps_per_s": steps / wall,
                  "section_steps_per_s": steps * n / wall, "peak_rss_mb": resource.getrusage(
                      resource.RUSAGE_SELF).ru_maxrss / 1024, "load_average_1min": __import__("os").getloadavg()[0]}))
"""


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[12, 50, 250], help="sections per line (250: the Long id)")
    p.add_argument("--steps", type=int, default=8, help="env steps timed per size (after the reset)")
    p.add_argument("--out", default="results/scale.json")
    a = p.parse_args(argv)
    if a.steps < 1 or any(n < 1 or n > 256 for n in a.sizes):
        p.error("--steps must be >= 1 and --sizes in [1, 256]")
    rows = []
    for n in a.sizes:
        done = subprocess.run([sys.executable, "-c", _ONE, str(n), str(a.steps)], capture_output=True, text=True,
                              check=True, env=os.environ.copy())
        rows.append(json.loads(done.stdout.strip().splitlines()[-1]))
        r = rows[-1]
        print(f"{n:4d} sections: reset {r['reset_s']:.1f} s, {r['line_steps_per_s']:.2f} line-steps/s "
              f"({r['section_steps_per_s']:.0f} section-steps/s), peak {r['peak_rss_mb']:.0f} MB "
              f"[load {r['load_average_1min']:.1f}]", flush=True)
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
