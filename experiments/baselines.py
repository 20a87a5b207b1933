"""The leaderboard's baselines from the standard libraries: their learning curves, and their export to the
committed folder that ``trackenv leaderboard --policies baselines`` scores.

    python experiments/baselines.py curves maskable-ppo-ranked=runs/baseline_maskable \\
        rllib-ppo-ranked=runs/baseline_rllib rllib-shared-ppo=runs/baseline_shared
    python experiments/baselines.py export maskable-ppo-ranked=runs/baseline_maskable ...

``curves`` reads each run's record of return against env steps (:func:`curve`: its training episodes, and the
held-out evaluations of a run of ``experiments/train_ppo.py``), draws them against the best tuned rule's return
on the evaluation seeds, and writes ``experiments/saved/baselines/training_curves.json`` and
``docs/baselines_training.png`` (with ``--keep-others`` the curves of the runs not named are kept from that JSON,
so one baseline can be retrained and redrawn without the others' run folders). ``export`` copies each run's
final policy to ``experiments/saved/baselines/NAME`` (``NAME.zip`` and its observation statistics; an RLlib
run's summary and RLModule only, not its optimiser and runner state).
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path
from typing import Any

from trackenv_agents.learning.baselines import RLLIB_SUMMARY, SAVED_BASELINES, rllib_module_dir
from trackenv_agents.learning.tamping import stats_path

ROOT = Path(__file__).resolve().parents[1]


def _runs(items: list[str]) -> dict[str, Path]:
    runs = {}
    for item in items:
        name, sep, path = item.partition("=")
        if not sep or not name or not Path(path).is_dir():
            raise SystemExit(f"each run must be NAME=FOLDER of a training run, got {item!r}")
        runs[name] = Path(path)
    return runs


def _tensorboard_returns(run: Path) -> tuple[list[int], list[float]]:
    """The training episodes' mean return (stable-baselines3's ``rollout/ep_rew_mean``: the last 100 episodes,
    raw k€, VecMonitor sits under the normalisation) per roll-out, from the run's TensorBoard events."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    files = sorted(run.glob("*/events.out.tfevents.*"))
    if not files:
        return [], []
    events = EventAccumulator(str(files[-1]))
    events.Reload()
    rows = events.Scalars("rollout/ep_rew_mean")
    return [int(r.step) for r in rows], [float(r.value) for r in rows]


def curve(run: Path) -> dict[str, Any]:
    """A run's mean return per episode against env steps (line-steps) of its training episodes (the stochastic
    policy as it explores: RLlib's ``episode_return_mean`` per iteration, stable-baselines3's ``ep_rew_mean`` per
    roll-out) and, for a stable-baselines3 run, of its held-out evaluations (the deterministic policy, as the
    leaderboard plays it), with the wall time of its training."""
    if (run / RLLIB_SUMMARY).is_file():
        summary = json.loads((run / RLLIB_SUMMARY).read_text())
        hist = [h for h in summary["history"] if h["episode_return_mean"] is not None]
        return {"library": "RLlib", "env_config": summary["env_config"],
                "training": {"env_steps": [h["env_steps"] for h in hist],
                             "mean_return": [h["episode_return_mean"] for h in hist]},
                "iterations": len(summary["history"]),
                "train_seconds": sum(h["seconds"] for h in summary["history"])}
    summary = json.loads((run / "summary.json").read_text())
    meta = json.loads((run / "train_meta.json").read_text())
    evals = summary["evaluations"]
    steps, returns = _tensorboard_returns(run)
    return {"library": "stable-baselines3", "hyperparams": meta["hyperparams"],
            "training": {"env_steps": steps, "mean_return": returns},
            "evaluation": {"env_steps": [e["timesteps"] for e in evals],
                           "mean_return": [e["mean_return"] for e in evals], "seeds": meta["eval_seeds"]},
            "timesteps": summary["timesteps"], "train_seconds": summary["wall_seconds"]}


