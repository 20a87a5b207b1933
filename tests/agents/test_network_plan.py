"""``trackenv plan NETWORK.yaml`` and :func:`~trackenv_agents.network_plan.plan_network`: the network's plan is its
lines' plans and the machine's course, their costs add up, a section asked for where the machine is not is not
done for the machine, and the command plans a network file as it plans a line file."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from trackenv.envs.network_file import load_network
from trackenv.lines import EXAMPLE_NETWORK
from trackenv_agents.cli import main
from trackenv_agents.network_plan import plan_network


@pytest.fixture(scope="module")
def network_plan():
    return plan_network(EXAMPLE_NETWORK, years=0.75, futures=3)


def test_the_networks_costs_are_its_lines_and_the_moves(network_plan):
    plan = network_plan
    assert [len(p.line.sections) for p in plan.lines] == [100, 30] and plan.costs.shape == (3, 3)
    lines = sum(p.costs for p in plan.lines)
    assert np.allclose(plan.costs, lines + plan.move_costs, rtol=1e-12, atol=1e-9)
    for p in plan.lines:  # each line's parts add up to its cost
        assert np.allclose(sum(p.part_costs.values()), p.costs, rtol=1e-9, atol=1e-9)
    assert np.allclose(plan.works_on.sum(axis=1) + plan.idle_on.sum(axis=1) + plan.moved.mean(axis=0), 1.0)
    assert np.allclose(plan.moving_to.sum(axis=1), plan.moved.mean(axis=0))
    assert (plan.move_costs[plan.moved] == 10.0).all() and (plan.move_costs[~plan.moved] == 0.0).all()
    # what it leaves: every line's sections together (the JSON's top level), each line's in its plan
    lines_end = [p.end_state() for p in plan.lines]
    whole = plan.to_dict()["end_state"]
    assert whole["sections"] == 130 and whole["sections_at_sd_alert_end"] == pytest.approx(
        sum(e["sections_at_sd_alert_end"] for e in lines_end))
    assert whole["sd_mean_mm_end"] == pytest.approx(sum(e["sd_mean_mm_end"] * e["sections"] for e in lines_end) / 130)


def test_each_lines_entry_has_its_own_files_and_warnings(network_plan, monkeypatch):
    """Each of ``line_plans`` has the keys of a line's plan JSON: its files (written under ``line<i>/``, keyed as a
    line's) and the warnings about it, naming its file; the top level keeps them all."""
    from trackenv_agents.plan_report import LinePlan

    branch = network_plan.lines[1]
    monkeypatch.setattr(LinePlan, "validity_lines",  # a warning on the branch only
                        lambda self: ["warning: a section went beyond the model's validity"] if self is branch else [])
    files = {"network_csv": "n.csv", "line0_plan_csv": "line0/plan.csv", "line1_plan_csv": "line1/plan.csv",
             "line1_plot": "line1/plan.png"}
    d = network_plan.to_dict(files)
    assert [p["files"] for p in d["line_plans"]] == [{"plan_csv": "line0/plan.csv"},
                                                     {"plan_csv": "line1/plan.csv", "plot": "line1/plan.png"}]
    assert d["line_plans"][1]["warnings"] == [f"{branch.line.source}: a section went beyond the model's validity"]
    assert d["line_plans"][0]["warnings"] == []
    assert all(p["files"] == {} for p in network_plan.to_dict()["line_plans"])  # nothing written: no files


def test_the_machine_works_where_its_lines_plan_says_the_sections_are_tamped(network_plan):
    """A line's sections are tamped in a future's quarter only where the machine worked on that line then: the
    line's tamping share per quarter is at most the share of futures in which the machine worked there."""
    plan = network_plan
    for i, p in enumerate(plan.lines):
        tamped_somewhere = p.share.max(axis=1)  # (quarters,) the largest share of any section
        assert (tamped_somewhere <= plan.works_on[:, i] + 1e-12).all()


def test_a_machine_with_no_work_asked_for_stands_idle(tmp_path):
    """Under no maintenance the machine never moves and tamps nothing: every quarter it stands idle on its line
    (it was counted as working there), in the table, the JSON and network.csv."""
    plan = plan_network(EXAMPLE_NETWORK, years=0.5, futures=2, policy="no-maintenance")
    assert not plan.works_on.any() and not plan.moved.any()
    assert np.array_equal(plan.idle_on, [[1.0, 0.0], [1.0, 0.0]])
    assert "idle on line 0 100%; -" in plan.table()
    assert [q["idle_on"] for q in plan.to_dict()["quarters"]] == [[1.0, 0.0], [1.0, 0.0]]
    rows = (plan.write(tmp_path) and (tmp_path / "network.csv").read_text()).splitlines()
    assert rows[0].split(",")[2:8] == ["works_on_line0", "works_on_line1", "idle_on_line0", "idle_on_line1",
                                       "moving_to_line0", "moving_to_line1"]
    assert rows[1].split(",")[2:6] == ["0.000", "0.000", "1.000", "0.000"]


