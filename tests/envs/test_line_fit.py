"""The history fit of a line file (:func:`~trackenv.envs.line_fit.history_fit`): one section's data moves only
that section's fit and start, and a file that contradicts its history is named in a warning and in the table."""

from __future__ import annotations

import dataclasses
import math
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import trackenv  # noqa: F401  (registers the ids)
from trackenv.envs.line_config import LineConfig
from trackenv.envs.line_fit import FitWarning, _class_of, _growth, history_fit
from trackenv.lines import EXAMPLE

LINE = """\
name: Fit test line
as_of: 2025-06-30
traffic:
  annual_mgt: 12
  speed_kmh: 100
  freight_share: 0.2
sections: sections.csv
history: history.csv
"""
SECTIONS = """\
section,length_m,register,wet,annual_mgt,speed_kmh,freight_share,years_since_tamping,tampings_since_renewal,rate_factor
K10.0,200,plain,no,,,,3.5,2,
K10.2,200,plain,yes,,,,2,4,
K10.4,180,transition,,,,,1.0,5,
K11.23,200,switch_or_crossing,,15,80,0.5,1.5,7,
"""
HISTORY = """\
section,date,sd_mm,peak_mm
K10.0,2023-01-15,0.9,2.5
K10.0,2023-07-15,1.1,3.0
K10.0,2024-01-15,1.3,3.4
K10.0,2024-07-15,1.45,3.9
K10.0,2025-01-15,1.6,4.2
K10.2,2024-01-10,0.8,2.0
K10.2,2024-07-10,1.2,3.0
K10.2,2025-01-10,1.7,4.5
K10.4,2024-12-01,0.7,
K10.4,2025-05-01,1.1,
K11.23,2024-06-01,1.0,2.6
K11.23,2025-01-01,1.6,4.0
"""
OTHERS = [1, 2, 3]  # K10.2, K10.4, K11.23: the sections whose data the edits below leave alone


def write(folder: Path, sections: str = SECTIONS, history: str = HISTORY) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "sections.csv").write_text(sections)
    (folder / "history.csv").write_text(history)
    (folder / "line.yaml").write_text(LINE)
    return folder / "line.yaml"


