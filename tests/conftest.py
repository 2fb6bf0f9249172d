"""Shared test set-up: an isolated Prefect home, and a Prefect test server for flow tests."""

import fcntl
import os
import sys
import tempfile
from pathlib import Path

os.environ.setdefault("PREFECT_SERVER_ANALYTICS_ENABLED", "false")
os.environ.setdefault("PREFECT_HOME", tempfile.mkdtemp(prefix="valvemon-prefect-"))
os.environ.setdefault("PREFECT_LOGGING_TO_API_ENABLED", "false")

import pytest  # noqa: E402


@pytest.hookimpl(trylast=True)  # after pytest's own, which sets up the temporary folders
def pytest_configure(config):
    if os.environ.get("PYTEST_XDIST_WORKER"):
        one_compile_per_kernel(config._tmp_path_factory.getbasetemp().parent / "numba-locks")


def one_compile_per_kernel(locks: Path) -> None:
    """On a clean clone (no numba cache yet) both xdist workers reach the same kernels at about the
    same time and each compiled them (tests/model, transforms and archive: 72 CPU-s of compiling
    on two workers against 42 on one). Here a worker compiles a cached kernel under a lock file of
    that kernel shared by the workers; the other waits, then loads what the first wrote to numba's
    cache. numba's own (in-process) compiler lock is taken first, so threads queue as before; a
    kernel compiled inside another's compile (a callee) takes its own lock, and a lock this worker
    already holds is not taken again. Kernels without ``cache=True`` compile as before."""
    from numba.core.caching import NullCache
    from numba.core.compiler_lock import global_compiler_lock
    from numba.core.dispatcher import Dispatcher

    locks.mkdir(exist_ok=True)
    compile_, held = Dispatcher.compile, set()

    def compile(self, sig):
        with global_compiler_lock:
            key = f"{self.py_func.__module__}.{self.py_func.__qualname__}"
            if key in held or isinstance(self._cache, NullCache):
                return compile_(self, sig)
            with open(locks / key, "w") as fh:
                fcntl.flock(fh, fcntl.LOCK_EX)
                held.add(key)
                try:
                    return compile_(self, sig)
                finally:
                    held.discard(key)

    Dispatcher.compile = compile


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(items):
    """Every test that starts the Prefect API runs on one xdist worker (``--dist loadgroup``), so
    a run of the whole suite starts that server once, not once per worker. ``tryfirst``: xdist
    reads the group marks in its own hook of this name, which must see them."""
    for item in items:
        names = getattr(item, "fixturenames", ())
        callspec = getattr(item, "callspec", None)
        if "prefect_server" in names or (callspec is not None and callspec.params.get("prefect") is True):
            item.add_marker(pytest.mark.xdist_group("prefect"))
    # the end-to-end tests (tens of seconds each) first: xdist hands the tests out in this order
    # (after the groups, largest first), so a long one never starts last while the other worker idles
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)


@pytest.fixture(scope="session")
def prefect_server():
    """A temporary local Prefect API (SQLite) for tests that run real flows; ~15 s to start once."""
    from prefect.testing.utilities import prefect_test_harness

    with prefect_test_harness(server_startup_timeout=120):
        yield


def pytest_runtest_teardown(item):
    """Close Prefect's events client after each test that opened it. Left open, its websocket pings
    the test server every ~20 s from Prefect's event-loop thread and draws each ping's payload from
    the global ``random`` module; a Hypothesis test that a worker runs later then sees the state
    change mid-draw and warns "Do not use the `random` module inside strategies"."""
    worker = sys.modules.get("prefect.events.worker")
    if worker is not None:
        worker.EventsWorker.drain_all()  # returns at once when no client is open
