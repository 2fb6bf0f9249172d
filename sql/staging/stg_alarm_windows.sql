-- stg_alarm_windows: the alarm windows of the closed days (table alarm_windows), as
-- window_alarms judged them when the day was summarised.
-- One row per valve, edge and alarm window before the valve's watermark.
with

alarms as (
    select * from alarm_windows
),

final as (
    select * from alarms
)

select * from final
