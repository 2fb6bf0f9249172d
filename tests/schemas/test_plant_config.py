"""The plant configuration: the spec's example is accepted as written, broken ones are named."""

import copy
import math
import re
import tomllib
from datetime import datetime, timezone
from pathlib import Path

import pytest
import tomli_w

from flows.common.config import load_plant_config
from schemas.plant_config import ConfigError, parse_plant_config, plant_config_to_dict

EXAMPLE = Path(__file__).parents[1] / "fixtures" / "plant_example.toml"


@pytest.fixture
def raw() -> dict:
    return tomllib.loads(EXAMPLE.read_text())


def test_example_is_accepted_in_si():
    cfg = load_plant_config(EXAMPLE)
    v = cfg.valve("V017")
    assert cfg.name == "MILL1" and cfg.timezone == "Europe/Vienna"
    assert cfg.export.good_quality == ("Good", "192")
    assert v.design.x_max_m == pytest.approx(3.5e-3)
    assert v.design.underlap_m == pytest.approx((4e-5,) * 4)
    assert v.design.taper_angle_rad("1r") == pytest.approx(math.radians(10.48))
    assert v.design.taper_angle_rad("s2") == pytest.approx(math.radians(5.24))
    assert v.piston_area_m2 == pytest.approx(math.pi * 0.14**2 / 4)
    assert v.annulus_area_m2 == pytest.approx(math.pi * (0.14**2 - 0.1**2) / 4)
    assert v.v02_m3 == pytest.approx(7.1e-3) and v.bulk_modulus_pa == pytest.approx(1.5e9)
    assert v.commissioned == datetime(2025, 3, 1, tzinfo=timezone.utc)
    assert v.si_factor("p1") == 1e5 and v.si_factor("x_cyl") == 1e-3
    assert cfg.tag_index()["MILL1.V017.XREF"] == ("V017", "x_ref")


@pytest.mark.parametrize("export", [{}, {"max_bad_share": 0.2, "other_tags": "error"}])
def test_round_trip_through_toml_is_lossless(raw, tmp_path, export):
    raw["export"].update(export)
    cfg = parse_plant_config(raw)
    assert (cfg.export.max_bad_share, cfg.export.other_tags) == (export.get("max_bad_share", 0.05), export.get("other_tags", "ignore"))
    path = tmp_path / "plant.toml"
    path.write_bytes(tomli_w.dumps(plant_config_to_dict(cfg)).encode())
    assert load_plant_config(path) == cfg


def test_valve_overrides_its_type(raw):
    raw["valves"][0]["underlap_mm"] = {"1r": 0.06}
    raw["valves"][0]["contraction_coefficient"] = 0.7
    v = parse_plant_config(raw).valve("V017")
    assert v.design.underlap_m == pytest.approx((4e-5, 6e-5, 4e-5, 4e-5))
    assert v.design.contraction_coefficient == 0.7
    assert parse_plant_config(raw).valve_types["servo_4w"].contraction_coefficient == 0.675


def test_valve_family_per_type_defaults_and_round_trips(raw, tmp_path):
    assert parse_plant_config(raw).valve("V017").design.area_law == "eq3"
    assert parse_plant_config(raw).valve("V017").design.leakage_factor == 1.0
    raw["valve_types"]["sharp_4w"] = copy.deepcopy(raw["valve_types"]["servo_4w"]) | {"area_law": "sharp"}
    raw["valve_types"]["servo_4w"]["leakage_factor"] = 4.0
    cfg = parse_plant_config(raw)
    assert (cfg.valve_types["sharp_4w"].area_law, cfg.valve_types["sharp_4w"].leakage_factor) == ("sharp", 1.0)
    assert (cfg.valve("V017").design.area_law, cfg.valve("V017").design.leakage_factor) == ("eq3", 4.0)
    path = tmp_path / "plant.toml"
    path.write_bytes(tomli_w.dumps(plant_config_to_dict(cfg)).encode())
    assert load_plant_config(path) == cfg
    raw["valve_types"]["sharp_4w"]["leakage_factor"] = 2.0
    with pytest.raises(ConfigError, match=r"valve_types.sharp_4w.leakage_factor: 2 needs area_law = \"eq3\""):
        parse_plant_config(raw)


def test_naive_commissioning_time_is_plant_local(raw):
    raw["valves"][0]["commissioned"] = "2025-07-01T02:00:00"
    v = parse_plant_config(raw).valve("V017")
    assert v.commissioned == datetime(2025, 7, 1, 0, 0, tzinfo=timezone.utc)  # CEST = UTC+2


