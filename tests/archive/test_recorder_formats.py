"""The simulator's recorder formats (iba-style ASCII with header rows, TDMS) ingest into the same
lake, byte for byte, as the wide CSV of the same plant and seed — snapshots (TDMS with a time
channel) and a continuous recording (TDMS waveform properties)."""

from __future__ import annotations

import dataclasses
from datetime import timedelta
from pathlib import Path

import numpy as np
import pytest
from nptdms import TdmsFile

from flows.common.errors import ValvemonError
from flows.ingest.flow import run_ingest
from flows.simulate.archive import ASCII_HEADER_ROWS, DEFAULT_COMMISSIONED, ArchivePlan, SimulateRequest, generate_plant_config, plan_request, resolve_scenarios, write_archive

from .conftest import PLAN, SCENARIOS

CONTINUOUS = ArchivePlan(DEFAULT_COMMISSIONED + timedelta(hours=5, minutes=59, seconds=50), DEFAULT_COMMISSIONED + timedelta(hours=6, seconds=20), continuous=True, file_s=60.0)
"""30 s back to back across 06:00, in minute files (the first one 10 s, the last one 20 s)."""


def _archive(out: Path, file_format: str, plan: ArchivePlan) -> Path:
    config = generate_plant_config("T1", 2, "wide")
    if file_format == "ascii":
        config = dataclasses.replace(config, export=dataclasses.replace(config.export, header_rows=ASCII_HEADER_ROWS, separator="\t"))
    write_archive(config, out, plan, resolve_scenarios(config, None, SCENARIOS), seed=11, file_format=file_format)
    return out


def _lake(out: Path, wh: Path) -> dict[str, bytes]:
    summary = run_ingest(out / "plant.toml", [out / "exports"], wh)
    assert summary.files_ingested == len(list((out / "exports").iterdir())) and summary.quarantined == 0
    return {str(p.relative_to(wh)): p.read_bytes() for p in sorted((wh / "lake").rglob("*.parquet"))}


@pytest.mark.parametrize("plan", [PLAN, CONTINUOUS], ids=["snapshots", "continuous"])
def test_ascii_and_tdms_give_the_lake_of_the_wide_csv_byte_for_byte(tmp_path, plan):
    lakes = {f: _lake(_archive(tmp_path / f, f, plan), tmp_path / f"wh_{f}") for f in ("csv", "ascii", "tdms")}
    assert lakes["csv"] and sum(len(b) for b in lakes["csv"].values()) > 10_000
    assert lakes["ascii"] == lakes["csv"]
    assert lakes["tdms"] == lakes["csv"]
    names = sorted(p.name for p in (tmp_path / "tdms" / "exports").iterdir())
    assert all(n.endswith(".tdms") for n in names) and all(n.endswith(".txt") for n in sorted(p.name for p in (tmp_path / "ascii" / "exports").iterdir()))
    first = TdmsFile.read(tmp_path / "tdms" / "exports" / names[0])
    ch = first["valvemon"]["T1.V001.P1"]
    assert ch.properties["unit_string"] == "bar" and ch.properties["description"] == "V001 p1"
    if plan.continuous:  # waveform: 10 s from 05:59:50 at 1 kHz
        assert "timestamp" not in first["valvemon"] and ch.properties["wf_increment"] == 0.001
        assert ch.properties["wf_start_time"] == np.datetime64(plan.start.replace(tzinfo=None), "us") and len(ch) == 10_000
    else:  # windows with pauses: a time channel
        assert len(first["valvemon"]["timestamp"]) == len(ch)


def test_ascii_header_lines(tmp_path):
    out = _archive(tmp_path / "a", "ascii", CONTINUOUS)
    lines = sorted((out / "exports").iterdir())[0].read_text().splitlines()
    assert lines[0].split("\t")[:3] == ["timestamp", "T1.V001.PS", "T1.V001.PR"]
    assert lines[1].split("\t")[:3] == ["", "V001 ps", "V001 pr"]
    assert lines[2].split("\t")[:3] == ["", "bar", "bar"] and lines[2].split("\t")[6] == "mm"
    assert lines[3].startswith("2025-01-01T05:59:50.000000Z\t")


@pytest.mark.parametrize(
    "kw, message",
    [
        (dict(format="tdms", gzip=True), "--gzip: only for text formats (TDMS is binary)"),
        (dict(format="tdms", layout="wide"), "--layout: only with --format parquet"),
        (dict(format="ascii", config_path="LONG"), "--format/--layout: wide contradicts export.layout = 'long'"),
    ],
)
def test_simulate_format_options(tmp_path, kw, message):
    if kw.get("config_path") == "LONG":
        kw["config_path"] = Path(__file__).parents[1] / "fixtures" / "plant_example.toml"
    with pytest.raises(ValvemonError, match=message.replace("(", r"\(").replace(")", r"\)")):
        plan_request(SimulateRequest(out=tmp_path, **kw))


def test_generated_plant_for_ascii_has_iba_header_rows(tmp_path):
    config, _, _, file_format = plan_request(SimulateRequest(out=tmp_path, format="ascii"))
    assert file_format == "ascii" and config.export.layout == "wide"
    assert config.export.header_rows == ("tag", "name", "unit") and config.export.separator == "\t"
    config, _, _, file_format = plan_request(SimulateRequest(out=tmp_path, format="tdms"))
    assert file_format == "tdms" and config.export.layout == "wide"
