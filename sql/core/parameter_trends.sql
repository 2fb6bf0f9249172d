-- parameter_trends: the long-term trend of each parameter and where it meets its wear bounds.
-- One row per valve, edge, parameter and wear bound (side low or high).
--
-- Trend: ordinary least squares of the parameter over operating hours on the ok windows without
-- an alarm of the UTC days within trend_span_hours of the edge's latest ok window (the days whose
-- latest alarm-free window lies within it: the span counted in whole days): all of them, however
-- many a continuous recording gives. The sums come a day at a time (parameter_days: count, means,
-- centred sums of squares and products of the alarm-free windows of the day), merged exactly:
-- Sxx = sum(Sxx_day + n_day (mean_day - mean)^2), and so on; slope Sxy / Sxx, intercept
-- mean_value - slope mean_hours. Level: the median of the alarm-free ok windows within
-- change_history_hours before the edge's latest ok window, or of the latest change_history_windows
-- of them if those reach further back, whatever trend_span_hours is (a span shorter than those
-- windows does not thin the level); what "the long-term trend exceeds a bound" is judged on.
-- The level's windows are read raw: the open ones (open_values) and the closed ones
-- from the valve's raw_from on (stg_summary_watermarks; its alarms in stg_alarm_windows).
--
-- End of life: the hour at which the trend line reaches the bound, mean_hours + (bound -
-- mean_value) / slope, with its 95 % confidence interval by Fieller's theorem: the hours x at
-- which the bound lies inside the confidence band of the line, i.e. the roots of
--     (b d - c)^2 = t^2 s^2 (1/n + d^2 / Sxx),  d = x - mean_hours,  c = bound - mean_value,
-- with b the slope, s^2 the residual variance (n - 2 degrees of freedom) and t the 97.5 %
-- quantile of Student's t (Cornish-Fisher expansion, within 0.1 % for df >= 3). The interval
-- is bounded when the slope is significant at 5 % (b^2 > t^2 s^2 / Sxx); otherwise, or when
-- the slope points away from the bound, no end of life is predicted.
-- crossing_status: predicted | away_from_bound | not_significant | too_little_data.
with

days as (
    select * from parameter_days
),

bounds as (
    select * from stg_condition_bounds
),

marks as (
    select * from stg_summary_watermarks
),

latest as (
    -- the edge's latest ok window: every ok window has an alpha_hat
    select valve_id, edge, max(operating_hours) as latest_hours, max(last_window_start) as latest_start
    from days
    where parameter = 'alpha_hat'
    group by valve_id, edge
),

span_days as (
    select days.*, latest.latest_hours
    from days
    join latest using (valve_id, edge)
    join bounds using (valve_id, parameter)
    where days.n_clean > 0 and days.clean_last_hours >= latest.latest_hours - bounds.trend_span_hours
),

pool_reference as (
    -- one day's means as the reference the others are pooled relative to: exact for a constant parameter
    select valve_id, edge, parameter, min(clean_mean_hours) as ref_hours, min(clean_mean_value) as ref_value
    from span_days
    group by valve_id, edge, parameter
),

pooled as (
    select
        valve_id, edge, parameter,
        sum(n_clean) as n_fits,
        max(clean_last_hours) - min(clean_first_hours) as span_hours,
        any_value(latest_hours) as latest_hours,
        any_value(ref_hours) + sum(n_clean * (clean_mean_hours - ref_hours)) / sum(n_clean) as mean_hours,
        any_value(ref_value) + sum(n_clean * (clean_mean_value - ref_value)) / sum(n_clean) as mean_value
    from span_days
    join pool_reference using (valve_id, edge, parameter)
    group by valve_id, edge, parameter
),

merged as (
    select
        pooled.*,
        sum(span_days.clean_sxx + span_days.n_clean * (span_days.clean_mean_hours - pooled.mean_hours) ** 2) as sxx,
        -- a parameter constant over the span has no variance: exactly, not the day means' round-off
        case when min(span_days.min_value) < max(span_days.max_value) then
            sum(span_days.clean_syy + span_days.n_clean * (span_days.clean_mean_value - pooled.mean_value) ** 2) else 0 end as syy,
        case when min(span_days.min_value) < max(span_days.max_value) then
            sum(span_days.clean_sxy + span_days.n_clean * (span_days.clean_mean_hours - pooled.mean_hours)
                                                       * (span_days.clean_mean_value - pooled.mean_value)) else 0 end as sxy
    from pooled
    join span_days using (valve_id, edge, parameter)
    group by all
),

closed_recent as (
    -- the closed alarm-free windows from raw_from on (the constant bound lets the scan skip older row groups)
    select stg_fit_parameters.valve_id, stg_fit_parameters.edge, stg_fit_parameters.parameter,
           stg_fit_parameters.window_start, stg_fit_parameters.value
    from stg_fit_parameters
    join marks using (valve_id)
    anti join stg_alarm_windows using (valve_id, edge, window_start)
    where stg_fit_parameters.window_start >= marks.raw_from
        and stg_fit_parameters.window_start < marks.summarised_before
        and stg_fit_parameters.window_start >= (select coalesce(min(raw_from), 'infinity'::timestamptz) from marks)
),

