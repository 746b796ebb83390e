"""Faults of the simulated drive: detection -> FAULT + 0x603F + EMCY, fault reset, injector."""

from __future__ import annotations

import queue
import time

import numpy as np
import pytest

from daq.protocol.cia402 import State, path, state_from_statusword
from sim_drivers.faults import (
    EXCESS_TORQUE,
    FOLLOWING_ERROR,
    INJECTED_FAULT,
    PLANT_FAULT,
    POSITION_LIMIT,
    FaultInjector,
    error_register,
)
from sim_drivers.plant import JointPlant
from sim_drivers.plant_config import load_plant
from sim_drivers.testing import DEFAULT_PLANT, LockstepMaster, configure_pdo, make_rig

NODE = 7
TPDOS = {
    0x180 + NODE: ("<Hi", ("6041", "6064")),
    0x280 + NODE: ("<hi", ("6077", "606C")),
}


def _enable(rig, mode: int) -> None:
    rig.node.sdo[0x6060].raw = mode
    for _, cw in path(State.SWITCH_ON_DISABLED, State.OPERATION_ENABLED):
        rig.node.sdo[0x6040].raw = cw
    rig.node.nmt.state = "OPERATIONAL"
    rig.node.sdo[0x1000].raw  # noqa: B018 - barrier: NMT start processed


def _states(sw: np.ndarray) -> list[State]:
    return [state_from_statusword(int(v)) for v in sw]


def _cst_master(rig) -> LockstepMaster:
    return LockstepMaster(rig.network, 0x200 + NODE, "<Hh", TPDOS)


def _csp_master(rig) -> LockstepMaster:
    configure_pdo(rig.node, "rpdo", 1, [(0x6040, 0)], enabled=False)
    configure_pdo(rig.node, "rpdo", 2, [(0x6040, 0), (0x607A, 0)])
    return LockstepMaster(rig.network, 0x300 + NODE, "<Hi", TPDOS)


def test_error_register_classes():
    assert error_register(0) == 0
    assert error_register(FOLLOWING_ERROR) == 0x21
    assert error_register(INJECTED_FAULT) == 0x81
    assert error_register(0x2310) == 0x03
    with pytest.raises(ValueError, match="fault_code"):
        FaultInjector(fault_code=0)


def test_injected_fault_emcy_and_fault_reset_over_rpdo():
    rig = make_rig(node_id=NODE, fault_injector=FaultInjector(fault_at_cycle=100))
    try:
        _enable(rig, 10)
        master = _cst_master(rig)
        x = np.full(200, 500)
        res = master.run(0x0F, x)
        states = _states(res.received["6041"])
        assert states[:100] == [State.OPERATION_ENABLED] * 100
        assert states[100:] == [State.FAULT] * 100
        assert [e.code for e in rig.node.emcy.active] == [INJECTED_FAULT]
        assert rig.node.sdo[0x603F].raw == INJECTED_FAULT
        rec = rig.drive.record
        assert np.all(rec["tau_cmd"][100:] == 0.0)
        assert np.all(rec["q"][100:] == rec["q"][100])  # power off, brake holds
        res = master.run(0x80, x[:3])  # rising edge of bit 7: transition 15
        assert _states(res.received["6041"]) == [State.SWITCH_ON_DISABLED] * 3
        assert rig.node.emcy.active == []
        assert rig.node.sdo[0x603F].raw == 0
        for cw in (0x06, 0x07, 0x0F):
            res = master.run(cw, x[:1])
        assert _states(res.received["6041"]) == [State.OPERATION_ENABLED]
        master.close()
    finally:
        rig.close()


def test_following_error_in_csp_faults_with_bit_13():
    rig = make_rig(node_id=NODE)
    try:
        rig.node.sdo[0x6065].raw = 1000
        master = _csp_master(rig)
        _enable(rig, 8)
        target = np.zeros(50, dtype=np.int64)
        target[20:] = 5000  # a step no loop can follow within 1000 counts
        res = master.run(0x0F, target)
        sw = res.received["6041"]
        assert _states(sw[:20]) == [State.OPERATION_ENABLED] * 20
        assert _states(sw[20:]) == [State.FAULT] * 30
        assert sw[20] & 0x2000  # CSP following error bit
        assert rig.node.sdo[0x603F].raw == FOLLOWING_ERROR
        assert rig.node.emcy.log[-1].code == FOLLOWING_ERROR
        master.close()
    finally:
        rig.close()


