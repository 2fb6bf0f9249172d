"""The daily summaries the condition views read instead of the whole history, moved forward by
every publish (:func:`update_summaries`).

A valve's windows are *closed* before its watermark ``summarised_before`` (a UTC midnight: the
start of the latest day it has windows on) and *open* from it on. For the closed days the
tables ``edge_day_summaries`` (per valve, edge and day), ``parameter_day_summaries`` (per valve,
edge, day and parameter: the daily points and the alarm-free windows' sums of the trend's least
squares) and ``alarm_windows`` (every alarm window) hold what the views ``open_edge_days``,
``open_parameter_days`` and ``window_alarms`` computed for those days when they were open; the
views read them, and compute only the open windows, with the change detector's history before
them, raw (``raw_from``, the earliest window they read). So a night costs the new day and the
detector's history, not the valve's whole history (``docs/warehouse.md``, "What a report
recomputes").

Which days change: the rows of ``edge_fits`` monitored since the last update
(``monitored_at`` > ``monitored_through``; a rerun, a backfill or late data re-monitor a span,
and every row they write carries the time of the run) mark their valve's days from the first of
them on as changed: those closed days and every later one are computed again (a window's
verdict depends on the windows before it). Another ``condition_bounds`` row (a changed bound or
detector setting) or a newer baseline version among those rows rebuilds the valve from its first
day. All of it in one transaction: a run killed halfway leaves the summaries as they were, and
a rerun with nothing new changes nothing.
"""

from __future__ import annotations

from datetime import datetime

import duckdb

from flows.common.warehouse_db import transaction
from flows.report.views import materialise_views

SUMMARY_TABLES = ("edge_day_summaries", "parameter_day_summaries")
"""The per-day summary tables, keyed by valve, edge and ``day_utc`` (and parameter)."""

_HISTORY = "to_microseconds(cast(b.change_history_hours * 3600e6 as bigint))"
"""The change detector's history ``change_history_hours`` as an interval (SQL, bounds alias ``b``)."""


def _midnight(ts: str) -> str:
    """SQL: the UTC midnight starting the day of the TIMESTAMPTZ expression ``ts``."""
    return f"timezone('UTC', cast(cast(timezone('UTC', {ts}) as date) as timestamp))"


PLAN_SQL = f"""
CREATE OR REPLACE TEMP TABLE _summary_plan AS
WITH bounds AS (
    SELECT valve_id, md5(CAST(b AS VARCHAR)) AS bounds_hash
    FROM (SELECT * EXCLUDE (updated_at) FROM condition_bounds) AS b
),
marks AS (SELECT * FROM summary_watermarks),
fresh_rows AS (
    SELECT f.valve_id, f.edge, f.window_start, f.monitored_at, f.baseline_version
    FROM edge_fits f
    JOIN bounds USING (valve_id)
    LEFT JOIN marks USING (valve_id)
    WHERE f.monitored_at > coalesce(marks.monitored_through, '-infinity'::timestamptz)
      AND f.monitored_at > (SELECT coalesce(min(coalesce(m.monitored_through, '-infinity'::timestamptz)), '-infinity'::timestamptz)
                             FROM bounds LEFT JOIN marks m USING (valve_id))
),
fresh AS (
    SELECT valve_id, min(window_start) AS first_start, max(window_start) AS last_start, max(monitored_at) AS monitored_through
    FROM fresh_rows GROUP BY valve_id
),
summarised_versions AS (
    SELECT valve_id, edge, max(baseline_version) AS version FROM edge_day_summaries GROUP BY ALL
),
newer_baseline AS (
    SELECT DISTINCT fresh_rows.valve_id
    FROM fresh_rows JOIN summarised_versions USING (valve_id, edge)
    WHERE fresh_rows.baseline_version > summarised_versions.version
),
judged AS (
    SELECT
        bounds.valve_id, bounds.bounds_hash,
        marks.summarised_before AS old_before, marks.raw_from AS old_raw_from,
        marks.valve_id IS NULL OR marks.bounds_hash <> bounds.bounds_hash OR newer_baseline.valve_id IS NOT NULL AS rebuild,
        greatest(coalesce(marks.summarised_before, '-infinity'::timestamptz),
                 coalesce({_midnight("fresh.last_start")}, '-infinity'::timestamptz)) AS close_before,
        greatest(coalesce(marks.monitored_through, '-infinity'::timestamptz),
                 coalesce(fresh.monitored_through, '-infinity'::timestamptz)) AS monitored_through,
        fresh.first_start
    FROM bounds
    LEFT JOIN marks USING (valve_id)
    LEFT JOIN fresh USING (valve_id)
    LEFT JOIN newer_baseline USING (valve_id)
),
final AS (
    SELECT
        *,
        CASE WHEN rebuild THEN '-infinity'::timestamptz
             ELSE least(old_before, coalesce({_midnight("first_start")}, old_before)) END AS from_before
    FROM judged
    WHERE close_before > '-infinity'::timestamptz
)
SELECT * FROM final
"""
"""Per configured valve with fits: whether it is rebuilt, the watermark the recomputation starts
from (``from_before``: the first changed day, or the old watermark) and the new one
(``close_before``)."""


