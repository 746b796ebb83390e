"""Master side of one CiA 402 drive: presence, mode, PDO configuration, cyclic frames.

SDO, NMT, EMCY and heartbeat go through a ``canopen.RemoteNode``; the cyclic PDOs are packed
and unpacked with :mod:`struct` directly (the mapping is fixed and verified here), because
canopen's object-dictionary encode/decode costs about twice a raw frame per cycle
(``notes/performance.md``). canopen's ``BaseNode402`` is not used (0.4 s per transition,
bare ``RuntimeError``); the CiA 402 sequencing uses :mod:`daq.protocol.cia402`.

PDOs are configured by explicit SDO writes, never by ``PdoMap.save()`` (canopen 2.4.x
writes no entries when the EDS declares the mapping objects as ARRAY), and every written
sub-index is read back before the drive is started; a mismatch raises
:class:`daq.ConfigError` naming the node, the PDO and the object.

Cyclic layout (all synchronous, transmission type 1):

=====  ===========  =====================================================  =======
 PDO    COB-ID       mapping                                                 bytes
=====  ===========  =====================================================  =======
RPDO1  0x200 + id   0x6040 controlword u16, 0x6071 target torque i16 (CST)   4
                    0x6040 controlword u16, 0x607A target position i32 (CSP) 6
TPDO1  0x180 + id   0x6041 statusword u16, 0x6064 position i32,
                    0x6077 torque actual i16                                 8
TPDO2  0x280 + id   0x606C velocity actual i32, 0x6061 mode display i8      5
=====  ===========  =====================================================  =======

Every other RPDO/TPDO the EDS declares is disabled (COB-ID bit 31).

A dead master must stop the drives
----------------------------------
The master produces its own heartbeat (:class:`MasterHeartbeat`: COB-ID 0x700 +
``daq.master_node_id``, state byte 0x05, every ``daq.master_heartbeat_ms``) with python-can's
``send_periodic`` (the kernel's broadcast manager on socketcan, a thread elsewhere): it lasts
exactly as long as the process (and its socket), so a killed master falls silent. Each drive
whose EDS has 0x1016 gets ``0x1016.1 = (master id << 16) | consumer time [ms]``
(:meth:`MasterDrive.set_master_heartbeat`, read back) and faults when the heartbeat stops
(EMCY 0x8130 on CiA 301 drives). A *hung* master whose periodic heartbeat keeps going is
covered by the drive's SYNC-loss reaction, armed by the communication cycle period 0x1006
(:meth:`MasterDrive.set_sync_period`: the cycle [µs] in paced mode, 0 = off in lockstep,
where SYNCs may be far apart in wall time without anything being wrong). Without 0x1016 in
the EDS (Ingenia EVE-NET-C) the master says so (a note in the run's log and summary) and
carries on.

A hung master whose SYNC keeps coming (``sync_source = "periodic"``: the kernel's broadcast
manager, or a bridge, sends SYNC and heartbeat without the main loop) is caught only by the
drive's deadline monitoring of the received PDO: the RPDO1 event timer 0x1400 sub 5 [ms]
(CiA 301; :meth:`MasterDrive.set_rpdo_timeout`, written and read back; the simulated drive
faults with EMCY 0x8250 "RPDO timeout"). The master writes it in paced mode (the cycle x 3 +
100 ms, :func:`rpdo_timeout_ms`) and 0 in lockstep; an EDS whose 0x1400 has no sub-index 5
(Maxon EPOS4, Elmo Gold, Nanotec C5-E of ``../shared/eds``) gets a note instead.
"""

from __future__ import annotations

import logging
import math
import struct
from dataclasses import dataclass
from pathlib import Path

import canopen
from canopen.sdo.exceptions import SdoAbortedError, SdoCommunicationError

from daq import ConfigError
from daq.protocol.cia402 import SUPPORTED_MODE_BIT, Mode, supported_modes

from .config import DriveConfig, Scaling
from .heartbeat import MasterHeartbeat
from .sdo_log import handled_sdo_failures

__all__ = ["MasterDrive", "MasterHeartbeat", "pdo_lengths", "pdo_specs", "rpdo_timeout_ms"]

logger = logging.getLogger(__name__)

OBJECT_NAMES = {
    0x6040: "controlword",
    0x6041: "statusword",
    0x6060: "modes of operation",
    0x6061: "modes of operation display",
    0x6064: "position actual value",
    0x606C: "velocity actual value",
    0x6071: "target torque",
    0x6076: "motor rated torque",
    0x6077: "torque actual value",
    0x6080: "max motor speed",
    0x607A: "target position",
    0x6502: "supported drive modes",
}

