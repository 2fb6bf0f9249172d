"""The plant configuration (``docs/configuration.md``): parsed, validated, in SI.

:func:`parse_plant_config` takes the dictionary a TOML parser returns and gives a frozen
:class:`PlantConfig`; every problem raises :class:`ConfigError` naming the key
(``valves[1].tags.p1.unit``) and what was expected. :func:`plant_config_to_dict` writes a
configuration back in the file's own units, so a round trip through TOML is lossless.

Keys the project adds to the specification (all optional; every key is documented in
``docs/configuration.md``):

- ``[export] sample_rate_hz`` (default 1000): the uniform grid the lake is built on. [Hz]
- ``[export] max_gap_s`` (default 0.005): samples further apart than this are a gap;
  nothing is interpolated across a gap. [s]
- ``[export] duplicate_rule`` (default ``"last"``): the same tag and time with different
  values keeps the ``"last"`` row in file order, or ``"first"``, or is an ``"error"``.
- ``[export] max_bad_share`` (default :data:`DEFAULT_MAX_BAD_SHARE`): the share of a tag's
  samples in one file that may be quarantined as ``out_of_range``, ``bad_timestamp`` or
  ``implausible_time`` before the file is refused (``docs/ingest.md``, "Quarantine or refusal").
- ``[export] other_tags`` (default ``"ignore"``): tags (long) and columns (wide) of an export
  that no valve of the plant has are read past and counted (``"ignore"``) or refuse the file
  (``"error"``).
- ``[export] header_rows`` (wide only; default: one header line of tags): what each header line of
  a wide text export holds, in file order: ``"tag"`` (the column names, once), ``"unit"`` (each
  column's unit, at most once; checked against ``[valves.tags]``, or taken from it where a tag
  leaves ``unit`` out), ``"name"`` (descriptions, shown in messages) or ``"skip"`` (anything
  else) — iba's ASCII export is ``["tag", "name", "unit"]`` (:data:`HEADER_ROW_KINDS`).
- ``[export] tdms_group`` (optional): the TDMS group whose channels are read (default: every group).
- ``[export] timestamp_format = "seconds"`` or ``"milliseconds"``: the time column counts from the
  file's start, found on a ``"start_time"`` header line (its second cell) or in the file's name,
  both read with ``[export] start_time_format`` (:data:`RELATIVE_TIME_FORMATS`).
- ``[export] clock_steps`` (wide only; default ``"quarantine"``): a wide export's rows are in time
  order, so a backward step of its clock by more than a few sample periods quarantines the rows
  after it (``clock_step``); ``"accept"`` takes the file's order as untrusted and sorts it as the
  long layout does (:data:`CLOCK_STEP_RULES`).
- ``[valves] baseline_window = { start = ..., end = ... }`` (spec) and ``[valves] scenario``
  (written by ``valvemon simulate`` for the record; ignored by monitoring).
- ``[valve_types.NAME.bounds]``: the condition bounds of step 5b (:class:`ConditionBounds`,
  every key optional with a documented default); a valve may override single keys in its own
  ``[valves.bounds]`` table.
- ``[retention]`` (optional; absent = nothing is ever deleted): ``keep_days``, ``mode``
  (``"drop"`` or ``"thin"``) and ``thin_keep_s_per_hour`` (:class:`RetentionSpec`), what
  ``valvemon retention`` and the nightly run do with old lake partitions (``docs/warehouse.md``,
  "Retention").
- ``[lake] codec`` (optional; default ``"none"``): the Parquet codec the lake's files are written
  with, ``"none"``, ``"lz4"`` or ``"zstd"`` (:class:`LakeSpec`; disk against CPU:
  ``docs/ingest.md``, "Storage").
- ``[valves.tolerances]`` (issue 17, optional; every key optional with a documented default,
  :class:`ModelTolerances`): how well the base model's uncertain parameters are known -- the
  one-σ tolerances of the nuisance priors of ``valvemon discrepancy`` (docs/discrepancy.md).
- ``[monitor] window_s`` (default :data:`DEFAULT_WINDOW_S`): the length of a monitoring window;
  a recording at least half as long is cut at every multiple of it since the UTC epoch
  (``transforms.windows``). It must divide a day, so windows start at the same times every day. [s]
- ``[monitor] window_rows`` (default :data:`DEFAULT_WINDOW_ROWS`): about the most rows of a window
  the monitor evaluates (every k-th row of a longer one, each the mean of the k rows it stands
  for); 0 = every row. A window whose thinned
  points would leave an edge near a fit threshold (sparse motion) is evaluated at every row, so the
  setting changes the speed, not which windows give an estimate.
- ``[notify]`` (optional; absent = nothing is sent): where ``valvemon report`` sends the night's
  changes (a webhook's JSON POST and/or mail, ``[notify.mail]``) and which (:class:`NotifySpec`,
  ``docs/notify.md``). A mail password is never in the file: ``password_env`` names the
  environment variable that holds it.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, fields, replace
from datetime import datetime, timezone
from typing import Any, Callable
from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

from schemas.errors import ConfigError
from schemas.fields import EDGES, REQUIRED_SIGNALS, SIGNAL_KIND, SIGNALS
from schemas.units import UnitError, si_factor


@dataclass(frozen=True)
class TagSpec:
    """One signal's historian tag and the unit its values are exported in."""

    tag: str
    unit: str | None
    """None: taken from each export file (``export.header_rows`` holds ``"unit"``)."""


@dataclass(frozen=True)
class ExportSpec:
    """How the plant's historian export files are laid out."""

    layout: str = "long"
    timestamp_column: str = "timestamp"
    timestamp_format: str = "iso8601"
    tag_column: str = "tag"
    value_column: str = "value"
    quality_column: str | None = None
    good_quality: tuple[str, ...] = ()
    separator: str = ","
    decimal: str = "."
    sample_rate_hz: float = 1000.0
    max_gap_s: float = 0.005
    duplicate_rule: str = "last"
    max_bad_share: float = 0.05
    """Share of a tag's samples in one file that may be quarantined as out of range or for their
    time (:data:`DEFAULT_MAX_BAD_SHARE`); more refuses the file."""
    other_tags: str = "ignore"
    """Tags or columns no valve has: ``"ignore"`` (read past, counted) or ``"error"``."""
    header_rows: tuple[str, ...] = ("tag",)
    """What each header line of a text export holds, in order (:data:`HEADER_ROW_KINDS`)."""
    tdms_group: str | None = None
    """The TDMS group that holds the tags (None: every group)."""
    start_time_format: str | None = None
    """With a relative ``timestamp_format`` (:data:`RELATIVE_TIME_FORMATS`): the strftime pattern of
    the file's start, on the ``start_time`` header line or in the file's name."""
    clock_steps: str = "quarantine"
    """A wide export whose clock steps back: ``"quarantine"`` the rows after the step, or ``"accept"``
    (sort them in, as the long layout does)."""
    ambiguous_time: str = "refuse"
    """A local time in the hour the clocks repeat in autumn that nothing else resolves (a start
    time; local times that never leave that hour): ``"refuse"`` the file, or take the
    ``"earlier"`` (summer time) or ``"later"`` instant."""

    @property
    def relative_time(self) -> bool:
        """Whether the time column counts from the file's start (``"seconds"``, ``"milliseconds"``)."""
        return self.timestamp_format in RELATIVE_TIME_FORMATS

    @property
    def units_in_file(self) -> bool:
        """Whether text exports carry a unit row (TDMS files may carry ``unit_string`` anyway)."""
        return "unit" in self.header_rows


