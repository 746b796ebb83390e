"""The n-dof arm on the bus: one ArmPlant behind k simulated drives stepping on SYNC."""

from __future__ import annotations

import queue

import can
import canopen
import numpy as np
import pytest

from sim_drivers import SimError
from sim_drivers.arm import ArmParams, ArmPlant
from sim_drivers.arm_bus import ArmOnBus
from sim_drivers.robots import ur10
from sim_drivers.testing import unique_channel

K = 3
NODES = (4, 5, 6)


@pytest.fixture(scope="module")
def params() -> ArmParams:
    return ArmParams.from_model(ur10(K))


def _enable(master: canopen.Network, arm: ArmOnBus) -> list[canopen.RemoteNode]:
    nodes = []
    for d in arm.drives:
        node = master.add_node(d.node_id, str(d.dod.path))
        node.sdo[0x6060].raw = 10
        for cw in (6, 7, 15):
            node.sdo[0x6040].raw = cw
        nodes.append(node)
    master.nmt.state = "OPERATIONAL"
    for node in nodes:
        node.sdo[0x1000].raw  # noqa: B018 - barrier: NMT start processed
    return nodes


@pytest.mark.parametrize("dispatch", ["inline", "thread"])
def test_one_arm_steps_once_per_sync_with_every_joints_torque(params, dispatch):
    """A master on python-can's VirtualBus closes a PD loop over the bus (CST); the counts it
    receives equal an offline ArmPlant stepped with the torques the drives recorded."""
    ch = unique_channel("armbus")
    q0 = np.array([0.1, -0.6, 0.4])
    arm = ArmOnBus(params, ch, NODES, cycle_s=0.001, q0=q0, seed=3, dispatch=dispatch)
    master = canopen.Network(can.Bus(interface="virtual", channel=ch))
    master.NOTIFIER_CYCLE = 0.05
    master.connect()
    try:
        _enable(master, arm)
        q: queue.SimpleQueue = queue.SimpleQueue()
        for n in NODES:
            master.subscribe(0x180 + n, lambda cid, data, ts: q.put((cid, bytes(data))))
        cpr = params.drive.counts_per_rad
        tpu = params.drive.torque_per_permille
        counts = np.zeros((0, K), dtype=np.int64)
        now = np.rint(q0 * cpr).astype(np.int64)
        n_cycles = 150
        received = np.zeros((n_cycles, K), dtype=np.int64)
        for c in range(n_cycles):
            qm = now / cpr
            tau = 800.0 * (q0 + 0.05 * np.sin(c / 40.0) - qm)  # PD-less P loop: enough here
            x = np.clip(np.rint(tau / tpu), -30000, 30000).astype(int)
            for k, n in enumerate(NODES):
                master.send_message(0x200 + n, np.array([15, x[k]], "<i2").tobytes())
            master.send_message(0x80, b"")
            for _ in range(K):
                cid, data = q.get(timeout=2.0)
                now[NODES.index(cid - 0x180)] = int.from_bytes(data[2:6], "little", signed=True)
            received[c] = now
        with pytest.raises(queue.Empty):
            q.get(timeout=0.05)  # no duplicate TPDO
        assert arm.steps == n_cycles - 1  # first SYNC: no torque commanded before it
        # the same arm offline: step k applies the torques the drives took at SYNC k
        tau_cmd = np.stack([d.record["tau_cmd"] for d in arm.drives], axis=1)
        assert tau_cmd.shape == (n_cycles, K)
        off = ArmPlant(params, 0.001, seed=3)
        off.reset(q0)
        for c in range(1, n_cycles):
            off.step(tau_cmd[c - 1])
            assert np.array_equal(received[c], np.rint(off.q * cpr).astype(np.int64)), c
        assert np.abs(received[-1] / cpr - q0).max() < 0.2  # the loop held the arm
        counts = np.stack([d.record["counts"] for d in arm.drives], axis=1)
        assert np.array_equal(counts, received)  # what the drives sent is what arrived
    finally:
        master.disconnect()
        arm.close()


def test_node_ids_must_match_the_joints(params):
    with pytest.raises(SimError, match="expected 3 node ids"):
        ArmOnBus(params, unique_channel("armbus"), (1, 2), cycle_s=0.001)
