"""The ``trackenv`` command: validate, paper, bench, evaluate, train, calibrate.

Each subcommand prints a human summary, or exactly one JSON object on stdout with ``--json`` (progress bars go
to stderr). Results (JSON and PNG) are written under ``results/`` unless ``--out`` says otherwise.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any

from trackenv._json import json_default

DEFAULT_N_TEST = 24  # held-out episodes `trackenv evaluate` scores by default (a few minutes on 2 cores)


def _emit(args: argparse.Namespace, payload: dict[str, Any], human: str) -> None:
    if args.json:
        print(json.dumps(payload, default=json_default))
    else:
        print(human)


def cmd_validate(args: argparse.Namespace) -> int:
    from trackenv.validation import run_validation

    summary = run_validation(out_dir=args.out or "results/validation", make_plots=not args.no_plots)
    lines = ["trackenv validate — track model against closed forms and the paper"]
    lines += [f"  {k}: {v}" for k, v in summary.items() if not isinstance(v, (list, dict))]
    for k, v in summary.items():
        if isinstance(v, dict):
            lines.append(f"  {k}:")
            lines += [f"    {kk}: {vv}" for kk, vv in v.items() if not isinstance(vv, (list, dict))]
    _emit(args, summary, "\n".join(lines))
    return 0


def cmd_paper(args: argparse.Namespace) -> int:
    from trackenv.paper import format_summary, reproduce_paper

    summary = reproduce_paper(
        out_dir=args.out or "results/paper",
        iterations=args.iterations,
        cycles_per_iteration=args.cycles,
        make_plots=not args.no_plots,
        progress=not args.json,
    )
    _emit(args, summary, format_summary(summary))
    return 0


def cmd_bench(args: argparse.Namespace) -> int:
    from tqdm.auto import tqdm

    from trackenv.bench import STAGES, format_benchmarks, run_benchmarks

    with tqdm(total=len(STAGES), desc="bench", unit="benchmark", leave=False) as bar:

        def step(name: str) -> None:
            if bar.n or name != STAGES[0]:
                bar.update(1)
            bar.set_postfix_str(name)

        result = run_benchmarks(quick=args.quick, progress=step)
        bar.update(bar.total - bar.n)
    _emit(args, result, format_benchmarks(result))
    return 0


def cmd_evaluate_line(args: argparse.Namespace) -> int:
    from .line_compare import format_line_table, line_comparison, parse_seeds

    t0 = time.perf_counter()
    seeds = parse_seeds(args.seeds) if args.seeds else None
    result = line_comparison(args.env, seeds=seeds, n_train=args.n_train or 2, retune=args.retune,
                             progress=not args.json, out_dir=args.out or "results/line_compare")
    result["wall_time_s"] = time.perf_counter() - t0
    _emit(args, result, format_line_table(result))
    return 0


def cmd_calibrate(args: argparse.Namespace) -> int:
    from trackenv.line_calibration import format_calibration

    from .line_compare import parse_seeds, run_calibration

    overrides = {"horizon_years": args.horizon_years} if args.horizon_years else {}
    result = run_calibration(args.scenario, parse_seeds(args.seeds), args.threshold,
                             out_dir=args.out or "results/line_calibration", progress=not args.json, **overrides)
    result.pop("trajectories", None)
    _emit(args, result, format_calibration(result) + f"\nplot: {result['plot']}")
    return 0


def cmd_evaluate(args: argparse.Namespace) -> int:
    if args.env is not None and args.env != "trackenv/Tamping-v0":
        return cmd_evaluate_line(args)
    from .compare import run_comparison

    extra = {}
    if args.quick and args.policy == "ppo":
        raise SystemExit("trackenv evaluate: --quick uses a small track; the trained policy needs the default one")
    if args.policy in ("ppo", "all") and not args.quick:  # the shipped policy knows the default track only
        try:
            from .train import load_trained

            extra["ppo"] = load_trained(args.model)
        except Exception as exc:  # a missing or broken model must not hide the heuristics' results
            if args.policy == "ppo":
                raise SystemExit(f"trackenv evaluate: cannot load the trained policy: {exc}") from exc
            print(f"warning: trained policy unavailable ({exc}); scoring heuristics only", file=sys.stderr)
    from .heuristics import TUNED_PARAMS_FILE as shipped

    tuned = None
    if not (args.retune or args.quick) and shipped.exists():
        tuned = shipped  # parameters tuned by `trackenv evaluate --retune` on the training seeds
    n_test = args.n_test if args.n_test is not None else (None if args.quick else DEFAULT_N_TEST)
    t0 = time.perf_counter()
    result = run_comparison(
        out_dir=args.out or "results/compare",
        n_test=n_test,
        n_train=args.n_train,
        quick=args.quick,
        progress=not args.json,
        extra_policies=extra,
        tuned=tuned,
    )
    result["tuned_from"] = str(tuned) if tuned else "tuned now on the training seeds"
    result["wall_time_s"] = time.perf_counter() - t0
    from .evaluation import format_table

    _emit(args, result, format_table(result["results"]))
    return 0


def cmd_train(args: argparse.Namespace) -> int:
    from .train import train

    t0 = time.perf_counter()
    path = train(
        algo=args.algo,
        total_timesteps=args.timesteps,
        n_envs=args.n_envs,
        seed=args.seed,
        out_dir=args.out or "runs/ppo",
        progress=not args.json,
        resume=args.resume,
        hyperparams=args.hyperparams,
    )
    wall = time.perf_counter() - t0
    payload = {"model": str(path), "wall_time_s": wall}
    _emit(args, payload, f"trained {args.algo} -> {path} in {wall:.0f} s")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="trackenv", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)

    def common(sp: argparse.ArgumentParser) -> None:
        sp.add_argument("--json", action="store_true", help="print one JSON object instead of a summary")
        sp.add_argument("--out", default=None, help="output folder for JSON and PNG")

    sp = sub.add_parser("validate", help="static, receptance and moving-wheelset checks with plots")
    common(sp)
    sp.add_argument("--no-plots", action="store_true")
    sp.set_defaults(func=cmd_validate)

    sp = sub.add_parser("paper", help="reproduce the paper's settlement scenarios (Fig. 10 and 11)")
    common(sp)
    sp.add_argument("--iterations", type=int, default=6)
    sp.add_argument("--cycles", type=float, default=50_000)
    sp.add_argument("--no-plots", action="store_true")
    sp.set_defaults(func=cmd_paper)

    sp = sub.add_parser("bench", help="speed of the dynamics, the loop and the env")
    common(sp)
    sp.add_argument("--quick", action="store_true")
    sp.set_defaults(func=cmd_bench)

    sp = sub.add_parser("evaluate", help="score the trained policy and the tuned heuristics on held-out seeds")
    common(sp)
    sp.add_argument("--policy", choices=("all", "ppo", "heuristics"), default="all")
    sp.add_argument("--model", default=None, help="path of a trained model (default: the shipped one)")
    sp.add_argument("--n-test", type=int, default=None, help="held-out episodes (default 24 of the 200 test seeds)")
    sp.add_argument("--n-train", type=int, default=None, help="episodes for tuning the heuristics")
    sp.add_argument("--quick", action="store_true", help="a small, fast configuration (about a minute)")
    sp.add_argument(
        "--retune", action="store_true", help="tune the heuristics again instead of using the shipped parameters"
    )
    sp.add_argument("--env", default=None,
                    help="a TampingLine id (trackenv/TampingLine-v0, ...Small-v0, ...Hard-v0): score the line rules")
    sp.add_argument("--seeds", default=None, help="held-out episodes of the line: A:B (seeds A..B-1) or a,b,c")
    sp.set_defaults(func=cmd_evaluate)

    sp = sub.add_parser("calibrate", help="TampingLine without tamping and under a threshold rule vs published ranges")
    common(sp)
    sp.add_argument("--scenario", default="default", choices=("small", "default", "hard"))
    sp.add_argument("--seeds", default="2000:2002", help="episodes: A:B or a,b,c")
    sp.add_argument("--threshold", type=float, default=2.0, help="SD [mm] at which the rule tamps a section")
    sp.add_argument("--horizon-years", type=float, default=None)
    sp.set_defaults(func=cmd_calibrate)

    sp = sub.add_parser("train", help="train a PPO agent (stable-baselines3)")
    common(sp)
    sp.add_argument("--algo", choices=("ppo", "maskable_ppo"), default="ppo")
    sp.add_argument("--timesteps", type=int, default=None)
    sp.add_argument("--n-envs", type=int, default=8)
    # = trackenv_agents.train.DEFAULT_TRAIN_SEED, written out: importing it here would load torch for every command
    sp.add_argument("--seed", type=int, default=20_000,
                    help="env i starts with seed + i (default: apart from the test, tuning and evaluation seeds)")
    sp.add_argument("--resume", default=None, help="output folder of an earlier run to continue for --timesteps")
    sp.add_argument("--hyperparams", default=None, help="JSON file overriding agents/ppo_config.json key by key")
    sp.set_defaults(func=cmd_train)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except ValueError as exc:
        print(f"trackenv {args.command}: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
