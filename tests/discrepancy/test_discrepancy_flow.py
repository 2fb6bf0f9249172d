"""``valvemon discrepancy`` end to end: a warehouse whose lake holds a valve with a hidden effect,
the flow (its function, as a command runs it without a Prefect API), the warehouse tables and the overlay pictures; the command line's checks."""

from datetime import datetime, timedelta, timezone
from pathlib import Path

import duckdb
import polars as pl
import pytest
from typer.testing import CliRunner

from flows.cli import app
from flows.common.errors import ValvemonError
from flows.common.lake import partition_path, write_partition
from flows.common.warehouse_db import db_path
from flows.discrepancy.flow import DISCREPANCY_TABLES, discrepancy_flow, plant_params_for
from model.effects import Effects
from schemas.fields import DISCREPANCY_FINDING_FIELDS
from schemas.plant_config import ConfigError

from .simdata import simulate_lake

FIXTURE = Path(__file__).resolve().parents[1] / "fixtures" / "plant_example.toml"
VALVE = "V017"
START = datetime(2025, 3, 2, tzinfo=timezone.utc)


def _write_lake(warehouse: Path, frame: pl.DataFrame) -> None:
    for (day,), part in frame.partition_by("date", as_dict=True).items():
        write_partition(partition_path(warehouse, VALVE, day), part.sort("timestamp_utc"))


def _config(tmp_path: Path, baseline_window: bool) -> Path:
    text = FIXTURE.read_text()
    if baseline_window:
        text = text.replace(
            'density_kg_m3 = 870\n',
            f'density_kg_m3 = 870\nbaseline_window = {{ start = "{START.isoformat()}", end = "{(START + timedelta(hours=3)).isoformat()}" }}\n',
            1,
        )
    path = tmp_path / "plant.toml"
    path.write_text(text)
    return path


def test_plant_model_from_the_configuration():
    from flows.common.config import load_plant_config
    from model import TABLE1

    cfg = load_plant_config(FIXTURE)
    plant = plant_params_for(cfg.valve(VALVE), cfg.export)
    assert plant.cylinder.A1 == pytest.approx(TABLE1.cylinder.A1)
    assert plant.nominal_condition.alpha == (0.675,) * 4
    assert plant.sensors.sample_rate_hz == cfg.export.sample_rate_hz


def test_flow_names_the_hidden_effect_and_stores_everything(tmp_path):
    warehouse = tmp_path / "wh"
    # commissioning: 2 clean hourly windows; afterwards 2 windows with a leaking rod seal
    clean = simulate_lake(None, n_windows=2, seed=60, valve_id=VALVE, start=START)
    leak = simulate_lake(Effects(external_leakage_m3_s_pa=1e-12), n_windows=2, seed=61, valve_id=VALVE, start=START + timedelta(hours=6))
    _write_lake(warehouse, pl.concat([clean, leak]))
    config = _config(tmp_path, baseline_window=True)
    report = discrepancy_flow.fn(str(config), str(warehouse), VALVE, start=(START + timedelta(hours=5)).isoformat())
    assert report.condition_source == "commissioning" and report.n_records == 2
    assert [f["effect"] for f in report.findings] == ["external_leakage"]
    f = report.findings[0]
    assert f["parameter_name"] == "K_e" and f["parameter_unit"] == "m3/(s*Pa)" and f["rank"] == 1
    assert f["parameter_value"] == pytest.approx(1e-12, rel=0.05)
    assert f["gap_after"] * 3 <= f["gap_before"]
    assert all(p.exists() and p.parent == warehouse / "reports" / "discrepancy" for p in report.plots)
    with duckdb.connect(str(db_path(warehouse)), read_only=True) as con:
        cols = [r[0] for r in con.execute("DESCRIBE discrepancy_findings").fetchall()]
        assert cols[:9] == ["valve_id", "run_at", "effect", "parameter_name", "parameter_value", "parameter_unit", "gap_before", "gap_after", "rank"]
        assert cols == [fl.name for fl in DISCREPANCY_FINDING_FIELDS]
        counts = {t: con.execute(f"SELECT count(*) FROM {t} WHERE run_id = ?", [report.run_id]).fetchone()[0] for t in DISCREPANCY_TABLES}
        assert counts["discrepancy_findings"] == 1 and counts["discrepancy_candidates"] == 11
        assert counts["discrepancy_monitoring"] == 4 and counts["discrepancy_condition"] == 4
        # stages x signals (p1, p2, X whole; p1, p2 hydraulic; X mechanical) x regions
        assert counts["discrepancy_gaps"] == 2 * 6 * 7 and counts["discrepancy_residuals"] == 2 * 3 * 7
        kind, before, after, floor = con.execute("SELECT gap_kind, gap_kind_before, gap_kind_after, gap_kind_floor FROM discrepancy_findings WHERE run_id = ?",
                                                 [report.run_id]).fetchone()
        assert kind == "hydraulic" and after * 1.5 <= before and 0.03 < floor < 0.08  # a leak acts on the chambers; Table 1's 0.05 bar noise
        src = con.execute("SELECT DISTINCT source FROM discrepancy_condition WHERE run_id = ?", [report.run_id]).fetchall()
        assert src == [("commissioning",)]


