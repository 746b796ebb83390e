"""What a paced run changes for its duration to keep the cycle loop on time.

MCAP chunks compressed and written by a worker thread (``FastWriter.start_background`` /
``RunLog.background_chunks``): the log is the same as one written in the cycle loop, a write
error of the worker reaches the thread that logs (and is recognised as the log's, not the
bus's), the worker runs one real-time priority below the cycle loop, and a paced run uses
it. Python's GIL switch interval (``daq.switch_interval_s``): set during a paced run,
restored after it. Nothing here depends on how fast the machine is.
"""

from __future__ import annotations

import errno
import io
import json
import os
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
from daq_campaigns import sine_campaign
from mcap.reader import make_reader

from daq import ConfigError
from daq.protocol.logformat import FRAME
from daq.protocol.reader import read_run
from daq.runtime.config import parse_daq
from daq.runtime.mcaplog import FastWriter, RunLog
from daq.runtime.runner import run_campaign
from daq.runtime.safety import log_failed
from sim_drivers.plant_config import default_plant
from trajectories.robot_campaign import RobotCampaign

WORKER = "mcap-chunk-writer"


def _fill(log: RunLog, n: int) -> None:
    fr = FRAME.pack(1.5, 0x80, 0, b"") + FRAME.pack(1.5, 0x201, 4, b"\x0f\x00\x10\x00")
    for c in range(n):
        for ax in range(2):
            log.state(ax, c, c * 1e-3, 0.001 * c + ax, -0.5 * c, 2.0 * c, 3.0, c * 7 + ax,
                      -c, c % 1000, -(c % 1000), 0x1237, c & 1)
        log.setpoint(c, c * 1e-3, 0.002 * c, 0.1, 0.2, c // 100, 0)
        log.frames(c, fr, 2)
        if c == 500:
            log.event(c, c * 1e-3, "info", "half way", -1)


def _write(path, background: bool) -> None:
    log = RunLog(path, n_axes=2, cycle_s=0.001, chunk_seconds=0.02,
                 metadata={"payload": {"mass_kg": "1.0", "arm_m": "0.5"}},
                 attachments=[("c.toml", "application/toml", b"name = 'x'\n")])
    if background:
        log.background_chunks()
        assert any(t.name == WORKER for t in threading.enumerate())
    _fill(log, 2000)
    log.close({"status": "done"})


def _chunks(path) -> int:
    with open(path, "rb") as f:
        return len(make_reader(f).get_summary().chunk_indexes)


def test_background_chunks_write_the_same_log(tmp_path):
    fg, bg = tmp_path / "fg.mcap", tmp_path / "bg.mcap"
    _write(fg, background=False)
    _write(bg, background=True)
    assert not any(t.name == WORKER for t in threading.enumerate())  # ended by close()
    assert _chunks(bg) == _chunks(fg) > 10
    for ax in range(2):
        a, b = read_run(fg, axis=ax), read_run(bg, axis=ax)
        assert not b.truncated and b.metadata["result"]["status"] == "done"
        for name in ("cycle", "q", "dq", "tau_ref", "counts", "flags", "q_ref", "segment"):
            assert np.array_equal(getattr(a, name), getattr(b, name)), name
        assert b.events == a.events and len(b.events) == 1


class _FullDisk(io.BytesIO):
    """A stream that accepts ``limit`` bytes, then fails like a full disk."""

    def __init__(self, limit: int) -> None:
        super().__init__()
        self.limit = limit

    def write(self, data) -> int:  # noqa: ANN001 - io.BytesIO's signature
        if self.tell() + len(data) > self.limit:
            raise OSError(errno.ENOSPC, "No space left on device")
        return super().write(data)


def test_worker_write_error_reaches_the_logging_thread(tmp_path):
    f = _FullDisk(limit=600)  # the header fits, a chunk of 1 kB (incompressible) does not
    w = FastWriter(f, chunk_size=1000)
    w.start()
    w.start_background()
    for k in range(6):  # > one chunk: the worker writes it and fails
        w.add_message(0, k, os.urandom(200), k)
    with pytest.raises(OSError, match="No space left") as info:
        w.drain()
    assert log_failed(info.value)  # the engine's test: the log's file, not the bus
    size = len(f.getvalue())
    with pytest.raises(OSError, match="No space left"):  # the next full chunk raises too
        for k in range(20):
            w.add_message(0, k, os.urandom(200), k)
    assert len(f.getvalue()) == size  # nothing written after the failure
    with pytest.raises(OSError):
        w.stop_background()
    assert w._worker is None


def test_worker_runs_one_realtime_priority_below_the_loop():
    out: dict = {}

    def loop() -> None:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(10))
        except (PermissionError, OSError, AttributeError):
            out["skip"] = True
            return
        try:
            w = FastWriter(io.BytesIO(), chunk_size=100)
            w.start()
            w.start_background()
            w.add_message(0, 0, bytes(200), 0)  # one chunk through the worker
            w.drain()  # the worker set its priority before taking it
            tid = w._worker.native_id
            out["worker"] = (os.sched_getscheduler(tid), os.sched_getparam(tid).sched_priority)
            w.stop_background()
        finally:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))

    th = threading.Thread(target=loop)
    th.start()
    th.join()
    if out.get("skip"):
        pytest.skip("SCHED_FIFO not permitted here (needs CAP_SYS_NICE)")
    assert out["worker"] == (os.SCHED_FIFO, 9)


