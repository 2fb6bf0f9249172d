"""Export writers for synthetic archives: long CSV, wide CSV (with the plant's header rows: iba's
ASCII export), Parquet and TDMS, one file a day (or per ``--file-minutes``).

A writer is opened on one file (one UTC day of a plant) and fed *chunks*: a block of
consecutive samples for every tag of the plant, as an int64 array of µs-UTC timestamps (n,)
and a float64 array of values in the tags' export units (n, n_tags), columns in the order of
:attr:`ExportColumns.tags`. Chunks arrive in time order, so the file's rows are in time order;
in the long layout the rows of one time stamp follow the tag order (valve by valve, signal by
signal). Nothing but the current chunk is ever held in memory.

Values are rounded to a per-tag number of decimals before they are written, in every format
(:func:`decimals_for_step`), so the long CSV, the wide CSV and the Parquet file of an archive
hold exactly the same numbers, and a CSV field is the shortest decimal that reads back as the
very float written (polars prints the shortest round-trip representation).

Gzip: each chunk is written as its own gzip member (polars ``write_csv(compression="gzip")``),
which RFC 1952 allows; ``gzip``/``zcat``, Python's ``gzip``, polars, pandas and DuckDB read
such a multi-member file as one stream. The member headers carry no time stamp, so the bytes
are reproducible.
"""

from __future__ import annotations

import gzip as _gzip
import math
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

import numpy as np
import polars as pl
import pyarrow as pa
import pyarrow.parquet as pq

from schemas.plant_config import ExportSpec

ISO8601_FORMAT = "%Y-%m-%dT%H:%M:%S%.6fZ"
"""How ``timestamp_format = "iso8601"`` is written: UTC, microseconds, a ``Z``."""

PARQUET_COMPRESSION = "zstd"

GZIP_LEVEL = 3
"""Gzip level of ``.csv.gz`` exports: as fast as writing plain CSV with polars, and within
10 % of level 6's size on archive data (docs/simulate.md)."""

CSV_BATCH_ROWS = 16_384
"""Rows polars formats per batch when writing CSV."""


def decimals_for_step(step: float, noise_std: float = 0.0) -> int | None:
    """Decimals that keep a signal's resolution: the smallest d with 10^-d <= resolution / 10.

    The resolution is the quantisation step, or (without quantisation) the noise standard
    deviation; both in the unit the value is written in. The rounding error is then at most
    1/20 of a quantisation step, so the quantisation level of every sample stays recoverable.
    ``None`` (no rounding) when the signal has neither.
    """
    resolution = step if step > 0 else noise_std
    if not resolution > 0:
        return None
    return max(0, math.ceil(-math.log10(resolution / 10.0) - 1e-9))


@dataclass(frozen=True)
class ExportColumns:
    """The tags of one archive, in column order, with their rounding."""

    tags: tuple[str, ...]
    decimals: tuple[int | None, ...]
    """Decimals each tag's values are rounded to (``None``: written at full precision)."""
    units: tuple[str, ...] = ()
    """Each tag's unit (header rows ``"unit"``, TDMS ``unit_string``); empty: none written."""
    names: tuple[str, ...] = ()
    """Each tag's description (header rows ``"name"``, TDMS ``description``); empty: none written."""

    def __post_init__(self):
        if len(self.tags) != len(self.decimals) or len(self.units) not in (0, len(self.tags)) or len(self.names) not in (0, len(self.tags)):
            raise ValueError("one decimals entry (and unit, name if given) per tag")
        if len(set(self.tags)) != len(self.tags):
            raise ValueError("tags must be unique")

    def round(self, values: np.ndarray) -> np.ndarray:
        """``values`` (n, n_tags) rounded column by column (half to even, :func:`numpy.round`),
        in place, with -0.0 made 0.0; returns it."""
        for d in sorted({d for d in self.decimals if d is not None}):
            cols = [i for i, di in enumerate(self.decimals) if di == d]
            if len(cols) == values.shape[1]:
                np.round(values, d, out=values)
            else:
                values[:, cols] = np.round(values[:, cols], d)
        values += 0.0
        return values


def _repeated(strings, codes: np.ndarray, decode: bool) -> pl.Series:
    """A string column given as distinct values and int32 codes: categorical (cheap to build and
    to write as CSV), or plain strings when ``decode`` (Parquet files get String columns)."""
    arr = pa.DictionaryArray.from_arrays(pa.array(codes), pa.array(strings, pa.string()) if isinstance(strings, (list, tuple)) else strings)
    return pl.from_arrow(arr.dictionary_decode() if decode else arr)  # type: ignore[return-value]


