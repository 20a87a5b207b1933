"""Reproduce the paper's section 4 (Fig. 10 and Fig. 11): settlement and contact force over 6 iterations.

    python experiments/reproduce_paper.py --out results/paper
    python experiments/reproduce_paper.py --iterations 3 --cycles 25000 --no-plots --json
    python experiments/reproduce_paper.py --interpolation cubic   # the smooth reading, for comparison

Writes paper.json and the two figures under --out and prints a short summary (or the summary as JSON).
"""

from __future__ import annotations

import argparse
import json

from trackenv_studies.paper import PAPER_ELEMENTS_PER_BAY, format_summary, reproduce_paper


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="results/paper", help="output folder (paper.json, PNG figures)")
    parser.add_argument("--iterations", type=int, default=6, help="iterations per scenario (default 6)")
    parser.add_argument("--cycles", type=float, default=50_000,
                        help="load cycles (axle passes) per iteration (default 50000)")
    parser.add_argument("--interpolation", choices=("linear", "cubic"), default="linear",
                        help="settlement between sleepers: linear, the paper's reading (default), or cubic spline")
    parser.add_argument("--elements-per-bay", type=int, default=None,
                        help="rail elements per sleeper bay (default: 8 for linear, 2 for cubic: converged)")
    parser.add_argument("--no-plots", action="store_true", help="skip the PNG figures")
    parser.add_argument("--json", action="store_true", help="print the summary as JSON instead of text")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    try:
        epb = args.elements_per_bay or (PAPER_ELEMENTS_PER_BAY if args.interpolation == "linear" else 2)
        summary = reproduce_paper(args.out, iterations=args.iterations, cycles_per_iteration=args.cycles,
                                  make_plots=not args.no_plots, progress=not args.no_progress,
                                  interpolation=args.interpolation, elements_per_bay=epb)
    except ValueError as exc:
        parser.error(str(exc))
    print(json.dumps(summary, indent=2) if args.json else format_summary(summary))
    return summary


if __name__ == "__main__":
    main()
