"""A plan's rule tuned on the line itself: ``trackenv plan LINE.yaml --tune N``.

The shipped rules' thresholds were tuned on the presets (the default line runs at 100 km/h, 25 MGT a year). A
line of one's own differs: a faster line has tighter limits and a dearer geometry per millimetre, other traffic
settles it at another rate. :func:`tune_plan_rule` searches the rule's grid (:meth:`param_grid`, plus the shipped
parameters) on ``N`` futures of the line from its state as of its file, each over :data:`TUNE_YEARS` (the
presets' episode length, so that what a rule leaves undone after the plan's horizon still costs), on the
training seeds (from 1000: apart from the plan's futures, seeds 0, 1, ...), and the plan then runs the cheapest.
Its cost on those futures is in-sample: the documentation's line-files page gives what it is worth on futures it
did not see.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from trackenv.envs.choices import action_type_for

from .evaluation.harness import TRAIN_SEEDS
from .evaluation.tuning import tune

__all__ = ["TUNE_YEARS", "RuleTuning", "tune_plan_rule"]

#: years of each training future: the presets' episodes, on which the shipped parameters were tuned
TUNE_YEARS = 10.0


@dataclass(frozen=True)
class RuleTuning:
    """What :func:`tune_plan_rule` found: the ``params`` it chose and the ``shipped_params``, their mean costs
    over the ``futures`` training futures (k€ over :data:`TUNE_YEARS`, in-sample), the first training seed
    ``seed`` and the number of ``candidates`` searched."""

    params: dict[str, Any]
    shipped_params: dict[str, Any]
    cost_keur: float
    shipped_cost_keur: float
    futures: int
    seed: int
    candidates: int

    def to_dict(self) -> dict[str, Any]:
        return {"params": dict(self.params), "shipped_params": dict(self.shipped_params),
                "cost_keur": self.cost_keur, "shipped_cost_keur": self.shipped_cost_keur, "futures": self.futures,
                "seeds": [self.seed, self.seed + self.futures - 1], "years": TUNE_YEARS,
                "candidates": self.candidates}

    def text(self, policy: str) -> str:
        """One line for the plan's table: the parameters that changed (a choice rule has a dozen), both costs."""
        changed = ", ".join(f"{k} {_shown(v)} (shipped {_shown(self.shipped_params.get(k))})"
                            for k, v in self.params.items() if v != self.shipped_params.get(k))
        chose = f"chose {changed}" if changed else "kept the shipped parameters"
        return (f"tuned on this line: {policy} {chose}; {self.cost_keur:.0f} against {self.shipped_cost_keur:.0f} k€ "
                f"with the shipped ones over {TUNE_YEARS:g} years, means over {self.futures} training futures "
                f"(seeds {self.seed}-{self.seed + self.futures - 1}, in-sample; {self.candidates} candidates)")


def _shown(value: Any) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)


def tune_plan_rule(rule: Any, config: Any, futures: int, progress: bool = False) -> RuleTuning:
    """Tune ``rule`` (a bound line rule with its shipped parameters: :func:`~trackenv_agents.planning.line_policy`)
    on ``futures`` futures of ``config`` (the plan's line config) over :data:`TUNE_YEARS`: its class's grid and
    its own parameters, each scored on the same futures (one batched run); ``progress``: a progress bar on
    stderr. ValueError for a policy that has nothing to tune (an agent, a rule without parameters)."""
    grid = list(type(rule).param_grid()) if hasattr(type(rule), "param_grid") else []
    shipped = dict(getattr(rule, "params", None) or {})
    if not shipped or not any(grid):
        raise ValueError(f"tune: {getattr(rule, 'name', type(rule).__name__)!r} has no parameters to tune: tune "
                         f"a rule with thresholds or intervals (grouped-threshold, section-threshold, ...)")
    if not isinstance(futures, int) or isinstance(futures, bool) or not 1 <= futures <= len(TRAIN_SEEDS):
        raise ValueError(f"tune must be an integer in [1, {len(TRAIN_SEEDS)}] (training futures), got {futures!r}")
    candidates = [shipped, *(g for g in grid if g != shipped)]
    train = config.replace(horizon_years=TUNE_YEARS)
    found = tune(type(rule), train, train_seeds=TRAIN_SEEDS[:futures], grid=candidates, progress=progress,
                 action_type=action_type_for(config))
    costs = {tuple(sorted(row["params"].items())): row["mean_cost"] for row in found["table"]}
    return RuleTuning(dict(found["best_params"]), shipped, float(found["best_mean_cost"]),
                      float(costs[tuple(sorted(shipped.items()))]), futures, TRAIN_SEEDS[0], len(candidates))

