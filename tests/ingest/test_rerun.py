"""Idempotence, overlapping exports, the manifest, and crashes at any point followed by a rerun."""

from __future__ import annotations

from datetime import timedelta

import pytest
from blake3 import blake3
from polars.testing import assert_frame_equal

import flows.common.lake
import flows.ingest.flow
from flows.common.errors import ValvemonError
from tests.ingest.conftest import BASE, DATA, T0, base_lake, expected_lake, ingest, lake, table


def _files(wh):
    return {p.relative_to(wh).as_posix(): (p.stat().st_mtime_ns, p.read_bytes()) for p in (wh / "lake").rglob("*") if p.is_file()}


def _split(tmp_path):
    """base_long.csv as two overlapping exports: seconds 0–2 and 2–4 (second 2 in both)."""
    lines = (DATA / "base_long.csv").read_text().splitlines()
    header, rows = lines[0], lines[1:]
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    a.write_text("\n".join([header, *rows[:18]]) + "\n")
    b.write_text("\n".join([header, *rows[12:]]) + "\n")
    return a, b


def test_ingesting_the_same_export_again_changes_nothing(plant, tmp_path):
    wh = tmp_path / "wh"
    cfg2, _ = plant("pi.toml", quality_column=None, good_quality=None)
    ingest(cfg2, DATA / "pi_tag_major.csv", wh)
    before = _files(wh)
    again = ingest(cfg2, DATA / "pi_tag_major.csv", wh)
    assert again.files_skipped == 1 and again.files_ingested == 0
    forced = ingest(cfg2, DATA / "pi_tag_major.csv", wh, force=True)
    assert forced.files_ingested == 1 and forced.rows_added == 0 and forced.partitions_written == 0
    assert _files(wh) == before  # not even rewritten
    assert table(wh, "quarantine").height == 3  # a forced re-read replaces the file's quarantine rows
    assert table(wh, "ingest_manifest").height == 1
    assert table(wh, "ingest_runs")["status"].to_list() == ["ok", "ok", "ok"]


def test_identical_content_under_another_name_is_recognised(plant, tmp_path):
    cfg, _ = plant()
    copy = tmp_path / "copy.csv"
    copy.write_bytes((DATA / "base_long.csv").read_bytes())
    ingest(cfg, DATA / "base_long.csv", tmp_path / "wh")
    assert ingest(cfg, copy, tmp_path / "wh").files_skipped == 1


def test_overlapping_exports_merge_without_duplicates(plant, tmp_path):
    cfg, _ = plant()
    a, b = _split(tmp_path)
    ra = ingest(cfg, a, tmp_path / "wh")
    rb = ingest(cfg, b, tmp_path / "wh")
    assert_frame_equal(lake(tmp_path / "wh"), base_lake())
    assert (ra.rows_written, ra.rows_added, rb.rows_written, rb.rows_added) == (3, 3, 3, 2)
    # in either order
    ingest(cfg, [b, a], tmp_path / "wh2")
    assert_frame_equal(lake(tmp_path / "wh2"), base_lake())


@pytest.mark.parametrize("rule, expected_p1", [("last", 150.0), ("first", 102.0)])
def test_a_later_export_that_disagrees_follows_the_duplicate_rule(plant, tmp_path, rule, expected_p1):
    cfg, _ = plant(duplicate_rule=rule)
    revised = tmp_path / "revised.csv"
    revised.write_text((DATA / "base_long.csv").read_text().replace("MILL1.V017.P1,102.0", "MILL1.V017.P1,150.0"))
    ingest(cfg, DATA / "base_long.csv", tmp_path / "wh")
    report = ingest(cfg, revised, tmp_path / "wh")
    want = dict(BASE)
    want["p1"] = [100.0, 101.5, expected_p1, 103.5, 104.0]
    assert_frame_equal(lake(tmp_path / "wh"), expected_lake([T0 + timedelta(seconds=i) for i in range(5)], want))
    assert report.lake_conflicts == 1


