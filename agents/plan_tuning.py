"""A plan's rule tuned on the line itself: ``trackenv plan LINE.yaml --tune N``.

The shipped rules' thresholds were tuned on the presets (the default line runs at 100 km/h, 15 MGT a year). A
line of one's own differs: a faster line has tighter limits and a dearer geometry per millimetre, other traffic
settles it at another rate. :func:`tune_plan_rule` searches the rule's grid (:meth:`param_grid`, plus the shipped
parameters; a choice rule's campaign first, then its choices around the best campaign: :func:`tuning_stages`) on ``N``
futures of the line from its state as of its file, each over :data:`TUNE_YEARS` (the presets' episode length, so
that what a rule leaves undone after the plan's horizon still costs), on the training seeds (from 1000: apart from
the plan's futures, seeds 0, 1, ...), and the plan then runs the cheapest. Its cost on those futures is in-sample:
the documentation's line-files page gives what it is worth on futures it did not see.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from trackenv.envs.choices import action_type_for

from .evaluation.harness import TRAIN_SEEDS
from .evaluation.tuning import RACE_LEVEL, RACE_MARGIN, race
from .plan_report import counted
from .rules.choices import CHOICE_OFF, ChoiceThreshold, choice_grid
from .rules.line import GroupedThreshold

__all__ = ["TUNE_YEARS", "RuleTuning", "check_apart", "check_tunable", "tune_plan_rule", "tuning_stages"]

#: years of each training future: the presets' episodes, on which the shipped parameters were tuned
TUNE_YEARS = 10.0
#: a choice rule's parameters whose value 0 switches their choice off: not the end of a range of thresholds
_OFF_AT_ZERO = frozenset(k for k, (_, off) in CHOICE_OFF.items() if off == 0 and not isinstance(off, bool))


@dataclass(frozen=True)
class RuleTuning:
    """What :func:`tune_plan_rule` found: the ``params`` it chose and the ``shipped_params``, their mean costs
    over the ``futures`` training futures (k€ over :data:`TUNE_YEARS`, in-sample), the first training seed
    ``seed``, the number of ``candidates`` searched and the values each parameter took among them (``searched``:
    only the parameters that varied; a parameter not in it was not tuned), the ``stages`` searched in turn where
    more than one, each its name and its number of candidates (:func:`tuning_stages`: a choice rule's campaign,
    then its choices). ``dropped``: the candidates the race stopped early as clearly dearer
    (:func:`~trackenv_agents.evaluation.tuning.race`), each its params, the futures it ran and its mean cost on
    them. ``alone``: the line was tuned
    alone, as if it had a machine of its own (a line of a network)."""

    params: dict[str, Any]
    shipped_params: dict[str, Any]
    cost_keur: float
    shipped_cost_keur: float
    futures: int
    seed: int
    candidates: int
    searched: dict[str, list[Any]] = field(default_factory=dict)
    alone: bool = False
    stages: tuple[tuple[str, int], ...] = ()
    dropped: tuple[dict[str, Any], ...] = ()

    @property
    def seeds(self) -> list[int]:
        return list(range(self.seed, self.seed + self.futures))

    def rule(self, shipped: Any, config: Any) -> Any:
        """The rule of ``shipped``'s class with the chosen :attr:`params`, bound to ``config`` (what a plan runs)."""
        return type(shipped)(**self.params).bind(config)

    def at_edge(self) -> list[str]:
        """The parameters whose chosen value is the smallest or the largest searched (of at least three): the
        line's best may lie beyond the grid. A choice switched off (its parameter at 0) is no end of a range."""
        out = []
        for k, values in self.searched.items():
            if k in _OFF_AT_ZERO:
                values = [v for v in values if v != 0]
            numbers = all(isinstance(v, int | float) and not isinstance(v, bool) for v in values)
            if len(values) >= 3 and numbers and self.params.get(k) in (values[0], values[-1]):
                out.append(k)
        return out

    def to_dict(self) -> dict[str, Any]:
        return {"params": dict(self.params), "shipped_params": dict(self.shipped_params),
                "cost_keur": self.cost_keur, "shipped_cost_keur": self.shipped_cost_keur, "futures": self.futures,
                "seeds": self.seeds, "years": TUNE_YEARS, "candidates": self.candidates,
                "searched": {k: list(v) for k, v in self.searched.items()}, "at_edge": self.at_edge(),
                "stages": [{"name": name, "candidates": n} for name, n in self.stages],
                "dropped": [dict(d) for d in self.dropped], "alone": self.alone}

    def lines(self, policy: str) -> list[str]:
        """The plan's table's lines: what changed (a choice rule has a dozen parameters), both costs, what was
        searched, and where the choice lies at the grid's edge."""
        changed = ", ".join(f"{k} {_shown(v)} (shipped {_shown(self.shipped_params.get(k))})"
                            for k, v in self.params.items() if v != self.shipped_params.get(k))
        chose = f"chose {changed}" if changed else "kept the shipped parameters"
        where = "this line alone (as if it had a machine of its own)" if self.alone else "this line"
        futures = counted(self.futures, "training future", "training futures")
        stages = (f" in {len(self.stages)} stages (" + ", then ".join(f"{n} for the {name}" for name, n in self.stages)
                  + "; " if len(self.stages) > 1 else " (")
        lines = [f"tuned on {where}: {policy} {chose}; {self.cost_keur:.0f} against {self.shipped_cost_keur:.0f} k€ "
                 f"with the shipped ones over {TUNE_YEARS:g} years, means over {futures} "
                 f"({_seeds_text(self.seed, self.futures)}, in-sample)",
                 f"  searched {self.candidates} candidates{stages}combinations of a grid, not every one) with "
                 + ", ".join(
                     f"{k} from {_shown(v[0])} to {_shown(v[-1])}" if len(v) > 2
                     else f"{k} {' or '.join(map(_shown, v))}" for k, v in self.searched.items())]
        if self.dropped:
            after = sorted({d["futures"] for d in self.dropped})
            lines.append(f"  {len(self.dropped)} of them stopped after {' or '.join(map(str, after))} of the "
                         f"{self.futures} futures: dearer than the best so far by more than {100 * RACE_MARGIN:g} %, "
                         f"significantly (paired t-test, one-sided {100 * (1 - RACE_LEVEL):g} %)")
        edge = self.at_edge()
        if edge:
            lines.append(f"  at the grid's edge: {', '.join(f'{k} {_shown(self.params[k])}' for k in edge)}: the "
                         f"line's best may lie beyond it")
        return lines


