"""The repository stands alone: no tracked file refers to a path outside it (the method's
equations are docs/model.md, the interfaces docs/interfaces.md), and the docs name capabilities,
not issue numbers."""

import re
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUTSIDE = re.compile(r"\.\./" + "shared|/work/" + "shared|shared/" + "spec")
ISSUE_NUMBER = re.compile(r"\bissues? \d+|(?<![\w&])#\d+\b", re.IGNORECASE)


def _tracked() -> list[Path]:
    out = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    return [ROOT / name for name in out.decode().split("\0") if name]


def _text(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8")
    except (UnicodeDecodeError, FileNotFoundError, IsADirectoryError):
        return ""  # binary (pictures, Parquet fixtures), or deleted but not yet staged


def test_no_tracked_file_refers_to_a_path_outside_the_repository():
    found = [f"{p.relative_to(ROOT)}:{n}: {line.strip()}" for p in _tracked()
             for n, line in enumerate(_text(p).splitlines(), 1) if OUTSIDE.search(line)]
    assert not found, "\n".join(found)
    assert (ROOT / "docs" / "model.md").is_file() and (ROOT / "docs" / "interfaces.md").is_file()


def test_the_docs_name_capabilities_not_issue_numbers():
    docs = [ROOT / "BENCHMARKS.md", *sorted((ROOT / "docs").glob("*.md"))]
    found = [f"{p.name}:{n}: {line.strip()}" for p in docs
             for n, line in enumerate(_text(p).splitlines(), 1) if ISSUE_NUMBER.search(line)]
    assert not found, "\n".join(found)
