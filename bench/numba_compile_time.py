"""A pytest plugin: the CPU each test process spends compiling numba kernels (BENCHMARKS LAT-12).

    PYTHONPATH=bench VALVEMON_COMPILE_OUT=DIR .venv/bin/python -m pytest -p numba_compile_time -n 2 -q

Each process (the controller and every xdist worker) writes ``DIR/compile_<worker>.json``: the
seconds spent in numba's compiler, each kernel's own share (its callees' compiles taken out) and
the process's CPU seconds. Run it on a clean clone once without the set-up's kernel compile
(``find flows transforms model schemas -name '*.nb[ic]' -delete``) and once after ``make setup``.
"""

from __future__ import annotations

import collections
import json
import os
import time
from pathlib import Path

from numba.core import event

_RECORDER = event.RecordingListener()
event.register("numba:compile", _RECORDER)
_CPU0 = time.process_time()


def _own_seconds(buffer) -> collections.Counter:
    """Seconds per kernel between its compile's start and end events, less its nested compiles."""
    own: collections.Counter = collections.Counter()
    stack: list[list] = []
    for ts, ev in buffer:
        fn = ev.data["dispatcher"].py_func
        if ev.is_start:
            stack.append([f"{fn.__module__}.{fn.__qualname__}", ts, 0.0])
            continue
        name, t0, nested = stack.pop()
        own[name] += ts - t0 - nested
        if stack:
            stack[-1][2] += ts - t0
    return own


def pytest_sessionfinish(session) -> None:
    out = Path(os.environ.get("VALVEMON_COMPILE_OUT", "."))
    out.mkdir(parents=True, exist_ok=True)
    own = _own_seconds(_RECORDER.buffer)
    worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
    (out / f"compile_{worker}.json").write_text(json.dumps({
        "worker": worker, "compile_s": sum(own.values()), "cpu_s": time.process_time() - _CPU0, "kernels": own.most_common(),
    }, indent=1))
