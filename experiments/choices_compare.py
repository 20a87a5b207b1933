"""What the choices are worth: the rules that use them against the best tamping-only rule, and the value of
information (the same family with and without inspections and surveys), on the three ids with every choice.

For each scenario (``choices``: ``trackenv/TampingLine-v1``; ``wet``: ``trackenv/TampingLineWet-v0``;
``defects``: ``trackenv/TampingLineDefects-v0``):

1. ``--tune``: the grouped threshold (the best tamping rule) over a small grid of campaigns on the training
   seeds, then the choice rules (:mod:`trackenv_agents.rules.choices`) around the best campaign
   (:func:`~trackenv_agents.rules.choices.choice_grid`); the tuned parameters are written to
   ``agents/rules/<scenario>_tuned_heuristics.json`` (what ``trackenv evaluate`` reads by default).
2. The grouped threshold and the choice rule on the held-out seeds (``--seeds``, default 0:100), the choice rule
   without looking on ``--voi-seeds`` (default the same), paired per episode: the choice rule against the
   grouped threshold, and against the same family without looking; saved as
   ``experiments/saved/choices_compare_<scenario>.json`` (per-episode costs and the paired differences).
3. ``--report``: the saved scenarios as one Markdown table (``experiments/saved/choices_compare.md``) and a plot.

    python experiments/choices_compare.py --scenario wet --tune          # one scenario: tune, then score
    python experiments/choices_compare.py --scenario wet --scenario defects --scenario choices --tune \
        --voi-seeds 0:30                                                 # what the documentation shows
    python experiments/choices_compare.py --report                       # the table and the plot
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

from trackenv.envs.line_config import scenario
from trackenv_agents.evaluation.harness import evaluate_many
from trackenv_agents.evaluation.line_compare import parse_seeds
from trackenv_agents.evaluation.statistics import paired_difference
from trackenv_agents.evaluation.tuning import tune_many
from trackenv_agents.rules.choices import ChoiceThreshold, ChoiceThresholdNoLooking, choice_grid, choices_off
from trackenv_agents.rules.line import GroupedThreshold
from trackenv_agents.rules.problems import TUNED_FILES

SAVED = Path(__file__).resolve().parent / "saved"
IDS = {"choices": "trackenv/TampingLine-v1", "wet": "trackenv/TampingLineWet-v0",
       "defects": "trackenv/TampingLineDefects-v0"}
#: what the issue asks of each scenario: the choice rule's cost at most this share of the tamping-only rule's
TARGET = {"choices": 1.0, "wet": 0.90, "defects": 0.95}
#: the grouped threshold's campaigns searched on each scenario (trigger, include) [mm]
CAMPAIGNS = ((3.5, 1.75), (3.0, 1.5), (2.5, 1.25))
RULES = (GroupedThreshold, ChoiceThreshold, ChoiceThresholdNoLooking)


def tune(name: str, train_seeds: list[int], batch_size: int) -> dict[str, Any]:
    """Tune the three rules on ``train_seeds`` of scenario ``name`` and write its tuned-parameter file: the
    grouped threshold's campaign first, then each choice family around it; a family keeps every choice off (the
    grouped threshold itself) where no grid point beats that on the training seeds."""
    cfg = scenario(name)
    known = _known_rows(name, train_seeds)
    best = _tune_grid(GroupedThreshold, [{"trigger_mm": t, "include_mm": i} for t, i in CAMPAIGNS], cfg,
                      train_seeds, batch_size, known)
    base = best[0]["params"]
    params: dict[str, Any] = {GroupedThreshold.name: base}
    tables = {GroupedThreshold.name: best}
    for cls in (ChoiceThreshold, ChoiceThresholdNoLooking):
        off = {"params": {**base, **choices_off(cls)}, "mean_cost": best[0]["mean_cost"]}
        table = sorted([*_tune_grid(cls, choice_grid(cls, base), cfg, train_seeds, batch_size, known), off],
                       key=lambda row: row["mean_cost"])
        params[cls.name], tables[cls.name] = table[0]["params"], table
    payload = {"scenario": name, "train_seeds": train_seeds, "tuned_by": "experiments/choices_compare.py --tune",
               "params": params,
               "train_mean_cost": {rule: [{"params": row["params"], "mean_cost": row["mean_cost"]} for row in table]
                                   for rule, table in tables.items()}}
    TUNED_FILES[name].write_text(json.dumps(payload, indent=1) + "\n")
    return params


def _known_rows(name: str, train_seeds: list[int]) -> dict[str, list[dict[str, Any]]]:
    """The training costs already in scenario ``name``'s tuned file, where it was tuned on ``train_seeds``: a grid
    point scored there with the same code need not run again (an episode is a function of its seed and actions)."""
    path = TUNED_FILES[name]
    if not path.exists():
        return {}
    saved = json.loads(path.read_text())
    return saved.get("train_mean_cost", {}) if saved.get("train_seeds") == train_seeds else {}


def _tune_grid(cls: type, grid: list[dict[str, Any]], cfg: Any, train_seeds: list[int], batch_size: int,
               known: dict[str, list[dict[str, Any]]]) -> list[dict[str, Any]]:
    """``cls`` over ``grid`` on ``train_seeds`` (the points in ``known`` read from there), sorted by cost."""
    def key(params: dict[str, Any]) -> str:  # every parameter, defaults included
        return json.dumps(cls(**params).params, sort_keys=True)

    old = {key(row["params"]): row for row in known.get(cls.name, [])}
    rows = [old[key(g)] for g in grid if key(g) in old]
    new = [g for g in grid if key(g) not in old]
    if new:
        rows += tune_many([cls], cfg, train_seeds, batch_size, False, grids=[new], action_type="choices")[0]["table"]
    return sorted(({"params": r["params"], "mean_cost": r["mean_cost"]} for r in rows),
                  key=lambda row: row["mean_cost"])


def evaluate(name: str, params: dict[str, Any], seeds: list[int], voi_seeds: list[int],
             batch_size: int) -> dict[str, Any]:
    """The grouped threshold and the choice rule on ``seeds`` of scenario ``name``, the choice rule without
    looking on ``voi_seeds`` (a subset), with the paired differences. A rule whose parameters and seeds are those
    of the saved comparison is read from it (an episode is a function of its seed and actions)."""
    cfg = scenario(name)
    path = SAVED / f"choices_compare_{name}.json"
    saved = json.loads(path.read_text())["rules"] if path.exists() else {}
    summaries, results = {}, {}
    for cls, rule_seeds in zip(RULES, (seeds, seeds, voi_seeds), strict=True):
        old = saved.get(cls.name)
        if old and old["seeds"] == rule_seeds and cls(**old["params"]).params == cls(**params[cls.name]).params:
            summaries[cls.name] = old
            results[cls.name] = SimpleNamespace(policy=cls.name, seeds=np.array(old["seeds"]),
                                                cost=np.array(old["episode_costs"]))
            continue
        r = evaluate_many([cls(**params[cls.name])], cfg, rule_seeds, action_type="choices",
                          batch_size=batch_size)[0]
        summaries[cls.name] = {**r.summary(), "seeds": r.seeds.tolist(), "episode_costs": r.cost.tolist()}
        results[cls.name] = r
    tamping, choice, no_looking = (results[cls.name] for cls in RULES)

    def compare(a, b) -> dict[str, Any]:
        d = paired_difference(a, b)
        common = np.isin(b.seeds, a.seeds)
        ref = float(b.cost[common].mean())
        return {**d, "reference_mean_cost": ref, "relative": d["mean_difference"] / ref,
                "relative_ci": [d["ci_low"] / ref, d["ci_high"] / ref]}

    return {"scenario": name, "env": IDS[name], "seeds": seeds, "voi_seeds": voi_seeds, "rules": summaries,
            "choices_vs_tamping": compare(choice, tamping), "value_of_information": compare(choice, no_looking),
            "target_ratio": TARGET[name]}


def report(names: list[str]) -> str:
    """The saved scenarios as a Markdown table, and the plot beside it."""
    rows = ["| id | episodes | grouped threshold (tamping only) k€ | choice rule k€ | choice rule vs grouped threshold "
            "(paired, 95 % CI) | issue asks | met | episodes | choice rule without looking k€ | value of "
            "information (paired, 95 % CI) |",
            "|---|---:|---:|---:|---:|---|---|---:|---:|---:|"]
    saved = [json.loads((SAVED / f"choices_compare_{n}.json").read_text()) for n in names
             if (SAVED / f"choices_compare_{n}.json").exists()]
    for s in saved:
        r = s["rules"]
        cvt, voi = s["choices_vs_tamping"], s["value_of_information"]
        target = s["target_ratio"]
        met = cvt["relative"] <= target - 1.0 if target < 1.0 else cvt["mean_difference"] <= 0.0
        ask = "no worse" if target >= 1.0 else f"≤ {100 * (target - 1):.0f} %"
        rows.append(
            f"| `{s['env']}` | {cvt['n_episodes']} | {r['grouped-threshold']['mean_cost']:.0f} "
            f"| {r['choice-threshold']['mean_cost']:.0f} "
            f"| {cvt['mean_difference']:+.0f} [{cvt['ci_low']:+.0f}, {cvt['ci_high']:+.0f}] "
            f"({100 * cvt['relative']:+.1f} %) | {ask} | {'yes' if met else 'no'} | {voi['n_episodes']} "
            f"| {voi['reference_mean_cost']:.0f} "
            f"| {-voi['mean_difference']:+.0f} [{-voi['ci_high']:+.0f}, {-voi['ci_low']:+.0f}] "
            f"({-100 * voi['relative']:+.1f} %) |")
    rows.append("")
    rows.append("Costs are means per 10-year episode (k€) on held-out seeds from 0; differences are the choice rule "
                "minus the other, paired per episode, with 95 % bootstrap CIs; the value of information is what "
                "looking saves (the rule without inspections and surveys minus the one with, on the episodes both "
                "ran).")
    rows.append("")
    rows.append("| id | rule | " + " | ".join(("tamp", "spot_tamp", "drainage", "renew", "inspect", "survey"))
                + " |")
    rows.append("|---|---|" + "---:|" * 6)
    for s in saved:
        for rule, v in s["rules"].items():
            rows.append(f"| `{s['env']}` | {rule} | " + " | ".join(f"{v['choices'][c]:.1f}" for c in
                                                                  ("tamp", "spot_tamp", "drainage", "renew",
                                                                   "inspect", "survey")) + " |")
    rows += ["", "| id | rule | tuned parameters (choices left off not shown) | training cost k€ |",
             "|---|---|---|---:|"]
    for s in saved:
        tuned = json.loads(TUNED_FILES[s["scenario"]].read_text())
        for rule, params in tuned["params"].items():
            shown = ", ".join(f"{k} = {v}" for k, v in params.items() if v not in (0, 0.0, False)
                              and not (k in ("fast_growth_mm_per_year", "inspect_age_years") and not _uses(k, params)))
            cost = min(row["mean_cost"] for row in tuned["train_mean_cost"][rule])
            rows.append(f"| `{s['env']}` | {rule} | {shown} | {cost:.0f} |")
    table = "\n".join(rows)
    (SAVED / "choices_compare.md").write_text(table + "\n")
    if saved:
        plot(saved, str(SAVED / "choices_compare.png"))
    return table


def _uses(key: str, params: dict[str, Any]) -> bool:
    """Whether a rule with ``params`` reads the parameter ``key`` (the growth threshold and the inspection age
    only matter where a choice that reads them is on)."""
    if key == "fast_growth_mm_per_year":
        return any(params.get(k) for k in ("drain_after_tampings", "survey_fast", "renew_after_tampings"))
    return bool(params.get("inspect_margin_mm") or params.get("inspect_peak_mm"))


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
    ap.add_argument("--train-seeds", default="1000:1004", metavar="A:B", help="training episodes (default 1000:1004)")
    ap.add_argument("--seeds", default="0:100", metavar="A:B", help="held-out episodes (default 0:100)")
    ap.add_argument("--voi-seeds", default=None, metavar="A:B",
                    help="held-out episodes of the rule without looking (default: --seeds)")
    ap.add_argument("--batch-size", type=int, default=50)
    ap.add_argument("--report", action="store_true", help="write the table and the plot of the saved scenarios")
    args = ap.parse_args()
    SAVED.mkdir(parents=True, exist_ok=True)
    for name in args.scenario or []:
        t0 = time.perf_counter()
        if args.tune:
            params = tune(name, parse_seeds(args.train_seeds), args.batch_size)
        else:
            params = json.loads(TUNED_FILES[name].read_text())["params"]
        seeds = parse_seeds(args.seeds)
        out = evaluate(name, params, seeds, parse_seeds(args.voi_seeds) if args.voi_seeds else seeds, args.batch_size)
        out["wall_time_s"] = time.perf_counter() - t0
        (SAVED / f"choices_compare_{name}.json").write_text(json.dumps(out, indent=1, default=float) + "\n")
        print(f"{name}: {json.dumps(out['choices_vs_tamping'])}", flush=True)
    if args.report:
        print(report(sorted(IDS)))


if __name__ == "__main__":
    main()
