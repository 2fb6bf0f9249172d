-- threshold_breaches: every ok window whose parameter lies beyond one of its bounds.
-- One row per valve, edge, window, parameter and bound crossed (kind fault or wear, side low
-- or high). A single window beyond a wear bound is not yet "worn" (valve_condition judges the
-- long-term level); beyond a fault bound it is an alarm.
with

checks as (
    select * from fit_checks
),

crossed as (
    select valve_id, edge, window_start, operating_hours, parameter, value,
           'fault' as bound_kind, 'low' as bound_side, fault_low as bound_value
    from checks where value < fault_low
    union all
    select valve_id, edge, window_start, operating_hours, parameter, value, 'fault', 'high', fault_high
    from checks where value > fault_high
    union all
    select valve_id, edge, window_start, operating_hours, parameter, value, 'wear', 'low', wear_low
    from checks where value < wear_low
    union all
    select valve_id, edge, window_start, operating_hours, parameter, value, 'wear', 'high', wear_high
    from checks where value > wear_high
),

final as (
    select * from crossed
)

select * from final
