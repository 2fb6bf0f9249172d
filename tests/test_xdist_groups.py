"""The Prefect API's tests share one xdist worker under ``make test`` (``-n 3 --dist loadgroup``).

``tests/conftest.py`` marks every test that uses the ``prefect_server`` fixture with
``xdist_group("prefect")``, so the test API (~20 s to start) starts once per suite. That grouping
fails silently when pytest and xdist disagree on how a group is carried (pytest 9.2's node ids):
each worker then starts its own API. This test runs a small suite with the same hook and checks
where its tests ran.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CONFTEST = """
import pytest
from tests.conftest import pytest_collection_modifyitems  # the hook under test

@pytest.fixture
def prefect_server():
    yield
"""

MODULE = """
import os
from pathlib import Path

def _record(name):
    Path(os.environ["GROUPS_OUT"], name).write_text(os.environ["PYTEST_XDIST_WORKER"])

def test_api_{i}(prefect_server):
    _record("api_{i}")

def test_plain_{i}():
    _record("plain_{i}")
"""


def test_prefect_tests_share_one_worker(tmp_path):
    suite, out = tmp_path / "suite", tmp_path / "out"
    suite.mkdir()
    out.mkdir()
    (suite / "conftest.py").write_text(CONFTEST)
    for i in range(6):
        (suite / f"test_m{i}.py").write_text(MODULE.format(i=i))
    env = {**os.environ, "PYTEST_DISABLE_PLUGIN_AUTOLOAD": "1", "GROUPS_OUT": str(out), "PYTHONPATH": str(ROOT)}
    done = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "xdist.plugin", "-n", "2", "--dist", "loadgroup", "-p", "no:cacheprovider", "--rootdir", str(suite), str(suite)],
        cwd=suite, env=env, capture_output=True, text=True, timeout=120,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    workers = {p.name: p.read_text() for p in out.iterdir()}
    assert len(workers) == 12
    api = {w for name, w in workers.items() if name.startswith("api_")}
    assert len(api) == 1, f"the Prefect API's tests ran on {sorted(api)}: {workers}"
    # the plain tests still spread over both workers (the group does not serialise the suite)
    assert set(workers.values()) == {"gw0", "gw1"}
