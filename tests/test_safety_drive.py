"""Master loss seen from the simulated drive: heartbeat consumer 0x1016 and SYNC watchdog 0x1006.

Real drive, real master frames on python-can's virtual bus (:func:`sim_drivers.testing.make_rig`),
the master's heartbeat from :class:`daq.runtime.master.MasterHeartbeat`. Timings are checked against
the configured consumer time / SYNC timeout with generous upper margins (the host is shared);
the lower bounds (never before the configured time) are exact.
"""

from __future__ import annotations

import time

import numpy as np
import pytest
from canopen.sdo.exceptions import SdoAbortedError

from daq.protocol.cia402 import State, path, state_from_statusword
from daq.runtime.master import MasterHeartbeat
from sim_drivers.drive import SYNC_LOSS_FLOOR_S, SYNC_LOSS_PERIODS
from sim_drivers.faults import HEARTBEAT_LOST, SYNC_LOST, error_register
from sim_drivers.testing import LockstepMaster, make_rig

NODE = 9
MASTER = 127
TPDOS = {
    0x180 + NODE: ("<Hi", ("6041", "6064")),
    0x280 + NODE: ("<hi", ("6077", "606C")),
}
SLACK_S = 2.0  # how long to wait for something that must happen [s]
MARGIN_S = 0.25  # allowed lateness of a reaction on a loaded host [s]


@pytest.fixture
def rig():
    r = make_rig(node_id=NODE)
    yield r
    r.close()


def _enable_cst(rig) -> LockstepMaster:
    rig.node.sdo[0x6060].raw = 10
    for _, cw in path(State.SWITCH_ON_DISABLED, State.OPERATION_ENABLED):
        rig.node.sdo[0x6040].raw = cw
    rig.node.nmt.state = "OPERATIONAL"
    rig.node.sdo[0x1000].raw  # noqa: B018 - barrier: NMT start processed
    return LockstepMaster(rig.network, 0x200 + NODE, "<Hh", TPDOS)


def _wait_for(pred, timeout: float) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(0.005)
    return pred()


def _emcy_codes(rig) -> list[int]:
    return [e.code for e in rig.node.emcy.log]


def test_heartbeat_loss_faults_an_enabled_drive_with_emcy_8130(rig):
    consumer_ms, period_ms = 250, 50
    rig.node.sdo[0x1016][1].raw = (MASTER << 16) | consumer_ms
    assert rig.node.sdo[0x1016][1].raw == (MASTER << 16) | consumer_ms
    assert rig.drive.heartbeat_consumers == {MASTER: (0.25, False, 0)}  # not before the 1st
    hb = MasterHeartbeat(rig.network.bus, MASTER, period_ms)
    hb.start()
    try:
        master = _enable_cst(rig)
        res = master.run(0x0F, np.full(300, 100))
        assert state_from_statusword(int(res.received["6041"][-1])) is State.OPERATION_ENABLED
        assert _wait_for(lambda: rig.drive.heartbeat_consumers[MASTER][2] >= 3, SLACK_S)
        assert rig.drive.heartbeat_consumers[MASTER][1]  # monitoring started
        # the master dies: no heartbeat, no SYNC
        hb.stop()
        t_stop = time.monotonic()
        assert _wait_for(lambda: rig.drive.state is State.FAULT, consumer_ms / 1000 + SLACK_S)
        delay = rig.drive.fault_time - t_stop
        # the last heartbeat left at most one period before t_stop
        assert delay >= (consumer_ms - period_ms) / 1000 - 0.005
        assert delay <= consumer_ms / 1000 + MARGIN_S
        assert _wait_for(lambda: HEARTBEAT_LOST in _emcy_codes(rig), SLACK_S)
        assert rig.node.sdo[0x603F].raw == HEARTBEAT_LOST
        assert rig.node.sdo[0x1001].raw == error_register(HEARTBEAT_LOST) == 0x11
        assert rig.drive.heartbeat_timeouts == 1
        # a late SYNC finds the power stage off
        res = master.run(0x0F, np.full(3, 100))
        assert [state_from_statusword(int(s)) for s in res.received["6041"]] == [State.FAULT] * 3
        assert np.all(rig.drive.record["tau_cmd"][-3:] == 0.0)
        master.close()
    finally:
        hb.stop()


