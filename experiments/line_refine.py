"""Refine the tuned line rules whose best parameters sit at the edge of the grid searched so far: tune again on
the same training seeds over only the grid points not yet scored, keep a new point only if it beats the saved
best on those seeds, and update agents/line_tuned_heuristics.json (``--save``). Scores of the saved best are
recomputed on the same seeds, so old and new points are compared on common random numbers."""

from __future__ import annotations

import argparse
import json
import time

from trackenv.envs.line_config import scenario
from trackenv_agents.evaluation import evaluate_many
from trackenv_agents.line_heuristics import LINE_HEURISTICS, LINE_TUNED_FILE


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenario", default="default")
    ap.add_argument("--rules", nargs="+", default=[n for n in LINE_HEURISTICS if n != "no-maintenance"])
    ap.add_argument("--skip", type=json.loads, default={}, help="JSON {rule: [params already scored, ...]}")
    ap.add_argument("--batch-size", type=int, default=24)
    ap.add_argument("--save", action="store_true")
    args = ap.parse_args(argv)
    cfg = scenario(args.scenario)
    saved = json.loads(LINE_TUNED_FILE.read_text())
    seeds, best = saved["train_seeds"], saved["params"]
    t0 = time.time()
    pols, keys = [], []
    for name in args.rules:
        cls = LINE_HEURISTICS[name]
        done = args.skip.get(name, [])
        grid = [best[name]] + [p for p in cls.param_grid() if p != best[name] and p not in done]
        pols += [cls(**p) for p in grid]
        keys += [(name, p) for p in grid]
    res = evaluate_many(pols, cfg, seeds, batch_size=args.batch_size, progress=True, desc="refine")
    out = {}
    for (name, p), r in zip(keys, res, strict=True):
        out.setdefault(name, []).append((float(r.cost.mean()), p))
        print(name, json.dumps(p), f"{r.cost.mean():.1f}", flush=True)
    for name, rows in out.items():
        cost, p = min(rows, key=lambda x: x[0])
        print("best", name, json.dumps(p), f"{cost:.1f}", "(was", json.dumps(best[name]) + ")", flush=True)
        best[name] = p
    if args.save:
        saved["params"] = best
        LINE_TUNED_FILE.write_text(json.dumps(saved, indent=1) + "\n")
    print(f"done {time.time() - t0:.0f}s", flush=True)
    return out


if __name__ == "__main__":
    main()
