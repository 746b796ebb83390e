"""Drives spread over several CAN buses, seen by the master as one python-can bus.

A 6-axis arm at 1 kHz does not fit on one 1 Mbit/s bus (``daq.runtime.busload``): the drives are
spread over several buses (``[[daq.drives]] channel``), each with its own SYNC. The master
code (SDO/NMT start-up, the cyclic engine, the heartbeat) stays the one it is for a single
bus: :class:`MultiBus` is a :class:`can.BusABC` over the member buses that

- routes each frame it sends by the node id of its COB-ID (the CANopen predefined
  connection set: SDO 0x600+id, RPDOs 0x200/0x300/0x400/0x500+id, ...) to the bus of that
  node; an NMT command (0x000) to the bus of the node it addresses (all buses for node 0);
  SYNC (0x080), TIME (0x100), the master's own heartbeat and any COB-ID of a node on no bus
  to every bus;
- receives from all member buses: a frame already waiting on any member first (members
  taken in turn, so that none starves), else it waits on all of them -- ``select`` on their
  file descriptors when every member has one (socketcan), else by polling every
  ``poll_s``;
- forwards periodic sends to the member buses' own ``send_periodic`` (the kernel's
  broadcast manager on socketcan), one per destination bus.

Node ids are unique over all buses (``daq.runtime.config`` refuses a repeated one), so a
COB-ID names one bus. Pure bus code: no CANopen state, no threads of its own.

:func:`open_buses` opens the master's bus(es) of a ``[daq]`` configuration: one python-can
bus per channel (``interface``, ``bitrate``), or with ``--simulate`` or python-can's
``virtual`` interface the master's end of the virtual channel (:class:`sim_drivers.simbus.SimBus`,
queued: the master code reads it like any python-can bus); a :class:`MultiBus` over them when
there are several. On a channel clocked by simulated drives in lockstep (``SimNetwork`` with
``sync_cycle_s``) the master's periodic sends (its heartbeat) then follow the SYNCs like the
drives' (:func:`sync_clocked`).
"""

from __future__ import annotations

import contextlib
import select
import time
from collections.abc import Mapping, Sequence
from typing import Any

import can
from can.broadcastmanager import CyclicTask

from daq import ConfigError
from sim_drivers.simbus import SimBus

BROADCAST_COB_IDS = (0x000, 0x080, 0x100)  # NMT (node 0), SYNC, TIME


class _Tasks(CyclicTask):
    """Periodic sends on several member buses, stopped together."""

    def __init__(self, tasks: Sequence[CyclicTask]) -> None:
        self.tasks = list(tasks)

    def stop(self) -> None:
        for t in self.tasks:
            t.stop()


