"""What the choices are worth: the rules that use them against the best tamping-only rule, and the value of
information (the same family with and without inspections and surveys), on the three ids with every choice.

For each scenario (``choices``: ``trackenv/TampingLine-v1``; ``wet``: ``trackenv/TampingLineWet-v0``;
``defects``: ``trackenv/TampingLineDefects-v0``):

1. ``--tune``: the grouped threshold (the best tamping rule) over a small grid of campaigns on the training
   seeds, then the choice rules (:mod:`trackenv_agents.rules.choices`) around the best campaign
   (:func:`~trackenv_agents.rules.choices.choice_grid`); the tuned parameters are written to
   ``agents/rules/<scenario>_tuned_heuristics.json`` (what ``trackenv evaluate`` reads by default).
2. The three tuned rules on the held-out seeds (``--seeds``, default 0:100), paired per episode: the choice rule
   against the grouped threshold, and against the same family without looking; saved as
   ``experiments/saved/choices_compare_<scenario>.json`` (per-episode costs and the paired differences).
3. ``--report``: the saved scenarios as one Markdown table (``experiments/saved/choices_compare.md``) and a plot.

    python experiments/choices_compare.py --scenario wet --tune          # one scenario: tune, then score
    python experiments/choices_compare.py --report                       # the table and the plot
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from trackenv.envs.line_config import scenario
from trackenv_agents.evaluation.harness import evaluate_many
from trackenv_agents.evaluation.line_compare import parse_seeds
from trackenv_agents.evaluation.statistics import paired_difference
from trackenv_agents.evaluation.tuning import tune_many
from trackenv_agents.rules.choices import ChoiceThreshold, ChoiceThresholdNoLooking, choice_grid
from trackenv_agents.rules.line import GroupedThreshold
from trackenv_agents.rules.problems import TUNED_FILES

SAVED = Path(__file__).resolve().parent / "saved"
IDS = {"choices": "trackenv/TampingLine-v1", "wet": "trackenv/TampingLineWet-v0",
       "defects": "trackenv/TampingLineDefects-v0"}
#: what the issue asks of each scenario: the choice rule's cost at most this share of the tamping-only rule's
TARGET = {"choices": 1.0, "wet": 0.90, "defects": 0.95}
#: the grouped threshold's campaigns searched on each scenario (trigger, include) [mm]
CAMPAIGNS = ((3.5, 1.75), (3.0, 1.5), (2.5, 1.25), (2.5, 1.5))
RULES = (GroupedThreshold, ChoiceThreshold, ChoiceThresholdNoLooking)


def tune(name: str, train_seeds: list[int], batch_size: int) -> dict[str, Any]:
    """Tune the three rules on ``train_seeds`` of scenario ``name`` and write its tuned-parameter file."""
    cfg = scenario(name)
    grids = [[{"trigger_mm": t, "include_mm": i} for t, i in CAMPAIGNS]]
    best = tune_many([GroupedThreshold], cfg, train_seeds, batch_size, False, grids=grids,
                     action_type="choices")[0]
    base = best["best_params"]
    family = [ChoiceThreshold, ChoiceThresholdNoLooking]
    tuned = tune_many(family, cfg, train_seeds, batch_size, False, grids=[choice_grid(c, base) for c in family],
                      action_type="choices")
    params = {GroupedThreshold.name: base, **{family[i].name: v["best_params"] for i, v in tuned.items()}}
    tables = {GroupedThreshold.name: best["table"], **{family[i].name: v["table"] for i, v in tuned.items()}}
    payload = {"scenario": name, "train_seeds": train_seeds, "tuned_by": "experiments/choices_compare.py --tune",
               "params": params,
               "train_mean_cost": {rule: [{"params": row["params"], "mean_cost": row["mean_cost"]} for row in table]
                                   for rule, table in tables.items()}}
    TUNED_FILES[name].write_text(json.dumps(payload, indent=1) + "\n")
    return params


def evaluate(name: str, params: dict[str, Any], seeds: list[int], batch_size: int) -> dict[str, Any]:
    """The three tuned rules on ``seeds`` of scenario ``name``, with the paired differences."""
    cfg = scenario(name)
    results = evaluate_many([cls(**params[cls.name]) for cls in RULES], cfg, seeds, action_type="choices",
                            batch_size=batch_size)
    by = {r.policy: r for r in results}
    tamping, choice, blind = (by[cls.name] for cls in RULES)

    def compare(a, b) -> dict[str, Any]:
        d = paired_difference(a, b)
        return {**d, "relative": d["mean_difference"] / float(b.cost.mean()),
                "relative_ci": [d["ci_low"] / float(b.cost.mean()), d["ci_high"] / float(b.cost.mean())]}

    return {"scenario": name, "env": IDS[name], "seeds": seeds,
            "rules": {r.policy: {**r.summary(), "episode_costs": r.cost.tolist()} for r in results},
            "choices_vs_tamping": compare(choice, tamping), "value_of_information": compare(choice, blind),
            "target_ratio": TARGET[name]}


def report(names: list[str]) -> str:
    """The saved scenarios as a Markdown table, and the plot beside it."""
    rows = ["| id | grouped threshold (tamping only) k€ | choice rule k€ | choices vs tamping only (paired, 95 % CI) "
            "| issue asks | met | without looking k€ | value of information (paired, 95 % CI) |",
            "|---|---:|---:|---:|---|---|---:|---:|"]
    saved = [json.loads((SAVED / f"choices_compare_{n}.json").read_text()) for n in names
             if (SAVED / f"choices_compare_{n}.json").exists()]
    for s in saved:
        r = s["rules"]
        cvt, voi = s["choices_vs_tamping"], s["value_of_information"]
        target = s["target_ratio"]
        met = cvt["relative"] <= target - 1.0 if target < 1.0 else cvt["mean_difference"] <= 0.0
        ask = "no worse" if target >= 1.0 else f"≤ {100 * (target - 1):.0f} %"
        rows.append(
            f"| `{s['env']}` | {r['grouped-threshold']['mean_cost']:.0f} | {r['choice-threshold']['mean_cost']:.0f} "
            f"| {cvt['mean_difference']:+.0f} [{cvt['ci_low']:+.0f}, {cvt['ci_high']:+.0f}] "
            f"({100 * cvt['relative']:+.1f} %) | {ask} | {'yes' if met else 'no'} "
            f"| {r['choice-threshold-no-looking']['mean_cost']:.0f} "
            f"| {-voi['mean_difference']:+.0f} [{-voi['ci_high']:+.0f}, {-voi['ci_low']:+.0f}] "
            f"({-100 * voi['relative']:+.1f} %) |")
    n = {len(s["seeds"]) for s in saved}
    rows.append("")
    spans = sorted({f"{s['seeds'][0]}–{s['seeds'][-1]}" for s in saved})
    rows.append(f"Held-out seeds: {', '.join(spans)} "
                f"({'/'.join(str(k) for k in sorted(n))} episodes per rule and id); costs are means per 10-year "
                "episode; differences are the choice rule minus the other, paired per episode; the value of "
                "information is what looking saves (the rule without inspections and surveys minus the one with).")
    rows.append("")
    rows.append("| id | rule | " + " | ".join(("tamp", "spot_tamp", "drainage", "renew", "inspect", "survey"))
                + " |")
    rows.append("|---|---|" + "---:|" * 6)
    for s in saved:
        for rule, v in s["rules"].items():
            rows.append(f"| `{s['env']}` | {rule} | " + " | ".join(f"{v['choices'][c]:.1f}" for c in
                                                                  ("tamp", "spot_tamp", "drainage", "renew",
                                                                   "inspect", "survey")) + " |")
    table = "\n".join(rows)
    (SAVED / "choices_compare.md").write_text(table + "\n")
    if saved:
        plot(saved, str(SAVED / "choices_compare.png"))
    return table


def plot(saved: list[dict[str, Any]], out_png: str) -> str:
    """The relative paired differences with their 95 % CIs, per id: choices vs tamping only, and the value of
    information."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.0, 3.8))
    ax = fig.subplots()
    x = np.arange(len(saved))
    for k, (key, label, sign) in enumerate((("choices_vs_tamping", "choice rule vs grouped threshold", 1.0),
                                           ("value_of_information", "choice rule vs no looking", 1.0))):
        mid = np.array([sign * 100 * s[key]["relative"] for s in saved])
        lo = np.array([sign * 100 * s[key]["relative_ci"][0] for s in saved])
        hi = np.array([sign * 100 * s[key]["relative_ci"][1] for s in saved])
        ax.errorbar(x + (k - 0.5) * 0.2, mid, yerr=[mid - lo, hi - mid], fmt="o", capsize=4, label=label)
    for i, s in enumerate(saved):
        if s["target_ratio"] < 1.0:
            ax.plot([i - 0.3, i + 0.3], [100 * (s["target_ratio"] - 1)] * 2, "k--", lw=0.8)
    ax.axhline(0.0, color="grey", lw=0.8)
    ax.set_xticks(x, [s["env"].split("/")[1] for s in saved])
    ax.set_ylabel("paired cost difference [% of the other rule]")
    ax.set_title("What the choices are worth (held-out episodes, 95 % CIs; dashed: the issue's target)", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out_png, dpi=110)
    return out_png


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", choices=sorted(IDS), action="append", help="scenario(s) to run (repeatable)")
    ap.add_argument("--tune", action="store_true", help="tune on the training seeds first (else: the shipped files)")
    ap.add_argument("--train-seeds", default="1000:1008", metavar="A:B", help="training episodes (default 1000:1008)")
    ap.add_argument("--seeds", default="0:100", metavar="A:B", help="held-out episodes (default 0:100)")
    ap.add_argument("--batch-size", type=int, default=20)
    ap.add_argument("--report", action="store_true", help="write the table and the plot of the saved scenarios")
    args = ap.parse_args()
    SAVED.mkdir(parents=True, exist_ok=True)
    for name in args.scenario or []:
        t0 = time.perf_counter()
        if args.tune:
            params = tune(name, parse_seeds(args.train_seeds), args.batch_size)
        else:
            params = json.loads(TUNED_FILES[name].read_text())["params"]
        out = evaluate(name, params, parse_seeds(args.seeds), args.batch_size)
        out["wall_time_s"] = time.perf_counter() - t0
        (SAVED / f"choices_compare_{name}.json").write_text(json.dumps(out, indent=1, default=float) + "\n")
        print(f"{name}: {json.dumps(out['choices_vs_tamping'])}", flush=True)
    if args.report:
        print(report(sorted(IDS)))


if __name__ == "__main__":
    main()
