"""What the choices are worth: the rules that use them against the best tamping-only rule, and the value of
information (the same family with and without inspections and surveys), on the three ids with every choice.

For each scenario (``choices``: ``trackenv/TampingLine-v1``; ``wet``: ``trackenv/TampingLineWet-v0``;
``defects``: ``trackenv/TampingLineDefects-v0``):

1. ``--tune``: the grouped threshold (the best tamping rule) over a small grid of campaigns (:data:`CAMPAIGNS`)
   on the training seeds, and each family of choice rules (:mod:`trackenv_agents.rules.choices`) over its choice
   settings (:func:`~trackenv_agents.rules.choices.choice_grid`) at every one of these campaigns, jointly; the
   tuned parameters are written to ``agents/rules/<scenario>_tuned_heuristics.json`` (what ``trackenv
   evaluate`` reads by default).
2. The grouped threshold, the choice rule and the rule with spot tamping alone on the held-out seeds
   (``--seeds``, default 0:100), the choice rule without looking on ``--voi-seeds`` (default the same), paired
   per episode: the choice rule and the spot-tamping rule against the grouped threshold, and the choice rule
   against the same family without looking; saved as ``experiments/saved/choices_compare_<scenario>.json``
   (per-episode costs and the paired differences).
3. ``--report``: the saved scenarios as one Markdown table (``experiments/saved/choices_compare.md``) and a plot.

    python experiments/choices_compare.py --scenario wet --tune          # one scenario: tune, then score
    python experiments/choices_compare.py --scenario wet --scenario defects --scenario choices --tune \
        --voi-seeds 0:30                                                 # what the documentation shows
    python experiments/choices_compare.py --scenario defects --tune --train-seeds 1000:1016
                                                                         # the defects line as shipped
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
from trackenv_agents.rules.choices import (
    ChoiceThreshold,
    ChoiceThresholdNoLooking,
    ChoiceThresholdSpotOnly,
    choice_grid,
    choices_off,
)
from trackenv_agents.rules.line import GroupedThreshold
from trackenv_agents.rules.problems import TUNED_FILES

SAVED = Path(__file__).resolve().parent / "saved"
IDS = {"choices": "trackenv/TampingLine-v1", "wet": "trackenv/TampingLineWet-v0",
       "defects": "trackenv/TampingLineDefects-v0"}
#: what the issue asks of each scenario: the choice rule's cost at most this share of the tamping-only rule's
TARGET = {"choices": 1.0, "wet": 0.90, "defects": 0.95}
#: the campaigns searched on each scenario (trigger, include) [mm], for the grouped threshold and, jointly with
#: their choices, for the choice rules
CAMPAIGNS = ((2.5, 1.25), (3.0, 1.5), (3.5, 1.75), (4.0, 2.0), (4.5, 2.25))
CHOICE_FAMILIES = (ChoiceThreshold, ChoiceThresholdNoLooking, ChoiceThresholdSpotOnly)
RULES = (GroupedThreshold, *CHOICE_FAMILIES)


def tune(name: str, train_seeds: list[int], batch_size: int, keep: tuple[str, ...] = ()) -> dict[str, Any]:
    """Tune the rules on ``train_seeds`` of scenario ``name`` and write its tuned-parameter file: the grouped
    threshold over :data:`CAMPAIGNS`, and each choice family over its choice settings at every campaign; a
    family's settings with every choice off are the grouped threshold itself (its cost read from there), so a
    family keeps every choice off where no grid point beats the best campaign on the training seeds. The rules
    named in ``keep`` keep their shipped parameters (the cheapest on the training seeds did worse on held-out
    episodes); their training costs still join the file's tables."""
    cfg = scenario(name)
    shipped = json.loads(TUNED_FILES[name].read_text())["params"] if TUNED_FILES[name].exists() else {}
    missing = [rule for rule in keep if rule not in shipped]
    if missing:
        raise ValueError(f"--keep: no shipped parameters of {missing} for scenario {name!r}")
    known = _known_rows(name, train_seeds)
    campaigns = [{"trigger_mm": t, "include_mm": i} for t, i in CAMPAIGNS]
    best = _tune_grid(GroupedThreshold, campaigns, cfg, train_seeds, batch_size, known)
    params: dict[str, Any] = {GroupedThreshold.name: best[0]["params"]}
    tables = {GroupedThreshold.name: best}
    for cls in CHOICE_FAMILIES:
        off = [{"params": {**row["params"], **choices_off(cls)}, "mean_cost": row["mean_cost"]} for row in best]
        grid = [point for campaign in campaigns for point in choice_grid(cls, campaign)]
        table = sorted([*_tune_grid(cls, grid, cfg, train_seeds, batch_size, known), *off],
                       key=lambda row: row["mean_cost"])
        params[cls.name], tables[cls.name] = table[0]["params"], table
    params |= {rule: shipped[rule] for rule in keep}
    tuned_by = "experiments/choices_compare.py --tune" + (f" --keep {','.join(keep)}" if keep else "")
    payload = {"scenario": name, "train_seeds": train_seeds, "tuned_by": tuned_by,
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
    """The grouped threshold, the choice rule and the spot-tamping rule on ``seeds`` of scenario ``name``, the
    choice rule without looking on ``voi_seeds`` (a subset), with the paired differences; a family with no
    parameters in ``params`` (not tuned on the scenario) is left out. A rule whose parameters and seeds are those
    of the saved comparison is read from it (an episode is a function of its seed and actions)."""
    cfg = scenario(name)
    path = SAVED / f"choices_compare_{name}.json"
    saved = json.loads(path.read_text())["rules"] if path.exists() else {}
    summaries, results = {}, {}
    for cls in (c for c in RULES if c.name in params):
        rule_seeds = voi_seeds if cls is ChoiceThresholdNoLooking else seeds
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
    tamping, choice, no_looking = (results[cls.name] for cls in RULES[:3])

    def compare(a, b) -> dict[str, Any]:
        d = paired_difference(a, b)
        common = np.isin(b.seeds, a.seeds)
        ref = float(b.cost[common].mean())
        return {**d, "reference_mean_cost": ref, "relative": d["mean_difference"] / ref,
                "relative_ci": [d["ci_low"] / ref, d["ci_high"] / ref]}

    out = {"scenario": name, "env": IDS[name], "seeds": seeds, "voi_seeds": voi_seeds, "rules": summaries,
           "choices_vs_tamping": compare(choice, tamping), "value_of_information": compare(choice, no_looking),
           "target_ratio": TARGET[name]}
    if ChoiceThresholdSpotOnly.name in results:
        out["spot_vs_tamping"] = compare(results[ChoiceThresholdSpotOnly.name], tamping)
    return out


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
    spot = [s for s in saved if "spot_vs_tamping" in s]
    if spot:
        rows += ["", "| id | episodes | grouped threshold k€ | spot tamping alone k€ | spot tamping alone vs grouped "
                 "threshold (paired, 95 % CI) | issue asks | met |", "|---|---:|---:|---:|---:|---|---|"]
    for s in spot:
        d, target = s["spot_vs_tamping"], s["target_ratio"]
        met = d["relative"] <= target - 1.0 and d["ci_high"] < 0.0
        rows.append(f"| `{s['env']}` | {d['n_episodes']} | {d['reference_mean_cost']:.0f} "
                    f"| {s['rules'][ChoiceThresholdSpotOnly.name]['mean_cost']:.0f} "
                    f"| {d['mean_difference']:+.0f} [{d['ci_low']:+.0f}, {d['ci_high']:+.0f}] "
                    f"({100 * d['relative']:+.1f} % [{100 * d['relative_ci'][0]:+.1f}, "
                    f"{100 * d['relative_ci'][1]:+.1f}]) | ≤ {100 * (target - 1):.0f} % | {'yes' if met else 'no'} |")
    if spot:
        rows.append("")
        rows.append("Spot tamping alone: `choice-threshold-spot-only`, the grouped threshold's campaigns with spot "
                    "tamping and no other choice, minus the grouped threshold, paired per episode.")
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
            table_rows = tuned["train_mean_cost"][rule]  # the shipped setting (a kept rule: not the cheapest)
            cost = next((row["mean_cost"] for row in table_rows if row["params"] == params),
                        min(row["mean_cost"] for row in table_rows))
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
    for k, (key, label) in enumerate((("choices_vs_tamping", "choice rule vs grouped threshold"),
                                      ("value_of_information", "choice rule vs no looking"),
                                      ("spot_vs_tamping", "spot tamping alone vs grouped threshold"))):
        at = [i for i, s in enumerate(saved) if key in s]
        if not at:
            continue
        mid = np.array([100 * saved[i][key]["relative"] for i in at])
        lo = np.array([100 * saved[i][key]["relative_ci"][0] for i in at])
        hi = np.array([100 * saved[i][key]["relative_ci"][1] for i in at])
        ax.errorbar(x[at] + (k - 1) * 0.2, mid, yerr=[mid - lo, hi - mid], fmt="o", capsize=4, label=label)
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
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenario", choices=sorted(IDS), action="append", help="scenario(s) to run (repeatable)")
    ap.add_argument("--tune", action="store_true", help="tune on the training seeds first (else: the shipped files)")
    ap.add_argument("--train-seeds", default="1000:1004", metavar="A:B", help="training episodes (default 1000:1004)")
    ap.add_argument("--keep", default="", metavar="RULE[,RULE]",
                    help="with --tune: rules that keep their shipped parameters")
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
            params = tune(name, parse_seeds(args.train_seeds), args.batch_size,
                          tuple(rule for rule in args.keep.split(",") if rule))
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