def _shown(value: Any) -> str:
    if isinstance(value, bool):
        return "on" if value else "off"
    return f"{value:g}" if isinstance(value, float) else str(value)


def _seeds_text(first: int, count: int) -> str:
    """``count`` consecutive seeds from ``first`` for people: "seed 1000" or "seeds 1000-1007"."""
    return f"seed {first}" if count == 1 else f"seeds {first}-{first + count - 1}"


def check_tunable(rule: Any, futures: int) -> None:
    """ValueError unless ``rule`` has parameters and a grid to tune and ``futures`` is a number of training
    futures in [1, len(TRAIN_SEEDS)]: what :func:`tune_plan_rule` needs, checked before a plan starts."""
    grid = list(type(rule).param_grid()) if hasattr(type(rule), "param_grid") else []
    if not getattr(rule, "params", None) or not any(grid):
        raise ValueError(f"tune: {getattr(rule, 'name', type(rule).__name__)!r} has no parameters to tune: tune "
                         f"a rule with thresholds or intervals (grouped-threshold, section-threshold, ...)")
    if not isinstance(futures, int) or isinstance(futures, bool) or not 1 <= futures <= len(TRAIN_SEEDS):
        raise ValueError(f"tune must be an integer in [1, {len(TRAIN_SEEDS)}] (training futures), got {futures!r}")


def check_apart(seed: int, futures: int, tune: int) -> None:
    """ValueError where a plan's futures (seeds ``seed`` .. ``seed + futures - 1``) are among the tuning's
    training futures (seeds from 1000): the forecast would be in-sample."""
    first, last = TRAIN_SEEDS[0], TRAIN_SEEDS[0] + tune - 1
    if tune and seed <= last and seed + futures - 1 >= first:
        raise ValueError(f"seed: the plan's futures ({_seeds_text(seed, futures)}) overlap the tuning's training "
                         f"futures ({_seeds_text(first, tune)}): its forecast would be in-sample; choose a seed below "
                         f"{first - futures + 1} or above {last}")


#: a search stage: the candidates to try from the best parameters found so far
Stage = Callable[[dict[str, Any]], list[dict[str, Any]]]


