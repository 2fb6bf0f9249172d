-- parameter_trends: the long-term trend of each parameter and where it meets its wear bounds.
-- One row per valve, edge, parameter and wear bound (side low or high).
--
-- Trend: ordinary least squares of the parameter over operating hours (regr_slope,
-- regr_intercept) on the ok windows without an alarm (window_alarms) of the last
-- trend_span_hours before the edge's latest ok window: all of them, however many a
-- continuous recording gives. Level: the median of those of them within change_history_hours
-- before the edge's latest ok window, or of the latest change_history_windows of them if those
-- reach further back; what "the long-term trend exceeds a bound" is judged on.
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

checks as (
    select * from fit_checks
),

alarms as (
    select valve_id, edge, window_start, is_alarm from window_alarms
),

bounds as (
    select * from stg_condition_bounds
),

latest as (
    select valve_id, edge, max(operating_hours) as latest_hours, max(window_start) as latest_start
    from stg_edge_fits
    where is_ok
    group by valve_id, edge
),

clean as (
    select checks.*
    from checks
    join alarms using (valve_id, edge, window_start)
    where not alarms.is_alarm
),

in_span as (
    select
        clean.valve_id, clean.edge, clean.parameter, clean.window_start, clean.operating_hours,
        clean.value, latest.latest_hours,
        row_number() over (
            partition by clean.valve_id, clean.edge, clean.parameter order by clean.window_start desc
        ) <= bounds.change_history_windows
            or clean.window_start > latest.latest_start
                                    - to_microseconds(cast(bounds.change_history_hours * 3600e6 as bigint)) as in_level
    from clean
    join latest using (valve_id, edge)
    join bounds using (valve_id, parameter)
    where clean.operating_hours >= latest.latest_hours - bounds.trend_span_hours
),

fitted as (
    select
        in_span.valve_id,
        in_span.edge,
        in_span.parameter,
        count(*) as n_fits,
        max(in_span.operating_hours) - min(in_span.operating_hours) as span_hours,
        any_value(in_span.latest_hours) as latest_hours,
        regr_slope(in_span.value, in_span.operating_hours) as slope_per_hour,
        regr_intercept(in_span.value, in_span.operating_hours) as intercept,
        regr_avgx(in_span.value, in_span.operating_hours) as mean_hours,
        regr_avgy(in_span.value, in_span.operating_hours) as mean_value,
        regr_sxx(in_span.value, in_span.operating_hours) as sxx,
        regr_syy(in_span.value, in_span.operating_hours) as syy,
        regr_sxy(in_span.value, in_span.operating_hours) as sxy,
        median(in_span.value) filter (where in_span.in_level) as level,
        count(*) filter (where in_span.in_level) as level_n
    from in_span
    group by in_span.valve_id, in_span.edge, in_span.parameter
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
