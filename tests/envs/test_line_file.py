"""Lines from files: the loader and its one-line errors (one test per kind of fault), the config that carries a
line, the engine applying it over the draws, the history fit, and the example line that ships."""

from __future__ import annotations

import pickle
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import trackenv  # noqa: F401  (registers the ids)
from trackenv.envs.line import TampingLine, TampingLineVectorEnv
from trackenv.envs.line_config import SLEEPER_SPACING_M, LineConfig
from trackenv.envs.line_episode import LineBatch
from trackenv.envs.line_file import LineDescription, LineFileError, load_line
from trackenv.envs.line_fit import drawn_section_factor, history_fit, line_overrides, zone_factors
from trackenv.lines import EXAMPLE

LINE = """\
name: Test line
as_of: 2026-01-01
traffic:
  annual_mgt: 15
  speed_kmh: 100
  freight_share: 0.4
sections: sections.csv
history: history.csv
"""
SECTIONS = """\
# a comment line, as the example's units line
section,length_m,register,wet,annual_mgt,years_since_tamping,tampings_since_renewal
A,200,plain,no,,2,1
B,200,transition,no,,3,2
C,200,switch_or_crossing,no,30,1.5,0
D,200,plain,yes,,0.5,3
"""
HISTORY = """\
section,date,sd_mm,peak_mm
A,2024-03-01,0.6,2.0
A,2025-01-05,0.8,2.5
A,2025-12-01,1.0,3.1
B,2023-06-01,1.2,4
B,2024-06-01,1.5,5
B,2025-06-01,1.9,6
C,2025-01-01,0.9,3
"""

#: SECTIONS with a ``defects`` column: two known on B, none known on D, blank (not known) on A and C
DEFECTS = (SECTIONS.replace("renewal\n", "renewal,defects\n").replace(",1\n", ",1,\n").replace(",2\n", ",2,2\n")
           .replace(",0\n", ",0,\n").replace(",3\n", ",3,0\n"))


def write(folder: Path, line: str = LINE, sections: str = SECTIONS, history: str | None = HISTORY) -> Path:
    (folder / "sections.csv").write_text(sections)
    if history is not None:
        (folder / "history.csv").write_text(history)
    path = folder / "line.yaml"
    path.write_text(line)
    return path


@pytest.fixture
def line_file(tmp_path: Path) -> Path:
    return write(tmp_path)


# ---------------------------------------------------------------------- loading
def test_a_line_file_loads_in_si(line_file):
    line = load_line(line_file)
    assert line.n_sections == 4 and line.length_m == 800.0 and line.as_of == "2026-01-01"
    assert [s.register for s in line.sections] == ["plain", "transition", "switch_or_crossing", "plain"]
    assert [s.wet for s in line.sections] == [False, False, False, True]
    assert line.traffic_factors() == (1.0, 1.0, 2.0, 1.0)  # blank: the line's 15 MGT
    assert line.sections[0].speed_kmh == 100.0 and line.freight_axle_load_t == 22.5  # the default
    a = line.measurements("A")
    assert [m.sd_m for m in a] == pytest.approx([0.6e-3, 0.8e-3, 1.0e-3]) and a[0].peak_m == pytest.approx(2e-3)
    assert line.years_before("2025-01-01") == pytest.approx(1.0, abs=1e-3)


def test_the_description_round_trips_and_is_hashable(line_file):
    line = load_line(line_file)
    again = LineDescription.from_dict(line.to_dict())
    assert again == line and hash(again) == hash(line)
    assert pickle.loads(pickle.dumps(line)) == line


def test_a_line_is_named_by_its_file_or_else_by_its_name(line_file):
    """``label``, what messages and tables show of a line: the file it was read from (kept through ``to_dict``, as
    a saved config keeps it), or for a line given as data its quoted name (the whole description is kilobytes)."""
    line = load_line(line_file)
    assert line.path == line.label == str(line_file)
    assert LineDescription.from_dict(line.to_dict()).path == str(Path(line_file).resolve())  # from any folder
    again = LineDescription.from_dict({k: v for k, v in line.to_dict().items() if k != "source"})
    assert again.path is None and again.label == "'Test line'"
    with pytest.raises(LineFileError, match=r"<line dict>, source: must be the path of the file the line was read "
                                            r"from, got '<dict>'"):
        LineDescription.from_dict({**line.to_dict(), "source": "<dict>"})


