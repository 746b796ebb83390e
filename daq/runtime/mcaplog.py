"""MCAP run log: one file per payload run, written as data arrives.

Channels (see ``docs/log-format.md`` for the full description):

``/joint/<axis>/state``
    One message per cycle and drive, ``ros2msg`` schema ``jointid_msgs/msg/JointState``,
    ``cdr`` encoding (little endian). The record has a fixed size (68 bytes) so that the
    reader decodes whole chunks with one numpy structured dtype, and Foxglove plots every
    field without a custom decoder.
``/setpoint``
    One message per cycle: the planned reference (``jointid_msgs/msg/Setpoint``, cdr).
``/joint/<axis>/setpoint``
    Instead of ``/setpoint`` in a robot campaign's log (``axis_setpoints=True``): each drive's
    own joint reference, one message per cycle and drive (same schema).
``/can/raw``
    One message per cycle with every CAN frame sent or received during the cycle
    (``jointid_msgs/msg/CanFrames``, cdr; a sequence of fixed 24-byte frame records).
``/events``
    State changes, EMCY, faults, operator actions: JSON described by a JSON Schema.

Metadata records ``campaign``, ``drive<k>``, ``plant``, ``payload``, ``software`` and, on
close, ``result``; attachments: the campaign file, every EDS, the plant file.

Log times are integer nanoseconds: ``start_ns + cycle * cycle_ns`` (the nominal sample time
of the cycle, ``start_ns`` the wall-clock start of the run); publish times are the wall
clock when the record was written. The writer's chunk size is chosen so that a chunk holds
about ``chunk_seconds`` of data: a killed process loses at most that much (with chunks written
in the background, :meth:`RunLog.background_chunks`, also the chunks still queued: the paced
clock's engine uses it, so that compressing a chunk -- 0.3-1.5 ms -- is no part of a cycle).
"""

from __future__ import annotations

import json
import os
import queue
import struct
import threading
import time
import zlib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import zstandard
from mcap.data_stream import RecordBuilder
from mcap.records import (
    Attachment,
    AttachmentIndex,
    Channel,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    Metadata,
    MetadataIndex,
    Opcode,
    Schema,
    Statistics,
    SummaryOffset,
)

from daq import DaqError, __version__
from daq.protocol.logformat import (
    CAN_HEAD_STRUCT,
    CAN_SCHEMA,
    CAN_SCHEMA_NAME,
    CDR_HEADER,
    EVENT_SCHEMA,
    FRAME,
    SETPOINT_SCHEMA,
    SETPOINT_SCHEMA_NAME,
    SETPOINT_STRUCT,
    STATE_SCHEMA,
    STATE_SCHEMA_NAME,
    STATE_SIZE,
    STATE_STRUCT,
)
from daq.protocol.reader import MAGIC

_HEAD = struct.Struct("<BQ")  # record header: opcode, length
_MSG = struct.Struct("<BQHIQQ")  # message record header: opcode, length, channel, seq, times
_CHUNK_HEAD = struct.Struct("<BQQQQI")  # opcode, length, start, end, uncompressed size, crc
_MSG_INDEX_HEAD = struct.Struct("<BQHI")  # opcode, length, channel id, records length
_INDEX_ENTRY = np.dtype([("log_time", "<u8"), ("offset", "<u8")])
_ID_TO_LOG_TIME = np.arange(9, 23)  # a message record's channel id .. log time, from its start


def message_offsets(raw: bytes) -> np.ndarray:
    """Offsets of the message records in the uncompressed records of a chunk, shape (n,).

    Walks the record headers (opcode, length); other records (schemas, channels written
    inside chunks by other writers) are skipped.

    Raises
    ------
    ValueError
        If a record runs past the end of ``raw``.
    """
    out: list[int] = []
    n = len(raw)
    pos = 0
    unpack = _HEAD.unpack_from
    while pos < n:
        if pos + 9 > n:
            raise ValueError(f"record header at {pos} runs past the chunk end ({n})")
        opcode, length = unpack(raw, pos)
        if opcode == Opcode.MESSAGE:
            out.append(pos)
        pos += 9 + length
    if pos != n:
        raise ValueError(f"last record runs past the chunk end ({pos} > {n})")
    return np.asarray(out, np.int64)


