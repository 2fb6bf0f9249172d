"""COMTRADE recordings (IEEE C37.111-1999 and -2013): a ``.cfg`` beside its ``.dat``, read in bounded batches.

Protection relays and recorders (iba's extractor among them) write COMTRADE: the ``.cfg`` (text)
describes the channels, their scaling, the sample rates and the start; the ``.dat`` holds one
record per sample — ASCII lines or little-endian binary records (``BINARY``: int16 analog values,
``BINARY32``: int32, ``FLOAT32``: float32), each ``sample number, time stamp, analog values,
digital values`` (binary: the digital channels packed 16 to a word).

The ingest reads it in the wide layout: **each analog channel is one tag, named by its channel
id** (``ch_id``); analog channels of other equipment and every digital channel are read past and
counted (``export.other_tags``). A value is ``a·raw + b`` as the ``.cfg`` says; one scaled to the
secondary side (``PS = S``) is multiplied by ``primary / secondary``, so every value is the
primary quantity, in the channel's unit ``uu`` (checked against the configuration as a unit
header line is, ``transforms.ingest.units``). A missing value (ASCII ``99999`` or an empty field,
binary ``0x8000`` / ``0x80000000``) is an empty cell: no sample. The channels' ``skew`` is not
applied (it is below a µs on the recorders seen).

The time of sample *n* (1-based) is the first sample's time in the ``.cfg`` plus

- the **sample-rate table** (``nrates`` lines ``samp, endsamp``): each sample ``1 / samp`` after
  the one before, ``samp`` of the segment it lies in (the ``comtrade`` package's convention); or,
  where the rate is 0 (``nrates = 0``: time stamps are *critical*, C37.111 §7),
- the ``.dat``'s **time stamp** × ``timemult``, in µs (ns when the ``.cfg``'s times have 9
  fractional digits, 2013); a missing time stamp (``0xFFFFFFFF``, an empty ASCII field) makes the
  sample's time unreadable (quarantined as ``bad_timestamp``).

The first sample's time is local time in ``plant.timezone`` for a 1999 file; a 2013 file's
``time_code`` (``+1``, ``-5h30``: the recorded time's offset from UTC) applies when it has one.
Elapsed time is added in UTC.

Refused, in one line naming the file: a ``.cfg`` that is not COMTRADE 1999/2013 (the line and what
was expected), a ``.cfg`` without its ``.dat``, a ``.dat`` shorter (or longer) than the ``.cfg``
promises, an ASCII line that is not a sample record. Memory is bounded by a batch: binary records
are read with ``numpy.fromfile`` a batch at a time, ASCII lines in blocks of text.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Iterator

import numpy as np
import polars as pl

from flows.common.errors import ValvemonError
from flows.ingest.formats.blocks import line_blocks, lookahead
from schemas.plant_config import ExportSpec
from transforms.ingest.errors import IngestError
from transforms.ingest.timestamps import localize
from transforms.ingest.units import FileUnits

SUFFIXES = (".cfg",)
FILE_FORMATS = ("comtrade",)
"""The manifest's ``file_format`` of the files this module reads."""
REVISIONS = ("1999", "2013")
"""``rev_year`` values read (2001 is read as 1999, which it amends)."""
DAT_KINDS = {"BINARY": "<i2", "BINARY32": "<i4", "FLOAT32": "<f4"}
"""Binary ``.dat`` kinds → the dtype of an analog value (``ASCII`` is text)."""
MISSING_RAW = {"BINARY": -32768, "BINARY32": -(2**31)}
"""The raw value of a missing binary sample."""
ASCII_MISSING = 99999.0
"""The raw value of a missing ASCII sample (1999; 2013 also leaves the field empty)."""
MISSING_TIMESTAMP = 0xFFFFFFFF
_TIME_CODE = re.compile(r"^([+-]?)(\d{1,2})(?:h(\d{1,2}))?$")


@dataclass(frozen=True)
class Analog:
    """One analog channel of the ``.cfg``."""

    number: int
    ch_id: str
    unit: str
    a: float
    b: float
    factor: float
    """``primary / secondary`` for a channel scaled to the secondary side, else 1."""
    line: int


