"""Benchmark the physics: one pass (dt 1e-4 and auto), batched passes (all threads and one), a car, the paper loop,
the env and the native vector env.

    python experiments/benchmark.py                # full run, writes results/bench.json
    python experiments/benchmark.py --quick --json

Prints a table (or the JSON with --json) and writes the JSON to --out.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from trackenv_studies.bench import format_benchmarks, run_benchmarks


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats (a smoke test; rougher figures)")
    parser.add_argument("--json", action="store_true", help="print the JSON instead of the table")
    parser.add_argument("--out", default="results/bench.json",
                        help="where to write the JSON ('' for nowhere)")
    args = parser.parse_args(argv)
    result = run_benchmarks(quick=args.quick)
    if args.out:
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(result, indent=2))
    print(json.dumps(result, indent=2) if args.json else format_benchmarks(result))
    return result


if __name__ == "__main__":
    main()
