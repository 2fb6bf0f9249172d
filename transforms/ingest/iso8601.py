"""A compiled reader for the common shape of ISO-8601 text: ``YYYY-MM-DD[T ]hh:mm:ss[.f…]`` with
an optional offset (``Z``, ``±hh``, ``±hhmm``, ``±hh:mm``), 1 to 9 fractional digits.

It reads a whole column straight from its Arrow buffers (offsets and bytes), about ten times
faster than Arrow's own cast, and gives up — the caller then takes the general path
(:func:`transforms.ingest.timestamps.parse_timestamps`, Arrow's parser and the format
candidates) — at the first element it does not recognise or is not sure of: another shape,
blanks around the text, an impossible date or time (month 13, 31 April, 29 February of a
common year, hour 24, second 60), an offset with minutes ≥ 60 or hours ≥ 24, a year outside
1678–2261 (the ns range), a mix of zoned and naive text. What it accepts it reads exactly as
Arrow does (``tests/ingest/test_iso8601.py`` compares them), so the fast path changes no result.
"""

from __future__ import annotations

import numba
import numpy as np
import pyarrow as pa

_NS_PER_S = 1_000_000_000


@numba.njit(cache=True, nogil=True)
def _days_from_civil(y: int, m: int, d: int) -> int:
    """Days since 1970-01-01 of a proleptic Gregorian date (H. Hinnant's algorithm)."""
    if m <= 2:
        y -= 1
    era = (y if y >= 0 else y - 399) // 400
    yoe = y - era * 400
    mp = m + 9 if m <= 2 else m - 3
    doy = (153 * mp + 2) // 5 + d - 1
    doe = yoe * 365 + yoe // 4 - yoe // 100 + doy
    return era * 146097 + doe - 719468


@numba.njit(cache=True, nogil=True)
def _digits(data, a: int, k: int) -> int:
    """The number written by ``k`` ASCII digits at ``data[a:]``; -1 if one is no digit."""
    v = 0
    for j in range(a, a + k):
        c = data[j] - 48
        if c < 0 or c > 9:
            return -1
        v = v * 10 + c
    return v


@numba.njit(cache=True, nogil=True)
def _parse_column(offsets, data, valid, zoned: bool, out) -> int:
    """Parse every valid element into ``out`` (int64 ns); the index of the first element it
    does not accept, or -1 when all were read."""
    n = len(out)
    prev = -1  # start of the last element whose date and time (to the second) were read
    base = 0  # those as seconds since the epoch
    for i in range(n):
        if not valid[i]:
            out[i] = 0
            continue
        a = offsets[i]
        e = offsets[i + 1]
        if e - a < 19:
            return i
        same = prev >= 0
        if same:  # consecutive rows often share the second: compare, latest digit first
            for j in range(18, -1, -1):
                if data[a + j] != data[prev + j]:
                    same = False
                    break
        if not same:
            if data[a + 4] != 45 or data[a + 7] != 45 or data[a + 13] != 58 or data[a + 16] != 58:  # - - : :
                return i
            sep = data[a + 10]
            if sep != 84 and sep != 32:  # 'T' or ' '
                return i
            y = _digits(data, a, 4)
            mo = _digits(data, a + 5, 2)
            d = _digits(data, a + 8, 2)
            h = _digits(data, a + 11, 2)
            mi = _digits(data, a + 14, 2)
            s = _digits(data, a + 17, 2)
            if y < 1678 or y > 2261 or mo < 1 or mo > 12 or d < 1 or h < 0 or h > 23 or mi < 0 or mi > 59 or s < 0 or s > 59:
                return i
            if mo == 2:
                leap = (y % 4 == 0 and y % 100 != 0) or y % 400 == 0
                dim = 29 if leap else 28
            elif mo == 4 or mo == 6 or mo == 9 or mo == 11:
                dim = 30
            else:
                dim = 31
            if d > dim:
                return i
            base = _days_from_civil(y, mo, d) * 86400 + h * 3600 + mi * 60 + s
            prev = a
        p = a + 19
        frac = 0
        if p < e and data[p] == 46:  # '.'
            p += 1
            k = 0
            while p < e and k < 10:
                c = data[p] - 48
                if c < 0 or c > 9:
                    break
                frac = frac * 10 + c
                k += 1
                p += 1
            if k == 0 or k > 9:
                return i
            for _ in range(9 - k):
                frac *= 10
        off_s = 0
        if p < e:
            if not zoned:
                return i
            c = data[p]
            if c == 90:  # 'Z'
                p += 1
            elif c == 43 or c == 45:  # '+' '-'
                sign = 1 if c == 43 else -1
                p += 1
                rest = e - p
                if rest == 2:
                    oh = _digits(data, p, 2)
                    om = 0
                elif rest == 4:
                    oh = _digits(data, p, 2)
                    om = _digits(data, p + 2, 2)
                elif rest == 5 and data[p + 2] == 58:
                    oh = _digits(data, p, 2)
                    om = _digits(data, p + 3, 2)
                else:
                    return i
                if oh < 0 or om < 0 or oh > 23 or om > 59:
                    return i
                off_s = sign * (oh * 3600 + om * 60)
                p = e
            else:
                return i
            if p != e:
                return i
        elif zoned:
            return i
        out[i] = (base - off_s) * _NS_PER_S + frac
    return -1


def parse_iso_column(arr: pa.Array | pa.ChunkedArray, *, zoned: bool) -> pa.Array | None:
    """Text → ``timestamp[ns, UTC]`` (``zoned``, every element with an offset) or naive
    ``timestamp[ns]`` (no element with an offset); None when an element is not of the accepted
    shape (module doc). Nulls stay null."""
    if isinstance(arr, pa.ChunkedArray):
        arr = arr.combine_chunks() if arr.num_chunks != 1 else arr.chunk(0)
    if arr.type == pa.string():
        arr = arr.cast(pa.large_string())
    elif arr.type != pa.large_string():
        return None
    n = len(arr)
    validity, offsets_buf, data_buf = arr.buffers()
    offsets = np.frombuffer(offsets_buf, dtype=np.int64, count=n + 1, offset=arr.offset * 8)
    data = np.frombuffer(data_buf, dtype=np.uint8) if data_buf is not None and data_buf.size else np.zeros(1, dtype=np.uint8)
    valid = np.ones(n, dtype=np.bool_) if arr.null_count == 0 else arr.is_valid().to_numpy(zero_copy_only=False)
    out = np.empty(n, dtype=np.int64)
    if _parse_column(offsets, data, valid, zoned, out) != -1:
        return None
    mask = None if arr.null_count == 0 else ~valid
    return pa.array(out, type=pa.timestamp("ns", "UTC" if zoned else None), mask=mask)
