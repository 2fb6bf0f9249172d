-- stg_parameter_days: the closed days of each parameter (table parameter_day_summaries):
-- median, minimum, maximum, and the alarm-free windows' count, means and centred sums of
-- squares and products over operating hours (they merge exactly into the trend's least squares).
-- One row per valve, edge, UTC day before the valve's watermark and parameter.
with

days as (
    select * from parameter_day_summaries
),

final as (
    select * from days
)

select * from final
