"""Screen TampingLine design variants for room to learn, cheaply, before a full ``line_room.py`` run.

For one variant of the default line (``--set name=value`` overrides, validated by :class:`LineConfig`):

1. grid-tune grouped-threshold and section-threshold (the two best state-aware families on the default line)
   and uniform periodic on ``--seeds`` (in sample: the rule is tuned on the very episodes it is scored on, which
   favours the rule, so the room measured here is conservative);
2. the per-section hindsight search (:func:`trackenv_agents.evaluation.line_hindsight.hindsight_bound`, ``--rounds``
   local-search rounds) from the best state-aware rule's schedule on the same episodes, with the three rules'
   schedules under the other recording designs as candidates, as ``line_room.py`` does (``--no-recorded``: without
   them, as in the first screen of the results).

Prints and writes (``--out``) the mean costs, the state-aware vs uniform gap and the hindsight vs rule gap per
episode. A variant worth a full run shows a hindsight gap clearly above 10 % here.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from trackenv.envs.line_config import scenario
from trackenv_agents.evaluation.harness import bind_policy
from trackenv_agents.evaluation.line_hindsight import hindsight_bound, recorded_rule_schedules, replay
from trackenv_agents.evaluation.tuning import tune_many
from trackenv_agents.rules.line import LINE_HEURISTICS, GroupedThreshold, SectionThreshold, UniformPeriodic


def _value(text: str):
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--set", nargs="*", default=[], metavar="NAME=VALUE", help="LineConfig overrides")
    ap.add_argument("--seeds", default="1000:1004")
    ap.add_argument("--rounds", type=int, default=1)
    ap.add_argument("--batch-size", type=int, default=24)
    ap.add_argument("--no-recorded", action="store_true")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    overrides = {k: _value(v) for k, v in (s.split("=", 1) for s in args.set)}
    cfg = scenario("default", **overrides)
    a, b = (int(v) for v in args.seeds.split(":"))
    seeds = list(range(a, b))
    t0 = time.time()
    classes = [GroupedThreshold, SectionThreshold, UniformPeriodic]
    tuned = tune_many(classes, cfg, seeds, args.batch_size, progress=False)
    best = {classes[i].name: t for i, t in tuned.items()}
    for name, t in best.items():
        print(f"{name:20s} {t['best_mean_cost']:8.1f} {json.dumps(t['best_params'])}", flush=True)
    aware = min((t for n, t in best.items() if n != UniformPeriodic.name), key=lambda t: t["best_mean_cost"])
    uniform = best[UniformPeriodic.name]
    out = {"overrides": overrides, "seeds": seeds, "rules": {n: {k: t[k] for k in ("best_params", "best_mean_cost")}
                                                             for n, t in best.items()},
           "aware_vs_uniform": 1.0 - aware["best_mean_cost"] / uniform["best_mean_cost"], "episodes": []}
    print(f"aware vs uniform: -{100 * out['aware_vs_uniform']:.1f} %  ({time.time() - t0:.0f} s)", flush=True)
    pol = bind_policy(LINE_HEURISTICS[aware["policy"]](**aware["best_params"]), cfg)
    rules = [cls(**best[cls.name]["best_params"]) for cls in classes]
    rule_costs = aware["table"][0]["episode_costs"]
    for seed, rule_cost in zip(seeds, rule_costs, strict=True):
        plan, _ = replay(cfg, seed, pol)
        extra = () if args.no_recorded else tuple(recorded_rule_schedules(cfg, [seed], rules)[0])
        h = hindsight_bound(cfg, seed, plan, rounds=args.rounds, sd_thresholds_mm=(2.0, 3.0), extra_schedules=extra)
        out["episodes"].append({"seed": seed, "rule": rule_cost, "hindsight": h["cost"], "search": h["search"]})
        print(f"seed {seed}: rule {rule_cost:.1f} hindsight {h['cost']:.1f} "
              f"({100 * (h['cost'] / rule_cost - 1):+.1f} %)  ({time.time() - t0:.0f} s)", flush=True)
    r = np.array([e["rule"] for e in out["episodes"]])
    h = np.array([e["hindsight"] for e in out["episodes"]])
    out["hindsight_gap"] = float(1.0 - h.sum() / r.sum())
    print(f"hindsight vs {aware['policy']}: -{100 * out['hindsight_gap']:.1f} % of the mean "
          f"({time.time() - t0:.0f} s)", flush=True)
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(out, indent=1, default=float))
    return out


if __name__ == "__main__":
    main()
