"""Train the per-section policy on TampingLine: counterfactual policy iteration from the best tuned rule (then
MaskablePPO for ``--timesteps`` line-steps, none by default).

Example: ``python experiments/train_line.py --out runs/ppo_line`` (the default line, the shipped
hyper-parameters: 6 iterations of 16 training episodes, each run and forked, a held-out evaluation of 16 episodes
after each; the documentation's agents page gives its wall time). ``--scenario small`` for the small line;
``--export`` copies
the best iteration (``best_model.zip``) to ``agents/learning/pretrained/ppo_tamping_line.zip``, which
``trackenv evaluate --env trackenv/TampingLine-v0`` then scores next to the rules.
``trackenv train --env trackenv/TampingLine-v0`` runs the same training.

The 60 m track (``trackenv/Tamping-v1``, six 10 m sections on one physics segment): ``--scenario track60`` (each
decision priced forks the whole line, :func:`~trackenv_agents.learning.line_counterfactual.line_forks`);
``--export`` then copies it to ``agents/learning/pretrained/cpi_track60.zip`` (``cpi-track60-agent``). The shipped
one has the model-predictive planner as advisor (``--advisor model-predictive``: its SD history, which the forks
carry on, is the agent's recurrent state); the documentation's agents page gives the command.
``--campaign`` prices whole campaigns there instead of single sections' choices
(:func:`~trackenv_agents.learning.line_campaigns.campaign_counterfactuals`).

The lines with every choice: ``--scenario wet --advisor choice-threshold`` trains the network's tamping with the
wet line's tuned choice rule as advisor (the agent answers in choice codes, the rule's other choices with its
tamping); ``--export`` then copies it to ``agents/learning/pretrained/cpi_choice_line.zip`` (``cpi-choice-agent``).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from trackenv_agents.learning.line import (
    DEFAULT_CHOICE_PRETRAINED,
    DEFAULT_LINE_PRETRAINED,
    export_line_policy,
    train_line,
)
from trackenv_agents.learning.tamping import DEFAULT_TRAIN_SEED
from trackenv_agents.shipped import TRACK60_PRETRAINED_FILE


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenario", choices=["small", "default", "hard", "choices", "wet", "defects", "track60"],
                   default="default", help="the line preset (track60: the 60 m track of trackenv/Tamping-v1)")
    p.add_argument("--advisor", default=None,
                   help="the advisor rule (default: ppo.yml's); a choice rule (choice-threshold) on the lines with "
                        "every choice; model-predictive (the planner) on the 60 m track")
    p.add_argument("--horizon-years", type=float, default=None, help="shorter or longer episodes")
    p.add_argument("--iterations", type=int, default=None, help="policy iterations (default: hyperparams/ppo.yml)")
    p.add_argument("--episodes", type=int, default=None, help="training episodes per iteration (default: ppo.yml)")
    p.add_argument("--timesteps", type=int, default=None,
                   help="line-steps of MaskablePPO afterwards (default: ppo.yml)")
    p.add_argument("--n-envs", type=int, default=None, help="lines in PPO's batch")
    p.add_argument("--seed", type=int, default=DEFAULT_TRAIN_SEED,
                   help="first training episode (default: apart from the test, tuning and evaluation seeds)")
    p.add_argument("--eval-seeds", default="10000:10016", help="held-out episodes A:B, paired with the rule")
    p.add_argument("--hyperparams", default=None,
                   help="YAML (RL Zoo form) or JSON overriding the trackenv/TampingLine-v0 entry of ppo.yml")
    p.add_argument("--init", default=None, metavar="ZIP",
                   help="start the network from this saved line policy's weights (e.g. the shipped "
                        "agents/learning/pretrained/ppo_tamping_line.zip)")
    p.add_argument("--learn-choices", action="store_true",
                   help="the network also decides spot tamping and drainage (with a choice rule as advisor)")
    p.add_argument("--campaign", action="store_true",
                   help="price whole campaigns (track60: line_campaigns.campaign_counterfactuals) instead of "
                        "single sections' other choices")
    p.add_argument("--out", default="runs/ppo_line")
    p.add_argument("--no-progress", action="store_true")
    p.add_argument("--export", action="store_true",
                   help=f"copy the best iteration to {DEFAULT_LINE_PRETRAINED} ({DEFAULT_CHOICE_PRETRAINED} with a "
                        f"choice rule as advisor, {TRACK60_PRETRAINED_FILE} on track60)")
    a = p.parse_args(argv)
    from trackenv.envs.line_config import scenario
    from trackenv_agents.evaluation.line_compare import parse_seeds

    config = scenario(a.scenario, **({"horizon_years": a.horizon_years} if a.horizon_years else {}))
    t0 = time.time()
    hyperparams = a.hyperparams
    if a.advisor is not None or a.learn_choices or a.campaign:
        from trackenv_agents.learning.line import LINE_ENV_ID, LINE_ZOO
        from trackenv_agents.learning.tamping import load_hyperparams

        given = load_hyperparams(a.hyperparams, env_id=LINE_ENV_ID, schema=LINE_ZOO) if a.hyperparams else {}
        hyperparams = {**given, **({"advisor": a.advisor} if a.advisor is not None else {}),
                       **({"learn_choices": True} if a.learn_choices else {}),
                       **({"campaign_forks": True} if a.campaign else {})}
    path = train_line(config, total_timesteps=a.timesteps, n_envs=a.n_envs, seed=a.seed, out_dir=a.out,
                      hyperparams=hyperparams, progress=not a.no_progress, eval_seeds=parse_seeds(a.eval_seeds),
                      iterations=a.iterations, episodes_per_iteration=a.episodes, init_policy=a.init)
    summary = json.loads((path.parent / "summary.json").read_text())
    print(f"saved {path}; policy iteration {summary['policy_iteration_seconds']:.0f} s "
          f"({summary['line_steps_per_second']:.1f} line-steps/s of physics, forks included); "
          f"{time.time() - t0:.0f} s wall in all")
    for it in summary["iterations"]:
        ev = it.get("evaluation")
        if ev is not None:
            d = ev["vs_baseline"]
            print(f"iteration {it['iteration']}: held-out {ev['mean_cost']:.1f} k€, vs {d['b']} "
                  f"{d['mean_difference']:+.1f} k€ [{d['ci_low']:+.1f}, {d['ci_high']:+.1f}]")
    if a.export:
        best = Path(a.out) / "best_model.zip"
        from trackenv_agents.rules.choices import CHOICE_RULES

        choice = a.advisor in CHOICE_RULES
        dest = TRACK60_PRETRAINED_FILE if a.scenario == "track60" else (
            DEFAULT_CHOICE_PRETRAINED if choice else DEFAULT_LINE_PRETRAINED)
        model = best if best.exists() else path
        print(f"exported {model} to {export_line_policy(model, dest)}")


if __name__ == "__main__":
    main()
