"""``run_report`` on a hand-built warehouse: pictures, HTML (rendered in headless Chromium), the
discrepancy workflow's findings in it, the BI hand-off read by four readers, and the snapshot that
keeps readers and writer apart."""

from __future__ import annotations

import base64
import copy
import os
import re
import shutil
import subprocess
import sys
import tempfile
import textwrap
import tomllib
from datetime import timedelta
from pathlib import Path

import duckdb
import numpy as np
import polars as pl
import pytest
import tomli_w

from flows.common.config import load_plant_config
from flows.common.warehouse_db import connect, insert_frame
from flows.monitor.flow import ensure_baselines, ensure_monitor_tables, monitor_params
from flows.report.flow import run_report
from flows.report.views import connect_snapshot, publish_snapshot, snapshot_path
from schemas.fields import DISCREPANCY_FINDING_FIELDS, EDGE_FIT_FIELDS, FLEET_RANKING_FIELDS, VALVE_CONDITION_FIELDS, polars_schema

from tests.report.viewdb import COMMISSIONED, Warehouse

pytestmark = pytest.mark.xdist_group("report_built")  # one worker builds the shared `built` once

EXAMPLE = Path(__file__).parents[1] / "fixtures" / "plant_example.toml"
VALVES = ("VA", "VB", "VC")
HOURS = np.arange(0.0, 120.0, 1.0)
CHROMIUM = Path("/usr/bin/chromium")


def _plant(tmp: Path) -> Path:
    raw = tomllib.loads(EXAMPLE.read_text())
    template = raw["valves"][0]
    raw["valves"] = []
    for vid in VALVES:
        v = copy.deepcopy(template)
        v["id"] = vid
        v["commissioned"] = COMMISSIONED.isoformat()
        for t in v["tags"].values():
            t["tag"] = t["tag"].replace("V017", vid)
        raw["valves"].append(v)
    path = tmp / "plant.toml"
    path.write_bytes(tomli_w.dumps(raw).encode())
    return path


def _fits(w: Warehouse) -> pl.DataFrame:
    w.add_healthy_edges("VA", HOURS, seed=11)
    w.add_healthy_edges("VB", HOURS, seed=12, skip=("1r",))
    a, x, e = np.full(HOURS.size, 0.98), np.full(HOURS.size, 0.23), np.full(HOURS.size, 0.10)
    a[-6:], x[-6:], e[-6:] = 2.53, 11.8, 1.13  # edge 1r breaks (Table 2)
    w.add_fits("VB", "1r", HOURS, a, x, e)
    w.add_healthy_edges("VC", HOURS, seed=13, skip=("s2",))
    w.add_fits("VC", "s2", HOURS, 1.0 + 0.0015 * HOURS, 0.1 + 0.02 * HOURS, 0.2)  # wear
    return w.q("SELECT * FROM edge_fits")


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("report")
    config_path = _plant(tmp)
    config = load_plant_config(config_path)
    warehouse = tmp / "wh"
    for v in config.valves:  # nominal baselines, as `valvemon monitor` makes them without commissioning data
        ensure_baselines(v, monitor_params(v, config.export.sample_rate_hz), warehouse)
    w = Warehouse()
    fits = _fits(w).cast(dict(polars_schema(EDGE_FIT_FIELDS)))
    w.con.close()
    with connect(warehouse) as con:
        ensure_monitor_tables(con)
        insert_frame(con, "edge_fits", fits)
    result = run_report(config_path, warehouse)
    return config_path, warehouse, result, fits


def test_report_conditions(built):
    _, _, result, _ = built
    rank = result.ranking
    assert rank["valve_id"].to_list()[:2] == ["VB", "VC"]
    assert rank["state"].to_list()[0] == "faulty"
    assert rank.filter(pl.col("valve_id") == "VC")["limiting_edge"][0] == "s2"


