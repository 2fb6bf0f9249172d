"""The report's data-quality section: what the ingest set aside, read past and refused.

:func:`data_quality` reads the ingest's ledger from the snapshot (``quarantine`` by reason,
``ingest_manifest`` per file, the messages of failed ``ingest_runs``); :func:`quality_section`
renders it. Rules and reasons: ``docs/ingest.md``, "Quarantine or refusal".
"""

from __future__ import annotations

import html
from dataclasses import dataclass

import polars as pl

from flows.common.warehouse_db import query_frame
from schemas.fields import QUARANTINE_REASONS

FILES_SHOWN = 20
"""Files listed: those with the most samples set aside or read past."""
REFUSALS_SHOWN = 10
"""Latest failed ingest runs listed."""


@dataclass
class DataQuality:
    """The ingest's ledger, summed for the report."""

    totals: dict
    """files, samples_in, quarantined, other_samples over every ingested file."""
    by_reason: dict[str, int]
    """Quarantined samples per reason (:data:`QUARANTINE_REASONS` order, zeros left out)."""
    files: pl.DataFrame
    """Files with samples set aside or read past, worst first (at most :data:`FILES_SHOWN`)."""
    refusals: pl.DataFrame
    """The latest failed runs: finished_at, message."""


def _has(con, table: str) -> bool:
    return bool(con.execute("SELECT count(*) FROM duckdb_tables() WHERE table_name = ?", [table]).fetchall()[0][0])


def data_quality(con) -> DataQuality | None:
    """The summary (None when nothing was ever ingested into the warehouse)."""
    if not _has(con, "ingest_manifest"):
        return None
    totals = query_frame(
        con, "SELECT count(*) AS files, coalesce(sum(samples_in), 0) AS samples_in, coalesce(sum(quarantined), 0) AS quarantined, "
        "coalesce(sum(other_samples), 0) AS other_samples FROM ingest_manifest",
    ).row(0, named=True)  # fmt: skip
    counts = dict(con.execute("SELECT reason, count(*) FROM quarantine GROUP BY reason").fetchall()) if _has(con, "quarantine") else {}
    files = query_frame(
        con,
        "SELECT source_file, samples_in, quarantined, out_of_range, bad_timestamp, implausible_time, field_count, clock_step, truncated, "
        "other_tags, other_tag_names "
        "FROM ingest_manifest WHERE quarantined > 0 OR other_tags > 0 ORDER BY quarantined DESC, other_samples DESC, source_file "
        f"LIMIT {FILES_SHOWN}",
    )
    refusals = query_frame(
        con, f"SELECT finished_at, message FROM ingest_runs WHERE status = 'failed' ORDER BY started_at DESC LIMIT {REFUSALS_SHOWN}"
    ) if _has(con, "ingest_runs") else pl.DataFrame(schema={"finished_at": pl.Datetime("us", "UTC"), "message": pl.String})  # fmt: skip
    return DataQuality(totals, {r: int(counts[r]) for r in QUARANTINE_REASONS if counts.get(r)}, files, refusals)


def _names(text: str, limit: int = 6) -> str:
    names = [n for n in text.split(",") if n]
    return ", ".join(names[:limit]) + (f" … ({len(names)})" if len(names) > limit else "")


def quality_section(q: DataQuality) -> list[str]:
    """HTML of the section "Data quality"."""
    t = q.totals
    share = t["quarantined"] / t["samples_in"] if t["samples_in"] else 0.0
    parts = [
        "<h2 id='data-quality'>Data quality</h2>",
        f"<p>{t['files']:,} export files ingested: {t['samples_in']:,} samples, {t['quarantined']:,} quarantined "
        f"({share:.3%}), {t['other_samples']:,} samples of other equipment's tags read past.</p>",
    ]
    if q.by_reason:
        parts.append("<table><tr><th>reason</th><th>samples quarantined</th></tr>")
        parts += [f"<tr><td>{html.escape(r)}</td><td class='num'>{n:,}</td></tr>" for r, n in q.by_reason.items()]
        parts.append("</table>")
    if q.files.height:
        parts.append(
            "<table><tr><th>file</th><th>samples</th><th>quarantined</th><th>out of range</th><th>bad timestamp</th>"
            "<th>implausible time</th><th>wrong field count</th><th>after a clock step</th><th>cut (truncated)</th><th>other tags</th></tr>"
        )
        for r in q.files.iter_rows(named=True):
            parts.append(
                f"<tr><td>{html.escape(r['source_file'])}</td><td class='num'>{r['samples_in']:,}</td><td class='num'>{r['quarantined']:,}</td>"
                f"<td class='num'>{r['out_of_range']:,}</td><td class='num'>{r['bad_timestamp']:,}</td><td class='num'>{r['implausible_time']:,}</td>"
                f"<td class='num'>{r['field_count']:,}</td><td class='num'>{r['clock_step']:,}</td><td>{'yes' if r['truncated'] else ''}</td>"
                f"<td>{html.escape(_names(r['other_tag_names']))}</td></tr>"
            )
        parts.append("</table>")
    if q.refusals.height:
        parts.append("<p>Files refused (latest failed ingest runs):</p><ul>")
        parts += [f"<li>{r['finished_at']:%Y-%m-%d %H:%M} UTC: {html.escape(r['message'] or '')}</li>" for r in q.refusals.iter_rows(named=True)]
        parts.append("</ul>")
    parts.append(
        '<p class="note">A sample is quarantined (table <code>quarantine</code>, with file, line and raw text) for a bad '
        "quality code, a missing or non-numeric value, an unreadable timestamp, a time later than the ingest's + 1 day "
        "or before the valve was commissioned, a value outside its column's physical range, a text row whose field count "
        "is not the header's, a cut last line, or a wide row at or after a step back of the recorder's clock; a file is refused when "
        "a tag's unreadable timestamps, implausible times or values out of range exceed <code>export.max_bad_share</code>. Tags of other equipment are "
        "read past (<code>export.other_tags</code>). Per file: table <code>ingest_manifest</code>.</p>"
    )
    return parts
