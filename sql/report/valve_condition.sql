-- valve_condition: the latest verdict per valve and edge (interfaces.md).
-- One row per configured valve (stg_condition_bounds) and edge s1, 1r, s2, 2r.
--
-- state:
--   faulty   an alarm (fault bound or significant departure from the recent trend, see
--            window_alarms) in the last fault_hold_hours before the edge's latest ok window;
--   worn     otherwise, the long-term level of a parameter (parameter_trends.level, median of
--            the latest alarm-free windows) lies beyond a wear bound;
--   unknown  otherwise, fewer than trend_min_fits ok, alarm-free windows in the trend span
--            (or no fits at all);
--   healthy  otherwise.
-- Remaining life, the one rule every other view, picture and export reads (fleet_ranking takes
-- its worst edge's row; docs/monitoring.md, "Remaining life"). remaining_basis says what the
-- figures rest on:
--   faulty          remaining_hours (and _low, _high) 0: replace now;
--   worn            0 as well: the long-term level is beyond a wear bound;
--   forecast        healthy, and the soonest predicted crossing of a wear bound by a parameter's
--                   trend (parameter_trends: significant slope, bounded 95 % interval) lies
--                   within the horizon, horizon_spans times the span of operating hours the trend
--                   was fitted on (remaining_horizon_hours); _high is null where the interval
--                   reaches beyond the horizon;
--   beyond_horizon  healthy, a trend heads for a bound but reaches it only beyond the horizon:
--                   no figure (a linear extrapolation that far is no forecast), null;
--   no_trend        healthy, no trend heads significantly toward a bound: null;
--   too_little_data unknown: null.
-- leak_scale: the edge's closed-edge leakage over Eq. 3's, median over the ok windows that resolved it
-- (null where none did: edge_fits.leak_scale_held, the report says undetermined) of the
-- latest UTC day that has one (a growing leakage is a wear signal; the trend picture shows it a
-- point a day), leak_scale_baseline
-- the commissioning value (1 for a nominal baseline: Eq. 3 assumed).
-- edge_law: the edge law the baseline's shape follows; where the commissioning window shows
-- another than the configured area_law, edge_law_note says so and is appended to the reason.
-- first_alarm_start, last_alarm_start: the earliest and the latest of those recent alarm windows
-- (null when there are none): where a fault began (condition_changes names it).
-- The Eq. 9 standstill check (standstill_indicator) is a valve-wide quick indicator: its
-- result is appended to the reason and given in eq9_ok, it does not change an edge's state.
with

settings as (
    -- the horizon of a forecast in spans of the data behind it (chosen from the wear study:
    -- docs/monitoring.md, "Remaining life: the forecast horizon")
    select 3.0 as horizon_spans
),

valves as (
    select distinct valve_id, fault_hold_hours, trend_min_fits from stg_condition_bounds
),

edges as (
    select * from (values ('s1', 1), ('1r', 2), ('s2', 3), ('2r', 4)) as e(edge, edge_order)
),

grid as (
    select valves.*, edges.edge, edges.edge_order from valves cross join edges
),

days as (
    select * from edge_days
),

windows as (
    select
        valve_id, edge,
        sum(n_windows) as n_windows,
        sum(n_ok) as n_ok_windows,
        max(last_window_start) as last_window_start,
        arg_max(last_status, last_window_start) as last_status,
        max(last_ok_window_start) as last_ok_window_start,
        max(last_ok_operating_hours) as operating_hours,
        arg_max(alpha_hat, last_ok_window_start) filter (where last_ok_window_start is not null) as alpha_hat,
        arg_max(x_hat_pct, x_hat_window_start) filter (where x_hat_window_start is not null) as x_hat_pct,
        arg_max(e_mm2, last_ok_window_start) filter (where last_ok_window_start is not null) as e_mm2,
        arg_max(leak_scale_median, day_utc) filter (where leak_n > 0) as leak_scale
    from days
    group by valve_id, edge
),

recent_alarms as (
    select
        fault_alarms.valve_id, fault_alarms.edge,
        count(*) as n_recent_alarms,
        arg_max(fault_alarms.reason, fault_alarms.window_start) as last_alarm_reason,
        min(fault_alarms.window_start) as first_alarm_start,
        max(fault_alarms.window_start) as last_alarm_start
    from fault_alarms
    join windows using (valve_id, edge)
    join valves using (valve_id)
    where fault_alarms.operating_hours >= windows.operating_hours - valves.fault_hold_hours
    group by fault_alarms.valve_id, fault_alarms.edge
),

trends as (
    select * from parameter_trends
),

levels as (
    select
        valve_id, edge,
        max(n_fits) as n_trend_fits,
        max(level) filter (where parameter = 'alpha_hat') as alpha_level,
        max(level) filter (where parameter = 'x_hat_pct') as x_hat_pct_level,
        max(level) filter (where parameter = 'e_mm2') as e_mm2_level,
        string_agg(
            printf('%s level %.3g %s wear bound %.3g', parameter, level,
                   case when side = 'high' then 'above' else 'below' end, bound),
            '; ' order by parameter, side) filter (where level_beyond_bound) as wear_reason
    from trends
    group by valve_id, edge
),

soonest as (
    select
        valve_id, edge,
        arg_min(parameter, remaining_hours) as limiting_parameter,
        arg_min(side, remaining_hours) as limiting_side,
        arg_min(bound, remaining_hours) as limiting_bound,
        min(remaining_hours) as remaining_hours,
        arg_min(remaining_hours_low, remaining_hours) as remaining_hours_low,
        arg_min(remaining_hours_high, remaining_hours) as remaining_hours_high,
        arg_min(end_of_life_hours, remaining_hours) as end_of_life_hours
    from trends
    where crossing_status = 'predicted'
    group by valve_id, edge
),

horizon as (
    select valve_id, edge, settings.horizon_spans * max(span_hours) as remaining_horizon_hours
    from trends cross join settings
    where span_hours > 0
    group by valve_id, edge, settings.horizon_spans
),

standstill as (
    select * from standstill_indicator
),

baseline_leak as (
    -- the commissioning (or nominal: 1) leakage of each edge's current baseline version
    select
        valve_id, edge,
        arg_max(leak_scale, version) as leak_scale,
        arg_max(edge_law, version) as edge_law,
        arg_max(edge_law_note, version) as edge_law_note
    from baselines group by valve_id, edge
),

judged as (
    select
        grid.valve_id,
        grid.edge,
        grid.edge_order,
        case
            when coalesce(recent_alarms.n_recent_alarms, 0) > 0 then 'faulty'
            when levels.wear_reason is not null then 'worn'
            when coalesce(levels.n_trend_fits, 0) < grid.trend_min_fits then 'unknown'
            else 'healthy'
        end as state,
        grid.trend_min_fits,
        windows.*  exclude (valve_id, edge),
        recent_alarms.* exclude (valve_id, edge),
        levels.* exclude (valve_id, edge),
        soonest.* exclude (valve_id, edge),
        horizon.remaining_horizon_hours,
        standstill.eq9_ok,
        standstill.eq9_residual,
        standstill.eq9_expected,
        standstill.eq9_tolerance,
        baseline_leak.leak_scale as leak_scale_baseline,
        baseline_leak.edge_law,
        baseline_leak.edge_law_note
    from grid
    left join windows using (valve_id, edge)
    left join recent_alarms using (valve_id, edge)
    left join levels using (valve_id, edge)
    left join soonest using (valve_id, edge)
    left join horizon using (valve_id, edge)
    left join standstill using (valve_id)
    left join baseline_leak using (valve_id, edge)
),

life as (
    select
        *,
        case
            when state = 'faulty' then 'faulty'
            when state = 'worn' then 'worn'
            when state = 'unknown' then 'too_little_data'
            when remaining_hours <= remaining_horizon_hours then 'forecast'
            when remaining_hours is not null then 'beyond_horizon'
            else 'no_trend'
        end as remaining_basis
    from judged
),

final as (
    select
        valve_id,
        edge,
        state,
        case state
            when 'faulty' then printf('fault: %s (%d alarm window(s) since %s%s)', last_alarm_reason, n_recent_alarms,
                                      strftime(first_alarm_start, '%Y-%m-%d %H:%M UTC'),
                                      case when n_recent_alarms > 1 then strftime(last_alarm_start, ', the last at %Y-%m-%d %H:%M UTC') else '' end)
            when 'worn' then 'worn: ' || wear_reason
            when 'unknown' then
                case
                    when n_windows is null then 'no fits yet'
                    when n_ok_windows = 0 then printf('no ok fit in %d window(s); last status %s', n_windows, last_status)
                    else printf('too little data: %d ok alarm-free window(s) in the trend span, %d needed',
                                coalesce(n_trend_fits, 0), trend_min_fits)
                end
            else
                case remaining_basis
                    when 'forecast' then
                        printf('healthy; %s trend reaches its %s wear bound %.3g within the horizon',
                               limiting_parameter, limiting_side, limiting_bound)
                    when 'beyond_horizon' then
                        printf('healthy; %s trend reaches its %s wear bound %.3g only beyond the horizon (%g × the span of its data)',
                               limiting_parameter, limiting_side, limiting_bound, (select horizon_spans from settings))
                    else 'healthy; no significant trend toward a wear bound'
                end
        end
        || case
            when eq9_ok = false then printf('; Eq. 9 standstill check fails (residual %.2f, expected %.2f ± %.2f)',
                                            eq9_residual, eq9_expected, eq9_tolerance)
            else ''
        end
        || case when coalesce(edge_law_note, '') <> '' then '; ' || edge_law_note else '' end as reason,
        case remaining_basis when 'forecast' then remaining_hours when 'faulty' then 0.0 when 'worn' then 0.0 end as remaining_hours,
        case remaining_basis when 'forecast' then remaining_hours_low when 'faulty' then 0.0 when 'worn' then 0.0 end as remaining_hours_low,
        case remaining_basis
            when 'forecast' then case when remaining_hours_high <= remaining_horizon_hours then remaining_hours_high end
            when 'faulty' then 0.0 when 'worn' then 0.0
        end as remaining_hours_high,
        case when remaining_basis in ('forecast', 'beyond_horizon') then limiting_parameter end as limiting_parameter,
        case remaining_basis when 'forecast' then end_of_life_hours end as end_of_life_hours,
        operating_hours,
        last_window_start,
        last_ok_window_start,
        alpha_hat,
        x_hat_pct,
        e_mm2,
        alpha_level,
        x_hat_pct_level,
        e_mm2_level,
        coalesce(n_windows, 0) as n_windows,
        coalesce(n_ok_windows, 0) as n_ok_windows,
        coalesce(n_recent_alarms, 0) as n_recent_alarms,
        eq9_ok,
        edge_order,
        leak_scale,
        leak_scale_baseline,
        edge_law,
        remaining_basis,
        case when state = 'healthy' then remaining_horizon_hours end as remaining_horizon_hours,
        first_alarm_start,
        last_alarm_start
    from life
)

select * from final order by valve_id, edge_order
