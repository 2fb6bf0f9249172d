-- stg_standstill_checks: Eq. 9 at standstill per window (table standstill_checks, written
-- from the lake by `valvemon report`), with the deviation from the value the valve's design
-- gives at rest and the verdict against the configured tolerance.
with

checks as (
    select * from standstill_checks
),

bounds as (
    select valve_id, eq9_expected, eq9_tolerance from condition_bounds
),

final as (
    select
        checks.valve_id,
        checks.window_start,
        checks.window_end,
        checks.operating_hours,
        checks.n_samples,
        checks.ps_bar,
        checks.pr_bar,
        checks.p1_bar,
        checks.p2_bar,
        checks.x_spool_mm,
        checks.eq9_residual,
        bounds.eq9_expected,
        bounds.eq9_tolerance,
        checks.eq9_residual - bounds.eq9_expected as eq9_deviation,
        abs(checks.eq9_residual - bounds.eq9_expected) <= bounds.eq9_tolerance as eq9_ok
    from checks
    join bounds using (valve_id)
)

select * from final
