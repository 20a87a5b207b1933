"""Validate the track model against closed forms and the paper's figures; print the summary as JSON.

python experiments/validate_track.py --out results/validation
"""

from __future__ import annotations

import argparse
import json

from trackenv_studies.validation import run_validation


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="results/validation", help="output folder (summary.json, PNG plots)")
    parser.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    args = parser.parse_args(argv)
    summary = run_validation(args.out, make_plots=not args.no_plots)
    print(json.dumps(summary, indent=2))


if __name__ == "__main__":
    main()