def test_a_request_where_the_machine_is_not_is_not_done_for_the_machine(tmp_path):
    """With the machine on the branch, what the main line's policy asks for in the first quarter is not done, in
    every future, for the reason ``machine``: where the machine moves there and where it stays on the branch (its
    line's requests are then the ones passed on: the main line's are still asked, by its own policy)."""
    for path in EXAMPLE_NETWORK.parent.glob("example*"):
        shutil.copy(path, tmp_path / path.name)
    network = tmp_path / "example_network.yaml"
    network.write_text(network.read_text().replace("machine_on: example.yaml", "machine_on: example_branch.yaml"))
    plan = plan_network(network, years=0.5, futures=2)
    assert plan.network.start_line == 1
    main_line = plan.lines[0]
    asked = [main_line.unmet_counts(0, int(j)) for j in np.flatnonzero(main_line.unmet_share[0] >= 0.5)]
    # each for the machine in both futures, but a section tamped just before as_of (masked: the env's first reason)
    assert {"machine": 2} in asked and all(c in ({"machine": 2}, {"recent_work": 2}) for c in asked)
    assert not main_line.share[0].any()  # nothing tamped on the main line in the first quarter
    assert "the machine on another line or moving in 2 of 2 futures" in plan.table()


def test_every_line_is_planned_on_the_networks_calendar_and_scenario():
    plan = plan_network(EXAMPLE_NETWORK, years=0.5, futures=2, scenario="wet")
    assert all(p.line.as_of == plan.network.as_of and p.dates == plan.dates for p in plan.lines)
    assert plan.costs.shape == (2, 2) and np.isfinite(plan.costs).all()
    with pytest.raises(ValueError, match="the network's machine tamps only"):
        plan_network(EXAMPLE_NETWORK, years=0.25, futures=1, scenario="wet", policy="choice-threshold")


def test_the_choice_agent_plans_a_network_tamping_only():
    """``cpi-choice-agent`` plays the network as the leaderboard plays it (its tamping, the lines' action tamping
    only), where a choice rule is refused."""
    plan = plan_network(EXAMPLE_NETWORK, years=0.5, futures=1, scenario="wet", policy="cpi-choice-agent")
    assert plan.policy == "cpi-choice-agent" and np.isfinite(plan.costs).all()
    assert all(p.choices == ("tamp",) for p in plan.lines)
    assert sum(float(p.share.sum()) for p in plan.lines) > 0  # it tamped somewhere


