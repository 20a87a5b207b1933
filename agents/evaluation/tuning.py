"""Grid search of the heuristics' parameters on the training seeds, all candidates in one batched run.

Every candidate is scored by the harness (:func:`trackenv_agents.evaluation.harness.evaluate_many`), so a grid costs
one vector env per batch whatever the number of candidates; the test seeds are never used here. :func:`race` is the
same search that stops running the candidates that are clearly dearer on the first seeds (a plan's tuning on a line
of one's own, where every episode is a whole line's ten years).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy import stats

from trackenv.envs.line_config import LineConfig
from trackenv.envs.problems import ProblemConfig, problem_config

from .harness import TRAIN_SEEDS, evaluate_many

if TYPE_CHECKING:
    from ..rules.base import Heuristic

__all__ = ["RACE_LEVEL", "RACE_MARGIN", "race", "race_rounds", "tune", "tune_many"]

#: a race drops a candidate whose mean cost over the futures run so far exceeds the leader's, paired per future, by
#: more than this share of the leader's mean cost and by more than the 97.5 % quantile of Student's t times the
#: standard error of the paired differences (a one-sided test at 2.5 %)
RACE_MARGIN = 0.02
#: the one-sided level of that test
RACE_LEVEL = 0.975


def tune(policy_cls: type[Heuristic], config: LineConfig | dict | str | None = None,
         train_seeds: Iterable[int] = TRAIN_SEEDS, grid: Sequence[dict] | None = None, batch_size: int = 32,
         progress: bool = False, executor: Any = None, action_type: str = "multibinary",
         desc: str | None = None) -> dict[str, Any]:
    """Grid search of ``policy_cls`` over ``grid`` (default ``policy_cls.param_grid()``) on ``train_seeds``
    (``action_type``: the env's, "choices" for the rules that use the choices; ``desc``: the progress bar's).

    Returns ``{"policy", "best_params", "best_mean_cost", "table"}``; ``table`` lists every candidate's
    params, mean cost and per-episode costs on the training seeds, sorted by cost (ties: grid order).
    """
    grid = list(policy_cls.param_grid() if grid is None else grid)
    if not grid:
        raise ValueError("empty parameter grid")
    return tune_many([policy_cls], problem_config(config), list(train_seeds), batch_size, progress,
                     grids=[grid], executor=executor, action_type=action_type, desc=desc)[0]


def tune_many(classes: Sequence[type[Heuristic]], cfg: ProblemConfig, train_seeds: Sequence[int], batch_size: int,
              progress: bool, grids: Sequence[Sequence[dict]] | None = None, executor: Any = None,
              action_type: str = "multibinary", desc: str | None = None) -> dict[int, dict]:
    """:func:`tune` for several classes in one batched run, each over its grid (default its
    ``param_grid()``); table rows also hold the per-episode costs, in ``train_seeds`` order."""
    if grids is None:
        grids = [cls.param_grid() for cls in classes]
    cands = [(i, g) for i, grid in enumerate(grids) for g in grid]
    if desc is None:
        desc = f"tune {getattr(classes[0], 'name', classes[0].__name__)}" if len(classes) == 1 else "tune"
    results = evaluate_many([classes[i](**g) for i, g in cands], cfg, train_seeds, action_type=action_type,
                            batch_size=batch_size, progress=progress, desc=desc, executor=executor)
    out: dict[int, dict] = {}
    for i, cls in enumerate(classes):
            out[i] = _found(cls, [_row(g, r.cost.tolist(), r.tampings_per_km_year.tolist())
                               for (j, g), r in zip(cands, results, strict=True) if j == i])
    return out


def _row(params: dict, episode_costs: list[float], tampings_per_km_year: list[float]) -> dict[str, Any]:
    """A candidate's row of a search's table: its params, its mean cost and tampings and its per-episode costs."""
    return {"params": dict(params), "mean_cost": float(np.mean(episode_costs)),
            "tampings_per_km_year": float(np.mean(tampings_per_km_year)), "episode_costs": episode_costs}


def _found(cls: type[Heuristic], rows: list[dict[str, Any]]) -> dict[str, Any]:
    """A search's result: its ``table`` (``rows`` sorted by mean cost; ties in the grid's order) and the best."""
    rows = sorted(rows, key=lambda row: float(row["mean_cost"]))
    return {"policy": getattr(cls, "name", cls.__name__), "best_params": rows[0]["params"],
            "best_mean_cost": rows[0]["mean_cost"], "table": rows}


def race_rounds(futures: int) -> list[int]:
    """The numbers of futures after which a race of ``futures`` futures looks at its candidates: half of them (at
    least two), then all; fewer than four futures are not raced. One look at half: a line's ten-year futures differ
    enough that the first two can rank two candidates the other way round from all eight (the default line at
    180 km/h: the best over eight futures 10 % dearer than another over the first two)."""
    return [futures // 2, futures] if futures >= 4 else [futures]


def race(policy_cls: type[Heuristic], config: LineConfig | dict | str | None, train_seeds: Sequence[int],
         grid: Sequence[dict], keep: Sequence[dict] = (), batch_size: int = 32, progress: bool = False,
         executor: Any = None, action_type: str = "multibinary", desc: str | None = None) -> dict[str, Any]:
    """:func:`tune` that stops running the candidates that are clearly dearer: every candidate of ``grid`` runs
    the first futures of ``train_seeds``, and after each round of :func:`race_rounds` a candidate is dropped
    where its mean cost exceeds the leader's (the lowest so far), paired per future, by more than
    :data:`RACE_MARGIN` of the leader's cost and significantly (Student's t at :data:`RACE_LEVEL`, one-sided);
    the others run the next futures. The leader and the candidates of ``keep`` (a plan's shipped parameters,
    whose cost it reports) are never dropped. Each episode's cost is the one :func:`tune` gives (the episodes do
    not depend on which others share their batch), so the survivors' rows equal :func:`tune`'s; a dropped
    candidate is one the full search would have found dearer unless its first futures were unlike the rest.

    Returns :func:`tune`'s dict, its ``table`` the candidates that ran every future, plus ``dropped``: each
    dropped candidate's params, the futures it ran (``futures``) and its ``mean_cost`` on them.
    """
    cfg = problem_config(config)
    seeds = [int(s) for s in train_seeds]
    grid = [dict(g) for g in grid]
    if not grid:
        raise ValueError("empty parameter grid")
    name = desc or f"tune {getattr(policy_cls, 'name', policy_cls.__name__)}"
    costs: list[list[float]] = [[] for _ in grid]
    tampings: list[list[float]] = [[] for _ in grid]
    alive = list(range(len(grid)))
    dropped: list[dict[str, Any]] = []
    done = 0
    for n in race_rounds(len(seeds)):
        text = name if n == len(seeds) and done == 0 else f"{name}, futures {done + 1}-{n} of {len(seeds)}"
        results = evaluate_many([policy_cls(**grid[i]) for i in alive], cfg, seeds[done:n], action_type=action_type,
                                batch_size=batch_size, progress=progress, desc=text, executor=executor)
        for i, r in zip(alive, results, strict=True):
            costs[i] += r.cost.tolist()
            tampings[i] += r.tampings_per_km_year.tolist()
        done = n
        if n == len(seeds):
            break
        means = {i: float(np.mean(costs[i])) for i in alive}
        leader = min(alive, key=lambda i: means[i])
        for i in list(alive):
            if i == leader or grid[i] in keep:
                continue
            diff = np.asarray(costs[i]) - np.asarray(costs[leader])
            spread = float(stats.t.ppf(RACE_LEVEL, n - 1)) * float(diff.std(ddof=1)) / math.sqrt(n)
            if diff.mean() > max(RACE_MARGIN * means[leader], spread):
                alive.remove(i)
                dropped.append({"params": grid[i], "futures": n, "mean_cost": means[i]})
    return {**_found(policy_cls, [_row(grid[i], costs[i], tampings[i]) for i in alive]), "dropped": dropped}
