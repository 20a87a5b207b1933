"""The presentation of a plan (:mod:`trackenv_agents.plan_report`): what it names where the env did not apply what
the policy asked for, and the names :mod:`trackenv_agents.planning` gives of it."""

from __future__ import annotations

import numpy as np

from trackenv_agents import plan_report, planning
from trackenv_agents.plan_report import UNMET_REASONS, LinePlan


def _plan(choices: tuple[str, ...], min_steps: int, **reasons: list[int]) -> LinePlan:
    """A plan of one quarter, one section and four futures with only the counts of ``reasons`` (what
    :meth:`LinePlan.unmet_note` reads)."""
    counts = {k: np.array([[reasons.get(k, 0)]]) for k in UNMET_REASONS}
    return LinePlan(None, "p", 0.25, 4, 0, ("2026-01-01",), np.zeros((1, 1, 7)), np.zeros((4, 1)), {}, None,
                    choices=choices, unmet_reasons=counts, min_steps_between_tampings=min_steps)


def test_the_reasons_come_most_frequent_first_with_the_futures_counted_once():
    plan = _plan(("tamp",), 1, recent_work=1, capacity=3)
    assert plan.unmet_counts(0, 0) == {"capacity": 3, "recent_work": 1}
    assert plan.unmet_note(0, 0) == ("beyond the possession's capacity in 3 of 4 futures, tamped in the previous "
                                     "quarter in 1")
    assert _plan(("tamp",), 1).unmet_note(0, 0) == ""


def test_the_reasons_name_the_work_and_the_steps_between_tampings():
    """With choices beyond tamping the recent work is any track work; the steps are the config's."""
    worked = _plan(("tamp", "drainage"), 2, recent_work=2)
    assert worked.unmet_note(0, 0) == "worked on in the last 2 quarters in 2 of 4 futures"
    note = _plan(("tamp",), 1, not_enabled=1, budget=1, unknown=1).unmet_note(0, 0)
    assert note == ("not a choice of the scenario in 1 of 4 futures, beyond the annual budget left in 1, for a reason "
                    "the plan does not know in 1")


def test_planning_gives_the_reports_names():
    """Callers import the report's names from :mod:`trackenv_agents.planning` as before the report had a module."""
    for name in ("LinePlan", "RECOMMEND_SHARE", "STATE_COLUMNS", "LIMIT_FIELDS", "GEOMETRY_NOTE", "SECTION_LINES",
                 "SECTION_LABELS", "UNMET_REASONS", "line_summary", "summary_lines", "rule_thresholds", "step_date"):
        assert getattr(planning, name) is getattr(plan_report, name) and name in planning.__all__


def _line(defects: list[int | None], wet: list[str]):
    from trackenv.envs.line_file import LineDescription

    rows = [{"section": f"S{j}", "length_m": 200, "register": "plain", "wet": w, "years_since_tamping": 1,
             "tampings_since_renewal": 0, **({} if d is None else {"defects": d})}
            for j, (d, w) in enumerate(zip(defects, wet, strict=True))]
    return LineDescription.from_dict({"name": "n", "as_of": "2026-01-01", "sections": rows,
                                      "traffic": {"annual_mgt": 15, "speed_kmh": 100, "freight_share": 0.3}})


def test_the_scenario_note_counts_the_files_known_defects_and_suspected_wet_zones():
    """The header's scenario line says what the file adds to the model beside the preset: its known short defects
    (and whether the model draws them on the rest) and its suspected wet zones (with the probability, the plan's
    --set one where given); nothing on the default preset and a file without them."""
    from trackenv_agents.plan_report import scenario_note

    line = _line([2, None, 0, None], ["no", "suspected", "yes", "no"])
    assert scenario_note("default") is None and scenario_note("default", _line([None], ["yes"])) is None
    assert scenario_note("default", line) == (
        "short defects: the file's 2 on 1 section (1 section known free of them), none on the rest (2.4 m each "
        "settling 2.5 times faster, on a zone the faster of the two, counted once in a section's length: an "
        "assumption; the policies see the measurements, not these counts); suspected wet: 1 section, each with a "
        "hidden wet spot in 50% of the futures (an assumption; the other sections 10%) that starts at a quarter "
        "drawn over the horizon")
    defects = scenario_note("defects", line, {"suspected_wet_probability": 0.3})
    assert defects.startswith("scenario defects: every choice")
    assert ("short defects: the file's 2 on 1 section (1 section known free of them), the model's draws on the rest, "
            "about 1 a section (2.4 m each settling 5 times faster" in defects)
    assert ("suspected wet: 1 section, each with a hidden wet spot in 30% of the futures (an assumption; the other "
            "sections 10%) that starts at a quarter drawn over the horizon, which a survey finds") in defects
    wet = scenario_note("wet", line)
    assert "in 50% of the futures (an assumption; the other sections 35%) that starts at a quarter drawn over the " \
           "horizon, working from the start in 40% of them, which a survey finds" in wet
    assert "the model draws short defects" in scenario_note("defects", _line([None], ["no"]))