def cmd_curves(runs: dict[str, Path], out_json: Path, out_png: Path, scenario_name: str,
               keep_others: bool = False) -> dict[str, Any]:
    from matplotlib.figure import Figure

    from trackenv.envs.line_config import scenario
    from trackenv_agents.evaluation.harness import evaluate_one
    from trackenv_agents.rules import tuned_rule

    curves = {name: curve(run) for name, run in runs.items()}
    if keep_others and out_json.is_file():
        kept = json.loads(out_json.read_text())
        if kept.get("scenario") != scenario_name:
            raise SystemExit(f"--keep-others: {out_json} holds the curves of scenario {kept.get('scenario')!r}, "
                             f"not {scenario_name!r}")
        curves = {**kept["curves"], **curves}  # the file's order, the named runs' curves in place, new ones last
    seeds = next((c["evaluation"]["seeds"] for c in curves.values() if "evaluation" in c), list(range(10_000, 10_008)))
    config = scenario(scenario_name)
    rule = "grouped-threshold"
    ref = evaluate_one(tuned_rule(config, rule), config, seeds)
    payload = {"scenario": scenario_name, "curves": curves,
               "reference": {"policy": rule, "seeds": seeds, "mean_return": -float(ref.cost.mean())}}
    fig = Figure(figsize=(7.5, 6.0))
    train_ax, eval_ax = fig.subplots(2, 1, sharex=True, height_ratios=[2, 1])
    for k, (name, c) in enumerate(curves.items()):
        train_ax.plot(c["training"]["env_steps"], c["training"]["mean_return"], "o-", color=f"C{k}", label=name)
        if "evaluation" in c:
            eval_ax.plot(c["evaluation"]["env_steps"], c["evaluation"]["mean_return"], "s--", color=f"C{k}",
                         label=name)
    train_ax.set_title("training episodes (the stochastic policy; seeds from 20000)", fontsize=9)
    eval_ax.set_title(f"held-out evaluation (the deterministic policy; seeds {seeds[0]}-{seeds[-1]})", fontsize=9)
    eval_ax.axhline(payload["reference"]["mean_return"], color="k", ls="--", lw=1,
                    label=f"{rule} (tuned rule), same seeds")
    eval_ax.set_xlabel("line-steps (env steps of the line)")
    for ax in (train_ax, eval_ax):
        ax.set_ylabel("mean return [k€]")
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    out_png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out_png, dpi=110)
    out_json.parent.mkdir(parents=True, exist_ok=True)
    out_json.write_text(json.dumps(payload, indent=1) + "\n")
    return payload


def cmd_export(runs: dict[str, Path], dest: Path) -> list[Path]:
    dest.mkdir(parents=True, exist_ok=True)
    written = []
    for name, run in runs.items():
        if (run / RLLIB_SUMMARY).is_file():
            summary = json.loads((run / RLLIB_SUMMARY).read_text())
            module = rllib_module_dir(run, bool(summary["env_config"].get("multi_agent", False)))
            target = dest / name
            if target.exists():
                shutil.rmtree(target)
            shutil.copytree(module, rllib_module_dir(target, bool(summary["env_config"].get("multi_agent", False))))
            summary.pop("checkpoint", None)  # an absolute path of the training machine
            (target / RLLIB_SUMMARY).write_text(json.dumps(summary, indent=1) + "\n")
        else:
            target = dest / f"{name}.zip"
            shutil.copyfile(run / "model.zip", target)
            shutil.copyfile(stats_path(run / "model.zip"), stats_path(target))
        written.append(target)
    return written


def main(argv: list[str] | None = None) -> Any:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="command", required=True)
    c = sub.add_parser("curves", help="learning curves (JSON and PNG)")
    c.add_argument("runs", nargs="+", metavar="NAME=FOLDER")
    c.add_argument("--scenario", default="default", help="the line the runs trained on (for the reference rule)")
    c.add_argument("--out-json", default=str(SAVED_BASELINES / "training_curves.json"))
    c.add_argument("--out-png", default=str(ROOT / "docs" / "baselines_training.png"))
    c.add_argument("--keep-others", action="store_true",
                   help="keep the curves of runs not named from --out-json (retrain one baseline, redraw all)")
    e = sub.add_parser("export", help="copy each run's final policy to the committed baselines")
    e.add_argument("runs", nargs="+", metavar="NAME=FOLDER")
    e.add_argument("--dest", default=str(SAVED_BASELINES))
    a = p.parse_args(argv)
    runs = _runs(a.runs)
    if a.command == "curves":
        out = cmd_curves(runs, Path(a.out_json), Path(a.out_png), a.scenario, a.keep_others)
        print(json.dumps({k: {part: v[part]["mean_return"][-1:] for part in ("training", "evaluation") if part in v}
                          for k, v in out["curves"].items()}))
        return out
    written = cmd_export(runs, Path(a.dest))
    print("\n".join(map(str, written)))
    return written


if __name__ == "__main__":
    main()
