"""The master and the simulated drives in different processes, over a loopback bridge.

``python -m sim_drivers.serve --bridge-port 0`` (a subprocess, :class:`ServeProcess`) serves a
drive on a virtual bus and a python-can-remote bridge on ``ws://127.0.0.1:<port>/<token>``; the
test process runs the real master (``daq.runner.run_campaign``, ``[daq] interface =
"remote"``) against it and reads the log back. Every subprocess is bounded in time and
stopped in ``finally``.
"""

from __future__ import annotations

import itertools
import time

import can
import numpy as np
import pytest
from daq_campaigns import joint_campaign

from daq.protocol.cia402 import State, state_from_statusword
from daq.protocol.reader import read_frames, read_run
from daq.runtime.runner import run_campaign
from daq.runtime.simrig import plant_scaling
from sim_drivers.drive import TORQUE_DELAY_CYCLES
from sim_drivers.plant_config import default_plant
from sim_drivers.remote import ServeProcess
from trajectories.robot_campaign import RobotCampaign

_chan = itertools.count()
pytestmark = pytest.mark.slow  # subprocesses and paced (real-time) runs


def remote_campaign(url: str, node_id: int = 1, *, sync_source: str = "runner",
                    periods: int = 1, name: str = "xproc", cycle_s: float = 0.001,
                    **daq) -> RobotCampaign:
    sc = plant_scaling(default_plant())
    return joint_campaign(
        name, cycle_s=cycle_s,
        sine={"amplitude": 0.1, "frequency_hz": 0.5, "periods": periods},
        daq={"interface": "remote", "channel": url, "clock": "paced",
             "sync_source": sync_source,
             # a shared 2-core host stalls for tens of ms, now and then for more than the
             # default RPDO deadline (3 cycles + 100 ms: 0.138 s seen with two test suites
             # and a demo beside): the TPDO watchdog and the drives' RPDO deadline of this
             # test tolerate that (3 cycles + 400 ms, within the served drive's 0.5 s
             # SYNC-loss floor)
             "tpdo_timeout_cycles": 200, "rpdo_margin_ms": 400, "max_following_error": 0.5,
             # the start-up lateness check holds but never refuses these runs beside busy
             # loops (4 ms, two busy loops: 26-40 % late or missing, daq.runtime.safety)
             "lateness_warn": 1.0, "lateness_stop": 1.0,
             # the served drives are simulated single joints (serve prints their timing)
             "torque_delay_cycles": TORQUE_DELAY_CYCLES,
             "drives": [{"node_id": node_id, "scaling": {
                 "rated_torque_Nm": sc.rated_torque_Nm, "gear_ratio": sc.gear_ratio,
                 "encoder_counts_per_rev": sc.encoder_counts_per_rev}}],
             **daq})


#: control cycle of this file's paced runs [s]: 4 ms, so that a drive served in another
#: process through the loopback bridge answers in time on 2 busy cores (at 1 ms a quarter of
#: the TPDOs came late with both cores loaded, with today's code and the older one alike)
CYCLE_S = 0.004


@pytest.fixture
def served():
    # the drive's SYNC-loss floor at 0.5 s: a shared CI host stalls for 0.1 s now and then
    with ServeProcess((3,), channel=f"xproc{next(_chan)}",
                      args=("--sync-loss-floor", "0.5", "--cycle", str(CYCLE_S))) as s:
        yield s