def fit_and_start(path: Path) -> tuple[list, np.ndarray]:
    """The fit of each section, and its true SD [m] after reset(seed=0) (the observation shows the file's last
    runs)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitWarning)
        fit = history_fit(LineConfig(line=path))
        env = gym.make("trackenv/TampingLine-v0", line=path, horizon_years=0.5)
        env.reset(seed=0)
    return list(fit.sections), env.unwrapped.batch.sd.copy()


# ---------------------------------------------------------------------- one section's data, one section's fit
@pytest.mark.slow
def test_editing_one_sections_history_moves_no_other_section(tmp_path):
    """Deleting K10.0's 2023-2024 runs (its class then has no section to fit) or moving its last tamping earlier
    (a longer span to simulate) changes K10.0's fit and start, and nothing of any other section: neither its fit
    nor the SD it starts from after reset(seed=0). (Each class is simulated alone, and a section's ρ prior is
    taken over its own span; before, the classes shared one simulated line and one span.)"""
    base_fit, base_sd = fit_and_start(write(tmp_path / "base"))
    edits = {
        "history": write(tmp_path / "history", history="\n".join(
            r for r in HISTORY.splitlines() if not r.startswith(("K10.0,2023", "K10.0,2024"))) + "\n"),
        "years": write(tmp_path / "years", sections=SECTIONS.replace("K10.0,200,plain,no,,,,3.5,",
                                                                     "K10.0,200,plain,no,,,,4.5,")),
    }
    for name, path in edits.items():
        fit, sd = fit_and_start(path)
        assert fit[0] != base_fit[0] and sd[0] != base_sd[0], name  # the edited section does move
        for j in OTHERS:
            assert fit[j] == base_fit[j], (name, fit[j], base_fit[j])
        np.testing.assert_array_equal(sd[OTHERS], base_sd[OTHERS], err_msg=name)


def test_a_class_growth_does_not_depend_on_the_span_simulated(tmp_path):
    """What the fix relies on: a class's simulated growth over its first year is the same whether it is
    simulated for one year or for two (a longer-tamped section of its class changes nothing of the others')."""
    config = LineConfig(line=write(tmp_path))
    cls = _class_of(config.line, config.line.sections[3])
    short, long = _growth(config, cls, 1.0), _growth(config, cls, 2.0)
    n = short.phi.size
    assert long.phi.size > n
    np.testing.assert_array_equal(short.phi, long.phi[:n])
    np.testing.assert_array_equal(short.rho, long.rho[: n - 1])
    assert short.rho_prior(1.0, config.steps_per_year) == long.rho_prior(1.0, config.steps_per_year)


# ---------------------------------------------------------------------- a file that contradicts its history
def test_a_given_rate_factor_the_history_contradicts_warns(tmp_path):
    """K11.23 given rate_factor 1.8 while its history (1.0 mm in 2024-06, 1.6 mm in 2025-01) fits about 0.5:
    a FitWarning naming the section, both factors and both residuals; the table says the same."""
    path = write(tmp_path, sections=SECTIONS.replace("0.5,1.5,7,", "0.5,1.5,7,1.8"))
    with pytest.warns(FitWarning, match=r"section K11\.23: rate_factor 1\.8 contradicts the history") as caught:
        fit = history_fit(LineConfig(line=path))
    s = fit.sections[3]
    assert s.status == "given" and s.rate_factor == 1.8
    assert 0.3 < s.fitted_rate_factor < 0.8  # the history's own factor
    assert s.residual_mm - s.fitted_residual_mm > 2 * math.hypot(0.1, 0.05)  # the documented threshold
    message = str(caught[0].message)
    assert f"{s.residual_mm:.3f} mm" in message and f"{s.fitted_rate_factor:.2f}" in message
    assert f"{s.fitted_residual_mm:.3f} mm" in message
    assert len([w for w in caught if issubclass(w.category, FitWarning)]) == 1  # the other sections agree
    row = next(r for r in fit.table().splitlines() if r.startswith("K11.23"))
    assert "contradicts the history" in row and f"{s.fitted_rate_factor:.2f}" in row
    assert [f.note for f in fit.sections[:3]] == ["", "", ""]


def test_a_given_rate_factor_the_history_bears_out_is_quiet(tmp_path):
    """The same section given the factor its history fits: no warning, no note."""
    with warnings.catch_warnings():  # (the fit is cached per config: it warns on its first run only)
        warnings.simplefilter("ignore", FitWarning)
        fitted = history_fit(LineConfig(line=write(tmp_path / "a", sections=SECTIONS.replace(
            "0.5,1.5,7,", "0.5,1.5,7,1.8")))).sections[3].fitted_rate_factor
    path = write(tmp_path / "b", sections=SECTIONS.replace("0.5,1.5,7,", f"0.5,1.5,7,{fitted:.3f}"))
    with warnings.catch_warnings():
        warnings.simplefilter("error", FitWarning)
        s = history_fit(LineConfig(line=path)).sections[3]
    assert s.status == "given" and s.note == "" and s.residual_mm < 0.2


def test_a_history_without_a_drop_across_the_stated_tamping_warns(tmp_path):
    """K10.0 said tamped a year before as_of (2024-06-30) while its SD rises steadily through that date (1.1,
    1.3 mm before, 1.45 mm after): a FitWarning naming the section, the date and the runs."""
    path = write(tmp_path, sections=SECTIONS.replace("K10.0,200,plain,no,,,,3.5,", "K10.0,200,plain,no,,,,1,"))
    with pytest.warns(FitWarning, match=r"section K10\.0: the history shows no drop across the last tamping "
                                        r"that years_since_tamping 1 puts on 2024-06-30: 1\.1, 1\.3 mm before") as w:
        fit = history_fit(LineConfig(line=path))
    assert len([x for x in w if issubclass(x.category, FitWarning)]) == 1
    assert "no drop" in fit.sections[0].note and "no drop" in fit.table()


def test_the_first_observation_is_the_files_last_run_dated_back_to_it(tmp_path):
    """At as_of a planner knows each section's last recording-car run, not a fresh one: the first observation shows
    it (SD, mean-to-peak) with its age in whole steps (K10.0 0.45 years before as_of: two quarters), where the
    model ran its own reading at as_of. A run before the section's last tamping (K10.4 said tamped after it) is not
    the section's state: the model's reading stands there. A run older than the horizon (a quarter here) is read
    too, within the observation's bounds (a plan's first quarter did not depend on its length)."""
    sections = SECTIONS.replace("K10.4,180,transition,,,,,1.0,5,", "K10.4,180,transition,,,,,0.1,5,")
    path = write(tmp_path, sections=sections)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FitWarning)
        env = gym.make("trackenv/TampingLine-v1", line=path, horizon_years=0.25)
        obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    np.testing.assert_allclose(obs["section_sd"][[0, 1, 3]], [1.6, 1.7, 1.6], rtol=1e-6)
    np.testing.assert_allclose(obs["section_peak"][[0, 1, 3]], [4.2, 4.5, 4.0], rtol=1e-6)
    np.testing.assert_allclose(obs["section_measurement_age"], [0.5, 0.5, 0.0, 0.5])
    assert obs["section_sd"][2] != pytest.approx(1.1, abs=1e-3)  # K10.4: the model's own reading
    assert obs["measurement_age"][0] == 0.0  # the line's latest run: the model's on K10.4
    truth = env.unwrapped.batch.sd[:4] * 1e3
    assert not np.allclose(truth[[0, 1, 3]], obs["section_sd"][[0, 1, 3]])  # the fit's state, not the runs


