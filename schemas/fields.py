"""The field registry: every column valvemon writes, named once with dtype, unit and range.

The polars, pyarrow and pandera schemas of each table are built from these definitions
(:func:`polars_schema`, :func:`arrow_schema`, :func:`pandera_schema`), so a column cannot mean
one thing in the lake and another in the warehouse.

pandera and pyarrow are imported only when a schema of theirs is built: the registry itself is
read by every command, ``valvemon --help`` and ``valvemon query`` included, and pandera alone
takes seconds to import. The pandera schemas of the tables are built on first use
(``SENSOR_SCHEMA`` …, :data:`PANDERA_SCHEMAS`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from typing import TYPE_CHECKING

import polars as pl

if TYPE_CHECKING:
    import pandera.polars as pa
    import pyarrow as pa_arrow

EDGES: tuple[str, ...] = ("s1", "1r", "s2", "2r")
"""The four control edges, in the order every array and table uses."""

SIGNALS: tuple[str, ...] = ("ps", "pr", "p1", "p2", "x_spool", "x_cyl", "x_ref")
"""Signal names of the plant configuration's ``[valves.tags]`` table."""

REQUIRED_SIGNALS: tuple[str, ...] = ("ps", "pr", "p1", "p2", "x_spool", "x_cyl")
"""Signals without which a valve cannot be monitored (``x_ref`` is optional)."""

SIGNAL_KIND: dict[str, str] = {
    "ps": "pressure",
    "pr": "pressure",
    "p1": "pressure",
    "p2": "pressure",
    "x_spool": "spool_position",
    "x_cyl": "position",
    "x_ref": "spool_position",
}
"""Kind of each signal, which decides the units it accepts (see :mod:`schemas.units`)."""


@dataclass(frozen=True)
class Field:
    """One column: name (with unit suffix), dtype, unit, meaning and physical range."""

    name: str
    dtype: pl.DataType
    unit: str
    description: str
    nullable: bool = False
    ge: float | None = None
    le: float | None = None
    isin: tuple[str, ...] | None = None


UTC_US = pl.Datetime("us", "UTC")

# Columns several tables share, to the letter.
_VALVE_ID = Field("valve_id", pl.Utf8, "", "Valve identifier.")
_EDGE = Field("edge", pl.Utf8, "", "Control edge.", isin=EDGES)
_WINDOW_START = Field("window_start", UTC_US, "", "First sample of the monitoring window (UTC).")
_WINDOW_END = Field("window_end", UTC_US, "", "Last sample of the monitoring window (UTC).")
_OPERATING_HOURS = Field("operating_hours", pl.Float64, "h", "Calendar hours since commissioning at window_start.")

SIGNAL_COLUMN: dict[str, str] = {
    "ps": "ps_pa",
    "pr": "pr_pa",
    "p1": "p1_pa",
    "p2": "p2_pa",
    "x_spool": "x_spool_m",
    "x_cyl": "x_cyl_m",
    "x_ref": "x_ref_m",
}
"""Canonical lake column of each configured signal."""

SENSOR_FIELDS: tuple[Field, ...] = (
    Field("valve_id", pl.Utf8, "", "Valve identifier; also the hive partition key."),
    Field("date", pl.Date, "", "UTC calendar date of the sample; also the hive partition key."),
    Field("timestamp_utc", UTC_US, "", "Sample time, microseconds, UTC."),
    Field("ps_pa", pl.Float32, "Pa", "Supply pressure.", ge=-1e5, le=6e7),
    Field("pr_pa", pl.Float32, "Pa", "Return (tank) pressure.", ge=-1e5, le=6e7),
    Field("p1_pa", pl.Float32, "Pa", "Head-side chamber pressure (port 1).", ge=-1e5, le=6e7),
    Field("p2_pa", pl.Float32, "Pa", "Rod-side chamber pressure (port 2).", ge=-1e5, le=6e7),
    Field("x_spool_m", pl.Float32, "m", "Spool position x; > 0 opens s1 and 2r.", ge=-0.02, le=0.02),
    Field("x_cyl_m", pl.Float32, "m", "Cylinder position X; grows on extension.", ge=-0.1, le=20.0),
    Field("x_ref_m", pl.Float32, "m", "Spool reference from the position controller.", nullable=True, ge=-0.02, le=0.02),
)
"""The lake's canonical sensor frame (``lake/sensors/valve_id=…/date=…``).

The signals are float32: measured against float64 (``docs/ingest.md``, "Storage"), the zstd
lake is ~15 % smaller on disk and half the size in memory, decodes ~1.8× faster per core and is
written ~1.5× faster, while float32's round-off (≤ 6e-8 relative: ≤ 1 Pa at 200 bar, ≤ 0.03 µm
at 0.6 m) stays below 1/1000 of a 16-bit sensor's quantisation step. Cast to Float64 before
long accumulations.
"""


def polars_schema(fields: tuple[Field, ...]) -> pl.Schema:
    """Polars schema of a table."""
    return pl.Schema({f.name: f.dtype for f in fields})


def arrow_schema(fields: tuple[Field, ...]) -> pa_arrow.Schema:
    """Pyarrow schema of a table, with units and descriptions as field metadata."""
    import pyarrow as pa_arrow

    empty = pl.DataFrame(schema=polars_schema(fields)).to_arrow()
    return pa_arrow.schema(
        [
            pa_arrow.field(
                f.name,
                empty.schema.field(f.name).type,
                nullable=f.nullable,
                metadata={"unit": f.unit, "description": f.description},
            )
            for f in fields
        ]
    )


def _checks(f: Field) -> list[pa.Check]:
    import pandera.polars as pa

    checks = []
    if f.ge is not None:
        checks.append(pa.Check.ge(f.ge, name=f"{f.name} >= {f.ge:g} {f.unit}".rstrip()))
    if f.le is not None:
        checks.append(pa.Check.le(f.le, name=f"{f.name} <= {f.le:g} {f.unit}".rstrip()))
    if f.isin is not None:
        checks.append(pa.Check.isin(list(f.isin)))
    return checks


def pandera_schema(fields: tuple[Field, ...], name: str) -> pa.DataFrameSchema:
    """Pandera schema of a table: names, dtypes, nullability and physical ranges.

    Validate collected frames (``schema.validate(df, lazy=True)``): on a LazyFrame pandera
    checks only names and types.
    """
    import pandera.polars as pa

    return pa.DataFrameSchema(
        {f.name: pa.Column(f.dtype, checks=_checks(f), nullable=f.nullable) for f in fields},
        name=name,
        strict=True,
        ordered=True,
    )



def conforms(frame: pl.DataFrame, fields: tuple[Field, ...]) -> bool:
    """Whether ``frame`` passes every check of ``pandera_schema(fields)``, in one polars pass.

    The same checks as the pandera schema: the columns by name and order, their dtypes, no null
    (nor NaN, in a float column) where a field is not nullable, and ``ge``, ``le`` and ``isin``
    with nulls passing (pandera's ``ignore_na``; a NaN fails ``le``, as in pandera). True only
    when all hold; False when any fails or cannot be told here (a dtype that is not exactly the
    field's): validate with pandera then, which names the failure. On millions of rows this is
    ~30× cheaper than pandera's one query per check (``docs/ingest.md``, "Throughput").
    """
    if frame.columns != [f.name for f in fields]:
        return False
    if any(frame.schema[f.name] != f.dtype for f in fields):
        return False
    checks = []
    for f in fields:
        c = pl.col(f.name)
        if not f.nullable:
            checks.append(c.is_not_null().all(ignore_nulls=False))
            if f.dtype.is_float():
                checks.append(c.is_not_nan().all())
        if f.ge is not None:
            checks.append(c.ge(f.ge).all())
        if f.le is not None:
            checks.append(c.le(f.le).all())
        if f.isin is not None:
            checks.append(c.is_in(list(f.isin)).all())
    if not checks or frame.height == 0:
        return True
    return all(frame.select(e.alias(str(i)) for i, e in enumerate(checks)).row(0))


