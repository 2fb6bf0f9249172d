"""Wide text exports with several header lines (iba's ASCII export: signal ids or tags, names, units).

``export.header_rows`` says what each header line holds, in file order (``schemas.plant_config``:
``"tag"`` — the column names, matched to the configured tags —, ``"name"``, ``"unit"``,
``"start_time"`` — the recording's start in the second cell, for a relative time column —,
``"skip"``). :func:`read_header_rows` reads those lines from the start of a file and gives the
``tag`` line (the one header line the CSV decoder is given in front of every block), the number of
header lines (the first data line is the next) and the unit of every configured tag's column,
which ``transforms.ingest.units`` checks against the configuration. Other columns' units are
given too and not looked at.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from typing import IO

from flows.common.errors import ValvemonError
from schemas.plant_config import ExportSpec
from transforms.ingest.units import FileUnits


@dataclass(frozen=True)
class HeaderRows:
    """The header lines of one text export."""

    tag_line: bytes
    """The ``tag`` line as the file holds it (with its line end)."""
    lines: int
    """Header lines read: the first data line is ``lines + 1``."""
    units: FileUnits | None
    """Column (tag) → (unit as written, ``column N 'name'``); None without a ``unit`` line."""
    start: tuple[str, int] | None = None
    """The ``start_time`` line's second cell and the line's number; None without such a line."""


def _fields(line: bytes, separator: str) -> list[str]:
    text = line.decode("utf-8", errors="replace").rstrip("\r\n")
    return next(csv.reader([text], delimiter=separator, quotechar='"'), [])


def _width(row: list[str]) -> int:
    """Fields up to the last non-empty one (a trailing separator adds none)."""
    n = len(row)
    while n and not row[n - 1].strip():
        n -= 1
    return n


def _is_number(cell: str, decimal: str) -> bool:
    try:
        float(cell.replace(",", ".") if decimal == "," else cell)
    except ValueError:
        return False
    return True


def read_header_rows(fh: IO[bytes], export: ExportSpec, where: str) -> HeaderRows:
    """Read ``export.header_rows`` lines from ``fh`` (positioned at the file's start).

    Parameters
    ----------
    where : str
        The file, for messages.

    Raises
    ------
    ValvemonError
        Naming the file and line: fewer lines than header rows, a tag line without the time
        column, a header line holding data (the header rows are missing), a header line with more
        fields than the tag line.
    """
    kinds = export.header_rows
    expected = f"export.header_rows = {list(kinds)}"
    raw = []
    for i in range(len(kinds)):
        line = fh.readline()
        if not line:
            raise ValvemonError(f"{where}: expected {len(kinds)} header lines ({expected}), the file has {i}")
        raw.append(line)
    fields = [_fields(line, export.separator) for line in raw]
    t = kinds.index("tag")
    names = fields[t]
    if export.timestamp_column not in names:
        found = ", ".join(repr(c) for c in names[:4])
        raise ValvemonError(
            f"{where}: line {t + 1}: expected the header line 'tag' ({expected}) with the time column {export.timestamp_column!r} "
            f"(export.timestamp_column), found {found}{', …' if len(names) > 4 else ''}"
        )
    start = None
    for i, (kind, row) in enumerate(zip(kinds, fields)):
        if kind == "start_time":
            if len(row) < 2 or not row[1].strip():
                text = raw[i].decode("utf-8", errors="replace").rstrip("\r\n")
                raise ValvemonError(f"{where}: line {i + 1}: expected the recording's start time in the second cell of the 'start_time' line ({expected}), found {text!r}")
            start = (row[1].strip(), i + 1)
        if kind in ("skip", "start_time"):
            continue
        cells = [c.strip() for j, c in enumerate(row) if j < len(names) and names[j] != export.timestamp_column and c.strip()]
        if cells and all(_is_number(c, export.decimal) for c in cells):
            raise ValvemonError(f"{where}: line {i + 1}: expected the header line {kind!r} ({expected}), found numbers (data): the header rows are missing")
        n, m = _width(row), _width(names)
        if n > m:
            raise ValvemonError(f"{where}: line {i + 1}: the {kind!r} line has {n} fields, the 'tag' line (line {t + 1}) {m}")
    units = None
    if "unit" in kinds:
        row = fields[kinds.index("unit")]
        label = fields[kinds.index("name")] if "name" in kinds else []
        units = {}
        for j, name in enumerate(names):
            if name != export.timestamp_column:
                desc = f" {label[j].strip()!r}" if j < len(label) and label[j].strip() else ""
                units[name] = (row[j] if j < len(row) else "", f"column {j + 1}{desc}")
    return HeaderRows(raw[t], len(kinds), units, start)

