"""Reading historian exports: finding them, hashing them, telling their format, decoding CSV
(long or wide, plain or gzip) and Parquet into the raw frame the ingest checks
(:func:`read_export`). Shared by the whole-file path (:mod:`flows.ingest.flow`) and the batched
one (:mod:`flows.ingest.batches`)."""

from __future__ import annotations

import gzip
import hashlib
import mmap
import os
import re
import zlib
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import numpy as np
import polars as pl
import pyarrow as pa
import pyarrow.parquet as pq
from blake3 import blake3

from flows.common.errors import ValvemonError
from schemas.plant_config import ExportSpec
from transforms.ingest import TagTable
from transforms.ingest.text_rows import FIELD_COUNT, ROW_FAULT_COLUMN, TRUNCATED, ragged_rows, unterminated, width_bounds
from transforms.ingest.units import FileUnits

EXPORT_SUFFIXES = (".csv", ".csv.gz", ".txt", ".tsv", ".tsv.gz", ".txt.gz", ".parquet", ".pq", ".tdms")
"""Files a folder argument contributes (searched recursively, sorted by path)."""

_GZIP_MAGIC = b"\x1f\x8b"
_PARQUET_MAGIC = b"PAR1"
_TDMS_MAGIC = b"TDSm"
"""A TDMS file's first bytes (its first segment's lead-in); ``flows.ingest.tdms`` reads it (npTDMS is
imported only then)."""
_NOT_BLANK = re.compile(rb"\S")

HASH_PREFIX = "blake3:"
"""The manifest's content hash is ``blake3:<64 hex digits>`` (BLAKE3-256 of the file's bytes)."""
LEGACY_HASH_PREFIX = "sha256:"
"""Files ingested before BLAKE3 keep their SHA-256, ``sha256:<64 hex digits>`` (docs/ingest.md)."""


HASH_BLOCK_BYTES = 16 * 1024 * 1024
"""With ``drop_pages``, :func:`content_hash` hashes a memory map in blocks of this size and drops
each block's pages from the process after it (a plain memory map keeps every page of a large
file resident until it is unmapped)."""


def content_hash(data, *, drop_pages: bool = False) -> str:
    """The manifest's content hash of a file's bytes (any buffer: bytes, mmap): ``blake3:<hex>``.

    ``drop_pages`` (an mmap only): hash block by block, releasing each block's pages, so the
    resident memory stays one block whatever the file's size (the batched ingest)."""
    if not drop_pages or not isinstance(data, mmap.mmap):
        return HASH_PREFIX + blake3(data).hexdigest()
    hasher = blake3()
    size = len(data)
    with memoryview(data) as view:
        for a in range(0, size, HASH_BLOCK_BYTES):
            hasher.update(view[a : a + HASH_BLOCK_BYTES])
            data.madvise(mmap.MADV_DONTNEED, a, min(HASH_BLOCK_BYTES, size - a))
    return HASH_PREFIX + hasher.hexdigest()


def legacy_hash(path: Path) -> str:
    """The content hash the manifest held before BLAKE3: ``sha256:<hex>`` of the file's bytes."""
    with _mapped(path) as data:
        return LEGACY_HASH_PREFIX + hashlib.sha256(data).hexdigest()


@contextmanager
def _mapped(path: Path) -> Iterator[mmap.mmap | bytes]:
    """The file's bytes, memory-mapped (no copy; ``b""`` for an empty file)."""
    with open(path, "rb") as fh:
        if os.fstat(fh.fileno()).st_size == 0:
            yield b""
            return
        data = mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
        try:
            yield data
        finally:
            data.close()


# --- files -----------------------------------------------------------------------------------


def discover_files(paths: list[str | Path]) -> list[Path]:
    """The export files named by the arguments: files as given, folders searched recursively.

    Raises
    ------
    ValvemonError
        For a path that does not exist, or when nothing is found.
    """
    out: list[Path] = []
    seen: set[Path] = set()
    for p in map(Path, paths):
        if p.is_dir():
            found = sorted(f for f in p.rglob("*") if f.is_file() and f.name.lower().endswith(EXPORT_SUFFIXES) and not f.name.startswith("."))
        elif p.exists():
            found = [p]
        else:
            raise ValvemonError(f"{p}: no such file or folder")
        for f in found:
            key = f.resolve()
            if key not in seen:
                seen.add(key)
                out.append(f)
    if not out:
        raise ValvemonError(f"no export files ({', '.join(EXPORT_SUFFIXES)}) in {', '.join(map(str, paths))}")
    return out


def sniff_format(path: Path, head: bytes) -> str:
    """``"parquet"``, ``"tdms"``, ``"csv.gz"`` or ``"csv"``, from the file's first bytes (then its name)."""
    if head.startswith(_PARQUET_MAGIC):
        return "parquet"
    if head.startswith(_TDMS_MAGIC):
        return "tdms"
    if head.startswith(_GZIP_MAGIC):
        return "csv.gz"
    if path.name.lower().endswith((".parquet", ".pq")):
        return "parquet"
    return "csv"


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


def _is_text(t: pa.DataType) -> bool:
    return pa.types.is_string(t) or pa.types.is_large_string(t) or pa.types.is_string_view(t)