@dataclass(frozen=True)
class Cfg:
    """What the ingest needs of a ``.cfg``."""

    rev_year: str
    analogs: tuple[Analog, ...]
    digitals: tuple[str, ...]
    rates: tuple[tuple[float, int], ...]
    """``(samp, endsamp)`` per segment (``samp`` 0: the time stamps are the time)."""
    samples: int
    start: datetime
    """The first sample's time as written (naive)."""
    start_line: int
    ft: str
    timemult: float
    stamp_ns: int
    """Nanoseconds per time-stamp unit (1000: µs; 1: ns)."""
    utc_offset_s: int | None
    """A 2013 file's ``time_code`` in seconds (None: local time in ``plant.timezone``)."""

    @property
    def timestamped(self) -> bool:
        """Whether some sample's time is its time stamp (a rate of 0)."""
        return any(samp == 0 for samp, _ in self.rates)


class _Lines:
    """The ``.cfg``'s lines, read one at a time, for messages with the line number."""

    def __init__(self, path: Path, text: str):
        self.path, self.lines, self.i = path, text.splitlines(), 0

    def next(self, what: str) -> list[str]:
        while self.i < len(self.lines):
            self.i += 1
            line = self.lines[self.i - 1].strip().strip("\x1a")
            if line:
                return [f.strip() for f in line.split(",")]
        raise ValvemonError(f"{self.path}: line {self.i + 1}: expected {what}, the file ends (a COMTRADE .cfg, IEEE C37.111)")

    def fail(self, what: str, fields: list[str]) -> ValvemonError:
        return ValvemonError(f"{self.path}: line {self.i}: expected {what}, found {','.join(fields)!r} (a COMTRADE .cfg, IEEE C37.111)")


def _number(lines: _Lines, fields: list[str], k: int, what: str, kind=float):
    try:
        return kind(fields[k]) if k < len(fields) and fields[k] != "" else kind(0)
    except ValueError:
        raise lines.fail(what, fields) from None


def _time(lines: _Lines, what: str) -> tuple[datetime, int]:
    """``dd/mm/yyyy,hh:mm:ss.ssssss[sss]`` → (naive time to the µs, fractional digits)."""
    fields = lines.next(what)
    m = re.fullmatch(r"(\d{1,2})/(\d{1,2})/(\d{4}),(\d{1,2}):(\d{2}):(\d{2})(?:\.(\d{1,9}))?", ",".join(fields))
    if m is None:
        raise lines.fail(what, fields)
    d, mo, y, h, mi, s, frac = m.groups()
    frac = frac or ""
    try:
        t = datetime(int(y), int(mo), int(d), int(h), int(mi), int(s), int((frac + "000000")[:6]))
    except ValueError:
        raise lines.fail(what, fields) from None
    return t, len(frac)


