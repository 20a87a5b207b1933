"""Train the per-section policy on TampingLine (warm start by cloning the best tuned rule, then MaskablePPO).

Example: ``python experiments/train_line.py --timesteps 1280 --out runs/ppo_line`` (the default line; ~10
line-steps a second with 8 lines on 2 cores, plus ~2 minutes of cloning and ~1 minute per held-out
evaluation of 16 episodes); ``--scenario small`` for the small line; ``--export`` copies the result to
``agents/pretrained/ppo_tamping_line.zip``, which ``trackenv evaluate --env trackenv/TampingLine-v0`` then
scores next to the rules — export a policy only if it is at least as good as the rule on held-out episodes
(``summary.json``'s last ``vs_baseline``).
"""

from __future__ import annotations

import argparse
import json
import time

from trackenv_agents.train import DEFAULT_TRAIN_SEED
from trackenv_agents.train_line import DEFAULT_LINE_PRETRAINED, export_line_policy, train_line


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenario", choices=["small", "default", "hard"], default="default")
    p.add_argument("--horizon-years", type=float, default=None, help="shorter or longer episodes")
    p.add_argument("--algo", choices=["ppo", "maskable_ppo"], default=None, help="default: agents/hyperparams/ppo.yml")
    p.add_argument("--timesteps", type=int, default=None, help="line-steps of PPO (default: hyperparams/ppo.yml)")
    p.add_argument("--n-envs", type=int, default=None)
    p.add_argument("--seed", type=int, default=DEFAULT_TRAIN_SEED,
                   help="line i starts with seed + i (default: apart from the test, tuning and evaluation seeds)")
    p.add_argument("--eval-seeds", default="10000:10016", help="held-out episodes A:B, paired with the rule")
    p.add_argument("--eval-freq", type=int, default=None)
    p.add_argument("--checkpoint-every", type=int, default=None)
    p.add_argument("--hyperparams", default=None,
                   help="YAML (RL Zoo form) or JSON overriding the trackenv/TampingLine-v0 entry of ppo.yml")
    p.add_argument("--out", default="runs/ppo_line")
    p.add_argument("--no-progress", action="store_true")
    p.add_argument("--export", action="store_true", help=f"copy the result to {DEFAULT_LINE_PRETRAINED}")
    a = p.parse_args(argv)
    from trackenv.envs.line_config import scenario
    from trackenv_agents.line_compare import parse_seeds

    config = scenario(a.scenario, **({"horizon_years": a.horizon_years} if a.horizon_years else {}))
    t0 = time.time()
    path = train_line(config, algo=a.algo, total_timesteps=a.timesteps, n_envs=a.n_envs, seed=a.seed, out_dir=a.out,
                      hyperparams=a.hyperparams, progress=not a.no_progress, eval_seeds=parse_seeds(a.eval_seeds),
                      eval_freq=a.eval_freq, checkpoint_every=a.checkpoint_every)
    summary = json.loads((path.parent / "summary.json").read_text())
    print(f"saved {path}; {summary['timesteps']} line-steps in {summary['wall_seconds']:.0f} s of learning "
          f"({summary['steps_per_second']:.1f} line-steps/s of training); {time.time() - t0:.0f} s wall in all")
    if summary["evaluations"]:
        last = summary["evaluations"][-1]
        d = last.get("vs_baseline")
        vs = "" if d is None else (f"; vs {d['b']}: {d['mean_difference']:+.1f} k€ [{d['ci_low']:+.1f}, "
                                   f"{d['ci_high']:+.1f}] on {d['n_episodes']} paired episodes")
        print(f"held-out: mean cost {-last['mean_return']:.1f} k€{vs}")
    if a.export:
        print(f"exported to {export_line_policy(path)}")


if __name__ == "__main__":
    main()
