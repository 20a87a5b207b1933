"""A finished plan and how it is presented: :class:`LinePlan`, what :func:`~trackenv_agents.planning.plan_line`
gathered in its futures, as a table, plain data, CSV files and a figure.

The plan's numbers are per quarter and section: the share of futures in which the section gets each choice, the
state the policy decided on (:data:`STATE_COLUMNS`), the section's limits (:data:`LIMIT_FIELDS`), and how often
the env did not apply what the policy asked for, by its reason (:data:`UNMET_REASONS`); per future and quarter,
the costs in their parts. Everything a reader sees is made from these here: what the plan read from the line
file (:func:`line_summary`, so a unit mistake shows), the quarters' recommendations and costs, the numbers behind
the decision to take now against the limits and the rule's thresholds (:func:`rule_thresholds`), why sections
asked for were not done, when the recording car runs, and ``plan.csv``, ``costs.csv`` and ``plan.png``. Running
the futures (:mod:`trackenv_agents.planning`) and saying what they gave are kept apart so that either can change
without the other.
"""

from __future__ import annotations

import csv
import datetime as dt
import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from trackenv.envs.choices import CHOICES
from trackenv.envs.line_episode import VALID_PEAK_M
from trackenv.envs.line_file import DAYS_PER_YEAR

#: The share of futures from which a section's choice in a quarter is recommended.
RECOMMEND_SHARE = 0.5


