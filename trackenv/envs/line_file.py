"""Lines from files: the schema of a line file, its loader and its checks.

A line is described by a YAML file (the line: its name, the date its state describes, its traffic) that names
a CSV file of its sections (one row per section: length, register class, known or suspected wet zone, traffic,
years since tamping, tampings since renewal, known short defects) and, optionally, a CSV file of its measured
history (recording-car runs: section, date, SD, mean-to-peak). :func:`load_line` reads them into a
:class:`LineDescription`: frozen and hashable (tuples), so a :class:`~trackenv.envs.line_config.LineConfig`
carries it (``LineConfig(line=...)``, ``gym.make("trackenv/TampingLine-v0", line="my_line.yaml")``) and
snapshots, pickling and config comparison keep working. The schema, with units, is on the documentation's page
"Lines from files" and in :data:`LINE_KEYS`, :data:`SECTION_COLUMNS` and :data:`HISTORY_COLUMNS`.

The files are in the units a railway uses (m, mm, MGT a year, km/h, years); the description keeps the file's
values with the unit in each name, and gives the SD and mean-to-peak in SI too (``sd_m``). Every fault in a
file raises :class:`LineFileError`, a ``ValueError`` whose text is one line naming the file, the row and the
field, and what is allowed: a command line prints it and exits with status 2. A misspelled key or column is an
error (with the closest known name), never a silent default; YAML is read with ``yaml.safe_load`` only.

Bounds: the line's own fields (number of sections, speed, traffic) and a section's own speed and traffic are
checked by :class:`~trackenv.envs.line_config.LineConfig`, the one place their ranges live, and its refusal is
reported against the file; a section's length has the range a line file allows (:data:`SECTION_LENGTH_RANGE_M`,
from ``LineConfig``'s bounds), and the other per-section and history fields have theirs in the column tables
below. Values that fit another unit (an SD given in m where mm is expected, a length in km, a share in per cent,
an axle load in kg) are named as such, and the usual slips of a spreadsheet's export (cells separated by ';', an
unquoted decimal comma, a trailing ',') are named in the error.
"""

from __future__ import annotations

import csv
import dataclasses
import datetime as dt
import difflib
import math
import os
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from .line_config import PER_SECTION_BOUNDS, REGISTER_CLASSES, LineConfig

#: The schema version this trackenv reads (the optional ``schema`` key of a line file).
SCHEMA_VERSION = 1
DAYS_PER_YEAR = 365.25
#: The lengths a line file's section may have [m]: at least the segment of track that represents it in the
#: physics (``LineConfig``'s default ``segment_length_m``, 30 m; a line file's config has one segment per
#: section) and at most ``LineConfig``'s longest section (1000 m).
SECTION_LENGTH_RANGE_M = (float(LineConfig.segment_length_m), PER_SECTION_BOUNDS["section_length_m"][1])


class LineFileError(ValueError):
    """A fault in a line file (or a line given as a dict): its text is one line naming the file, the row and the
    field, and what is allowed."""


@dataclass(frozen=True)
class Field:
    """One key of a line file or one column of its CSV files: its unit, whether it is required, the range a
    value must lie in (in the file's unit; None: checked elsewhere or unbounded) and what it means."""

    unit: str
    required: bool
    meaning: str
    low: float | None = None
    high: float | None = None


#: The keys of a line file (YAML). ``traffic`` is a mapping of :data:`TRAFFIC_KEYS`.
LINE_KEYS: dict[str, Field] = {
    "schema": Field("-", False, f"version of this schema (default {SCHEMA_VERSION})"),
    "name": Field("-", True, "the line's name"),
    "description": Field("-", False, "free text"),
    "as_of": Field("YYYY-MM-DD", True, "the date the sections' state describes: years since tamping count to it, "
                                       "no measurement is later, and an episode starts there"),
    "traffic": Field("-", True, "the line's traffic (keys below); a section's own columns override it"),
    "sections": Field("path", True, "the sections CSV file, relative to this file"),
    "history": Field("path", False, "the measured-history CSV file, relative to this file"),
    "costs": Field("-", False, "the line's own costs where they differ from the defaults (keys below): a branch's "
                   "speed restriction delays fewer trains than a main line's"),
    "capacity": Field("sections", False, "the line's possession capacity: sections of work a quarter (at most its "
                      "sections; default the config's, 6); on a network too (the machine's capacity, the network "
                      "file's, applies to the lines that give none)", 1),
}

#: The keys of a line file's ``costs`` mapping: fields of :class:`~trackenv.envs.line_config.LineConfig` (whose
#: docstring gives the defaults and their sources), each in k€ and within a plausibility window: a value above it
#: is taken for euros.
COST_KEYS: dict[str, Field] = {
    "possession_cost": Field("k€", False, "a step with track work on the line (call-out, night possession)",
                             0.0, 1000.0),
    "tamping_cost_per_m": Field("k€/m", False, "tamping a metre of track (0.01: 10 €/m)", 0.0, 1.0),
    "renewal_cost_per_m": Field("k€/m", False, "renewing a metre of ballast (0.15: 150 €/m)", 0.0, 10.0),
    "speed_restriction_cost": Field("k€", False, "a section-quarter at or above the intervention limit (a temporary "
                                    "speed restriction's delays)", 0.0, 1000.0),
    "immediate_action_cost": Field("k€", False, "a section-quarter at the immediate-action limit (a closure)",
                                   0.0, 10000.0),
    "geometry_cost_per_section_year": Field("k€", False, "a section-year at the SD alert limit (scaled by (SD / SD "
                                            "alert)²: poorer ride, faster wear)", 0.0, 1000.0),
}

