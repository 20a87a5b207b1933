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
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ValueError(f"--compare names {', '.join(twice)} more than once")
    return names


def _end_state(plan: Any) -> dict[str, float] | None:
    """What ``plan`` (a line's or a network's) leaves, over all its lines' sections: the mean true SD and the
    sections at or above their SD alert at the start and the end (means over the futures; None: not known)."""
    lines = getattr(plan, "lines", None)
    lines = lines if isinstance(lines, tuple) else (plan,)
    if any(p.sd_start_mm is None or p.sd_end_mm is None or "sd_alert" not in p.limits_mm for p in lines):
        return None
    start = np.concatenate([p.sd_start_mm for p in lines], axis=1)
    end = np.concatenate([p.sd_end_mm for p in lines], axis=1)
    alert = np.concatenate([p.limits_mm["sd_alert"] for p in lines])
    return {"sd_mean_mm_start": float(start.mean()), "sd_mean_mm_end": float(end.mean()),
            "sections_at_sd_alert_start": float((start >= alert).sum(axis=1).mean()),
            "sections_at_sd_alert_end": float((end >= alert).sum(axis=1).mean()), "sections": int(alert.size)}


def compare_plans(plans: dict[str, Any], episode_years: float | None = None) -> dict[str, Any]:
    """The comparison of ``plans`` (policy name -> its plan, a line's or a network's, all of the same file,
    years, futures and seed, their futures run in episodes of one length, ``episode_years`` where not the plan's;
    the first the reference): per policy its cost per future (k€ over the plan, with the machine's moves on a
    network), their mean and 10-90 % spread, the paired difference to the reference's with a 95 % bootstrap CI
    and the futures in which it is cheaper, and what it leaves (:func:`_end_state`)."""
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
                     "end_state": _end_state(plans[name])})
    source = getattr(first, "network", None) or first.line
    return {"file": str(source.source), "name": source.name, "as_of": source.as_of, "years": first.years,
            "futures": first.futures, "seed": first.seed, "scenario": first.scenario, "episode_years": episode_years,
            "reference": names[0], "results": rows}


def format_comparison(d: dict[str, Any]) -> str:
    """:func:`compare_plans`' result as a table."""
    futures = counted(d["futures"], "future", "futures")
    episodes = "" if d.get("episode_years") is None else (
        f", each the first {years_text(d['years'])} of a {d['episode_years']:g}-year episode (a trained policy's)")
    out = [f"Policies compared on the same {futures} of {d['name']} ({d['file']}) from {d['as_of']}, "
           f"{years_text(d['years'])} ({d['scenario']}){episodes}; differences paired per future, against "
           f"{d['reference']}:",
           f"{'policy':<28} {'cost k€':>8} {'10-90 %':>13}  {'vs ' + d['reference'] + ', k€ [95 % CI]':<34} "
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
        out.append(f"{r['policy']:<28} {r['mean_keur']:>8.1f} {spread:>13}  {vs:<34} {cheaper:>8}  {left}")
    out.append("cost: k€ over the plan (the network's with the machine's moves), mean and 10-90 % of the futures; a "
               "policy cheaper within the plan may leave more to pay after it (the last column)")
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
