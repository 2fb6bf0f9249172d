-- trend_daily: the parameters over calendar time, one row per valve, edge, UTC day and
-- parameter: windows of the day, ok windows, alarms, median, minimum and maximum. The closed
-- days come from their summaries, the open ones are computed now (parameter_days, edge_days).
with

values_by_day as (
    select * exclude (last_window_start) from parameter_days
),

days as (
    select valve_id, edge, day_utc, n_windows, n_ok, n_alarms from edge_days
),

final as (
    select
        values_by_day.valve_id, values_by_day.edge, values_by_day.day_utc, values_by_day.parameter,
        days.n_windows, days.n_ok, days.n_alarms,
        values_by_day.median_value, values_by_day.min_value, values_by_day.max_value,
        values_by_day.operating_hours
    from values_by_day
    join days using (valve_id, edge, day_utc)
)

select * from final order by valve_id, edge, day_utc, parameter
