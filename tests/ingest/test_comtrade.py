"""COMTRADE recordings (IEEE C37.111-1999 and -2013): the same lake as the same samples written as
a wide CSV, in every data file type, with another equipment's analog and digital channels read
past and counted; each refusal is one line naming the file."""

from __future__ import annotations

from datetime import datetime, timezone

import numpy as np
import polars as pl
import pytest
from polars.testing import assert_frame_equal

from flows.common.errors import ValvemonError
from tests.ingest.comtrade_files import RAW_DTYPE, Analog, Recording, write_comtrade
from tests.ingest.conftest import ingest, lake, table
from tests.ingest.test_recorder_formats import TAG, UNIT, plant_file

RATE = dict(timestamp_format="iso8601", sample_rate_hz=10.0, max_gap_s=0.25)
T0_US = int(datetime(2025, 3, 1, 12, tzinfo=timezone.utc).timestamp() * 1e6)
# raw value ranges and a, b per signal: a·raw + b in bar or mm
SCALE = {"ps": (0.01, 0.0), "pr": (0.001, 0.5), "p1": (0.01, -5.0), "p2": (0.01, 1.0), "x_spool": (0.0001, 0.0), "x_cyl": (0.02, 100.0)}
RAW = {"ps": (20500, 21500), "pr": (0, 2000), "p1": (5000, 15000), "p2": (5000, 15000), "x_spool": (-9000, 9000), "x_cyl": (0, 15000)}


def recording(n: int, ft: str, seed: int = 1, **kw) -> Recording:
    """V017's six signals (p1 scaled to the secondary side, 1:10), another equipment's current
    and two digital channels, at 10 Hz."""
    rng = np.random.default_rng(seed)
    dtype = RAW_DTYPE[ft]
    analogs = []
    for s, tag in TAG.items():
        a, b = SCALE[s]
        raw = rng.integers(*RAW[s], n).astype(dtype)
        if s == "p1":
            analogs.append(Analog(tag, UNIT[s], raw, a / 10, b / 10, "S", 100.0, 10.0))
        else:
            analogs.append(Analog(tag, UNIT[s], raw, a, b))
    analogs.insert(2, Analog("FEEDER3 IA", "A", rng.integers(-3000, 3000, n).astype(dtype), 0.5, 0.0, "S", 600.0, 1.0))
    digitals = [("CB1 OPEN", rng.integers(0, 2, n)), ("TRIP", np.zeros(n, dtype=np.int64))]
    return Recording(analogs, digitals, **kw)


def csv_lake(tmp_path, rec: Recording, t_utc_us: np.ndarray) -> pl.DataFrame:
    """The lake of the recording's V017 samples written as a wide CSV with UTC times."""
    folder = tmp_path / "csv"
    folder.mkdir()
    t = pl.Series(t_utc_us).cast(pl.Datetime("us", "UTC")).dt.strftime("%Y-%m-%dT%H:%M:%S%.6fZ")
    values = {c.ch_id: c.scaled() for c in rec.analogs if c.ch_id in TAG.values()}
    pl.DataFrame({"Time": t} | values).write_csv(folder / "same.csv", separator="\t")
    ingest(plant_file(folder, **RATE), folder / "same.csv", folder / "wh")
    return lake(folder / "wh")


@pytest.mark.parametrize("ft", ["ASCII", "BINARY", "BINARY32", "FLOAT32"])
def test_a_1999_recording_gives_the_lake_of_the_wide_csv(tmp_path, ft):
    """Local time (Vienna, +01:00) from the .cfg, the sample-rate table; the current of feeder 3
    and the two digital channels are read past and counted."""
    rec = recording(3000, ft)
    cfg = write_comtrade(tmp_path / "rec.cfg", rec, ft)
    report = ingest(plant_file(tmp_path, **RATE), tmp_path, tmp_path / "wh")  # found in the folder by its .cfg
    assert report.files_ingested == 1 and report.quarantined == 0
    assert_frame_equal(lake(tmp_path / "wh"), csv_lake(tmp_path, rec, T0_US + np.arange(3000) * 100_000))
    m = table(tmp_path / "wh", "ingest_manifest").row(0, named=True)
    assert (m["source_file"], m["file_format"], m["rows_in"], m["samples_in"]) == (str(cfg), "comtrade", 3000, 18_000)
    assert (m["other_tags"], m["other_samples"], m["other_tag_names"]) == (3, 9000, "FEEDER3 IA,CB1 OPEN,TRIP")
    assert m["size_bytes"] == cfg.stat().st_size + cfg.with_suffix(".dat").stat().st_size


