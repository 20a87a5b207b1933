"""What ``trackenv plan --tune N`` is worth: the rule tuned on a line against the shipped parameters, on futures the
tuning did not see.

For each line (the default line's sections and traffic at ``--speeds`` km/h: a faster line has tighter limits and a
dearer geometry per millimetre than the 100 km/h line the shipped parameters were tuned on), the rule ``--policy``
(default the grouped threshold; a choice rule on a line file of a ``--scenario`` with the choices) is tuned as
``--tune`` tunes it (:func:`trackenv_agents.plan_tuning.tune_plan_rule`: its grid and the shipped
parameters on ``--tune`` training futures of 10 years, seeds 1000..), then the tuned and the shipped rule run the
held-out episodes ``--seeds`` (10 years each), paired per episode (95 % bootstrap CI of the mean difference).
``--line-file PATH`` does the same on a line file (from its state as of the file, as ``trackenv plan`` models it),
``--fast`` on the faster passes (``--engine fast --pass-reuse-mm 1``) for both. ``--network PATH``: a network
file planned over 10 years as ``trackenv plan NETWORK.yaml`` plans it, with ``--tune`` and without (each line's rule
tuned on the line alone, then the lines sharing the machine), on the futures ``--seeds``, paired per future.

    python experiments/plan_tuning.py                       # 100, 140 and 180 km/h, --tune 8, seeds 0:100
    python experiments/plan_tuning.py --speeds '' --line-file trackenv/lines/example.yaml --seeds 0:32 --fast \
        --out experiments/saved/plan_tuning_example.json
    python experiments/plan_tuning.py --speeds '' --line-file trackenv/lines/example.yaml --scenario wet \
        --policy choice-threshold --seeds 0:32 --fast --out experiments/saved/plan_tuning_example_wet.json

Writes ``experiments/saved/plan_tuning.json`` (``--out``); about 8 minutes per line of 12 sections on two cores,
15 for the example line's 100 sections with ``--fast``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from trackenv.envs.line_config import scenario
from trackenv_agents.evaluation.harness import evaluate_many
from trackenv_agents.evaluation.line_compare import parse_seeds
from trackenv_agents.evaluation.statistics import bootstrap_ci, paired_difference
from trackenv_agents.network_plan import plan_network
from trackenv_agents.plan_tuning import TUNE_YEARS, tune_plan_rule
from trackenv_agents.planning import line_policy, plan_config

OUT = Path(__file__).resolve().parent / "saved" / "plan_tuning.json"


def one_line(label: str, config, futures: int, seeds: list[int], policy: str, scenario: str | None) -> dict:
    """The tuning of ``policy`` with the shipped parameters of ``scenario`` (None: the config's preset) and the
    held-out comparison on the line of ``config`` (10-year episodes)."""
    config = config.replace(horizon_years=TUNE_YEARS)
    shipped = line_policy(policy, config, scenario)
    t0 = time.perf_counter()
    tuning = tune_plan_rule(shipped, config, futures, progress=True)
    tuned = type(shipped)(**tuning.params)
    tuned_s = time.perf_counter() - t0
    results = evaluate_many([shipped, tuned], config, seeds, progress=True, desc=f"held out, {label}")
    diff = paired_difference(results[1], results[0])
    base = float(results[0].cost.mean())
    return {"line": label, "policy": policy, "scenario": scenario, "engine": config.engine,
            "tuning": tuning.to_dict(), "tuning_s": round(tuned_s, 1),
            "held_out": {"episodes": len(seeds), "seeds": [seeds[0], seeds[-1]], "shipped_keur": base,
                         "tuned_keur": float(results[1].cost.mean()), "tuned_minus_shipped": diff,
                         "relative": diff["mean_difference"] / base,
                         "relative_ci": [diff["ci_low"] / base, diff["ci_high"] / base]}}


def one_network(path: str, futures: int, seeds: list[int], fast: dict, policy: str) -> dict:
    """The network's 10-year plan with each line's rule tuned (``futures`` training futures) and with the shipped
    parameters, on the plan's futures ``seeds`` (consecutive), paired per future."""
    kw = dict(policy=policy, years=TUNE_YEARS, futures=len(seeds), seed=seeds[0], **fast)
    t0 = time.perf_counter()
    tuned = plan_network(path, tune=futures, progress=lambda n: None, **kw)
    tuned_s = time.perf_counter() - t0
    shipped = plan_network(path, **kw)
    a, b = tuned.costs.sum(axis=1), shipped.costs.sum(axis=1)
    low, high = bootstrap_ci(a - b)
    lines = [{"line": p.line.name, "tuning": p.tuning.to_dict(), "shipped_keur": float(s.costs.sum(axis=1).mean()),
              "tuned_keur": float(p.costs.sum(axis=1).mean())} for p, s in zip(tuned.lines, shipped.lines, strict=True)]
    return {"network": path, "engine": fast.get("engine", "classic"), "tuning_and_plan_s": round(tuned_s, 1),
            "futures": len(seeds), "seeds": [seeds[0], seeds[-1]], "shipped_keur": float(b.mean()),
            "tuned_keur": float(a.mean()), "tuned_minus_shipped": float((a - b).mean()), "ci": [low, high],
            "relative": float((a - b).mean() / b.mean()), "cheaper_in": int((a < b).sum()),
            "moves_shipped_keur": float(shipped.move_costs.sum(axis=1).mean()),
            "moves_tuned_keur": float(tuned.move_costs.sum(axis=1).mean()), "lines": lines}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--speeds", default="100,140,180", help="the default line at these speeds, km/h, comma-separated")
    ap.add_argument("--line-file", default=None, help="a line file, after the speeds")
    ap.add_argument("--network", default=None, help="a network file, after the lines")
    ap.add_argument("--policy", default="grouped-threshold", help="the rule tuned (a choice rule with --scenario)")
    ap.add_argument("--scenario", default="default", help="how a line file is modelled (as trackenv plan --scenario)")
    ap.add_argument("--fast", action="store_true", help="the faster passes (engine fast, pass reuse 1 mm)")
    ap.add_argument("--tune", type=int, default=8, help="training futures (as trackenv plan --tune N)")
    ap.add_argument("--seeds", default="0:100", help="held-out episodes A:B")
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args()
    seeds = parse_seeds(args.seeds)
    fast = {"engine": "fast", "pass_reuse_tolerance_m": 1e-3} if args.fast else {}
    lines = [(f"{float(v):g} km/h", scenario("default", speed_kmh=float(v), **fast))
             for v in args.speeds.split(",") if v]
    if args.line_file:
        lines.append((args.line_file, plan_config(args.line_file, args.scenario, **fast)))
    rows = []
    for label, config in lines:
        rows.append(one_line(label, config, args.tune, seeds, args.policy,
                             args.scenario if label == args.line_file else None))
        h = rows[-1]["held_out"]
        print(f"{label}: tuned {rows[-1]['tuning']['params']} — shipped {h['shipped_keur']:.1f}, tuned "
              f"{h['tuned_keur']:.1f} k€, {100 * h['relative']:+.1f} % [{100 * h['relative_ci'][0]:+.1f}, "
              f"{100 * h['relative_ci'][1]:+.1f}]", flush=True)
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps({"rule": args.policy, "lines": rows}, indent=1) + "\n")
    if args.network:
        row = one_network(args.network, args.tune, seeds, fast, args.policy)
        print(f"{args.network}: shipped {row['shipped_keur']:.1f}, tuned {row['tuned_keur']:.1f} k€ over 10 years, "
              f"{100 * row['relative']:+.1f} %, CI {row['ci']}, cheaper in {row['cheaper_in']} of {len(seeds)}",
              flush=True)
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps({"rule": args.policy, "lines": rows, "network": row}, indent=1) + "\n")


if __name__ == "__main__":
    main()
