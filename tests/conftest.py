"""Shared test set-up: an isolated Prefect home, and a Prefect test server for flow tests."""

import os
import sys
import tempfile

os.environ.setdefault("PREFECT_SERVER_ANALYTICS_ENABLED", "false")
os.environ.setdefault("PREFECT_HOME", tempfile.mkdtemp(prefix="valvemon-prefect-"))
os.environ.setdefault("PREFECT_LOGGING_TO_API_ENABLED", "false")

import pytest  # noqa: E402


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
