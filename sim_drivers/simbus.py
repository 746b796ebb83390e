"""The simulated drives' end of a python-can virtual channel: one bus object for all of them.

Why not one ``can.Bus(interface="virtual")`` per simulated drive: python-can's
``VirtualBus.send`` deep-copies every frame into the queue of every *other* bus object on the
channel, and each bus object has its own notifier thread waking up for every frame; with n
drives each on its own bus, one cycle (SYNC, n RPDOs, 2 n TPDOs) costs O(n^2) copies and
thread wake-ups (``benchmarks/bench_daq.py``, ``/work/shared/notes/performance.md``).

:class:`SimBus` is a python-can bus (:class:`can.BusABC`) that joins an existing virtual
channel of python-can's ``virtual`` interface, so the master keeps its ordinary
``can.Bus(interface="virtual", channel=...)`` -- the same master code as on socketcan -- and
sees the simulated drives as peers on the channel. All simulated drives share it (through one
``canopen.Network``). Frames it receives are delivered in one of two ways:

``dispatch="thread"``
    Queued; a single notifier thread (``canopen.Network.connect``) receives them, as on any
    python-can bus. For the paced clock: the drives answer in their own thread, like real
    drives answer in parallel with the master.
``dispatch="inline"``
    Handed to the listeners (the drives' ``canopen.Network``) at once, in the sending
    thread, serialised by one lock: the master's ``bus.send(SYNC)`` returns after every
    drive stepped and queued its TPDOs, so a lockstep cycle has no thread hand-off at all.
    Only for the lockstep clock (a SYNC send then takes as long as the drives' work).

Frames the drives send are delivered to every other bus object on the channel as a fresh
:class:`can.Message` (timestamp, ``is_rx``, channel set like ``VirtualBus`` does), built
directly instead of by ``copy.deepcopy``.

Simulated time (the lockstep clock)
-----------------------------------
An ``"inline"`` SimBus built with ``sync_cycle_s`` makes its channel *clocked*: simulated time
advances by ``sync_cycle_s`` with each SYNC (COB-ID 0x080) it receives, and nothing else makes
it pass. Every ``send_periodic`` of a SimBus on a clocked channel -- the drives' heartbeat
producers (canopen's ``LocalNode``) and the master's own heartbeat when the master's end is a
SimBus (``daq.runtime.buses.open_buses`` on the virtual interface) -- is then a
:class:`SyncPeriodicTask`: one frame when it starts (as python-can's thread task does), then
one every ``max(1, round(period / sync_cycle_s))`` SYNCs, sent right after the drives handled
that SYNC, from the SYNC sender's thread. So in lockstep the heartbeats are as deterministic
as the PDOs: a host stall stops SYNC and heartbeats together, and a run faster than real time
does not spread them out. Without ``sync_cycle_s`` (and for the paced clock) periodic sends
are python-can's wall-clock thread tasks. :attr:`SimBus.sync_count` is the number of SYNCs the
channel's clock has seen.

This relies on the layout of python-can's virtual interface (a module-level ``channels``
dict of lists of per-bus queues with ``put(msg, block, timeout)``), checked when the bus is
built: :class:`~sim_drivers.SimError` if it is not there. At most one ``"inline"`` SimBus per
channel (two would call into each other's drives under their locks).

:class:`SimNetwork` is the rig of the simulated side: one SimBus, one ``canopen.Network``
(one notifier thread in ``"thread"`` mode, none inline) shared by every
:class:`~sim_drivers.drive.SimulatedDrive` of the channel, and an orderly :meth:`close`
(drives stopped -- heartbeats and watchdogs first --, then the notifier, then the bus).
"""

from __future__ import annotations

import contextlib
import logging
import queue
import threading
import time
from collections.abc import Iterable
from typing import Any

import can
import canopen
from can.broadcastmanager import ModifiableCyclicTaskABC, RestartableCyclicTaskABC
from can.interfaces import virtual as _virtual

from sim_drivers import SimError

logger = logging.getLogger(__name__)

__all__ = ["SimBus", "SimNetwork", "SyncPeriodicTask"]

DISPATCH = ("inline", "thread")