class FastWriter:
    """A minimal MCAP writer with a fast path for messages.

    The mcap library's ``Writer.add_message`` builds a record object, updates its statistics
    and message index per message (``benchmarks/bench_mcap_writer.py`` measures both
    writers on the same messages); here a message is one ``struct.pack`` appended to the
    chunk buffer plus the append of its offset to a list. When a chunk is full, the channel
    ids and log times of its messages are gathered from the buffer with numpy at those
    offsets: the chunk's time range, the per-channel counts and one MessageIndex record per
    channel (entries sorted by log time) are computed there, once per chunk.

    Layout written (standard MCAP, read by the ``mcap`` library and ``@mcap/core``): magic,
    header; schema and channel records in the data section as soon as they are registered;
    each chunk followed at once by its MessageIndex records; metadata and attachments
    between chunks; on :meth:`finish`, data end, the summary (schemas, channels,
    statistics, chunk indexes pointing to the message indexes, attachment and metadata
    indexes, summary offsets), footer and closing magic. Each finished chunk is written and
    flushed to the OS at once, so a killed process loses only the chunk being filled.
    """

    def __init__(self, stream: Any, chunk_size: int, level: int = 3) -> None:
        self._f = stream
        self.chunk_size = chunk_size
        self._z = zstandard.ZstdCompressor(level=level)
        self._buf = bytearray()
        self._offs: list[int] = []
        self._schemas: list[Schema] = []
        self._channels: list[Channel] = []
        self._counts: dict[int, int] = {}
        self._chunk_indexes: list[ChunkIndex] = []
        self._meta_indexes: list[MetadataIndex] = []
        self._att_indexes: list[AttachmentIndex] = []
        self._msg_start = -1
        self._msg_end = 0
        self._queue: queue.Queue[tuple[bytes, list[int]] | None] | None = None
        self._worker: threading.Thread | None = None
        self._error: BaseException | None = None

    # -- background chunks ------------------------------------------------------------------
    def start_background(self) -> None:
        """From now on a full chunk is handed to a worker thread, which compresses and writes
        the chunks in order (zstd releases the GIL while it compresses); the thread adding
        messages only copies the buffer. A write error of the worker is raised by the next
        :meth:`add_message` that fills a chunk, or by :meth:`drain`; no chunk is written after
        it. Under SCHED_FIFO/RR the worker runs one priority below the thread that started
        it (a cycle loop at that priority preempts it, other processes do not). Every other
        write (records, metadata, :meth:`finish`) first waits for the queue (:meth:`drain`).
        Idempotent."""
        if self._worker is not None:
            return
        policy, prio = _sched_of_thread()
        self._queue = queue.Queue()
        self._worker = threading.Thread(target=self._work, args=(policy, prio), daemon=True,
                                        name="mcap-chunk-writer")
        self._worker.start()

    def _work(self, policy: int, prio: int) -> None:
        if prio > 1:  # one below the cycle loop's real-time priority
            try:
                os.sched_setscheduler(0, policy, os.sched_param(prio - 1))
            except (AttributeError, OSError):  # pragma: no cover - kept at the loop's priority
                pass
        q = self._queue
        assert q is not None
        while True:
            item = q.get()
            try:
                if item is None:
                    return
                if self._error is None:  # after a failure nothing more is written
                    raw, offs = item
                    self.write_chunk(raw, np.asarray(offs, np.int64))
                    self._f.flush()
            except BaseException as exc:  # noqa: BLE001 - raised in the writing thread
                self._error = exc
            finally:
                q.task_done()

    def drain(self) -> None:
        """Wait until the worker wrote every queued chunk; raise its error if it had one."""
        if self._queue is not None:
            self._queue.join()
        if self._error is not None:
            raise self._error

    def stop_background(self) -> None:
        """Write the queued chunks, end the worker (idempotent); raise its error if any."""
        if self._worker is None:
            return
        try:
            self.drain()
        finally:
            assert self._queue is not None
            self._queue.put(None)
            self._worker.join()
            self._worker = None
            self._queue = None

    def _record(self, rec: Any) -> tuple[int, int]:
        self.drain()
        b = RecordBuilder()
        rec.write(b)
        data = b.end()
        offset = self._f.tell()
        self._f.write(data)
        return offset, len(data)

    def start(self, profile: str = "", library: str = "") -> None:
        self._f.write(MAGIC)
        self._record(Header(profile=profile, library=library))

    def register_schema(self, name: str, encoding: str, data: bytes, fixed_id: int = 0) -> int:
        """Write a schema record; ids count from 1 unless ``fixed_id`` is given. Returns the
        id."""
        sid = fixed_id or len(self._schemas) + 1
        sch = Schema(id=sid, name=name, encoding=encoding, data=data)
        self._schemas.append(sch)
        self._record(sch)
        return sid

    def register_channel(self, topic: str, message_encoding: str, schema_id: int,
                         fixed_id: int = -1, metadata: Mapping[str, str] | None = None) -> int:
        """Write a channel record; ids count from 0 unless ``fixed_id`` is given. Returns the
        id."""
        cid = fixed_id if fixed_id >= 0 else len(self._channels)
        ch = Channel(id=cid, topic=topic, message_encoding=message_encoding,
                     schema_id=schema_id, metadata=dict(metadata or {}))
        self._channels.append(ch)
        self._record(ch)
        return cid

    def add_message(self, channel_id: int, log_time: int, data: bytes, publish_time: int,
                    sequence: int = 0) -> None:
        buf = self._buf
        self._offs.append(len(buf))
        buf += _MSG.pack(5, 22 + len(data), channel_id, sequence, log_time, publish_time)
        buf += data
        if len(buf) > self.chunk_size:
            self.flush_chunk()

    def flush_chunk(self) -> None:
        """Compress and write the chunk being filled (if any), then flush the file; with
        :meth:`start_background`, hand it to the worker instead."""
        if self._error is not None:
            raise self._error
        if not self._buf:
            return
        raw = bytes(self._buf)
        offs = self._offs
        self._buf = bytearray()
        self._offs = []
        if self._queue is not None:
            self._queue.put((raw, offs))
            return
        self.write_chunk(raw, np.asarray(offs, np.int64))
        self._f.flush()

    def write_chunk(self, raw: bytes, offsets: np.ndarray) -> None:
        """Write one chunk of uncompressed records ``raw`` and its message indexes.

        ``offsets`` are the offsets of the message records in ``raw``
        (:func:`message_offsets`).
        """
        if not len(offsets):
            return
        b = np.frombuffer(raw, np.uint8)
        head_bytes = b[offsets[:, None] + _ID_TO_LOG_TIME]  # (n, 14): channel, seq, log time
        cid = np.ascontiguousarray(head_bytes[:, :2]).view("<u2").reshape(-1)
        lt = np.ascontiguousarray(head_bytes[:, 6:]).view("<u8").reshape(-1)
        start, end = int(lt.min()), int(lt.max())
        comp = self._z.compress(raw)
        head = (_CHUNK_HEAD.pack(Opcode.CHUNK, 8 + 8 + 8 + 4 + 4 + 4 + 8 + len(comp), start, end,
                                 len(raw), zlib.crc32(raw))
                + b"\x04\x00\x00\x00zstd" + struct.pack("<Q", len(comp)))
        offset = self._f.tell()
        chunk_length = len(head) + len(comp)
        # message indexes: one record per channel, entries by log time (stable: file order)
        order = np.lexsort((lt, cid))
        entries = np.empty(len(order), _INDEX_ENTRY)
        entries["log_time"] = lt[order]
        entries["offset"] = offsets[order]
        flat = entries.tobytes()
        cid_s = cid[order]
        bounds = [0, *(np.flatnonzero(cid_s[1:] != cid_s[:-1]) + 1).tolist(), len(order)]
        index_offsets: dict[int, int] = {}
        pos = offset + chunk_length
        parts = [head, comp]
        counts = self._counts
        for i0, i1 in zip(bounds[:-1], bounds[1:], strict=True):
            channel = int(cid_s[i0])
            nbytes = 16 * (i1 - i0)
            rec = _MSG_INDEX_HEAD.pack(Opcode.MESSAGE_INDEX, 6 + nbytes, channel, nbytes)
            parts.append(rec)
            parts.append(flat[16 * i0 : 16 * i1])
            index_offsets[channel] = pos
            pos += len(rec) + nbytes
            counts[channel] = counts.get(channel, 0) + (i1 - i0)
        self._f.write(b"".join(parts))
        index_length = pos - offset - chunk_length
        self._chunk_indexes.append(ChunkIndex(
            message_start_time=start, message_end_time=end,
            chunk_start_offset=offset, chunk_length=chunk_length,
            message_index_offsets=index_offsets, message_index_length=index_length,
            compression="zstd", compressed_size=len(comp), uncompressed_size=len(raw)))
        if self._msg_start < 0 or start < self._msg_start:
            self._msg_start = start
        self._msg_end = max(self._msg_end, end)

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        self.flush_chunk()
        offset, length = self._record(Metadata(name=name, metadata=data))
        self._meta_indexes.append(MetadataIndex(offset=offset, length=length, name=name))

    def add_attachment(self, create_time: int, log_time: int, name: str, media_type: str,
                       data: bytes) -> None:
        self.flush_chunk()
        offset, length = self._record(Attachment(create_time=create_time, log_time=log_time,
                                                 name=name, media_type=media_type, data=data))
        self._att_indexes.append(AttachmentIndex(
            offset=offset, length=length, create_time=create_time, log_time=log_time,
            data_size=len(data), name=name, media_type=media_type))

    def finish(self) -> None:
        """Last chunk, data end, summary (with offsets), footer, closing magic."""
        self.flush_chunk()
        self.stop_background()
        self._record(DataEnd(data_section_crc=0))
        summary_start = self._f.tell()
        b = RecordBuilder()
        offsets: list[SummaryOffset] = []

        def group(opcode: int, records: list[Any]) -> None:
            start = b.count
            for r in records:
                r.write(b)
            if records:
                offsets.append(SummaryOffset(group_opcode=opcode,
                                             group_start=summary_start + start,
                                             group_length=b.count - start))

        group(Opcode.SCHEMA, self._schemas)
        group(Opcode.CHANNEL, self._channels)
        stats = Statistics(
            message_count=sum(self._counts.values()), schema_count=len(self._schemas),
            channel_count=len(self._channels), attachment_count=len(self._att_indexes),
            metadata_count=len(self._meta_indexes), chunk_count=len(self._chunk_indexes),
            message_start_time=max(self._msg_start, 0), message_end_time=self._msg_end,
            channel_message_counts=dict(sorted(self._counts.items())))
        group(Opcode.STATISTICS, [stats])
        group(Opcode.CHUNK_INDEX, self._chunk_indexes)
        group(Opcode.ATTACHMENT_INDEX, self._att_indexes)
        group(Opcode.METADATA_INDEX, self._meta_indexes)
        offset_start = summary_start + b.count
        for o in offsets:
            o.write(b)
        self._f.write(b.end())
        self._record(Footer(summary_start=summary_start, summary_offset_start=offset_start,
                            summary_crc=0))
        self._f.write(MAGIC)


