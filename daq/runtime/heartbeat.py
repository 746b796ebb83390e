"""The master's own heartbeat producer (CiA 301), which the drives' consumers watch: a dead
master stops the drives (:mod:`daq.runtime.master`)."""

from __future__ import annotations

import time

import can


class MasterHeartbeat:
    """The master's own heartbeat producer (CiA 301): ``0x700 + node_id``, one data byte
    0x05 (OPERATIONAL), every ``period_ms`` [ms], sent by python-can's ``send_periodic``.

    Parameters
    ----------
    bus : can.BusABC
        The master's bus.
    node_id : int
        The master's node id 1..127.
    period_ms : int
        Producer period [ms] (> 0).
    """

    def __init__(self, bus: can.BusABC, node_id: int, period_ms: int) -> None:
        self.bus = bus
        self.node_id = node_id
        self.period_ms = period_ms
        self.msg = can.Message(arbitration_id=0x700 + node_id, data=b"\x05",
                               is_extended_id=False)
        self._task: can.broadcastmanager.CyclicSendTaskABC | None = None
        self.started_at = 0.0

    def start(self) -> None:
        """Send one heartbeat now and then every period (idempotent)."""
        if self._task is not None:
            return
        self.bus.send(self.msg)
        self.started_at = time.monotonic()
        self._task = self.bus.send_periodic(self.msg, self.period_ms / 1000.0)

    def beat(self) -> None:
        """Send one heartbeat now, outside the period: after 0x1016 was written, so that the
        drives start monitoring (CiA 301: at the first heartbeat received) before they are
        started rather than up to one period later."""
        if self._task is not None:
            self.bus.send(self.msg)

    def stop(self) -> None:
        """Stop sending (the drives' consumers time out after their consumer time)."""
        task, self._task = self._task, None
        if task is not None:
            task.stop()

    @property
    def running(self) -> bool:
        return self._task is not None
