"""The leaderboard's baselines from the standard libraries: their learning curves, and their export to the
committed folder that ``trackenv leaderboard --policies baselines`` scores.

    python experiments/baselines.py curves maskable-ppo-ranked=runs/baseline_maskable \\
        rllib-ppo-ranked=runs/baseline_rllib rllib-shared-ppo=runs/baseline_shared
    python experiments/baselines.py export maskable-ppo-ranked=runs/baseline_maskable ...

``curves`` reads each run's record of return against env steps (a run of ``experiments/train_ppo.py``: its
held-out evaluations, ``evaluations.json``; a run of ``experiments/train_rllib.py``: the mean return of its
training episodes per iteration, ``rllib_summary.json``), draws them against the best tuned rule's return on the
same evaluation seeds, and writes ``experiments/saved/baselines/training_curves.json`` and
``docs/baselines_training.png``. ``export`` copies each run's final policy to
``experiments/saved/baselines/NAME`` (``NAME.zip`` and its observation statistics; an RLlib run's summary and
RLModule only, not its optimiser and runner state).
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


def curve(run: Path) -> dict[str, Any]:
    """A run's return against env steps (line-steps): its held-out evaluations (SB3) or its training episodes'
    mean return per iteration (RLlib), with the wall time of its training."""
    if (run / RLLIB_SUMMARY).is_file():
        summary = json.loads((run / RLLIB_SUMMARY).read_text())
        hist = [h for h in summary["history"] if h["episode_return_mean"] is not None]
        return {"source": "training episodes (RLlib)", "env_config": summary["env_config"],
                "env_steps": [h["env_steps"] for h in hist], "mean_return": [h["episode_return_mean"] for h in hist],
                "iterations": len(summary["history"]),
                "train_seconds": sum(h["seconds"] for h in summary["history"])}
    summary = json.loads((run / "summary.json").read_text())
    meta = json.loads((run / "train_meta.json").read_text())
    evals = summary["evaluations"]
    return {"source": f"held-out evaluation, seeds {meta['eval_seeds'][0]}-{meta['eval_seeds'][-1]}",
            "hyperparams": meta["hyperparams"], "env_steps": [e["timesteps"] for e in evals],
            "mean_return": [e["mean_return"] for e in evals], "timesteps": summary["timesteps"],
            "train_seconds": summary["wall_seconds"], "eval_seeds": meta["eval_seeds"]}


def cmd_curves(runs: dict[str, Path], out_json: Path, out_png: Path, scenario_name: str) -> dict[str, Any]:
    from matplotlib.figure import Figure

    from trackenv.envs.line_config import scenario
    from trackenv_agents.evaluation.harness import evaluate_one
    from trackenv_agents.rules import LINE_HEURISTICS, tuned_params_for

    curves = {name: curve(run) for name, run in runs.items()}
    seeds = next((c["eval_seeds"] for c in curves.values() if "eval_seeds" in c), list(range(10_000, 10_008)))
    config = scenario(scenario_name)
    rule = "grouped-threshold"
    ref = evaluate_one(LINE_HEURISTICS[rule](**tuned_params_for(config).get(rule, {})), config, seeds)
    payload = {"scenario": scenario_name, "curves": curves,
               "reference": {"policy": rule, "seeds": seeds, "mean_return": -float(ref.cost.mean())}}
    fig = Figure(figsize=(7, 4))
    ax = fig.add_subplot()
    for name, c in curves.items():
        ax.plot(c["env_steps"], c["mean_return"], "o-", label=f"{name} ({c['source']})")
    ax.axhline(payload["reference"]["mean_return"], color="k", ls="--", lw=1,
               label=f"{rule} (tuned rule), evaluation seeds")
    ax.set_xlabel("line-steps (env steps of the line)")
    ax.set_ylabel("mean return per episode [k€]")
    ax.set_yscale("symlog", linthresh=1000)
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
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)
    c = sub.add_parser("curves", help="learning curves (JSON and PNG)")
    c.add_argument("runs", nargs="+", metavar="NAME=FOLDER")
    c.add_argument("--scenario", default="default", help="the line the runs trained on (for the reference rule)")
    c.add_argument("--out-json", default=str(SAVED_BASELINES / "training_curves.json"))
    c.add_argument("--out-png", default=str(ROOT / "docs" / "baselines_training.png"))
    e = sub.add_parser("export", help="copy each run's final policy to the committed baselines")
    e.add_argument("runs", nargs="+", metavar="NAME=FOLDER")
    e.add_argument("--dest", default=str(SAVED_BASELINES))
    a = p.parse_args(argv)
    runs = _runs(a.runs)
    if a.command == "curves":
        out = cmd_curves(runs, Path(a.out_json), Path(a.out_png), a.scenario)
        print(json.dumps({k: {"env_steps": v["env_steps"][-1:], "mean_return": v["mean_return"][-1:]}
                          for k, v in out["curves"].items()}))
        return out
    written = cmd_export(runs, Path(a.dest))
    print("\n".join(map(str, written)))
    return written


if __name__ == "__main__":
    main()