@pytest.mark.parametrize("sync_source", ["runner", "periodic"])
def test_paced_campaign_against_drive_in_another_process(served, tmp_path, sync_source):
    assert served.url.startswith("ws://127.0.0.1:")
    c = remote_campaign(served.url, 3, sync_source=sync_source, periods=2, cycle_s=CYCLE_S)
    r = run_campaign(c, out_dir=tmp_path, prompt=lambda *a: True)
    assert r.ok, f"{r.reason}\nserve output:\n{served.output}"
    run = r.runs[0]
    a = read_run(run.path)
    assert a.metadata["campaign"]["interface"] == "remote"
    assert float(a.metadata["campaign"]["torque_delay_cycles"]) == TORQUE_DELAY_CYCLES == 0.5
    # the bridge's address is logged, its access token is not (anywhere in the file)
    base, token = served.url.rsplit("/", 1)
    assert f"{base}/<token>" in a.metadata["campaign"]["bus"]
    assert a.metadata["campaign"]["channel"] == f"{base}/<token>"
    assert token.encode() not in run.path.read_bytes()
    assert a.metadata["result"]["sync_offset"] == "-1"  # the drive is not ours
    # the RPDO deadline given to the drive in the other process, and read back from it
    assert a.metadata["safety"]["rpdo_timeout_ms"] == "412"
    assert a.metadata["drive0"]["rpdo_event_timer_ms"] == "412"
    assert np.array_equal(a.cycle, np.arange(run.cycles))
    ok = (a.flags & 1) == 0
    # most cycles answered (how many arrive in time is the host's: benchmarks, not here)
    assert ok.mean() > 0.5, f"TPDO missing in {np.sum(~ok)} of {ok.size} cycles"
    moving = (a.segment >= 0) & ok
    assert moving.sum() > 750  # of the plan's 2 periods x 2 s / 4 ms = 1000 moving cycles
    # the drive in the other process followed the plan: its encoder came back every cycle
    # (95 % of the moving cycles within 0.05 rad; a host stall of the loaded machine delays
    # the targets for a moment -- 0.094 rad once with two suites and a demo beside -- while a
    # wrong encoder scale, sign or unit would be off on most cycles)
    err = np.abs(a.q - a.q_ref)[moving]
    assert np.quantile(err, 0.95) < 0.05, np.quantile(err, [0.5, 0.95, 1.0])
    assert np.max(err) < 0.5 * np.ptp(a.q_ref[moving])
    assert np.ptp(a.q[moving]) > 0.15
    enabled = [state_from_statusword(int(s)) is State.OPERATION_ENABLED
               for s in a.statusword[moving]]
    assert all(enabled)
    frames = read_frames(run.path)
    ids = set(np.unique(frames["id"]).tolist())
    assert {0x203, 0x183, 0x283, 0x703} <= ids  # RPDO1, TPDO1/2, drive heartbeat
    # SYNC: logged when the runner sends it; a periodic SYNC runs in the bridge (python-can-
    # remote's send_periodic runs server side) and is not echoed back to the master
    assert (0x80 in ids) == (sync_source == "runner")
    assert "Traceback" not in served.output


def test_third_listener_sees_the_sync_train(served, tmp_path):
    """A passive client of the bridge (its own connection) receives every SYNC the master
    sends and every TPDO the drive answers with, in order."""
    listener = can.Bus(interface="remote", channel=served.url)
    got: list[can.Message] = []
    try:
        c = remote_campaign(served.url, 3, name="listened", cycle_s=CYCLE_S)
        r = run_campaign(c, out_dir=tmp_path, prompt=lambda *a: True)
        end = time.monotonic() + 5.0
        while time.monotonic() < end:
            m = listener.recv(0.2)
            if m is None:
                break
            got.append(m)
    finally:
        listener.shutdown()
    assert r.ok, r.reason
    run = r.runs[0]
    syncs = [m for m in got if m.arbitration_id == 0x80]
    logged = read_frames(run.path)
    n_sync_logged = int(np.sum(logged["id"] == 0x80))
    assert len(syncs) == n_sync_logged == run.cycles
    tpdo1 = [m for m in got if m.arbitration_id == 0x183]
    assert len(tpdo1) >= 0.9 * run.cycles
    period = np.diff([m.timestamp for m in syncs])
    assert np.median(period) == pytest.approx(CYCLE_S, abs=2e-4)


def test_serve_process_refuses_to_hang(tmp_path):
    """A serve process that cannot start (bad plant file) is reported within the bound,
    with its output, and leaves no process behind."""
    from sim_drivers import SimError

    bad = tmp_path / "plant.toml"
    bad.write_text("not = [valid\n")
    t0 = time.monotonic()
    with pytest.raises(SimError, match="did not start within"):
        ServeProcess((1,), channel="bad", args=("--plant", str(bad)), start_timeout_s=20.0)
    assert time.monotonic() - t0 < 20.0
