-- fault_alarms: every window that raised a short-term alarm (step 5b), newest first.
-- One row per valve, edge and alarm window, with the three parameters, their robust z-scores
-- against the recent history and the reason.
with

alarms as (
    select * from window_alarms where is_alarm
),

final as (
    select
        valve_id, edge, window_start, window_end, operating_hours,
        alpha_hat, x_hat_pct, e_mm2, alpha_z, x_hat_pct_z, e_mm2_z,
        beyond_fault_bound, change_alarm, reason
    from alarms
)

select * from final order by window_start desc, valve_id, edge
