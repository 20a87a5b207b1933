"""Figures of evaluation results: the cost box plot of a comparison.

Figures use the pyplot-free :class:`matplotlib.figure.Figure` API: no global state, the user's backend untouched.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .harness import EvaluationResult

__all__ = ["plot_comparison"]


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
