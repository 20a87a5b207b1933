"""Grid-tune some heuristics on the training seeds and merge their best parameters into the shipped file.

    python experiments/tune_heuristics.py --policies periodic campaign --n-train 32
    python experiments/tune_heuristics.py --policies periodic campaign --n-train 100 --ray-address auto

Each named heuristic is searched over its ``param_grid()`` on the first ``--n-train`` training seeds (all
candidates batched in one run); the best parameters replace that heuristic's entry in ``--file`` (default
``agents/rules/tuned_heuristics.json``, which ``trackenv evaluate`` uses), with the seeds it was tuned on. Entries
of other heuristics are kept as they are. The full tuning tables, with the cost of every candidate in every
episode, go to ``--out``, together with the **hindsight bound**: the mean over episodes of the cheapest
candidate *of that episode*. No rule in the grids can beat it, and a learned policy that beats the best
single rule by much more than the bound's margin would have to act better than every rule in hindsight.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from trackenv.envs.config import TampingEnvConfig
from trackenv_agents.evaluation.harness import TRAIN_SEEDS
from trackenv_agents.evaluation.tuning import tune_many
from trackenv_agents.rules.tamping import HEURISTICS, TUNED_PARAMS_FILE

DEFAULT_FILE = TUNED_PARAMS_FILE


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policies", nargs="+", required=True, choices=sorted(set(HEURISTICS) - {"random"}))
    parser.add_argument("--n-train", type=int, default=32, help=f"training seeds (1 to {len(TRAIN_SEEDS)})")
    parser.add_argument("--file", default=str(DEFAULT_FILE), help="tuned-parameter file to update")
    parser.add_argument("--out", default="results/tuning.json", help="full tuning tables and hindsight bound")
    parser.add_argument("--batch-size", type=int, default=64, help="envs stepped together")
    parser.add_argument("--no-progress", action="store_true")
    parser.add_argument("--ray", action="store_true", help="run the batches as tasks on a local Ray")
    parser.add_argument("--ray-address", default=None, help="run them on a Ray cluster ('auto', ray://HEAD:10001)")
    args = parser.parse_args(argv)
    if not 1 <= args.n_train <= len(TRAIN_SEEDS):
        parser.error(f"--n-train must be in [1, {len(TRAIN_SEEDS)}], got {args.n_train}")
    seeds = list(TRAIN_SEEDS[: args.n_train])
    classes = [HEURISTICS[name] for name in args.policies]
    executor = None
    if args.ray or args.ray_address:
        from trackenv_agents.evaluation.distributed import RayExecutor

        executor = RayExecutor(address=args.ray_address)
    try:
        tuned = tune_many(classes, TampingEnvConfig(), seeds, args.batch_size, not args.no_progress,
                          executor=executor)
    finally:
        if executor is not None:
            executor.close()
    path = Path(args.file)
    data = json.loads(path.read_text()) if path.exists() else {"best_params": {}}
    data.setdefault("tuned_on", {})
    for t in tuned.values():
        name = t["policy"]
        data["best_params"][name] = t["best_params"]
        data["tuned_on"][name] = {"train_seeds": [seeds[0], seeds[-1]], "n_episodes": len(seeds)}
        print(f"{name}: {t['best_params']}  mean cost {t['best_mean_cost']:.1f} k€ on {len(seeds)} episodes")
    path.write_text(json.dumps(data, indent=1) + "\n")
    print(f"updated {path}")
    costs = np.array([row["episode_costs"] for t in tuned.values() for row in t["table"]])
    best_rule = float(costs.mean(axis=1).min())
    hindsight = float(costs.min(axis=0).mean())
    report = {"train_seeds": seeds, "tables": {t["policy"]: t["table"] for t in tuned.values()},
              "best_single_rule_mean_cost": best_rule, "hindsight_bound_mean_cost": hindsight,
              "hindsight_margin": 1.0 - hindsight / best_rule}
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(report, indent=1) + "\n")
    print(f"best single rule {best_rule:.1f} k€; per-episode best of the {costs.shape[0]} candidates "
          f"{hindsight:.1f} k€ ({100 * report['hindsight_margin']:.1f} % lower); tables in {out}")
    return report


if __name__ == "__main__":
    main()
