"""An export taken batch by batch → the same lake rows, quarantine, gaps and counts as the whole file.

:class:`ExportStream` is fed the file's rows in consecutive batches (:meth:`ExportStream.feed`)
and returns, per batch, the lake rows it can already give; the last batch (``final=True``)
flushes the rest. Per tag it carries across a batch edge only what the whole-file rules
(``docs/ingest.md``, "Rules") need to see on both sides:

- the samples at the tag's latest time (a run of duplicates or conflicts may go on in the next
  batch), held back unresolved, with their lines;
- the last sample already put on the grid, the *anchor*: the next batch's first samples are
  interpolated from it and a gap after it is found, and grid instants up to it are not produced
  twice;
- per valve, the grid rows beyond the point every signal of the valve has reached (a lake row
  needs all required signals, ``x_ref`` where it has a value).

So an export cut into any batches gives what the whole file gives, as long as every tag's times
never go back across a batch edge and the valve's signals advance together (time-ordered
exports, wide or long interleaved). Where that does not hold — times that go back across an
edge, a signal that begins behind rows already given, a repeated autumn hour of local times
near an edge — :class:`NotStreamable` is raised and the caller processes the file whole.
Memory per batch is the batch plus the carry (a few samples per tag, rows of at most a batch).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from datetime import datetime, timedelta, timezone
from zoneinfo import ZoneInfo

import numpy as np
import polars as pl

from schemas.fields import FAULT_REASONS, REQUIRED_SIGNALS, SIGNAL_COLUMN
from schemas.plant_config import PlantConfig
from transforms.ingest.errors import IngestError
from transforms.ingest.frames import assemble_valve, validate_raw_rows, validate_sensor_frame
from transforms.ingest.grid import Grid, Gridded, GridTimes, grid_times, prepare_tag, to_grid
from transforms.ingest.clock import ClockSteps
from transforms.ingest.wide_batch import gridded_columns, lake_value
from transforms.ingest.samples import FUTURE_TOLERANCE_NS, QUARANTINE_COLUMNS, TagTable, check_required_signals, empty_quarantine, samples_of, split_by_tag, tag_blocks

GAP_COLUMNS = {
    "valve_id": pl.String,
    "signal": pl.String,
    "tag": pl.String,
    "gap_start": pl.Datetime("us", "UTC"),
    "gap_end": pl.Datetime("us", "UTC"),
    "duration_s": pl.Float64,
}
_NONE = np.zeros(0, dtype=np.int64)
_DONE = np.iinfo(np.int64).max


class NotStreamable(Exception):
    """The export's order does not allow batch-by-batch processing (module doc)."""


@dataclass
class ExportCounts:
    """What an export held and what became of it (see ``docs/ingest.md``, "Counts")."""

    rows_in: int = 0
    samples_in: int = 0
    quarantined: int = 0
    duplicates: int = 0
    conflicts: int = 0
    gaps: int = 0
    rows_out: int = 0
    accepted: int = 0
    """Samples left after quarantine and de-duplication (samples_in − quarantined − duplicates − conflicts)."""
    time_start: datetime | None = None
    time_end: datetime | None = None
    valves: tuple[str, ...] = ()
    bad_timestamp: int = 0
    implausible_time: int = 0
    out_of_range: int = 0
    """Of ``quarantined``: the faults whose share ``export.max_bad_share`` bounds."""
    other_tags: dict[str, int] = field(default_factory=dict)
    """Tags (columns) no valve has → their samples, read past (not in ``samples_in``)."""
    field_count: int = 0
    """Of ``quarantined``: samples of text rows whose field count is not the header's."""
    truncated: int = 0
    """1 when the file's last line has no line end (a cut file; its samples are quarantined), else 0."""
    clock_step: int = 0
    """Of ``quarantined``: samples of a wide export's rows at and after a step of its clock."""
    clock_step_message: str | None = None
    """Where the clock stepped back, by how much, and what became of the rows after it."""
    rows_added: int = 0
    lake_conflicts: int = 0
    partitions: int = 0
    partitions_written: int = 0
    """What merging with the lake did (the flows fill these): rows the lake did not have, rows that
    differed from the lake's, valve-days touched and written."""


