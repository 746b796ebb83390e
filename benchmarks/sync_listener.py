"""A passive third process on the bus: record every SYNC (COB-ID 0x80) until SIGTERM.

Usage: ``python benchmarks/sync_listener.py ws://127.0.0.1:PORT/TOKEN OUT.npy`` (used by
``bench_daq.py --cross-process``). Connects to a python-can-remote bridge (loopback), prints
``listening`` once connected, and on SIGTERM/SIGINT writes an (n, 2) float64 array: column 0
the bus timestamp python-can gave the frame in the bridge process [s, epoch], column 1 this
process's ``time.time()`` when it received it [s, epoch].
"""

from __future__ import annotations

import signal
import sys
import time

import can
import numpy as np


def main(argv: list[str]) -> int:
    url, out = argv
    stop = False

    def on_signal(*_: object) -> None:
        nonlocal stop
        stop = True

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    bus = can.Bus(interface="remote", channel=url, can_filters=[
        {"can_id": 0x80, "can_mask": 0x7FF}])
    print("listening", flush=True)
    rows: list[tuple[float, float]] = []
    now = time.time
    try:
        while not stop:
            msg = bus.recv(0.1)
            if msg is not None and msg.arbitration_id == 0x80:
                rows.append((msg.timestamp, now()))
    finally:
        bus.shutdown()
        np.save(out, np.array(rows, dtype=np.float64).reshape(-1, 2))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
