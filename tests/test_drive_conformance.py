"""CANopen / CiA 402 conformance of the simulated drive with the generic EDS.

The master is canopen's own ``RemoteNode``/``BaseNode402`` on a python-can virtual bus
(its own bus object; the drive has another). "Nothing arrived" checks use an SDO round trip
as a barrier: the drive handles frames in order, so any frame it sends because of an earlier
request reaches the master before that SDO response.
"""

from __future__ import annotations

import math
import queue
import struct

import numpy as np
import pytest
from canopen.sdo.exceptions import SdoAbortedError, SdoCommunicationError

from daq.protocol.cia402 import (
    TRANSITION_CONTROLWORD,
    TRANSITIONS,
    Command,
    State,
    path,
    state_from_statusword,
)
from sim_drivers.od import generic_eds_path, load_drive_od
from sim_drivers.testing import (
    LockstepMaster,
    configure_pdo,
    make_rig,
    read_all_variables,
)

NODE = 5


@pytest.fixture
def rig():
    r = make_rig(node_id=NODE)
    yield r
    r.close()


def _frames(rig, cob: int) -> queue.SimpleQueue:
    q: queue.SimpleQueue = queue.SimpleQueue()
    rig.network.subscribe(cob, lambda c, d, t: q.put(bytes(d)))
    return q


def _drain(q: queue.SimpleQueue) -> list[bytes]:
    out = []
    while True:
        try:
            out.append(q.get_nowait())
        except queue.Empty:
            return out


def _barrier(rig) -> None:
    rig.node.sdo[0x1000].raw  # noqa: B018 - round trip through the drive's receive thread


def _state(rig) -> State:
    return state_from_statusword(rig.node.sdo[0x6041].raw)


def _go(rig, goal: State) -> None:
    """Drive the CiA 402 state machine to ``goal`` with SDO controlwords."""
    start = _state(rig)
    if start is State.FAULT:
        rig.node.sdo[0x6040].raw = 0
    for _, cw in path(start, goal):
        rig.node.sdo[0x6040].raw = cw
    assert _state(rig) is goal


def _enable(rig, mode: int) -> None:
    rig.node.sdo[0x6060].raw = mode
    _go(rig, State.OPERATION_ENABLED)
    rig.node.nmt.state = "OPERATIONAL"
    _barrier(rig)
    assert rig.drive.nmt_state == "OPERATIONAL"


# ---------------------------------------------------------------------------- NMT
def test_bootup_then_heartbeat_in_each_nmt_state():
    rig = make_rig(node_id=NODE, start=False)
    try:
        hb = _frames(rig, 0x700 + NODE)
        rig.drive.start()
        assert hb.get(timeout=2) == b"\x00"  # boot-up first
        assert hb.get(timeout=2) == b"\x7f"  # then heartbeat per 0x1017 (100 ms default)
        rig.node.sdo[0x1017].raw = 10
        rig.node.nmt.state = "OPERATIONAL"
        seen = set()
        while b"\x05" not in seen:
            seen.add(hb.get(timeout=2))
        rig.node.nmt.state = "STOPPED"
        while hb.get(timeout=2) != b"\x04":
            pass
        assert rig.drive.nmt_state == "STOPPED"
    finally:
        rig.close()


def test_pdos_only_while_operational_and_no_sdo_while_stopped(rig):
    tpdo1 = _frames(rig, 0x180 + NODE)
    rig.network.send_message(0x80, b"")
    _barrier(rig)
    assert _drain(tpdo1) == []  # pre-operational: SYNC ignored
    rig.node.nmt.state = "OPERATIONAL"
    rig.network.send_message(0x80, b"")
    _barrier(rig)
    assert len(_drain(tpdo1)) == 1
    rig.node.nmt.state = "STOPPED"
    rig.network.send_message(0x80, b"")
    rig.node.sdo.RESPONSE_TIMEOUT = 0.1
    with pytest.raises(SdoCommunicationError):
        rig.node.sdo[0x1000].raw  # noqa: B018
    rig.node.nmt.state = "PRE-OPERATIONAL"
    _barrier(rig)
    assert _drain(tpdo1) == []
    assert rig.drive.cycle == 1


