-- trend_operating_hours: each parameter over operating hours, with what the pictures draw.
-- One row per valve, edge, ok window and parameter: the value, the rolling median of the
-- previous windows, the fitted trend line (parameter_trends), the wear and fault bounds and
-- whether the window raised an alarm.
with

checks as (
    select * from fit_checks
),

alarms as (
    select valve_id, edge, window_start, is_alarm from window_alarms
),

lines as (
    select distinct on (valve_id, edge, parameter)
        valve_id, edge, parameter, slope_per_hour, intercept, n_fits
    from parameter_trends
    order by valve_id, edge, parameter
),

final as (
    select
        checks.valve_id,
        checks.edge,
        checks.parameter,
        checks.window_start,
        checks.operating_hours,
        checks.value,
        checks.ref_median as rolling_median,
        checks.z,
        lines.intercept + lines.slope_per_hour * checks.operating_hours as trend_value,
        checks.wear_low,
        checks.wear_high,
        checks.fault_low,
        checks.fault_high,
        alarms.is_alarm
    from checks
    join alarms using (valve_id, edge, window_start)
    left join lines using (valve_id, edge, parameter)
)

select * from final order by valve_id, edge, parameter, window_start
