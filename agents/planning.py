"""What to do on a line from its present state: ``trackenv plan LINE.yaml`` and :func:`plan_line`.

A line file (:mod:`trackenv.envs.line_file`) says what the line is and where it stands at its ``as_of`` date;
:func:`plan_line` runs a maintenance policy on it for the next ``years`` in ``futures`` sampled futures (each
an episode of the line from that state: what the file does not know, the hidden wet spots and fields and the
rates, drawn again, the rates of sections with a history from their posterior), all in one vector env. The plan
is what the policy does in them: per quarter and section the share of futures in which the section is tamped
(recommended where it is at least half), and the cost forecast with its spread over the futures::

    from pathlib import Path
    from trackenv.lines import EXAMPLE
    from trackenv_agents.planning import plan_line

    plan = plan_line(EXAMPLE, policy="grouped-threshold", years=3, futures=8)
    print(plan.table())
    plan.write(Path("results/plan"))          # plan.csv, costs.csv, plan.png

The first quarter's recommendation is the decision to take now; the later quarters are a forecast, which the
next recording run and a new plan revise.
"""

from __future__ import annotations

import csv
import datetime as dt
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

#: The share of futures from which a section's tamping in a quarter is recommended.
RECOMMEND_SHARE = 0.5
DEFAULT_POLICY = "grouped-threshold"
#: The shipped trained per-section policy, by the name the other commands give it.
AGENT_POLICY = "cpi-agent"


def line_policy(name: str, config: Any) -> Any:
    """The policy ``name`` bound to ``config``: a line rule with its shipped tuned parameters
    (:func:`~trackenv_agents.rules.tuned_params_for`: a line from a file takes the default line's), the shipped
    agent (``cpi-agent``) or a trained per-section policy by the path of its ``.zip``; ValueError for another."""
    from .rules import LINE_HEURISTICS, tuned_params_for

    if name in LINE_HEURISTICS:
        return LINE_HEURISTICS[name](**tuned_params_for(config).get(name, {})).bind(config)
    if name == AGENT_POLICY or name.endswith(".zip"):
        from .learning.line import load_line_trained

        try:
            agent = load_line_trained(None if name == AGENT_POLICY else name, name=Path(name).stem)
        except FileNotFoundError as exc:
            raise ValueError(f"policy {name!r}: {exc}") from None
        return agent.bind(config)
    raise ValueError(f"unknown policy {name!r}; known: {', '.join(LINE_HEURISTICS)}, {AGENT_POLICY} or the path of "
                     "a trained per-section policy (.zip)")


def trained_horizon_years(policy: Any) -> float | None:
    """The episode length a trained policy learnt on (its ``time`` feature is the share of that horizon gone);
    None for a rule, which reads no horizon."""
    return getattr(policy, "horizon_years", None)


