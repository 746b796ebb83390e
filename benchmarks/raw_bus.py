"""The reference of the lockstep benchmarks: a raw python-can virtual-bus round trip.

Two ``can.Bus(interface="virtual")`` objects on one channel; a responder thread receives a
frame and answers with one frame; the main thread sends, then waits for the answer
(``bus.recv``). No canopen, no drive, no plant: the floor of any request/answer exchange
between two threads on python-can's virtual bus (one deep copy per frame, one thread
hand-off each way). Pinned to one CPU like ``daq.runner`` pins itself (``daq.cpu`` = -1:
the last allowed CPU), or not.

Usage (also imported by ``bench_daq.py``)::

    python benchmarks/raw_bus.py [--frames 20000]
"""

from __future__ import annotations

import argparse
import contextlib
import itertools
import os
import threading
import time

import can

_chan = itertools.count()


@contextlib.contextmanager
def pinned(pin: bool):
    """Pin the process to its last allowed CPU for the block (as ``daq.runner`` does)."""
    old = os.sched_getaffinity(0) if pin and hasattr(os, "sched_setaffinity") else None
    if old is not None:
        os.sched_setaffinity(0, {max(old)})
    try:
        yield
    finally:
        if old is not None:
            os.sched_setaffinity(0, old)


def round_trip_us(frames: int = 20000, *, pin: bool = True) -> float:
    """Median over 5 blocks of the wall time of one round trip [µs]: 8-byte frame out,
    8-byte frame back, answered by another thread on its own virtual bus object."""
    with pinned(pin):
        channel = f"raw_rtt_{os.getpid()}_{next(_chan)}"
        master = can.Bus(interface="virtual", channel=channel)
        peer = can.Bus(interface="virtual", channel=channel)
        running = True

        def responder() -> None:
            answer = can.Message(arbitration_id=0x181, data=bytes(8), is_extended_id=False)
            while running:
                msg = peer.recv(0.05)
                if msg is not None and msg.arbitration_id == 0x201:
                    peer.send(answer)

        th = threading.Thread(target=responder, daemon=True, name="raw-rtt-responder")
        th.start()
        ask = can.Message(arbitration_id=0x201, data=bytes(8), is_extended_id=False)
        blocks = []
        try:
            per_block = max(1, frames // 5)
            for _ in range(5):
                t0 = time.perf_counter()
                for _ in range(per_block):
                    master.send(ask)
                    if master.recv(2.0) is None:
                        raise TimeoutError("raw round trip: no answer within 2 s")
                blocks.append((time.perf_counter() - t0) / per_block * 1e6)
        finally:
            running = False
            th.join(1.0)
            master.shutdown()
            peer.shutdown()
    blocks.sort()
    return blocks[len(blocks) // 2]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=20000)
    args = ap.parse_args()
    for pin in (True, False):
        us = round_trip_us(args.frames, pin=pin)
        print(f"raw python-can virtual round trip, {'pinned  ' if pin else 'unpinned'}: "
              f"{us:6.1f} us ({1e6 / us:,.0f} round trips/s)")


if __name__ == "__main__":
    main()