@dataclass
class _TagCarry:
    """What one tag carries into the next batch."""

    last_ns: int
    """Its latest time so far: the next batch's samples must not be earlier."""
    held_t: np.ndarray
    held_v: np.ndarray
    held_line: np.ndarray
    """The samples at ``last_ns``, file order, not yet resolved."""
    anchor: tuple[int, float] | None = None
    """The last sample on the grid already (time ns, value)."""


@dataclass
class _ValveRows:
    """A valve's grid points not yet given as lake rows, per signal, and how far rows were given."""

    pending: dict[str, list[tuple[np.ndarray, np.ndarray]]] = field(default_factory=dict)
    reached: dict[str, int] = field(default_factory=dict)
    """Signal → the instant (µs) up to which all its grid points are known."""
    given_to: int = -_DONE
    """Rows up to this instant (µs) were given."""


def tags_by_column(config: PlantConfig, valve_id: str) -> dict[str, str]:
    """Lake column → historian tag of one valve."""
    v = config.valve(valve_id)
    return {SIGNAL_COLUMN[s]: t.tag for s, t in v.tags.items()}


class _Lines:
    """The lines of one tag's samples in a batch: the held ones, then ``line_all[sel]``; built only
    when asked (they are needed for the held samples and for a message)."""

    def __init__(self, head: np.ndarray, line_all: np.ndarray, sel, keep: np.ndarray | None = None):
        self.head, self.line_all, self.sel, self.keep = head, line_all, sel, keep

    def __call__(self) -> np.ndarray:
        lines = np.concatenate([self.head, self.line_all[self.sel]])
        return lines if self.keep is None else lines[self.keep]

    def at(self, idx: np.ndarray) -> np.ndarray:
        """The lines of the samples ``idx`` (of all, before :meth:`only`)."""
        h = len(self.head)
        if len(idx) and idx[0] >= h:
            rest = idx - h
            return self.line_all[self.sel][rest] if isinstance(self.sel, slice) else self.line_all[self.sel[rest]]
        return np.concatenate([self.head, self.line_all[self.sel]])[idx]

    def only(self, keep: np.ndarray) -> _Lines:
        return _Lines(self.head, self.line_all, self.sel, keep)


def near_clock_change(t0_ns: int, t1_ns: int, tz: str) -> bool:
    """Whether local times of ``tz`` change their UTC offset within an hour of ``[t0, t1]``."""
    if tz == "UTC":
        return False
    zone = ZoneInfo(tz)
    a = datetime.fromtimestamp(t0_ns / 1e9, timezone.utc) - timedelta(hours=1)
    b = datetime.fromtimestamp(t1_ns / 1e9, timezone.utc) + timedelta(hours=1)
    return a.astimezone(zone).utcoffset() != b.astimezone(zone).utcoffset()


