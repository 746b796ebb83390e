"""NMT slave and master-loss watchdogs of :class:`sim_drivers.drive.SimulatedDrive` (CiA 301).

- NMT: boot-up frame (0x700+id, data 0x00) on start, on reset node and on reset
  communication, then PRE-OPERATIONAL; heartbeat producer per 0x1017; PRE-OPERATIONAL /
  OPERATIONAL / STOPPED. Reset node restores every object to its EDS/DCF value and the CiA 402
  state machine to SWITCH ON DISABLED; reset communication restores 0x1000-0x1FFF.
- Heartbeat consumer 0x1016, SYNC watchdog 0x1006 and RPDO deadline monitoring (event timer
  0x1400+n sub 5): see "Losing the master" in :mod:`sim_drivers.drive`. All three run in one
  daemon thread per drive (:meth:`NmtMixin._watchdog_loop`).
"""

from __future__ import annotations

import logging
from collections.abc import Callable

from canopen.sdo.exceptions import SdoAbortedError

from daq.protocol.cia402 import CYCLIC_MODES, State
from sim_drivers.faults import HEARTBEAT_LOST, RPDO_TIMEOUT, SYNC_LOST, error_register

logger = logging.getLogger("sim_drivers.drive")  # one logger for the whole drive, as before

# NMT states (heartbeat byte values).
NMT_INITIALISING = 0
NMT_STOPPED = 4
NMT_OPERATIONAL = 5
NMT_PRE_OPERATIONAL = 127
NMT_STATE_NAMES = {
    NMT_INITIALISING: "INITIALISING",
    NMT_STOPPED: "STOPPED",
    NMT_OPERATIONAL: "OPERATIONAL",
    NMT_PRE_OPERATIONAL: "PRE-OPERATIONAL",
}
SYNC_LOSS_PERIODS = 3  # SYNC watchdog: timeout in periods of 0x1006
SYNC_LOSS_FLOOR_S = 0.1  # SYNC watchdog: shortest timeout [s] (host stalls, see docstring)
_WD_IDLE_S = 0.5  # watchdog thread: re-check period while nothing is armed [s]
#: what a drive's watchdogs run on: ``time.monotonic()``, or SYNCs received x cycle
#: (:mod:`sim_drivers.drive`, "Clock")
CLOCKS = ("wall", "sync")
#: the cyclic modes (CSP, CSV, CST) as 0x6061 values: the SYNC watchdog is armed only in them
CYCLIC_MODE_INTS = frozenset(int(m) for m in CYCLIC_MODES)


class HbConsumer:
    """One entry of 0x1016: the heartbeat of ``node`` watched with ``time_s`` [s]."""

    __slots__ = ("sub", "node", "time_s", "last", "active", "timed_out", "received", "cb")

    def __init__(self, sub: int, node: int, time_s: float) -> None:
        self.sub = sub
        self.node = node
        self.time_s = time_s
        self.last = 0.0  # drive clock time of the last heartbeat [s]
        self.active = False  # a heartbeat was received since the entry was set
        self.timed_out = False
        self.received = 0
        self.cb: Callable | None = None