HEADER_ROW_KINDS: tuple[str, ...] = ("tag", "name", "unit", "skip", "start_time")
"""What a header line of a text export can hold: the tags (the column names; exactly one such
line), names (descriptions), units, the recording's start (its second cell, with a relative
``timestamp_format``), or anything else (skipped)."""

RELATIVE_TIME_FORMATS: tuple[str, ...] = ("seconds", "milliseconds")
"""``timestamp_format`` values of a time column that counts from the file's start."""


DEFAULT_MAX_BAD_SHARE = ExportSpec.max_bad_share
"""5 %: a configuration error (a wrong unit in the TOML, a wrong ``timestamp_format``, a recorder
clock years off) faults nearly every sample of a tag, while transmitter glitches and short
faults fault a few in a thousand (one 1e308 in 2,000 samples is 0.05 %; a transmitter out of
range for a minute of an hour file 1.7 %); ``docs/ingest.md``, "Quarantine or refusal"."""

OTHER_TAGS_RULES: tuple[str, ...] = ("ignore", "error")
CLOCK_STEP_RULES: tuple[str, ...] = ("quarantine", "accept")

AMBIGUOUS_TIME_RULES: tuple[str, ...] = ("refuse", "earlier", "later")
"""``export.ambiguous_time``: what a local time in the repeated autumn hour is when nothing tells."""

DEFAULT_WINDOW_S = 60.0
"""Default monitoring window length (docs/monitoring.md, "Continuous recordings", measured on
simulated 20-min recordings): twice the shortest length at which every window-edge was fitted
(30 s; at 10 s 5 % were not), 95 % of its window-edges with ≥ 11,000 points (the fit needs 500), its
window-to-window scatter of α̂, x̂ and e below a tenth of the condition bounds' ``*_sigma_floor``;
a 10 s snapshot (shorter than half of it) is never cut. [s]"""


DEFAULT_WINDOW_ROWS = 6000
"""Default rows a monitoring window evaluates (docs/monitoring.md, "Fewer points, not faster
points"): a window of n samples is evaluated on every k-th row, k = max(1, n // 6000), each the
mean of the k rows it stands for: a 60 s window at 1 kHz on every 10th row (a tenth of the monitor's per-row work), a 10 s snapshot on
every row. Measured on simulated 20-min recordings, its 60 s windows' scatter and errors stay far
inside the condition bounds' ``*_sigma_floor``."""


@dataclass(frozen=True)
class MonitorSpec:
    """How the monitor cuts recordings into windows (``[monitor]``)."""

    window_s: float = DEFAULT_WINDOW_S
    """Window length; a run of samples at least half as long is cut at its multiples since the
    epoch, a shorter one (a snapshot) is one window. [s]"""
    window_rows: int = DEFAULT_WINDOW_ROWS
    """About the most rows of a window steps 2–3 and Eq. 7 evaluate: every k-th row, the mean of
    the k rows from it, k = max(1, n // window_rows) for a window of n samples (every row where that leaves an edge
    short of information: ``transforms.monitor.THIN_MARGIN``); 0 = every row."""


@dataclass(frozen=True)
class ConditionBounds:
    """Step 5b: when an edge is faulty or worn, and how its remaining life is extrapolated.

    Units are those of the ``edge_fits`` columns the bounds are compared with (α̂ relative,
    x̂ in % of x_max, e in mm²). The paper gives no thresholds (Sec. 4 and 5.2: they are to be
    found empirically per valve category), so the defaults are set from its own numbers:

    - **fault** (one window is enough): the paper's faulty edge 1r (Table 2: α̂ 2.53,
      x̂ 11.8 % x_max, e 1.13 mm²) lies beyond all three fault bounds; its normal valve
      (0.98, 0.23 %, 0.10 mm²) and the worn edge after 16,700 h (Table 3: 1.17, 3.7 %,
      0.18 mm²) lie well inside them.
    - **wear** (the long-term level, not one window): above Table 3's 16,700 h state, whose
      "operational performance is flawless" (α̂ 1.17 → bound 1.30, x̂ 3.7 % → bound 6 %),
      e above the 0.10–0.32 mm² seen on sound valves → 0.50 mm². Lower bounds catch the
      opposite drift (silting, a clogged edge): α̂ 0.80, x̂ −5 %.
    - **change detection** (a significant departure from the edge's own recent trend): a robust
      z-score of each window against the median and IQR (/1.349) of its history: the ok windows
      of the previous ``change_history_hours`` (a day: 24 hourly snapshots, 1,440 one-minute
      windows of a continuous recording), or the previous ``change_history_windows`` ok windows
      if those reach further back (sparse snapshots); |z| > ``change_z`` alarms. The scale is never taken
      below the ``*_sigma_floor`` values (ordinary window-to-window scatter of a sound edge), so
      a quiet history does not turn a normal wobble into an alarm. z = 6 keeps the false-alarm
      rate of Gaussian scatter below 1e-8 per window and parameter.
    - **trend / remaining life**: ordinary least squares of each parameter over operating hours
      on the ok, alarm-free windows of the last ``trend_span_hours``; at least
      ``trend_min_fits`` windows spanning ``trend_min_span_hours``, otherwise "unknown".
    - **Eq. 9** at standstill: the residual (p1−pr)/(ps−p1) − (ps−p2)/(p2−pr) is compared
      with the value the valve's design gives at rest (``eq9_expected``; Table 1: −0.17, not 0,
      see model.md); a deviation beyond ``eq9_tolerance`` fails the check (broken edge 1r:
      −1.1 … −1.8 over the sticking band and 190–210 bar; healthy −0.164 … −0.171; worn after
      16,700 h −0.08).
    """

    alpha_fault_low: float = 0.50
    alpha_fault_high: float = 1.80
    alpha_wear_low: float = 0.80
    alpha_wear_high: float = 1.30
    x_hat_pct_fault_low: float = -10.0
    x_hat_pct_fault_high: float = 10.0
    x_hat_pct_wear_low: float = -5.0
    x_hat_pct_wear_high: float = 6.0
    e_mm2_fault_high: float = 0.80
    e_mm2_wear_high: float = 0.50
    change_z: float = 6.0
    change_history_windows: int = 24
    change_min_history: int = 8
    alpha_sigma_floor: float = 0.02
    x_hat_pct_sigma_floor: float = 0.30
    e_mm2_sigma_floor: float = 0.03
    fault_hold_hours: float = 24.0
    trend_min_fits: int = 10
    trend_min_span_hours: float = 24.0
    trend_span_hours: float = 5000.0
    eq9_tolerance: float = 0.5
    eq9_expected: float | None = None
    """None: the residual of the design's rest state (computed by the report from Eq. 3/4)."""
    change_history_hours: float = 24.0
    """The change detector's history and the long-term level on the clock [h]: the ok windows of
    this many hours (never fewer than ``change_history_windows``)."""


BOUND_KEYS: tuple[str, ...] = tuple(f.name for f in fields(ConditionBounds))
"""Keys of a ``bounds`` table, in the order they are written."""

_INT_BOUNDS = {"change_history_windows", "change_min_history", "trend_min_fits"}