RPDO_CST = ((0x6040, 0, 16), (0x6071, 0, 16))
RPDO_CSP = ((0x6040, 0, 16), (0x607A, 0, 32))
TPDO1 = ((0x6041, 0, 16), (0x6064, 0, 32), (0x6077, 0, 16))
TPDO2 = ((0x606C, 0, 32), (0x6061, 0, 8))

RPDO_CST_STRUCT = struct.Struct("<Hh")
RPDO_CSP_STRUCT = struct.Struct("<Hi")
TPDO1_STRUCT = struct.Struct("<Hih")
TPDO2_STRUCT = struct.Struct("<ib")

COB_DISABLED = 0x80000000
RPDO_TIMEOUT_CYCLES = 3  # RPDO event timer: this many cycles ...
RPDO_TIMEOUT_MARGIN_MS = 100  # ... plus this margin [ms] (host stalls), like the heartbeat


def rpdo_timeout_ms(cycle_s: float, paced: bool,
                    margin_ms: int = RPDO_TIMEOUT_MARGIN_MS) -> int:
    """RPDO1 event timer for the drives [ms]: ``ceil(3 x cycle) + margin_ms`` (``[daq]
    rpdo_margin_ms``, default 100) when paced, 0 (off) in lockstep, where cycles may be far
    apart in wall time."""
    if not paced:
        return 0
    return min(0xFFFF, math.ceil(RPDO_TIMEOUT_CYCLES * cycle_s * 1000.0 - 1e-9)
               + int(margin_ms))


@dataclass(frozen=True)
class PdoSpec:
    """One PDO to configure: number (1-based), direction, COB-ID and mapping."""

    name: str  # "RPDO1"
    comm_index: int  # 0x1400 / 0x1800 + n - 1
    map_index: int  # 0x1600 / 0x1A00 + n - 1
    cob_id: int
    entries: tuple[tuple[int, int, int], ...]  # (index, subindex, bits)

    @property
    def n_bytes(self) -> int:
        return sum(b for _, _, b in self.entries) // 8

    def words(self) -> list[int]:
        return [(i << 16) | (s << 8) | b for i, s, b in self.entries]


def pdo_specs(node_id: int, mode: Mode) -> tuple[PdoSpec, PdoSpec, PdoSpec]:
    """The cyclic PDO layout of a drive (RPDO1, TPDO1, TPDO2)."""
    rpdo = RPDO_CST if mode is Mode.CYCLIC_SYNC_TORQUE else RPDO_CSP
    return (
        PdoSpec("RPDO1", 0x1400, 0x1600, 0x200 + node_id, rpdo),
        PdoSpec("TPDO1", 0x1800, 0x1A00, 0x180 + node_id, TPDO1),
        PdoSpec("TPDO2", 0x1801, 0x1A01, 0x280 + node_id, TPDO2),
    )


def pdo_lengths(mode: Mode) -> tuple[int, int, int]:
    """Data lengths [byte] of the cyclic frames of one drive (RPDO1, TPDO1, TPDO2)."""
    return tuple(s.n_bytes for s in pdo_specs(1, mode))  # type: ignore[return-value]


def _u(data: bytes) -> int:
    return int.from_bytes(data, "little")