#: The keys of a line file's ``traffic`` mapping; their ranges are :class:`LineConfig`'s.
TRAFFIC_KEYS: dict[str, Field] = {
    "annual_mgt": Field("MGT/year", True, "million gross tonnes a year"),
    "speed_kmh": Field("km/h", True, "line speed"),
    "freight_share": Field("-", True, "share of the tonnage that is freight, a fraction in [0, 1]"),
    "freight_axle_load_t": Field("t", False, "freight axle load (default 22.5 t: EN 15528 line category D)"),
}
DEFAULT_FREIGHT_AXLE_LOAD_T = 22.5

#: The most known short local defects a section's row may give (``defects``, 0-20): a larger count is taken for a
#: fault (another column's value) **[assumption]**. The model holds fewer in the 30 m segment that represents a
#: section (3 with the defaults: ``LineConfig.known_defects_fit``), which the config checks.
MAX_KNOWN_DEFECTS = 20
#: The columns of the sections CSV, one row per section in line order.
SECTION_COLUMNS: dict[str, Field] = {
    "section": Field("-", True, "the section's id: unique, any text (a kilometre post, an asset number)"),
    "length_m": Field("m", True, "section length: what its tamping, renewal and geometry cost and its possession "
                      "work scale with (its physics is the line's segment either way)", *SECTION_LENGTH_RANGE_M),
    "register": Field("-", True, "asset-register class (any case): " + ", ".join(REGISTER_CLASSES) + " (transition: a "
                      "bridge or culvert approach; switch_or_crossing: switches and crossings, level crossings)"),
    "wet": Field("yes/no", False, "a known wet zone (a cutting or formation with poor drainage): yes, y, true or 1; "
                 "no, n, false or 0 (any case); blank: no; suspected (any case): not known wet, but a hidden wet spot "
                 "is likelier than elsewhere (LineConfig's suspected_wet_probability)"),
    "annual_mgt": Field("MGT/year", False, "the section's tonnage (its axle passes); blank: the line's"),
    "speed_kmh": Field("km/h", False, "the section's speed (its passes, time steps and quality limits: a station's "
                       "switches, a restriction); blank: the line's"),
    "freight_share": Field("-", False, "the section's freight share of its tonnage (its mix of axle passes: freight "
                           "joining at a junction); blank: the line's"),
    "years_since_tamping": Field("year", True, "time from the section's last tamping (or renewal) to as_of",
                                 0.0, 50.0),
    "tampings_since_renewal": Field("-", True, "tampings since the last ballast renewal (a whole number)",
                                    0, 100),
    "rate_factor": Field("-", False, "the section's settlement-rate factor where it is known (1: typical plain "
                         "track); blank: drawn per episode, or fitted to the measured history", 0.01, 100.0),
    "km": Field("km", False, "the chainage where the section starts (its kilometre post): rising down the file, and "
                "no section starting before the one above it ends (a gap is fine: a chainage jump, sections not in "
                "the file); it checks the file's order, which the line's model follows; blank: not known",
                -1000.0, 10000.0),
    "defects": Field("-", False, "the number of known short local defects in the section (insulated joints, welds, "
                     "a failed sleeper, a crossing nose), a whole number; blank: not known, drawn as the config draws "
                     "them (LineConfig's local_defects_mean)", 0, MAX_KNOWN_DEFECTS),
}
#: Two sections overlap where one starts more than this before the one above it ends [m] (a chainage given to
#: the metre, lengths rounded).
CHAINAGE_TOLERANCE_M = 1.0

#: The columns of the history CSV: one row per recording-car run and section, in date order per section.
#: The SD range is a plausibility window (good track ~0.5 mm, poor ~3-5 mm over 200 m; EN 13848-6): a value
#: outside it is taken for a wrong unit.
HISTORY_COLUMNS: dict[str, Field] = {
    "section": Field("-", True, "a section id of the sections file"),
    "date": Field("YYYY-MM-DD", True, "date of the run; increasing per section, not after as_of"),
    "sd_mm": Field("mm", True, "standard deviation of the D1 (3-25 m) longitudinal level over the section",
                   0.05, 15.0),
    "peak_mm": Field("mm", False, "D1 mean-to-peak over the section (not below its SD); not used by the fit",
                     0.1, 60.0),
}

_YES, _NO = ("yes", "y", "true", "1"), ("no", "n", "false", "0", "")


@dataclass(frozen=True)
class Section:
    """One section of a line file, in line order (SI where the unit is not in the name). ``wet``: a known wet
    zone; ``wet_suspected``: not known wet, but suspected (its hidden wet spot is likelier: the config's
    ``suspected_wet_probability``); never both. ``defects``: the number of known short local defects (None: not
    known, drawn as without a file)."""

    id: str
    length_m: float
    register: str
    wet: bool
    annual_mgt: float
    speed_kmh: float
    freight_share: float
    years_since_tamping: float
    tampings_since_renewal: int
    rate_factor: float | None = None
    km: float | None = None
    wet_suspected: bool = False
    defects: int | None = None

    def __post_init__(self) -> None:
        if self.wet and self.wet_suspected:
            raise ValueError(f"section {self.id}: wet and wet_suspected exclude each other (a known wet zone is "
                             f"not merely suspected)")

    @property
    def wet_text(self) -> str:
        """The ``wet`` column's value for this section: "yes" (known), "suspected" or "no"."""
        return "yes" if self.wet else "suspected" if self.wet_suspected else "no"

    @property
    def register_index(self) -> int:
        """The register class as the observation codes it (0 plain, 1 transition, 2 switch or crossing)."""
        return REGISTER_CLASSES.index(self.register)