def context_sql(at: str, lower: str) -> str:
    """SQL selecting ``valve_id, raw_from`` for the plan's valves: the earliest window the views
    must read raw when the valve's watermark is the plan's column ``at``, reading the windows from
    the plan's column ``lower`` (a lower bound of the result) on.

    The change detector's history of any window from the watermark on, and the level's windows,
    lie after the earliest of: ``change_history_hours`` before the watermark and before each
    edge's latest ok window before it; each parameter's ``change_history_windows``-th latest
    window and latest alarm-free window before it (or its first). Windows only get added after the
    watermark, so none of these moves back while the watermark stays."""
    return f"""
    WITH plan AS (SELECT valve_id, {at} AS at_, {lower} AS lower_ FROM _summary_plan),
    rows_before AS (
        SELECT p.valve_id, p.edge, p.parameter, p.window_start,
               a.window_start IS NULL AS is_clean
        FROM stg_fit_parameters p
        JOIN plan USING (valve_id)
        LEFT JOIN stg_alarm_windows a USING (valve_id, edge, window_start)
        WHERE p.window_start < plan.at_ AND p.window_start >= plan.lower_
          AND p.window_start >= (SELECT min(lower_) FROM plan)
    ),
    ranked AS (
        SELECT *,
               row_number() OVER (PARTITION BY valve_id, edge, parameter ORDER BY window_start DESC) AS rank_all,
               CASE WHEN is_clean THEN row_number() OVER (PARTITION BY valve_id, edge, parameter, is_clean ORDER BY window_start DESC) END AS rank_clean
        FROM rows_before
    ),
    earliest AS (
        SELECT r.valve_id,
               min(r.window_start) FILTER (WHERE r.rank_all <= b.change_history_windows
                                            OR r.rank_clean <= b.change_history_windows) AS by_count,
               min(r.latest_start) - any_value({_HISTORY}) AS by_hours
        FROM (SELECT *, max(window_start) OVER (PARTITION BY valve_id, edge) AS latest_start FROM ranked) r
        JOIN stg_condition_bounds b ON b.valve_id = r.valve_id AND b.parameter = r.parameter
        GROUP BY r.valve_id
    )
    SELECT plan.valve_id,
           least(plan.at_ - {_HISTORY}, coalesce(earliest.by_count, plan.at_), coalesce(earliest.by_hours, plan.at_)) AS raw_from
    FROM plan
    JOIN stg_condition_bounds b ON b.valve_id = plan.valve_id AND b.parameter = 'alpha_hat'
    LEFT JOIN earliest ON earliest.valve_id = plan.valve_id
    """