def test_heartbeat_loss_outside_operation_is_emcy_only_and_monitoring_restarts(rig):
    consumer_ms = 150
    rig.node.sdo[0x1016][2].raw = (MASTER << 16) | consumer_ms
    hb = MasterHeartbeat(rig.network.bus, MASTER, 30)
    hb.start()
    try:
        assert _wait_for(lambda: rig.drive.heartbeat_consumers[MASTER][1], SLACK_S)
        hb.stop()
        assert _wait_for(lambda: rig.drive.heartbeat_timeouts == 1, consumer_ms / 1000 + SLACK_S)
        assert _wait_for(lambda: _emcy_codes(rig) == [HEARTBEAT_LOST], SLACK_S)
        assert rig.drive.state is State.SWITCH_ON_DISABLED  # nothing to stop
        assert rig.node.emcy.log[0].register & 0x10  # communication error bit
        time.sleep(2 * consumer_ms / 1000)
        assert rig.drive.heartbeat_timeouts == 1  # reported once per loss
        hb.start()  # the master is back: monitoring restarts, a second loss is reported again
        assert _wait_for(lambda: not rig.drive._consumers[2].timed_out, SLACK_S)
        hb.stop()
        assert _wait_for(lambda: rig.drive.heartbeat_timeouts == 2, consumer_ms / 1000 + SLACK_S)
    finally:
        hb.stop()


def test_consumer_entries_are_validated_and_reset_with_communication(rig):
    sdo = rig.node.sdo[0x1016]
    assert sdo[0].raw == 2
    sdo[1].raw = (MASTER << 16) | 300
    with pytest.raises(SdoAbortedError) as err:  # the same node twice (CiA 301)
        sdo[2].raw = (MASTER << 16) | 500
    assert err.value.code == 0x06040043
    sdo[2].raw = (5 << 16) | 500
    assert set(rig.drive.heartbeat_consumers) == {MASTER, 5}
    sdo[2].raw = (5 << 16) | 0  # time 0: entry off
    assert set(rig.drive.heartbeat_consumers) == {MASTER}
    rig.node.nmt.send_command(0x82)  # reset communication: 0x1016 back to the EDS (0)
    assert _wait_for(lambda: rig.drive.heartbeat_consumers == {}, SLACK_S)
    assert sdo[1].raw == 0


def test_sync_loss_in_cyclic_mode_faults_with_8100(rig):
    rig.node.sdo[0x1006].raw = 1000  # 1 ms cycle
    timeout = max(SYNC_LOSS_PERIODS * 0.001, SYNC_LOSS_FLOOR_S)
    assert rig.drive.sync_timeout_s == pytest.approx(timeout)
    master = _enable_cst(rig)
    res = master.run(0x0F, np.full(200, 50))
    assert state_from_statusword(int(res.received["6041"][-1])) is State.OPERATION_ENABLED
    last_sync = rig.drive.last_sync_time
    n_before = len(rig.drive.record["cycle"])
    # the master hangs: no more SYNC
    assert _wait_for(lambda: rig.drive.state is State.FAULT, timeout + SLACK_S)
    delay = rig.drive.fault_time - last_sync
    assert timeout <= delay <= timeout + MARGIN_S  # armed by NMT start, too
    assert _wait_for(lambda: SYNC_LOST in _emcy_codes(rig), SLACK_S)
    assert rig.node.sdo[0x603F].raw == SYNC_LOST
    assert rig.drive.sync_losses == 1
    assert len(rig.drive.record["cycle"]) == n_before  # no cycle ran after the last SYNC
    master.close()


def test_sync_watchdog_off_with_1006_zero_and_outside_operation(rig):
    assert rig.drive.sync_timeout_s == 0.0  # EDS default 0x1006 = 0
    master = _enable_cst(rig)
    master.run(0x0F, np.full(20, 50))
    time.sleep(SYNC_LOSS_FLOOR_S * 3)  # lockstep pause: not a fault with 0x1006 = 0
    res = master.run(0x0F, np.full(20, 50))
    assert [state_from_statusword(int(s)) for s in res.received["6041"]] == (
        [State.OPERATION_ENABLED] * 20)
    # armed, but the drive is not enabled: nothing to stop
    master.run(0x06, np.zeros(3))  # shutdown -> READY TO SWITCH ON
    rig.node.sdo[0x1006].raw = 1000
    time.sleep(SYNC_LOSS_FLOOR_S * 3)
    assert rig.drive.state is State.READY_TO_SWITCH_ON
    assert rig.drive.sync_losses == 0
    # enabling arms it from the moment of enabling (not from a stale last SYNC)
    master.run(0x0F, np.zeros(1))
    assert rig.drive.state is State.OPERATION_ENABLED
    master.run(0x0F, np.zeros(5))
    assert rig.drive.state is State.OPERATION_ENABLED
    assert _emcy_codes(rig) == []
    master.close()
