-- fleet_ranking: the valves in order of urgency, one row per configured valve.
-- urgency_rank 1 = look at it first. Tiers, in this order:
--   1 faulty (an edge is faulty; more faulty edges first),
--   2 worn (an edge is worn),
--   3 Eq. 9 standstill check fails although no edge is faulty or worn,
--   4 healthy with a forecast within the horizon (soonest remaining_hours_low first),
--   5 unknown (too little data to judge an edge),
--   6 healthy without a forecast within the horizon.
-- The remaining life is that of the worst edge, its valve_condition row as it is (the rule is
-- written there once): 0 with the faulty or worn edge named, the soonest forecast within the
-- horizon, or null with remaining_basis saying why. limiting_edge: the edge the figures are of.
with

conditions as (
    select * from valve_condition
),

standstill as (
    select * from standstill_indicator
),

per_valve as (
    select
        valve_id,
        count(*) filter (where state = 'faulty') as edges_faulty,
        count(*) filter (where state = 'worn') as edges_worn,
        count(*) filter (where state = 'unknown') as edges_unknown,
        coalesce(
            arg_min(edge, edge_order) filter (where remaining_basis = 'faulty'),
            arg_min(edge, edge_order) filter (where remaining_basis = 'worn'),
            arg_min(edge, remaining_hours) filter (where remaining_basis = 'forecast'),
            arg_min(edge, edge_order) filter (where remaining_basis = 'too_little_data'),
            arg_min(edge, edge_order) filter (where remaining_basis = 'beyond_horizon'),
            arg_min(edge, edge_order)
        ) as worst_edge,
        max(last_window_start) as last_window_start,
        max(operating_hours) as operating_hours
    from conditions
    group by valve_id
),

tiered as (
    select
        per_valve.*,
        conditions.reason,
        conditions.remaining_hours,
        conditions.remaining_hours_low,
        conditions.remaining_hours_high,
        case when conditions.remaining_hours is not null then per_valve.worst_edge end as limiting_edge,
        conditions.remaining_basis,
        conditions.remaining_horizon_hours,
        standstill.eq9_ok,
        standstill.eq9_residual,
        case
            when edges_faulty > 0 then 'faulty'
            when edges_worn > 0 then 'worn'
            when edges_unknown = 4 then 'unknown'
            else 'healthy'
        end as state,
        case
            when edges_faulty > 0 then 1
            when edges_worn > 0 then 2
            when standstill.eq9_ok = false then 3
            when conditions.remaining_basis = 'forecast' then 4
            when edges_unknown > 0 then 5
            else 6
        end as urgency_tier
    from per_valve
    join conditions on conditions.valve_id = per_valve.valve_id and conditions.edge = per_valve.worst_edge
    left join standstill on standstill.valve_id = per_valve.valve_id
),

final as (
    select
        row_number() over (
            order by urgency_tier, edges_faulty desc, remaining_hours_low nulls last,
                     remaining_hours nulls last, valve_id
        ) as urgency_rank,
        valve_id,
        state,
        urgency_tier,
        edges_faulty,
        edges_worn,
        edges_unknown,
        worst_edge,
        reason,
        remaining_hours,
        remaining_hours_low,
        remaining_hours_high,
        limiting_edge,
        eq9_ok,
        eq9_residual,
        operating_hours,
        last_window_start,
        remaining_basis,
        remaining_horizon_hours
    from tiered
)

select * from final order by urgency_rank