class MultiBus(can.BusABC):
    """Several buses as one (module docstring).

    Parameters
    ----------
    buses : mapping of str to can.BusABC
        Channel name -> open bus. Shut down with this one.
    node_bus : mapping of int to str
        Node id -> channel of its bus.
    poll_s : float
        Polling period while waiting on members without a file descriptor [s].
    """

    def __init__(self, buses: Mapping[str, can.BusABC], node_bus: Mapping[int, str],
                 *, poll_s: float = 0.0001) -> None:
        if not buses:
            raise ValueError("MultiBus: no bus")
        unknown = sorted(set(node_bus.values()) - set(buses))
        if unknown:
            raise ValueError(f"MultiBus: nodes on unknown buses {unknown}")
        super().__init__(channel=",".join(buses))
        self.buses = dict(buses)
        self.members = list(self.buses.values())
        self._by_node = {int(n): self.buses[ch] for n, ch in node_bus.items()}
        self.poll_s = float(poll_s)
        self.channel_info = " + ".join(f"{ch}: {b.channel_info}" for ch, b in self.buses.items())
        self._next = 0
        self._fds: list[int] | None = []
        for b in self.members:
            try:
                fd = b.fileno()
            except (NotImplementedError, AttributeError, OSError):
                fd = -1
            if fd < 0:
                self._fds = None
                break
            self._fds.append(fd)

    def route(self, msg: can.Message) -> list[can.BusABC]:
        """The member buses a frame goes to."""
        cid = msg.arbitration_id
        if msg.is_extended_id:
            return self.members
        if cid == 0x000:
            node = msg.data[1] if len(msg.data) >= 2 else 0
        elif cid in BROADCAST_COB_IDS:
            return self.members
        else:
            node = cid & 0x7F
        bus = self._by_node.get(node)
        return [bus] if bus is not None else self.members

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        for bus in self.route(msg):
            bus.send(msg, timeout)

    def _recv_any(self) -> can.Message | None:
        n = len(self.members)
        start = self._next
        for i in range(n):
            k = (start + i) % n
            msg = self.members[k].recv(0.0)
            if msg is not None:
                self._next = (k + 1) % n
                return msg
        return None

    def recv(self, timeout: float | None = None) -> can.Message | None:
        """:meth:`can.BusABC.recv`, first without its overhead when a member has a frame
        waiting and no filter is set."""
        if self._filters is None:
            msg = self._recv_any()
            if msg is not None or timeout == 0:
                return msg
        return super().recv(timeout)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        msg = self._recv_any()
        if msg is not None or timeout == 0:
            return msg, False
        end = None if timeout is None else time.perf_counter() + timeout
        while True:
            left = None if end is None else end - time.perf_counter()
            if left is not None and left <= 0:
                return None, False
            if self._fds is not None:
                select.select(self._fds, [], [], left)
            else:
                time.sleep(self.poll_s if left is None else min(self.poll_s, left))
            msg = self._recv_any()
            if msg is not None:
                return msg, False

    def _send_periodic_internal(self, msgs, period, duration=None, autostart=True,
                                modifier_callback=None):  # noqa: ANN001 - python-can's API
        msgs = [msgs] if isinstance(msgs, can.Message) else list(msgs)
        per_bus: dict[int, tuple[can.BusABC, list[can.Message]]] = {}
        for m in msgs:
            for b in self.route(m):
                per_bus.setdefault(id(b), (b, []))[1].append(m)
        tasks = [b.send_periodic(ms, period, duration, autostart=autostart,
                                 modifier_callback=modifier_callback)
                 for b, ms in per_bus.values()]
        return tasks[0] if len(tasks) == 1 else _Tasks(tasks)

    def flush_tx_buffer(self) -> None:
        for b in self.members:
            b.flush_tx_buffer()

    def shutdown(self) -> None:
        super().shutdown()
        for b in self.members:
            b.shutdown()


def open_buses(cfg: Any, *, simulated: bool = False) -> can.BusABC:
    """The master's bus for a ``[daq]`` configuration (:class:`daq.runtime.config.DaqConfig`).

    One bus per channel of ``cfg.channels``: ``can.Bus(interface, channel, bitrate)``
    (``interface = "config"``: python-can's own configuration, one bus), or with
    ``simulated`` or ``interface = "virtual"`` a queued :class:`~sim_drivers.simbus.SimBus`
    on the virtual channel (the same frames as python-can's ``VirtualBus``, without its deep
    copies). Several channels: a :class:`MultiBus` routing by node id.

    Raises
    ------
    daq.ConfigError
        A bus cannot be opened (one line naming the interface and channel).
    """
    opened: dict[str, can.BusABC] = {}
    try:
        for ch in cfg.channels:
            if simulated or cfg.interface == "virtual":
                opened[ch] = SimBus(ch, dispatch="thread")
                continue
            kwargs: dict[str, Any] = {"interface": cfg.interface, "channel": ch}
            if cfg.interface == "config":  # python-can's own configuration decides everything
                kwargs = {}
            elif cfg.interface != "virtual":
                kwargs["bitrate"] = cfg.bitrate
            try:
                opened[ch] = can.Bus(**kwargs)
            except (can.CanError, OSError, ValueError, ImportError) as exc:
                raise ConfigError(f"{cfg.source}: daq.interface: cannot open "
                                  f"{cfg.interface} {ch}: {exc}") from None
    except BaseException:
        for b in opened.values():
            with contextlib.suppress(Exception):
                b.shutdown()
        raise
    if len(opened) == 1:
        return next(iter(opened.values()))
    return MultiBus(opened, {d.node_id: d.channel or cfg.channel for d in cfg.drives})


def sync_clocked(bus: can.BusABC) -> bool:
    """True when every channel of the master's ``bus`` is clocked by its SYNCs (simulated
    drives in lockstep, :mod:`sim_drivers.simbus` "Simulated time"): the drives' heartbeats
    are then paced by SYNC and the master judges them on its SYNC count."""
    members = bus.members if isinstance(bus, MultiBus) else [bus]
    return all(isinstance(b, SimBus) and b.channel_clock() is not None for b in members)
