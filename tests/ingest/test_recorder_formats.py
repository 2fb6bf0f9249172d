"""Recorder formats: wide text with header rows (iba ASCII: tags, names, units) and TDMS.

Every file holds the reference data of ``conftest.BASE`` (valve V017, 2025-03-01 12:00:00–04 UTC,
bar and mm) and must give :func:`conftest.base_lake`; a bad file must give one line naming the
file and what was expected, with the lake and the manifest untouched.
"""

from __future__ import annotations

import tomllib

import numpy as np
import polars as pl
import pytest
import tomli_w
from nptdms import ChannelObject, GroupObject, TdmsWriter
from polars.testing import assert_frame_equal

import flows.ingest.formats
from flows.common.errors import ValvemonError
from schemas.units import PSI_PA
from tests.ingest.conftest import BASE, EXAMPLE, T0, base_lake, expected_lake, ingest, lake, table

TAG = {"ps": "MILL1.V017.PS", "pr": "MILL1.V017.PR", "p1": "MILL1.V017.P1", "p2": "MILL1.V017.P2", "x_spool": "MILL1.V017.XS", "x_cyl": "MILL1.V017.XC"}
UNIT = {"ps": "bar", "pr": "bar", "p1": "bar", "p2": "bar", "x_spool": "mm", "x_cyl": "mm"}
WIDE = dict(layout="wide", timestamp_column="Time", timestamp_format="%Y-%m-%d %H:%M:%S%.f", separator="\t")
T0_US = int(T0.timestamp() * 1e6)


def plant_file(folder, *, drop_units=(), **export):
    """The example plant, wide, on a 1 Hz grid; ``drop_units``: signals whose unit is left out."""
    raw = tomllib.loads(EXAMPLE.read_text())
    for k in ("tag_column", "value_column", "quality_column", "good_quality"):
        raw["export"].pop(k, None)
    raw["export"].update({"sample_rate_hz": 1.0, "max_gap_s": 2.5} | WIDE | export)
    for s in drop_units:
        del raw["valves"][0]["tags"][s]["unit"]
    path = folder / "plant.toml"
    path.write_bytes(tomli_w.dumps(raw).encode())
    return path


def ascii_export(path, rows=("skip", "tag", "name", "unit"), units=None, *, values=BASE):
    """An iba-style ASCII export of the reference data (or ``values``): header lines as ``rows``
    says, tab-separated."""
    units = UNIT | (units or {})
    cells = {
        "skip": ["[ibaAnalyzer]", *(f"[0:{k}]" for k in range(6))],
        "tag": ["Time", *TAG.values()],
        "name": ["", *(f"V017 {s}" for s in TAG)],
        "unit": ["s", *(units[s] for s in TAG)],
    }
    lines = ["\t".join(cells[r]) for r in rows]
    lines += ["\t".join([f"2025-03-01 13:00:0{i}.000", *(repr(values[s][i]) for s in TAG)]) for i in range(5)]
    path.write_text("\n".join(lines) + "\n")
    return path


def _untouched(wh):
    assert not (wh / "lake").exists() or not list((wh / "lake").rglob("*.parquet"))
    assert table(wh, "ingest_manifest").height == 0


# --- ASCII with header rows ------------------------------------------------------------------


def test_iba_ascii_with_id_tag_name_and_unit_lines(tmp_path):
    cfg = plant_file(tmp_path, header_rows=["skip", "tag", "name", "unit"])
    report = ingest(cfg, ascii_export(tmp_path / "iba.txt"), tmp_path / "wh")
    assert_frame_equal(lake(tmp_path / "wh"), base_lake())
    assert (report.rows_read, report.samples_read, report.rows_written) == (5, 30, 5)


