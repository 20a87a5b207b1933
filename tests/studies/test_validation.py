"""Test of trackenv_studies.validation.run_validation: the summary, its tolerances, and the plots."""

from __future__ import annotations

import json
import math

import pytest

from trackenv_studies.validation import run_validation

PLOTS = (
    "fig4_static_deflection.png",
    "fig4_receptance.png",
    "fig6a_contact_force_rest.png",
    "fig6a_contact_force_loaded.png",
)


@pytest.mark.slow
def test_run_validation(tmp_path):
    summary = run_validation(tmp_path, make_plots=True)
    keys = {"track", "static", "receptance", "loaded_pass", "bare_wheelset_from_rest", "plots"}
    assert set(summary) >= keys
    # written and JSON-able
    assert json.loads((tmp_path / "summary.json").read_text()) == summary
    for name in PLOTS:
        assert name in summary["plots"]
        png = tmp_path / name
        assert png.exists() and png.stat().st_size > 5_000
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    static = summary["static"]
    assert set(static["positions"]) == {"15.0", "15.3"}
    for p in static["positions"].values():
        assert abs(p["rel_error"]) < 0.05
    assert static["max_abs_rel_error"] < 0.05

    rec = summary["receptance"]
    pinned = (math.pi / 0.6) ** 2 * math.sqrt(6.11e6 / 60.0) / (2 * math.pi)
    assert rec["pinned_pinned_closed_form_hz"] == pytest.approx(pinned, rel=1e-12)
    assert abs(rec["pinned_pinned_found_hz"] / pinned - 1) < 0.10
    assert abs(rec["pinned_pinned_rel_error"]) < 0.10
    assert rec["static_limit_max_abs_rel_error"] < 0.01

    loaded = summary["loaded_pass"]
    f_sl = (80 / 3.6) / 0.6
    assert loaded["sleeper_passing_hz"] == pytest.approx(f_sl)
    for mesh in ("elements_per_bay_2", "elements_per_bay_4"):
        run = loaded[mesh]
        assert run["static_wheel_load_N"] == pytest.approx(900 * 9.81 + 100e3)
        assert abs(run["mean_force_rel_error"]) < 0.01
        assert abs(run["sleeper_passing_peak_hz"] - f_sl) < 1.5
        assert run["sleeper_passing_amplitude_over_median"] > 5.0
        assert run["peak_central_force_N"] > run["static_wheel_load_N"]
    assert abs(loaded["elements_per_bay_4"]["dominant_peak_hz"] - f_sl) < 1.5

    rest = summary["bare_wheelset_from_rest"]
    assert rest["paper_peaks_hz"] == [36.0, 67.0, 74.0]
    assert rest["elements_per_bay"] == 4  # converged: at 2 the element-passing frequency falls on 74 Hz
    assert rest["min_force_N"] >= 0.0
    assert rest["mean_central_force_N"] == pytest.approx(rest["static_wheel_load_N"], rel=0.01)
    for f_paper, found in rest["nearest_to_paper_peaks"].items():
        assert abs(found["found_hz"] - float(f_paper)) < 3.0
    # the pass/fail lines `trackenv validate` prints: one per tolerance above, all passing
    assert len(summary["checks"]) == 2 + 2 + 2 * 3 + 1 + 3
    assert all(c["passed"] for c in summary["checks"]), [c for c in summary["checks"] if not c["passed"]]


def test_run_validation_without_plots(tmp_path, monkeypatch):
    """make_plots=False writes only the summary (checked cheaply: the heavy parts are stubbed out)."""
    import trackenv_studies.validation as val

    monkeypatch.setattr(val, "_receptance_summary", lambda track: ({"stub": 1}, {}))
    monkeypatch.setattr(val, "_loaded_pass_summary", lambda: ({"stub": 2}, {}))
    monkeypatch.setattr(val, "_rest_pass_summary", lambda: ({"stub": 3}, ()))
    summary = run_validation(tmp_path / "out", make_plots=False)
    assert summary["plots"] == []
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["summary.json"]
    assert abs(summary["static"]["positions"]["15.0"]["rel_error"]) < 0.05
