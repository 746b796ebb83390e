"""Master-side helpers to exercise a :class:`~sim_drivers.drive.SimulatedDrive` over the bus.

Used by the conformance tests and ``benchmarks/bench_drive.py``: a rig (drive + canopen
master ``BaseNode402`` on a virtual bus), PDO configuration written explicitly over SDO
(canopen 2.4.1's ``PdoMap.save()`` writes no entries for ARRAY-typed maps, see
``/work/shared/notes/canopen.md``), and a lockstep master that sends RPDO + SYNC and waits
for the TPDOs through a callback-fed queue.
"""

from __future__ import annotations

import itertools
import os
import queue
import struct
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import can
import canopen
import numpy as np
from canopen.profiles.p402 import BaseNode402

from sim_drivers.drive import SimulatedDrive, open_virtual_bus
from sim_drivers.faults import FaultInjector
from sim_drivers.od import STRUCT_CODE, DriveOD, generic_eds_path, iter_variables, load_drive_od
from sim_drivers.plant import JointPlant
from sim_drivers.plant_config import load_plant

_counter = itertools.count()
DEFAULT_PLANT = Path(__file__).with_name("data") / "plant_default.toml"


def unique_channel(prefix: str = "jointid") -> str:
    """A virtual-bus channel name no other rig in this process uses."""
    return f"{prefix}-{os.getpid()}-{next(_counter)}"


@dataclass
class DriveRig:
    """A simulated drive and a canopen master (``BaseNode402``) on one virtual channel.

    Attributes
    ----------
    drive : SimulatedDrive
    plant : JointPlant
    network : canopen.Network
        The master's network (its own bus object on the channel).
    node : BaseNode402
        The master's view of the drive, built from the same EDS/DCF.
    """

    drive: SimulatedDrive
    plant: JointPlant
    network: canopen.Network
    node: BaseNode402
    drive_bus: can.BusABC
    channel: str
    eds: Path
    _closed: bool = field(default=False, repr=False)

    def close(self) -> None:
        """Stop the drive, disconnect the master, shut the drive's bus."""
        if self._closed:
            return
        self._closed = True
        self.drive.stop()
        self.network.disconnect()
        self.drive_bus.shutdown()

    def __enter__(self) -> DriveRig:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def make_rig(
    eds: str | Path | None = None,
    *,
    node_id: int = 5,
    channel: str | None = None,
    fault_injector: FaultInjector | None = None,
    plant: JointPlant | None = None,
    start: bool = True,
    cycle_s: float = 0.001,
) -> DriveRig:
    """Build a drive (default plant ``sim_drivers/data/plant_default.toml``) and a master.

    With ``start`` the drive sends its boot-up and the master sees it PRE-OPERATIONAL.
    """
    channel = channel or unique_channel()
    path = generic_eds_path() if eds is None else Path(eds)
    if plant is None:
        plant = JointPlant(load_plant(DEFAULT_PLANT), cycle_s, seed=1)
    dod: DriveOD = load_drive_od(path, node_id)
    drive_bus = open_virtual_bus(channel)
    drive = SimulatedDrive(
        drive_bus, node_id, plant, dod, fault_injector=fault_injector, cycle_s=cycle_s
    )
    network = canopen.Network(open_virtual_bus(channel))
    network.NOTIFIER_CYCLE = 0.05  # notifier poll period [s]: quick disconnect
    network.connect()
    node = BaseNode402(node_id, str(path))
    network.add_node(node)
    rig = DriveRig(drive, plant, network, node, drive_bus, channel, path)
    if start:
        drive.start()
        node.nmt.state = "PRE-OPERATIONAL"  # master's view; the drive already is
    return rig


def configure_pdo(
    node: canopen.RemoteNode,
    kind: str,
    number: int,
    entries: Sequence[tuple[int, int]],
    *,
    trans_type: int = 1,
    enabled: bool = True,
) -> None:
    """Configure PDO ``number`` (1-based) of ``kind`` ``"rpdo"``/``"tpdo"`` over SDO.

    Order per CiA 301: disable (COB-ID bit 31), transmission type, sub 0 = 0, entries, sub 0
    = n, enable. ``entries`` are ``(index, subindex)``; sizes come from the dictionary.
    """
    comm = (0x1400 if kind == "rpdo" else 0x1800) + number - 1
    mapping = comm + 0x200
    sdo = node.sdo
    cob = sdo[comm][1].raw
    sdo[comm][1].raw = cob | 0x80000000
    sdo[comm][2].raw = trans_type
    sdo[mapping][0].raw = 0
    od = node.object_dictionary
    for i, (index, subindex) in enumerate(entries, start=1):
        obj = od[index]
        var = obj if isinstance(obj, canopen.objectdictionary.ODVariable) else obj[subindex]
        sdo[mapping][i].raw = index << 16 | subindex << 8 | len(var)
    sdo[mapping][0].raw = len(entries)
    if enabled:
        sdo[comm][1].raw = cob & ~0x80000000


