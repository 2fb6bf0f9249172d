"""An export file read in bounded batches: Parquet by record batches, CSV (plain or gzip) by blocks of lines.

:func:`open_export` hashes the file (memory-mapped) and checks that it is not empty;
:func:`export_batches` then yields ``(frame, first_line, final)`` of at most about
:data:`BATCH_SAMPLES` samples each, decoded exactly as a whole file is (``flows.ingest.flow``:
``read_csv_export`` per block of lines with the header line in front, the Parquet tag and
quality text as codes), so that memory is bounded by the batch, not the file.
"""

from __future__ import annotations

import gzip
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Iterator

import polars as pl
import pyarrow as pa
import pyarrow.parquet as pq

from flows.common.errors import ValvemonError
from flows.ingest.header_rows import HeaderRows, read_header_rows
from flows.ingest.read import _NOT_BLANK, _is_text, _mapped, _value_columns, content_hash, enum_column, read_csv_export, sniff_format
from schemas.plant_config import ExportSpec
from transforms.ingest import TagTable
from transforms.ingest.units import FileUnits

BATCH_SAMPLES = 4_194_304
"""Samples per batch (a wide row holds one per tag column): ~0.5 GB of working memory."""
CSV_BLOCK_BYTES = 48 * 1024 * 1024
"""Bytes of CSV text per batch (cut at a line end): ~1 M long rows; a long CSV takes ~10× its text in
working memory (128 MB blocks peaked at 2.0 GB for an hour of one valve, 48 MB at 1.0 GB)."""


@dataclass
class ExportSource:
    """An export file, hashed and checked, not yet read."""

    path: Path
    file_format: str
    file_hash: str
    """``content_hash`` of the file's bytes."""
    size_bytes: int
    header: HeaderRows | None = None
    """A text export's header lines when ``export.header_rows`` has more than the tag line."""
    units: FileUnits | None = None
    """The units the file states (a unit header row, TDMS ``unit_string``); None: it states none."""


def open_export(path: Path, export: ExportSpec) -> ExportSource:
    """Hash one export file and check it is not empty (``read_export``'s checks before decoding);
    read a text export's header rows (``export.header_rows``) and a TDMS file's metadata, for
    the units they state.

    Raises
    ------
    ValvemonError
        Naming the file: unreadable, empty, header rows missing, a truncated TDMS file.
    """
    path = Path(path)
    empty = f"{path}: empty file (expected a {export.layout} export with a header line)"
    try:
        with _mapped(path) as raw:
            size = len(raw)
            if not size:
                raise ValvemonError(empty)
            fmt = sniff_format(path, bytes(raw[:4]))
            if fmt == "csv" and _NOT_BLANK.search(raw) is None:
                raise ValvemonError(empty)
            digest = content_hash(raw, drop_pages=True)
    except (OSError, ValueError) as exc:
        raise ValvemonError(f"{path}: cannot read the file ({getattr(exc, 'strerror', None) or exc})") from None
    src = ExportSource(path, fmt, digest, size)
    if fmt == "tdms":
        from flows.ingest.tdms import tdms_units

        src.units = tdms_units(path, export)
    elif fmt != "parquet" and export.header_rows != ExportSpec.header_rows:
        try:
            with gzip.open(path, "rb") if fmt == "csv.gz" else open(path, "rb") as fh:
                src.header = read_header_rows(fh, export, str(path))
        except (EOFError, gzip.BadGzipFile, zlib.error) as exc:
            raise ValvemonError(f"{path}: truncated or corrupt gzip file ({exc})") from None
        src.units = src.header.units
    return src


