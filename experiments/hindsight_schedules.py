"""How much cheaper could a whole-track campaign schedule be if it knew each episode's future?

    python experiments/hindsight_schedules.py --n-episodes 8

For each training episode (seed), a local search over open-loop schedules "tamp every section at steps
S" (S a set of planning steps) looks for the cheapest S *for that episode*: it starts from the best periodic
schedule of that episode and repeatedly tries every schedule one move away (shift one campaign by 1, 2 or 4
steps, drop one, add one between two others or near an end), all candidates of a round simulated together in
one batched env with the episode's seed, and keeps the best until no move helps.

Every good rule found so far tamps the whole track at once (partial campaigns cost more, see
``experiments/tune_heuristics.py``), so the result bounds what *timing* can gain: a policy that decides
only when to tamp the whole track, from what it observes, cannot on average be cheaper than these
per-episode optima. The report compares them with the best single periodic rule on the same episodes.
Writes ``results/hindsight_schedules.json``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from trackenv.envs.config import TampingEnvConfig
from trackenv.envs.vector import TampingVectorEnv
from trackenv_agents.evaluation.harness import TRAIN_SEEDS
from trackenv_agents.rules.tamping import Periodic

# the whole-track intervals of the periodic rule's tuning grid, in steps of the default calendar (4 a year)
PERIODIC_STEPS = tuple(Periodic(**p).interval_steps for p in Periodic.param_grid() if p["sections"] == "all")


def periodic_schedule(interval: int, horizon: int) -> tuple[int, ...]:
    """The steps at which a rule tamping every ``interval`` steps tamps (never at step 0)."""
    return tuple(range(interval, horizon, interval))


def schedule_costs(config: TampingEnvConfig, seed: int, schedules: list[tuple[int, ...]]) -> np.ndarray:
    """Total cost (k€) of each whole-track schedule in the episode of ``seed`` (all simulated together)."""
    venv = TampingVectorEnv(len(schedules), config)
    venv.reset(seed=[int(seed)] * len(schedules))
    due = np.zeros((len(schedules), config.horizon_steps), dtype=bool)
    for row, steps in enumerate(schedules):
        due[row, list(steps)] = True
    cost = np.zeros(len(schedules))
    for step in range(config.horizon_steps):
        action = np.repeat(due[:, step, None], config.n_sections, axis=1).astype(np.int8)
        _, reward, _, _, _ = venv.step(action)
        cost -= reward
    venv.close()
    return cost


def neighbours(schedule: tuple[int, ...], horizon: int) -> list[tuple[int, ...]]:
    """The schedules one move away (no two campaigns in consecutive steps: the env masks a re-tamp)."""
    out = set()
    s = list(schedule)
    for i, step in enumerate(s):
        for shift in (-4, -2, -1, 1, 2, 4):
            out.add(tuple(sorted(s[:i] + [step + shift] + s[i + 1:])))
        out.add(tuple(s[:i] + s[i + 1:]))
    bounds = [0, *s, horizon]
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        if b - a >= 4:
            out.add(tuple(sorted(s + [(a + b) // 2])))
    for extra in (2, 4, horizon - 4):
        out.add(tuple(sorted(set(s + [extra]))))

    def valid(c: tuple[int, ...]) -> bool:
        return (all(1 <= x < horizon for x in c) and len(set(c)) == len(c)
                and all(b - a >= 2 for a, b in zip(c[:-1], c[1:], strict=False)))

    return [c for c in out if valid(c) and c != tuple(schedule)]


def search(config: TampingEnvConfig, seed: int, max_rounds: int = 8) -> dict:
    """Local search for the cheapest whole-track schedule of one episode (see the module docstring)."""
    horizon = config.horizon_steps
    starts = [periodic_schedule(k, horizon) for k in PERIODIC_STEPS]
    start_costs = schedule_costs(config, seed, starts)
    best_i = int(np.argmin(start_costs))
    best, best_cost = starts[best_i], float(start_costs[best_i])
    evaluated = len(starts)
    for _ in range(max_rounds):
        cand = neighbours(best, horizon)
        costs = schedule_costs(config, seed, cand)
        evaluated += len(cand)
        i = int(np.argmin(costs))
        if costs[i] >= best_cost - 1e-9:
            break
        best, best_cost = cand[i], float(costs[i])
    return {"seed": int(seed), "periodic_costs": dict(zip(PERIODIC_STEPS, start_costs.tolist(), strict=True)),
            "best_schedule_steps": list(best), "best_cost": best_cost, "schedules_evaluated": evaluated}


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n-episodes", type=int, default=8, help=f"training seeds (1 to {len(TRAIN_SEEDS)})")
    parser.add_argument("--max-rounds", type=int, default=8, help="improvement rounds per episode")
    parser.add_argument("--out", default="results/hindsight_schedules.json")
    args = parser.parse_args(argv)
    if not 1 <= args.n_episodes <= len(TRAIN_SEEDS):
        parser.error(f"--n-episodes must be in [1, {len(TRAIN_SEEDS)}], got {args.n_episodes}")
    if args.max_rounds < 0:
        parser.error(f"--max-rounds must be >= 0, got {args.max_rounds}")
    config = TampingEnvConfig()
    t0 = time.time()
    episodes = [search(config, seed, args.max_rounds)
                for seed in tqdm(TRAIN_SEEDS[: args.n_episodes], desc="episodes", unit="ep")]
    periodic = np.array([[e["periodic_costs"][k] for k in PERIODIC_STEPS] for e in episodes])
    best_rule_i = int(np.argmin(periodic.mean(axis=0)))
    best_rule = float(periodic[:, best_rule_i].mean())
    optimum = float(np.mean([e["best_cost"] for e in episodes]))
    report = {
        "config": config.to_dict(), "episodes": episodes,
        "best_periodic_interval_years": PERIODIC_STEPS[best_rule_i] / config.steps_per_year,
        "best_periodic_mean_cost": best_rule,
        "per_episode_best_periodic_mean_cost": float(periodic.min(axis=1).mean()),
        "hindsight_schedule_mean_cost": optimum,
        "hindsight_margin_vs_best_periodic": 1.0 - optimum / best_rule,
        "wall_seconds": time.time() - t0,
    }
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(report, indent=1))
    print(f"{len(episodes)} episodes: best periodic rule ({report['best_periodic_interval_years']} yr) "
          f"{best_rule:.1f} k€; per-episode best periodic {report['per_episode_best_periodic_mean_cost']:.1f}; "
          f"per-episode best whole-track schedule in hindsight {optimum:.1f} "
          f"({100 * report['hindsight_margin_vs_best_periodic']:.1f} % below the rule) -> {out}")
    return report


if __name__ == "__main__":
    main()