# --- ingest: raw rows, quarantine, gaps, manifest, runs ---------------------------------------

UTC_NS = pl.Datetime("ns", "UTC")
"""Export timestamps before they are put on the lake's grid (PI writes 100 ns)."""

_FILE_HASH = Field("file_hash", pl.Utf8, "", "Content hash of the source file (as in ingest_manifest.file_hash).")
_SOURCE_FILE = Field("source_file", pl.Utf8, "", "Path of the source file as given to the ingest.")
_LINE = Field("line", pl.Int64, "", "Line of the source file (CSV, header = line 1) or row (Parquet, first row = 1).", ge=1)

RAW_ROW_FIELDS: tuple[Field, ...] = (
    _LINE,
    Field("tag", pl.Categorical, "", "Historian tag name as exported (during ingest an Enum of the plant's tags, which also checks them)."),
    Field("timestamp_utc", UTC_NS, "", "Sample time at the export's full resolution, UTC."),
    Field("value_si", pl.Float64, "", "Sample value converted to the SI unit of the tag's signal (Pa or m).", ge=-1e12, le=1e12),
)
"""One accepted sample of one tag, as the ingest reads it from an export (long form)."""

QUARANTINE_REASONS: tuple[str, ...] = (
    "bad_quality", "non_numeric", "non_finite", "missing_value", "missing_tag", "bad_timestamp", "implausible_time", "out_of_range",
    "field_count", "truncated", "clock_step",
)  # fmt: skip
"""Why a sample is quarantined (``transforms.ingest.samples``; ``docs/ingest.md``)."""

FAULT_REASONS: tuple[str, ...] = ("bad_timestamp", "implausible_time", "out_of_range", "field_count")
"""The quarantine reasons whose share per tag and file ``export.max_bad_share`` bounds; each is
also a column of ``ingest_manifest``."""

QUARANTINE_FIELDS: tuple[Field, ...] = (
    _FILE_HASH,
    _SOURCE_FILE,
    _LINE,
    Field("tag", pl.Utf8, "", "Historian tag name.", nullable=True),
    Field("timestamp_raw", pl.Utf8, "", "Timestamp as written in the export.", nullable=True),
    Field("value_raw", pl.Utf8, "", "Value as written in the export (e.g. a PI digital state).", nullable=True),
    Field("quality", pl.Utf8, "", "Quality code as written in the export.", nullable=True),
    Field("reason", pl.Utf8, "", "Why the sample was set aside.", isin=QUARANTINE_REASONS),
    Field("run_id", pl.Utf8, "", "Ingest run that read the file."),
    Field("ingested_at", UTC_US, "", "When the ingest read the file."),
)
"""Samples of an export set aside by the ingest (table ``quarantine``)."""

GAP_FIELDS: tuple[Field, ...] = (
    _FILE_HASH,
    _SOURCE_FILE,
    _VALVE_ID,
    Field("signal", pl.Utf8, "", "Signal of the plant configuration's [valves.tags].", isin=SIGNALS),
    Field("tag", pl.Utf8, "", "Historian tag name."),
    Field("gap_start", UTC_US, "", "Last sample before the gap (UTC, truncated to µs)."),
    Field("gap_end", UTC_US, "", "First sample after the gap (UTC, truncated to µs)."),
    Field("duration_s", pl.Float64, "s", "Time between the two samples.", ge=0.0),
)
"""Gaps longer than ``export.max_gap_s`` between consecutive accepted samples of a tag (table ``ingest_gaps``)."""

MANIFEST_FIELDS: tuple[Field, ...] = (
    Field("file_hash", pl.Utf8, "", "Content hash of the file, 'blake3:' + BLAKE3-256 in hex ('sha256:' + SHA-256 for files ingested before BLAKE3); the table's key."),
    Field("source_file", pl.Utf8, "", "Path of the file when it was ingested."),
    Field("size_bytes", pl.Int64, "B", "File size.", ge=0),
    Field("file_format", pl.Utf8, "", "How the file was read.", isin=("csv", "csv.gz", "parquet", "tdms")),
    Field("layout", pl.Utf8, "", "Export layout of the plant configuration.", isin=("long", "wide")),
    Field("rows_in", pl.Int64, "", "Data rows in the file.", ge=0),
    Field("samples_in", pl.Int64, "", "Tag values in the file (long: one per row; wide: non-empty cells).", ge=0),
    Field("quarantined", pl.Int64, "", "Samples set aside (table quarantine).", ge=0),
    Field("duplicates", pl.Int64, "", "Exact duplicate samples dropped (same tag, time and value).", ge=0),
    Field("conflicts", pl.Int64, "", "Samples dropped by export.duplicate_rule (same tag and time, other value).", ge=0),
    Field("gaps", pl.Int64, "", "Gaps longer than export.max_gap_s (table ingest_gaps).", ge=0),
    Field("rows_out", pl.Int64, "", "Lake rows (valve × grid instant) the file yields.", ge=0),
    Field("rows_added", pl.Int64, "", "Lake rows that were not in the lake before.", ge=0),
    Field("lake_conflicts", pl.Int64, "", "Lake rows already present with other values, resolved by export.duplicate_rule.", ge=0),
    Field("partitions", pl.Int64, "", "Lake partitions (valve, UTC date) the file touches.", ge=0),
    Field("valves", pl.Utf8, "", "Valve ids found in the file, comma-separated."),
    Field("time_start", UTC_US, "", "Earliest accepted sample (UTC).", nullable=True),
    Field("time_end", UTC_US, "", "Latest accepted sample (UTC).", nullable=True),
    Field("run_id", pl.Utf8, "", "Ingest run that ingested the file."),
    Field("ingested_at", UTC_US, "", "When the file was ingested."),
    Field("bad_timestamp", pl.Int64, "", "Of quarantined: samples whose timestamp is missing or not in export.timestamp_format.", ge=0),
    Field("implausible_time", pl.Int64, "", "Of quarantined: samples later than the ingest's time + 1 day or before their valve's commissioned.", ge=0),
    Field("out_of_range", pl.Int64, "", "Of quarantined: samples outside the physical range of their lake column (e.g. 1e308).", ge=0),
    Field("other_tags", pl.Int64, "", "Tags (long) or columns (wide) of the file that no valve has, read past (export.other_tags = 'ignore').", ge=0),
    Field("other_samples", pl.Int64, "", "Rows (long) or non-empty cells (wide) of those tags, not in samples_in.", ge=0),
    Field("other_tag_names", pl.Utf8, "", "Those tags, comma-separated in the order of the file (empty: none)."),
    Field("field_count", pl.Int64, "", "Of quarantined: samples of text rows whose field count is not the header's.", ge=0),
    Field("truncated", pl.Int64, "", "1 when the text file's last line has no line end (the file was cut; that line's samples are quarantined), else 0.", ge=0, le=1),
    Field("clock_step", pl.Int64, "", "Of quarantined: samples of a wide export's rows at and after a backward step of its clock (export.clock_steps).", ge=0),
)
"""One row per ingested export file (table ``ingest_manifest``)."""