def test_reset_communication_sends_bootup_and_restores_comm_objects(rig):
    hb = _frames(rig, 0x700 + NODE)
    rig.node.sdo[0x1017].raw = 0
    rig.node.sdo[0x6065].raw = 1234
    configure_pdo(rig.node, "tpdo", 1, [(0x6041, 0)])
    _go(rig, State.READY_TO_SWITCH_ON)
    _drain(hb)
    rig.node.nmt.state = "RESET COMMUNICATION"
    assert hb.get(timeout=2) == b"\x00"
    assert rig.drive.nmt_state == "PRE-OPERATIONAL"
    assert rig.node.sdo[0x1017].raw == 100
    assert rig.node.sdo[0x1A00][0].raw == 2
    assert rig.node.sdo[0x1A00][2].raw == 0x60640020
    assert rig.node.sdo[0x6065].raw == 1234  # application object kept
    assert _state(rig) is State.READY_TO_SWITCH_ON


def test_reset_node_restores_application_objects_and_state_machine(rig):
    rig.node.sdo[0x1017].raw = 0  # no heartbeat between the drain and the boot-up
    hb = _frames(rig, 0x700 + NODE)
    rig.node.sdo[0x6065].raw = 1234
    rig.node.sdo[0x6060].raw = 8
    _go(rig, State.OPERATION_ENABLED)
    _drain(hb)
    rig.node.nmt.state = "RESET"
    assert hb.get(timeout=2) == b"\x00"
    assert hb.get(timeout=2) == b"\x7f"  # reset node restored 0x1017 = 100 ms
    assert rig.node.sdo[0x6065].raw == 50000
    assert rig.node.sdo[0x6061].raw == 0
    assert _state(rig) is State.SWITCH_ON_DISABLED


# ---------------------------------------------------------------------------- SDO
def test_sdo_reads_every_object_and_writes_back_every_writable_one(rig):
    od = rig.node.object_dictionary
    values = read_all_variables(rig.node)
    assert len(values) >= 100
    live = {
        (0x6041, 0): 0x0250,  # switch on disabled + voltage enabled + remote
        (0x6502, 0): 0x380,
        (0x6076, 0): 5000,  # plant_default: 5 N m rated motor torque [mN m]
    }
    for key, value in values.items():
        obj = od[key[0]]
        var = obj if key[1] == 0 and key[0] not in (0x1018, 0x607D, 0x60C2) and not hasattr(
            obj, "subindices"
        ) else obj[key[1]]
        expected = live.get(key, var.default)
        assert value == expected, f"0x{key[0]:04X}.{key[1]}"
    for (index, subindex), value in values.items():
        if 0x1400 <= index <= 0x1BFF:
            continue  # PDO parameters: see the remap tests
        obj = od[index]
        sdo = rig.node.sdo[index] if not hasattr(obj, "subindices") else (
            rig.node.sdo[index][subindex]
        )
        var = sdo.od
        if not var.writable:
            if index not in (0x1008,):
                with pytest.raises(SdoAbortedError) as err:
                    sdo.raw = value
                assert err.value.code in (0x06010002, 0x06090030)
            continue
        sdo.raw = value
        assert sdo.raw == value, f"0x{index:04X}.{subindex}"


def test_sdo_aborts_for_missing_objects_and_unsupported_modes(rig):
    with pytest.raises(SdoAbortedError) as err:
        rig.node.sdo.upload(0x2345, 0)
    assert err.value.code == 0x06020000
    with pytest.raises(SdoAbortedError) as err:
        rig.node.sdo[0x6060].raw = 1  # profile position: not in 0x6502
    assert err.value.code == 0x06090030
    assert rig.node.sdo[0x6061].raw == 0
    rig.node.sdo[0x6060].raw = 10
    assert rig.node.sdo[0x6061].raw == 10
    with pytest.raises(SdoAbortedError) as err:
        rig.node.sdo[0x6060].raw = 4  # profile torque: not advertised by the generic EDS
    assert err.value.code == 0x06090030
    assert rig.node.sdo[0x6061].raw == 10


