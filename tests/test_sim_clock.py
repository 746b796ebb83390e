"""Simulated time in lockstep: heartbeats paced by SYNC and watchdogs judged on SYNC count.

A clocked :class:`sim_drivers.simbus.SimNetwork` (``sync_cycle_s``) paces every periodic send of
its channel by the SYNCs it receives; a drive with ``clock="sync"`` runs its heartbeat consumer
on the SYNCs it received; the runner's ``--simulate`` lockstep rig uses both and judges the
drives' heartbeats on its own SYNC count. Wall-time pauses without SYNC are then nothing, and
a heartbeat loss is detected at a reproducible cycle. (The wall-clock watchdogs are tested in
test_safety_drive.py, test_safety_run.py, test_rpdo_timeout.py and test_cross_process_kill.py.)
"""

from __future__ import annotations

import itertools
import time

import can
import canopen
import numpy as np
import pytest
from daq_campaigns import joint_campaign

from daq.protocol.cia402 import State, path
from daq.protocol.reader import read_frames, read_run
from daq.runtime.runner import run_campaign
from sim_drivers import SimError
from sim_drivers.drive import DriveError, SimulatedDrive
from sim_drivers.faults import HEARTBEAT_LOST, FaultInjector
from sim_drivers.plant import JointPlant
from sim_drivers.plant_config import default_plant
from sim_drivers.simbus import SimBus, SimNetwork, SyncPeriodicTask
from sim_drivers.testing import unique_channel

NODE = 5
MASTER = 127
SYNC = can.Message(arbitration_id=0x80, data=b"", is_extended_id=False)
_chan = itertools.count()


def _hb(node: int, state: int = 5) -> can.Message:
    return can.Message(arbitration_id=0x700 + node, data=bytes([state]), is_extended_id=False)


class Recorder(can.Listener):
    """Frames of one COB-ID received by an inline SimBus, with the channel's SYNC count."""

    def __init__(self, sim: SimBus, cob: int) -> None:
        self.sim, self.cob, self.at = sim, cob, []

    def on_message_received(self, msg: can.Message) -> None:
        if msg.arbitration_id == self.cob:
            self.at.append(self.sim.sync_count)


def test_periodic_sends_on_a_clocked_channel_follow_the_syncs_not_the_wall_clock():
    ch = unique_channel("clock")
    sim = SimBus(ch, dispatch="inline", sync_cycle_s=0.001)
    master = SimBus(ch, dispatch="thread")
    rec = Recorder(sim, 0x700 + MASTER)
    sim.add_listener(rec)
    try:
        for _ in range(3):
            master.send(SYNC)
        task = master.send_periodic(_hb(MASTER), 0.1)  # 100 SYNCs of 1 ms
        assert isinstance(task, SyncPeriodicTask) and task.every == 100
        assert rec.at == [3]  # one frame at start, like python-can's thread task
        time.sleep(0.35)  # wall time without SYNC: no simulated time, no frame
        assert rec.at == [3]
        for _ in range(250):
            master.send(SYNC)
        assert rec.at == [3, 103, 203]
        task.modify_data(_hb(MASTER, 0x7F))  # new data, same pace
        for _ in range(100):
            master.send(SYNC)
        assert rec.at == [3, 103, 203, 303]
        task.stop()
        for _ in range(300):
            master.send(SYNC)
        assert rec.at == [3, 103, 203, 303] and sim.sync_count == 653
        # with a duration [s] of simulated time: ends by itself
        rec.at.clear()
        master.send_periodic(_hb(MASTER), 0.01, duration=0.05)
        for _ in range(100):
            master.send(SYNC)
        assert rec.at == [653, 663, 673, 683, 693]
    finally:
        master.shutdown()
        sim.shutdown()


def test_without_sync_cycle_periodic_sends_stay_on_the_wall_clock():
    ch = unique_channel("clock")
    sim = SimBus(ch, dispatch="inline")
    master = SimBus(ch, dispatch="thread")
    try:
        task = master.send_periodic(_hb(MASTER), 0.01)
        assert not isinstance(task, SyncPeriodicTask)
        task.stop()
    finally:
        master.shutdown()
        sim.shutdown()
    with pytest.raises(SimError, match="sync_cycle_s"):
        SimBus(unique_channel("clock"), dispatch="thread", sync_cycle_s=0.001)
    with pytest.raises(DriveError, match="clock: expected one of"):
        SimulatedDrive(canopen.Network(), NODE, JointPlant(default_plant(), 0.001),
                       clock="simulated")


