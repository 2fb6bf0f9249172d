"""Arrays as the compiled kernels take them: one kind of array per kernel argument.

numba compiles a kernel, and loads it from its cache, once for each kind of array it is given
(read-only or writable, float32 or float64): polars and Arrow hand their columns out as read-only
views and copies of them are writable. A clean clone's test suite compiled 15 CPU-s of such twins;
a command's start-up pays ~8 ms a load. The arrays a kernel only reads are therefore given to it
read-only."""

from __future__ import annotations

import numpy as np


def read_only(a: np.ndarray) -> np.ndarray:
    """``a`` as a read-only view (itself if it is one)."""
    if not a.flags.writeable:
        return a
    v = a.view()
    v.flags.writeable = False
    return v


def float_array(a) -> np.ndarray:
    """A contiguous float32 or float64 array as it is (the kernels compute in float64 either
    way, and a float32 lake column needs no conversion pass), anything else as float64; read-only
    (:func:`read_only`)."""
    a = np.asarray(a)
    if a.dtype in (np.float32, np.float64):
        return read_only(np.ascontiguousarray(a))
    return read_only(np.ascontiguousarray(a, dtype=np.float64))