@dataclass(frozen=True)
class Measurement:
    """One recording-car run over one section: its ``date`` (ISO), SD and mean-to-peak of the D1 level as the
    file gives them [mm] (so a description round-trips through its dict exactly), in SI as ``sd_m``,
    ``peak_m``."""

    section: str
    date: str
    sd_mm: float
    peak_mm: float | None = None

    @property
    def sd_m(self) -> float:
        return self.sd_mm * 1e-3

    @property
    def peak_m(self) -> float | None:
        return None if self.peak_mm is None else self.peak_mm * 1e-3


@dataclass(frozen=True)
class LineDescription:
    """A line as its files describe it (:func:`load_line`); frozen and hashable, so a config can carry it.

    ``as_of`` (ISO date) is the date the sections' state describes; ``speed_kmh``, ``annual_mgt``,
    ``freight_share`` and ``freight_axle_load_t`` are the line's traffic; ``sections`` in line order;
    ``history`` in date order per section; ``costs`` the line's own costs (name, k€) of :data:`COST_KEYS`, where
    the file gives them. ``source`` names the file it was read from (not compared)."""

    name: str
    as_of: str
    speed_kmh: float
    annual_mgt: float
    freight_share: float
    freight_axle_load_t: float
    sections: tuple[Section, ...]
    history: tuple[Measurement, ...] = ()
    description: str = ""
    source: str = field(default="<dict>", compare=False)
    costs: tuple[tuple[str, float], ...] = ()
    capacity: int | None = None

    @property
    def n_sections(self) -> int:
        return len(self.sections)

    @property
    def section_length_m(self) -> float:
        """The line's section length [m]: the most common of its sections' lengths (of equally common ones, the
        first in line order); the unit of a possession's ``capacity`` and of the costs of a section."""
        lengths = [s.length_m for s in self.sections]
        return max(dict.fromkeys(lengths), key=lengths.count)

    @property
    def per_section(self) -> tuple[tuple[str, tuple[float, ...]], ...]:
        """What differs between its sections, as :class:`~trackenv.envs.line_config.LineConfig` takes it
        (``per_section``): for each of length, speed, annual tonnage and freight share that is not the line's on
        every section, its value per section."""
        line = {"section_length_m": self.section_length_m, "speed_kmh": self.speed_kmh,
                "annual_mgt": self.annual_mgt, "freight_share": self.freight_share}
        out = []
        for name, attr in (("annual_mgt", "annual_mgt"), ("freight_share", "freight_share"),
                           ("section_length_m", "length_m"), ("speed_kmh", "speed_kmh")):
            values = tuple(float(getattr(s, attr)) for s in self.sections)
            if any(v != line[name] for v in values):
                out.append((name, values))
        return tuple(out)

    @property
    def length_m(self) -> float:
        return sum(s.length_m for s in self.sections)

    @property
    def defects_known(self) -> bool:
        """Whether the file gives a count of known short defects on any section (its ``defects`` column): its
        config then counts each section's local defects once in the section's length
        (:func:`~trackenv.envs.line_config.file_fields`: ``local_defect_near_m``)."""
        return any(s.defects is not None for s in self.sections)

    @property
    def path(self) -> str | None:
        """The file the line was read from; None for a line given as data (a dict, a saved config), whose
        ``source`` is a placeholder in angle brackets."""
        return None if self.source.startswith("<") else self.source

    @property
    def label(self) -> str:
        """The line for people: its :attr:`path`, else its quoted name, in place of the whole description that
        ``to_dict`` writes (kilobytes: every section and measurement)."""
        return self.path or repr(self.name)

    def traffic_factors(self) -> tuple[float, ...]:
        """Per section, its tonnage over the line's (its axle passes are those of the line's tonnage times this)."""
        return tuple(s.annual_mgt / self.annual_mgt for s in self.sections)

    def measurements(self, section: str) -> tuple[Measurement, ...]:
        """The history of one section, in date order."""
        return tuple(m for m in self.history if m.section == section)

    def years_before(self, date: str) -> float:
        """Years from ``date`` (ISO) to ``as_of``."""
        return (dt.date.fromisoformat(self.as_of) - dt.date.fromisoformat(date)).days / DAYS_PER_YEAR

    # ------------------------------------------------------------------ the dict form (the files' units)
    def to_dict(self) -> dict[str, Any]:
        """The line as plain data in the files' keys and units (JSON-ready); :meth:`from_dict` reads it back."""
        traffic = {"annual_mgt": self.annual_mgt, "speed_kmh": self.speed_kmh, "freight_share": self.freight_share,
                   "freight_axle_load_t": self.freight_axle_load_t}
        sections = []
        for s in self.sections:
            row: dict[str, Any] = {"section": s.id, "length_m": s.length_m, "register": s.register,
                                   "wet": s.wet_text, "annual_mgt": s.annual_mgt,
                                   "speed_kmh": s.speed_kmh, "freight_share": s.freight_share,
                                   "years_since_tamping": s.years_since_tamping,
                                   "tampings_since_renewal": s.tampings_since_renewal}
            if s.rate_factor is not None:
                row["rate_factor"] = s.rate_factor
            if s.km is not None:
                row["km"] = s.km
            if s.defects is not None:
                row["defects"] = s.defects
            sections.append(row)
        history = []
        for m in self.history:
            h: dict[str, Any] = {"section": m.section, "date": m.date, "sd_mm": m.sd_mm}
            if m.peak_mm is not None:
                h["peak_mm"] = m.peak_mm
            history.append(h)
        out: dict[str, Any] = {"name": self.name, "as_of": self.as_of, "traffic": traffic, "sections": sections,
                               "history": history}
        if self.description:
            out["description"] = self.description
        if self.costs:
            out["costs"] = dict(self.costs)
        if self.capacity is not None:
            out["capacity"] = self.capacity
        if self.path is not None:  # a saved config names the file its line came from, from any folder
            out["source"] = str(Path(self.path).resolve())
        return out

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], source: str = "<line dict>") -> LineDescription:
        """A line from plain data with a line file's keys, whose ``sections`` and ``history`` are lists of rows
        (mappings of the CSV columns): checked as a file is, faults reported against ``source``. A ``source`` key
        (:meth:`to_dict` writes the file a line was read from) becomes the line's :attr:`path`."""
        if not isinstance(d, Mapping):
            raise LineFileError(f"{source}: a line must be a mapping of {_names(LINE_KEYS)}, got {type(d).__name__}")
        keys = {**LINE_KEYS, "sections": Field("-", True, "rows"), "history": Field("-", False, "rows"),
                "source": Field("path", False, "the file the line was read from")}
        _check_keys(source, "", d, keys)
        rows = {}
        for key, columns in (("sections", SECTION_COLUMNS), ("history", HISTORY_COLUMNS)):
            value = d.get(key, [])
            if not isinstance(value, (list, tuple)) or not all(isinstance(r, Mapping) for r in value):
                raise LineFileError(f"{source}, {key}: must be a list of rows (mappings of its columns)")
            rows[key] = [(f"{source}, {key}[{i}]", r) for i, r in enumerate(value)]
            for where, r in rows[key]:
                _check_keys(where, "", r, columns, what="column")
        line = _build(source, d, rows["sections"], rows["history"])
        read_from = d.get("source")
        if read_from is None:
            return line
        if not isinstance(read_from, str) or not read_from or read_from.startswith("<"):
            raise LineFileError(f"{source}, source: must be the path of the file the line was read from, got "
                                f"{read_from!r}")
        return dataclasses.replace(line, source=read_from)


