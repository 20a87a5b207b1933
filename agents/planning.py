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
next recording run and a new plan revise. The plan repeats what it read from the file (:func:`line_summary`, so a
unit mistake shows), and records per quarter and section the state the policy decided on (the measured SD and
mean-to-peak it observed, their age, the true SD and mean-to-peak; means over the futures) with each section's
limits and the rule's thresholds, so the table can say what the numbers behind the decision to take now are.
"""

from __future__ import annotations

import csv
import datetime as dt
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from trackenv.envs.choices import CHOICES, action_type_for
from trackenv.envs.line_config import LINE_FILE_FIELDS, SCENARIOS, LineConfig, check_horizon
from trackenv.envs.line_config import scenario as preset
from trackenv.envs.line_file import DAYS_PER_YEAR

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


def step_date(as_of: str, step: int, steps_per_year: int) -> str:
    """The date (ISO) ``step`` model steps after ``as_of``: a step is 365.25 / ``steps_per_year`` days, the date
    rounded to the day."""
    start = dt.date.fromisoformat(as_of)
    return (start + dt.timedelta(days=round(step * DAYS_PER_YEAR / steps_per_year))).isoformat()


def line_summary(line: Any) -> dict[str, Any]:
    """What a plan reads from a line file (a :class:`~trackenv.envs.line_file.LineDescription`), in the file's
    units, for a reader to check them: the number of sections and the length [km], the ranges over the sections of
    the speed [km/h], the tonnage [MGT/year] and the freight share, the freight axle load [t], the counts of
    transitions, switches or crossings and known wet zones, and the date of the last recording-car run in the
    history with its age [years before ``as_of``] (None without a history)."""
    sections = line.sections

    def span(attr: str) -> list[float]:
        values = [float(getattr(s, attr)) for s in sections]
        return [min(values), max(values)]

    last = max((m.date for m in line.history), default=None)
    return {
        "sections": len(sections), "length_km": line.length_m / 1000.0,
        "speed_kmh": span("speed_kmh"), "annual_mgt": span("annual_mgt"), "freight_share": span("freight_share"),
        "freight_axle_load_t": float(line.freight_axle_load_t),
        "transitions": sum(s.register == "transition" for s in sections),
        "switches_crossings": sum(s.register == "switch_or_crossing" for s in sections),
        "known_wet": sum(bool(s.wet) for s in sections),
        "last_recording": None if last is None else {"date": last, "years_before": line.years_before(last)},
    }


def _span(values: list[float], fmt: str) -> str:
    low, high = values
    return format(low, fmt) if low == high else f"{low:{fmt}}-{high:{fmt}}"


def _count(n: int, what: str, plural: str) -> str:
    return f"{n} {what if n == 1 else plural}"


def summary_lines(summary: dict[str, Any]) -> list[str]:
    """The two lines of text that repeat a :func:`line_summary`."""
    last = summary["last_recording"]
    run = ("no recording-car history" if last is None else
           f"last recording-car run {last['date']} ({last['years_before']:.2f} years before as_of)")
    sections = _count(summary["sections"], "section", "sections")
    return [f"read from the file: {sections}, {summary['length_km']:.2f} km; speed "
            f"{_span(summary['speed_kmh'], 'g')} km/h; tonnage {_span(summary['annual_mgt'], 'g')} MGT/year; "
            f"freight share {_span(summary['freight_share'], '.2f')}, freight axle load "
            f"{summary['freight_axle_load_t']:g} t",
            f"  {_count(summary['transitions'], 'transition', 'transitions')}, "
            f"{_count(summary['switches_crossings'], 'switch or crossing', 'switches or crossings')}, "
            f"{_count(summary['known_wet'], 'known wet zone', 'known wet zones')}; {run}"]


#: The per-section state a plan records per quarter (means over the futures, before the quarter's work): what the
#: policy observed (the last measured SD and D1 mean-to-peak, their age) and the true SD and mean-to-peak.
STATE_COLUMNS = {"measured_sd_mm": "measured SD [mm]", "measured_peak_mm": "measured D1 mean-to-peak [mm]",
                 "measurement_age_years": "age of that measurement [year]", "sd_mm": "true SD [mm]",
                 "peak_mm": "true D1 mean-to-peak [mm]"}
#: A section's quality limits in its speed band (:class:`~trackenv.physics.geometry.BandLimits`), by the name the
#: plan gives them [mm]: the D1 mean-to-peak's alert, intervention and immediate-action limits and the SD alert.
LIMIT_FIELDS = {"alert": "alert_m", "intervention": "intervention_m", "immediate_action": "immediate_action_m",
                "sd_alert": "sd_alert_m"}
GEOMETRY_NOTE = ("geometry is a notional cost of poor track geometry (poorer ride, faster wear of track and "
                 "vehicles), not money spent")


def rule_thresholds(params: dict[str, Any]) -> dict[str, float]:
    """A rule's level thresholds from its ``params``: those in mm (name ending ``_mm``: ``trigger_mm``,
    ``include_mm``, ``threshold_mm``, ``spot_peak_mm``, ...) that are on (above 0); margins, which are no
    levels, left out; none for a trained policy."""
    return {k: float(v) for k, v in params.items() if k.endswith("_mm") and "margin" not in k
            and isinstance(v, int | float) and not isinstance(v, bool) and v > 0}


def trained_horizon_years(policy: Any) -> float | None:
    """The episode length a trained policy learnt on (its ``time`` feature is the share of that horizon gone);
    None for a rule, which reads no horizon."""
    return getattr(policy, "horizon_years", None)


@dataclass(frozen=True, eq=False)
class LinePlan:
    """A plan (:func:`plan_line`): ``choice_share`` (quarters, sections, choices) the share of futures in which
    each section gets each choice (indexed by code, :data:`~trackenv.envs.choices.CHOICES`) in each quarter,
    ``costs`` (futures, quarters) k€, ``parts`` the cost parts per future (k€, summed over the plan),
    ``part_costs`` the same per future and quarter ((futures, quarters) k€), ``state`` what the sections were
    before each quarter's work (:data:`STATE_COLUMNS`, each (quarters, sections), means over the futures),
    ``limits_mm`` each section's limits in its speed band (:data:`LIMIT_FIELDS`, each (sections,) mm),
    ``unmet_share`` (quarters, sections) the share of futures in which the policy asked for a choice the env did
    not apply (masked, e.g. tamped in the last ``min_steps_between_tampings`` steps, or beyond the capacity),
    ``policy_params`` the policy's parameters (a rule's thresholds; empty or the file of a trained policy),
    ``dates`` the first day of each quarter, the ``fit`` of the line's history, the ``scenario``, ``choices``,
    ``engine`` and ``pass_reuse_tolerance_m`` (m) the line was planned with, and the model's ``steps_per_year``
    and ``measurement_interval`` (steps between recording-car runs)."""

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
    part_costs: dict[str, np.ndarray] = field(default_factory=dict)
    state: dict[str, np.ndarray] = field(default_factory=dict)
    limits_mm: dict[str, np.ndarray] = field(default_factory=dict)
    policy_params: dict[str, Any] = field(default_factory=dict)
    unmet_share: np.ndarray | None = None
    steps_per_year: int = 4
    measurement_interval: int = 4
    config_changes: dict[str, Any] = field(default_factory=dict)

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

    def recording_runs(self) -> list[tuple[int, str]]:
        """The model's recording-car runs after ``as_of`` (the first quarter reads the file's last runs), as (step,
        date): one every ``measurement_interval`` steps, closing the quarter of that number (read by the next
        quarter's decision); those within the plan and the first after it."""
        runs = []
        step = self.measurement_interval
        while True:
            runs.append((step, step_date(self.line.as_of, step, self.steps_per_year)))
            if step >= len(self.dates):
                return runs
            step += self.measurement_interval

    def recording_note(self) -> str:
        """When the plan's decisions see a new recording-car run (:meth:`recording_runs`), in a line."""
        runs = self.recording_runs()
        inside = [(step, date) for step, date in runs if step < len(self.dates)]
        every = f"every {_count(self.measurement_interval, 'quarter', 'quarters')}"
        first = ("Q1 reads each section's last run in the file (the model's own at as_of where it has none)"
                 if self.line.history else "Q1 reads the model's own run at as_of (the file has no history)")
        if not inside:
            return (f"recording-car runs: {first}; the model's then {every}: the next {runs[-1][1]}, after the "
                    f"plan")
        listed = ", ".join(f"{date} (read in Q{step + 1})" for step, date in inside[:3])
        return f"recording-car runs: {first}; the model's then {every}: {listed}{', ...' if len(inside) > 3 else ''}"

    def to_dict(self) -> dict[str, Any]:
        """The plan as plain data (JSON-ready), opening with what it was run on (:func:`line_summary`); per quarter
        the sections recommended for each choice, the mean cost and its parts, and the sections' ``state``
        (:data:`STATE_COLUMNS`, lists in the order of ``section_ids``)."""
        ids = [s.id for s in self.line.sections]
        total = self.costs.sum(axis=1)
        quarters = []
        for q, (d, rec, c) in enumerate(zip(self.dates, self.recommended, self.costs.T, strict=True)):
            row: dict[str, Any] = {"from": d}
            for name in self.choices:
                code = CHOICES.index(name)
                row[name] = [i for i, r in zip(ids, rec, strict=True) if r == code]
            if self.unmet_share is not None:
                row["asked_not_done"] = [i for i, u in zip(ids, self.unmet_share[q], strict=True)
                                         if u >= RECOMMEND_SHARE]
            quarters.append({**row, "cost_mean_keur": float(c.mean()),
                             "cost_parts_mean_keur": {k: float(v[:, q].mean()) for k, v in self.part_costs.items()},
                             "state": {k: _rounded(v[q]) for k, v in self.state.items()}})
        return {
            "line": self.line.name, "as_of": self.line.as_of, "line_summary": line_summary(self.line),
            "policy": self.policy, "policy_params": dict(self.policy_params), "scenario": self.scenario,
            "years": self.years, "futures": self.futures, "seed": self.seed, "engine": self.engine,
            "config_changes": dict(self.config_changes),
            "pass_reuse_mm": self.pass_reuse_tolerance_m * 1e3, "section_ids": ids,
            "limits_mm": {k: _rounded(v) for k, v in self.limits_mm.items()},
            "recording_runs": [date for _, date in self.recording_runs()], "quarters": quarters,
            "cost_keur": {"mean": float(total.mean()), "p10": float(np.quantile(total, 0.1)),
                          "p90": float(np.quantile(total, 0.9))},
            "cost_parts_mean_keur": {k: float(v.mean()) for k, v in self.parts.items()},
            "fit": {"fitted": len(self.fit.fitted), "median_residual_mm": self.fit.to_dict()["median_residual_mm"]},
        }

    def table(self) -> str:
        """The plan as text: what it was run on, per quarter its mean cost and the sections recommended for each
        choice, the first quarter's recommended sections against their limits, when the model's recording car
        runs, then the cost forecast."""
        from .evaluation.line_compare import changes_note, engine_note

        d = self.to_dict()
        engine = engine_note({"engine": self.engine, "pass_reuse_tolerance_m": self.pass_reuse_tolerance_m})
        lines = [f"Plan for {d['line']} from {d['as_of']}: {self.policy} ({self.scenario}), {_years(self.years)}, "
                 f"{self.futures} futures{engine}{changes_note(self.config_changes)}",
                 *summary_lines(d["line_summary"]),
                 f"{'quarter':<8} {'from':<11} {'cost k€':>8}  recommended (in at least half the futures)"]
        for q, row in enumerate(d["quarters"]):
            if self.choices == ("tamp",):
                what = " ".join(row["tamp"]) or "-"
            else:
                what = "; ".join(f"{name} {' '.join(row[name])}" for name in self.choices if row[name]) or "-"
            lines.append(f"Q{q + 1:<7} {row['from']:<11} {row['cost_mean_keur']:>8.1f}  {what}")
        lines += [*self.decision_lines(), self.recording_note()]
        c = d["cost_keur"]
        parts = ", ".join(f"{k} {v:.0f}" for k, v in d["cost_parts_mean_keur"].items())
        lines.append(f"cost over {_years(self.years)}: {c['mean']:.0f} k€ mean, {c['p10']:.0f}-{c['p90']:.0f} k€ "
                     f"over 10-90 % of the futures ({parts})")
        if "geometry" in self.parts:
            lines.append(f"  ({GEOMETRY_NOTE})")
        fit = d["fit"]
        if fit["fitted"]:
            whose = "1 section's rate" if fit["fitted"] == 1 else f"{fit['fitted']} sections' rates"
            lines.append(f"history: {whose} fitted, median residual "
                         f"{fit['median_residual_mm']:.3f} mm (trackenv.envs.history_fit)")
        return "\n".join(lines)

    def decision_lines(self) -> list[str]:
        """A line per section recommended in the first quarter (the decision to take now): the measured SD and
        D1 mean-to-peak the policy saw against the limits of the section's speed band, the measurement's age and
        the true SD and mean-to-peak (means over the futures), under a line with the rule's level thresholds
        (:func:`rule_thresholds`); then the same for the sections the policy asked for in at least half the
        futures that the env did not work on (:attr:`unmet_share`). Numbers only: what the model had, not a
        reason it does not have."""
        if not len(self.dates) or not self.state or not self.limits_mm:
            return []
        first = self.recommended[0]
        unmet = np.zeros_like(first, dtype=bool) if self.unmet_share is None else self.unmet_share[0] >= RECOMMEND_SHARE
        thresholds = rule_thresholds(self.policy_params)
        rule = f" ({self.policy}: {', '.join(f'{k} {v:g}' for k, v in thresholds.items())})" if thresholds else ""
        lines = []
        if first.any():
            lines.append(f"Q1's recommended sections as the policy saw them{rule}, means over the futures [mm]:")
            for code in np.unique(first[first > 0]):
                lines += self._section_lines(np.flatnonzero(first == code), CHOICES[code])
        if unmet.any():
            lines.append("Q1's sections asked for by the policy in at least half the futures but not done (masked, "
                         "e.g. tamped in the last min_steps_between_tampings steps, or beyond the capacity):")
            lines += self._section_lines(np.flatnonzero(unmet), "asked, not done")
        return lines

    def _section_lines(self, at: np.ndarray, what: str) -> list[str]:
        """:meth:`_section_line` of the sections ``at`` in line order, at most :data:`SECTION_LINES` of them (the
        rest counted: their numbers are in plan.csv and the JSON)."""
        lines = [self._section_line(int(j), what) for j in at[:SECTION_LINES]]
        if len(at) > SECTION_LINES:
            lines.append(f"  ... and {len(at) - SECTION_LINES} more {what} (plan.csv, --json)")
        return lines

    def _section_line(self, j: int, what: str) -> str:
        st = {k: float(v[0, j]) for k, v in self.state.items()}
        lim = {k: float(v[j]) for k, v in self.limits_mm.items()}
        section = self.line.sections[j]
        known = [name for name, on in (("transition", section.register == "transition"),
                                       ("switch or crossing", section.register == "switch_or_crossing"),
                                       ("known wet", section.wet)) if on]
        tag = f" ({', '.join(known)})" if known else ""
        return (f"  {section.id}{tag} {what}: measured SD {st['measured_sd_mm']:.2f} (SD alert "
                f"{lim['sd_alert']:g}), peak {st['measured_peak_mm']:.2f} (alert {lim['alert']:g}, intervention "
                f"{lim['intervention']:g}, immediate action {lim['immediate_action']:g}), "
                f"{st['measurement_age_years']:.2f} years old; true SD {st['sd_mm']:.2f}, peak {st['peak_mm']:.2f}")

    def write(self, folder: Path) -> dict[str, str]:
        """Write ``plan.csv`` (quarter, date, section, choice, share of futures, recommended, then the section's
        state before the quarter's work, :data:`STATE_COLUMNS`; a row per choice a section gets in some future),
        ``costs.csv`` (quarter, date, mean, p10, p90 k€, then the mean of each cost part k€) and ``plan.png`` into
        ``folder``; returns their paths."""
        folder.mkdir(parents=True, exist_ok=True)
        paths = {"plan_csv": folder / "plan.csv", "costs_csv": folder / "costs.csv", "plot": folder / "plan.png"}
        self._write_choices(paths["plan_csv"])
        self._write_costs(paths["costs_csv"])
        self.plot(paths["plot"])
        return {k: str(v) for k, v in paths.items()}

    def _write_choices(self, path: Path) -> None:
        with path.open("w", newline="") as f:
            w = csv.writer(f, lineterminator="\n")
            w.writerow(["quarter", "from", "section", "choice", "share_of_futures", "recommended", *self.state])
            for q, (date, shares, rec) in enumerate(zip(self.dates, self.choice_share, self.recommended,
                                                       strict=True)):
                for j, (s, share, r) in enumerate(zip(self.line.sections, shares, rec, strict=True)):
                    state = [f"{v[q, j]:.3f}" for v in self.state.values()]
                    for code in np.flatnonzero(share[1:] > 0) + 1:
                        w.writerow([q + 1, date, s.id, CHOICES[code], f"{share[code]:.3f}", int(r == code), *state])

    def _write_costs(self, path: Path) -> None:
        with path.open("w", newline="") as f:
            w = csv.writer(f, lineterminator="\n")
            w.writerow(["quarter", "from", "cost_mean_keur", "cost_p10_keur", "cost_p90_keur",
                        *(f"{name}_mean_keur" for name in self.part_costs)])
            for q, (date, c) in enumerate(zip(self.dates, self.costs.T, strict=True)):
                w.writerow([q + 1, date, f"{c.mean():.3f}", f"{np.quantile(c, 0.1):.3f}",
                            f"{np.quantile(c, 0.9):.3f}", *(f"{v[:, q].mean():.3f}" for v in self.part_costs.values())])

    def plot(self, path: Path) -> None:
        """Save :meth:`figure` to ``path``."""
        self.figure().savefig(path)

    def figure(self) -> Any:
        """The plan along the line over time (share of futures in which each section gets a choice in each
        quarter, the recommended ones outlined, one colour per choice; km below, the file's section ids above)
        above the cumulative cost forecast by date (mean and 10-90 % band): a pyplot-free
        :class:`matplotlib.figure.Figure`."""
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
        self._section_axis(top, km)
        top.set_title(f"{self.line.name}: {self.policy} ({self.scenario}), {self.futures} futures from "
                      f"{self.line.as_of}")
        top.legend(loc="upper center", bbox_to_anchor=(0.5, -0.16), fontsize=7, ncol=5,
                   title=f"recommended: made in at least {RECOMMEND_SHARE:.0%} of the futures", title_fontsize=7)
        fig.colorbar(mesh, ax=top, label="share of futures tamping" if self.choices == ("tamp",)
                     else "share of futures with a choice")
        self._cost_panel(bottom)
        fig.tight_layout()
        return fig

    def _section_axis(self, ax: Any, km: np.ndarray) -> None:
        """The file's section ids along the top of the plan panel, at their sections' middles: every one up to
        :data:`SECTION_LABELS`, else every n-th (the first and the last always)."""
        ids = [s.id for s in self.line.sections]
        every = -(-len(ids) // SECTION_LABELS)
        shown = sorted({*range(0, len(ids), every), len(ids) - 1})
        if every > 1 and len(shown) > 1 and shown[-1] - shown[-2] < every / 2:
            shown.pop(-2)  # the last label would overlap its neighbour
        ids_axis = ax.secondary_xaxis("top")
        ids_axis.set_xticks([(km[i] + km[i + 1]) / 2 for i in shown], [ids[i] for i in shown], rotation=90,
                            fontsize=7)
        nth = f"{every}{'nd' if every == 2 else 'rd' if every == 3 else 'th'}"
        ids_axis.set_xlabel("section" if every == 1 else f"section (every {nth} labelled)", fontsize=8)

    def _cost_panel(self, ax: Any) -> None:
        """The cumulative cost forecast at the end of each quarter (mean and 10-90 % band), from 0 at ``as_of``,
        against the dates."""
        steps = len(self.dates)
        cum = np.concatenate([np.zeros((self.costs.shape[0], 1)), np.cumsum(self.costs, axis=1)], axis=1)
        x = np.arange(steps + 1)
        ax.fill_between(x, np.quantile(cum, 0.1, axis=0), np.quantile(cum, 0.9, axis=0), alpha=0.3,
                        label="10-90 % of futures")
        ax.plot(x, cum.mean(axis=0), label="mean")
        every = max(-(-steps // 8), 1)
        ticks = list(range(0, steps + 1, every))
        ax.set_xticks(ticks, [step_date(self.line.as_of, k, self.steps_per_year) for k in ticks], fontsize=8)
        ax.set_xlim(0, steps)
        ax.set_xlabel("date (cost summed from as_of to the end of each quarter)")
        ax.set_ylabel("cumulative cost [k€]")
        ax.legend(fontsize=7)


#: At most this many sections of one choice get a line of their numbers in the table.
SECTION_LINES = 8
#: At most this many section ids label the plot's line axis (more sections: every n-th).
SECTION_LABELS = 20


def _rounded(values: np.ndarray) -> list[float]:
    return [round(float(v), 3) for v in values]


def _record_state(state: dict[str, np.ndarray], step: int, obs: dict[str, Any], info: dict[str, Any]) -> None:
    """Store in ``state`` (:data:`STATE_COLUMNS`) the sections' state before step ``step``'s work, means over the
    futures: from the observation the policy acts on (the measured SD and peak, and the age of the measurement:
    each section's own where the problem has inspections, else the recording car's) and from the info of the step
    before (the true SD and peak after it)."""
    sd = np.asarray(obs["section_sd"], dtype=float)
    age = obs.get("section_measurement_age", np.broadcast_to(np.asarray(obs["measurement_age"]), sd.shape))
    values = {"measured_sd_mm": sd, "measured_peak_mm": obs["section_peak"], "measurement_age_years": age,
              "sd_mm": info["section_sd_mm"], "peak_mm": info["section_peak_mm"]}
    for key, value in values.items():
        state[key][step] = np.asarray(value, dtype=float).mean(axis=0)


@dataclass
class _Futures:
    """What :func:`_run_futures` gathers: choice shares (steps, sections, choices), costs (futures, steps) k€, the
    cost parts (each (futures, steps) k€), the state (:data:`STATE_COLUMNS`, each (steps, sections)) and the share
    of futures in which the policy asked for a choice that was not applied (steps, sections)."""

    share: np.ndarray
    costs: np.ndarray
    part_costs: dict[str, np.ndarray]
    state: dict[str, np.ndarray]
    unmet_share: np.ndarray


def _run_futures(env: Any, rule: Any, steps: int, seeds: list[int], progress: Callable[[int], Any] | None
                 ) -> _Futures:
    """Run ``rule`` for ``steps`` steps in the vector env ``env`` from the seeds ``seeds``, recording per step
    the sections' state before its work, the choices made and the costs in their parts."""
    futures = len(seeds)
    obs, info = env.reset(seed=seeds)
    sections = np.shape(obs["section_sd"])[1]
    out = _Futures(np.zeros((steps, sections, len(CHOICES))), np.zeros((futures, steps)), {},
                   {key: np.zeros((steps, sections)) for key in STATE_COLUMNS}, np.zeros((steps, sections)))
    for step in range(steps):
        _record_state(out.state, step, obs, info)
        action, _ = rule.predict(obs, deterministic=True)
        obs, reward, _, _, info = env.step(action)
        codes = np.asarray(info["section_choices"])  # (futures, sections)
        out.share[step] = (codes[..., None] == np.arange(len(CHOICES))).mean(axis=0)
        out.unmet_share[step] = ((np.asarray(action).reshape(codes.shape) != 0) & (codes == 0)).mean(axis=0)
        out.costs[:, step] = -np.asarray(reward)
        for key, value in info["costs"].items():
            if not key.startswith("_"):
                out.part_costs.setdefault(key, np.zeros((futures, steps)))[:, step] = np.asarray(value)
        if progress is not None:
            progress(1)
    return out


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

    from .evaluation.line_compare import without_engine

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
    run = _run_futures(env, rule, steps, [seed + i for i in range(futures)], progress)
    batch = env.batch  # the limits of each section's speed band: the same on every future's line
    assert batch is not None  # built at reset
    limits = {name: batch.section_limits(attr)[:cfg.n_sections] * 1e3 for name, attr in LIMIT_FIELDS.items()}
    env.close()
    dates = tuple(step_date(cfg.line.as_of, q, cfg.steps_per_year) for q in range(steps))
    params = getattr(rule, "params", None)
    return LinePlan(cfg.line, policy, float(years), futures, seed, dates, run.share, run.costs,
                    {k: v.sum(axis=1) for k, v in run.part_costs.items()}, fit, scenario, tuple(cfg.choices),
                    cfg.engine, cfg.pass_reuse_tolerance_m, part_costs=run.part_costs, state=run.state,
                    limits_mm=limits, policy_params=dict(params) if isinstance(params, dict) else {},
                    unmet_share=run.unmet_share,
                    steps_per_year=cfg.steps_per_year, measurement_interval=cfg.measurement_interval,
                    config_changes=without_engine(config))
