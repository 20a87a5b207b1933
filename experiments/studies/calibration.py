"""Calibration of TampingLine against published figures: what the default line does without tamping and under
a threshold rule, side by side with the ranges of the literature (``trackenv calibrate``).

Figures (each from the env's *true* state, ``info``):

* plain-track SD growth per year: per plain section (register 0, no wet spot), the least-squares slope of its
  SD over the untamped run; median and 10-90 % spread between sections, also per 100 MGT;
* transition zone / plain and switch-or-crossing / plain: ratio of the median SD growth of each class to the
  plain median;
* SD after against SD before tamping: the least-squares line SD_after = α + β·SD_before (Audley & Andrews'
  form) over the threshold rule's tampings, true SD just before and just after tamping;
* years between tampings per class under the threshold rule: section-years / tampings.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode

from trackenv.envs.line import TampingLineVectorEnv
from trackenv.envs.line_config import LineConfig
from trackenv.physics._checks import check_scalar

#: Published ranges the figures are compared with (low, high, source); [unverified] where the figure could not be
#: traced to its primary source (the documentation's line-problem page lists them).
PUBLISHED = {
    "plain_growth_mm_per_100mgt": (0.5, 1.5, "SD growth of plain track, of the order of 0.5-1.5 mm per 100 MGT "
                                              "[unverified]; lognormal between sections (Andrade & Teixeira 2011)"),
    "transition_ratio": (4.0, 8.0, "transition zones need 4-8x the maintenance of open track "
                                   "(Wang & Markine 2018, doi 10.1177/0954409717748789)"),
    "switch_ratio": (3.0, 7.0, "switches and crossings ~5x the maintenance per length (GB: 24 % of the budget "
                               "on 5 % of track miles) [unverified]; range ours"),
    "tamping_beta": (0.2, 0.5, "SD_after = α + β·SD_before with β < 1 (Audley & Andrews 2013 form); ballast "
                               "memory keeps 0.2-0.5 of the shape (RTRI) [assumption]"),
    "plain_years_between": (3.0, 10.0, "plain-track tamping cycles of several years on main lines "
                                       "[unverified]; 8-10 tampings per ballast life of ~30-40 years"),
}


def run_line(config: LineConfig, seeds: Sequence[int], threshold_mm: float | None = None,
             progress: Any = None) -> dict[str, np.ndarray]:
    """Run ``len(seeds)`` episodes of ``config`` in one vector env, no tamping (``threshold_mm`` None) or
    tamping every section whose *measured* SD reaches ``threshold_mm`` (worst first within the capacity).
    Returns per step (H+1, lines, S) true SD [m], tamped flags, register (lines, S) and wet-spot flags."""
    env = TampingLineVectorEnv(len(seeds), config, autoreset_mode=AutoresetMode.NEXT_STEP)  # last info in place
    obs, info = env.reset(seed=list(seeds))
    reg = obs["register"].astype(int)
    sd = [info["section_sd_m"]]
    tamped, wet, after = [], [], []
    for _ in range(config.horizon_steps):
        if threshold_mm is None:
            a = np.zeros((len(seeds), config.n_sections), dtype=np.int8)
        else:
            a = (obs["section_sd"] >= threshold_mm).astype(np.int8)
        obs, _, _, _, info = env.step(a)
        sd.append(info["section_sd_m"])
        tamped.append(info["tamped_sections"])
        wet.append(info["wet_spot_active"])
        after.append(info["section_sd_after_tamping_m"])
        if progress is not None:
            progress(1)
    return {"sd": np.array(sd), "tamped": np.array(tamped), "register": reg, "wet": np.array(wet),
            "sd_after_tamping": np.array(after)}


def _slopes(sd: np.ndarray, years: np.ndarray) -> np.ndarray:
    t = years - years.mean()
    return np.tensordot(t, sd - sd.mean(axis=0), axes=(0, 0)) / float(t @ t)


def calibrate(config: LineConfig | None = None, seeds: Sequence[int] = (2000, 2001, 2002),
              threshold_mm: float = 2.0, progress: Any = None) -> dict[str, Any]:
    """The calibration table: emergent figures vs :data:`PUBLISHED` (see the module docstring)."""
    cfg = LineConfig.coerce(config)
    threshold_mm = check_scalar("threshold_mm", threshold_mm, low=0.0, low_inclusive=False)
    free = run_line(cfg, seeds, None, progress)
    rule = run_line(cfg, seeds, threshold_mm, progress)
    years = np.arange(cfg.horizon_steps + 1) / cfg.steps_per_year
    slope = _slopes(free["sd"] * 1e3, years)  # (lines, S) mm/year
    ever_wet = free["wet"].any(axis=0)
    reg = free["register"]
    plain = slope[(reg == 0) & ~ever_wet]
    med = float(np.median(plain))
    per_100mgt = med / cfg.annual_mgt * 100.0
    zone = {k: slope[(reg == k) & ~ever_wet] for k in (1, 2)}
    ratio = {k: float(np.median(v) / med) if v.size else float("nan") for k, v in zone.items()}
    # tamping effect: true SD just before and just after the tamping
    t_idx, line, sec = np.nonzero(rule["tamped"])
    before = rule["sd"][t_idx, line, sec] * 1e3
    after = rule["sd_after_tamping"][t_idx, line, sec] * 1e3
    if before.size >= 2 and np.ptp(before) > 0:
        beta, alpha = np.polyfit(before, after, 1)
    else:
        beta = alpha = float("nan")
    section_years = cfg.horizon_years * len(seeds)
    counts = rule["tamped"].sum(axis=0)  # (lines, S)
    between = {}
    for k, name in ((0, "plain"), (1, "transition"), (2, "switch_or_crossing")):
        m = rule["register"] == k
        n_t = counts[m].sum()
        between[name] = float(section_years * m.sum() / len(seeds) / n_t) if n_t else float("inf")
    figures = {
        "plain_growth_mm_per_year_median": med,
        "plain_growth_mm_per_year_p10_p90": [float(np.quantile(plain, 0.1)), float(np.quantile(plain, 0.9))],
        "plain_growth_mm_per_100mgt": per_100mgt,
        "transition_ratio": ratio[1],
        "switch_ratio": ratio[2],
        "tamping_alpha_mm": float(alpha),
        "tamping_beta": float(beta),
        "tamping_sd_before_mean_mm": float(before.mean()) if before.size else float("nan"),
        "tamping_sd_after_mean_mm": float(after.mean()) if after.size else float("nan"),
        "years_between_tampings": between,
        "plain_years_between": between["plain"],
    }
    table = []
    for key, (lo, hi, src) in PUBLISHED.items():
        v = float(figures[key])  # type: ignore[arg-type]
        table.append({"figure": key, "value": v, "low": lo, "high": hi, "inside": bool(lo <= v <= hi),
                      "source": src})
    return {"config": cfg.to_dict(), "seeds": list(seeds), "threshold_mm": threshold_mm, "figures": figures,
            "table": table, "n_plain_sections": int(plain.size),
            "n_zone_sections": {k: int(v.size) for k, v in zone.items()},
            "trajectories": {"years": years.tolist(), "free_sd_mm": (free["sd"] * 1e3).tolist(),
                             "rule_sd_mm": (rule["sd"] * 1e3).tolist(), "register": reg.tolist(),
                             "before_mm": before.tolist(), "after_mm": after.tolist()}}


def format_calibration(result: dict[str, Any]) -> str:
    rows = [f"{'figure':30s} {'value':>8s}  {'published':>12s}  inside  source"]
    for r in result["table"]:
        rows.append(f"{r['figure']:30s} {r['value']:8.2f}  {r['low']:5.2f}-{r['high']:<6.2f}  "
                    f"{'yes' if r['inside'] else 'NO':6s}  {r['source'][:70]}")
    f = result["figures"]
    rows.append(f"plain growth median {f['plain_growth_mm_per_year_median']:.3f} mm/yr, 10-90 % "
                f"{f['plain_growth_mm_per_year_p10_p90'][0]:.3f}-{f['plain_growth_mm_per_year_p10_p90'][1]:.3f}; "
                f"tamping: SD {f['tamping_sd_before_mean_mm']:.2f} -> {f['tamping_sd_after_mean_mm']:.2f} mm "
                f"(after = {f['tamping_alpha_mm']:.2f} + {f['tamping_beta']:.2f}·before); years between tampings "
                + ", ".join(f"{k} {v:.1f}" for k, v in f["years_between_tampings"].items()))
    return "\n".join(rows)


def plot_calibration(result: dict[str, Any], out_png: str) -> str:
    """SD of every section without tamping by class, and SD after vs before tamping (pyplot-free)."""
    from matplotlib.figure import Figure

    tr = result["trajectories"]
    years = np.array(tr["years"])
    sd = np.array(tr["free_sd_mm"])
    reg = np.array(tr["register"])
    fig = Figure(figsize=(10, 4))
    ax, bx = fig.subplots(1, 2)
    colours = {0: "tab:grey", 1: "tab:red", 2: "tab:blue"}
    names = {0: "plain", 1: "transition", 2: "switch/crossing"}
    seen = set()
    for b in range(reg.shape[0]):
        for j in range(reg.shape[1]):
            k = int(reg[b, j])
            ax.plot(years, sd[:, b, j], color=colours[k], lw=0.8, label=None if k in seen else names[k])
            seen.add(k)
    ax.set_xlabel("year")
    ax.set_ylabel("SD of D1 level [mm]")
    ax.set_title("no tamping")
    ax.legend()
    bx.scatter(tr["before_mm"], tr["after_mm"], s=10)
    lim = max(tr["before_mm"] + [1.0])
    bx.plot([0, lim], [0, lim], "k--", lw=0.8)
    bx.set_xlabel("SD before tamping [mm]")
    bx.set_ylabel("SD right after tamping [mm]")
    bx.set_title("threshold rule")
    fig.tight_layout()
    fig.savefig(out_png, dpi=110)
    return out_png