def test_report_contains_the_expected_figures(built):
    _, warehouse, result, _ = built
    reports = warehouse / "reports"
    expected = {"fleet_overview.png"} | {f"characteristics_{v}.png" for v in VALVES} | {f"trends_{v}.png" for v in VALVES}
    assert {p.name for p in result.pngs} == expected
    assert {p.name for p in reports.glob("*.png")} == expected
    import matplotlib.image as mpimg

    for p in result.pngs:
        img = mpimg.imread(p)
        assert img.shape[0] > 300 and img.shape[1] > 800
        assert float(img[..., :3].std()) > 0.05, f"{p.name} is blank"
    text = result.html.read_text()
    assert result.html == reports / "report.html"
    images = re.findall(r'<img alt="([^"]*)" src="data:image/png;base64,([A-Za-z0-9+/=]+)"', text)
    assert len(images) == len(expected)
    for _, data in images:
        assert base64.b64decode(data)[:8] == b"\x89PNG\r\n\x1a\n"
    # self-contained: no external reference of any kind
    assert not re.search(r"(src|href)\s*=\s*[\"'](?!data:|#)", text)
    assert "<script" not in text and "@import" not in text and "url(" not in text
    for vid in VALVES:
        assert f"id='valve-{vid}'" in text
    assert "faulty" in text and "alpha_hat 2.53" in text


def _finding(valve_id: str, run_id: str, hour: int, effect: str, gap_before: float, gap_after: float, png: Path) -> dict:
    row = {f.name: None for f in DISCREPANCY_FINDING_FIELDS}
    at = COMMISSIONED + timedelta(hours=hour)
    return row | {
        "run_id": run_id, "valve_id": valve_id, "run_at": at, "effect": effect, "variant": "", "rank": 1,
        "gap_before": gap_before, "gap_after": gap_after, "window_start": at, "window_end": at, "n_records": 3,
        "condition_source": "design", "plot_path": str(png), "ci_level": 0.95,
        **{f"gap_{s}_{w}_{u}": 0.1 for s, u in (("p1", "bar"), ("p2", "bar"), ("x", "mm")) for w in ("before", "after")},
    }  # fmt: skip


def test_report_shows_the_latest_discrepancy_run_of_each_analysed_valve(built, tmp_path):
    from flows.discrepancy.flow import store_run

    config_path, built_warehouse, built_result, _ = built
    assert "Model discrepancy" not in built_result.html.read_text()  # the workflow never ran there
    warehouse = tmp_path / "wh"
    shutil.copytree(built_warehouse, warehouse)
    folder = warehouse / "reports" / "discrepancy"
    folder.mkdir()
    png = shutil.copy(built_warehouse / "reports" / "fleet_overview.png", folder / "VB_0000_1_external_leakage.png")
    elsewhere = Path("/moved/warehouse/reports/discrepancy") / png.name  # found by name in this warehouse
    older = _finding("VB", "r1", 1, "none", 0.15, 0.15, folder / "VB_r1_none.png")
    newer = _finding("VB", "r2", 2, "external_leakage", 0.9, 0.1, elsewhere)
    newer |= {"parameter_name": "K_e", "parameter_value": 1e-12, "parameter_unit": "m3/(s*Pa)"}
    findings = pl.DataFrame([older, newer], schema=polars_schema(DISCREPANCY_FINDING_FIELDS))
    store_run(warehouse, {"discrepancy_findings": findings})
    text = run_report(config_path, warehouse, valve_ids=["VA"]).html.read_text()
    section = text[text.index("<h2 id='discrepancy'>Model discrepancy</h2>"):]
    assert "<h3 id='discrepancy-VB'>Valve VB: external_leakage</h3>" in section  # the newer run only
    assert section.count("<h3") == 1 and section.count("<tr><td class='num'>") == 1
    assert "K_e = 1e-12 m3/(s*Pa)" in section and "<td class='num'>0.9</td><td class='num'>0.1</td>" in section
    images = re.findall(r'<img alt="VB: external_leakage overlay" src="data:image/png;base64,([A-Za-z0-9+/=]+)"', section)
    assert len(images) == 1 and base64.b64decode(images[0]) == png.read_bytes()