# One case per kind of fault: (what the files say, what the one line must name). Each gives a LineFileError
# (a ValueError) of one line naming the file, and for a CSV the row, and the field with what is allowed.
FAULTS = {
    "missing field (column)": (dict(sections=SECTIONS.replace(",tampings_since_renewal", "").replace(",1\n", "\n")
                                    .replace(",2\n", "\n").replace(",0\n", "\n").replace(",3\n", "\n")),
                               ["sections.csv, header", "missing column 'tampings_since_renewal'"]),
    "missing field (key)": (dict(line=LINE.replace("  speed_kmh: 100\n", "")),
                            ["line.yaml", "missing key 'traffic.speed_kmh'", "km/h"]),
    "empty cell": (dict(sections=SECTIONS.replace("B,200,transition,no,,3,2", "B,200,transition,no,,,2")),
                   ["sections.csv, row 4 (section B)", "years_since_tamping: empty"]),
    "negative length": (dict(sections=SECTIONS.replace("B,200", "B,-200")),
                        ["row 4 (section B)", "length_m: must be a positive length [m], got -200"]),
    "zero length": (dict(sections=SECTIONS.replace("A,200", "A,0")), ["row 3 (section A)", "length_m", "got 0"]),
    "unknown register class": (dict(sections=SECTIONS.replace("switch_or_crossing", "swich")),
                               ["row 5 (section C)", "register: 'swich' is not one of plain, transition, "
                                "switch_or_crossing"]),
    "misspelled register class": (dict(sections=SECTIONS.replace("transition", "transtion")),
                                  ["row 4 (section B)", "did you mean 'transition'?"]),
    "a cost in euros": (dict(line=LINE + "costs:\n  speed_restriction_cost: 20000\n"),
                        ["line.yaml", "costs.speed_restriction_cost: 20000 k€ is outside [0, 1000] k€",
                         "give it in k€ (a larger value is taken for euros)"]),
    "a negative cost": (dict(line=LINE + "costs:\n  tamping_cost_per_m: -0.01\n"),
                        ["costs.tamping_cost_per_m: -0.01 k€/m is outside [0, 1] k€/m"]),
    "a misspelt cost": (dict(line=LINE + "costs:\n  possesion_cost: 5\n"),
                        ["unknown key 'costs.possesion_cost'; did you mean 'possession_cost'?"]),
    "costs not a mapping": (dict(line=LINE + "costs: 5\n"), ["costs: must be a mapping of possession_cost"]),
    "register class abbreviated": (dict(sections=SECTIONS.replace("switch_or_crossing", "S&C")),
                                   ["row 5 (section C)", "'S&C' is not one of", "did you mean 'switch_or_crossing'?"]),
    "history out of order": (dict(history=HISTORY.replace("B,2024-06-01", "B,2023-01-01")),
                             ["history.csv, row 6 (section B)", "date: 2023-01-01 is not after", "date order"]),
    "SD in m, not mm": (dict(history=HISTORY.replace("A,2025-01-05,0.8", "A,2025-01-05,0.0008")),
                        ["history.csv, row 3 (section A)", "sd_mm", "outside [0.05, 15] mm",
                         "it looks like m: give it in mm"]),
    "length in km": (dict(sections=SECTIONS.replace(",200,", ",0.2,")),
                     ["length_m", "it looks like km: give it in m"]),
    "freight share in per cent": (dict(line=LINE.replace("freight_share: 0.4", "freight_share: 40")),
                                  ["traffic.freight_share", "per cent: give a fraction"]),
    "empty line file": (dict(line=""), ["line.yaml: empty file"]),
    "empty sections file": (dict(sections=""), ["sections.csv: empty file", "expected a header row"]),
    "no section rows": (dict(sections=SECTIONS.splitlines()[1] + "\n"), ["sections.csv: a header and no rows"]),
    "misspelled key": (dict(line=LINE.replace("annual_mgt", "anual_mgt")),
                       ["line.yaml", "unknown key 'traffic.anual_mgt'; did you mean 'annual_mgt'?"]),
    "misspelled column": (dict(sections=SECTIONS.replace("years_since_tamping", "years_since_tamp")),
                          ["sections.csv, header", "unknown column 'years_since_tamp'"]),
    "bad number": (dict(sections=SECTIONS.replace("A,200,plain,no,,2,1", "A,200,plain,no,,2.5.1,1")),
                   ["row 3 (section A)", "years_since_tamping: '2.5.1' is not a number [year]"]),
    "decimal comma": (dict(history=HISTORY.replace("B,2023-06-01,1.2,4", 'B,2023-06-01,"1,2",4')),
                      ["row 5 (section B)", "is not a number [mm]; use a decimal point"]),
    "missing sections file": (dict(line=LINE.replace("sections: sections.csv", "sections: sectoins.csv")),
                              ["line.yaml, key sections: no such sections file", "sectoins.csv"]),
    "duplicate section ids": (dict(sections=SECTIONS.replace("\nC,", "\nA,")),
                              ["sections.csv, row 5", "id 'A' repeats row 3", "unique"]),
    "unknown section in history": (dict(history=HISTORY + "E,2025-01-01,1.0,3\n"),
                                   ["history.csv, row 9", "'E' is not a section of the sections file"]),
    "section speed out of range": (dict(sections=SECTIONS.replace("annual_mgt,", "speed_kmh,")
                                        .replace("no,30,", "no,400,")),
                                   ["row 5 (section C)", "speed_kmh: speed_kmh must lie in [5, 300], got 400"]),
    "section freight share in per cent": (dict(sections=SECTIONS.replace("annual_mgt,", "freight_share,")
                                               .replace("no,30,", "no,40,")),
                                          ["row 5 (section C)", "freight_share", "per cent: give a fraction"]),
    "section shorter than the segment": (dict(sections=SECTIONS.replace("D,200", "D,20")),
                                         ["row 6 (section D)", "length_m: 20 m is outside [30, 1000] m, the "
                                          "lengths a line file allows (at least the 30 m segment"]),
    "section longer than a line file allows": (dict(sections=SECTIONS.replace("B,200", "B,2000")),
                                               ["row 4 (section B)", "length_m: 2000 m is outside [30, 1000] m"]),
    "rate factor zero": (dict(sections=SECTIONS.replace("renewal\n", "renewal,rate_factor\n").replace(",1\n", ",1,\n")
                              .replace(",0\n", ",0,\n").replace(",2\n", ",2,0\n").replace(",3\n", ",3,\n")),
                         ["row 4 (section B)", "rate_factor: 0 is outside [0.01, 100] (1: typical plain track)"]),
    "semicolon-separated CSV": (dict(sections=SECTIONS.replace(",", ";")),
                                ["sections.csv, header", "separates its cells with ';'",
                                 "needs ',' between cells"]),
    "unquoted decimal comma": (dict(history=HISTORY.replace("B,2023-06-01,1.2,4", "B,2023-06-01,1,2,4")),
                               ["history.csv, row 5", "5 cells where the header has 4 columns",
                                "a decimal comma? the cells '1', '2' look like 1,2 split in two: use a decimal point",
                                "(1.2); other such neighbours: '2', '4'"]),
    "trailing comma": (dict(sections=SECTIONS.replace("A,200,plain,no,,2,1", "A,200,plain,no,,2,1,")),
                       ["row 3", "8 cells where the header has 7 columns", "(a trailing ',')"]),
    "axle load in kg": (dict(line=LINE.replace("freight_share: 0.4", "freight_share: 0.4\n  freight_axle_load_t: "
                                                                      "22500")),
                        ["traffic.freight_axle_load_t", "got 22500; it looks like kg: give it in t"]),
    "axle load in kN": (dict(line=LINE.replace("freight_share: 0.4", "freight_share: 0.4\n  freight_axle_load_t: "
                                                                      "225")),
                        ["traffic.freight_axle_load_t", "got 225; it looks like kN: give it in t"]),
    "invalid YAML": (dict(line=LINE.replace("traffic:", "traffic: [")), ["line.yaml, line", "not valid YAML"]),
    "bad date": (dict(history=HISTORY.replace("2024-03-01", "01/03/2024")),
                 ["row 2 (section A)", "'01/03/2024' is not a date; write YYYY-MM-DD"]),
    "history after as_of": (dict(history=HISTORY.replace("2025-12-01", "2026-02-01")),
                            ["row 4 (section A)", "is after as_of 2026-01-01"]),
    "peak below SD (swapped columns)": (dict(history=HISTORY.replace("B,2024-06-01,1.5,5", "B,2024-06-01,5,1.5")),
                                        ["row 6 (section B)", "peak_mm: 1.5 mm is below the SD 5 mm"]),
    "tampings not whole": (dict(sections=SECTIONS.replace("D,200,plain,yes,,0.5,3", "D,200,plain,yes,,0.5,2.5")),
                           ["row 6 (section D)", "tampings_since_renewal: must be a whole number"]),
    "wet not yes/no": (dict(sections=SECTIONS.replace("D,200,plain,yes", "D,200,plain,damp")),
                       ["row 6 (section D)", "wet: 'damp' is not yes, no or suspected (accepted, in any case: yes, y, "
                        "true, 1 for yes; no, n, false, 0 or blank for no; suspected for a suspected wet zone)"]),
    "wet maybe (suspected)": (dict(sections=SECTIONS.replace("D,200,plain,yes", "D,200,plain,Maybe")),
                              ["row 6 (section D)", "wet: 'Maybe' is not yes, no or suspected",
                               "did you mean 'suspected'?"]),
    "defects not whole": (dict(sections=DEFECTS.replace("B,200,transition,no,,3,2,2", "B,200,transition,no,,3,2,1.5")),
                          ["row 4 (section B)", "defects: must be a whole number, got '1.5'"]),
    "defects above 20": (dict(sections=DEFECTS.replace("B,200,transition,no,,3,2,2", "B,200,transition,no,,3,2,21")),
                         ["row 4 (section B)", "defects: 21 is outside [0, 20] (known short defects in the section)"]),
    "defects negative": (dict(sections=DEFECTS.replace("B,200,transition,no,,3,2,2", "B,200,transition,no,,3,2,-1")),
                         ["row 4 (section B)", "defects: -1 is outside [0, 20]"]),
    "defects not a number": (dict(sections=DEFECTS.replace("B,200,transition,no,,3,2,2",
                                                           "B,200,transition,no,,3,2,two")),
                             ["row 4 (section B)", "defects: 'two' is not a number"]),
    "cells missing in a row": (dict(sections=SECTIONS.replace("A,200,plain,no,,2,1", "A,200,plain,no,2,1")),
                               ["row 3", "6 cells where the header has 7 columns"]),
    "too many sections": (dict(sections=SECTIONS.splitlines()[1] + "\n"
                               + "".join(f"X{i},200,plain,no,,1,0\n" for i in range(300))),
                          ["sections (300 rows)", "n_sections must be an integer in [1, 256], got 300",
                           "split the line into lines of a network file"]),
    "tonnage in kilotonnes": (dict(line=LINE.replace("annual_mgt: 15", "annual_mgt: 15000")),
                              ["traffic.annual_mgt", "got 15000; it looks like kt/year: give it in MGT/year"]),
    # YAML takes a date-shaped value for a date and fails to build one, outside its own errors
    "impossible date in the line file": (dict(line=LINE.replace("as_of: 2026-01-01", "as_of: 2026-13-01")),
                                         ["line.yaml, line", "'2026-13-01' is not a date", "month must be in 1..12"]),
    "unsupported schema": (dict(line="schema: 2\n" + LINE), ["line.yaml, schema: version 2 is not supported"]),
    "a list, not a mapping": (dict(line="- name\n- as_of\n"), ["line.yaml: a line file is a YAML mapping"]),
}


