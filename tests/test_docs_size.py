"""The docs stay a newcomer's evening and BENCHMARKS.md a dashboard: line counts and widths are held,
BENCHMARKS.md is one table per area with today's figure, anchor, ratio, command, date and machine
in every row, and every figure the README and the docs quote from it carries its row's figure."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = sorted((ROOT / "docs").glob("*.md"))
PAGES = [ROOT / "README.md", ROOT / "BENCHMARKS.md", *DOCS]
MAX_LINES = {"README.md": 200, "BENCHMARKS.md": 300, "discrepancy.md": 400}
OTHER_PAGE_LINES = 300
PROSE_WIDTH = 200  # a line of text or code; table rows may be wider (a row is one line)
TABLE_WIDTH = 400
AREAS = ["Simulator", "Ingest", "Monitor", "Report", "Retention", "Discrepancy", "Latency", "Plant-day"]
COLUMNS = ["id", "measure", "today", "anchor", "ratio", "command", "date", "machine"]
ROW_ID = re.compile(r"^[A-Z]{3}-\d+$")
CITATION = re.compile(r"\[([A-Z]{3}-\d+)\]\((?:(?:\.\./)?BENCHMARKS\.md)?#([a-z0-9-]+)\)")
NUMBER = re.compile(r"\d+(?:,\d{3})*(?:\.\d+)?")


def _numbers(text: str) -> list[str]:
    return [n.replace(",", "") for n in NUMBER.findall(text)]


def _anchor(heading: str) -> str:
    return re.sub(r"[^a-z0-9 -]", "", heading.lower()).strip().replace(" ", "-")


def _cells(line: str) -> list[str]:
    return [c.strip() for c in re.split(r"(?<!\\)\|", line.strip())[1:-1]]


def _benchmark_rows() -> dict[str, tuple[str, list[str]]]:
    """Row id -> (the anchor of its section, its cells)."""
    rows, section = {}, None
    for line in (ROOT / "BENCHMARKS.md").read_text(encoding="utf-8").splitlines():
        if line.startswith("## "):
            section = _anchor(line[3:])
        elif line.startswith("|") and ROW_ID.match(_cells(line)[0]):
            cells = _cells(line)
            assert cells[0] not in rows, f"BENCHMARKS.md: row {cells[0]} twice"
            rows[cells[0]] = (section, cells)
    return rows


def _headline(today: str) -> str:
    """The figure a quote must carry: the first number of two or more characters in the row's
    `today` cell (else its first number)."""
    numbers = _numbers(today)
    assert numbers, f"no figure in {today!r}"
    return next((n for n in numbers if len(n) > 1), numbers[0])


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_a_page_is_read_in_an_evening(page):
    lines = page.read_text(encoding="utf-8").splitlines()
    limit = MAX_LINES.get(page.name, OTHER_PAGE_LINES)
    assert len(lines) <= limit, f"{page.relative_to(ROOT)}: {len(lines)} lines, more than {limit}"
    wide = [f"{page.name}:{n}: {len(line)} characters" for n, line in enumerate(lines, 1)
            if len(line) > (TABLE_WIDTH if line.lstrip().startswith("|") else PROSE_WIDTH)]
    assert not wide, "lines too wide (split them, do not hide text in long lines):\n" + "\n".join(wide)


def test_benchmarks_is_one_table_per_area_with_every_column_filled():
    text = (ROOT / "BENCHMARKS.md").read_text(encoding="utf-8")
    headings = [line[3:] for line in text.splitlines() if line.startswith("## ")]
    for area in AREAS:
        assert any(h.startswith(area) for h in headings), f"BENCHMARKS.md has no section for {area}"
    header = "| " + " | ".join(COLUMNS) + " |"
    assert text.count(header) >= len(AREAS)
    rows = _benchmark_rows()
    assert len(rows) >= 3 * len(AREAS)
    for row_id, (_, cells) in rows.items():
        assert len(cells) == len(COLUMNS), f"{row_id}: {len(cells)} cells, expected {len(COLUMNS)}"
        row = dict(zip(COLUMNS, cells))
        assert all(row[c] for c in COLUMNS), f"{row_id}: an empty cell"
        assert re.fullmatch(r"20\d\d-\d\d-\d\d", row["date"]), f"{row_id}: date {row['date']!r}"
        assert _numbers(row["today"]), f"{row_id}: no figure today"
        assert row["command"] != "—", f"{row_id}: no command"
        assert "core" in row["machine"] and "load" in row["machine"], f"{row_id}: say the machine's cores and load"


def test_every_quoted_figure_carries_its_benchmarks_row():
    rows = _benchmark_rows()
    quoted = set()
    for page in PAGES:
        for paragraph in re.split(r"\n\s*\n", page.read_text(encoding="utf-8")):
            start = 0
            for m in CITATION.finditer(paragraph):
                row_id, anchor = m.groups()
                where = f"{page.name}: [{row_id}]"
                assert row_id in rows, f"{where}: no such row in BENCHMARKS.md"
                section, cells = rows[row_id]
                assert anchor == section, f"{where}: links #{anchor}, the row is under #{section}"
                if page.name != "BENCHMARKS.md":
                    figure = _headline(cells[COLUMNS.index("today")])
                    before = paragraph[start:m.start()]
                    assert figure in _numbers(before), f"{where}: the quote before it lacks the row's figure {figure}"
                    quoted.add(row_id)
                start = m.end()
    assert quoted, "no page quotes BENCHMARKS.md"


def test_the_verdicts_are_explained_within_the_first_100_lines_of_the_discrepancy_page():
    head = "\n".join((ROOT / "docs" / "discrepancy.md").read_text(encoding="utf-8").splitlines()[:100])
    sections = dict(re.findall(r"^### `(\w+)`[^\n]*\n(.*?)(?=^#|\Z)", head, re.S | re.M))
    for verdict in ("none", "named", "ambiguous", "unexplained"):
        assert verdict in sections, f"the verdict {verdict} has no section in the first 100 lines"
        meaning, _, next_step = sections[verdict].partition("**Next:**")
        assert len(meaning.strip()) > 80, f"{verdict}: say what it means"
        assert len(next_step.strip()) > 80, f"{verdict}: say what to do next (**Next:** ...)"
