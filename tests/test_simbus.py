"""SimBus / SimNetwork: the simulated drives' shared end of a python-can virtual channel."""

from __future__ import annotations

import queue
import threading
import time

import can
import canopen
import numpy as np
import pytest
from can.interfaces import virtual

from sim_drivers import SimError
from sim_drivers.drive import SimulatedDrive
from sim_drivers.plant import JointPlant
from sim_drivers.plant_config import default_plant
from sim_drivers.simbus import SimBus, SimNetwork
from sim_drivers.testing import unique_channel

# a bus thread dying at shutdown (e.g. a notifier reading a closed bus) fails the test
pytestmark = pytest.mark.filterwarnings("error::pytest.PytestUnhandledThreadExceptionWarning")


def _frame(cid: int, data: bytes) -> can.Message:
    return can.Message(arbitration_id=cid, data=data, is_extended_id=False)


def test_inline_delivery_happens_inside_the_senders_send():
    ch = unique_channel("simbus")
    sim = SimBus(ch, dispatch="inline")
    master = can.Bus(interface="virtual", channel=ch)
    try:
        got: list[tuple[int, bytes, bool, str, threading.Thread]] = []

        class L(can.Listener):
            def on_message_received(self, msg: can.Message) -> None:
                got.append((msg.arbitration_id, bytes(msg.data), msg.is_rx, msg.channel,
                            threading.current_thread()))

        sim.add_listener(L())
        master.send(_frame(0x201, b"\x0f\x00\x10\x00"))
        assert got == [(0x201, b"\x0f\x00\x10\x00", True, ch, threading.current_thread())]
        assert sim.recv(0.0) is None  # inline: nothing queued
        # the other way: a fresh message, stamped like VirtualBus does
        t0 = time.time()
        sim.send(_frame(0x181, b"\x37\x12\x01\x02\x03\x04\x05\x06"))
        sim.send_frame(0x281, b"\x01\x02\x03\x04\x05")
        m1, m2 = master.recv(1.0), master.recv(1.0)
        assert (m1.arbitration_id, bytes(m1.data), m1.dlc) == (0x181, bytes.fromhex(
            "3712010203040506"), 8)
        assert (m2.arbitration_id, bytes(m2.data), m2.dlc) == (0x281, b"\x01\x02\x03\x04\x05",
                                                                 5)
        for m in (m1, m2):
            assert m.is_rx and m.channel == ch and not m.is_extended_id
            assert t0 <= m.timestamp <= time.time()
        assert (sim.frames_in, sim.frames_out) == (1, 2)
        with pytest.raises(SimError, match="already has an inline SimBus"):
            SimBus(ch, dispatch="inline")
    finally:
        master.shutdown()
        sim.shutdown()
    assert ch not in virtual.channels  # the channel is gone with its last bus
    with pytest.raises(can.CanOperationError):
        sim.send(_frame(0x181, b""))
    sim.put(_frame(0x80, b""))  # a late frame to a closed SimBus is dropped, not raised


def test_thread_mode_is_an_ordinary_queued_bus():
    ch = unique_channel("simbus")
    sim = SimBus(ch, dispatch="thread")
    master = can.Bus(interface="virtual", channel=ch)
    reader = can.BufferedReader()
    notifier = can.Notifier(sim, [reader], 0.05)
    try:
        for i in range(50):
            master.send(_frame(0x200 + i, bytes([i])))
        ids = []
        for _ in range(50):
            m = reader.get_message(1.0)
            assert m is not None
            ids.append((m.arbitration_id, bytes(m.data)))
        assert ids == [(0x200 + i, bytes([i])) for i in range(50)]  # order kept
    finally:
        notifier.stop(1.0)
        master.shutdown()
        sim.shutdown()


TPDOS = {1: ("<Hi", ("6041", "6064")), 2: ("<hi", ("6077", "606C"))}


