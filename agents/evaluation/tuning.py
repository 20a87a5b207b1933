"""Grid search of the heuristics' parameters on the training seeds, all candidates in one batched run.

Every candidate is scored by the harness (:func:`trackenv_agents.evaluation.harness.evaluate_many`), so a grid costs
one vector env per batch whatever the number of candidates; the test seeds are never used here.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING, Any

from trackenv.envs.line_config import LineConfig
from trackenv.envs.problems import ProblemConfig, problem_config

from .harness import TRAIN_SEEDS, evaluate_many

if TYPE_CHECKING:
    from ..rules.base import Heuristic

__all__ = ["tune", "tune_many"]


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
        rows = sorted(({"params": dict(g), "mean_cost": float(r.cost.mean()),
                        "tampings_per_km_year": float(r.tampings_per_km_year.mean()),
                        "episode_costs": r.cost.tolist()}
                       for (j, g), r in zip(cands, results, strict=True) if j == i),
                      key=lambda row: row["mean_cost"])
        out[i] = {"policy": getattr(cls, "name", cls.__name__), "best_params": rows[0]["params"],
                  "best_mean_cost": rows[0]["mean_cost"], "table": rows}
    return out
