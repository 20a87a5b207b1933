"""Room to learn on TampingLine: tuned rules vs the best uniform periodic rule vs a hindsight bound (per section;
on the 60 m track, ``--scenario track60``, whose six sections share one segment, of the whole line:
:mod:`trackenv_agents.evaluation.line_hindsight_whole`).

1. Grid-tune every line heuristic on training seeds (``--n-train``, seeds 1000+).
2. Score the tuned rules on held-out seeds (``--n-test``, seeds 0+) with 95 % CIs and paired differences.
3. For ``--n-hindsight`` of those episodes, ``--hindsight-batch`` at a time, the per-section hindsight search
   from the best rule's schedule (:func:`trackenv_agents.evaluation.line_hindsight.hindsight_bounds`), with every tuned
   rule's own schedule on the episode and the best rule's (``--recorded-rules all``: every rule's) under
   ``--designs`` other recording designs as candidates
   (:func:`trackenv_agents.evaluation.line_hindsight.recorded_rule_schedules`).

Searches of other seeds (``--test-start``) merge with ``line_room_summary.py``.

Writes results/line_room.json (and the tuned parameters to the scenario's file of
:data:`trackenv_agents.rules.problems.TUNED_FILES` with ``--save-tuned``; ``--use-saved`` reads them from there);
progress goes to stdout (run it with a log file in the background).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from trackenv.envs.line_config import scenario
from trackenv_agents.evaluation.harness import evaluate_many
from trackenv_agents.evaluation.line_hindsight import (
    RECORDING_DESIGNS,
    hindsight_bounds,
    recorded_rule_schedules,
    room_summary,
    schedule_rows,
)
from trackenv_agents.evaluation.statistics import paired_difference
from trackenv_agents.evaluation.tuning import tune_many
from trackenv_agents.rules.line import LINE_HEURISTICS, UniformPeriodic
from trackenv_agents.rules.problems import tuned_file_for


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenario", default="default")
    ap.add_argument("--n-train", type=int, default=8)
    ap.add_argument("--n-test", type=int, default=100)
    ap.add_argument("--test-start", type=int, default=0, help="first held-out seed")
    ap.add_argument("--n-hindsight", type=int, default=20)
    ap.add_argument("--batch-size", type=int, default=24)
    ap.add_argument("--rounds", type=int, default=3, help="local-search rounds of the hindsight search")
    ap.add_argument("--thresholds", type=float, nargs="+", default=[2.0, 3.0],
                    help="true-SD thresholds [mm] of the hindsight search's closed-loop candidates")
    ap.add_argument("--designs", type=int, default=1,
                    help="how many of RECORDING_DESIGNS (every step without error, twice a year, once a year) give "
                         "the hindsight search the rules' schedules under that recording as candidates (0: none)")
    ap.add_argument("--recorded-rules", choices=("best", "all"), default="best",
                    help="whose schedules under those designs: the best rule's or every tuned rule's")
    ap.add_argument("--hindsight-batch", type=int, default=10, help="episodes searched together (one batch)")
    ap.add_argument("--save-tuned", action="store_true")
    ap.add_argument("--use-saved", action="store_true", help="skip tuning: the saved tuned parameters")
    ap.add_argument("--out", default="results/line_room.json")
    args = ap.parse_args(argv)
    cfg = scenario(args.scenario)
    t0 = time.time()
    classes = [c for n, c in LINE_HEURISTICS.items() if n != "no-maintenance"]
    train = list(range(1000, 1000 + args.n_train))
    if args.use_saved:
        saved = json.loads(tuned_file_for(cfg).read_text())
        best, train = saved["params"], saved["train_seeds"]
    else:
        tuned = tune_many(classes, cfg, train, args.batch_size, progress=True)
        best = {classes[i].name: t["best_params"] for i, t in tuned.items()}
    print("tuned", json.dumps(best), f"{time.time() - t0:.0f}s", flush=True)
    if args.save_tuned and not args.use_saved:
        tuned_file_for(cfg).write_text(json.dumps({"scenario": args.scenario, "train_seeds": train, "params": best},
                                              indent=1) + "\n")
    pols = [LINE_HEURISTICS[n](**p) for n, p in best.items()]
    test = list(range(args.test_start, args.test_start + args.n_test))
    res = evaluate_many(pols, cfg, test, batch_size=args.batch_size, progress=True, desc="test")
    by = {r.policy: r for r in res}
    uniform = by[UniformPeriodic.name]
    aware = min((r for r in res if r.policy != UniformPeriodic.name), key=lambda r: r.cost.mean())
    best_rule = min(res, key=lambda r: r.cost.mean())
    summ = [r.summary() for r in sorted(res, key=lambda r: r.cost.mean())]
    for s in summ:
        print(f"{s['policy']:24s} {s['mean_cost']:8.1f} [{s['ci_low']:.1f}, {s['ci_high']:.1f}]", flush=True)
    d1 = paired_difference(aware, uniform)
    d1["relative"] = d1["mean_difference"] / float(uniform.cost.mean())
    print("state-aware vs uniform", json.dumps(d1), f"{time.time() - t0:.0f}s", flush=True)
    out = {"scenario": args.scenario, "train_seeds": train, "test_seeds": test, "tuned": best,
           "results": summ, "aware_vs_uniform": d1,
           "episode_costs": {r.policy: r.cost.tolist() for r in res},
           "best_rule": best_rule.policy, "best_aware": aware.policy}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=1, default=float))
    # hindsight on the first episodes, from the best rule's own schedule; every tuned rule's own schedule (recorded
    # by the evaluation) and the rules' schedules under other recording designs are candidates too
    own = {r.policy: dict(zip(r.seeds.tolist(), r.tamped, strict=True)) for r in res}
    rule_cost = dict(zip(best_rule.seeds.tolist(), best_rule.cost.tolist(), strict=True))
    designs = RECORDING_DESIGNS[: args.designs]
    recorders = pols if args.recorded_rules == "all" else [p for p in pols if p.name == best_rule.policy]
    hs: list[dict] = []
    seeds = test[: args.n_hindsight]
    for k in range(0, len(seeds), args.hindsight_batch):
        chunk = seeds[k : k + args.hindsight_batch]
        recorded = recorded_rule_schedules(cfg, chunk, recorders, designs) if designs else [[] for _ in chunk]
        episodes = [(s, own[best_rule.policy][s], tuple(own[n][s] for n in own if n != best_rule.policy)
                     + tuple(recorded[i])) for i, s in enumerate(chunk)]
        for h in hindsight_bounds(cfg, episodes, rounds=args.rounds, sd_thresholds_mm=tuple(args.thresholds),
                                  progress=True):
            if abs(h["start_cost"] - rule_cost[h["seed"]]) > 1e-6 * rule_cost[h["seed"]]:
                raise RuntimeError(f"seed {h['seed']}: the search prices the rule's schedule at {h['start_cost']}, "
                                   f"the evaluation at {rule_cost[h['seed']]}")
            hs.append({"seed": h["seed"], "rule": rule_cost[h["seed"]], "hindsight": h["cost"],
                       "replayed": h["replayed_cost"], "search": h["search"],
                       "schedule": schedule_rows(h["schedule"])})
            print("hindsight", json.dumps({k_: v for k_, v in hs[-1].items() if k_ != "schedule"}),
                  f"{time.time() - t0:.0f}s", flush=True)
        out["hindsight"] = {"episodes": hs, "best_rule": best_rule.policy,
                            **room_summary({x["seed"]: x["rule"] for x in hs}, hs)}
        Path(args.out).write_text(json.dumps(out, indent=1, default=float))
        print("room", json.dumps({k_: v for k_, v in out["hindsight"].items()
                                  if k_ not in ("episodes", "per_episode_relative", "seeds")}), flush=True)
    print("done", f"{time.time() - t0:.0f}s", flush=True)
    return out


if __name__ == "__main__":
    main()