open_recent as (
    select valve_id, edge, parameter, window_start, value from open_values where is_clean
),

recent as (
    select * from closed_recent
    union all
    select * from open_recent
),

level_windows as (
    select
        recent.valve_id, recent.edge, recent.parameter, recent.value,
        row_number() over (
            partition by recent.valve_id, recent.edge, recent.parameter order by recent.window_start desc
        ) <= bounds.change_history_windows
            or recent.window_start > latest.latest_start
                                     - to_microseconds(cast(bounds.change_history_hours * 3600e6 as bigint)) as in_level
    from recent
    join latest using (valve_id, edge)
    join bounds using (valve_id, parameter)
    where recent.window_start <= latest.latest_start
),

levels as (
    select
        valve_id, edge, parameter,
        median(value) filter (where in_level) as level,
        count(*) filter (where in_level) as level_n
    from level_windows
    group by valve_id, edge, parameter
),

fitted as (
    select
        merged.valve_id, merged.edge, merged.parameter, merged.n_fits, merged.span_hours, merged.latest_hours,
        case when merged.sxx > 0 then merged.sxy / merged.sxx end as slope_per_hour,
        case when merged.sxx > 0 then merged.mean_value - merged.sxy / merged.sxx * merged.mean_hours end as intercept,
        merged.mean_hours, merged.mean_value, merged.sxx, merged.syy, merged.sxy,
        levels.level, coalesce(levels.level_n, 0) as level_n
    from merged
    left join levels using (valve_id, edge, parameter)
),

stats as (
    select
        fitted.*,
        bounds.wear_low,
        bounds.wear_high,
        bounds.trend_min_fits,
        bounds.trend_min_span_hours,
        bounds.change_min_history,
        case when n_fits > 2 and sxx > 0
             then greatest(syy - sxy * sxy / sxx, 0) / (n_fits - 2) end as resid_var,
        case when n_fits > 2
             then 1.959963984540054 + 2.372271230298562 / (n_fits - 2)
                  + 2.8224986157396112 / pow(n_fits - 2, 2) + 2.555849679507722 / pow(n_fits - 2, 3)
                  + 1.5895340533938225 / pow(n_fits - 2, 4) end as t_quantile,
        n_fits >= bounds.trend_min_fits
            and span_hours >= bounds.trend_min_span_hours and sxx > 0 as enough_data
    from fitted
    join bounds using (valve_id, parameter)
),

sides as (
    select stats.*, 'high' as side, wear_high as bound from stats where wear_high is not null
    union all
    select stats.*, 'low' as side, wear_low as bound from stats where wear_low is not null
),

fieller as (
    select
        *,
        bound - mean_value as c,
        resid_var / sxx as slope_var,
        slope_per_hour * slope_per_hour - t_quantile * t_quantile * resid_var / sxx as g
    from sides
),

roots as (
    select
        *,
        case
            when not enough_data then 'too_little_data'
            when (side = 'high' and slope_per_hour <= 0) or (side = 'low' and slope_per_hour >= 0) then 'away_from_bound'
            when g <= 0 then 'not_significant'
            else 'predicted'
        end as crossing_status,
        sqrt(greatest(t_quantile * t_quantile * (c * c * slope_var + g * resid_var / n_fits), 0)) as root_half
    from fieller
),

final as (
    select
        valve_id, edge, parameter, side, bound,
        n_fits, span_hours, latest_hours, slope_per_hour, intercept, mean_hours, mean_value,
        sqrt(resid_var) as resid_sd, sqrt(slope_var) as slope_se, t_quantile,
        level, level_n, change_min_history,
        level_n >= change_min_history
            and ((side = 'high' and level > bound) or (side = 'low' and level < bound)) as level_beyond_bound,
        crossing_status,
        case when crossing_status = 'predicted' then mean_hours + c / slope_per_hour end as end_of_life_hours,
        case when crossing_status = 'predicted'
             then mean_hours + least((slope_per_hour * c - root_half) / g, (slope_per_hour * c + root_half) / g) end as end_of_life_hours_low,
        case when crossing_status = 'predicted'
             then mean_hours + greatest((slope_per_hour * c - root_half) / g, (slope_per_hour * c + root_half) / g) end as end_of_life_hours_high,
        case when crossing_status = 'predicted'
             then greatest(mean_hours + c / slope_per_hour - latest_hours, 0) end as remaining_hours,
        case when crossing_status = 'predicted'
             then greatest(mean_hours + least((slope_per_hour * c - root_half) / g, (slope_per_hour * c + root_half) / g) - latest_hours, 0) end as remaining_hours_low,
        case when crossing_status = 'predicted'
             then greatest(mean_hours + greatest((slope_per_hour * c - root_half) / g, (slope_per_hour * c + root_half) / g) - latest_hours, 0) end as remaining_hours_high
    from roots
)

select * from final
