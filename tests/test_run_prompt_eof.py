"""``jointid run`` without ``--yes`` whose standard input is closed (a script, a notebook
cell, CI): the payload prompt gets no answer. The refusal must say so and name ``--yes``,
in one line, exit 1, no ``--out`` folder left (docs/api.md's recording command, run as a
script, ended with "operator declined payload 0": nobody declined anything)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_run_with_stdin_closed_names_yes(tmp_path):
    out = tmp_path / "runs"
    proc = subprocess.run(
        [sys.executable, "-m", "daq.app.cli", "run", str(ROOT / "examples" / "campaign.toml"),
         "--simulate", str(ROOT / "examples" / "plant_rx130l.toml"), "--quick",
         "--out", str(out)],
        stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert proc.returncode == 1, proc.stderr
    last = [ln for ln in proc.stderr.splitlines() if ln.startswith("jointid run:")]
    assert len(last) == 1, proc.stderr
    assert "--yes" in last[0] and "standard input" in last[0], last[0]
    assert "declined" not in last[0], last[0]
    assert not out.exists()
