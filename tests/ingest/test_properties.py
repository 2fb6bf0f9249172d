"""Property tests: shuffling, duplicating and dropping rows of an export loses and invents nothing.

They run on the pure function (``transforms.ingest.process_export``) with an export frame in
memory: a gridded long export of valve V017 at 1 Hz (max gap 2.5 s).
"""

from __future__ import annotations

from datetime import timedelta

import numpy as np
import polars as pl
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from polars.testing import assert_frame_equal

from schemas.plant_config import parse_plant_config
from tests.ingest.conftest import EXAMPLE, T0
from transforms.ingest import IngestError, process_export

TAGS = ["MILL1.V017.PS", "MILL1.V017.PR", "MILL1.V017.P1", "MILL1.V017.P2", "MILL1.V017.XS", "MILL1.V017.XC"]
SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _config(rule: str = "last"):
    import tomllib

    raw = tomllib.loads(EXAMPLE.read_text())
    raw["export"].update({"sample_rate_hz": 1.0, "max_gap_s": 2.5, "duplicate_rule": rule})
    return parse_plant_config(raw)


CONFIG = {rule: _config(rule) for rule in ("last", "first")}


@st.composite
def exports(draw, max_instants: int = 12):
    """A gridded long export: n instants × 6 tags, values on a coarse lattice (exact in binary)."""
    n = draw(st.integers(1, max_instants))
    values = draw(st.lists(st.integers(-400, 400), min_size=6 * n, max_size=6 * n))
    rows = []
    for i in range(n):
        t = (T0 + timedelta(seconds=i)).strftime("%Y-%m-%dT%H:%M:%S.000Z")
        for j, tag in enumerate(TAGS):
            v = values[6 * i + j]
            rows.append((t, tag, v / 256.0 if tag.endswith("XS") else 100.0 + v / 8.0, "Good"))  # within the physical ranges
    return pl.DataFrame(rows, schema={"timestamp": pl.String, "tag": pl.String, "value": pl.Float64, "quality": pl.String}, orient="row")


def _lake(df: pl.DataFrame, rule: str = "last"):
    r = process_export(df, CONFIG[rule])
    frame = pl.concat([p.frame for p in r.partitions]) if r.partitions else None
    return frame, r.counts


@SETTINGS
@given(data=st.data(), df=exports())
def test_shuffled_and_duplicated_rows_give_the_same_lake(data, df):
    clean, _ = _lake(df)
    copies = data.draw(st.lists(st.integers(0, df.height - 1), max_size=10))
    noisy = pl.concat([df, df[copies]]) if copies else df
    order = data.draw(st.permutations(range(noisy.height)))
    noisy = noisy[list(order)]
    got, counts = _lake(noisy)
    assert_frame_equal(got, clean)
    assert counts.duplicates == len(copies) and counts.conflicts == 0
    assert counts.samples_in == counts.accepted + counts.duplicates + counts.conflicts + counts.quarantined


@SETTINGS
@given(data=st.data(), df=exports())
def test_dropped_rows_lose_only_themselves_and_invent_nothing(data, df):
    clean, _ = _lake(df)
    drop = set(data.draw(st.lists(st.integers(0, df.height - 1), max_size=df.height)))
    kept = df.with_row_index("i").filter(~pl.col("i").is_in(sorted(drop))).drop("i")
    if kept.height == 0:
        return
    if kept["tag"].n_unique() < len(TAGS):  # a tag gone entirely: the export lacks a required signal
        with pytest.raises(IngestError, match="required signal"):
            _lake(kept)
        return
    got, counts = _lake(kept)
    assert counts.samples_in == counts.accepted == kept.height
    dropped_at = df.with_row_index("i").filter(pl.col("i").is_in(sorted(drop)))["timestamp"].to_list()
    complete = sorted(set(df["timestamp"].to_list()) - set(dropped_at))
    complete_t = [pl.Series([t]).str.to_datetime(time_zone="UTC", time_unit="us")[0] for t in complete]
    got_t = [] if got is None else got["timestamp_utc"].to_list()
    # nothing lost: every instant whose six samples all survived is in the lake, with its values
    assert set(complete_t) <= set(got_t)
    if complete_t:
        assert_frame_equal(got.filter(pl.col("timestamp_utc").is_in(complete_t)), clean.filter(pl.col("timestamp_utc").is_in(complete_t)))
    # nothing invented: no instant outside the export, and every value lies between the surviving
    # samples of its tag that bracket it (interpolated only within the gap limit)
    assert set(got_t) <= set(clean["timestamp_utc"].to_list())
    if got is None:
        return
    surv = kept.with_columns(t=pl.col("timestamp").str.to_datetime(time_zone="UTC", time_unit="us"))
    col_of = dict(zip(TAGS, ["ps_pa", "pr_pa", "p1_pa", "p2_pa", "x_spool_m", "x_cyl_m"]))
    factor = dict(zip(TAGS, [1e5] * 4 + [1e-3] * 2))
    for tag in TAGS:
        s = surv.filter(pl.col("tag") == tag).sort("t")
        t = s["t"].dt.epoch("us").to_numpy()
        v = s["value"].to_numpy() * factor[tag]
        stored = got[col_of[tag]].dtype  # the lake's storage dtype (float32, schemas.fields)
        v = pl.Series(v).cast(stored).to_numpy()
        for ts, val in zip(got["timestamp_utc"].dt.epoch("us").to_list(), got[col_of[tag]].to_list()):
            k = np.searchsorted(t, ts)
            if k < len(t) and t[k] == ts:
                assert val == v[k]  # a surviving sample on the grid: its own value, bit for bit
            else:
                assert 0 < k < len(t) and t[k] - t[k - 1] <= 2_500_000
                lo, hi = min(v[k - 1], v[k]), max(v[k - 1], v[k])
                assert lo <= val <= hi  # interpolated between its bracketing samples


@SETTINGS
@given(data=st.data(), df=exports(), rule=st.sampled_from(["last", "first"]))
def test_conflicting_rows_follow_the_rule_in_file_order(data, df, rule):
    i = data.draw(st.integers(0, df.height - 1))
    changed = df[i].with_columns(pl.col("value") + 1.0)
    where = data.draw(st.integers(0, df.height))
    noisy = pl.concat([df[:where], changed, df[where:]])
    got, counts = _lake(noisy, rule)
    clean, _ = _lake(df, rule)
    original_first = where > i  # the original row comes before the changed copy in file order
    keep_changed = (rule == "last") == original_first
    expected = _lake(pl.concat([df[:i], changed, df[i + 1 :]]), rule)[0] if keep_changed else clean
    assert_frame_equal(got, expected)
    assert counts.conflicts == 1 and counts.duplicates == 0