def test_a_later_export_that_disagrees_is_refused_under_rule_error(plant, tmp_path):
    cfg, _ = plant(duplicate_rule="error")
    revised = tmp_path / "revised.csv"
    revised.write_text((DATA / "base_long.csv").read_text().replace("MILL1.V017.P1,102.0", "MILL1.V017.P1,150.0"))
    ingest(cfg, DATA / "base_long.csv", tmp_path / "wh")
    with pytest.raises(ValvemonError, match=r"tag MILL1.V017.P1: valve V017 at 2025-03-01T12:00:02Z: column p1_pa is 10200000.0 in the lake but 15000000.0"):
        ingest(cfg, revised, tmp_path / "wh")
    assert_frame_equal(lake(tmp_path / "wh"), base_lake())


def test_manifest_records_hash_counts_and_time_range(plant, tmp_path):
    cfg, _ = plant()
    ingest(cfg, DATA / "duplicates.csv", tmp_path / "wh")
    m = table(tmp_path / "wh", "ingest_manifest").row(0, named=True)
    assert m["file_hash"] == "blake3:" + blake3((DATA / "duplicates.csv").read_bytes()).hexdigest()
    assert (m["rows_in"], m["samples_in"], m["rows_out"], m["rows_added"], m["quarantined"], m["partitions"]) == (21, 21, 3, 3, 0, 1)
    assert (m["time_start"], m["time_end"]) == (T0, T0 + timedelta(seconds=2))
    assert m["valves"] == "V017" and m["layout"] == "long" and m["file_format"] == "csv"
    run = table(tmp_path / "wh", "ingest_runs").row(0, named=True)
    assert (run["rows_read"], run["rows_written"], run["duplicates"], run["conflicts"], run["status"]) == (21, 3, 2, 1, "ok")


# --- crashes ----------------------------------------------------------------------------------

class Crash(RuntimeError):
    pass


@pytest.fixture
def wide(plant):
    cfg, _ = plant("wide.toml", layout="wide", tag_column=None, value_column=None, quality_column=None, good_quality=None)
    return cfg


def test_crash_after_the_temp_file_keeps_the_old_partition_and_a_rerun_completes(wide, tmp_path, monkeypatch):
    clean = tmp_path / "clean"
    ingest(wide, DATA / "midnight.csv", clean)
    wh = tmp_path / "wh"
    calls = []

    def crash_on_second(tmp, path):
        calls.append(path)
        if len(calls) == 2:
            assert tmp.exists() and tmp.stat().st_size > 0  # the new content was written beside it
            raise Crash("killed between the temporary file and the rename")
        return real_commit(tmp, path)

    real_commit = flows.common.lake._commit
    monkeypatch.setattr(flows.common.lake, "_commit", crash_on_second)
    with pytest.raises(Crash):
        ingest(wide, DATA / "midnight.csv", wh)
    monkeypatch.setattr(flows.common.lake, "_commit", real_commit)
    # first partition new, second absent (it never existed): never a half-written file
    assert [p.parent.name for p in (wh / "lake").rglob("part-0.parquet")] == ["date=2025-03-01"]
    assert table(wh, "ingest_manifest").height == 0
    assert table(wh, "ingest_runs")["status"].to_list() == ["failed"]
    ingest(wide, DATA / "midnight.csv", wh)
    assert_frame_equal(lake(wh), lake(clean))
    assert not [p for p in (wh / "lake").rglob("*.tmp")]


def test_crash_replacing_an_existing_partition_leaves_the_old_content(plant, tmp_path, monkeypatch):
    cfg, _ = plant()
    a, b = _split(tmp_path)
    wh = tmp_path / "wh"
    ingest(cfg, a, wh)
    old = lake(wh)

    def write_then_die(*args):
        real_write(*args)
        raise Crash("killed after fsync of the temporary file")

    real_write = flows.common.lake._write_temp
    monkeypatch.setattr(flows.common.lake, "_write_temp", write_then_die)
    with pytest.raises(Crash):
        ingest(cfg, b, wh)
    monkeypatch.setattr(flows.common.lake, "_write_temp", real_write)
    assert_frame_equal(lake(wh), old)
    ingest(cfg, b, wh)
    assert_frame_equal(lake(wh), base_lake())


