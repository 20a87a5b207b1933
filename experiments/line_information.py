"""How much of the room below the best rule is information about the present: the grouped threshold tuned anew
under recording designs that see more of the line's present state, on the leaderboard's default-line episodes,
against the hindsight bound.

    python experiments/line_information.py                        # the designs below, ~25 min on 2 cores
    python experiments/line_information.py --design perfect --train-seeds 1000:1004 --out results/info.json
    python experiments/line_information.py --design preset --design perfect --train-agent runs/line_information \
        --out experiments/saved/line_information_trained.json  # and the learner retrained under each, ~25 min

The default line measures once a year with noise (the preset: ``measurement_interval`` 4 steps, SD noise 0.1 mm,
mean-to-peak noise 0.5 mm). Each design changes only what the recording car tells, not the track: the episodes
of a seed are the same (the measurement draws come after the track's). Per design the grouped threshold is tuned
over :data:`GRID` on the training seeds, then the tuned rule and the shipped agent (``cpi-agent``, not retrained:
its features read the measurement's age, so it takes a fresher measurement as it comes) are scored on the
leaderboard's default-line seeds. Every cost is compared, paired per episode, with the reference of the
leaderboard, the grouped threshold with its shipped parameters under the preset's own recording, and with the
hindsight bound, the leaderboard's saved schedules replayed here and capped at the reference's cost: the share of
the reference-to-bound gap a policy closes (the normalised score). A rule that knows the present exactly, every
step, but not the future, shows how much of that gap a better view of the present could buy; the rest of the
bound's gain comes from knowing the future (how each tamping comes out, when a wet spot starts, the
measurements' errors) and from choosing each episode's schedule with that knowledge. With ``--train-agent`` the
line's policy iteration is also trained under each design, the design's tuned rule as its advisor, with the
settings and seeds of the shipped agent's training, and scored beside them (``"trained"``).

All runs use ``engine="fast"`` and ``pass_reuse_tolerance_m=1e-3`` (episode costs within a tenth of a percent of
the classic engine's; the documentation's Performance page), the bound's replays included.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "experiments" / "saved" / "line_information.json"
FAST = {"engine": "fast", "pass_reuse_tolerance_m": 1e-3}
#: recording designs by their ``--design`` name: what the recording car tells (the preset's measurement fields
#: they change)
DESIGNS: dict[str, dict[str, float]] = {
    "preset": {},
    "twice": {"measurement_interval": 2},
    "quarterly": {"measurement_interval": 1},
    "perfect": {"measurement_interval": 1, "sd_noise_mm": 0.0, "peak_noise_mm": 0.0},
}
#: each design's name in the tables and the saved JSON
LABELS = {"preset": "once a year (the preset)", "twice": "twice a year", "quarterly": "every quarter",
          "perfect": "every quarter, no error"}
#: the grouped threshold's (trigger, include) grid [mm], include below the trigger: wider and lower than the rule's
#: own ``param_grid`` (a fresher view may tamp earlier)
GRID = [{"trigger_mm": t, "include_mm": i} for t in (1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 4.5, 5.0, 6.0)
        for i in (0.75, 1.0, 1.25, 1.5, 2.0, 2.5, 3.0) if i < t]
#: where the design measures every step without error, the model-predictive planner of the 60 m track also runs
#: (its parameters as shipped when this experiment's results were saved, not tuned on the line; ``neighbour_mm``
#: at its maximum: the line's sections are separate segments, so a tamping leaves no step at a neighbour's boundary)
PLANNER = {"neighbour_mm": 100.0, "tamped_sd_slope": 0.44, "regrowth_factor": 1.5, "prior_growth_mm_per_step": 0.04,
           "own_slope_weight": 0.5, "forecast_error_mm_per_step": 0.0}


def bound_schedules() -> tuple[list[int], list[np.ndarray]]:
    """The leaderboard's default-line seeds and their saved bound schedules."""
    from trackenv_agents.evaluation.leaderboard import SHIPPED_BOUNDS
    from trackenv_agents.evaluation.line_hindsight import schedule_from_rows

    found = sorted(SHIPPED_BOUNDS.glob("default_*.json"))
    if len(found) != 1:
        raise SystemExit(f"expected one bound file of the default line in {SHIPPED_BOUNDS}, found {len(found)}")
    episodes = json.loads(found[0].read_text())["episodes"]
    seeds = sorted(int(s) for s in episodes)
    return seeds, [schedule_from_rows(episodes[str(s)]["schedule"]) for s in seeds]


def paired(cost: np.ndarray, reference: np.ndarray) -> dict[str, float]:
    """cost − reference per episode: mean, 95 % bootstrap CI, and relative to the reference's mean."""
    from trackenv_agents.evaluation.statistics import bootstrap_ci

    d = np.asarray(cost) - np.asarray(reference)
    lo, hi = bootstrap_ci(d)
    return {"mean": float(d.mean()), "ci": [lo, hi], "relative": float(d.mean() / np.mean(reference))}


def score(cost: np.ndarray, reference: np.ndarray, bound: np.ndarray) -> dict:
    """The policy's costs against the reference and the share of the reference-to-bound gap it closes."""
    from trackenv_agents.evaluation.leaderboard import normalised_score

    n = normalised_score(reference, cost, bound)
    return {"mean_keur": float(np.mean(cost)), "vs_reference": paired(cost, reference),
            "normalised_score": n["score"], "normalised_score_ci": n["ci"]}