def test_header_rows_streamed_in_blocks_give_the_whole_files_lake_and_lines(tmp_path, monkeypatch):
    """Blocks of a few lines each: the header rows stay in front, line numbers run on (a bad value
    on the file's line 7 is quarantined as line 7)."""
    monkeypatch.setattr(flows.ingest.formats, "CSV_BLOCK_BYTES", 64)
    cfg = plant_file(tmp_path, header_rows=["skip", "tag", "name", "unit"])
    path = ascii_export(tmp_path / "iba.txt")
    text = path.read_text().splitlines()
    text[6] = text[6].replace(repr(BASE["p2"][2]), "Shutdown")  # line 7: the third data row
    path.write_text("\n".join(text) + "\n")
    ingest(cfg, path, tmp_path / "wh")
    want = dict(BASE) | {"p2": [90.0, 89.5, (89.5 + 88.5) / 2, 88.5, 88.0]}
    assert_frame_equal(lake(tmp_path / "wh"), expected_lake([T0.replace(second=i) for i in range(5)], want), check_exact=False, rel_tol=2e-7)
    assert table(tmp_path / "wh", "quarantine").select("line", "tag", "value_raw").rows() == [(7, TAG["p2"], "Shutdown")]


def test_a_unit_that_differs_from_the_configuration_refuses_the_file(tmp_path):
    cfg = plant_file(tmp_path, header_rows=["skip", "tag", "name", "unit"])
    path = ascii_export(tmp_path / "iba.txt", units={"p1": "psi"})
    with pytest.raises(ValvemonError) as err:
        ingest(cfg, path, tmp_path / "wh")
    msg = str(err.value)
    assert msg == f"{path}: column 4 'V017 p1' (tag MILL1.V017.P1): unit 'psi' in the file, 'bar' in the configuration (valves[0].tags.p1.unit)"
    _untouched(tmp_path / "wh")


def test_an_unknown_unit_in_the_file_refuses_it(tmp_path):
    cfg = plant_file(tmp_path, header_rows=["tag", "unit"], drop_units=["ps"])
    path = ascii_export(tmp_path / "iba.txt", rows=("tag", "unit"), units={"ps": "kp/cm2"})
    with pytest.raises(ValvemonError, match=r"iba.txt: column 2 \(tag MILL1.V017.PS\): unknown pressure unit 'kp/cm2' \(expected one of bar, Pa, kPa, MPa, psi\) in the file$"):
        ingest(cfg, path, tmp_path / "wh")
    _untouched(tmp_path / "wh")


def test_units_left_out_of_the_configuration_are_taken_from_the_file(tmp_path):
    """p1 in psi and x_spool in µm in the file, no unit for them in the TOML: converted by the file's."""
    cfg = plant_file(tmp_path, header_rows=["tag", "unit"], drop_units=["p1", "x_spool"])
    values = dict(BASE, p1=[v / (PSI_PA / 1e5) for v in BASE["p1"]], x_spool=[v * 1000 for v in BASE["x_spool"]])
    path = ascii_export(tmp_path / "iba.txt", rows=("tag", "unit"), units={"p1": "psi", "x_spool": "µm"}, values=values)
    ingest(cfg, path, tmp_path / "wh")
    assert_frame_equal(lake(tmp_path / "wh"), base_lake(), check_exact=False, rel_tol=1e-6)
    other = ascii_export(tmp_path / "plain.txt", rows=("tag", "unit"), units={"p1": ""})
    with pytest.raises(ValvemonError, match=r"plain.txt: column 4 \(tag MILL1.V017.P1\): no unit in the file and none in the configuration \(valves\[0\].tags.p1.unit\)"):
        ingest(cfg, other, tmp_path / "wh2")


def test_header_rows_missing_is_one_clear_line(tmp_path):
    cfg = plant_file(tmp_path, header_rows=["tag", "name", "unit"])
    path = ascii_export(tmp_path / "one_header.txt", rows=("tag",))
    with pytest.raises(ValvemonError) as err:
        ingest(cfg, path, tmp_path / "wh")
    assert str(err.value) == (
        f"{path}: line 2: expected the header line 'name' (export.header_rows = ['tag', 'name', 'unit']), found numbers (data): the header rows are missing"
    )
    bare = tmp_path / "no_header.txt"
    bare.write_text("\n".join(path.read_text().splitlines()[1:]) + "\n")
    with pytest.raises(ValvemonError) as err:
        ingest(cfg, bare, tmp_path / "wh")
    assert str(err.value) == (
        f"{bare}: line 1: expected the header line 'tag' (export.header_rows = ['tag', 'name', 'unit']) with the time column 'Time' "
        "(export.timestamp_column), found '2025-03-01 13:00:00.000', '210.0', '2.0', '100.0', …"
    )
    short = tmp_path / "short.txt"
    short.write_text("Time\tMILL1.V017.PS\n")
    with pytest.raises(ValvemonError, match=r"short.txt: expected 3 header lines \(export.header_rows = \['tag', 'name', 'unit'\]\), the file has 1$"):
        ingest(cfg, short, tmp_path / "wh")
    _untouched(tmp_path / "wh")


