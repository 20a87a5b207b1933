"""Networks from files: several line files that share one tamping machine.

A network file (YAML) names the line files of a maintenance area and what the shared machine adds::

    name: Northern maintenance area
    lines:                 # line files, relative to this file (the documentation's page "Lines from files")
      - valley.yaml
      - branch.yaml
    machine_on: valley.yaml   # optional: the line the machine is on now (a listed file or a line's name);
                              # default the first
    capacity: 6               # optional: sections a step on the machine's line; default each line's own
    move_cost: 10             # optional: k€ to move the machine to another line; default NetworkConfig's

:func:`load_network` reads it (and every line file, each checked as :func:`~trackenv.envs.line_file.load_line`
checks it) into a :class:`NetworkDescription`, whose :meth:`~NetworkDescription.config` is the
:class:`~trackenv.envs.network.NetworkConfig` of ``trackenv/TampingNetwork-v0`` with each line a line of its own.
The lines' ``as_of`` dates must lie within one step (a quarter) of each other: the lines step together from the
latest of them. Every fault raises :class:`~trackenv.envs.line_file.LineFileError` naming the file and the key.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from .line_config import LineConfig
from .line_file import (
    DAYS_PER_YEAR,
    Field,
    LineDescription,
    LineFileError,
    _in_range,
    _integer,
    _number,
    _text,
    checked_mapping,
    load_line,
    yaml_document,
    yaml_mapping,
)
from .network import NetworkConfig

__all__ = ["NETWORK_KEYS", "NetworkDescription", "is_network_file", "load_network", "load_network_or_none"]

#: The network config's own fields that a network file sets, each with where (not fields of its lines)
_MACHINE_FIELDS = {"move_cost": "move_cost: 20, in k€", "start_line": "machine_on: the line the machine is on",
                   "n_lines": "lines: the line files", "line_config": "lines: the line files",
                   "machine_on": "machine_on: the line the machine is on"}

#: The keys of a network file (YAML).
NETWORK_KEYS: dict[str, Field] = {
    "name": Field("-", True, "the network's name"),
    "description": Field("-", False, "free text"),
    "lines": Field("paths", True, "the line files of the network (at least one), relative to this file"),
    "machine_on": Field("-", False, "the line the machine is on now: one of the listed files, or a line's name "
                        "(default: the first line)"),
    "capacity": Field("sections", False, "sections the machine tamps a step on its line (default: each line's "
                      "own capacity)", 1, None),
    "move_cost": Field("k€", False, f"moving the machine to another line (default {NetworkConfig.move_cost:g} "
                       "k€; at most 1000 k€: a larger value is taken for euros)", 0.0, 1000.0),
}


@dataclass(frozen=True)
class NetworkDescription:
    """A network as its file describes it (:func:`load_network`): its lines in the file's order, the machine's
    line now, and the machine's ``capacity`` and ``move_cost`` where the file gives them (None: the defaults).
    ``source`` names the file (not compared)."""

    name: str
    lines: tuple[LineDescription, ...]
    start_line: int = 0
    capacity: int | None = None
    move_cost: float | None = None
    description: str = ""
    source: str = field(default="<dict>", compare=False)

    @property
    def as_of(self) -> str:
        """The date the network's plan starts from: the latest of its lines' ``as_of``."""
        return max(line.as_of for line in self.lines)

    def config(self, line_configs: Sequence[LineConfig] | None = None, *, capacity: int | None = None,
               **line_fields: Any) -> NetworkConfig:
        """The :class:`~trackenv.envs.network.NetworkConfig` of this network: each line a
        :class:`~trackenv.envs.line_config.LineConfig` of its file with ``line_fields`` (any field but the file's
        own: a scenario's hidden parts, costs, the horizon, the engine), or ``line_configs`` where the caller made
        them (one per line, in the file's order: a plan models each line as its scenario); the machine's fields
        from the file, ``capacity`` over the file's. :class:`~trackenv.envs.line_file.LineFileError` naming a line
        whose ``as_of`` is more than a step before the latest, or whose config a field refuses."""
        for name, key in _MACHINE_FIELDS.items():
            if name in line_fields:
                raise ValueError(f"{name} is the network's, not a line's: set it in the network file {self.source} "
                                 f"({key})")
        lines = list(line_configs) if line_configs is not None else []
        for i, line in enumerate(self.lines if line_configs is None else ()):
            try:
                lines.append(LineConfig.from_dict({**line_fields, "line": line}))
            except ValueError as exc:
                raise LineFileError(f"{self.source}, lines[{i}] ({line.source}): {exc}") from None
        # a step in whole days, rounded up: 92 for a quarter, so that 1 October and 1 January step together
        step_days = math.ceil(DAYS_PER_YEAR / lines[0].steps_per_year)
        for i, line in enumerate(self.lines):
            late = -line.years_before(self.as_of) * DAYS_PER_YEAR  # days from its as_of to the latest
            if late > step_days + 1e-9:
                k, latest = next((k, other) for k, other in enumerate(self.lines) if other.as_of == self.as_of)
                raise LineFileError(f"{self.source}, lines[{i}] ({line.source}): as_of {line.as_of} is {late:.0f} "
                                    f"days before the network's latest ({self.as_of}, lines[{k}]: "
                                    f"{latest.source}); the lines step together, so "
                                    f"their states must be dated within one step ({step_days} days): bring "
                                    f"the file up to its last measurements")
        move_cost = NetworkConfig.move_cost if self.move_cost is None else self.move_cost
        try:
            return NetworkConfig(line_config=lines, capacity=self.capacity if capacity is None else capacity,
                                 move_cost=move_cost, start_line=self.start_line)
        except ValueError as exc:
            raise LineFileError(f"{self.source}: {exc}") from None

    def to_dict(self) -> dict[str, Any]:
        """The network as plain data: its own fields, each line as :meth:`LineDescription.to_dict`."""
        out = {f.name: getattr(self, f.name) for f in fields(self) if f.name not in ("lines", "source")}
        return {**out, "lines": [line.to_dict() for line in self.lines]}


def is_network_file(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` is a network file (a YAML mapping with ``lines``) rather than a line file; False for
    anything else, whose loader then names the fault."""
    return _is_network(yaml_document(path))


def _is_network(doc: Any) -> bool:
    """Whether a file's YAML document ``doc`` is a network file's (a mapping with ``lines``)."""
    return isinstance(doc, dict) and "lines" in doc


def load_network(path: str | os.PathLike[str]) -> NetworkDescription:
    """Read a network file (YAML) and every line file it names into a :class:`NetworkDescription`.

    Raises :class:`~trackenv.envs.line_file.LineFileError` for a fault in the network file (an unknown or
    missing key, no lines, a line listed twice, a ``machine_on`` that names no line or two, a bad number) or in
    a line file (reported as :func:`~trackenv.envs.line_file.load_line` reports it)."""
    return _network(Path(path), yaml_mapping(Path(path), "network file", NETWORK_KEYS))


def load_network_or_none(path: str | os.PathLike[str]) -> NetworkDescription | None:
    """:func:`load_network` where ``path`` is a network file (:func:`is_network_file`), else None (a line file,
    or a file whose loader then names the fault), reading the file once for both: what ``trackenv plan`` takes."""
    doc = yaml_document(path)
    if not _is_network(doc):
        return None
    return _network(Path(path), checked_mapping(Path(path), "network file", NETWORK_KEYS, doc))


def _network(path: Path, doc: dict[str, Any]) -> NetworkDescription:
    """The :class:`NetworkDescription` of the network file ``path`` from its YAML mapping ``doc`` (its keys
    checked): every line file read, every value checked (:func:`load_network`)."""
    source = str(path)
    listed = doc["lines"]
    if not isinstance(listed, list) or not listed or not all(isinstance(p, str) and p.strip() for p in listed):
        raise LineFileError(f"{source}, lines: must be a list of line files (paths relative to this file), got "
                            f"{listed!r}")
    files = [(path.parent / p.strip()).resolve() for p in listed]  # relative to the network file
    for i, file in enumerate(files):
        if file in files[:i]:
            raise LineFileError(f"{source}, lines[{i}]: {listed[i]!r} is listed twice")
    lines = []
    for i, file in enumerate(files):
        try:
            lines.append(load_line(file))
        except LineFileError as exc:
            raise LineFileError(f"{source}, lines[{i}] ({listed[i].strip()!r}, relative to the network file): "
                                f"{exc}") from None
    start = _machine_line(source, doc.get("machine_on"), listed, files, tuple(lines))
    capacity = None
    if doc.get("capacity") is not None:
        capacity = _integer(source, "capacity", doc["capacity"])
        most = max(line.n_sections for line in lines)
        if not 1 <= capacity <= most:
            raise LineFileError(f"{source}, capacity: {capacity} is outside [1, {most}] sections (the most any of "
                                f"its lines has); it counts sections a step, not metres")
    move_cost = None
    if doc.get("move_cost") is not None:
        move_cost = _in_range(source, "move_cost", _number(source, "move_cost", doc["move_cost"], "k€"),
                              NETWORK_KEYS["move_cost"], "; give it in k€ (10 is ten thousand euros)")
    return NetworkDescription(_text(source, "name", doc["name"]), tuple(lines), start, capacity, move_cost,
                              _text(source, "description", doc.get("description", "")), source)


def _machine_line(source: str, value: Any, listed: list[str], files: list[Path],
                  lines: tuple[LineDescription, ...]) -> int:
    """The index of the line ``machine_on`` names (a listed file, compared as a path relative to the network
    file's folder: ``./branch.yaml`` is ``branch.yaml``; or a line's name); 0 if not given. ``files``: the
    listed files resolved, in the order of ``listed``."""
    if value is None:
        return 0
    text = _text(source, "machine_on", value)
    named = (Path(source).parent / text).resolve()
    by_file = [i for i, file in enumerate(files) if file == named]
    by_name = [i for i, line in enumerate(lines) if line.name == text]
    found = sorted(set(by_file or by_name))
    if len(found) == 1:
        return found[0]
    known = ", ".join(repr(p.strip()) for p in listed)
    if not found:
        raise LineFileError(f"{source}, machine_on: {text!r} is neither a listed line file ({known}) nor a line's "
                            f"name")
    raise LineFileError(f"{source}, machine_on: {text!r} is the name of lines {found}: name the file instead "
                        f"({known})")