def train_agent(config, advisor_params: dict, out_dir: Path) -> Path:
    """The line's counterfactual policy iteration with the shipped settings (6 iterations of 16 episodes, the
    training seeds and held-out seeds of ``trackenv train``) on ``config``, the grouped threshold with
    ``advisor_params`` as its advisor; the best iteration's model."""
    from trackenv_agents.learning.line import train_line

    train_line(config, out_dir=out_dir, progress=False, hyperparams={"advisor_params": advisor_params})
    return out_dir / "best_model.zip"


def run(designs: list[str], train_seeds: list[int], progress: bool = True, agents_dir: Path | None = None) -> dict:
    """Tune and score every design of ``designs`` (names of :data:`DESIGNS`; see the module docstring); with
    ``agents_dir``, also train the line's policy iteration under each design with its tuned rule as advisor (into
    ``agents_dir/<design>``) and score it (``"trained"``)."""
    from trackenv.envs.line_config import scenario
    from trackenv_agents.evaluation.harness import evaluate_many
    from trackenv_agents.evaluation.line_hindsight import replay_schedules
    from trackenv_agents.evaluation.tuning import tune_many
    from trackenv_agents.learning.line import load_line_trained
    from trackenv_agents.rules.line import GroupedThreshold
    from trackenv_agents.rules.model_predictive import ModelPredictive
    from trackenv_agents.rules.problems import tuned_rule
    from trackenv_agents.shipped import LINE_AGENT_NAME, SHIPPED_AGENTS

    base = scenario("default", **FAST)
    seeds, plans = bound_schedules()
    agent = load_line_trained(SHIPPED_AGENTS[LINE_AGENT_NAME], name=LINE_AGENT_NAME)
    t0 = time.perf_counter()
    reference = evaluate_many([tuned_rule(base, "grouped-threshold", require_tuned=True)], base, seeds)[0].cost
    bound = np.minimum(replay_schedules(base, seeds, plans), reference)
    out = {"seeds": seeds, "train_seeds": train_seeds, "grid": GRID, "fast_options": FAST,
           "reference": {"policy": "grouped-threshold, shipped parameters, the preset's recording",
                         "mean_keur": float(reference.mean()), "costs": reference.tolist()},
           "bound": {"mean_keur": float(bound.mean()), "vs_reference": paired(bound, reference),
                     "costs": bound.tolist()},
           "designs": {}}
    for design in designs:
        name = LABELS[design]
        cfg = base.replace(**DESIGNS[design])
        tuned = tune_many([GroupedThreshold], cfg, train_seeds, batch_size=32, progress=progress, grids=[GRID])[0]
        policies = {"rule": GroupedThreshold(**tuned["best_params"]), LINE_AGENT_NAME: agent}
        if ModelPredictive.unfit_for(cfg) is None:
            policies["model-predictive"] = ModelPredictive(**PLANNER)
        if agents_dir is not None:
            t1 = time.perf_counter()
            policies["trained"] = load_line_trained(train_agent(cfg, tuned["best_params"], agents_dir / design))
            out.setdefault("training_s", {})[name] = time.perf_counter() - t1
        results = evaluate_many(list(policies.values()), cfg, seeds, progress=progress, desc=name)
        out["designs"][name] = {"fields": DESIGNS[design], "tuned_params": tuned["best_params"],
                                "train_mean_keur": tuned["best_mean_cost"]}
        for key, r in zip(policies, results, strict=True):
            out["designs"][name][key] = {**score(r.cost, reference, bound), "costs": r.cost.tolist()}
        print(f"{name}: tuned {tuned['best_params']}; " + "; ".join(
            f"{k} {out['designs'][name][k]['mean_keur']:.1f} k€ "
            f"({100 * out['designs'][name][k]['vs_reference']['relative']:+.1f} %, normalised "
            f"{out['designs'][name][k]['normalised_score']:.2f})" for k in policies), flush=True)
    out["wall_s"] = time.perf_counter() - t0
    return out


def main(argv: list[str] | None = None) -> int:
    from trackenv_agents.evaluation.line_compare import parse_seeds

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--design", action="append", choices=sorted(DESIGNS),
                        help="a recording design (repeatable; default: all): " +
                             ", ".join(f"{k} = {v}" for k, v in LABELS.items()))
    parser.add_argument("--train-seeds", default="1000:1016", help="the tuning's episodes, A:B or a,b,c")
    parser.add_argument("--train-agent", default=None, metavar="DIR",
                        help="also train the policy iteration under each design (its tuned rule as advisor; about 5 "
                             "minutes a design) into DIR/<design>, and score it")
    parser.add_argument("--out", default=str(OUT))
    args = parser.parse_args(argv)
    designs = args.design or list(DESIGNS)
    result = run(designs, parse_seeds(args.train_seeds), agents_dir=None if args.train_agent is None
                 else Path(args.train_agent))
    given = sys.argv[1:] if argv is None else argv
    result["command"] = " ".join(["python experiments/line_information.py", *given])
    print(f"reference {result['reference']['mean_keur']:.1f} k€, bound {result['bound']['mean_keur']:.1f} k€ "
          f"({100 * result['bound']['vs_reference']['relative']:+.1f} %); {result['wall_s']:.0f} s")
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(result, indent=1) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
