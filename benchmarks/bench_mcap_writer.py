"""MCAP writers on the same messages: ours (``FastWriter``) vs the ``mcap`` library's ``Writer``.

Usage::

    python benchmarks/bench_mcap_writer.py [--cycles 20000] [--axes 1] [--repeat 5]

Both writers get the same pre-built messages (the runner's per-cycle mix: one
``/joint/<axis>/state`` per axis, one ``/setpoint``, one ``/can/raw`` batch of 4 frames, all
packed with the ``daq.protocol.logformat`` structs), the same zstd level (3), the same chunk
size (:func:`daq.runtime.mcaplog.chunk_size_for`, ``--chunk-seconds`` of data at 1 kHz) and
write to a file in a temporary directory; both files carry message indexes and a summary.
The time of one run is from ``start`` to ``finish`` (the whole file); the two writers
alternate within each repeat, so both see the same host load; the table prints the median
messages/s of each and the ratio ours / library. Each file is then read back by the
``mcap`` library's indexed reader, which must return every message (checked, not timed).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from daq.protocol.logformat import (
    CAN_HEAD_STRUCT,
    CAN_SCHEMA,
    CAN_SCHEMA_NAME,
    CDR_HEADER,
    FRAME,
    SETPOINT_SCHEMA,
    SETPOINT_SCHEMA_NAME,
    SETPOINT_STRUCT,
    STATE_SCHEMA,
    STATE_SCHEMA_NAME,
    STATE_STRUCT,
)
from daq.runtime.mcaplog import FastWriter, chunk_size_for

Message = tuple[int, int, bytes, int, int]  # channel, log time [ns], data, publish [ns], seq


def channels(n_axes: int) -> list[tuple[str, str, str]]:
    """(topic, schema name, schema text) in channel-id order."""
    out = [(f"/joint/{k}/state", STATE_SCHEMA_NAME, STATE_SCHEMA) for k in range(n_axes)]
    out.append(("/setpoint", SETPOINT_SCHEMA_NAME, SETPOINT_SCHEMA))
    out.append(("/can/raw", CAN_SCHEMA_NAME, CAN_SCHEMA))
    return out


def messages(n_cycles: int, n_axes: int, cycle_ns: int = 1_000_000) -> list[Message]:
    """The runner's per-cycle mix, packed once (channel ids as :func:`channels`)."""
    t0 = time.time_ns()
    frames = b"".join(FRAME.pack(1.0 + k * 1e-4, 0x181 + k, 8, bytes(range(8)))
                      for k in range(4))
    out: list[Message] = []
    for c in range(n_cycles):
        lt = t0 + c * cycle_ns
        t = c * cycle_ns * 1e-9
        for ax in range(n_axes):
            out.append((ax, lt, STATE_STRUCT.pack(
                CDR_HEADER, t, c, 0.1 * t, 0.2, 1.5, 1.4, c * 3, 40, 120, 118, 0x1237, 0, 0),
                lt + 1000, c))
        out.append((n_axes, lt, SETPOINT_STRUCT.pack(CDR_HEADER, t, c, 0.1 * t, 0.1, 0.0, 2, 0),
                    lt + 2000, c))
        out.append((n_axes + 1, lt, CAN_HEAD_STRUCT.pack(CDR_HEADER, c, 4) + frames, lt + 3000,
                    c))
    return out


def write_ours(path: Path, msgs: list[Message], n_axes: int, chunk_size: int) -> float:
    with open(path, "wb") as f:
        t0 = time.perf_counter()
        w = FastWriter(f, chunk_size)
        w.start(library="bench")
        ids: dict[str, int] = {}
        for topic, name, text in channels(n_axes):
            sid = ids.get(name) or w.register_schema(name, "ros2msg", text.encode())
            ids[name] = sid
            w.register_channel(topic, "cdr", sid)
        add = w.add_message
        for ch, lt, data, pt, seq in msgs:
            add(ch, lt, data, pt, seq)
        w.finish()
        return time.perf_counter() - t0


def write_library(path: Path, msgs: list[Message], n_axes: int, chunk_size: int) -> float:
    with open(path, "wb") as f:
        t0 = time.perf_counter()
        w = Writer(f, chunk_size=chunk_size, compression=CompressionType.ZSTD)
        w.start(profile="", library="bench")
        ids: dict[str, int] = {}
        cids: list[int] = []
        for topic, name, text in channels(n_axes):
            sid = ids.get(name) or w.register_schema(name, "ros2msg", text.encode())
            ids[name] = sid
            cids.append(w.register_channel(topic, "cdr", sid))
        add = w.add_message
        for ch, lt, data, pt, seq in msgs:
            add(cids[ch], lt, data, pt, seq)
        w.finish()
        return time.perf_counter() - t0


def count_indexed(path: Path) -> tuple[int, int]:
    """(messages read by the mcap indexed reader, chunks carrying message indexes)."""
    with open(path, "rb") as f:
        r = make_reader(f, validate_crcs=True)
        summary = r.get_summary()
        indexed = sum(1 for ci in summary.chunk_indexes if ci.message_index_offsets)
        return sum(1 for _ in r.iter_messages()), indexed


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cycles", type=int, default=20000)
    ap.add_argument("--axes", type=int, default=1)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--chunk-seconds", type=float, default=0.1)
    args = ap.parse_args(argv)
    msgs = messages(args.cycles, args.axes)
    chunk = chunk_size_for(args.axes, 4, 1e-3, args.chunk_seconds)
    rates: dict[str, list[float]] = {"ours (FastWriter)": [], "mcap library Writer": []}
    writers = {"ours (FastWriter)": write_ours, "mcap library Writer": write_library}
    with tempfile.TemporaryDirectory() as tmp:
        paths = {k: Path(tmp) / f"{i}.mcap" for i, k in enumerate(writers)}
        for rep in range(args.repeat):
            order = list(writers) if rep % 2 == 0 else list(writers)[::-1]
            for name in order:
                dt = writers[name](paths[name], msgs, args.axes, chunk)
                rates[name].append(len(msgs) / dt)
        print(f"{len(msgs)} messages ({args.cycles} cycles, {args.axes} axis/axes + setpoint + "
              f"CAN), chunk {chunk} B, zstd 3, median of {args.repeat}")
        print(f"{'writer':<22} {'msg/s':>10} {'us/msg':>8} {'file [kB]':>10} {'read back':>10}")
        for name in writers:
            med = statistics.median(rates[name])
            n_read, n_indexed = count_indexed(paths[name])
            size = paths[name].stat().st_size / 1e3
            print(f"{name:<22} {med:>10.0f} {1e6 / med:>8.2f} {size:>10.1f} {n_read:>10d}")
            if n_read != len(msgs) or n_indexed == 0:
                print(f"error: {name}: read {n_read} of {len(msgs)} messages, "
                      f"{n_indexed} indexed chunks", file=sys.stderr)
                return 1
        ours, lib = (statistics.median(rates[k]) for k in writers)
        print(f"ratio ours / library: {ours / lib:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
