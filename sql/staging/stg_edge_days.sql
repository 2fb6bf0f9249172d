-- stg_edge_days: the closed days of each valve and edge (table edge_day_summaries): windows,
-- ok windows, alarms, the day's latest window and ok values, the leakage of the day.
-- One row per valve, edge and UTC day before the valve's watermark.
with

days as (
    select * from edge_day_summaries
),

final as (
    select * exclude (baseline_version) from days
)

select * from final
