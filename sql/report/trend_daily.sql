-- trend_daily: the parameters over calendar time, one row per valve, edge, UTC day and
-- parameter: windows of the day, ok windows, alarms, median, minimum and maximum.
with

fits as (
    select * from stg_edge_fits
),

days as (
    select
        valve_id, edge, cast(timezone('UTC', window_start) as date) as day_utc,
        count(*) as n_windows, count(*) filter (where is_ok) as n_ok
    from fits
    group by all
),

alarms as (
    select
        valve_id, edge, cast(timezone('UTC', window_start) as date) as day_utc,
        count(*) filter (where is_alarm) as n_alarms
    from window_alarms
    group by all
),

values_by_day as (
    select
        valve_id, edge, cast(timezone('UTC', window_start) as date) as day_utc, parameter,
        median(value) as median_value, min(value) as min_value, max(value) as max_value,
        max(operating_hours) as operating_hours
    from stg_fit_parameters
    group by all
),

final as (
    select
        values_by_day.valve_id, values_by_day.edge, values_by_day.day_utc, values_by_day.parameter,
        days.n_windows, days.n_ok, coalesce(alarms.n_alarms, 0) as n_alarms,
        values_by_day.median_value, values_by_day.min_value, values_by_day.max_value,
        values_by_day.operating_hours
    from values_by_day
    join days using (valve_id, edge, day_utc)
    left join alarms using (valve_id, edge, day_utc)
)

select * from final order by valve_id, edge, day_utc, parameter
