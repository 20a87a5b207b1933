"""`trackenv evaluate --env trackenv/TampingLine-v0` and `trackenv calibrate`: the line's comparison and
calibration, written as JSON and PNG (the logic of the env and the calibration lives in the library)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from trackenv.envs.line_config import LineConfig, scenario

from .evaluation import _bound, evaluate_many, policy_name
from .line_heuristics import LINE_HEURISTICS, line_tuned_params
from .statistics import paired_difference
from .tuning import tune_many


def scenario_of(env_id: str) -> str:
    """The scenario name registered for a TampingLine id."""
    import gymnasium as gym

    import trackenv  # noqa: F401

    spec = gym.spec(env_id)
    if not spec.entry_point.endswith(":TampingLine"):
        raise ValueError(f"{env_id} is not a TampingLine id")
    return spec.kwargs["scenario"]


def parse_seeds(text: str) -> list[int]:
    """'A:B' -> A..B-1; 'a,b,c' -> those."""
    if ":" in text:
        a, b = (int(v) for v in text.split(":"))
        if b <= a:
            raise ValueError(f"--seeds A:B needs B > A, got {text!r}")
        return list(range(a, b))
    return [int(v) for v in text.split(",") if v]


def line_comparison(env_id: str = "trackenv/TampingLine-v0", seeds: list[int] | None = None,
                    n_train: int = 2, retune: bool = False, batch_size: int = 24, progress: bool = True,
                    out_dir: str = "results/line_compare", extra: dict[str, Any] | None = None,
                    executor: Any = None, **overrides: Any) -> dict[str, Any]:
    """Tuned line heuristics (shipped parameters, or tuned now on ``n_train`` training seeds 1000+) and the
    ``extra`` policies (by name, e.g. the trained line policy) scored on ``seeds`` with 95 % CIs, and the paired
    difference of each against the best. ``executor``: runs the batches of episodes (e.g.
    :class:`~trackenv_agents.distributed.RayExecutor`), with the same results as here."""
    name = scenario_of(env_id)
    cfg = scenario(name, **overrides)
    classes = [c for n, c in LINE_HEURISTICS.items() if n != "no-maintenance"]
    params = {} if retune else line_tuned_params()
    tuned_from = "shipped (agents/line_tuned_heuristics.json)" if params else f"tuned now on {n_train} seeds"
    if not params:
        t = tune_many(classes, cfg, list(range(1000, 1000 + n_train)), batch_size, progress, executor=executor)
        params = {classes[i].name: v["best_params"] for i, v in t.items()}
    pols = [LINE_HEURISTICS["no-maintenance"]()] + [LINE_HEURISTICS[n](**p) for n, p in params.items()]
    pols += list((extra or {}).values())
    seeds = seeds or list(range(8))
    res = evaluate_many(pols, cfg, seeds, batch_size=batch_size, progress=progress, desc="test", executor=executor)
    res.sort(key=lambda r: float(r.cost.mean()))
    best = res[0]
    rows = []
    for r in res:
        s = r.summary()
        s["vs_best"] = None if r is best else paired_difference(r, best)
        rows.append(s)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    payload = {"env": env_id, "scenario": name, "config": cfg.to_dict(), "seeds": seeds, "tuned_from": tuned_from,
               "results": rows}
    (out / "line_compare.json").write_text(json.dumps(payload, indent=1, default=float))
    from .reporting import plot_comparison

    payload["plot"] = plot_comparison(res, str(out / "line_compare.png"))
    by_name = {policy_name(p): p for p in pols}
    payload["episode_plot"] = plot_line_episode(by_name[best.policy], cfg, seeds[0], str(out / "line_episode.png"))
    return payload


def format_line_table(payload: dict[str, Any]) -> str:
    lines = [f"{payload['env']} ({payload['scenario']}), {len(payload['seeds'])} held-out episodes, parameters "
             f"{payload['tuned_from']}",
             f"{'policy':22s} {'cost k€':>8s} {'95% CI':>16s} {'vs best (paired, 95% CI)':>30s}  params"]
    for r in payload["results"]:
        d = r["vs_best"]
        diff = "-" if d is None else f"{d['mean_difference']:+.1f} [{d['ci_low']:+.1f}, {d['ci_high']:+.1f}]"
        ps = ", ".join(f"{k}={v}" for k, v in r["params"].items() if k not in
                       ("steps_per_year", "horizon_steps", "capacity"))
        lines.append(f"{r['policy']:22s} {r['mean_cost']:8.1f} [{r['ci_low']:6.1f}, {r['ci_high']:6.1f}] "
                     f"{diff:>30s}  {ps}")
    if payload.get("episode_plot"):
        lines.append(f"plots: {payload['plot']}, {payload['episode_plot']} (the best rule on episode "
                     f"{payload['seeds'][0]})")
    return "\n".join(lines)


def plot_line_episode(policy: Any, cfg: LineConfig, seed: int, out_png: str) -> str:
    """One episode of ``policy`` (SB3-style ``predict``): true SD of every section over time, tampings marked."""
    from matplotlib.figure import Figure

    from trackenv.envs.line import TampingLine

    pol = _bound(policy, cfg)
    env = TampingLine(cfg)
    obs, info = env.reset(seed=seed)
    sd, tam, meas = [info["section_sd_m"] * 1e3], [], [obs["section_sd"].copy()]
    for _ in range(cfg.horizon_steps):
        a = pol.predict(obs)[0]
        obs, _, _, _, info = env.step(a)
        sd.append(info["section_sd_m"] * 1e3)
        meas.append(obs["section_sd"].copy())
        tam.append(info["tamped_sections"])
    sd, tam, meas = np.array(sd), np.array(tam), np.array(meas)
    years = np.arange(cfg.horizon_steps + 1) / cfg.steps_per_year
    fig = Figure(figsize=(10, 4.5))
    ax = fig.subplots()
    reg = env.batch.register
    for j in range(cfg.n_sections):
        col = f"C{j % 10}"
        ax.plot(years, sd[:, j], color=col, lw=1.2 if reg[j] else 0.8,
                label=f"s{j}" + {0: "", 1: " (transition)", 2: " (switch)"}[int(reg[j])])
        ax.plot(years, meas[:, j], color=col, lw=0.5, ls=":")
        for t in np.flatnonzero(tam[:, j]):
            ax.plot(years[t], sd[t, j], "v", color=col, ms=6)
    ax.axhline(env.batch.limits.sd_alert_m * 1e3, color="k", ls="--", lw=0.8, label="SD alert")
    ax.set_xlabel("year")
    ax.set_ylabel("SD of D1 level [mm] (solid true, dotted measured; ▼ tamping)")
    ax.set_title(f"{policy_name(pol)} on {cfg.n_sections} sections, seed {seed}")
    ax.legend(fontsize=6, ncol=2)
    fig.tight_layout()
    fig.savefig(out_png, dpi=110)
    return out_png


def run_calibration(scenario_name: str = "default", seeds: list[int] | None = None, threshold_mm: float = 2.0,
                    out_dir: str = "results/line_calibration", progress: bool = True, **overrides: Any) -> dict:
    from trackenv.line_calibration import calibrate, plot_calibration

    cfg = scenario(scenario_name, **overrides)
    seeds = seeds or [2000, 2001]
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=2 * cfg.horizon_steps, desc="calibrate", unit="step")
    try:
        result = calibrate(cfg, seeds, threshold_mm, progress=bar.update if bar is not None else None)
    finally:
        if bar is not None:
            bar.close()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    result["plot"] = plot_calibration(result, str(out / "line_calibration.png"))
    (out / "line_calibration.json").write_text(json.dumps(result, indent=1, default=float))
    return result