class MasterDrive:
    """The master's handle on one drive.

    Parameters
    ----------
    network : canopen.Network
        Connected network.
    cfg : DriveConfig
        Node id, EDS, mode, heartbeat, scaling.
    sdo_timeout_s : float
        SDO response timeout [s].

    Raises
    ------
    daq.ConfigError
        The EDS cannot be read, lacks an object of the cyclic layout or does not advertise
        the requested mode in 0x6502.
    """

    def __init__(self, network: canopen.Network, cfg: DriveConfig, sdo_timeout_s: float = 0.3):
        self.cfg = cfg
        self.node_id = cfg.node_id
        self.name = f"node {cfg.node_id}"
        try:
            od = canopen.import_od(str(cfg.eds), cfg.node_id)
        except Exception as exc:  # canopen raises bare errors on malformed files
            raise ConfigError(f"{cfg.eds}: cannot read the EDS ({exc})") from None
        self.od = od
        self.check_eds()
        self.node = canopen.RemoteNode(cfg.node_id, od)
        network.add_node(self.node)
        self.node.sdo.RESPONSE_TIMEOUT = sdo_timeout_s
        self.specs = pdo_specs(cfg.node_id, cfg.mode)
        self.rpdo_struct = RPDO_CST_STRUCT if cfg.mode is Mode.CYCLIC_SYNC_TORQUE else (
            RPDO_CSP_STRUCT)
        self.scaling: Scaling | None = cfg.scaling
        self.notes: list[str] = []  # start-up problems that do not stop the run
        self.consumer_value: int | None = None  # 0x1016.1 written, None if not
        self.rpdo_timer_ms: int | None = None  # 0x1400.5 written, None if not

    # -- static checks ------------------------------------------------------------------
    def check_eds(self) -> None:
        """Refuse an EDS that lacks an object of the cyclic layout or the requested mode."""
        od, cfg = self.od, self.cfg
        for spec in pdo_specs(cfg.node_id, cfg.mode):
            for idx in (spec.comm_index, spec.map_index):
                if idx not in od:
                    raise ConfigError(f"{self.name}: {cfg.eds.name} has no object 0x{idx:04X} "
                                      f"needed for {spec.name}")
            for idx, _, _ in spec.entries:
                if idx not in od:
                    raise ConfigError(f"{self.name}: {cfg.eds.name} has no object 0x{idx:04X} "
                                      f"({OBJECT_NAMES.get(idx, '')}) needed in {spec.name}")
        if 0x6502 in od:
            default = getattr(od[0x6502], "default", None)
            if isinstance(default, int):
                self._check_mode_mask(default, f"{cfg.eds.name} 0x6502 default")

    def _check_mode_mask(self, mask: int, where: str) -> None:
        mode = self.cfg.mode
        if not mask >> SUPPORTED_MODE_BIT[mode] & 1:
            have = ", ".join(sorted(m.name.lower() for m in supported_modes(mask))) or "none"
            raise ConfigError(
                f"{self.name}: {where} = 0x{mask:X} does not support {mode.name.lower()} "
                f"(mode {int(mode)}; supported: {have})"
            )

    # -- SDO helpers --------------------------------------------------------------------
    def upload(self, index: int, sub: int = 0) -> bytes:
        try:
            with handled_sdo_failures():
                return self.node.sdo.upload(index, sub)
        except SdoAbortedError as exc:
            raise ConfigError(f"{self.name}: reading 0x{index:04X}.{sub} aborted: {exc}") from None
        except SdoCommunicationError:
            raise ConfigError(f"{self.name}: no SDO answer reading 0x{index:04X}.{sub}") from None

    def download(self, index: int, sub: int, value: int, size: int, what: str = "") -> None:
        data = (value & ((1 << (8 * size)) - 1)).to_bytes(size, "little")
        try:
            with handled_sdo_failures():
                self.node.sdo.download(index, sub, data)
        except SdoAbortedError as exc:
            raise ConfigError(
                f"{self.name}: {what or 'writing'} 0x{index:04X}.{sub} = 0x{value:X} refused "
                f"by the drive: {exc}"
            ) from None
        except SdoCommunicationError:
            raise ConfigError(f"{self.name}: no SDO answer writing 0x{index:04X}.{sub}") from None

    # -- start-up sequence --------------------------------------------------------------
    def check_present(self) -> int:
        """Read 0x1000 (device type); refuse a node that does not answer."""
        try:
            with handled_sdo_failures():
                raw = self.node.sdo.upload(0x1000, 0)
        except SdoCommunicationError:
            raise ConfigError(
                f"{self.name}: no answer to SDO (is node {self.node_id} on the bus and powered?)"
            ) from None
        except SdoAbortedError as exc:
            raise ConfigError(f"{self.name}: reading device type 0x1000 aborted: {exc}") from None
        return _u(raw)

    def check_mode_supported(self) -> int:
        """Read 0x6502 from the drive and refuse the configured mode if it is missing."""
        mask = _u(self.upload(0x6502, 0))
        self._check_mode_mask(mask, "0x6502 (supported drive modes)")
        return mask

    def configure_pdos(self) -> None:
        """Write the cyclic PDO layout by SDO, disable the other PDOs, read everything back.

        Raises
        ------
        daq.ConfigError
            ``"node 1: RPDO1 mapping 0x1600.2 read back 0x00000000 != written 0x60710010"``.
        """
        for spec in self.specs:
            words = spec.words()
            self.download(spec.comm_index, 1, spec.cob_id | COB_DISABLED, 4, f"{spec.name} COB-ID")
            self.download(spec.map_index, 0, 0, 1, f"{spec.name} mapping count")
            for k, w in enumerate(words, start=1):
                self.download(spec.map_index, k, w, 4, f"{spec.name} mapping")
            self.download(spec.map_index, 0, len(words), 1, f"{spec.name} mapping count")
            self.download(spec.comm_index, 2, 1, 1, f"{spec.name} transmission type")
            self.download(spec.comm_index, 1, spec.cob_id, 4, f"{spec.name} COB-ID")
        used = {s.comm_index for s in self.specs}
        others = [(0x1400 + n, f"RPDO{n + 1}") for n in range(512)] + [
            (0x1800 + n, f"TPDO{n + 1}") for n in range(512)
        ]
        disabled = []
        for idx, name in others:
            if idx in used or idx not in self.od:
                continue
            cob = _u(self.upload(idx, 1))
            if not cob & COB_DISABLED:
                self.download(idx, 1, cob | COB_DISABLED, 4, f"{name} COB-ID (disable)")
            disabled.append((idx, name))
        self.verify_pdos(disabled)

    def verify_pdos(self, disabled: list[tuple[int, str]] = ()) -> None:
        """Read every configured sub-index back and compare with what was written."""
        for spec in self.specs:
            cob = _u(self.upload(spec.comm_index, 1))
            if cob & 0x9FFFFFFF != spec.cob_id:  # bits 29/30 (frame format, RTR) may differ
                raise ConfigError(f"{self.name}: {spec.name} COB-ID 0x{spec.comm_index:04X}.1 "
                                  f"read back 0x{cob:08X} != written 0x{spec.cob_id:08X}")
            tt = _u(self.upload(spec.comm_index, 2))
            if tt != 1:
                raise ConfigError(f"{self.name}: {spec.name} transmission type "
                                  f"0x{spec.comm_index:04X}.2 read back {tt} != written 1")
            words = spec.words()
            n = _u(self.upload(spec.map_index, 0))
            if n != len(words):
                raise ConfigError(f"{self.name}: {spec.name} mapping count "
                                  f"0x{spec.map_index:04X}.0 read back {n} != written "
                                  f"{len(words)}")
            for k, w in enumerate(words, start=1):
                got = _u(self.upload(spec.map_index, k))
                if got != w:
                    raise ConfigError(
                        f"{self.name}: {spec.name} mapping 0x{spec.map_index:04X}.{k} read back "
                        f"0x{got:08X} != written 0x{w:08X} "
                        f"({OBJECT_NAMES.get(w >> 16, 'object')} 0x{w >> 16:04X})"
                    )
        for idx, name in disabled:
            cob = _u(self.upload(idx, 1))
            if not cob & COB_DISABLED:
                raise ConfigError(f"{self.name}: {name} COB-ID 0x{idx:04X}.1 read back "
                                  f"0x{cob:08X}: still enabled after disabling it")

    def set_mode(self) -> None:
        """Write 0x6060 (modes of operation) and check 0x6061 follows."""
        mode = int(self.cfg.mode)
        self.download(0x6060, 0, mode, 1, "modes of operation")
        shown = int.from_bytes(self.upload(0x6061, 0)[:1], "little", signed=True)
        if shown != mode:
            raise ConfigError(f"{self.name}: 0x6061 (modes of operation display) = {shown} "
                              f"after writing 0x6060 = {mode}")

    def set_heartbeat(self) -> None:
        """Write the heartbeat producer time 0x1017 [ms] (skipped when 0)."""
        if self.cfg.heartbeat_ms:
            self.download(0x1017, 0, self.cfg.heartbeat_ms, 2, "heartbeat producer time")

    def set_master_heartbeat(self, master_id: int, consumer_ms: int) -> int | None:
        """Make the drive watch the master's heartbeat: 0x1016.1 = (id << 16) | time [ms].

        Writes 0 first (some drives refuse to change a non-zero entry in place), then the
        entry, and reads it back. Returns the value written, or None when the EDS has no
        0x1016 (nothing written: the caller reports it).

        Raises
        ------
        daq.ConfigError
            The drive refuses the entry or reads back another value.
        """
        if 0x1016 not in self.od:
            return None
        value = ((master_id & 0xFF) << 16) | (consumer_ms & 0xFFFF)
        self.download(0x1016, 1, 0, 4, "heartbeat consumer time")
        self.download(0x1016, 1, value, 4, "heartbeat consumer time")
        got = _u(self.upload(0x1016, 1))
        if got != value:
            raise ConfigError(f"{self.name}: heartbeat consumer 0x1016.1 read back 0x{got:08X} "
                              f"!= written 0x{value:08X}")
        return value

    def clear_master_heartbeat(self) -> str:
        """0x1016.1 = 0 (stop watching the master) before a normal shutdown.

        Returns
        -------
        str
            "" when cleared (or the EDS has no 0x1016), else a note for the run's summary:
            the drive faults (EMCY 0x8130) when the master's heartbeat stops.
        """
        if 0x1016 not in self.od:
            return ""
        try:
            with handled_sdo_failures():
                self.node.sdo.download(0x1016, 1, bytes(4))
        except SdoAbortedError as exc:
            why = f"refused: {exc}"
        except SdoCommunicationError:
            why = "no SDO answer: is the drive off, or its bus gone?"
        else:
            return ""
        return (f"{self.name}: heartbeat consumer 0x1016.1 not cleared after the run ({why}): "
                f"if the drive still watches the master, it faults (EMCY 0x8130) when its "
                f"heartbeat stops")

    def set_sync_period(self, period_us: int) -> bool | None:
        """Write the communication cycle period 0x1006 [µs] (0: no SYNC monitoring).

        Returns True when written and read back, False when the drive refused it or read
        back another value (the caller reports it), None when the EDS has no 0x1006.
        """
        if 0x1006 not in self.od:
            return None
        try:
            with handled_sdo_failures():
                self.node.sdo.download(0x1006, 0, int(period_us).to_bytes(4, "little"))
                return _u(self.node.sdo.upload(0x1006, 0)) == period_us
        except (SdoAbortedError, SdoCommunicationError):
            return False

    def has_rpdo_timer(self) -> bool:
        """Whether the EDS declares the RPDO1 event timer (0x1400 sub 5)."""
        if 0x1400 not in self.od:
            return False
        try:
            return 5 in self.od[0x1400]
        except TypeError:  # a VAR at 0x1400: no sub-indices
            return False

    def set_rpdo_timeout(self, timeout_ms: int) -> int | None:
        """RPDO1 deadline monitoring: write the event timer 0x1400.5 [ms] (0: off), read back.

        Returns the value written, or None when the EDS has no 0x1400 sub 5 (nothing
        written: the caller reports it).

        Raises
        ------
        daq.ConfigError
            The drive refuses the value or reads back another one.
        """
        if not self.has_rpdo_timer():
            return None
        self.download(0x1400, 5, timeout_ms, 2, "RPDO1 event timer")
        got = _u(self.upload(0x1400, 5))
        if got != timeout_ms:
            raise ConfigError(f"{self.name}: RPDO1 event timer 0x1400.5 read back {got} != "
                              f"written {timeout_ms} ms")
        return timeout_ms

    def set_interpolation_period(self, cycle_s: float) -> None:
        """Write 0x60C2 (interpolation time period) when present; ignore a refusal."""
        if 0x60C2 not in self.od:
            return
        ms = round(cycle_s * 1000)
        if abs(ms - cycle_s * 1000) > 1e-9 or not 1 <= ms <= 255:
            return
        try:
            with handled_sdo_failures():
                self.node.sdo.download(0x60C2, 1, bytes([ms]))
                self.node.sdo.download(0x60C2, 2, (-3 & 0xFF).to_bytes(1, "little"))
        except (SdoAbortedError, SdoCommunicationError):
            pass

    def set_max_torque(self, max_torque: float) -> int | None:
        """Write 0x6072 (max torque, per mille of rated) to cover ``max_torque`` [N m].

        The master saturates its own command at ``max_torque``; a drive whose 0x6072 is lower
        (Nanotec's default is 100 per mille) would fault on excess torque. Returns the value
        written, or None when the drive has no 0x6072.
        """
        if 0x6072 not in self.od or self.scaling is None:
            return None
        x = min(32767, int(math.ceil(max_torque / self.scaling.torque_per_unit)))
        self.download(0x6072, 0, x, 2, "max torque")
        return x

    def max_motor_speed_rpm(self) -> int | None:
        """The max motor speed 0x6080 [rpm] (CiA 402) the drive's EDS gives as default; None
        when the EDS has no 0x6080, no default, or "no limit" (0 or 0xFFFFFFFF). (The EDS,
        not the drive: some EDS declare the object without a value, and a simulated drive
        then serves a placeholder.)"""
        if 0x6080 not in self.od:
            return None
        rpm = getattr(self.od[0x6080], "default", None)
        if not isinstance(rpm, int) or isinstance(rpm, bool):
            return None
        return rpm if 0 < rpm < 0xFFFFFFFF else None

    def read_scaling(self) -> Scaling:
        """The scaling from the campaign, else from the drive (0x6076, 0x6091, 0x608F).

        Raises
        ------
        daq.ConfigError
            When neither the campaign nor the drive gives the rated torque and encoder
            resolution.
        """
        if self.scaling is not None:
            return self.scaling
        try:
            rated = _u(self.upload(0x6076, 0)) / 1000.0
        except ConfigError:
            rated = 0.0
        gear = 1.0
        counts = 0
        try:
            num, den = _u(self.upload(0x6091, 1)), _u(self.upload(0x6091, 2))
            gear = num / den if num and den else 1.0
        except ConfigError:
            pass
        try:
            inc, rev = _u(self.upload(0x608F, 1)), _u(self.upload(0x608F, 2))
            counts = inc // rev if inc and rev else 0
        except ConfigError:
            pass
        if rated <= 0 or counts <= 0:
            raise ConfigError(
                f"{self.name}: the drive gives no rated torque (0x6076) or encoder resolution "
                f"(0x608F): set daq.drives.scaling (rated_torque_Nm, encoder_counts_per_rev, "
                f"gear_ratio)"
            )
        self.scaling = Scaling(rated, gear, counts)
        return self.scaling

    def start_up(self, cycle_s: float, max_torque: float | None = None, *,
                 master_id: int = 0, consumer_ms: int = 0,
                 sync_period_us: int | None = None,
                 rpdo_timeout_ms: int | None = None) -> Scaling:
        """Full start-up sequence before NMT start: presence, mode, PDOs, heartbeat,
        master-loss reactions, max torque (0x6072) covering ``max_torque`` [N m].

        Parameters
        ----------
        cycle_s : float
            Control cycle [s].
        max_torque : float or None
            Torque the master may command [N m].
        master_id, consumer_ms : int
            Master node id and heartbeat consumer time [ms] for 0x1016.1 (0: not written).
        sync_period_us : int or None
            Communication cycle period written to 0x1006 [µs] (0: SYNC monitoring off;
            None: not written).
        rpdo_timeout_ms : int or None
            RPDO1 event timer written to 0x1400.5 [ms] (0: deadline monitoring off;
            None: not written). Without 0x1400.5 in the EDS a non-zero value becomes a
            note.

        Returns
        -------
        Scaling
            What the drive will be driven with. Problems that do not stop the run (no
            0x1016 in the EDS, 0x1006 refused) are appended to :attr:`notes`.
        """
        self.notes = []
        self.consumer_value = None
        self.rpdo_timer_ms = None
        self.check_present()
        self.node.nmt.send_command(0x80)  # enter PRE-OPERATIONAL
        self.check_mode_supported()
        self.configure_pdos()
        self.set_mode()
        self.set_interpolation_period(cycle_s)
        self.set_heartbeat()
        if master_id and consumer_ms:
            self.consumer_value = self.set_master_heartbeat(master_id, consumer_ms)
            if self.consumer_value is None:
                self.notes.append(
                    f"{self.name}: {self.cfg.eds.name} has no 0x1016 (heartbeat consumer): "
                    f"the drive will not stop by itself if the master dies")
        if sync_period_us is not None:
            ok = self.set_sync_period(sync_period_us)
            if ok is False:
                self.notes.append(f"{self.name}: communication cycle period 0x1006 = "
                                  f"{sync_period_us} us refused or not read back: no SYNC-loss "
                                  f"reaction configured")
        if rpdo_timeout_ms is not None:
            self.rpdo_timer_ms = self.set_rpdo_timeout(rpdo_timeout_ms)
            if self.rpdo_timer_ms is None and rpdo_timeout_ms:
                self.notes.append(
                    f"{self.name}: {self.cfg.eds.name} has no RPDO1 event timer (0x1400 sub 5): "
                    f"the drive will not stop by itself if a hung master's SYNC keeps coming")
        scaling = self.read_scaling()
        if max_torque is not None:
            self.set_max_torque(max_torque)
        return scaling

    def nmt_start(self) -> None:
        self.node.nmt.send_command(0x01)

    def nmt_preop(self) -> None:
        self.node.nmt.send_command(0x80)

    def eds_bytes(self) -> bytes:
        return Path(self.cfg.eds).read_bytes()