# ---------------------------------------------------------------------- loading
def load_line(path: str | os.PathLike[str]) -> LineDescription:
    """Read a line file (YAML) and the CSV files it names into a checked :class:`LineDescription`.

    Raises :class:`LineFileError` (one line: the file, the row, the field and what is allowed) for anything
    wrong in them: a missing or empty file, invalid YAML, an unknown key or column, a missing field, a bad
    number, date or class, a value out of its range or in another unit, duplicate section ids, a history out of
    date order or naming an unknown section, traffic the engine cannot take."""
    path = Path(path)
    doc = yaml_mapping(path, "line file", LINE_KEYS)
    sections = _csv_rows(path, doc, "sections", SECTION_COLUMNS)
    history = _csv_rows(path, doc, "history", HISTORY_COLUMNS) if doc.get("history") is not None else []
    return _build(str(path), doc, sections, history)


def yaml_document(path: str | os.PathLike[str]) -> Any:
    """The YAML document of the file ``path``, or None where it cannot be read or parsed (a loader,
    :func:`yaml_mapping`, then names the fault): to tell a line file from a network file."""
    try:
        return yaml.safe_load(Path(path).read_text(encoding="utf-8-sig"))
    except (OSError, UnicodeDecodeError, ValueError, yaml.YAMLError):
        return None


def yaml_mapping(path: Path, what: str, keys: dict[str, Field]) -> dict[str, Any]:
    """The YAML mapping of the file ``path`` (a ``what``: "line file", "network file") with only ``keys`` and
    every required one of them, else :class:`LineFileError` naming the fault."""
    text = _read_text(path, what)
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as e:
        mark = getattr(e, "problem_mark", None)
        where = f", line {mark.line + 1}" if mark is not None else ""
        problem = getattr(e, "problem", None) or "syntax error"
        raise LineFileError(f"{path}{where}: not valid YAML ({problem})") from None
    except ValueError as e:  # YAML reads 2026-13-45 as a date and fails to build it, outside its own errors
        raise LineFileError(f"{path}{_impossible_date(text)}: {e}") from None
    return checked_mapping(path, what, keys, doc)


def checked_mapping(path: Path, what: str, keys: dict[str, Field], doc: Any) -> dict[str, Any]:
    """``doc``, the YAML document of the file ``path`` (a ``what``), if it is a mapping with only ``keys`` and every
    required one of them, else :class:`LineFileError` naming the fault: :func:`yaml_mapping`'s checks, for a
    document already read."""
    if doc is None:
        raise LineFileError(f"{path}: empty file; a {what} is a YAML mapping of {_names(keys)}")
    if not isinstance(doc, dict):
        csv = (" (a CSV file: give the YAML file that names it under 'sections' or 'history')"
               if Path(path).suffix.lower() == ".csv" else "")
        raise LineFileError(f"{path}: a {what} is a YAML mapping of {_names(keys)}, got a "
                            f"{type(doc).__name__}{csv}")
    if what == "line file" and "lines" in doc and "sections" not in doc:
        raise LineFileError(f"{path}: a network file (it lists line files under 'lines'), not a line file: plan it "
                            f"with trackenv plan, read it with trackenv.envs.load_network")
    if what == "network file" and "sections" in doc and "lines" not in doc:
        raise LineFileError(f"{path}: a line file (it has 'sections'), not a network file: read it with "
                            f"trackenv.envs.load_line, or list it under 'lines' in a network file")
    _check_keys(str(path), "", doc, keys)
    return doc


def _impossible_date(text: str) -> str:
    """", line N: 'YYYY-MM-DD' is not a date" for the first date-shaped value of ``text`` that names no day of
    the calendar (YAML takes it for a date and fails to build one), or "" where none is found."""
    for number, line in enumerate(text.splitlines(), start=1):
        for match in re.finditer(r"\b(\d{4})-(\d{1,2})-(\d{1,2})\b", line.split("#", 1)[0]):
            try:
                dt.date(*(int(g) for g in match.groups()))
            except ValueError:
                return f", line {number}: {match.group(0)!r} is not a date"
    return ""