class SimBus(can.BusABC):
    """A python-can bus on a virtual channel shared by all simulated drives.

    Parameters
    ----------
    channel : str
        The virtual channel (the master opens ``can.Bus(interface="virtual", channel=...)``
        on the same name, before or after).
    dispatch : {"inline", "thread"}
        How received frames reach the listeners (module docstring).
    sync_cycle_s : float or None
        ``"inline"`` only: make the channel clocked, one SYNC = ``sync_cycle_s`` [s] of
        simulated time (module docstring); None: periodic sends on the wall clock.
    **kwargs
        Passed to :class:`can.BusABC` (``can_filters``).

    Notes
    -----
    In ``"inline"`` mode, register the receivers with :meth:`add_listener` (for a
    ``canopen.Network``: its ``listeners``) instead of starting a notifier; ``recv``
    then never returns a frame.
    """

    def __init__(self, channel: str, *, dispatch: str = "thread",
                 sync_cycle_s: float | None = None, **kwargs: Any) -> None:
        if dispatch not in DISPATCH:
            raise SimError(f"SimBus: dispatch: expected one of {DISPATCH}, got {dispatch!r}")
        if sync_cycle_s is not None and (dispatch != "inline" or not sync_cycle_s > 0):
            raise SimError(f"SimBus: sync_cycle_s: expected a period > 0 [s] with "
                           f"dispatch='inline', got {sync_cycle_s!r} with {dispatch!r}")
        channels = getattr(_virtual, "channels", None)
        lock = getattr(_virtual, "channels_lock", None)
        if not isinstance(channels, dict) or lock is None:
            raise SimError(f"SimBus: python-can {can.__version__}: the virtual interface has "
                           f"no 'channels' registry to join")
        with lock:
            if dispatch == "inline" and any(isinstance(p, SimBus) and p.dispatch == "inline"
                                            for p in channels.get(channel, ())):
                raise SimError(f"SimBus: channel {channel!r} already has an inline SimBus "
                               f"(one per channel)")
        super().__init__(channel=channel, **kwargs)
        self.channel_id = channel
        self.channel_info = f"virtual channel {channel} (jointid SimBus, {dispatch} dispatch)"
        self.dispatch = dispatch
        self.frames_in = 0
        self.frames_out = 0
        self._rx: queue.SimpleQueue[can.Message] = queue.SimpleQueue()
        self._listeners: list[can.Listener] = []
        self._lock = threading.RLock()
        self._open = True
        self.sync_cycle_s = sync_cycle_s
        self.sync_count = 0  # SYNCs received (clocked channel)
        self._sync_tasks: list[SyncPeriodicTask] = []
        with lock:
            self._peers: list[Any] = channels.setdefault(channel, [])
            self._peers.append(self)

    # -- called by the other bus objects of the channel (VirtualBus.send) ------------------
    def put(self, msg: can.Message, block: bool = True, timeout: float | None = None) -> None:
        """Receive one frame from a peer (the ``queue.Queue.put`` of the virtual interface)."""
        if not self._open:
            return
        self.frames_in += 1
        if self.dispatch == "thread":
            self._rx.put(msg)
            return
        if self._filters is not None and not self._matches_filters(msg):
            return
        with self._lock:
            for listener in self._listeners:
                try:
                    listener.on_message_received(msg)
                except Exception:  # a receiver's bug must not break the sender's send()
                    logger.exception("SimBus %s: listener %r failed", self.channel_id,
                                     listener)
            if (self.sync_cycle_s is not None and msg.arbitration_id == 0x80
                    and not msg.is_extended_id and not msg.is_remote_frame
                    and not msg.is_error_frame):
                self._tick()

    # -- simulated time ----------------------------------------------------------------------
    def _tick(self) -> None:
        """One SYNC of a clocked channel: time advances, due periodic frames go out."""
        self.sync_count = n = self.sync_count + 1
        for task in tuple(self._sync_tasks):
            try:
                task._on_sync(n)
            except Exception:
                logger.exception("SimBus %s: periodic task 0x%03X failed", self.channel_id,
                                 task.arbitration_id)

    def channel_clock(self) -> SimBus | None:
        """The SimBus that keeps this channel's simulated time (None: not clocked)."""
        for peer in tuple(self._peers):
            if isinstance(peer, SimBus) and peer.sync_cycle_s is not None and peer._open:
                return peer
        return None

    def _send_periodic_internal(self, msgs, period, duration=None, autostart=True,
                                modifier_callback=None):  # noqa: ANN001 - python-can's API
        """python-can's thread task, or on a clocked channel a :class:`SyncPeriodicTask`."""
        clock = self.channel_clock()
        if clock is None or modifier_callback is not None:
            return super()._send_periodic_internal(msgs, period, duration, autostart,
                                                   modifier_callback)
        task = SyncPeriodicTask(self, clock, msgs, period, duration)
        if autostart:
            task.start()
        return task

    # -- BusABC ------------------------------------------------------------------------------
    def add_listener(self, listener: can.Listener) -> None:
        """Deliver received frames to ``listener`` (``"inline"`` mode)."""
        with self._lock:
            self._listeners.append(listener)

    def add_listeners(self, listeners: Iterable[can.Listener]) -> None:
        for listener in listeners:
            self.add_listener(listener)

    def recv(self, timeout: float | None = None) -> can.Message | None:
        """:meth:`can.BusABC.recv` without its per-frame overhead when no filter is set."""
        if self._filters is not None:
            return super().recv(timeout)
        if not self._open:
            raise can.CanOperationError("Cannot operate on a closed bus")
        try:
            if timeout is None:
                return self._rx.get()
            return self._rx.get(timeout=timeout) if timeout > 0 else self._rx.get_nowait()
        except queue.Empty:
            return None

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if not self._open:
            raise can.CanOperationError("Cannot operate on a closed bus")
        try:
            if timeout is None:
                return self._rx.get(), False
            return self._rx.get(timeout=timeout) if timeout > 0 else self._rx.get_nowait(), False
        except queue.Empty:
            return None, False

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if not self._open:
            raise can.CanOperationError("Cannot operate on a closed bus")
        ts = time.time()
        data = bytes(msg.data) if msg.data is not None else b""
        self.frames_out += 1
        for peer in self._peers:
            if peer is self:
                continue
            copy = can.Message(
                timestamp=ts, arbitration_id=msg.arbitration_id,
                is_extended_id=msg.is_extended_id, is_remote_frame=msg.is_remote_frame,
                is_error_frame=msg.is_error_frame, channel=self.channel_id, dlc=msg.dlc,
                data=data, is_fd=msg.is_fd, is_rx=True, bitrate_switch=msg.bitrate_switch,
                error_state_indicator=msg.error_state_indicator, check=False,
            )
            try:
                peer.put(copy, block=True, timeout=timeout)
            except queue.Full:
                raise can.CanOperationError(
                    "Could not send message to one or more recipients") from None

    def send_frame(self, can_id: int, data: bytes) -> None:
        """Send a classic data frame (11-bit id unless ``can_id`` > 0x7FF): :meth:`send`
        without building the caller's :class:`can.Message` first (the drives' TPDOs)."""
        if not self._open:
            raise can.CanOperationError("Cannot operate on a closed bus")
        ts = time.time()
        self.frames_out += 1
        ext = can_id > 0x7FF
        for peer in self._peers:
            if peer is not self:
                peer.put(can.Message(timestamp=ts, arbitration_id=can_id, is_extended_id=ext,
                                     channel=self.channel_id, data=data, is_rx=True,
                                     check=False))

    def shutdown(self) -> None:
        super().shutdown()
        if self._open:
            self._open = False
            with _virtual.channels_lock:
                if self in self._peers:
                    self._peers.remove(self)
                if not self._peers and _virtual.channels.get(self.channel_id) is self._peers:
                    del _virtual.channels[self.channel_id]
            with self._lock:
                self._listeners.clear()
                self._sync_tasks.clear()


