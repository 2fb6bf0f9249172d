"""The installed `valvemon` command (`flows.cli:console`) ends a successful command without the
interpreter's teardown, with its exit status and all its output; a failure, and a command that
leaves a thread running, exit as `flows.cli.main` does."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import tomllib
from pathlib import Path

import duckdb
import pytest

ROOT = Path(__file__).resolve().parents[1]

# a module global that an ordinary exit's teardown finalizes, an exit handler, and optionally a
# thread (not a daemon) that is still running when the command returns
_SCRIPT = textwrap.dedent("""
    import atexit, sys, threading, time

    class Teardown:
        def __del__(self):
            print("finalized", file=sys.stderr)

    kept = Teardown()
    atexit.register(lambda: print("exit handler", file=sys.stderr))
    entry, thread, *args = sys.argv[1:]
    import flows.cli

    if thread == "thread":  # still running for 0.3 s after the command returned
        returned = threading.Event()
        threading.Thread(target=lambda: (returned.wait(), time.sleep(0.3), print("thread ended", file=sys.stderr))).start()
        command = flows.cli.main

        def main():
            try:
                command()
            finally:
                returned.set()

        flows.cli.main = main
    sys.argv = ["valvemon", *args]
    getattr(flows.cli, entry)()
""")

ROWS = 1000
"""Rows printed (4.9 kB: less than standard output's buffer on a pipe, so they reach the pipe
only when it is flushed)."""


def _run(entry: str, args: list[str], tmp_path: Path, thread: bool = False) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if not k.startswith("PREFECT_API") and k != "PYTHONUNBUFFERED"}  # buffered, as usual
    env |= {"PYTHONPATH": str(ROOT), "PREFECT_HOME": str(tmp_path / "prefect-home")}
    cmd = [sys.executable, "-c", _SCRIPT, entry, "thread" if thread else "-", *args]
    return subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=120)


@pytest.fixture
def warehouse(tmp_path: Path) -> Path:
    snapshot = tmp_path / "wh" / "snapshot"
    snapshot.mkdir(parents=True)
    duckdb.connect(str(snapshot / "valvemon.duckdb")).close()
    return tmp_path / "wh"


def test_the_installed_command_is_console():
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert scripts == {"valvemon": "flows.cli:console"}


@pytest.mark.parametrize("entry, torn_down", [("console", False), ("main", True)])
def test_success_exits_0_with_all_its_output(entry, torn_down, warehouse, tmp_path):
    """`console` skips the teardown (the global is never finalized), `main` does not; both run
    the exit handlers and write every row."""
    sql = f"SELECT range AS n FROM range({ROWS})"
    r = _run(entry, ["query", sql, "--format", "csv", "--warehouse", str(warehouse)], tmp_path)
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert lines[0] == "n" and lines[1:] == [str(i) for i in range(ROWS)]
    assert "exit handler" in r.stderr.splitlines()
    assert ("finalized" in r.stderr.splitlines()) == torn_down, r.stderr


@pytest.mark.parametrize(
    "args, code, message",
    [
        (["query", "SELECT * FROM no_such_table"], 1, "valvemon: error: "),
        (["query", "SELECT 1", "--bogus"], 2, "valvemon: error: No such option: --bogus"),
    ],
)
def test_a_failure_exits_as_main_does(args, code, message, warehouse, tmp_path):
    """One line on stderr, the status, and the ordinary exit (teardown included)."""
    r = _run("console", [*args, "--warehouse", str(warehouse)], tmp_path)
    assert r.returncode == code
    errors = [line for line in r.stderr.splitlines() if line.startswith("valvemon:")]
    assert len(errors) == 1 and errors[0].startswith(message), r.stderr
    assert "finalized" in r.stderr.splitlines()


def test_a_running_thread_is_waited_for(warehouse, tmp_path):
    """A thread that is not a daemon still running when the command returns: the ordinary exit,
    which waits for it."""
    r = _run("console", ["query", "SELECT 1 AS n", "--format", "csv", "--warehouse", str(warehouse)], tmp_path, thread=True)
    assert r.returncode == 0 and r.stdout.split() == ["n", "1"]
    assert "thread ended" in r.stderr.splitlines() and "finalized" in r.stderr.splitlines()
