"""Rows of delimited text whose field count is not the header's (no I/O).

A text export's row with a field too few or too many cannot be read by position: a field missing in
the middle moves every value after it one column left, and a file cut inside its last line stores a
cut value. The CSV decoder (polars) fills missing trailing fields with nulls and drops nothing
else, so the ingest asks :func:`ragged_rows` which rows those are and quarantines them whole
(``docs/ingest.md``, "Rows of the wrong width"). :func:`width_bounds` says which counts are right.
"""

from __future__ import annotations

import csv

import numba
import numpy as np

ROW_FAULT_COLUMN = "\x00row_fault"
"""A column the CSV reader adds to a frame (only when some row is faulty): ``"field_count"`` for a
row whose field count is not the header's, ``"truncated"`` for a last line without a line end (a
cut file), null for every other row. ``transforms.ingest.samples`` quarantines those rows whole
and removes the column."""

FIELD_COUNT, TRUNCATED = "field_count", "truncated"


def header_fields(line: bytes, separator: str) -> list[str]:
    """The fields of one line of delimited text (quotes as the decoder reads them)."""
    text = line.decode("utf-8", errors="replace").rstrip("\r\n")
    return next(csv.reader([text], delimiter=separator, quotechar='"'), [])


def first_row(block: bytes) -> bytes:
    """The first line of ``block`` that holds something (b"" if none)."""
    return next((line for line in block.split(b"\n", 64) if line.strip()), b"")


def with_trailing_separator(header: bytes, row: bytes, separator: str) -> bytes:
    """The header line as the rows are written: when the file's first data row ``row`` has one
    field more than ``header``, that field empty (every row ends in a separator, the header
    does not), the header with a separator added at its end, so the rows read as having the
    header's width plus its trailing unnamed column (:func:`width_bounds`); else ``header``.
    A trailing separator on only some rows is still the wrong width: the habit is the file's."""
    if not row or not header.strip():
        return header
    names, cells = header_fields(header, separator), header_fields(row, separator)
    if len(cells) != len(names) + 1 or cells[-1] != "" or names[-1] == "":
        return header
    body = header.rstrip(b"\r\n")
    return body + separator.encode() + header[len(body) :]


def width_bounds(columns: list[str]) -> tuple[int, int]:
    """The field counts a data row may have, ``(lo, hi)``, from the decoder's column names: the
    header's (``hi``), or down to its last named column (``lo``) when it ends in unnamed ones (a
    trailing separator on the header line) — but such a shorter row must then end in a value, not
    in a separator (:func:`ragged_rows`)."""
    hi = len(columns)
    lo = hi
    while lo > 1 and (columns[lo - 1] == "" or columns[lo - 1].startswith("_duplicated_")):
        lo -= 1
    return lo, hi


@numba.njit(cache=True, nogil=True)
def _scan(buf, sep, quote, lo, hi):
    """Rows (0 = the header line, not checked) of the wrong width: their indices and field counts.
    A row has ``hi`` fields, or ``lo … hi-1`` ending in a non-empty field (the header's trailing
    unnamed columns left out, not a field missing before a trailing separator). A separator or a
    line end between quotes is part of a field (as the decoder reads it); a blank line (nothing,
    or only ``\r``) is no row to check."""
    rows = []
    counts = []
    row = 0
    fields = 1
    length = 0
    last = 0
    in_quote = False
    for i in range(len(buf)):
        b = buf[i]
        if b == quote:
            in_quote = not in_quote
            length += 1
            last += 1
        elif in_quote:
            length += 1
            last += 1
        elif b == 10:  # \n
            if row > 0 and length > 0 and fields != hi and not (lo <= fields < hi and last > 0):
                rows.append(row)
                counts.append(fields)
            row += 1
            fields = 1
            length = 0
            last = 0
        elif b == sep:
            fields += 1
            length += 1
            last = 0
        elif b != 13:  # \r
            length += 1
            last += 1
    if row > 0 and length > 0 and fields != hi and not (lo <= fields < hi and last > 0):
        rows.append(row)
        counts.append(fields)
    return np.array(rows, dtype=np.int64), np.array(counts, dtype=np.int64)


def ragged_rows(text, separator: str, lo: int, hi: int) -> tuple[np.ndarray, np.ndarray]:
    """The data rows of CSV text (header line first; any buffer of bytes) of the wrong width
    (``lo``, ``hi``: :func:`width_bounds`): their positions among the data rows (0 = the line after
    the header, blank lines counted, as the decoder's frame rows) and their field counts."""
    buf = np.frombuffer(text, dtype=np.uint8)
    rows, counts = _scan(buf, np.uint8(ord(separator)), np.uint8(ord('"')), lo, hi)
    return rows - 1, counts


def unterminated(text) -> bool:
    """Whether the text's last line has no line end and holds something (a file cut inside it)."""
    tail = bytes(text[-65536:])
    return not tail.endswith(b"\n") and bool(tail.rsplit(b"\n", 1)[-1].strip())