@dataclass(frozen=True)
class ValveDesign:
    """A valve type's design data (paper, Table 1), SI."""

    x_max_m: float
    bore_radius_m: float
    spool_radius_m: float
    taper_angle_port1_rad: float
    taper_angle_port2_rad: float
    underlap_m: tuple[float, float, float, float]
    """Underlap per edge in the order s1, 1r, s2, 2r. [m]"""
    contraction_coefficient: float
    bounds: ConditionBounds = field(default_factory=ConditionBounds)
    """Condition bounds of step 5b (``[valve_types.NAME.bounds]``)."""
    area_law: str = "eq3"
    """The valve family's area law, ``"eq3"`` (the paper's Eq. 3) or ``"sharp"`` (sharp edges, no
    closed-edge leakage): what the simulator builds (``model.area``); the monitor identifies the
    leakage from the data and takes the law's open-edge shape as a commissioning baseline's
    carrier unless the commissioning window shows the other law (docs/monitoring.md)."""
    leakage_factor: float = 1.0
    """Eq. 3's closed-edge leakage times this far from the edge (worn lands; ``model.area``),
    for the simulator; 1 = Eq. 3. [-]"""

    def taper_angle_rad(self, edge: str) -> float:
        """Taper angle of an edge: port 1 for s1 and 1r, port 2 for s2 and 2r. [rad]"""
        return self.taper_angle_port1_rad if edge in ("s1", "1r") else self.taper_angle_port2_rad


# --- model tolerances (issue 17: nuisance priors of the discrepancy workflow) -----------------


@dataclass(frozen=True)
class ModelTolerances:
    """One-σ tolerances of the base model's uncertain parameters (``[valves.tolerances]``), the
    priors of the discrepancy workflow's nuisance parameters. Defaults: manufacturing scatter of
    servo valve edges (α 3 %, underlap 5 µm), Table 1's β range 1.4–1.6 GPa and dead volumes from
    piping drawings (7 %), seal-friction datasheets (30 %), a weighed moving mass (2 %); the edges'
    shape beyond Eq. 3's nominal: the radial clearance R − r (50 %: a sharp-edged spool, no
    clearance intercept, is 2σ below) and the closed lands' leakage (100 % of Eq. 3's: worn lands
    leaking 3× are 2σ above).

    Attributes (SI, relative values as fractions)
    ----------
    alpha_rel, underlap_m, bulk_modulus_rel, volume_rel, friction_rel, mass_rel, clearance_rel, land_leakage_rel : float
    """

    alpha_rel: float = 0.03
    underlap_m: float = 5.0e-6
    bulk_modulus_rel: float = 0.07
    volume_rel: float = 0.07
    friction_rel: float = 0.30
    mass_rel: float = 0.02
    clearance_rel: float = 0.5
    land_leakage_rel: float = 1.0


_TOLERANCE_KEYS = {  # file key: (attribute, scale to SI, largest value in the file's unit)
    "alpha_pct": ("alpha_rel", 0.01, 50.0),
    "underlap_um": ("underlap_m", 1e-6, 1000.0),
    "bulk_modulus_pct": ("bulk_modulus_rel", 0.01, 50.0),
    "volume_pct": ("volume_rel", 0.01, 50.0),
    "friction_pct": ("friction_rel", 0.01, 100.0),
    "mass_pct": ("mass_rel", 0.01, 50.0),
    "clearance_pct": ("clearance_rel", 0.01, 100.0),
    "land_leakage_pct": ("land_leakage_rel", 0.01, 1000.0),
}


def _parse_tolerances(raw: Any, key: str) -> ModelTolerances:
    t = _table(raw, key)
    _no_unknown(t, set(_TOLERANCE_KEYS), key)
    kw = {}
    for name, (attr, scale, hi) in _TOLERANCE_KEYS.items():
        if name in t:
            kw[attr] = _number(t[name], f"{key}.{name}", 0.0, hi) * scale
    return ModelTolerances(**kw)


def _tolerances_dict(tol: ModelTolerances) -> dict[str, float]:
    return {name: _r(getattr(tol, attr) / scale) for name, (attr, scale, _) in _TOLERANCE_KEYS.items()}


# --- valves ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ValveSpec:
    """One monitored valve with its positioning unit, SI."""

    id: str
    type: str
    design: ValveDesign
    commissioned: datetime
    piston_diameter_m: float
    rod_diameter_m: float
    stroke_m: float
    v01_m3: float
    v02_m3: float
    bulk_modulus_pa: float
    density_kg_m3: float
    tags: dict[str, TagSpec]
    baseline_window: tuple[datetime, datetime] | None = None
    scenario: str | None = None
    overrides: frozenset[str] = field(default_factory=frozenset)
    """Design keys this valve sets itself (kept for writing the file back)."""
    tolerances: ModelTolerances | None = None
    """``[valves.tolerances]`` as given (None: the documented defaults of :class:`ModelTolerances`)."""

    @property
    def piston_area_m2(self) -> float:
        """Head-side piston area A1 = π D² / 4. [m²]"""
        return math.pi * self.piston_diameter_m**2 / 4

    @property
    def annulus_area_m2(self) -> float:
        """Rod-side annulus area A2 = A1 − π d² / 4. [m²]"""
        return self.piston_area_m2 - math.pi * self.rod_diameter_m**2 / 4

    def si_factor(self, signal: str, unit: str | None = None) -> float:
        """Factor from the exported unit of ``signal`` (or ``unit``) to SI; NaN when neither the
        configuration nor the caller gives one (units taken from each file)."""
        unit = unit if unit is not None else self.tags[signal].unit
        if unit is None:
            return math.nan
        return si_factor(unit, SIGNAL_KIND[signal], self.design.x_max_m)


@dataclass(frozen=True)
class RetentionSpec:
    """What becomes of lake partitions older than ``keep_days`` once their fits exist
    (``valvemon retention``; ``docs/warehouse.md``, "Retention")."""

    keep_days: int = 90
    """Days (UTC dates before the run's date) whose lake partitions stay whole. [d]"""
    mode: str = "thin"
    """``"thin"``: keep the first ``thin_keep_s_per_hour`` of every hour with data; ``"drop"``:
    delete the whole partition."""
    thin_keep_s_per_hour: float = 10.0
    """Seconds kept from the first sample of each UTC hour that has data (thin mode); 10 s is
    one periodic snapshot, ~0.3 % of a continuous hour. [s]"""


RETENTION_MODES: tuple[str, ...] = ("thin", "drop")


LAKE_CODECS: tuple[str, ...] = ("none", "lz4", "zstd")
"""Parquet codecs the lake's float columns may be written with (``[lake] codec``)."""


@dataclass(frozen=True)
class LakeSpec:
    """How the sensor lake's files are written (``docs/ingest.md``, "Storage")."""

    codec: str = "none"
    """Parquet codec of every lake file the ingest and retention write: ``"none"`` (the default:
    the cheapest to write and read), ``"lz4"`` (~29 % less disk on noisy float32 signals, its
    decode on every read: the monitor ~0.5 CPU s more a continuous valve-day) or ``"zstd"``
    (smaller still, slower). Files of any codec are read alike, so changing it applies to the
    files written from then on."""


@dataclass(frozen=True)
class MailSpec:
    """An SMTP relay and the message's addresses (``[notify.mail]``)."""

    host: str
    sender: str
    """The ``From`` address (key ``from``)."""
    to: tuple[str, ...]
    port: int = 587
    starttls: bool = True
    """Upgrade the connection with STARTTLS before anything is sent (the relay must offer it)."""
    user: str | None = None
    """Login name (None: the ``from`` address, when a password is configured)."""
    password_env: str | None = None
    """Name of the environment variable holding the password (None: no login)."""


