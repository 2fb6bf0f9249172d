-- open_edge_days: the open days of each valve and edge (from the valve's watermark on,
-- stg_summary_watermarks; every day of a valve without one), summarised as edge_day_summaries
-- keeps the closed ones: windows, ok windows, alarms, the day's latest window and latest ok
-- values, the day's closed-edge leakage (median, minimum, maximum).
-- One row per valve, edge and open UTC day with windows. flows/report/summaries.py writes its
-- rows of a day into edge_day_summaries when the day closes.
with

marks as (
    select * from stg_summary_watermarks
),

valves as (
    select valve_id from stg_condition_bounds where parameter = 'alpha_hat'
),

fits as (
    select stg_edge_fits.*
    from stg_edge_fits
    join valves using (valve_id)
    left join marks using (valve_id)
    where stg_edge_fits.window_start >= coalesce(marks.summarised_before, '-infinity'::timestamptz)
        and stg_edge_fits.window_start >= (select coalesce(min(summarised_before), '-infinity'::timestamptz) from marks)
),

alarms as (
    select valve_id, edge, cast(timezone('UTC', window_start) as date) as day_utc, count(*) as n_alarms
    from window_alarms
    where is_alarm
    group by all
),

days as (
    select
        valve_id,
        edge,
        cast(timezone('UTC', window_start) as date) as day_utc,
        max(baseline_version) as baseline_version,
        count(*) as n_windows,
        count(*) filter (where is_ok) as n_ok,
        max(window_start) as last_window_start,
        arg_max(status, window_start) as last_status,
        max(window_start) filter (where is_ok) as last_ok_window_start,
        max(operating_hours) filter (where is_ok) as last_ok_operating_hours,
        arg_max(alpha_hat, window_start) filter (where is_ok) as alpha_hat,
        max(window_start) filter (where is_ok and x_hat_determined) as x_hat_window_start,
        arg_max(x_hat_pct, window_start) filter (where is_ok and x_hat_determined) as x_hat_pct,
        arg_max(e_mm2, window_start) filter (where is_ok) as e_mm2,
        count(*) filter (where is_ok and leak_scale is not null) as leak_n,
        median(leak_scale) filter (where is_ok and leak_scale is not null) as leak_scale_median,
        min(leak_scale) filter (where is_ok and leak_scale is not null) as leak_scale_min,
        max(leak_scale) filter (where is_ok and leak_scale is not null) as leak_scale_max,
        max(operating_hours) filter (where is_ok and leak_scale is not null) as leak_operating_hours
    from fits
    group by all
),

final as (
    select
        days.valve_id, days.edge, days.day_utc, days.baseline_version,
        days.n_windows, days.n_ok, coalesce(alarms.n_alarms, 0) as n_alarms,
        days.* exclude (valve_id, edge, day_utc, baseline_version, n_windows, n_ok)
    from days
    left join alarms using (valve_id, edge, day_utc)
)

select * from final
