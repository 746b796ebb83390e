"""PDO configuration by SDO against real canopen LocalNodes on python-can's virtual bus."""

from __future__ import annotations

import itertools

import can
import canopen
import pytest
from canopen.sdo.exceptions import SdoAbortedError

from daq import ConfigError
from daq.protocol.cia402 import Mode
from daq.runtime.config import DriveConfig, Scaling, generic_eds
from daq.runtime.master import MasterDrive, pdo_specs
from tests.conftest import VENDOR_EDS, shared_path

_chan = itertools.count()


@pytest.fixture
def bus_pair():
    """A master network and a device network on one fresh virtual channel."""
    channel = f"test_master_{next(_chan)}"
    master = canopen.Network(can.Bus(interface="virtual", channel=channel))
    device = canopen.Network(can.Bus(interface="virtual", channel=channel))
    for net in (master, device):
        net.NOTIFIER_CYCLE = 0.02  # quick teardown
        net.connect()
    yield master, device
    master.disconnect()
    device.disconnect()


def _local(device, eds, node_id=1):
    from sim_drivers.od import load_drive_od

    dod = load_drive_od(eds, node_id)
    node = canopen.LocalNode(node_id, dod.od)
    device.add_node(node)
    return node


def _cfg(eds, mode=Mode.CYCLIC_SYNC_TORQUE, node_id=1):
    return DriveConfig(node_id, eds, mode, 100, Scaling(5.0, 100.0, 4096))


def _stored(node, index, sub):
    return int.from_bytes(node.sdo.upload(index, sub), "little")


@pytest.mark.parametrize("mode", [Mode.CYCLIC_SYNC_TORQUE, Mode.CYCLIC_SYNC_POSITION])
def test_configure_generic_eds_writes_and_reads_back(bus_pair, mode):
    master, device = bus_pair
    eds = generic_eds()
    local = _local(device, eds)
    drive = MasterDrive(master, _cfg(eds, mode))
    drive.configure_pdos()
    for spec in pdo_specs(1, mode):
        assert _stored(local, spec.comm_index, 1) == spec.cob_id
        assert _stored(local, spec.comm_index, 2) == 1
        assert _stored(local, spec.map_index, 0) == len(spec.entries)
        for k, w in enumerate(spec.words(), start=1):
            assert _stored(local, spec.map_index, k) == w
    # the EDS's other PDOs are disabled (bit 31 of the COB-ID)
    for idx in (0x1401, 0x1402, 0x1403, 0x1802, 0x1803):
        assert _stored(local, idx, 1) & 0x80000000
    expect = 0x60710010 if mode is Mode.CYCLIC_SYNC_TORQUE else 0x607A0020
    assert _stored(local, 0x1600, 2) == expect


def test_readback_mismatch_is_refused_naming_the_object(bus_pair):
    master, device = bus_pair
    eds = generic_eds()
    local = _local(device, eds)

    # a drive that acknowledges but silently keeps its old entry in 0x1600.2 (what the
    # canopen 2.4 save() bug looks like from the master); its default there is 0x60710010
    original = local.set_data

    def set_data(index, subindex, data, check_writable=False):
        if index == 0x1600 and subindex == 2:
            return None
        return original(index, subindex, data, check_writable=check_writable)

    local.set_data = set_data
    drive = MasterDrive(master, _cfg(eds, Mode.CYCLIC_SYNC_POSITION))
    with pytest.raises(ConfigError, match=r"node 1: RPDO1 mapping 0x1600\.2 read back "
                                          r"0x60710010 != written 0x607A0020"):
        drive.configure_pdos()


def test_refused_mapping_write_names_pdo(bus_pair):
    master, device = bus_pair
    eds = generic_eds()
    local = _local(device, eds)

    def refuse(index, subindex, od, data):
        if index == 0x1A01 and subindex == 1:
            raise SdoAbortedError(0x06040041)

    local.add_write_callback(refuse)
    drive = MasterDrive(master, _cfg(eds))
    with pytest.raises(ConfigError, match=r"node 1: TPDO2 mapping 0x1A01\.1 = 0x606C0020 refused"):
        drive.configure_pdos()


def test_unknown_node_is_refused(bus_pair):
    master, _device = bus_pair
    drive = MasterDrive(master, _cfg(generic_eds(), node_id=9), sdo_timeout_s=0.05)
    with pytest.raises(ConfigError, match="node 9: no answer to SDO"):
        drive.check_present()


def test_eds_without_cst_is_refused(bus_pair):
    master, _ = bus_pair
    eds = shared_path("eds", "ingenia_everest-net-c.eds")
    with pytest.raises(ConfigError, match=r"node 1: .*0x6502.*0x301A5 does not support "
                                          r"cyclic_sync_torque"):
        MasterDrive(master, _cfg(eds))
    # CSP is advertised: accepted
    MasterDrive(master, _cfg(eds, Mode.CYCLIC_SYNC_POSITION, node_id=2))


def test_drive_reporting_no_cst_is_refused(bus_pair):
    master, device = bus_pair
    eds = generic_eds()
    local = _local(device, eds)
    local.sdo[0x6502].raw = 1 << 7  # CSP only, served live
    drive = MasterDrive(master, _cfg(eds))
    with pytest.raises(ConfigError, match=r"0x6502 \(supported drive modes\) = 0x80 does not"):
        drive.check_mode_supported()


@pytest.mark.parametrize("name", VENDOR_EDS)
def test_vendor_eds_pdo_configuration(bus_pair, name):
    """Each vendor file that advertises CST: the layout is written and read back."""
    master, device = bus_pair
    eds = shared_path("eds", name)
    local = _local(device, eds)
    try:
        drive = MasterDrive(master, _cfg(eds))
    except ConfigError as exc:
        assert "does not support" in str(exc) or "has no object" in str(exc)
        pytest.skip(f"{name}: {exc}")
    drive.configure_pdos()
    for spec in drive.specs:
        for k, w in enumerate(spec.words(), start=1):
            assert _stored(local, spec.map_index, k) == w


def test_scaling_read_from_the_drive_when_the_campaign_has_none(bus_pair):
    master, device = bus_pair
    eds = shared_path("eds", "elmo_gold.dcf")
    local = _local(device, eds)
    local.sdo[0x6076].raw = 5000  # mN m
    local.sdo[0x608F][1].raw = 4096  # encoder increments
    local.sdo[0x608F][2].raw = 1  # per motor revolution
    local.sdo[0x6091][1].raw = 100  # motor revolutions
    local.sdo[0x6091][2].raw = 1  # per shaft revolution
    cfg = DriveConfig(1, eds, Mode.CYCLIC_SYNC_TORQUE, 100, None)
    sc = MasterDrive(master, cfg).read_scaling()
    assert (sc.rated_torque_Nm, sc.gear_ratio, sc.encoder_counts_per_rev) == (5.0, 100.0, 4096)


def test_scaling_missing_everywhere_is_refused(bus_pair):
    master, device = bus_pair
    eds = generic_eds()  # has 0x6076 but no 0x608F encoder resolution
    _local(device, eds)
    cfg = DriveConfig(1, eds, Mode.CYCLIC_SYNC_TORQUE, 100, None)
    with pytest.raises(ConfigError, match=r"node 1: the drive gives no rated torque .*set "
                                          r"daq.drives.scaling"):
        MasterDrive(master, cfg).read_scaling()