def _read_text(path: Path, what: str, named_by: str = "") -> str:
    if not path.is_file():
        raise LineFileError(f"{named_by}no such {what}: {path}")
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as e:
        raise LineFileError(f"{path}: cannot be read as UTF-8 text ({e.__class__.__name__})") from None
    return text


def _csv_rows(line_path: Path, doc: dict, key: str, columns: dict[str, Field]) -> list[tuple[str, dict[str, str]]]:
    """The data rows of the CSV file that key ``key`` of the line file names: (where, {column: text}) with
    ``where`` naming the file and its line; blank lines and lines starting with ``#`` are skipped."""
    value = doc[key]
    if not isinstance(value, str) or not value.strip():
        raise LineFileError(f"{line_path}, key {key}: must be the path of a CSV file, got {value!r}")
    path = line_path.parent / value
    text = _read_text(path, f"{key} file", f"{line_path}, key {key}: ")
    reader = csv.reader(text.splitlines())
    header: list[str] | None = None
    rows = []
    for cells in reader:
        if not cells or all(not c.strip() for c in cells) or cells[0].lstrip().startswith("#"):
            continue
        cells = [c.strip() for c in cells]
        if header is None:
            header = cells
            _check_separator(path, header)
            _check_header(path, header, columns)
            continue
        where = f"{path}, row {reader.line_num}"
        if len(cells) != len(header):
            raise LineFileError(f"{where}: {len(cells)} cells where the header has {len(header)} columns"
                                + _extra_cells_hint(cells, len(header)))
        rows.append((where, dict(zip(header, cells))))
    if header is None:
        raise LineFileError(f"{path}: empty file; expected a header row with the columns {_names(columns)}")
    if not rows:
        raise LineFileError(f"{path}: a header and no rows; the {key} file needs one row per "
                            + ("section" if key == "sections" else "measurement"))
    return rows


def _check_separator(path: Path, header: list[str]) -> None:
    """A header whose cells hold ';' or a tab: a spreadsheet's export with another separator (the whole header
    read as one column), named as such."""
    for sep, name in ((";", "';'"), ("\t", "tabs")):
        if any(sep in cell for cell in header):
            raise LineFileError(f"{path}, header: the file separates its cells with {name} (the header reads as "
                                f"{header[0]!r}); a line file's CSV needs ',' between cells: export it as "
                                f"comma-separated CSV")


def _extra_cells_hint(cells: list[str], n_columns: int) -> str:
    """For a row with more cells than the header: the likely cause, or "". Extra empty cells at its end: a
    trailing ','; else two neighbouring cells of digits: a decimal comma (1,3 for 1.3) splitting a number (every
    such pair named: which one was split, the row alone cannot tell)."""
    extra = len(cells) - n_columns
    if extra <= 0:
        return ""
    if not any(cells[n_columns:]):
        return f"; it ends in {extra} empty cell{'s' * (extra > 1)} more (a trailing ',')"
    pairs = [(a, b) for a, b in zip(cells, cells[1:]) if re.fullmatch(r"[-+]?\d+", a) and re.fullmatch(r"\d+", b)]
    if not pairs:
        return ""
    (a, b), others = pairs[0], pairs[1:]  # the row alone cannot tell which pair was one number: name them all
    more = f"; other such neighbours: {', '.join(f'{x!r}, {y!r}' for x, y in others)}" if others else ""
    return (f"; a decimal comma? the cells {a!r}, {b!r} look like {a},{b} split in two: use a decimal point "
            f"({a}.{b}){more}")


def _check_header(path: Path, header: list[str], columns: dict[str, Field]) -> None:
    seen = set()
    for name in header:
        if name in seen:
            raise LineFileError(f"{path}, header: column {name!r} appears twice")
        seen.add(name)
        if name not in columns and not difflib.get_close_matches(name, list(columns), n=1):
            # (a spreadsheet's "comment" or "notes" column)
            raise LineFileError(f"{path}, header: unknown column {name!r} (known: {_names(columns)}); the file "
                                f"keeps no other columns: a note goes on a line of its own starting with '#'")
    _check_keys(str(path), "", dict.fromkeys(header, ""), columns, what="column", where="header")


def _check_keys(source: str, prefix: str, d: Mapping[str, Any], known: dict[str, Field], what: str = "key",
                where: str = "") -> None:
    """Unknown keys (with the closest known name) and missing required ones, as :class:`LineFileError`."""
    at = f"{source}, {where}" if where else source
    for name in d:
        if name not in known:
            hint = difflib.get_close_matches(str(name), list(known), n=1)
            did = f"; did you mean {hint[0]!r}?" if hint else ""
            raise LineFileError(f"{at}: unknown {what} '{prefix}{name}'{did} (known: {_names(known)})")
    for name, f in known.items():
        if f.required and name not in d:
            raise LineFileError(f"{at}: missing {what} '{prefix}{name}' ({f.meaning}; unit {f.unit})")


def _names(known: Iterable[str]) -> str:
    return ", ".join(known)


# ---------------------------------------------------------------------- values
def _text(where: str, name: str, value: Any) -> str:
    if isinstance(value, (dt.date, bool)) or value is None or isinstance(value, (list, dict)):
        raise LineFileError(f"{where}, {name}: must be text, got {value!r}")
    return str(value).strip()