@pytest.mark.parametrize("kind", list(FAULTS))
def test_every_fault_is_one_line_naming_file_row_and_field(tmp_path, kind):
    files, expected = FAULTS[kind]
    path = write(tmp_path, **files)
    with pytest.raises(LineFileError) as err:
        load_line(path)
    text = str(err.value)
    assert isinstance(err.value, ValueError)
    assert "\n" not in text and text.startswith(str(tmp_path))
    for part in expected:
        assert part in text, f"{part!r} not in {text!r}"


@pytest.mark.parametrize("length", ["10", "20", "2000"])
def test_a_bad_section_length_is_said_in_the_files_terms(tmp_path, length):
    """A section's length out of what a line file allows names the file's column and range, never the config's
    fields (section_length_m, segment_length_m, sections_per_segment: a line file cannot set them)."""
    with pytest.raises(LineFileError) as err:
        load_line(write(tmp_path, sections=SECTIONS.replace("C,200", f"C,{length}")))
    text = str(err.value)
    assert f"sections.csv, row 5 (section C), length_m: {length} m is outside [30, 1000] m" in text
    for internal in ("section_length_m", "segment_length_m", "sections_per_segment"):
        assert internal not in text


def test_the_documented_section_length_range_is_the_loaders():
    """The page states the range a line file's section length may take, the loader's."""
    from trackenv.envs.line_file import SECTION_LENGTH_RANGE_M

    page = (Path(__file__).resolve().parents[2] / "docs" / "environments" / "line-files.md").read_text()
    row = next(line for line in page.splitlines() if line.startswith("| `length_m` |"))
    lo, hi = SECTION_LENGTH_RANGE_M
    assert f"{lo:g}-{hi:g} m" in row and "30-1000 m" in page.split("### The sections (CSV)")[0]


@pytest.mark.parametrize("yes, no", [("Y", "N"), ("y", "n"), ("YES", "No"), ("true", "FALSE"), ("1", "0")])
def test_wet_takes_the_documented_yes_and_no(tmp_path, yes, no):
    sections = SECTIONS.replace("A,200,plain,no", f"A,200,plain,{no}").replace("D,200,plain,yes",
                                                                               f"D,200,plain,{yes}")
    assert [s.wet for s in load_line(write(tmp_path, sections=sections)).sections] == [False, False, False, True]


def test_a_dimensionless_value_out_of_range_gets_no_unit_and_no_per_cent_hint(tmp_path):
    """tampings_since_renewal 150: no '-' for a unit and no 'it looks like per cent' (that is for fractions)."""
    with pytest.raises(LineFileError) as err:
        load_line(write(tmp_path, sections=SECTIONS.replace("D,200,plain,yes,,0.5,3", "D,200,plain,yes,,0.5,150")))
    assert str(err.value).endswith("row 6 (section D), tampings_since_renewal: 150 is outside [0, 100]")


def test_a_missing_line_file_is_one_line(tmp_path):
    with pytest.raises(LineFileError, match=r"^no such line file: .*nowhere\.yaml$"):
        load_line(tmp_path / "nowhere.yaml")


def test_a_sections_own_speed_traffic_and_length_load_into_the_config(tmp_path):
    sections = (SECTIONS.replace("annual_mgt,", "annual_mgt,speed_kmh,freight_share,")
                .replace("A,200,plain,no,,", "A,250,plain,no,,,,")
                .replace("B,200,transition,no,,", "B,200,transition,no,,80,,")
                .replace("C,200,switch_or_crossing,no,30,", "C,150,switch_or_crossing,no,30,80,0.7,")
                .replace("D,200,plain,yes,,", "D,200,plain,yes,,,0.7,"))
    line = load_line(write(tmp_path, sections=sections, history=None, line=LINE.replace("history: history.csv\n",
                                                                                        "")))
    assert [s.speed_kmh for s in line.sections] == [100.0, 80.0, 80.0, 100.0]  # blank: the line's
    assert [s.freight_share for s in line.sections] == [0.4, 0.4, 0.7, 0.7]
    assert line.section_length_m == 200.0 and line.length_m == 800.0  # the most common length is the line's
    c = LineConfig(line=line)
    assert c.section_length_m == 200.0
    assert dict(c.per_section) == {"annual_mgt": (15.0, 15.0, 30.0, 15.0), "freight_share": (0.4, 0.4, 0.7, 0.7),
                                   "section_length_m": (250.0, 200.0, 150.0, 200.0),
                                   "speed_kmh": (100.0, 80.0, 80.0, 100.0)}
    assert c.length_factors.tolist() == [1.25, 1.0, 0.75, 1.0]
    # the file's values can be given again only as they are
    assert LineConfig(line=line, per_section=dict(c.per_section)) == c
    with pytest.raises(ValueError, match="per_section=.* conflicts with the line file"):
        LineConfig(line=line, per_section={"speed_kmh": (100.0,) * 4})
    batch = LineBatch(c, 1)
    assert batch.pass_speed.tolist() == pytest.approx([100 / 3.6, 80 / 3.6, 80 / 3.6, 100 / 3.6])
    assert batch.traffic_factor.tolist() == [1.0, 1.0, 2.0, 1.0]