# ---------------------------------------------------------------------------- PDO
def test_pdo_remap_reads_back_and_is_used_after_nmt_start(rig):
    node = rig.node
    configure_pdo(node, "tpdo", 3, [(0x6061, 0), (0x6074, 0), (0x6078, 0), (0x603F, 0)])
    configure_pdo(node, "tpdo", 1, [(0x6041, 0)], trans_type=2)
    node.tpdo.read()
    assert node.tpdo[3].enabled and node.tpdo[3].trans_type == 1
    assert [(v.index, v.subindex, v.length) for v in node.tpdo[3].map] == [
        (0x6061, 0, 8), (0x6074, 0, 16), (0x6078, 0, 16), (0x603F, 0, 16)
    ]
    assert [(v.index, v.length) for v in node.tpdo[1].map] == [(0x6041, 16)]
    t1, t3 = _frames(rig, 0x180 + NODE), _frames(rig, 0x380 + NODE)
    node.sdo[0x6060].raw = 8
    node.nmt.state = "OPERATIONAL"
    for _ in range(4):
        rig.network.send_message(0x80, b"")
    _barrier(rig)
    tpdo3 = _drain(t3)
    assert len(tpdo3) == 4
    assert struct.unpack("<bhhH", tpdo3[0]) == (8, 0, 0, 0)
    assert [struct.unpack("<H", d)[0] for d in _drain(t1)] == [0x0250, 0x0250]  # every 2nd


@pytest.mark.parametrize(
    ("index", "sub", "value", "code"),
    [
        (0x1A02, 1, 0x60650020, 0x06040041),  # 0x6065 is not mappable
        (0x1602, 1, 0x60410010, 0x06040041),  # read-only object in an RPDO
        (0x1A02, 1, 0x60640010, 0x06040041),  # wrong length for 0x6064
        (0x1A02, 1, 0x23450010, 0x06020000),  # no such object
        (0x1A00, 1, 0x60410010, 0x08000022),  # TPDO1 is enabled
    ],
)
def test_pdo_mapping_writes_are_validated(rig, index, sub, value, code):
    if index != 0x1A00:
        rig.node.sdo[index][0].raw = 0
    with pytest.raises(SdoAbortedError) as err:
        rig.node.sdo[index][sub].raw = value
    assert err.value.code == code


def test_pdo_mapping_longer_than_64_bits_and_entries_with_nonzero_count_are_refused(rig):
    m = rig.node.sdo[0x1A02]
    m[0].raw = 0
    m[1].raw = 0x60640020
    m[2].raw = 0x606C0020
    m[3].raw = 0x607A0020
    with pytest.raises(SdoAbortedError) as err:
        m[0].raw = 3
    assert err.value.code == 0x06040042
    m[0].raw = 2
    with pytest.raises(SdoAbortedError) as err:
        m[1].raw = 0x60410010
    assert err.value.code == 0x08000022
    with pytest.raises(SdoAbortedError) as err:
        m[0].raw = 9  # more than the 8 slots
    assert err.value.code == 0x06090031


# ---------------------------------------------------------------------------- CiA 402
_SOURCE = {number: (src, dst) for (src, _), (dst, number) in TRANSITIONS.items()}


@pytest.mark.parametrize("number", sorted(_SOURCE))
def test_every_controlword_transition_of_the_standard_table(rig, number):
    src, dst = _SOURCE[number]
    if number in (11, 12):
        rig.node.sdo[0x605A].raw = 6  # stay in QUICK STOP ACTIVE
    if src is State.QUICK_STOP_ACTIVE:
        _go(rig, State.OPERATION_ENABLED)
        rig.node.sdo[0x6040].raw = Command.QUICK_STOP
    else:
        _go(rig, src)
    assert _state(rig) is src
    rig.node.sdo[0x6040].raw = TRANSITION_CONTROLWORD[number]
    assert _state(rig) is dst


def test_enable_operation_in_ready_to_switch_on_takes_3_and_4(rig):
    _go(rig, State.READY_TO_SWITCH_ON)
    rig.node.sdo[0x6040].raw = Command.ENABLE_OPERATION
    assert _state(rig) is State.OPERATION_ENABLED


def test_quick_stop_option_2_completes_to_switch_on_disabled_and_16_reenables(rig):
    _go(rig, State.OPERATION_ENABLED)
    rig.node.sdo[0x6040].raw = Command.QUICK_STOP  # 11, then 12 automatic (at rest)
    assert _state(rig) is State.SWITCH_ON_DISABLED
    rig.node.sdo[0x605A].raw = 5
    _go(rig, State.OPERATION_ENABLED)
    rig.node.sdo[0x6040].raw = Command.QUICK_STOP
    assert _state(rig) is State.QUICK_STOP_ACTIVE
    rig.node.sdo[0x6040].raw = TRANSITION_CONTROLWORD[16]
    assert _state(rig) is State.OPERATION_ENABLED