def parse_cfg(path: Path) -> Cfg:
    """The ``.cfg`` of a COMTRADE recording (module doc).

    Raises
    ------
    ValvemonError
        Naming the file and the line: not a 1999 or 2013 ``.cfg``.
    """
    raw = path.read_bytes()
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        text = raw.decode("cp1252", errors="replace")  # station names in a Windows code page
    lines = _Lines(path, text)
    head = lines.next("station_name,rec_dev_id,rev_year")
    rev = head[2] if len(head) > 2 else "1991"
    if rev not in (*REVISIONS, "2001"):
        raise lines.fail(f"station_name,rec_dev_id,rev_year with rev_year {' or '.join(REVISIONS)}", head)
    counts = lines.next("TT,##A,##D (the number of channels)")
    m = [re.fullmatch(r"(\d+)([AD]?)", c.upper()) for c in counts]
    if len(counts) != 3 or not all(m) or m[1].group(2) != "A" or m[2].group(2) != "D":
        raise lines.fail("TT,##A,##D (the number of channels)", counts)
    n_analog, n_digital = int(m[1].group(1)), int(m[2].group(1))
    analogs = []
    for _ in range(n_analog):
        f = lines.next("an analog channel An,ch_id,ph,ccbm,uu,a,b,skew,min,max,primary,secondary,PS")
        if len(f) < 10:
            raise lines.fail("an analog channel An,ch_id,ph,ccbm,uu,a,b,skew,min,max,primary,secondary,PS", f)
        what = "an analog channel's numbers"
        number, a, b = _number(lines, f, 0, what, int), _number(lines, f, 5, what), _number(lines, f, 6, what)
        factor = 1.0
        if len(f) < 13 or f[12].upper() not in ("P", "S"):  # critical in C37.111-1999 and -2013: a blank one is not "primary"
            raise lines.fail("an analog channel's PS field P or S (are a·raw + b primary or secondary values?) in field 13 of "
                             "An,ch_id,ph,ccbm,uu,a,b,skew,min,max,primary,secondary,PS", f)  # fmt: skip
        if f[12].upper() == "S":
            primary, secondary = _number(lines, f, 10, what), _number(lines, f, 11, what)
            if not (primary > 0 and secondary > 0):
                raise lines.fail("primary and secondary factors > 0 for a channel scaled to the secondary side (PS = S)", f)
            factor = primary / secondary
        analogs.append(Analog(number, f[1], f[4], a, b, factor, lines.i))
    digitals = [lines.next("a digital channel Dn,ch_id,ph,ccbm,y")[1:2] or [""] for _ in range(n_digital)]
    lines.next("lf (the line frequency)")
    nrates = _number(lines, counted := lines.next("nrates"), 0, "nrates", int)
    if nrates < 0:
        raise lines.fail("nrates >= 0 (the number of sample rates; 0: time stamps only)", counted)
    rates = []
    for _ in range(max(nrates, 1)):
        f = lines.next("samp,endsamp")
        rates.append((_number(lines, f, 0, "samp,endsamp"), _number(lines, f, 1, "samp,endsamp", int)))
    if nrates == 0 and rates[0][0] != 0:
        raise lines.fail("0,endsamp after nrates = 0", [str(rates[0][0]), str(rates[0][1])])
    if any(samp < 0 for samp, _ in rates) or any(e2 < e1 for (_, e1), (_, e2) in zip(rates, rates[1:])):
        raise lines.fail("sample rates >= 0 and rising endsamp", [str(r) for r in rates])
    start, digits = _time(lines, "the first sample's time dd/mm/yyyy,hh:mm:ss.ssssss")
    start_line = lines.i
    _time(lines, "the trigger time dd/mm/yyyy,hh:mm:ss.ssssss")
    ft = lines.next("the .dat's file type ASCII, BINARY, BINARY32 or FLOAT32")
    kind = ft[0].upper()
    if kind not in ("ASCII", *DAT_KINDS):
        raise lines.fail("the .dat's file type ASCII, BINARY, BINARY32 or FLOAT32", ft)
    timemult = 1.0
    if lines.i < len(lines.lines) and any(x.strip() for x in lines.lines[lines.i :]):
        given = lines.next("timemult")
        timemult = _number(lines, given, 0, "timemult")
        if given[0] == "":
            timemult = 1.0  # left out: time stamps in µs (ns) as written
        elif not timemult > 0:
            raise lines.fail("timemult > 0 (the time stamps' multiplier)", given)
    offset = None
    if rev == "2013" and any(x.strip() for x in lines.lines[lines.i :]):
        codes = lines.next("time_code,local_code")
        tc = _TIME_CODE.match(codes[0].replace(" ", ""))
        if tc is None:
            raise lines.fail("time_code,local_code (time_code such as +1, 0 or -5h30)", codes)
        offset = (-1 if tc.group(1) == "-" else 1) * (int(tc.group(2)) * 3600 + int(tc.group(3) or 0) * 60)
    return Cfg(rev, tuple(analogs), tuple(d[0] for d in digitals), tuple(rates), rates[-1][1], start, start_line, kind, timemult, 1 if digits > 6 else 1000, offset)


def dat_path(cfg_path: Path) -> Path:
    """The ``.dat`` beside a ``.cfg`` (the same stem; ``.dat`` or ``.DAT``).

    Raises
    ------
    ValvemonError
        When there is none.
    """
    for suffix in (".dat", ".DAT", ".Dat"):
        p = cfg_path.with_suffix(suffix)
        if p.is_file():
            return p
    raise ValvemonError(f"{cfg_path}: no data file {cfg_path.with_suffix('.dat').name} beside it (a COMTRADE recording is a .cfg and its .dat)")


