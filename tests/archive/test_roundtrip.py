"""The exported samples are what the simulator and the sensor model produced, in the tags' units.

The expected values are recomputed here from the model's public API -- the window's condition
as recorded in truth.parquet, the window's inputs and sensor noise from its documented seed --
and compared with the files as polars reads them (no ingest code involved).
"""

from __future__ import annotations

import re
from datetime import datetime, timezone

import numpy as np
import polars as pl

from flows.simulate.archive import TAG_SUFFIX, plant_params_for_valve, window_rng
from flows.simulate.writers import decimals_for_step
from model.params import EDGES, ValveCondition
from model.sensors import measure
from model.simulate import simulate_inputs
from model.trajectory import window_inputs
from schemas.fields import SIGNAL_KIND, SIGNALS
from schemas.units import si_factor

from .conftest import PLAN, SEED

SIGNAL_ATTR = {s: s for s in SIGNALS}


def _expected(config, valve_id: str, start_us: int, truth: pl.DataFrame) -> dict[str, np.ndarray]:
    """SI readings of one window, recomputed from the truth's condition and the window's seed."""
    valve = config.valve(valve_id)
    params = plant_params_for_valve(valve, config.export)
    rows = truth.filter((pl.col("valve_id") == valve_id) & (pl.col("window_start").dt.epoch("us") == start_us))
    assert rows["edge"].to_list() == list(EDGES)
    cond = ValveCondition(tuple(rows["underlap_m"]), tuple(rows["alpha"]), params.nominal_condition.x_l_fraction)
    rng = window_rng(SEED, valve_id, start_us)
    result = simulate_inputs(params, [cond], [window_inputs(params, PLAN.window_s, rng)])
    m = measure(result, params.sensors, rng)
    return {s: np.asarray(getattr(m, SIGNAL_ATTR[s]))[0] for s in SIGNALS}


def _window_starts() -> list[int]:
    return [int(s) for _, starts in PLAN.days() for s in starts]


def test_long_csv_gz_round_trip(long_gz):
    out, config, summary = long_gz
    files = sorted((out / "exports").iterdir())
    assert [f.name for f in files] == ["T1_2025-01-01.csv.gz", "T1_2025-01-02.csv.gz", "T1_2025-01-03.csv.gz"]
    df = pl.concat([pl.read_csv(f, schema_overrides={"timestamp": pl.String, "value": pl.Float64}) for f in files])
    assert df.columns == ["timestamp", "tag", "value", "quality"]
    assert df.height == summary.rows == 2 * 4 * PLAN.n_samples * len(SIGNALS)
    iso = re.compile(r"^\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{6}Z$")
    assert all(iso.match(t) for t in df["timestamp"].unique().to_list())
    assert df["quality"].unique().to_list() == ["Good"]
    df = df.with_columns(t=pl.col("timestamp").str.to_datetime("%Y-%m-%dT%H:%M:%S%.6fZ", time_unit="us").dt.epoch("us"))
    # rows in time order; within a time stamp valve by valve, signal by signal
    assert df["t"].diff().drop_nulls().min() >= 0
    tags = [config.valve(v).tags[s].tag for v in ("V001", "V002") for s in SIGNALS]
    assert df["tag"].head(len(tags)).to_list() == tags
    truth = pl.read_parquet(out / "truth.parquet")
    starts = _window_starts()
    assert sorted(df["t"].unique().to_list()) == sorted(s + k * PLAN.period_us for s in starts for k in range(PLAN.n_samples))
    for vid in ("V001", "V002"):
        valve = config.valve(vid)
        for start in starts:
            expected = _expected(config, vid, start, truth)
            for s in SIGNALS:
                tag = valve.tags[s].tag
                assert tag == f"T1.{vid}.{TAG_SUFFIX[s]}"
                got = (
                    df.filter((pl.col("tag") == tag) & (pl.col("t") >= start) & (pl.col("t") < start + PLAN.n_samples * PLAN.period_us))
                    .sort("t")["value"]
                    .to_numpy()
                )
                f = si_factor(valve.tags[s].unit, SIGNAL_KIND[s], valve.design.x_max_m)
                ch = getattr(plant_params_for_valve(valve, config.export).sensors, s)
                d = decimals_for_step(ch.step / f, ch.noise_std / f)
                # exactly the documented rounding of the unit-converted reading ...
                np.testing.assert_array_equal(got, np.round(expected[s] / f, d), err_msg=f"{vid} {s} {start}")
                # ... which keeps the quantisation resolution: error <= 1/20 of a step
                assert np.max(np.abs(got * f - expected[s])) <= ch.step / 20 * (1 + 1e-9), (vid, s)


