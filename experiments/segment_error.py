"""How well a segment of standing track represents its 200 m section: SD growth of segments of L m against full
200 m sections, same episodes, no tamping.

The section-level draws of an episode (rate factor along the line, register) come first from the seed's
generator and are therefore the same for every segment length; the per-sleeper fields (stiffness, rate,
initial level) are drawn for the modelled length. We compare the SD growth (least-squares slope of the true
SD over the run, mm/year) section by section and on average. Writes results/segment_error.json.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from trackenv.envs.line_config import scenario
from trackenv_studies.calibration import _slopes, run_line


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[3000, 3001])
    ap.add_argument("--lengths", type=float, nargs="+", default=[30.0, 60.0])
    ap.add_argument("--years", type=float, default=4.0)
    ap.add_argument("--out", default="results/segment_error.json")
    args = ap.parse_args(argv)
    base = {"horizon_years": args.years, "wet_spot_probability": 0.0}
    out = {"seeds": args.seeds, "years": args.years, "lengths": {}}
    t0 = time.time()
    ref_cfg = scenario("small", segment_length_m=200.0, **base)
    ref = run_line(ref_cfg, args.seeds)
    years = np.arange(ref_cfg.horizon_steps + 1) / ref_cfg.steps_per_year
    g_ref = _slopes(ref["sd"] * 1e3, years)
    print(f"200 m sections: mean SD growth {g_ref.mean():.3f} mm/yr ({time.time() - t0:.0f}s)", flush=True)
    for L in args.lengths:
        cfg = scenario("small", segment_length_m=L, **base)
        res = run_line(cfg, args.seeds)
        g = _slopes(res["sd"] * 1e3, years)
        assert np.array_equal(res["register"], ref["register"])
        rel_mean = float((g.mean() - g_ref.mean()) / g_ref.mean())
        plain = res["register"] == 0
        rel_plain = float((g[plain].mean() - g_ref[plain].mean()) / g_ref[plain].mean()) if plain.any() else None
        out["lengths"][str(L)] = {"mean_growth_mm_per_year": float(g.mean()), "relative_error_of_mean": rel_mean,
                                  "relative_error_plain": rel_plain,
                                  "per_section_ratio_median": float(np.median(g / g_ref)),
                                  "growth": g.tolist()}
        print(f"{L:.0f} m segments: mean {g.mean():.3f} mm/yr, error of the mean {100 * rel_mean:+.1f} %, "
              f"plain {100 * (rel_plain or 0):+.1f} %, per-section median ratio {np.median(g / g_ref):.2f} "
              f"({time.time() - t0:.0f}s)", flush=True)
    out["reference_growth"] = g_ref.tolist()
    out["register"] = ref["register"].tolist()
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=1))
    return out


if __name__ == "__main__":
    main()
