-- parameter_days: every day of each parameter: the closed days' summaries (stg_parameter_days)
-- and the open days computed now (open_parameter_days). One row per valve, edge, UTC day and
-- parameter with an ok value.
with

closed as (
    select * from stg_parameter_days
),

open as (
    select * from open_parameter_days
),

final as (
    select * from closed
    union all by name
    select * from open
)

select * from final
