-- window_alarms: the short-term verdict per ok window (all three parameters together).
-- One row per valve, edge and ok window; is_alarm when any parameter is beyond a fault bound
-- or departs significantly from its recent trend; reason lists which and by how much.
with

checks as (
    select * from fit_checks
),

described as (
    select
        *,
        case
            when beyond_fault_bound and change_alarm then
                printf('%s %.3g beyond fault bound and |z| = %.1f', parameter, value, abs(z))
            when beyond_fault_bound then
                printf('%s %.3g beyond fault bound [%s, %s]', parameter, value,
                       coalesce(printf('%.3g', fault_low), '-inf'), printf('%.3g', fault_high))
            when change_alarm then
                printf('%s %.3g departs from recent median %.3g (z = %.1f)', parameter, value, ref_median, z)
        end as message
    from checks
),

final as (
    select
        valve_id,
        edge,
        window_start,
        any_value(window_end) as window_end,
        any_value(operating_hours) as operating_hours,
        max(value) filter (where parameter = 'alpha_hat') as alpha_hat,
        max(value) filter (where parameter = 'x_hat_pct') as x_hat_pct,
        max(value) filter (where parameter = 'e_mm2') as e_mm2,
        max(z) filter (where parameter = 'alpha_hat') as alpha_z,
        max(z) filter (where parameter = 'x_hat_pct') as x_hat_pct_z,
        max(z) filter (where parameter = 'e_mm2') as e_mm2_z,
        bool_or(beyond_fault_bound) as beyond_fault_bound,
        bool_or(change_alarm) as change_alarm,
        bool_or(is_alarm) as is_alarm,
        string_agg(message, '; ' order by parameter) as reason
    from described
    group by valve_id, edge, window_start
)

select * from final
