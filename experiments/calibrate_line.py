"""Calibration of the default TampingLine against published ranges (the logic of ``trackenv calibrate``):
no tamping and a threshold rule on a few episodes; writes docs/line_calibration.png and
results/line_calibration/line_calibration.json and prints the table."""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

from trackenv_agents.evaluation.line_compare import parse_seeds, run_calibration
from trackenv_studies.calibration import format_calibration


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenario", default="default")
    ap.add_argument("--seeds", default="2000:2004")
    ap.add_argument("--threshold", type=float, default=2.0)
    ap.add_argument("--out", default="results/line_calibration")
    ap.add_argument("--docs", default="docs/line_calibration.png", help="copy of the plot for the documentation")
    args = ap.parse_args(argv)
    res = run_calibration(args.scenario, parse_seeds(args.seeds), args.threshold, out_dir=args.out)
    print(format_calibration(res))
    if args.docs:
        Path(args.docs).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(res["plot"], args.docs)
    return res


if __name__ == "__main__":
    main()