@dataclass(frozen=True, eq=False)
class LinePlan:
    """A plan (:func:`plan_line`): ``share`` (quarters, sections) of futures in which each section is tamped in
    each quarter, ``costs`` (futures, quarters) k€, ``parts`` the cost parts per future (k€, summed over the
    plan), ``dates`` the first day of each quarter, and the ``fit`` of the line's history."""

    line: Any
    policy: str
    years: float
    futures: int
    seed: int
    dates: tuple[str, ...]
    share: np.ndarray
    costs: np.ndarray
    parts: dict[str, np.ndarray]
    fit: Any

    @property
    def recommended(self) -> np.ndarray:
        """(quarters, sections) bool: tamped in at least :data:`RECOMMEND_SHARE` of the futures."""
        return self.share >= RECOMMEND_SHARE

    def to_dict(self) -> dict[str, Any]:
        ids = [s.id for s in self.line.sections]
        total = self.costs.sum(axis=1)
        return {
            "line": self.line.name, "as_of": self.line.as_of, "policy": self.policy, "years": self.years,
            "futures": self.futures, "seed": self.seed,
            "quarters": [{"from": d, "tamp": [i for i, r in zip(ids, rec, strict=True) if r],
                          "cost_mean_keur": float(c.mean())}
                         for d, rec, c in zip(self.dates, self.recommended, self.costs.T, strict=True)],
            "cost_keur": {"mean": float(total.mean()), "p10": float(np.quantile(total, 0.1)),
                          "p90": float(np.quantile(total, 0.9))},
            "cost_parts_mean_keur": {k: float(v.mean()) for k, v in self.parts.items()},
            "fit": {"fitted": len(self.fit.fitted), "median_residual_mm": self.fit.to_dict()["median_residual_mm"]},
        }

    def table(self) -> str:
        """The plan as text: per quarter the sections to tamp and its mean cost, then the cost forecast."""
        d = self.to_dict()
        lines = [f"Plan for {d['line']} from {d['as_of']}: {self.policy}, {self.years:g} years, {self.futures} "
                 "futures",
                 f"{'quarter':<8} {'from':<11} {'cost k€':>8}  tamp (in at least half the futures)"]
        for q, row in enumerate(d["quarters"]):
            tamp = " ".join(row["tamp"]) if row["tamp"] else "-"
            lines.append(f"Q{q + 1:<7} {row['from']:<11} {row['cost_mean_keur']:>8.1f}  {tamp}")
        c = d["cost_keur"]
        parts = ", ".join(f"{k} {v:.0f}" for k, v in d["cost_parts_mean_keur"].items())
        lines.append(f"cost over {self.years:g} years: {c['mean']:.0f} k€ mean, {c['p10']:.0f}-{c['p90']:.0f} k€ "
                     f"over 10-90 % of the futures ({parts})")
        fit = d["fit"]
        if fit["fitted"]:
            lines.append(f"history: {fit['fitted']} sections' rates fitted, median residual "
                         f"{fit['median_residual_mm']:.3f} mm (trackenv.envs.history_fit)")
        return "\n".join(lines)

    def write(self, folder: Path) -> dict[str, str]:
        """Write ``plan.csv`` (quarter, date, section, share of futures, recommended), ``costs.csv`` (quarter,
        date, mean, p10, p90 k€) and ``plan.png`` into ``folder``; returns their paths."""
        folder.mkdir(parents=True, exist_ok=True)
        paths = {"plan_csv": folder / "plan.csv", "costs_csv": folder / "costs.csv", "plot": folder / "plan.png"}
        with paths["plan_csv"].open("w", newline="") as f:
            w = csv.writer(f, lineterminator="\n")
            w.writerow(["quarter", "from", "section", "share_of_futures", "recommended"])
            for q, (date, share, rec) in enumerate(zip(self.dates, self.share, self.recommended, strict=True)):
                for s, sh, r in zip(self.line.sections, share, rec, strict=True):
                    if sh > 0:
                        w.writerow([q + 1, date, s.id, f"{sh:.3f}", int(r)])
        with paths["costs_csv"].open("w", newline="") as f:
            w = csv.writer(f, lineterminator="\n")
            w.writerow(["quarter", "from", "cost_mean_keur", "cost_p10_keur", "cost_p90_keur"])
            for q, (date, c) in enumerate(zip(self.dates, self.costs.T, strict=True)):
                w.writerow([q + 1, date, f"{c.mean():.3f}", f"{np.quantile(c, 0.1):.3f}",
                            f"{np.quantile(c, 0.9):.3f}"])
        self.plot(paths["plot"])
        return {k: str(v) for k, v in paths.items()}

    def plot(self, path: Path) -> None:
        """The plan along the line over time (share of futures tamping each section in each quarter, the
        recommended ones outlined) above the cumulative cost forecast (mean and 10-90 % band)."""
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        km = np.cumsum([0.0] + [s.length_m for s in self.line.sections]) / 1000.0
        quarters = np.arange(len(self.dates) + 1)
        fig = Figure(figsize=(10, 6.5), dpi=100)
        FigureCanvasAgg(fig)
        top, bottom = fig.subplots(2, 1, gridspec_kw={"height_ratios": [3, 1.4]})
        mesh = top.pcolormesh(km, quarters, self.share, cmap="Blues", vmin=0.0, vmax=1.0, shading="flat")
        q, j = np.nonzero(self.recommended)
        top.scatter((km[j] + km[j + 1]) / 2, q + 0.5, marker="s", s=12, facecolors="none", edgecolors="crimson",
                    linewidths=0.8, label=f"recommended (≥ {RECOMMEND_SHARE:.0%} of futures)")
        zones = {1: ("transition", "darkorange"), 2: ("switch or crossing", "purple")}
        for code, (label, colour) in zones.items():
            at = [i for i, s in enumerate(self.line.sections) if s.register_index == code]
            top.scatter((km[at] + km[np.array(at, dtype=int) + 1]) / 2 if at else [], [-0.4] * len(at), marker="^",
                        color=colour, s=18, label=label, clip_on=False)
        wet = [i for i, s in enumerate(self.line.sections) if s.wet]
        top.scatter((km[wet] + km[np.array(wet, dtype=int) + 1]) / 2 if wet else [], [-0.4] * len(wet), marker="v",
                    color="teal", s=18, label="known wet", clip_on=False)
        top.set_ylim(len(self.dates), -0.8)
        step = max(len(self.dates) // 8, 1)
        top.set_yticks(np.arange(0, len(self.dates), step) + 0.5, [self.dates[i] for i in range(0, len(self.dates),
                                                                                                 step)])
        top.set_xlabel("position along the line [km]")
        top.set_title(f"{self.line.name}: {self.policy}, {self.futures} futures from {self.line.as_of}")
        top.legend(loc="lower right", fontsize=7, ncol=4)
        fig.colorbar(mesh, ax=top, label="share of futures tamping")
        cum = np.cumsum(self.costs, axis=1)
        x = np.arange(1, len(self.dates) + 1)
        bottom.fill_between(x, np.quantile(cum, 0.1, axis=0), np.quantile(cum, 0.9, axis=0), alpha=0.3,
                            label="10-90 % of futures")
        bottom.plot(x, cum.mean(axis=0), label="mean")
        bottom.set_xlabel("quarter")
        bottom.set_ylabel("cumulative cost [k€]")
        bottom.legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(path)


def plan_line(line: Any, *, policy: str = DEFAULT_POLICY, years: float = 3.0, futures: int = 8, seed: int = 0,
              progress: Callable[[int], Any] | None = None, **config: Any) -> LinePlan:
    """Plan maintenance on ``line`` (a line file's path or a :class:`~trackenv.envs.line_file.LineDescription`)
    for ``years`` from its ``as_of``: the line rule ``policy`` run in ``futures`` futures (episodes from seeds
    ``seed``, ``seed + 1``, ...) in one vector env; ``config``: further :class:`LineConfig` fields (costs,
    capacity, ...). ``progress(1)`` is called after each quarter."""
    from gymnasium.vector import AutoresetMode

    from trackenv.envs.line import TampingLineVectorEnv
    from trackenv.envs.line_config import LineConfig
    from trackenv.envs.line_fit import history_fit

    cfg = LineConfig(line=line, horizon_years=years, **config)
    rule = line_policy(policy, cfg)
    steps = cfg.horizon_steps
    trained = trained_horizon_years(rule)
    if trained is not None:
        # a trained policy reads the time left in its training episode: the futures run in episodes of that
        # length, of which the plan takes its first ``years`` (the line goes on after the plan, as in training)
        if years > trained:
            raise ValueError(f"years: the policy {policy!r} was trained on {trained:g}-year episodes; plan at most "
                             f"{trained:g} years with it, got {years:g}")
        cfg = cfg.replace(horizon_years=trained)
        rule = rule.bind(cfg)
    fit = history_fit(cfg)
    env = TampingLineVectorEnv(futures, cfg, autoreset_mode=AutoresetMode.NEXT_STEP)
    obs, _ = env.reset(seed=[seed + i for i in range(futures)])
    share = np.zeros((steps, cfg.n_sections))
    costs = np.zeros((futures, steps))
    parts: dict[str, np.ndarray] = {}
    for step in range(steps):
        action, _ = rule.predict(obs, deterministic=True)
        obs, reward, _, _, info = env.step(action)
        share[step] = np.asarray(info["tamped_sections"], dtype=float).mean(axis=0)
        costs[:, step] = -np.asarray(reward)
        for key, value in info["costs"].items():
            if not key.startswith("_"):
                parts[key] = parts.get(key, np.zeros(futures)) + np.asarray(value)
        if progress is not None:
            progress(1)
    env.close()
    start = dt.date.fromisoformat(cfg.line.as_of)
    dates = tuple((start + dt.timedelta(days=round(q * 365.25 / cfg.steps_per_year))).isoformat()
                  for q in range(steps))
    return LinePlan(cfg.line, policy, float(years), futures, seed, dates, share, costs, parts, fit)