def test_a_kill_leaving_a_temp_file_is_tidied_by_the_next_write(plant, tmp_path):
    cfg, _ = plant()
    wh = tmp_path / "wh"
    ingest(cfg, DATA / "base_long.csv", wh)
    part = next((wh / "lake").rglob("part-0.parquet"))
    stale = part.parent / ".part-0.parquet.deadbeef.tmp"
    stale.write_bytes(b"half a parquet file")  # what SIGKILL during the write leaves
    assert_frame_equal(lake(wh), base_lake())  # readers never see it
    revised = tmp_path / "revised.csv"
    revised.write_text((DATA / "base_long.csv").read_text().replace("MILL1.V017.P1,102.0", "MILL1.V017.P1,150.0"))
    ingest(cfg, revised, wh)
    assert not stale.exists()


def test_crash_between_partitions_then_rerun_equals_one_clean_run(wide, tmp_path, monkeypatch):
    clean = tmp_path / "clean"
    ingest(wide, DATA / "midnight.csv", clean)
    wh = tmp_path / "wh"
    real = flows.common.lake._commit
    n = []

    def die_second(tmp, path):
        n.append(path)
        if len(n) == 2:
            raise Crash("killed between putting two files in place")
        return real(tmp, path)

    monkeypatch.setattr(flows.common.lake, "_commit", die_second)
    with pytest.raises(Crash):
        ingest(wide, DATA / "midnight.csv", wh)
    monkeypatch.setattr(flows.common.lake, "_commit", real)
    ingest(wide, DATA / "midnight.csv", wh)
    assert_frame_equal(lake(wh), lake(clean))
    assert _bytes_equal(clean, wh)


def _bytes_equal(a, b) -> bool:
    fa = {k: v[1] for k, v in _files(a).items()}
    fb = {k: v[1] for k, v in _files(b).items()}
    return fa == fb


def test_crash_before_the_manifest_then_rerun_counts_nothing_twice(plant, tmp_path, monkeypatch):
    cfg, _ = plant("pi.toml", quality_column=None, good_quality=None)
    wh = tmp_path / "wh"
    real = flows.ingest.flow.record_file

    def die(*a, **k):
        raise Crash("killed after the partitions, before the manifest")

    monkeypatch.setattr(flows.ingest.flow, "record_file", die)
    with pytest.raises(Crash):
        ingest(cfg, DATA / "pi_tag_major.csv", wh)
    monkeypatch.setattr(flows.ingest.flow, "record_file", real)
    report = ingest(cfg, DATA / "pi_tag_major.csv", wh)
    assert report.files_ingested == 1 and report.rows_added == 0  # the lake already had the rows
    assert table(wh, "quarantine").height == 3 and table(wh, "ingest_manifest").height == 1
    assert lake(wh).height == 5


def _make_legacy(wh):
    """Turn a warehouse into one written before BLAKE3: column file_sha256 holding bare SHA-256 hex."""
    import hashlib

    import duckdb

    con = duckdb.connect(str(wh / "valvemon.duckdb"))
    try:
        files = con.execute("SELECT file_hash, source_file FROM ingest_manifest").fetchall()
        for t in ("ingest_manifest", "quarantine", "ingest_gaps"):
            for h, src in files:
                sha = hashlib.sha256(open(src, "rb").read()).hexdigest()
                con.execute(f"UPDATE {t} SET file_hash = ? WHERE file_hash = ?", [sha, h])
            con.execute(f"ALTER TABLE {t} RENAME COLUMN file_hash TO file_sha256")
    finally:
        con.close()


