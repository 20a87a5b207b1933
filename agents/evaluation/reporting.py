"""Figures and text of evaluation results: the cost box plot of a comparison, and how the tables write a CI and a
count of episodes.

Figures use the pyplot-free :class:`matplotlib.figure.Figure` API: no global state, the user's backend untouched.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .harness import EvaluationResult

__all__ = ["ci_text", "count_text", "plot_comparison"]


def ci_text(low: float, high: float, n_episodes: int, signed: bool = False, digits: int = 1) -> str:
    """A 95 % CI as the tables print it, ``[low, high]`` (``signed``: with the sign, as a difference), or "n/a"
    on fewer than 2 episodes: a bootstrap of one episode only repeats it, a CI of zero width that claims a
    certainty one episode cannot give."""
    if n_episodes < 2:
        return "n/a"
    form = f"{{:{'+' if signed else ''}.{digits}f}}"
    return f"[{form.format(low)}, {form.format(high)}]"


def count_text(n: int, noun: str) -> str:
    """``n`` and ``noun``, plural but for one: "1 held-out episode", "8 held-out episodes"."""
    return f"{n} {noun}{'' if n == 1 else 's'}"


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
    ax.set_title(f"Tamping policies on {count_text(n, 'held-out episode')} (mean ▲)")
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    fig.savefig(out_png, dpi=120)
    return out_png
