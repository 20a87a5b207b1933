"""Compare maintenance policies: tune every heuristic on training seeds, score all on held-out test seeds.

    from trackenv_agents.compare import run_comparison
    out = run_comparison(quick=True)          # ~1 min: 30 m track, 3 sections, 1.5 years, few seeds
    out = run_comparison(n_test=32, n_train=16)

Writes ``comparison.json`` (summaries, tuning tables, paired differences to the best policy, config, seeds),
``costs.png`` (per-episode costs per policy) and ``episode.png`` (one test episode under the best heuristic)
to ``out_dir``. A trained agent joins through ``extra_policies`` (name -> object with SB3's ``predict``).
"""

from __future__ import annotations

import json
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from trackenv._json import json_default
from trackenv.envs.config import TampingEnvConfig

QUICK_CONFIG = {"track_length_m": 30.0, "n_sections": 3, "horizon_years": 1.5}
QUICK_N_TEST, QUICK_N_TRAIN = 6, 2


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
    """Tune each heuristic of :data:`trackenv_agents.heuristics.HEURISTICS` (but the random baseline) on the first
    ``n_train`` training seeds, evaluate them, a random baseline and ``extra_policies`` on the first
    ``n_test`` test seeds; returns ``{"results": [summaries sorted by mean cost], ...}`` and writes the files
    to ``out_dir`` (``None``: write nothing).

    ``quick``: unless given, config = the 30 m / 3 section / 1.5 year track, n_test = 6, n_train = 3.
    Defaults otherwise: ``TampingEnvConfig()``, all of ``TEST_SEEDS`` (200) and ``TRAIN_SEEDS`` (100).
    ``executor``: runs the episode batches (e.g. :class:`trackenv_agents.distributed.RayExecutor`).
    """
    from .evaluation import (
        TEST_SEEDS,
        TRAIN_SEEDS,
        compare_results,
        format_table,
        paired_difference,
        plot_comparison,
        plot_episode,
    )
    from .heuristics import HEURISTICS, RandomPolicy, tuned_params

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
