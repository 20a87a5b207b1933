"""``trackenv plan``: a plan from a line file (table, JSON, CSV and plot), and every malformed file one line on
stderr with exit status 2."""

from __future__ import annotations

import csv
import json
import re
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from trackenv.envs.line_fit import FitWarning
from trackenv_agents.cli import main
from trackenv_agents.planning import plan_line

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "envs"))
from test_line_file import FAULTS, HISTORY, LINE, write  # noqa: E402  (the malformed files of the loader's tests)

#: The loader's test line with section B (a transition) measured rough (SD 2.6 -> 3.8 mm over two years): the
#: default grouped threshold (trigger 3.5 mm) calls a campaign on it in the first quarter.
ROUGH_B = HISTORY.replace("B,2023-06-01,1.2,4\nB,2024-06-01,1.5,5\nB,2025-06-01,1.9,6",
                          "B,2023-06-01,2.6,8\nB,2024-06-01,3.2,10\nB,2025-06-01,3.8,12")
FAST = {"engine": "fast", "pass_reuse_tolerance_m": 1e-3}


@pytest.fixture(scope="module")
def rough_plan(tmp_path_factory):
    """Half a year of the grouped threshold in two futures on the line with a rough section B, and its files."""
    folder = tmp_path_factory.mktemp("rough")
    plan = plan_line(write(folder, history=ROUGH_B), years=0.5, futures=2, **FAST)
    return plan, plan.write(folder / "plan")


def test_plan_writes_its_table_csv_and_plot(tmp_path, capsys):
    line = write(tmp_path)
    out = tmp_path / "plan"
    assert main(["plan", str(line), "--years", "0.5", "--futures", "2", "--json", "--out", str(out)]) == 0
    payload = json.loads(capsys.readouterr().out)
    assert payload["policy"] == "grouped-threshold" and len(payload["quarters"]) == 2
    assert payload["quarters"][0]["from"] == "2026-01-01" and payload["quarters"][1]["from"] == "2026-04-02"
    assert payload["cost_keur"]["p10"] <= payload["cost_keur"]["mean"] <= payload["cost_keur"]["p90"]
    assert payload["fit"]["fitted"] == 2
    assert list(payload)[:3] == ["line", "as_of", "line_summary"]  # what the plan was run on comes first
    with open(payload["files"]["costs_csv"]) as f:
        rows = list(csv.DictReader(f))
    assert [r["quarter"] for r in rows] == ["1", "2"]
    assert Path(payload["files"]["plot"]).stat().st_size > 10_000
    assert Path(payload["files"]["plan_csv"]).exists()


def test_the_plan_is_what_the_policy_does_in_the_futures(tmp_path):
    """The shares are those of the futures (multiples of 1/2 for two), and each future's quarters cost what its
    cost parts add up to."""
    plan = plan_line(write(tmp_path), policy="section-threshold", years=0.5, futures=2, capacity=4)
    assert plan.share.shape == (2, 4) and plan.costs.shape == (2, 2)
    rule_tamps = plan.share[0]
    assert set(np.unique(rule_tamps)) <= {0.0, 0.5, 1.0}
    total = sum(v for v in plan.parts.values())
    assert np.allclose(total, plan.costs.sum(axis=1))
    assert "Q1" in plan.table() and "k€" in plan.table()


def test_the_shipped_agent_plans_within_the_episodes_it_was_trained_on(tmp_path, capsys):
    """The agent's futures run in its 10-year training episodes, of which the plan takes the years asked; more
    years than it was trained on: one line, exit 2."""
    plan = plan_line(write(tmp_path), policy="cpi-agent", years=0.5, futures=2, capacity=4)
    assert plan.share.shape == (2, 4) and plan.costs.shape == (2, 2)
    assert np.allclose(sum(v for v in plan.parts.values()), plan.costs.sum(axis=1))
    assert main(["plan", str(write(tmp_path)), "--policy", "cpi-agent", "--years", "12"]) == 2
    err = capsys.readouterr().err  # refused before the work: no progress bar on the line of the message
    assert err == ("trackenv plan: years: the policy 'cpi-agent' was trained on 10-year episodes; plan at most 10 "
                   "years with it, got 12\n")
    assert main(["plan", str(write(tmp_path)), "--policy", "no-such-policy"]) == 2
    assert "cpi-agent" in capsys.readouterr().err


def test_every_shipped_agent_plans_by_its_name(tmp_path):
    """``cpi-choice-agent`` by name is the shipped file of the lines with every choice: on the wet scenario its
    plan is that of the same file given by path, to the cost, and its choices are the scenario's."""
    from trackenv_agents.shipped import CHOICE_AGENT_NAME, SHIPPED_AGENTS

    line = write(tmp_path)
    kw = {"years": 0.5, "futures": 2, "capacity": 4, "scenario": "wet"}
    by_name = plan_line(line, policy=CHOICE_AGENT_NAME, **kw)
    by_path = plan_line(line, policy=str(SHIPPED_AGENTS[CHOICE_AGENT_NAME]), **kw)
    assert np.array_equal(by_name.costs, by_path.costs)
    assert np.array_equal(by_name.choice_share, by_path.choice_share)
    assert by_name.choice_share.shape[-1] > 2  # choice codes beyond wait and tamp


@pytest.mark.parametrize("kind", list(FAULTS))
def test_a_malformed_file_is_one_line_and_exit_2(tmp_path, capsys, kind):
    files, expected = FAULTS[kind]
    line = write(tmp_path, **files)
    assert main(["plan", str(line), "--out", str(tmp_path / "plan")]) == 2
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert err.startswith("trackenv plan: ") and "\n" not in err and captured.out == ""
    assert expected[-1] in err
    assert not (tmp_path / "plan").exists()


def test_plan_refuses_an_unknown_policy_and_a_missing_file(tmp_path, capsys):
    assert main(["plan", str(write(tmp_path)), "--policy", "greedy"]) == 2
    err = capsys.readouterr().err
    # the line's rules and agents (not the 60 m track's, which plans no line), the choice rules for their scenarios
    assert "unknown policy 'greedy'; known: " in err and "cpi-track60-agent" not in err
    assert "cpi-choice-agent (with --scenario choices, wet or defects also choice-threshold," in err
    assert main(["plan", str(write(tmp_path)), "--policy", "grouped-treshold"]) == 2
    assert "unknown policy 'grouped-treshold' (did you mean 'grouped-threshold'?)" in capsys.readouterr().err
    assert main(["plan", str(tmp_path / "none.yaml")]) == 2
    assert "no such line file" in capsys.readouterr().err
    assert main(["plan", str(tmp_path / "sections.csv")]) == 2  # the sections given for the line file
    assert capsys.readouterr().err.rstrip().endswith(
        "got a str (a CSV file: give the YAML file that names it under 'sections' or 'history')")
    # the 60 m track's agent plans with a planner that needs the SD of every step, which a line file's line lacks
    assert main(["plan", str(write(tmp_path)), "--policy", "cpi-track60-agent"]) == 2
    assert "policy 'cpi-track60-agent' cannot run on this line: needs an SD measured every step" in \
        capsys.readouterr().err