def test_a_notes_column_is_refused_saying_where_notes_go(tmp_path, line_file):
    """A spreadsheet's "comment" column (no known column near its name) is refused, saying that a note goes on a
    line of its own starting with '#', which the loader skips."""
    sections = line_file.parent / "sections.csv"
    rows = [r for r in sections.read_text().splitlines() if r.strip() and not r.startswith("#")]
    sections.write_text("\n".join([rows[0] + ",comment", *(r + ",checked 2025" for r in rows[1:])]) + "\n")
    with pytest.raises(LineFileError, match=r"unknown column 'comment' .*a note goes on a line of its own starting "
                                            r"with '#'"):
        load_line(line_file)
    sections.write_text("\n".join([rows[0], "# checked 2025", *rows[1:]]) + "\n")
    assert len(load_line(line_file).sections) == len(rows) - 1


def test_a_line_dict_is_checked_as_a_file(line_file):
    d = load_line(line_file).to_dict()
    d["sections"][1]["register"] = "bridge"
    with pytest.raises(LineFileError, match=r"^<line dict>, sections\[1\] \(section B\), register: 'bridge'"):
        LineDescription.from_dict(d)
    d = load_line(line_file).to_dict()
    d["sections"][0]["lenght_m"] = d["sections"][0].pop("length_m")
    with pytest.raises(LineFileError, match="unknown column 'lenght_m'; did you mean 'length_m'"):
        LineDescription.from_dict(d)


# ---------------------------------------------------------------------- the config
def test_the_config_takes_the_files_fields(line_file):
    c = LineConfig(line=str(line_file), capacity=3)
    assert (c.n_sections, c.section_length_m, c.speed_kmh, c.annual_mgt, c.freight_share) == (4, 200.0, 100.0,
                                                                                               15.0, 0.4)
    assert c.line == load_line(line_file) and c.capacity == 3
    assert LineConfig(line=line_file).capacity == 4  # at most the line's sections
    # the round trip through to_dict keeps the line (a JSON-ready dict), and the config stays hashable
    assert LineConfig.from_dict(c.to_dict()) == c and hash(c.replace(horizon_years=2.0)) != hash(c)
    assert c.replace(horizon_years=2.0).line == c.line
    assert pickle.loads(pickle.dumps(c)) == c
    small = LineConfig.coerce("small").replace(line=line_file)  # the scenario's capacity, the file's sections
    assert (small.n_sections, small.capacity) == (4, 3)
    assert small.replace(line=None).n_sections == 12  # without the file, the defaults again


@pytest.mark.parametrize("make", [
    lambda p: LineConfig(line=p, n_sections=7),
    lambda p: LineConfig(line=p).replace(speed_kmh=80.0),
    lambda p: gym.make("trackenv/TampingLine-v0", line=p, annual_mgt=20.0),
])
def test_a_field_the_file_sets_cannot_be_given_as_well(line_file, make):
    with pytest.raises(ValueError, match="line file"):
        make(line_file)


# ---------------------------------------------------------------------- the engine
def test_the_zone_factors_are_the_engines():
    """zone_factors (which the file's register applies) equals what the engine's draw puts on each class."""
    base = LineConfig(n_sections=6, capacity=3)
    plain = LineBatch(base.replace(transition_probability=0.0, switch_probability=0.0), 1)
    plain.start([0], [np.random.default_rng(5)])
    n = base.n_sleepers
    for cls, probs in ((1, dict(transition_probability=1.0, switch_probability=0.0)),
                       (2, dict(transition_probability=0.0, switch_probability=1.0))):
        zoned = LineBatch(base.replace(**probs), 1)
        zoned.start([0], [np.random.default_rng(5)])  # the same draws: the register only multiplies
        rate, stiff = zone_factors(np.full(6, cls), n, base)
        assert np.allclose(zoned.base_rate / plain.base_rate, rate, rtol=1e-12)
        for j in range(6):
            k_z, k_p = zoned.model_tracks[j].ballast_stiffness, plain.model_tracks[j].ballast_stiffness
            first = (k_z.size - n) // 2
            assert np.allclose((k_z / k_p)[first : first + n], stiff[j], rtol=1e-12)


def test_the_drawn_section_factor_is_recovered():
    c = LineConfig(n_sections=6, capacity=3, transition_probability=0.0, switch_probability=0.0)
    batch = LineBatch(c, 1)
    batch.start([0], [np.random.default_rng(9)])
    rng = np.random.default_rng(9)  # the draw's first numbers: the AR(1) of the section factors
    e = rng.standard_normal(6)
    rho = np.exp(-c.section_length_m / c.rate_correlation_m)
    z = [e[0]]
    for j in range(1, 6):
        z.append(rho * z[-1] + np.sqrt(1 - rho * rho) * e[j])
    expected = np.exp(c.rate_sigma * np.array(z) - c.rate_sigma**2 / 2)
    assert np.allclose(drawn_section_factor(batch.base_rate, c), expected, rtol=1e-9)


def test_the_engine_applies_the_file(line_file):
    env = TampingLine(line=line_file, horizon_years=1.0)
    obs, info = env.reset(seed=3)
    assert obs["register"].tolist() == [0, 1, 2, 0]
    assert obs["years_since_tamping"].tolist() == [2.0, 3.0, 1.5, 0.5]
    assert obs["tampings_since_renewal"].tolist() == [1, 2, 0, 3]
    assert info["wet_spot_active"].tolist() == [False, False, False, True]  # known, wet from the start
    rows = env.engine.get_state(0).rows
    assert rows["traffic_factor"].tolist() == [1.0, 1.0, 2.0, 1.0]  # the config's (per_section annual_mgt)
    assert rows["wet_onset"][3] == -1  # not hidden: no onset to come
    # the sections with a fitted history start at the SD the fit gives
    fit = history_fit(env.config)
    for j, f in enumerate(fit.sections):
        if not np.isnan(f.start_sd_mm):
            assert info["section_sd_m"][j] * 1e3 == pytest.approx(f.start_sd_mm, rel=2e-3)


def test_a_sections_traffic_drives_its_settlement(tmp_path):
    """Two draws of the same line, one with section B at twice the traffic: B settles more in a step (by
    (2N)^0.2 / N^0.2 = 1.15 in the consolidation phase of Shenton's law, up to 2 in its linear phase), A as before."""
    one_traffic = SECTIONS.replace(",30,", ",,")
    settled = []
    for mgt in ("", "30"):
        sections = one_traffic.replace("B,200,transition,no,,3,2", f"B,200,transition,no,{mgt},0,2")
        line = LINE.replace("history: history.csv\n", "")
        env = TampingLine(line=write(tmp_path, line=line, sections=sections, history=None), horizon_years=1.0)
        env.reset(seed=1)
        env.step(np.zeros(4, np.int8))
        settled.append(env.engine.get_state(0).rows["u"].mean(axis=1))
    ratio = settled[1] / settled[0]
    assert 1.1 < ratio[1] < 2.0 and ratio[0] == pytest.approx(1.0, rel=1e-6)


