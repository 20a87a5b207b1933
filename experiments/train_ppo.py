"""Train PPO / MaskablePPO on the tamping environment.

Example: ``python experiments/train_ppo.py --timesteps 8000 --n-envs 8 --out runs/ppo --export``;
continue a killed run from its last checkpoint: ``--resume runs/ppo`` (or a finished one to a new total:
``--resume runs/ppo --timesteps 16000``). ``--scenario`` trains on a line scenario instead of the 60 m track
(the ranked MaskablePPO baseline of the leaderboard:
``--scenario default --hyperparams experiments/baselines/maskable_ranked.json``).
"""

from __future__ import annotations

import argparse
import json
import time

from trackenv.envs.line_config import LineConfig
from trackenv_agents.evaluation.line_compare import parse_seeds
from trackenv_agents.learning.tamping import (
    DEFAULT_EVAL_SEEDS,
    DEFAULT_PRETRAINED,
    DEFAULT_TRAIN_SEED,
    export_policy,
    train,
)


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--algo", choices=["ppo", "maskable_ppo"], default=None,
                   help="default: agents/learning/hyperparams/ppo.yml")
    p.add_argument("--timesteps", type=int, default=None,
                   help="total env steps (default: agents/learning/hyperparams/ppo.yml)")
    p.add_argument("--n-envs", type=int, default=None)
    p.add_argument("--seed", type=int, default=None,
                   help=f"env i starts with seed + i (default {DEFAULT_TRAIN_SEED}: apart from the test, tuning and "
                        f"evaluation seeds)")
    p.add_argument("--out", default=None, help="default: runs/ppo (with --resume: the resumed folder)")
    p.add_argument("--config-json", default=None, help="JSON file of LineConfig fields (the 60 m preset's changed)")
    p.add_argument("--scenario", default=None, help="a line scenario (small, default, hard, ...) instead of the 60 m "
                                                    "track; --config-json then changes that scenario's fields")
    p.add_argument("--eval-seeds", default=None,
                   help=f"held-out evaluation seeds, A:B or a,b,c (default {DEFAULT_EVAL_SEEDS[0]}:"
                        f"{DEFAULT_EVAL_SEEDS[-1] + 1})")
    p.add_argument("--hyperparams", default=None,
                   help="YAML (RL Zoo form) or JSON overriding agents/learning/hyperparams/ppo.yml")
    p.add_argument("--eval-freq", type=int, default=None)
    p.add_argument("--checkpoint-every", type=float, default=None, help="seconds between checkpoints (0: none)")
    p.add_argument("--resume", default=None, help="folder of a run to continue in place from its last checkpoint")
    p.add_argument("--no-progress", action="store_true")
    p.add_argument("--export", action="store_true", help=f"copy the result to {DEFAULT_PRETRAINED}")
    a = p.parse_args(argv)
    config = None if a.scenario is None else LineConfig.coerce(a.scenario)
    if a.config_json:
        with open(a.config_json) as f:
            config = LineConfig.coerce(a.scenario or "track60").replace(**json.load(f))
    eval_seeds = DEFAULT_EVAL_SEEDS if a.eval_seeds is None else parse_seeds(a.eval_seeds)
    t0 = time.time()
    path = train(algo=a.algo, config=config, total_timesteps=a.timesteps, n_envs=a.n_envs, seed=a.seed,
                 out_dir=a.out, hyperparams=a.hyperparams, progress=not a.no_progress, eval_seeds=eval_seeds,
                 eval_freq=a.eval_freq, checkpoint_every_s=a.checkpoint_every, resume=a.resume)
    wall = time.time() - t0
    with open(path.parent / "summary.json") as f:
        summary = json.load(f)
    print(f"saved {path}; {summary['timesteps_this_run']} steps ({summary['timesteps']} in all) in "
          f"{summary['wall_seconds']:.0f} s of learning ({summary['steps_per_second']:.1f} steps/s; "
          f"{wall:.0f} s wall in all)")
    if a.export:
        print(f"exported to {export_policy(path)}")


if __name__ == "__main__":
    main()
