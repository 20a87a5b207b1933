"""The model-predictive planner (:class:`trackenv_agents.rules.model_predictive.ModelPredictive`) on the 60 m track
(``trackenv/Tamping-v1``): its model's free parameters chosen on training episodes, then scored against the
tuned grouped threshold on held-out episodes, paired, and against the whole-line hindsight bound where its
schedules are saved.

1. **Choose** (seeds 3000–3063, none a held-out seed): every (regrowth factor, SD slope after tamping, SD from
   which a campaign takes a tamped section's neighbours, prior growth, weight of a section's own tamping in its
   slope) of the grid with a certain forecast, the cheapest mean cost kept; then, with those, the forecast
   error's growth per step (:data:`FORECAST_ERRORS`), the cheapest kept.
2. **Score** (seeds 0–199, the held-out episodes of the 60 m track's comparisons): the planner against the tuned
   grouped threshold, paired bootstrap 95 % CI, and against the same planner with a certain forecast.
3. **Normalised score** on the leaderboard's seeds 0–47 (as the leaderboard computes it): the share of the gap
   from the rule to the saved hindsight bound (``experiments/searches/line_room_track60_0-47.json``) closed.

    python experiments/model_predictive.py      # ~10 min on 2 cores; writes experiments/saved/model_predictive.json
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from trackenv.envs.line_config import scenario
from trackenv_agents.evaluation.harness import evaluate_many
from trackenv_agents.evaluation.leaderboard import normalised_score
from trackenv_agents.evaluation.line_compare import parse_seeds
from trackenv_agents.evaluation.line_hindsight import saved_schedules
from trackenv_agents.evaluation.statistics import bootstrap_ci, paired_difference
from trackenv_agents.rules.model_predictive import ModelPredictive
from trackenv_agents.rules.problems import tuned_rule

HERE = Path(__file__).resolve().parent
BOUND = HERE / "searches" / "line_room_track60_0-47.json"
GRID = [{"regrowth_factor": g, "tamped_sd_slope": s, "neighbour_mm": n, "prior_growth_mm_per_step": h,
         "own_slope_weight": w, "forecast_error_mm_per_step": 0.0}
        for g in (1.26, 1.5) for s in (0.44, 0.5) for n in (0.5, 1.0) for h in (0.04, 0.06) for w in (0.0, 0.5)]
#: the forecast error's growth per step searched at the chosen grid point [mm]
FORECAST_ERRORS = (0.0, 0.01, 0.015, 0.02, 0.025, 0.03, 0.04)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--train-seeds", default="3000:3064")
    ap.add_argument("--seeds", default="0:200", help="held-out episodes")
    ap.add_argument("--out", default=str(HERE / "saved" / "model_predictive.json"))
    a = ap.parse_args(argv)
    t0 = time.time()
    config = scenario("track60")
    rule = tuned_rule(config, "grouped-threshold", require_tuned=True)
    train = parse_seeds(a.train_seeds)
    grid = [ModelPredictive(**params) for params in GRID]
    tuning = evaluate_many([rule, *grid], config, train, batch_size=64, progress=True, desc="choose")
    means = [float(r.cost.mean()) for r in tuning[1:]]
    certain = GRID[int(np.argmin(means))]
    errors = evaluate_many([ModelPredictive(**{**certain, "forecast_error_mm_per_step": e}) for e in FORECAST_ERRORS],
                           config, train, batch_size=64, progress=True, desc="forecast error")
    error_means = [float(r.cost.mean()) for r in errors]
    chosen = {**certain, "forecast_error_mm_per_step": FORECAST_ERRORS[int(np.argmin(error_means))]}
    print("chosen", chosen, f"{min(error_means):.1f} k€ against the rule's {tuning[0].cost.mean():.1f} on the "
          f"training seeds", flush=True)
    seeds = parse_seeds(a.seeds)
    held = evaluate_many([rule, ModelPredictive(**chosen), ModelPredictive(**certain)], config, seeds,
                         batch_size=100, progress=True, desc="held-out")
    d = paired_difference(held[1], held[0])
    e = paired_difference(held[1], held[2])
    rel = bootstrap_ci((held[1].cost - held[0].cost) / held[0].cost.mean())
    out = {"chosen": chosen, "train_seeds": a.train_seeds, "seeds": a.seeds, "rule": dict(rule.params),
           "training": [{"params": p, "mean_cost": m} for p, m in zip(GRID, means, strict=True)],
           "training_rule_mean": float(tuning[0].cost.mean()),
           "forecast_error": [{"forecast_error_mm_per_step": x, "mean_cost": m}
                              for x, m in zip(FORECAST_ERRORS, error_means, strict=True)],
           "held_out": {"rule_mean": float(held[0].cost.mean()), "planner_mean": float(held[1].cost.mean()),
                        "difference": {k: d[k] for k in ("mean_difference", "ci_low", "ci_high",
                                                         "a_better_fraction")},
                        "relative": d["mean_difference"] / float(held[0].cost.mean()),
                        "relative_ci": [float(rel[0]), float(rel[1])],
                        "certain_forecast_mean": float(held[2].cost.mean()),
                        "vs_certain_forecast": {k: e[k] for k in ("mean_difference", "ci_low", "ci_high",
                                                                  "a_better_fraction")},
                        "planner_parts": {k: float(v.mean()) for k, v in held[1].cost_parts.items() if v.any()},
                        "rule_parts": {k: float(v.mean()) for k, v in held[0].cost_parts.items() if v.any()},
                        "planner_sections_tamped": float(held[1].tamped.sum(axis=(1, 2)).mean()),
                        "rule_sections_tamped": float(held[0].tamped.sum(axis=(1, 2)).mean())}}
    bound_seeds, _, bound_costs = saved_schedules([BOUND], config)
    on = [s for s in bound_seeds if s in set(seeds)]
    if on:
        pos = {s: i for i, s in enumerate(held[0].seeds.tolist())}
        idx = [pos[s] for s in on]
        bound = np.array([c for s, c in zip(bound_seeds, bound_costs, strict=True) if s in set(on)])
        out["normalised"] = {"seeds": f"{on[0]}:{on[-1] + 1}", "n_episodes": len(on),
                             "bound_mean": float(bound.mean()),
                             **normalised_score(held[0].cost[idx], held[1].cost[idx], bound)}
    out["wall_seconds"] = time.time() - t0
    print(json.dumps({k: out[k] for k in ("held_out", "normalised") if k in out}, indent=1))
    Path(a.out).write_text(json.dumps(out, indent=1) + "\n")
    print(f"wrote {a.out} ({out['wall_seconds']:.0f} s)")


if __name__ == "__main__":
    main()
