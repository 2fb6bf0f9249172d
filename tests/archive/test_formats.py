"""Long CSV, wide CSV and Parquet (long and wide) hold the same values; same seed, same bytes."""

from __future__ import annotations

import gzip

import polars as pl
import pytest

from schemas.fields import SIGNALS

from .conftest import make_archive


def _long_from_wide(df: pl.DataFrame) -> pl.DataFrame:
    return df.unpivot(index="timestamp", variable_name="tag", value_name="value")


def _canon(df: pl.DataFrame) -> pl.DataFrame:
    ts = df["timestamp"]
    if ts.dtype == pl.String:
        ts = ts.str.to_datetime("%Y-%m-%dT%H:%M:%S%.6fZ", time_unit="us", time_zone="UTC")
    return df.select(ts.alias("timestamp"), pl.col("tag").cast(pl.String), pl.col("value").cast(pl.Float64)).sort("timestamp", "tag")


def _read_all(out, reader) -> pl.DataFrame:
    return pl.concat([reader(f) for f in sorted((out / "exports").iterdir())])


def test_long_wide_and_parquet_hold_the_same_values(long_gz, wide_csv, long_parquet, wide_parquet):
    csv = lambda f: pl.read_csv(f, infer_schema=False).with_columns(pl.exclude("timestamp", "tag", "quality").cast(pl.Float64))  # noqa: E731
    long_csv = _canon(_read_all(long_gz[0], csv))
    wide = _read_all(wide_csv[0], csv)
    assert wide.columns[0] == "timestamp" and len(wide.columns) == 1 + 2 * len(SIGNALS)
    assert wide["timestamp"].is_sorted()
    wide_csv_long = _canon(_long_from_wide(wide))
    long_pq = _canon(_read_all(long_parquet[0], pl.read_parquet))
    wide_pq = _canon(_long_from_wide(_read_all(wide_parquet[0], pl.read_parquet)))
    assert long_csv.height == 4 * 2 * 1500 * len(SIGNALS)
    for other in (wide_csv_long, long_pq, wide_pq):
        assert long_csv.equals(other)
    # every archive of the same plant and seed records the same truth
    t = pl.read_parquet(long_gz[0] / "truth.parquet")
    for arch in (wide_csv, long_parquet, wide_parquet):
        assert t.equals(pl.read_parquet(arch[0] / "truth.parquet"))


def test_gzip_file_is_valid_gzip(long_gz):
    f = sorted((long_gz[0] / "exports").iterdir())[0]
    with gzip.open(f, "rt") as fh:
        assert fh.readline() == "timestamp,tag,value,quality\n"
        rows = sum(1 for _ in fh)
    assert rows == 1 * 2 * 1500 * len(SIGNALS)  # one window on the first day


@pytest.mark.parametrize("file_format, gz", [("csv", True), ("parquet", False)])
def test_same_seed_same_bytes_other_seed_other_data(tmp_path, file_format, gz):
    make_archive(tmp_path / "a", file_format=file_format, gzip=gz, seed=5)
    make_archive(tmp_path / "b", file_format=file_format, gzip=gz, seed=5)
    make_archive(tmp_path / "c", file_format=file_format, gzip=gz, seed=6)
    names = sorted(p.relative_to(tmp_path / "a") for p in (tmp_path / "a").rglob("*") if p.is_file())
    assert len(names) == 2 + 3
    assert names == sorted(p.relative_to(tmp_path / "b") for p in (tmp_path / "b").rglob("*") if p.is_file())
    for n in names:
        assert (tmp_path / "a" / n).read_bytes() == (tmp_path / "b" / n).read_bytes(), n
        if n.parts[0] == "exports" or n.name == "truth.parquet":  # the seed changes data and scatter
            assert (tmp_path / "a" / n).read_bytes() != (tmp_path / "c" / n).read_bytes(), n
    assert (tmp_path / "a" / "plant.toml").read_bytes() == (tmp_path / "c" / "plant.toml").read_bytes()


def test_worker_processes_write_the_same_archive(tmp_path, long_gz):
    """Windows are seeded by (seed, valve, start): batching and processes do not matter."""
    make_archive(tmp_path, gzip=True, workers=1, batch_samples=1500)  # one window per call, 2 in flight
    for f in sorted((long_gz[0] / "exports").iterdir()):
        assert (tmp_path / "exports" / f.name).read_bytes() == f.read_bytes(), f.name
    assert (tmp_path / "truth.parquet").read_bytes() == (long_gz[0] / "truth.parquet").read_bytes()
