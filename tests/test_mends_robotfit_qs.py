"""RobotFit refuses a bad q_s in one line before it reads any file (the file paths here do
not exist: the old code read them first and said "no such file")."""

from __future__ import annotations

import pytest
from example_campaign import ROOT

from ident import DataError, IdentError
from ident.api import RobotFit

ROBOT = ROOT / "examples" / "robots" / "rx130l.toml"


@pytest.mark.parametrize("q_s, what", [("scna", "q_s 'scna'"), ("", "q_s ''"),
                                       (-0.1, "q_s -0.1"), ([0.1, "x"], "q_s[1] 'x'"),
                                       ([0.1, "scan"], "q_s[1] 'scan'"),
                                       ({"j1": 0.0}, "q_s['j1'] 0.0")])
def test_bad_qs_refused_before_the_files(tmp_path, q_s, what):
    missing = tmp_path / "no_such_run.mcap"
    with pytest.raises(DataError) as exc:
        RobotFit(ROBOT, q_s=q_s).fit([missing], validation=[missing])
    msg = str(exc.value)
    assert "\n" not in msg and msg.startswith(what), msg
    assert "'scan'" in msg and "'scan-joints'" in msg, msg  # the accepted words
    assert "no such file" not in msg and str(missing) not in msg, msg


@pytest.mark.parametrize("q_s", ["scan", " Scan-Joints ", 0.05, "0.05", [0.1, 0.2],
                                 {"j1": 0.1}])
def test_good_qs_reaches_the_files(tmp_path, q_s):
    """A good q_s passes the check: the error is then the missing file's."""
    missing = tmp_path / "no_such_run.mcap"
    with pytest.raises(IdentError, match="no such file"):
        RobotFit(ROBOT, q_s=q_s).fit([missing])
