"""Refine the tuned line rules on more training episodes: each rule's saved best and its neighbours
(:data:`NEIGHBOURS`) scored together on ``--n-train`` training seeds 1000+ (default 32; the grid search of
``line_room.py`` uses 8), on common random numbers; the cheapest per rule is kept (``--save`` writes it to
agents/rules/line_tuned_heuristics.json with the seeds it was chosen on).

Why: the grids are searched on 8 episodes, where neighbouring points differ by less than the spread between
episodes; the rules are the learner's yardstick, so their parameters get the same care as the learner's.
"""

from __future__ import annotations

import argparse
import json
import time

from trackenv.envs.line_config import scenario
from trackenv_agents.evaluation.harness import evaluate_many
from trackenv_agents.rules.line import LINE_HEURISTICS, LINE_TUNED_FILE

#: the candidates scored besides each rule's saved best (the points around the 8-episode optimum of 2026-12-02)
NEIGHBOURS: dict[str, list[dict]] = {
    "grouped-threshold": [{"trigger_mm": t, "include_mm": i} for t in (3.0, 3.25, 3.5, 3.75, 4.0)
                          for i in (1.75, 2.0, 2.25)],
    "section-threshold": [{"threshold_mm": v} for v in (1.75, 2.0, 2.25)],
    "budgeted-worst-first": [{"every_years": 1.0, "n_worst": k, "min_sd_mm": 2.0} for k in (4, 5, 6)],
    "register-periodic": [{"plain_years": 6.0, "zone_years": 1.0}],
    "uniform-periodic": [{"interval_years": 2.0, "offset_years": 0.0}],
}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenario", default="default")
    ap.add_argument("--rules", nargs="+", default=list(NEIGHBOURS))
    ap.add_argument("--n-train", type=int, default=32, help="training episodes: seeds 1000..1000+N-1")
    ap.add_argument("--batch-size", type=int, default=64)
    ap.add_argument("--save", action="store_true")
    args = ap.parse_args(argv)
    cfg = scenario(args.scenario)
    saved = json.loads(LINE_TUNED_FILE.read_text())
    seeds = list(range(1000, 1000 + args.n_train))
    best = saved["params"]
    t0 = time.time()
    keys = []
    for name in args.rules:
        keys += [(name, p) for p in [best[name]] + [p for p in NEIGHBOURS.get(name, []) if p != best[name]]]
    res = evaluate_many([LINE_HEURISTICS[n](**p) for n, p in keys], cfg, seeds, batch_size=args.batch_size,
                        progress=True, desc="refine")
    out: dict[str, list] = {}
    for (name, p), r in zip(keys, res, strict=True):
        out.setdefault(name, []).append((float(r.cost.mean()), p))
        print(name, json.dumps(p), f"{r.cost.mean():.1f}", flush=True)
    for name, rows in out.items():
        cost, p = min(rows, key=lambda x: x[0])
        print("best", name, json.dumps(p), f"{cost:.1f}", "(was", json.dumps(best[name]) + ")", flush=True)
        best[name] = p
    if args.save:
        saved["params"] = best
        saved["refine_seeds"] = seeds
        LINE_TUNED_FILE.write_text(json.dumps(saved, indent=1) + "\n")
    print(f"done {time.time() - t0:.0f}s", flush=True)
    return out


if __name__ == "__main__":
    main()
