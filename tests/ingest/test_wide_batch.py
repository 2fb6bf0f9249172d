"""A wide batch that already is the lake's grid (``transforms.ingest.wide_batch``) gives, batch by
batch, exactly what the general rules give: lake rows, counts, quarantine, gaps and the state
carried to the next batch, however the export is cut and wherever one irregular row sits.

The exports are wide, 1 kHz (max gap 5 ms), typed as the simulator's Parquet hour files are:
a time column and a float column per tag of valve V017.
"""

from __future__ import annotations

import tomllib
from datetime import timedelta

import numpy as np
import polars as pl
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from polars.testing import assert_frame_equal

import transforms.ingest.stream as stream_module
from schemas.plant_config import parse_plant_config
from tests.ingest.conftest import EXAMPLE, T0
from transforms.ingest.stream import ExportStream

TAGS = ["MILL1.V017.PS", "MILL1.V017.PR", "MILL1.V017.P1", "MILL1.V017.P2", "MILL1.V017.XS", "MILL1.V017.XC", "MILL1.V017.XREF"]
IRREGULAR = ("missing_cell", "out_of_range", "nan", "off_grid", "gap", "repeated_row", "no_time", "clock_back")


def _config():
    raw = tomllib.loads(EXAMPLE.read_text())
    for key in ("tag_column", "value_column", "quality_column", "good_quality"):
        raw["export"].pop(key, None)
    raw["export"].update({"layout": "wide", "sample_rate_hz": 1000.0, "max_gap_s": 0.005})
    return parse_plant_config(raw)


CONFIG = _config()


def wide_export(n: int, seed: int, irregular: str | None = None, at: int = 0) -> pl.DataFrame:
    """``n`` rows on the 1 kHz grid (values exact in binary), with one ``irregular`` row at ``at``."""
    rng = np.random.default_rng(seed)
    t_us = (int(T0.timestamp()) * 10**6 + np.arange(n, dtype=np.int64) * 1000).astype(object)
    cols = {tag: (rng.integers(-400, 400, n) / 256.0 if tag.endswith(("XS", "XREF")) else 100.0 + rng.integers(-400, 400, n) / 8.0) for tag in TAGS}
    cols = {k: v.astype(object) for k, v in cols.items()}
    if irregular == "missing_cell":
        cols[TAGS[2]][at] = None
    elif irregular == "out_of_range":
        cols[TAGS[0]][at] = 1e9
    elif irregular == "nan":
        cols[TAGS[4]][at] = float("nan")
    elif irregular == "off_grid":
        t_us[at] += 300
    elif irregular == "no_time":
        t_us[at] = None
    elif irregular == "clock_back":
        t_us[at:] = [t - 60 * 10**6 for t in t_us[at:]]
    df = pl.DataFrame({"timestamp": pl.Series(list(t_us), dtype=pl.Int64).cast(pl.Datetime("us", "UTC")), **{k: pl.Series(list(v), dtype=pl.Float64) for k, v in cols.items()}})
    if irregular == "gap":
        df = df.filter(~pl.int_range(pl.len()).is_between(at, at + 9))
    elif irregular == "repeated_row":
        df = pl.concat([df.slice(0, at + 1), df.slice(at, None)])
    return df


def _streamed(df: pl.DataFrame, cuts: list[int], monkeypatch, gridded: bool):
    """Frames and stream of the export fed in batches; ``gridded``: the one-pass path allowed."""
    taken = []

    def spy(*args, **kwargs):
        out = real(*args, **kwargs) if gridded else None
        taken.append(out is not None)
        return out

    real = stream_module.gridded_columns
    with monkeypatch.context() as m:
        m.setattr(stream_module, "gridded_columns", spy)
        stream = ExportStream(CONFIG)
        bounds = [0, *sorted(set(c for c in cuts if 0 < c < df.height)), df.height]
        frames = []
        for k, (a, b) in enumerate(zip(bounds[:-1], bounds[1:])):
            batch = df.slice(a, b - a)
            batch = pl.concat([batch.slice(0, batch.height // 2), batch.slice(batch.height // 2)], rechunk=False)  # as read: a chunk per row group
            frames += stream.feed(batch, first_line=1 + a, final=k == len(bounds) - 2)
    return frames, stream, taken


def _state(stream: ExportStream) -> tuple:
    carry = {k: (c.last_ns, c.held_t.tolist(), c.held_v.tolist(), c.held_line.tolist(), c.anchor) for k, c in stream._carry.items()}
    valves = {k: (v.given_to, v.reached, {s: [(t.tolist(), x.tolist()) for t, x in p] for s, p in v.pending.items()}) for k, v in stream._valves.items()}
    return carry, valves, stream._tag_samples.tolist(), stream._present


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(data=st.data(), n=st.integers(2, 120), seed=st.integers(0, 3), irregular=st.sampled_from((None, *IRREGULAR)))
def test_a_gridded_batch_gives_what_the_general_rules_give(data, n, seed, irregular, monkeypatch):
    df = wide_export(n, seed, irregular, data.draw(st.integers(0, n - 1)))
    cuts = data.draw(st.lists(st.integers(1, max(df.height - 1, 1)), max_size=6))
    try:
        want, general, _ = _streamed(df, cuts, monkeypatch, gridded=False)
    except Exception as exc:  # refused (a required tag wholly quarantined, ...): refused alike
        with pytest.raises(type(exc)):
            _streamed(df, cuts, monkeypatch, gridded=True)
        return
    got, fast, taken = _streamed(df, cuts, monkeypatch, gridded=True)
    assert len(got) == len(want)
    for g, w in zip(got, want):
        assert_frame_equal(g, w)
    assert fast.counts == general.counts
    assert_frame_equal(fast.quarantine_frame(), general.quarantine_frame())
    assert_frame_equal(fast.gap_frame(), general.gap_frame())
    assert _state(fast) == _state(general)
    sizes = np.diff([0, *sorted(set(c for c in cuts if 0 < c < df.height)), df.height])
    if irregular is None and sizes[0] > 1:  # a clean export: every batch of two rows or more in one pass
        assert taken == [bool(k > 1) for k in sizes]


def test_a_gridded_export_turns_general_at_its_irregular_batch_and_back(monkeypatch):
    """Cut into four batches with an out-of-range value in the second: the first, third and
    fourth batch take the one pass, the second the general rules (which quarantine the sample)."""
    df = wide_export(400, 1, "out_of_range", 150)
    got, stream, taken = _streamed(df, [100, 200, 300], monkeypatch, gridded=True)
    assert taken == [True, False, True, True]
    assert stream.counts.out_of_range == stream.counts.quarantined == 1
    assert sum(f.height for f in got) == 400
    lake = pl.concat(got)
    assert lake["ps_pa"].null_count() == 0
    assert lake["timestamp_utc"].diff().drop_nulls().eq(timedelta(milliseconds=1)).all()