def _number(where: str, name: str, value: Any, unit: str) -> float:
    """A finite number from a cell's text or a YAML/dict value; a bool, a decimal comma or text is refused."""
    if isinstance(value, bool) or value is None:
        raise LineFileError(f"{where}, {name}: must be a number [{unit}], got {value!r}")
    if isinstance(value, (int, float)):
        v = float(value)
    else:
        text = str(value).strip()
        if text == "":
            raise LineFileError(f"{where}, {name}: empty; a number [{unit}] is required")
        try:
            v = float(text)
        except ValueError:
            hint = "; use a decimal point" if "," in text and _is_float(text.replace(",", ".")) else ""
            km, plus, m = text.partition("+")
            if unit == "km" and plus and km.strip().isdigit() and _is_float(m):  # a chainage as km+m: 12+345
                hint = f"; give the kilometre post as a decimal number of km ({text} is {int(km) + float(m) / 1e3:g})"
            raise LineFileError(f"{where}, {name}: {text!r} is not a number [{unit}]{hint}") from None
    if not math.isfinite(v):
        raise LineFileError(f"{where}, {name}: must be a finite number [{unit}], got {value!r}")
    return v


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _in_range(where: str, name: str, v: float, f: Field, why: str = "") -> float:
    """``v`` if it lies in the field's range, else a :class:`LineFileError` naming the range (with its unit
    where it has one), ``why`` it is that range and another unit the value would fit."""
    lo, hi = f.low, f.high
    if (lo is None or v >= lo) and (hi is None or v <= hi):
        return v
    unit = "" if f.unit == "-" else f" {f.unit}"
    raise LineFileError(f"{where}, {name}: {v:g}{unit} is outside [{lo:g}, {hi:g}]{unit}{why}"
                        + _unit_hint(v, lo, hi, f.unit))


def _unit_hint(v: float, lo: float | None, hi: float | None, unit: str) -> str:
    """Which other unit a value out of range would fit (a length in km, an SD in m or µm, a share in %, an axle
    load in kg or kN)."""
    others = {"mm": ((1e3, "m"), (1e-3, "µm")), "m": ((1e3, "km"),), "km": ((1e-3, "m"),),
              "MGT/year": ((1e-6, "t/year"), (1e-3, "kt/year")),
              "t": ((1e-3, "kg"), (1 / 9.81, "kN")),
              "-": ((1e-2, "per cent"),) if hi is not None and hi <= 1 else ()}.get(unit, ())
    for scale, name in others:
        w = v * scale
        if (lo is None or w >= lo) and (hi is None or w <= hi):
            return f"; it looks like {name}: give it in {unit}" if unit != "-" else f"; it looks like {name}: " \
                                                                                   "give a fraction"
    return ""


def _integer(where: str, name: str, value: Any) -> int:
    v = _number(where, name, value, "-")
    if v != int(v):
        raise LineFileError(f"{where}, {name}: must be a whole number, got {value!r}")
    return int(v)


def _date(where: str, name: str, value: Any) -> str:
    if isinstance(value, dt.datetime):
        value = value.date()
    if isinstance(value, dt.date):
        return value.isoformat()
    text = "" if value is None else str(value).strip()
    try:
        if len(text) != 10:
            raise ValueError
        return dt.date.fromisoformat(text).isoformat()
    except ValueError:
        raise LineFileError(f"{where}, {name}: {text!r} is not a date; write YYYY-MM-DD") from None


def _choice(where: str, name: str, value: Any, choices: tuple[str, ...]) -> str:
    """``value`` as one of ``choices``, in any case (``Plain`` is ``plain``, as ``wet`` takes ``Yes``); else a
    LineFileError with the likely word."""
    text = _text(where, name, value)
    if text.lower() in choices:
        return text.lower()
    said = _SAID_OTHERWISE.get(text.lower())
    hint = [said] if said in choices else difflib.get_close_matches(text, choices, n=1)
    did = f"; did you mean {hint[0]!r}?" if hint else ""
    raise LineFileError(f"{where}, {name}: {text!r} is not one of {', '.join(choices)}{did}")


#: the usual abbreviations and other words for a register class, for the hint (the file must say it our way)
_SAID_OTHERWISE = {"s&c": "switch_or_crossing", "s+c": "switch_or_crossing", "switch": "switch_or_crossing",
                   "crossing": "switch_or_crossing", "turnout": "switch_or_crossing", "points": "switch_or_crossing",
                   "bridge": "transition", "bridge transition": "transition", "open": "plain",
                   "plain line": "plain", "plain track": "plain"}


_SUSPECTED = "suspected"
#: other words for a suspected wet zone, for the hint (the file must say "suspected")
_SUSPECTED_OTHERWISE = ("maybe", "suspect", "possible", "possibly", "probable", "probably", "likely", "perhaps",
                        "?")


def _wet(where: str, value: Any) -> str:
    """The ``wet`` cell as "yes" (a known wet zone), "no" or "suspected", each in its accepted forms in any case
    (a bool from a dict: yes or no); else a LineFileError listing them, with "suspected" for the words that mean
    it."""
    if isinstance(value, bool):
        return "yes" if value else "no"
    text = "" if value is None else str(value).strip().lower()
    if text in _YES:
        return "yes"
    if text in _NO:
        return "no"
    if text == _SUSPECTED:
        return _SUSPECTED
    did = f"; did you mean {_SUSPECTED!r}?" if text in _SUSPECTED_OTHERWISE else ""
    raise LineFileError(f"{where}, wet: {value!r} is not yes, no or {_SUSPECTED} (accepted, in any case: "
                        f"{', '.join(_YES)} for yes; {', '.join(_NO[:-1])} or blank for no; {_SUSPECTED} for a "
                        f"suspected wet zone){did}")


