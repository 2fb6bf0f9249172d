"""Settings of the model-discrepancy workflow (every value SI), with the reasons for the defaults.

The defaults are argued for the plant of Table 1 recorded at 1 kHz (pressure noise ~0.05 bar,
spool 1 µm, cylinder 1 µm); ``docs/discrepancy.md`` explains the method they belong to.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

__all__ = ["DiscrepancySettings"]


@dataclass(frozen=True)
class DiscrepancySettings:
    """How the discrepancy workflow cuts, smooths, segments, selects and replays.

    Attributes
    ----------
    sample_period_s : float | None
        Nominal sample period; None = the median time step of the data. [s]
    gap_limit_periods : float
        A time step longer than this many sample periods ends a record (as in monitoring).
    min_record_s, max_record_s : float
        Records (contiguous runs) shorter than ``min_record_s`` are skipped; longer ones are cut
        into pieces of ``max_record_s``. [s]
    max_records : int
        At most this many records are diagnosed (evenly spaced over the span).
    window_s : float | None
        Length of the monitoring windows (``[monitor] window_s``): a run of samples at least
        half as long (a continuous recording) is cut at every multiple of it since the epoch
        before it is cut into records (:func:`transforms.windows.window_starts`), so a record
        lies in one monitoring window; step 4 monitors with it. None: whole runs (snapshots are
        whole runs either way). [s]
    savgol_window, savgol_order : int
        Savitzky-Golay stencil for smoothed signals, v_X = dX/dt, a = d^2X/dt^2 and dp/dt
        (the monitoring's 21/3, ``transforms.params``).
    interval_samples : int
        Length L of the integration intervals of the residuals (20 samples = 20 ms): the chamber
        equations are integrated over each interval (no pressure derivative needed) and the
        motion equation over two (a second difference of X, no acceleration needed).
    interval_smoothing : int
        Every integrated residual term is averaged over this many shifts of its interval (odd;
        a boxcar, the same on every term), which averages the noise of the end samples
        (:mod:`transforms.discrepancy.residuals`). At most ``savgol_window``.
    v_move_m_s : float
        |v_X| above which the motion equation is used (2 v_0: the Stribeck excess has decayed to
        2 % of d_s - d_c). [m/s]
    v_load_m_s : float
        |v_X| above which the cylinder is taken not to stick, so the motion equation shows the
        load (2 mm/s: 50 x the velocity noise of the Savitzky-Golay derivative). [m/s]
    v_standstill_m_s : float
        |v_X| below which a sample counts as standstill for the regions and the replay's
        restarts (monitoring's 5 mm/s). [m/s]
    step_half_width : int
        Half-width w (samples) of the load-step detector: a jump of the load estimate between
        two straight-and-curved fits over w samples on either side.
    step_threshold_n : float
        Smallest load step the detector reports. [N]
    step_threshold_sigmas : float
        ... and at least this many robust standard deviations of the detector output.
    step_guard_samples : int
        Samples on either side of a detected load step left out of the motion equation.
    load_knot_s : float
        Knot spacing of the piecewise-linear load where the load ramps within segments
        (:mod:`transforms.discrepancy.load`, step 3): a rolling force reaches a new level over
        0.1–0.4 s. [s]
    corner_half_width_s : float
        Half-width of the filter that finds the ramps' corners: the slope change between a
        straight line and one bent at the sample, fitted over ±this
        (:func:`transforms.discrepancy.load.ramp_load`). [s]
    corner_min_n_s, corner_sigmas : float
        A corner is a slope change of the load of at least ``corner_min_n_s`` and
        ``corner_sigmas`` robust σ of that filter's output. [N/s], [–]
    corner_coarse_factor : float
        The corners the fit missed are looked for once more with the filter this many times wider
        (±0.15 s) and the floor ``corner_min_n_s`` / factor^1.5 (its noise falls as width^-1.5):
        a gentle ramp of a few hundred newtons over 0.3 s. [–]
    ramp_ratio, ramp_min_n : float
        The piecewise-linear load is used where it leaves at most 1/``ramp_ratio`` of the
        residual RMS of one constant per segment, and that RMS is above ``ramp_min_n`` (about 3×
        the force balance's noise, ~40 N at 0.05 bar: a rolling force that moves a few hundred
        newtons within a segment leaves 145–220 N); both RMS taken above the noise the recorded
        X's white noise leaves in the balance. [–], [N]
    corner_ratio : float
        Where the 0.1 s grid does not pass ``ramp_ratio``, the load on the ramps' corners is still
        used where it leaves at most 1/this of the residual RMS of one constant per segment
        (both with the motion columns, on the samples at speed;
        :func:`transforms.discrepancy.load.corners_pay`): one ramp at the start of a move (a
        260 N ramp over 0.5 s: 1.8). [–]
    knot_insertions, knot_rss_share, knot_velocity_corr2 : int, float, float
        After the corner filters, up to ``knot_insertions`` more knots, one at a time: the one
        that takes most of the joint fit's residual, kept if that is at least ``knot_rss_share``
        of the residual's slow part (its mean over the triangle's 2L + 1 samples, where the force
        balance's noise has little power), and only where the knot's tent function, apart from
        the other load columns and the acceleration, shares at most ``knot_velocity_corr2``
        (squared correlation) with v_X, so that a knot does not trade with the friction
        (:func:`transforms.discrepancy.load.missed_knot`). They shape the load the replays
        integrate, not the one the regression eliminates: a corner the filters miss or misplace,
        such as the end of an 8 kN ramp (the filters 0.16 s early). [–], [–], [–]
    replay_segment_s : float
        The replay restarts from the measured state every this many seconds (multiple
        shooting), so a small flow error cannot make the position drift over a whole record. [s]
    mechanical_segment_s : float
        The mechanical replay (X on the recorded pressures) restarts from the measured state
        every this many seconds: it integrates the force twice, open loop, so a force error of
        100 N moves X by ~2 µm over 0.5 s at Table 1's mass but by ~50 mm over 2.5 s. [s]
    mechanical_friction_rel : float
        The mechanical replay moves the model's viscous friction by what the load estimate leaves
        of the force balance along v_X, by at most this fraction of it
        (:func:`transforms.discrepancy.load.motion_mismatch`): a calibrated d_v 0.4–0.75 % off
        put X 0.09–0.17 mm off on the reference plant (floor ~0.011 mm), while a friction change
        of the library's typical 20 % still shows. A piecewise-linear load takes the excess
        where its knots follow v_X, up to ``load_friction_rel`` of d_v
        (:func:`transforms.discrepancy.load.friction_within`). [–]
    load_friction_rel : float
        Of a friction mismatch beyond ``mechanical_friction_rel``, the most a piecewise-linear
        load takes along the part of v_X its knots follow, as a fraction of d_v: the clean
        reference valves' joint fits gave the velocity column up to 2.6 % (a long slow move whose
        speed is nearly linear between the knots), while a friction change of the library's
        typical 20 % must keep most of itself in the force balance (moved into the load whole,
        its mechanical gap before fell from 4.5 mm to 0.3 mm on seed 2 with commissioning). [–]
    mechanical_mass_rel : float
        The mechanical replay moves the model's mass by what the load estimate leaves of the
        force balance along the acceleration, by at most this fraction of it, and not at all
        beyond twice it (``rows.tapered``; the weight stays as the load estimate took it): with a
        new load level every second, commissioning calibrations of the reference plant put the
        mass 2.1–2.8 % low, the diagnosed windows' fits found 11–108 kg of it, and on seed 5 X
        was replayed 2.8× its floor without this, 1.4× with it; a mass change of the library's
        typical 10 % stays whole in the mechanical gap. [–]
    block_s : float
        Length of the cross-validation blocks. [s]
    max_effects : int
        At most this many effects are named.
    min_t_stat : float
        A candidate is significant only if its cross-validated improvement, paired over blocks,
        has at least this t statistic ...
    min_relative_gain : float
        ... reduces the cross-validated residual sum of squares by at least this fraction ...
    min_z : float
        ... and its parameter is at least this many (jackknife) standard errors from neutral.
    ci_level : float
        Level of the parameter intervals.
    gauss_newton_iterations : int
        Refinement iterations of a named effect's parameter on the exact (non-linearised)
        residuals.
    reconstruct_spool, reconstruct_cylinder : bool
        Reconstruct the spool position from the recorded reference, the cylinder's X, v_X, a_X
        with a smoother, before anything else (:mod:`transforms.discrepancy.states`); off (the
        default): their Savitzky–Golay values. The spool alone (``valvemon discrepancy
        --reconstruct-spool``) reads the reference plant's valves at the noisy end of plant
        sensors better and at 1 µm worse; the cylinder as well reads worse at both
        (docs/discrepancy.md, "Positions as plants record them").
    spool_offset_s : float
        The recorded spool position's offset from Eq. 1's response to the reference is smoothed
        over this long. [s]
    """

    sample_period_s: float | None = None
    gap_limit_periods: float = 3.0
    min_record_s: float = 2.0
    max_record_s: float = 30.0
    max_records: int = 48
    window_s: float | None = None
    savgol_window: int = 21
    savgol_order: int = 3
    interval_samples: int = 20
    interval_smoothing: int = 21
    v_move_m_s: float = 0.03
    v_load_m_s: float = 2e-3
    v_standstill_m_s: float = 5e-3
    step_half_width: int = 40
    step_threshold_n: float = 400.0
    step_threshold_sigmas: float = 8.0
    step_guard_samples: int = 40
    load_knot_s: float = 0.1
    corner_half_width_s: float = 0.05
    corner_min_n_s: float = 3000.0
    corner_sigmas: float = 4.0
    corner_coarse_factor: float = 3.0
    ramp_ratio: float = 3.0
    ramp_min_n: float = 120.0
    corner_ratio: float = 1.5
    knot_insertions: int = 3
    knot_rss_share: float = 0.15
    knot_velocity_corr2: float = 0.05
    replay_segment_s: float = 2.5
    mechanical_segment_s: float = 0.5
    mechanical_friction_rel: float = 0.01
    load_friction_rel: float = 0.03
    mechanical_mass_rel: float = 0.02
    block_s: float = 1.0
    max_effects: int = 3
    min_t_stat: float = 4.0
    min_relative_gain: float = 0.02
    min_z: float = 5.0
    ci_level: float = 0.95
    gauss_newton_iterations: int = 6
    reconstruct_spool: bool = False
    reconstruct_cylinder: bool = False
    spool_offset_s: float = 1.0

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if v is None or isinstance(v, bool):
                continue
            if not v > 0:
                raise ValueError(f"{f.name} must be > 0, got {v}")
        if self.savgol_window % 2 != 1 or self.savgol_window < 5:
            raise ValueError("savgol_window must be odd and >= 5")
        if not 2 <= self.savgol_order < self.savgol_window:
            raise ValueError("savgol_order must be in [2, savgol_window)")
        if not 0 < self.ci_level < 1:
            raise ValueError("ci_level must be in (0, 1)")
        if self.interval_smoothing % 2 != 1 or self.interval_smoothing > self.savgol_window:
            raise ValueError("interval_smoothing must be odd and at most savgol_window")
        if self.min_record_s > self.max_record_s:
            raise ValueError("min_record_s must not exceed max_record_s")