@pytest.mark.slow
def test_the_example_line_round_trips_through_plan(tmp_path, capsys):
    """file -> env -> plan -> CSV and plot, on the example line that ships (a short plan)."""
    from trackenv.lines import EXAMPLE

    assert main(["plan", str(EXAMPLE), "--years", "0.5", "--futures", "2", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert out.startswith("Plan for Example Valley Line (synthetic) from 2026-01-01")
    assert "80 sections' rates fitted" in out
    for name in ("plan.csv", "costs.csv", "plan.png"):
        assert (tmp_path / name).stat().st_size > 0


def test_a_plan_with_every_choice_recommends_each_by_name(tmp_path, capsys):
    """In a scenario with every choice the plan records each choice's share of futures (they add up to one per
    section and quarter), the rule takes that scenario's tuned parameters, and the JSON, table and CSV name the
    choices."""
    from trackenv.envs.choices import CHOICES
    from trackenv_agents.planning import PLAN_SCENARIOS

    plan = plan_line(write(tmp_path), policy="choice-threshold", scenario="wet", years=0.5, futures=2)
    assert plan.choice_share.shape == (2, 4, 7) and np.allclose(plan.choice_share.sum(axis=2), 1.0)
    assert plan.choices == ("tamp", "spot_tamp", "drainage", "renew", "inspect", "survey")
    assert np.allclose(plan.share, 1.0 - plan.choice_share[:, :, 0])
    # the wet line's tuned rule surveys every section not surveyed yet in the first quarter
    assert plan.choice_share[0, :, 6].sum() > 0
    quarter = plan.to_dict()["quarters"][0]
    assert set(plan.choices) <= set(quarter) and plan.to_dict()["scenario"] == "wet"
    # the plot outlines each recommended choice on a white halo, a rarer choice above a commoner one
    top = plan.figure().axes[0]
    marks = {c.get_label(): c for c in top.collections if c.get_label() in plan.choices}
    counts = {name: int((plan.recommended == CHOICES.index(name)).sum()) for name in marks}
    assert counts["survey"] > 0
    for name, mark in marks.items():
        (halo,) = [c for c in top.collections if abs(c.zorder - (mark.zorder - 0.05)) < 1e-9]
        assert np.array_equal(halo.get_offsets(), mark.get_offsets()) and halo.get_edgecolor()[0].tolist() == [1.0] * 4
        assert all(mark.zorder > other.zorder for o, other in marks.items() if counts[o] > counts[name])
    out = tmp_path / "plan"
    assert main(["plan", str(write(tmp_path)), "--scenario", "wet", "--policy", "choice-threshold", "--years", "0.5",
                 "--futures", "2", "--out", str(out)]) == 0
    table = capsys.readouterr().out
    assert "(scenario wet)" in table and "the model draws hidden wet spots on about 35% of the sections" in table
    with open(out / "plan.csv") as f:
        rows = list(csv.DictReader(f))
    assert rows and {r["choice"] for r in rows} <= set(plan.choices)
    assert "survey" in {r["choice"] for r in rows}
    # the command offers exactly the scenarios that take the line from its file
    assert PLAN_SCENARIOS == ("default", "choices", "wet", "defects")


def test_a_choice_rule_needs_a_scenario_with_the_choices(tmp_path, capsys):
    """A rule of the choices on the default scenario, which has tamping only: one line naming the scenarios it
    needs (it is no unknown policy)."""
    assert main(["plan", str(write(tmp_path)), "--policy", "choice-threshold"]) == 2
    assert capsys.readouterr().err == ("trackenv plan: policy 'choice-threshold' uses the choices beyond tamping: "
                                       "plan with --scenario choices, wet or defects\n")


def test_the_engine_options_reach_the_plan_and_are_named(tmp_path, capsys):
    """``--engine fast --pass-reuse-mm 1`` plan on the faster passes (the config fields, the JSON and the table's
    first line say so); none given: the preset's classic engine, every pass computed; out of range: one line and
    exit status 2. Both plan the same tampings here and cost within a percent (the engines' costs are compared in
    tests/envs/test_line_engine.py and tests/envs/test_line_pass_reuse.py)."""
    line = write(tmp_path)
    argv = ["plan", str(line), "--years", "1", "--futures", "2", "--json", "--out", str(tmp_path / "plan")]
    assert main([*argv, "--engine", "fast", "--pass-reuse-mm", "1"]) == 0
    fast = json.loads(capsys.readouterr().out)
    assert fast["engine"] == "fast" and fast["pass_reuse_mm"] == pytest.approx(1.0)
    assert main(argv) == 0
    classic = json.loads(capsys.readouterr().out)
    assert classic["engine"] == "classic" and classic["pass_reuse_mm"] == 0.0
    assert [q["tamp"] for q in fast["quarters"]] == [q["tamp"] for q in classic["quarters"]]
    assert fast["cost_keur"]["mean"] == pytest.approx(classic["cost_keur"]["mean"], rel=1e-2)
    plan = plan_line(line, years=0.5, futures=2, engine="fast", pass_reuse_tolerance_m=5e-4)
    assert plan.table().splitlines()[0].endswith("2 futures, engine fast, pass reuse 0.5 mm")
    assert plan_line(line, years=0.5, futures=2).table().splitlines()[0].endswith("2 futures")
    assert main([*argv, "--pass-reuse-mm", "3"]) == 2
    assert "--pass-reuse-mm must be in [0, 2] mm, got 3" in capsys.readouterr().err


def test_the_years_are_checked_under_their_own_name(tmp_path, capsys):
    """Less than a quarter (one model step) or more than 100 years: an error naming ``years`` (the config's
    horizon is what it sets), before the fit and the futures."""
    for bad in (0.1, 101.0):
        with pytest.raises(ValueError, match=r"years must lie in \[0.25, 100\]"):
            plan_line(write(tmp_path), years=bad, futures=1)
    assert main(["plan", str(write(tmp_path)), "--years", "0.2"]) == 2
    assert capsys.readouterr().err == "trackenv plan: years must lie in [0.25, 100], got 0.2\n"


def test_the_fits_warnings_come_after_the_progress_bar_and_in_the_json(tmp_path, capsys):
    """A line file whose rate factor contradicts its history: `trackenv plan` says so on its own line after the
    progress bar (not inside it), once, and lists it under "warnings" in --json."""
    from test_line_fit import SECTIONS
    from test_line_fit import write as write_fit_line

    line = write_fit_line(tmp_path / "line", sections=SECTIONS.replace("0.5,1.5,7,", "0.5,1.5,7,1.7"))
    argv = ["plan", str(line), "--years", "0.5", "--futures", "1", "--out", str(tmp_path / "plan")]
    assert main(argv) == 0
    notes = [r for r in re.split(r"[\r\n]", capsys.readouterr().err) if "contradicts the history" in r]
    assert len(notes) == 1 and notes[0].startswith("trackenv plan: warning: ") and "section K11.23" in notes[0]
    assert main([*argv, "--json"]) == 0
    payload = json.loads(capsys.readouterr().out)
    fit = [w for w in payload["warnings"] if "section K11.23" in w]
    assert len(fit) == 1 and "rate_factor 1.7 contradicts the history" in fit[0]


def test_the_plan_repeats_what_it_read_from_the_file(tmp_path):
    """The table's two lines after the first and the JSON's ``line_summary`` say what the plan ran on, in the
    file's units, so a unit mistake in the file shows: sections, length, speed, tonnage and freight ranges, axle
    load, known zones, and the last recording-car run with its age; a file without a history says so."""
    from trackenv.envs.line_file import load_line
    from trackenv_agents.planning import line_summary

    plan = plan_line(write(tmp_path), years=0.5, futures=1, **FAST)
    summary = plan.to_dict()["line_summary"]
    assert summary == {"sections": 4, "length_km": 0.8, "speed_kmh": [100.0, 100.0], "annual_mgt": [15.0, 30.0],
                       "freight_share": [0.4, 0.4], "freight_axle_load_t": 22.5, "transitions": 1,
                       "switches_crossings": 1, "known_wet": 1, "suspected_wet": 0,
                       "known_defects": {"sections_given": 0, "sections_with": 0, "defects": 0},
                       "last_recording": {"date": "2025-12-01", "years_before": pytest.approx(31 / 365.25)},
                       "costs": {}}
    read = plan.table().splitlines()[1:3]
    assert read[0] == ("read from the file: 4 sections, 0.80 km; speed 100 km/h; tonnage 15-30 MGT/year; freight "
                       "share 0.40, freight axle load 22.5 t")
    assert read[1] == ("  1 transition, 1 switch or crossing, 1 section in a known wet zone; last recording-car run "
                       "2025-12-01 (0.08 years before as_of)")
    assert not plan.table().splitlines()[3].startswith("  own costs")
    (tmp_path / "bare").mkdir()
    bare = write(tmp_path / "bare", line=LINE.replace("history: history.csv\n", ""), history=None)
    assert line_summary(load_line(bare))["last_recording"] is None
    (tmp_path / "own").mkdir()
    own = load_line(write(tmp_path / "own", line=LINE + "costs:\n  speed_restriction_cost: 4\n"))
    assert line_summary(own)["costs"] == {"speed_restriction_cost": 4.0}
    (tmp_path / "marked").mkdir()
    from test_line_file import SUSPECTED

    marked = line_summary(load_line(write(tmp_path / "marked", sections=SUSPECTED)))
    assert marked["suspected_wet"] == 1 and marked["known_wet"] == 1
    assert marked["known_defects"] == {"sections_given": 2, "sections_with": 1, "defects": 2}
    from trackenv_agents.plan_report import summary_lines

    assert summary_lines(line_summary(own))[2] == "  own costs: speed_restriction_cost 4 (k€; the rest the defaults)"


def test_the_plan_records_the_state_each_quarter_decided_on(rough_plan, tmp_path):
    """Per quarter and section the plan keeps the means over the futures of what the policy observed (the measured
    SD and peak, their age) and of the true SD and peak before the quarter's work: the first quarter's are the
    reset's observation and info; B, tamped in the first quarter, is smoother in the second, while its measurement
    (no recording run until the fourth quarter) is the same, a quarter older."""
    from gymnasium.vector import AutoresetMode

    from trackenv.envs.line import TampingLineVectorEnv
    from trackenv.physics.geometry import QualityLimits
    from trackenv_agents.planning import STATE_COLUMNS, plan_config

    plan, files = rough_plan
    assert set(plan.state) == set(STATE_COLUMNS) and all(v.shape == (2, 4) for v in plan.state.values())
    env = TampingLineVectorEnv(2, plan_config(write(tmp_path, history=ROUGH_B), years=0.5, **FAST),
                               autoreset_mode=AutoresetMode.NEXT_STEP)
    obs, info = env.reset(seed=[0, 1])
    env.close()
    assert np.allclose(plan.state["measured_sd_mm"][0], obs["section_sd"].mean(axis=0))
    assert np.allclose(plan.state["peak_mm"][0], info["section_peak_mm"].mean(axis=0))
    assert plan.recommended[0, 1] == 1 and plan.share[0, 1] == 1.0  # B tamped in every future
    assert plan.state["sd_mm"][1, 1] < plan.state["sd_mm"][0, 1] - 1.0
    assert np.allclose(plan.state["measured_sd_mm"][1], plan.state["measured_sd_mm"][0])
    assert np.allclose(plan.state["measurement_age_years"], [[0.0] * 4, [0.25] * 4])
    limits = QualityLimits.en13848().for_speed(100 / 3.6)  # the test line's speed band
    assert plan.limits_mm["sd_alert"] == pytest.approx([limits.sd_alert_m * 1e3] * 4)
    assert plan.limits_mm["immediate_action"] == pytest.approx([limits.immediate_action_m * 1e3] * 4)
    quarter = plan.to_dict()["quarters"][0]
    assert quarter["state"]["sd_mm"] == pytest.approx(plan.state["sd_mm"][0], abs=1e-3)
    with open(files["plan_csv"]) as f:
        row = next(r for r in csv.DictReader(f) if r["quarter"] == "1" and r["section"] == "B")
    assert float(row["measured_sd_mm"]) == pytest.approx(plan.state["measured_sd_mm"][0, 1], abs=1e-3)
    assert {"measured_peak_mm", "measurement_age_years", "sd_mm", "peak_mm"} <= set(row)
    assert (row["register"], row["wet"], row["defects"]) == ("transition", "no", "")  # the file's, to filter by


def test_the_table_gives_the_numbers_behind_the_decision_to_take_now(rough_plan, monkeypatch):
    """For each section recommended in the first quarter a line of its measured SD and peak against the limits of
    its speed band, under the rule's thresholds (at most ``SECTION_LINES`` per choice, the rest counted); then when
    the model's next recording run falls (after a plan of half a year; read in the fifth quarter of a longer one);
    and what the geometry cost is."""
    import dataclasses

    from trackenv_agents import plan_report

    plan, _ = rough_plan
    text = plan.table()
    b = plan.state["measured_sd_mm"][0, 1]
    assert ("Q1's recommended sections as the policy saw them (grouped-threshold: trigger_mm 3.5, include_mm 1.75), "
            "means over the futures [mm]:") in text
    assert (f"  B (transition) tamp: measured SD {b:.2f} (SD alert 2.25), peak "
            f"{plan.state['measured_peak_mm'][0, 1]:.2f} (alert 12, intervention 15.5, immediate action 26), "
            "0.59 years old; true SD") in text  # its run of 2025-06-01 (it read 0.00: D's model reading at as_of)
    assert "recording-car runs: Q1 reads each section's last run in the file (the model's own at as_of where it " \
           "has none); the model's then every 4 quarters: the next 2027-01-01, after the plan" in text
    longer = dataclasses.replace(plan, dates=plan.dates * 3)  # six quarters
    assert longer.recording_runs() == [(4, "2027-01-01"), (8, "2028-01-01")]
    assert longer.recording_note().endswith("every 4 quarters: 2027-01-01 (read in Q5)")
    assert "geometry is a notional cost of poor track geometry" in text
    assert list(np.flatnonzero(plan.recommended[0])) == [1, 3]  # B and D: D above include_mm
    monkeypatch.setattr(plan_report, "SECTION_LINES", 1)
    capped = plan.table()
    assert "  B (transition) tamp:" in capped and "  D (known wet) tamp:" not in capped
    assert "  ... and 1 more tamp (plan.csv, --json)" in capped


def test_the_table_names_the_sections_asked_for_but_not_done(tmp_path):
    """A section the rule asks for that the env masks (D, rough but tamped a quarter ago: at most one tamping per
    step, ``min_steps_between_tampings``) is not recommended; the table gives its numbers under their own line with
    that reason, and the JSON lists it per quarter with its reasons."""
    from test_line_file import SECTIONS

    sections = SECTIONS.replace("D,200,plain,yes,,0.5,3", "D,200,plain,yes,,0.25,3")
    plan = plan_line(write(tmp_path, sections=sections, history=ROUGH_B + "D,2025-12-01,4.0,10\n"), years=0.5,
                     futures=2, **FAST)
    assert plan.recommended[0, 3] == 0 and plan.recommended[1, 3] == 1  # done a quarter later
    assert plan.unmet_share is not None and list(plan.unmet_share[0]) == [0.0, 0.0, 0.0, 1.0]
    text = plan.table()
    assert "Q1's sections asked for by the policy in at least half the futures but not done" in text
    assert (f"  D (known wet) asked, not done (tamped in the previous quarter in 2 of 2 futures): measured SD "
            f"{plan.state['measured_sd_mm'][0, 3]:.2f} (SD alert") in text
    assert "masked, e.g." not in text  # the reason, not a list of what it might be
    assert plan.to_dict()["quarters"][0]["asked_not_done"] == ["D"]
    assert plan.to_dict()["quarters"][0]["asked_not_done_why"] == {"D": {"recent_work": 2}}


class _AskEverySection:
    """A policy that asks for a tamping of every section in every step (the rules keep within the capacity)."""

    def predict(self, obs, deterministic=True):
        return np.ones(np.shape(obs["section_sd"]), dtype=np.int8), None


def test_the_table_says_a_section_asked_for_was_beyond_the_capacity(tmp_path, monkeypatch):
    """With a capacity of one section and every section asked for, the env keeps the worst measured (B) and drops
    the rest: the table names the capacity for them in Q1; B, tamped in Q1 and asked again in Q2, was tamped in the
    previous quarter. Every section asked for and not done is counted under exactly one reason."""
    from trackenv_agents import planning

    monkeypatch.setattr(planning, "line_policy", lambda *args, **kwargs: _AskEverySection())
    plan = plan_line(write(tmp_path, history=ROUGH_B), years=0.5, futures=2, capacity=1, **FAST)
    assert list(plan.recommended[0]) == [0, 1, 0, 0]
    assert list(plan.unmet_share[0]) == [1.0, 0.0, 1.0, 1.0]
    counted = sum(plan.unmet_reasons.values())
    assert np.array_equal(counted, np.rint(plan.unmet_share * plan.futures)) and not plan.unmet_reasons["unknown"].any()
    assert list(plan.unmet_reasons["capacity"][0]) == [2, 0, 2, 2]
    assert plan.unmet_reasons["recent_work"][1, 1] == 2
    text = plan.table()
    assert "  A asked, not done (beyond the possession's capacity in 2 of 2 futures): measured SD" in text
    assert "  B (transition) asked, not done" not in text  # done in Q1
    assert plan.unmet_note(1, 1) == "tamped in the previous quarter in 2 of 2 futures"
    assert plan.to_dict()["quarters"][0]["asked_not_done_why"]["C"] == {"capacity": 2}


def test_the_table_says_a_section_asked_for_was_beyond_the_budget(tmp_path):
    """An annual budget below one campaign's cost: the rule asks for B in both futures and the env drops it for
    the budget, which the table names."""
    plan = plan_line(write(tmp_path, history=ROUGH_B), years=0.5, futures=2, annual_budget=1.0, **FAST)
    assert plan.unmet_reasons["budget"][0, 1] == 2 and plan.recommended[0, 1] == 0
    assert "  B (transition) asked, not done (beyond the annual budget left in 2 of 2 futures): measured SD" in \
        plan.table()


def test_each_section_not_done_gets_the_first_reason_the_env_checks():
    """:func:`~trackenv_agents.planning.unmet_reasons` on one step of two lines by hand: a choice the config does
    not enable, track work on a section worked on too recently, work beyond the capacity (the worse measured SD
    kept), beyond the budget on a clipped line, and a drop no reason explains (a line the env did not clip)."""
    from types import SimpleNamespace

    from trackenv.envs.choices import code
    from trackenv_agents.planning import unmet_reasons

    config = SimpleNamespace(choices=("tamp", "inspect"), choice_work={"tamp": 1.0, "spot_tamp": 0.5, "drainage": 0.5,
                             "renew": 2.0, "inspect": 0.0, "survey": 0.0}, length_factors=np.ones(5), capacity=2,
                             annual_budget=100.0)
    tamp, inspect, drainage = code("tamp"), code("inspect"), code("drainage")
    want = np.array([[drainage, tamp, tamp, tamp, tamp], [inspect, tamp, 0, 0, 0]])
    applied = np.array([[0, 0, tamp, 0, 0], [0, tamp, 0, 0, 0]])  # line 0: D fits the capacity, not the budget
    allowed = np.array([[True, False, True, True, True], [True] * 5])
    sd = np.array([[1.0, 9.0, 5.0, 3.0, 2.0], [1.0] * 5])
    why = unmet_reasons(config, want, applied, allowed, sd, clipped=np.array([True, False]))
    assert {k: v.astype(int).tolist() for k, v in why.items()} == {
        "not_enabled": [[1, 0, 0, 0, 0], [0] * 5],
        "recent_work": [[0, 1, 0, 0, 0], [0] * 5],
        "machine": [[0] * 5, [0] * 5],
        "capacity": [[0, 0, 0, 0, 1], [0] * 5],
        "budget": [[0, 0, 0, 1, 0], [0] * 5],
        "unknown": [[0] * 5, [1, 0, 0, 0, 0]],
    }
    # the same step on a network whose machine worked on line 0 only: line 1's drop is the machine's
    why = unmet_reasons(config, want, applied, allowed, sd, clipped=np.array([True, False]),
                        working=np.array([True, False]))
    assert why["machine"].astype(int).tolist() == [[0] * 5, [1, 0, 0, 0, 0]] and not why["unknown"].any()


def test_the_costs_come_in_their_parts_and_the_plot_names_sections_and_dates(rough_plan):
    """costs.csv carries each cost part's mean per quarter (they add up to the quarter's mean cost); the plot labels
    the line with the file's section ids and the cost panel with dates."""
    plan, files = rough_plan
    with open(files["costs_csv"]) as f:
        rows = list(csv.DictReader(f))
    parts = [k for k in rows[0] if k.endswith("_mean_keur") and k != "cost_mean_keur"]
    assert {"possession_mean_keur", "tamping_mean_keur", "geometry_mean_keur"} <= set(parts)
    for row in rows:
        assert sum(float(row[k]) for k in parts) == pytest.approx(float(row["cost_mean_keur"]), abs=1e-2)
    assert float(rows[0]["tamping_mean_keur"]) > 0 and float(rows[1]["tamping_mean_keur"]) == 0
    axes = plan.figure().axes
    labels = {t.get_text() for ax in [*axes, *(c for a in axes for c in a.child_axes)] for t in ax.get_xticklabels()}
    assert {"A", "B", "C", "D"} <= labels and {"2026-01-01", "2026-07-03"} <= labels


def test_a_section_line_names_the_files_suspected_wet_zone_and_known_defects(tmp_path):
    """Section B, rough and recommended in Q1, suspected wet with two known short defects in the file: its line in
    the table says so beside its register."""
    from test_line_file import SECTIONS

    rows = [row + (",defects" if row.startswith("section,") else "" if row.startswith("#") else ",")
            for row in SECTIONS.splitlines()]
    marked = "\n".join(rows).replace("B,200,transition,no,,3,2,", "B,200,transition,Suspected,,3,2,2") + "\n"
    assert "Suspected,,3,2,2" in marked
    plan = plan_line(write(tmp_path, sections=marked, history=ROUGH_B), years=0.25, futures=1, **FAST)
    assert "  B (transition, suspected wet, 2 known short defects) tamp: measured SD" in plan.table()


def test_a_recommended_tamping_that_is_a_ballast_renewal_says_so(tmp_path):
    """Section B, rough and tamped in the first quarter, has had 8 tampings since its last renewal: the model renews
    it instead (its cost is a renewal's), and the table and plan.csv say so; B with 2 tampings is a tamping."""
    from test_line_file import SECTIONS

    due = SECTIONS.replace("B,200,transition,no,,3,2", "B,200,transition,no,,3,8")
    assert due != SECTIONS
    plan = plan_line(write(tmp_path, sections=due, history=ROUGH_B), years=0.25, futures=2, **FAST)
    b = [s.id for s in plan.line.sections].index("B")
    assert plan.recommended[0, b] == 1 and plan.state["renewal_due"][0, b] == 1.0
    assert "B (transition) tamp, a ballast renewal in 100% of the futures that tamp it:" in plan.table()
    assert plan.renewed_share[0, b] == 1.0
    (q1,) = [row for row in plan.table().splitlines() if row.startswith("Q1 ")]
    assert "B (renewal)" in q1
    rows = [r for r in csv.DictReader((Path(plan.write(tmp_path / "plan")["plan_csv"])).open())
            if r["section"] == "B"]
    assert rows and float(rows[0]["renewal_due"]) == 1.0
    plain = plan_line(write(tmp_path, history=ROUGH_B), years=0.25, futures=2, **FAST)
    assert plain.state["renewal_due"][0, b] == 0.0 and "a ballast renewal" not in plain.table()


def test_a_quarter_recommending_more_than_the_capacity_says_so(rough_plan):
    """Recommended sections are those of at least half the futures: where they are more than the capacity, the
    quarter's row says that no future tamps them all."""
    import dataclasses

    plan, _ = rough_plan
    q = int(np.flatnonzero((plan.recommended == 1).sum(axis=1) >= 2)[0])
    n = int((plan.recommended[q] == 1).sum())
    assert "more than the capacity" not in plan.table()
    tight = dataclasses.replace(plan, capacity=n - 1)
    assert f"(more than the capacity of {n - 1}: each future tamps at most {n - 1};" in tight.table()


def test_a_section_beyond_the_models_validity_is_named_by_its_id(tmp_path, capsys):
    """A section whose file gives it a rate factor of 100 (against its history) runs away within a year: the plan
    names the section by its id in its table, its JSON and its warnings (not the engine's warning, which names a
    row of its batch). (Short defects settling 100 times faster did this before a fitted section's start and rate
    took its defects as its SD counts them; its history now holds its growth.)"""
    from test_line_file import SECTIONS

    sections = SECTIONS.replace("tampings_since_renewal\n", "tampings_since_renewal,rate_factor\n")
    sections = "\n".join(row + ("," if not row.startswith(("section", "B,")) else ",100" if row.startswith("B,")
                                 else "") for row in sections.strip().splitlines()) + "\n"
    out = tmp_path / "plan"
    args = ["plan", str(write(tmp_path, sections=sections)), "--policy", "no-maintenance", "--years", "1",
            "--futures", "2", "--engine", "fast", "--pass-reuse-mm", "1", "--json", "--out", str(out)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitWarning)
        # the runaway's settlement outgrows the implicit step's Newton iterations too (expected here)
        warnings.filterwarnings("ignore", message="the implicit settlement step did not converge",
                                category=RuntimeWarning)
        assert main(args) == 0
    captured = capsys.readouterr()
    d = json.loads(captured.out)
    assert set(d["beyond_validity_peak_mm"]) == {"B"} and d["beyond_validity_peak_mm"]["B"] > 250
    assert any("went beyond the model's validity (250 mm) in some future (B " in w for w in d["warnings"])
    assert "has left the model's validity" not in captured.err


def test_the_plan_says_what_it_leaves_against_what_it_started_from(rough_plan, tmp_path):
    """The true SD at the start of each future is the reset's, at the end the last step's; ``end_state`` and the
    table's line give their means and the sections at their SD alert. Without maintenance the rough section B is
    left rougher than under the rule, which tamps it: the same start, a worse end."""
    plan, _ = rough_plan
    e = plan.to_dict()["end_state"]
    assert plan.sd_start_mm.shape == plan.sd_end_mm.shape == (2, 4)
    assert e["sd_mean_mm_start"] == pytest.approx(plan.state["sd_mm"][0].mean())
    alert = plan.limits_mm["sd_alert"]
    assert e["sections_at_sd_alert_start"] == pytest.approx((plan.sd_start_mm >= alert).sum(axis=1).mean())
    assert "left at the end (true state, mean of the futures): SD " in plan.table()
    idle = plan_line(write(tmp_path, history=ROUGH_B), years=0.5, futures=2, policy="no-maintenance", **FAST)
    np.testing.assert_array_equal(idle.sd_start_mm, plan.sd_start_mm)
    assert (idle.sd_end_mm[:, 1] > plan.sd_end_mm[:, 1] + 1.0).all()  # B: tamped by the rule, not without it
    assert idle.end_state()["sd_mean_mm_end"] > e["sd_mean_mm_end"]


def test_plan_compares_policies_on_the_same_futures(tmp_path, capsys):
    """``trackenv plan FILE --compare A,B``: each policy's plan on the same futures, their costs paired per
    future (a policy against itself would differ by 0; here each cost is its own plan's, in ``compare.csv`` per
    future), what each leaves, and each plan's files in a folder of its own."""
    from trackenv_agents.cli import DEFAULT_PLAN_POLICY, main
    from trackenv_agents.planning import DEFAULT_POLICY

    assert DEFAULT_PLAN_POLICY == DEFAULT_POLICY
    line, out = write(tmp_path, history=ROUGH_B), tmp_path / "cmp"
    argv = ["plan", str(line), "--years", "0.5", "--futures", "2", "--engine", "fast", "--pass-reuse-mm", "1",
            "--out", str(out)]
    assert main([*argv, "--compare", "grouped-threshold,no-maintenance", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    rows = {r["policy"]: r for r in d["comparison"]["results"]}
    assert list(rows) == ["grouped-threshold", "no-maintenance"] and d["comparison"]["reference"] == "grouped-threshold"
    assert (d["comparison"]["engine"], d["comparison"]["pass_reuse_mm"]) == ("fast", 1.0)
    alone = plan_line(line, years=0.5, futures=2, policy="no-maintenance", **FAST)
    np.testing.assert_allclose(rows["no-maintenance"]["cost_keur"], alone.costs.sum(axis=1), rtol=1e-12)
    diff = np.subtract(rows["no-maintenance"]["cost_keur"], rows["grouped-threshold"]["cost_keur"])
    assert rows["no-maintenance"]["vs_first"]["mean_keur"] == pytest.approx(diff.mean())
    assert rows["grouped-threshold"]["vs_first"]["mean_keur"] == 0.0
    left = {name: row["end_state"]["sd_mean_mm_end"] for name, row in rows.items()}
    assert left["no-maintenance"] > left["grouped-threshold"]
    assert (out / "1-grouped-threshold" / "plan.csv").is_file() and (out / "2-no-maintenance" / "plan.csv").is_file()
    lines = (out / "compare.csv").read_text().splitlines()
    assert lines[0] == "future,seed,grouped-threshold_keur,no-maintenance_keur" and len(lines) == 3
    assert main([*argv, "--compare", "grouped-threshold,no-maintenance"]) == 0
    table = capsys.readouterr().out
    assert "Policies compared on the same 2 futures of" in table and "no-maintenance" in table
    assert "cost: k€ over the plan, mean" in table  # a line's (it named the network's moves on a line too)


@pytest.mark.parametrize("extra, message", [
    (["--compare", "grouped-threshold"], "--compare needs at least two policies"),
    (["--compare", "grouped-threshold,grouped-threshold"], "--compare grouped-threshold: given more than once"),
    (["--compare", "grouped-threshold,,no-maintenance"], "an empty item (a comma too many?)"),
    (["--compare", "grouped-threshold,no-such-rule"], "no-such-rule"),
    (["--compare", "a,b", "--tune", "2"], "tune one policy at a time"),
    (["--compare", "a,b", "--policy", "no-maintenance"], "give the policies to compare in --compare"),
])
def test_plan_compare_refuses_what_it_cannot_compare_in_one_line(tmp_path, capsys, extra, message):
    from trackenv_agents.cli import main

    assert main(["plan", str(write(tmp_path)), "--out", str(tmp_path / "o"), *extra]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


def test_compared_with_a_trained_policy_every_policy_runs_its_training_episodes(tmp_path, capsys):
    """A future's draws depend on its episode's length, and cpi-agent runs ten-year episodes (it reads the time
    left in them): compared with it, a rule runs the same ten-year futures, so the two are paired."""
    from trackenv_agents.cli import main

    line = write(tmp_path, history=ROUGH_B)
    assert main(["plan", str(line), "--years", "0.5", "--futures", "2", "--engine", "fast", "--pass-reuse-mm", "1",
                 "--out", str(tmp_path / "cmp"), "--compare", "grouped-threshold,cpi-agent", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)["comparison"]
    assert d["episode_years"] == 10.0
    rule = plan_line(line, years=0.5, futures=2, episode_years=10.0, **FAST)
    short = plan_line(line, years=0.5, futures=2, **FAST)
    costs = d["results"][0]["cost_keur"]
    np.testing.assert_allclose(costs, rule.costs.sum(axis=1), rtol=1e-12)
    assert not np.allclose(costs, short.costs.sum(axis=1))  # the half-year episodes draw other futures
    with pytest.raises(ValueError, match="trained on episodes of 10 years"):
        plan_line(line, policy="cpi-agent", years=0.5, futures=1, episode_years=5.0, **FAST)


def test_a_plan_says_which_first_readings_are_the_models_and_lists_the_worst_first(rough_plan):
    """Section D has no recording-car run in the file: Q1's SD there is the model's draw, and its line says so (it
    read "measured SD", and an engineer would act on it); the JSON lists it. A quarter's sections are listed worst
    measured SD first (the worst were hidden behind "... and 2 more" in line order)."""
    from trackenv_agents.plan_report import _listed

    plan, _ = rough_plan
    assert plan.to_dict()["q1_model_sd"] == ["D"] and plan.model_read()["sd"].tolist() == [False, False, False, True]
    guessed = plan._section_line(3, "tamp")
    assert guessed.startswith("  D (known wet) tamp, on the model's reading only (the file has no run of it since "
                              "its last tamping: measure it before acting): SD ")
    assert "years old" not in guessed  # (it read "0.00 years old", as if just measured)
    assert "B (transition) tamp: measured SD" in plan._section_line(1, "tamp")
    listed = [line.split()[0] for line in plan._section_lines(np.arange(4), "tamp")]
    measured = [j for j in np.argsort(-plan.state["measured_sd_mm"][0], kind="stable") if j != 3]
    assert listed == [plan.line.sections[j].id for j in measured] + ["D"]  # the model's reading last
    assert listed[0] == "B"  # the rough section
    assert "recommended (in at least 1 of the 2 futures)" in plan.table()  # "half" of two futures is either one
    ids = [f"S{i}" for i in range(15)]
    assert _listed(ids) == " ".join(ids[:12]) + " ... and 3 more (plan.csv)" and _listed(ids[:3]) == "S0 S1 S2"


def test_a_capacity_above_the_lines_sections_is_refused_not_cut(tmp_path, capsys):
    """A config cuts a capacity above the file's sections to their number (the default 6 on 4 sections); given to
    a plan it was cut silently while the header said "changed: capacity=300": now refused, naming the limit."""
    line = write(tmp_path)
    with pytest.raises(ValueError, match="capacity must be at most the line's 4 sections, got 5"):
        plan_line(line, years=0.25, futures=1, capacity=5)
    assert main(["plan", str(line), "--set", "capacity=5", "--years", "0.25", "--futures", "1", "--out",
                 str(tmp_path / "o")]) == 2
    assert "capacity must be at most the line's 4 sections, got 5" in capsys.readouterr().err
    assert plan_line(line, years=0.25, futures=1, capacity=4, **FAST).capacity == 4


def test_a_wet_plan_knows_the_files_wet_zones_only(tmp_path):
    """The wet preset surveys half its sections before the start; on a line file that revealed wet spots the model
    drew as known and planned their drainage (a probe's plan drained a section the file did not flag). A plan knows
    the file's known wet zones (D) and nothing else unless ``surveyed_share`` is given."""
    from trackenv.envs.line import TampingLine
    from trackenv_agents.planning import plan_config

    cfg = plan_config(write(tmp_path), "wet", years=0.5)
    assert cfg.surveyed_share == 0.0 and plan_config(write(tmp_path), "wet", surveyed_share=0.5).surveyed_share == 0.5
    for seed in range(4):
        obs, _ = TampingLine(cfg).reset(seed=seed)
        assert obs["section_survey"].tolist() == [-1, -1, -1, 1]


def test_a_plan_that_recommends_nothing_while_the_line_passes_its_alert_warns(tmp_path, capsys):
    """Half a year of the shipped grouped threshold (trigger 3.5 mm) on the fit test line recommends nothing while
    sections pass their SD alert (2.25 mm at 100 km/h): a warning names the trigger and --tune; a network's line
    (whose machine may be elsewhere) gets none; stderr prints at most PRINTED_WARNINGS, the table counts them."""
    from test_line_fit import write as write_fit_line

    from trackenv_agents.cli import PRINTED_WARNINGS, _say_warnings
    from trackenv_agents.planning import plan_warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitWarning)
        plan = plan_line(write_fit_line(tmp_path / "line"), years=0.5, futures=1, **FAST)
    end = plan.end_state()
    assert not plan.recommended.any() and end["sections_at_sd_alert_end"] > end["sections_at_sd_alert_start"]
    (idle,) = [w for w in plan_warnings(plan) if "nothing is recommended" in w]
    assert "the rule's trigger_mm 3.5 mm is above the SD alert of 4 of 4 sections" in idle and "--tune 8" in idle
    assert not [w for w in plan_warnings(plan, alone=False) if "nothing is recommended" in w]
    import dataclasses  # no maintenance recommends nothing by design: no warning (noise in a --compare)

    assert not [w for w in plan_warnings(dataclasses.replace(plan, policy="no-maintenance"))
                if "nothing is recommended" in w]
    _say_warnings([f"note {i}" for i in range(PRINTED_WARNINGS + 3)])
    err = capsys.readouterr().err.splitlines()
    assert len(err) == PRINTED_WARNINGS + 1
    assert err[-1] == "trackenv plan: warning: ... and 3 more (--json lists every one)"


def test_the_cost_is_split_into_spend_disruption_and_notional_and_a_choice_rule_says_what_it_uses(rough_plan,
                                                                                                   tmp_path):
    """The headline cost is mostly the notional geometry cost: the table and the JSON split it into money spent on
    the track, disrupted traffic and the notional parts (the groups add up to the total). A choice rule's plan says
    which choices its parameters switch on: on the `choices` preset none (its tuned rule is the grouped threshold;
    an engineer saw "the choices" do nothing and could not see why)."""
    from trackenv_agents.plan_report import COST_GROUPS

    plan, _ = rough_plan
    d = plan.to_dict()
    groups = d["cost_groups_mean_keur"]
    assert set(groups) == set(COST_GROUPS) and sum(groups.values()) == pytest.approx(d["cost_keur"]["mean"])
    assert groups["spent"] > 0 and f"spent on the track (possessions, track work, inspections, surveys) " \
        f"{groups['spent']:.0f} k€" in plan.table()
    assert "parameters: the shipped ones (trigger_mm 3.5, include_mm 1.75)" in plan.table()
    quiet = plan_line(write(tmp_path), policy="choice-threshold", scenario="choices", years=0.25, futures=1, **FAST)
    assert "choices beyond tamping: none (its parameters switch every one off" in quiet.table()
    wet = plan_line(write(tmp_path), policy="choice-threshold", scenario="wet", years=0.25, futures=1, **FAST)
    assert "choices beyond tamping: spot_tamp, drainage, survey" in wet.table()


def test_a_file_whose_last_run_is_years_old_warns(tmp_path):
    """A line file measured last 6 years before its ``as_of`` (an old file, or an ``as_of`` typo) plans from the
    model's projection over those years: a warning says so; the loader's test line (measured a month before) none."""
    from trackenv_agents.planning import plan_warnings

    old = write(tmp_path, line=LINE.replace("as_of: 2026-01-01", "as_of: 2031-12-01"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitWarning)
        plan = plan_line(old, years=0.25, futures=1, **FAST)
    notes = plan_warnings(plan)
    stale = [w for w in notes if "recording-car" in w]
    assert len(stale) == 1 and "(2025-12-01) is 6.0 years before as_of" in stale[0]
    assert notes[0] == stale[0]  # the line's own warnings first: the section notes may be many (stderr prints 8)
    # Q1's lines give each section's own run's age (the observation's line-wide age is the newest reading's)
    for j in np.flatnonzero(~plan.model_read()["sd"]):
        assert f"{plan.model_read()['age_years'][j]:.2f} years old" in plan._section_line(int(j), "tamp")
        assert plan.model_read()["age_years"][j] > 5.9
    fresh = plan_line(write(tmp_path), years=0.25, futures=1, **FAST)
    assert not [w for w in plan_warnings(fresh) if "recording-car" in w]


def test_the_renewal_mark_and_the_model_reading_star_say_what_the_futures_did(rough_plan):
    """"(renewal)" marks a recommended tamping that is a renewal in most of the futures that tamp the section (a
    network plan marked a tamping whose renewal was due only in the future that had tamped it the quarter before,
    while its costs held no renewal); Q1's ids on the model's reading only carry a ``*`` and the table says why."""
    import dataclasses

    plan, _ = rough_plan
    due = {k: v.copy() for k, v in plan.state.items()}
    due["renewal_due"][0, 1] = 0.5  # due in one of the two futures
    for renewed, marked in ((0.0, False), (1.0, True)):
        share = np.zeros_like(plan.renewed_share)
        share[0, 1] = renewed
        assert ("B" in dataclasses.replace(plan, state=due, renewed_share=share).renewals(0)) is marked
    assert plan.tamp_text(0, ["B", "D"], {"D"}) == "B D*"
    # on a line with choices the tamping row marks its renewals too (it did only with tamping alone)
    renewing = dataclasses.replace(plan, state=due, renewed_share=np.where(np.arange(4) == 1, 1.0, 0.0)[None]
                                   .repeat(plan.renewed_share.shape[0], axis=0),
                                   choices=("tamp", "spot_tamp", "drainage", "renew", "inspect", "survey"))
    rows = [r for r in renewing.table().splitlines() if r.startswith("Q") and "tamp B" in r]
    assert rows and all("B (renewal)" in r for r in rows)
    choice = plan.choice_share.copy()
    choice[0, 3] = 0.0
    choice[0, 3, 1] = 1.0  # D (no run in the file) tamped in Q1 in every future
    table = dataclasses.replace(plan, choice_share=choice).table()
    (q1,) = [row for row in table.splitlines() if row.startswith("Q1 ")]
    assert "D*" in q1 and "* on the model's reading only: the file has no run of the section" in table


def test_a_value_the_file_sets_anyway_is_no_change(tmp_path):
    """``--set speed_kmh=100`` on a 100 km/h file is taken (the same value) but changes nothing: the header's
    "changed:" does not list it (it did); another field it does."""
    plan = plan_line(write(tmp_path), years=0.25, futures=1, speed_kmh=100.0, possession_cost=9.0, **FAST)
    assert plan.config_changes == {"possession_cost": 9.0}
    assert "changed: possession_cost=9" in plan.table().splitlines()[0]


def test_a_capacity_that_reaches_each_section_once_in_a_decade_warns():
    """The default capacity (6 sections a quarter) on a 250-section line reaches each section once in 10.4 years:
    a probe planned a 50 km line with it unawares. A plan whose capacity reaches each section less often than
    every CAPACITY_CYCLE_YEARS warns (the example's 100 sections at 2 a quarter: 12.5 years), at 3 a quarter
    (8.3 years) not; a network's line (the machine's capacity) not."""
    import dataclasses

    from trackenv.lines import EXAMPLE
    from trackenv_agents.planning import plan_warnings

    plan = plan_line(EXAMPLE, years=0.25, futures=1, capacity=2, **FAST)
    (cap,) = [w for w in plan_warnings(plan) if "possession capacity" in w]
    assert "a possession capacity of 2 sections a quarter reaches each of the line's 100 sections once in 12.5 years" \
        in cap and "--set capacity=N" in cap
    assert not [w for w in plan_warnings(dataclasses.replace(plan, capacity=3)) if "possession capacity" in w]
    assert not [w for w in plan_warnings(plan, alone=False) if "possession capacity" in w]


def test_a_plan_takes_the_files_capacity_and_names_it(tmp_path, capsys):
    """A line file's ``capacity`` is the plan's (the header says it is the file's), and ``--set capacity`` of
    another value is refused in one line as for the file's other fields."""
    line = write(tmp_path, line=LINE + "capacity: 2\n")
    plan = plan_line(line, years=0.25, futures=1, **FAST)
    assert plan.capacity == 2 and "possession capacity: 2 sections of work a quarter (the file's)" in plan.table()
    assert main(["plan", str(line), "--set", "capacity=3", "--years", "0.25", "--futures", "1"]) == 2
    assert "capacity=3 conflicts with the line file" in capsys.readouterr().err