class NmtMixin:
    """NMT state, resets, heartbeat consumers and the SYNC watchdog (mixin of
    :class:`~sim_drivers.drive.SimulatedDrive`, which holds the state)."""

    @property
    def nmt_state(self) -> str:
        """NMT state name (``"PRE-OPERATIONAL"``, ``"OPERATIONAL"``, ``"STOPPED"``, ...)."""
        return NMT_STATE_NAMES[self.nmt]

    def _boot(self) -> None:
        """Initialisation -> boot-up frame -> PRE-OPERATIONAL, heartbeat per 0x1017."""
        self._set_nmt(NMT_INITIALISING)
        self._resubscribe_sync()
        self.network.send_message(0x700 + self.node_id, b"\x00")
        self._set_nmt(NMT_PRE_OPERATIONAL)
        self._load_watchdogs()
        hb = int(self._stored(0x1017, 0) or 0) if self._has(0x1017, 0) else 0
        self._heartbeat_stopped = False
        self.node.nmt.start_heartbeat(hb)

    def _set_nmt(self, state: int) -> None:
        was = self.nmt
        self.nmt = state
        if state != was:
            self._wd_wake.set()  # the SYNC watchdog is armed in OPERATIONAL only
        self.node.nmt._state = state
        if state == NMT_OPERATIONAL and was != NMT_OPERATIONAL:
            self._build_layouts()
        elif state != NMT_OPERATIONAL and was == NMT_OPERATIONAL:
            self._unsubscribe_pdos()
        if not self._heartbeat_stopped:
            self.node.nmt.update_heartbeat()

    def _reset(self, application: bool) -> None:
        self.node.nmt.stop_heartbeat()
        self._unsubscribe_pdos()
        store = self.node.data_store
        for index in list(store):
            if application or 0x1000 <= index <= 0x1FFF:
                del store[index]
        if application:
            for name in self._extra_names.values():
                self.__dict__.pop(name, None)
            self._extra_names.clear()
            self.error_code = 0
            self.error_register = 0
            self._internal_limit = self._following_error = False
            self._load_application()
            self._reset_state_machine()
        self._boot()

    def _on_nmt(self, can_id: int, data: bytes, timestamp: float) -> None:
        if len(data) < 2 or data[1] not in (0, self.node_id):
            return
        with self._lock:
            self._nmt_command(data[0])

    def _nmt_command(self, cmd: int) -> None:
        if cmd == 0x01 and self.nmt in (NMT_PRE_OPERATIONAL, NMT_STOPPED):
            self._set_nmt(NMT_OPERATIONAL)
        elif cmd == 0x02:
            self._set_nmt(NMT_STOPPED)
        elif cmd == 0x80:
            self._set_nmt(NMT_PRE_OPERATIONAL)
        elif cmd == 0x81:
            self._reset(application=True)
        elif cmd == 0x82:
            self._reset(application=False)

    @property
    def last_sync_time(self) -> float:
        """When the last SYNC was received [s] (0: none yet): ``time.monotonic()``, or the
        simulated time with the ``"sync"`` clock."""
        return self._last_sync

    @property
    def sync_timeout_s(self) -> float:
        """SYNC-loss timeout [s] from 0x1006 (0: the SYNC watchdog is off)."""
        return self._sync_timeout_s

    @property
    def rpdo_timers(self) -> dict[int, tuple[float, float]]:
        """RPDOs under deadline monitoring: number -> (event timer [s], drive clock time of
        the last reception [s], 0 when none yet)."""
        return {rx.number: (rx.timer_s, rx.last) for rx in self._rx_timed}

    @property
    def heartbeat_consumers(self) -> dict[int, tuple[float, bool, int]]:
        """Watched nodes from 0x1016: node id -> (consumer time [s], monitoring started,
        heartbeats received)."""
        return {c.node: (c.time_s, c.active, c.received) for c in self._consumers.values()}

    @property
    def heartbeat_last(self) -> dict[int, float]:
        """Watched nodes from 0x1016: node id -> when its last heartbeat was received [s] on
        the drive's clock (``time.monotonic()``, or simulated time; 0: none yet)."""
        return {c.node: c.last for c in self._consumers.values()}

    def _set_sync_period(self, period_us: int) -> None:
        period = int(period_us) * 1e-6
        self._sync_timeout_s = (max(SYNC_LOSS_PERIODS * period, self.sync_loss_floor_s)
                                if period > 0 else 0.0)
        self._wd_wake.set()

    def _load_watchdogs(self) -> None:
        """(Re)read 0x1016 and 0x1006 from the dictionary (boot, reset communication)."""
        self._set_sync_period(int(self._stored(0x1006, 0) or 0) if self._has(0x1006, 0) else 0)
        entries: dict[int, HbConsumer] = {}
        if 0x1016 in self.dod.od:
            for sub in range(1, 128):
                if not self._has(0x1016, sub):
                    continue
                value = int(self._stored(0x1016, sub) or 0)
                node, ms = (value >> 16) & 0xFF, value & 0xFFFF
                if node and ms:
                    entries[sub] = HbConsumer(sub, node, ms / 1000.0)
        self._set_consumers(entries)

    def _write_consumer(self, sub: int, value: int) -> None:
        """SDO write to 0x1016.sub: validate (CiA 301), then watch the new entry."""
        node, ms = (value >> 16) & 0xFF, value & 0xFFFF
        if node and ms and any(c.node == node and c.sub != sub
                               for c in self._consumers.values()):
            raise SdoAbortedError(0x06040043)  # general parameter incompatibility
        entries = {s: c for s, c in self._consumers.items() if s != sub}
        if node and ms:
            entries[sub] = HbConsumer(sub, node, ms / 1000.0)
        self._set_consumers(entries)

    def _set_consumers(self, entries: dict[int, HbConsumer]) -> None:
        for c in self._consumers.values():
            if c.cb is not None:
                self._safe_unsubscribe(0x700 + c.node, c.cb)
        self._consumers = entries
        if self._started:
            for c in entries.values():
                c.cb = self._make_consumer_handler(c)
                self.network.subscribe(0x700 + c.node, c.cb)
        self._wd_wake.set()

    def _make_consumer_handler(self, c: HbConsumer) -> Callable:
        wake = self._wd_wake
        now = self._now

        def handler(can_id: int, data: bytes, timestamp: float) -> None:
            c.last = now()
            c.received += 1
            if not c.active or c.timed_out:
                c.active = True
                c.timed_out = False
                wake.set()

        return handler

    def _watchdog_loop(self) -> None:
        """Sleep until the earliest deadline, check, repeat (the drive's timer thread)."""
        wake = self._wd_wake
        while self._wd_run:
            try:
                wait = self._check_watchdogs()
            except Exception:  # never let the safety thread die silently
                logger.exception("node %d: watchdog check failed", self.node_id)
                wait = _WD_IDLE_S
            wake.wait(wait)
            wake.clear()

    def _check_watchdogs(self) -> float:
        """Fire what timed out; return the time to the next deadline [s]."""
        wait = _WD_IDLE_S
        with self._lock:
            now = self._now()
            for c in list(self._consumers.values()):
                if not c.active or c.timed_out:
                    continue
                left = c.last + c.time_s - now
                if left <= 0.0:
                    c.timed_out = True
                    self.heartbeat_timeouts += 1
                    logger.warning("node %d: heartbeat of node %d lost (none for %.3f s, "
                                   "consumer time %g s, %d received)", self.node_id, c.node,
                                   now - c.last, c.time_s, c.received)
                    if self.cia_state in (State.OPERATION_ENABLED, State.QUICK_STOP_ACTIVE):
                        self.fault(HEARTBEAT_LOST)
                    else:
                        self.node.emcy.send(HEARTBEAT_LOST,
                                            self.error_register | error_register(HEARTBEAT_LOST))
                elif left < wait:
                    wait = left
            timeout = self._sync_timeout_s
            if (timeout and self.nmt == NMT_OPERATIONAL
                    and self.cia_state is State.OPERATION_ENABLED
                    and self.mode_display in CYCLIC_MODE_INTS):
                left = max(self._last_sync, self._enabled_at) + timeout - now
                if left <= 0.0:
                    self.sync_losses += 1
                    logger.warning("node %d: no SYNC for %.3f s (timeout %g s)", self.node_id,
                                   now - self._last_sync, timeout)
                    self.fault(SYNC_LOST)
                elif left < wait:
                    wait = left
            elif timeout and timeout < wait:
                wait = timeout  # configured, not armed: look again within one timeout
            if self._rx_timed:
                wait = self._check_rpdo_deadlines(now, wait)
        return wait

    def _check_rpdo_deadlines(self, now: float, wait: float) -> float:
        """RPDO deadline monitoring (CiA 301 event timer 0x1400+n sub 5): armed in NMT
        OPERATIONAL, OPERATION ENABLED, cyclic mode, from the first reception of the RPDO;
        counted from its last reception or from enabling, whichever is later. A timeout is
        a fault 0x8250 (called with the lock held); returns the time to the next deadline."""
        armed = (self.nmt == NMT_OPERATIONAL and self.cia_state is State.OPERATION_ENABLED
                 and self.mode_display in CYCLIC_MODE_INTS)
        for rx in self._rx_timed:
            if not armed or rx.last <= 0.0:
                if rx.timer_s < wait:
                    wait = rx.timer_s  # configured, not armed: look again within one timer
                continue
            left = max(rx.last, self._enabled_at) + rx.timer_s - now
            if left <= 0.0:
                self.rpdo_timeouts += 1
                logger.warning("node %d: RPDO%d timeout (none for %.3f s, event timer %g ms)",
                               self.node_id, rx.number, now - rx.last, rx.timer_s * 1e3)
                self.fault(RPDO_TIMEOUT)
                return wait
            if left < wait:
                wait = left
        return wait
