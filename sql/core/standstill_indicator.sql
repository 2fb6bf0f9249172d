-- standstill_indicator: the Eq. 9 quick check per valve, independent of the fits.
-- One row per valve that has standstill windows: the latest window's residual against the
-- value the design gives at rest (eq9_expected ± eq9_tolerance), the valve's own early
-- reference (median of its first five standstill windows) and how many windows failed in the
-- last fault_hold_hours.
with

checks as (
    select * from stg_standstill_checks
),

hold as (
    select distinct valve_id, fault_hold_hours from stg_condition_bounds
),

numbered as (
    select
        *,
        row_number() over (partition by valve_id order by window_start) as seq,
        max(operating_hours) over (partition by valve_id) as latest_hours
    from checks
),

final as (
    select
        numbered.valve_id,
        count(*) as n_windows,
        max(numbered.window_start) as last_window_start,
        arg_max(numbered.eq9_residual, numbered.window_start) as eq9_residual,
        any_value(numbered.eq9_expected) as eq9_expected,
        any_value(numbered.eq9_tolerance) as eq9_tolerance,
        arg_max(numbered.eq9_deviation, numbered.window_start) as eq9_deviation,
        arg_max(numbered.eq9_ok, numbered.window_start) as eq9_ok,
        median(numbered.eq9_residual) filter (where numbered.seq <= 5) as eq9_own_reference,
        arg_max(numbered.eq9_residual, numbered.window_start)
            - median(numbered.eq9_residual) filter (where numbered.seq <= 5) as eq9_drift,
        count(*) filter (where not numbered.eq9_ok
                         and numbered.operating_hours >= numbered.latest_hours - hold.fault_hold_hours) as n_recent_failures,
        arg_max(numbered.p1_bar, numbered.window_start) as p1_bar,
        arg_max(numbered.p2_bar, numbered.window_start) as p2_bar,
        arg_max(numbered.ps_bar, numbered.window_start) as ps_bar
    from numbered
    join hold using (valve_id)
    group by numbered.valve_id
)

select * from final
