"""Whether two warehouses of the same exports hold the same night: the lake files, ``edge_fits``
and every view, compared value for value (a speed change must not change what is estimated).

    .venv/bin/python bench/same_night.py WAREHOUSE_BEFORE WAREHOUSE_AFTER

Lake: the same files (by their path under the lake), each with the same rows and values, the
same Parquet schema (with its field metadata) and the same key-value metadata (the time grid
record). Database (the published snapshot): ``edge_fits`` and each view of ``sql/``, rows
sorted, with the columns that hold a time of the run itself (``*_at``, ``run_id``) left out, each
computed on one thread (with more, the views' sums differ in their last bits between two queries of
the same warehouse).
Prints one line per item and exits 1 on a difference.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import polars as pl
import pyarrow.parquet as pq

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from flows.common.lake import lake_root  # noqa: E402
from flows.common.warehouse_db import query_frame  # noqa: E402
from flows.report.views import connect_snapshot  # noqa: E402

RUN_COLUMNS = ("run_id", "monitored_at", "computed_at", "ingested_at", "fitted_at", "updated_at", "generated_at", "created_at", "checked_at", "started_at", "finished_at")
"""Columns that say when a run ran, not what it estimated."""


def lake_differences(a: Path, b: Path) -> list[str]:
    fa = {p.relative_to(lake_root(a)) for p in lake_root(a).rglob("*.parquet")}
    fb = {p.relative_to(lake_root(b)) for p in lake_root(b).rglob("*.parquet")}
    out = [f"lake file only in one: {sorted(map(str, fa ^ fb))}"] if fa != fb else []
    for rel in sorted(fa & fb):
        pa_, pb = lake_root(a) / rel, lake_root(b) / rel
        ma, mb = pq.ParquetFile(pa_), pq.ParquetFile(pb)
        if not ma.schema_arrow.equals(mb.schema_arrow, check_metadata=True):
            out.append(f"{rel}: Parquet schema differs")
        if ma.metadata.metadata != mb.metadata.metadata:
            out.append(f"{rel}: key-value metadata differs")
        if [ma.metadata.row_group(i).num_rows for i in range(ma.metadata.num_row_groups)] != [mb.metadata.row_group(i).num_rows for i in range(mb.metadata.num_row_groups)]:
            out.append(f"{rel}: row groups differ")
        if not pl.read_parquet(pa_).equals(pl.read_parquet(pb)):
            out.append(f"{rel}: rows or values differ")
    return out


def relations(con) -> list[str]:
    views = [r[0] for r in con.execute("SELECT view_name FROM duckdb_views() WHERE NOT internal ORDER BY view_name").fetchall()]
    return ["edge_fits", *views]


def table_frame(con, name: str) -> pl.DataFrame:
    df = query_frame(con, f"SELECT * FROM {name}")
    df = df.drop([c for c in df.columns if c in RUN_COLUMNS])
    return df.sort(df.columns, nulls_last=True) if df.height and df.width else df


def database_differences(a: Path, b: Path) -> tuple[list[str], list[str]]:
    ca, cb = connect_snapshot(a), connect_snapshot(b)
    for con in (ca, cb):  # DuckDB's parallel sums differ in their last bits from one query to the next
        con.execute("SET threads = 1")
    try:
        names = relations(ca)
        out = [f"relations differ: {sorted(set(names) ^ set(relations(cb)))}"] if set(names) != set(relations(cb)) else []
        same = []
        for name in names:
            x, y = table_frame(ca, name), table_frame(cb, name)
            if x.equals(y):
                same.append(f"{name} ({x.height} rows)")
            else:
                out.append(f"{name}: differs ({x.height} against {y.height} rows)")
        return out, same
    finally:
        ca.close()
        cb.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("before", type=Path)
    ap.add_argument("after", type=Path)
    args = ap.parse_args()
    lake = lake_differences(args.before, args.after)
    n_files = sum(1 for _ in lake_root(args.before).rglob("*.parquet"))
    db, same = database_differences(args.before, args.after)
    print(f"lake: {n_files} files, {'the same' if not lake else 'DIFFERENT'}")
    for line in lake + db:
        print("  " + line)
    print(f"database: {len(same)} relations the same: " + ", ".join(same))
    sys.exit(1 if lake or db else 0)


if __name__ == "__main__":
    main()
