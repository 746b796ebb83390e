"""RPDO deadline monitoring (CiA 301 event timer 0x1400 sub 5) of the simulated drive, and
which vendor EDS files declare it.

Real drive, real frames on python-can's virtual bus (:func:`sim_drivers.testing.make_rig`);
the SYNC keeps coming from a periodic task while the master's RPDOs stop (a hung master
whose SYNC is sent by the kernel or a bridge). Lower bounds exact, upper bounds with a
margin for the shared host.
"""

from __future__ import annotations

import time

import canopen
import numpy as np
import pytest

from daq import ConfigError
from daq.protocol.cia402 import State, path, state_from_statusword
from daq.runtime.config import parse_daq
from daq.runtime.master import MasterDrive, rpdo_timeout_ms
from sim_drivers.faults import RPDO_TIMEOUT
from sim_drivers.testing import LockstepMaster, make_rig
from tests.conftest import VENDOR_EDS, shared_path

NODE = 9
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


def _enable_cst(rig, timer_ms: int) -> LockstepMaster:
    rig.node.sdo[0x1400][5].raw = timer_ms
    assert rig.node.sdo[0x1400][5].raw == timer_ms
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


@pytest.mark.parametrize("timer_ms", [20, 120])
def test_rpdo_timeout_faults_with_8250_while_sync_continues(rig, timer_ms):
    master = _enable_cst(rig, timer_ms)
    res = master.run(0x0F, np.full(100, 50))
    assert state_from_statusword(int(res.received["6041"][-1])) is State.OPERATION_ENABLED
    assert rig.drive.rpdo_timers[1][0] == pytest.approx(timer_ms / 1000)
    # the master hangs, its SYNC keeps coming (periodic task: a thread on the virtual bus)
    rig.network.sync.start(0.001)
    try:
        last_rpdo = rig.drive.rpdo_timers[1][1]
        n0 = len(rig.drive.record["cycle"])
        assert _wait_for(lambda: rig.drive.state is State.FAULT, timer_ms / 1000 + SLACK_S)
        delay = rig.drive.fault_time - last_rpdo
        assert timer_ms / 1000 <= delay <= timer_ms / 1000 + MARGIN_S
        if timer_ms >= 100:  # (the periodic thread may take longer than 20 ms to start)
            # SYNCs arrived after the last RPDO: the SYNC watchdog could not catch it
            assert len(rig.drive.record["cycle"]) > n0
        assert _wait_for(lambda: RPDO_TIMEOUT in [e.code for e in rig.node.emcy.log], SLACK_S)
    finally:
        rig.network.sync.stop()
    assert rig.node.sdo[0x603F].raw == RPDO_TIMEOUT
    assert rig.node.sdo[0x1001].raw & 0x11 == 0x11  # generic + communication
    assert rig.drive.rpdo_timeouts == 1
    # power stage off: the plant is no longer stepped, the torque command is 0
    assert rig.drive.tau_cmd == 0.0
    master.close()


def test_rpdo_deadline_not_armed_when_off_disabled_or_never_received(rig):
    # timer 0 (EDS default): RPDOs may stop, SYNC goes on, nothing happens
    master = _enable_cst(rig, 0)
    master.run(0x0F, np.full(20, 50))
    assert rig.drive.rpdo_timers == {}
    rig.network.sync.start(0.001)
    try:
        time.sleep(0.15)
        assert rig.drive.state is State.OPERATION_ENABLED
        rig.network.sync.stop()
        # timer set, then the layout is rebuilt at the next SYNC: monitoring starts at the
        # first reception afterwards; RPDO then silence while NOT enabled: no fault
        rig.node.sdo[0x1400][5].raw = 150
        master.run(0x06, np.zeros(3))  # shutdown -> READY TO SWITCH ON
        assert rig.drive.rpdo_timers[1][0] == pytest.approx(0.15)
        rig.network.sync.start(0.001)
        time.sleep(0.4)
        assert rig.drive.state is State.READY_TO_SWITCH_ON
        rig.network.sync.stop()
        # enabled again by RPDO, RPDOs keep coming with every SYNC: no fault
        # (the TPDOs of the SYNC-only stretch are still queued: the state is read directly)
        master.run(0x0F, np.zeros(300))
        assert rig.drive.state is State.OPERATION_ENABLED, (
            rig.drive.rpdo_timeouts, [hex(e.code) for e in rig.node.emcy.log])
    finally:
        rig.network.sync.stop()
    assert rig.drive.rpdo_timeouts == 0
    master.close()


def test_master_timer_rule():
    assert rpdo_timeout_ms(0.001, paced=True) == 103  # 3 cycles + 100 ms
    assert rpdo_timeout_ms(0.004, paced=True) == 112
    assert rpdo_timeout_ms(0.001, paced=False) == 0  # lockstep: off
    # [daq] rpdo_margin_ms: the margin over the 3 cycles (a loaded host's stalls)
    assert parse_daq({}, "c.toml").rpdo_margin_ms == 100
    margin = parse_daq({"rpdo_margin_ms": 400}, "c.toml").rpdo_margin_ms
    assert rpdo_timeout_ms(0.004, True, margin) == 412
    assert rpdo_timeout_ms(0.004, False, margin) == 0
    for bad in (-1, 60001, 1.5, "x"):
        with pytest.raises(ConfigError, match="rpdo_margin_ms") as e:
            parse_daq({"rpdo_margin_ms": bad}, "c.toml")
        assert "\n" not in str(e.value) and "c.toml" in str(e.value)


# the RPDO event timer in the vendor files of ../shared/eds
HAS_RPDO_TIMER = {
    "maxon_epos4-module-50-5.eds": False,
    "elmo_gold.dcf": False,
    "nanotec_c5-e-2-09.eds": False,
    "ingenia_everest-net-c.eds": True,
    "zeroerr_erob-edriver.eds": True,
}


@pytest.mark.parametrize("name", VENDOR_EDS)
def test_vendor_eds_rpdo_event_timer(name):
    eds = shared_path("eds", name)
    mode = "csp" if name.startswith("ingenia") else "cst"  # Ingenia: no CST in 0x6502
    cfg = parse_daq({"drives": [{"node_id": 1, "eds": str(eds), "mode": mode}]}).drives[0]
    net = canopen.Network()  # not connected: only the dictionary is looked at
    md = MasterDrive(net, cfg)
    assert md.has_rpdo_timer() is HAS_RPDO_TIMER[name]