def test_plan_plans_a_network_file(tmp_path, capsys):
    out = tmp_path / "plan"
    assert main(["plan", str(EXAMPLE_NETWORK), "--years", "0.5", "--futures", "2", "--json", "--out", str(out)]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["network"] == load_network(EXAMPLE_NETWORK).name and len(d["line_plans"]) == 2
    assert d["lines"] == [p["line"] for p in d["line_plans"]] and len(d["quarters"]) == 2
    assert all(len(q["works_on"]) == len(q["idle_on"]) == 2
               and abs(sum(q["works_on"]) + sum(q["idle_on"]) + q["moving"] - 1) < 1e-9 for q in d["quarters"])
    assert all(abs(sum(q["moving_to"]) - q["moving"]) < 1e-9 for q in d["quarters"])
    assert {Path(p).name for p in d["files"].values()} == {"network.csv", "network.png", "plan.csv", "costs.csv",
                                                        "plan.png"}
    assert (out / "line1" / "plan.csv").is_file() and (out / "network.csv").read_text().startswith("quarter,from")
    sources = [line.source for line in load_network(EXAMPLE_NETWORK).lines]
    for i, line_plan in enumerate(d["line_plans"]):  # each line's entry has a line plan's files and warnings
        assert line_plan["files"] == {"plan_csv": str(out / f"line{i}" / "plan.csv"),
                                      "costs_csv": str(out / f"line{i}" / "costs.csv"),
                                      "plot": str(out / f"line{i}" / "plan.png")}
        assert all(w.startswith(f"{sources[i]}") for w in line_plan["warnings"])
    assert [w for line_plan in d["line_plans"] for w in line_plan["warnings"]] == d["warnings"]
    main(["plan", str(EXAMPLE_NETWORK), "--years", "0.25", "--futures", "1", "--out", str(out)])
    text, err = capsys.readouterr()
    # the bar says what the start waits for (seconds per line with a history; it stood at 0 with no word)
    assert ("plan: starting 2 lines (130 sections, fitting the histories of 100 sections that have one; once per "
            "plan)") in err
    assert "plan (quarters)" in err
    assert text.startswith("Network plan for Example Valley network (synthetic) from 2026-01-01")
    assert "cost of the network over 3 months" in text or "cost of the network over 0.25" in text


def test_a_faulty_network_file_is_one_line_and_exit_2(tmp_path, capsys):
    path = tmp_path / "network.yaml"
    path.write_text("name: N\nlines:\n  - nowhere.yaml\n")
    assert main(["plan", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert "no such line file" in err and len(err.splitlines()) == 1


def test_plan_reads_the_network_file_once(monkeypatch, capsys):
    """``trackenv plan NETWORK.yaml`` reads the network file once, to tell it from a line file and to load it (it
    read it twice); each line file once too."""
    reads: list[str] = []
    read_text = Path.read_text

    def counted(self, *args, **kwargs):
        reads.append(self.name)
        return read_text(self, *args, **kwargs)

    monkeypatch.setattr(Path, "read_text", counted)
    # refused once the network is loaded, before the futures: the reads are the loading's
    assert main(["plan", str(EXAMPLE_NETWORK), "--policy", "choice-threshold", "--scenario", "wet"]) == 2
    assert "the network's machine tamps only" in capsys.readouterr().err
    assert reads.count("example_network.yaml") == 1 and reads.count("example_branch.yaml") == 1


def test_a_choice_policy_on_a_network_is_refused_before_anything_runs(capsys):
    assert main(["plan", str(EXAMPLE_NETWORK), "--policy", "choice-threshold", "--scenario", "wet"]) == 2
    captured = capsys.readouterr()
    assert "the network's machine tamps only" in captured.err and "plan (quarters)" not in captured.err


def test_two_copies_of_a_line_keep_their_files_and_the_plans_capacity_is_the_machines(tmp_path):
    """Two files of equal content share one line config, but each line's plan names its own file; a capacity given
    to the plan is the machine's, over the network file's."""
    for path in EXAMPLE_NETWORK.parent.glob("example_branch*"):
        shutil.copy(path, tmp_path / path.name)
    shutil.copy(tmp_path / "example_branch.yaml", tmp_path / "branch_copy.yaml")
    network = tmp_path / "network.yaml"
    network.write_text("name: two branches\nlines:\n  - example_branch.yaml\n  - branch_copy.yaml\ncapacity: 2\n")
    plan = plan_network(network, years=0.25, futures=1, capacity=3)
    assert [Path(p.line.source).name for p in plan.lines] == ["example_branch.yaml", "branch_copy.yaml"]
    assert [p.capacity for p in plan.lines] == [3, 3]
    assert "line 1: Example Branch Line (synthetic) (" in plan.table() and "branch_copy.yaml)" in plan.table()


def test_a_network_plan_names_each_lines_known_defects_and_suspected_wet_zones(tmp_path):
    """A network of the branch and a copy whose file gives known short defects and a suspected wet zone: the copy's
    lines in the table's header count them, as a line's plan does; the plain branch's say nothing of them."""
    for path in EXAMPLE_NETWORK.parent.glob("example_branch*"):
        shutil.copy(path, tmp_path / path.name)
    rows = (tmp_path / "example_branch_sections.csv").read_text().splitlines()
    marked = [rows[0] + ",defects", rows[1] + ",2", rows[2].replace(",no,", ",suspected,") + ",",
              *(row + "," for row in rows[3:])]
    (tmp_path / "marked_sections.csv").write_text("\n".join(marked) + "\n")
    (tmp_path / "marked.yaml").write_text((tmp_path / "example_branch.yaml").read_text().replace(
        "example_branch_sections.csv", "marked_sections.csv"))
    network = tmp_path / "network.yaml"
    network.write_text("name: branch and marked copy\nlines:\n  - example_branch.yaml\n  - marked.yaml\n")
    table = plan_network(network, years=0.25, futures=1).table()
    header = table.split("quarter  ")[0]
    plain, copy = header.split("line 1: ")
    assert "short defects" not in plain and "suspected wet" not in plain
    assert "short defects: the file's 2 on 1 section, none on the rest" in copy
    assert "suspected wet: 1 section, each with a hidden wet spot in 50% of the futures" in copy


def test_a_networks_first_line_draws_the_futures_of_a_network_of_it_alone(network_plan, tmp_path):
    """The docs compare a line with and without sharing the machine this way: a network file listing the first
    line alone, planned with the same seed, gives that line the same futures (the same quarters while the machine
    is on it in both: the first quarter here)."""
    for path in EXAMPLE_NETWORK.parent.glob("example*"):
        shutil.copy(path, tmp_path / path.name)
    alone = tmp_path / "alone.yaml"
    alone.write_text("name: the main line alone\nlines:\n  - example.yaml\n")
    plan = plan_network(alone, years=0.75, futures=3)  # the same horizon: an episode draws its whole course
    assert network_plan.works_on[0, 0] == 1.0  # the shared machine stays on the main line in the first quarter
    np.testing.assert_array_equal(plan.lines[0].costs[:, 0], network_plan.lines[0].costs[:, 0])