def test_a_unit_line_wider_than_the_tag_line_is_refused(tmp_path):
    cfg = plant_file(tmp_path, header_rows=["tag", "unit"])
    path = ascii_export(tmp_path / "wide_units.txt", rows=("tag", "unit"))
    lines = path.read_text().splitlines()
    lines[1] += "\tbar"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(ValvemonError, match=r"wide_units.txt: line 2: the 'unit' line has 8 fields, the 'tag' line \(line 1\) 7$"):
        ingest(cfg, path, tmp_path / "wh")


# --- TDMS -------------------------------------------------------------------------------------


def tdms_export(path, *, time_channel=False, units=None, group="rec", extra=(), values=BASE):
    """The reference data as a TDMS file: one channel per tag in ``group``; time from waveform
    properties (1 s increment) or from a time channel ``Time`` of TDMS timestamps (or epoch ms)."""
    units = UNIT | (units or {})
    start = np.datetime64(T0_US, "us")
    objects = [GroupObject(group)]
    if time_channel == "epoch_ms":
        objects.append(ChannelObject(group, "Time", T0_US // 1000 + np.arange(5, dtype=np.int64) * 1000))
    elif time_channel:
        objects.append(ChannelObject(group, "Time", start + np.arange(5) * np.timedelta64(1, "s")))
    for s, tag in TAG.items():
        props = {"unit_string": units[s]}
        if not time_channel:
            props |= {"wf_start_time": start, "wf_increment": 1.0, "wf_start_offset": 0.0}
        objects.append(ChannelObject(group, tag, np.array(values[s]), properties=props))
    objects += list(extra)
    with TdmsWriter(str(path)) as w:
        w.write_segment(objects)
    return path


@pytest.mark.parametrize("time_channel", [False, True, "epoch_ms"])
def test_tdms_waveform_or_time_channel(tmp_path, time_channel):
    """Time from the waveform properties, a channel of TDMS timestamps, or one of epoch ms."""
    cfg = plant_file(tmp_path, **({"timestamp_format": "epoch_ms"} if time_channel == "epoch_ms" else {}))
    report = ingest(cfg, tdms_export(tmp_path / "rec.tdms", time_channel=time_channel), tmp_path / "wh")
    assert_frame_equal(lake(tmp_path / "wh"), base_lake())
    assert (report.rows_read, report.samples_read, report.rows_written) == (5, 30, 5)
    assert table(tmp_path / "wh", "ingest_manifest")["file_format"].to_list() == ["tdms"]


def test_tdms_in_many_segments_read_in_small_batches_gives_the_whole_files_lake(tmp_path, monkeypatch):
    """3,000 samples at 10 Hz written 7 per segment, read 1,024 rows per batch (the least): the lake
    equals the one of the same data as a wide text file."""
    monkeypatch.setattr(flows.ingest.formats, "BATCH_SAMPLES", 6)
    cfg = plant_file(tmp_path, timestamp_format="iso8601", sample_rate_hz=10.0, max_gap_s=0.25)
    rng = np.random.default_rng(3)
    n = 3000
    lo_hi = {"ps": (200, 220), "pr": (1, 3), "p1": (50, 150), "p2": (50, 150), "x_spool": (-1, 1), "x_cyl": (100, 500)}
    data = {tag: np.round(rng.uniform(*lo_hi[s], n), 3) for s, tag in TAG.items()}
    start = np.datetime64(T0_US, "us")
    with TdmsWriter(str(tmp_path / "rec.tdms")) as w:
        for a in range(0, n, 7):
            props = lambda s: {"wf_start_time": start, "wf_increment": 0.1, "unit_string": UNIT[s]} if a == 0 else None  # noqa: E731
            w.write_segment([ChannelObject("rec", tag, data[tag][a : a + 7], properties=props(s)) for s, tag in TAG.items()])
    t = pl.Series(T0_US + np.arange(n, dtype=np.int64) * 100_000).cast(pl.Datetime("us", "UTC")).dt.strftime("%Y-%m-%dT%H:%M:%S%.6fZ")
    pl.DataFrame({"Time": t} | data).write_csv(tmp_path / "same.txt", separator="\t")
    ingest(cfg, tmp_path / "rec.tdms", tmp_path / "wh_tdms")
    ingest(cfg, tmp_path / "same.txt", tmp_path / "wh_csv")
    got = lake(tmp_path / "wh_tdms")
    assert got.height == n
    assert_frame_equal(got, lake(tmp_path / "wh_csv"))


def test_tdms_group_selects_the_channels_of_one_time_base(tmp_path):
    """A second group at another rate: refused as a mixed time base unless export.tdms_group names one."""
    slow = [GroupObject("slow"), ChannelObject("slow", "TEMP", np.arange(2.0), properties={"wf_start_time": np.datetime64(T0_US, "us"), "wf_increment": 10.0})]
    path = tdms_export(tmp_path / "rec.tdms", group="fast", extra=slow)
    with pytest.raises(ValvemonError, match=r"rec.tdms: channel 'slow'/'TEMP' has 2 values, channel 'fast'/'MILL1.V017.PS' 5: channels of one time base expected \(set export.tdms_group\)$"):
        ingest(plant_file(tmp_path), path, tmp_path / "wh")
    ingest(plant_file(tmp_path, tdms_group="fast"), path, tmp_path / "wh")
    assert_frame_equal(lake(tmp_path / "wh"), base_lake())
    with pytest.raises(ValvemonError, match=r"rec.tdms: no group 'other' \(export.tdms_group\); the file's groups are 'fast', 'slow'$"):
        ingest(plant_file(tmp_path, tdms_group="other"), path, tmp_path / "wh2", force=True)


def test_tdms_unit_string_is_checked_like_a_unit_line(tmp_path):
    path = tdms_export(tmp_path / "rec.tdms", units={"x_spool": "um"})
    with pytest.raises(ValvemonError) as err:
        ingest(plant_file(tmp_path), path, tmp_path / "wh")
    assert str(err.value) == f"{path}: channel 'rec'/'MILL1.V017.XS' (tag MILL1.V017.XS): unit 'um' in the file, 'mm' in the configuration (valves[0].tags.x_spool.unit)"
    _untouched(tmp_path / "wh")
    ingest(plant_file(tmp_path, drop_units=["x_spool"], header_rows=["tag", "unit"]), path, tmp_path / "wh_um")  # the file's unit, µm
    assert_frame_equal(lake(tmp_path / "wh_um"), base_lake().with_columns(pl.col("x_spool_m") / 1000), check_exact=False, rel_tol=1e-6)


def test_a_truncated_tdms_file_is_refused(tmp_path):
    path = tdms_export(tmp_path / "rec.tdms")
    whole = path.read_bytes()
    for cut in (len(whole) - 8, 40):  # in the data; in the metadata
        path.write_bytes(whole[:cut])
        with pytest.raises(ValvemonError, match=r"rec.tdms: (truncated TDMS file|not a readable TDMS file)"):
            ingest(plant_file(tmp_path), path, tmp_path / "wh")
        _untouched(tmp_path / "wh")
    path.write_bytes(whole[:-8])
    with pytest.raises(ValvemonError) as err:
        ingest(plant_file(tmp_path), path, tmp_path / "wh")
    assert str(err.value) == f"{path}: truncated TDMS file (its last segment ends at byte {len(whole) - 8:,} of {len(whole) - 8:,} or is incomplete; expected whole segments)"


def test_tdms_files_need_the_wide_layout_and_a_time(tmp_path):
    path = tdms_export(tmp_path / "rec.tdms")
    raw = tomllib.loads(EXAMPLE.read_text())  # the example plant: long layout
    (tmp_path / "long.toml").write_bytes(tomli_w.dumps(raw).encode())
    with pytest.raises(ValvemonError, match=r"rec.tdms: a TDMS file is read in the wide layout \(a channel per tag\); the configuration has export.layout = 'long'$"):
        ingest(tmp_path / "long.toml", path, tmp_path / "wh")
    bare = tmp_path / "bare.tdms"
    with TdmsWriter(str(bare)) as w:
        w.write_segment([ChannelObject("rec", tag, np.array(BASE[s])) for s, tag in TAG.items()])
    with pytest.raises(ValvemonError, match=r"bare.tdms: channel 'rec'/'MILL1.V017.PS' has no time: neither a time channel 'Time' \(export.timestamp_column\) nor the waveform properties"):
        ingest(plant_file(tmp_path), bare, tmp_path / "wh")


@pytest.mark.parametrize("fmt", ["ascii", "tdms"])
def test_the_read_as_one_batch_gives_the_same_lake(tmp_path, fmt):
    """The reader taken whole (one batch: what an export that cannot be streamed is read as)
    reads both formats with the file's units (p1 in psi, left out of the configuration)."""
    from flows.common.config import load_plant_config
    from flows.ingest.flow import merge_batches
    from flows.ingest.formats import iload, open_export
    from transforms.ingest import TagTable

    config = load_plant_config(plant_file(tmp_path, header_rows=["skip", "tag", "name", "unit"], drop_units=["p1"]))
    psi = dict(BASE, p1=[v / (PSI_PA / 1e5) for v in BASE["p1"]])
    make = ascii_export if fmt == "ascii" else tdms_export
    path = make(tmp_path / f"rec.{'txt' if fmt == 'ascii' else 'tdms'}", units={"p1": "psi"}, values=psi)
    src = open_export(path, config.export, config.timezone)
    tags = TagTable.from_config(config)
    batches = list(iload(src, config.export, tags, whole=True))
    assert [(b.first_line, b.final) for b in batches] == [(5 if fmt == "ascii" else 1, True)] and src.units[TAG["p1"]][0] == "psi"
    report, _ = merge_batches(src, batches, config, tmp_path / "wh", "run", tags)
    assert report.counts.rows_out == 5
    assert_frame_equal(lake(tmp_path / "wh"), base_lake(), check_exact=False, rel_tol=1e-6)


@pytest.mark.parametrize(
    "make, expected",
    [
        (lambda d: ascii_export(d / "mismatch.txt", rows=("tag", "name", "unit"), units={"p2": "psi"}), "unit 'psi' in the file, 'bar' in the configuration (valves[0].tags.p2.unit)"),
        (lambda d: ascii_export(d / "one_header.txt", rows=("tag",)), "line 2: expected the header line 'name'"),
        (lambda d: _cut(tdms_export(d / "cut.tdms"), 8), "truncated TDMS file"),
    ],
)
def test_bad_recorder_files_are_one_line_with_exit_status_1(tmp_path, monkeypatch, capsys, make, expected):
    from tests.ingest.conftest import run_cli

    cfg = plant_file(tmp_path, header_rows=["tag", "name", "unit"])
    path = make(tmp_path)
    code, out, err = run_cli(["ingest", "--config", str(cfg), "--warehouse", str(tmp_path / "wh"), str(path)], monkeypatch, capsys)
    assert code == 1 and out == ""
    assert err.count("\n") == 1 and err.startswith(f"valvemon: error: {path}: ") and expected in err
    assert not (tmp_path / "wh" / "lake").exists()


def _cut(path, n):
    path.write_bytes(path.read_bytes()[:-n])
    return path


def test_a_tdms_index_beside_the_file_is_not_read(tmp_path):
    """npTDMS given a path prefers ``rec.tdms_index`` for the metadata; the ingest reads the
    ``.tdms`` itself (the content hash covers only it), so a stale index changes nothing."""
    other = tmp_path / "other"
    other.mkdir()
    with TdmsWriter(str(other / "rec.tdms"), index_file=True) as w:  # an index of other data: 2 samples
        w.write_segment([ChannelObject("rec", tag, np.array(BASE[s][:2])) for s, tag in TAG.items()])
    path = tdms_export(tmp_path / "rec.tdms")
    (tmp_path / "rec.tdms_index").write_bytes((other / "rec.tdms_index").read_bytes())
    ingest(plant_file(tmp_path), path, tmp_path / "wh")
    assert_frame_equal(lake(tmp_path / "wh"), base_lake())