def _campaign(clock: str, **daq) -> RobotCampaign:
    return sine_campaign(f"paced_bg_{clock}", clock=clock, chunk_seconds=0.02, **daq)


def _run(tmp_path, c: RobotCampaign) -> tuple[object, list[tuple[set[str], float]]]:
    """Run ``c`` on the simulated drive; what the cycle loop's progress calls saw: the
    threads and the GIL switch interval."""
    seen: list[tuple[set[str], float]] = []

    def progress(p) -> None:  # noqa: ANN001 - called from the cycle loop
        seen.append(({t.name for t in threading.enumerate()}, sys.getswitchinterval()))

    r = run_campaign(c, out_dir=tmp_path, simulate=default_plant(), yes=True,
                     progress=progress)
    assert r.status == "done", r.reason
    assert seen
    return r, seen


def test_paced_run_writes_its_chunks_in_the_background(tmp_path):
    before = sys.getswitchinterval()
    r, seen = _run(tmp_path, _campaign("paced", switch_interval_s=0.0003))
    assert all(WORKER in names for names, _ in seen)
    assert not any(t.name == WORKER for t in threading.enumerate())
    run = r.runs[0]
    a = read_run(run.path)
    assert not a.truncated and np.array_equal(a.cycle, np.arange(run.cycles))
    assert _chunks(run.path) > 5
    # the switch interval of the run, and Python's again after it
    assert all(sw == pytest.approx(0.0003) for _, sw in seen)
    assert sys.getswitchinterval() == before


def test_switch_interval_zero_keeps_pythons(tmp_path):
    before = sys.getswitchinterval()
    _, seen = _run(tmp_path, _campaign("paced", switch_interval_s=0.0))
    assert all(sw == before for _, sw in seen)


def test_lockstep_run_changes_neither(tmp_path):
    before = sys.getswitchinterval()
    _, seen = _run(tmp_path, _campaign("lockstep", switch_interval_s=0.0003))
    assert not any(WORKER in names for names, _ in seen)
    assert all(sw == before for _, sw in seen)


def test_switch_interval_config():
    assert parse_daq({}).switch_interval_s == pytest.approx(0.0002)
    assert parse_daq({"switch_interval_s": 0}).switch_interval_s == 0
    with pytest.raises(ConfigError, match=r"c.toml: daq.switch_interval_s: .*>= 0"):
        parse_daq({"switch_interval_s": -0.001}, "c.toml")


PACED_FSIZE_SCRIPT = """
import json, resource, sys
resource.setrlimit(resource.RLIMIT_FSIZE, ({limit}, resource.RLIM_INFINITY))
sys.path.insert(0, {tests!r})
from daq.runtime.runner import run_campaign
from sim_drivers.plant_config import default_plant
from test_fault_injection_run import campaign
c = campaign({{"clock": "paced", "tpdo_timeout_cycles": 50, "heartbeat_timeout_s": 2.0,
              "max_following_error": 1.0}}, periods=20, n_payloads=1)
r = run_campaign(c, out_dir=sys.argv[1], simulate=default_plant(), yes=True)
run = r.runs[-1]
print(json.dumps({{"status": r.status, "reason": r.reason, "cycles": run.cycles,
                  "fault_cycle": run.fault_cycle, "path": str(run.path)}}))
"""


def test_paced_log_write_failure_in_the_worker_stops_the_run(tmp_path):
    """A file-size limit under a paced run's log (EFBIG; a full disk gives ENOSPC): the
    worker's write fails, the cycle loop hears of it at the next full chunk and stops the
    run with the log's own reason; the chunks written before stay readable."""
    limit = 400_000  # [byte]: header, attachments and a few seconds of data
    root = Path(__file__).resolve().parents[1]
    script = PACED_FSIZE_SCRIPT.format(limit=limit, tests=str(root / "tests"))
    out = tmp_path / "out"
    p = subprocess.run([sys.executable, "-c", script, str(out)], capture_output=True,
                       text=True, timeout=300,
                       env=dict(os.environ, OPENBLAS_NUM_THREADS="1", PYTHONPATH=str(root)))
    assert p.returncode == 0, p.stderr[-3000:]
    res = json.loads(p.stdout.strip().splitlines()[-1])
    log = out / "inj_payload0.mcap"
    assert res["status"] == "stopped"
    assert res["reason"] == f"log write failed: {log}: File too large"
    assert log.stat().st_size <= limit
    with pytest.warns(RuntimeWarning, match="truncated run log"):
        a = read_run(log)
    assert a.truncated and 100 <= len(a) <= res["fault_cycle"]
    assert np.array_equal(a.cycle, np.arange(len(a)))