def test_quantisation_levels_survive_the_csv(long_gz):
    """Distinct quantised readings stay distinct in the file, and no level is invented."""
    out, config, _ = long_gz
    df = pl.read_csv(out / "exports" / "T1_2025-01-02.csv.gz", schema_overrides={"value": pl.Float64})
    valve = config.valve("V001")
    for s in ("p1", "pr", "x_spool", "x_cyl"):
        ch = getattr(plant_params_for_valve(valve, config.export).sensors, s)
        f = valve.si_factor(s)
        v = df.filter(pl.col("tag") == valve.tags[s].tag)["value"].to_numpy() * f
        levels = (v - ch.lo) / ch.step
        # readings sit on the quantisation grid to within 1/20 step after the round trip
        assert np.max(np.abs(levels - np.round(levels))) <= 0.05 + 1e-9, s
        assert np.unique(np.round(levels)).size == np.unique(v).size, s


def test_archive_timestamps_are_window_grid(long_parquet):
    out, config, summary = long_parquet
    df = pl.read_parquet(out / "exports" / "T1_2025-01-01.parquet")
    assert df.schema["timestamp"] == pl.Datetime("us", "UTC")
    assert df["timestamp"].min() == datetime(2025, 1, 1, 12, tzinfo=timezone.utc)
    assert df["timestamp"].dt.date().unique().to_list() == [datetime(2025, 1, 1).date()]


def test_configured_units_layout_and_separators(tmp_path):
    """A plant with psi, Pa, %, m and um tags, no x_ref, wide layout, ';' and ',' and epoch_ms."""
    import tomllib
    from datetime import timedelta

    from flows.common.config import load_plant_config
    from flows.simulate.archive import ArchivePlan, resolve_scenarios, write_archive
    from schemas.plant_config import parse_plant_config

    with open("tests/fixtures/plant_example.toml", "rb") as fh:
        raw = tomllib.load(fh)
    raw["export"] = {"layout": "wide", "timestamp_column": "t_ms", "timestamp_format": "epoch_ms", "separator": ";", "decimal": ","}
    tags = raw["valves"][0]["tags"]
    del tags["x_ref"]
    units = {"ps": "psi", "pr": "Pa", "p1": "MPa", "p2": "kPa", "x_spool": "%", "x_cyl": "um"}
    for s, u in units.items():
        tags[s]["unit"] = u
    config = parse_plant_config(raw)
    start = config.valves[0].commissioned + timedelta(days=3)
    plan = ArchivePlan(start, start + timedelta(hours=1), 24, 0.5)
    write_archive(config, tmp_path, plan, resolve_scenarios(config, "broken_edge", {}), seed=2)
    assert load_plant_config(tmp_path / "plant.toml").valves[0].tags == config.valves[0].tags
    (f,) = (tmp_path / "exports").iterdir()
    assert f.name == "MILL1_2025-03-04.csv"
    text = f.read_text()
    assert text.splitlines()[0] == "t_ms;" + ";".join(config.valves[0].tags[s].tag for s in units)
    df = pl.read_csv(f, separator=";", decimal_comma=True)
    assert df["t_ms"].to_list() == [int(start.timestamp() * 1000) + k for k in range(500)]
    truth = pl.read_parquet(tmp_path / "truth.parquet")
    valve = config.valves[0]
    params = plant_params_for_valve(valve, config.export)
    cond = ValveCondition(tuple(truth["underlap_m"]), tuple(truth["alpha"]), params.nominal_condition.x_l_fraction)
    start_us = int(start.timestamp()) * 1_000_000
    rng = window_rng(2, "V017", start_us)
    m = measure(simulate_inputs(params, [cond], [window_inputs(params, 0.5, rng)]), params.sensors, rng)
    for s, u in units.items():
        f_si = si_factor(u, SIGNAL_KIND[s], valve.design.x_max_m)
        ch = getattr(params.sensors, s)
        d = decimals_for_step(ch.step / f_si, ch.noise_std / f_si)
        np.testing.assert_array_equal(df[valve.tags[s].tag].to_numpy(), np.round(getattr(m, s)[0] / f_si, d), err_msg=s)
    assert truth["edge"].to_list() == list(EDGES) and truth["broken"].to_list() == [False, True, False, False]
