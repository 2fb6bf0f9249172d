-- condition_changes: what changed between the latest two recorded runs (docs/notify.md).
-- Every `valvemon report` (the nightly run's too) and every backfill records each edge's
-- valve_condition row in table condition_history; this view compares the latest run ("tonight")
-- with the one before. An edge the earlier run did not have (the first run, a new valve) counts
-- as having been neither faulty nor worn. One row per edge and change:
--   faulty           the edge is faulty and was not: window_start is the first recent alarm
--                    window (where the fault began);
--   new_alarm        faulty before and now, with a later alarm window than before: window_start
--                    is the latest alarm window;
--   worn             the edge is worn and was not;
--   remaining_below  healthy, and its forecast remaining life lies below the run's
--                    remaining_below_h ([notify]) where it did not before (null: not judged);
--   recovered        healthy again after faulty or worn.
-- For worn, remaining_below and recovered window_start is the latest ok window. reason is the
-- edge's reason at the latest run. No row: nothing changed.
with

runs as (
    select run_id, max(run_at) as run_at
    from condition_history
    group by run_id
),

latest as (
    select run_id, run_at, row_number() over (order by run_at desc, run_id desc) as run_rank
    from runs
    qualify run_rank <= 2
),

tonight as (
    select h.* from condition_history h join latest using (run_id) where latest.run_rank = 1
),

before as (
    select h.*, latest.run_at as before_run_at
    from condition_history h join latest using (run_id) where latest.run_rank = 2
),

pairs as (
    select
        tonight.valve_id,
        tonight.edge,
        tonight.edge_order,
        before.state as state_before,
        tonight.state as state_after,
        tonight.reason,
        before.remaining_hours as remaining_hours_before,
        tonight.remaining_hours as remaining_hours_after,
        tonight.remaining_below_h,
        before.last_alarm_start as last_alarm_before,
        tonight.first_alarm_start,
        tonight.last_alarm_start,
        tonight.last_ok_window_start,
        tonight.run_id,
        tonight.run_at,
        tonight.report_path,
        before.run_id as run_id_before,
        before.before_run_at as run_at_before
    from tonight
    left join before using (valve_id, edge)
),

judged as (
    -- an edge changes state in at most one way; a healthy edge may also cross the horizon
    select
        *,
        case
            when state_after = 'faulty' and state_before is distinct from 'faulty' then 'faulty'
            when state_after = 'faulty' and last_alarm_start > coalesce(last_alarm_before, '-infinity'::timestamptz) then 'new_alarm'
            when state_after = 'worn' and state_before is distinct from 'worn' then 'worn'
            when state_after = 'healthy' and state_before in ('faulty', 'worn') then 'recovered'
        end as state_change,
        case
            when state_after = 'healthy' and remaining_hours_after < remaining_below_h
                and not coalesce(state_before = 'healthy' and remaining_hours_before < remaining_below_h, false)
            then 'remaining_below'
        end as life_change
    from pairs
),

unnested as (
    select *, unnest([state_change, life_change]) as change from judged
),

changes as (
    select * from unnested where change is not null
),

final as (
    select
        valve_id,
        edge,
        change,
        state_before,
        state_after,
        reason,
        case change
            when 'faulty' then first_alarm_start
            when 'new_alarm' then last_alarm_start
            else last_ok_window_start
        end as window_start,
        remaining_hours_before,
        remaining_hours_after,
        remaining_below_h,
        run_id,
        run_at,
        run_id_before,
        run_at_before,
        report_path,
        edge_order
    from changes
)

select * from final order by valve_id, edge_order, change
