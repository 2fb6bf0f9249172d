-- fault_alarms: every window that raised a short-term alarm (step 5b), newest first: those of
-- the closed days as they were judged when summarised (stg_alarm_windows), those of the open
-- days judged now (window_alarms). One row per valve, edge and alarm window, with the three
-- parameters, their robust z-scores against the recent history and the reason.
with

closed as (
    select * from stg_alarm_windows
),

open as (
    select * exclude (is_alarm) from window_alarms where is_alarm
),

alarms as (
    select * from open
    union all by name
    select * from closed
),

final as (
    select
        valve_id, edge, window_start, window_end, operating_hours,
        alpha_hat, x_hat_pct, e_mm2, alpha_z, x_hat_pct_z, e_mm2_z,
        beyond_fault_bound, change_alarm, reason
    from alarms
)

select * from final order by window_start desc, valve_id, edge
