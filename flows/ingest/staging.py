"""One export's lake rows → merged, staged lake files, committed together at the end of the file.

:class:`LakeStager` takes the rows :class:`transforms.ingest.stream.ExportStream` gives (per
valve, in time order), buffers them per valve and UTC day, and writes them when they are
complete — an hour once the rows have gone past it, a day once they have gone past the day, all
at the end of the file, or everything when the buffer exceeds :data:`BUFFER_ROWS` — merging each
with the lake file it belongs to (``transforms.ingest.merge``) into a hidden temporary file
(``flows.common.lake.stage_file``). Nothing is visible to readers until :meth:`LakeStager.commit`
renames the temporary files into place after the last batch (a file refused half-way leaves the
lake as it was) and then removes day files whose rows moved into hour files.

The day folder's form (``flows.common.lake``): a day file while the day holds at most
``DAY_FILE_MAX_ROWS`` rows, else hour files; a day that outgrows its day file is switched to hour
files by this ingest (the day file's rows are split into hour files, merged with the new rows,
and the day file is removed last). A file that touches a day only rewrites the files of the
hours it touches.

A run killed at any moment leaves each lake file old or new, and the export is not in the
manifest; running it again merges the same rows into the same files and ends with the lake one
clean run gives (``docs/ingest.md``, "Atomic partitions").
"""

from __future__ import annotations

from contextlib import AbstractContextManager, ExitStack
from datetime import date
from pathlib import Path
from typing import Callable

import polars as pl
import pyarrow.parquet as pq

from flows.common.lake import (
    DAY_FILE_MAX_ROWS,
    PART_NAME,
    US_PER_HOUR,
    clear_stale,
    commit_files,
    day_files,
    hour_path,
    partition_path,
    read_partition,
    row_group_spans,
    stage_file,
    stage_link,
)
from schemas.plant_config import PlantConfig
from transforms.ingest import merge_partition, split_days, tags_by_column
from transforms.ingest.frames import time_slices

BUFFER_ROWS = 8_388_608
"""Lake rows held before everything buffered is written, complete or not (bounds memory when
one file holds many valves)."""
US_PER_DAY = 24 * US_PER_HOUR


def _hours(frame: pl.DataFrame) -> list[tuple[int, pl.DataFrame]]:
    """A day's rows (sorted) → ``(UTC hour, rows)`` slices (the hours' edges found by bisection,
    not by a pass over the rows)."""
    return [(int(k % 24), part) for k, part in time_slices(frame, US_PER_HOUR)]


