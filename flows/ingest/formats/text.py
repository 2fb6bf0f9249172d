"""Text exports: CSV (long or wide, plain or gzip, ``,`` ``;`` or tab), iba-style ASCII with header
lines (``export.header_rows``), read in blocks of lines.

``detect``: any file that is no other format (gzip by its first bytes: ``csv.gz``). ``describe``
reads the header lines a recorder writes above its tag line (``header_rows``: units, names, the
start time of a relative time column). ``iload`` cuts the text (decompressed as it is read) into
blocks of about ``block_bytes`` at line ends and decodes each with :func:`read_csv_export` with the
tag line in front, so values, quarantine and messages are those of the whole file and line numbers
run on across blocks.
"""

from __future__ import annotations

import csv
import gzip
import re
import zlib
from pathlib import Path
from typing import IO, Iterator

import polars as pl

from flows.common.errors import ValvemonError
from flows.ingest.formats.blocks import line_blocks, lookahead
from flows.ingest.formats.header_rows import read_header_rows
from schemas.plant_config import ExportSpec
from transforms.ingest import TagTable

SUFFIXES = (".csv", ".csv.gz", ".txt", ".tsv", ".tsv.gz", ".txt.gz")
FILE_FORMATS = ("csv", "csv.gz")
"""The manifest's ``file_format`` of the files this module reads."""
_GZIP_MAGIC = b"\x1f\x8b"
_NOT_BLANK = re.compile(rb"\S")


def detect(head: bytes, name: str) -> str:
    """``"csv.gz"`` for gzip bytes, else ``"csv"`` (the format of last resort)."""
    return "csv.gz" if head.startswith(_GZIP_MAGIC) else "csv"


def is_blank(path: Path) -> bool:
    """Whether a plain text file holds nothing but white space (read in blocks)."""
    with open(path, "rb") as fh:
        while block := fh.read(1 << 20):
            if _NOT_BLANK.search(block):
                return False
    return True


def _open(src) -> IO[bytes]:
    return gzip.open(src.path, "rb") if src.file_format == "csv.gz" else open(src.path, "rb")


def describe(src, export: ExportSpec, timezone: str) -> None:
    """A text export's header lines when ``export.header_rows`` has more than the tag line
    (``src.layout``), with the units and start time they state."""
    if export.header_rows == ExportSpec.header_rows:
        return
    try:
        with _open(src) as fh:
            src.layout = read_header_rows(fh, export, str(src.path))
    except (EOFError, gzip.BadGzipFile, zlib.error) as exc:
        raise ValvemonError(f"{src.path}: truncated or corrupt gzip file ({exc})") from None
    src.units, src.start = src.layout.units, src.layout.start


def _csv_options(export: ExportSpec, encoding: str = "utf8") -> dict:
    return {
        "separator": export.separator,
        "decimal_comma": export.decimal == ",",
        "infer_schema": False,
        "encoding": encoding,
        "quote_char": '"',
    }


def _value_columns(columns: list[str], export: ExportSpec) -> list[str]:
    if export.layout == "long":
        return [export.value_column] if export.value_column in columns else []
    skip = {export.timestamp_column, export.quality_column}
    return [c for c in columns if c not in skip]


def read_csv_export(data: bytes | Path, export: ExportSpec, tags: TagTable | None = None) -> pl.DataFrame:
    """A CSV export's bytes (decompressed), or its file, → frame in file order.

    Value columns are read as Float64 and, in the long layout, the tag column as an Enum of
    the plant's tags (the fast path). Only if that fails (a cell that is no number, a tag the
    plant does not have, bytes that are not UTF-8) is the file read again with those columns
    as text (invalid UTF-8 replaced), so that quarantine and the error message can show what
    the file says.
    """
    opts = _csv_options(export)
    try:
        header = pl.read_csv(data, n_rows=0, **opts).columns
    except pl.exceptions.ComputeError:
        opts = _csv_options(export, "utf8-lossy")  # not UTF-8 (e.g. Latin-1 headers): keep going
        header = pl.read_csv(data, n_rows=0, **opts).columns
    values = _value_columns(header, export)
    overrides: dict[str, pl.DataType] = {c: pl.Float64 for c in values}
    if export.layout == "long" and tags is not None and export.tag_column in header:
        overrides[export.tag_column] = tags.enum
    try:
        return pl.read_csv(data, schema_overrides=overrides, **opts)
    except pl.exceptions.ComputeError:
        pass  # a value that is no number, a tag the plant does not have, bad UTF-8: the careful path
    opts = _csv_options(export, "utf8-lossy")
    overrides.pop(export.tag_column, None)
    try:
        df = pl.read_csv(data, schema_overrides=overrides, ignore_errors=True, **opts)
    except pl.exceptions.ComputeError as exc:
        raise (ragged_line(data, export.separator) or exc) from None
    suspicious = [c for c in values if df[c].null_count()]
    if suspicious:
        text = pl.read_csv(data, columns=suspicious, **opts)
        df = df.with_columns([text[c] for c in suspicious])
    return df


