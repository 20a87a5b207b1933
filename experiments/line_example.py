"""Make the example line that ships with trackenv (``trackenv/lines/example*``) and measure how well the history
fit recovers the rates the engine generated its history with.

    python experiments/line_example.py            # write the files, fit them, the recovery study (~2 min)
    python experiments/line_example.py --check    # only fit the shipped files and compare with the truth

Writes ``results/line_example.json`` (the figures quoted on the documentation's page "Lines from files").
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from trackenv.envs.line_config import LineConfig
from trackenv.envs.line_fit import _simulated_growth, history_fit
from trackenv_studies.line_files import example_line, fit_recovery, write_line

ROOT = Path(__file__).resolve().parents[1]
LINES = ROOT / "trackenv" / "lines"
HEADER = """The example line that ships with trackenv: synthetic, made by trackenv's own engine
(python experiments/line_example.py). Schema: the documentation's page "Lines from files".
Units: speed km/h, traffic million gross tonnes (MGT) a year, freight share a fraction, axle load t."""


def recovery_on_line(line, truth: dict[str, float], rate_sigma: float = 0.5) -> dict:
    """The fit of ``line``'s history against the truth, over its fitted sections."""
    for cached in (history_fit, _simulated_growth):  # time the fit itself, not a cache
        cached.cache_clear()
    t0 = time.perf_counter()
    fit = history_fit(LineConfig(line=line))
    seconds = time.perf_counter() - t0
    fitted = fit.fitted
    true = np.array([truth[f.section] for f in fitted])
    med = np.array([f.rate_factor for f in fitted])
    lo, hi = np.array([f.rate_p10 for f in fitted]), np.array([f.rate_p90 for f in fitted])
    prior = -rate_sigma**2 / 2
    statuses: dict[str, int] = {}
    for f in fit.sections:
        statuses[f.status] = statuses.get(f.status, 0) + 1
    return {
        "sections": len(fit.sections), "statuses": statuses, "fit_seconds": seconds,
        "coverage_80": float(np.mean((lo <= true) & (true <= hi))),
        "correlation_log": float(np.corrcoef(np.log(true), np.log(med))[0, 1]),
        "rms_log_error": float(np.sqrt(np.mean(np.log(med / true) ** 2))),
        "rms_log_error_prior": float(np.sqrt(np.mean((prior - np.log(true)) ** 2))),
        "median_ratio": float(np.median(med / true)),
        "median_residual_mm": float(np.median([f.residual_mm for f in fitted])),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--check", action="store_true", help="fit the shipped files only (no rewrite, no study)")
    ap.add_argument("--out", default=str(ROOT / "results" / "line_example.json"))
    args = ap.parse_args()
    t0 = time.perf_counter()
    line, truth = example_line()
    print(f"example line made in {time.perf_counter() - t0:.1f} s", flush=True)
    out: dict = {}
    if not args.check:
        path = write_line(line, LINES, "example", header=HEADER)
        print(f"wrote {path} and its CSV files", flush=True)
    from trackenv.envs.line_file import load_line

    shipped = load_line(LINES / "example.yaml")
    if shipped != line:
        raise SystemExit("the shipped example differs from the one made now: run without --check to rewrite it")
    out["example"] = recovery_on_line(shipped, truth["effective_rate"])
    print("example line:", json.dumps(out["example"]), flush=True)
    if not args.check:
        for name, noise in (("plain_5y_noise_0.1mm", 0.1), ("plain_5y_noise_free", 0.0)):
            runs = [fit_recovery(n_sections=24, seeds=(seed,), years=5.0, truth_seed=seed, sd_noise_mm=noise)
                    for seed in (1, 2, 3, 4)]
            out[name] = {k: float(np.mean([r[k] for r in runs])) if not isinstance(runs[0][k], str) else runs[0][k]
                         for k in runs[0]}
            out[name]["sections"] = sum(r["sections"] for r in runs)
            print(name, json.dumps(out[name]), flush=True)
    out["seconds"] = time.perf_counter() - t0
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=1))
    print(f"wrote {args.out} ({out['seconds']:.0f} s)")


if __name__ == "__main__":
    main()
