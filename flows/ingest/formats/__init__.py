"""Every export format behind one streaming reader: a module per format, one dispatcher.

In the style of ObsPy's and pyrocko's io plugins, a format is one module of this package with

- ``SUFFIXES``: the file names a folder contributes (``discover_files``), and ``FILE_FORMATS``: the
  manifest's ``file_format`` values it reads;
- ``detect(head, name) -> str | None``: its ``file_format`` (the manifest's) if the file's first
  bytes (and name) are this format's, else None;
- ``describe(src, export, timezone)``: what the file states before its data — units, the start
  time of a relative time column, the format's own layout (``src.layout``) — or a one-line
  refusal naming the file;
- ``iload(src, export, tags, batch_samples, block_bytes)``: the file's rows as a stream of
  ``Batch(frame, first_line, final)``, wide (a time column and a column per tag) or long
  (time, tag, value) frames as the configured layout says, decoded as the whole file would be,
  with the file's line (or row) of each batch's first row;
- optionally ``members(path)``: the files that make up the export (COMTRADE: the ``.cfg`` and
  its ``.dat``), all of which the content hash covers.

:func:`open_export` tells the format (:data:`FORMATS` are asked in order; text takes anything),
hashes the file and builds the one identity record, :class:`ExportSource`; :func:`iload` streams
it. The ingest has one path: ``open_export`` → ``iload`` → ``transforms.ingest.stream.ExportStream``
→ the lake; an export that cannot be taken batch by batch is read by the same path as one batch
(``whole=True``). Adding a format means adding a module here and naming it in :data:`FORMATS`.
"""

from __future__ import annotations

import gzip
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator, NamedTuple

import polars as pl
import pyarrow as pa

from flows.common.errors import ValvemonError
from flows.ingest.formats import comtrade, parquet, tdms, text
from flows.ingest.formats.blocks import WHOLE
from flows.ingest.hashing import content_hash
from schemas.plant_config import ExportSpec
from transforms.ingest import TagTable
from transforms.ingest.errors import IngestError
from transforms.ingest.timestamps import parse_start_time, start_in_name
from transforms.ingest.units import FileUnits

FORMATS = (tdms, parquet, comtrade, text)
"""The format modules, in the order :func:`detect` asks them (magic bytes before names; text last:
it takes any file)."""
READERS = {name: module for module in FORMATS for name in module.FILE_FORMATS}
"""``file_format`` → its module."""
EXPORT_SUFFIXES = tuple(dict.fromkeys(s for f in FORMATS for s in f.SUFFIXES))
"""Files a folder argument contributes (searched recursively, sorted by path)."""
KIND = {"parquet": "Parquet", "tdms": "TDMS", "comtrade": "COMTRADE"}
"""A format's name in messages (text formats: CSV)."""

BATCH_SAMPLES = 4_194_304
"""Samples per batch (a wide row holds one per tag column): ~0.5 GB of working memory."""
CSV_BLOCK_BYTES = 48 * 1024 * 1024
"""Bytes of text per batch (cut at a line end): ~1 M long rows; a long CSV takes ~10× its text in
working memory (128 MB blocks peaked at 2.0 GB for an hour of one valve, 48 MB at 1.0 GB)."""


class Batch(NamedTuple):
    """Consecutive rows of an export, as read."""

    frame: pl.DataFrame
    first_line: int
    """The file's line (text) or row (binary formats, first = 1) of the frame's first row."""
    final: bool


@dataclass
class ExportSource:
    """An export file, hashed and described, not yet read: what identifies it in the manifest
    and what it states about its data."""

    path: Path
    file_format: str
    """The manifest's ``file_format``: csv, csv.gz, parquet, tdms, comtrade."""
    file_hash: str
    """``blake3:`` + the BLAKE3-256 of the export's bytes (of all its :func:`members`)."""
    size_bytes: int
    units: FileUnits | None = None
    """The units the file states (a unit header row, TDMS ``unit_string``, a COMTRADE channel's
    ``uu``); None: it states none."""
    start: tuple[str, int] | None = None
    """A text export's ``start_time`` header line: the start time as written and its line."""
    origin_ns: int | None = None
    """The file's start time (UTC ns) that a relative ``timestamp_format`` counts from."""
    layout: Any = None
    """The format's own description of the file (header rows, COMTRADE channels)."""