def test_a_drop_after_the_stated_tamping_warns_as_a_tamping_the_file_does_not_state(tmp_path):
    """K10.0's SD falls from 1.45 to 0.6 mm between two runs after the tamping the file states (3.5 years before
    as_of): tamped again, not said; the fit ran one curve through the drop and warned of nothing. Now a
    FitWarning names both runs and the stated date, once (no second note that the curve fits poorly)."""
    path = write(tmp_path, history=HISTORY.replace("K10.0,2025-01-15,1.6,4.2", "K10.0,2025-01-15,0.6,1.8"))
    with pytest.warns(FitWarning, match=r"section K10\.0: the SD drops from 1\.45 to 0\.6 mm between the runs of "
                                        r"2024-07-15 and 2025-01-15, after the last tamping that "
                                        r"years_since_tamping 3\.5 puts on 2021-12-30") as w:
        fit = history_fit(LineConfig(line=path))
    assert len([x for x in w if issubclass(x.category, FitWarning)]) == 1
    assert "drops from" in fit.sections[0].note and "misses" not in fit.sections[0].note


def test_a_history_in_cm_and_a_curve_that_misses_its_runs_warn(tmp_path):
    """Every SD of K10.2 a tenth of what it was (given in cm): a warning asking for the unit. K10.0's runs since
    its tamping jump from 1.0 to 3.0 mm in half a year and stay there, which no settlement curve follows (with no
    drop): a warning that the fitted curve misses them by more than 3 times the fit's error."""
    history = (HISTORY.replace("K10.2,2024-01-10,0.8,2.0", "K10.2,2024-01-10,0.08,2.0")
               .replace("K10.2,2024-07-10,1.2,3.0", "K10.2,2024-07-10,0.12,3.0")
               .replace("K10.2,2025-01-10,1.7,4.5", "K10.2,2025-01-10,0.17,4.5")
               .replace("K10.0,2023-07-15,1.1,3.0", "K10.0,2023-07-15,0.95,3.0")
               .replace("K10.0,2024-01-15,1.3,3.4", "K10.0,2024-01-15,1.0,3.4")
               .replace("K10.0,2024-07-15,1.45,3.9", "K10.0,2024-07-15,3.0,3.9")
               .replace("K10.0,2025-01-15,1.6,4.2", "K10.0,2025-01-15,3.05,4.2"))
    with pytest.warns(FitWarning) as w:
        fit = history_fit(LineConfig(line=write(tmp_path, history=history)))
    notes = {f.section: f.note for f in fit.sections if f.note}
    assert set(notes) == {"K10.0", "K10.2"}
    assert "every run measures an SD below 0.3 mm (at most 0.17 mm)" in notes["K10.2"] and "in cm?" in notes["K10.2"]
    assert notes["K10.0"].startswith("the fitted curve misses the measured SD by 0.4") and "more than 3 x" in \
        notes["K10.0"]
    assert len([x for x in w if issubclass(x.category, FitWarning)]) == 2


