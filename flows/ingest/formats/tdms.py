"""TDMS recordings (NI LabVIEW/DAQmx, test benches, iba) read in bounded batches with npTDMS.

A TDMS file holds groups of channels. The ingest reads it in the wide layout: **each channel is
one tag, named by the channel's name** (the group name is not part of the tag), from every group
or from ``export.tdms_group`` only. The time of sample ``i`` comes from

- a **time channel** named ``export.timestamp_column`` beside the data channels (TDMS timestamps,
  which are UTC; or numbers read per ``export.timestamp_format``, e.g. ``epoch_ms``), or else
- the channels' **waveform properties**: ``wf_start_time + wf_start_offset + i · wf_increment``
  (seconds), the same for every channel read.

All channels read share that one time base (the same length; the same waveform properties), so
row ``i`` of the frame is sample ``i`` of every channel; the frame's "line" of a sample is
``i + 1``. A channel's ``unit_string`` property (NI's convention), when set, is its unit
(``transforms.ingest.units``). :func:`iload` reads rows ``[a, b)`` of each channel with
``TdmsChannel.read_data(offset, length)`` (npTDMS finds the segments by a binary search), so memory
is bounded by the batch, not by the file.
"""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import numpy as np
import polars as pl

from flows.common.errors import ValvemonError
from schemas.plant_config import ExportSpec
from transforms.ingest.units import FileUnits

SUFFIXES = (".tdms",)
FILE_FORMATS = ("tdms",)
"""The manifest's ``file_format`` of the files this module reads."""
_MAGIC = b"TDSm"
"""A TDMS file's first bytes (its first segment's lead-in)."""
TDMS_EPOCH_S = -2_082_844_800
"""1904-01-01T00:00:00Z, the TDMS epoch, in Unix seconds."""


def _ns(seconds, fractions):
    """TDMS time (seconds since 1904, 2^-64 s fractions) → Unix ns, rounded to the nearest ns
    (numpy arrays or Python ints; the fraction's 30 low bits, < 6e-11 s, are dropped first so the
    product fits 64 bits)."""
    if isinstance(seconds, np.ndarray):
        frac = ((fractions.astype(np.uint64) >> np.uint64(30)) * np.uint64(1_000_000_000) + np.uint64(1 << 33)) >> np.uint64(34)
        return (seconds.astype(np.int64) + TDMS_EPOCH_S) * 1_000_000_000 + frac.astype(np.int64)
    return (int(seconds) + TDMS_EPOCH_S) * 1_000_000_000 + (((int(fractions) >> 30) * 1_000_000_000 + (1 << 33)) >> 34)


@dataclass
class TdmsLayout:
    """What of a TDMS file is read, and its time base."""

    channels: list
    """The data channels (``TdmsChannel``), one per tag, in file order."""
    tags: list[str]
    time: object | None
    """The time channel, or None (waveform properties)."""
    start_ns: int
    step_ns: float
    """Waveform time base (unused with a time channel). [ns]"""
    length: int
    units: FileUnits


def _path(ch) -> str:
    return f"channel {ch.group_name!r}/{ch.name!r}"


def _waveform(ch, where: str, time_name: str) -> tuple[int, float]:
    from nptdms.timestamp import TdmsTimestamp

    p = ch.properties
    if "wf_start_time" not in p or "wf_increment" not in p:
        raise ValvemonError(
            f"{where}: {_path(ch)} has no time: neither a time channel {time_name!r} (export.timestamp_column) "
            "nor the waveform properties wf_start_time and wf_increment"
        )
    start = p["wf_start_time"]
    if not isinstance(start, TdmsTimestamp):
        raise ValvemonError(f"{where}: {_path(ch)}: wf_start_time is not a TDMS timestamp ({start!r})")
    increment = float(p["wf_increment"])
    if not increment > 0:
        raise ValvemonError(f"{where}: {_path(ch)}: wf_increment {increment!r} is not a positive number of seconds")
    offset_ns = round(float(p.get("wf_start_offset", 0.0)) * 1e9)
    return _ns(start.seconds, start.second_fractions) + offset_ns, increment * 1e9


