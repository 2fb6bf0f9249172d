"""The one error the pure ingest functions raise: what is wrong, and where in the export."""

from __future__ import annotations


class IngestError(ValueError):
    """An export the ingest refuses; names the line (or row), the tag and what was expected.

    The flows prefix the file's path, so the whole message is one line such as
    ``exports/day1.csv: line 17: tag MILL1.V017.P1: local time 2025-03-30 02:30:00 does not
    exist in Europe/Vienna (clocks jump forward)``.
    """

    def __init__(self, message: str, *, line: int | None = None, tag: str | None = None):
        self.line = line
        self.tag = tag
        self.detail = message
        where = []
        if line is not None:
            where.append(f"line {line}")
        if tag is not None:
            where.append(f"tag {tag}")
        super().__init__(": ".join([*where, message]))
