"""Keep freed heap memory in the process for the next chunk's arrays (glibc only).

Used by monitoring, the ingest, the backfill and the report's standstill check. Monitoring runs its compiled kernels chunk
after chunk (a valve-week, ~1.7 M rows), and each chunk allocates the same ~100 bytes per row
of temporary arrays again (Savitzky–Golay values, selection codes, points). glibc serves
allocations above its mmap threshold (at most 32 MB, adapted upwards as blocks are freed) with
fresh ``mmap`` pages and unmaps them on ``free``, so each chunk pays one page fault per 4 KiB it
touches: ~22 % of steps 2–4b (measured with BENCHMARKS.md's MON-3). :func:`retain_freed_memory` raises
the mmap and trim thresholds (``mallopt``), so large blocks come from the heap and stay there
after ``free``, ready for the next chunk.

The price: the process keeps its high-water mark of heap memory until it exits, which a batch
run (``valvemon monitor``, a backfill worker) reaches anyway. polars allocates with its own
allocator (jemalloc), which :func:`retain_polars_memory` asks the same before polars is imported
(the ``valvemon monitor``, ``ingest`` and ``report`` commands do). Elsewhere than on glibc :func:`retain_freed_memory` does
nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import sys

_M_TRIM_THRESHOLD = -1
_M_TOP_PAD = -2
_M_MMAP_THRESHOLD = -3

MMAP_THRESHOLD_BYTES = 1 << 30
"""Blocks below 1 GiB come from the heap."""
TRIM_THRESHOLD_BYTES = (1 << 31) - 1
"""Free heap memory is returned to the system only above 2 GiB."""
TOP_PAD_BYTES = 64 << 20
"""The heap grows 64 MiB at a time."""

POLARS_ALLOCATOR_CONF = "dirty_decay_ms:-1,muzzy_decay_ms:-1"
"""polars' allocator (jemalloc, configured by ``_RJEM_MALLOC_CONF``) keeping freed pages: without
it each chunk's decoded columns come on fresh pages (one page fault per 4 KiB; on a valve-day of
continuous recording ~3.5 of the monitor's 16 CPU s went to the kernel, measured as
BENCHMARKS.md's MON-1)."""


def retain_polars_memory() -> bool:
    """Make polars keep its freed memory for the next chunk (:data:`POLARS_ALLOCATOR_CONF`, unless
    the environment sets its own). It takes effect only before polars is imported (jemalloc reads
    its configuration once); True if it will. Like :func:`retain_freed_memory`, the process
    then keeps its high-water mark until it exits."""
    if "polars" in sys.modules:
        return False
    os.environ.setdefault("_RJEM_MALLOC_CONF", POLARS_ALLOCATOR_CONF)
    return True


_done: bool | None = None


def retain_freed_memory() -> bool:
    """Apply the settings once per process; True if the C library took them."""
    global _done
    if _done is None:
        _done = False
        if sys.platform.startswith("linux"):
            try:
                libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
                mallopt = libc.mallopt
            except (OSError, AttributeError):  # not glibc (musl has no mallopt)
                return False
            mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
            mallopt.restype = ctypes.c_int
            _done = all(
                mallopt(option, value) == 1
                for option, value in (
                    (_M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES),
                    (_M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES),
                    (_M_TOP_PAD, TOP_PAD_BYTES),
                )
            )
    return _done
