"""The per-section hindsight search on held-out episodes of TampingLine, from a tuned rule's schedule
(:func:`trackenv_agents.line_hindsight.hindsight_bound`), with every tuned rule's schedule under the other
recording designs as candidates (as ``line_room.py``; ``--no-recorded`` leaves them out). Writes
results/line_hindsight.json as it goes, so a long run over many seeds can be split and merged."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from trackenv.envs.line_config import scenario
from trackenv_agents.evaluation import _bound
from trackenv_agents.line_heuristics import LINE_HEURISTICS, line_tuned_params
from trackenv_agents.line_hindsight import hindsight_bound, recorded_rule_schedules, replay, schedule_rows


def main(argv=None) -> list:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenario", default="default")
    ap.add_argument("--rule", default="grouped-threshold")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--thresholds", type=float, nargs="+", default=[2.0, 3.0])
    ap.add_argument("--extra-rules", nargs="*", default=[], help="other tuned rules whose schedules are candidates")
    ap.add_argument("--no-recorded", action="store_true")
    ap.add_argument("--out", default="results/line_hindsight.json")
    args = ap.parse_args(argv)
    cfg = scenario(args.scenario)
    t0, out = time.time(), []

    params = line_tuned_params()
    tuned = [LINE_HEURISTICS[n](**p) for n, p in params.items()]

    def rollout(name, seed):
        return replay(cfg, seed, _bound(LINE_HEURISTICS[name](**params.get(name, {})), cfg))

    for seed in args.seeds:
        plan, rule_cost = rollout(args.rule, seed)
        extra = tuple(rollout(n, seed)[0] for n in args.extra_rules)
        if not args.no_recorded:
            extra += tuple(recorded_rule_schedules(cfg, seed, tuned))
        h = hindsight_bound(cfg, seed, plan, rounds=args.rounds, sd_thresholds_mm=tuple(args.thresholds),
                            extra_schedules=extra)
        out.append({"seed": seed, "rule": args.rule, "rule_cost": rule_cost, "hindsight": h["cost"],
                    "replayed": h["replayed_cost"], "search": h["search"],
                    "tampings_rule": int(plan.sum()), "tampings_hindsight": int(h["schedule"].sum()),
                    "schedule": schedule_rows(h["schedule"])})
        print(json.dumps(out[-1]), f"{time.time() - t0:.0f}s", flush=True)
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(out, indent=1))
    return out


if __name__ == "__main__":
    main()