@dataclass
class ComtradeLayout:
    """A recording's channels as the ingest reads them: a column per channel, names unique."""

    cfg: Cfg
    dat: Path
    columns: list[str]
    """Analog channels, then digital ones (frame column names: the channel ids)."""
    units: FileUnits
    origin_ns: int
    """The first sample's time (UTC ns)."""


def _columns(cfg: Cfg, export: ExportSpec, path: Path) -> list[str]:
    """Column names: the channel ids. Two analog channels of one id refuse the file; a digital
    channel's id that is empty or already taken becomes ``Dn`` (``n`` its number), or ``id#Dn``."""
    out: list[str] = []
    lines: dict[str, int] = {}
    for c in cfg.analogs:
        name = c.ch_id or f"A{c.number}"
        if name in lines or name == export.timestamp_column:
            where = f"also on line {lines[name]}" if name in lines else "the name of the time column (export.timestamp_column)"
            raise ValvemonError(f"{path}: line {c.line}: analog channel id {name!r} is {where}: channel ids must differ")
        lines[name] = c.line
        out.append(name)
    taken = set(out) | {export.timestamp_column}
    for k, d in enumerate(cfg.digitals):
        name = d if d and d not in taken else f"{d}#D{k + 1}" if d else f"D{k + 1}"
        taken.add(name)
        out.append(name)
    return out


def comtrade_layout(path: Path, export: ExportSpec, timezone: str) -> ComtradeLayout:
    """Parse the ``.cfg``, find the ``.dat`` and check its size (module doc).

    Raises
    ------
    ValvemonError
        Naming the file: the layout is not wide, the ``.cfg`` is not COMTRADE, no ``.dat``, a
        ``.dat`` of another size than promised, a first time that does not exist locally.
    """
    if export.layout != "wide":
        raise ValvemonError(f"{path}: a COMTRADE recording is read in the wide layout (a channel per tag); the configuration has export.layout = {export.layout!r}")
    cfg = parse_cfg(path)
    dat = dat_path(path)
    if cfg.ft != "ASCII":
        record = _record_dtype(cfg).itemsize
        size, want = dat.stat().st_size, cfg.samples * record
        if size != want:
            short = "shorter" if size < want else "longer"
            raise ValvemonError(f"{dat}: {size:,} bytes, {short} than the {cfg.samples:,} samples of {record} bytes its .cfg promises ({want:,} bytes)")
    columns = _columns(cfg, export, path)
    units = {columns[k]: (c.unit, f"line {c.line}: analog channel {c.number}") for k, c in enumerate(cfg.analogs)}
    naive = pl.Series([cfg.start], dtype=pl.Datetime("ns"))
    if cfg.utc_offset_s is not None:
        origin = int(naive.to_physical()[0]) - cfg.utc_offset_s * 10**9
    else:
        try:
            origin = int(localize(naive, timezone, ambiguous=export.ambiguous_time).to_physical()[0])
        except IngestError as exc:
            raise ValvemonError(f"{path}: line {cfg.start_line}: {exc.detail}") from None
    return ComtradeLayout(cfg, dat, columns, units, origin)


def _record_dtype(cfg: Cfg) -> np.dtype:
    words = math.ceil(len(cfg.digitals) / 16)
    return np.dtype([("n", "<u4"), ("t", "<u4"), ("a", DAT_KINDS[cfg.ft], (len(cfg.analogs),)), ("d", "<u2", (words,))])


def _elapsed_ns(cfg: Cfg, n: np.ndarray, stamps: np.ndarray | None) -> np.ndarray:
    """Nanoseconds after the first sample of samples ``n`` (1-based), from the rate table or,
    where the rate is 0, from the time stamps (float; NaN where a needed stamp is missing)."""
    samp = np.array([r[0] for r in cfg.rates])
    end = np.array([r[1] for r in cfg.rates])
    start_n = np.r_[1, end[:-1]]
    step = np.divide(1e9, samp, out=np.zeros_like(samp), where=samp > 0)
    start_t = np.r_[0.0, np.cumsum((end - start_n) * step)[:-1]]
    k = np.minimum(np.searchsorted(end, n, side="left"), len(end) - 1)
    t = start_t[k] + (n - start_n[k]) * step[k]
    if cfg.timestamped:
        by_stamp = samp[k] == 0
        if stamps is None:
            stamps = np.full(len(n), np.nan)
        t = np.where(by_stamp, stamps * cfg.timemult * cfg.stamp_ns, t)
    return t


