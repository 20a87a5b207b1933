"""What the race of ``trackenv plan --tune N`` costs in accuracy and saves in episodes.

For each tuning (the grouped threshold on the default line's sections and traffic at 100, 140 and 180 km/h; on the
example line file with the faster passes; the choice rule on the example line planned as a wet line), the full
search runs every candidate of every stage on all ``--tune`` training futures (``tune_plan_rule`` with its race
replaced by :func:`~trackenv_agents.evaluation.tuning.tune`), and its per-future costs are saved. The race
(:func:`~trackenv_agents.evaluation.tuning.race`) is then replayed on those costs (the harness replaced by a lookup:
an episode's cost does not depend on its batch), so that each race is compared with the full search on the same
episodes: whether it chooses the same parameters, and the share of the episodes it runs. ``--replay`` replays the
saved costs only (seconds); ``--rounds 2,4`` replays a race that looks after other numbers of futures (a trial).

    python experiments/tuning_race.py                     # the five tunings, about 40 minutes on 2 cores
    python experiments/tuning_race.py --replay --rounds 2,4

Writes ``experiments/saved/tuning_race.json`` (``--out``).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

import trackenv_agents.plan_tuning as plan_tuning
from trackenv.envs.line_config import scenario
from trackenv_agents.evaluation import tuning
from trackenv_agents.planning import line_policy, plan_config
from trackenv_agents.rules.problems import every_rule

OUT = Path(__file__).resolve().parent / "saved" / "tuning_race.json"
FAST = {"engine": "fast", "pass_reuse_tolerance_m": 1e-3}
EXAMPLE = str(Path(__file__).resolve().parents[1] / "trackenv" / "lines" / "example.yaml")


def cases() -> dict[str, tuple[Any, str, str | None]]:
    """Each tuning's line config (10-year episodes), rule and scenario of its shipped parameters."""
    out: dict[str, tuple[Any, str, str | None]] = {
        f"default line at {v} km/h": (scenario("default", speed_kmh=float(v)), "grouped-threshold", None)
        for v in (100, 140, 180)}
    out["example line (fast)"] = (plan_config(EXAMPLE, "default", **FAST), "grouped-threshold", "default")
    out["example line as a wet line (fast)"] = (plan_config(EXAMPLE, "wet", **FAST), "choice-threshold", "wet")
    return out


def full_search(config: Any, policy: str, preset: str | None, futures: int) -> dict[str, Any]:
    """The tuning of ``tune_plan_rule`` with every candidate on every future: each stage's candidates, their
    per-future costs and the parameters chosen."""
    config = config.replace(horizon_years=plan_tuning.TUNE_YEARS)
    stages: list[dict[str, Any]] = []

    def every_future(cls, cfg, seeds, grid, keep=(), **kw):
        found = tuning.tune(cls, cfg, seeds, grid=grid, **kw)
        stages.append({"candidates": [r["params"] for r in found["table"]],
                       "episode_costs": [r["episode_costs"] for r in found["table"]]})
        return {**found, "dropped": []}

    race, plan_tuning.race = plan_tuning.race, every_future
    try:
        t0 = time.perf_counter()
        chosen = plan_tuning.tune_plan_rule(line_policy(policy, config, preset), config, futures, progress=True)
    finally:
        plan_tuning.race = race
    return {"policy": policy, "futures": futures, "chosen": chosen.params, "shipped": chosen.shipped_params,
            "seconds": round(time.perf_counter() - t0, 1), "stages": stages}


def replay(case: dict[str, Any], rounds: list[int] | None) -> dict[str, Any]:
    """The race on ``case``'s saved costs (``rounds``: other looks than :func:`~tuning.race_rounds`'s): per stage
    the parameters it keeps as best, and the episodes it runs against the full search's."""
    costs: dict[str, list[float]] = {}
    seeds = list(range(1000, 1000 + case["futures"]))
    for stage in case["stages"]:
        for params, per_future in zip(stage["candidates"], stage["episode_costs"], strict=True):
            costs[json.dumps(params, sort_keys=True)] = per_future
    run = {"episodes": 0}

    def lookup(policies, cfg, seeds_now, **kw):
        run["episodes"] += len(policies) * len(seeds_now)
        return [SimpleNamespace(cost=np.array([costs[json.dumps(p.params, sort_keys=True)][s - 1000]
                                               for s in seeds_now]), tampings_per_km_year=np.zeros(len(seeds_now)))
                for p in policies]

    saved = tuning.evaluate_many, tuning.problem_config, tuning.race_rounds
    tuning.evaluate_many, tuning.problem_config = lookup, (lambda config: config)
    if rounds:
        tuning.race_rounds = lambda n: [*(r for r in rounds if r < n), n]
    try:
        cls = every_rule()[case["policy"]]
        out = []
        for stage in case["stages"]:
            full_best = stage["candidates"][int(np.argmin([np.mean(c) for c in stage["episode_costs"]]))]
            shipped = case["shipped"] if case["shipped"] in stage["candidates"] else None
            run["episodes"] = 0
            found = tuning.race(cls, None, seeds, stage["candidates"], keep=[shipped] if shipped else [])
            out.append({"candidates": len(stage["candidates"]), "same_choice": found["best_params"] == full_best,
                        "raced_best_excess": found["best_mean_cost"] / float(np.min(
                            [np.mean(c) for c in stage["episode_costs"]])) - 1.0,
                        "episodes": run["episodes"], "full_episodes": len(stage["candidates"]) * len(seeds),
                        "dropped": len(found["dropped"])})
    finally:
        tuning.evaluate_many, tuning.problem_config, tuning.race_rounds = saved
    return {"stages": out, "episode_share": sum(s["episodes"] for s in out) / sum(s["full_episodes"] for s in out)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--tune", type=int, default=8, help="training futures (as trackenv plan --tune N)")
    ap.add_argument("--replay", action="store_true", help="replay the race on the saved costs only")
    ap.add_argument("--rounds", default="", help="looks of a trial race, e.g. 2,4 (default: the race's own)")
    ap.add_argument("--cases", default="", help="run only the tunings whose label contains one of these "
                    "(comma-separated, e.g. 180,wet), added to the saved file")
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args()
    rounds = [int(r) for r in args.rounds.split(",") if r]
    only = [c for c in args.cases.split(",") if c]
    saved = json.loads(args.out.read_text()) if args.replay or (only and args.out.is_file()) else {"cases": {}}
    if not args.replay:
        for label, (config, policy, preset) in cases().items():
            if only and not any(c in label for c in only):
                continue
            saved["cases"][label] = full_search(config, policy, preset, args.tune)
            args.out.parent.mkdir(parents=True, exist_ok=True)
            args.out.write_text(json.dumps(saved, indent=1) + "\n")
    for label, case in saved["cases"].items():
        result = replay(case, rounds)
        if not rounds:
            case["race"] = result
        same = all(s["same_choice"] for s in result["stages"])
        worst = max(s["raced_best_excess"] for s in result["stages"])
        print(f"{label}: {'the same choice' if same else f'another choice, +{100 * worst:.2f} % in-sample'}, "
              f"{100 * result['episode_share']:.0f} % of the episodes "
              f"({', '.join(str(s['dropped']) + ' of ' + str(s['candidates']) for s in result['stages'])} stopped)")
    if not rounds:
        args.out.write_text(json.dumps(saved, indent=1) + "\n")


if __name__ == "__main__":
    main()