def test_fault_transitions_13_14_15_and_emcy(rig):
    _go(rig, State.OPERATION_ENABLED)
    rig.drive.fault(0xFF01)  # 13 + 14
    assert _state(rig) is State.FAULT  # the EMCY frame was sent before this SDO response
    assert [e.code for e in rig.node.emcy.active] == [0xFF01]
    assert rig.node.emcy.log[-1].register == 0x81
    assert rig.node.sdo[0x603F].raw == 0xFF01
    assert rig.node.sdo[0x1001].raw == 0x81
    rig.node.sdo[0x6040].raw = Command.ENABLE_OPERATION  # no transition out of FAULT
    assert _state(rig) is State.FAULT
    rig.node.sdo[0x6040].raw = Command.FAULT_RESET  # 15 on the rising edge of bit 7
    assert _state(rig) is State.SWITCH_ON_DISABLED
    assert rig.node.sdo[0x603F].raw == 0
    assert rig.node.sdo[0x1001].raw == 0
    assert rig.node.emcy.active == []  # the "error reset" EMCY frame arrived


def test_base_node_402_state_machine_and_mode_with_sync_running(rig):
    """canopen's own CiA 402 master: controlword by event RPDO, statusword and mode display
    by synchronous TPDO while canopen's SYNC producer runs."""
    node = rig.node
    configure_pdo(node, "rpdo", 1, [(0x6040, 0)], trans_type=255)
    configure_pdo(node, "tpdo", 1, [(0x6041, 0), (0x6061, 0)], trans_type=1)
    configure_pdo(node, "tpdo", 2, [(0x6077, 0)], enabled=False)
    node.nmt.state = "OPERATIONAL"
    node.setup_402_state_machine()
    rig.network.sync.start(0.002)
    try:
        node.tpdo[1].wait_for_reception(2)
        node.op_mode = "CYCLIC SYNCHRONOUS TORQUE"
        assert node.op_mode == "CYCLIC SYNCHRONOUS TORQUE"
        node.state = "OPERATION ENABLED"
        assert node.state == "OPERATION ENABLED"
        assert rig.drive.state is State.OPERATION_ENABLED
        node.check_statusword()
        assert node.statusword & 0x1000  # bit 12 in a cyclic mode
        node.state = "SWITCH ON DISABLED"
        assert rig.drive.state is State.SWITCH_ON_DISABLED
        with pytest.raises(TypeError):
            node.op_mode = "PROFILED POSITION"
    finally:
        rig.network.sync.stop()


# ---------------------------------------------------------------------------- lockstep
N_CYCLES = 10_000


def test_cst_lockstep_10000_cycles_no_lost_or_duplicated_pdo(rig):
    _enable(rig, 10)
    i = np.arange(N_CYCLES)
    x = (420 + 300 * np.sin(2 * math.pi * i / 1500) + (i % 7)).astype(np.int64)
    master = LockstepMaster(
        rig.network,
        0x200 + NODE,
        "<Hh",
        {
            0x180 + NODE: ("<Hi", ("6041", "6064")),
            0x280 + NODE: ("<hi", ("6077", "606C")),
        },
    )
    res = master.run(0x0F, x)
    master.close()
    rec = rig.drive.record
    assert res.tpdo_frames == 2 * N_CYCLES and res.extra_frames == 0
    assert rig.drive.tpdo_sent == 2 * N_CYCLES
    assert np.array_equal(rec["cycle"], np.arange(N_CYCLES))
    assert np.array_equal(rec["target_torque"], x)  # every RPDO applied once, in order
    assert np.array_equal(res.received["6064"], rec["counts"])
    assert np.ptp(rec["counts"]) > 5000  # the joint moves: a shifted stream cannot match
    assert np.all(res.received["6041"] == 0x1237)  # operation enabled + bit 12
    plant = rig.plant
    expected_6077 = [plant.permille_from_torque(t) for t in rec["tau_applied"]]
    assert np.array_equal(res.received["6077"], expected_6077)
    assert np.allclose(rec["tau_cmd"], [plant.torque_from_permille(v) for v in x])