def _frame(layout: ComtradeLayout, export: ExportSpec, n: np.ndarray, stamps: np.ndarray | None, analog: list[np.ndarray], digital: list) -> pl.DataFrame:
    """One batch as a wide frame: the UTC time of samples ``n`` (1-based), the analog channels
    scaled (NaN where missing) and the digital ones (numpy arrays or Series of 0/1)."""
    cfg = layout.cfg
    elapsed = _elapsed_ns(cfg, n, stamps)
    ok = np.isfinite(elapsed)
    ns = np.where(ok, np.rint(np.where(ok, elapsed, 0.0)), 0).astype(np.int64) + layout.origin_ns
    time = pl.Series(export.timestamp_column, ns, dtype=pl.Int64)
    if not ok.all():
        time = time.scatter(np.flatnonzero(~ok), None)
    columns = [time.cast(pl.Datetime("ns", "UTC"))]
    for name, c, raw in zip(layout.columns, cfg.analogs, analog):
        columns.append(pl.Series(name, (c.a * raw + c.b) * c.factor if c.factor != 1.0 else c.a * raw + c.b, dtype=pl.Float64))
    columns += [pl.Series(name, bits).cast(pl.UInt8, strict=False) for name, bits in zip(layout.columns[len(cfg.analogs) :], digital)]
    return pl.DataFrame(columns)