def _sched_of_thread() -> tuple[int, int]:
    """(scheduling policy, real-time priority) of the calling thread ((0, 0): not known)."""
    try:
        policy = os.sched_getscheduler(0)
        if policy in (os.SCHED_FIFO, os.SCHED_RR):
            return policy, os.sched_getparam(0).sched_priority
        return policy, 0
    except (AttributeError, OSError):  # pragma: no cover - not Linux
        return 0, 0


def chunk_size_for(n_axes: int, frames_per_cycle: int, cycle_s: float, seconds: float) -> int:
    """Chunk size [byte] holding about ``seconds`` of data at the given cycle."""
    per_cycle = (n_axes * (STATE_SIZE + 31) + (SETPOINT_STRUCT.size + 31) + 47
                 + frames_per_cycle * FRAME.size)
    return max(4096, int(per_cycle * seconds / cycle_s))


class RunLog:
    """Writer of one payload run's MCAP file.

    Parameters
    ----------
    path : path-like
        Output file (overwritten).
    n_axes : int
        Number of drives; channels ``/joint/0/state`` ... are created.
    cycle_s : float
        Cycle time [s]; sets the log times and the chunk size.
    metadata : mapping of str to mapping of str to str
        Metadata records written first (``campaign``, ``drive0``, ``payload``, ...).
    attachments : sequence of (name, media_type, bytes)
        Files attached to the log (campaign TOML, EDS, plant TOML).
    chunk_seconds : float
        Target amount of data per chunk [s of campaign time].
    frames_per_cycle : int
        Expected CAN frames per cycle (for the chunk size only).
    axis_setpoints : bool
        One setpoint channel per axis (``/joint/<axis>/setpoint``, :meth:`setpoint_axis`)
        instead of the one ``/setpoint`` (robot campaigns: every joint has its reference).

    Use as a context manager or call :meth:`close` on every exit path.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        n_axes: int,
        cycle_s: float,
        metadata: Mapping[str, Mapping[str, str]] = (),
        attachments: Sequence[tuple[str, str, bytes]] = (),
        chunk_seconds: float = 1.0,
        frames_per_cycle: int = 4,
        axis_setpoints: bool = False,
    ) -> None:
        self.path = Path(path)
        try:
            self._file = open(self.path, "wb")  # noqa: SIM115 - closed in close()
        except OSError as exc:
            raise DaqError(f"{self.path}: cannot create the run log: {exc.strerror}") from exc
        self.cycle_ns = int(round(cycle_s * 1e9))
        self.start_ns = time.time_ns()
        self.n_messages = 0
        self.closed = False
        w = FastWriter(
            self._file, chunk_size_for(n_axes, frames_per_cycle, cycle_s, chunk_seconds)
        )
        self._w = w
        w.start(profile="", library=f"jointid {__version__}")
        sid = w.register_schema(STATE_SCHEMA_NAME, "ros2msg", STATE_SCHEMA.encode())
        self._state_ch = [
            w.register_channel(f"/joint/{k}/state", "cdr", sid) for k in range(n_axes)
        ]
        sid = w.register_schema(SETPOINT_SCHEMA_NAME, "ros2msg", SETPOINT_SCHEMA.encode())
        if axis_setpoints:
            self._setpoint_ch = -1
            self._axis_sp_ch = [w.register_channel(f"/joint/{k}/setpoint", "cdr", sid)
                                for k in range(n_axes)]
        else:
            self._setpoint_ch = w.register_channel("/setpoint", "cdr", sid)
            self._axis_sp_ch = []
        sid = w.register_schema(CAN_SCHEMA_NAME, "ros2msg", CAN_SCHEMA.encode())
        self._can_ch = w.register_channel("/can/raw", "cdr", sid)
        sid = w.register_schema("jointid.Event", "jsonschema", EVENT_SCHEMA)
        self._event_ch = w.register_channel("/events", "json", sid)
        for name, record in dict(metadata).items():
            w.add_metadata(name, {str(k): str(v) for k, v in record.items()})
        for name, media, data in attachments:
            w.add_attachment(self.start_ns, self.start_ns, name, media, bytes(data))
        self._add = w.add_message

    # -- hot path -------------------------------------------------------------------------
    def state(
        self,
        axis: int,
        cycle: int,
        t: float,
        q: float,
        dq: float,
        tau_ref: float,
        tau_actual: float,
        counts: int,
        velocity_raw: int,
        tau_ref_raw: int,
        tau_actual_raw: int,
        statusword: int,
        flags: int = 0,
    ) -> None:
        """Log one drive's state for one cycle (units as in :data:`STATE_SCHEMA`)."""
        lt = self.start_ns + cycle * self.cycle_ns
        self._add(
            self._state_ch[axis],
            lt,
            STATE_STRUCT.pack(
                CDR_HEADER, t, cycle, q, dq, tau_ref, tau_actual, counts, velocity_raw,
                tau_ref_raw, tau_actual_raw, statusword, flags, 0,
            ),
            time.time_ns(),
            cycle,
        )
        self.n_messages += 1

    def setpoint(
        self,
        cycle: int,
        t: float,
        q_ref: float,
        dq_ref: float,
        ddq_ref: float,
        segment: int,
        target_raw: int = 0,
    ) -> None:
        """Log the planned reference of one cycle."""
        self._setpoint_on(self._setpoint_ch, cycle, t, q_ref, dq_ref, ddq_ref, segment,
                          target_raw)

    def setpoint_axis(
        self,
        axis: int,
        cycle: int,
        t: float,
        q_ref: float,
        dq_ref: float,
        ddq_ref: float,
        segment: int,
        target_raw: int = 0,
    ) -> None:
        """Log the planned reference of one axis for one cycle (``axis_setpoints`` logs)."""
        self._setpoint_on(self._axis_sp_ch[axis], cycle, t, q_ref, dq_ref, ddq_ref, segment,
                          target_raw)

    def _setpoint_on(self, channel: int, cycle: int, t: float, q_ref: float, dq_ref: float,
                     ddq_ref: float, segment: int, target_raw: int) -> None:
        self._add(
            channel,
            self.start_ns + cycle * self.cycle_ns,
            SETPOINT_STRUCT.pack(CDR_HEADER, t, cycle, q_ref, dq_ref, ddq_ref, segment, target_raw),
            time.time_ns(),
            cycle,
        )
        self.n_messages += 1

    def frames(self, cycle: int, packed: bytes | bytearray, n_frames: int) -> None:
        """Log the CAN frames of one cycle.

        ``packed`` is the concatenation of ``n_frames`` records packed with :data:`FRAME`.
        """
        self._add(
            self._can_ch,
            self.start_ns + cycle * self.cycle_ns,
            CAN_HEAD_STRUCT.pack(CDR_HEADER, cycle, n_frames) + packed,
            time.time_ns(),
            cycle,
        )
        self.n_messages += 1

    # -- low rate ---------------------------------------------------------------------------
    def event(self, cycle: int, t: float, kind: str, message: str, axis: int = -1) -> None:
        """Log an event (state change, EMCY, fault, operator action...)."""
        data = json.dumps(
            {"t": t, "cycle": cycle, "kind": kind, "axis": axis, "message": message}
        ).encode()
        self._add(
            self._event_ch, self.start_ns + max(cycle, 0) * self.cycle_ns, data, time.time_ns(), 0
        )
        self.n_messages += 1

    def background_chunks(self) -> None:
        """Compress and write full chunks in a worker thread from now on
        (:meth:`FastWriter.start_background`): the paced cycle loop then only copies a full
        chunk's buffer. A write error surfaces at the next full chunk or at :meth:`close`."""
        self._w.start_background()

    def close(self, result: Mapping[str, str] | None = None) -> None:
        """Write the ``result`` metadata record, the summary and close the file (idempotent)."""
        if self.closed:
            return
        self.closed = True
        try:
            if result is not None:
                self._w.add_metadata("result", {str(k): str(v) for k, v in result.items()})
            self._w.finish()
        finally:
            try:
                self._w.stop_background()  # (after a failure: the worker ends all the same)
            except Exception:  # noqa: BLE001, S110 - the error was raised above already
                pass
            self._file.close()

    def __enter__(self) -> RunLog:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