def test_flow_without_effect_writes_none(tmp_path):
    warehouse = tmp_path / "wh"
    _write_lake(warehouse, simulate_lake(None, n_windows=2, seed=62, valve_id=VALVE, start=START))
    report = discrepancy_flow.fn(str(_config(tmp_path, False)), str(warehouse), VALVE)
    assert report.condition_source == "design"
    assert [f["effect"] for f in report.findings] == ["none"]
    f = report.findings[0]
    assert f["rank"] == 1 and f["parameter_name"] is None and f["gap_before"] == f["gap_after"] < 0.2
    assert len(report.plots) == 1 and report.plots[0].name.endswith("_none.png")
    # the positions' noise as the records estimate it: the simulator's 1 µm, the spool's ~0.03 % of x_max
    assert 0.9e-6 < report.spool_noise_m < 1.2e-6 and 0.9e-6 < report.cylinder_noise_m < 1.3e-6, (report.spool_noise_m, report.cylinder_noise_m)
    from flows.discrepancy.flow import summary_lines

    line = next(x for x in summary_lines(report) if "positions as recorded" in x)
    assert "(0.03% of x_max)" in line and line.endswith("the spool taken as the reading smoothed"), line
    # x_ref is recorded, but a spool this quiet reads better smoothed: no hint to reconstruct it
    assert report.spool_reference_records == report.n_records == 2
    assert not any("--reconstruct-spool" in x for x in summary_lines(report))


def test_cli_checks_before_starting_prefect(tmp_path):
    runner = CliRunner()
    config = _config(tmp_path, False)
    cases = [
        (["discrepancy", "--config", str(config), "--valve", "NOPE"], "no valve 'NOPE'"),
        (["discrepancy", "--config", str(config), "--valve", VALVE, "--from", "2025-03-02", "--to", "2025-03-01"], "--to must be later"),
        (["discrepancy", "--config", str(config), "--valve", VALVE, "--valve-condition", "commissioning"], "needs a baseline_window"),
        (["discrepancy", "--config", str(config), "--valve", VALVE, "--valve-condition", "guess"], "--valve-condition must be one of"),
        (["discrepancy", "--config", str(config), "--valve", VALVE, "--from", "yesterday"], "not an ISO-8601"),
    ]
    for args, message in cases:
        result = runner.invoke(app, args + ["--warehouse", str(tmp_path / "wh")])
        assert result.exit_code != 0
        assert isinstance(result.exception, (ValvemonError, ConfigError)) and message in str(result.exception), (args, result.exception)


