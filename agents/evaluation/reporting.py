"""Tables and figures of evaluation results: text and Markdown tables of summaries, cost box plots, episodes.

Figures use the pyplot-free :class:`matplotlib.figure.Figure` API: no global state, the user's backend untouched.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from trackenv.envs.config import TampingEnvConfig

from .harness import EvaluationResult, policy_name, policy_params, record_episode

__all__ = ["format_markdown", "format_table", "plot_comparison", "plot_episode"]

_COLUMNS = (("policy", "policy", "{}"), ("params", "params", "{}"), ("n", "n_episodes", "{:d}"),
            ("cost k€", "mean_cost", "{:.1f}"), ("95% CI", None, None),
            ("tamp/km·yr", "tampings_per_km_year", "{:.3f}"),
            ("IAL exc.", "immediate_action_exceedances", "{:d}"),
            ("final SD mm", "mean_final_sd_mm", "{:.2f}"))


def _fmt_params(params: Mapping[str, Any]) -> str:
    return ", ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in params.items()) or "-"


def _cells(rows: Sequence[Mapping[str, Any]]) -> list[list[str]]:
    out = []
    for r in rows:
        cells = []
        for _, key, fmt in _COLUMNS:
            if key is None:
                cells.append(f"[{r['ci_low']:.1f}, {r['ci_high']:.1f}]")
            elif key == "params":
                cells.append(_fmt_params(r.get("params", {})))
            else:
                cells.append(fmt.format(r[key]))
        out.append(cells)
    return out


def format_table(rows: Sequence[Mapping[str, Any]]) -> str:
    """A fixed-width text table of summaries."""
    head = [c[0] for c in _COLUMNS]
    body = _cells(rows)
    widths = [max(len(h), *(len(b[i]) for b in body)) if body else len(h) for i, h in enumerate(head)]
    num = [i >= 2 for i in range(len(head))]

    def line(cells):
        padded = (c.rjust(w) if n else c.ljust(w) for c, w, n in zip(cells, widths, num, strict=True))
        return "  ".join(padded).rstrip()

    return "\n".join([line(head), "  ".join("-" * w for w in widths), *(line(b) for b in body)])


def format_markdown(rows: Sequence[Mapping[str, Any]]) -> str:
    """A Markdown table of summaries."""
    head = [c[0] for c in _COLUMNS]
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join(["---"] * 2 + ["---:"] * (len(head) - 2)) + "|"]
    lines += ["| " + " | ".join(c.replace("|", "\\|") for c in b) + " |" for b in _cells(rows)]
    return "\n".join(lines)


def plot_comparison(results: Sequence[EvaluationResult], out_png: str) -> str:
    """Box plot (with the episodes as dots) of the per-episode life-cycle cost of each policy."""
    from matplotlib.figure import Figure  # pyplot-free: no global state, the user's backend untouched

    fig = Figure(figsize=(max(5.0, 1.4 * len(results) + 2), 4.5))
    ax = fig.subplots()
    data = [r.cost for r in results]
    ax.boxplot(data, showmeans=True, showfliers=False)
    rng = np.random.default_rng(0)
    for i, d in enumerate(data, start=1):
        ax.plot(i + rng.uniform(-0.15, 0.15, d.size), d, ".", alpha=0.35, color="C0", ms=4)
    ax.set_xticks(range(1, len(results) + 1), [r.policy for r in results], rotation=20, ha="right")
    ax.set_ylabel("life-cycle cost per episode [k€]")
    n = results[0].n_episodes if results else 0
    ax.set_title(f"Tamping policies on {n} held-out episodes (mean ▲)")
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    fig.savefig(out_png, dpi=120)
    return out_png


def plot_episode(policy: Any, config: TampingEnvConfig | dict | None, seed: int, out_png: str) -> str:
    """One episode under ``policy``: section SD over time with tamping marks (top), cost per step (bottom)."""
    from matplotlib.figure import Figure  # pyplot-free: no global state, the user's backend untouched

    cfg = TampingEnvConfig.coerce(config)
    tr = record_episode(policy, cfg, seed)
    years = np.concatenate([[0.0], tr["year"]])
    lim = cfg.quality_limits.for_speed(cfg.speed)
    fig = Figure(figsize=(8, 6))
    ax1, ax2 = fig.subplots(2, 1, sharex=True, height_ratios=(2, 1))
    for s in range(cfg.n_sections):
        color = f"C{s % 10}"
        ax1.plot(years, tr["section_sd_mm"][:, s], color=color, label=f"section {s + 1}")
        steps = np.flatnonzero(tr["tamped"][:, s])
        # a tamping happens at the start of step k, i.e. at year k / steps_per_year
        ax1.plot(steps / cfg.steps_per_year, tr["section_sd_mm"][steps, s], "v", color=color, ms=7)
    ax1.axhline(lim.sd_alert_m * 1e3, color="k", ls="--", lw=1, label="SD alert limit")
    ax1.set_ylabel("section SD of D1 level [mm]")
    ax1.legend(fontsize=7, ncol=2)
    label = " ".join(x for x in (policy_name(policy), _fmt_params(policy_params(policy))) if x != "-")
    ax1.set_title(f"{label}, seed {seed} "
                  f"(▼ tamping); total {tr['cost'].sum():.1f} k€")
    ax2.bar(tr["year"] - 0.5 / cfg.steps_per_year, tr["cost"], width=0.8 / cfg.steps_per_year, color="C3")
    ax2.set_xlabel("year")
    ax2.set_ylabel("cost per step [k€]")
    for ax in (ax1, ax2):
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out_png, dpi=120)
    return out_png
