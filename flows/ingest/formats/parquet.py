"""Parquet exports (long or wide; typed or text columns), read by record batches.

``iload`` reads a file of typed columns with polars, a slice of the batch size at a time (only the
row groups of the slice are read; polars decodes numbers and timestamps ~1.3× faster than Arrow), and
one with text tag or quality columns with ``ParquetFile.iter_batches`` (without pre-buffering, which
would read the whole file), joining record batches up to the batch size. The tag and quality columns, when they hold
text, are read dictionary-encoded (as Parquet stores such columns) and become polars Enum columns
from their codes, without decoding a string per row (:func:`enum_column`): the tag column an Enum
of the plant's tags (when every tag of the file is one, else text, so that the error names the
tag), the quality column an Enum of its codes. A row's "line" is its row number (first = 1).
"""

from __future__ import annotations

from typing import Iterator

import numpy as np
import polars as pl
import pyarrow as pa
import pyarrow.parquet as pq

from flows.ingest.formats.blocks import lookahead
from flows.ingest.formats.text import _value_columns
from schemas.plant_config import ExportSpec
from transforms.ingest import TagTable
from transforms.ingest.samples import refuse_repeated_columns

SUFFIXES = (".parquet", ".pq")
FILE_FORMATS = ("parquet",)
"""The manifest's ``file_format`` of the files this module reads."""
_MAGIC = b"PAR1"


def detect(head: bytes, name: str) -> str | None:
    """Parquet by its magic bytes, or by its name unless the bytes are gzip's."""
    if head.startswith(_MAGIC) or (name.endswith(SUFFIXES) and not head.startswith(b"\x1f\x8b")):
        return "parquet"
    return None


def describe(src, export: ExportSpec, timezone: str) -> None:
    """A Parquet file states no units (the configuration's hold)."""


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


def iload(src, export: ExportSpec, tags: TagTable | None, batch_samples: int, block_bytes: int) -> Iterator[tuple[pl.DataFrame, int, bool]]:
    """The file's rows in batches of about ``batch_samples`` samples: ``(frame, row of its first, last)``."""
    path = src.path
    schema = pq.read_schema(path)
    refuse_repeated_columns(schema.names)
    wanted = [export.tag_column if export.layout == "long" else None, export.quality_column]
    coded = [c for c in wanted if c and c in schema.names and _is_text(schema.field(c).type)]
    per_row = max(len(_value_columns(schema.names, export)), 1)
    pf = pq.ParquetFile(path, read_dictionary=coded, pre_buffer=False, buffer_size=8 << 20)  # pre-buffering reads the whole file
    first = 1
    rows = max(batch_samples // per_row, 1024)
    n = pf.metadata.num_rows
    if not coded and n:  # typed columns only: polars decodes them faster than Arrow, slice by slice
        scan = pl.scan_parquet(path, hive_partitioning=False)
        cuts = _slices(pf.metadata, rows)
        for a, b in zip(cuts[:-1], cuts[1:]):
            df = scan.slice(a, b - a).collect()  # a chunk per row group: a batch that is the lake's grid is converted chunk by chunk
            yield df, a + 1, b >= n
        return
    empty = True
    for batch, final in lookahead(_coalesced(pf.iter_batches(batch_size=min(rows, 1 << 31), use_threads=False), rows)):
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


def _slices(md: pq.FileMetaData, rows: int) -> list[int]:
    """Row numbers that cut the file into slices of about ``rows`` rows, each at a row group's
    end where the row groups allow (a row group is decoded once, not once for each slice it
    falls into), else every ``rows`` rows; the first 0, the last the file's rows."""
    ends = np.cumsum([md.row_group(i).num_rows for i in range(md.num_row_groups)])
    cuts, previous = [0], 0
    for end in map(int, ends):
        if end - cuts[-1] > rows and previous > cuts[-1]:
            cuts.append(previous)  # the slice ends where the row group before this one ends
        while end - cuts[-1] > rows:  # a row group larger than a slice: cut inside it
            cuts.append(cuts[-1] + rows)
        previous = end
    if previous > cuts[-1]:
        cuts.append(previous)
    return cuts


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