class RaggedLine(ValueError):
    """A CSV line with more fields than the header; ``row`` counts the lines after the header
    (the first data line is 1), blank ones included."""

    def __init__(self, row: int, fields: int, expected: int):
        self.row, self.fields, self.expected = row, fields, expected
        super().__init__(f"{fields} fields where the header has {expected} (a separator too many?)")

    def at(self, first_line: int) -> str:
        """The message, with the file's line (``first_line``: the file's line of row 1)."""
        return f"line {first_line + self.row - 1}: {self}"


def ragged_line(data: bytes | Path, separator: str) -> RaggedLine | None:
    """The first line of CSV text (header first) with more fields than the header, quotes
    respected; None if there is none or the bytes are no text (NUL bytes: the caller's read failed
    for another reason)."""
    text = data.read_bytes() if isinstance(data, Path) else data
    if b"\x00" in text[: 1 << 16]:
        return None
    sep = separator.encode()
    lines = text.split(b"\n")

    def fields(line: bytes) -> int:
        if b'"' not in line:
            return line.count(sep) + 1
        try:
            return len(next(csv.reader([line.decode("utf-8", "replace").rstrip("\r")], delimiter=separator)))
        except csv.Error:  # not CSV at all (binary): not a ragged line
            return 0

    expected = fields(lines[0])
    for row, line in enumerate(lines[1:], start=1):
        if line.count(sep) >= expected and (n := fields(line)) > expected:
            return RaggedLine(row, n, expected)
    return None


def iload(src, export: ExportSpec, tags: TagTable | None, batch_samples: int, block_bytes: int) -> Iterator[tuple[pl.DataFrame, int, bool]]:
    """The file's data lines in blocks of about ``block_bytes``, each decoded with the tag line in
    front: ``(frame, the file's line of its first row, last)``."""
    with _open(src) as fh:
        header = fh.readline()
        first = 2
        if src.layout is not None:  # several header lines: the tag line in front of every block
            for _ in range(src.layout.lines - 1):
                fh.readline()
            header, first = src.layout.tag_line, src.layout.lines + 1
        elif not header.strip():  # blank lines before the header (or nothing at all inside a gzip)
            head = fh.read(1 << 16)
            if not head.strip():
                raise ValvemonError(f"{src.path}: empty file inside the gzip (expected a {export.layout} export with a header line)")
            fh = _Prefixed(header + head, fh)
            header = b""
        any_block = False
        for block, final in lookahead(line_blocks(fh, block_bytes)):
            any_block = True
            try:
                df = read_csv_export(header + block, export, tags)
            except RaggedLine as exc:
                raise ValvemonError(f"{src.path}: {exc.at(first)}") from None
            if tags is not None and export.tag_column in df.columns and not isinstance(df[export.tag_column].dtype, pl.Enum):
                tags = None  # a tag no valve has (or a value that is no number): the next blocks read tags as text, not twice
            yield df, first, final
            first += block.count(b"\n")
        if not any_block:
            yield read_csv_export(header, export, tags), first, True


class _Prefixed:
    """A byte stream with some bytes already read put back in front."""

    def __init__(self, head: bytes, fh: IO[bytes]):
        self.head, self.fh = head, fh

    def read(self, n: int) -> bytes:
        if self.head:
            out, self.head = self.head, b""
            return out
        return self.fh.read(n)