def _set(d: dict, path: str, value) -> None:
    *parents, last = path.split(".")
    for p in parents:
        d = d[int(p)] if p.isdigit() else d[p]
    if value is _DELETE:
        del d[last]
    else:
        d[last] = value


_DELETE = object()


@pytest.mark.parametrize(
    "path, value, message",
    [
        ("plant.colour", "red", "plant.colour: unknown key"),
        ("export.layout", "tall", "export.layout: 'tall' is not one of"),
        ("valves.0.v01_l", -3.0, "valves[0].v01_l: -3.0 must be > 0"),
        ("valves.0.v02_l", 4.0, "valves[0].v02_l: 4 L must exceed the rod-side stroke volume"),
        ("valves.0.tags.p1.unit", "bars", "valves[0].tags.p1.unit: unknown pressure unit 'bars'"),
        ("valves.0.tags.p2.tag", "MILL1.V017.P1", "valves[0].tags.p2.tag: tag 'MILL1.V017.P1' is used twice"),
        ("valves.0.tags.x_cyl", _DELETE, "valves[0].tags.x_cyl: missing required signal"),
        ("valves.0.id", "V 17", "valves[0].id: 'V 17' may hold only letters"),
        ("valves.0.type", "servo_3w", "valves[0].type: unknown valve type 'servo_3w'"),
        ("valves.0.density_kg_m3", _DELETE, "valves[0].density_kg_m3: missing required key"),
        ("valves.0.rod_diameter_mm", 150, "valves[0].rod_diameter_mm: the rod must be thinner"),
        ("valve_types.servo_4w.underlap_mm", {"s1": 4.0, "1r": 0.04, "s2": 0.04, "2r": 0.04}, "valve_types.servo_4w.underlap_mm.s1: an underlap of 4 mm is not smaller than the stroke"),
        ("valve_types.servo_4w.spool_radius_mm", 10.5, "spool radius must be smaller than the bore radius"),
        ("plant.timezone", "Mars/Olympus", "plant.timezone: 'Mars/Olympus' is not an IANA time zone"),
        ("valves.0.commissioned", "yesterday", "valves[0].commissioned: 'yesterday' is not an ISO-8601"),
        ("valves.0.tags.x_spool.unit", "%", None),
        ("valves.0.tags.x_cyl.unit", "%", "valves[0].tags.x_cyl.unit: unknown position unit '%'"),
        ("export.good_quality", _DELETE, "export.good_quality: missing required key"),
        ("export.max_bad_share", 0, "export.max_bad_share: 0 must be > 0"),
        ("export.max_bad_share", 1.5, "export.max_bad_share: 1.5 must be <= 1"),
        ("export.max_bad_share", "5%", "export.max_bad_share: expected a finite number, got '5%'"),
        ("export.max_bad_share", 1, None),
        ("export.other_tags", "skip", "export.other_tags: 'skip' is not one of 'ignore', 'error'"),
        ("export.other_tags", "error", None),
        ("valve_types.servo_4w.area_law", "round", "valve_types.servo_4w.area_law: 'round' is not one of 'eq3', 'sharp'"),
        ("valve_types.servo_4w.leakage_factor", 0, "valve_types.servo_4w.leakage_factor: 0 must be > 0"),
        ("valves.0.area_law", 3, "valves[0].area_law: expected a non-empty string, got 3"),
    ],
)
def test_broken_configurations_name_the_key(raw, path, value, message):
    broken = copy.deepcopy(raw)
    _set(broken, path, value)
    if message is None:
        parse_plant_config(broken)
        return
    with pytest.raises(ConfigError) as err:
        parse_plant_config(broken)
    assert message in str(err.value)


def test_duplicate_valve_id(raw):
    raw["valves"].append(copy.deepcopy(raw["valves"][0]))
    for s, t in raw["valves"][1]["tags"].items():
        t["tag"] = t["tag"].replace("V017", "V018")
    with pytest.raises(ConfigError, match=r"valves\[1\]\.id: 'V017' is used twice"):
        parse_plant_config(raw)


