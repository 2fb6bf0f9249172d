"""plant.toml describes the archive and reads back as the configuration used; truth.parquet
is the model's condition over operating hours."""

from __future__ import annotations

from datetime import timedelta

import numpy as np
import polars as pl
import pytest

from flows.common.config import load_plant_config
from flows.simulate.archive import (
    ArchivePlan,
    generate_plant_config,
    parse_scenario,
    resolve_scenarios,
    scatter_seed,
    with_scenarios,
    write_archive,
)
from model import condition as mcond
from model.params import EDGES
from schemas.plant_config import ValveDesign

from .conftest import PLAN, SCENARIOS, SEED

FIXTURE = "tests/fixtures/plant_example.toml"


def test_plant_toml_is_the_config_used(long_gz):
    out, config, _ = long_gz
    written = load_plant_config(out / "plant.toml")
    assert written == with_scenarios(config, SCENARIOS)
    assert {v.id: v.scenario for v in written.valves} == SCENARIOS
    assert written.export.layout == "long" and written.export.quality_column == "quality"
    d = written.valve_types["servo_4w"]
    assert d == ValveDesign(3.5e-3, 10.0e-3, 9.99e-3, d.taper_angle_port1_rad, d.taper_angle_port2_rad, (4e-5,) * 4, 0.675)


def test_configured_plant_round_trip_and_rerun(tmp_path):
    """--config: the plant's own layout and units; plant.toml re-runs to the same archive."""
    config = load_plant_config(FIXTURE)
    start = config.valves[0].commissioned + timedelta(hours=100)  # 2025-03-05 04:00; one window at 12:00
    plan = ArchivePlan(start, start + timedelta(hours=12), 2, 1.0)
    scenarios = resolve_scenarios(config, "wear", {"V017": "broken_edge:s2@120"})
    write_archive(config, tmp_path / "a", plan, scenarios, seed=3)
    written = load_plant_config(tmp_path / "a" / "plant.toml")
    assert written == with_scenarios(config, {"V017": "broken_edge:s2@120"})
    # the scenario keys make plant.toml reproduce the archive
    write_archive(written, tmp_path / "b", plan, resolve_scenarios(written, None, {}), seed=3)
    fa = sorted((tmp_path / "a" / "exports").iterdir())
    fb = sorted((tmp_path / "b" / "exports").iterdir())
    assert [f.name for f in fa] == [f.name for f in fb] == ["MILL1_2025-03-05.csv"]
    assert fa[0].read_bytes() == fb[0].read_bytes()
    assert (tmp_path / "a" / "truth.parquet").read_bytes() == (tmp_path / "b" / "truth.parquet").read_bytes()
    df = pl.read_csv(fa[0])
    assert set(df["tag"].unique()) == set(config.tag_index())


def test_truth_follows_the_condition_model(long_gz):
    out, config, _ = long_gz
    truth = pl.read_parquet(out / "truth.parquet")
    starts = [int(s) for _, st in PLAN.days() for s in st]
    assert truth.height == 2 * len(EDGES) * len(starts)
    assert truth.schema["window_start"] == pl.Datetime("us", "UTC")
    for vid, spec in SCENARIOS.items():
        valve = config.valve(vid)
        t = truth.filter(pl.col("valve_id") == vid).sort("window_start", maintain_order=True)
        assert t["scenario"].unique().to_list() == [spec]
        since = (t["window_start"] - valve.commissioned).dt.total_microseconds().to_numpy() / 3.6e9
        np.testing.assert_allclose(t["operating_hours"].to_numpy(), since)
        np.testing.assert_allclose(t["operating_hours"].to_numpy()[:: len(EDGES)], [12, 24, 36, 48])
        assert t["edge"].to_list() == list(EDGES) * 4
        base = mcond.ValveCondition(valve.design.underlap_m, (valve.design.contraction_coefficient,) * 4)
        scen = parse_scenario(spec, scatter_seed=scatter_seed(SEED, vid), x_max_m=valve.design.x_max_m)
        xu, al = mcond.condition_arrays(scen, [12, 24, 36, 48], base)
        new = mcond.manufactured(base, scatter_seed(SEED, vid))
        np.testing.assert_allclose(t["underlap_m"].to_numpy().reshape(4, 4), xu, rtol=1e-12)
        np.testing.assert_allclose(t["alpha"].to_numpy().reshape(4, 4), al, rtol=1e-12)
        np.testing.assert_allclose(t["alpha_rel"].to_numpy().reshape(4, 4), al / np.asarray(new.alpha), rtol=1e-12)
        dx = xu - np.asarray(new.underlap_m)
        np.testing.assert_allclose(t["underlap_change_m"].to_numpy().reshape(4, 4), dx, rtol=1e-9, atol=1e-15)
        np.testing.assert_allclose(t["x_hat_pct"].to_numpy().reshape(4, 4), dx / 3.5e-3 * 100, rtol=1e-9, atol=1e-12)
        # the manufacturing scatter makes valves differ from the design and from each other
        assert not np.allclose(np.asarray(new.alpha), 0.675)
    v1 = truth.filter(pl.col("valve_id") == "V001")
    assert (v1["alpha_rel"] > 1).all() and (v1["underlap_change_m"] > 0).all()  # wear
    v2 = truth.filter((pl.col("valve_id") == "V002") & (pl.col("edge") == "1r")).sort("window_start")
    assert v2["broken"].to_list() == [False, False, True, True]
    np.testing.assert_allclose(v2["alpha_rel"].to_numpy(), [1, 1, 2.5, 2.5], rtol=1e-12)
    np.testing.assert_allclose(v2["x_hat_pct"].to_numpy(), [0, 0, 11.8, 11.8], atol=1e-9)
    other = truth.filter((pl.col("valve_id") == "V002") & (pl.col("edge") != "1r"))
    assert not other["broken"].any() and np.allclose(other["alpha_rel"].to_numpy(), 1.0)


@pytest.mark.parametrize(
    "spec, name, edge, hours",
    [("healthy", "healthy", None, 0.0), ("wear", "wear", None, 0.0), ("broken_edge", "broken_edge", "1r", 0.0), ("broken_edge:s2@4000", "broken_edge", "s2", 4000.0)],
)
def test_scenario_names(spec, name, edge, hours):
    s = parse_scenario(spec)
    assert (s.name, s.broken_edge, s.broken_from_h) == (name, edge, hours)


@pytest.mark.parametrize("spec", ["broken", "wear:s1", "broken_edge:x9", "healthy@3", "broken_edge@-1"])
def test_bad_scenario_names(spec):
    with pytest.raises(ValueError, match="scenario"):
        parse_scenario(spec)


def test_generated_plant_matches_the_spec_example():
    example = load_plant_config(FIXTURE)
    gen = generate_plant_config("MILL1", 2)
    assert gen.valve_types["servo_4w"] == example.valve_types["servo_4w"]
    v, e = gen.valves[1], example.valves[0]
    assert v.id == "V002" and v.tags["x_ref"].tag == "MILL1.V002.XREF" and v.tags["p1"].unit == "bar"
    for k in ("piston_diameter_m", "rod_diameter_m", "stroke_m", "v01_m3", "v02_m3", "bulk_modulus_pa", "density_kg_m3"):
        assert getattr(v, k) == pytest.approx(getattr(e, k)), k
