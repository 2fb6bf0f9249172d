"""flows/common/warehouse_db.py: the process's DuckDB host attaches the warehouse per unit of work."""

import subprocess
import sys
import threading
import time

import duckdb
import pytest

import flows.common.warehouse_db as wdb
from flows.common.errors import ValvemonError
from flows.common.warehouse_db import connect, db_path


def _other_process_opens(warehouse) -> bool:
    code = f"import duckdb; duckdb.connect({str(db_path(warehouse))!r}).close()"
    return subprocess.run([sys.executable, "-c", code], capture_output=True).returncode == 0


def test_the_file_is_locked_while_in_use_and_released_after(tmp_path):
    with connect(tmp_path) as con:
        con.execute("CREATE TABLE t (x INTEGER)")
        assert not _other_process_opens(tmp_path)  # attached read-write: the file is locked
        with connect(tmp_path) as inner:  # nested in the same thread: the same attachment
            inner.execute("INSERT INTO t VALUES (1)")
        assert con.execute("SELECT count(*) FROM t").fetchall() == [(1,)]
        assert not _other_process_opens(tmp_path)  # still in use by the outer unit of work
    assert wdb._HOST.attached == {}
    assert _other_process_opens(tmp_path)  # detached: checkpointed and unlocked
    plain = duckdb.connect(str(db_path(tmp_path)), read_only=True)
    try:
        assert plain.execute("SELECT x FROM t").fetchall() == [(1,)]
    finally:
        plain.close()


def test_threads_share_the_attachment(tmp_path):
    with connect(tmp_path) as con:
        con.execute("CREATE TABLE t (x INTEGER)")
    errors = []

    def write(k):
        try:
            for i in range(20):
                with connect(tmp_path) as c:
                    c.execute("INSERT INTO t VALUES (?)", [k * 100 + i])
        except Exception as exc:  # pragma: no cover - reported below
            errors.append(exc)

    threads = [threading.Thread(target=write, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    with connect(tmp_path, read_only=True) as con:
        assert con.execute("SELECT count(DISTINCT x) FROM t").fetchall() == [(80,)]


def test_read_write_waits_for_a_read_only_user_in_the_process(tmp_path):
    with connect(tmp_path) as con:
        con.execute("CREATE TABLE t (x INTEGER)")
    held = threading.Event()
    release = threading.Event()

    def reader():
        with connect(tmp_path, read_only=True) as con:
            con.execute("SELECT count(*) FROM t").fetchall()
            held.set()
            release.wait(10)

    t = threading.Thread(target=reader)
    t.start()
    held.wait(10)
    with pytest.raises(ValvemonError, match="open read-only in this process"):
        with connect(tmp_path, wait_s=0.2):
            pass
    threading.Timer(0.3, release.set).start()
    start = time.monotonic()
    with connect(tmp_path, wait_s=10) as con:  # gets it once the reader is done
        con.execute("INSERT INTO t VALUES (1)")
    assert time.monotonic() - start >= 0.2
    t.join()


def test_a_missing_file_read_only_is_a_clear_error(tmp_path):
    with pytest.raises(ValvemonError, match="cannot open the warehouse database"):
        with connect(tmp_path / "nowhere", read_only=True):
            pass


def test_transaction_commits_the_block_or_rolls_it_back(tmp_path):
    with connect(tmp_path) as con:
        con.execute("CREATE TABLE t (x INTEGER)")
        with wdb.transaction(con):
            con.execute("INSERT INTO t VALUES (1)")
        with pytest.raises(RuntimeError):
            with wdb.transaction(con):
                con.execute("INSERT INTO t VALUES (2)")
                raise RuntimeError("mid-way")
        assert con.execute("SELECT list(x) FROM t").fetchone()[0] == [1]