def test_a_file_line_is_the_same_alone_and_in_the_vector_env(line_file):
    single = TampingLine(line=line_file, horizon_years=0.5)
    vec = TampingLineVectorEnv(2, line=line_file, horizon_years=0.5)
    obs, _ = single.reset(seed=4)
    vobs, _ = vec.reset(seed=4)
    assert np.array_equal(vobs["section_sd"][0], obs["section_sd"])
    action = np.array([1, 0, 0, 1], np.int8)
    obs, r, *_ = single.step(action)
    vobs, vr, *_ = vec.step(np.stack([action, action]))
    assert vr[0] == r and np.array_equal(vobs["section_sd"][0], obs["section_sd"])
    via_make = gym.make_vec("trackenv/TampingLine-v0", num_envs=2, vectorization_mode="vector_entry_point",
                            line=str(line_file), horizon_years=0.5)
    assert via_make.unwrapped.config == vec.config


def test_state_and_pickle_with_a_file(line_file):
    env = TampingLine(line=line_file, horizon_years=1.0)
    env.reset(seed=2)
    state = env.get_state()
    clone = pickle.loads(pickle.dumps(env))
    a = env.step(np.ones(4, np.int8))[1]
    assert clone.step(np.ones(4, np.int8))[1] == a
    other = TampingLine(line=load_line(line_file), horizon_years=1.0)  # an equal config
    other.set_state(state)
    assert other.step(np.ones(4, np.int8))[1] == a


# ---------------------------------------------------------------------- the history fit
def test_the_fit_reports_every_section(line_file):
    fit = history_fit(LineConfig(line=line_file))
    status = [f.status for f in fit.sections]
    assert status == ["fitted", "fitted", "start SD only", "no history"]
    a = fit.sections[0]
    assert a.points == 3 and a.rate_p10 < a.rate_factor < a.rate_p90 and a.residual_mm < 0.2
    assert fit.sections[2].start_sd_mm == pytest.approx(0.9)
    assert "A" in fit.table() and fit.to_dict()["fitted"] == 2
    o = line_overrides(LineConfig(line=line_file))
    assert np.isnan(o.rate_cdf[2:]).all() and np.all(np.diff(o.rate_cdf[0]) >= 0)


def test_the_fit_recovers_rates_the_engine_generated():
    """24 plain sections with rates drawn from the engine's prior, five years of noise-free recording-car runs
    generated by the engine: the fitted rates follow the true ones, far better than the prior does."""
    from trackenv_studies.line_files import fit_recovery

    r = fit_recovery(n_sections=24, seeds=(2,), years=5.0, truth_seed=1, sd_noise_mm=0.0)
    assert r["correlation_log"] > 0.85
    assert r["rms_log_error"] < 0.5 * r["rms_log_error_prior"]
    assert 0.8 < r["median_ratio"] < 1.25
    assert r["median_residual_mm"] < 0.03


# ---------------------------------------------------------------------- the example line
@pytest.mark.slow
def test_the_example_line_runs_an_episode():
    line = load_line(EXAMPLE)
    assert line.n_sections == 100 and line.length_m == 20_000.0 and line.section_length_m == 200.0
    assert {s.length_m for s in line.sections} == {150.0, 200.0, 250.0}
    assert {s.speed_kmh for s in line.sections} == {80.0, 120.0}  # the station's switches
    assert {(s.annual_mgt, s.freight_share) for s in line.sections} == {(18.0, 0.35), (24.0, 0.5)}  # the branch
    registers = [s.register for s in line.sections]
    assert registers.count("transition") == 4 and registers.count("switch_or_crossing") == 5
    assert sum(s.wet for s in line.sections) == 8 and len(line.history) > 1000
    env = gym.make("trackenv/TampingLine-v0", line=EXAMPLE, horizon_years=0.5)
    obs, info = env.reset(seed=0)
    assert obs["section_sd"].shape == (100,)
    total = 0.0
    for _ in range(2):
        obs, r, _, truncated, info = env.step(env.action_space.sample() * 0)
        total += r
    assert truncated and np.isfinite(total)
    fit = history_fit(env.unwrapped.config)
    assert len(fit.fitted) > 50


def test_the_documented_schema_is_the_loaders():
    """The schema tables of the documentation's page list every key and column the loader knows, with its
    unit and whether it is required."""
    from trackenv.envs.line_file import COST_KEYS, HISTORY_COLUMNS, LINE_KEYS, SECTION_COLUMNS, TRAFFIC_KEYS

    page = (Path(__file__).resolve().parents[2] / "docs" / "environments" / "line-files.md").read_text()
    rows = {}
    for line in page.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if line.startswith("| `") and len(cells) >= 3:
            rows.setdefault(cells[0].strip("`"), []).append((cells[1], cells[2]))
    tables = [(LINE_KEYS, ""), (TRAFFIC_KEYS, "traffic."), (COST_KEYS, "costs."), (SECTION_COLUMNS, ""),
              (HISTORY_COLUMNS, "")]
    for known, prefix in tables:
        for name, field in known.items():
            assert (field.unit, "yes" if field.required else "no") in rows[prefix + name], name


def test_a_line_files_costs_are_its_configs_and_its_own(tmp_path):
    """``costs`` in the file set those fields of the line's config (a quiet branch's speed restriction is
    cheaper); they travel with the line (its dict round trip, a replace), a --set of another value is refused
    as for its traffic, and the same value is taken."""
    from trackenv.envs import scenario

    path = write(tmp_path, line=LINE + "costs:\n  speed_restriction_cost: 4\n  possession_cost: 8.5\n")
    line = load_line(path)
    assert line.costs == (("possession_cost", 8.5), ("speed_restriction_cost", 4.0))
    config = scenario("default", line=path)
    assert (config.speed_restriction_cost, config.possession_cost) == (4.0, 8.5)
    assert config.immediate_action_cost == scenario("default").immediate_action_cost  # not given: the default
    assert LineDescription.from_dict(line.to_dict()) == line
    assert type(config).from_dict(config.to_dict()) == config
    assert config.replace(horizon_years=2.0).speed_restriction_cost == 4.0
    with pytest.raises(ValueError, match=r"speed_restriction_cost=20.0 conflicts with the line file .*, which sets "
                                         r"it to 4.0: leave it out"):
        scenario("default", line=path, speed_restriction_cost=20.0)  # 20 is the default: still refused
    with pytest.raises(ValueError, match="speed_restriction_cost come\\(s\\) from the line file"):
        config.replace(speed_restriction_cost=3.0)
    assert scenario("default", line=path, speed_restriction_cost=4.0).speed_restriction_cost == 4.0
    (tmp_path / "plain").mkdir()
    plain = scenario("default", line=write(tmp_path / "plain"))
    assert plain.speed_restriction_cost == 20.0 and config.replace(line=plain.line).speed_restriction_cost == 20.0


def test_only_a_cost_above_its_range_is_taken_for_euros(tmp_path):
    with pytest.raises(LineFileError) as err:
        load_line(write(tmp_path, line=LINE + "costs:\n  tamping_cost_per_m: -0.01\n"))
    assert "euros" not in str(err.value)


