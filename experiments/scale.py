"""How the line scales with its length, and the network of lines: line-steps per second and peak memory of one
line of 12, 50 and 250 sections (the default line, a 10 km line and ``trackenv/TampingLineLong-v0``, random
allowed actions), of one episode of ``trackenv/TampingNetwork-v0`` (its default: 3 lines of 12 sections and
one machine, under the network version of the threshold rule), and a batch of network episodes run as Ray
tasks on 2 local workers (or a cluster: ``--ray-address``) checked identical to the same batch in one process.

Each size and the network episode run in a fresh process, so its peak resident memory (``ru_maxrss``) is its
own: the library, the compiled kernel and the episode together. Writes ``results/scale.json`` and prints a
table::

    python experiments/scale.py                      # 12, 50, 250 sections, 8 steps each; the network; Ray
    python experiments/scale.py --sizes 12 250 --steps 4 --no-ray
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

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


_NETWORK = r"""
import json, os, resource, sys, time
import gymnasium as gym
import trackenv  # noqa: F401
from trackenv_agents.rules import NetworkRule
env = gym.make("trackenv/TampingNetwork-v0")
config = env.unwrapped.config
rule = NetworkRule().bind(config)
t0 = time.perf_counter()
obs, _ = env.reset(seed=0)
reset_s = time.perf_counter() - t0
total, moves, steps = 0.0, 0, 0
t0 = time.perf_counter()
truncated = False
while not truncated:
    obs, reward, _, truncated, info = env.step(rule.predict(obs)[0])
    total, moves, steps = total + reward, moves + info["moved"], steps + 1
wall = time.perf_counter() - t0
print(json.dumps({"lines": config.n_lines, "sections_per_line": config.sections_per_line, "steps": steps,
                  "reset_s": reset_s, "network_steps_per_s": steps / wall,
                  "line_steps_per_s": steps * config.n_lines / wall,
                  "section_steps_per_s": steps * config.n_sections / wall, "episode_return": total, "moves": moves,
                  "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "load_average_1min": os.getloadavg()[0]}))
"""


def network_episode() -> dict:
    """One episode of the default network in a fresh process (its own peak memory)."""
    done = subprocess.run([sys.executable, "-c", _NETWORK], capture_output=True, text=True, check=True,
                          env=os.environ.copy())
    return json.loads(done.stdout.strip().splitlines()[-1])


def ray_batch(episodes: int, horizon_years: float, address: str | None) -> dict:
    """``episodes`` episodes of the default network (horizon ``horizon_years``) under the network threshold rule,
    one per seed 0, 1, ..., through the evaluation harness: in this process, then as Ray tasks (one episode
    each) on a local Ray of 2 CPUs or the cluster at ``address``; whether the costs agree bit for bit."""
    import time

    from trackenv.envs.network import NetworkConfig
    from trackenv_agents.evaluation.distributed import RayExecutor
    from trackenv_agents.evaluation.harness import evaluate_many
    from trackenv_agents.rules import NetworkRule

    config = NetworkConfig.coerce(None, horizon_years=horizon_years)
    seeds = list(range(episodes))
    t0 = time.perf_counter()
    (here,) = evaluate_many([NetworkRule()], config, seeds=seeds, batch_size=1)
    local_s = time.perf_counter() - t0
    with RayExecutor(address=address, num_cpus=None if address else 2) as executor:
        t0 = time.perf_counter()
        (there,) = evaluate_many([NetworkRule()], config, seeds=seeds, batch_size=1, executor=executor)
        ray_s = time.perf_counter() - t0
    same = bool(np.array_equal(here.cost, there.cost) and np.array_equal(here.sum_rewards, there.sum_rewards)
                and all(np.array_equal(here.cost_parts[k], there.cost_parts[k]) for k in here.cost_parts))
    return {"episodes": episodes, "steps_per_episode": config.horizon_steps, "lines": config.n_lines,
            "ray": address or "local, 2 CPUs", "one_process_s": local_s, "ray_s": ray_s, "identical": same,
            "costs": here.cost.tolist(), "load_average_1min": os.getloadavg()[0]}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[12, 50, 250], help="sections per line (250: the Long id)")
    p.add_argument("--steps", type=int, default=8, help="env steps timed per size (after the reset)")
    p.add_argument("--no-network", action="store_true", help="skip the network episode")
    p.add_argument("--no-ray", action="store_true", help="skip the batch of network episodes on Ray")
    p.add_argument("--ray-episodes", type=int, default=4, help="network episodes of the Ray batch")
    p.add_argument("--ray-horizon-years", type=float, default=1.0, help="horizon of the Ray batch's episodes")
    p.add_argument("--ray-address", default=None, help="a Ray cluster (default: a local Ray of 2 CPUs)")
    p.add_argument("--out", default="results/scale.json")
    a = p.parse_args(argv)
    if a.steps < 1 or any(n < 1 or n > 256 for n in a.sizes):
        p.error("--steps must be >= 1 and --sizes in [1, 256]")
    if a.ray_episodes < 1:
        p.error("--ray-episodes must be >= 1")
    rows = []
    for n in a.sizes:
        done = subprocess.run([sys.executable, "-c", _ONE, str(n), str(a.steps)], capture_output=True, text=True,
                              check=True, env=os.environ.copy())
        rows.append(json.loads(done.stdout.strip().splitlines()[-1]))
        r = rows[-1]
        print(f"{n:4d} sections: reset {r['reset_s']:.1f} s, {r['line_steps_per_s']:.2f} line-steps/s "
              f"({r['section_steps_per_s']:.0f} section-steps/s), peak {r['peak_rss_mb']:.0f} MB "
              f"[load {r['load_average_1min']:.1f}]", flush=True)
    report: dict = {"lines": rows}
    if not a.no_network:
        r = report["network"] = network_episode()
        print(f"network of {r['lines']} x {r['sections_per_line']} sections, one episode of {r['steps']} steps: "
              f"reset {r['reset_s']:.1f} s, {r['line_steps_per_s']:.2f} line-steps/s "
              f"({r['section_steps_per_s']:.0f} section-steps/s), {r['moves']} moves, peak {r['peak_rss_mb']:.0f} MB "
              f"[load {r['load_average_1min']:.1f}]", flush=True)
    if not a.no_ray:
        r = report["ray"] = ray_batch(a.ray_episodes, a.ray_horizon_years, a.ray_address)
        print(f"network batch of {r['episodes']} episodes x {r['steps_per_episode']} steps: one process "
              f"{r['one_process_s']:.1f} s, Ray ({r['ray']}) {r['ray_s']:.1f} s, identical: {r['identical']} "
              f"[load {r['load_average_1min']:.1f}]", flush=True)
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(report, indent=1))
    return 0 if report.get("ray", {}).get("identical", True) else 1


if __name__ == "__main__":
    raise SystemExit(main())