@pytest.mark.skipif(not CHROMIUM.exists() and not os.environ.get("CI"), reason="chromium not installed (make test installs it)")
def test_html_renders_in_headless_chromium(built, tmp_path):
    _, _, result, _ = built
    shot = tmp_path / "shot.png"
    profile = tempfile.mkdtemp(prefix="chromium-profile-")
    try:
        subprocess.run(
            [str(CHROMIUM), "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
             "--disable-component-update", "--disable-sync", "--no-first-run", f"--user-data-dir={profile}",
             "--hide-scrollbars", "--window-size=1400,2400", f"--screenshot={shot}", result.html.resolve().as_uri()],
            check=True, capture_output=True, timeout=120,
        )  # fmt: skip
    finally:
        shutil.rmtree(profile, ignore_errors=True)
    import matplotlib.image as mpimg

    img = mpimg.imread(shot)[..., :3]
    assert img.shape[:2] == (2400, 1400)
    non_white = (img < 0.9).any(axis=2).mean()
    assert non_white > 0.05, f"screenshot nearly blank ({non_white:.1%} non-white pixels)"
    # the state cards are drawn: the faulty red (#d32f2f) and the healthy green (#4caf50) appear
    red = ((np.abs(img - np.array([0xD3, 0x2F, 0x2F]) / 255) < 0.03).all(axis=2)).sum()
    green = ((np.abs(img - np.array([0x4C, 0xAF, 0x50]) / 255) < 0.03).all(axis=2)).sum()
    assert red > 500 and green > 500
    keep = os.environ.get("VALVEMON_KEEP_SCREENSHOT")
    if keep:
        shutil.copy(shot, keep)


def test_bi_export_reads_the_same_in_duckdb_polars_pandas_pyarrow(built):
    _, warehouse, result, fits = built
    root = warehouse / "export"
    fits_dir = root / "edge_fits"
    assert sorted(p.name for p in fits_dir.iterdir()) == ["_exported_through", *(f"valve_id={v}" for v in VALVES)]
    days = fits.select(valve_id="valve_id", day=pl.col("window_start").dt.date()).unique()
    assert sorted(p.relative_to(fits_dir).parts[:2] for p in fits_dir.glob("*/*/part-0.parquet")) == sorted(
        (f"valve_id={v}", f"date={d.isoformat()}") for v, d in days.iter_rows())  # a partition per valve and UTC day
    names = [f.name for f in EDGE_FIT_FIELDS]
    glob = str(fits_dir / "**" / "*.parquet")

    d = duckdb.sql(f"SELECT * FROM read_parquet('{glob}', hive_partitioning = false)").pl()
    assert d.columns == names and d.height == fits.height
    d2 = duckdb.sql(f"SELECT valve_id, count(*) AS n FROM read_parquet('{glob}', hive_partitioning = true) GROUP BY 1 ORDER BY 1").fetchall()
    assert d2 == [(v, fits.filter(pl.col("valve_id") == v).height) for v in VALVES]
    types = {r[0]: r[1] for r in duckdb.sql(f"DESCRIBE SELECT * FROM read_parquet('{glob}', hive_partitioning = false)").fetchall()}
    assert types["window_start"] == "TIMESTAMP WITH TIME ZONE" and types["n_points"] == "INTEGER"

    p = pl.read_parquet(glob, hive_partitioning=False)
    assert p.schema == polars_schema(EDGE_FIT_FIELDS)
    key = ["valve_id", "edge", "window_start"]
    assert p.sort(key).equals(fits.sort(key))

    import pandas as pd

    pdf = pd.read_parquet(next((fits_dir / "valve_id=VB").glob("date=*/part-0.parquet")))
    assert list(pdf.columns) == names and set(pdf["valve_id"]) == {"VB"}
    assert str(pdf["window_start"].dtype) == "datetime64[us, UTC]"

    import pyarrow.dataset as ds
    import pyarrow.parquet as pq

    table = ds.dataset(fits_dir, format="parquet", partitioning="hive").to_table()
    assert table.num_rows == fits.height
    schema = pq.read_schema(next((fits_dir / "valve_id=VA").glob("date=*/part-0.parquet")))
    assert schema.names == names
    assert str(schema.field("window_start").type) == "timestamp[us, tz=UTC]"
    assert schema.field("x_hat_mm").metadata[b"unit"] == b"mm"

    cond = pl.read_parquet(root / "valve_condition.parquet")
    assert cond.columns == [f.name for f in VALVE_CONDITION_FIELDS] and cond.height == 4 * len(VALVES)
    assert cond.filter((pl.col("valve_id") == "VB") & (pl.col("edge") == "1r"))["state"][0] == "faulty"
    rank = pd.read_parquet(root / "fleet_ranking.parquet")
    assert list(rank.columns) == [f.name for f in FLEET_RANKING_FIELDS] and rank["valve_id"].iloc[0] == "VB"