def export_batches(src: ExportSource, export: ExportSpec, tags: TagTable | None = None, batch_samples: int | None = None, csv_block_bytes: int | None = None) -> Iterator[tuple[pl.DataFrame, int, bool]]:
    """The export's rows in batches: ``(frame, line of its first row, last batch)``, of about
    ``batch_samples`` samples (default :data:`BATCH_SAMPLES`) or ``csv_block_bytes`` of CSV text
    (default :data:`CSV_BLOCK_BYTES`).

    Raises
    ------
    ValvemonError
        Naming the file: not a readable CSV/Parquet export, a truncated gzip, no data rows.
    """
    kind = {"parquet": "Parquet", "tdms": "TDMS"}.get(src.file_format, "CSV")
    batch_samples = batch_samples or BATCH_SAMPLES
    csv_block_bytes = csv_block_bytes or CSV_BLOCK_BYTES
    rows = 0
    try:
        if src.file_format == "parquet":
            batches = _parquet_batches(src.path, export, tags, batch_samples)
        elif src.file_format == "tdms":
            from flows.ingest.tdms import tdms_batches

            batches = tdms_batches(src.path, export, batch_samples)
        else:
            batches = _csv_batches(src, export, tags, csv_block_bytes)
        for df, first_line, final in batches:
            rows += df.height
            if final and rows == 0:
                raise ValvemonError(f"{src.path}: no data rows (only a header)")
            yield df, first_line, final
    except ValvemonError:
        raise
    except (EOFError, gzip.BadGzipFile, zlib.error) as exc:
        raise ValvemonError(f"{src.path}: truncated or corrupt gzip file ({exc})") from None
    except (pl.exceptions.PolarsError, pa.ArrowException, OSError, ValueError) as exc:
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ValvemonError(f"{src.path}: not a readable {kind} export ({reason})") from None


def _lookahead(it: Iterator) -> Iterator[tuple[object, bool]]:
    """Each item with whether it is the last."""
    prev = sentinel = object()
    for item in it:
        if prev is not sentinel:
            yield prev, False
        prev = item
    if prev is not sentinel:
        yield prev, True


def _parquet_batches(path: Path, export: ExportSpec, tags: TagTable | None, batch_samples: int) -> Iterator[tuple[pl.DataFrame, int, bool]]:
    schema = pq.read_schema(path)
    wanted = [export.tag_column if export.layout == "long" else None, export.quality_column]
    coded = [c for c in wanted if c and c in schema.names and _is_text(schema.field(c).type)]
    per_row = max(len(_value_columns(schema.names, export)), 1)
    pf = pq.ParquetFile(path, read_dictionary=coded, pre_buffer=False, buffer_size=8 << 20)  # pre-buffering reads the whole file
    first = 1
    rows = max(batch_samples // per_row, 1024)
    empty = True
    for batch, final in _lookahead(_coalesced(pf.iter_batches(batch_size=rows, use_threads=False), rows)):
        empty = False
        columns = []
        for name in batch.column_names:
            col = batch[name]
            if name in coded:
                enum = enum_column(col, tags.tags if tags is not None and name == export.tag_column else None)
                columns.append((enum if enum is not None else pl.from_arrow(col.cast(col.type.value_type))).alias(name))
            else:
                columns.append(pl.from_arrow(col).alias(name))
        df = pl.DataFrame(columns)
        yield df, first, final
        first += df.height
    if empty:
        yield pl.read_parquet(path), 1, True


def _coalesced(batches: Iterator[pa.RecordBatch], rows: int) -> Iterator[pa.Table]:
    """Record batches (at most one row group each) joined into tables of about ``rows`` rows."""
    pending, n = [], 0
    for b in batches:
        pending.append(b)
        n += b.num_rows
        if n >= rows:
            yield pa.Table.from_batches(pending)
            pending, n = [], 0
    if pending:
        yield pa.Table.from_batches(pending)


def _blocks(fh: IO[bytes], block_bytes: int) -> Iterator[bytes]:
    """The stream's bytes in blocks that end at a line end (the last one where the stream ends)."""
    rest = b""
    while True:
        chunk = fh.read(block_bytes)
        if not chunk:
            if rest:
                yield rest
            return
        data = rest + chunk if rest else chunk
        cut = data.rfind(b"\n") + 1
        if cut == 0:
            rest = data
            continue
        rest = data[cut:]
        yield data[:cut]


def _csv_batches(src: ExportSource, export: ExportSpec, tags: TagTable | None, block_bytes: int) -> Iterator[tuple[pl.DataFrame, int, bool]]:
    opener = gzip.open if src.file_format == "csv.gz" else open
    with opener(src.path, "rb") as fh:
        header = fh.readline()
        first = 2
        if src.header is not None:  # several header lines: the tag line in front of every block
            for _ in range(src.header.lines - 1):
                fh.readline()
            header, first = src.header.tag_line, src.header.lines + 1
        elif not header.strip():  # blank lines before the header (or nothing at all inside a gzip)
            head = fh.read(1 << 16)
            if not head.strip():
                raise ValvemonError(f"{src.path}: empty file inside the gzip (expected a {export.layout} export with a header line)")
            fh = _Prefixed(header + head, fh)
            header = b""
        any_block = False
        for block, final in _lookahead(_blocks(fh, block_bytes)):
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
