-- stg_condition_bounds: each valve's bounds (table condition_bounds, written from the plant
-- configuration's [valve_types.NAME.bounds] by `valvemon report`) in long form.
-- One row per valve and parameter; e_mm2 has upper bounds only (an error cannot be "too good").
with

bounds as (
    select * from condition_bounds
),

settings as (
    select
        valve_id, change_z, change_history_hours, change_history_windows, change_min_history, fault_hold_hours,
        trend_min_fits, trend_min_span_hours, trend_span_hours
    from bounds
),

per_parameter as (
    select valve_id, 'alpha_hat' as parameter,
           alpha_fault_low as fault_low, alpha_fault_high as fault_high,
           alpha_wear_low as wear_low, alpha_wear_high as wear_high,
           alpha_sigma_floor as sigma_floor, true as two_sided
    from bounds
    union all
    select valve_id, 'x_hat_pct',
           x_hat_pct_fault_low, x_hat_pct_fault_high,
           x_hat_pct_wear_low, x_hat_pct_wear_high,
           x_hat_pct_sigma_floor, true
    from bounds
    union all
    select valve_id, 'e_mm2',
           null::double, e_mm2_fault_high,
           null::double, e_mm2_wear_high,
           e_mm2_sigma_floor, false
    from bounds
),

final as (
    select per_parameter.*, settings.* exclude (valve_id)
    from per_parameter
    join settings using (valve_id)
)

select * from final
