"""Issue 18, the ingest rows: sample-level faults quarantined, a file refused above
``export.max_bad_share``, tags of other equipment read past, and the bad
inputs that must keep failing cleanly. Each test starts from a warehouse holding one clean
window (``base_long.csv``) and asserts the lake and the ledger (``ingest_manifest``,
``quarantine``) before and after.
"""

from __future__ import annotations

import gzip
import tomllib
from datetime import datetime, timedelta, timezone
from pathlib import Path

import numpy as np
import polars as pl
import pytest
import tomli_w
from polars.testing import assert_frame_equal

import flows.ingest.formats
from flows.common.errors import ValvemonError
from flows.ingest.flow import ingest_lock
from tests.ingest.conftest import BASE, DATA, FACTOR, base_lake, ingest, lake, run_cli, table

T1 = datetime(2025, 3, 2, 0, 0, 0, tzinfo=timezone.utc)
SECONDS = 334
"""A generated export: 334 s × 6 tags = 2,004 long rows (the issue's "2,000 rows")."""
TAGS = {s: f"MILL1.V017.{t}" for s, t in {"ps": "PS", "pr": "PR", "p1": "P1", "p2": "P2", "x_spool": "XS", "x_cyl": "XC"}.items()}


def _value(signal: str, i: int) -> float:
    return BASE[signal][i % 5] + 0.25 * (i % 7)


def _iso(t: datetime) -> str:
    return t.isoformat().replace("+00:00", "Z")


def long_rows(seconds: int = SECONDS, start: datetime = T1, edit=None, extra=None) -> list[list[str]]:
    """Rows ``timestamp, tag, value, quality`` (time-major); ``edit(i, signal, row)`` may change a
    row, ``extra(i)`` add rows after second ``i``'s."""
    rows = []
    for i in range(seconds):
        t = _iso(start + timedelta(seconds=i))
        for s, tag in TAGS.items():
            row = [t, tag, repr(_value(s, i)), "Good"]
            if edit is not None:
                edit(i, s, row)
            rows.append(row)
        if extra is not None:
            rows += extra(i, t)
    return rows


def write_csv(path: Path, rows: list[list[str]], header: str = "timestamp,tag,value,quality") -> Path:
    path.write_text(header + "\n" + "".join(",".join(r) + "\n" for r in rows))
    return path


def line_of(second: int, signal: str) -> int:
    """The file line of a signal's row at a second (header = line 1) of :func:`long_rows`."""
    return 2 + 6 * second + list(TAGS).index(signal)


def ledger(wh: Path) -> tuple[pl.DataFrame, pl.DataFrame]:
    """The ingest's ledger without its clock columns: manifest and quarantine, sorted."""
    manifest = table(wh, "ingest_manifest").drop("ingested_at", "run_id").sort("file_hash")
    quarantine = table(wh, "quarantine").drop("ingested_at", "run_id").sort("file_hash", "line")
    return manifest, quarantine


@pytest.fixture
def warehouse(plant, tmp_path):
    """``warehouse(**export) -> (config, wh)``: a warehouse holding the clean window of ``base_long.csv``."""

    def make(units: dict[str, str] | None = None, **export):
        wh = tmp_path / "wh"
        ingest(plant()[0], DATA / "base_long.csv", wh)
        assert_frame_equal(lake(wh), base_lake())
        return plant("test.toml", units=units, **export)[0], wh

    return make


def refused(cfg: Path, path: Path, wh: Path) -> str:
    """Ingest a file that must be refused: its one-line message; the lake and ledger unchanged."""
    before, ledger_before = lake(wh), ledger(wh)
    with pytest.raises(ValvemonError) as err:
        ingest(cfg, path, wh)
    assert_frame_equal(lake(wh), before)
    for a, b in zip(ledger(wh), ledger_before):
        assert_frame_equal(a, b)
    assert not list((wh / "lake").rglob("*.tmp"))
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith(f"{path}: ")
    return msg


def new_day(wh: Path) -> pl.DataFrame:
    return lake(wh).filter(pl.col("date") == T1.date())


def file_row(wh: Path, path: Path) -> dict:
    return table(wh, "ingest_manifest").filter(pl.col("source_file") == str(path)).row(0, named=True)