INGEST_RUN_FIELDS: tuple[Field, ...] = (
    Field("run_id", pl.Utf8, "", "Identifier of the ingest run; the table's key."),
    Field("started_at", UTC_US, "", "When the run started."),
    Field("finished_at", UTC_US, "", "When the run ended (null while running or after a crash).", nullable=True),
    Field("status", pl.Utf8, "", "running, ok or failed.", isin=("running", "ok", "failed")),
    Field("message", pl.Utf8, "", "The error of a failed run.", nullable=True),
    Field("config_file", pl.Utf8, "", "Plant configuration used."),
    Field("files_seen", pl.Int64, "", "Export files named by the run.", ge=0),
    Field("files_ingested", pl.Int64, "", "Files read into the lake.", ge=0),
    Field("files_skipped", pl.Int64, "", "Files skipped because the manifest already holds their content.", ge=0),
    Field("rows_read", pl.Int64, "", "Data rows read.", ge=0),
    Field("samples_read", pl.Int64, "", "Tag values read.", ge=0),
    Field("rows_written", pl.Int64, "", "Lake rows produced.", ge=0),
    Field("rows_added", pl.Int64, "", "Lake rows new to the lake.", ge=0),
    Field("quarantined", pl.Int64, "", "Samples set aside.", ge=0),
    Field("duplicates", pl.Int64, "", "Exact duplicate samples dropped.", ge=0),
    Field("conflicts", pl.Int64, "", "Samples dropped by export.duplicate_rule.", ge=0),
    Field("lake_conflicts", pl.Int64, "", "Lake rows replaced or kept by export.duplicate_rule.", ge=0),
    Field("gaps", pl.Int64, "", "Gaps found.", ge=0),
    Field("partitions_written", pl.Int64, "", "Lake partition files replaced.", ge=0),
)
"""One row per ``valvemon ingest`` run with its counts (table ``ingest_runs``)."""

PANDERA_SCHEMAS: dict[str, tuple[tuple[Field, ...], str]] = {
    "SENSOR_SCHEMA": (SENSOR_FIELDS, "sensor_frame"),
    "RAW_ROW_SCHEMA": (RAW_ROW_FIELDS, "raw_rows"),
    "QUARANTINE_SCHEMA": (QUARANTINE_FIELDS, "quarantine"),
    "GAP_SCHEMA": (GAP_FIELDS, "ingest_gaps"),
}
"""The module's pandera schemas, by attribute name: (fields, schema name); built on first use."""


@cache
def _pandera_constant(attr: str) -> pa.DataFrameSchema:
    return pandera_schema(*PANDERA_SCHEMAS[attr])


def validate_table(frame: pl.DataFrame, attr: str) -> pl.DataFrame:
    """``frame`` validated against the pandera schema ``attr`` (``"SENSOR_SCHEMA"`` …): checked in
    one pass (:func:`conforms`), and by pandera — which raises ``SchemaErrors`` naming the
    failure — only when that pass finds one."""
    if conforms(frame, PANDERA_SCHEMAS[attr][0]):
        return frame
    return _pandera_constant(attr).validate(frame, lazy=True)


def __getattr__(attr: str):
    """``SENSOR_SCHEMA`` and the other :data:`PANDERA_SCHEMAS`, built (importing pandera) on first use."""
    if attr in PANDERA_SCHEMAS:
        return _pandera_constant(attr)
    raise AttributeError(f"module {__name__!r} has no attribute {attr!r}")

# --- monitoring (steps 2–6) ----------------------------------------------------------------

EDGE_FIT_FIELDS: tuple[Field, ...] = (
    _VALVE_ID,
    _EDGE,
    _WINDOW_START,
    _WINDOW_END,
    _OPERATING_HOURS,
    Field("n_points", pl.Int32, "", "Opening-area points used by the fit.", ge=0),
    Field("alpha_hat", pl.Float64, "", "Relative change of α against the baseline (1 = unchanged).", nullable=True),
    Field("x_hat_mm", pl.Float64, "mm", "Change of underlap in the edge's opening coordinate; > 0 = more open.", nullable=True),
    Field("x_hat_pct", pl.Float64, "%", "x_hat_mm in % of x_max.", nullable=True),
    Field("e_mm2", pl.Float64, "mm²", "Normalised error of Eq. 8 (RMS residual).", nullable=True),
    Field("status", pl.Utf8, "", "ok, or why the window gave no estimate."),
    Field("alpha_ci_low", pl.Float64, "", "Lower bound of the 95 % confidence interval of alpha_hat.", nullable=True),
    Field("alpha_ci_high", pl.Float64, "", "Upper bound of the 95 % confidence interval of alpha_hat.", nullable=True),
    Field("x_hat_ci_low_mm", pl.Float64, "mm", "Lower bound of the 95 % confidence interval of x_hat_mm.", nullable=True),
    Field("x_hat_ci_high_mm", pl.Float64, "mm", "Upper bound of the 95 % confidence interval of x_hat_mm.", nullable=True),
    Field("u_min_mm", pl.Float64, "mm", "Smallest opening coordinate among the points.", nullable=True),
    Field("u_max_mm", pl.Float64, "mm", "Largest opening coordinate among the points.", nullable=True),
    Field("baseline_version", pl.Int32, "", "Version of the baseline characteristic fitted against.", nullable=True),
    Field("monitored_at", UTC_US, "", "When this row was computed."),
    Field("leak_scale", pl.Float64, "", "The edge's closed-edge leakage in the window over Eq. 3's (0 = none).", nullable=True, ge=0.0),
    Field("leak_scale_ci_low", pl.Float64, "", "Lower bound of the 95 % confidence interval of leak_scale.", nullable=True),
    Field("leak_scale_ci_high", pl.Float64, "", "Upper bound of the 95 % confidence interval of leak_scale.", nullable=True),
    Field("u_spread_mm", pl.Float64, "mm", "The points' spread in u as the fit's covariance sees it "
          "(the standard deviation of u on a straight characteristic).", nullable=True),
    Field("x_hat_determined", pl.Boolean, "",
          "False where u_spread_mm < 0.1 mm: too short a range of u to tell a shift from a scale; "
          "x_hat_mm is then not used by the trends and the change detector.", nullable=True),
    Field("leak_scale_held", pl.Boolean, "",
          "True where the window cannot resolve its own leakage (its interval of leak_scale is 1 or wider: it cannot tell "
          "none from Eq. 3's): leak_scale is then the commissioning's, held; the views show it as undetermined.", nullable=True),
    Field("row_stride", pl.Int32, "", "The window was evaluated on every row_stride-th row ([monitor] window_rows; 1: every row); "
          "n_points × row_stride is its population in samples.", nullable=True, ge=1),
)
"""One row per valve, edge and monitoring window (table ``edge_fits``, interfaces.md)."""

