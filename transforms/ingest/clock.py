"""Steps of a recorder's clock in a wide export (no I/O).

A recorder or a wide historian export writes its rows in time order. A row much earlier than a row
before it is then not data out of order but a clock that was set back (a time server's correction,
a wrong daylight-saving switch, a recorder reset): every row after the step carries a wrong time,
and sorting them in would store them, e.g., an hour early. :class:`ClockSteps` follows a file's
rows batch by batch and marks the rows from the first such step to the end of the file, which the
ingest quarantines (``clock_step``; ``docs/ingest.md``, "Clock steps"). The long layout is not
checked: its exports are legitimately grouped by tag or out of order, and are sorted.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime, timedelta, timezone

import numba
import numpy as np
import polars as pl

CLOCK_STEP_PERIODS = 4
"""A row more than this many sample periods earlier than the latest row before it is a clock step:
beyond any jitter of a recorder's time stamps (a time stamp is rounded to a period at most), far
below the seconds to hours a clock is set back by."""

_NONE = np.iinfo(np.int64).min


@numba.njit(cache=True, nogil=True)
def _first_step(t: np.ndarray, latest_ns: int, allowed_ns: int, limit_ns: int) -> tuple[int, int, int]:
    """One pass over a batch's row times (file order; :data:`_NONE`: unreadable): the first row
    more than ``limit_ns`` earlier than the latest readable, plausible (≤ ``allowed_ns``) time
    before it, counting ``latest_ns`` from earlier batches. Returns ``(row, the latest time
    before it, its time)``, or ``(-1, the latest time of all, 0)``."""
    before = latest_ns
    for i in range(len(t)):
        ti = t[i]
        if ti > allowed_ns:
            continue  # an implausible time neither steps nor moves the clock
        if ti != _NONE and ti + limit_ns < before:
            return i, before, ti
        if ti > before:
            before = ti
    return -1, before, 0


def _iso(t_ns: int) -> str:
    return (datetime(1970, 1, 1, tzinfo=timezone.utc) + timedelta(microseconds=t_ns // 1000)).isoformat().replace("+00:00", "Z")


@dataclass
class ClockSteps:
    """The clock of one wide export, followed row by row across its batches.

    Parameters
    ----------
    limit_ns : int
        A backward step longer than this is a clock step (:data:`CLOCK_STEP_PERIODS` periods). [ns]
    latest_ns_allowed : int
        Times after this are implausible (quarantined for it) and do not move the clock. [ns]
    """

    limit_ns: int
    latest_ns_allowed: int
    latest_ns: int = _NONE
    """The latest row time before the step (or so far)."""
    line: int | None = None
    """The file's line of the first row after the step (None: no step yet)."""
    step_to_ns: int = 0
    """That row's time."""

    @classmethod
    def for_grid(cls, sample_rate_hz: float, latest_ns_allowed: int) -> ClockSteps:
        return cls(round(CLOCK_STEP_PERIODS * 1e9 / sample_rate_hz), latest_ns_allowed)

    def after_step(self, t_ns: pl.Series, lines: pl.Series) -> pl.Series | None:
        """Rows of this batch (file order) at or after the file's first clock step (None: none).

        ``t_ns``: each row's time (UTC, ns; null for an unreadable one, which does not count)."""
        if self.line is not None:
            return pl.repeat(True, len(t_ns), eager=True)
        t = t_ns.cast(pl.Int64).fill_null(_NONE).to_numpy()
        i, before, t_i = _first_step(t, self.latest_ns, self.latest_ns_allowed, self.limit_ns)
        if i < 0:
            self.latest_ns = before
            return None
        self.latest_ns, self.line, self.step_to_ns = before, int(lines[i]), t_i
        mask = np.zeros(len(t), dtype=bool)
        mask[i:] = True
        return pl.Series(mask)

    def message(self, samples: int) -> str | None:
        """What the step was and what became of the rows after it (None: no step)."""
        if self.line is None:
            return None
        back = (self.latest_ns - self.step_to_ns) / 1e9
        return (
            f"line {self.line}: the clock steps back: time {_iso(self.step_to_ns)} after {_iso(self.latest_ns)} on an earlier line ({back:,.3f} s earlier); "
            f"{samples:,} samples from there to the end of the file are quarantined (clock_step); "
            f'export.clock_steps = "accept" takes the file\'s order as untrusted and sorts them in'
        )