def small_batches(monkeypatch, block_bytes: int = 4096) -> None:
    """Make the streamed ingest read CSV in blocks of ``block_bytes`` (~80 long rows)."""
    monkeypatch.setattr(flows.ingest.formats, "CSV_BLOCK_BYTES", block_bytes)


# --- one sample faulted in 2,000 rows: quarantined, the rest ingested --------------------------


@pytest.mark.parametrize(
    "edit, reason, raw",
    [
        (lambda row: row.__setitem__(2, "1e308"), "out_of_range", "1e+308"),  # the value as read
        (lambda row: row.__setitem__(0, "2025-03-02 noon"), "bad_timestamp", "2025-03-02 noon"),
        (lambda row: row.__setitem__(0, "2099-03-02T00:01:40Z"), "implausible_time", "2099-03-02T00:01:40Z"),
        (lambda row: row.__setitem__(0, "2025-02-28T00:01:40Z"), "implausible_time", "2025-02-28T00:01:40Z"),
    ],
    ids=["1e308", "unreadable-time", "year-2099", "before-commissioning"],
)
def test_one_faulty_sample_in_2000_rows_is_quarantined_with_its_line(warehouse, tmp_path, monkeypatch, edit, reason, raw):
    """Today the whole file is refused (1e308, an unreadable time) or a 2099 partition is
    written silently; now that one sample is quarantined and the rest reaches the lake."""
    cfg, wh = warehouse()
    small_batches(monkeypatch)
    path = write_csv(tmp_path / "one.csv", long_rows(edit=lambda i, s, row: edit(row) if (i, s) == (100, "ps") else None))
    old_lake, (old_manifest, _) = lake(wh), ledger(wh)
    ingest(cfg, path, wh)
    assert_frame_equal(lake(wh).filter(pl.col("date") != T1.date()), old_lake)  # the clean window untouched
    day = new_day(wh)
    assert day.height == SECONDS and day["timestamp_utc"].min() == T1
    assert lake(wh)["date"].max() == T1.date()  # no 2099 partition
    ps = dict(zip(day["timestamp_utc"].to_list(), day["ps_pa"].to_list()))
    at = T1 + timedelta(seconds=100)
    mid = (_value("ps", 99) + _value("ps", 101)) / 2 * FACTOR["ps"]  # the grid interpolates across the missing sample
    assert ps[at] == pytest.approx(mid, rel=1e-6)
    row = file_row(wh, path)
    assert (row["samples_in"], row["quarantined"], row[reason]) == (6 * SECONDS, 1, 1)
    assert sum(row[r] for r in ("out_of_range", "bad_timestamp", "implausible_time")) == 1
    q = table(wh, "quarantine").filter(pl.col("source_file") == str(path))
    assert q.select("line", "tag", "timestamp_raw" if reason != "out_of_range" else "value_raw", "reason").rows() == [
        (line_of(100, "ps"), TAGS["ps"], raw, reason)
    ]
    assert table(wh, "ingest_manifest").height == old_manifest.height + 1


def test_one_faulty_sample_in_a_wide_parquet_file(warehouse, tmp_path, plant):
    """The wide layout and Parquet: a 1e308 cell is one sample quarantined, its row's other cells stay."""
    _, wh = warehouse()
    cfg, _ = plant(name="wide.toml", layout="wide", tag_column=None, value_column=None, quality_column=None, good_quality=None)
    times = [T1 + timedelta(seconds=i) for i in range(SECONDS)]
    data = {"timestamp": times} | {tag: [_value(s, i) for i in range(SECONDS)] for s, tag in TAGS.items()}
    data[TAGS["x_cyl"]][7] = 1e308
    path = tmp_path / "wide.parquet"
    pl.DataFrame(data).write_parquet(path)
    ingest(cfg, path, wh)
    row = file_row(wh, path)
    assert (row["samples_in"], row["quarantined"], row["out_of_range"], row["rows_out"]) == (6 * SECONDS, 1, 1, SECONDS)
    q = table(wh, "quarantine").filter(pl.col("source_file") == str(path))
    assert q.select("line", "tag", "reason").rows() == [(8, TAGS["x_cyl"], "out_of_range")]
    assert new_day(wh)["ps_pa"][7] == pytest.approx(_value("ps", 7) * 1e5)


