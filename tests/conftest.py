"""Shared test set-up: an isolated Prefect home, and a Prefect test server for flow tests."""

import os
import tempfile

os.environ.setdefault("PREFECT_SERVER_ANALYTICS_ENABLED", "false")
os.environ.setdefault("PREFECT_HOME", tempfile.mkdtemp(prefix="valvemon-prefect-"))
os.environ.setdefault("PREFECT_LOGGING_TO_API_ENABLED", "false")

import pytest  # noqa: E402


@pytest.fixture(scope="session")
def prefect_server():
    """A temporary local Prefect API (SQLite) for tests that run real flows; ~15 s to start once."""
    from prefect.testing.utilities import prefect_test_harness

    with prefect_test_harness(server_startup_timeout=120):
        yield