def _defects(where: str, value: Any) -> int | None:
    """The ``defects`` cell: a whole number of known short defects in :data:`SECTION_COLUMNS`' range, or None
    where blank (not known)."""
    if _blank(value):
        return None
    count = _integer(where, "defects", value)
    _in_range(where, "defects", count, SECTION_COLUMNS["defects"], " (known short defects in the section)")
    return count


def _blank(value: Any) -> bool:
    return value is None or (isinstance(value, str) and value.strip() == "")


# ---------------------------------------------------------------------- the description
def _build(source: str, doc: Mapping[str, Any], section_rows: Sequence[tuple[str, Mapping[str, Any]]],
           history_rows: Sequence[tuple[str, Mapping[str, Any]]]) -> LineDescription:
    """Check the line's keys and rows and build the description."""
    schema = doc.get("schema", SCHEMA_VERSION)
    if schema != SCHEMA_VERSION or isinstance(schema, bool):
        raise LineFileError(f"{source}, schema: version {schema!r} is not supported; this trackenv reads "
                            f"version {SCHEMA_VERSION}")
    name = _text(source, "name", doc["name"])
    if not name:
        raise LineFileError(f"{source}, name: must not be empty")
    description = _text(source, "description", doc.get("description", ""))
    as_of = _date(source, "as_of", doc["as_of"])
    traffic = doc["traffic"]
    if not isinstance(traffic, Mapping):
        raise LineFileError(f"{source}, traffic: must be a mapping of {_names(TRAFFIC_KEYS)}, got {traffic!r}")
    _check_keys(source, "traffic.", traffic, TRAFFIC_KEYS)
    line_traffic = {k: _number(source, f"traffic.{k}", traffic[k], f.unit) for k, f in TRAFFIC_KEYS.items()
                    if k in traffic}
    line_traffic.setdefault("freight_axle_load_t", DEFAULT_FREIGHT_AXLE_LOAD_T)
    for key, value in line_traffic.items():
        _config_check(source, f"traffic.{key}", key, value, TRAFFIC_KEYS[key].unit)
    sections = _sections(section_rows, line_traffic)
    _config_check(source, f"sections ({len(sections)} rows)", "n_sections", len(sections), "sections")
    history = _history(history_rows, {s.id for s in sections}, as_of)
    capacity = None
    if doc.get("capacity") is not None:
        capacity = _integer(source, "capacity", doc["capacity"])
        if not 1 <= capacity <= len(sections):
            raise LineFileError(f"{source}, capacity: sections of work a quarter, in [1, {len(sections)}] (the "
                                f"line's sections), got {capacity}")
    return LineDescription(name=name, as_of=as_of, sections=tuple(sections), history=tuple(history),
                           description=description, source=source, costs=_costs(source, doc.get("costs")),
                           capacity=capacity, **line_traffic)


def _costs(source: str, costs: Any) -> tuple[tuple[str, float], ...]:
    """The file's ``costs`` mapping (:data:`COST_KEYS`), checked, in the keys' order; () where it has none."""
    if costs is None:
        return ()
    if not isinstance(costs, Mapping):
        raise LineFileError(f"{source}, costs: must be a mapping of {_names(COST_KEYS)}, got {costs!r}")
    _check_keys(source, "costs.", costs, COST_KEYS)
    out = []
    for key, f in COST_KEYS.items():
        if key in costs:
            v = _number(source, f"costs.{key}", costs[key], f.unit)
            euros = "; give it in k€ (a larger value is taken for euros)" if f.high is not None and v > f.high else ""
            out.append((key, _in_range(source, f"costs.{key}", v, f, euros)))
    return tuple(out)


def _sections(rows: Sequence[tuple[str, Mapping[str, Any]]], line: dict[str, float]) -> list[Section]:
    out: list[Section] = []
    seen: dict[str, str] = {}
    cols = SECTION_COLUMNS
    # the values already checked (the line's were, with its traffic)
    checked: dict[str, set[float]] = {k: {line[k]} for k in ("annual_mgt", "speed_kmh", "freight_share")}
    above: Section | None = None  # the last section with a chainage
    for where, row in rows:
        sid = _text(where, "section", row["section"])
        if not sid:
            raise LineFileError(f"{where}, section: empty; every section needs an id")
        if sid in seen:
            raise LineFileError(f"{where}, section: id {sid!r} repeats {seen[sid]}; section ids must be unique")
        seen[sid] = where.rsplit(", ", 1)[-1]
        at = f"{where} (section {sid})"
        length = _number(at, "length_m", row["length_m"], "m")
        if length <= 0:
            raise LineFileError(f"{at}, length_m: must be a positive length [m], got {length:g}")
        _in_range(at, "length_m", length, cols["length_m"],
                  f", the lengths a line file allows (at least the {SECTION_LENGTH_RANGE_M[0]:g} m segment of track "
                  f"that represents a section)")
        traffic = {}
        for key in ("annual_mgt", "speed_kmh", "freight_share"):
            value = row.get(key)
            traffic[key] = line[key] if _blank(value) else _number(at, key, value, cols[key].unit)
            if traffic[key] not in checked[key]:  # the range of the line's value (LineConfig's)
                _config_check(at, key, key, traffic[key], cols[key].unit)
                checked[key].add(traffic[key])
        years = _in_range(at, "years_since_tamping",
                          _number(at, "years_since_tamping", row["years_since_tamping"], "year"),
                          cols["years_since_tamping"])
        count = _integer(at, "tampings_since_renewal", row["tampings_since_renewal"])
        _in_range(at, "tampings_since_renewal", count, cols["tampings_since_renewal"])
        rate = row.get("rate_factor")
        rate_factor = None if _blank(rate) else _in_range(at, "rate_factor", _number(at, "rate_factor", rate, "-"),
                                                          cols["rate_factor"], " (1: typical plain track)")
        km = None if _blank(row.get("km")) else _in_range(at, "km", _number(at, "km", row["km"], "km"), cols["km"])
        wet = _wet(at, row.get("wet"))
        out.append(Section(id=sid, length_m=length, register=_choice(at, "register", row["register"],
                                                                     REGISTER_CLASSES),
                           wet=wet == "yes", wet_suspected=wet == "suspected", years_since_tamping=years,
                           tampings_since_renewal=count, rate_factor=rate_factor, km=km,
                           defects=_defects(at, row.get("defects")), **traffic))
        if km is not None:
            _check_chainage(at, out[-1], above)
            above = out[-1]
    _check_chainage_unit(rows, out)
    return out