def test_an_unreadable_time_in_a_wide_csv_quarantines_the_samples_of_its_row(warehouse, tmp_path, plant):
    _, wh = warehouse()
    cfg, _ = plant(name="wide.toml", layout="wide", tag_column=None, value_column=None, quality_column=None, good_quality=None)
    lines = ["timestamp," + ",".join(TAGS.values())]
    for i in range(SECONDS):
        t = "02.03.2025 00:00:11" if i == 11 else _iso(T1 + timedelta(seconds=i))
        lines.append(t + "," + ",".join(repr(_value(s, i)) for s in TAGS))
    path = tmp_path / "wide.csv"
    path.write_text("\n".join(lines) + "\n")
    ingest(cfg, path, wh)
    row = file_row(wh, path)
    assert (row["samples_in"], row["quarantined"], row["bad_timestamp"], row["rows_out"]) == (6 * SECONDS, 6, 6, SECONDS)
    q = table(wh, "quarantine").filter(pl.col("source_file") == str(path)).sort("tag")
    assert q.select("line", "timestamp_raw", "reason").unique().rows() == [(13, "02.03.2025 00:00:11", "bad_timestamp")]
    assert sorted(q["tag"].to_list()) == sorted(TAGS.values())


# --- mostly faulty: refused, naming the likely cause -------------------------------------------


def test_a_signal_mostly_out_of_range_is_refused_with_todays_message_and_the_unit(warehouse, tmp_path):
    """The TOML says MPa where the file is in bar: every supply pressure is out of range."""
    cfg, wh = warehouse(units={"ps": "MPa"})
    path = write_csv(tmp_path / "mpa.csv", long_rows())
    msg = refused(cfg, path, wh)
    assert msg.startswith(f"{path}: tag MILL1.V017.PS: valve V017, column ps_pa at 2025-03-02T00:00:00Z: value 210000000.0 fails check 'ps_pa <= 6e+07 Pa' (line 2)")
    assert msg.endswith(f"{SECONDS} of {SECONDS} samples of tag MILL1.V017.PS in the file (100.0%) are out of range, more than export.max_bad_share = 0.05: a wrong unit? valves[0].tags.ps.unit is 'MPa'")


def test_timestamps_mostly_unreadable_are_refused_naming_the_format(warehouse, tmp_path):
    cfg, wh = warehouse(timestamp_format="%d.%m.%Y %H:%M:%S")
    path = write_csv(tmp_path / "iso.csv", long_rows())
    msg = refused(cfg, path, wh)
    assert msg.startswith(f"{path}: line 2: tag MILL1.V017.PS: timestamp '2025-03-02T00:00:00Z' does not match export.timestamp_format '%d.%m.%Y %H:%M:%S'")
    assert msg.endswith("are without a readable timestamp, more than export.max_bad_share = 0.05: a wrong export.timestamp_format? it is '%d.%m.%Y %H:%M:%S'")


def test_a_recorder_clock_in_2099_is_refused_and_writes_no_2099_partition(warehouse, tmp_path):
    """Today: ingested silently into 2099 partitions."""
    cfg, wh = warehouse()
    path = write_csv(tmp_path / "2099.csv", long_rows(start=datetime(2099, 3, 2, tzinfo=timezone.utc)))
    msg = refused(cfg, path, wh)
    assert msg.startswith(f"{path}: line 2: tag MILL1.V017.PS: time 2099-03-02T00:00:00Z is more than a day after the ingest's time ")
    assert "are at implausible times, more than export.max_bad_share = 0.05: a recorder clock that is off" in msg


def test_max_bad_share_1_keeps_a_mostly_faulty_file_in_quarantine(warehouse, tmp_path):
    """``max_bad_share = 1``: nothing is refused for faults; every faulty sample is quarantined."""
    cfg, wh = warehouse(max_bad_share=1.0)
    path = write_csv(tmp_path / "2099.csv", long_rows(seconds=10, start=datetime(2099, 3, 2, tzinfo=timezone.utc)))
    ingest(cfg, path, wh)
    assert_frame_equal(lake(wh), base_lake())
    row = file_row(wh, path)
    assert (row["quarantined"], row["implausible_time"], row["rows_out"], row["valves"]) == (60, 60, 0, "V017")
    assert table(wh, "quarantine").filter(pl.col("source_file") == str(path))["reason"].unique().to_list() == ["implausible_time"]