FILE_SUFFIXES = {"csv": ".csv", "ascii": ".txt", "parquet": ".parquet", "tdms": ".tdms"}
"""File name suffix per file format (text formats get ``.gz`` with gzip)."""


def export_suffix(file_format: str, gzip: bool) -> str:
    """File name suffix: ``.csv``, ``.txt`` (ASCII with header rows), ``.parquet``, ``.tdms``; ``.gz`` added for gzip text."""
    return FILE_SUFFIXES[file_format] + (".gz" if gzip and file_format in ("csv", "ascii") else "")


class DayWriter:
    """Writes the chunks of one day into one export file (see the module docstring)."""

    def __init__(self, path: Path, export: ExportSpec, columns: ExportColumns, timezone: str):
        self.path = Path(path)
        self.export = export
        self.columns = columns
        self.timezone = timezone
        self.rows = 0
        """Rows written so far (long layout: one per sample and tag; wide: one per sample)."""

    # -- the time column ---------------------------------------------------------------------

    def _time_series(self, timestamps_us: np.ndarray, n_repeat: int, for_parquet: bool) -> pl.Series:
        """The time column as the export's ``timestamp_format`` asks.

        ``iso8601``: Datetime(µs, UTC), written as ``2025-03-01T00:00:00.001000Z`` (Parquet:
        a native UTC timestamp); ``epoch_ms``: integer milliseconds since 1970 UTC; any other
        value is a strftime pattern applied to the plant's local time (``[plant] timezone``),
        since such timestamps carry no offset (Parquet: the formatted strings).
        """
        fmt = self.export.timestamp_format
        name = self.export.timestamp_column
        ts = np.repeat(timestamps_us, n_repeat) if n_repeat > 1 else timestamps_us
        if fmt == "epoch_ms":
            return pl.Series(name, ts // 1000, dtype=pl.Int64)
        s = pl.Series(name, ts, dtype=pl.Int64).cast(pl.Datetime("us", "UTC"))
        if fmt == "iso8601":
            return s
        s = s.dt.convert_time_zone(self.timezone)
        return s.dt.to_string(fmt) if for_parquet else s

    def _csv_datetime_format(self) -> str | None:
        fmt = self.export.timestamp_format
        if fmt == "iso8601":
            return ISO8601_FORMAT
        if fmt == "epoch_ms":
            return None
        return fmt

    # -- frames ------------------------------------------------------------------------------

    def _frame(self, timestamps_us: np.ndarray, values: np.ndarray, for_parquet: bool) -> pl.DataFrame:
        e = self.export
        n, k = values.shape
        if k != len(self.columns.tags):
            raise ValueError(f"chunk has {k} columns, the archive has {len(self.columns.tags)} tags")
        if timestamps_us.shape != (n,):
            raise ValueError("one time stamp per chunk row")
        self.columns.round(values)
        if e.layout == "long":
            tag = _repeated(self.columns.tags, np.tile(np.arange(k, dtype=np.int32), n), decode=for_parquet)
            if for_parquet or e.timestamp_format == "epoch_ms":
                time_col = self._time_series(timestamps_us, k, for_parquet)
            else:
                # each time stamp is formatted once and repeated for the k tags
                text = self._time_series(timestamps_us, 1, False).dt.to_string(self._csv_datetime_format())
                time_col = _repeated(text.to_arrow(), np.repeat(np.arange(n, dtype=np.int32), k), decode=False)
            cols = [
                time_col.alias(e.timestamp_column),
                tag.alias(e.tag_column),
                pl.Series(e.value_column, values.reshape(-1), dtype=pl.Float64),
            ]
            if e.quality_column is not None:
                cols.append(_repeated([e.good_quality[0]], np.zeros(n * k, np.int32), decode=for_parquet).alias(e.quality_column))
            return pl.DataFrame(cols)
        cols = [self._time_series(timestamps_us, 1, for_parquet)]
        cols += [pl.Series(tag, np.ascontiguousarray(values[:, i]), dtype=pl.Float64) for i, tag in enumerate(self.columns.tags)]
        if e.quality_column is not None:
            cols.append(pl.repeat(e.good_quality[0], n, dtype=pl.String, eager=True).alias(e.quality_column))
        return pl.DataFrame(cols)

    def write(self, timestamps_us: np.ndarray, values: np.ndarray) -> int:
        """Append a chunk; returns the number of rows written. ``values`` is rounded in place."""
        raise NotImplementedError

    def close(self) -> None:
        """Finish the file."""
        raise NotImplementedError

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class CsvDayWriter(DayWriter):
    """Long or wide CSV with the export's separator and decimal mark, optionally gzip; a wide file
    starts with the lines of ``export.header_rows`` (tags, names, units, ``skip`` lines as iba's
    signal ids ``[0:k]``)."""

    def __init__(self, path: Path, export: ExportSpec, columns: ExportColumns, timezone: str, gzip: bool = False):
        super().__init__(path, export, columns, timezone)
        self.gzip = gzip
        self._fh: BinaryIO | None = open(self.path, "wb")

    def _header_rows(self) -> bytes:
        """The header lines of ``export.header_rows`` (wide layout)."""
        e, c = self.export, self.columns
        cells = {
            "tag": [e.timestamp_column, *c.tags],
            "name": ["", *(c.names or c.tags)],
            "unit": ["", *(c.units or [""] * len(c.tags))],
            "skip": ["", *(f"[0:{k}]" for k in range(len(c.tags)))],
        }
        text = "".join(e.separator.join(cells[kind]) + "\n" for kind in e.header_rows).encode()
        return _gzip.compress(text, GZIP_LEVEL, mtime=0) if self.gzip else text

    def write(self, timestamps_us: np.ndarray, values: np.ndarray) -> int:
        if self._fh is None:
            raise ValueError(f"{self.path}: writer is closed")
        df = self._frame(timestamps_us, values, for_parquet=False)
        rows = self.export.layout == "wide" and self.export.header_rows != ExportSpec.header_rows
        if rows and self.rows == 0:
            self._fh.write(self._header_rows())
        df.write_csv(
            self._fh,
            include_header=self.rows == 0 and not rows,
            separator=self.export.separator,
            decimal_comma=self.export.decimal == ",",
            datetime_format=self._csv_datetime_format(),
            compression="gzip" if self.gzip else "uncompressed",
            compression_level=GZIP_LEVEL if self.gzip else None,
            batch_size=CSV_BATCH_ROWS,
        )
        self.rows += df.height
        return df.height

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None


class ParquetDayWriter(DayWriter):
    """Long or wide Parquet (zstd), one row group per chunk, streamed with pyarrow."""

    def __init__(self, path: Path, export: ExportSpec, columns: ExportColumns, timezone: str):
        super().__init__(path, export, columns, timezone)
        self._writer: pq.ParquetWriter | None = None
        self._closed = False

    def _table(self, timestamps_us: np.ndarray, values: np.ndarray) -> pa.Table:
        """The chunk as an Arrow table (built directly: no polars round trip for the big columns)."""
        e = self.export
        n, k = values.shape
        if k != len(self.columns.tags) or timestamps_us.shape != (n,):
            return self._frame(timestamps_us, values, for_parquet=True).to_arrow()  # raises the shape error
        self.columns.round(values)
        rep = k if e.layout == "long" else 1
        if e.timestamp_format == "iso8601":
            time_col = pa.array(np.repeat(timestamps_us, rep), pa.timestamp("us", tz="UTC"))
        elif e.timestamp_format == "epoch_ms":
            time_col = pa.array(np.repeat(timestamps_us // 1000, rep), pa.int64())
        else:
            text = self._time_series(timestamps_us, 1, for_parquet=True).to_arrow()
            time_col = text.take(pa.array(np.repeat(np.arange(n, dtype=np.int32), rep)))
        cols: dict[str, pa.Array] = {e.timestamp_column: time_col}
        if e.layout == "long":
            codes = pa.array(np.tile(np.arange(k, dtype=np.int32), n))
            cols[e.tag_column] = pa.DictionaryArray.from_arrays(codes, pa.array(self.columns.tags, pa.string())).dictionary_decode()
            cols[e.value_column] = pa.array(values.reshape(-1))
            m = n * k
        else:
            for i, tag in enumerate(self.columns.tags):
                cols[tag] = pa.array(np.ascontiguousarray(values[:, i]))
            m = n
        if e.quality_column is not None:
            cols[e.quality_column] = pa.DictionaryArray.from_arrays(pa.array(np.zeros(m, np.int32)), pa.array([e.good_quality[0]], pa.string())).dictionary_decode()
        return pa.table(cols)

    def write(self, timestamps_us: np.ndarray, values: np.ndarray) -> int:
        if self._closed:
            raise ValueError(f"{self.path}: writer is closed")
        table = self._table(timestamps_us, values)
        if self._writer is None:
            self._writer = pq.ParquetWriter(self.path, table.schema, compression=PARQUET_COMPRESSION)
        self._writer.write_table(table)
        self.rows += table.num_rows
        return table.num_rows

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()
            self._writer = None
        self._closed = True


TDMS_GROUP = "valvemon"
"""The group a TDMS file's channels are written to unless ``export.tdms_group`` names one."""


class TdmsDayWriter(DayWriter):
    """TDMS (wide: one channel per tag, named by the tag, in one group), one segment per chunk.

    ``waveform``: the samples are back to back on the export's grid (a continuous recording), and
    the time is the channels' waveform properties ``wf_start_time`` (UTC) and ``wf_increment``;
    otherwise (snapshots: windows with pauses between them) a time channel named
    ``export.timestamp_column`` holds each sample's TDMS timestamp. Channel properties:
    ``unit_string`` and ``description`` from :class:`ExportColumns`.
    """

    def __init__(self, path: Path, export: ExportSpec, columns: ExportColumns, timezone: str, waveform: bool = False):
        from nptdms import TdmsWriter

        if export.layout != "wide":
            raise ValueError("TDMS files are written in the wide layout (a channel per tag)")
        super().__init__(path, export, columns, timezone)
        self.waveform = waveform
        self.group = export.tdms_group or TDMS_GROUP
        self.period_us = round(1e6 / export.sample_rate_hz)
        self._next_us: int | None = None
        self._writer = TdmsWriter(str(self.path))
        self._writer.open()
        self._closed = False

    def _properties(self, k: int, t0_us: int) -> dict:
        c = self.columns
        props: dict = {}
        if c.units:
            props["unit_string"] = c.units[k]
        if c.names:
            props["description"] = c.names[k]
        if self.waveform:
            props |= {"wf_start_time": np.datetime64(int(t0_us), "us"), "wf_increment": self.period_us / 1e6, "wf_start_offset": 0.0}
        return props

    def write(self, timestamps_us: np.ndarray, values: np.ndarray) -> int:
        from nptdms import ChannelObject

        if self._closed:
            raise ValueError(f"{self.path}: writer is closed")
        self._frame(timestamps_us[:0], values[:0], for_parquet=True)  # the shape checks
        n = len(timestamps_us)
        self.columns.round(values)
        first = self.rows == 0
        if self.waveform and ((not first and int(timestamps_us[0]) != self._next_us) or np.any(np.diff(timestamps_us) != self.period_us)):
            raise ValueError(f"{self.path}: a waveform TDMS file needs samples back to back on the {self.period_us} µs grid")
        objects = []
        if not self.waveform:
            objects.append(ChannelObject(self.group, self.export.timestamp_column, timestamps_us.astype("datetime64[us]")))
        for k, tag in enumerate(self.columns.tags):
            objects.append(ChannelObject(self.group, tag, np.ascontiguousarray(values[:, k]), properties=self._properties(k, int(timestamps_us[0])) if first else None))
        self._writer.write_segment(objects)
        self._next_us = int(timestamps_us[-1]) + self.period_us
        self.rows += n
        return n

    def close(self) -> None:
        if not self._closed:
            self._writer.close()
            self._closed = True


def open_day_writer(
    path: Path, export: ExportSpec, columns: ExportColumns, timezone: str, file_format: str, gzip: bool = False, continuous: bool = False
) -> DayWriter:
    """A writer for one day's file: ``file_format`` is ``"csv"``, ``"ascii"`` (wide text with the
    plant's header rows), ``"parquet"`` or ``"tdms"`` (layout from ``export``; ``continuous``: TDMS
    time from waveform properties instead of a time channel)."""
    if file_format == "parquet":
        return ParquetDayWriter(path, export, columns, timezone)
    if file_format in ("csv", "ascii"):
        return CsvDayWriter(path, export, columns, timezone, gzip=gzip)
    if file_format == "tdms":
        return TdmsDayWriter(path, export, columns, timezone, waveform=continuous)
    raise ValueError(f"unknown export file format {file_format!r}")
