"""Statistics of evaluation results: percentile bootstrap CIs and paired differences on common seeds.

Each bootstrap draws from its own generator (seeded), so a table or a CI is reproducible.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .harness import EvaluationResult

__all__ = ["N_BOOTSTRAP", "bootstrap_ci", "paired_difference"]

N_BOOTSTRAP = 2000


def bootstrap_ci(x: np.ndarray, n_resamples: int = N_BOOTSTRAP, level: float = 0.95,
                 seed: int = 0) -> tuple[float, float]:
    """Percentile bootstrap CI of the mean of ``x`` (its own generator: reproducible)."""
    x = np.asarray(x, dtype=float)
    if x.size == 0:
        return math.nan, math.nan
    rng = np.random.default_rng(seed)
    means = x[rng.integers(0, x.size, size=(n_resamples, x.size))].mean(axis=1)
    a = (1.0 - level) / 2
    lo, hi = np.quantile(means, [a, 1.0 - a])
    return float(lo), float(hi)


def paired_difference(a: EvaluationResult, b: EvaluationResult, n_resamples: int = N_BOOTSTRAP) -> dict:
    """Mean of the per-episode cost differences a − b on common seeds, with a 95 % bootstrap CI."""
    common, ia, ib = np.intersect1d(a.seeds, b.seeds, return_indices=True)
    if common.size == 0:
        raise ValueError("the two results share no seeds")
    d = a.cost[ia] - b.cost[ib]
    lo, hi = bootstrap_ci(d, n_resamples)
    return {"a": a.policy, "b": b.policy, "n_episodes": int(common.size), "mean_difference": float(d.mean()),
            "ci_low": lo, "ci_high": hi, "a_better_fraction": float(np.mean(d < 0))}
