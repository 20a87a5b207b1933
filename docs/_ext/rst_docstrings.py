"""A griffe extension for the documentation site: render trackenv's reST-flavoured docstrings as Markdown.

The docstrings are written for readers of the source and for ``help()``: reST simple tables (the env specs'
observation and info tables) and Sphinx roles (``:class:`~trackenv.Track```). mkdocstrings renders docstrings
as Markdown, where a simple table's ``====`` lines would turn its header row into a heading and a role would
show its markup. This extension rewrites both when griffe loads the package, so the site shows the docstrings
as they are meant, and the docstrings stay the one source of each fact. Nothing in the package changes.
"""

from __future__ import annotations

import re
from typing import Any

import griffe

_BORDER = re.compile(r"^(?P<indent>\s*)=+(?:\s+=+)+\s*$")
# :class:`~a.b.C` -> `C`;  :func:`a.b.f` -> `a.b.f`;  :meth:`.f` -> `f`
_ROLE = re.compile(r":(?:py:)?(?:class|func|meth|mod|data|attr|obj|exc|const):`(?P<tilde>~?)\.?(?P<target>[^`]+)`")


def _role(match: re.Match[str]) -> str:
    target = match["target"].strip()
    if match["tilde"]:
        target = target.rsplit(".", 1)[-1]
    return f"`{target}`"


def _columns(border: str) -> list[int]:
    """Start of each column: where each run of ``=`` begins."""
    return [m.start() for m in re.finditer(r"=+", border)]


def _cells(line: str, starts: list[int]) -> list[str]:
    ends = [*starts[1:], None]
    return [line[a:b].strip() if b is not None else line[a:].strip() for a, b in zip(starts, ends)]


def _table(lines: list[str], starts: list[int], indent: str) -> list[str]:
    """A reST simple table (the lines between and including its borders) as a Markdown pipe table."""
    body = [ln for ln in lines if not _BORDER.match(ln)]
    rows: list[list[str]] = []
    for ln in body:
        if not ln.strip():
            continue
        cells = _cells(ln, starts)
        if rows and not cells[0]:  # a continuation line: its text belongs to the row above
            rows[-1] = [f"{a} {b}".strip() for a, b in zip(rows[-1], cells)]
        else:
            rows.append(cells)
    if not rows:
        return lines
    header, *rest = rows
    out = [indent + "| " + " | ".join(header) + " |", indent + "|" + "---|" * len(header)]
    out += [indent + "| " + " | ".join(c.replace("|", "\\|") for c in row) + " |" for row in rest]
    return out


def to_markdown(text: str) -> str:
    """Rewrite the reST simple tables and Sphinx roles of one docstring as Markdown."""
    lines = text.splitlines()
    out: list[str] = []
    i = 0
    while i < len(lines):
        m = _BORDER.match(lines[i])
        if m is None:
            out.append(lines[i])
            i += 1
            continue
        # a simple table has three borders: top, under the header, bottom
        borders = [i]
        j = i + 1
        while j < len(lines) and len(borders) < 3:
            if _BORDER.match(lines[j]):
                borders.append(j)
            elif not lines[j].strip():
                break
            j += 1
        if len(borders) < 3:
            out.append(lines[i])
            i += 1
            continue
        if out and out[-1].strip():
            out.append("")  # a Markdown table needs a blank line before it
        out += _table(lines[i : borders[2] + 1], _columns(lines[i]), m["indent"])
        i = borders[2] + 1
    return _outside_code(_ROLE.sub(_role, "\n".join(out)))


def _outside_code(text: str) -> str:
    """Escape what Markdown would misread outside code spans: ``S[i, j] [N/m]`` is a reference link there."""
    parts = re.split(r"(`+[^`]*`+)", text)
    return "".join(p if i % 2 else p.replace("][", "]\\[").replace("] [", "] \\[") for i, p in enumerate(parts))


class RstDocstrings(griffe.Extension):
    """Rewrites every loaded object's docstring (see the module's docstring)."""

    def on_instance(self, *, node: Any, obj: griffe.Object, agent: Any, **kwargs: Any) -> None:
        if obj.docstring is not None:
            obj.docstring.value = to_markdown(obj.docstring.value)
