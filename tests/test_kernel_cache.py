"""flows/common/kernel_cache.py: ``make setup`` fills numba's cache with every part, and a wrong part is refused."""

import re
from pathlib import Path

from flows.common.kernel_cache import PARTS, main

ROOT = Path(__file__).resolve().parents[1]


def test_make_setup_runs_every_part_and_no_other():
    text = (ROOT / "Makefile").read_text()
    parts = re.search(r"^KERNEL_PARTS := (.*)$", text, re.M).group(1).split()
    assert parts == [f"$(VENV)/.kernels-{p}" for p in PARTS]
    assert re.search(r"^setup: .*\$\(KERNEL_PARTS\)", text, re.M)


def test_an_unknown_part_is_refused_before_any_work(capsys, tmp_path, monkeypatch):
    monkeypatch.setattr("tempfile.tempdir", str(tmp_path))
    assert main(["snapshot", "busy"]) == 2
    assert capsys.readouterr().err == "kernel_cache: unknown part 'busy'; the parts are snapshot, continuous\n"
    assert list(tmp_path.iterdir()) == []
