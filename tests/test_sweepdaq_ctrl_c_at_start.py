"""Ctrl-C while ``jointid`` is still starting (found by the acquisition sweep): the subcommand
modules take seconds to import (scipy, pinocchio...), and a SIGINT in that time ended in a
Python traceback (exit -2) instead of the one line and exit 130 of every other interrupt.
The signal is sent once the child has begun loading scipy (its package in /proc/PID/maps), i.e. in
the middle of those imports, before anything is planned or opened."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(not Path("/proc/self/maps").exists(), reason="needs /proc")]


def _loading_scipy(pid: int) -> bool:
    try:
        return "/scipy/" in Path(f"/proc/{pid}/maps").read_text()
    except OSError:
        return False


def test_ctrl_c_during_start_up_is_one_line_exit_130(tmp_path):
    exe = shutil.which("jointid") or ""
    cmd = [exe] if exe else [sys.executable, "-m", "daq.app.cli"]
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1")
    proc = subprocess.Popen([*cmd, "plan", str(ROOT / "examples" / "campaign.toml")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=tmp_path, env=env)
    try:
        t_end = time.monotonic() + 60
        while not _loading_scipy(proc.pid) and proc.poll() is None:
            assert time.monotonic() < t_end, "the child never loaded scipy"
            time.sleep(0.002)
        assert proc.poll() is None, proc.communicate()
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert "Traceback" not in err, err[-2000:]
    assert proc.returncode == 130, (proc.returncode, err[-2000:])
    assert err.strip().splitlines()[-1] == "jointid: interrupted (SIGINT)"
    assert "condition number" not in out  # stopped before the plan was printed
