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

import gzip
import re
import zlib
from contextlib import nullcontext
from pathlib import Path
from typing import IO, Iterator

import numpy as np
import polars as pl

from flows.common.errors import ValvemonError
from flows.ingest.formats.blocks import line_blocks, lookahead
from flows.ingest.formats.header_rows import read_header_rows
from flows.ingest.hashing import _mapped
from schemas.plant_config import ExportSpec
from transforms.ingest import TagTable
from transforms.ingest.samples import refuse_repeated_columns
from transforms.ingest.text_rows import (
    FIELD_COUNT,
    ROW_FAULT_COLUMN,
    TRUNCATED,
    first_row,
    header_fields,
    ragged_rows,
    unterminated,
    width_bounds,
    with_trailing_separator,
)

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
    plant does not have, bytes that are not UTF-8, a row with more fields than the header) is the
    file read again with those columns as text (invalid UTF-8 replaced), so that quarantine and
    the error message can show what the file says. Rows whose field count is not the header's,
    and a last line without a line end, are marked in :data:`ROW_FAULT_COLUMN` (added only then;
    :func:`mark_row_faults`).
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
        return mark_row_faults(pl.read_csv(data, schema_overrides=overrides, **opts), data, export.separator)
    except pl.exceptions.ComputeError:
        pass  # a value that is no number, a tag the plant does not have, bad UTF-8, a row too wide: the careful path
    opts = _csv_options(export, "utf8-lossy")
    overrides.pop(export.tag_column, None)
    too_wide = False
    try:
        df = pl.read_csv(data, schema_overrides=overrides, ignore_errors=True, **opts)
    except pl.exceptions.ComputeError:
        if _binary(data):  # NUL bytes: not text at all, not a row too wide
            raise
        too_wide = opts["truncate_ragged_lines"] = True  # a row too wide: read, and marked below
        df = pl.read_csv(data, schema_overrides=overrides, ignore_errors=True, **opts)
    suspicious = [c for c in values if df[c].null_count()]
    if suspicious:
        text = pl.read_csv(data, columns=suspicious, **opts)
        df = df.with_columns([text[c] for c in suspicious])
    return mark_row_faults(df, data, export.separator, maybe_wide=too_wide)


def _binary(data: bytes | Path) -> bool:
    """Whether the text's first 64 KiB hold a NUL byte (binary data, not text)."""
    if isinstance(data, Path):
        with open(data, "rb") as fh:
            return b"\x00" in fh.read(1 << 16)
    return b"\x00" in data[: 1 << 16]


def mark_row_faults(df: pl.DataFrame, data: bytes | Path, separator: str, *, maybe_wide: bool = False) -> pl.DataFrame:
    """``df`` (the decoder's frame of ``data``) with :data:`ROW_FAULT_COLUMN` when a row's field
    count is not the header's or the last line has no line end (``transforms.ingest.text_rows``).

    The text is scanned only when a row may be of the wrong width: the decoder fills a short
    row's missing fields with nulls, so a last named column without nulls rules short rows out,
    and a row too wide made the fast read fail (``maybe_wide``)."""
    lo, hi = width_bounds(df.columns)
    maybe_short = df.height > 0 and df[df.columns[lo - 1]].null_count() > 0
    with _mapped(data) if isinstance(data, Path) else nullcontext(data) as text:
        cut = unterminated(text)
        if not (maybe_short or maybe_wide or cut):
            return df
        rows = ragged_rows(text, separator, lo, hi)[0] if maybe_short or maybe_wide else np.zeros(0, dtype=np.int64)
    rows = rows[rows < df.height]
    if not len(rows) and not (cut and df.height):
        return df
    fault = pl.repeat(None, df.height, dtype=pl.String, eager=True).alias(ROW_FAULT_COLUMN)
    if len(rows):
        fault = fault.scatter(rows, FIELD_COUNT)
    if cut and df.height:
        fault = fault.scatter(df.height - 1, TRUNCATED)
    return df.with_columns(fault)


def iload(src, export: ExportSpec, tags: TagTable | None, batch_samples: int, block_bytes: int) -> Iterator[tuple[pl.DataFrame, int, bool]]:
    """The file's data lines in blocks of about ``block_bytes``, each decoded with the tag line in
    front: ``(frame, the file's line of its first row, last)``. A separator at the end of every
    row that the tag line lacks is added to the tag line (``with_trailing_separator``)."""
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
        if header.strip():
            tag_line = 1 if src.layout is None else export.header_rows.index("tag") + 1
            refuse_repeated_columns(header_fields(header, export.separator), line=tag_line)
        any_block = False
        for block, final in lookahead(line_blocks(fh, block_bytes)):
            if not any_block:
                header = with_trailing_separator(header, first_row(block), export.separator)
            any_block = True
            df = read_csv_export(header + block, export, tags)
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