def test_sync_clock_drive_times_out_the_master_heartbeat_at_a_fixed_sync():
    """Consumer time 400 ms, master heartbeat every 100 ms, both on the channel's SYNCs: no
    timeout however long the wall-clock pauses; once the heartbeat stops, EMCY 0x8130 and
    FAULT at the first SYNC 400 ms of simulated time after the last heartbeat."""
    ch = unique_channel("clock")
    sim = SimNetwork(ch, dispatch="inline", sync_cycle_s=0.001)
    plant = JointPlant(default_plant(), 0.001, seed=1)
    plant.reset(0.0)
    drive = sim.add(SimulatedDrive(sim.network, NODE, plant, clock="sync"))
    bus = SimBus(ch, dispatch="thread")
    net = canopen.Network(bus)
    net.NOTIFIER_CYCLE = 0.05
    net.connect()
    emcy: list[int] = []
    net.subscribe(0x80 + NODE, lambda cid, data, ts: emcy.append(data[0] | data[1] << 8))
    task = None
    try:
        node = net.add_node(NODE, str(drive.dod.path))
        node.sdo[0x1016][1].raw = (MASTER << 16) | 400
        node.sdo[0x6060].raw = 10
        for _, cw in path(State.SWITCH_ON_DISABLED, State.OPERATION_ENABLED):
            node.sdo[0x6040].raw = cw
        task = bus.send_periodic(_hb(MASTER), 0.1)  # monitoring starts at its first frame
        net.nmt.state = "OPERATIONAL"
        node.sdo[0x1000].raw  # noqa: B018 - barrier: NMT start processed
        assert drive.heartbeat_consumers[MASTER][:2] == (0.4, True)
        heard = []  # drive.syncs at each master heartbeat received
        for k in range(1000):
            bus.send(SYNC)
            if drive.heartbeat_consumers[MASTER][2] > len(heard) + 1:
                heard.append(drive.syncs)
            if k in (100, 500):
                time.sleep(0.6)  # a host stall longer than the consumer time: no SYNC
        assert np.all(np.diff(heard) == 100)
        assert drive.heartbeat_timeouts == 0 and drive.state is State.OPERATION_ENABLED
        task.stop()
        last = heard[-1]
        while drive.state is not State.FAULT and drive.syncs < last + 1000:
            bus.send(SYNC)
        assert drive.state is State.FAULT and drive.heartbeat_timeouts == 1
        # 400 ms after the last heartbeat, judged on SYNC x 1 ms (float rounding: +1)
        assert last + 400 <= drive.syncs <= last + 401
        assert node.sdo[0x603F].raw == HEARTBEAT_LOST
        assert emcy == [HEARTBEAT_LOST]
    finally:
        if task is not None:
            task.stop()
        net.disconnect()
        sim.close()


def campaign(daq=None, periods=2):
    return joint_campaign(
        "clocked", cycle_s=0.001,
        sine={"amplitude": 0.3, "frequency_hz": 0.5, "periods": periods},
        daq={"channel": f"test_clock_{next(_chan)}", "quick_stop_cycles": 2, **(daq or {})})


def test_simulated_lockstep_run_paces_heartbeats_by_sync_and_a_stall_is_nothing(tmp_path):
    """The drive's heartbeats in the log come every 100 cycles exactly (SYNC-paced), also
    across a 1.2 s wall-clock stall of the main loop (longer than the consumer time and the master's
    heartbeat timeout), and the run ends normally."""
    stalled = {}

    def progress(p):
        if p.phase == "run" and p.cycle > 1000 and "at" not in stalled:
            stalled["at"] = p.cycle
            time.sleep(1.2)

    r = run_campaign(campaign(), out_dir=tmp_path, simulate=default_plant(), yes=True,
                     progress=progress)
    assert r.ok, r.reason
    assert "at" in stalled
    fr = read_frames(r.runs[0].path)
    hb = fr["cycle"][fr["id"] == 0x700 + 1]
    assert len(hb) >= len(read_run(r.runs[0].path)) // 100 - 1
    # the first is the start-up's (logged with cycle 0's frames); the run's are logged at the
    # cycle whose SYNC made them (the master takes every queued frame each cycle): 99, 199, ..
    assert hb[0] == 0 and hb[1] == 99, hb[:3]
    assert np.all(np.diff(hb[1:]) == 100), np.diff(hb)


def test_heartbeat_loss_is_detected_at_the_same_cycle_every_time(tmp_path):
    """The drive stops heartbeating at its cycle 300: the master's watchdog (0.3 s, checked
    every 16 cycles) stops the run at one cycle, the same in two runs, 300-316 cycles after
    the last heartbeat in the log."""
    cycles = []
    for k in range(2):
        inj = FaultInjector(stop_heartbeat_at_cycle=300)
        r = run_campaign(campaign({"heartbeat_timeout_s": 0.3}), out_dir=tmp_path / str(k),
                         simulate=default_plant(), yes=True, fault_injectors={1: inj})
        assert r.status == "stopped" and "heartbeat lost" in r.reason, r.reason
        fr = read_frames(r.runs[0].path)
        last = int(fr["cycle"][fr["id"] == 0x700 + 1].max())
        f = r.runs[0].fault_cycle
        assert 300 < f - last <= 300 + 16, (f, last)
        cycles.append((f, last))
    assert cycles[0] == cycles[1]
