"""What the monitoring algorithm (steps 2–4b) needs to know about one valve, and its settings.

Everything is SI. The physical part is what Eq. 7 and its three siblings use (model.md: A1, A2,
V01, V02, β, ρ) plus the underlaps and x_max for the step-3 spool rule and the fit's search
range. The method part carries the defaults argued below; the flows layer builds one
:class:`MonitorParams` per valve from the plant configuration.

Why these defaults (1 kHz sampling, pressure noise σ_p ≈ 0.05–0.1 bar, Table 1 cylinder)
-------------------------------------------------------------------------------------------

Savitzky–Golay window 21 samples, polynomial order 3.
    For a symmetric window the derivative coefficients of order 3 equal those of order 4 and the
    smoothing coefficients of order 3 equal those of order 2, so order 3 buys a derivative exact
    for quartics at the noise of an order-3 fit. Two errors compete:

    * noise: σ(dp/dt) = σ_p / Δt · ‖w‖₂. For L = 21, order 3: ‖w‖₂ = 0.091 → σ(dp/dt) ≈ 9·10⁵ Pa/s
      at σ_p = 0.1 bar. In Eq. 7 this enters as V·σ(dp/dt)/β ≈ 1.8·10⁻⁶ m³/s on port 1 (V1 ≈ 3 L),
      about 1 % of the displacement flow A1·v_X at 10 mm/s, and it is zero-mean, so it
      averages out over a population of points. Quantisation of a 16-bit converter over 250 bar
      (0.004 bar steps, σ = 0.001 bar) is negligible beside σ_p.
    * bias: the derivative's gain error at frequency f. The cylinder/load mass-spring of
      Table 1 (m = 6 t, β = 1.5 GPa, V1 ≈ 3 L, V2 ≈ 7 L) rings near 20–25 Hz, the fastest
      pressure content that carries flow information. At 25 Hz the gain error is −1.3 % for
      L = 21/order 3, −5.7 % for L = 31/order 3, and −25 % for L = 21/order 2 (order 2 is far too
      biased at any useful length). A bias does not average out; it is kept near 1 %.

    L = 15/order 3 would halve the bias but raise the noise by 70 %; L = 21 is the compromise.
    The smoothed p1, p2 (used in the pressure differences) have a noise factor 0.33.

Gap limit 3 sample periods.
    A step longer than that starts a new monitoring window (hourly 10 s windows are separated by
    about an hour; a single dropped sample does not split a window). Inside a window, the
    Savitzky–Golay stencil is additionally never laid across an irregular step (one deviating by
    more than ``step_tolerance`` from the sample period), because its weights assume a uniform
    grid: such samples get no derivative.

Standstill |v_X| < 5 mm/s.
    Below it the flow through the open edge is small, the Eq. 7 numerator is dominated by the
    derivative noise (port 2, V2 ≈ 7 L, A2 = 7.5·10⁻³ m²: 4.3·10⁻⁶ m³/s noise against
    3.8·10⁻⁵ m³/s of displacement flow at 5 mm/s, about 11 %), and friction is in its stick-slip
    range (Stribeck velocity 15 mm/s). With the spool more than 1 mm open and |Δp| ≥ 10 bar the
    cylinder moves at several cm/s, so the rule removes little that matters.

Pressure peaks: |dp1/dt| or |dp2/dt| > 2·10⁹ Pa/s, or the compressibility flow of the edge's
port larger than 0.5 × its displacement flow (|V dp/dt / β| > 0.5 |A v_X|).
    The absolute bound lies just under what the valve alone can produce (40 mm² open at 200 bar
    into 3 L: about 3·10⁹ Pa/s); faster pressure changes are load impacts or sensor glitches.
    The ratio rule is the paper's own reason for discarding peaks ("dp/dt may dominate the
    terms with v_X"): the compressibility term carries the ±7 % uncertainty of β (1.4–1.6 GPa);
    at a ratio of 0.5 it can bias a point by at most 0.07·0.5/(1 − 0.5) = 7 %, typically far
    less.

Spool margin 1 mm above the largest underlap of the opposite side (model.md).
    Eq. 7 takes the closed edge of the same port as carrying no flow. Its leakage area decays only
    like 1/|u|: within 0.1 mm of the underlap the plain formula is off by 20–100 %, beyond 1 mm
    by at most a few per cent (s2, whose closed edge 2r sees p2 − p_r ≈ 150 bar while s2 itself
    carries p_s − p2 of a few tens of bar: −3.7 % at u = 1 mm, −0.7 % at 2.5 mm). The margin is
    kept although that rest is now corrected (below): the correction rests on the model's leakage
    branch, and 1 mm keeps what it has to correct at a few per cent.

Closed-edge leakage correction, ``leakage_passes = 1`` (flows/monitor/flow.py turns it on).
    The flow through the closed edge o of the same port is subtracted from each point with o's
    α·A of Eq. 3 (its leakage branch), scaled and shifted to o's state in *that window*: first
    o's baseline state (the nominal characteristic, or the commissioning fit's α_b, x_b against
    it), then, after a first estimate of every edge in every window (from every 8th point), o's
    own α̂_o, x̂_o. A bias that varies with u is what hurts: at narrow coverage (u ≈ 1.04–1.37 mm,
    slow moves) α̂ and x̂ are nearly confounded, so ~0.3 % of u-dependent bias becomes ~30 µm of
    x̂. Measured on 31 simulated valves along the wear scenario (docs/monitoring.md): worst x̂
    error 1.28 % of x_max (s2) uncorrected, 0.92 % with the nominal leakage subtracted (the worn
    closed edge leaks more than nominal), 0.14 % with the correction that follows the window.
    One pass suffices: a second changes x̂ by at most 0.013 % of x_max (0.4 µm), α̂ by 3·10⁻⁴.

Step-4a baseline: nominal-shaped (``baseline_grid_m`` 0.05 mm).
    Â = S(u)·c(u): S the nominal characteristic scaled and shifted onto the commissioning points
    (Eq. 8), c a piecewise-linear factor on the quantile knots below, Â sampled every 0.05 mm and
    widened by the x̂ search bound with c held at its end values. A plain chord over a sparse
    1.4 mm segment misses Eq. 3's curvature by ~1 % of slope on port 1, and a later window that
    lives inside that segment, or beyond the commissioning range, inherits it (0.3 % of x_max
    with the leakage corrected, ≤ 0.015 % with the shaped baseline, noiseless).

|Δp| across the edge ≥ 2 bar.
    A ∝ 1/sqrt|Δp|: a pressure error δ gives a relative area error δ/(2|Δp|). The smoothed
    chamber pressure (0.33 × 0.05 bar) against the raw supply/return sensor (0.05 bar) leaves
    σ ≈ 0.05 bar, 1.3 % per point at 2 bar (random, it averages out); a 0.1 bar sensor offset
    biases by 2.5 % at 2 bar and 0.6 % at 8 bar. The bound must stay well below the drops a fault
    produces: the paper's broken edge 1r (α ×2.5, +0.41 mm) is so open that p1 − p_r falls to
    8–10 bar while it carries the retracting flow (simulated with model/), so a 10 bar bound
    would throw away exactly the points that show the fault. Near Δp = 0 even the flow
    direction is unknown.

At least 500 points and 0.25 mm of u-coverage for a fit.
    Points are correlated over the 21-sample stencil, so 500 points are about 25 independent
    derivative estimates. α̂ and x̂ are separated by the slope of Â over u. The usable range
    is [underlap + 1 mm, x_max] ≈ 2.5 mm, but a too-open edge needs little spool stroke: on the
    simulated broken edge 1r of Table 2 the points cover only 1.04–1.45 mm, and still give
    α̂ = 2.50 ± 0.01, x̂ = 0.41 ± 0.006 mm (truth 2.5, 0.413 mm). A population narrower than
    0.25 mm (10 % of the usable range) is reported as ``too_little_coverage``.

Fit search |x̂| ≤ 1.5 mm (43 % of x_max).
    The paper's broken edge is at +0.41 mm (11.8 % x_max), its worn edge at +0.13 mm; the
    search range covers several times that. An optimum on the bound is reported as such.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from math import pi

from schemas.fields import EDGES

__all__ = ["EDGES", "MonitorParams"]


def _edge_tuple(value: Mapping[str, float] | Sequence[float], name: str) -> tuple[float, ...]:
    if isinstance(value, Mapping):
        missing = [e for e in EDGES if e not in value]
        extra = [k for k in value if k not in EDGES]
        if missing or extra:
            raise ValueError(f"{name}: needs exactly the edges {EDGES}, missing {missing}, unknown {extra}")
        return tuple(float(value[e]) for e in EDGES)
    out = tuple(float(v) for v in value)
    if len(out) != len(EDGES):
        raise ValueError(f"{name}: needs {len(EDGES)} values in the order {EDGES}, got {len(out)}")
    return out


@dataclass(frozen=True)
class MonitorParams:
    """Design data of one valve/cylinder (SI) and the settings of steps 2–4b.

    ``underlap_m`` may be given as a mapping ``{"s1": ..., "1r": ..., "s2": ..., "2r": ...}`` or
    as a 4-sequence in the order of :data:`EDGES`; it is stored as a tuple in that order.
    """

    piston_area_m2: float
    annulus_area_m2: float
    v01_m3: float
    v02_m3: float
    bulk_modulus_pa: float
    density_kg_m3: float
    underlap_m: tuple[float, float, float, float]
    x_max_m: float

    # step 2: windows and Savitzky–Golay
    sample_period_s: float | None = None
    """Nominal sample period; None = the median time step of the valve's data."""
    gap_limit_periods: float = 3.0
    window_s: float | None = None
    """Length of a monitoring window (a run at least half as long is cut at every multiple of it
    since the epoch, :mod:`transforms.windows`); None = a window is a whole run. The flows set
    it from the plant configuration (``[monitor] window_s``)."""
    step_tolerance: float = 0.1
    """Relative deviation of a time step from the sample period beyond which the SG stencil is cut."""
    window_rows: int | None = None
    """Rows of a window that steps 2–3 and Eq. 7 evaluate, at most about this many: a window of n
    samples is evaluated on every k-th row from its first, k = max(1, n // window_rows), each
    evaluated row the mean of the k rows it stands for (the Savitzky–Golay stencils convolved with
    a k-row box, the raw signals averaged alike: every sample's information is kept); a window whose thinned populations would fall short of
    twice a fit threshold is evaluated at every row (:data:`transforms.monitor.THIN_MARGIN`), and
    the thresholds count samples, k per point. None = every row. The flows set it from the plant
    configuration (``[monitor] window_rows``, default 6,000: a 60 s window at 1 kHz every 10th
    row, a 10 s snapshot every row; docs/monitoring.md, "Fewer points, not faster points")."""
    savgol_window: int = 21
    savgol_order: int = 3

    # step 3: selection
    standstill_velocity_m_s: float = 5e-3
    peak_dpdt_pa_s: float = 2e9
    compressibility_ratio_max: float = 0.5
    spool_margin_m: float = 1e-3
    min_dp_pa: float = 2e5

    # step 4a / 4b
    min_points: int = 500
    min_coverage_m: float = 0.25e-3
    x_hat_bound_m: float = 1.5e-3
    ci_level: float = 0.95
    max_knots: int = 12
    min_knot_spacing_m: float = 0.1e-3
    points_per_knot_interval: int = 200
    baseline_grid_m: float = 0.05e-3
    """Sampling step of a carrier-shaped step-4a characteristic (transforms.baseline)."""
    leakage_passes: int = 1
    """Refits with the closed edge's leakage rebuilt from its own estimate (0: its baseline state only)."""
    leak_min_points: int = 10_000
    """The closed-edge leakage is identified at commissioning only from at least this many points of
    the other edge (about 40 s of Table 1's moves; transforms.leakage): a single 10 s snapshot
    leaves λ's error (±0.2 … ±0.9, and biased) larger than what it corrects; with fewer, Eq. 3's
    leakage is kept (λ = 1, reported without an interval)."""
    leak_block_points: int = 50
    """λ at commissioning is fitted to the means of this many consecutive points' equations
    (transforms.baseline.leak_scale_lstsq; 50 ms at 1 kHz, two periods of the load's 20–25 Hz ringing): the ringing, where the Savitzky–Golay
    derivatives err by ~1 %, would otherwise alias into λ (−0.3 … −0.8 on s2's closed edge)."""
    leak_scale_prior_sd: float = 1.0
    """Prior standard deviation of the commissioning closed-edge leakage scale λ about Eq. 3's
    (λ = 1; transforms.leakage, transforms.monitor.commissioning_baseline; inf: the data alone)."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "underlap_m", _edge_tuple(self.underlap_m, "underlap_m"))
        if not (isinstance(self.leakage_passes, int) and self.leakage_passes >= 0):
            raise ValueError(f"leakage_passes must be an integer >= 0, got {self.leakage_passes}")
        for f in fields(self):
            if f.name in ("underlap_m", "leakage_passes"):
                continue
            v = getattr(self, f.name)
            if v is None:
                continue
            if isinstance(v, (int, float)) and not v > 0:
                raise ValueError(f"{f.name} must be > 0, got {v}")
        if self.annulus_area_m2 >= self.piston_area_m2:
            raise ValueError("annulus_area_m2 must be smaller than piston_area_m2")
        if self.savgol_window % 2 != 1 or self.savgol_window < 3:
            raise ValueError(f"savgol_window must be odd and >= 3, got {self.savgol_window}")
        if not 0 < self.savgol_order < self.savgol_window:
            raise ValueError("savgol_order must be in [1, savgol_window)")
        if any(abs(u) >= self.x_max_m for u in self.underlap_m):
            raise ValueError("underlaps must be smaller than x_max_m")
        if not 0 < self.ci_level < 1:
            raise ValueError("ci_level must be in (0, 1)")
        if self.step_tolerance >= 0.5:
            raise ValueError("step_tolerance must be < 0.5")

    @classmethod
    def from_design(
        cls,
        *,
        piston_diameter_m: float,
        rod_diameter_m: float,
        v01_m3: float,
        v02_m3: float,
        bulk_modulus_pa: float,
        density_kg_m3: float,
        underlap_m: Mapping[str, float] | Sequence[float],
        x_max_m: float,
        **settings: object,
    ) -> MonitorParams:
        """Build from diameters: A1 = π D²/4, A2 = A1 − π d²/4 (Eq. 5)."""
        a1 = pi * piston_diameter_m**2 / 4.0
        a2 = a1 - pi * rod_diameter_m**2 / 4.0
        return cls(
            piston_area_m2=a1,
            annulus_area_m2=a2,
            v01_m3=v01_m3,
            v02_m3=v02_m3,
            bulk_modulus_pa=bulk_modulus_pa,
            density_kg_m3=density_kg_m3,
            underlap_m=underlap_m,  # type: ignore[arg-type]
            x_max_m=x_max_m,
            **settings,  # type: ignore[arg-type]
        )

    @property
    def half_window(self) -> int:
        return self.savgol_window // 2

    def underlap(self, edge: str) -> float:
        return self.underlap_m[EDGES.index(edge)]

    def spool_limit_m(self, edge: str) -> float:
        """|x| must exceed this for the edge's points (model.md's rule plus the margin).

        Edges s1, 2r (x > 0) need x ≥ max(x_1r, x_s2) + margin; edges 1r, s2 (x < 0) need
        x ≤ −(max(x_s1, x_2r) + margin).
        """
        if edge in ("s1", "2r"):
            return max(self.underlap("1r"), self.underlap("s2")) + self.spool_margin_m
        if edge in ("1r", "s2"):
            return max(self.underlap("s1"), self.underlap("2r")) + self.spool_margin_m
        raise ValueError(f"unknown edge {edge!r}")