def test_query_formats(built, tmp_path, capsys):
    from flows.report.query import run_query

    _, warehouse, _, _ = built
    sql = "SELECT valve_id, state, remaining_hours FROM fleet_ranking ORDER BY urgency_rank"
    run_query(sql, warehouse, fmt="csv")
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "valve_id,state,remaining_hours" and out[1].startswith("VB,faulty,")
    run_query(sql, warehouse, fmt="json", out=tmp_path / "q.json")
    assert pl.read_json(tmp_path / "q.json")["valve_id"].to_list()[0] == "VB"
    run_query(sql, warehouse, fmt="parquet", out=tmp_path / "q.parquet")
    assert pl.read_parquet(tmp_path / "q.parquet").height == len(VALVES)
    run_query(sql, warehouse, fmt="table")
    table = capsys.readouterr().out
    assert "VB" in table and "faulty" in table and "3 row(s)" in table
    from flows.common.errors import ValvemonError

    with pytest.raises(ValvemonError, match="needs --out"):
        run_query(sql, warehouse, fmt="parquet")
    with pytest.raises(ValvemonError, match="query failed: Catalog Error"):
        run_query("SELECT * FROM no_such_table", warehouse)


_HOLD_WRITER = textwrap.dedent("""
    import sys, time
    from pathlib import Path
    from flows.common.warehouse_db import connect
    warehouse, ready, go = sys.argv[1:4]
    with connect(warehouse) as con:              # the nightly writer, mid-transaction
        con.execute("BEGIN TRANSACTION")
        con.execute("DELETE FROM condition_bounds")
        Path(ready).touch()
        while not Path(go).exists():
            time.sleep(0.05)
        con.execute("ROLLBACK")
""")

_HOLD_READER = textwrap.dedent("""
    import sys, time
    from pathlib import Path
    from flows.report.views import connect_snapshot
    warehouse, ready, go = sys.argv[1:4]
    con = connect_snapshot(warehouse)           # a BI user with the snapshot open
    before = con.execute("SELECT count(*) FROM edge_fits").fetchall()[0][0]
    Path(ready).touch()
    while not Path(go).exists():
        time.sleep(0.05)
    after = con.execute("SELECT count(*) FROM edge_fits").fetchall()[0][0]
    print(before, after)
""")


def _wait_for(path: Path, proc: subprocess.Popen) -> None:
    while not path.exists():
        if proc.poll() is not None:
            raise AssertionError(f"helper process ended early: {proc.communicate()}")
        proc.wait(timeout=None) if False else None
        import time

        time.sleep(0.05)


