"""`valvemon` failures are one line on stderr with a non-zero exit status, whatever failed:
usage errors (2), the known errors (1), the file system (1), and anything unforeseen (1, with
the traceback only on request)."""

from __future__ import annotations

import sys

import pytest

import flows.report.query
from flows.cli import TRACEBACK_ENV, main


def _run(args: list[str], monkeypatch, capsys) -> tuple[int, str, str]:
    monkeypatch.setattr(sys, "argv", ["valvemon", *args])
    with pytest.raises(SystemExit) as exit_:
        main()
    out = capsys.readouterr()
    return exit_.value.code, out.out, out.err


@pytest.mark.parametrize(
    "args, expected",
    [
        (["monitor"], "valvemon: error: Missing parameter: config (see 'valvemon monitor --help')\n"),
        (["query", "select 1", "--bogus"], "valvemon: error: No such option: --bogus (see 'valvemon query --help')\n"),
        (["nosuchcommand"], "valvemon: error: No such command 'nosuchcommand'. (see 'valvemon --help')\n"),
    ],
)
def test_usage_errors_are_one_line_with_status_2(args, expected, monkeypatch, capsys):
    code, out, err = _run(args, monkeypatch, capsys)
    assert (code, out, err) == (2, "", expected)


def test_help_exits_0(monkeypatch, capsys):
    code, out, err = _run(["query", "--help"], monkeypatch, capsys)
    assert code == 0 and out.startswith("Usage: valvemon query") and err == ""


def test_a_missing_file_is_one_line(tmp_path, monkeypatch, capsys):
    code, _, err = _run(["monitor", "--config", str(tmp_path / "nope.toml"), "--warehouse", str(tmp_path)], monkeypatch, capsys)
    assert code == 1 and err == f"valvemon: error: {tmp_path / 'nope.toml'}: no such configuration file\n"


def _raise(exc):
    def run_query(*a, **k):
        raise exc

    return run_query


def test_a_file_system_error_is_one_line(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(flows.report.query, "run_query", _raise(PermissionError(13, "Permission denied", "/data/wh/snapshot")))
    code, _, err = _run(["query", "select 1", "--warehouse", str(tmp_path)], monkeypatch, capsys)
    assert code == 1 and err == "valvemon: error: /data/wh/snapshot: Permission denied\n"


def test_an_unforeseen_failure_is_one_line_and_its_traceback_on_request(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(flows.report.query, "run_query", _raise(TypeError("bad operand\nsecond line")))
    code, out, err = _run(["query", "select 1", "--warehouse", str(tmp_path)], monkeypatch, capsys)
    assert code == 1 and out == ""
    assert err == f"valvemon: error: unexpected TypeError: bad operand (set {TRACEBACK_ENV}=1 for the traceback)\n"
    monkeypatch.setenv(TRACEBACK_ENV, "1")
    monkeypatch.setattr(sys, "argv", ["valvemon", "query", "select 1", "--warehouse", str(tmp_path)])
    with pytest.raises(TypeError, match="bad operand"):
        main()
