"""PDO handling of :class:`sim_drivers.drive.SimulatedDrive` (CiA 301).

Mapping writes over SDO are validated (mappable objects only 0x06040041, at most 64 bits
0x06040042, only while the PDO is disabled and sub 0 is 0 0x08000022); the layouts are rebuilt
from the dictionary on NMT start (and on the next SYNC after a communication object changed)
into ``struct.Struct`` objects. Synchronous RPDOs (types 0-240) are latched and applied on
SYNC; event RPDOs (254/255) on reception. Synchronous TPDOs (type n in 1-240: every n-th SYNC;
0: every SYNC) are sent by the cycle; event TPDOs (254/255) when their content changed.
"""

from __future__ import annotations

import logging
import operator
import struct
from collections.abc import Callable
from typing import Any

import canopen
from canopen.sdo.exceptions import SdoAbortedError

from sim_drivers.faults import PDO_LENGTH_ERROR
from sim_drivers.nmt import NMT_OPERATIONAL
from sim_drivers.od import STRUCT_CODE, DriveConfigError, struct_code

logger = logging.getLogger("sim_drivers.drive")  # one logger for the whole drive, as before

_PDO_NOT_VALID = 0x80000000


def wrap_i32(x: int) -> int:
    """``x`` wrapped to int32 (two's complement), as a drive reports 0x6064."""
    return ((x + 0x80000000) & 0xFFFFFFFF) - 0x80000000


def clip_int(x: int, lo: int, hi: int) -> int:
    """``x`` clipped to ``[lo, hi]``."""
    return lo if x < lo else hi if x > hi else x


class RxPdo:
    __slots__ = ("cob_id", "sync", "struct", "names", "latched", "number", "handler",
                 "timer_s", "last")

    def __init__(self, number: int, cob_id: int, sync: bool, st: struct.Struct, names: tuple,
                 timer_s: float = 0.0):
        self.number = number
        self.cob_id = cob_id
        self.sync = sync
        self.struct = st
        self.names = names
        self.latched: bytes | None = None
        self.handler: Callable | None = None
        self.timer_s = timer_s  # event timer 0x1400+n sub 5 [s] (0: no deadline monitoring)
        self.last = 0.0  # drive clock time of the last reception [s] (0: none yet)


class TxPdo:
    __slots__ = ("cob_id", "every", "count", "struct", "getter", "single", "last", "number")

    def __init__(
        self, number: int, cob_id: int, every: int, st: struct.Struct, names: tuple[str, ...]
    ):
        self.number = number
        self.cob_id = cob_id
        self.every = every  # 0: event driven
        self.count = 0
        self.struct = st
        self.getter = operator.attrgetter(*names) if names else (lambda obj: ())
        self.single = len(names) == 1
        self.last: bytes | None = None

    def payload(self, drive: Any) -> bytes:
        values = self.getter(drive)
        try:
            return self.struct.pack(values) if self.single else self.struct.pack(*values)
        except struct.error:  # a value outside its mapped type: saturate, like a drive
            values = (values,) if self.single else values
            return self.struct.pack(*_saturate(self.struct.format, values))


_INT_RANGES = {
    "b": (-0x80, 0x7F), "B": (0, 0xFF), "h": (-0x8000, 0x7FFF), "H": (0, 0xFFFF),
    "i": (-0x80000000, 0x7FFFFFFF), "I": (0, 0xFFFFFFFF),
    "q": (-(1 << 63), (1 << 63) - 1), "Q": (0, (1 << 64) - 1),
}


def _saturate(fmt: str, values: tuple) -> list:
    """Clip integer values to the ranges of their struct codes (padding codes skipped)."""
    codes = [c for c in fmt.lstrip("<") if not c.isdigit() and c != "x"]
    out = []
    for code, v in zip(codes, values, strict=True):
        rng = _INT_RANGES.get(code)
        out.append(clip_int(int(v), *rng) if rng else v)
    return out


