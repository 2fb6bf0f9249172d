"""``valvemon query``'s options refuse what makes no sense, and CSV takes nested columns (issue 46,
minor items): ``--max-rows -1`` is refused in one line (it printed "first -1 shown"); a list or
struct column (the ``baselines`` table's) is written to CSV as JSON text, which reads back to the
same values (it failed with "unexpected ComputeError")."""

from __future__ import annotations

import io
import json

import polars as pl

from tests.ingest.conftest import run_cli
from tests.report.test_query_out import lake_wh  # noqa: F401 - the fixture


def test_negative_max_rows_is_refused(lake_wh, monkeypatch, capsys):  # noqa: F811
    code, out, err = run_cli(["query", "SELECT 1 AS a", "--warehouse", str(lake_wh), "--max-rows", "-1"], monkeypatch, capsys)
    assert code == 1 and out == "" and err == "valvemon: error: --max-rows: -1 is negative; expected the number of rows to show (0 or more)\n"
    code, out, _ = run_cli(["query", "SELECT 1 AS a", "--warehouse", str(lake_wh), "--max-rows", "0"], monkeypatch, capsys)
    assert code == 0 and "1 row(s), first 0 shown" in out


def test_nested_columns_as_json_text_in_csv(lake_wh, monkeypatch, capsys):  # noqa: F811
    sql = ("SELECT 1 AS n, [1.5, 2.0] AS l, {'edge': 's1', 'at': TIMESTAMPTZ '2025-01-01 00:00:00+00'} AS s "
           "UNION ALL SELECT 2, NULL, NULL ORDER BY n")  # fmt: skip
    code, out, err = run_cli(["query", sql, "--warehouse", str(lake_wh), "--format", "csv"], monkeypatch, capsys)
    assert code == 0, err
    back = pl.read_csv(io.StringIO(out))
    assert back.columns == ["n", "l", "s"] and back["n"].to_list() == [1, 2]
    assert json.loads(back["l"][0]) == [1.5, 2.0] and back["l"][1] is None
    assert json.loads(back["s"][0]) == {"edge": "s1", "at": "2025-01-01T00:00:00+00:00"} and back["s"][1] is None