class SyncPeriodicTask(ModifiableCyclicTaskABC, RestartableCyclicTaskABC):
    """A periodic send paced by the SYNCs of a clocked channel (:class:`SimBus`, module
    docstring): one frame at :meth:`start`, then one every ``max(1, round(period /
    sync_cycle_s))`` SYNCs, in turn when several messages are given; ``duration`` [s] of
    simulated time, when given, ends it.

    Parameters
    ----------
    bus : SimBus
        The bus the frames are sent on (the task's owner).
    clock : SimBus
        The channel's clocked SimBus (:meth:`SimBus.channel_clock`).
    messages, period, duration
        As python-can's ``send_periodic`` ([s]).
    """

    def __init__(self, bus: SimBus, clock: SimBus, messages: Any, period: float,
                 duration: float | None = None) -> None:
        super().__init__(messages, period)
        self.bus = bus
        self.clock = clock
        cycle = float(clock.sync_cycle_s or period)
        self.every = max(1, round(period / cycle))  # SYNCs per frame
        self.end = None if duration is None else max(1, round(duration / cycle))
        self._started_at = 0
        self._index = 0
        self._running = False

    def start(self) -> None:
        """Send the first frame now, then one every ``every`` SYNCs (idempotent)."""
        if self._running:
            return
        self._running = True
        self._started_at = self.clock.sync_count
        with self.clock._lock:
            self.clock._sync_tasks.append(self)
        self._send()

    def stop(self) -> None:
        """No more frames (idempotent)."""
        self._running = False
        with self.clock._lock:
            if self in self.clock._sync_tasks:
                self.clock._sync_tasks.remove(self)

    def modify_data(self, messages: Any) -> None:
        """Send ``messages`` from the next frame on (same arbitration id), keeping the pace."""
        messages = self._check_and_convert_messages(messages)
        self._check_modified_messages(messages)
        self.messages = messages
        self._index = 0

    def _on_sync(self, n: int) -> None:
        k = n - self._started_at
        if self.end is not None and k >= self.end:
            self.stop()
            return
        if k % self.every == 0:
            self._send()

    def _send(self) -> None:
        if not self._running or not self.bus._open:
            return
        msg = self.messages[self._index]
        self._index = (self._index + 1) % len(self.messages)
        self.bus.send(msg)