class LakeStager:
    """The lake files of one export, staged and then committed together (module doc).

    Parameters
    ----------
    warehouse : Path
        The warehouse folder.
    config : PlantConfig
        The plant (``export.duplicate_rule``, ``export.max_gap_s`` for the row groups).
    lock : callable
        ``lock(day file path)``: a context manager held from the first write to a day folder
        until the commit (the backfill's partition lock; the ingest holds the warehouse lock).
    """

    def __init__(self, warehouse: Path, config: PlantConfig, lock: Callable[[Path], AbstractContextManager]):
        self.warehouse, self.config, self.lock = Path(warehouse), config, lock
        self.rule = config.export.duplicate_rule
        self.gap_us = max(int(round(config.export.max_gap_s * 1e6)), 1)
        self.codec = config.lake.codec
        self.buffer: dict[tuple[str, date], list[pl.DataFrame]] = {}
        self.first: dict[tuple[str, date], int] = {}
        """The earliest buffered time (µs) of each valve-day in the buffer."""
        self.buffered = 0
        self.staged: dict[Path, Path] = {}
        """Final path → its staged temporary file, in the order written."""
        self.removed: list[Path] = []
        self.folders: set[Path] = set()
        self.days: set[tuple[str, date]] = set()
        self.days_written: set[tuple[str, date]] = set()
        self.rows_added = 0
        self.lake_conflicts = 0
        self._locks = ExitStack()

    # --- rows in ------------------------------------------------------------------------------

    def add(self, frame: pl.DataFrame) -> None:
        """One valve's new lake rows, sorted, later than any it gave before."""
        vid = frame["valve_id"][0]
        for day, part in split_days(frame):
            if (vid, day) not in self.buffer:
                self.first[(vid, day)] = part["timestamp_utc"].to_physical()[0]
            self.buffer.setdefault((vid, day), []).append(part)
            self.days.add((vid, day))
            self.buffered += part.height

    def flush(self, given_to: dict[str, int] | None) -> None:
        """Write what is complete: rows before the hour of ``given_to[valve]`` (µs; the export
        gives no rows before it any more), or everything (``None``: the end of the file)."""
        force = given_to is None or self.buffered > BUFFER_ROWS
        for key in list(self.buffer):
            vid, day = key
            upto = None if force else given_to.get(vid)
            day_end = (day.toordinal() - 719163 + 1) * US_PER_DAY  # 719163: date(1970, 1, 1).toordinal()
            complete = force or upto >= day_end
            before = None if force else upto // US_PER_HOUR * US_PER_HOUR
            if not complete and self.first[key] >= before:
                continue  # no complete hour buffered (the usual case within an hour): nothing to write yet
            rows = pl.concat(self.buffer.pop(key))
            del self.first[key]
            self.buffered -= rows.height
            keep = self._write(vid, day, rows, complete=complete, before=before)
            if keep is not None and keep.height:
                self.buffer[key] = [keep]
                self.first[key] = keep["timestamp_utc"].to_physical()[0]
                self.buffered += keep.height

    # --- the day folder -----------------------------------------------------------------------

    def _folder(self, vid: str, day: date) -> Path:
        day_file = partition_path(self.warehouse, vid, day)
        folder = day_file.parent
        if folder not in self.folders:
            self._locks.enter_context(self.lock(day_file))
            clear_stale(folder)
            self.folders.add(folder)
        return folder

    def _current(self, path: Path) -> pl.DataFrame | None:
        """A lake file's content as this export has it so far: staged, stored, or none."""
        if path in self.staged:
            return read_partition(self.staged[path])
        if path in self.removed:
            return None
        return read_partition(path)

    def _by_hour(self, folder: Path) -> bool:
        """Whether the day folder is (or became, in this export) stored by the hour."""
        day_file = folder / PART_NAME
        if day_file in self.staged or (day_file.exists() and day_file not in self.removed):
            return False
        return any(p.parent == folder for p in self.staged) or bool(day_files(folder))

    def _rows_of(self, path: Path) -> int:
        if path in self.staged:
            return pq.ParquetFile(self.staged[path]).metadata.num_rows
        return pq.ParquetFile(path).metadata.num_rows if path.exists() else 0

    def _write(self, vid: str, day: date, rows: pl.DataFrame, *, complete: bool, before: int | None) -> pl.DataFrame | None:
        """Merge a day's buffered rows into its files; returns the rows kept for later."""
        folder = self._folder(vid, day)
        day_file = folder / PART_NAME
        if not self._by_hour(folder):
            if self._rows_of(day_file) + rows.height <= DAY_FILE_MAX_ROWS:
                if not complete:
                    return rows  # the day may still fit its day file: wait for the rest
                self._merge(vid, day, day_file, rows)
                return None
            self._switch(vid, day, day_file)
        if before is not None:  # only the hours the export has gone past
            cut = int(rows["timestamp_utc"].to_physical().search_sorted(before))
            rows, rest = rows.slice(0, cut), rows.slice(cut)
        else:
            rest = None
        for hour, part in _hours(rows) if rows.height else []:
            self._merge(vid, day, hour_path(folder, hour), part)
        return rest

    def _switch(self, vid: str, day: date, day_file: Path) -> None:
        """A day outgrows its day file: its rows go to hour files, the day file goes at the commit.
        A day file whose rows lie in one hour (the first hour file of a recording) already is that
        hour's file, byte for byte: it is staged under the hour's name without being read or
        written again."""
        hour = self._one_hour(day_file)
        if hour is not None:
            target = hour_path(day_file.parent, hour)
            stale = self.staged.pop(target, None)
            if stale is not None:
                stale.unlink(missing_ok=True)
            self.staged[target] = self.staged.pop(day_file) if day_file in self.staged else stage_link(day_file, target)
            if day_file.exists():
                self.removed.append(day_file)
            self.days_written.add((vid, day))
            return
        old = self._current(day_file)
        if day_file in self.staged:
            self.staged.pop(day_file).unlink(missing_ok=True)
        if day_file.exists():
            self.removed.append(day_file)
        for hour, part in _hours(old) if old is not None and old.height else []:
            self._stage(vid, day, hour_path(day_file.parent, hour), part)

    def _one_hour(self, day_file: Path) -> int | None:
        """The UTC hour that holds every row of the day file as this export has it (footer
        statistics, no data read), None if it spans more (or has no rows or statistics)."""
        path = self.staged.get(day_file, day_file)
        if day_file in self.removed or not path.exists():
            return None
        spans = row_group_spans(path)
        if not spans or not sum(n for n, _, _ in spans):
            return None
        first, last = min(a for _, a, _ in spans), max(b for _, _, b in spans)
        hour = first // US_PER_HOUR
        return int(hour % 24) if last // US_PER_HOUR == hour else None

    def _merge(self, vid: str, day: date, path: Path, rows: pl.DataFrame) -> None:
        merged = merge_partition(self._current(path), rows, self.rule, tags_by_column(self.config, vid))
        self.rows_added += merged.rows_added
        self.lake_conflicts += merged.lake_conflicts
        if merged.changed:
            self._stage(vid, day, path, merged.frame)

    def _stage(self, vid: str, day: date, path: Path, frame: pl.DataFrame) -> None:
        old = self.staged.pop(path, None)
        self.staged[path] = stage_file(path, frame, gap_us=self.gap_us, codec=self.codec)
        if old is not None:
            old.unlink(missing_ok=True)
        self.days_written.add((vid, day))

    # --- the end --------------------------------------------------------------------------------

    def commit(self) -> None:
        """Put every staged file in place, then remove the day files that were switched."""
        commit_files([(tmp, path) for path, tmp in self.staged.items()], self.removed)
        self.staged.clear()
        self.removed.clear()

    def discard(self) -> None:
        """Forget the staged files (a refused file leaves the lake as it was)."""
        for tmp in self.staged.values():
            tmp.unlink(missing_ok=True)
        self.staged.clear()
        self.removed.clear()

    def release(self) -> None:
        """Release the day folders' locks."""
        self._locks.close()