BASELINE_FIELDS: tuple[Field, ...] = (
    _VALVE_ID,
    _EDGE,
    Field("version", pl.Int32, "", "Version per valve and edge, 1, 2, … (a new definition adds one).", ge=1),
    Field("source", pl.Utf8, "", "nominal (α_nominal·A(u), Eq. 3) or commissioning (step 4a fit).", isin=("nominal", "commissioning")),
    Field("definition", pl.Utf8, "", "What the baseline was built from (design data, window); a change makes a new version."),
    Field("knots_u_mm", pl.List(pl.Float64), "mm", "Knots of the piecewise-linear characteristic in the opening coordinate."),
    Field("values_mm2", pl.List(pl.Float64), "mm²", "α·A at the knots."),
    Field("n_points", pl.Int32, "", "Points of the commissioning fit (0 for nominal).", ge=0),
    Field("plausible", pl.Boolean, "", "Step 5a: value and shape agree with the nominal characteristic."),
    Field("plausibility_reasons", pl.Utf8, "", "Failed checks of step 5a, '; '-separated (empty when plausible)."),
    Field("alpha_vs_nominal", pl.Float64, "", "Scale of the baseline against the nominal characteristic.", nullable=True),
    Field("x_vs_nominal_mm", pl.Float64, "mm", "Shift of the baseline against the nominal characteristic.", nullable=True),
    Field("created_at", UTC_US, "", "When this version was stored."),
    Field("leak_branch_scale", pl.Float64, "", "λ₁: the edge's closed-edge leakage is Eq. 3's branch × λ₁ ...", nullable=True, ge=0.0),
    Field("leak_gap_scale", pl.Float64, "", "... + λ₂ × that branch with worn lands (4× Eq. 3's far from the edge).", nullable=True, ge=0.0),
    Field("leak_scale", pl.Float64, "", "That leakage over Eq. 3's 1 mm inside the edge (1 = Eq. 3, 0 = none).", nullable=True, ge=0.0),
    Field("leak_scale_ci_low", pl.Float64, "", "Lower 95 % bound of leak_scale (NULL: not identified, Eq. 3 kept).", nullable=True),
    Field("leak_scale_ci_high", pl.Float64, "", "Upper bound of the 95 % interval of leak_scale.", nullable=True),
    Field("edge_law", pl.Utf8, "", "Edge law the characteristic's shape follows: eq3, or sharp where the commissioning window shows straight edges.", nullable=True),
    Field("edge_law_note", pl.Utf8, "", "Why edge_law is not the configured area_law (empty when it is).", nullable=True),
)
"""Versioned baseline characteristics per valve and edge (table ``baselines``)."""

SELECTION_FIELDS: tuple[Field, ...] = (
    _VALVE_ID,
    _EDGE,
    Field("window_start", UTC_US, "", "First sample of the window (UTC)."),
    Field("window_end", UTC_US, "", "Last sample of the window (UTC)."),
    Field("rule", pl.Utf8, "", "Step-3 rule: no_derivative, standstill, pressure_peak, spool_range, small_dp."),
    Field("n_samples", pl.Int64, "", "Samples in the window.", ge=0),
    Field("n_flagged", pl.Int64, "", "Samples the rule flags on its own.", ge=0),
    Field("n_removed", pl.Int64, "", "Samples the rule removes that no earlier rule removed.", ge=0),
    Field("n_selected", pl.Int64, "", "Samples left for the edge after all rules.", ge=0),
)
"""What each step-3 rule removed, per window and edge (table ``selection_stats``)."""

# --- report (condition, fleet ranking, BI hand-off) ---------------------------------------

# ``condition_bounds`` and ``standstill_checks`` are tables ``valvemon report`` writes;
# ``valve_condition`` and ``fleet_ranking`` are views (``sql/report``) whose columns are fixed
# here, so the exported Parquet files keep a stable, documented schema.

STATES: tuple[str, ...] = ("healthy", "worn", "faulty", "unknown")
"""The states of ``valve_condition`` (interfaces.md)."""

CONDITION_BOUNDS_FIELDS: tuple[Field, ...] = (
    _VALVE_ID,
    Field("valve_type", pl.Utf8, "", "Valve type of the plant configuration."),
    Field("x_max_mm", pl.Float64, "mm", "Spool stroke x_max (x_hat_pct is in % of it).", ge=0.0),
    Field("alpha_fault_low", pl.Float64, "", "alpha_hat below this in one window: faulty."),
    Field("alpha_fault_high", pl.Float64, "", "alpha_hat above this in one window: faulty."),
    Field("alpha_wear_low", pl.Float64, "", "Long-term level of alpha_hat below this: worn."),
    Field("alpha_wear_high", pl.Float64, "", "Long-term level of alpha_hat above this: worn."),
    Field("x_hat_pct_fault_low", pl.Float64, "%", "x_hat_pct below this in one window: faulty."),
    Field("x_hat_pct_fault_high", pl.Float64, "%", "x_hat_pct above this in one window: faulty."),
    Field("x_hat_pct_wear_low", pl.Float64, "%", "Long-term level of x_hat_pct below this: worn."),
    Field("x_hat_pct_wear_high", pl.Float64, "%", "Long-term level of x_hat_pct above this: worn."),
    Field("e_mm2_fault_high", pl.Float64, "mm²", "e_mm2 above this in one window: faulty."),
    Field("e_mm2_wear_high", pl.Float64, "mm²", "Long-term level of e_mm2 above this: worn."),
    Field("change_z", pl.Float64, "", "Robust z-score beyond which a window departs significantly from its recent trend."),
    Field("change_history_windows", pl.Int32, "", "Fewest previous ok windows the rolling median and IQR are taken over (when change_history_hours holds fewer); also for the long-term level."),
    Field("change_min_history", pl.Int32, "", "Fewest previous ok windows for a z-score."),
    Field("alpha_sigma_floor", pl.Float64, "", "Smallest scale of the alpha_hat z-score."),
    Field("x_hat_pct_sigma_floor", pl.Float64, "%", "Smallest scale of the x_hat_pct z-score."),
    Field("e_mm2_sigma_floor", pl.Float64, "mm²", "Smallest scale of the e_mm2 z-score."),
    Field("fault_hold_hours", pl.Float64, "h", "An alarm keeps the edge faulty this long after its window."),
    Field("trend_min_fits", pl.Int32, "", "Fewest ok, alarm-free windows for a trend (else unknown)."),
    Field("trend_min_span_hours", pl.Float64, "h", "Shortest span of operating hours for a remaining-life forecast."),
    Field("trend_span_hours", pl.Float64, "h", "Trailing span of operating hours the trend is fitted on."),
    Field("eq9_expected", pl.Float64, "", "Eq. 9 residual the valve's design gives at rest."),
    Field("eq9_tolerance", pl.Float64, "", "Largest |residual - expected| of a sound valve."),
    Field("updated_at", UTC_US, "", "When the row was written from the plant configuration."),
    Field("change_history_hours", pl.Float64, "h", "Hours of previous ok windows the rolling median and IQR are taken over (at least change_history_windows windows); also the span of the long-term level."),
)
"""Each configured valve's bounds (table ``condition_bounds``, replaced by every report)."""

STANDSTILL_FIELDS: tuple[Field, ...] = (
    _VALVE_ID,
    _WINDOW_START,
    _WINDOW_END,
    _OPERATING_HOURS,
    Field("n_samples", pl.Int64, "", "Standstill samples of the window used (cylinder at rest, |x| small, settled).", ge=0),
    Field("ps_bar", pl.Float64, "bar", "Median supply pressure over those samples."),
    Field("pr_bar", pl.Float64, "bar", "Median return pressure."),
    Field("p1_bar", pl.Float64, "bar", "Median head-side pressure."),
    Field("p2_bar", pl.Float64, "bar", "Median rod-side pressure."),
    Field("x_spool_mm", pl.Float64, "mm", "Median spool position."),
    Field("eq9_residual", pl.Float64, "", "Median of (p1-pr)/(ps-p1) - (ps-p2)/(p2-pr) (Eq. 9; 0 for the idealised valve)."),
    Field("computed_at", UTC_US, "", "When this row was computed."),
)
"""Eq. 9 at standstill per window (table ``standstill_checks``, filled incrementally from the lake)."""

REMAINING_BASES: tuple[str, ...] = ("faulty", "worn", "forecast", "beyond_horizon", "no_trend", "too_little_data")
"""What a remaining life rests on (view ``valve_condition``, docs/monitoring.md "Remaining life")."""

_REMAINING_BASIS = Field(
    "remaining_basis", pl.Utf8, "", "What remaining_hours rests on: faulty or worn (0), forecast (a trend's crossing "
    "within the horizon), beyond_horizon, no_trend or too_little_data (null).", isin=REMAINING_BASES,
)
_REMAINING_HORIZON = Field(
    "remaining_horizon_hours", pl.Float64, "h", "The forecast horizon of a healthy edge: 3 × the span of operating "
    "hours its trend was fitted on; no forecast reaches beyond it.", nullable=True,
)

