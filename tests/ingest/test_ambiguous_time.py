"""A local time in the hour that the clocks repeat in autumn (Europe/Vienna, 2025-10-26: 02:00-03:00
twice) is refused where nothing tells which pass it is (issue 46, item 4): a relative-time
recording's start time, a COMTRADE 1999 start, a file whose local times all lie in that hour.
The message names the file, the time and the two UTC instants; ``export.ambiguous_time =
"earlier" | "later"`` takes the one the plant knows, and then two recordings of the two passes
land an hour apart, nothing overwritten."""

from __future__ import annotations

from datetime import datetime, timedelta, timezone

import numpy as np
import polars as pl
import pytest

from flows.common.errors import ValvemonError
from schemas.errors import ConfigError
from tests.ingest.comtrade_files import write_comtrade
from tests.ingest.conftest import ingest, lake, table
from tests.ingest.test_comtrade import RATE, recording
from tests.ingest.test_recorder_formats import TAG
from tests.ingest.test_relative_time import RELATIVE, relative_export, samples

N = 600  # 60 s at 10 Hz
EARLIER, LATER = datetime(2025, 10, 26, 0, 30, tzinfo=timezone.utc), datetime(2025, 10, 26, 1, 30, tzinfo=timezone.utc)
TWO = "2025-10-26T00:30:00Z (summer time) or 2025-10-26T01:30:00Z"


def _relative(tmp_path, name: str, seed: int, **export):
    folder = tmp_path / name
    folder.mkdir()
    path = folder / "rec.txt"
    relative_export(path, [f"{i / 10:.3f}".replace(".", ",") for i in range(N)], samples(N, seed), start_line="Startzeit\t26.10.2025 02:30:00,000")
    from tests.ingest.test_recorder_formats import plant_file

    cfg = plant_file(folder, **RELATIVE, timestamp_format="seconds", header_rows=["start_time", "skip", "tag", "name", "unit"],
                     start_time_format="%d.%m.%Y %H:%M:%S,%3f", **export)  # fmt: skip
    return cfg, path


def test_a_start_time_in_the_repeated_hour_is_refused(tmp_path):
    cfg, path = _relative(tmp_path, "a", 1)
    wh = tmp_path / "wh"
    with pytest.raises(ValvemonError) as err:
        ingest(cfg, path, wh)
    message = str(err.value)
    assert message.startswith(f"{path}: line 1: local time 2025-10-26 02:30:00 is in the hour Europe/Vienna repeats") and TWO in message, message
    assert "export.ambiguous_time" in message and "\n" not in message
    assert not (wh / "lake").exists()


def test_the_two_passes_land_an_hour_apart_when_the_plant_says_which(tmp_path):
    """The issue's reproduction: both files landed at 00:30 UTC, 2,000 conflicts, the second's values kept."""
    wh = tmp_path / "wh"
    first, second = _relative(tmp_path, "first", 1, ambiguous_time="earlier"), _relative(tmp_path, "second", 2, ambiguous_time="later")
    ingest(first[0], first[1], wh)
    ingest(second[0], second[1], wh)
    got = lake(wh)
    assert got.height == 2 * N
    starts = got.group_by(pl.col("timestamp_utc").dt.hour().alias("hour")).agg(pl.col("timestamp_utc").min()).sort("hour")["timestamp_utc"].to_list()
    assert starts == [EARLIER, LATER]
    assert table(wh, "ingest_manifest")["lake_conflicts"].to_list() == [0, 0]
    second_values = samples(N, 2)["ps"] * 1e5
    np.testing.assert_allclose(got.filter(pl.col("timestamp_utc") >= LATER).sort("timestamp_utc")["ps_pa"].to_numpy(), second_values)


def test_a_comtrade_1999_start_in_the_repeated_hour(tmp_path):
    rec = recording(N, "BINARY", start="26/10/2025,02:30:00.000000")
    cfg_path = write_comtrade(tmp_path / "rec.cfg", rec, "BINARY")
    from tests.ingest.test_recorder_formats import plant_file

    with pytest.raises(ValvemonError) as err:
        ingest(plant_file(tmp_path, **RATE), cfg_path, tmp_path / "wh")
    assert str(err.value).startswith(f"{cfg_path}: line ") and TWO in str(err.value), str(err.value)
    ingest(plant_file(tmp_path, **RATE, ambiguous_time="later"), cfg_path, tmp_path / "wh")
    assert lake(tmp_path / "wh")["timestamp_utc"].min() == LATER


@pytest.mark.parametrize(
    "first, last, expected",
    [("02:10:00", "02:50:00", None), ("02:30:00", "03:10:00", LATER), ("01:50:00", "02:30:00", EARLIER)],
    ids=["all-in-the-hour", "into-winter-time", "from-summer-time"],
)
def test_local_times_that_never_go_back(tmp_path, first, last, expected):
    """A wide export of local times: inside the repeated hour only, the order cannot tell (refused);
    reaching past its end without going back, it is the second pass; from before it, the first."""
    from tests.ingest.test_recorder_formats import plant_file

    t = pl.datetime_range(datetime.fromisoformat(f"2025-10-26 {first}"), datetime.fromisoformat(f"2025-10-26 {last}"), "10s", eager=True)
    values = samples(len(t), 3)
    path = tmp_path / "local.csv"
    pl.DataFrame({"Time": t.dt.strftime("%Y-%m-%d %H:%M:%S.%3f")} | {TAG[s]: values[s] for s in TAG}).write_csv(path, separator="\t")
    cfg = plant_file(tmp_path, sample_rate_hz=0.1, max_gap_s=25.0)
    if expected is None:
        with pytest.raises(ValvemonError, match=r"local.csv: line 2: .*local time 2025-10-26 02:10:00 is in the hour Europe/Vienna repeats"):
            ingest(cfg, path, tmp_path / "wh")
        return
    ingest(cfg, path, tmp_path / "wh")
    got = lake(tmp_path / "wh")["timestamp_utc"]
    assert len(got) == len(t) and got.diff().drop_nulls().unique().to_list() == [timedelta(seconds=10)]
    assert got.filter((got.dt.minute() == 30) & (got.dt.second() == 0)).to_list() == [expected]  # 02:30 local: the one instant the file has at minute 30


def test_the_setting_is_checked(tmp_path):
    from tests.ingest.test_recorder_formats import plant_file

    with pytest.raises(ConfigError, match="export.ambiguous_time"):
        ingest(plant_file(tmp_path, ambiguous_time="first"), [], tmp_path / "wh")