def test_readers_and_the_writer_never_wait_for_each_other(built, tmp_path):
    config_path, warehouse, _, fits = built
    env = os.environ | {"PYTHONPATH": str(Path(__file__).parents[2])}
    # 1. a writer holds the live database read-write: a reader (the real CLI) still answers from the snapshot
    ready, go = tmp_path / "w.ready", tmp_path / "w.go"
    writer = subprocess.Popen([sys.executable, "-c", _HOLD_WRITER, str(warehouse), str(ready), str(go)], env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    try:
        _wait_for(ready, writer)
        cli = Path(sys.executable).parent / "valvemon"
        q = subprocess.run([str(cli), "query", "SELECT count(*) AS n FROM edge_fits", "--format", "csv", "--warehouse", str(warehouse)],
                           env=env, capture_output=True, text=True, timeout=300)  # fmt: skip
        assert q.returncode == 0, q.stderr
        assert q.stdout.split() == ["n", str(fits.height)]
        # the live file is locked by the writer: --live gives up with a clear message instead of blocking
        from flows.common.errors import ValvemonError

        with pytest.raises(ValvemonError, match="cannot open the database"):
            connect_snapshot(warehouse, live=True, wait_s=0.2)
    finally:
        go.touch()
        writer.communicate(timeout=120)
    assert writer.returncode == 0
    # 2. a reader holds the snapshot open: the writer adds rows and publishes a new snapshot meanwhile
    ready, go = tmp_path / "r.ready", tmp_path / "r.go"
    reader = subprocess.Popen([sys.executable, "-c", _HOLD_READER, str(warehouse), str(ready), str(go)], env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    try:
        _wait_for(ready, reader)
        extra = fits.filter(pl.col("valve_id") == "VA").with_columns(pl.col("window_start") + timedelta(days=30))
        with connect(warehouse, wait_s=5) as con:
            insert_frame(con, "edge_fits", extra)
            publish_snapshot(con, warehouse)
    finally:
        go.touch()
        out, err = reader.communicate(timeout=120)
    assert reader.returncode == 0, err
    assert out.split() == [str(fits.height)] * 2  # the open reader keeps its consistent old snapshot
    con = connect_snapshot(warehouse)
    try:
        assert con.execute("SELECT count(*) FROM edge_fits").fetchall()[0][0] == fits.height + extra.height
        assert con.execute("SELECT count(*) FROM valve_condition").fetchall()[0][0] == 4 * len(VALVES)  # views copied too
    finally:
        con.close()
    assert [p.name for p in snapshot_path(warehouse).parent.iterdir()] == ["valvemon.duckdb"]


def test_pictures_drawn_in_worker_processes_are_the_files_drawn_here(built, tmp_path):
    from flows.common.warehouse_db import query_frame
    from flows.report.figures import fleet_figure, render_figures

    _, warehouse, result, _ = built  # three valves: seven pictures, drawn in this process
    con = connect_snapshot(warehouse)
    try:
        conditions = query_frame(con, "SELECT * FROM valve_condition ORDER BY valve_id, edge_order")
    finally:
        con.close()
    jobs = [(fleet_figure, (result.ranking, conditions, tmp_path / f"fleet_{k}.png")) for k in range(3)]
    assert render_figures(jobs, workers=2) == [tmp_path / f"fleet_{k}.png" for k in range(3)]
    drawn_here = (warehouse / "reports" / "fleet_overview.png").read_bytes()
    assert all((tmp_path / f"fleet_{k}.png").read_bytes() == drawn_here for k in range(3))


def test_a_picture_is_drawn_again_only_when_what_it_shows_changed(built, tmp_path):
    from flows.common.warehouse_db import query_frame
    from flows.report.figures import fleet_figure, render_figures

    _, warehouse, result, _ = built
    con = connect_snapshot(warehouse)
    try:
        conditions = query_frame(con, "SELECT * FROM valve_condition")
    finally:
        con.close()
    drawn = []

    def counted(ranking, conditions, path):
        drawn.append(path)
        return fleet_figure(ranking, conditions, path)

    path = tmp_path / "fleet.png"
    assert render_figures([(counted, (result.ranking, conditions, path))], workers=0) == [path]
    first = path.read_bytes()
    assert first == (warehouse / "reports" / "fleet_overview.png").read_bytes()
    # the same rows in another order (a query without ORDER BY): kept, not drawn
    assert render_figures([(counted, (result.ranking, conditions.reverse(), path))], workers=0) == [path]
    assert drawn == [path] and path.read_bytes() == first
    # a valve's state changed: drawn again, and the picture shows it
    changed = conditions.with_columns(state=pl.when(pl.col("valve_id") == VALVES[0]).then(pl.lit("faulty")).otherwise(pl.col("state")))
    assert changed["state"].to_list() != conditions["state"].to_list()
    render_figures([(counted, (result.ranking, changed, path))], workers=0)
    assert drawn == [path, path] and path.read_bytes() != first
    # a picture whose record of its inputs is gone is drawn again, whatever it shows
    (tmp_path / ".fleet.png.key").unlink()
    render_figures([(counted, (result.ranking, changed, path))], workers=0)
    assert len(drawn) == 3