@pytest.mark.parametrize("max_bad_share, refused_", [(1.0, False), (0.5, True)])
def test_quarantine_rows_beyond_the_bound_wait_on_disk_and_are_removed(warehouse, tmp_path, monkeypatch, max_bad_share, refused_):
    """Memory does not grow with the quarantined samples: past ``SPILL_ROWS`` they go to temporary
    Parquet files, inserted with the file's ledger in file order, then deleted (also when refused)."""
    import tempfile

    import flows.ingest.spill

    cfg, wh = warehouse(max_bad_share=max_bad_share)
    small_batches(monkeypatch, 1024)
    monkeypatch.setattr(flows.ingest.spill, "SPILL_ROWS", 20)
    spill_dir = tmp_path / "tmp"
    spill_dir.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(spill_dir))
    written = []
    real = pl.DataFrame.write_parquet
    monkeypatch.setattr(pl.DataFrame, "write_parquet", lambda self, path, **kw: (written.append(self.height), real(self, path, **kw))[1])
    path = write_csv(tmp_path / "2099.csv", long_rows(seconds=40, start=datetime(2099, 3, 2, tzinfo=timezone.utc)))
    if refused_:
        assert "40 of 40 samples of tag MILL1.V017.PS in the file (100.0%) are at implausible times" in refused(cfg, path, wh)
    else:
        ingest(cfg, path, wh)
        q = table(wh, "quarantine").filter(pl.col("source_file") == str(path))
        assert q["line"].to_list() == list(range(2, 242)) and set(q["reason"]) == {"implausible_time"}
        assert file_row(wh, path)["quarantined"] == 240
    assert len(written) >= 5 and all(n >= 20 for n in written[:5])  # spilled, in parts of >= SPILL_ROWS rows
    assert list(spill_dir.iterdir()) == []


@pytest.mark.parametrize("faulty, accepted", [(10, True), (30, False)])
def test_the_share_is_per_file_over_all_its_batches(warehouse, tmp_path, monkeypatch, faulty, accepted):
    """Faults bunched in one batch of ~80 rows: 10 of a tag's 334 samples (3 %) are quarantined
    though they are most of that batch; 30 (9 %) refuse the file after its last batch, before
    anything of it is committed (earlier batches were staged)."""
    cfg, wh = warehouse()
    small_batches(monkeypatch)
    path = write_csv(tmp_path / "bunch.csv", long_rows(edit=lambda i, s, row: row.__setitem__(2, "1e308") if s == "p2" and 200 <= i < 200 + faulty else None))
    if not accepted:
        assert "30 of 334 samples of tag MILL1.V017.P2 in the file (9.0%) are out of range" in refused(cfg, path, wh)
        return
    ingest(cfg, path, wh)
    row = file_row(wh, path)
    assert (row["quarantined"], row["out_of_range"], row["rows_out"]) == (faulty, faulty, SECONDS - faulty)  # no lake rows inside the 11 s gap
    assert table(wh, "ingest_gaps").filter(pl.col("source_file") == str(path))["tag"].to_list() == [TAGS["p2"]]


# --- other equipment's tags ----------------------------------------------------------------------


def _other(i: int, t: str) -> list[list[str]]:
    return [[t, "MILL1.V099.P1", "1.0", "Good"], [t, "MILL1.PUMP3.SPEED", "Shutdown", "Bad"]]


