"""The line envs with the classic and the fast pass engine (``LineConfig.engine``): throughput, and how much an
episode's cost moves.

    python experiments/engine_ab.py speed --pairs 4 --budget 15   # alternating processes, saved to experiments/saved/
    python experiments/engine_ab.py time --engine fast            # one process's figures (what speed runs)
    python experiments/engine_ab.py costs --seeds 8               # one episode per seed and engine

``speed``: ``TampingLine-v0`` (random actions, line-steps/s) and its 8-line native vector env (env steps/s), as
``trackenv bench`` measures them (a reset, a warm-up step, then steps for ``--budget`` seconds each), each
engine in its own process, in the order A B B A A B ... so that a drift of the machine over the run favours
neither. Each process also reports the CPU seconds of its steps (all threads) and the load average. Both sides
run with the same environment (``import trackenv`` sets the OpenMP wait policy for both).

``costs``: one episode of ``TampingLine-v0`` per seed under the grouped-threshold rule (its defaults), with each
engine: the episode's cost (minus the summed reward) and its parts, and the relative difference fast − classic.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from ab_speed import load_range, timed_runs  # experiments/ab_speed.py: the scripts run from experiments/

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "experiments" / "saved" / "engine_ab.json"
ENGINES = ("classic", "fast")
ENV_ID = "trackenv/TampingLine-v0"


def _steps_per_s(env, budget_s: float) -> tuple[float, float]:
    """Random-action steps/s of ``env`` (reset, one warm-up step, then ``budget_s`` seconds) and CPU s per step."""
    env.action_space.seed(0)
    env.reset(seed=0)
    env.step(env.action_space.sample())
    steps, cpu0, began = 0, time.process_time(), time.perf_counter()
    while time.perf_counter() - began < budget_s:
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        steps += 1
        if np.ndim(terminated) == 0 and (terminated or truncated):  # (the vector env resets its own lines)
            env.reset()
    wall = time.perf_counter() - began
    return steps / wall, (time.process_time() - cpu0) / steps


def time_engine(engine: str, budget_s: float) -> dict:
    """This process's figures with ``engine``: the line env's line-steps/s and the 8-line vector env's env
    steps/s, with CPU seconds per step."""
    import gymnasium as gym

    from trackenv.envs.line import TampingLineVectorEnv

    line, line_cpu = _steps_per_s(gym.make(ENV_ID, engine=engine), budget_s)
    vector, vector_cpu = _steps_per_s(TampingLineVectorEnv(8, scenario="default", engine=engine), budget_s)
    return {"engine": engine, "line_steps_per_s": line, "line_cpu_s_per_step": line_cpu,
            "vector8_env_steps_per_s": 8 * vector, "vector8_cpu_s_per_vector_step": vector_cpu,
            "load": os.getloadavg()[0]}


def speed(pairs: int, budget_s: float) -> dict:
    runs = timed_runs(ENGINES, pairs,
                      lambda engine: [sys.executable, __file__, "time", "--engine", engine, "--budget", str(budget_s)])
    keys = ("line_steps_per_s", "vector8_env_steps_per_s", "line_cpu_s_per_step", "vector8_cpu_s_per_vector_step")
    med = {e: {k: statistics.median(r[k] for r in v) for k in keys} for e, v in runs.items()}
    pair_ratios = {k: [f[k] / c[k] for c, f in zip(runs["classic"], runs["fast"])] for k in keys[:2]}
    summary = {"median": med, "median_ratio": {k: statistics.median(v) for k, v in pair_ratios.items()},
               "cpu_ratio": {k: med["classic"][k] / med["fast"][k] for k in keys[2:]},
               "pair_ratios": pair_ratios, "load_range": load_range(runs), "pairs": pairs,
               "budget_s": budget_s, "cpus": os.cpu_count(), "runs": runs}
    print(json.dumps({k: summary[k] for k in ("median", "median_ratio", "cpu_ratio", "load_range")}))
    return summary


def episode(engine: str, seed: int) -> dict:
    """One episode of the line env under the grouped-threshold rule: its cost and cost parts."""
    import gymnasium as gym

    sys.path.insert(0, str(ROOT))
    from agents.rules.line import GroupedThreshold

    env, policy = gym.make(ENV_ID, engine=engine), GroupedThreshold()
    obs, _ = env.reset(seed=seed)
    cost, parts, done = 0.0, {}, False
    while not done:
        obs, reward, terminated, truncated, info = env.step(policy.predict(obs, deterministic=True)[0])
        cost -= float(reward)
        for key, value in info["costs"].items():
            parts[key] = parts.get(key, 0.0) + float(np.sum(value))
        done = terminated or truncated
    return {"cost": cost, "parts": parts}


def costs(seeds: int) -> dict:
    rows = []
    for seed in range(seeds):
        res = {e: episode(e, seed) for e in ENGINES}
        c, f = res["classic"]["cost"], res["fast"]["cost"]
        rows.append({"seed": seed, "classic": res["classic"], "fast": res["fast"], "relative": (f - c) / c})
        print(f"seed {seed}: classic {c:9.3f}  fast {f:9.3f}  {100 * (f - c) / c:+.3f} %", flush=True)
    rel = [abs(r["relative"]) for r in rows]
    summary = {"policy": "grouped-threshold", "env_id": ENV_ID, "seeds": seeds,
               "mean_relative": statistics.mean(r["relative"] for r in rows),
               "mean_abs_relative": statistics.mean(rel), "max_abs_relative": max(rel), "episodes": rows}
    print(json.dumps({k: summary[k] for k in ("mean_relative", "mean_abs_relative", "max_abs_relative")}))
    return summary


def _save(key: str, record: dict) -> None:
    saved = json.loads(OUT.read_text()) if OUT.exists() else {}
    OUT.write_text(json.dumps({**saved, key: record}, indent=1) + "\n")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("what", choices=("speed", "time", "costs"))
    parser.add_argument("--engine", choices=ENGINES, default="fast")
    parser.add_argument("--pairs", type=int, default=4)
    parser.add_argument("--budget", type=float, default=15.0, help="seconds per figure")
    parser.add_argument("--seeds", type=int, default=8)
    args = parser.parse_args()
    if args.what == "speed":
        _save("speed", speed(args.pairs, args.budget))
    elif args.what == "costs":
        _save("costs", costs(args.seeds))
    else:
        print(json.dumps(time_engine(args.engine, args.budget)))


if __name__ == "__main__":
    main()
