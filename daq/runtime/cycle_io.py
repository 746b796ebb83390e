"""Bus I/O of one control cycle: the listener that sorts TPDOs, heartbeats, EMCY and
records every frame of the cycle for the log (``/can/raw``).

Heartbeats are stamped with :attr:`CycleIO.clock`: ``time.monotonic()``, or in lockstep on a
channel clocked by simulated drives (:meth:`CycleIO.use_sync_clock`,
:func:`daq.runtime.buses.sync_clocked`) the SYNCs sent so far times the cycle -- the time the
simulated drives' heartbeats are produced on (:mod:`daq.runtime.simrig`), so the master's
heartbeat watchdog does not depend on the host's speed either."""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable, Sequence

import can
from can_remote.websocket import WebsocketClosed

from daq.protocol.logformat import FRAME

#: what a failing bus raises from ``send``/``recv``: python-can's errors, the OS's (socketcan,
#: a TCP bridge reset) and python-can-remote's closed WebSocket (its bridge process died)
BUS_ERRORS: tuple[type[BaseException], ...] = (can.CanError, OSError, WebsocketClosed)


class CycleIO(can.Listener):
    """Receives every frame in the notifier thread: TPDOs into slots, heartbeats, EMCY, and
    the raw-frame record of the cycle (struct-packed, no per-frame object kept)."""

    def __init__(self, node_ids: Sequence[int]) -> None:
        self.n = len(node_ids)
        self.tpdo: dict[int, tuple[int, int, int]] = {}
        for d, nid in enumerate(node_ids):
            self.tpdo[0x180 + nid] = (d, 0, 1 << (2 * d))
            self.tpdo[0x280 + nid] = (d, 1, 1 << (2 * d + 1))
        self.hb_index = {0x700 + nid: d for d, nid in enumerate(node_ids)}
        self.emcy_index = {0x80 + nid: d for d, nid in enumerate(node_ids)}
        self.full = (1 << (2 * self.n)) - 1
        self.mask = 0
        self.data: list[list[bytes]] = [[b"", b""] for _ in node_ids]
        self.q: queue.SimpleQueue = queue.SimpleQueue()
        self.lock = threading.Lock()
        self.frames = bytearray()
        self.n_frames = 0
        self.syncs = 0  # SYNCs sent (sent() with COB-ID 0x080)
        self.clock: Callable[[], float] = time.monotonic  # heartbeat times [s]
        now = self.clock()
        self.hb_time = [now] * self.n
        self.hb_state = [-1] * self.n
        self.emcy: list[tuple[int, int, int]] = []  # (drive, code, register)
        self.log_frames = True
        self.direct = False  # True: the main thread pumps the bus itself (see pump)
        #: per drive, its TPDO1 frames received since begin_cycle (two or more: an answer to
        #: an earlier SYNC came with this one's; the start-up lateness check counts them)
        self.answers = [0] * self.n

    def on_message_received(self, msg: can.Message) -> None:
        cid = msg.arbitration_id
        data = bytes(msg.data)  # once: logged and kept
        if self.log_frames:
            rec = FRAME.pack(msg.timestamp, cid, msg.dlc, data)
            if self.direct:
                self.frames += rec
                self.n_frames += 1
            else:
                with self.lock:
                    self.frames += rec
                    self.n_frames += 1
        slot = self.tpdo.get(cid)
        if slot is not None:
            d, s, bit = slot
            self.data[d][s] = data
            if not s:
                self.answers[d] += 1
            m = self.mask | bit
            self.mask = m
            if m == self.full and not self.direct:
                self.q.put(True)
            return
        d = self.hb_index.get(cid)
        if d is not None:
            self.hb_time[d] = self.clock()
            self.hb_state[d] = data[0] & 0x7F if data else -1
            return
        d = self.emcy_index.get(cid)
        if d is not None and len(data) >= 3:
            code = data[0] | data[1] << 8
            if code:  # 0 = error reset / no error
                self.emcy.append((d, code, data[2]))

    def use_sync_clock(self, cycle_s: float) -> None:
        """Stamp heartbeats with simulated time: SYNCs sent x ``cycle_s`` [s]."""
        self.clock = lambda: self.syncs * cycle_s
        self.hb_time = [self.clock()] * self.n

    def sent(self, ts: float, cid: int, data: bytes) -> None:
        if cid == 0x80:
            self.syncs += 1
        rec = FRAME.pack(ts, cid, len(data), data)
        if self.direct:  # no notifier thread: nobody else appends
            self.frames += rec
            self.n_frames += 1
            return
        with self.lock:
            self.frames += rec
            self.n_frames += 1

    def take_frames(self) -> tuple[bytes, int]:
        with self.lock:
            buf, n = bytes(self.frames), self.n_frames
            self.frames.clear()
            self.n_frames = 0
        return buf, n

    def begin_cycle(self) -> None:
        self.mask = 0
        self.answers = [0] * self.n
        q = self.q
        while not q.empty():
            q.get_nowait()

    def pump(self, bus: can.BusABC, timeout: float) -> bool:
        """Receive on the calling thread until every TPDO of the cycle arrived or ``timeout``
        [s] passed; True when complete. Used while the notifier is stopped (one thread
        hand-off less per cycle than notifier + queue)."""
        perf = time.perf_counter
        end = perf() + timeout
        recv = bus.recv
        on = self.on_message_received
        full = self.full
        while self.mask != full:
            remaining = end - perf()
            msg = recv(remaining if remaining > 0 else 0.0)
            if msg is None:
                return False
            on(msg)
        return True

    def wait(self, timeout: float) -> bool:
        try:
            self.q.get(timeout=timeout) if timeout > 0 else self.q.get_nowait()
            return True
        except queue.Empty:
            return self.mask == self.full