def test_command_line_says_what_it_found_how_sure_and_why():
    from flows.discrepancy.flow import DiscrepancyReport, summary_lines

    finding = {
        "effect": "spool_sensor_offset", "variant": "", "rank": 1, "parameter_name": "delta_x", "parameter_value": 9e-6,
        "parameter_unit": "m", "parameter_ci_low": None, "parameter_ci_high": None, "gap_before": 0.3, "gap_after": 0.1,
        "gap_explained": None, "alternative_effect": None, "alternative_t": None, "verdict": "ambiguous", "confidence": 0.71,
        "verdict_reason": "the data fit either spool_sensor_offset or the base model with an underlap pattern",
        "alternatives": "the base model with underlap_s1 -9.0 µm (-1.8σ)", "separate_by": "a commissioning window",
        "nuisances": "alpha_s1=0.68 - (+0.3σ); underlap_s1=31.00 µm (-1.8σ)", "gap_nominal": 2.4,
    }
    lines = summary_lines(DiscrepancyReport("V1", "r" * 32, 4, [finding], [], 0.3, 0.1, "design"))
    text = "\n".join(lines)
    assert "verdict AMBIGUOUS" in text and "confidence 71%" in text
    assert "why: the data fit either" in text and "other readings: the base model with underlap_s1" in text
    assert "to tell them apart: a commissioning window" in text
    assert "gap 2.4 with the design data → 0.3" in text and "underlap_s1=31.00 µm (-1.8σ)" in text and "alpha_s1" not in text


def test_command_line_shows_an_unexplained_disagreement():
    from flows.discrepancy.flow import DiscrepancyReport, summary_lines

    finding = {
        "effect": "none", "variant": "", "rank": 1, "parameter_name": None, "parameter_value": None, "parameter_unit": None,
        "parameter_ci_low": None, "parameter_ci_high": None, "gap_before": 0.55, "gap_after": 0.55, "gap_explained": None,
        "alternative_effect": None, "alternative_t": None, "verdict": "unexplained", "confidence": 0.999,
        "verdict_reason": "the data disagree with the model in a way no library effect explains: load_mass_change fits the equations, but ...",
        "alternatives": "load_mass_change delta_m=-1.4e+03 kg (not confirmed)", "separate_by": None, "nuisances": "",
        "disagreement": "the motion (Eq. 5, X): the replayed X is off by 0.3 mm RMS in region retracting", "gap_nominal": None,
    }
    text = "\n".join(summary_lines(DiscrepancyReport("V1", "r" * 32, 4, [finding], [], 0.55, 0.55, "commissioning")))
    assert "verdict UNEXPLAINED -- the data disagree with the model in a way no library effect explains" in text
    assert "where: the motion (Eq. 5, X): the replayed X is off by 0.3 mm RMS in region retracting" in text
    assert "no library effect named" in text and "found load_mass_change" not in text


def test_findings_row_of_a_reading_decided_against_the_tolerances_has_its_acting_gap():
    # a reading of the nuisance verdict (no selection: ``named`` empty) keeps the gap where it acts in
    # the findings row, as the selection's names and ``unexplained`` do; ``none`` leaves it null
    from types import SimpleNamespace

    from flows.discrepancy.flow import verdict_columns
    from model.effects import library_entry
    from transforms.discrepancy.verdict import Verdict

    v = Verdict("named", 0.99, library_entry("load_mass_change"), 600.0, gap_kind="mechanical", floor=0.001, acting_before=0.2, acting_after=0.02)
    row = verdict_columns(SimpleNamespace(verdict=v, named=[], gap_nominal=1.0, lag_finding=""), 1)
    assert (row["verdict"], row["gap_kind"], row["gap_kind_before"], row["gap_kind_after"], row["gap_kind_floor"]) == ("named", "mechanical", 0.2, 0.02, 0.001)
    none = verdict_columns(SimpleNamespace(verdict=Verdict("none", 0.9, None, float("nan")), named=[], gap_nominal=1.0, lag_finding=""), 1)
    assert none["gap_kind"] is None and none["gap_kind_before"] is None


