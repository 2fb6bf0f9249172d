-- open_parameter_days: the open days of each parameter (from the valve's watermark on), as
-- parameter_day_summaries keeps the closed ones: the day's median, minimum and maximum, and the
-- alarm-free windows' count, first and last operating hours, means and centred sums of squares
-- and products (regr_sxx, regr_syy, regr_sxy: what parameter_trends merges into its least
-- squares). The values and verdicts come from open_values. One row per valve, edge, open UTC day and parameter. flows/report/summaries.py
-- writes a day's rows into parameter_day_summaries when the day closes.
with

judged as (
    select *, cast(timezone('UTC', window_start) as date) as day_utc from open_values
),

final as (
    select
        valve_id, edge, day_utc, parameter,
        count(*) as n_values,
        median(value) as median_value,
        min(value) as min_value,
        max(value) as max_value,
        max(operating_hours) as operating_hours,
        max(window_start) as last_window_start,
        count(*) filter (where is_clean) as n_clean,
        min(operating_hours) filter (where is_clean) as clean_first_hours,
        max(operating_hours) filter (where is_clean) as clean_last_hours,
        avg(operating_hours) filter (where is_clean) as clean_mean_hours,
        avg(value) filter (where is_clean) as clean_mean_value,
        regr_sxx(value, operating_hours) filter (where is_clean) as clean_sxx,
        regr_syy(value, operating_hours) filter (where is_clean) as clean_syy,
        regr_sxy(value, operating_hours) filter (where is_clean) as clean_sxy
    from judged
    group by valve_id, edge, day_utc, parameter
)

select * from final