def test_a_warehouse_from_before_blake3_still_knows_its_files(plant, tmp_path):
    import hashlib

    cfg, _ = plant()
    wh = tmp_path / "wh"
    lines = (DATA / "base_long.csv").read_text().splitlines()
    gapped = tmp_path / "gap.csv"  # seconds 1 and 2 missing: a 3 s gap per tag, one quarantined sample
    kept = [ln for ln in lines if "12:00:01" not in ln and "12:00:02" not in ln]
    kept[-1] = kept[-1].rsplit(",", 1)[0] + ",Bad"
    gapped.write_text("\n".join(kept) + "\n")
    ingest(cfg, [DATA / "duplicates.csv", gapped], wh)
    before = {t: table(wh, t) for t in ("ingest_manifest", "quarantine", "ingest_gaps")}
    assert before["ingest_gaps"].height == 6 and before["quarantine"].height == 1
    _make_legacy(wh)
    sha = {p.name: "sha256:" + hashlib.sha256(p.read_bytes()).hexdigest() for p in (DATA / "duplicates.csv", gapped)}

    # the first connection migrates: column renamed, values marked as SHA-256, nothing lost
    summary = ingest(cfg, [DATA / "duplicates.csv"], wh)
    assert (summary.files_skipped, summary.files_ingested) == (1, 0)  # known by its SHA-256
    m = table(wh, "ingest_manifest").sort("source_file")
    new = "blake3:" + blake3((DATA / "duplicates.csv").read_bytes()).hexdigest()
    assert sorted(m["file_hash"].to_list()) == sorted([new, sha["gap.csv"]])  # the file seen again was re-keyed
    gaps, quarantine = table(wh, "ingest_gaps"), table(wh, "quarantine")
    assert gaps.height == 6 and set(gaps["file_hash"]) == {sha["gap.csv"]}
    assert quarantine.height == 1 and set(quarantine["file_hash"]) == {sha["gap.csv"]}
    assert_frame_equal(m.drop("file_hash"), before["ingest_manifest"].sort("source_file").drop("file_hash"))

    # the re-keyed file is now matched by its BLAKE3 hash; the other still by its SHA-256
    summary = ingest(cfg, [DATA / "duplicates.csv", gapped], wh)
    assert (summary.files_skipped, summary.files_ingested) == (2, 0)
    assert table(wh, "ingest_manifest").height == 2 and table(wh, "ingest_gaps").height == 6 and table(wh, "quarantine").height == 1
    key = "blake3:" + blake3(gapped.read_bytes()).hexdigest()
    assert set(table(wh, "ingest_gaps")["file_hash"]) == {key} and set(table(wh, "quarantine")["file_hash"]) == {key}

    # --force reads it again and replaces (not doubles) its quarantine and gap rows
    ingest(cfg, [gapped], wh, force=True)
    assert table(wh, "ingest_manifest").height == 2 and table(wh, "ingest_gaps").height == 6 and table(wh, "quarantine").height == 1


def test_backfill_recognises_and_rekeys_a_legacy_file(plant, tmp_path):
    from flows.common.warehouse_db import connect
    from flows.ingest.flow import rekey_file
    from flows.orchestration.backfill import ensure_backfill_tables, ingest_export, manifest_hashes

    cfg, config = plant()
    wh = tmp_path / "wh"
    ingest(cfg, [DATA / "duplicates.csv"], wh)
    with connect(wh) as con:  # a progress row as an older backfill wrote it
        ensure_backfill_tables(con)
        con.execute("INSERT INTO backfill_progress (unit_kind, unit_key, file_hash, run_id, finished_at) VALUES ('ingest', 'k', ?, 'r', now())",
                    ["blake3:" + blake3((DATA / "duplicates.csv").read_bytes()).hexdigest()])  # fmt: skip
    _make_legacy(wh)
    with connect(wh) as con:
        con.execute("UPDATE backfill_progress SET file_hash = (SELECT file_sha256 FROM ingest_manifest)")
        con.execute("ALTER TABLE backfill_progress RENAME COLUMN file_hash TO file_sha256")
    known = manifest_hashes(wh)  # migrates the ingest tables
    with connect(wh) as con:
        ensure_backfill_tables(con)  # migrates backfill_progress
        assert con.execute("SELECT file_hash FROM backfill_progress").fetchone()[0].startswith("sha256:")
    assert len(known.hashes) == 1 and next(iter(known.hashes)).startswith("sha256:")
    out = ingest_export(DATA / "duplicates.csv", config, wh, known, "run")
    new = "blake3:" + blake3((DATA / "duplicates.csv").read_bytes()).hexdigest()
    assert out.report.skipped and out.records is None and out.rekey == (next(iter(known.hashes)), new)
    with connect(wh) as con:
        rekey_file(con, *out.rekey)
        assert con.execute("SELECT file_hash FROM backfill_progress").fetchone()[0] == new
    assert manifest_hashes(wh).hashes == frozenset([new])
    assert ingest_export(DATA / "duplicates.csv", config, wh, manifest_hashes(wh), "run").rekey is None
