"""Compare maintenance policies: tune every heuristic on training seeds, score all on held-out test seeds.

    from trackenv_agents.evaluation.tamping_compare import compare, run_comparison
    rows = compare(["periodic", "sd_threshold"], train_seeds=range(1000, 1010))  # summaries, best first
    out = run_comparison(quick=True)          # ~1 min: 30 m track, 3 sections, 1.5 years, few seeds
    out = run_comparison(n_test=32, n_train=16)

Writes ``comparison.json`` (summaries, tuning tables, paired differences to the best policy, config, seeds),
``costs.png`` (per-episode costs per policy) and ``episode.png`` (one test episode under the best heuristic)
to ``out_dir``. A trained agent joins through ``extra_policies`` (name -> object with SB3's ``predict``).
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from trackenv._json import json_default
from trackenv.envs.config import TampingEnvConfig
from trackenv.envs.problems import problem_config

from .harness import TEST_SEEDS, TRAIN_SEEDS, EvaluationResult, evaluate_many
from .reporting import format_table, plot_comparison, plot_episode
from .statistics import paired_difference
from .tuning import tune_many

QUICK_CONFIG = {"track_length_m": 30.0, "n_sections": 3, "horizon_years": 1.5}
QUICK_N_TEST, QUICK_N_TRAIN = 6, 2


def compare_results(policies: Sequence[Any] | Mapping[str, Any],
                    config: TampingEnvConfig | dict | None = None,
                    test_seeds: Iterable[int] = TEST_SEEDS, train_seeds: Iterable[int] | None = None,
                    tune_heuristics: bool = True, batch_size: int = 32, progress: bool = False,
                    executor: Any = None) -> tuple[list[EvaluationResult], dict[str, dict]]:
    """Tune (classes with a ``param_grid``, on ``train_seeds``) and evaluate on ``test_seeds``.

    ``policies``: heuristic classes (tuned if ``tune_heuristics`` and ``train_seeds`` are given, else default
    parameters), registry names (as classes), or ready policy objects (used as they are); or a mapping
    name -> any of these (the name labels the result). Returns the results sorted by mean cost and the tuning
    tables by policy name.
    """
    from ..rules import rules_for

    cfg = problem_config(config)
    rules = rules_for(cfg)
    items = list(policies.items()) if isinstance(policies, Mapping) else [(None, p) for p in policies]
    items = [(label, rules[p] if isinstance(p, str) else p) for label, p in items]
    tunable = [i for i, (_, p) in enumerate(items) if isinstance(p, type) and hasattr(p, "param_grid")]
    tuning: dict[str, dict] = {}
    chosen: list[Any] = []
    tuned = {}
    if tune_heuristics and train_seeds is not None and tunable:
        tuned = tune_many([items[i][1] for i in tunable], cfg, list(train_seeds), batch_size, progress,
                          executor=executor)
    for i, (label, p) in enumerate(items):
        if isinstance(p, type):
            if i in tunable and tunable.index(i) in tuned:
                t = tuned[tunable.index(i)]
                tuning[label or t["policy"]] = t
                obj = p(**t["best_params"])
            else:
                obj = p()
        else:
            obj = p
        chosen.append(obj)
    results = evaluate_many(chosen, cfg, test_seeds, batch_size=batch_size, progress=progress, desc="test",
                            executor=executor)
    for (label, _), r in zip(items, results, strict=True):
        if label is not None:
            r.policy = label
    results.sort(key=lambda r: float(r.cost.mean()))
    return results, tuning


def compare(policies: Sequence[Any] | Mapping[str, Any], config: TampingEnvConfig | dict | None = None,
            test_seeds: Iterable[int] = TEST_SEEDS, train_seeds: Iterable[int] | None = None,
            tune_heuristics: bool = True, batch_size: int = 32, progress: bool = False,
            executor: Any = None) -> list[dict]:
    """Summaries (:meth:`EvaluationResult.summary`) of :func:`compare_results`, sorted by mean cost."""
    results, _ = compare_results(policies, config, test_seeds, train_seeds, tune_heuristics, batch_size,
                                 progress, executor)
    return [r.summary() for r in results]


def run_comparison(
    out_dir: str | Path | None = "results/compare",
    config: TampingEnvConfig | dict | None = None,
    n_test: int | None = None,
    n_train: int | None = None,
    quick: bool = False,
    progress: bool = True,
    extra_policies: Mapping[str, Any] | None = None,
    batch_size: int = 32,
    tuned: Mapping[str, dict] | str | Path | None = None,
    executor: Any = None,
) -> dict[str, Any]:
    """Tune each heuristic of :data:`trackenv_agents.rules.tamping.HEURISTICS` (but the random baseline) on the first
    ``n_train`` training seeds, evaluate them, a random baseline and ``extra_policies`` on the first
    ``n_test`` test seeds; returns ``{"results": [summaries sorted by mean cost], ...}`` and writes the files
    to ``out_dir`` (``None``: write nothing).

    ``quick``: unless given, config = the 30 m / 3 section / 1.5 year track, n_test = 6, n_train = 3.
    Defaults otherwise: ``TampingEnvConfig()``, all of ``TEST_SEEDS`` (200) and ``TRAIN_SEEDS`` (100).
    ``executor``: runs the episode batches (e.g. :class:`trackenv_agents.evaluation.distributed.RayExecutor`).
    """
    from ..rules.tamping import HEURISTICS, RandomPolicy, tuned_params

    t0 = time.perf_counter()
    config = TampingEnvConfig.coerce(QUICK_CONFIG if quick and config is None else config)
    if n_test is None:
        n_test = QUICK_N_TEST if quick else len(TEST_SEEDS)
    if n_train is None:
        n_train = QUICK_N_TRAIN if quick else len(TRAIN_SEEDS)
    if not 1 <= n_test <= len(TEST_SEEDS) or not 1 <= n_train <= len(TRAIN_SEEDS):
        raise ValueError(
            f"n_test must be in [1, {len(TEST_SEEDS)}] and n_train in [1, {len(TRAIN_SEEDS)}], got {n_test}, {n_train}"
        )
    test_seeds, train_seeds = list(TEST_SEEDS[:n_test]), list(TRAIN_SEEDS[:n_train])

    policies: dict[str, Any] = {name: cls for name, cls in HEURISTICS.items() if name != "random"}
    if tuned is not None:  # parameters tuned earlier: evaluate those, do not tune again
        if not isinstance(tuned, Mapping):
            tuned = tuned_params(tuned)
        for name, params in tuned.items():
            if name not in policies:
                raise ValueError(f"tuned parameters for unknown heuristic {name!r}")
            policies[name] = HEURISTICS[name](**params)
    policies["random"] = RandomPolicy(p=0.05, seed=0)
    for name, pol in (extra_policies or {}).items():
        if name in policies:
            raise ValueError(f"extra policy name {name!r} clashes with a heuristic")
        policies[name] = pol
    results, tuning = compare_results(
        policies, config, test_seeds, train_seeds, tune_heuristics=True, batch_size=batch_size, progress=progress,
        executor=executor,
    )
    summaries = [r.summary() for r in results]
    episode_costs = {r.policy: np.asarray(r.cost).tolist() for r in results}
    best = results[0]
    paired = [paired_difference(r, best) for r in results[1:]]
    out: dict[str, Any] = {
        "results": summaries,
        "tuning": tuning,
        "paired_vs_best": paired,
        "config": config.to_dict(),
        "test_seeds": test_seeds,
        "train_seeds": train_seeds,
        "quick": quick,
        "episode_costs": episode_costs,
    }
    if out_dir is not None:
        d = Path(out_dir)
        d.mkdir(parents=True, exist_ok=True)
        plot_comparison(results, str(d / "costs.png"))
        best_heur = next((r for r in results if r.policy in HEURISTICS and r.policy != "random"), None)
        out["files"] = {"json": str(d / "comparison.json"), "costs": str(d / "costs.png")}
        if best_heur is not None:
            pol = HEURISTICS[best_heur.policy](**best_heur.params)
            plot_episode(pol, config, test_seeds[0], str(d / "episode.png"))
            out["files"]["episode"] = str(d / "episode.png")
        for name, pol in (extra_policies or {}).items():  # the same held-out episode under each trained agent
            plot_episode(pol, config, test_seeds[0], str(d / f"episode_{name}.png"))
            out["files"][f"episode_{name}"] = str(d / f"episode_{name}.png")
        out["best_params"] = {r.policy: r.params for r in results if r.policy in HEURISTICS and r.policy != "random"}
    out["wall_time_s"] = time.perf_counter() - t0
    out["table"] = format_table(summaries)
    if out_dir is not None:
        (Path(out_dir) / "comparison.json").write_text(json.dumps(out, indent=2, default=json_default))
    return out