class ExportStream:
    """One export, fed batch by batch (module doc).

    Parameters
    ----------
    config : PlantConfig
        The plant.
    tags : TagTable, optional
        ``TagTable.from_config(config)``, when the caller already has it.
    origin_ns : int, optional
        The file's start time (UTC ns), which a relative ``export.timestamp_format`` counts from.
    """

    def __init__(self, config: PlantConfig, tags: TagTable | None = None, *, now: datetime | None = None, origin_ns: int | None = None):
        self.config = config
        self.origin_ns = origin_ns
        self.tags = tags or TagTable.from_config(config)
        self.grid = Grid.from_export(config.export.sample_rate_hz, config.export.max_gap_s)
        self.now_ns = time.time_ns() if now is None else round(now.timestamp() * 1e6) * 1000
        self.counts = ExportCounts()
        n_tags = len(self.tags.tags)
        self._tag_samples = np.zeros(n_tags, dtype=np.int64)
        self._faults = np.zeros((n_tags, len(FAULT_REASONS)), dtype=np.int64)
        self._first_faults: dict[tuple[int, int], str] = {}
        self.quarantine: list[pl.DataFrame] = []
        self.gaps: list[pl.DataFrame] = []
        self._present: set[str] = set()
        self._carry: dict[int, _TagCarry] = {}
        self._valves: dict[str, _ValveRows] = {}
        self._span: list[int] = []
        self._batches = 0
        self._times: GridTimes | None = None
        """The grid's pass over the last tag's times: the next tag of a wide batch has the same."""
        export = config.export
        self.clock = None
        if export.layout == "wide" and export.clock_steps == "quarantine":
            self.clock = ClockSteps.for_grid(export.sample_rate_hz, self.now_ns + FUTURE_TOLERANCE_NS)

    def feed(self, df: pl.DataFrame, *, first_line: int, final: bool) -> list[pl.DataFrame]:
        """The lake rows this batch completes: one validated sensor frame per valve, in time order.

        Parameters
        ----------
        df : DataFrame
            The batch, the file's next rows as read (columns as the file names them).
        first_line : int
            Line number of the batch's first row (CSV: the file's line; Parquet: its row).
        final : bool
            The last batch: everything carried is resolved and given.

        Raises
        ------
        IngestError
            What the file is refused for (as for the whole file).
        NotStreamable
            The export cannot be taken batch by batch (module doc).
        """
        self._batches += 1
        frames = self._feed_gridded(df, first_line=first_line, final=final)
        if frames is None:
            frames = self._feed_samples(df, first_line=first_line, final=final)
        if final and self._span:
            c = self.counts
            c.time_start, c.time_end = pl.Series([min(self._span), max(self._span)], dtype=pl.Int64).cast(pl.Datetime("ns", "UTC")).to_list()
        return frames

    def _close(self) -> None:
        """After the last batch's counts: the fault totals, and the file refused where its faults
        or tags say so."""
        c = self.counts
        totals = dict(zip(FAULT_REASONS, (int(x) for x in self._faults.sum(axis=0))))
        c.bad_timestamp, c.implausible_time, c.out_of_range = totals["bad_timestamp"], totals["implausible_time"], totals["out_of_range"]
        c.clock_step_message = None if self.clock is None else self.clock.message(c.clock_step)
        self._refuse_if_mostly_faulty()
        if c.other_tags and not self._present:
            names = ", ".join(list(c.other_tags)[:5]) + (", …" if len(c.other_tags) > 5 else "")
            raise IngestError(f"no tag of the plant configuration in the file, only {len(c.other_tags)} other tags ({names})")
        c.valves = tuple(check_required_signals(frozenset(self._present), self.config))

    def _feed_samples(self, df: pl.DataFrame, *, first_line: int, final: bool) -> list[pl.DataFrame]:
        """:meth:`feed` by the general rules: samples, quarantine, each tag sorted, de-duplicated
        and put on the grid, a valve's rows where all its signals have reached."""
        export, tags = self.config.export, self.tags
        df = df.rechunk()  # the columns contiguous: each tag's values taken without a copy
        samples = samples_of(df, self.config, tags, first_line=first_line, now_ns=self.now_ns, clock=self.clock, origin_ns=self.origin_ns)
        c = self.counts
        c.rows_in += samples.rows_in
        c.samples_in += samples.samples_in
        c.quarantined += samples.quarantine.height
        if samples.quarantine.height:
            self.quarantine.append(samples.quarantine)
            reasons = samples.quarantine["reason"]
            c.field_count += int(reasons.eq("field_count").sum())
            c.clock_step += int(reasons.eq("clock_step").sum())
        c.truncated |= int(samples.truncated)
        self._present |= samples.tags_present
        self._tag_samples += samples.tag_samples
        self._faults += samples.faults
        for key, what in samples.first_faults.items():
            self._first_faults.setdefault(key, what)
        for name, k in samples.other_tags.items():
            c.other_tags[name] = c.other_tags.get(name, 0) + k
        if final:
            self._close()
        acc = samples.accepted
        validate_raw_rows(acc)
        local = not export.relative_time  # relative times are counted from a start in UTC: never ambiguous
        if local and not (final and self._batches == 1) and acc.height and self.config.timezone != "UTC":
            ts = acc["timestamp_utc"].to_physical()
            if near_clock_change(int(ts.min()), int(ts.max()), self.config.timezone):
                raise NotStreamable("local times near a change of the clocks")
        if samples.blocks is not None:  # wide: a block per tag, its columns without a copy
            per_tag = [(tid, t, v, lines, slice(0, len(t))) for tid, t, v, lines in tag_blocks(acc, samples.blocks)]
        else:
            line_all = acc["line"].to_numpy()
            per_tag = [
                (tid, t, v, line_all, sel)
                for tid, t, v, sel in split_by_tag(acc["tag"].to_physical().to_numpy(), acc["timestamp_utc"].to_physical().to_numpy(), acc["value_si"].to_numpy())
            ]
        seen = set()
        for tid, t, v, line_all, sel in per_tag:
            seen.add(tid)
            carry = self._carry.get(tid)
            head = _NONE
            if carry is not None:
                if t.min() < carry.last_ns:
                    raise NotStreamable(f"tag {tags.tags[tid]}: times go back across a batch edge")
                t, v, head = np.concatenate([carry.held_t, t]), np.concatenate([carry.held_v, v]), carry.held_line
            self._tag(tid, t, v, _Lines(head, line_all, sel), carry, final)
        if final:
            for tid in [k for k in self._carry if k not in seen]:
                carry = self._carry[tid]
                self._tag(tid, carry.held_t, carry.held_v, _Lines(carry.held_line, _NONE, slice(0, 0)), carry, True)
        frames = self._give(final)
        if frames:  # every valve in one check (one call per valve costs more)
            validate_sensor_frame(pl.concat(frames), {f["valve_id"][0]: tags_by_column(self.config, f["valve_id"][0]) for f in frames})
        return frames

    def _feed_gridded(self, df: pl.DataFrame, *, first_line: int, final: bool) -> list[pl.DataFrame] | None:
        """:meth:`feed` for a wide batch that already is the lake's grid
        (``transforms.ingest.wide_batch``), continuing the batch before it on the grid: its rows
        become lake rows in one pass per column, and the state left for the next batch is the one
        :meth:`_feed_samples` leaves (the last row held, the row before it given). None, with
        nothing changed, for any other batch."""
        export, tags, grid = self.config.export, self.tags, self.grid
        P = grid.period_ns
        if export.layout != "wide" or P > grid.max_gap_ns or (self.clock is not None and self.clock.line is not None):
            return None
        try:
            b = gridded_columns(df, export, self.config.timezone, tags, P, self.now_ns, self.origin_ns)
        except IngestError:
            return None  # the general path names it
        if b is None or (self.clock is not None and b.t_ns[1] + self.clock.limit_ns < self.clock.latest_ns):
            return None
        t0, t1 = int(b.t_ns[1]), int(b.t_ns[-1])
        if not export.relative_time and not (final and self._batches == 1) and self.config.timezone != "UTC" and near_clock_change(t0, t1, self.config.timezone):
            return None
        tids = list(b.columns)
        by_valve: dict[str, dict[str, int]] = {}
        for tid in tids:
            by_valve.setdefault(tags.valve_ids[tid], {})[tags.signals[tid]] = tid
        if any(s not in signals for signals in by_valve.values() for s in REQUIRED_SIGNALS):
            return None
        first = self._continues(by_valve, t0 - P)
        if first is None:
            return None
        if self.clock is not None:
            self.clock.latest_ns = max(self.clock.latest_ns, t1)
        if first == 0:
            for tid in tids:
                b.columns[tid][0] = self._carry[tid].held_v[0]
        n = len(b.t_ns) - 1  # rows of the batch (slot 0: the held row of the batch before)
        stop = n + 1 if final else n  # the last row waits for the next batch, as a held sample
        c = self.counts
        c.rows_in += n
        c.samples_in += n * len(tids)
        for tid in tids:
            self._tag_samples[tid] += n
        self._present |= {tags.tags[tid] for tid in tids}
        if final:
            self._close()
        rows = stop - first
        c.accepted += rows * len(tids)
        self._span += [int(b.t_ns[first]), int(b.t_ns[stop - 1])]
        given = _DONE if final else int(b.t_us[stop - 1])
        self._carry.clear()
        frames = []
        for valve in self.config.valves:
            signals = by_valve.get(valve.id)
            if signals is None:
                continue
            frame = assemble_valve(valve.id, {s: Gridded(b.t_us[first:stop], b.columns[tid][first:stop], _NONE, _NONE) for s, tid in signals.items()})
            c.rows_out += frame.height
            frames.append(frame)
            self._valves[valve.id] = _ValveRows({}, dict.fromkeys(signals, given), given)
        if not final:
            for tid in tids:
                factor = tags.factors[tid]
                v_last, v_before = b.raw[tid][-1] * factor, b.raw[tid][-2] * factor
                self._carry[tid] = _TagCarry(t1, b.t_ns[-1:].copy(), np.array([v_last]), np.array([first_line + n - 1], dtype=np.int64), (int(b.t_ns[-2]), float(v_before)))
        return frames

    def _continues(self, by_valve: dict[str, dict[str, int]], held_ns: int) -> int | None:
        """Where a gridded batch's lake rows begin in its columns: 1 for a file's first batch (no
        state), 0 when every tag of the batch (and no other) holds one sample at ``held_ns``, one
        period before the batch, its row before that given (and it fits the lake), None else."""
        tids = {tid for signals in by_valve.values() for tid in signals.values()}
        if not self._carry and not self._valves:
            return 1
        if set(self._carry) != tids or set(self._valves) != set(by_valve):
            return None
        given = (held_ns - self.grid.period_ns) // 1000
        for tid in tids:
            h = self._carry[tid]
            if len(h.held_t) != 1 or h.last_ns != held_ns or h.anchor is None or h.anchor[0] != held_ns - self.grid.period_ns or not lake_value(float(h.held_v[0]), tid, self.tags):
                return None
        for vid, signals in by_valve.items():
            rows = self._valves[vid]
            if rows.pending or rows.given_to != given or rows.reached != dict.fromkeys(signals, given):
                return None
        return 0

    def _refuse_if_mostly_faulty(self) -> None:
        """Refuse the file (after its last batch, before anything is committed) when a tag's
        faults of one kind exceed ``export.max_bad_share`` of its samples, naming the first such
        sample and the likely cause."""
        export = self.config.export
        limit = export.max_bad_share
        share = self._faults / np.maximum(self._tag_samples, 1)[:, None]
        over = np.argwhere(share.T > limit)  # (fault, tag id), faults in FAULT_REASONS order
        if not len(over):
            return
        kind, tid = (int(x) for x in over[0])
        tag, signal = self.tags.tags[tid], self.tags.signals[tid]
        n, m = int(self._faults[tid, kind]), int(self._tag_samples[tid])
        reason = FAULT_REASONS[kind]
        if reason == "out_of_range":
            i = next(i for i, v in enumerate(self.config.valves) if v.id == self.tags.valve_ids[tid])
            what = "out of range"
            cause = f"a wrong unit? valves[{i}].tags.{signal}.unit is {self.config.valves[i].tags[signal].unit!r}"
        elif reason == "bad_timestamp":
            what = "without a readable timestamp"
            cause = f"a wrong export.timestamp_format? it is {export.timestamp_format!r}"
        elif reason == "field_count":
            what = "in rows whose field count is not the header's"
            cause = f"a separator missing or added in the rows, or a wrong export.separator? it is {export.separator!r}"
        else:
            what = "at implausible times"
            cause = "a recorder clock that is off, or a wrong plant.timezone or export.timestamp_format?"
        raise IngestError(
            f"{self._first_faults[(tid, kind)]}; {n:,} of {m:,} samples of tag {tag} in the file ({n / m:.1%}) are {what}, "
            f"more than export.max_bad_share = {limit:g}: {cause}"
        )

    def _tag(self, tid: int, t: np.ndarray, v: np.ndarray, lines, carry: _TagCarry | None, final: bool) -> None:
        """One tag's samples of this batch (after the held ones): resolve, grid, carry."""
        export, tags, c = self.config.export, self.tags, self.counts
        tag, valve_id, signal = tags.tags[tid], tags.valve_ids[tid], tags.signals[tid]
        held = None
        if not final and len(t):
            t_max = t.max()
            at_max = t == t_max
            idx_held = np.flatnonzero(at_max)
            held = _TagCarry(int(t_max), t[idx_held], v[idx_held], lines.at(idx_held), carry.anchor if carry else None)
            n = len(t) - len(idx_held)
            if idx_held[0] == n:  # the usual case: the latest samples come last
                t, v = t[:n], v[:n]
            else:
                keep = ~at_max
                t, v, lines = t[keep], v[keep], lines.only(keep)
        self._carry.pop(tid, None)
        if held is not None:
            self._carry[tid] = held
        rows = self._valves.setdefault(valve_id, _ValveRows())
        if len(t) == 0:
            self._reach(rows, signal, held)
            return
        series = prepare_tag(t, v, lines, export.duplicate_rule, tag)
        c.duplicates += series.duplicates
        c.conflicts += series.conflicts
        c.accepted += len(series.t_ns)
        self._span += [int(series.t_ns[0]), int(series.t_ns[-1])]
        anchor = carry.anchor if carry is not None else None
        t_ns, values = series.t_ns, series.values
        if anchor is not None:
            t_ns, values = np.concatenate(([anchor[0]], t_ns)), np.concatenate(([anchor[1]], values))
        if self._times is None or not self._times.same_times(t_ns):
            self._times = grid_times(t_ns, self.grid)
        g = to_grid(t_ns, values, self.grid, self._times)
        if anchor is not None:  # instants up to the anchor were given with the previous batch
            first = int(np.searchsorted(g.t_us, anchor[0] // 1000, side="right"))  # t_us * 1000 <= anchor ns
            g = Gridded(g.t_us[first:], g.values[first:], g.gap_start_ns, g.gap_end_ns)
        if held is not None:
            held.anchor = (int(series.t_ns[-1]), float(series.values[-1]))
        if len(g.gap_start_ns):
            n = len(g.gap_start_ns)
            c.gaps += n
            self.gaps.append(
                pl.DataFrame(
                    {
                        "valve_id": [valve_id] * n,
                        "signal": [signal] * n,
                        "tag": [tag] * n,
                        "gap_start": pl.Series(g.gap_start_ns // 1000).cast(pl.Datetime("us", "UTC")),
                        "gap_end": pl.Series(g.gap_end_ns // 1000).cast(pl.Datetime("us", "UTC")),
                        "duration_s": (g.gap_end_ns - g.gap_start_ns) / 1e9,
                    },
                    schema=GAP_COLUMNS,
                )
            )
        if len(g.t_us):
            if g.t_us[0] <= rows.given_to:
                raise NotStreamable(f"tag {tag}: samples behind lake rows already given")
            rows.pending.setdefault(signal, []).append((g.t_us, g.values))
        self._reach(rows, signal, held)

    @staticmethod
    def _reach(rows: _ValveRows, signal: str, held: _TagCarry | None) -> None:
        """How far the signal's grid instants are all known: later ones lie after its anchor (the
        last sample on the grid), or, before it has one, at or after its held samples."""
        if held is None:
            rows.reached[signal] = _DONE
        elif held.anchor is not None:
            rows.reached[signal] = held.anchor[0] // 1000
        else:
            rows.reached[signal] = (held.last_ns - 1) // 1000

    def _give(self, final: bool) -> list[pl.DataFrame]:
        """Lake rows up to where every signal of a valve has reached (all of them when final)."""
        frames = []
        for valve in self.config.valves:
            rows = self._valves.get(valve.id)
            if rows is None or not all(s in rows.reached for s in REQUIRED_SIGNALS):
                continue  # (final: every sample of a required signal was quarantined: no lake rows)
            upto = _DONE if final else min(rows.reached.values())
            if upto <= rows.given_to:
                continue
            signals = {}
            for s, parts in rows.pending.items():
                t = np.concatenate([p[0] for p in parts]) if len(parts) > 1 else parts[0][0]
                v = np.concatenate([p[1] for p in parts]) if len(parts) > 1 else parts[0][1]
                cut = int(np.searchsorted(t, upto, side="right"))
                signals[s] = Gridded(t[:cut], v[:cut], _NONE, _NONE)
                rows.pending[s] = [(t[cut:], v[cut:])] if cut < len(t) else []
            rows.pending = {s: p for s, p in rows.pending.items() if p}
            rows.given_to = upto
            if all(s in signals for s in REQUIRED_SIGNALS):
                frame = assemble_valve(valve.id, signals)
                if frame.height:
                    self.counts.rows_out += frame.height
                    frames.append(frame)
        return frames

    def given_to(self) -> dict[str, int]:
        """Valve → the instant (µs) up to which its lake rows were given: later rows come after it."""
        return {v: r.given_to for v, r in self._valves.items()}

    def quarantine_frame(self) -> pl.DataFrame:
        """The quarantined samples of the batches so far (:data:`QUARANTINE_COLUMNS`)."""
        return pl.concat(self.quarantine) if self.quarantine else empty_quarantine().select(QUARANTINE_COLUMNS)

    def gap_frame(self) -> pl.DataFrame:
        """The gaps found so far."""
        return pl.concat(self.gaps) if self.gaps else pl.DataFrame(schema=GAP_COLUMNS)
