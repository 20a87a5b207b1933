"""What to do on a line from its present state: ``trackenv plan LINE.yaml`` and :func:`plan_line`.

A line file (:mod:`trackenv.envs.line_file`) says what the line is and where it stands at its ``as_of`` date;
:func:`plan_line` runs a maintenance policy on it for the next ``years`` in ``futures`` sampled futures (each
an episode of the line from that state: what the file does not know, the hidden wet spots and fields and the
rates, drawn again, the rates of sections with a history from their posterior), all in one vector env. The plan
is what the policy does in them: per quarter and section the share of futures in which the section gets each
choice (recommended where one choice is made in at least half of them), and the cost forecast with its spread
over the futures.

``scenario`` says how the line is modelled beyond its file (:data:`PLAN_SCENARIOS`): ``default`` draws the
hidden parts as on the default line and plans tamping only; ``choices`` adds every intervention and inspection
(spot tamping, drainage, renewal, an extra measurement, a survey) and the contact sensor; ``wet`` and
``defects`` draw the hidden parts as on the wet, poorly drained line and on the line of many short defects,
with every choice. A rule takes the tuned parameters of that scenario::

    from pathlib import Path
    from trackenv.lines import EXAMPLE
    from trackenv_agents.planning import plan_line

    plan = plan_line(EXAMPLE, policy="grouped-threshold", years=3, futures=8)
    print(plan.table())
    wet = plan_line(EXAMPLE, policy="choice-threshold", scenario="wet")   # surveys, drainage, ...
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

from trackenv.envs.choices import CHOICES, action_type_for
from trackenv.envs.line_config import LINE_FILE_FIELDS, SCENARIOS, LineConfig, check_horizon
from trackenv.envs.line_config import scenario as preset

from .shipped import SHIPPED_AGENTS

#: The share of futures from which a section's choice in a quarter is recommended.
RECOMMEND_SHARE = 0.5
#: The scenarios a line from a file can be planned in: those that leave the line's own fields (its sections,
#: lengths and traffic) to the file.
PLAN_SCENARIOS = tuple(name for name, fields_ in SCENARIOS.items() if not set(fields_) & set(LINE_FILE_FIELDS))
DEFAULT_POLICY = "grouped-threshold"


def line_policy(name: str, config: Any, scenario: str | None = None, years: float | None = None) -> Any:
    """The policy ``name`` bound to ``config``: a rule of the config (:func:`~trackenv_agents.rules.rules_for`:
    the tamping rules, and the choice rules where the config has more choices) with the shipped tuned parameters
    of ``scenario`` (default: those of the preset ``config`` is, else the default line's), a shipped agent by its
    name (:data:`~trackenv_agents.shipped.SHIPPED_AGENTS`: ``cpi-agent``, ``cpi-choice-agent``,
    ``cpi-track60-agent``) or a trained policy by the path of its ``.zip`` (a per-section policy runs on any line;
    a model of ``trackenv train`` only on the line it was trained on); ValueError for another, or for an agent
    that cannot run on ``config`` (its reason), or that learnt on episodes shorter than a plan of ``years``."""
    from .rules import TUNED_FILES, line_tuned_params, rules_for, tuned_rule

    rules = rules_for(config)
    if name in rules:
        if scenario is not None and TUNED_FILES.get(scenario, Path()).is_file():
            return rules[name](**line_tuned_params(TUNED_FILES[scenario]).get(name, {})).bind(config)
        return tuned_rule(config, name).bind(config)
    if name in SHIPPED_AGENTS or name.endswith(".zip"):
        from .learning.baselines import load_baseline

        try:
            agent = load_baseline(SHIPPED_AGENTS.get(name, name), name=Path(name).stem)
        except FileNotFoundError as exc:
            raise ValueError(f"policy {name!r}: {exc}") from None
        why = agent.unfit_for(config)
        if why is not None:
            raise ValueError(f"policy {name!r} cannot run on this line: {why}")
        trained = trained_horizon_years(agent)
        if years is not None and trained is not None and years > trained:
            raise ValueError(f"years: the policy {name!r} was trained on {trained:g}-year episodes; plan at most "
                             f"{trained:g} years with it, got {years:g}")
        bind = getattr(agent, "bind", None)
        return bind(config) if callable(bind) else agent
    from .rules.problems import every_rule

    if name in every_rule():
        with_choices = [s for s in PLAN_SCENARIOS if tuple(preset(s).choices) != ("tamp",)]
        raise ValueError(f"policy {name!r} uses the choices beyond tamping: plan with --scenario "
                         f"{', '.join(with_choices[:-1])} or {with_choices[-1]}")
    raise ValueError(f"unknown policy {name!r}; known: {', '.join([*rules, *SHIPPED_AGENTS])} or the path of a "
                     "trained policy (.zip)")


def plan_config(line: Any, scenario: str = "default", years: float | None = None, **config: Any) -> Any:
    """The :class:`~trackenv.envs.line_config.LineConfig` of ``line`` (a line file's path or a
    :class:`~trackenv.envs.line_file.LineDescription`) modelled as on the preset ``scenario``
    (:data:`PLAN_SCENARIOS`), with further ``config`` fields; ``years``: the plan's, its horizon (checked under
    that name, in the config's range: whole steps, at least one, at most ``MAX_HORIZON_YEARS``)."""
    if scenario not in PLAN_SCENARIOS:
        raise ValueError(f"scenario must be one of {', '.join(PLAN_SCENARIOS)} (those that take the line's sections "
                         f"and traffic from its file), got {scenario!r}")
    if years is not None:
        steps_per_year = config.get("steps_per_year", LineConfig.steps_per_year)
        config["horizon_years"] = check_horizon("years", years, steps_per_year)
    return preset(scenario, line=line, **config)


def _years(years: float) -> str:
    return f"{years:g} year{'' if years == 1 else 's'}"


def trained_horizon_years(policy: Any) -> float | None:
    """The episode length a trained policy learnt on (its ``time`` feature is the share of that horizon gone);
    None for a rule, which reads no horizon."""
    return getattr(policy, "horizon_years", None)


@dataclass(frozen=True, eq=False)
class LinePlan:
    """A plan (:func:`plan_line`): ``choice_share`` (quarters, sections, choices) the share of futures in which
    each section gets each choice (indexed by code, :data:`~trackenv.envs.choices.CHOICES`) in each quarter,
    ``costs`` (futures, quarters) k€, ``parts`` the cost parts per future (k€, summed over the plan), ``dates``
    the first day of each quarter, the ``fit`` of the line's history, and the ``scenario``, ``choices``,
    ``engine`` and ``pass_reuse_tolerance_m`` (m) the line was planned with."""

    line: Any
    policy: str
    years: float
    futures: int
    seed: int
    dates: tuple[str, ...]
    choice_share: np.ndarray
    costs: np.ndarray
    parts: dict[str, np.ndarray]
    fit: Any
    scenario: str = "default"
    choices: tuple[str, ...] = ("tamp",)
    engine: str = "classic"
    pass_reuse_tolerance_m: float = 0.0

    @property
    def share(self) -> np.ndarray:
        """(quarters, sections): the share of futures in which the section gets any choice but nothing (with
        tamping only: is tamped)."""
        return 1.0 - self.choice_share[:, :, 0]

    @property
    def recommended(self) -> np.ndarray:
        """(quarters, sections) int: the code of the choice made in at least :data:`RECOMMEND_SHARE` of the
        futures (the more frequent, then the lower code, where two reach it), 0 (nothing) where none does."""
        work = self.choice_share[:, :, 1:]
        best = work.argmax(axis=2)
        return np.where(np.take_along_axis(work, best[..., None], axis=2)[..., 0] >= RECOMMEND_SHARE, best + 1, 0)

    def to_dict(self) -> dict[str, Any]:
        ids = [s.id for s in self.line.sections]
        total = self.costs.sum(axis=1)
        quarters = []
        for d, rec, c in zip(self.dates, self.recommended, self.costs.T, strict=True):
            row: dict[str, Any] = {"from": d}
            for name in self.choices:
                code = CHOICES.index(name)
                row[name] = [i for i, r in zip(ids, rec, strict=True) if r == code]
            quarters.append({**row, "cost_mean_keur": float(c.mean())})
        return {
            "line": self.line.name, "as_of": self.line.as_of, "policy": self.policy, "scenario": self.scenario,
            "years": self.years, "futures": self.futures, "seed": self.seed, "engine": self.engine,
            "pass_reuse_mm": self.pass_reuse_tolerance_m * 1e3, "quarters": quarters,
            "cost_keur": {"mean": float(total.mean()), "p10": float(np.quantile(total, 0.1)),
                          "p90": float(np.quantile(total, 0.9))},
            "cost_parts_mean_keur": {k: float(v.mean()) for k, v in self.parts.items()},
            "fit": {"fitted": len(self.fit.fitted), "median_residual_mm": self.fit.to_dict()["median_residual_mm"]},
        }

    def table(self) -> str:
        """The plan as text: per quarter its mean cost and the sections recommended for each choice, then the cost
        forecast."""
        from .evaluation.line_compare import engine_note

        d = self.to_dict()
        engine = engine_note({"engine": self.engine, "pass_reuse_tolerance_m": self.pass_reuse_tolerance_m})
        lines = [f"Plan for {d['line']} from {d['as_of']}: {self.policy} ({self.scenario}), {_years(self.years)}, "
                 f"{self.futures} futures{engine}",
                 f"{'quarter':<8} {'from':<11} {'cost k€':>8}  recommended (in at least half the futures)"]
        for q, row in enumerate(d["quarters"]):
            if self.choices == ("tamp",):
                what = " ".join(row["tamp"]) or "-"
            else:
                what = "; ".join(f"{name} {' '.join(row[name])}" for name in self.choices if row[name]) or "-"
            lines.append(f"Q{q + 1:<7} {row['from']:<11} {row['cost_mean_keur']:>8.1f}  {what}")
        c = d["cost_keur"]
        parts = ", ".join(f"{k} {v:.0f}" for k, v in d["cost_parts_mean_keur"].items())
        lines.append(f"cost over {_years(self.years)}: {c['mean']:.0f} k€ mean, {c['p10']:.0f}-{c['p90']:.0f} k€ "
                     f"over 10-90 % of the futures ({parts})")
        fit = d["fit"]
        if fit["fitted"]:
            lines.append(f"history: {fit['fitted']} sections' rates fitted, median residual "
                         f"{fit['median_residual_mm']:.3f} mm (trackenv.envs.history_fit)")
        return "\n".join(lines)

    def write(self, folder: Path) -> dict[str, str]:
        """Write ``plan.csv`` (quarter, date, section, choice, share of futures, recommended; a row per choice a
        section gets in some future), ``costs.csv`` (quarter, date, mean, p10, p90 k€) and ``plan.png`` into
        ``folder``; returns their paths."""
        folder.mkdir(parents=True, exist_ok=True)
        paths = {"plan_csv": folder / "plan.csv", "costs_csv": folder / "costs.csv", "plot": folder / "plan.png"}
        with paths["plan_csv"].open("w", newline="") as f:
            w = csv.writer(f, lineterminator="\n")
            w.writerow(["quarter", "from", "section", "choice", "share_of_futures", "recommended"])
            for q, (date, shares, rec) in enumerate(zip(self.dates, self.choice_share, self.recommended,
                                                       strict=True)):
                for s, share, r in zip(self.line.sections, shares, rec, strict=True):
                    for code in np.flatnonzero(share[1:] > 0) + 1:
                        w.writerow([q + 1, date, s.id, CHOICES[code], f"{share[code]:.3f}", int(r == code)])
        with paths["costs_csv"].open("w", newline="") as f:
            w = csv.writer(f, lineterminator="\n")
            w.writerow(["quarter", "from", "cost_mean_keur", "cost_p10_keur", "cost_p90_keur"])
            for q, (date, c) in enumerate(zip(self.dates, self.costs.T, strict=True)):
                w.writerow([q + 1, date, f"{c.mean():.3f}", f"{np.quantile(c, 0.1):.3f}",
                            f"{np.quantile(c, 0.9):.3f}"])
        self.plot(paths["plot"])
        return {k: str(v) for k, v in paths.items()}

    def plot(self, path: Path) -> None:
        """The plan along the line over time (share of futures in which each section gets a choice in each
        quarter, the recommended ones outlined, one colour per choice) above the cumulative cost forecast (mean and
        10-90 % band)."""
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        km = np.cumsum([0.0] + [s.length_m for s in self.line.sections]) / 1000.0
        quarters = np.arange(len(self.dates) + 1)
        fig = Figure(figsize=(10, 7.5), dpi=100)
        FigureCanvasAgg(fig)
        top, bottom = fig.subplots(2, 1, gridspec_kw={"height_ratios": [3, 1.4]})
        mesh = top.pcolormesh(km, quarters, self.share, cmap="Blues", vmin=0.0, vmax=1.0, shading="flat")
        colours = dict(zip(CHOICES[1:], ("crimson", "gold", "navy", "black", "limegreen", "magenta"), strict=True))
        for name in self.choices:
            q, j = np.nonzero(self.recommended == CHOICES.index(name))
            top.scatter((km[j] + km[j + 1]) / 2, q + 0.5, marker="s", s=12, facecolors="none",
                        edgecolors=colours[name], linewidths=0.8, label=name)
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
        top.set_title(f"{self.line.name}: {self.policy} ({self.scenario}), {self.futures} futures from "
                      f"{self.line.as_of}")
        top.legend(loc="upper center", bbox_to_anchor=(0.5, -0.16), fontsize=7, ncol=5,
                   title=f"recommended: made in at least {RECOMMEND_SHARE:.0%} of the futures", title_fontsize=7)
        fig.colorbar(mesh, ax=top, label="share of futures tamping" if self.choices == ("tamp",)
                     else "share of futures with a choice")
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
              scenario: str = "default", progress: Callable[[int], Any] | None = None, **config: Any) -> LinePlan:
    """Plan maintenance on ``line`` (a line file's path or a :class:`~trackenv.envs.line_file.LineDescription`)
    for ``years`` from its ``as_of``: the policy ``policy`` (:func:`line_policy`) run in ``futures`` futures
    (episodes from seeds ``seed``, ``seed + 1``, ...) in one vector env, the line modelled as on the preset
    ``scenario`` (:data:`PLAN_SCENARIOS`); ``config``: further :class:`LineConfig` fields (costs, capacity, ...).
    ``progress(1)`` is called after each quarter."""
    from gymnasium.vector import AutoresetMode

    from trackenv.envs.line import TampingLineVectorEnv
    from trackenv.envs.line_fit import history_fit

    cfg = plan_config(line, scenario, years=years, **config)
    rule = line_policy(policy, cfg, scenario, years=years)
    steps = cfg.horizon_steps
    trained = trained_horizon_years(rule)
    if trained is not None:
        # a trained policy reads the time left in its training episode: the futures run in episodes of that
        # length, of which the plan takes its first ``years`` (the line goes on after the plan, as in training)
        cfg = cfg.replace(horizon_years=trained)
        rule = rule.bind(cfg)
    fit = history_fit(cfg)
    env = TampingLineVectorEnv(futures, cfg, autoreset_mode=AutoresetMode.NEXT_STEP, action_type=action_type_for(cfg))
    obs, _ = env.reset(seed=[seed + i for i in range(futures)])
    share = np.zeros((steps, cfg.n_sections, len(CHOICES)))
    costs = np.zeros((futures, steps))
    parts: dict[str, np.ndarray] = {}
    for step in range(steps):
        action, _ = rule.predict(obs, deterministic=True)
        obs, reward, _, _, info = env.step(action)
        codes = np.asarray(info["section_choices"])  # (futures, sections)
        share[step] = (codes[..., None] == np.arange(len(CHOICES))).mean(axis=0)
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
    return LinePlan(cfg.line, policy, float(years), futures, seed, dates, share, costs, parts, fit, scenario,
                    tuple(cfg.choices), cfg.engine, cfg.pass_reuse_tolerance_m)