def test_a_2013_recording_with_time_stamps_and_a_time_code(tmp_path):
    """nrates = 0: the time stamps × timemult are the time; the .cfg's time code +2 (the
    recorded times are UTC+2) applies, not plant.timezone; missing samples are empty cells."""
    n = 2000
    rec = recording(n, "BINARY", seed=4, rev="2013", start="01/03/2025,14:00:00.000000", time_code="+2", stamps=np.arange(n) * 1000, timemult=100.0)
    rec.analogs[0].raw[[5, 6]] = -32768  # ps missing at two samples
    write_comtrade(tmp_path / "rec.cfg", rec, "BINARY")
    ingest(plant_file(tmp_path, **RATE), tmp_path / "rec.cfg", tmp_path / "wh")
    m = table(tmp_path / "wh", "ingest_manifest").row(0, named=True)
    assert (m["samples_in"], m["quarantined"]) == (6 * n - 2, 0)
    # the CSV holds the raw -32768 scaled (-327.68 bar): quarantined out of range; both lakes
    # interpolate ps at the two instants from its neighbours, as for any missing sample
    assert_frame_equal(lake(tmp_path / "wh"), csv_lake(tmp_path, rec, T0_US + np.arange(n) * 100_000))


def _cut(path, n):
    path.write_bytes(path.read_bytes()[:-n])


@pytest.mark.parametrize(
    "spoil, expected",
    [
        (lambda cfg: cfg.with_suffix(".dat").unlink(), "{cfg}: no data file rec.dat beside it (a COMTRADE recording is a .cfg and its .dat)"),
        (lambda cfg: _cut(cfg.with_suffix(".dat"), 13), "{dat}: 71,987 bytes, shorter than the 3,000 samples of 24 bytes its .cfg promises (72,000 bytes)"),
        (lambda cfg: cfg.write_text(cfg.read_text().replace("STATION,REC1,1999", "STATION,REC1,1991")), "{cfg}: line 1: expected station_name,rec_dev_id,rev_year with rev_year 1999 or 2013, found 'STATION,REC1,1991' (a COMTRADE .cfg, IEEE C37.111)"),
        (lambda cfg: cfg.write_text(cfg.read_text().replace(",mm,", ",um,", 1)), "{cfg}: line 8: analog channel 6 (tag MILL1.V017.XS): unit 'um' in the file, 'mm' in the configuration (valves[0].tags.x_spool.unit)"),
    ],
    ids=["no dat", "short dat", "1991", "unit"],
)
def test_a_bad_binary_recording_is_refused_in_one_line(tmp_path, spoil, expected):
    cfg = write_comtrade(tmp_path / "rec.cfg", recording(3000, "BINARY"), "BINARY")
    spoil(cfg)
    with pytest.raises(ValvemonError) as err:
        ingest(plant_file(tmp_path, **RATE), cfg, tmp_path / "wh")
    assert str(err.value) == expected.format(cfg=cfg, dat=cfg.with_suffix(".dat"))
    assert not (tmp_path / "wh" / "lake").exists()


@pytest.mark.parametrize(
    "spoil, expected",
    [
        (lambda dat: dat.write_text("\r\n".join(dat.read_text().splitlines()[:-3]) + "\r\n"), "{dat}: 2,997 samples, fewer than the 3,000 its .cfg promises (a truncated data file)"),
        (lambda dat: dat.write_bytes(dat.read_bytes().replace(b"\r\n7,", b"\r\n7,600000,1,2\r\n", 1)), "{dat}: line 7: expected a sample record of 11 fields (n, time stamp, analog and digital values), found '7,600000,1,2'"),
    ],
    ids=["short", "broken line"],
)
def test_a_bad_ascii_recording_is_refused_in_one_line(tmp_path, spoil, expected):
    cfg = write_comtrade(tmp_path / "rec.cfg", recording(3000, "ASCII"), "ASCII")
    spoil(cfg.with_suffix(".dat"))
    with pytest.raises(ValvemonError) as err:
        ingest(plant_file(tmp_path, **RATE), cfg, tmp_path / "wh")
    assert str(err.value) == expected.format(dat=cfg.with_suffix(".dat"))
    assert not (tmp_path / "wh" / "lake").exists()