def test_a_last_tamping_decades_ago_asks_for_the_unit(tmp_path):
    """K10.4's years_since_tamping 30 (months, meant as 2.5 years): a warning asking whether it is given in months;
    20 years, the threshold itself, none."""
    for years, noted in ((30, True), (20, False)):
        sections = SECTIONS.replace("K10.4,180,transition,,,,,1.0,5,", f"K10.4,180,transition,,,,,{years},5,")
        with warnings.catch_warnings(record=True) as w:
            warnings.simplefilter("always")
            fit = history_fit(LineConfig(line=write(tmp_path / str(years), sections=sections)))
        notes = {f.section: f.note for f in fit.sections if f.note}
        assert set(notes) == ({"K10.4"} if noted else set()), notes
        if noted:
            assert notes["K10.4"].startswith("years_since_tamping 30: no tamping in more than 20 years")
            assert "months?" in notes["K10.4"]
            assert len([x for x in w if issubclass(x.category, FitWarning)]) == 1


@pytest.mark.slow
def test_the_example_line_fits_without_a_warning():
    """The shipped example (made by the engine, so consistent) contradicts neither check: their thresholds
    leave its tamped sections, its given-nothing rates and its noisy runs alone."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", FitWarning)
        fit = history_fit(LineConfig(line=EXAMPLE))
    assert not any(s.note for s in fit.sections) and len(fit.fitted) > 50
    assert {f.name for f in dataclasses.fields(fit.sections[0])} >= {"fitted_rate_factor", "note"}


# ---------------------------------------------------------------------- local defects (the "defects" scenario)
DEFECTS_LINE = LINE.replace("as_of: 2025-06-30", "as_of: 2025-10-01").replace("annual_mgt: 12", "annual_mgt: 22")
DEFECTS_SECTIONS = """\
section,length_m,register,wet,annual_mgt,speed_kmh,freight_share,years_since_tamping,tampings_since_renewal
K25.8,200,plain,no,,,,4.5,3
K43.8,200,transition,no,28,,0.45,1.75,6
K44.2,200,transition,no,28,,0.45,1.75,2
K45.4,200,plain,no,28,,0.45,3.75,1
"""
DEFECTS_HISTORY = """\
section,date,sd_mm,peak_mm
K25.8,2022-10-01,0.98,2.9
K25.8,2023-04-02,1.05,3.1
K25.8,2023-10-01,1.22,3.4
K25.8,2024-04-01,1.43,4.0
K25.8,2024-09-30,1.38,3.7
K25.8,2025-04-01,1.47,4.7
K25.8,2025-10-01,1.60,4.9
K43.8,2024-04-01,0.97,3.1
K43.8,2024-09-30,1.33,4.0
K43.8,2025-04-01,1.75,5.9
K43.8,2025-10-01,1.91,5.1
K44.2,2024-04-01,1.04,2.8
K44.2,2024-09-30,1.52,5.0
K44.2,2025-04-01,2.04,5.7
K44.2,2025-10-01,2.46,8.4
K45.4,2022-10-01,1.32,4.2
K45.4,2023-04-02,1.35,3.5
K45.4,2023-10-01,1.59,4.7
K45.4,2024-04-01,1.73,5.7
K45.4,2024-09-30,2.15,6.4
K45.4,2025-04-01,2.44,7.7
K45.4,2025-10-01,2.46,7.1
"""


def test_under_local_defects_a_section_starts_at_its_last_run_and_fits_as_without(tmp_path):
    """With local defects counted once in a section's 200 m (the "defects" scenario), a section's SD is the
    defect-weighted one: the start is scaled to that SD (not the 30 m segment's own, where a drawn defect weighs
    seven times more), so a section measured at as_of starts within a couple of the car's errors of its last run
    as without defects (it once started up to 1.2 mm off); and the fit's class simulations are of the sections'
    own fields (a defect's runaway draws once drove two transition sections' rate to the grid's bottom with a
    "misses the measured SD" warning), so the fit is the default scenario's."""
    from trackenv.envs.line import TampingLine
    from trackenv.envs.line_config import scenario
    from trackenv.envs.line_fit import last_runs

    folder = tmp_path / "line"
    folder.mkdir()
    (folder / "sections.csv").write_text(DEFECTS_SECTIONS)
    (folder / "history.csv").write_text(DEFECTS_HISTORY)
    (folder / "line.yaml").write_text(DEFECTS_LINE)
    path = folder / "line.yaml"
    plain = history_fit(LineConfig(line=path))
    with warnings.catch_warnings():
        warnings.simplefilter("error", FitWarning)  # no section's history is called wrong
        config = scenario("defects", line=path, horizon_years=0.5)
        fit = history_fit(config)
    for with_defects, without in zip(fit.sections, plain.sections, strict=True):
        assert with_defects.status == without.status == "fitted"
        assert with_defects.residual_mm == pytest.approx(without.residual_mm, abs=0.02)
        assert with_defects.rate_factor == pytest.approx(without.rate_factor, rel=0.1)
        assert with_defects.residual_mm < 0.15
    last = last_runs(config.line)["last_sd_m"] * 1e3
    env = TampingLine(config)
    near = []
    for seed in range(4):
        _, info = env.reset(seed=seed)
        np.testing.assert_allclose(np.asarray(info["section_sd_m"]) * 1e3, last, atol=0.25)
        near.append(env.batch.defect_near[:4].any(axis=1))
    assert np.any(near)  # some sections drew a defect


