-- edge_days: every day of each valve and edge: the closed days' summaries (stg_edge_days) and
-- the open days computed now (open_edge_days). One row per valve, edge and UTC day with windows.
with

closed as (
    select * from stg_edge_days
),

open as (
    select * exclude (baseline_version) from open_edge_days
),

final as (
    select * from closed
    union all by name
    select * from open
)

select * from final
