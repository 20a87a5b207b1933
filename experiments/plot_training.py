"""Plot the held-out evaluation curve of one or more training runs against the tuned heuristics.

    python experiments/plot_training.py runs/ppo runs/ppo_more --out docs/training_curve.png

Reads each run's ``evaluations.json`` (written by the evaluation callback of
:func:`trackenv_agents.learning.tamping.train`) and draws mean return against env steps; the tuned heuristics of
``agents/rules/tuned_heuristics.json`` are scored on the same evaluation seeds and drawn as horizontal lines, so
the curve reads as "how far from the best rule".
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from trackenv.envs import scenario
from trackenv_agents.evaluation.harness import evaluate_many
from trackenv_agents.learning.tamping import DEFAULT_EVAL_SEEDS
from trackenv_agents.rules import tuned_rule


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", nargs="+", help="training output folders, in training order")
    parser.add_argument("--labels", nargs="*", default=None, help="legend label per run (default: folder names)")
    parser.add_argument("--out", default="results/training_curve.png")
    parser.add_argument("--references", nargs="*", default=["uniform-periodic", "grouped-threshold", "no-maintenance"],
                        help="tuned heuristics drawn as lines")
    args = parser.parse_args(argv)
    labels = args.labels or [f"PPO {Path(run).name}" for run in args.runs]
    if len(labels) != len(args.runs):
        parser.error(f"--labels needs one label per run ({len(args.runs)}), got {len(labels)}")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    config = scenario("track60")
    policies = [tuned_rule(config, name) for name in args.references]
    refs = evaluate_many(policies, config, DEFAULT_EVAL_SEEDS, batch_size=len(DEFAULT_EVAL_SEEDS) * len(policies))
    fig, ax = plt.subplots(figsize=(7, 4))
    curves = {}
    for run, label in zip(args.runs, labels, strict=True):
        history = json.loads((Path(run) / "evaluations.json").read_text())
        steps = [h["timesteps"] for h in history]
        returns = [h["mean_return"] for h in history]
        curves[run] = list(zip(steps, returns, strict=True))
        ax.plot(steps, returns, "o-", label=label)
    for ref, style in zip(refs, ("--", "-.", ":", (0, (1, 3))), strict=False):
        ax.axhline(-ref.cost.mean(), color="k", ls=style, lw=1, label=f"{ref.policy} (tuned)")
    ax.set_xlabel("env steps")
    ax.set_ylabel(f"mean return on {len(DEFAULT_EVAL_SEEDS)} evaluation seeds [k€]")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=110)
    out = {"curves": curves, "references": {r.policy: -float(r.cost.mean()) for r in refs}, "png": args.out}
    print(json.dumps(out, indent=1))
    return out


if __name__ == "__main__":
    main()
