"""Instants as the command line and the flows take them: ISO-8601 text, a date or a datetime."""

from __future__ import annotations

from datetime import date, datetime, timezone

from flows.common.errors import ValvemonError


def utc_instant(value: str | date | datetime | None, option: str | None = None) -> datetime | None:
    """``value`` as an aware UTC datetime (naive = UTC, a date = its midnight); None stays None.

    ``option`` (``"--from"``, …) names where the text came from in the error message.

    Raises
    ------
    ValvemonError
        For text that is no ISO-8601 date or date-time.
    """
    if value is None:
        return None
    if isinstance(value, str):
        try:
            value = datetime.fromisoformat(value.strip().replace("Z", "+00:00"))
        except ValueError:
            where = f"{option}: " if option else ""
            raise ValvemonError(f"{where}{value!r} is not an ISO-8601 date or date-time") from None
    if not isinstance(value, datetime):
        value = datetime(value.year, value.month, value.day)
    return value.replace(tzinfo=timezone.utc) if value.tzinfo is None else value.astimezone(timezone.utc)