VALVE_CONDITION_FIELDS: tuple[Field, ...] = (
    _VALVE_ID,
    _EDGE,
    Field("state", pl.Utf8, "", "healthy, worn, faulty or unknown.", isin=STATES),
    Field("reason", pl.Utf8, "", "Why, in words, with the numbers."),
    Field("remaining_hours", pl.Float64, "h", "Operating hours until a parameter's trend reaches its wear bound, within the forecast horizon; 0 when faulty or worn; null otherwise (remaining_basis says why).", nullable=True),
    Field("remaining_hours_low", pl.Float64, "h", "Lower end of its 95 % interval.", nullable=True),
    Field("remaining_hours_high", pl.Float64, "h", "Upper end of its 95 % interval (null where it lies beyond the horizon).", nullable=True),
    Field("limiting_parameter", pl.Utf8, "", "The parameter whose trend reaches its bound first.", nullable=True),
    Field("end_of_life_hours", pl.Float64, "h", "Operating hours at which that happens (forecasts within the horizon).", nullable=True),
    Field("operating_hours", pl.Float64, "h", "Operating hours of the latest ok window.", nullable=True),
    Field("last_window_start", UTC_US, "", "Latest monitoring window of the edge (any status).", nullable=True),
    Field("last_ok_window_start", UTC_US, "", "Latest window with an estimate.", nullable=True),
    Field("alpha_hat", pl.Float64, "", "alpha_hat of the latest ok window.", nullable=True),
    Field("x_hat_pct", pl.Float64, "%", "x_hat_pct of the latest ok window that determined it (x_hat_determined).", nullable=True),
    Field("e_mm2", pl.Float64, "mm²", "e_mm2 of the latest ok window.", nullable=True),
    Field("alpha_level", pl.Float64, "", "Long-term level (median of the latest alarm-free windows) of alpha_hat.", nullable=True),
    Field("x_hat_pct_level", pl.Float64, "%", "Long-term level of x_hat_pct.", nullable=True),
    Field("e_mm2_level", pl.Float64, "mm²", "Long-term level of e_mm2.", nullable=True),
    Field("n_windows", pl.Int64, "", "Windows of the edge against its current baseline.", ge=0),
    Field("n_ok_windows", pl.Int64, "", "Of which gave an estimate.", ge=0),
    Field("n_recent_alarms", pl.Int64, "", "Alarm windows within fault_hold_hours of the latest ok window.", ge=0),
    Field("eq9_ok", pl.Boolean, "", "Latest Eq. 9 standstill check of the valve passed (null: no standstill data).", nullable=True),
    Field("edge_order", pl.Int32, "", "1..4 for s1, 1r, s2, 2r (for sorting)."),
    Field("leak_scale", pl.Float64, "", "Closed-edge leakage over Eq. 3's (0 = none), median of the ok windows.", nullable=True),
    Field("leak_scale_baseline", pl.Float64, "", "The same at commissioning (1 for a nominal baseline: Eq. 3 assumed).", nullable=True),
    Field("edge_law", pl.Utf8, "", "Edge law of the current baseline's shape (eq3, sharp; a note in reason when not the configured one).", nullable=True),
    _REMAINING_BASIS,
    _REMAINING_HORIZON,
    Field("first_alarm_start", UTC_US, "", "Earliest of the recent alarm windows (n_recent_alarms): where the fault began.", nullable=True),
    Field("last_alarm_start", UTC_US, "", "Latest of the recent alarm windows.", nullable=True),
)
"""View ``valve_condition`` (interfaces.md), as exported to ``export/valve_condition.parquet``."""

FLEET_RANKING_FIELDS: tuple[Field, ...] = (
    Field("urgency_rank", pl.Int64, "", "1 = look at this valve first.", ge=1),
    _VALVE_ID,
    Field("state", pl.Utf8, "", "Worst state of its edges (unknown only if all four are).", isin=STATES),
    Field("urgency_tier", pl.Int32, "", "1 faulty, 2 worn, 3 Eq. 9 fails, 4 healthy with forecast, 5 unknown, 6 healthy."),
    Field("edges_faulty", pl.Int64, "", "Faulty edges.", ge=0),
    Field("edges_worn", pl.Int64, "", "Worn edges.", ge=0),
    Field("edges_unknown", pl.Int64, "", "Edges without enough data.", ge=0),
    Field("worst_edge", pl.Utf8, "", "The edge that decides the state.", isin=EDGES),
    Field("reason", pl.Utf8, "", "Its reason."),
    Field("remaining_hours", pl.Float64, "h", "The worst edge's remaining life (valve_condition): 0 when faulty or worn, the soonest forecast within the horizon, else null.", nullable=True),
    Field("remaining_hours_low", pl.Float64, "h", "Lower end of its 95 % interval.", nullable=True),
    Field("remaining_hours_high", pl.Float64, "h", "Upper end of its 95 % interval (null where beyond the horizon).", nullable=True),
    Field("limiting_edge", pl.Utf8, "", "The edge the remaining life is of (null when there is none).", nullable=True),
    Field("eq9_ok", pl.Boolean, "", "Latest Eq. 9 standstill check passed.", nullable=True),
    Field("eq9_residual", pl.Float64, "", "Its residual.", nullable=True),
    Field("operating_hours", pl.Float64, "h", "Operating hours of the latest ok window.", nullable=True),
    Field("last_window_start", UTC_US, "", "Latest monitoring window.", nullable=True),
    _REMAINING_BASIS,
    _REMAINING_HORIZON,
)
"""View ``fleet_ranking``, as exported to ``export/fleet_ranking.parquet``."""

# --- model discrepancy (issue 7) -----------------------------------------------------------

DISCREPANCY_EFFECTS: tuple[str, ...] = (
    "internal_leakage",
    "external_leakage",
    "entrained_air",
    "spool_sensor_offset",
    "pressure_sensor_offset",
    "pressure_sensor_gain",
    "supply_line_resistance",
    "friction_change",
    "load_mass_change",
)
"""The library's effect names (interfaces.md; ``model.effects.EFFECT_NAMES``)."""

DISCREPANCY_STAGES = "0 = the base model; k = the base model with the effects named 1 … k (fitted parameters)."
_STAGE = Field("stage", pl.Int32, "", DISCREPANCY_STAGES, ge=0)
_REGION = Field("region", pl.Utf8, "", "Operating region.", isin=("all", "extending", "retracting", "standstill", "pressure_low", "pressure_mid", "pressure_high"))
_REGION_SAMPLES = Field("n_samples", pl.Int64, "", "Samples of the region.", ge=0)

_RUN_FIELDS: tuple[Field, ...] = (
    Field("run_id", pl.Utf8, "", "Identifier of the discrepancy run."),
    _VALVE_ID,
    Field("run_at", UTC_US, "", "When the run started (UTC)."),
)