def _check_chainage_unit(rows: Sequence[tuple[str, Mapping[str, Any]]], sections: list[Section]) -> None:
    """A LineFileError where the ``km`` column (three sections with one at least) steps by each section's length
    taken as km: chainages in metres (0, 200, 400: a short line's fit the km range)."""
    given = [(where, s.km, s.length_m) for (where, _), s in zip(rows, sections, strict=True) if s.km is not None]
    if len(given) < 3 or not all(abs((b[1] - a[1]) - a[2]) <= CHAINAGE_TOLERANCE_M
                                 for a, b in zip(given[:-1], given[1:], strict=True)):
        return
    where = given[1][0].rsplit(", row", 1)[0]
    first, second = given[0][1], given[1][1]
    raise LineFileError(f"{where}, km: the chainages step by the sections' lengths in metres ({first:g}, "
                        f"{second:g}, ...): give them in km ({first / 1e3:g}, {second / 1e3:g}, ...)")


def _check_chainage(at: str, section: Section, above: Section | None) -> None:
    """A LineFileError where ``section`` starts before ``above`` (the last section above it with a chainage) ends,
    by more than :data:`CHAINAGE_TOLERANCE_M`: the rows are out of chainage order (a sheet sorted by another
    column) or overlap."""
    if above is None or above.km is None or section.km is None:
        return
    end = above.km + above.length_m / 1000.0
    if section.km >= end - CHAINAGE_TOLERANCE_M / 1000.0:
        return
    why = ("the rows are out of chainage order (a sheet sorted by another column, or listed in falling "
           "chainage?)" if section.km < above.km else "the two overlap")
    raise LineFileError(f"{at}, km: starts at km {section.km:g}, before section {above.id} (km {above.km:g}, "
                        f"{above.length_m:g} m) ends at km {end:g}: {why}; list the sections in the order of rising "
                        f"chainage, each after the one above it")


def _history(rows: Sequence[tuple[str, Mapping[str, Any]]], ids: set[str], as_of: str) -> list[Measurement]:
    out: list[Measurement] = []
    last: dict[str, tuple[str, str]] = {}
    cols = HISTORY_COLUMNS
    for where, row in rows:
        sid = _text(where, "section", row["section"])
        if sid not in ids:
            hint = difflib.get_close_matches(sid, sorted(ids), n=1)
            did = f"; did you mean {hint[0]!r}?" if hint else ""
            raise LineFileError(f"{where}, section: {sid!r} is not a section of the sections file{did}")
        at = f"{where} (section {sid})"
        date = _date(at, "date", row["date"])
        if date > as_of:
            raise LineFileError(f"{at}, date: {date} is after as_of {as_of}; the history ends at the line's as_of")
        if sid in last and date <= last[sid][0]:
            raise LineFileError(f"{at}, date: {date} is not after this section's previous run {last[sid][0]} "
                                f"({last[sid][1]}); the history must be in date order per section")
        last[sid] = (date, where.rsplit(", ", 1)[-1])
        sd = _in_range(at, "sd_mm", _number(at, "sd_mm", row["sd_mm"], "mm"), cols["sd_mm"])
        peak_value = row.get("peak_mm")
        peak = None
        if not _blank(peak_value):
            peak = _in_range(at, "peak_mm", _number(at, "peak_mm", peak_value, "mm"), cols["peak_mm"])
            if peak < sd:
                raise LineFileError(f"{at}, peak_mm: {peak:g} mm is below the SD {sd:g} mm; a mean-to-peak is "
                                    "at least the SD (columns swapped?)")
        out.append(Measurement(section=sid, date=date, sd_mm=sd, peak_mm=peak))
    return out


def _config_check(where: str, key: str, config_field: str, value: float, unit: str) -> None:
    """Check a line-level value against :class:`LineConfig`'s range for ``config_field`` (the one place it
    lives), reported against the file."""
    from .line_config import LineConfig

    kwargs: dict[str, Any] = {config_field: value, "capacity": 1}
    if config_field == "n_sections":
        kwargs[config_field] = int(value)
    try:
        LineConfig(**kwargs)
    except ValueError as e:
        lo_hi = _config_range(str(e))
        hint = _unit_hint(value, *lo_hi, unit) if lo_hi else ""
        if config_field == "n_sections" and value > 1:
            hint += ("; split the line into lines of a network file (trackenv plan NETWORK.yaml plans them "
                     "together) or give it longer sections")
        raise LineFileError(f"{where}, {key}: {e}{hint}") from None


def _config_range(message: str) -> tuple[float, float] | None:
    """The [low, high] a config check's message states, for the unit hint."""
    start, end = message.find("["), message.find("]")
    if start < 0 or end < start:
        return None
    try:
        lo, hi = (float(x) for x in message[start + 1 : end].split(","))
    except ValueError:
        return None
    return lo, hi