def discover_files(paths: list[str | Path], skipped: Callable[[Path, str], None] | None = None) -> list[Path]:
    """The export files named by the arguments: files as given, folders searched recursively for
    :data:`EXPORT_SUFFIXES` (sorted by path). ``skipped(file, why)`` is told of a folder's file
    that looks like part of an export but is not read: a COMTRADE ``.dat`` without its ``.cfg``.

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
            for dat in sorted(f for f in p.rglob("*") if f.suffix.lower() == ".dat" and not f.name.startswith(".")) if skipped else ():
                if not any(dat.with_suffix(s).is_file() for s in (".cfg", ".CFG", ".Cfg")):
                    skipped(dat, f"a COMTRADE data file without its .cfg beside it ({dat.with_suffix('.cfg').name}): not read")
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


def detect(path: Path, head: bytes):
    """The format module and ``file_format`` of a file, from its first bytes and name."""
    return next((m, name) for m in FORMATS if (name := m.detect(head, path.name.lower())) is not None)  # text takes any file


def members(module, path: Path) -> list[Path]:
    """The files an export consists of (the content hash covers them all)."""
    return module.members(path) if hasattr(module, "members") else [path]


def open_export(path: Path, export: ExportSpec, timezone: str) -> ExportSource:
    """Tell one export's format, hash it, check it is not empty, and read what it states before
    its data (the format's ``describe``: header rows, TDMS metadata, the COMTRADE ``.cfg``), and
    the start time of a relative time column (:func:`time_origin`).

    Raises
    ------
    ValvemonError
        Naming the file: unreadable, empty, header rows missing, a truncated TDMS file, a
        COMTRADE ``.cfg`` without its ``.dat``, no start time for relative times.
    """
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            head = fh.read(8)
        if not head:
            raise ValvemonError(f"{path}: empty file (expected a {export.layout} export with a header line)")
        module, fmt = detect(path, head)
        if fmt == "csv" and text.is_blank(path):
            raise ValvemonError(f"{path}: empty file (expected a {export.layout} export with a header line)")
        files = members(module, path)
        digest, size = content_hash(files)
    except (OSError, ValueError) as exc:
        raise ValvemonError(f"{path}: cannot read the file ({getattr(exc, 'strerror', None) or exc})") from None
    src = ExportSource(path, fmt, digest, size)
    module.describe(src, export, timezone)
    src.origin_ns = time_origin(path, src.start, export, timezone)
    return src


def time_origin(path: Path, start: tuple[str, int] | None, export: ExportSpec, timezone: str) -> int | None:
    """The file's start time (UTC ns) that a relative ``export.timestamp_format`` counts from: the
    ``start_time`` header line's (``start``: its text and line), else the first part of the file's
    name written in ``export.start_time_format`` (``DEMO_20250301T010000.txt`` with
    ``"%Y%m%dT%H%M%S"``); None for absolute timestamps.

    Raises
    ------
    ValvemonError
        Naming the file and the line (or its name): no start time, or one that cannot be read.
    """
    if not export.relative_time:
        return None
    fmt = export.start_time_format
    if start is not None:
        written, where = start[0], f"{path}: line {start[1]}"
    else:
        where = f"{path}: file name {path.name!r}"
        try:
            written = start_in_name(path.name, fmt)
        except IngestError as exc:
            raise ValvemonError(f"{where}: {exc}") from None
        if written is None:
            raise ValvemonError(
                f"{where}: no start time: no 'start_time' header line (export.header_rows) and no part of the name "
                f"written in export.start_time_format {fmt!r} (export.timestamp_format {export.timestamp_format!r} counts from the start)"
            )
    try:
        return parse_start_time(written, fmt, timezone, ambiguous=export.ambiguous_time)
    except IngestError as exc:
        raise ValvemonError(f"{where}: {exc}") from None


def iload(
    src: ExportSource,
    export: ExportSpec,
    tags: TagTable | None = None,
    *,
    whole: bool = False,
    batch_samples: int | None = None,
    block_bytes: int | None = None,
) -> Iterator[Batch]:
    """The export's rows in batches of about ``batch_samples`` samples (default
    :data:`BATCH_SAMPLES`) or ``block_bytes`` of text (default :data:`CSV_BLOCK_BYTES`);
    ``whole``: the file as one batch.

    Raises
    ------
    ValvemonError
        Naming the file: not a readable export of its format, a truncated gzip, no data rows.
    """
    module = READERS[src.file_format]
    if whole:
        batch_samples = block_bytes = WHOLE
    rows = 0
    try:
        for df, first_line, final in module.iload(src, export, tags, batch_samples or BATCH_SAMPLES, block_bytes or CSV_BLOCK_BYTES):
            rows += df.height
            if final and rows == 0:
                raise ValvemonError(f"{src.path}: no data rows (only a header)")
            yield Batch(df, first_line, final)
    except ValvemonError:
        raise
    except IngestError as exc:  # what the reader refuses in the file's content (a header naming a column twice)
        raise ValvemonError(f"{src.path}: {exc}") from None
    except (EOFError, gzip.BadGzipFile, zlib.error) as exc:
        raise ValvemonError(f"{src.path}: truncated or corrupt gzip file ({exc})") from None
    except (pl.exceptions.PolarsError, pa.ArrowException, OSError, ValueError) as exc:
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ValvemonError(f"{src.path}: not a readable {KIND.get(src.file_format, 'CSV')} export ({reason})") from None