class _Dispatch(can.Listener):
    """Frames of an inline :class:`SimBus` to the subscribers of a ``canopen.Network``: what
    canopen's ``MessageListener`` + ``Network.notify`` do (error and remote frames dropped,
    callbacks of the COB-ID in subscription order, a failing callback logged), without the
    network's node scanner, which the drives' side never uses."""

    def __init__(self, network: canopen.Network) -> None:
        self.subscribers = network.subscribers

    def on_message_received(self, msg: can.Message) -> None:
        if msg.is_error_frame or msg.is_remote_frame:
            return
        subs = self.subscribers.get(msg.arbitration_id)
        if subs:
            cid, data, ts = msg.arbitration_id, msg.data, msg.timestamp
            for callback in tuple(subs):  # a callback may (un)subscribe
                try:
                    callback(cid, data, ts)
                except Exception:
                    logger.exception("SimBus: callback for 0x%03X failed", cid)


class SimNetwork:
    """The simulated drives of one channel: one :class:`SimBus`, one ``canopen.Network``.

    Parameters
    ----------
    channel : str
        Virtual channel shared with the master.
    dispatch : {"inline", "thread"}
        :class:`SimBus` delivery: ``"inline"`` for the lockstep clock, ``"thread"`` (one
        notifier thread for all the drives) for the paced clock.
    sync_cycle_s : float or None
        ``"inline"`` only: the channel's simulated time per SYNC [s] (module docstring,
        "Simulated time"); give it with drives built with ``clock="sync"``.

    Attributes
    ----------
    bus : SimBus
    network : canopen.Network
        Give it to each ``SimulatedDrive(network, ...)``, then :meth:`add` the drive.
    drives : list
        Started drives, in the order added.
    """

    def __init__(self, channel: str, *, dispatch: str = "inline",
                 sync_cycle_s: float | None = None) -> None:
        self.bus = SimBus(channel, dispatch=dispatch, sync_cycle_s=sync_cycle_s)
        self.network = canopen.Network(self.bus)
        self.network.NOTIFIER_CYCLE = 0.05  # notifier poll period [s]: quick close()
        if dispatch == "inline":
            self.bus.add_listener(_Dispatch(self.network))
        else:
            self.network.connect()  # one notifier thread for every drive of the channel
        self.drives: list[Any] = []
        self._closed = False

    @property
    def channel(self) -> str:
        return self.bus.channel_id

    def add(self, drive: Any) -> Any:
        """Start ``drive`` (built on :attr:`network`) and keep it for :meth:`close`."""
        if drive.network is not self.network:
            raise SimError(f"SimNetwork {self.channel}: node {drive.node_id} was built on "
                           f"another network")
        drive.start()
        self.drives.append(drive)
        return drive

    def close(self) -> None:
        """Stop every drive (heartbeat, watchdog, subscriptions), then the notifier, then
        shut the bus. Idempotent."""
        if self._closed:
            return
        self._closed = True
        for d in self.drives:
            with contextlib.suppress(Exception):
                d.stop()
        net = self.network
        if net.notifier is not None:
            with contextlib.suppress(Exception):
                net.notifier.stop(1.0)
            net.notifier = None
        self.bus.shutdown()

    def __enter__(self) -> SimNetwork:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
