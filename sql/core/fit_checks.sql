-- fit_checks: step 5b short-term assessment of every open ok window and parameter: the windows
-- from the valve's watermark on (stg_summary_watermarks; every window of a valve without one).
-- The closed days' verdicts were computed by this view when they were summarised; their alarm
-- windows are in stg_alarm_windows. One row per valve, edge, open window and parameter.
--
-- Two independent tests:
--   * bounds: the value lies beyond the parameter's fault bounds (one window is enough);
--   * change: a robust z-score against the edge's own recent history,
--       z = (value - median) / max(IQR / 1.349, sigma_floor)
--     where the median and the interquartile range IQR (/ 1.349: the standard deviation of
--     normal scatter) are taken over the history: the previous ok windows that started within
--     change_history_hours before this one, or the previous change_history_windows ok windows
--     if those reach further back (this window excluded). So the history is on the clock (a day:
--     24 hourly snapshots, 1,440 one-minute windows of a continuous recording) and never
--     shorter than change_history_windows windows (sparse snapshots). |z| > change_z is a
--     significant departure from the recent trend (for e_mm2 only z > change_z: a larger error
--     means a changed shape, a smaller one does not). With fewer than change_min_history
--     previous windows z is null. The floor keeps a very quiet history from turning ordinary
--     scatter into alarms; slow wear moves the median along and raises no alarm.
--     (The IQR, not the MAD: DuckDB computes windowed quantiles over frames of varying length
--     with a sort tree, ~4x faster than its windowed MAD on 1,440-window histories.)
with

marks as (
    select * from stg_summary_watermarks
),

parameters as (
    -- the open windows and the history before them that the first of them is judged against
    select
        stg_fit_parameters.*,
        stg_fit_parameters.window_start >= coalesce(marks.summarised_before, '-infinity'::timestamptz) as is_open
    from stg_fit_parameters
    left join marks using (valve_id)
    where stg_fit_parameters.window_start >= coalesce(marks.raw_from, '-infinity'::timestamptz)
        -- a constant bound, so that the scan skips the closed history's row groups
        and stg_fit_parameters.window_start >= (select coalesce(min(raw_from), '-infinity'::timestamptz) from marks)
),

bounds as (
    select * from stg_condition_bounds
),

paired as (
    select
        parameters.*,
        bounds.fault_low, bounds.fault_high, bounds.wear_low, bounds.wear_high,
        bounds.sigma_floor, bounds.two_sided, bounds.change_z, bounds.change_min_history,
        bounds.change_history_windows,
        count(*) over (
            partition by parameters.valve_id, parameters.edge, parameters.parameter
            order by parameters.window_start
            range between to_microseconds(cast(bounds.change_history_hours * 3600e6 as bigint)) preceding and current row
        ) - 1 as n_in_hours
    from parameters
    join bounds using (valve_id, parameter)
),

history as (
    select
        paired.* exclude (n_in_hours, change_history_windows),
        quantile_cont(paired.value, [0.25, 0.5, 0.75]) over recent as ref_quartiles,
        count(paired.value) over recent as ref_n
    from paired
    window recent as (
        partition by paired.valve_id, paired.edge, paired.parameter
        order by paired.window_start
        rows between greatest(paired.n_in_hours, paired.change_history_windows) preceding and 1 preceding
    )
),

reference as (
    select
        * exclude (ref_quartiles),
        ref_quartiles[2] as ref_median,
        greatest((ref_quartiles[3] - ref_quartiles[1]) / 1.3489795003921634, sigma_floor) as ref_scale
    from history
),

scored as (
    select *, case when ref_n >= change_min_history then (value - ref_median) / ref_scale end as z
    from reference
),

final as (
    select
        valve_id, edge, window_start, window_end, operating_hours, parameter, value,
        ref_median, ref_scale, ref_n, z,
        fault_low, fault_high, wear_low, wear_high, change_z,
        coalesce(value < fault_low, false) or coalesce(value > fault_high, false) as beyond_fault_bound,
        coalesce(value < wear_low, false) or coalesce(value > wear_high, false) as beyond_wear_bound,
        coalesce(case when two_sided then abs(z) > change_z else z > change_z end, false) as change_alarm,
        (coalesce(value < fault_low, false) or coalesce(value > fault_high, false)
            or coalesce(case when two_sided then abs(z) > change_z else z > change_z end, false)) as is_alarm
    from scored
    where is_open
)

select * from final
