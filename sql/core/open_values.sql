-- open_values: the three parameters of every open ok window (from the valve's watermark on) in
-- long form, with the window's verdict (window_alarms): is_clean when it raised no alarm.
-- One row per valve, edge, open ok window and parameter (x_hat_pct only where determined).
with

verdicts as (
    select valve_id, edge, window_start, operating_hours, not is_alarm as is_clean, alpha_hat, x_hat_pct, e_mm2
    from window_alarms
),

final as (
    unpivot verdicts on alpha_hat, x_hat_pct, e_mm2 into name parameter value value
)

select * from final