def test_the_fits_section_sd_is_the_engines():
    """``sd_weights`` with ``weighted_sd`` give the section SD the engine observes (``LineBatch._segment_sd``, its
    local defects once in its length), on the short-defect preset's draws: the fit scales the start to the same
    number (two implementations of one weighting, kept equal here)."""
    from trackenv.envs.line import TampingLine
    from trackenv.envs.line_config import SLEEPER_SPACING_M, scenario
    from trackenv.envs.line_fit import sd_weights, weighted_sd
    from trackenv.physics.geometry import d1_filter

    config = scenario("defects", n_sections=8, capacity=4, horizon_years=0.5)
    env = TampingLine(config)
    env.reset(seed=3)
    batch = env.batch
    segs = np.arange(config.n_sections)
    assert batch.defect_near[segs].any()  # some segments drew a defect
    d1 = d1_filter(batch.level[segs], SLEEPER_SPACING_M)
    lengths = config.section_length_m * batch.length_factor[segs]
    np.testing.assert_allclose(weighted_sd(d1, sd_weights(batch.defect_near[segs], lengths, config)),
                               batch._segment_sd(d1, segs), rtol=1e-12)


def test_a_section_with_known_defects_starts_at_its_history_like_the_others(tmp_path):
    """A file's known short defects (its ``defects`` column, which counts them once in the section's length:
    ``local_defect_near_m`` 3 m) go the drawn defects' way through the fit: the classes are simulated without
    defects, so the fit is the same file's without the column (up to the rounding of uniform weights), and each
    section, with its known defects in the episode's draw, starts at the SD its fit gives at as_of."""
    from trackenv.envs.line import TampingLine

    counted = (DEFECTS_SECTIONS.replace("renewal\n", "renewal,defects\n").replace(",4.5,3\n", ",4.5,3,2\n")
               .replace(",1.75,6\n", ",1.75,6,\n").replace(",1.75,2\n", ",1.75,2,1\n")
               .replace(",3.75,1\n", ",3.75,1,0\n"))
    paths = {}
    for name, sections in (("counted", counted), ("plain", DEFECTS_SECTIONS)):
        folder = tmp_path / name
        folder.mkdir()
        (folder / "sections.csv").write_text(sections)
        (folder / "history.csv").write_text(DEFECTS_HISTORY)
        (folder / "line.yaml").write_text(DEFECTS_LINE)
        paths[name] = folder / "line.yaml"
    config = LineConfig(line=paths["counted"], horizon_years=0.5)
    assert [s.defects for s in config.line.sections] == [2, None, 1, 0] and config.local_defect_near_m == 3.0
    fit, plain = history_fit(config), history_fit(LineConfig(line=paths["plain"], horizon_years=0.5))
    for known, without in zip(fit.sections, plain.sections, strict=True):
        assert known.status == without.status == "fitted"
        assert known.rate_factor == pytest.approx(without.rate_factor, rel=1e-6)
        assert known.start_sd_mm == pytest.approx(without.start_sd_mm, rel=1e-6)
    env = TampingLine(config)
    for seed in range(3):
        _, info = env.reset(seed=seed)
        assert env.batch.defect_near[[0, 2]].any(axis=1).all() and not env.batch.defect_near[3].any()
        np.testing.assert_allclose(np.asarray(info["section_sd_m"]) * 1e3, [f.start_sd_mm for f in fit.sections],
                                   rtol=2e-3)
