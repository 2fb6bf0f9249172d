"""The command line run as a user runs it, in a subprocess: several commands one after the other
through its entry point (``flows.cli.main``) in one process, each with its own exit status,
stdout and stderr (a process of its own per command costs ~0.4 CPU-s of start-up)."""

from __future__ import annotations

import json
import subprocess
import sys

_COMMANDS = """
import contextlib, io, json, sys
from flows.cli import main
done = []
for args in json.loads(sys.argv[1]):
    sys.argv, out, err, code = ["valvemon", *args], io.StringIO(), io.StringIO(), 0
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            main()
        except SystemExit as exc:
            code = exc.code
    done.append((code, out.getvalue(), err.getvalue()))
print(json.dumps(done))
"""


def run_each(commands: list[list[str]], env: dict[str, str]) -> list[tuple[int, str, str]]:
    """(exit status, stdout, stderr) of each of ``commands`` (argument lists after ``valvemon``)."""
    proc = subprocess.run([sys.executable, "-c", _COMMANDS, json.dumps(commands)], env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    return [tuple(r) for r in json.loads(proc.stdout)]