@dataclass(frozen=True)
class NotifySpec:
    """Where and what ``valvemon report`` sends at the end of a run (``docs/notify.md``)."""

    webhook_url: str | None = None
    """A JSON POST to this URL (``text`` plus the changes; Teams, Slack, Mattermost accept it)."""
    mail: MailSpec | None = None
    faulty: bool = True
    """Send edges that became faulty, and new alarms on edges already faulty."""
    worn: bool = True
    """Send edges that became worn."""
    recovered: bool = True
    """Send edges back to healthy from faulty or worn."""
    remaining_below_h: float | None = None
    """Send healthy edges whose forecast remaining life dropped below this (None: not sent). [h]"""
    no_change: bool = False
    """On a night without a change to send, send one line saying so."""
    retries: int = 3
    """Attempts per message and channel in one run before it is kept for the next."""
    timeout_s: float = 10.0
    """Time allowed for one attempt (connect, send). [s]"""


@dataclass(frozen=True)
class PlantConfig:
    """A whole plant: export layout, valve types and monitored valves."""

    name: str
    timezone: str
    export: ExportSpec
    valve_types: dict[str, ValveDesign]
    valves: tuple[ValveSpec, ...]
    monitor: MonitorSpec = field(default_factory=MonitorSpec)
    retention: RetentionSpec | None = None
    """None: no retention configured, the lake is never thinned or dropped."""
    lake: LakeSpec = field(default_factory=LakeSpec)
    notify: NotifySpec | None = None
    """None: no ``[notify]`` section, nothing is sent."""

    def valve(self, valve_id: str) -> ValveSpec:
        """The valve with this id (``KeyError`` naming it if absent)."""
        for v in self.valves:
            if v.id == valve_id:
                return v
        raise KeyError(f"valve {valve_id!r} is not in plant {self.name!r}")

    def tag_index(self) -> dict[str, tuple[str, str]]:
        """Historian tag → (valve id, signal)."""
        return {t.tag: (v.id, s) for v in self.valves for s, t in v.tags.items()}


# --- parsing helpers -------------------------------------------------------------------------

_VALVE_ID = re.compile(r"^[A-Za-z0-9_-]+$")


def _table(value: Any, key: str) -> dict:
    if not isinstance(value, dict):
        raise ConfigError(f"{key}: expected a table, got {type(value).__name__}")
    return value


def _no_unknown(table: dict, allowed: set[str], key: str) -> None:
    unknown = sorted(set(table) - allowed)
    if unknown:
        where = f"{key}." if key else ""
        raise ConfigError(f"{where}{unknown[0]}: unknown key (expected one of {', '.join(sorted(allowed))})")


def _required(table: dict, name: str, key: str) -> Any:
    if name not in table:
        where = f"{key}." if key else ""
        raise ConfigError(f"{where}{name}: missing required key")
    return table[name]


def _str(value: Any, key: str, choices: tuple[str, ...] | None = None) -> str:
    if not isinstance(value, str) or not value:
        raise ConfigError(f"{key}: expected a non-empty string, got {value!r}")
    if choices is not None and value not in choices:
        raise ConfigError(f"{key}: {value!r} is not one of {', '.join(repr(c) for c in choices)}")
    return value


