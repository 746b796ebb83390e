"""``jointid fit --q-s`` out of range is one line naming the flag, before any file is read
(it was "q_s must be positive [rad/s], got 0.0" after loading, without the flag; the
``--robot`` path already named it)."""

from __future__ import annotations

import subprocess
import sys

import pytest


@pytest.mark.parametrize("value", ["0", "-0.03", "nan", "inf"])
def test_qs_out_of_range_names_the_flag_before_reading(tmp_path, value):
    # the input does not exist: the option is refused first
    r = subprocess.run([sys.executable, "-m", "daq.app.cli", "fit", "absent.csv",
                        "--model", "paper", "--q-s", value],
                       cwd=tmp_path, capture_output=True, text=True, timeout=300)  # fmt: skip
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2, r.stderr
    assert len(lines) == 1, r.stderr
    assert f"--q-s '{value}'" in lines[0] and "> 0" in lines[0], lines[0]