def disable_pdos(node: canopen.RemoteNode, kind: str) -> None:
    """Disable every PDO of ``kind`` (``"rpdo"``/``"tpdo"``) the dictionary declares."""
    base = 0x1400 if kind == "rpdo" else 0x1800
    for n in range(512):
        if base + n not in node.object_dictionary:
            continue
        cob = node.sdo[base + n][1].raw
        if not cob & 0x80000000:
            node.sdo[base + n][1].raw = cob | 0x80000000


@dataclass
class LockstepResult:
    """What the master saw in a lockstep run: one row per cycle."""

    sent: np.ndarray  # setpoint sent per cycle (int64)
    received: dict[str, np.ndarray]  # TPDO values per cycle, by "0xIIII" object key
    tpdo_frames: int  # TPDO frames received in total
    extra_frames: int  # frames that arrived after the run (duplicates)


class LockstepMaster:
    """Lockstep cyclic exchange with raw frames: RPDO + SYNC out, TPDOs back.

    The master writes the setpoint RPDO (controlword + one target) and a SYNC each cycle,
    then blocks until every configured TPDO of that cycle arrived through a callback-fed
    queue. Payloads are packed and unpacked with ``struct`` from the layouts given.

    Parameters
    ----------
    network : canopen.Network
        The master's network.
    rpdo_cob : int
        COB-ID of the setpoint RPDO.
    rpdo_format : str
        struct format of the RPDO (e.g. ``"<Hh"`` controlword + target torque).
    tpdos : dict[int, tuple[str, tuple[str, ...]]]
        COB-ID -> (struct format, names of the fields) of each synchronous TPDO.
    sync_cob : int
        SYNC COB-ID.
    timeout : float
        Seconds to wait for one cycle's TPDOs before raising ``TimeoutError``.
    """

    def __init__(
        self,
        network: canopen.Network,
        rpdo_cob: int,
        rpdo_format: str,
        tpdos: dict[int, tuple[str, tuple[str, ...]]],
        *,
        sync_cob: int = 0x80,
        timeout: float = 2.0,
    ) -> None:
        self.network = network
        self.rpdo_cob = rpdo_cob
        self.rpdo_struct = struct.Struct(rpdo_format)
        self.tpdos = {cob: (struct.Struct(fmt), names) for cob, (fmt, names) in tpdos.items()}
        self.sync_cob = sync_cob
        self.timeout = timeout
        self.queue: queue.SimpleQueue[tuple[int, bytes]] = queue.SimpleQueue()
        for cob in self.tpdos:
            network.subscribe(cob, self._on_tpdo)

    def _on_tpdo(self, can_id: int, data: bytes, timestamp: float) -> None:
        self.queue.put((can_id, bytes(data)))

    def close(self) -> None:
        for cob in self.tpdos:
            self.network.unsubscribe(cob, self._on_tpdo)

    def run(
        self,
        controlword: int,
        setpoints: Sequence[int] | np.ndarray,
        *,
        missing: Sequence[int] = (),
    ) -> LockstepResult:
        """Run ``len(setpoints)`` cycles; raise ``TimeoutError`` when a TPDO is lost.

        Cycles listed in ``missing`` are expected to bring no TPDO (their rows stay 0):
        the master does not wait for them.
        """
        skip = frozenset(missing)
        n = len(setpoints)
        names = [nm for _, nms in self.tpdos.values() for nm in nms]
        out = {nm: np.zeros(n, dtype=np.int64) for nm in names}
        send = self.network.send_message
        pack = self.rpdo_struct.pack
        get = self.queue.get
        expected = len(self.tpdos)
        tpdos = self.tpdos
        frames = 0
        sync = b""
        for i, x in enumerate(np.asarray(setpoints, dtype=np.int64).tolist()):
            send(self.rpdo_cob, pack(controlword, x))
            send(self.sync_cob, sync)
            if i in skip:
                continue
            seen = 0
            while seen < expected:
                try:
                    cob, data = get(timeout=self.timeout)
                except queue.Empty:
                    raise TimeoutError(f"cycle {i}: TPDO missing after {self.timeout} s") from None
                st, nms = tpdos[cob]
                for nm, v in zip(nms, st.unpack_from(data), strict=True):
                    out[nm][i] = v
                seen += 1
                frames += 1
        extra = 0
        try:
            while True:
                self.queue.get(timeout=0.05)
                extra += 1
        except queue.Empty:
            pass
        return LockstepResult(np.asarray(setpoints, dtype=np.int64), out, frames, extra)


def read_all_variables(node: canopen.RemoteNode) -> dict[tuple[int, int], Any]:
    """SDO upload of every readable numeric variable the node's dictionary declares."""
    values: dict[tuple[int, int], Any] = {}
    for var in iter_variables(node.object_dictionary):
        if not var.readable or var.data_type not in STRUCT_CODE:
            continue
        obj = node.object_dictionary[var.index]
        if isinstance(obj, canopen.objectdictionary.ODVariable):
            values[(var.index, 0)] = node.sdo[var.index].raw
        else:
            values[(var.index, var.subindex)] = node.sdo[var.index][var.subindex].raw
    return values
