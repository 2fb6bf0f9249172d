-- stg_summary_watermarks: how far each valve's daily summaries reach (table summary_watermarks,
-- moved by every writing command's publish, flows/report/summaries.py).
-- One row per valve that has summaries: its windows before summarised_before (a UTC midnight)
-- are in edge_day_summaries, parameter_day_summaries and alarm_windows; from it on the views
-- compute them; raw_from is the earliest window they read raw (the change detector's history
-- of the first open window, the level's windows). A valve without a row has nothing summarised.
-- The views skip windows before the earliest watermark of all (so that a scan skips the closed
-- history's row groups): every publish gives each configured valve with fits its row, so a
-- snapshot is exact; the live database lacks a new valve's row between the monitor's commit of
-- its first fits and the publish that ends that command.
with

marks as (
    select * from summary_watermarks
),

final as (
    select valve_id, summarised_before, raw_from from marks
)

select * from final