DISCREPANCY_FINDING_FIELDS: tuple[Field, ...] = (
    _VALVE_ID,
    Field("run_at", UTC_US, "", "When the run started (UTC)."),
    Field("effect", pl.Utf8, "", "The named effect, or none.", isin=DISCREPANCY_EFFECTS + ("none",)),
    Field("parameter_name", pl.Utf8, "", "The effect's parameter (K_i, K_e, air_fraction, delta_x, delta_p1, delta_p2, gain_p1, gain_p2, R_s, delta_d_v, delta_m); null for none.", nullable=True),
    Field("parameter_value", pl.Float64, "", "Its fitted value, in parameter_unit (SI); null for none.", nullable=True),
    Field("parameter_unit", pl.Utf8, "", "Unit of parameter_value (m3/(s*Pa), -, m, Pa, Pa*s2/m6, N*s/m, kg); null for none.", nullable=True),
    Field("gap_before", pl.Float64, "", "Normalised replay gap (RMS of the p1, p2 errors in bar and the X error in mm, docs/discrepancy.md) with the effects named before this one.", ge=0.0),
    Field("gap_after", pl.Float64, "", "The same gap with this effect added (none: equal to gap_before).", ge=0.0),
    Field("rank", pl.Int32, "", "1 = the effect named first (none: 1).", ge=1),
    Field("run_id", pl.Utf8, "", "Identifier of the discrepancy run (joins the other discrepancy_* tables)."),
    Field("parameter_ci_low", pl.Float64, "", "Lower bound of the parameter's interval (jackknife over 1 s blocks).", nullable=True),
    Field("parameter_ci_high", pl.Float64, "", "Upper bound of the parameter's interval.", nullable=True),
    Field("ci_level", pl.Float64, "", "Level of the interval.", ge=0.0, le=1.0),
    Field("variant", pl.Utf8, "", "Which signal the effect concerns (p1, p2) where the name has variants; else empty."),
    Field("cv_relative_gain", pl.Float64, "", "Share of the cross-validated residual sum of squares the effect removed when it was named.", nullable=True),
    Field("t_stat", pl.Float64, "", "t statistic of the blocks' relative cross-validated gains.", nullable=True),
    Field("z_score", pl.Float64, "", "|parameter − neutral| in jackknife standard errors (linearised step).", nullable=True),
    Field("gap_p1_before_bar", pl.Float64, "bar", "RMS replay error of p1 before.", ge=0.0),
    Field("gap_p1_after_bar", pl.Float64, "bar", "RMS replay error of p1 after.", ge=0.0),
    Field("gap_p2_before_bar", pl.Float64, "bar", "RMS replay error of p2 before.", ge=0.0),
    Field("gap_p2_after_bar", pl.Float64, "bar", "RMS replay error of p2 after.", ge=0.0),
    Field("gap_x_before_mm", pl.Float64, "mm", "RMS replay error of X before.", ge=0.0),
    Field("gap_x_after_mm", pl.Float64, "mm", "RMS replay error of X after.", ge=0.0),
    Field("window_start", UTC_US, "", "First sample diagnosed (UTC)."),
    Field("window_end", UTC_US, "", "Last sample diagnosed (UTC)."),
    Field("n_records", pl.Int32, "", "Records (contiguous windows) diagnosed.", ge=1),
    Field("plot_path", pl.Utf8, "", "Overlay picture of measured against simulated before and after (under WAREHOUSE/reports/discrepancy/).", nullable=True),
    Field("alternative_effect", pl.Utf8, "", "The runner-up (name[variant]) when this effect was hard to tell from it on the data (t of its blockwise advantage < 2); null otherwise.", nullable=True),
    Field("alternative_t", pl.Float64, "", "t statistic of this effect's blockwise cross-validated advantage over the runner-up.", nullable=True),
    Field("gap_explained", pl.Float64, "", "1 − gap_after² / gap_before²: the share of the squared gap this effect removed (a named effect that leaves most of the gap explains little of the disagreement).", nullable=True),
    Field("condition_source", pl.Utf8, "", "Valve condition the model used: design (configured design data) or commissioning (α and underlap per edge fitted on the configured baseline_window).", isin=("design", "commissioning")),
)
"""One row per discrepancy run and named effect (table ``discrepancy_findings``, interfaces.md);
the first nine columns are the specified ones."""

# --- discrepancy verdicts with nuisance parameters (issue 17) ---------------------------------

DISCREPANCY_VERDICTS = ("named", "ambiguous", "unexplained", "none")
DISCREPANCY_FINDING_FIELDS = DISCREPANCY_FINDING_FIELDS + (
    Field("verdict", pl.Utf8, "", "named (the effect explains what the base model's uncertain parameters cannot within their tolerances, and its replay closes the gap where it acts), ambiguous (another reading explains the same data: see alternatives), unexplained (the equations point at an effect whose replay does not close its gap: the data disagree with the model in a way no library effect explains; see disagreement) or none.", isin=DISCREPANCY_VERDICTS, nullable=True),
    Field("confidence", pl.Float64, "", "How sure the verdict's first reading is, in [0, 1] (docs/discrepancy.md, Verdicts).", ge=0.0, le=1.0, nullable=True),
    Field("alternatives", pl.Utf8, "", "The other readings of the same data ('; '-separated: effects with their values, or the base model with nuisance values); null if none.", nullable=True),
    Field("separate_by", pl.Utf8, "", "What data would tell the readings apart (ambiguous verdicts).", nullable=True),
    Field("verdict_reason", pl.Utf8, "", "One sentence: why this verdict.", nullable=True),
    Field("nuisances", pl.Utf8, "", "The calibrated nuisance parameters, 'name=value unit (zσ)' '; '-separated, z = deviation from nominal in prior σ; null when the model was taken as exact.", nullable=True),
    Field("gap_nominal", pl.Float64, "", "Normalised replay gap of the nominal (design-data, uncalibrated) base model.", ge=0.0, nullable=True),
    Field("gap_kind", pl.Utf8, "", "Where the effect acts and is judged: hydraulic (p1, p2 replayed on the recorded cylinder motion) or mechanical (X replayed on the recorded pressures); null without one.", isin=("hydraulic", "mechanical"), nullable=True),
    Field("gap_kind_before", pl.Float64, "", "That gap (RMS on the 1 bar / 1 mm scales) of the model before the effect is added.", ge=0.0, nullable=True),
    Field("gap_kind_after", pl.Float64, "", "... and with it: named needs ≥ 1.5× less, or ≤ 2× gap_kind_floor.", ge=0.0, nullable=True),
    Field("gap_kind_floor", pl.Float64, "", "That gap's noise floor: what the recorded sensor noise alone leaves through the replay.", ge=0.0, nullable=True),
    Field("disagreement", pl.Utf8, "", "unexplained: which equation, signal and operating region disagree, and how much; with any verdict, a pressure transmitter lagging the others (which, how many ms).", nullable=True),
)

DISCREPANCY_CANDIDATE_FIELDS: tuple[Field, ...] = _RUN_FIELDS + (
    Field("effect", pl.Utf8, "", "Library effect.", isin=DISCREPANCY_EFFECTS),
    Field("variant", pl.Utf8, "", "p1, p2 or empty."),
    Field("parameter_name", pl.Utf8, "", "The effect's parameter."),
    Field("parameter_unit", pl.Utf8, "", "Its unit (SI)."),
    Field("parameter_value", pl.Float64, "", "Estimate of the linearised regression against the base model alone."),
    Field("parameter_se", pl.Float64, "", "Its jackknife standard error.", nullable=True),
    Field("cv_relative_gain", pl.Float64, "", "Share of the base model's cross-validated residual sum of squares it removes alone."),
    Field("t_stat", pl.Float64, "", "t statistic of the blocks' relative gains."),
    Field("z_score", pl.Float64, "", "|estimate| in standard errors.", nullable=True),
    Field("significant", pl.Boolean, "", "Passes every significance rule on its own (docs/discrepancy.md)."),
    Field("unconfirmed", pl.Boolean, "", "Selected, but adding it did not shrink the replay gap, so it was not named."),
    Field("score_rank", pl.Int32, "", "Rank by cross-validated gain against the base model (1 = largest).", ge=1),
)
"""Every library candidate scored against the base model, per run (table ``discrepancy_candidates``)."""

