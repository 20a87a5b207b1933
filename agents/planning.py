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
next recording run and a new plan revise. Besides the choices and costs, the futures record per quarter and
section the state the policy decided on (the measured SD and mean-to-peak it observed, their age, the true SD and
mean-to-peak; means over the futures) and, where the env did not apply what the policy asked for, why (the reasons
of :data:`~trackenv_agents.plan_report.UNMET_REASONS`, read from the env's masks, config and step info as the env
resolves a step), with each section's limits and the rule's parameters.

This module makes the plan: the policy (:func:`line_policy`), the config (:func:`plan_config`) and the loop over
the futures (:func:`plan_line`). The finished plan and everything it says, the table, the JSON, the files and the
figure, are :mod:`trackenv_agents.plan_report`'s (:class:`LinePlan`); its names are importable from here too.
"""

from __future__ import annotations

import difflib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from trackenv.envs.choices import (
    CHOICES,
    IS_TRACK_WORK,
    NOTHING,
    action_type_for,
    enabled_codes,
    work_on_sections,
    work_per_code,
)
from trackenv.envs.line_config import LINE_FILE_FIELDS, SCENARIOS, LineConfig, check_horizon
from trackenv.envs.line_config import scenario as preset
from trackenv.envs.line_episode import fit_worst

from .plan_report import (
    GEOMETRY_NOTE,
    LIMIT_FIELDS,
    RECOMMEND_SHARE,
    SECTION_LABELS,
    SECTION_LINES,
    STATE_COLUMNS,
    UNMET_REASONS,
    LinePlan,
    line_summary,
    rule_thresholds,
    step_date,
    summary_lines,
    years_text,
)
from .shipped import SHIPPED_AGENTS, TRACK60_AGENT_NAME

#: The scenarios a line from a file can be planned in: those that leave the line's own fields (its sections,
#: lengths and traffic) to the file.
PLAN_SCENARIOS = tuple(name for name, fields_ in SCENARIOS.items() if not set(fields_) & set(LINE_FILE_FIELDS))
DEFAULT_POLICY = "grouped-threshold"
#: A line file whose last recording-car run is older than this before its ``as_of`` [year] gets a plan warning: the
#: recording car runs on a main line once or several times a year **[assumption]**, so such a file is likely old or
#: its ``as_of`` a typo.
STALE_RUN_YEARS = 2.0
#: A line plan warns where its possession capacity reaches each section less often than once in this many years
#: (a line's sections are tamped every few years, a quiet branch's every 10-15 **[assumption]**): the default
#: capacity of 6 sections a quarter on a 50 km line of 250 sections (the `long` preset's capacity is 25).
CAPACITY_CYCLE_YEARS = 10.0
#: The share of a line file's sections surveyed for wet spots before a plan starts beyond the file's known wet
#: zones (:func:`plan_config`): none, whatever the scenario's.
PLAN_SURVEYED_SHARE = 0.0

__all__ = ["CAPACITY_CYCLE_YEARS", "DEFAULT_POLICY", "GEOMETRY_NOTE", "LIMIT_FIELDS", "PLAN_SCENARIOS",
           "PLAN_SURVEYED_SHARE", "RECOMMEND_SHARE", "SECTION_LABELS", "SECTION_LINES", "STALE_RUN_YEARS",
           "STATE_COLUMNS", "UNMET_REASONS", "LinePlan", "capacity_cut", "check_capacity", "line_limits", "line_plan",
           "line_policy", "line_summary", "plan_config", "plan_line", "plan_warnings", "rule_thresholds", "step_date",
           "summary_lines", "trained_horizon_years", "unmet_reasons"]


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
    # the 60 m track's agent plans no line; the choice rules are named for the scenarios that have the choices
    known = [*rules, *(a for a in SHIPPED_AGENTS if a != TRACK60_AGENT_NAME)]
    close = difflib.get_close_matches(name, [*known, *every_rule()], n=1)
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    beyond = [r for r in every_rule() if r not in rules]
    more = f" (with --scenario choices, wet or defects also {', '.join(beyond)})" if beyond else ""
    raise ValueError(f"unknown policy {name!r}{hint}; known: {', '.join(known)}{more} or the path of a trained "
                     "policy (.zip)")


def plan_config(line: Any, scenario: str = "default", years: float | None = None, **config: Any) -> Any:
    """The :class:`~trackenv.envs.line_config.LineConfig` of ``line`` (a line file's path or a
    :class:`~trackenv.envs.line_file.LineDescription`) modelled as on the preset ``scenario``
    (:data:`PLAN_SCENARIOS`), with further ``config`` fields; ``years``: the plan's, its horizon (checked under
    that name, in the config's range: whole steps, at least one, at most ``MAX_HORIZON_YEARS``).

    What the line's owner knows of its wet spots is the file's known wet zones (surveyed from the start): a
    scenario's ``surveyed_share`` (the wet line surveys half its sections before the start) would reveal wet spots
    the model drew and the file does not know, and plan their drainage, so a plan takes none unless ``config``
    gives one (:data:`PLAN_SURVEYED_SHARE`); the other sections may hide a wet spot that a survey finds."""
    if scenario not in PLAN_SCENARIOS:
        raise ValueError(f"scenario must be one of {', '.join(PLAN_SCENARIOS)} (those that take the line's sections "
                         f"and traffic from its file), got {scenario!r}")
    if years is not None:
        steps_per_year = config.get("steps_per_year", LineConfig.steps_per_year)
        config["horizon_years"] = check_horizon("years", years, steps_per_year)
    config.setdefault("surveyed_share", PLAN_SURVEYED_SHARE)
    return preset(scenario, line=line, **config)


def episode_horizon(policy: Any, episode_years: float | None = None) -> float | None:
    """The length [years] of the episodes a plan of ``policy`` runs its futures in where it is not the plan's own:
    ``episode_years`` where given, else a trained policy's training episodes (:func:`trained_horizon_years`);
    None for a rule with none given. ValueError where a trained policy would run episodes other than its
    training's."""
    trained = trained_horizon_years(policy)
    if trained is not None and episode_years is not None and episode_years != trained:
        raise ValueError(f"the policy was trained on episodes of {trained:g} years and reads the time left in them: "
                         f"it cannot run futures of {episode_years:g}-year episodes")
    return trained if episode_years is None else episode_years