def test_file_errors_name_the_file(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[plant\nname = 1")
    with pytest.raises(ConfigError, match="bad.toml: not valid TOML"):
        load_plant_config(bad)
    with pytest.raises(ConfigError, match="missing.toml: no such configuration file"):
        load_plant_config(tmp_path / "missing.toml")


# --- [valve_types.NAME.bounds] and [valves.bounds] ------------------------------------------


def test_bounds_default_when_absent(raw):
    from schemas.plant_config import ConditionBounds

    cfg = parse_plant_config(raw)
    b = cfg.valve("V017").design.bounds
    assert b == ConditionBounds()
    # the paper's faulty edge (Table 2) is beyond every fault bound; its normal valve and the
    # worn edge after 16,700 h (Table 3) are inside every wear bound
    assert 2.53 > b.alpha_fault_high and 11.8 > b.x_hat_pct_fault_high and 1.13 > b.e_mm2_fault_high
    for alpha, x_pct, e in ((0.98, 0.23, 0.10), (1.17, 3.7, 0.18), (1.04, 0.1, 0.32)):
        assert b.alpha_wear_low < alpha < b.alpha_wear_high
        assert b.x_hat_pct_wear_low < x_pct < b.x_hat_pct_wear_high
        assert e < b.e_mm2_wear_high


def test_bounds_per_type_and_valve_override(raw, tmp_path):
    raw["valve_types"]["servo_4w"]["bounds"] = {"alpha_wear_high": 1.25, "change_z": 5, "trend_min_fits": 6, "eq9_expected": -0.2}
    raw["valves"][0]["bounds"] = {"x_hat_pct_wear_high": 5.0}
    cfg = parse_plant_config(raw)
    b = cfg.valve("V017").design.bounds
    assert (b.alpha_wear_high, b.change_z, b.trend_min_fits, b.x_hat_pct_wear_high, b.eq9_expected) == (1.25, 5.0, 6, 5.0, -0.2)
    assert cfg.valve_types["servo_4w"].bounds.x_hat_pct_wear_high == 6.0
    path = tmp_path / "plant.toml"
    written = plant_config_to_dict(cfg)
    assert written["valves"][0]["bounds"] == {"x_hat_pct_wear_high": 5.0}
    assert written["valve_types"]["servo_4w"]["bounds"]["alpha_wear_high"] == 1.25
    path.write_bytes(tomli_w.dumps(written).encode())
    assert load_plant_config(path) == cfg


def test_bounds_round_trip_keeps_an_override_equal_to_its_type(raw, tmp_path):
    raw["valves"][0]["bounds"] = {"alpha_wear_high": 1.30}  # same as the default
    cfg = parse_plant_config(raw)
    path = tmp_path / "plant.toml"
    path.write_bytes(tomli_w.dumps(plant_config_to_dict(cfg)).encode())
    assert load_plant_config(path) == cfg


@pytest.mark.parametrize(
    "bounds, message",
    [
        ({"colour": 1}, "valve_types.servo_4w.bounds.colour: unknown key"),
        ({"alpha_wear_high": 2.0}, "valve_types.servo_4w.bounds.alpha_fault_high: 1.8 must be >= alpha_wear_high = 2"),
        ({"alpha_wear_low": 1.1}, "valve_types.servo_4w.bounds.alpha_wear_low: the wear bounds of alpha must enclose 1"),
        ({"x_hat_pct_wear_high": -1.0}, "valve_types.servo_4w.bounds.x_hat_pct_wear_high: the wear bounds of x_hat_pct must enclose 0"),
        ({"x_hat_pct_wear_high": -6.0}, "valve_types.servo_4w.bounds.x_hat_pct_wear_high: -6 must be > x_hat_pct_wear_low = -5"),
        ({"e_mm2_wear_high": 0.9}, "valve_types.servo_4w.bounds.e_mm2_fault_high: 0.8 must be >= e_mm2_wear_high"),
        ({"change_history_windows": 4.5}, "valve_types.servo_4w.bounds.change_history_windows: expected an integer"),
        ({"change_min_history": 30}, "change_min_history: 30 must be <= change_history_windows = 24"),
        ({"e_mm2_sigma_floor": -0.1}, "valve_types.servo_4w.bounds.e_mm2_sigma_floor: -0.1 must be > 0"),
        ({"x_hat_pct_sigma_floor": 0}, "x_hat_pct_sigma_floor: 0 must be > 0"),
        ({"trend_min_span_hours": 9000.0}, "trend_min_span_hours: 9000 must be <= trend_span_hours"),
        ({"change_z": "six"}, "valve_types.servo_4w.bounds.change_z: expected a finite number"),
        ({"trend_min_fits": 4}, "valve_types.servo_4w.bounds.trend_min_fits: 4 must be >= 5"),
        ("strict", "valve_types.servo_4w.bounds: expected a table"),
    ],
)
def test_broken_bounds_name_the_key(raw, bounds, message):
    raw["valve_types"]["servo_4w"]["bounds"] = bounds
    with pytest.raises(ConfigError) as err:
        parse_plant_config(raw)
    assert message in str(err.value)


def test_valve_bounds_errors_name_the_valve(raw):
    raw["valves"][0]["bounds"] = {"alpha_fault_low": 0.9}
    with pytest.raises(ConfigError, match=r"valves\[0\]\.bounds\.alpha_wear_low: 0\.8 must be >= alpha_fault_low = 0\.9"):
        parse_plant_config(raw)


def test_retention_is_off_unless_configured_and_round_trips(raw, tmp_path):
    assert parse_plant_config(raw).retention is None
    raw["retention"] = {"keep_days": 30}
    r = parse_plant_config(raw).retention
    assert (r.keep_days, r.mode, r.thin_keep_s_per_hour) == (30, "thin", 10.0)
    for table in ({"keep_days": 7, "mode": "drop"}, {"keep_days": 90, "mode": "thin", "thin_keep_s_per_hour": 2.5}):
        raw["retention"] = table
        cfg = parse_plant_config(raw)
        path = tmp_path / "plant.toml"
        path.write_bytes(tomli_w.dumps(plant_config_to_dict(cfg)).encode())
        assert load_plant_config(path) == cfg and tomllib.loads(path.read_text())["retention"] == table | ({"thin_keep_s_per_hour": 2.5} if table["mode"] == "thin" else {})


def test_lake_codec_defaults_to_none_is_chosen_and_round_trips(raw, tmp_path):
    assert parse_plant_config(raw).lake.codec == "none"
    path = tmp_path / "plant.toml"
    path.write_bytes(tomli_w.dumps(plant_config_to_dict(parse_plant_config(raw))).encode())
    assert "lake" not in tomllib.loads(path.read_text())  # the default is not written back
    raw["lake"] = {"codec": "lz4"}
    cfg = parse_plant_config(raw)
    path.write_bytes(tomli_w.dumps(plant_config_to_dict(cfg)).encode())
    assert cfg.lake.codec == "lz4" and load_plant_config(path) == cfg and tomllib.loads(path.read_text())["lake"] == {"codec": "lz4"}
    for table, message in (({"codec": "gzip"}, "lake.codec: 'gzip' is not one of 'none', 'lz4', 'zstd'"),
                           ({"codec": "lz4", "level": 3}, "lake.level: unknown key"), ("lz4", "lake: expected a table")):
        raw["lake"] = table
        with pytest.raises(ConfigError, match=re.escape(message)):
            parse_plant_config(raw)


@pytest.mark.parametrize(
    "table, message",
    [
        ({}, "retention.keep_days: missing required key"),
        ({"keep_days": 0}, "retention.keep_days: expected a whole number of days >= 1, got 0"),
        ({"keep_days": 1.5}, "retention.keep_days: expected a whole number of days >= 1, got 1.5"),
        ({"keep_days": True}, "retention.keep_days: expected a whole number"),
        ({"keep_days": 9, "mode": "delete"}, "retention.mode: 'delete' is not one of 'thin', 'drop'"),
        ({"keep_days": 9, "mode": "drop", "thin_keep_s_per_hour": 10}, "retention.thin_keep_s_per_hour: only used with mode = 'thin'"),
        ({"keep_days": 9, "thin_keep_s_per_hour": 0}, "retention.thin_keep_s_per_hour: 0 must be > 0"),
        ({"keep_days": 9, "thin_keep_s_per_hour": 3600}, "retention.thin_keep_s_per_hour: 3600 must be < 3600"),
        ({"keep_days": 9, "keep_hours": 3}, "retention.keep_hours: unknown key"),
        ("90 days", "retention: expected a table"),
    ],
)
def test_broken_retention_names_the_key(raw, table, message):
    raw["retention"] = table
    with pytest.raises(ConfigError) as err:
        parse_plant_config(raw)
    assert message in str(err.value)


# --- [monitor] window_s ------------------------------------------------------------------------


def test_monitor_window_default_and_round_trip(raw, tmp_path):
    from schemas.plant_config import DEFAULT_WINDOW_S

    assert parse_plant_config(raw).monitor.window_s == DEFAULT_WINDOW_S
    assert "monitor" not in plant_config_to_dict(parse_plant_config(raw))  # the default is not written
    raw["monitor"] = {"window_s": 300, "window_rows": 0}
    cfg = parse_plant_config(raw)
    assert cfg.monitor.window_s == 300.0
    assert cfg.monitor.window_rows == 0
    path = tmp_path / "plant.toml"
    path.write_bytes(tomli_w.dumps(plant_config_to_dict(cfg)).encode())
    assert load_plant_config(path) == cfg


@pytest.mark.parametrize(
    "monitor, message",
    [
        ({"window_s": 0}, "monitor.window_s: 0 must be >= 1"),
        ({"window_s": 7}, "monitor.window_s: 7 s does not divide a day"),
        ({"window_s": 172_800}, "monitor.window_s: 172800 must be <= 86400"),
        ({"window_s": "1 min"}, "monitor.window_s: expected a finite number"),
        ({"window": 60}, "monitor.window: unknown key"),
        ({"window_rows": 500}, "monitor.window_rows: expected 0 (every row) or a whole number >= 1000, got 500"),
        ({"window_rows": 6000.5}, "monitor.window_rows: expected 0 (every row) or a whole number >= 1000"),
        ("60", "monitor: expected a table"),
    ],
)
def test_broken_monitor_window_names_the_key(raw, monitor, message):
    raw["monitor"] = monitor
    with pytest.raises(ConfigError) as err:
        parse_plant_config(raw)
    assert message in str(err.value)


# --- [valves.tolerances] (issue 17: nuisance priors of the discrepancy workflow) ------------


def test_tolerances_default_parse_and_round_trip(raw):
    from schemas.plant_config import ModelTolerances

    assert parse_plant_config(raw).valves[0].tolerances is None
    raw["valves"][0]["tolerances"] = {"underlap_um": 8, "friction_pct": 40}
    v = parse_plant_config(raw).valves[0]
    assert v.tolerances == ModelTolerances(underlap_m=8e-6, friction_rel=0.4)
    again = parse_plant_config(tomllib.loads(tomli_w.dumps(plant_config_to_dict(parse_plant_config(raw)))))
    assert again.valves[0].tolerances == v.tolerances


@pytest.mark.parametrize("value,message", [
    ({"friction_pct": -1}, r"valves\[0\]\.tolerances\.friction_pct: .*"),
    ({"underlap_um": 5000}, r"valves\[0\]\.tolerances\.underlap_um: .*"),
    ({"beta_pct": 5}, r"valves\[0\]\.tolerances\.beta_pct: unknown key \(expected one of alpha_pct"),
    ({"mass_pct": "two"}, r"valves\[0\]\.tolerances\.mass_pct: .*"),
])
def test_broken_tolerances_name_the_key(raw, value, message):
    raw["valves"][0]["tolerances"] = value
    with pytest.raises(ConfigError, match=message):
        parse_plant_config(raw)


def _wide(raw: dict, **export) -> dict:
    for k in ("tag_column", "value_column", "quality_column", "good_quality"):
        raw["export"].pop(k)
    raw["export"] |= {"layout": "wide"} | export
    return raw


def test_header_rows_default_one_tag_line_and_round_trip(raw, tmp_path):
    assert parse_plant_config(raw).export.header_rows == ("tag",)
    _wide(raw, header_rows=["skip", "tag", "name", "unit"], tdms_group="fast")
    del raw["valves"][0]["tags"]["p1"]["unit"]  # taken from the files' unit line
    config = parse_plant_config(raw)
    assert config.export.header_rows == ("skip", "tag", "name", "unit") and config.export.tdms_group == "fast"
    assert config.valves[0].tags["p1"].unit is None and math.isnan(config.valves[0].si_factor("p1"))
    assert config.valves[0].si_factor("p1", "psi") == pytest.approx(6894.757293168361)
    path = tmp_path / "p.toml"
    path.write_bytes(tomli_w.dumps(plant_config_to_dict(config)).encode())
    assert load_plant_config(path) == config


@pytest.mark.parametrize(
    "rows, layout, message",
    [
        (["tag", "units"], "wide", "export.header_rows[1]: 'units' is not one of 'tag', 'name', 'unit', 'skip'"),
        (["name", "unit"], "wide", "export.header_rows: needs one 'tag' line"),
        (["tag", "tag"], "wide", "export.header_rows: 'tag' may occur only once"),
        (["tag", "unit", "unit"], "wide", "export.header_rows: 'unit' may occur only once"),
        ([], "wide", "export.header_rows: expected a non-empty list"),
        ("tag", "wide", "export.header_rows: expected a non-empty list"),
        (["tag", "unit"], "long", "export.header_rows: header rows other than 'tag' are only for export.layout = 'wide'"),
    ],
)
def test_broken_header_rows_name_the_key(raw, rows, layout, message):
    if layout == "wide":
        _wide(raw)
    raw["export"]["header_rows"] = rows
    with pytest.raises(ConfigError, match=re.escape(message)):
        parse_plant_config(raw)


def test_a_unit_may_be_left_out_only_with_a_unit_line(raw):
    del raw["valves"][0]["tags"]["ps"]["unit"]
    with pytest.raises(ConfigError, match=re.escape("valves[0].tags.ps.unit: missing required key (it may be left out only when export.header_rows has a 'unit' line)")):
        parse_plant_config(raw)