def test_other_tags_are_read_past_counted_and_named(warehouse, tmp_path, monkeypatch):
    """Today: "unknown tag … no valve of the plant configuration has it" refuses the file."""
    cfg, wh = warehouse()
    small_batches(monkeypatch)
    clean = write_csv(tmp_path / "clean.csv", long_rows())
    mixed = write_csv(tmp_path / "mixed.csv", long_rows(extra=_other))
    ingest(cfg, mixed, wh)
    row = file_row(wh, mixed)
    assert (row["rows_in"], row["samples_in"], row["quarantined"]) == (8 * SECONDS, 6 * SECONDS, 0)
    assert (row["other_tags"], row["other_samples"], row["other_tag_names"]) == (2, 2 * SECONDS, "MILL1.V099.P1,MILL1.PUMP3.SPEED")
    ref = tmp_path / "ref"
    ingest(cfg, clean, ref)
    assert_frame_equal(new_day(wh), new_day(ref))
    assert file_row(ref, clean)["other_tag_names"] == ""


def test_other_columns_of_a_wide_export_are_read_past(warehouse, tmp_path, plant):
    _, wh = warehouse()
    cfg, _ = plant(name="wide.toml", layout="wide", tag_column=None, value_column=None, quality_column=None, good_quality=None)
    path = tmp_path / "wide.csv"
    text = (DATA / "base_wide.csv").read_text().splitlines()
    cells = ["MOTOR7.STATE", "MOTOR7.AMPS"]
    rows = [text[0] + "," + ",".join(cells)] + [line + (",Running,12.5" if i % 2 else ",,") for i, line in enumerate(text[1:]) if line.strip()]
    path.write_text("\n".join(rows) + "\n")
    ingest(cfg, path, tmp_path / "wide_wh")
    assert_frame_equal(lake(tmp_path / "wide_wh"), base_lake())
    row = file_row(tmp_path / "wide_wh", path)
    assert (row["other_tags"], row["other_samples"], row["other_tag_names"], row["quarantined"]) == (2, 4, "MOTOR7.STATE,MOTOR7.AMPS", 0)


def test_a_configured_tag_missing_beside_other_tags_is_todays_error(warehouse, tmp_path):
    cfg, wh = warehouse()
    path = write_csv(tmp_path / "no_xc.csv", [r for r in long_rows(extra=_other) if r[1] != TAGS["x_cyl"]])
    msg = refused(cfg, path, wh)
    assert msg == f"{path}: tag MILL1.V017.XC: valve V017: required signal x_cyl (tag MILL1.V017.XC) is missing from the export"


def test_a_file_of_other_equipment_only_is_refused(warehouse, tmp_path):
    cfg, wh = warehouse()
    path = write_csv(tmp_path / "pump.csv", [r for i in range(5) for r in _other(i, _iso(T1 + timedelta(seconds=i)))])
    msg = refused(cfg, path, wh)
    assert msg == f"{path}: no tag of the plant configuration in the file, only 2 other tags (MILL1.V099.P1, MILL1.PUMP3.SPEED)"


def test_other_tags_error_keeps_the_refusal(warehouse, tmp_path):
    cfg, wh = warehouse(other_tags="error")
    path = write_csv(tmp_path / "mixed.csv", long_rows(extra=_other))
    assert refused(cfg, path, wh) == f"{path}: line 8: unknown tag 'MILL1.V099.P1': no valve of the plant configuration has it"


# --- what held up and must stay ------------------------------------------------------------------


def _toml(cfg: Path, tmp_path: Path, change) -> Path:
    raw = tomllib.loads(cfg.read_text())
    change(raw)
    out = tmp_path / "changed.toml"
    out.write_bytes(tomli_w.dumps(raw).encode())
    return out