def test_csp_lockstep_10000_cycles_tracks_target(rig):
    node = rig.node
    configure_pdo(node, "rpdo", 1, [(0x6040, 0)], enabled=False)
    configure_pdo(node, "rpdo", 2, [(0x6040, 0), (0x607A, 0)])
    _enable(rig, 8)
    i = np.arange(N_CYCLES)
    amp = rig.plant.rad_to_counts(0.3)
    target = np.round(amp * (1 - np.cos(2 * math.pi * i / 4000))).astype(np.int64)
    master = LockstepMaster(
        rig.network,
        0x300 + NODE,
        "<Hi",
        {
            0x180 + NODE: ("<Hi", ("6041", "6064")),
            0x280 + NODE: ("<hi", ("6077", "606C")),
        },
    )
    res = master.run(0x0F, target)
    master.close()
    rec = rig.drive.record
    assert res.tpdo_frames == 2 * N_CYCLES and res.extra_frames == 0
    assert np.array_equal(rec["target_position"], target)
    assert np.array_equal(res.received["6064"], rec["counts"])
    assert np.all(res.received["6041"] == 0x1237)
    err = np.abs(res.received["6064"] - target)
    assert err.max() < load_drive_od(generic_eds_path(), NODE).od[0x6065].default
    assert err[2000:].max() < 0.02 * amp  # the PD loop follows within 2 % of the swing


# ---------------------------------------------------------------------------- misc
def test_event_tpdo_is_sent_when_its_content_changes(rig):
    node = rig.node
    configure_pdo(node, "tpdo", 1, [(0x6041, 0)], trans_type=255)
    configure_pdo(node, "tpdo", 2, [(0x6077, 0)], enabled=False)
    t1 = _frames(rig, 0x180 + NODE)
    node.nmt.state = "OPERATIONAL"
    _barrier(rig)
    node.sdo[0x6040].raw = Command.SHUTDOWN  # statusword changes -> one TPDO
    node.sdo[0x6040].raw = Command.SHUTDOWN  # no change -> none
    for _ in range(3):
        rig.network.send_message(0x80, b"")  # cycles, statusword unchanged -> none
    _barrier(rig)
    assert [struct.unpack("<H", d)[0] for d in _drain(t1)] == [0x0231]


def test_record_grows_by_chunks():
    from sim_drivers.drive import SimulatedDrive, open_virtual_bus
    from sim_drivers.plant import JointPlant
    from sim_drivers.plant_config import load_plant
    from sim_drivers.testing import DEFAULT_PLANT, unique_channel

    bus = open_virtual_bus(unique_channel())
    plant = JointPlant(load_plant(DEFAULT_PLANT), 0.001, seed=1)
    drive = SimulatedDrive(bus, 9, plant, record_chunk=64)
    try:
        drive.start()
        for i in range(150):
            drive.target_torque = i
            drive.step()
        rec = drive.record
        assert np.array_equal(rec["cycle"], np.arange(150))
        assert np.array_equal(rec["target_torque"], np.arange(150))
        assert rec["q"].dtype == np.float64 and len(rec["statusword"]) == 150
    finally:
        drive.stop()
        bus.shutdown()


def test_drive_configuration_errors_name_the_problem(tmp_path):
    from sim_drivers.drive import DriveError, SimulatedDrive
    from sim_drivers.od import DriveConfigError

    with pytest.raises(DriveConfigError, match="not found"):
        load_drive_od(tmp_path / "missing.eds", 1)
    with pytest.raises(DriveConfigError, match="node id 0"):
        load_drive_od(None, 0)
    text = generic_eds_path().read_text()
    start = text.index("[6041]")
    cut = text[:start] + text[text.index("[", start + 1):]
    (tmp_path / "no6041.eds").write_text(cut.replace("=0x6041\n", "=0x6040\n"))
    with pytest.raises(DriveConfigError, match="0x6041 missing"):
        load_drive_od(tmp_path / "no6041.eds", 1)
    with pytest.raises(DriveError, match="canopen.Network or can.BusABC"):
        SimulatedDrive("vcan0", 1, object())


def test_csv_follows_target_velocity(rig):
    node = rig.node
    configure_pdo(node, "rpdo", 1, [(0x6040, 0), (0x60FF, 0)])
    _enable(rig, 9)
    v = rig.plant.rad_to_counts(0.5)  # [counts/s]
    master = LockstepMaster(
        rig.network, 0x200 + NODE, "<Hi", {0x280 + NODE: ("<hi", ("6077", "606C"))}
    )
    res = master.run(0x0F, np.full(1500, v))
    master.close()
    assert np.all(rig.drive.record["mode"] == 9)
    vel = res.received["606C"][500:]
    assert abs(np.median(vel) - v) < 0.05 * v