def trained_horizon_years(policy: Any) -> float | None:
    """The episode length a trained policy learnt on (its ``time`` feature is the share of that horizon gone);
    None for a rule, which reads no horizon."""
    return getattr(policy, "horizon_years", None)


def _record_state(state: dict[str, np.ndarray], step: int, obs: dict[str, Any], info: dict[str, Any],
                  renewing: np.ndarray, line_sections: tuple[int, ...] | None = None) -> None:
    """Store in ``state`` (:data:`STATE_COLUMNS`) the sections' state before step ``step``'s work, means over the
    futures: from the observation the policy acts on (the measured SD and peak, and the age of the measurement:
    each section's own where the problem has inspections, else the recording car's), from the info of the step
    before (the true SD and peak after it) and from the engine (``renewing``: whether a section's next tamping is
    a ballast renewal, per future and section). On a network, ``line_sections``: each line's sections, over which
    its recording car's age is spread."""
    sd = np.asarray(obs["section_sd"], dtype=float)
    line_age = np.asarray(obs["measurement_age"])
    if line_sections is not None:
        line_age = np.repeat(line_age, line_sections, axis=1)
    age = obs.get("section_measurement_age", np.broadcast_to(line_age, sd.shape))
    values = {"measured_sd_mm": sd, "measured_peak_mm": obs["section_peak"], "measurement_age_years": age,
              "sd_mm": info["section_sd_mm"], "peak_mm": info["section_peak_mm"],
              "renewal_due": np.asarray(renewing).reshape(sd.shape)}
    for key, value in values.items():
        state[key][step] = np.asarray(value, dtype=float).mean(axis=0)