def _number(value: Any, key: str, lo: float | None = None, hi: float | None = None, *, open_lo: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(f"{key}: expected a finite number, got {value!r}")
    if lo is not None and (value <= lo if open_lo else value < lo):
        raise ConfigError(f"{key}: {value!r} must be {'>' if open_lo else '>='} {lo:g}")
    if hi is not None and value > hi:
        raise ConfigError(f"{key}: {value!r} must be <= {hi:g}")
    return float(value)


def _instant(value: Any, key: str, tz: ZoneInfo) -> datetime:
    if isinstance(value, str):
        try:
            value = datetime.fromisoformat(value.replace("Z", "+00:00"))
        except ValueError:
            raise ConfigError(f"{key}: {value!r} is not an ISO-8601 date-time") from None
    if not isinstance(value, datetime):
        raise ConfigError(f"{key}: expected an ISO-8601 date-time, got {value!r}")
    if value.tzinfo is None:
        value = value.replace(tzinfo=tz)
    return value.astimezone(timezone.utc)


# --- the tables ------------------------------------------------------------------------------

_TOP_KEYS = {"plant", "export", "monitor", "valve_types", "valves", "retention", "lake", "notify"}
_PLANT_KEYS = {"name", "timezone"}
_MONITOR_KEYS = {"window_s", "window_rows"}
_RETENTION_KEYS = {"keep_days", "mode", "thin_keep_s_per_hour"}
_LAKE_KEYS = {"codec"}
_NOTIFY_KEYS = {"webhook_url", "mail", "faulty", "worn", "recovered", "remaining_below_h", "no_change", "retries", "timeout_s"}
_MAIL_KEYS = {"host", "port", "from", "to", "starttls", "user", "password_env"}
_EXPORT_KEYS = {
    "layout", "timestamp_column", "timestamp_format", "tag_column", "value_column",
    "quality_column", "good_quality", "separator", "decimal", "sample_rate_hz", "max_gap_s",
    "duplicate_rule", "max_bad_share", "other_tags", "header_rows", "tdms_group", "start_time_format",
    "clock_steps", "ambiguous_time",
}  # fmt: skip


def _parse_export(raw: Any) -> ExportSpec:
    t = _table(raw, "export")
    _no_unknown(t, _EXPORT_KEYS, "export")
    layout = _str(_required(t, "layout", "export"), "export.layout", ("long", "wide"))
    kw: dict[str, Any] = {"layout": layout}
    kw["timestamp_column"] = _str(_required(t, "timestamp_column", "export"), "export.timestamp_column")
    kw["timestamp_format"] = _str(t.get("timestamp_format", "iso8601"), "export.timestamp_format")
    if layout == "long":
        kw["tag_column"] = _str(_required(t, "tag_column", "export"), "export.tag_column")
        kw["value_column"] = _str(_required(t, "value_column", "export"), "export.value_column")
    if "quality_column" in t:
        kw["quality_column"] = _str(t["quality_column"], "export.quality_column")
        good = _required(t, "good_quality", "export")
        if not isinstance(good, list) or not good or not all(isinstance(g, (str, int)) for g in good):
            raise ConfigError("export.good_quality: expected a non-empty list of quality codes")
        kw["good_quality"] = tuple(str(g) for g in good)
    kw["separator"] = _str(t.get("separator", ","), "export.separator", (",", ";", "\t"))
    kw["decimal"] = _str(t.get("decimal", "."), "export.decimal", (".", ","))
    if kw["decimal"] == "," and kw["separator"] == ",":
        raise ConfigError("export.decimal: ',' needs a separator other than ','")
    kw["sample_rate_hz"] = _number(t.get("sample_rate_hz", 1000.0), "export.sample_rate_hz", 0, 1e6, open_lo=True)
    kw["max_gap_s"] = _number(t.get("max_gap_s", 5.0 / kw["sample_rate_hz"]), "export.max_gap_s", 0, open_lo=True)
    if kw["max_gap_s"] < 1.0 / kw["sample_rate_hz"]:
        raise ConfigError("export.max_gap_s: must be at least one sample period")
    kw["duplicate_rule"] = _str(t.get("duplicate_rule", "last"), "export.duplicate_rule", ("last", "first", "error"))
    kw["max_bad_share"] = _number(t.get("max_bad_share", DEFAULT_MAX_BAD_SHARE), "export.max_bad_share", 0, 1, open_lo=True)
    kw["other_tags"] = _str(t.get("other_tags", "ignore"), "export.other_tags", OTHER_TAGS_RULES)
    if "header_rows" in t:
        kw["header_rows"] = _parse_header_rows(t["header_rows"], layout)
    if "tdms_group" in t:
        kw["tdms_group"] = _str(t["tdms_group"], "export.tdms_group")
    relative = kw["timestamp_format"] in RELATIVE_TIME_FORMATS
    if "start_time_format" in t:
        if not relative:
            raise ConfigError(f"export.start_time_format: only with a relative export.timestamp_format ({' or '.join(map(repr, RELATIVE_TIME_FORMATS))})")
        kw["start_time_format"] = _str(t["start_time_format"], "export.start_time_format")
    elif relative:
        raise ConfigError(
            f"export.start_time_format: required with export.timestamp_format = {kw['timestamp_format']!r} "
            "(the pattern of the file's start time, on its 'start_time' header line or in its name)"
        )
    if "start_time" in kw.get("header_rows", ()) and not relative:
        raise ConfigError(f"export.header_rows: a 'start_time' line needs a relative export.timestamp_format ({' or '.join(map(repr, RELATIVE_TIME_FORMATS))})")
    kw["clock_steps"] = _str(t.get("clock_steps", "quarantine"), "export.clock_steps", CLOCK_STEP_RULES)
    kw["ambiguous_time"] = _str(t.get("ambiguous_time", ExportSpec.ambiguous_time), "export.ambiguous_time", AMBIGUOUS_TIME_RULES)
    return ExportSpec(**kw)


def _parse_header_rows(raw: Any, layout: str) -> tuple[str, ...]:
    key = "export.header_rows"
    if not isinstance(raw, list) or not raw or not all(isinstance(r, str) for r in raw):
        raise ConfigError(f"{key}: expected a non-empty list of {', '.join(repr(k) for k in HEADER_ROW_KINDS)}, got {raw!r}")
    for i, r in enumerate(raw):
        if r not in HEADER_ROW_KINDS:
            raise ConfigError(f"{key}[{i}]: {r!r} is not one of {', '.join(repr(k) for k in HEADER_ROW_KINDS)}")
    for kind, most in (("tag", 1), ("unit", 1), ("name", 1), ("start_time", 1)):
        if raw.count(kind) > most:
            raise ConfigError(f"{key}: {kind!r} may occur only once (the file has one line of {kind}s)")
    if "tag" not in raw:
        raise ConfigError(f"{key}: needs one 'tag' line (the column names, matched to the configured tags)")
    if layout != "wide" and raw != ["tag"]:
        raise ConfigError(f"{key}: header rows other than 'tag' are only for export.layout = 'wide'")
    return tuple(raw)


def _parse_retention(raw: Any) -> RetentionSpec:
    t = _table(raw, "retention")
    _no_unknown(t, _RETENTION_KEYS, "retention")
    days = _required(t, "keep_days", "retention")
    if isinstance(days, bool) or not isinstance(days, int) or days < 1:
        raise ConfigError(f"retention.keep_days: expected a whole number of days >= 1, got {days!r}")
    mode = _str(t.get("mode", RetentionSpec.mode), "retention.mode", RETENTION_MODES)
    keep_s = RetentionSpec.thin_keep_s_per_hour
    if "thin_keep_s_per_hour" in t:
        if mode != "thin":
            raise ConfigError(f"retention.thin_keep_s_per_hour: only used with mode = 'thin' (mode is {mode!r})")
        keep_s = _number(t["thin_keep_s_per_hour"], "retention.thin_keep_s_per_hour", 0, 3600, open_lo=True)
        if keep_s >= 3600:
            raise ConfigError(f"retention.thin_keep_s_per_hour: {keep_s:g} must be < 3600 (a whole hour thins nothing)")
    return RetentionSpec(days, mode, keep_s)


def _parse_lake(raw: Any) -> LakeSpec:
    t = _table(raw, "lake")
    _no_unknown(t, _LAKE_KEYS, "lake")
    return LakeSpec(_str(t.get("codec", LakeSpec.codec), "lake.codec", LAKE_CODECS))


def _bool(value: Any, key: str) -> bool:
    if not isinstance(value, bool):
        raise ConfigError(f"{key}: expected true or false, got {value!r}")
    return value


def _address(value: Any, key: str) -> str:
    value = _str(value, key)
    if not re.fullmatch(r"[^@\s]+@[^@\s]+", value):
        raise ConfigError(f"{key}: {value!r} is not a mail address")
    return value


def _parse_mail(raw: Any) -> MailSpec:
    t = _table(raw, "notify.mail")
    if "password" in t:
        raise ConfigError("notify.mail.password: a password is never kept in the file; name the environment variable that holds it in password_env")
    _no_unknown(t, _MAIL_KEYS, "notify.mail")
    to = _required(t, "to", "notify.mail")
    to = [to] if isinstance(to, str) else to
    if not isinstance(to, list) or not to:
        raise ConfigError(f"notify.mail.to: expected an address or a list of addresses, got {to!r}")
    starttls = _bool(t.get("starttls", MailSpec.starttls), "notify.mail.starttls")
    port = t.get("port", MailSpec.port if starttls else 25)
    if isinstance(port, bool) or not isinstance(port, int) or not 0 < port < 65536:
        raise ConfigError(f"notify.mail.port: expected a port number 1-65535, got {port!r}")
    env = _str(t["password_env"], "notify.mail.password_env") if "password_env" in t else None
    if env is not None and not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", env):
        raise ConfigError(f"notify.mail.password_env: {env!r} is not an environment variable name")
    return MailSpec(
        host=_str(_required(t, "host", "notify.mail"), "notify.mail.host"),
        sender=_address(_required(t, "from", "notify.mail"), "notify.mail.from"),
        to=tuple(_address(a, f"notify.mail.to[{i}]") for i, a in enumerate(to)),
        port=port, starttls=starttls,
        user=_str(t["user"], "notify.mail.user") if "user" in t else None,
        password_env=env,
    )  # fmt: skip


def _parse_notify(raw: Any) -> NotifySpec:
    t = _table(raw, "notify")
    _no_unknown(t, _NOTIFY_KEYS, "notify")
    url = _str(t["webhook_url"], "notify.webhook_url") if "webhook_url" in t else None
    if url is not None and not re.match(r"https?://[^/\s]+", url):
        raise ConfigError(f"notify.webhook_url: {url!r} is not an http:// or https:// URL")
    mail = _parse_mail(t["mail"]) if "mail" in t else None
    if url is None and mail is None:
        raise ConfigError("notify: name a webhook_url or a [notify.mail] table (or leave [notify] out: nothing is sent)")
    kw: dict[str, Any] = {k: _bool(t[k], f"notify.{k}") for k in ("faulty", "worn", "recovered", "no_change") if k in t}
    if "remaining_below_h" in t:
        kw["remaining_below_h"] = _number(t["remaining_below_h"], "notify.remaining_below_h", 0, open_lo=True)
    if "retries" in t:
        n = t["retries"]
        if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= 10:
            raise ConfigError(f"notify.retries: expected a whole number of attempts 1-10, got {n!r}")
        kw["retries"] = n
    if "timeout_s" in t:
        kw["timeout_s"] = _number(t["timeout_s"], "notify.timeout_s", 0, 600, open_lo=True)
    return NotifySpec(webhook_url=url, mail=mail, **kw)


def _notify_dict(n: NotifySpec) -> dict:
    out: dict[str, Any] = {} if n.webhook_url is None else {"webhook_url": n.webhook_url}
    defaults = NotifySpec()
    for k in ("faulty", "worn", "recovered", "remaining_below_h", "no_change", "retries", "timeout_s"):
        if getattr(n, k) != getattr(defaults, k):
            out[k] = getattr(n, k)
    m = n.mail
    if m is not None:
        out["mail"] = {"host": m.host, "port": m.port, "from": m.sender, "to": list(m.to), "starttls": m.starttls}
        out["mail"] |= {k: getattr(m, k) for k in ("user", "password_env") if getattr(m, k) is not None}
    return out


def _parse_monitor(raw: Any) -> MonitorSpec:
    t = _table(raw, "monitor")
    _no_unknown(t, _MONITOR_KEYS, "monitor")
    window_s = _number(t.get("window_s", DEFAULT_WINDOW_S), "monitor.window_s", 1.0, 86_400.0)
    per_day = 86_400.0 / window_s
    if abs(per_day - round(per_day)) > 1e-9 * per_day:
        raise ConfigError(f"monitor.window_s: {window_s:g} s does not divide a day (86400 s) into whole windows (e.g. 60, 300, 600, 3600)")
    rows = t.get("window_rows", DEFAULT_WINDOW_ROWS)
    if isinstance(rows, bool) or not isinstance(rows, int) or not (rows == 0 or rows >= 1000):
        raise ConfigError(f"monitor.window_rows: expected 0 (every row) or a whole number >= 1000, got {rows!r}")
    return MonitorSpec(window_s=window_s, window_rows=rows)


_DESIGN_KEYS = {
    "x_max_mm", "bore_radius_mm", "spool_radius_mm", "taper_angle_port1_deg",
    "taper_angle_port2_deg", "underlap_mm", "contraction_coefficient", "bounds", "area_law",
    "leakage_factor",
}  # fmt: skip

AREA_LAWS = ("eq3", "sharp")
"""Values of ``area_law`` (``model.params.AREA_LAWS``; schemas imports nothing of ours)."""


def _parse_underlaps(raw: Any, key: str, base: tuple[float, ...] | None) -> tuple[float, float, float, float]:
    t = _table(raw, key)
    _no_unknown(t, set(EDGES), key)
    values = list(base) if base is not None else [None] * 4
    for i, edge in enumerate(EDGES):
        if edge in t:
            values[i] = _number(t[edge], f"{key}.{edge}") * 1e-3
        elif values[i] is None:
            raise ConfigError(f"{key}.{edge}: missing required key")
    return tuple(values)  # type: ignore[return-value]


def _parse_bounds(raw: Any, key: str, base: ConditionBounds) -> ConditionBounds:
    """A ``bounds`` table: each key optional, ``base`` supplies the rest; checked for order."""
    t = _table(raw, key)
    _no_unknown(t, set(BOUND_KEYS), key)
    kw: dict[str, Any] = {}
    for name in BOUND_KEYS:
        if name not in t:
            continue
        k = f"{key}.{name}"
        v = t[name]
        if name in _INT_BOUNDS:
            if isinstance(v, bool) or not isinstance(v, int):
                raise ConfigError(f"{k}: expected an integer, got {v!r}")
            kw[name] = int(_number(v, k, 2, 100_000))
        elif name.endswith("sigma_floor") or name.startswith(("e_mm2_", "trend_", "fault_", "change_", "eq9_tol")):
            kw[name] = _number(v, k, 0, 1e7, open_lo=True)
        elif name.startswith("alpha_"):
            kw[name] = _number(v, k, 0, 100, open_lo=True)
        else:
            kw[name] = _number(v, k, -100, 100)  # x_hat_pct_* and eq9_expected
    b = replace(base, **kw)
    for p in ("alpha", "x_hat_pct"):
        order = [f"{p}_fault_low", f"{p}_wear_low", f"{p}_wear_high", f"{p}_fault_high"]
        values = [getattr(b, n) for n in order]
        for lo_name, hi_name, lo, hi in zip(order, order[1:], values, values[1:]):
            if not (lo < hi if lo_name.endswith("wear_low") else lo <= hi):
                raise ConfigError(f"{key}.{hi_name}: {hi:g} must be {'>' if lo_name.endswith('wear_low') else '>='} {lo_name} = {lo:g}")
    if b.e_mm2_wear_high > b.e_mm2_fault_high:
        raise ConfigError(f"{key}.e_mm2_fault_high: {b.e_mm2_fault_high:g} must be >= e_mm2_wear_high = {b.e_mm2_wear_high:g}")
    for p, unchanged in (("alpha", 1.0), ("x_hat_pct", 0.0)):
        for side, bad in (("low", getattr(b, f"{p}_wear_low") >= unchanged), ("high", getattr(b, f"{p}_wear_high") <= unchanged)):
            if bad:
                raise ConfigError(f"{key}.{p}_wear_{side}: the wear bounds of {p} must enclose {unchanged:g} (unchanged)")
    if b.change_min_history > b.change_history_windows:
        raise ConfigError(f"{key}.change_min_history: {b.change_min_history} must be <= change_history_windows = {b.change_history_windows}")
    if b.trend_min_fits < 5:
        raise ConfigError(f"{key}.trend_min_fits: {b.trend_min_fits} must be >= 5 (a line, its scatter and a t quantile)")
    if b.trend_min_span_hours > b.trend_span_hours:
        raise ConfigError(f"{key}.trend_min_span_hours: {b.trend_min_span_hours:g} must be <= trend_span_hours = {b.trend_span_hours:g}")
    return b


def _parse_design(t: dict, key: str, base: ValveDesign | None) -> ValveDesign:
    """Design keys of a valve type (``base`` None) or a valve's overrides of its type."""

    def get(name: str, lo: float, hi: float, scale: float, current: float | None, open_lo: bool = True) -> float:
        if name in t:
            return _number(t[name], f"{key}.{name}", lo, hi, open_lo=open_lo) * scale
        if current is None:
            raise ConfigError(f"{key}.{name}: missing required key")
        return current

    b = base
    x_max = get("x_max_mm", 0, 50, 1e-3, b and b.x_max_m)
    bore = get("bore_radius_mm", 0, 500, 1e-3, b and b.bore_radius_m)
    spool = get("spool_radius_mm", 0, 500, 1e-3, b and b.spool_radius_m)
    if spool >= bore:
        raise ConfigError(f"{key}.spool_radius_mm: the spool radius must be smaller than the bore radius")
    phi1 = get("taper_angle_port1_deg", 0, 89, math.pi / 180, b and b.taper_angle_port1_rad)
    phi2 = get("taper_angle_port2_deg", 0, 89, math.pi / 180, b and b.taper_angle_port2_rad)
    if "underlap_mm" in t:
        underlaps = _parse_underlaps(t["underlap_mm"], f"{key}.underlap_mm", b and b.underlap_m)
    elif b is None:
        raise ConfigError(f"{key}.underlap_mm: missing required key")
    else:
        underlaps = b.underlap_m
    for edge, u in zip(EDGES, underlaps):
        if abs(u) >= x_max:
            raise ConfigError(f"{key}.underlap_mm.{edge}: an underlap of {u * 1e3:g} mm is not smaller than the stroke x_max = {x_max * 1e3:g} mm")
    alpha = get("contraction_coefficient", 0, 1.5, 1.0, b and b.contraction_coefficient)
    base_bounds = b.bounds if b is not None else ConditionBounds()
    bounds = _parse_bounds(t["bounds"], f"{key}.bounds", base_bounds) if "bounds" in t else base_bounds
    area_law = _str(t["area_law"], f"{key}.area_law", AREA_LAWS) if "area_law" in t else (b.area_law if b else "eq3")
    leakage_factor = get("leakage_factor", 0, 100, 1.0, b.leakage_factor if b else 1.0)
    if area_law == "sharp" and leakage_factor != 1.0:
        raise ConfigError(f"{key}.leakage_factor: {leakage_factor:g} needs area_law = \"eq3\" (a sharp-edged valve has no leakage branch)")
    return ValveDesign(x_max, bore, spool, phi1, phi2, underlaps, alpha, bounds, area_law, leakage_factor)


_VALVE_KEYS = {
    "id", "type", "commissioned", "piston_diameter_mm", "rod_diameter_mm", "stroke_mm", "v01_l",
    "v02_l", "bulk_modulus_gpa", "density_kg_m3", "tags", "baseline_window", "scenario", "tolerances",
} | _DESIGN_KEYS  # fmt: skip


def _parse_tags(raw: Any, key: str, x_max_m: float, units_in_file: bool = False) -> dict[str, TagSpec]:
    t = _table(raw, key)
    _no_unknown(t, set(SIGNALS), key)
    tags: dict[str, TagSpec] = {}
    for signal in SIGNALS:
        if signal not in t:
            if signal in REQUIRED_SIGNALS:
                raise ConfigError(f"{key}.{signal}: missing required signal")
            continue
        skey = f"{key}.{signal}"
        spec = _table(t[signal], skey)
        _no_unknown(spec, {"tag", "unit"}, skey)
        tag = _str(_required(spec, "tag", skey), f"{skey}.tag")
        if "unit" not in spec and units_in_file:
            tags[signal] = TagSpec(tag, None)  # the unit row of each file says it
            continue
        if "unit" not in spec:
            raise ConfigError(f"{skey}.unit: missing required key (it may be left out only when export.header_rows has a 'unit' line)")
        unit = _str(spec["unit"], f"{skey}.unit")
        try:
            si_factor(unit, SIGNAL_KIND[signal], x_max_m)
        except UnitError as exc:
            raise ConfigError(f"{skey}.unit: {exc}") from None
        tags[signal] = TagSpec(tag, unit)
    return tags


def _parse_valve(raw: Any, key: str, types: dict[str, ValveDesign], tz: ZoneInfo, units_in_file: bool = False) -> ValveSpec:
    t = _table(raw, key)
    _no_unknown(t, _VALVE_KEYS, key)
    vid = _str(_required(t, "id", key), f"{key}.id")
    if not _VALVE_ID.match(vid):
        raise ConfigError(f"{key}.id: {vid!r} may hold only letters, digits, '-' and '_'")
    type_name = _str(_required(t, "type", key), f"{key}.type")
    if type_name not in types:
        raise ConfigError(f"{key}.type: unknown valve type {type_name!r} (defined: {', '.join(sorted(types)) or 'none'})")
    overrides = frozenset(_DESIGN_KEYS & set(t))
    design = _parse_design(t, key, types[type_name]) if overrides else types[type_name]

    def num(name: str, lo: float, hi: float, scale: float) -> float:
        return _number(_required(t, name, key), f"{key}.{name}", lo, hi, open_lo=True) * scale

    piston = num("piston_diameter_mm", 0, 5000, 1e-3)
    rod = num("rod_diameter_mm", 0, 5000, 1e-3)
    if rod >= piston:
        raise ConfigError(f"{key}.rod_diameter_mm: the rod must be thinner than the piston ({rod * 1e3:g} >= {piston * 1e3:g} mm)")
    stroke = num("stroke_mm", 0, 20000, 1e-3)
    v01 = num("v01_l", 0, 1e5, 1e-3)
    v02 = num("v02_l", 0, 1e5, 1e-3)
    annulus = math.pi * (piston**2 - rod**2) / 4
    if v02 <= annulus * stroke:
        raise ConfigError(
            f"{key}.v02_l: {v02 * 1e3:g} L must exceed the rod-side stroke volume A2·stroke = "
            f"{annulus * stroke * 1e3:.3g} L (v02 is the rod-side volume at X = 0)"
        )
    baseline = None
    if "baseline_window" in t:
        bkey = f"{key}.baseline_window"
        b = _table(t["baseline_window"], bkey)
        _no_unknown(b, {"start", "end"}, bkey)
        start = _instant(_required(b, "start", bkey), f"{bkey}.start", tz)
        end = _instant(_required(b, "end", bkey), f"{bkey}.end", tz)
        if end <= start:
            raise ConfigError(f"{bkey}.end: must be later than start")
        baseline = (start, end)
    return ValveSpec(
        id=vid,
        type=type_name,
        design=design,
        commissioned=_instant(_required(t, "commissioned", key), f"{key}.commissioned", tz),
        piston_diameter_m=piston,
        rod_diameter_m=rod,
        stroke_m=stroke,
        v01_m3=v01,
        v02_m3=v02,
        bulk_modulus_pa=num("bulk_modulus_gpa", 0, 10, 1e9),
        density_kg_m3=num("density_kg_m3", 0, 5000, 1.0),
        tags=_parse_tags(_required(t, "tags", key), f"{key}.tags", design.x_max_m, units_in_file),
        baseline_window=baseline,
        scenario=_str(t["scenario"], f"{key}.scenario") if "scenario" in t else None,
        overrides=overrides,
        tolerances=_parse_tolerances(t["tolerances"], f"{key}.tolerances") if "tolerances" in t else None,
    )


def parse_plant_config(data: dict) -> PlantConfig:
    """Validate a plant configuration (as parsed from TOML) and convert it to SI.

    Raises
    ------
    ConfigError
        For unknown keys, missing required keys, impossible values, unknown units, duplicate
        valve ids or a historian tag used twice; the message starts with the key's path.
    """
    _no_unknown(_table(data, "top level"), _TOP_KEYS, "")
    plant = _table(_required(data, "plant", ""), "plant")
    _no_unknown(plant, _PLANT_KEYS, "plant")
    name = _str(_required(plant, "name", "plant"), "plant.name")
    tz_name = _str(_required(plant, "timezone", "plant"), "plant.timezone")
    try:
        tz = ZoneInfo(tz_name)
    except (ZoneInfoNotFoundError, ValueError):
        raise ConfigError(f"plant.timezone: {tz_name!r} is not an IANA time zone name") from None
    export = _parse_export(_required(data, "export", ""))
    monitor = _parse_monitor(data.get("monitor", {}))
    types_raw = _table(_required(data, "valve_types", ""), "valve_types")
    types: dict[str, ValveDesign] = {}
    for tname, traw in types_raw.items():
        tkey = f"valve_types.{tname}"
        tt = _table(traw, tkey)
        _no_unknown(tt, _DESIGN_KEYS, tkey)
        types[tname] = _parse_design(tt, tkey, None)
    valves_raw = _required(data, "valves", "")
    if not isinstance(valves_raw, list) or not valves_raw:
        raise ConfigError("valves: expected at least one [[valves]] table")
    valves = tuple(_parse_valve(v, f"valves[{i}]", types, tz, export.units_in_file) for i, v in enumerate(valves_raw))
    seen_ids: dict[str, int] = {}
    seen_tags: dict[str, str] = {}
    for i, v in enumerate(valves):
        if v.id in seen_ids:
            raise ConfigError(f"valves[{i}].id: {v.id!r} is used twice (also valves[{seen_ids[v.id]}])")
        seen_ids[v.id] = i
        for signal, spec in v.tags.items():
            here = f"valves[{i}].tags.{signal}.tag"
            if spec.tag in seen_tags:
                raise ConfigError(f"{here}: tag {spec.tag!r} is used twice (also {seen_tags[spec.tag]})")
            seen_tags[spec.tag] = here
    if export.layout == "wide":
        reserved = {export.timestamp_column}
        clash = reserved & set(seen_tags)
        if clash:
            raise ConfigError(f"export.timestamp_column: {clash.pop()!r} is also a tag name")
    retention = _parse_retention(data["retention"]) if "retention" in data else None
    lake = _parse_lake(data["lake"]) if "lake" in data else LakeSpec()
    notify = _parse_notify(data["notify"]) if "notify" in data else None
    return PlantConfig(name, tz_name, export, types, valves, monitor, retention, lake, notify)


# --- writing back ----------------------------------------------------------------------------


def _r(x: float) -> float:
    """A unit-converted value rounded to 12 significant digits, so files stay readable."""
    return float(f"{x:.12g}")


def _design_dict(d: ValveDesign, keys: frozenset[str] | set[str], base_bounds: ConditionBounds | None = None) -> dict:
    full: dict[str, Callable[[], Any]] = {
        "x_max_mm": lambda: _r(d.x_max_m * 1e3),
        "bore_radius_mm": lambda: _r(d.bore_radius_m * 1e3),
        "spool_radius_mm": lambda: _r(d.spool_radius_m * 1e3),
        "taper_angle_port1_deg": lambda: _r(math.degrees(d.taper_angle_port1_rad)),
        "taper_angle_port2_deg": lambda: _r(math.degrees(d.taper_angle_port2_rad)),
        "underlap_mm": lambda: {e: _r(u * 1e3) for e, u in zip(EDGES, d.underlap_m)},
        "contraction_coefficient": lambda: d.contraction_coefficient,
        "bounds": lambda: bounds_to_dict(d.bounds, base_bounds),
        "area_law": lambda: d.area_law,
        "leakage_factor": lambda: d.leakage_factor,
    }
    out = {k: full[k]() for k in full if k in keys}
    for k, default in (("area_law", "eq3"), ("leakage_factor", 1.0)):
        if base_bounds is None and out.get(k, default) == default:
            out.pop(k, None)  # a type's family at its default is not written
    if base_bounds is None and not out.get("bounds", True):
        del out["bounds"]  # a type's bounds all at their defaults
    return out


def bounds_to_dict(bounds: ConditionBounds, base: ConditionBounds | None = None) -> dict:
    """The keys of ``bounds`` that differ from ``base`` (default: the documented defaults)."""
    base = base if base is not None else ConditionBounds()
    return {k: getattr(bounds, k) for k in BOUND_KEYS if getattr(bounds, k) != getattr(base, k) and getattr(bounds, k) is not None}


def _iso(t: datetime) -> str:
    return t.astimezone(timezone.utc).isoformat().replace("+00:00", "Z")


def plant_config_to_dict(config: PlantConfig) -> dict:
    """The configuration as a TOML-ready dictionary in the file's own units (mm, L, GPa, °)."""
    e = config.export
    export: dict[str, Any] = {"layout": e.layout, "timestamp_column": e.timestamp_column, "timestamp_format": e.timestamp_format}
    if e.layout == "long":
        export |= {"tag_column": e.tag_column, "value_column": e.value_column}
    if e.quality_column is not None:
        export |= {"quality_column": e.quality_column, "good_quality": list(e.good_quality)}
    export |= {
        "separator": e.separator,
        "decimal": e.decimal,
        "sample_rate_hz": e.sample_rate_hz,
        "max_gap_s": e.max_gap_s,
        "duplicate_rule": e.duplicate_rule,
    }
    if e.max_bad_share != DEFAULT_MAX_BAD_SHARE:
        export["max_bad_share"] = e.max_bad_share
    if e.other_tags != ExportSpec.other_tags:
        export["other_tags"] = e.other_tags
    if e.header_rows != ExportSpec.header_rows:
        export["header_rows"] = list(e.header_rows)
    if e.tdms_group is not None:
        export["tdms_group"] = e.tdms_group
    if e.start_time_format is not None:
        export["start_time_format"] = e.start_time_format
    if e.clock_steps != ExportSpec.clock_steps:
        export["clock_steps"] = e.clock_steps
    if e.ambiguous_time != ExportSpec.ambiguous_time:
        export["ambiguous_time"] = e.ambiguous_time
    valves = []
    for v in config.valves:
        d: dict[str, Any] = {"id": v.id, "type": v.type, "commissioned": _iso(v.commissioned)}
        d |= _design_dict(v.design, v.overrides, config.valve_types[v.type].bounds)
        d |= {
            "piston_diameter_mm": _r(v.piston_diameter_m * 1e3),
            "rod_diameter_mm": _r(v.rod_diameter_m * 1e3),
            "stroke_mm": _r(v.stroke_m * 1e3),
            "v01_l": _r(v.v01_m3 * 1e3),
            "v02_l": _r(v.v02_m3 * 1e3),
            "bulk_modulus_gpa": _r(v.bulk_modulus_pa / 1e9),
            "density_kg_m3": v.density_kg_m3,
        }
        if v.baseline_window is not None:
            d["baseline_window"] = {"start": _iso(v.baseline_window[0]), "end": _iso(v.baseline_window[1])}
        if v.scenario is not None:
            d["scenario"] = v.scenario
        if v.tolerances is not None:
            d["tolerances"] = _tolerances_dict(v.tolerances)
        d["tags"] = {s: {"tag": t.tag} | ({"unit": t.unit} if t.unit is not None else {}) for s, t in v.tags.items()}
        valves.append(d)
    out: dict[str, Any] = {"plant": {"name": config.name, "timezone": config.timezone}, "export": export}
    if config.monitor != MonitorSpec():
        out["monitor"] = {"window_s": config.monitor.window_s, "window_rows": config.monitor.window_rows}
    out |= {"valve_types": {n: _design_dict(t, _DESIGN_KEYS) for n, t in config.valve_types.items()}, "valves": valves}
    r = config.retention
    if r is not None:
        out["retention"] = {"keep_days": r.keep_days, "mode": r.mode} | ({"thin_keep_s_per_hour": r.thin_keep_s_per_hour} if r.mode == "thin" else {})
    if config.lake != LakeSpec():
        out["lake"] = {"codec": config.lake.codec}
    if config.notify is not None:
        out["notify"] = _notify_dict(config.notify)
    return out
