-- stg_fit_parameters: the three condition parameters of every ok window in long form.
-- One row per valve, edge, window and parameter: alpha_hat (relative, 1 = unchanged),
-- x_hat_pct (change of underlap in % of x_max, > 0 = more open; only where the window determined
-- it, x_hat_determined), e_mm2 (Eq. 8 error, mm²).
with

ok_fits as (
    select * from stg_edge_fits where is_ok
),

alpha as (
    select valve_id, edge, window_start, window_end, operating_hours,
           'alpha_hat' as parameter, alpha_hat as value
    from ok_fits
),

underlap as (
    select valve_id, edge, window_start, window_end, operating_hours,
           'x_hat_pct' as parameter, x_hat_pct as value
    from ok_fits
    where x_hat_determined
),

error as (
    select valve_id, edge, window_start, window_end, operating_hours,
           'e_mm2' as parameter, e_mm2 as value
    from ok_fits
),

final as (
    select * from alpha
    union all select * from underlap
    union all select * from error
)

select * from final