def test_excess_torque_in_cst_faults():
    rig = make_rig(node_id=NODE)
    try:
        rig.node.sdo[0x6072].raw = 500
        rig.node.sdo[0x60B2].raw = 50
        master = _cst_master(rig)
        _enable(rig, 10)
        x = np.array([440] * 10 + [451] * 5)  # 451 + 50 offset > 500
        res = master.run(0x0F, x)
        assert _states(res.received["6041"]) == [State.OPERATION_ENABLED] * 10 + [State.FAULT] * 5
        assert rig.node.sdo[0x603F].raw == EXCESS_TORQUE
        assert rig.drive.record["torque_demand"][9] == 490
        master.close()
    finally:
        rig.close()


def test_software_position_limit_faults():
    rig = make_rig(node_id=NODE)
    try:
        rig.node.sdo[0x607D][1].raw = -2000
        rig.node.sdo[0x607D][2].raw = 2000
        master = _cst_master(rig)
        _enable(rig, 10)
        res = master.run(0x0F, np.full(2000, 900))  # 450 N m against 207 N m of gravity
        states = _states(res.received["6041"])
        first = states.index(State.FAULT)
        assert states[:first] == [State.OPERATION_ENABLED] * first
        assert res.received["6064"][first] > 2000
        assert np.all(np.abs(res.received["6064"][:first]) <= 2000)
        assert rig.node.sdo[0x603F].raw == POSITION_LIMIT
        master.close()
    finally:
        rig.close()


class _BrokenPlant(JointPlant):
    """A real plant that fails at its 30th step (a plant-detected fault)."""

    __slots__ = ("calls",)

    def step(self, tau_cmd: float) -> None:
        self.calls = getattr(self, "calls", 0) + 1
        if self.calls == 30:
            raise FloatingPointError("integration diverged")
        super().step(tau_cmd)


def test_plant_failure_is_a_drive_fault_not_a_dead_bus_thread():
    plant = _BrokenPlant(load_plant(DEFAULT_PLANT), 0.001, seed=1)
    rig = make_rig(node_id=NODE, plant=plant)
    try:
        master = _cst_master(rig)
        _enable(rig, 10)
        res = master.run(0x0F, np.full(40, 420))
        states = _states(res.received["6041"])
        assert states[28] is State.OPERATION_ENABLED and states[29] is State.FAULT
        assert rig.node.sdo[0x603F].raw == PLANT_FAULT
        master.close()
    finally:
        rig.close()


def test_injector_drops_tpdos_for_k_cycles():
    rig = make_rig(
        node_id=NODE, fault_injector=FaultInjector(drop_tpdo_from_cycle=50, drop_tpdo_cycles=5)
    )
    try:
        master = _cst_master(rig)
        _enable(rig, 10)
        x = np.arange(100) % 50 + 400
        res = master.run(0x0F, x, missing=range(50, 55))
        rec = rig.drive.record
        keep = np.r_[0:50, 55:100]
        assert res.tpdo_frames == 2 * 95 and res.extra_frames == 0
        assert np.array_equal(res.received["6064"][keep], rec["counts"][keep])
        assert np.array_equal(rec["target_torque"], x)  # the drive kept cycling
        master.close()
    finally:
        rig.close()


def test_injector_stops_heartbeat():
    rig = make_rig(node_id=NODE, fault_injector=FaultInjector(stop_heartbeat_at_cycle=3))
    try:
        rig.node.sdo[0x1000].raw  # noqa: B018 - barrier: the boot-up frame is behind us
        hb: queue.SimpleQueue = queue.SimpleQueue()
        rig.network.subscribe(0x700 + NODE, lambda c, d, t: hb.put(bytes(d)))
        rig.node.sdo[0x1017].raw = 5
        master = _cst_master(rig)
        _enable(rig, 10)
        assert hb.get(timeout=2) in (b"\x7f", b"\x05")
        master.run(0x0F, np.full(5, 420))
        rig.node.sdo[0x1000].raw  # noqa: B018 - barrier
        time.sleep(0.1)  # a heartbeat already past its stop check may still arrive
        while not hb.empty():
            hb.get()
        time.sleep(0.1)  # 20 heartbeat periods
        assert hb.empty()
        assert rig.drive.nmt_state == "OPERATIONAL"
        master.close()
    finally:
        rig.close()
