"""Ctrl-C in ``jointid demo`` (left by the last session): the runner stopped the drive and
closed the log, but the demo took the interrupted campaign for a failed one and exited 2
("jointid demo: error: demo campaign interrupted: ..."). A SIGINT now exits 130 (the shell's
128 + 2), as in every other command, with one line saying it was interrupted, where, and
where the logs are; the log is complete and says the drive confirmed the stop. ``jointid run``
did so already (exit 130, its summary, then "jointid run: interrupted: ..."): proved here too.

Real subprocesses, a real SIGINT, sent once the run's progress line shows payload 1 running
(the drives enabled): waits on what the child prints, never on a time."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from daq_campaigns import sine_toml
from robot_campaigns import ARM3
from test_monitor import _campaign, _model_dir

from daq.protocol.reader import read_run
from sim_drivers.arm import ArmParams
from trajectories.robot import load_robot

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.slow  # jointid subprocesses
MARKER = "payload 1/"  # the progress line of the first payload's run (the drive enabled)


def _jointid() -> list[str]:
    exe = shutil.which("jointid") or ""
    return [exe] if exe else [sys.executable, "-m", "daq.app.cli"]


def _interrupt_when_running(args: list[str], cwd: Path) -> tuple[int, str]:
    """Start ``jointid ARGS``, send SIGINT once its stderr shows ``MARKER``; (exit code,
    stderr)."""
    proc = subprocess.Popen([*_jointid(), *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, cwd=cwd,
                            env=dict(os.environ, PYTHONDONTWRITEBYTECODE="1"))
    err = bytearray()
    seen = threading.Event()

    def read() -> None:
        while chunk := proc.stderr.read1(4096):
            err.extend(chunk)
            if MARKER.encode() in err:
                seen.set()
        seen.set()  # the child ended (the test then fails on its output)

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        seen.wait(600)
        assert proc.poll() is None, f"ended before its run: {err.decode()[-2000:]}"
        proc.send_signal(signal.SIGINT)
        proc.stdout.read()
        proc.wait(600)
    finally:
        if proc.poll() is None:
            proc.kill()
        reader.join(60)
    return proc.returncode, err.decode(errors="replace")


def _interrupted_log(path: Path) -> None:
    """The log of the interrupted payload: complete, status interrupted, the operator's stop
    and the drive's confirmation (SWITCH ON DISABLED read back) as its last events."""
    a = read_run(path)
    assert not a.truncated
    assert a.metadata["result"]["status"] == "interrupted"
    assert a.metadata["result"]["reason"] == "interrupted by the operator (SIGINT)"
    kinds = [(e["kind"], e["message"]) for e in a.events]
    assert ("operator", "SIGINT: stopping") in kinds
    assert kinds[-1] == ("stop", "drives disabled")


def test_ctrl_c_in_the_demo_exits_130_with_the_drive_stopped(tmp_path):
    out = tmp_path / "demo"
    code, err = _interrupt_when_running(["demo", "--quick", "--out", str(out)], tmp_path)
    assert "Traceback" not in err, err[-3000:]
    assert code == 130, (code, err[-3000:])
    assert err.strip().splitlines()[-1] == (
        f"jointid: interrupted (SIGINT): the demo campaign stopped in payload 0 (drives "
        f"disabled); its logs are closed in {out / 'logs'}")
    assert "error" not in err
    assert sorted(p.name for p in (out / "logs").glob("*.mcap")) == [
        "rx130l-joint3_quick_payload0.mcap"]
    _interrupted_log(out / "logs" / "rx130l-joint3_quick_payload0.mcap")
    assert not (out / "report.html").exists() and not (out / "fit.json").exists()


def test_ctrl_c_in_run_exits_130_with_the_drive_stopped(tmp_path):
    src = tmp_path / "long.toml"
    src.write_text(sine_toml("long", "test_daqleft4_sigint_run", masses=(0.0, 2.0), periods=200))
    out = tmp_path / "runs"
    code, err = _interrupt_when_running(
        ["run", str(src), "--simulate", str(ROOT / "examples" / "plant_rx130l.toml"),
         "--yes", "--out", str(out)], tmp_path)
    assert "Traceback" not in err, err[-3000:]
    assert code == 130, (code, err[-3000:])
    lines = err.strip().replace("\r", "\n").splitlines()
    assert lines[-1] == "jointid run: interrupted: interrupted by the operator (SIGINT)"
    assert "campaign long: interrupted (interrupted by the operator (SIGINT))" in lines
    assert sorted(p.name for p in out.glob("*.mcap")) == ["long_payload0.mcap"]
    _interrupted_log(out / "long_payload0.mcap")
    assert not (out / "long.state.json").exists()  # nothing completed


def test_ctrl_c_in_monitor_calibration_exits_130_and_writes_no_thresholds(tmp_path):
    """``jointid monitor --calibrate`` interrupted: exit 130 (it returned 1, or 0 with
    --stop), and no thresholds.json from the few cycles run (it was written from them, and a
    later --thresholds run would have used it); an older one in the folder is removed."""
    robot = load_robot(ARM3)
    model = _model_dir(tmp_path, (robot, ArmParams.from_robot(robot)))
    camp = _campaign(tmp_path, "sigint")
    out = tmp_path / "cal"
    out.mkdir()
    (out / "thresholds.json").write_text("{}")  # an older calibration's
    code, err = _interrupt_when_running(
        ["monitor", str(model), str(camp), "--simulate", "--calibrate", "-o", str(out)],
        tmp_path)
    assert "Traceback" not in err, err[-3000:]
    assert code == 130, (code, err[-3000:])
    assert err.strip().splitlines()[-1] == (
        f"jointid: interrupted (SIGINT): the monitor run stopped; its log is closed in {out}")
    assert not (out / "thresholds.json").exists()
    s = json.loads((out / "monitor.json").read_text())
    assert s["status"] == "interrupted" and s["thresholds"] is None
    assert s["calibration"].startswith("not written: the validation run ended interrupted")
    (log,) = s["logs"]
    assert read_run(out / log).metadata["result"]["status"] == "interrupted"