def unmet_reasons(config: Any, want: np.ndarray, applied: np.ndarray, allowed: np.ndarray, measured_sd: np.ndarray,
                  clipped: np.ndarray, working: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Why the env did not apply what was asked in one step, per line and section: for each of
    :data:`UNMET_REASONS` the (lines, sections) bool of the sections asked for (``want``, action codes, not
    "nothing") that got nothing (``applied``, ``info["section_choices"]``), each under the first reason that holds
    in the order the env resolves a step: not enabled by ``config``, track work on a section not ``allowed``
    (the engine's :meth:`~trackenv.envs.line_episode.LineBatch.allowed` before the step), on a network's line the
    machine was not ``working`` on (lines,; default every line) the machine, then on a line the env
    ``clipped`` (``info["clipped"]``) the work that does not fit the capacity after the worse ``measured_sd``
    (the observation's, per section) asked for with it (:func:`~trackenv.envs.line_episode.fit_worst`), and the rest
    beyond the annual budget where the config has one; ``unknown`` what none explains."""
    want = np.asarray(want, dtype=np.int64)
    unmet = (want != NOTHING) & (np.asarray(applied) == NOTHING)
    enabled = enabled_codes(config.choices)[want]
    recent = IS_TRACK_WORK[want] & ~np.asarray(allowed, dtype=bool)
    passed = np.where(enabled & ~recent, want, NOTHING)  # what reaches the capacity, as the env masks it
    work = work_on_sections(work_per_code(config.choice_work), passed, config.length_factors)
    clipped = np.asarray(clipped, dtype=bool)[:, None]
    over_capacity = clipped & ~fit_worst(work, np.asarray(measured_sd, dtype=float), config.capacity)
    over_budget = clipped & (config.annual_budget > 0)
    elsewhere = np.zeros_like(clipped) if working is None else ~np.asarray(working, dtype=bool)[:, None]
    left = unmet.copy()
    out = {}
    for reason, why in zip(UNMET_REASONS, (~enabled, recent, elsewhere, over_capacity, over_budget, True),
                           strict=True):
        out[reason] = left & why
        left &= ~out[reason]
    return out


@dataclass
class _MachineRecord:
    """What a network's futures add (:func:`_run_futures`): each line's costs (futures, steps, lines) and cost
    parts (each the same shape) k€, the machine's line after each step, whether it moved and whether it did
    track work (a choice applied anywhere: only its line can have any) (futures, steps)."""

    line_costs: np.ndarray
    line_part_costs: dict[str, np.ndarray]
    machine: np.ndarray
    moved: np.ndarray
    worked: np.ndarray


@dataclass
class _Futures:
    """What :func:`_run_futures` gathers: choice shares (steps, sections, choices), costs (futures, steps) k€, the
    cost parts (each (futures, steps) k€), the state (:data:`STATE_COLUMNS`, each (steps, sections)), the share
    of futures in which the policy asked for a choice that was not applied (steps, sections), the number of
    futures in which that was for each of :data:`UNMET_REASONS` (each (steps, sections)), each section's largest
    true D1 mean-to-peak in any future and step (sections,) mm, its true SD at the start and at the end of each
    future (``sd_start_mm``, ``sd_end_mm``: (futures, sections) mm); on a network the ``machine``'s record; and
    ``renewed_share`` (steps, sections): of the futures that tamp a section in a step, the share in which that
    tamping is a ballast renewal (0 where none tamps it)."""

    share: np.ndarray
    costs: np.ndarray
    part_costs: dict[str, np.ndarray]
    state: dict[str, np.ndarray]
    unmet_share: np.ndarray
    unmet_reasons: dict[str, np.ndarray]
    peak_max_mm: np.ndarray
    sd_start_mm: np.ndarray
    sd_end_mm: np.ndarray
    machine: _MachineRecord | None = None
    renewed_share: np.ndarray | None = None

    def line(self, index: int, at: slice) -> _Futures:
        """A network's line ``index`` (its sections ``at``) as the futures of a line: its sections' shares,
        state, reasons and peaks, and its own costs (the moves left out)."""
        assert self.machine is not None  # a network's futures
        m = self.machine
        return _Futures(self.share[:, at], m.line_costs[:, :, index],
                        {k: v[:, :, index] for k, v in m.line_part_costs.items()},
                        {k: v[:, at] for k, v in self.state.items()}, self.unmet_share[:, at],
                        {k: v[:, at] for k, v in self.unmet_reasons.items()}, self.peak_max_mm[at],
                        self.sd_start_mm[:, at], self.sd_end_mm[:, at],
                        renewed_share=None if self.renewed_share is None else self.renewed_share[:, at])


#: why the env did not apply what was asked in one step: (want, applied codes, allowed, measured SD, info) ->
#: :data:`UNMET_REASONS` -> (futures, sections) bool
UnmetReasons = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]], dict[str, np.ndarray]]


def _run_futures(env: Any, rule: Any, steps: int, seeds: list[int], progress: Callable[[int], Any] | None,
                 why: UnmetReasons | None = None, line_sections: tuple[int, ...] | None = None,
                 asked: Callable[[np.ndarray], np.ndarray] | None = None) -> _Futures:
    """Run ``rule`` for ``steps`` steps in the vector env ``env`` from the seeds ``seeds``, recording per step
    the sections' state before its work, the choices made, why those asked for were not made (``why``; default
    the line's :func:`unmet_reasons`) and the costs in their parts (on a network, each line's too: give
    ``line_sections``, each line's number of sections). What was asked for is the rule's action, or
    ``asked(action)`` called after the rule's ``predict`` (on a network, what the line policies asked for before
    the dispatch)."""
    if why is None:
        def why(want, codes, allowed, measured_sd, info):
            return unmet_reasons(env.config, want, codes, allowed, measured_sd, info["clipped"])
    futures = len(seeds)
    obs, info = env.reset(seed=seeds)
    sections = np.shape(obs["section_sd"])[1]
    out = _Futures(np.zeros((steps, sections, len(CHOICES))), np.zeros((futures, steps)), {},
                   {key: np.zeros((steps, sections)) for key in STATE_COLUMNS}, np.zeros((steps, sections)),
                   {key: np.zeros((steps, sections), dtype=np.int64) for key in UNMET_REASONS}, np.zeros(sections),
                   np.array(info["section_sd_mm"], dtype=float), np.zeros((futures, sections)),
                   renewed_share=np.zeros((steps, sections)))
    if "line_costs" in info:  # a network: each line's costs, and the machine
        lines = np.shape(info["line_costs"])[1]
        out.machine = _MachineRecord(np.zeros((futures, steps, lines)), {}, np.zeros((futures, steps), np.int64),
                                     np.zeros((futures, steps), bool), np.zeros((futures, steps), bool))
    tamp = CHOICES.index("tamp")
    for step in range(steps):
        renewing = np.asarray(env.batch.renewing()).reshape(np.shape(obs["section_sd"]))
        _record_state(out.state, step, obs, info, renewing, line_sections)
        action, _ = rule.predict(obs, deterministic=True)
        allowed, measured_sd = env.batch.allowed(), obs["section_sd"]  # as the env resolves the step's work
        obs, reward, _, _, info = env.step(action)
        codes = np.asarray(info["section_choices"])  # (futures, sections)
        want = np.asarray(action if asked is None else asked(action)).reshape(codes.shape).astype(np.int64)
        out.share[step] = (codes[..., None] == np.arange(len(CHOICES))).mean(axis=0)
        tamped = codes == tamp
        assert out.renewed_share is not None
        out.renewed_share[step] = (tamped & renewing).sum(axis=0) / np.maximum(tamped.sum(axis=0), 1)
        out.unmet_share[step] = ((want != 0) & (codes == 0)).mean(axis=0)
        for key, value in why(want, codes, allowed, measured_sd, info).items():
            out.unmet_reasons[key][step] = value.sum(axis=0)
        out.costs[:, step] = -np.asarray(reward)
        # the worst future's true peak (a peak is never negative: zeros start the maximum)
        out.peak_max_mm = np.maximum(out.peak_max_mm, np.asarray(info["section_peak_mm"], dtype=float).max(axis=0))
        _record_parts(out.part_costs, info["costs"], step, (futures, steps))
        if out.machine is not None:
            m = out.machine
            m.line_costs[:, step] = info["line_costs"]
            _record_parts(m.line_part_costs, info["line_cost_parts"], step, m.line_costs.shape)
            m.machine[:, step], m.moved[:, step] = info["machine_line"], info["moved"]
            m.worked[:, step] = (codes != 0).any(axis=1)
        if progress is not None:
            progress(1)
    out.sd_end_mm = np.array(info["section_sd_mm"], dtype=float)  # after the last step (NEXT_STEP: not reset yet)
    return out


def _record_parts(parts: dict[str, np.ndarray], step_parts: dict[str, Any], step: int, shape: tuple[int, ...]) -> None:
    """Store step ``step``'s cost parts (a vector env's info: each part per future, its ``_`` mask keys left out)
    in ``parts`` (each of ``shape``, the step on the second axis)."""
    for key, value in step_parts.items():
        if not key.startswith("_"):
            parts.setdefault(key, np.zeros(shape))[:, step] = np.asarray(value)


def plan_warnings(plan: LinePlan, alone: bool = True) -> list[str]:
    """The warnings of a line's plan, each naming its line file, the line's own first: a last recording-car run
    more than :data:`STALE_RUN_YEARS` before ``as_of``, the sections that went beyond the model's validity
    (:meth:`LinePlan.validity_lines`), for a line planned ``alone`` (not a network's, whose machine may be
    elsewhere) a capacity that reaches each section less often than every :data:`CAPACITY_CYCLE_YEARS` and a plan
    that recommends nothing while the line runs past its SD alert (:func:`_idle_note`); then the history fit's
    notes on its sections. ``trackenv plan`` prints them and puts them in the JSON, a network's
    per line and all together."""
    source = plan.line.source
    notes = []  # the line's own first (the section notes may be many; stderr prints the first few)
    last = line_summary(plan.line)["last_recording"]
    if last is not None and last["years_before"] > STALE_RUN_YEARS:
        notes.append(f"{source}: the last recording-car run in the file ({last['date']}) is "
                     f"{last['years_before']:.1f} years before as_of: the plan's start projects the sections' state "
                     f"over those years; a newer run (or as_of) gives a surer start")
    notes += [f"{source}: {text.removeprefix('warning: ')}" for text in plan.validity_lines()]
    cycle = None if plan.capacity is None else len(plan.line.sections) / (plan.capacity * plan.steps_per_year)
    if alone and cycle is not None and cycle > CAPACITY_CYCLE_YEARS:
        notes.append(f"{source}: a possession capacity of {plan.capacity} sections a quarter reaches each of the "
                     f"line's {len(plan.line.sections)} sections once in {cycle:.1f} years at best: give the line's "
                     f"own (capacity: in the line file, or --set capacity=N)")
    idle = _idle_note(plan) if alone else None
    notes += [f"{source}: {idle}"] if idle else []
    return notes + [f"{source}, section {s.section}: {s.note}" for s in plan.fit.sections if s.note]


def _idle_note(plan: LinePlan) -> str | None:
    """Where the plan recommends nothing in any quarter while more sections end at or above their SD alert than
    started there: a sentence saying so, naming the rule's trigger where it lies above most sections' SD alert (a
    rule tuned on a slower preset line waits past this line's alert); else None."""
    end = plan.end_state()
    if plan.policy == "no-maintenance" or plan.recommended.any() or end is None or \
            "sections_at_sd_alert_end" not in end:  # (no maintenance recommends nothing by design)
        return None
    if end["sections_at_sd_alert_end"] <= end["sections_at_sd_alert_start"]:
        return None
    text = (f"nothing is recommended in {years_text(plan.years)} while the sections at or above their SD alert grow "
            f"from {end['sections_at_sd_alert_start']:.1f} to {end['sections_at_sd_alert_end']:.1f} of "
            f"{end['sections']} (means over the futures)")
    key = next((k for k in ("trigger_mm", "threshold_mm") if k in plan.policy_params), None)
    alert = plan.limits_mm.get("sd_alert")
    if key is not None and alert is not None:
        above = int((float(plan.policy_params[key]) > alert).sum())
        if above > alert.size / 2:
            text += (f": the rule's {key} {float(plan.policy_params[key]):g} mm is above the SD alert of {above} of "
                     f"{alert.size} sections (median {float(np.median(alert)):g} mm at their speeds), so it waits "
                     f"past it; --tune 8 tunes it on this line")
    return text


def line_limits(batch: Any, row: int, n_sections: int) -> dict[str, np.ndarray]:
    """The limits of each section's speed band [mm] (:data:`LIMIT_FIELDS`) of the line in ``row`` of the line
    engine ``batch``: the same in every future of a plan."""
    return {name: batch.section_limits(attr)[row * n_sections:(row + 1) * n_sections] * 1e3
            for name, attr in LIMIT_FIELDS.items()}


def line_plan(line: Any, cfg: Any, run: _Futures, limits: dict[str, np.ndarray], *, policy: str, rule: Any,
              years: float, seed: int, dates: tuple[str, ...], scenario: str, choices: tuple[str, ...],
              config: dict[str, Any], tuning: Any = None) -> LinePlan:
    """The :class:`LinePlan` of ``line`` (its description) modelled by ``cfg`` from its futures ``run`` (a line's:
    :meth:`_Futures.line` on a network), with its ``limits``; ``config``: the fields the plan was given;
    ``tuning``: the rule's tuning on the line, where asked (:class:`~trackenv_agents.plan_tuning.RuleTuning`)."""
    from trackenv.envs.line_fit import history_fit

    params = getattr(rule, "params", None)
    return LinePlan(line, policy, float(years), run.costs.shape[0], seed, dates, run.share, run.costs,
                    {k: v.sum(axis=1) for k, v in run.part_costs.items()}, history_fit(cfg), scenario, choices,
                    cfg.engine, cfg.pass_reuse_tolerance_m, part_costs=run.part_costs, state=run.state,
                    limits_mm=limits, policy_params=dict(params) if isinstance(params, dict) else {},
                    unmet_share=run.unmet_share, unmet_reasons=run.unmet_reasons,
                    min_steps_between_tampings=cfg.min_steps_between_tampings,
                    steps_per_year=cfg.steps_per_year, measurement_interval=cfg.measurement_interval,
                    config_changes=_changes(config, line), capacity=cfg.capacity, peak_max_mm=run.peak_max_mm,
                    tuning=tuning, sd_start_mm=run.sd_start_mm, sd_end_mm=run.sd_end_mm,
                    renewed_share=run.renewed_share)


def capacity_cut(config: dict[str, Any], cfg: Any) -> bool:
    """Whether the fields ``config`` given for a line hold a ``capacity`` that its config ``cfg`` cut to the line
    file's sections (silently: a file's config takes at most its sections)."""
    return "capacity" in config and config["capacity"] != cfg.capacity


def check_capacity(config: dict[str, Any], cfg: Any) -> None:
    """ValueError where the fields ``config`` given for a line plan hold a ``capacity`` above the line's sections
    (:func:`capacity_cut`)."""
    if capacity_cut(config, cfg):
        raise ValueError(f"capacity must be at most the line's {cfg.n_sections} sections, got {config['capacity']!r}")


def _changes(config: dict[str, Any], line: Any) -> dict[str, Any]:
    """The fields a plan was given that change its model: not the engine's options, nor a value the line file
    sets anyway (``--set speed_kmh=120`` on a 120 km/h file changes nothing, and the header said it did)."""
    from trackenv.envs.line_config import file_fields

    from .evaluation.line_compare import without_engine

    theirs = file_fields(line)
    return {k: v for k, v in without_engine(config).items() if not (k in theirs and theirs[k] == v)}


def plan_line(line: Any, *, policy: str = DEFAULT_POLICY, years: float = 3.0, futures: int = 8, seed: int = 0,
              scenario: str = "default", progress: Callable[[int], Any] | None = None, tune: int = 0,
              episode_years: float | None = None, executor: Any = None, batch_size: int = 32,
              **config: Any) -> LinePlan:
    """Plan maintenance on ``line`` (a line file's path or a :class:`~trackenv.envs.line_file.LineDescription`)
    for ``years`` from its ``as_of``: the policy ``policy`` (:func:`line_policy`) run in ``futures`` futures
    (episodes from seeds ``seed``, ``seed + 1``, ...) in one vector env, the line modelled as on the preset
    ``scenario`` (:data:`PLAN_SCENARIOS`); ``config``: further :class:`LineConfig` fields (costs, capacity, ...).
    ``tune``: where > 0, the rule's parameters are first tuned on that many futures of this line
    (:func:`~trackenv_agents.plan_tuning.tune_plan_rule`, its batches of ``batch_size`` episodes run by
    ``executor``, e.g. on Ray) instead of the shipped ones. ``progress(1)`` is called
    after each quarter (and the tuning, where asked, shows its own progress bar). ``episode_years``: the length of
    the futures' episodes, of which the plan takes its first ``years`` (default: ``years``, or a trained policy's
    training episodes, :func:`episode_horizon`); a future's draws depend on it, so policies compared on the same
    futures run the same."""
    from gymnasium.vector import AutoresetMode

    from trackenv.envs.line import TampingLineVectorEnv

    cfg = plan_config(line, scenario, years=years, **config)
    check_capacity(config, cfg)
    rule = line_policy(policy, cfg, scenario, years=years)
    tuning = None
    if tune:
        from .plan_tuning import check_apart, tune_plan_rule

        check_apart(seed, futures, tune)
        tuning = tune_plan_rule(rule, cfg, tune, progress=progress is not None, desc=f"tune {policy}",
                                executor=executor, batch_size=batch_size)
        rule = tuning.rule(rule, cfg)
    steps = cfg.horizon_steps
    horizon = episode_horizon(rule, episode_years)
    if horizon is not None and horizon != cfg.horizon_years:
        # the futures run in episodes of that length, of which the plan takes its first ``years`` (the line goes on
        # after the plan; a trained policy reads the time left in its training episode)
        cfg = cfg.replace(horizon_years=horizon)
        rule = rule.bind(cfg)
    env = TampingLineVectorEnv(futures, cfg, autoreset_mode=AutoresetMode.NEXT_STEP, action_type=action_type_for(cfg))
    run = _run_futures(env, rule, steps, [seed + i for i in range(futures)], progress)
    assert env.batch is not None  # built at reset
    limits = line_limits(env.batch, 0, cfg.n_sections)
    env.close()
    dates = tuple(step_date(cfg.line.as_of, q, cfg.steps_per_year) for q in range(steps))
    return line_plan(cfg.line, cfg, run, limits, policy=policy, rule=rule, years=years, seed=seed, dates=dates,
                     scenario=scenario, choices=tuple(cfg.choices), config=config, tuning=tuning)