def _binary_batches(layout: ComtradeLayout, export: ExportSpec, rows: int) -> Iterator[tuple[pl.DataFrame, int, bool]]:
    cfg = layout.cfg
    dtype = _record_dtype(cfg)
    missing = MISSING_RAW.get(cfg.ft)
    with open(layout.dat, "rb") as fh:
        for a in range(0, cfg.samples, rows):
            b = min(a + rows, cfg.samples)
            rec = np.fromfile(fh, dtype=dtype, count=b - a)
            n = np.arange(a + 1, b + 1, dtype=np.int64)
            stamps = None
            if cfg.timestamped:
                stamps = rec["t"].astype(np.float64)
                stamps[rec["t"] == MISSING_TIMESTAMP] = np.nan
            analog = []
            for j in range(len(cfg.analogs)):
                raw = rec["a"][:, j].astype(np.float64)
                if missing is not None:
                    raw[rec["a"][:, j] == missing] = np.nan
                analog.append(raw)
            digital = [((rec["d"][:, k // 16] >> (k % 16)) & 1).astype(np.uint8) for k in range(len(cfg.digitals))]
            df = _frame(layout, export, n, stamps, analog, digital)
            yield _nan_to_null(df, layout), a + 1, b == cfg.samples


def _nan_to_null(df: pl.DataFrame, layout: ComtradeLayout) -> pl.DataFrame:
    """A missing raw value (NaN after scaling) is an empty cell: no sample."""
    names = layout.columns[: len(layout.cfg.analogs)]
    return df.with_columns([pl.col(c).fill_nan(None) for c in names if df[c].is_nan().any()])


def _ascii_batches(layout: ComtradeLayout, export: ExportSpec, block_bytes: int) -> Iterator[tuple[pl.DataFrame, int, bool]]:
    cfg = layout.cfg
    n_a, n_d = len(cfg.analogs), len(cfg.digitals)
    schema = {"n": pl.Int64, "t": pl.Float64} | {f"a{j}": pl.Float64 for j in range(n_a)} | {f"d{k}": pl.Int64 for k in range(n_d)}
    first = 1
    with open(layout.dat, "rb") as fh:
        for block, final in lookahead(line_blocks(fh, block_bytes)):
            lines = block.count(b"\n") + (not block.endswith(b"\n"))
            df = _ascii_block(block, schema, layout.dat, first)
            if first - 1 + df.height > cfg.samples:
                raise ValvemonError(f"{layout.dat}: line {cfg.samples + 1}: more samples than the {cfg.samples:,} its .cfg promises")
            n = np.arange(first, first + df.height, dtype=np.int64)
            stamps = df["t"].fill_null(np.nan).to_numpy() if cfg.timestamped else None
            analog = []
            for j in range(n_a):
                raw = df[f"a{j}"].fill_null(np.nan).to_numpy().copy()
                raw[raw == ASCII_MISSING] = np.nan
                analog.append(raw)
            digital = [df[f"d{k}"] for k in range(n_d)]
            if final and first - 1 + df.height < cfg.samples:
                raise ValvemonError(f"{layout.dat}: {first - 1 + df.height:,} samples, fewer than the {cfg.samples:,} its .cfg promises (a truncated data file)")
            yield _nan_to_null(_frame(layout, export, n, stamps, analog, digital), layout), first, final
            first += lines
        if first == 1 and cfg.samples:
            raise ValvemonError(f"{layout.dat}: no samples, the .cfg promises {cfg.samples:,} (a truncated data file)")


def _ascii_block(block: bytes, schema: dict, dat: Path, first: int) -> pl.DataFrame:
    """One block of ASCII sample lines (the file's lines ``first``…) → frame (``n, t, a0…, d0…``);
    a line that is no sample record (another number of fields, a blank line, text where a number
    belongs) refuses the file, naming the line."""
    block = block.rstrip(b"\x1a")  # a DOS end-of-file mark after the last line
    buf = np.frombuffer(block, dtype=np.uint8)
    ends = np.flatnonzero(buf == ord("\n"))
    if not block.endswith(b"\n"):
        ends = np.r_[ends, len(buf)]
    commas = np.searchsorted(np.flatnonzero(buf == ord(",")), ends)
    per_line = np.diff(np.r_[0, commas])
    wrong = np.flatnonzero(per_line != len(schema) - 1)
    if len(wrong):
        _refuse_line(block, ends, int(wrong[0]), len(schema), dat, first)
    try:
        return pl.read_csv(block, has_header=False, new_columns=list(schema), schema=schema)
    except pl.exceptions.PolarsError:
        pass
    for i, line in enumerate(block.split(b"\n")[: len(ends)]):
        try:
            [float(x) for x in line.split(b",") if x.strip()]
        except ValueError:
            _refuse_line(block, ends, i, len(schema), dat, first)
    raise ValvemonError(f"{dat}: lines {first:,} to {first + len(ends) - 1:,}: not a readable COMTRADE ASCII data file")


def _refuse_line(block: bytes, ends: np.ndarray, i: int, width: int, dat: Path, first: int):
    a = 0 if i == 0 else int(ends[i - 1]) + 1
    line = block[a : int(ends[i])].decode("utf-8", "replace").strip()
    raise ValvemonError(f"{dat}: line {first + i}: expected a sample record of {width} fields (n, time stamp, analog and digital values), found {line[:80]!r}")


def detect(head: bytes, name: str) -> str | None:
    """A COMTRADE recording is found by its ``.cfg`` (its ``.dat`` is read with it)."""
    return "comtrade" if name.endswith(SUFFIXES) else None


def members(path: Path) -> list[Path]:
    """The ``.cfg`` and its ``.dat``: the content hash covers both."""
    return [path, dat_path(path)]


def describe(src, export: ExportSpec, timezone: str) -> None:
    """Parse the ``.cfg`` and check the ``.dat``'s size (:func:`comtrade_layout`)."""
    src.layout = comtrade_layout(src.path, export, timezone)
    src.units = src.layout.units


def iload(src, export: ExportSpec, tags, batch_samples: int, block_bytes: int) -> Iterator[tuple[pl.DataFrame, int, bool]]:
    """The recording as wide frames: ``(frame, first sample number, last)``, of about
    ``batch_samples`` samples (binary) or ``block_bytes`` of text (ASCII); columns
    ``export.timestamp_column`` (UTC) and one per channel."""
    layout = src.layout
    if layout.cfg.samples == 0:
        raise ValvemonError(f"{layout.dat}: the .cfg promises no samples (endsamp 0)")
    if layout.cfg.ft == "ASCII":
        yield from _ascii_batches(layout, export, block_bytes)
    else:
        rows = max(batch_samples // max(len(layout.columns), 1), 1024)
        yield from _binary_batches(layout, export, rows)