class PdoMixin:
    """PDO mapping checks, layouts, RPDO application and event TPDOs (mixin of
    :class:`~sim_drivers.drive.SimulatedDrive`)."""

    def _check_pdo_write(self, index: int, subindex: int, od: Any, data: bytes) -> None:
        """Validate a write to a PDO communication (14xx/18xx) or mapping (16xx/1Axx) object."""
        is_map = 0x1600 <= index <= 0x17FF or 0x1A00 <= index <= 0x1BFF
        comm = index - 0x200 if is_map else index
        cob = self._stored(comm, 1) if self._has(comm, 1) else _PDO_NOT_VALID
        enabled = not (int(cob) & _PDO_NOT_VALID)
        value = od.decode_raw(data)
        if not is_map:
            if subindex == 1 and enabled and not value & _PDO_NOT_VALID:
                if (value ^ int(cob)) & 0x1FFFFFFF:
                    raise SdoAbortedError(0x06090030)  # COB-ID change of a valid PDO
            if subindex == 2 and not (value <= 240 or value >= 252):
                raise SdoAbortedError(0x06090030)
            return
        if enabled:
            raise SdoAbortedError(0x08000022)  # mapping change while the PDO is valid
        receive = index < 0x1A00
        if subindex == 0:
            obj = self.dod.od[index]
            slots = max((s for s in getattr(obj, "subindices", ()) if s > 0), default=0)
            if isinstance(obj, canopen.objectdictionary.ODArray):
                slots = max(slots, int(obj[0].default or 0))
            if value > slots or value > 64:
                raise SdoAbortedError(0x06090031)
            bits = 0
            for s in range(1, value + 1):
                entry = int(self._stored(index, s) or 0)
                if entry >> 16:
                    self._check_entry(entry, receive)
                bits += entry & 0xFF
            if bits > 64:
                raise SdoAbortedError(0x06040042)
            return
        if int(self._stored(index, 0) or 0) != 0:
            raise SdoAbortedError(0x08000022)  # entries only while sub 0 is 0
        if value >> 16:
            self._check_entry(value, receive)

    def _check_entry(self, entry: int, receive: bool) -> None:
        index, subindex, bits = entry >> 16, (entry >> 8) & 0xFF, entry & 0xFF
        if 1 <= index <= 7:  # dummy entries: data type sizes
            if bits % 8:
                raise SdoAbortedError(0x06040041)
            return
        if not self._has(index, subindex):
            raise SdoAbortedError(0x06020000)
        var = self._var(index, subindex)
        if not var.pdo_mappable or var.data_type not in _STRUCT_TYPES:
            raise SdoAbortedError(0x06040041)
        if receive and not var.writable or not receive and not var.readable:
            raise SdoAbortedError(0x06040041)
        if bits != len(var):
            raise SdoAbortedError(0x06040041)
        if bits > 64:
            raise SdoAbortedError(0x06040042)

    def _resubscribe_sync(self) -> None:
        self._safe_unsubscribe(self._sync_cob, self._on_sync)
        cob = self._stored(0x1005, 0) if self._has(0x1005, 0) else 0x80
        self._sync_cob = int(cob if cob is not None else 0x80) & 0x7FF
        self.network.subscribe(self._sync_cob, self._on_sync)

    def _unsubscribe_pdos(self) -> None:
        for rx in self._rx:
            if rx.handler is not None:
                self._safe_unsubscribe(rx.cob_id, rx.handler)
        self._rx = []
        self._rx_sync = []
        self._rx_timed = []
        self._tx_sync = []
        self._tx_event = []

    def _entries(self, map_index: int) -> tuple[struct.Struct, tuple]:
        count = int(self._stored(map_index, 0) or 0)
        codes: list[str] = []
        names: list[str] = []
        for s in range(1, count + 1):
            entry = int(self._stored(map_index, s) or 0)
            index, subindex, bits = entry >> 16, (entry >> 8) & 0xFF, entry & 0xFF
            if index == 0 or bits == 0:
                continue
            if 1 <= index <= 7:
                codes.append(f"{bits // 8}x")
                continue
            var = self._var(index, subindex)
            codes.append(struct_code(var))
            names.append(self._name_for(index, subindex))
        return struct.Struct("<" + "".join(codes)), tuple(names)

    def _name_for(self, index: int, subindex: int) -> str:
        name = self._live.get((index, subindex))
        if name is not None:
            return name
        name = self._extra_names.get((index, subindex))
        if name is None:
            name = f"_obj_{index:04X}_{subindex:02X}"
            self._extra_names[(index, subindex)] = name
            value = self._stored(index, subindex)
            setattr(self, name, 0 if value is None else value)
        return name

    def _build_layouts(self) -> None:
        """Read the PDO configuration from the dictionary into struct layouts and subscribe."""
        self._unsubscribe_pdos()
        self._layout_dirty = False
        self._resubscribe_sync()
        for n, cob, trans, (st, names) in self._valid_pdos(0x1400, 0x1600):
            timer_ms = int(self._stored(0x1400 + n, 5) or 0) if self._has(0x1400 + n, 5) else 0
            rx = RxPdo(n + 1, cob, trans <= 240, st, names, timer_ms / 1000.0)
            self._rx.append(rx)
            if rx.sync:
                self._rx_sync.append(rx)
            if rx.timer_s > 0.0:
                self._rx_timed.append(rx)
            self.network.subscribe(rx.cob_id, self._make_rx_handler(rx))
        if self._rx_timed:
            self._wd_wake.set()  # deadline monitoring configured: the watchdog thread looks
        for n, cob, trans, (st, names) in self._valid_pdos(0x1800, 0x1A00):
            if trans <= 240:
                self._tx_sync.append(TxPdo(n + 1, cob, max(trans, 1), st, names))
            elif trans >= 254:
                self._tx_event.append(TxPdo(n + 1, cob, 0, st, names))
            # 252/253 (RTR only): not served, LocalNode drops remote frames

    def _valid_pdos(self, comm_base: int, map_base: int):
        """Yield ``(n, cob_id, transmission_type, layout)`` of each valid, non-empty PDO whose
        communication object is ``comm_base + n`` and mapping object ``map_base + n``."""
        od = self.dod.od
        for n in range(512):
            comm = comm_base + n
            if comm not in od:
                continue
            cob = int(self._stored(comm, 1) or _PDO_NOT_VALID)
            if cob & _PDO_NOT_VALID or map_base + n not in od:
                continue
            trans = int(self._stored(comm, 2) or 0) if self._has(comm, 2) else 255
            layout = self._layout_or_none(map_base + n)
            if layout is not None:
                yield n, cob & 0x7FF, trans, layout

    def _layout_or_none(self, map_index: int) -> tuple[struct.Struct, tuple] | None:
        """Layout of one mapping object; None for an empty mapping (sub 0 = 0: the PDO is not
        used) or, logged, when a file's own default mapping names an object the simulation
        cannot pack (missing, or no fixed-size type)."""
        try:
            st, names = self._entries(map_index)
        except (DriveConfigError, SdoAbortedError) as exc:
            logger.warning("node %d: PDO mapping 0x%04X not served: %s", self.node_id,
                           map_index, exc)
            return None
        return (st, names) if st.size else None

    def _make_rx_handler(self, rx: RxPdo) -> Callable:
        now = self._now
        if rx.sync:

            def handler(can_id: int, data: bytes, timestamp: float) -> None:
                rx.latched = data
                rx.last = now()
        else:

            def handler(can_id: int, data: bytes, timestamp: float) -> None:
                rx.last = now()
                if self.nmt == NMT_OPERATIONAL:
                    if self._apply_rpdo(rx, data):
                        self._after_rx()

        rx.handler = handler
        return handler

    def _apply_rpdo(self, rx: RxPdo, data: bytes) -> bool:
        if len(data) < rx.struct.size:
            self.rx_length_errors += 1
            # CiA 301: "PDO not processed due to length error", a warning (no state change)
            self.node.emcy.send(PDO_LENGTH_ERROR, self.error_register | 0x11)
            return False
        self.__dict__.update(zip(rx.names, rx.struct.unpack_from(data), strict=False))
        return True

    def _after_rx(self) -> None:
        """Apply what RPDOs changed: mode request, controlword; then event TPDOs."""
        if self.mode_request != self.mode_display:
            self._apply_mode_request()
        self._evaluate_controlword()
        self._send_event_tpdos()

    def _apply_mode_request(self) -> None:
        """0x6060 arrived by RPDO: follow it if advertised, else keep the mode (no abort)."""
        if self.mode_request in self._supported or self.mode_request == 0:
            self.mode_display = self.mode_request
            self._update_statusword()
        else:
            self.rx_rejected_modes += 1
            self.mode_request = self.mode_display

    def _send_event_tpdos(self) -> None:
        if self.nmt != NMT_OPERATIONAL:
            return
        send = self._send
        for tx in self._tx_event:
            payload = tx.payload(self)
            if payload != tx.last:
                tx.last = payload
                send(tx.cob_id, payload)
                self.tpdo_sent += 1


_STRUCT_TYPES = frozenset(STRUCT_CODE)