def test_a_plant_grade_spool_reading_with_its_reference_gets_the_hint_to_reconstruct_it():
    from flows.discrepancy.flow import DiscrepancyReport, summary_lines

    def hint(noise_m, reference, reconstructed):
        r = DiscrepancyReport(VALVE, "r" * 32, 2, [], [], 0.0, 0.0, spool_noise_m=noise_m, spool_stroke_m=3.5e-3, cylinder_noise_m=10e-6,
                              spool_reconstructed=reconstructed, spool_reference_records=reference)
        return [x for x in summary_lines(r) if "--reconstruct-spool" in x]

    assert len(hint(7e-6, 2, 0)) == 1  # 0.2 % of x_max, x_ref recorded
    assert hint(7e-6, 2, 2) == [] and hint(7e-6, 0, 0) == [] and hint(1e-6, 2, 0) == []  # reconstructed; no x_ref; 0.03 %


def test_reconstruct_spool_reaches_the_diagnosis_and_needs_the_reference(tmp_path, monkeypatch):
    import flows.common.prefect_run as prefect_run
    import flows.discrepancy.flow as flow_module

    # the command line hands the option to the flow
    seen = {}

    def fake_run_flow(fn, **kwargs):
        seen.update(kwargs)
        return flow_module.DiscrepancyReport(VALVE, "r" * 32, 0, [], [], 0.0, 0.0, "design")

    monkeypatch.setattr(prefect_run, "run_flow", fake_run_flow)
    config = _config(tmp_path, False)
    result = CliRunner().invoke(app, ["discrepancy", "--config", str(config), "--valve", VALVE, "--warehouse", str(tmp_path / "wh"), "--reconstruct-spool"])
    assert result.exit_code == 0, result.output
    assert seen["reconstruct_spool"] is True

    # the flow diagnoses with it
    warehouse = tmp_path / "wh"
    lake = simulate_lake(None, n_windows=1, seed=63, valve_id=VALVE, start=START)
    _write_lake(warehouse, lake)
    settings = []

    class Stop(Exception):
        pass

    def fake_diagnose(records, plant, condition, s, **kwargs):
        settings.append(s)
        raise Stop

    monkeypatch.setattr(flow_module, "diagnose", fake_diagnose)
    for flag in (False, True):
        with pytest.raises(Stop):
            discrepancy_flow.fn(str(config), str(warehouse), VALVE, reconstruct_spool=flag)
    assert [s.reconstruct_spool for s in settings] == [False, True]
    # the command says in how many records the spool followed the reference (a reading that does not keeps its own)
    report = flow_module.DiscrepancyReport(VALVE, "r" * 32, 4, [], [], 0.0, 0.0, "design", spool_noise_m=7e-6, spool_stroke_m=3.5e-3,
                                           cylinder_noise_m=10e-6, spool_reconstructed=3)
    assert ("    positions as recorded: spool noise 7 µm (0.20% of x_max), cylinder 10 µm; the spool taken as Eq. 1's response to x_ref "
            "in 3 of 4 records") in flow_module.summary_lines(report)

    # without the spool reference in the lake it cannot: a clear error, not the reading in silence
    bare = tmp_path / "bare"
    _write_lake(bare, lake.with_columns(pl.lit(None, dtype=pl.Float64).alias("x_ref_m")))  # not recorded
    with pytest.raises(ValvemonError, match=r"--reconstruct-spool needs the spool reference \(x_ref_m\) in the lake; none of the span's 1 records"):
        discrepancy_flow.fn(str(config), str(bare), VALVE, reconstruct_spool=True)
    with pytest.raises(Stop):
        discrepancy_flow.fn(str(config), str(bare), VALVE)
