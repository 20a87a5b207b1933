"""Compare tamping policies: tune the heuristics on training seeds, score them on held-out test seeds.

    python experiments/compare_policies.py --quick             # ~1 min smoke run
    python experiments/compare_policies.py --n-test 32 --n-train 16
    python experiments/compare_policies.py --json

Writes comparison.json, costs.png and episode.png to --out and prints the table (or the JSON with --json).
"""

from __future__ import annotations

import argparse
import json

from trackenv_agents.evaluation.tamping_compare import run_comparison


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results/compare", help="output folder")
    parser.add_argument("--quick", action="store_true", help="tiny track, short horizon, few seeds")
    parser.add_argument("--n-test", type=int, default=None, help="held-out test seeds (default 200; quick 6)")
    parser.add_argument("--n-train", type=int, default=None, help="tuning seeds (default 100; quick 2)")
    parser.add_argument("--batch-size", type=int, default=32, help="envs stepped together")
    parser.add_argument("--json", action="store_true", help="print the JSON instead of the table")
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")
    args = parser.parse_args(argv)
    out = run_comparison(out_dir=args.out, n_test=args.n_test, n_train=args.n_train, quick=args.quick,
                         progress=not args.no_progress, batch_size=args.batch_size)
    if args.json:
        print(json.dumps({k: v for k, v in out.items() if k != "table"}, indent=2, default=str))
    else:
        print(out["table"])
        print(f"\n{len(out['test_seeds'])} test / {len(out['train_seeds'])} training episodes, "
              f"wall time {out['wall_time_s']:.0f} s; files in {args.out}")
    return out


if __name__ == "__main__":
    main()
