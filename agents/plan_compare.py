"""Policies compared on a plan's futures: ``trackenv plan FILE.yaml --compare A,B,...``.

An engineer choosing a policy for their own line or network asks which costs less from the state in their file,
and by how much. Every policy's plan runs the same futures (the same seeds draw the same hidden parts, traffic
and errors: everything random in a line's future is drawn at its start), so the costs are paired future by
future and their difference has a confidence interval far narrower than either cost's spread. The comparison
also says what each plan leaves at its end (:meth:`~trackenv_agents.plan_report.LinePlan.end_state`): a policy
that is cheap within a short horizon by letting the track run down pays after it.
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

import numpy as np

from .evaluation.statistics import bootstrap_ci
from .plan_report import counted, years_text

__all__ = ["check_compared", "compare_plans", "format_comparison", "write_comparison"]


def check_compared(names: list[str]) -> list[str]:
    """The policies of ``--compare``: at least two, each once (ValueError otherwise)."""
    names = [n.strip() for n in names if n.strip()]
    if len(names) < 2:
        raise ValueError(f"--compare needs at least two policies, comma-separated, got {names}")
    from .evaluation.line_compare import repeated

    twice = repeated(names)
    if twice:
        raise ValueError(f"--compare names {', '.join(twice)} more than once")
    return names


def compare_plans(plans: dict[str, Any], episode_years: float | None = None) -> dict[str, Any]:
    """The comparison of ``plans`` (policy name -> its plan, a line's or a network's, all of the same file,
    years, futures and seed, their futures run in episodes of one length, ``episode_years`` where not the plan's;
    the first the reference): per policy its cost per future (k€ over the plan, with the machine's moves on a
    network), their mean and 10-90 % spread, the paired difference to the reference's with a 95 % bootstrap CI
    and the futures in which it is cheaper, and what it leaves (``end_state()``:
    :func:`~trackenv_agents.plan_report.end_state`), and the first plan's engine and config changes."""
    names = list(plans)
    first = plans[names[0]]
    for name, plan in plans.items():
        if (plan.years, plan.futures, plan.seed) != (first.years, first.futures, first.seed):
            raise ValueError(f"{name}'s plan ran other futures ({plan.years} years, {plan.futures} futures from "
                             f"seed {plan.seed}) than {names[0]}'s")
    totals = {name: plan.costs.sum(axis=1) for name, plan in plans.items()}
    reference = totals[names[0]]
    rows = []
    for name, total in totals.items():
        d = total - reference
        lo, hi = bootstrap_ci(d)
        rows.append({"policy": name, "cost_keur": [float(x) for x in total], "mean_keur": float(total.mean()),
                     "p10_keur": float(np.quantile(total, 0.1)), "p90_keur": float(np.quantile(total, 0.9)),
                     "vs_first": {"mean_keur": float(d.mean()), "ci_low": lo, "ci_high": hi,
                                  "cheaper_futures": int((d < 0).sum())},
                     "end_state": plans[name].end_state()})
    network = getattr(first, "network", None)
    source = first.line if network is None else network
    line = first if network is None else first.lines[0]  # the engine and changes: the same on every line
    return {"file": str(source.source), "name": source.name, "as_of": source.as_of, "years": first.years,
            "engine": line.engine, "pass_reuse_mm": line.pass_reuse_tolerance_m * 1e3,
            "config_changes": dict(line.config_changes),
            "futures": first.futures, "seed": first.seed, "scenario": first.scenario, "episode_years": episode_years,
            "reference": names[0], "results": rows, "network": network is not None}


def format_comparison(d: dict[str, Any]) -> str:
    """:func:`compare_plans`' result as a table."""
    from .evaluation.line_compare import changes_note, engine_note

    futures = counted(d["futures"], "future", "futures")
    w = max(28, *(len(r["policy"]) for r in d["results"]))
    episodes = "" if d.get("episode_years") is None else (
        f", each the first {years_text(d['years'])} of a {d['episode_years']:g}-year episode (a trained policy's)")
    engine = engine_note({"engine": d["engine"], "pass_reuse_tolerance_m": d["pass_reuse_mm"] / 1e3})
    out = [f"Policies compared on the same {futures} of {d['name']} ({d['file']}) from {d['as_of']}, "
           f"{years_text(d['years'])}, scenario {d['scenario']}{engine}{changes_note(d['config_changes'])}"
           f"{episodes}; differences paired per future, against {d['reference']}:",
           f"{'policy':<{w}} {'cost k€':>8} {'10-90 %':>13}  {'vs ' + d['reference'] + ', k€ [95 % CI]':<34} "
           f"{'cheaper':>8}  left at the end: SD mm, sections at SD alert"]
    for r in d["results"]:
        v = r["vs_first"]
        vs = "—" if r["policy"] == d["reference"] else (
            f"{v['mean_keur']:+.1f} [{v['ci_low']:+.1f}, {v['ci_high']:+.1f}]")
        cheaper = "—" if r["policy"] == d["reference"] else f"{v['cheaper_futures']} of {d['futures']}"
        e = r["end_state"]
        left = "-" if e is None else (f"{e['sd_mean_mm_end']:.2f} (from {e['sd_mean_mm_start']:.2f}), "
                                      f"{e['sections_at_sd_alert_end']:.1f} of {e['sections']} "
                                      f"(from {e['sections_at_sd_alert_start']:.1f})")
        spread = f"{r['p10_keur']:.0f}-{r['p90_keur']:.0f}"
        out.append(f"{r['policy']:<{w}} {r['mean_keur']:>8.1f} {spread:>13}  {vs:<34} {cheaper:>8}  {left}")
    whose = " (the network's with the machine's moves)" if d.get("network") else ""
    out.append(f"cost: k€ over the plan{whose}, mean and 10-90 % of the futures; a policy cheaper within the plan "
               f"may leave more to pay after it (the last column)")
    return "\n".join(out)


def write_comparison(d: dict[str, Any], folder: Path) -> str:
    """Write ``compare.csv`` (per future its seed and each policy's cost, k€) into ``folder``; returns its path."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "compare.csv"
    with path.open("w", newline="") as f:
        w = csv.writer(f, lineterminator="\n")
        w.writerow(["future", "seed", *(f"{r['policy']}_keur" for r in d["results"])])
        for i in range(d["futures"]):
            w.writerow([i, d["seed"] + i, *(f"{r['cost_keur'][i]:.3f}" for r in d["results"])])
    return str(path)