def test_a_register_class_is_read_in_any_case(tmp_path):
    """``Plain`` and ``TRANSITION`` are the classes they name (the ``wet`` column took any case, the register did
    not); a word of another meaning is still refused with the likely class."""
    line = load_line(write(tmp_path, sections=SECTIONS.replace("A,200,plain", "A,200,Plain")
                           .replace("B,200,transition", "B,200,TRANSITION")))
    assert [s.register for s in line.sections][:2] == ["plain", "transition"]


def test_a_chainage_column_checks_the_files_order(tmp_path):
    """``km`` (optional) gives each section's start: a file in chainage order loads (a gap is a chainage jump) and
    round-trips its chainage; a sheet re-sorted by another column, or two sections that overlap, is refused naming
    the row and the section above."""
    ordered = (SECTIONS.replace("tampings_since_renewal\n", "tampings_since_renewal,km\n")
               .replace("A,200,plain,no,,2,1", "A,200,plain,no,,2,1,12.0")
               .replace("B,200,transition,no,,3,2", "B,200,transition,no,,3,2,12.2")
               .replace("C,200,switch_or_crossing,no,30,1.5,0", "C,200,switch_or_crossing,no,30,1.5,0,13.5")
               .replace("D,200,plain,yes,,0.5,3", "D,200,plain,yes,,0.5,3,"))
    line = load_line(write(tmp_path, sections=ordered))
    assert [s.km for s in line.sections] == [12.0, 12.2, 13.5, None]
    assert LineDescription.from_dict(line.to_dict()).sections == line.sections
    swapped = ordered.replace(",12.2\n", ",11.9\n")
    with pytest.raises(LineFileError, match=r"row 4 \(section B\), km: starts at km 11.9, before section A "
                                            r"\(km 12, 200 m\) ends at km 12.2: the rows are out of chainage order"):
        load_line(write(tmp_path, sections=swapped))
    with pytest.raises(LineFileError, match="ends at km 12.2: the two overlap"):
        load_line(write(tmp_path, sections=ordered.replace(",12.2\n", ",12.1\n")))
    # a kilometre post as km+m, and chainages in metres, each get the number to give
    with pytest.raises(LineFileError, match=r"'12\+200' is not a number \[km\]; give the kilometre post as a "
                                            r"decimal number of km \(12\+200 is 12.2\)"):
        load_line(write(tmp_path, sections=ordered.replace(",12.2\n", ",12+200\n")))
    metres = ordered.replace(",12.0\n", ",0\n").replace(",12.2\n", ",200\n").replace(",13.5\n", ",400\n")
    with pytest.raises(LineFileError, match=r"km: the chainages step by the sections' lengths in metres \(0, 200, "
                                            r"...\): give them in km \(0, 0.2, ...\)"):
        load_line(write(tmp_path, sections=metres))


def test_a_line_files_capacity_is_its_possessions(tmp_path):
    """``capacity`` in the file (sections of work a quarter) sets the line's config, round-trips, refuses a
    ``--set`` of another value as the file's other fields do, and one outside [1, sections] names the range; on a
    network it stays that line's while the machine's capacity applies to the lines that give none."""
    from trackenv.envs.network import NetworkConfig

    path = write(tmp_path, line=LINE + "capacity: 3\n")
    line = load_line(path)
    assert line.capacity == 3 and LineDescription.from_dict(line.to_dict()).capacity == 3
    assert LineConfig(line=path).capacity == 3 and LineConfig(line=path, capacity=3).capacity == 3
    with pytest.raises(ValueError, match="capacity=2 conflicts with the line file .* which sets it to 3"):
        LineConfig(line=path, capacity=2)
    other = tmp_path / "other"
    other.mkdir()
    for bad in (0, 5):
        with pytest.raises(LineFileError, match=r"capacity: sections of work a quarter, in \[1, 4\] \(the line's "
                                                rf"sections\), got {bad}"):
            load_line(write(other, line=LINE + f"capacity: {bad}\n"))
    net = NetworkConfig(line_config=[LineConfig(line=path), LineConfig(line=write(other))], capacity=2)
    assert [c.capacity for c in net.line_config] == [3, 2]


# ---------------------------------------------------------------------- known short defects, suspected wet zones
NO_HISTORY = LINE.replace("history: history.csv\n", "")
#: DEFECTS with C suspected wet, in mixed case (D stays known wet)
SUSPECTED = DEFECTS.replace("C,200,switch_or_crossing,no", "C,200,switch_or_crossing,SusPected")


def test_known_defects_and_a_suspected_wet_zone_load_and_round_trip(tmp_path):
    """``defects`` (blank: not known) and ``wet`` = suspected (any case) load into the sections, neither makes a
    section known wet, and the description round-trips through its dict (a blank count stays blank) and a
    config's."""
    line = load_line(write(tmp_path, sections=SUSPECTED))
    assert [s.defects for s in line.sections] == [None, 2, None, 0]
    assert [s.wet for s in line.sections] == [False, False, False, True]
    assert [s.wet_suspected for s in line.sections] == [False, False, True, False]
    rows = line.to_dict()["sections"]
    assert [r["wet"] for r in rows] == ["no", "no", "suspected", "yes"]
    assert ["defects" in r for r in rows] == [False, True, False, True]
    assert LineDescription.from_dict(line.to_dict()) == line
    config = LineConfig(line=line)
    assert LineConfig.from_dict(config.to_dict()) == config
    overrides = line_overrides(config)
    assert overrides.defects.tolist() == [-1, 2, -1, 0]
    assert overrides.wet.tolist() == [False, False, False, True]
    assert overrides.wet_suspected.tolist() == [False, False, True, False]
    (tmp_path / "plain").mkdir()
    plain = load_line(write(tmp_path / "plain"))
    assert all(s.defects is None and not s.wet_suspected for s in plain.sections)
    assert "defects" not in plain.to_dict()["sections"][0]


def test_a_file_with_known_defects_counts_them_once_in_the_section(tmp_path):
    """A 30 m segment's own SD would weigh a defect about seven times more than once in its 200 m section: a file
    that gives a count sets ``local_defect_near_m`` to the short-defect preset's 3 m, as it sets its other fields
    (another value given as well is refused; the preset's equal one is taken), and a file without counts, or with
    the column blank, leaves the config's (0 on the default line) as it was."""
    from trackenv.envs.line_config import KNOWN_DEFECT_NEAR_M, SCENARIOS, scenario

    folders = {name: tmp_path / name for name in ("known", "blank", "none")}
    for folder in folders.values():
        folder.mkdir()
    known = write(folders["known"], sections=DEFECTS, line=NO_HISTORY, history=None)
    blank = write(folders["blank"], sections=DEFECTS.replace(",2\n", ",\n").replace(",0\n", ",\n"), line=NO_HISTORY,
                  history=None)
    none = write(folders["none"], line=NO_HISTORY, history=None)
    assert KNOWN_DEFECT_NEAR_M == SCENARIOS["defects"]["local_defect_near_m"] == 3.0
    assert LineConfig(line=known).local_defect_near_m == 3.0
    assert LineConfig(line=blank).local_defect_near_m == LineConfig(line=none).local_defect_near_m == 0.0
    assert scenario("defects", line=known).local_defect_near_m == 3.0  # the preset's equal value
    with pytest.raises(ValueError, match=r"local_defect_near_m=5.0 conflicts with the line file .*, which sets it to "
                                         r"3.0: leave it out"):
        LineConfig(line=known, local_defect_near_m=5.0)
    with pytest.raises(ValueError, match=r"local_defect_near_m come\(s\) from the line file"):
        LineConfig(line=known).replace(local_defect_near_m=1.0)
    assert LineConfig(line=known).replace(line=load_line(none)).local_defect_near_m == 0.0  # the new file's
    # an env's keywords go through replace: the default's 0 gives way to the file's (it is not given)
    made = gym.make("trackenv/TampingLine-v0", line=str(known), horizon_years=0.5)
    assert made.unwrapped.config.local_defect_near_m == 3.0
    assert LineConfig(line=none, local_defect_near_m=5.0).local_defect_near_m == 5.0  # no counts: the config's
    # and a defect on a zone settles at the faster rate, as on the preset (multiplied, a few ran away)
    assert LineConfig(line=known).local_defect_in_zone == "faster" == SCENARIOS["defects"]["local_defect_in_zone"]
    assert LineConfig(line=none).local_defect_in_zone == "multiply"


