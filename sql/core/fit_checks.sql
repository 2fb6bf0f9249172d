-- fit_checks: step 5b short-term assessment of every ok window and parameter.
-- One row per valve, edge, window and parameter.
--
-- Two independent tests:
--   * bounds: the value lies beyond the parameter's fault bounds (one window is enough);
--   * change: a robust z-score against the edge's own recent history,
--       z = (value - median) / max(1.4826 * MAD, sigma_floor)
--     where median and MAD (median absolute deviation) are taken over the previous
--     change_history_windows ok windows (this window excluded). |z| > change_z is a significant
--     departure from the recent trend (for e_mm2 only z > change_z: a larger error means a
--     changed shape, a smaller one does not). With fewer than change_min_history previous
--     windows z is null. The floor keeps a very quiet history from turning ordinary scatter
--     into alarms; slow wear moves the median along and raises no alarm.
with

parameters as (
    select * from stg_fit_parameters
),

bounds as (
    select * from stg_condition_bounds
),

history as (
    select
        parameters.*,
        bounds.fault_low, bounds.fault_high, bounds.wear_low, bounds.wear_high,
        bounds.sigma_floor, bounds.two_sided, bounds.change_z, bounds.change_min_history,
        median(parameters.value) over recent as ref_median,
        mad(parameters.value) over recent as ref_mad,
        count(parameters.value) over recent as ref_n
    from parameters
    join bounds using (valve_id, parameter)
    window recent as (
        partition by parameters.valve_id, parameters.edge, parameters.parameter
        order by parameters.window_start
        rows between bounds.change_history_windows preceding and 1 preceding
    )
),

scored as (
    select
        *,
        greatest(1.4826 * ref_mad, sigma_floor) as ref_scale,
        case when ref_n >= change_min_history
             then (value - ref_median) / greatest(1.4826 * ref_mad, sigma_floor) end as z
    from history
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
)

select * from final