DISCREPANCY_GAP_FIELDS: tuple[Field, ...] = _RUN_FIELDS + (
    _STAGE,
    Field("signal", pl.Utf8, "", "Replayed signal: p1, p2, X of the whole replay; p1_hydraulic, p2_hydraulic of the replay on the recorded cylinder motion, X_mechanical of the replay on the recorded pressures.", isin=("p1", "p2", "X", "p1_hydraulic", "p2_hydraulic", "X_mechanical")),
    _REGION,
    Field("rms", pl.Float64, "", "RMS of replayed reading minus recorded signal, in unit.", nullable=True),
    Field("unit", pl.Utf8, "", "Pa or m."),
    _REGION_SAMPLES,
)
"""Replay gap per stage, signal and operating region (table ``discrepancy_gaps``)."""

DISCREPANCY_RESIDUAL_FIELDS: tuple[Field, ...] = _RUN_FIELDS + (
    _STAGE,
    Field("equation", pl.Utf8, "", "Chamber 1 or 2 continuity (Eq. 6) or the motion equation (Eq. 5).", isin=("chamber1", "chamber2", "motion")),
    _REGION,
    Field("rms", pl.Float64, "", "RMS of the pointwise residual (Savitzky–Golay derivatives), in unit.", nullable=True),
    Field("mean", pl.Float64, "", "Mean of the pointwise residual, in unit.", nullable=True),
    Field("unit", pl.Utf8, "", "m3/s (chambers) or N (motion)."),
    _REGION_SAMPLES,
)
"""Equation residuals per stage and operating region (table ``discrepancy_residuals``)."""

DISCREPANCY_MONITORING_FIELDS: tuple[Field, ...] = _RUN_FIELDS + (
    _EDGE,
    Field("effects", pl.Utf8, "", "The effects accounted for (name=value, '; '-separated), empty if none was named."),
    Field("n_windows", pl.Int32, "", "Windows with an ok fit both ways.", ge=0),
    Field("alpha_hat_recorded", pl.Float64, "", "Median α̂ of the monitoring on the signals as recorded (nominal baseline).", nullable=True),
    Field("alpha_hat_corrected", pl.Float64, "", "Median α̂ with the named effects accounted for.", nullable=True),
    Field("x_hat_mm_recorded", pl.Float64, "mm", "Median x̂ as recorded.", nullable=True),
    Field("x_hat_mm_corrected", pl.Float64, "mm", "Median x̂ with the effects accounted for.", nullable=True),
    Field("e_mm2_recorded", pl.Float64, "mm²", "Median e as recorded.", nullable=True),
    Field("e_mm2_corrected", pl.Float64, "mm²", "Median e with the effects accounted for.", nullable=True),
)
"""What the named effects did to α̂, x̂ and e (table ``discrepancy_monitoring``)."""

DISCREPANCY_CONDITION_FIELDS: tuple[Field, ...] = _RUN_FIELDS + (
    _EDGE,
    Field("source", pl.Utf8, "", "design or commissioning (fitted on the baseline_window).", isin=("design", "commissioning")),
    Field("alpha", pl.Float64, "", "Contraction coefficient α of the edge in the model.", ge=0.0),
    Field("alpha_se", pl.Float64, "", "Its jackknife standard error (commissioning fit).", nullable=True),
    Field("underlap_mm", pl.Float64, "mm", "Underlap of the edge in the model (its opening coordinate)."),
    Field("underlap_se_mm", pl.Float64, "mm", "Its jackknife standard error (commissioning fit).", nullable=True),
    Field("gap_design", pl.Float64, "", "Normalised replay gap of the commissioning records with the design condition.", nullable=True),
    Field("gap_fitted", pl.Float64, "", "The same with the fitted condition.", nullable=True),
)
"""The valve condition (α, underlap per edge) the discrepancy model used (table ``discrepancy_condition``)."""

# --- raw-data retention (``valvemon retention``) ---------------------------------------------

RETENTION_ACTIONS: tuple[str, ...] = ("drop", "thin")

STANDSTILL_PROGRESS_FIELDS: tuple[Field, ...] = (
    Field("valve_id", pl.Utf8, "", "Valve identifier; the table's key."),
    Field("checked_through", UTC_US, "", "Last lake sample the report's standstill check (Eq. 9) has read (UTC)."),
    Field("updated_at", UTC_US, "", "When the report last moved it."),
)
"""How far the report's standstill check has read each valve's lake (table ``standstill_progress``):
retention keeps a partition until the check has read past it."""

RETENTION_LOG_FIELDS: tuple[Field, ...] = (
    Field("action_id", pl.Utf8, "", "Identifier of the action; the table's key (also in the name of a dropped partition's hidden folder)."),
    _VALVE_ID,
    Field("date", pl.Date, "", "UTC date of the lake partition."),
    Field("action", pl.Utf8, "", "drop: the partition was deleted; thin: only the first thin_keep_s_per_hour of every hour was kept.", isin=RETENTION_ACTIONS),
    Field("rows_before", pl.Int64, "", "Lake rows of the partition before the action.", ge=0),
    Field("rows_after", pl.Int64, "", "Lake rows after it (0 for drop).", ge=0),
    Field("size_before_bytes", pl.Int64, "B", "Bytes of the partition's Parquet files before the action.", ge=0),
    Field("size_after_bytes", pl.Int64, "B", "Bytes after it (0 for drop).", ge=0),
    Field("keep_days", pl.Int32, "d", "retention.keep_days in force.", ge=1),
    Field("thin_keep_s_per_hour", pl.Float64, "s", "retention.thin_keep_s_per_hour in force (null for drop).", nullable=True, ge=0.0),
    Field("as_of", pl.Date, "", "The run's reference date: partitions older than keep_days before it were eligible."),
    Field("applied_at", UTC_US, "", "When the action was completed (an intent: when it was recorded)."),
    Field("state", pl.Utf8, "", "intent: recorded before the data change, which a killed run may have left part-done (the next run completes it); done: completed.", isin=("intent", "done")),
)
"""Every applied retention action, one row per partition and action (table ``retention_log``)."""

_DAY_UTC = Field("day_utc", pl.Date, "", "UTC day of the windows' window_start.")
_PARAMETER = Field("parameter", pl.Utf8, "", "Condition parameter: alpha_hat, x_hat_pct (%) or e_mm2 (mm²).", isin=("alpha_hat", "x_hat_pct", "e_mm2"))

EDGE_DAY_FIELDS: tuple[Field, ...] = (
    _VALVE_ID,
    _EDGE,
    _DAY_UTC,
    Field("baseline_version", pl.Int32, "", "The edge's current baseline version the day was summarised against.", nullable=True),
    Field("n_windows", pl.Int64, "", "Windows of the day (every status).", ge=0),
    Field("n_ok", pl.Int64, "", "Ok windows of the day.", ge=0),
    Field("n_alarms", pl.Int64, "", "Ok windows of the day that raised a short-term alarm.", ge=0),
    Field("last_window_start", UTC_US, "", "The day's latest window."),
    Field("last_status", pl.Utf8, "", "Status of the day's latest window."),
    Field("last_ok_window_start", UTC_US, "", "The day's latest ok window (null: none).", nullable=True),
    Field("last_ok_operating_hours", pl.Float64, "h", "Operating hours of the day's latest ok window.", nullable=True),
    Field("alpha_hat", pl.Float64, "", "alpha_hat of the day's latest ok window.", nullable=True),
    Field("x_hat_window_start", UTC_US, "", "The day's latest ok window that determined x_hat.", nullable=True),
    Field("x_hat_pct", pl.Float64, "%", "x_hat_pct of that window.", nullable=True),
    Field("e_mm2", pl.Float64, "mm²", "e_mm2 of the day's latest ok window.", nullable=True),
    Field("leak_n", pl.Int64, "", "Ok windows of the day with a closed-edge leakage estimate.", ge=0),
    Field("leak_scale_median", pl.Float64, "", "Median of their leak_scale.", nullable=True),
    Field("leak_scale_min", pl.Float64, "", "Minimum of their leak_scale.", nullable=True),
    Field("leak_scale_max", pl.Float64, "", "Maximum of their leak_scale.", nullable=True),
    Field("leak_operating_hours", pl.Float64, "h", "Operating hours of the latest of them.", nullable=True),
)
"""One row per valve, edge and closed UTC day of ``edge_fits`` (table ``edge_day_summaries``,
written by :func:`flows.report.summaries.update_summaries`)."""

