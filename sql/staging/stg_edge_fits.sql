-- stg_edge_fits: the fits of edge_fits against each valve's and edge's current baseline.
-- One row per valve, edge and monitoring window. A window fitted against an older baseline
-- version (design data or commissioning window changed since) is left out: its α̂ and x̂ are
-- relative to another characteristic. is_ok marks windows that gave all three estimates.
-- leak_scale (+ interval): the edge's closed-edge leakage in the window over Eq. 3's (0 = none);
-- null where the window could not resolve it (leak_scale_held: the commissioning's was held).
-- x_hat_determined: false where the window's points were too short a range of u to tell a shift
-- from a scale (u_spread_mm < 0.1 mm); its x_hat is not a trend or detector value.
-- Rows monitored before the column existed count as determined.
with

fits as (
    select * from edge_fits
),

current_baseline as (
    select valve_id, edge, max(baseline_version) as baseline_version
    from fits
    group by valve_id, edge
),

final as (
    select
        fits.valve_id,
        fits.edge,
        fits.window_start,
        fits.window_end,
        fits.operating_hours,
        fits.n_points,
        fits.alpha_hat,
        fits.x_hat_mm,
        fits.x_hat_pct,
        fits.e_mm2,
        fits.status,
        fits.baseline_version,
        case when fits.leak_scale_held then null else fits.leak_scale end as leak_scale,
        fits.leak_scale_ci_low,
        fits.leak_scale_ci_high,
        coalesce(fits.x_hat_determined, true) as x_hat_determined,
        coalesce(fits.leak_scale_held, false) as leak_scale_held,
        (fits.status = 'ok'
            and isfinite(fits.alpha_hat) and isfinite(fits.x_hat_pct) and isfinite(fits.e_mm2)) as is_ok
    from fits
    join current_baseline
        on fits.valve_id = current_baseline.valve_id
        and fits.edge = current_baseline.edge
        and fits.baseline_version is not distinct from current_baseline.baseline_version
)

select * from final
