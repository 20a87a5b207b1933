"""trackenv_studies.paper: the section-4 reproduction writes its JSON and figures and returns its summary."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from trackenv_studies.paper import format_summary, reproduce_paper


@pytest.mark.slow
def test_reproduce_paper_writes_json_figures_and_summary(tmp_path, capsys) -> None:
    d = reproduce_paper(tmp_path, iterations=2, progress=False)
    assert capsys.readouterr().err == ""  # no progress bar when progress=False
    assert set(d) == {"settings", "A", "B", "files", "wall_time_s"}
    assert d["settings"]["iterations"] == 2
    assert d["settings"]["static_wheel_load_kN"] == pytest.approx(108.829)
    assert d["settings"]["stiffness_change_m"] == pytest.approx(24.0)
    for name in ("A", "B"):
        assert set(d[name]) == {"description", "wall_time_s", "summary"}
        s = d[name]["summary"]
        assert len(s["max_contact_force_kN"]) == 2
        assert all(100.0 < f < 120.0 for f in s["max_contact_force_kN"])
        assert d[name]["wall_time_s"] > 0
    a, b = d["A"]["summary"], d["B"]["summary"]
    assert a["interior_sleepers"] == [3, 47]
    assert 0 <= a["final_settlement_spread"] < 0.02
    for key in ("max_differential_settlement_mm", "max_differential_settlement_location_m",
                "max_contact_force_increase_kN", "max_contact_force_increase_location_m"):
        assert len(b[key]) == 2
    assert len(b["max_differential_settlement_growth_mm"]) == 1
    assert abs(b["differential_settlement_location_m"] - 24.0) <= 1.8
    assert abs(b["contact_force_increase_location_m"] - 24.0) <= 1.8
    assert b["max_contact_force_increase_location_m"][0] is None  # iteration 1 is the reference

    # the files
    assert (tmp_path / "paper.json").is_file()
    for key in ("figure_A", "figure_B"):
        png = Path(d["files"][key])
        assert png.parent == tmp_path
        assert png.is_file() and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    full = json.loads((tmp_path / "paper.json").read_text())
    assert full["A"]["summary"] == d["A"]["summary"]
    for name in ("A", "B"):
        sc = full[name]
        n = len(sc["sleeper_positions_m"])
        assert n == 51
        for key in ("settlement_mm", "contact_force_kN", "sleeper_force_kN"):
            assert np.asarray(sc[key]).shape == (2, n)
        assert len(sc["max_contact_force_kN"]) == 2
        assert sc["cycles"] == [50_000.0, 100_000.0]
        u = np.asarray(sc["settlement_mm"])
        assert np.all(u > 0) and np.all(u[1] >= u[0])

    text = format_summary(d)
    assert "A uniform ballast" in text and "24" in text
    assert len(text.splitlines()) <= 10


def test_reproduce_paper_without_plots_and_bad_input(tmp_path) -> None:
    d = reproduce_paper(tmp_path / "out", iterations=1, cycles_per_iteration=1000, make_plots=False,
                        progress=False)
    assert set(d["files"]) == {"json"}
    assert not list((tmp_path / "out").glob("*.png"))
    assert d["B"]["summary"]["differential_settlement_grows"] is None  # needs 3 iterations to tell
    format_summary(d)
    for bad in (0, -1, 2.5):
        with pytest.raises(ValueError, match="iterations"):
            reproduce_paper(tmp_path, iterations=bad, make_plots=False, progress=False)
    with pytest.raises(ValueError, match="cycles_per_iteration"):
        reproduce_paper(tmp_path, cycles_per_iteration=-5, make_plots=False, progress=False)


def test_script_prints_summary(tmp_path, capsys) -> None:
    import importlib.util

    path = Path(__file__).resolve().parents[2] / "experiments" / "reproduce_paper.py"
    spec = importlib.util.spec_from_file_location("reproduce_paper_script", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    mod.main(["--out", str(tmp_path), "--iterations", "1", "--cycles", "1000", "--no-plots", "--json",
              "--no-progress"])
    out = json.loads(capsys.readouterr().out)
    assert out["settings"]["cycles_per_iteration"] == 1000
