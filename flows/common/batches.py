"""Finished rows held in memory and written to the warehouse database together.

One DuckDB transaction costs ~20–40 ms whatever its size (``BENCHMARKS.md``, "Plant-day",
DAY-9), so a write per chunk, file or unit would be the serial part of a long run. What a
batch holds is lost in a crash before its write; its producers are all idempotent, so a rerun
redoes that work and nothing else.
"""

from __future__ import annotations

import time
from typing import Callable, Generic, TypeVar

T = TypeVar("T")

WRITE_BATCH_S = 5.0
"""The oldest waiting item is written at the latest this long after it arrived."""


class WriteBatch(Generic[T]):
    """Collects items and hands them to ``write(items)``: once ``max_items`` are waiting (if
    given), once the oldest has waited ``max_wait_s``, and on :meth:`flush`."""

    def __init__(self, write: Callable[[list[T]], None], *, max_items: int | None = None, max_wait_s: float = WRITE_BATCH_S):
        self.write, self.max_items, self.max_wait_s = write, max_items, max_wait_s
        self.pending: list[T] = []
        self.oldest = 0.0

    def add(self, item: T) -> None:
        if not self.pending:
            self.oldest = time.monotonic()
        self.pending.append(item)
        full = self.max_items is not None and len(self.pending) >= self.max_items
        if full or time.monotonic() - self.oldest >= self.max_wait_s:
            self.flush()

    def flush(self) -> None:
        """Write what is waiting (nothing if nothing is)."""
        if self.pending:
            batch, self.pending = self.pending, []
            self.write(batch)