def enum_column(col: pa.ChunkedArray, categories: tuple[str, ...] | None = None) -> pl.Series | None:
    """A dictionary-encoded text column → a polars Enum, by its codes: no row's text is decoded.

    ``categories`` are the Enum's (the plant's tags); None: the column's distinct values. Each
    chunk's codes go through a lookup table of its own dictionary (Parquet has one per row
    group). Returns None when a value is not one of ``categories`` or a dictionary holds a null,
    so that the caller decodes the text and can name the value.
    """
    dictionaries = [ch.dictionary.to_pylist() for ch in col.chunks]
    if categories is None:
        categories = tuple(dict.fromkeys(v for d in dictionaries for v in d))
    position = {c: i for i, c in enumerate(categories)}
    if None in position or any(v not in position for d in dictionaries for v in d):
        return None
    enum = pl.Enum(list(categories))
    if len(categories) == 1 and not col.null_count:  # one code throughout (quality "Good")
        return pl.repeat(categories[0], len(col), dtype=enum, eager=True)
    physical = pl.Series(dtype=enum).to_physical().to_numpy().dtype
    codes = np.empty(len(col), dtype=physical)
    a = 0
    for ch, d in zip(col.chunks, dictionaries):
        lut = np.array([position[v] for v in d], dtype=physical)
        b = a + len(ch)
        np.take(lut, ch.indices.fill_null(0).to_numpy(), out=codes[a:b])
        a = b
    series = pl.Series(codes)
    if col.null_count:
        series = series.scatter(np.flatnonzero(col.is_null().to_numpy()), None)
    return series.cat.to(enum)


def read_parquet_export(path: Path, export: ExportSpec, tags: TagTable | None = None) -> pl.DataFrame:
    """A Parquet export → frame in file order.

    The tag and quality columns, when they hold text, are read dictionary-encoded (as Parquet
    stores such columns) and become Enum columns from their codes, without decoding a string
    per row: the tag column an Enum of the plant's tags (when every tag of the file is one,
    else text, so that the error names the tag), the quality column an Enum of its codes.
    """
    schema = pq.read_schema(path)
    wanted = [export.tag_column if export.layout == "long" else None, export.quality_column]
    coded = [c for c in wanted if c and c in schema.names and _is_text(schema.field(c).type)]
    if not coded:
        return pl.read_parquet(path)
    table = pq.read_table(path, columns=coded, read_dictionary=coded)
    columns = []
    for name in coded:
        col = table[name]
        enum = enum_column(col, tags.tags if tags is not None and name == export.tag_column else None)
        columns.append((enum if enum is not None else pl.from_arrow(col.cast(col.type.value_type))).alias(name))
    rest = [c for c in schema.names if c not in coded]  # polars decodes these faster than Arrow
    df = pl.read_parquet(path, columns=rest).with_columns(columns) if rest else pl.DataFrame(columns)
    return df.select(schema.names)


@dataclass
class ExportFile:
    """An export as read: its frame, where its rows start, and what identifies the file."""

    frame: pl.DataFrame
    first_line: int
    file_format: str
    file_hash: str
    """:func:`content_hash` of the file's bytes."""
    size_bytes: int
    path: Path | None = None
    units: FileUnits | None = None
    """The units the file states (a unit header row, TDMS ``unit_string``); None: it states none."""


def read_export(path: Path, export: ExportSpec, tags: TagTable | None = None) -> ExportFile:
    """Read one export file (CSV, gzip CSV, Parquet or TDMS) and hash its bytes.

    The file is memory-mapped and hashed (:func:`content_hash`) without a copy; a plain CSV or
    Parquet file is then decoded from the file by polars / Arrow (a gzip file from the
    decompressed bytes).

    Raises
    ------
    ValvemonError
        Naming the file: unreadable, empty, truncated gzip, not CSV/Parquet.
    """
    path = Path(path)
    empty = f"{path}: empty file (expected a {export.layout} export with a header line)"
    try:
        with _mapped(path) as raw:
            size = len(raw)
            if not size:
                raise ValvemonError(empty)
            digest = content_hash(raw)
            fmt = sniff_format(path, bytes(raw[:4]))
            data: bytes | Path = path
            if fmt == "csv.gz":
                try:
                    data = gzip.decompress(raw)
                except (EOFError, gzip.BadGzipFile, zlib.error) as exc:
                    raise ValvemonError(f"{path}: truncated or corrupt gzip file ({exc})") from None
                if not data or data.isspace():
                    raise ValvemonError(f"{path}: empty file inside the gzip (expected a {export.layout} export with a header line)")
            elif fmt == "csv" and _NOT_BLANK.search(raw) is None:
                raise ValvemonError(empty)
    except (OSError, ValueError) as exc:
        raise ValvemonError(f"{path}: cannot read the file ({getattr(exc, 'strerror', None) or exc})") from None
    units = None
    try:
        if fmt == "parquet":
            df = read_parquet_export(path, export, tags)
            first_line = 1
        elif fmt == "tdms":
            from flows.ingest.tdms import tdms_batches, tdms_units

            units = tdms_units(path, export)
            df = pl.concat([b[0] for b in tdms_batches(path, export, 1 << 62)])
            first_line = 1
        elif export.header_rows != ExportSpec.header_rows:
            from flows.ingest.header_rows import without_header_rows

            data, header = without_header_rows(data, export, str(path))
            df = read_csv_export(data, export, tags)
            first_line, units = header.lines + 1, header.units
        else:
            df = read_csv_export(data, export, tags)
            first_line = 2
    except ValvemonError:
        raise
    except (pl.exceptions.PolarsError, pa.ArrowException, OSError, ValueError) as exc:
        kind = {"parquet": "Parquet", "tdms": "TDMS"}.get(fmt, "CSV")
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ValvemonError(f"{path}: not a readable {kind} export ({reason})") from None
    if df.height == 0:
        raise ValvemonError(f"{path}: no data rows (only a header)")
    return ExportFile(df, first_line, fmt, digest, size, path, units)


# --- one file --------------------------------------------------------------------------------