def test_a_section_gives_no_more_known_defects_than_its_segment_holds(tmp_path):
    """Three known defects (each 2.4 m with 3 m either side) fit the 30 m segment that stands for a section; a
    fourth is refused naming the section and what to do (split it in the file), not modelled as a segment full of
    overlapping patches (which settles more evenly: a smoother section)."""
    three = write(tmp_path, sections=DEFECTS.replace(",3,2,2\n", ",3,2,3\n"), line=NO_HISTORY, history=None)
    config = LineConfig(line=three)
    assert config.known_defects_fit() == 3 and max(s.defects or 0 for s in config.line.sections) == 3
    four = write(tmp_path, sections=DEFECTS.replace(",3,2,2\n", ",3,2,4\n"), line=NO_HISTORY, history=None)
    with pytest.raises(ValueError, match=r"section B gives 4 known short defects; the 30 m segment that stands for "
                                         r"a section in the model holds at most 3 apart .*split the section"):
        LineConfig(line=four)


def test_known_defects_on_a_switch_do_not_run_away(tmp_path):
    """A station's switch at 60 km/h with three known joints, a year without maintenance on the default line: the
    file's defects settle at the faster of their rate and the switch's (not 4 × 2.5 times plain track, which took
    such a section past the engine's validity within a quarter), so no episode leaves the model's validity."""
    sections = DEFECTS.replace("C,200,switch_or_crossing,no,30,1.5,0,", "C,200,switch_or_crossing,no,30,1.5,0,3")
    assert ",1.5,0,3" in sections
    line = NO_HISTORY.replace("speed_kmh: 100", "speed_kmh: 60")
    assert line != NO_HISTORY
    path = write(tmp_path, sections=sections, line=line, history=None)
    for seed in range(3):
        env = TampingLine(line=path, horizon_years=1.0)
        env.reset(seed=seed)
        for _ in range(4):
            info = env.step(np.zeros(4, np.int8))[4]
            assert not np.any(info["beyond_validity"]) and info["section_sd_mm"].max() < 10.0


def test_a_suspicion_below_the_ordinary_chance_of_a_wet_spot_warns(tmp_path):
    """suspected_wet_probability below wet_spot_probability makes the file's suspected zones less likely wet than
    its other sections: a warning naming both; none without suspected zones or at the defaults."""
    path = write(tmp_path, sections=SUSPECTED, line=NO_HISTORY, history=None)
    with pytest.warns(UserWarning, match=r"suspected_wet_probability = 0.2 is below wet_spot_probability = 0.35"):
        LineConfig(line=path, suspected_wet_probability=0.2, wet_spot_probability=0.35)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        LineConfig(line=path)
        (tmp_path / "dry").mkdir()
        LineConfig(line=write(tmp_path / "dry", line=NO_HISTORY, history=None), suspected_wet_probability=0.0)


def _defect_sleepers(path: Path, seed: int, **config) -> np.ndarray:
    """(sections,) the number of each section's sleepers whose rate after reset(seed) differs from that of the
    same file with every count 0: with a defect's factor above every zone's (the file's ``local_defect_in_zone``
    is "faster"), the sleepers of its patches, a patch's sleepers times their number where they lie apart."""
    zero = path.parent / "zero"
    zero.mkdir(exist_ok=True)
    counted = (path.parent / "sections.csv").read_text().splitlines()
    header = counted[1].split(",")
    column = header.index("defects")
    rows = [r.split(",") for r in counted[2:]]
    for r in rows:
        r[column] = "0"
    write(zero, line=NO_HISTORY, sections="\n".join([counted[0], counted[1], *map(",".join, rows)]) + "\n",
          history=None)
    rates = []
    for p in (path, zero / "line.yaml"):
        env = TampingLine(line=p, horizon_years=0.5, **config)
        env.reset(seed=seed)
        rates.append(env.batch.base_rate[: env.config.n_sections].copy())
    return (rates[0] != rates[1]).sum(axis=1)


@pytest.mark.parametrize("mean", [0.0, 1.0])
def test_a_known_count_places_exactly_that_many_defects(tmp_path, mean):
    """A section's known count is its number of short defects in every episode (their positions drawn anew), on
    the default line (no defects drawn: ``local_defects_mean`` 0) and where the config draws them (mean 1): the
    rates of each section's segment carry exactly count × the patch's sleepers of the defect's factor (the known
    patches lie apart: each in its own third of the segment); a blank section draws as the config does (none at
    mean 0)."""
    sections = (DEFECTS.replace("A,200,plain,no,,2,1,", "A,200,plain,no,,2,1,3").replace(",3,2,2\n", ",3,2,\n")
                .replace(",1.5,0,\n", ",1.5,0,1\n"))
    path = write(tmp_path, line=NO_HISTORY, sections=sections, history=None)
    assert [s.defects for s in load_line(path).sections] == [3, None, 1, 0]
    c = LineConfig(line=path, local_defects_mean=mean)
    patch = int(round(c.local_defect_length_m / SLEEPER_SPACING_M))  # a patch's sleepers
    where = []
    for seed in range(4):
        defects = _defect_sleepers(path, seed, local_defects_mean=mean, local_defect_rate_factor=10.0) / patch
        np.testing.assert_allclose(defects[[0, 2, 3]], [3, 1, 0], atol=1e-6)
        if mean == 0:
            assert defects[1] == pytest.approx(0.0, abs=1e-6)  # blank: none drawn on the default line
        env = TampingLine(line=path, horizon_years=0.5, local_defects_mean=mean)
        env.reset(seed=seed)
        near = env.batch.defect_near[:4]
        assert near[0].any() and near[2].any() and not near[3].any()  # counted once: 3 m either side
        where.append(np.flatnonzero(near[0]).tolist())
    assert len({tuple(w) for w in where}) > 1  # the positions are drawn per episode