def tuning_stages(cls: type[Any]) -> list[tuple[str, Stage]]:
    """The grids :func:`tune_plan_rule` searches in turn for a rule of class ``cls``, each named and each from the
    best parameters so far: a choice rule's campaign triggers first (the grouped threshold's grid, with the
    choices as they are), then its choices around the best campaign (:func:`~trackenv_agents.rules.choices.
    choice_grid`), since the campaign carries most of a line's cost and the choice grid keeps it fixed; any other
    rule its own grid (:meth:`param_grid`) in one stage."""
    if issubclass(cls, ChoiceThreshold):
        def campaign(best: dict[str, Any]) -> list[dict[str, Any]]:
            return [{**best, **c} for c in GroupedThreshold.param_grid()]

        def choices(best: dict[str, Any]) -> list[dict[str, Any]]:
            return choice_grid(cls, {k: best[k] for k in ("trigger_mm", "include_mm")})

        return [("campaign's triggers", campaign), ("choices around the best campaign", choices)]
    return [("", lambda best: list(cls.param_grid()))]


def tune_plan_rule(rule: Any, config: Any, futures: int, progress: bool = False,
                   desc: str | None = None, executor: Any = None, batch_size: int = 32) -> RuleTuning:
    """Tune ``rule`` (a bound line rule with its shipped parameters: :func:`~trackenv_agents.planning.line_policy`)
    on ``futures`` futures of ``config`` (the plan's line config) over :data:`TUNE_YEARS`: the shipped parameters
    and each stage's grid (:func:`tuning_stages`), every candidate scored on the same futures;
    ``progress``: a progress bar a round on stderr (``desc`` its text). Each stage is a race
    (:func:`~trackenv_agents.evaluation.tuning.race`): the candidates clearly dearer on the first futures stop
    there; the shipped parameters run every future. ``executor`` runs the races' batches of ``batch_size``
    episodes (e.g. a :class:`~trackenv_agents.evaluation.distributed.RayExecutor`; None: here, in turn), with
    the same result. ValueError for a policy that has nothing to tune (:func:`check_tunable`)."""
    check_tunable(rule, futures)
    shipped = dict(rule.params)
    train = config.replace(horizon_years=TUNE_YEARS)
    best, best_cost, shipped_cost = shipped, math.inf, math.inf
    tried: list[dict[str, Any]] = [shipped]
    counts: list[tuple[str, int]] = []
    dropped: list[dict[str, Any]] = []
    named = tuning_stages(type(rule))
    for k, (name, stage) in enumerate(named):
        # the shipped parameters run in the first stage's batch
        candidates = [*([shipped] if k == 0 else []), *(c for c in stage(best) if c not in tried)]
        counts.append((name, len(candidates)))
        if not candidates:
            continue
        text = desc
        if len(named) > 1:
            text = (f"{desc or 'tune ' + type(rule).name}, stage {k + 1} of {len(named)}: {name} "
                    f"({len(candidates)} candidates)")
        found = race(type(rule), train, TRAIN_SEEDS[:futures], candidates, keep=[shipped], progress=progress,
                     action_type=action_type_for(config), desc=text, executor=executor, batch_size=batch_size)
        dropped += found["dropped"]
        if k == 0:
            shipped_cost = best_cost = float(next(row["mean_cost"] for row in found["table"]
                                                  if row["params"] == shipped))
        if found["best_mean_cost"] < best_cost:
            best, best_cost = dict(found["best_params"]), float(found["best_mean_cost"])
        tried += [c for c in candidates if c not in tried]
    return RuleTuning(best, shipped, best_cost, shipped_cost, futures, TRAIN_SEEDS[0], len(tried),
                      _searched(tried), stages=tuple(counts) if len(counts) > 1 else (), dropped=tuple(dropped))


def _searched(candidates: list[dict[str, Any]]) -> dict[str, list[Any]]:
    """Each parameter that varies among ``candidates`` with its values, sorted (a candidate without it: the
    rule's default, left out)."""
    values: dict[str, list[Any]] = {}
    for candidate in candidates:
        for key, value in candidate.items():
            if value not in values.setdefault(key, []):
                values[key].append(value)
    out = {}
    for key, seen in values.items():
        if len(seen) > 1:
            try:
                out[key] = sorted(seen)
            except TypeError:  # values of several types (None and a number): as first met
                out[key] = seen
    return out