def years_text(years: float) -> str:
    """"1 year", "3 years", "0.25 years": a plan's span in words."""
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
    transitions, switches or crossings, sections in known and in suspected wet zones, the file's known short
    defects (the sections that give a count, those with one or more, and their sum), the date of the last
    recording-car run in the
    history with its age [years before ``as_of``] (None without a history), and the line's own costs [k€] where
    the file gives any."""
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
        "suspected_wet": sum(s.wet_suspected for s in sections),
        "known_defects": {"sections_given": sum(s.defects is not None for s in sections),
                          "sections_with": sum(bool(s.defects) for s in sections),
                          "defects": sum(s.defects or 0 for s in sections)},
        "last_recording": None if last is None else {"date": last, "years_before": line.years_before(last)},
        "costs": dict(line.costs),
    }


def _span(values: list[float], fmt: str) -> str:
    low, high = values
    return format(low, fmt) if low == high else f"{low:{fmt}}-{high:{fmt}}"


def counted(n: int, what: str, plural: str) -> str:
    """``n`` things for people: "1 future", "8 futures"."""
    return f"{n} {what if n == 1 else plural}"


def summary_lines(summary: dict[str, Any]) -> list[str]:
    """The lines of text that repeat a :func:`line_summary` (two, and a third with the file's own costs)."""
    last = summary["last_recording"]
    run = ("no recording-car history" if last is None else
           f"last recording-car run {last['date']} ({last['years_before']:.2f} years before as_of)")
    sections = counted(summary["sections"], "section", "sections")
    return [f"read from the file: {sections}, {summary['length_km']:.2f} km; speed "
            f"{_span(summary['speed_kmh'], 'g')} km/h; tonnage {_span(summary['annual_mgt'], 'g')} MGT/year; "
            f"freight share {_span(summary['freight_share'], '.2f')}, freight axle load "
            f"{summary['freight_axle_load_t']:g} t",
            f"  {counted(summary['transitions'], 'transition', 'transitions')}, "
            f"{counted(summary['switches_crossings'], 'switch or crossing', 'switches or crossings')}, "
            f"{counted(summary['known_wet'], 'section in a known wet zone', 'sections in known wet zones')}; {run}",
            *([f"  own costs: {', '.join(f'{k} {v:g}' for k, v in summary['costs'].items())} (k€; the rest the "
               f"defaults)"] if summary.get("costs") else [])]


def end_state(plans: Sequence[Any]) -> dict[str, float] | None:
    """What line plans (:class:`LinePlan`, a line's or a network's lines) leave, against what they started from,
    over all their sections (means over the futures): the mean true SD [mm] and the number of sections at or above
    their SD alert limit at the start and at the end, and the number of ``sections`` (None where a plan does not
    know its start and end). A plan that spends little by leaving the track worse shows it here: its savings
    come back after the horizon."""
    if not plans or any(p.sd_start_mm is None or p.sd_end_mm is None for p in plans):
        return None
    start = np.concatenate([p.sd_start_mm for p in plans], axis=1)
    end = np.concatenate([p.sd_end_mm for p in plans], axis=1)
    out = {"sd_mean_mm_start": float(start.mean()), "sd_mean_mm_end": float(end.mean()), "sections": start.shape[1]}
    if all("sd_alert" in p.limits_mm for p in plans):
        alert = np.concatenate([p.limits_mm["sd_alert"] for p in plans])
        out["sections_at_sd_alert_start"] = float((start >= alert).sum(axis=1).mean())
        out["sections_at_sd_alert_end"] = float((end >= alert).sum(axis=1).mean())
    return out


#: The per-section state a plan records per quarter (means over the futures, before the quarter's work): what the
#: policy observed (the last measured SD and D1 mean-to-peak, their age) and the true SD and mean-to-peak.
STATE_COLUMNS = {"measured_sd_mm": "measured SD [mm]", "measured_peak_mm": "measured D1 mean-to-peak [mm]",
                 "measurement_age_years": "age of that measurement [year]", "sd_mm": "true SD [mm]",
                 "peak_mm": "true D1 mean-to-peak [mm]",
                 "renewal_due": "share of futures in which its next tamping is a ballast renewal (its tampings "
                                "since the last renewal reached the model's limit)"}
#: From this share of futures a recommended tamping is called a ballast renewal in the table.
RENEWAL_SHARE = 0.5
#: A section's quality limits in its speed band (:class:`~trackenv.physics.geometry.BandLimits`), by the name the
#: plan gives them [mm]: the D1 mean-to-peak's alert, intervention and immediate-action limits and the SD alert.
LIMIT_FIELDS = {"alert": "alert_m", "intervention": "intervention_m", "immediate_action": "immediate_action_m",
                "sd_alert": "sd_alert_m"}
GEOMETRY_NOTE = ("geometry is a notional cost of poor track geometry (poorer ride, faster wear of track and "
                 "vehicles), not money spent")

#: Why the env did not apply a choice the policy asked for (it became "nothing"), in the order the env checks
#: them (:meth:`~trackenv.envs.line_episode.LineBatch.resolve`), each future's section counted under the first
#: that holds: the scenario does not enable the choice; the section had track work within the last
#: ``min_steps_between_tampings`` steps; on a network, the machine was on another line or moving there; its work
#: did not fit the possession's capacity after the sections of worse measured SD asked for in the same step; the
#: step's work cost more than the annual budget had left; ``unknown`` where none of these explains it.
UNMET_REASONS = ("not_enabled", "recent_work", "machine", "capacity", "budget", "unknown")
#: At most this many sections of one choice get a line of their numbers in the table.
SECTION_LINES = 8
#: At most this many section ids of one choice in a quarter's row of the table (the rest counted: plan.csv and the
#: JSON list them all).
QUARTER_IDS = 12
#: At most this many section ids label the plot's line axis (more sections: every n-th).
SECTION_LABELS = 20


def rule_thresholds(params: dict[str, Any]) -> dict[str, float]:
    """A rule's level thresholds from its ``params``: those in mm (name ending ``_mm``: ``trigger_mm``,
    ``include_mm``, ``threshold_mm``, ``spot_peak_mm``, ...) that are on (above 0); margins, which are no
    levels, left out; none for a trained policy."""
    return {k: float(v) for k, v in params.items() if k.endswith("_mm") and "margin" not in k
            and isinstance(v, int | float) and not isinstance(v, bool) and v > 0}


#: The cost parts by what they are to a track manager: money spent on the track, traffic disrupted, and the notional
#: cost of poor geometry (:data:`GEOMETRY_NOTE`), each named and with its parts.
COST_GROUPS = {
    "spent": ("spent on the track (possessions, track work, inspections, surveys)",
              ("possession", "tamping", "renewal", "spot_tamping", "drainage", "inspection", "survey")),
    "disruption": ("traffic disrupted (speed restrictions, closures at the immediate-action limit)",
                   ("speed_restriction", "immediate_action")),
    "notional": ("notional (geometry, alerts)", ("geometry", "alert")),
}


def cost_groups(parts: dict[str, float]) -> dict[str, float]:
    """The mean cost parts ``parts`` [k€] summed by :data:`COST_GROUPS` (a group none of whose parts is there left
    out; a part of no group under ``other``, so that the groups add up to the total): what the headline cost is
    made of."""
    out = {name: float(sum(parts[k] for k in keys if k in parts))
           for name, (_, keys) in COST_GROUPS.items() if any(k in parts for k in keys)}
    grouped = {k for _, keys in COST_GROUPS.values() for k in keys}
    if set(parts) - grouped:
        out["other"] = float(sum(v for k, v in parts.items() if k not in grouped))
    return out


def cost_groups_text(parts: dict[str, float]) -> str:
    """:func:`cost_groups` of the mean cost parts ``parts`` [k€] as a line of a table ("" without parts)."""
    return "; ".join(f"{COST_GROUPS.get(name, ('other',))[0]} {value:.0f} k€"
                     for name, value in cost_groups(parts).items())


def scenario_note(scenario: str, line: Any = None, changes: dict[str, Any] | None = None) -> str | None:
    """What the preset ``scenario`` adds to the line file ``line``'s model (a description; None: not known), in a
    line of the table (None where nothing: the default preset on a file without known short defects or suspected
    wet zones): the wet line's hidden wet spots and the short-defect line's defects are the model's draws, not the
    file's; the file's own known defects and suspected wet zones are counted, with what the model does with them.
    The figures are the preset's, or those of the plan's ``changes`` (its ``--set`` fields) where it gives them."""
    from trackenv.envs.line_config import SCENARIOS, LineConfig

    fields = SCENARIOS.get(scenario, {})
    read = ("wet_spot_probability", "wet_spot_active_share", "suspected_wet_probability", "local_defects_mean",
            "segment_length_m", "local_defect_length_m", "local_defect_rate_factor")
    c = LineConfig.from_dict({**fields, **{k: v for k, v in (changes or {}).items() if k in read}})
    summary: dict[str, Any] = line_summary(line) if line is not None else {  # the file's defects, suspicions
        "sections": 0, "suspected_wet": 0, "known_defects": {"sections_given": 0, "sections_with": 0, "defects": 0}}
    sections, suspected, defects = summary["sections"], summary["suspected_wet"], summary["known_defects"]
    known = defects["sections_given"]
    parts = []
    if fields.get("choices"):
        parts.append(f"scenario {scenario}: every choice (spot tamping, drainage, renewal, inspections, surveys) and "
                     f"the contact sensor")
    if scenario == "wet":
        parts.append(f"beside the file's known wet zones the model draws hidden wet spots on about "
                     f"{c.wet_spot_probability:.0%} of the sections, {c.wet_spot_active_share:.0%} of them working "
                     f"from the start, which a survey finds (an assumption: a wetter line than the default)")
    defect = f"{c.local_defect_length_m:g} m each settling {c.local_defect_rate_factor:g} times faster"
    if known:
        free = known - defects["sections_with"]
        given = (f"the file's {defects['defects']} on {counted(defects['sections_with'], 'section', 'sections')}"
                 + (f" ({counted(free, 'section', 'sections')} known free of them)" if free else ""))
        rest = ("" if known == sections else f", the model's draws on the rest, about "
                f"{c.local_defects_mean:g} a section" if c.local_defects_mean > 0 else ", none on the rest")
        parts.append(f"short defects: {given}{rest} ({defect}, on a zone the faster of the two, counted once in a "
                     f"section's length: an assumption; the policies see the measurements, not these counts)")
    elif c.local_defects_mean > 0:
        parts.append(f"the model draws short defects (joints, welds, failed sleepers: about {c.local_defects_mean:g} "
                     f"a section, {defect}; an assumption, the file lists none)")
    if suspected:
        found = ", which a survey finds" if "survey" in c.choices else ""
        start = (f", working from the start in {c.wet_spot_active_share:.0%} of them" if c.wet_spot_active_share > 0
                 else "")
        parts.append(f"suspected wet: {counted(suspected, 'section', 'sections')}, each with a hidden wet spot in "
                     f"{c.suspected_wet_probability:.0%} of the futures (an assumption; the other sections "
                     f"{c.wet_spot_probability:.0%}) that starts at a quarter drawn over the horizon{start}{found}")
    return "; ".join(parts) or None


def recommend_count(futures: int) -> int:
    """In how many of ``futures`` a choice must be made to be recommended (:data:`RECOMMEND_SHARE` of them)."""
    return math.ceil(RECOMMEND_SHARE * futures - 1e-9)


#: The table's line under the quarters where a Q1 id carries a ``*`` (:meth:`LinePlan.model_read`).
MODEL_READING_NOTE = ("* on the model's reading only: the file has no run of the section since its last tamping; "
                      "measure it before acting")


def _marked(ids: Sequence[str], star: set[str] | frozenset[str], renewals: set[str]) -> list[str]:
    """Section ids as a quarter's row gives them: those of ``star`` (Q1 on the model's reading only) with a ``*``,
    the tampings of ``renewals`` marked "(renewal)"."""
    return [f"{i}{'*' if i in star else ''}{' (renewal)' if i in renewals else ''}" for i in ids]


def _listed(ids: Sequence[str]) -> str:
    """Section ids for a quarter's row: at most :data:`QUARTER_IDS`, the rest counted."""
    more = f" ... and {len(ids) - QUARTER_IDS} more (plan.csv)" if len(ids) > QUARTER_IDS else ""
    return " ".join(ids[:QUARTER_IDS]) + more


def _rounded(values: np.ndarray) -> list[float]:
    return [round(float(v), 3) for v in values]


@dataclass(frozen=True, eq=False)
class LinePlan:
    """A plan (:func:`plan_line`): ``choice_share`` (quarters, sections, choices) the share of futures in which
    each section gets each choice (indexed by code, :data:`~trackenv.envs.choices.CHOICES`) in each quarter,
    ``costs`` (futures, quarters) k€, ``parts`` the cost parts per future (k€, summed over the plan),
    ``part_costs`` the same per future and quarter ((futures, quarters) k€), ``state`` what the sections were
    before each quarter's work (:data:`STATE_COLUMNS`, each (quarters, sections), means over the futures),
    ``limits_mm`` each section's limits in its speed band (:data:`LIMIT_FIELDS`, each (sections,) mm),
    ``unmet_share`` (quarters, sections) the share of futures in which the policy asked for a choice the env did
    not apply, ``unmet_reasons`` the number of those futures per reason (:data:`UNMET_REASONS`, each (quarters,
    sections) int; ``min_steps_between_tampings`` the config's, which the reason ``recent_work`` names),
    ``policy_params`` the policy's parameters (a rule's thresholds; empty or the file of a trained policy),
    ``dates`` the first day of each quarter, the ``fit`` of the line's history, the ``scenario``, ``choices``,
    ``engine`` and ``pass_reuse_tolerance_m`` (m) the line was planned with, and the model's ``steps_per_year``
    and ``measurement_interval`` (steps between recording-car runs), the possession ``capacity`` (sections a
    quarter; None: not known), which the table names where a quarter recommends more, and ``peak_max_mm`` each
    section's largest true D1 mean-to-peak in any future (sections,; :meth:`beyond_validity`), and the rule's
    ``tuning`` on the line where the plan asked for one (:class:`~trackenv_agents.plan_tuning.RuleTuning`; None:
    the shipped parameters), and each section's true SD at the start and the end of each future (``sd_start_mm``,
    ``sd_end_mm``, (futures, sections) mm; None: not known): what the plan leaves (:meth:`end_state`); and
    ``renewed_share`` (quarters, sections): of the futures that tamp a section in a quarter, the share in which
    that tamping is a ballast renewal (None: not known)."""

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
    unmet_reasons: dict[str, np.ndarray] = field(default_factory=dict)
    min_steps_between_tampings: int = 1
    capacity: int | None = None
    peak_max_mm: np.ndarray | None = None
    tuning: Any = None
    sd_start_mm: np.ndarray | None = None
    sd_end_mm: np.ndarray | None = None
    renewed_share: np.ndarray | None = None

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
        every = f"every {counted(self.measurement_interval, 'quarter', 'quarters')}"
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
                if self.unmet_reasons:
                    row["asked_not_done_why"] = {i: self.unmet_counts(q, ids.index(i))
                                                 for i in row["asked_not_done"]}
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
            "cost_groups_mean_keur": cost_groups({k: float(v.mean()) for k, v in self.parts.items()}),
            "fit": {"fitted": len(self.fit.fitted), "median_residual_mm": self.fit.to_dict()["median_residual_mm"]},
            "beyond_validity_peak_mm": self.beyond_validity(),
            "q1_model_sd": [i for i, m in zip(ids, self.model_read()["sd"], strict=True) if m],
            "choices_on": self.choices_on(),
            "tuning": None if self.tuning is None else self.tuning.to_dict(),
            "end_state": self.end_state(),
        }

    def end_state(self) -> dict[str, float] | None:
        """What the plan leaves against what it started from (:func:`end_state`)."""
        return end_state([self])

    def end_state_line(self) -> str | None:
        """:meth:`end_state` as one line of the table (None where not known)."""
        e = self.end_state()
        if e is None:
            return None
        text = (f"left at the end (true state, mean of the futures): SD {e['sd_mean_mm_end']:.2f} mm on average "
                f"({e['sd_mean_mm_start']:.2f} at the start)")
        if "sections_at_sd_alert_end" in e:
            text += (f", {e['sections_at_sd_alert_end']:.1f} of {e['sections']} sections at or above their "
                     f"SD alert ({e['sections_at_sd_alert_start']:.1f} at the start)")
        return text

    def table(self) -> str:
        """The plan as text: what it was run on, per quarter its mean cost and the sections recommended for each
        choice, the first quarter's recommended sections against their limits, when the model's recording car
        runs, then the cost forecast."""
        from .evaluation.line_compare import changes_note, engine_note

        d = self.to_dict()
        engine = engine_note({"engine": self.engine, "pass_reuse_tolerance_m": self.pass_reuse_tolerance_m})
        capacity_from = "the file's" if self.line.capacity is not None else "--set capacity=N"
        lines = [f"Plan for {d['line']} from {d['as_of']}: {self.policy} (scenario {self.scenario}), "
                 f"{years_text(self.years)}, {counted(self.futures, 'future', 'futures')}{engine}"
                 f"{changes_note(self.config_changes)}",
                 *summary_lines(d["line_summary"]),
                 *([f"  possession capacity: {counted(self.capacity, 'section', 'sections')} of work a quarter "
                    f"({capacity_from})"] if self.capacity is not None else []),
                 *([f"  {note}"] if (note := scenario_note(self.scenario, self.line, self.config_changes)) else []),
                 *self.tuning_lines(),
                 f"{'quarter':<8} {'from':<11} {'cost k€':>8}  recommended (in at least "
                 f"{recommend_count(self.futures)} of the {self.futures} futures)"]
        guessed = {s.id for s, m in zip(self.line.sections, self.model_read()["sd"], strict=True) if m}
        starred = False
        for q, row in enumerate(d["quarters"]):
            star = guessed if q == 0 else set()
            starred |= any(i in star for name in self.choices for i in row[name])
            if self.choices == ("tamp",):
                what = self.tamp_text(q, row["tamp"], star) or "-"
            else:  # the tamping marked as on a tamping-only line (its renewals, the model's readings)
                renewals = self.renewals(q)
                what = "; ".join(f"{name} {_listed(_marked(row[name], star, renewals if name == 'tamp' else set()))}"
                                 for name in self.choices if row[name]) or "-"
            lines.append(f"Q{q + 1:<7} {row['from']:<11} {row['cost_mean_keur']:>8.1f}  {what}")
        if starred:
            lines.append(MODEL_READING_NOTE)
        lines += [*self.decision_lines(), self.recording_note(), *self.validity_lines()]
        c = d["cost_keur"]
        parts = ", ".join(f"{k} {v:.0f}" for k, v in d["cost_parts_mean_keur"].items())
        lines.append(f"cost over {years_text(self.years)}: {c['mean']:.0f} k€ mean, {c['p10']:.0f}-{c['p90']:.0f} k€ "
                     f"over 10-90 % of the futures ({parts})")
        groups = cost_groups_text(d["cost_parts_mean_keur"])
        if groups:
            lines.append(f"  {groups}")
        if "geometry" in self.parts:
            lines.append(f"  ({GEOMETRY_NOTE})")
        end = self.end_state_line()
        if end is not None:
            lines.append(end)
        fit = d["fit"]
        if fit["fitted"]:
            whose = "1 section's rate" if fit["fitted"] == 1 else f"{fit['fitted']} sections' rates"
            lines.append(f"history: {whose} fitted, median residual "
                         f"{fit['median_residual_mm']:.3f} mm (trackenv.envs.history_fit)")
        return "\n".join(lines)

    def tuning_lines(self) -> list[str]:
        """What the rule's parameters were tuned on: this line (``--tune``: what the tuning chose), or the
        preset, with how to tune them here (a rule with thresholds only; none for a trained policy)."""
        if self.tuning is not None:
            return [*self.tuning.lines(self.policy), *self.choices_line()]
        thresholds = rule_thresholds(self.policy_params)
        if not thresholds:
            return []
        shown = ", ".join(f"{k} {v:g}" for k, v in thresholds.items())
        return [f"parameters: the shipped ones ({shown}), tuned on the {self.scenario} preset's line; --tune 8 tunes "
                f"them on this line first (minutes)", *self.choices_line()]

    def choices_on(self) -> list[str] | None:
        """For a choice rule on a scenario with choices, the choices beyond tamping its parameters switch on (a
        scenario's tuned rule may switch every one off: the grouped threshold itself); None for another policy."""
        from .rules.choices import CHOICE_RULES, choices_on

        if self.policy not in CHOICE_RULES or self.choices == ("tamp",):
            return None
        return choices_on(self.policy_params)

    def choices_line(self) -> list[str]:
        """:meth:`choices_on` as a line of the table (none for another policy)."""
        on = self.choices_on()
        if on is None:
            return []
        if not on:
            return ["  choices beyond tamping: none (its parameters switch every one off: the grouped threshold "
                    "itself; --tune 8 searches them on this line)"]
        return [f"  choices beyond tamping: {', '.join(on)}"]

    def beyond_validity(self) -> dict[str, float]:
        """The sections whose true D1 mean-to-peak went beyond what the model represents
        (:data:`~trackenv.envs.line_episode.VALID_PEAK_M`) in some future, with that peak [mm]: their settlement
        ran away there, and the costs that follow are not physical."""
        if self.peak_max_mm is None:
            return {}
        limit = VALID_PEAK_M * 1e3
        return {s.id: float(p) for s, p in zip(self.line.sections, self.peak_max_mm, strict=True) if p > limit}

    def validity_lines(self) -> list[str]:
        """A warning for the table where :meth:`beyond_validity` names sections (none otherwise)."""
        beyond = self.beyond_validity()
        if not beyond:
            return []
        worst = ", ".join(f"{i} {p:.0f} mm" for i, p in sorted(beyond.items(), key=lambda kv: -kv[1])[:5])
        return [f"warning: the true D1 mean-to-peak of {len(beyond)} section(s) went beyond the model's validity "
                f"({VALID_PEAK_M * 1e3:.0f} mm) in some future ({worst}): their settlement ran away there and the "
                f"costs that follow are not physical (the scenario's defect and wet-spot rates: "
                f"local_defect_rate_factor, wet_spot_rate_factor)"]

    def tamp_text(self, quarter: int, tamped: list[str], star: set[str] | frozenset[str] = frozenset()) -> str:
        """The ids of the sections recommended for tamping in ``quarter`` as the table gives them: a ballast
        renewal marked "(renewal)", those of ``star`` with a ``*`` (Q1 on the model's reading only), and a note
        where they are more than the capacity."""
        text = _listed(_marked(tamped, star, self.renewals(quarter)))
        if self.capacity is not None and len(tamped) > self.capacity:
            text += (f" (more than the capacity of {self.capacity}: each future tamps at most {self.capacity}; "
                     f"listed, those of at least half the futures)")
        return text

    def renewals(self, quarter: int) -> set[str]:
        """The ids of the sections whose tamping in ``quarter`` is a ballast renewal in at least
        :data:`RENEWAL_SHARE` of the futures that tamp them (:attr:`renewed_share`; a plan without it: of all the
        futures, by ``renewal_due``, which can mark a tamping that is a renewal only in futures that do not tamp)."""
        due = self.state.get("renewal_due") if self.renewed_share is None else self.renewed_share
        if due is None:
            return set()
        return {s.id for s, share in zip(self.line.sections, due[quarter], strict=True) if share >= RENEWAL_SHARE}

    def decision_lines(self) -> list[str]:
        """A line per section recommended in the first quarter (the decision to take now): the measured SD and
        D1 mean-to-peak the policy saw against the limits of the section's speed band, the measurement's age and
        the true SD and mean-to-peak (means over the futures), under a line with the rule's level thresholds
        (:func:`rule_thresholds`); then the same for the sections the policy asked for in at least half the
        futures that the env did not work on (:attr:`unmet_share`), each with the env's reasons and in how many
        futures (:meth:`unmet_note`). The numbers are what the model had, not a reason it does not have."""
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
        if unmet.any() and not self.unmet_reasons:
            lines.append("Q1's sections asked for by the policy in at least half the futures but not done (masked, "
                         "e.g. tamped in the last min_steps_between_tampings steps, or beyond the capacity):")
            lines += self._section_lines(np.flatnonzero(unmet), "asked, not done")
        elif unmet.any():
            lines.append("Q1's sections asked for by the policy in at least half the futures but not done (why, in "
                         "how many futures):")
            lines += self._section_lines(np.flatnonzero(unmet), "asked, not done", lambda j: self.unmet_note(0, j))
        return lines

    def unmet_counts(self, quarter: int, section: int) -> dict[str, int]:
        """In how many futures the env did not apply what the policy asked for section index ``section`` in
        ``quarter`` (0: Q1), per reason (:data:`UNMET_REASONS`; those of no future left out), the most frequent
        first (ties in the env's order)."""
        counts = {k: int(self.unmet_reasons[k][quarter, section]) for k in UNMET_REASONS if k in self.unmet_reasons}
        return dict(sorted(((k, n) for k, n in counts.items() if n), key=lambda kv: -kv[1]))

    def unmet_note(self, quarter: int, section: int) -> str:
        """:meth:`unmet_counts` in words: "beyond the possession's capacity in 3 of 4 futures, tamped in the
        previous quarter in 1"."""
        parts = [f"{self._reason(k)} in {n}" for k, n in self.unmet_counts(quarter, section).items()]
        if parts:
            parts[0] += f" of {counted(self.futures, 'future', 'futures')}"
        return ", ".join(parts)

    def _reason(self, key: str) -> str:
        """The words for the reason ``key`` of :data:`UNMET_REASONS`."""
        if key == "recent_work":
            step = "quarter" if self.steps_per_year == 4 else "step"
            k = self.min_steps_between_tampings
            when = f"the previous {step}" if k == 1 else f"the last {k} {step}s"
            return f"{'tamped' if self.choices == ('tamp',) else 'worked on'} in {when}"
        return {"not_enabled": "not a choice of the scenario", "machine": "the machine on another line or moving",
                "capacity": "beyond the possession's capacity",
                "budget": "beyond the annual budget left", "unknown": "for a reason the plan does not know"}[key]

    def _section_lines(self, at: np.ndarray, what: str, why: Callable[[int], str] | None = None) -> list[str]:
        """:meth:`_section_line` of the sections ``at``, those measured first (then those on the model's reading
        only, :meth:`model_read`), each the worst measured SD first, at most :data:`SECTION_LINES` of them (the rest
        counted: their numbers are in plan.csv and the JSON); ``why(j)``: words after ``what`` in section ``j``'s
        line, in brackets."""
        if "measured_sd_mm" in self.state:
            at = at[np.lexsort((-self.state["measured_sd_mm"][0, at], self.model_read()["sd"][at]))]
        lines = [self._section_line(int(j), what if why is None else f"{what} ({why(int(j))})")
                 for j in at[:SECTION_LINES]]
        if len(at) > SECTION_LINES:
            where = "--json" if what.startswith("asked") else "plan.csv, --json"  # plan.csv has what was done
            lines.append(f"  ... and {len(at) - SECTION_LINES} more {what} ({where})")
        return lines

    def model_read(self) -> dict[str, np.ndarray]:
        """(sections,) bool each: where Q1's measured SD (``sd``) and D1 mean-to-peak (``peak``) are the model's
        own reading at ``as_of``, not a run of the file (no run since the section's last tamping, or a run without
        its peak: :func:`~trackenv.envs.line_fit.last_runs`). Such a number is a draw of the model: measure the
        section before acting on it. And ``age_years``: the age of the file's run at ``as_of`` (NaN where none),
        each section's own (the observation's line-wide age is the newest reading's, the model's where a section
        has no run)."""
        return self._model_read

    @functools.cached_property
    def _model_read(self) -> dict[str, np.ndarray]:
        """:meth:`model_read`, computed once per plan (every line of the table about a section asks)."""
        from trackenv.envs.line_fit import last_runs

        runs = last_runs(self.line)
        return {"sd": np.isnan(runs["last_sd_m"]), "peak": np.isnan(runs["last_peak_m"]),
                "age_years": runs["last_run_age_years"]}

    def _section_line(self, j: int, what: str) -> str:
        st = {k: float(v[0, j]) for k, v in self.state.items()}
        lim = {k: float(v[j]) for k, v in self.limits_mm.items()}
        section = self.line.sections[j]
        known = [name for name, on in (("transition", section.register == "transition"),
                                       ("switch or crossing", section.register == "switch_or_crossing"),
                                       ("known wet", section.wet), ("suspected wet", section.wet_suspected),
                                       (f"{counted(section.defects or 0, 'known short defect', 'known short defects')}",
                                        bool(section.defects))) if on]
        tag = f" ({', '.join(known)})" if known else ""
        if what == "tamp" and self.renewed_share is not None and self.renewed_share[0, j] >= RENEWAL_SHARE:
            what = f"tamp, a ballast renewal in {self.renewed_share[0, j]:.0%} of the futures that tamp it"
        elif what == "tamp" and self.renewed_share is None and st.get("renewal_due", 0.0) >= RENEWAL_SHARE:
            what = f"tamp, a ballast renewal in {st['renewal_due']:.0%} of the futures"
        sd = f"SD {st['measured_sd_mm']:.2f} (SD alert {lim['sd_alert']:g})"
        peak = (f"{st['measured_peak_mm']:.2f} (alert {lim['alert']:g}, intervention {lim['intervention']:g}, "
                f"immediate action {lim['immediate_action']:g})")
        truth = f"true SD {st['sd_mm']:.2f}, peak {st['peak_mm']:.2f}"
        read = self.model_read()
        if read["sd"][j]:  # a draw of the model where the file has no run: not a measurement
            return (f"  {section.id}{tag} {what}, on the model's reading only (the file has no run of it since its "
                    f"last tamping: measure it before acting): {sd}, peak {peak}; {truth}")
        peak_read = "the model's peak" if read["peak"][j] else "peak"
        return (f"  {section.id}{tag} {what}: measured {sd}, {peak_read} {peak}, {read['age_years'][j]:.2f} years "
                f"old; {truth}")

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
            w.writerow(["quarter", "from", "section", "choice", "share_of_futures", "recommended", *self.state,
                        "register", "wet", "defects"])
            for q, (date, shares, rec) in enumerate(zip(self.dates, self.choice_share, self.recommended,
                                                       strict=True)):
                for j, (s, share, r) in enumerate(zip(self.line.sections, shares, rec, strict=True)):
                    state = [f"{v[q, j]:.3f}" for v in self.state.values()]
                    known = [s.register, s.wet_text, "" if s.defects is None else s.defects]  # the file's, to filter
                    for code in np.flatnonzero(share[1:] > 0) + 1:
                        w.writerow([q + 1, date, s.id, CHOICES[code], f"{share[code]:.3f}", int(r == code), *state,
                                    *known])

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
        # each mark on a white halo (a navy drainage or a black renewal on a dark cell stays visible), the rarest
        # choices drawn last (a quarter's two drainages on top of its 77 surveys' neighbouring marks)
        marks = {name: np.nonzero(self.recommended == CHOICES.index(name)) for name in self.choices}
        on_top = sorted(self.choices, key=lambda name: -marks[name][0].size)
        for name, (q, j) in marks.items():
            x, z = (km[j] + km[j + 1]) / 2, 2.0 + 0.1 * on_top.index(name)
            top.scatter(x, q + 0.5, marker="s", s=12, facecolors="none", edgecolors="white", linewidths=2.4, zorder=z)
            top.scatter(x, q + 0.5, marker="s", s=12, facecolors="none", edgecolors=colours[name], linewidths=0.9,
                        label=name, zorder=z + 0.05)
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
        futures = counted(self.futures, "future", "futures")
        top.set_title(f"{self.line.name}: {self.policy} ({self.scenario}), {futures} from {self.line.as_of}")
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