@pytest.mark.parametrize(
    "make, expected",
    [
        (lambda d, c: (c, _write(d / "empty.csv", b"")), "empty file (expected a long export with a header line)"),
        (lambda d, c: (c, _write(d / "header.csv", b"timestamp,tag,value,quality\n")), "no data rows (only a header)"),
        (lambda d, c: (c, _write(d / "garbage.csv", np.random.default_rng(1).bytes(5000))), "not a readable CSV export ("),
        (lambda d, c: (c, _write(d / "garbage.parquet", b"PAR1" + np.random.default_rng(2).bytes(5000))), "not a readable Parquet export ("),
        (lambda d, c: (c, _write(d / "cut.csv.gz", gzip.compress((DATA / "base_long.csv").read_bytes())[:200])), "truncated or corrupt gzip file"),
        (lambda d, c: (_write(d / "bad.toml", b"[plant\nname = 1"), DATA / "base_long.csv"), "not valid TOML"),
        (lambda d, c: (_toml(c, d, lambda r: r["valves"][0].update(id="../V017")), DATA / "base_long.csv"), "valves[0].id: '../V017' may hold only letters, digits, '-' and '_'"),
        (lambda d, c: (_toml(c, d, lambda r: r["valves"][0].update(bulk_modulus_gpa=-1.5)), DATA / "base_long.csv"), "valves[0].bulk_modulus_gpa: -1.5 must be > 0"),
        (lambda d, c: (_toml(c, d, lambda r: r["export"].update(max_bad_share=0)), DATA / "base_long.csv"), "export.max_bad_share: 0 must be > 0"),
        (lambda d, c: (_toml(c, d, lambda r: r["export"].update(other_tags="skip")), DATA / "base_long.csv"), "export.other_tags: 'skip' is not one of 'ignore', 'error'"),
    ],
    ids=["empty", "header-only", "binary-garbage", "garbage-parquet", "truncated-gzip", "bad-toml", "valve-id-dotdot", "negative-beta", "max-bad-share-0", "other-tags-typo"],
)
def test_bad_inputs_fail_in_one_line_and_leave_the_lake(warehouse, tmp_path, monkeypatch, capsys, make, expected):
    cfg, wh = warehouse()
    config, path = make(tmp_path, cfg)
    before, ledger_before = lake(wh), ledger(wh)
    code, out, err = run_cli(["ingest", "--config", str(config), "--warehouse", str(wh), str(path)], monkeypatch, capsys)
    assert code == 1 and out == ""
    assert err.count("\n") == 1 and err.startswith("valvemon: error: ") and expected in err
    assert_frame_equal(lake(wh), before)
    for a, b in zip(ledger(wh), ledger_before):
        assert_frame_equal(a, b)
    assert not (wh / "lake" / "sensors" / "valve_id=..").exists()


def _write(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


def test_a_second_ingest_at_the_same_time_is_refused_and_the_lake_stays_correct(warehouse, tmp_path, monkeypatch, capsys):
    cfg, wh = warehouse()
    path = write_csv(tmp_path / "next.csv", long_rows(seconds=20))
    with ingest_lock(wh):  # the first ingest, still running
        code, out, err = run_cli(["ingest", "--config", str(cfg), "--warehouse", str(wh), str(path)], monkeypatch, capsys)
        assert code == 1 and err == f"valvemon: error: {wh}: another ingest is running on this warehouse\n"
        assert_frame_equal(lake(wh), base_lake())
    ingest(cfg, path, wh)
    assert new_day(wh).height == 20 and lake(wh).height == 25
    assert table(wh, "ingest_manifest").height == 2


def test_an_older_warehouse_gets_the_new_ledger_columns(plant, tmp_path):
    """A manifest created before these columns: they are added (0, '') and the ingest goes on."""
    from flows.common.warehouse_db import connect, create_table_sql
    from schemas.fields import MANIFEST_FIELDS

    cfg, _ = plant()
    wh = tmp_path / "wh"
    ingest(cfg, DATA / "base_long.csv", wh)
    old = [f for f in MANIFEST_FIELDS if f.name not in ("bad_timestamp", "implausible_time", "out_of_range", "other_tags", "other_samples", "other_tag_names")]
    with connect(wh) as con:
        kept = con.execute(f"SELECT {', '.join(f.name for f in old)} FROM ingest_manifest").fetchall()
        con.execute("DROP TABLE ingest_manifest")
        con.execute(create_table_sql("ingest_manifest", tuple(old), "file_hash"))
        con.executemany(f"INSERT INTO ingest_manifest VALUES ({', '.join('?' * len(old))})", kept)
    path = write_csv(tmp_path / "next.csv", long_rows(seconds=10, extra=_other))
    ingest(cfg, path, wh)
    rows = table(wh, "ingest_manifest").sort("time_start")
    assert rows.select("other_tags", "other_samples", "other_tag_names", "out_of_range").rows() == [(0, 0, "", 0), (2, 20, "MILL1.V099.P1,MILL1.PUMP3.SPEED", 0)]
    assert_frame_equal(lake(wh).filter(pl.col("date") != T1.date()), base_lake())