PARAMETER_DAY_FIELDS: tuple[Field, ...] = (
    _VALVE_ID,
    _EDGE,
    _DAY_UTC,
    _PARAMETER,
    Field("n_values", pl.Int64, "", "Ok windows of the day with the parameter.", ge=0),
    Field("median_value", pl.Float64, "", "Median of the day's values (unit of the parameter)."),
    Field("min_value", pl.Float64, "", "Minimum of the day's values."),
    Field("max_value", pl.Float64, "", "Maximum of the day's values."),
    Field("operating_hours", pl.Float64, "h", "Operating hours of the day's latest value."),
    Field("last_window_start", UTC_US, "", "The day's latest window with a value."),
    Field("n_clean", pl.Int64, "", "Values of alarm-free windows (what the trend is fitted on).", ge=0),
    Field("clean_first_hours", pl.Float64, "h", "Operating hours of the earliest of them.", nullable=True),
    Field("clean_last_hours", pl.Float64, "h", "Operating hours of the latest of them.", nullable=True),
    Field("clean_mean_hours", pl.Float64, "h", "Their mean operating hours.", nullable=True),
    Field("clean_mean_value", pl.Float64, "", "Their mean value.", nullable=True),
    Field("clean_sxx", pl.Float64, "h²", "Their centred sum of squares of operating hours.", nullable=True),
    Field("clean_syy", pl.Float64, "", "Their centred sum of squares of the values.", nullable=True),
    Field("clean_sxy", pl.Float64, "h", "Their centred sum of products of hours and values.", nullable=True),
)
"""One row per valve, edge, closed UTC day and parameter (table ``parameter_day_summaries``): the
daily points of the pictures, and the alarm-free windows' sums that merge exactly into the
trend's least squares."""

ALARM_WINDOW_FIELDS: tuple[Field, ...] = (
    _VALVE_ID,
    _EDGE,
    _WINDOW_START,
    _WINDOW_END,
    _OPERATING_HOURS,
    Field("alpha_hat", pl.Float64, "", "alpha_hat of the window.", nullable=True),
    Field("x_hat_pct", pl.Float64, "%", "x_hat_pct of the window (null: not determined).", nullable=True),
    Field("e_mm2", pl.Float64, "mm²", "e_mm2 of the window.", nullable=True),
    Field("alpha_z", pl.Float64, "", "Robust z-score of alpha_hat against the history.", nullable=True),
    Field("x_hat_pct_z", pl.Float64, "", "Robust z-score of x_hat_pct.", nullable=True),
    Field("e_mm2_z", pl.Float64, "", "Robust z-score of e_mm2.", nullable=True),
    Field("beyond_fault_bound", pl.Boolean, "", "A parameter lies beyond its fault bound."),
    Field("change_alarm", pl.Boolean, "", "A parameter departs significantly from its recent history."),
    Field("reason", pl.Utf8, "", "Which parameter and by how much."),
)
"""Every alarm window of the closed days (table ``alarm_windows``), as view ``window_alarms`` gave it."""

SUMMARY_WATERMARK_FIELDS: tuple[Field, ...] = (
    Field("valve_id", pl.Utf8, "", "Valve identifier; the table's key."),
    Field("summarised_before", UTC_US, "", "The valve's days before this UTC midnight are summarised (closed); its windows from it on are computed by the views."),
    Field("raw_from", UTC_US, "", "The earliest window the views read raw: the change detector's history of the first open window and the level's."),
    Field("bounds_hash", pl.Utf8, "", "Hash of the valve's condition_bounds the summaries were computed with; another rebuilds them."),
    Field("monitored_through", UTC_US, "", "Latest edge_fits.monitored_at seen; rows monitored from it on mark their days changed."),
    Field("updated_at", UTC_US, "", "When the summaries last moved."),
)
"""How far each valve's daily summaries reach (table ``summary_watermarks``)."""

# --- the night's changes and their messages (docs/notify.md) --------------------------------

_RUN_ID = Field("run_id", pl.Utf8, "", "Identifier of the run that recorded the condition.")

CONDITION_HISTORY_FIELDS: tuple[Field, ...] = (
    _RUN_ID,
    Field("run_at", UTC_US, "", "When the run recorded it (UTC)."),
    Field("run_kind", pl.Utf8, "", "report (valvemon report, the nightly run) or backfill.", isin=("report", "backfill")),
    _VALVE_ID,
    _EDGE,
    Field("edge_order", pl.Int32, "", "1..4 for s1, 1r, s2, 2r (for sorting)."),
    Field("state", pl.Utf8, "", "valve_condition.state at the run.", isin=STATES),
    Field("reason", pl.Utf8, "", "valve_condition.reason at the run."),
    Field("remaining_hours", pl.Float64, "h", "valve_condition.remaining_hours at the run.", nullable=True),
    Field("remaining_below_h", pl.Float64, "h", "The [notify] remaining_below_h the run was made with (null: none).", nullable=True),
    Field("first_alarm_start", UTC_US, "", "valve_condition.first_alarm_start at the run.", nullable=True),
    Field("last_alarm_start", UTC_US, "", "valve_condition.last_alarm_start at the run.", nullable=True),
    Field("last_ok_window_start", UTC_US, "", "valve_condition.last_ok_window_start at the run.", nullable=True),
    Field("report_path", pl.Utf8, "", "The report the run wrote (empty: none, a backfill)."),
)
"""Every edge's condition as each report (or backfill) found it (table ``condition_history``;
view ``condition_changes`` compares the latest two runs)."""

CHANGES: tuple[str, ...] = ("faulty", "new_alarm", "worn", "remaining_below", "recovered")
"""Kinds of change (view ``condition_changes``)."""

NOTIFICATION_STATUSES: tuple[str, ...] = ("sent", "unsent", "suppressed")
"""sent; unsent (every attempt failed: the next run tries again); suppressed (a backfill without --notify)."""

NOTIFICATION_FIELDS: tuple[Field, ...] = (
    Field("notification_id", pl.Utf8, "", "Identifier of the message on one channel; the table's key."),
    _RUN_ID,
    Field("created_at", UTC_US, "", "When the message was composed (UTC)."),
    Field("channel", pl.Utf8, "", "webhook or mail.", isin=("webhook", "mail")),
    Field("target", pl.Utf8, "", "The webhook's host or the mail's recipients (no secret)."),
    Field("status", pl.Utf8, "", "sent, unsent (tried again by the next run) or suppressed.", isin=NOTIFICATION_STATUSES),
    Field("n_changes", pl.Int64, "", "Changes the message names (0: the no-change line).", ge=0),
    Field("subject", pl.Utf8, "", "One line: the plant and what changed."),
    Field("body", pl.Utf8, "", "The message's text."),
    Field("payload", pl.Utf8, "", "The webhook's JSON body (the same for mail, for the record)."),
    Field("attempts", pl.Int64, "", "Attempts so far, over all runs.", ge=0),
    Field("last_attempt_at", UTC_US, "", "When it was last tried.", nullable=True),
    Field("sent_at", UTC_US, "", "When it went out.", nullable=True),
    Field("error", pl.Utf8, "", "Why the last attempt failed (empty when sent)."),
)
"""One row per message and channel (table ``notifications``)."""
