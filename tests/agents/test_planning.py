"""``trackenv plan``: a plan from a line file (table, JSON, CSV and plot), and every malformed file one line on
stderr with exit status 2."""

from __future__ import annotations

import csv
import json
import re
import sys
from pathlib import Path

import numpy as np
import pytest

from trackenv_agents.cli import main
from trackenv_agents.planning import plan_line

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "envs"))
from test_line_file import FAULTS, write  # noqa: E402  (the malformed files of the loader's tests)


def test_plan_writes_its_table_csv_and_plot(tmp_path, capsys):
    line = write(tmp_path)
    out = tmp_path / "plan"
    assert main(["plan", str(line), "--years", "0.5", "--futures", "2", "--json", "--out", str(out)]) == 0
    payload = json.loads(capsys.readouterr().out)
    assert payload["policy"] == "grouped-threshold" and len(payload["quarters"]) == 2
    assert payload["quarters"][0]["from"] == "2026-01-01" and payload["quarters"][1]["from"] == "2026-04-02"
    assert payload["cost_keur"]["p10"] <= payload["cost_keur"]["mean"] <= payload["cost_keur"]["p90"]
    assert payload["fit"]["fitted"] == 2
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
    assert "unknown policy 'greedy'" in capsys.readouterr().err
    assert main(["plan", str(tmp_path / "none.yaml")]) == 2
    assert "no such line file" in capsys.readouterr().err
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
    from trackenv_agents.planning import PLAN_SCENARIOS

    plan = plan_line(write(tmp_path), policy="choice-threshold", scenario="wet", years=0.5, futures=2)
    assert plan.choice_share.shape == (2, 4, 7) and np.allclose(plan.choice_share.sum(axis=2), 1.0)
    assert plan.choices == ("tamp", "spot_tamp", "drainage", "renew", "inspect", "survey")
    assert np.allclose(plan.share, 1.0 - plan.choice_share[:, :, 0])
    # the wet line's tuned rule surveys every section not surveyed yet in the first quarter
    assert plan.choice_share[0, :, 6].sum() > 0
    quarter = plan.to_dict()["quarters"][0]
    assert set(plan.choices) <= set(quarter) and plan.to_dict()["scenario"] == "wet"
    out = tmp_path / "plan"
    assert main(["plan", str(write(tmp_path)), "--scenario", "wet", "--policy", "choice-threshold", "--years", "0.5",
                 "--futures", "2", "--out", str(out)]) == 0
    assert "(wet)" in capsys.readouterr().out
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
    assert len(payload["warnings"]) == 1 and "rate_factor 1.7 contradicts the history" in payload["warnings"][0]
