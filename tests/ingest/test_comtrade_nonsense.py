"""What a COMTRADE recording cannot mean is refused in one line naming the .cfg's line (issue 46,
minor items): ``timemult`` <= 0 (time-reversed rows reached the lake), ``nrates`` < 0, an analog
channel whose PS field is blank or neither P nor S (C37.111-1999 and -2013 make it critical; a
blank one taken as primary made P1 10x low on a secondary-valued file). A ``.dat`` without its
``.cfg`` in an export folder gets a word on stderr."""

from __future__ import annotations

import pytest

from flows.common.errors import ValvemonError
from tests.ingest.comtrade_files import write_comtrade
from tests.ingest.conftest import ingest, lake
from tests.ingest.test_comtrade import RATE, recording
from tests.ingest.test_recorder_formats import plant_file


def _replace_line(cfg, k: int, text: str) -> None:
    lines = cfg.read_text().splitlines()
    lines[k] = text
    cfg.write_text("\r\n".join(lines) + "\r\n")


@pytest.mark.parametrize(
    "spoil, line, expected",
    [
        (lambda lines: (len(lines) - 1, "-1"), None, "expected timemult > 0 (the time stamps' multiplier), found '-1'"),
        (lambda lines: (len(lines) - 1, "0"), None, "expected timemult > 0 (the time stamps' multiplier), found '0'"),
        (lambda lines: (lines.index("50") + 1, "-1"), None, "expected nrates >= 0 (the number of sample rates; 0: time stamps only), found '-1'"),
        (lambda lines: (4, lines[4].rsplit(",", 1)[0] + ","), 5, "expected an analog channel's PS field P or S"),
        (lambda lines: (4, lines[4].rsplit(",", 1)[0] + ",X"), 5, "expected an analog channel's PS field P or S"),
    ],
    ids=["timemult -1", "timemult 0", "nrates -1", "blank PS", "PS X"],
)
def test_a_nonsensical_cfg_is_refused(tmp_path, spoil, line, expected):
    cfg = write_comtrade(tmp_path / "rec.cfg", recording(50, "BINARY"), "BINARY")
    k, text = spoil(cfg.read_text().splitlines())
    _replace_line(cfg, k, text)
    with pytest.raises(ValvemonError) as err:
        ingest(plant_file(tmp_path, **RATE), cfg, tmp_path / "wh")
    message = str(err.value)
    assert message.startswith(f"{cfg}: line {line or k + 1}: {expected}") and "\n" not in message, message
    assert not (tmp_path / "wh" / "lake").exists()


def test_a_dat_without_its_cfg_gets_a_word(tmp_path, capsys):
    folder = tmp_path / "exports"
    folder.mkdir()
    write_comtrade(folder / "good.cfg", recording(50, "BINARY"), "BINARY")
    orphan = write_comtrade(folder / "orphan.cfg", recording(50, "BINARY"), "BINARY")
    orphan.unlink()
    ingest(plant_file(tmp_path, **RATE), folder, tmp_path / "wh")
    assert lake(tmp_path / "wh").height == 50
    err = capsys.readouterr().err
    assert f"valvemon: warning: {folder / 'orphan.dat'}: a COMTRADE data file without its .cfg beside it (orphan.cfg): not read" in err
    assert "good.dat" not in err