def _first_steps(path: Path, seed: int, **config) -> tuple[dict, float]:
    env = TampingLine(line=path, horizon_years=0.5, **config)
    obs, _ = env.reset(seed=seed)
    _, reward, *_ = env.step(np.array([1, 0, 0, 1], np.int8))
    return obs, reward


@pytest.mark.parametrize("preset", ["default", "defects"])
def test_a_blank_defects_column_draws_as_without_it(tmp_path, preset):
    """The column blank on every section gives the episode of the same file without it, bit for bit (the
    Poisson draw is kept, on the default line and on the short-defect preset's, which draws defects); a count on
    the last section only leaves the draws of the sections before it as they were."""
    from trackenv.envs.line_config import SCENARIOS

    fields = {k: v for k, v in SCENARIOS[preset].items() if k != "choices" and k != "contact_sensor"}
    for name in ("without", "blank", "last"):
        (tmp_path / name).mkdir()
    blank_column = DEFECTS.replace(",2\n", ",\n").replace(",0\n", ",\n")
    without = write(tmp_path / "without", line=NO_HISTORY, history=None)
    blank = write(tmp_path / "blank", line=NO_HISTORY, sections=blank_column, history=None)
    last = write(tmp_path / "last", line=NO_HISTORY, sections=blank_column.replace("D,200,plain,yes,,0.5,3,",
                                                                                    "D,200,plain,yes,,0.5,3,2"),
                 history=None)
    drawn = []
    for seed in (0, 1):
        (obs_a, r_a), (obs_b, r_b) = _first_steps(without, seed, **fields), _first_steps(blank, seed, **fields)
        assert r_a == r_b and obs_a.keys() == obs_b.keys()
        for key in obs_a:
            np.testing.assert_array_equal(obs_a[key], obs_b[key])
        envs = [TampingLine(line=p, horizon_years=0.5, **fields) for p in (without, last)]
        for env in envs:
            env.reset(seed=seed)
        if preset == "defects":  # the same reach either way: the near sleepers compare
            np.testing.assert_array_equal(envs[0].batch.defect_near[:3], envs[1].batch.defect_near[:3])
            drawn.append(envs[1].batch.defect_near[:3].any())
        np.testing.assert_array_equal(envs[0].batch.base_rate[:3], envs[1].batch.base_rate[:3])
    assert any(drawn) or preset == "default"  # the preset's blank sections drew defects


def test_suspected_wet_sections_draw_their_spot_at_the_suspected_probability(tmp_path):
    """A suspected section's hidden wet spot is there with ``suspected_wet_probability`` (0.5 by default), the
    other sections' with ``wet_spot_probability`` (0 here, so exactly none), over 80 episodes (320 suspected
    draws: the share within 4 standard errors, ±0.11, of 0.5); a suspected section is not known wet: no survey
    result at the start and nothing working from it, unlike the known wet one. Its probability at 0 and 1 gives
    none and all."""
    sections = """\
section,length_m,register,wet,years_since_tamping,tampings_since_renewal
A,200,plain,suspected,2,1
B,200,plain,Suspected,3,2
C,200,plain,SUSPECTED,1,0
D,200,plain,no,1,0
E,200,plain,suspected,4,1
F,200,plain,yes,1,0
"""
    path = write(tmp_path, line=NO_HISTORY, sections=sections, history=None)
    suspected = np.array([True, True, True, False, True, False])

    def draws(lines: int, **fields) -> tuple[np.ndarray, LineBatch]:
        config = LineConfig(line=path, horizon_years=0.5, wet_spot_probability=0.0, **fields)
        batch = LineBatch(config, lines)
        batch.start(list(range(lines)), [np.random.default_rng([5, i]) for i in range(lines)])
        return batch.wet_present().reshape(lines, 6), batch

    wet, batch = draws(80)
    assert abs(wet[:, suspected].mean() - 0.5) < 0.11
    assert not wet[:, 3].any() and wet[:, 5].all()  # none elsewhere; the known one always
    survey = batch.survey.reshape(80, 6)
    assert (survey[:, suspected] == -1).all() and (survey[:, 5] == 1).all()  # not known: no survey result
    assert not batch.wet_active.reshape(80, 6)[:, suspected].any() and batch.wet_active.reshape(80, 6)[:, 5].all()
    assert draws(4, suspected_wet_probability=1.0)[0][:, suspected].all()
    assert not draws(4, suspected_wet_probability=0.0)[0][:, suspected].any()


def test_a_suspected_section_changes_nothing_but_its_wet_spots_probability(tmp_path):
    """The suspected sections' probability takes the place of ``wet_spot_probability`` in the same uniform draw:
    at the same probability the episode is that of the file without them, bit for bit; at another, only the wet
    spots differ (every other draw of the episode is the same)."""
    for name in ("plain", "suspected"):
        (tmp_path / name).mkdir()
    plain = write(tmp_path / "plain", line=NO_HISTORY, history=None)
    suspected = write(tmp_path / "suspected", line=NO_HISTORY, history=None,
                      sections=SECTIONS.replace("A,200,plain,no", "A,200,plain,suspected")
                      .replace("C,200,switch_or_crossing,no", "C,200,switch_or_crossing,suspected"))
    obs_a, r_a = _first_steps(plain, 2)
    obs_b, r_b = _first_steps(suspected, 2, suspected_wet_probability=LineConfig.wet_spot_probability)
    assert r_a == r_b
    for key in obs_a:
        np.testing.assert_array_equal(obs_a[key], obs_b[key])
    envs = [TampingLine(line=p, horizon_years=0.5, **kw) for p, kw in ((plain, {}),
                                                                       (suspected, {"suspected_wet_probability": 1.0}))]
    for env in envs:
        env.reset(seed=2)
    a, b = (env.engine.get_state(0).rows for env in envs)
    assert (b["wet_onset"][[0, 2]] >= 0).all()
    for key in ("offset", "influence", "defect_near", "wet_mask"):
        np.testing.assert_array_equal(a[key], b[key])


def test_suspected_wet_probability_is_checked():
    with pytest.raises(ValueError, match=r"suspected_wet_probability must lie in \[0, 1\], got 1.5"):
        LineConfig(suspected_wet_probability=1.5)
    assert LineConfig().suspected_wet_probability == 0.5


def test_an_env_made_with_keywords_takes_the_files_capacity_and_costs(tmp_path):
    """``gym.make(id, line=..., **fields)`` builds the id's config and replaces the line into it: the fields the
    new file sets (its capacity, its costs) give way to the file's, the id's defaults being no values given (they
    once conflicted: "capacity=6 conflicts with the line file")."""
    path = write(tmp_path, line=NO_HISTORY + "capacity: 3\ncosts:\n  speed_restriction_cost: 4\n", history=None)
    env = gym.make("trackenv/TampingLine-v0", line=str(path), horizon_years=0.5)
    assert (env.unwrapped.config.capacity, env.unwrapped.config.speed_restriction_cost) == (3, 4.0)
    with pytest.raises(ValueError, match="capacity=2 conflicts with the line file"):
        gym.make("trackenv/TampingLine-v0", line=str(path), capacity=2)