def _lockstep(dispatch: str, nodes=(1, 2, 3), cycles=300):
    """3 drives on one SimNetwork, a canopen master on python-can's VirtualBus: SDO, NMT,
    CiA 402 enable, then lockstep CST cycles (RPDO per drive + SYNC, 2 TPDOs per drive)."""
    ch = unique_channel("simnet")
    threads_before = {t.ident for t in threading.enumerate()}
    sim = SimNetwork(ch, dispatch=dispatch)
    master = canopen.Network(can.Bus(interface="virtual", channel=ch))
    master.NOTIFIER_CYCLE = 0.05
    master.connect()
    try:
        drives = []
        for k, nid in enumerate(nodes):
            plant = JointPlant(default_plant(), 0.001, seed=10 + k)
            plant.reset(0.0)
            drives.append(sim.add(SimulatedDrive(sim.network, nid, plant)))
        remotes = []
        for nid in nodes:
            node = master.add_node(nid, str(drives[0].dod.path))
            node.sdo[0x6060].raw = 10
            for cw in (6, 7, 15):
                node.sdo[0x6040].raw = cw
            remotes.append(node)
        master.nmt.state = "OPERATIONAL"  # broadcast
        for node in remotes:
            node.sdo[0x1000].raw  # noqa: B018 - barrier: NMT start processed
        q: queue.SimpleQueue = queue.SimpleQueue()
        cobs = {0x180 + n: (k, 0) for k, n in enumerate(nodes)}
        cobs.update({0x280 + n: (k, 1) for k, n in enumerate(nodes)})
        for cob in cobs:
            master.subscribe(cob, lambda cid, data, ts: q.put((cid, bytes(data))))
        x = (200 * np.sin(np.arange(cycles)[:, None] / 30.0 + np.arange(len(nodes)))).astype(
            int)
        counts = np.zeros((cycles, len(nodes)), dtype=np.int64)
        for c in range(cycles):
            for k, nid in enumerate(nodes):
                master.send_message(0x200 + nid, np.array([15, x[c, k]], "<i2").tobytes())
            master.send_message(0x80, b"")
            for _ in range(2 * len(nodes)):
                cid, data = q.get(timeout=2.0)
                k, which = cobs[cid]
                if which == 0:
                    counts[c, k] = int.from_bytes(data[2:6], "little", signed=True)
        time.sleep(0.05)
        assert q.empty(), "duplicated TPDO"
        for k, d in enumerate(drives):
            rec = d.record
            assert len(rec["cycle"]) == cycles
            assert np.array_equal(rec["counts"], counts[:, k])  # every TPDO, in order
            # the RPDO sent before SYNC c is latched and applied at SYNC c
            assert np.array_equal(rec["target_torque"], x[:, k])
        return drives
    finally:
        master.disconnect()
        sim.close()
        # every thread the rig started (notifier, heartbeat tasks, watchdogs) has ended
        end = time.monotonic() + 2.0
        while time.monotonic() < end and [t for t in threading.enumerate()
                                          if t.ident not in threads_before]:
            time.sleep(0.01)
        left = [t.name for t in threading.enumerate() if t.ident not in threads_before]
        assert not left, left


@pytest.mark.parametrize("dispatch", ["inline", "thread"])
def test_three_drives_share_one_network(dispatch):
    _lockstep(dispatch)


def test_inline_and_thread_dispatch_give_the_same_records():
    a = _lockstep("inline", cycles=200)
    b = _lockstep("thread", cycles=200)
    for da, db in zip(a, b, strict=True):
        ra, rb = da.record, db.record
        for key in ("counts", "target_torque", "tau_applied", "statusword"):
            assert np.array_equal(ra[key], rb[key]), key


def test_a_drive_from_another_network_is_refused():
    with SimNetwork(unique_channel("simnet")) as sim:
        other = canopen.Network()
        plant = JointPlant(default_plant(), 0.001, seed=1)
        with pytest.raises(SimError, match="built on another network"):
            sim.add(SimulatedDrive(other, 3, plant))