def tdms_layout(tdms, export: ExportSpec, where: str) -> TdmsLayout:
    """The channels to read and their time base (module doc).

    Raises
    ------
    ValvemonError
        Naming the file: not the wide layout, no such group, a tag in two groups, several time
        channels, channels of different lengths or time bases, no time at all.
    """
    if export.layout != "wide":
        raise ValvemonError(f"{where}: a TDMS file is read in the wide layout (a channel per tag); the configuration has export.layout = {export.layout!r}")
    groups = tdms.groups()
    if export.tdms_group is not None:
        names = [g.name for g in groups]
        if export.tdms_group not in names:
            raise ValvemonError(f"{where}: no group {export.tdms_group!r} (export.tdms_group); the file's groups are {', '.join(map(repr, names)) or 'none'}")
        groups = [tdms[export.tdms_group]]
    channels, times, seen = [], [], {}
    for g in groups:
        for ch in g.channels():
            if len(ch) == 0:
                continue
            if ch.name == export.timestamp_column:
                times.append(ch)
                continue
            if ch.name in seen:
                raise ValvemonError(f"{where}: {_path(ch)}: tag {ch.name!r} also in group {seen[ch.name]!r} (set export.tdms_group)")
            seen[ch.name] = ch.group_name
            channels.append(ch)
    if not channels:
        raise ValvemonError(f"{where}: no data channels (expected a TDMS channel per tag)")
    if len(times) > 1:
        raise ValvemonError(f"{where}: several time channels {export.timestamp_column!r} ({', '.join(_path(t) for t in times)}): set export.tdms_group")
    time = times[0] if times else None
    length = len(time) if time is not None else len(channels[0])
    start_ns, step_ns = (0, 0.0) if time is not None else _waveform(channels[0], where, export.timestamp_column)
    for ch in channels:
        if len(ch) != length:
            ref = _path(time) if time is not None else _path(channels[0])
            raise ValvemonError(f"{where}: {_path(ch)} has {len(ch):,} values, {ref} {length:,}: channels of one time base expected (set export.tdms_group)")
        if time is None and _waveform(ch, where, export.timestamp_column) != (start_ns, step_ns):
            raise ValvemonError(
                f"{where}: {_path(ch)}: waveform start or increment differs from {_path(channels[0])}: channels of one time base expected (set export.tdms_group)"
            )
    units = {ch.name: (str(ch.properties.get("unit_string", "")), _path(ch)) for ch in channels}
    return TdmsLayout(channels, [ch.name for ch in channels], time, start_ns, step_ns, length, units)


@contextmanager
def open_tdms(path: Path) -> Iterator:
    """The file's metadata (no data read), open for reading slices; refuses a file whose last
    segment was cut off.

    The file is given to npTDMS as an open file, not a path, so that it reads the metadata from
    the ``.tdms`` itself and not from a ``.tdms_index`` beside it (which the content hash does not
    cover and which may be stale).

    Raises
    ------
    ValvemonError
        Not a TDMS file, or truncated (npTDMS itself only warns and reads what is there).
    """
    from nptdms import TdmsFile  # imported when a TDMS file is read

    with open(path, "rb") as fh:
        try:
            tdms = TdmsFile.open(fh, raw_timestamps=True)
        except (ValueError, EOFError, OSError, KeyError) as exc:
            raise ValvemonError(f"{path}: not a readable TDMS file ({str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__})") from None
        with tdms:
            # npTDMS keeps no public record of where the last whole segment ends (a cut in a segment's
            # metadata ends its reading silently); without that record, its file_status alone is checked
            segments = getattr(getattr(tdms, "_reader", None), "_segments", None)
            size = path.stat().st_size
            end = size if segments is None else segments[-1].next_segment_pos if segments else 0
            if tdms.file_status.incomplete_final_segment or end != size:
                raise ValvemonError(f"{path}: truncated TDMS file (its last segment ends at byte {end:,} of {size:,} or is incomplete; expected whole segments)")
            yield tdms


def detect(head: bytes, name: str) -> str | None:
    return "tdms" if head.startswith(_MAGIC) else None


def describe(src, export: ExportSpec, timezone: str) -> None:
    """The ``unit_string`` of every data channel (:func:`tdms_layout`); refuses a truncated file."""
    with open_tdms(src.path) as tdms:
        src.units = tdms_layout(tdms, export, str(src.path)).units


def _times(layout: TdmsLayout, a: int, b: int) -> pl.Series:
    from nptdms.timestamp import TimestampArray

    if layout.time is None:
        step = layout.step_ns
        i = np.arange(a, b, dtype=np.int64)
        ns = layout.start_ns + (i * int(step) if step == int(step) else np.rint(i * step).astype(np.int64))
        return pl.Series(ns, dtype=pl.Int64).cast(pl.Datetime("ns", "UTC"))
    raw = layout.time.read_data(a, b - a)
    if isinstance(raw, TimestampArray):
        return pl.Series(_ns(raw.seconds, raw.second_fractions), dtype=pl.Int64).cast(pl.Datetime("ns", "UTC"))
    return pl.Series(raw)


def iload(src, export: ExportSpec, tags, batch_samples: int, block_bytes: int) -> Iterator[tuple[pl.DataFrame, int, bool]]:
    """The recording as wide frames of about ``batch_samples`` samples: ``(frame, first line, last)``,
    columns ``export.timestamp_column`` and one Float64 column per channel (tag)."""
    with open_tdms(src.path) as tdms:
        layout = tdms_layout(tdms, export, str(src.path))
        rows = max(batch_samples // len(layout.channels), 1024)
        for a in range(0, layout.length, rows):
            b = min(a + rows, layout.length)
            columns = [_times(layout, a, b).alias(export.timestamp_column)]
            columns += [pl.Series(tag, ch.read_data(a, b - a), dtype=pl.Float64) for tag, ch in zip(layout.tags, layout.channels)]
            yield pl.DataFrame(columns), a + 1, b == layout.length