def test_canopen_pdomap_save_on_record_maps_is_accepted_and_used(rig):
    node = rig.node
    node.tpdo.read()
    tpdo = node.tpdo[3]
    tpdo.clear()
    tpdo.add_variable(0x6061)
    tpdo.add_variable(0x6078)
    tpdo.trans_type = 1
    tpdo.enabled = True
    tpdo.save()  # canopen's own sequence: invalidate, type, count 0, entries, count, valid
    node.tpdo.read()
    assert [(v.index, v.length) for v in node.tpdo[3].map] == [(0x6061, 8), (0x6078, 16)]
    t3 = _frames(rig, 0x380 + NODE)
    node.sdo[0x6060].raw = 10
    node.nmt.state = "OPERATIONAL"
    rig.network.send_message(0x80, b"")
    _barrier(rig)
    assert [struct.unpack("<bh", d) for d in _drain(t3)] == [(10, 0)]


def test_two_drives_share_one_sync():
    from sim_drivers.drive import SimulatedDrive, open_virtual_bus
    from sim_drivers.plant import JointPlant
    from sim_drivers.plant_config import load_plant
    from sim_drivers.testing import DEFAULT_PLANT

    rig = make_rig(node_id=NODE)
    bus2 = open_virtual_bus(rig.channel)
    drive2 = SimulatedDrive(bus2, NODE + 1, JointPlant(load_plant(DEFAULT_PLANT), 0.001, seed=2))
    try:
        drive2.start()
        node2 = rig.network.add_node(NODE + 1, str(generic_eds_path()))
        for node in (rig.node, node2):
            node.sdo[0x6060].raw = 10
            for cw in (6, 7, 15):
                node.sdo[0x6040].raw = cw
        rig.network.nmt.send_command(0x01)  # start all nodes
        _barrier(rig)
        got: queue.SimpleQueue = queue.SimpleQueue()
        cobs = [0x180 + NODE, 0x280 + NODE, 0x181 + NODE, 0x281 + NODE]
        for cob in cobs:
            rig.network.subscribe(cob, lambda c, d, t: got.put((c, bytes(d))))
        counts = {NODE: [], NODE + 1: []}
        for i in range(1000):
            rig.network.send_message(0x200 + NODE, struct.pack("<Hh", 15, 450 + i % 50))
            rig.network.send_message(0x201 + NODE, struct.pack("<Hh", 15, 380 - i % 30))
            rig.network.send_message(0x80, b"")
            frames = dict(got.get(timeout=2) for _ in range(4))
            assert sorted(frames) == sorted(cobs)
            counts[NODE].append(struct.unpack("<Hi", frames[0x180 + NODE])[1])
            counts[NODE + 1].append(struct.unpack("<Hi", frames[0x181 + NODE])[1])
        assert np.array_equal(counts[NODE], rig.drive.record["counts"])
        assert np.array_equal(counts[NODE + 1], drive2.record["counts"])
        assert rig.drive.cycle == drive2.cycle == 1000
    finally:
        drive2.stop()
        bus2.shutdown()
        rig.close()


def test_short_rpdo_is_ignored_and_empty_tpdo_is_not_sent(rig):
    node = rig.node
    configure_pdo(node, "tpdo", 4, [])  # valid COB-ID, nothing mapped
    t4 = _frames(rig, 0x480 + NODE)
    node.sdo[0x6060].raw = 10
    node.nmt.state = "OPERATIONAL"
    rig.network.send_message(0x200 + NODE, struct.pack("<Hh", 0x0F, 123))
    rig.network.send_message(0x80, b"")
    rig.network.send_message(0x200 + NODE, b"\x0f\x00")  # 2 of 4 bytes
    rig.network.send_message(0x80, b"")
    _barrier(rig)
    assert rig.drive.rx_length_errors == 1
    assert [(e.code, e.register) for e in rig.node.emcy.log] == [(0x8210, 0x11)]
    assert rig.drive.state is State.SWITCH_ON_DISABLED  # a warning, no fault
    assert list(rig.drive.record["target_torque"]) == [123, 123]
    assert _drain(t4) == []


def test_serve_starts_drives_that_a_master_reaches():
    import canopen

    from sim_drivers.serve import start_drives
    from sim_drivers.testing import unique_channel

    channel = unique_channel()
    with start_drives("virtual", channel, [11, 12], q0=0.1) as served:
        net = canopen.Network()
        net.NOTIFIER_CYCLE = 0.05
        net.connect(interface="virtual", channel=channel)
        try:
            for node_id, drive in zip((11, 12), served.drives, strict=True):
                node = net.add_node(node_id, str(generic_eds_path()))
                assert node.sdo[0x6041].raw == 0x0250
                assert node.sdo[0x6064].raw == drive.plant.rad_to_counts(0.1)
        finally:
            net.disconnect()