def update_summaries(con: duckdb.DuckDBPyConnection, now: datetime) -> int:
    """Bring the daily summaries up to the latest day of every configured valve (module doc), in
    one transaction of the read-write connection ``con``, whose views exist. Returns the number
    of valve-days written."""
    with transaction(con):
        con.execute(PLAN_SQL)
        # nothing to close (the rows monitored since lie in the open day): only remember having seen them
        con.execute("""
            UPDATE summary_watermarks SET monitored_through = p.monitored_through
            FROM _summary_plan p
            WHERE summary_watermarks.valve_id = p.valve_id AND NOT p.rebuild AND p.from_before >= p.close_before
        """)
        con.execute("DELETE FROM _summary_plan WHERE NOT rebuild AND from_before >= close_before")
        if not con.execute("SELECT count(*) FROM _summary_plan").fetchone()[0]:
            con.execute("DROP TABLE _summary_plan")
            return 0
        # 1. open the changed days: the views then compute them (and their history) as open windows
        con.execute(f"""
            CREATE OR REPLACE TEMP TABLE _summary_from AS
            SELECT valve_id, CASE WHEN rebuild THEN '-infinity'::timestamptz
                                  WHEN from_before = old_before THEN old_raw_from END AS raw_from
            FROM _summary_plan
        """)
        late = con.execute("SELECT count(*) FROM _summary_from WHERE raw_from IS NULL").fetchone()[0]
        if late:  # late data before the watermark: its history, read from the first window on
            con.execute(f"""
                UPDATE _summary_from SET raw_from = c.raw_from
                FROM ({context_sql("from_before", "'-infinity'::timestamptz")}) c
                WHERE _summary_from.valve_id = c.valve_id AND _summary_from.raw_from IS NULL
            """)
        con.execute("DELETE FROM summary_watermarks WHERE valve_id IN (SELECT valve_id FROM _summary_plan)")
        con.execute("""
            INSERT INTO summary_watermarks
            SELECT p.valve_id, p.from_before, f.raw_from, p.bounds_hash, p.monitored_through, ?
            FROM _summary_plan p JOIN _summary_from f USING (valve_id)
        """, [now])
        for table in SUMMARY_TABLES:
            con.execute(f"DELETE FROM {table} t USING _summary_plan p WHERE t.valve_id = p.valve_id "
                        f"AND t.day_utc >= cast(timezone('UTC', p.from_before) AS date)")
        con.execute("DELETE FROM alarm_windows t USING _summary_plan p WHERE t.valve_id = p.valve_id AND t.window_start >= p.from_before")
        # 2. compute the open days once (temporary tables shadow the views), close those before the new watermark
        made = materialise_views(con, ("open_edge_days", "open_parameter_days"))
        try:
            for table, view in zip(SUMMARY_TABLES, ("open_edge_days", "open_parameter_days")):
                con.execute(f"INSERT INTO {table} BY NAME SELECT v.* FROM {view} v JOIN _summary_plan p USING (valve_id) "
                            f"WHERE v.day_utc < cast(timezone('UTC', p.close_before) AS date)")
            con.execute("""
                INSERT INTO alarm_windows BY NAME
                SELECT w.* EXCLUDE (is_alarm) FROM window_alarms w JOIN _summary_plan p USING (valve_id)
                WHERE w.is_alarm AND w.window_start < p.close_before
            """)
            written = con.execute("SELECT count(*) FROM open_edge_days v JOIN _summary_plan p USING (valve_id) "
                                  "WHERE v.day_utc < cast(timezone('UTC', p.close_before) AS date)").fetchone()[0]
        finally:
            for name in reversed(made):
                con.execute(f"DROP TABLE temp.{name}")
        # 3. the new watermark and the history its first open window needs
        con.execute(f"""
            UPDATE summary_watermarks SET summarised_before = p.close_before, raw_from = c.raw_from
            FROM _summary_plan p JOIN ({context_sql("close_before", "(SELECT raw_from FROM summary_watermarks m WHERE m.valve_id = _summary_plan.valve_id)")}) c USING (valve_id)
            WHERE summary_watermarks.valve_id = p.valve_id
        """)
        con.execute("DROP TABLE _summary_plan")
        con.execute("DROP TABLE _summary_from")
    return written
