"""Simulated drives in another process, reachable over a loopback python-can-remote bridge.

:class:`ServeProcess` starts ``python -m sim_drivers.serve --interface virtual --bridge-port 0``
(drives on a virtual bus inside that process, the bridge on
``ws://127.0.0.1:<port>/<token>``), waits (bounded) for the bridge line, keeps the process's
output (stdout and stderr: the drives' warnings, e.g. "heartbeat of node 127 lost") and stops
it on :meth:`close`. Used by the
cross-process tests and ``benchmarks/bench_daq.py``; a master in the calling process (or in a
third one) opens ``can.Bus(interface="remote", channel=serve.url)``.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Sequence

from sim_drivers import SimError

__all__ = ["ServeProcess"]

_BRIDGE_LINE = re.compile(r"bridge (ws://127\.0\.0\.1:\d+/[A-Za-z0-9_-]+)")
_SERVING_LINE = re.compile(r"serving node\(s\) .* on \w+:(\S+);")


class ServeProcess:
    """``python -m sim_drivers.serve`` in a subprocess with a loopback bridge.

    Parameters
    ----------
    node_ids : sequence of int
        Drives to serve (empty: only the bridge).
    channel : str
        Virtual-bus channel inside the serve process.
    interface : str
        The serve process's interface: ``"virtual"`` (drives and bridge on a bus inside
        it) or ``"remote"`` with ``channel`` the URL of another bridge (the drives in this
        process reach the bus through it; ``bridge=False`` then).
    bridge : bool
        Serve a bridge (``--bridge-port 0``) and wait for its line; else wait for the
        "serving" line.
    args : sequence of str
        More ``sim_drivers.serve`` arguments (``--cycle``, ``--q0``, ``--eds``...).
    start_timeout_s : float
        Wall time allowed for the process to print its bridge line [s].
    realtime_priority : int
        SCHED_FIFO priority of the serve process (0: the default policy; needs
        CAP_SYS_NICE), for benchmarks that run the master under SCHED_FIFO too.

    Attributes
    ----------
    url : str
        ``ws://127.0.0.1:<port>/<token>`` once started (its bridge, token included; without a
        bridge: the channel it serves on).
    proc : subprocess.Popen
    """

    def __init__(self, node_ids: Sequence[int] = (1,), *, channel: str = "jointid",
                 interface: str = "virtual", bridge: bool = True, args: Sequence[str] = (),
                 start_timeout_s: float = 30.0, realtime_priority: int = 0) -> None:
        env = dict(os.environ, PYTHONUNBUFFERED="1", OPENBLAS_NUM_THREADS="1")
        cmd = [sys.executable, "-m", "sim_drivers.serve", "--interface", interface,
               "--channel", channel, "--node-id", *map(str, node_ids),
               *(("--bridge-port", "0") if bridge else ()), *args]
        self._want = _BRIDGE_LINE if bridge else _SERVING_LINE
        self._lines: list[tuple[float, str]] = []
        self._lock = threading.Lock()
        self._ready = threading.Event()
        self.url = ""
        def fifo() -> None:
            if realtime_priority:
                os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(realtime_priority))

        self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                     stdin=subprocess.DEVNULL, text=True, bufsize=1, env=env,
                                     preexec_fn=fifo if realtime_priority else None)
        self._reader = threading.Thread(target=self._read, name="serve-output", daemon=True)
        self._reader.start()
        if not self._ready.wait(start_timeout_s) or not self.url:
            out = self.output
            self.close()
            raise SimError(f"sim_drivers.serve did not start within "
                           f"{start_timeout_s:g} s; output: {out.strip()[-500:]!r}")

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            with self._lock:
                self._lines.append((time.monotonic(), line.rstrip("\n")))
            m = self._want.search(line)
            if m and not self.url:
                self.url = m.group(1)
                self._ready.set()
        self._ready.set()  # the process ended: stop waiting

    @property
    def output(self) -> str:
        """Everything the process printed so far (stdout and stderr)."""
        with self._lock:
            return "\n".join(line for _, line in self._lines)

    def lines_since(self, t_monotonic: float) -> list[tuple[float, str]]:
        """Output lines read at or after ``t_monotonic`` (the reader's receive time)."""
        with self._lock:
            return [(t, s) for t, s in self._lines if t >= t_monotonic]

    def wait_for(self, pattern: str, timeout_s: float, since: float = 0.0) -> float | None:
        """``time.monotonic()`` when a line matching ``pattern`` (regex) was read, waiting
        up to ``timeout_s`` [s]; None on timeout."""
        rx = re.compile(pattern)
        end = time.monotonic() + timeout_s
        while True:
            for t, s in self.lines_since(since):
                if rx.search(s):
                    return t
            if time.monotonic() >= end or self.proc.poll() is not None:
                return None
            time.sleep(0.01)

    def kill(self, sig: int = signal.SIGKILL) -> None:
        """Send ``sig`` to the serve process."""
        if self.proc.poll() is None:
            self.proc.send_signal(sig)

    def close(self, timeout_s: float = 10.0) -> int | None:
        """SIGTERM (clean stop), then SIGKILL after ``timeout_s``; returns the exit code."""
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout_s)
        self._reader.join(timeout_s)
        if self.proc.stdout is not None:
            self.proc.stdout.close()
        return self.proc.returncode

    def __enter__(self) -> ServeProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
