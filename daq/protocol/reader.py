"""Read jointid MCAP run logs back into numpy arrays (for :mod:`ident`).

Chunk-wise: each compressed chunk is decompressed once and checked (sizes, CRC); the
offsets of the fixed-size state and setpoint records are collected by a walk over the
record headers and the records are decoded with one numpy structured dtype per chunk, so no
Python object is created per message beyond that walk. A closed file is read through its
chunk indexes: a damaged chunk is skipped with a warning naming the cycles lost, and the
chunks after it are read. A file truncated by a killed writer (no summary, a partial last
chunk) is read record by record up to its last complete chunk, with a warning. A file
without the MCAP magic is refused as "not an MCAP file".

(Past 600 lines: the indexed read of a closed file and the record-by-record read of a
truncated one share the chunk walk, its checks and the damage report; the decoding into
:class:`RunArrays` and the other readers (topics, frames, attachments) follow them.)
"""

from __future__ import annotations

import json
import os
import re
import struct
import warnings
import zlib
from collections.abc import Container, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from io import BytesIO
from pathlib import Path
from typing import Any

import numpy as np
import zstandard
from mcap.data_stream import ReadDataStream
from mcap.reader import make_reader
from mcap.records import Attachment, Channel, Metadata, Opcode, Schema
from mcap.summary import Summary

from daq import DaqError

from .logformat import (
    FRAME_DTYPE,
    SETPOINT_DTYPE,
    STATE_DTYPE,
    STATE_SCHEMA_NAME,
)


class LogReadError(DaqError):
    """A run log cannot be read (not an MCAP file, or not a jointid log)."""


@dataclass(frozen=True)
class RunArrays:
    """One payload run of one axis, as arrays over cycles (joint side, SI units).

    Attributes
    ----------
    t : ndarray, shape (n,)
        Campaign time of each cycle [s].
    cycle : ndarray of int64, shape (n,)
        Cycle counter (consecutive unless cycles were lost).
    q : ndarray, shape (n,)
        Joint position from the encoder [rad] (or [m]).
    dq : ndarray, shape (n,)
        Joint velocity from the drive (0x606C) [rad/s] (or [m/s]).
    counts : ndarray of int64, shape (n,)
        Position actual value [encoder counts].
    tau_ref : ndarray, shape (n,)
        Joint-side torque of the current reference sent [N m] (paper eq. 7).
    tau_actual : ndarray, shape (n,)
        Joint-side torque actual reported by the drive [N m].
    statusword : ndarray of uint16, shape (n,)
    flags : ndarray of uint8, shape (n,)
        Bit 0: TPDO missing in that cycle; bit 1: the runner was stopping.
    q_ref, dq_ref, ddq_ref : ndarray, shape (n,)
        Planned reference at the same cycles [rad], [rad/s], [rad/s^2] (NaN if absent):
        the axis's own (``/joint/<axis>/setpoint``, robot campaigns) or the shared
        ``/setpoint``.
    segment : ndarray of int32, shape (n,)
        Plan segment index (-1 if absent).
    payload_mass_kg, payload_arm_m : float
        Payload mounted during the run [kg], [m].
    revolute : bool
    metadata : dict of str to dict of str to str
        Every metadata record of the file.
    events : list of dict
        The ``/events`` messages (keys ``t``, ``cycle``, ``kind``, ``axis``, ``message``).
    truncated : bool
        The file ended before its summary (the writer was killed).
    lost_cycles : tuple of (int, int)
        Cycle ranges (first, last, inclusive) of the chunks found damaged and skipped (a
        warning names each); empty for an intact file.
    """

    t: np.ndarray
    cycle: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    counts: np.ndarray
    tau_ref: np.ndarray
    tau_actual: np.ndarray
    statusword: np.ndarray
    flags: np.ndarray
    q_ref: np.ndarray
    dq_ref: np.ndarray
    ddq_ref: np.ndarray
    segment: np.ndarray
    payload_mass_kg: float
    payload_arm_m: float
    revolute: bool
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    events: list[dict[str, Any]] = field(default_factory=list)
    truncated: bool = False
    lost_cycles: tuple[tuple[int, int], ...] = ()

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def valid(self) -> np.ndarray:
        """Cycles usable for identification, shape (n,) bool: the drive reported OPERATION
        ENABLED (statusword & 0x6F == 0x27), its TPDOs arrived and the runner was not stopping.
        Outside them (enable, stop, fault) the drive ignores the torque reference."""
        return ((self.statusword & 0x6F) == 0x27) & (self.flags == 0)

    def select(self, mask: np.ndarray) -> RunArrays:
        """The same run restricted to the cycles where ``mask`` is true."""
        arrays = {k: getattr(self, k)[mask] for k in _ARRAY_FIELDS}
        return replace(self, **arrays)

    def valid_only(self) -> RunArrays:
        """:meth:`select` of :attr:`valid` (what an identification should fit)."""
        return self.select(self.valid)


_ARRAY_FIELDS = ("t", "cycle", "q", "dq", "counts", "tau_ref", "tau_actual", "statusword",
                 "flags", "q_ref", "dq_ref", "ddq_ref", "segment")
_HEAD = struct.Struct("<BQ")  # opcode, record length
_CHUNK_FIXED = struct.Struct("<QQQII")  # start, end, uncompressed size, crc, compression len
_U64 = struct.Struct("<Q")
_FOOTER = struct.Struct("<BQQQI")  # opcode, length, summary start, summary offsets start, crc
MAGIC = b"\x89MCAP0\r\n"


@dataclass
class _Scan:
    channels: dict[int, tuple[str, str]] = field(default_factory=dict)  # id -> (topic, schema)
    schemas: dict[int, str] = field(default_factory=dict)
    parts: dict[str, list[np.ndarray]] = field(default_factory=dict)
    raw: dict[str, list[bytes]] = field(default_factory=dict)  # topic -> message data
    events: list[dict[str, Any]] = field(default_factory=list)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    attachments: dict[str, bytes] = field(default_factory=dict)
    truncated: bool = False
    n_chunks: int = 0
    #: chunks that could not be read: (file offset, first and last log time [ns], why)
    damaged: list[tuple[int, int, int, str]] = field(default_factory=list)
    #: (log time [ns], cycle) of the first and last state message of each chunk read
    anchors: list[tuple[int, int]] = field(default_factory=list)
    #: cycle ranges (first, last) of the damaged chunks
    lost_cycles: list[tuple[int, int]] = field(default_factory=list)


def _walk_chunk(data: bytes, scan: _Scan, topics: Container[str],
                raw_topics: set[str]) -> None:
    """Collect the records of one decompressed chunk into ``scan``.

    Raises
    ------
    ValueError
        If the records do not tile the chunk (a record runs past its end); nothing of the
        chunk's messages is kept then.
    """
    offsets: dict[int, list[int]] = {}
    n = len(data)
    pos = 0
    unpack_head = _HEAD.unpack_from
    unpack_cid = struct.Struct("<H").unpack_from
    channels = scan.channels
    new_channels: list[Channel] = []
    while pos + 9 <= n:
        opcode, length = unpack_head(data, pos)
        body = pos + 9
        if body + length > n:
            break
        if opcode == Opcode.MESSAGE:
            (cid,) = unpack_cid(data, body)
            lst = offsets.get(cid)
            if lst is None:
                lst = offsets[cid] = []
            lst.append(body + 22)
        elif opcode == Opcode.CHANNEL:
            new_channels.append(Channel.read(_stream(data[body : body + length])))
        elif opcode == Opcode.SCHEMA:
            rec = Schema.read(_stream(data[body : body + length]))
            scan.schemas[rec.id] = rec.name
        pos = body + length
    if pos != n:
        raise ValueError(f"the records of the chunk end at byte {pos} of {n}")
    for ch in new_channels:
        channels[ch.id] = (ch.topic, scan.schemas.get(ch.schema_id, ""))
    buf = np.frombuffer(data, np.uint8)
    for cid, offs in offsets.items():
        topic, schema = channels.get(cid, ("", ""))
        if schema == STATE_SCHEMA_NAME:
            for o in (offs[0], offs[-1]):  # log time and sequence (= cycle) of the message
                seq, lt = struct.unpack_from("<IQ", data, o - 20)
                scan.anchors.append((lt, seq))
        if topic == "/events":
            for o in offs:
                end = _message_end(data, o)
                scan.events.append(json.loads(data[o:end]))
            continue
        if topic in raw_topics:
            scan.raw.setdefault(topic, []).extend(data[o : _message_end(data, o)] for o in offs)
            continue
        if topic not in topics:
            continue
        dtype = STATE_DTYPE if schema == STATE_SCHEMA_NAME else SETPOINT_DTYPE
        idx = np.asarray(offs, dtype=np.int64)[:, None] + np.arange(dtype.itemsize)
        scan.parts.setdefault(topic, []).append(buf[idx].view(dtype).reshape(-1))


def _message_end(data: bytes, data_offset: int) -> int:
    """End of the message whose data starts at ``data_offset`` (its record length)."""
    start = data_offset - 22 - 9
    _, length = _HEAD.unpack_from(data, start)
    return start + 9 + length


def _stream(b: bytes) -> ReadDataStream:
    return ReadDataStream(BytesIO(b))


def chunk_records(path: Path, body: bytes | memoryview) -> tuple[bytes, int, int]:
    """The uncompressed records of a chunk record's ``body`` (after opcode and length),
    checked against the sizes and CRC it declares; and its first and last log time [ns].

    Raises
    ------
    ValueError, zstandard.ZstdError
        If the chunk is damaged (sizes, decompression, CRC).
    LogReadError
        If its compression is neither zstd nor none.
    """
    start, end, usize, crc, clen = _CHUNK_FIXED.unpack_from(body, 0)
    compression = bytes(body[32 : 32 + clen]).decode("utf-8")
    (dlen,) = _U64.unpack_from(body, 32 + clen)
    d0 = 40 + clen
    if d0 + dlen > len(body):
        raise ValueError(f"chunk data of {dlen} bytes runs past its record")
    data = body[d0 : d0 + dlen]
    if compression == "zstd":
        raw = zstandard.ZstdDecompressor().decompress(data, max_output_size=usize)
    elif compression == "":
        raw = bytes(data)
    else:
        raise LogReadError(f"{path}: unsupported chunk compression {compression!r}")
    if len(raw) != usize:
        raise ValueError(f"decompressed to {len(raw)} bytes, the chunk says {usize}")
    if crc and zlib.crc32(raw) != crc:
        raise ValueError("CRC mismatch")
    return raw, start, end


def _why(exc: BaseException) -> str:
    return f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__


def _read_summary(f: Any, size: int) -> Summary | None:
    """The summary of a closed file; None if the file has no footer (killed writer), no
    summary, or a summary that cannot be parsed (then it is read without it)."""
    tail = _FOOTER.size + len(MAGIC)
    if size < len(MAGIC) + tail:
        return None
    f.seek(size - tail)
    buf = f.read(tail)
    if buf[-len(MAGIC) :] != MAGIC:
        return None
    opcode, length, summary_start, _, _ = _FOOTER.unpack_from(buf)
    if opcode != Opcode.FOOTER or length != 20 or not 0 < summary_start <= size - tail:
        return None
    try:
        f.seek(0)
        return make_reader(f).get_summary()
    except Exception:  # damaged summary: the data section is read record by record
        return None


@contextmanager
def _opened(path: Path) -> Iterator[tuple[Any, int, Summary | None]]:
    """The run log opened for reading: (file, size [bytes], its summary or None: an
    unfinished log), after the MCAP magic was checked.

    Raises
    ------
    LogReadError
        The file cannot be opened or is not an MCAP file.
    """
    try:
        f = open(path, "rb")  # noqa: SIM115
    except OSError as exc:
        raise LogReadError(f"{path}: cannot open the run log: {exc.strerror}") from exc
    with f:
        size = os.fstat(f.fileno()).st_size
        if f.read(len(MAGIC)) != MAGIC:
            what = "an empty file" if size == 0 else "no MCAP magic at its start"
            raise LogReadError(f"{path}: not an MCAP file ({what})")
        yield f, size, _read_summary(f, size)


def _scan(path: Path, topics: Container[str], raw_topics: set[str] = frozenset(),
          attachments: bool = False) -> _Scan:
    scan = _Scan()
    with _opened(path) as (f, size, summary):
        if summary is not None and summary.chunk_indexes:
            _scan_indexed(f, path, summary, scan, topics, raw_topics, attachments)
        else:
            _scan_stream(f, path, size, scan, topics, raw_topics, attachments)
    _report_damage(path, scan)
    return scan


def _record_at(f: Any, offset: int, length: int, kind: int) -> Any:
    """The record of opcode ``kind`` (a ``_RECORDS`` class) that an index places at
    ``offset`` with ``length`` bytes (opcode and length included).

    Raises
    ------
    ValueError
        Another record there, or a length that does not match; the record's own errors
        when its bytes are damaged.
    """
    cls = _RECORDS[kind]
    f.seek(offset)
    buf = f.read(length)
    opcode, rec_len = _HEAD.unpack_from(buf)
    if opcode != kind or 9 + rec_len != length:
        raise ValueError(f"not a {cls.__name__} record")
    return cls.read(_stream(buf[9:]))


def _scan_indexed(f: Any, path: Path, summary: Summary, scan: _Scan, topics: Container[str],
                  raw_topics: set[str], attachments: bool) -> None:
    """A closed file: every chunk found through its chunk index; a damaged one is skipped."""
    for sid, sch in summary.schemas.items():
        scan.schemas[sid] = sch.name
    for cid, ch in summary.channels.items():
        scan.channels[cid] = (ch.topic, scan.schemas.get(ch.schema_id, ""))
    wanted: list[tuple[int, int, int]] = [(m.offset, m.length, Opcode.METADATA)
                                          for m in summary.metadata_indexes]
    if attachments:
        wanted += [(a.offset, a.length, Opcode.ATTACHMENT) for a in summary.attachment_indexes]
    for offset, length, kind in sorted(wanted, key=lambda w: w[0]):
        cls = _RECORDS[kind]
        try:
            _add_record(scan, _record_at(f, offset, length, kind))
        except Exception as exc:
            warnings.warn(f"{path}: {cls.__name__.lower()} record at offset {offset} damaged "
                          f"({_why(exc)}), skipped", RuntimeWarning, stacklevel=4)
    for ci in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset):
        try:
            f.seek(ci.chunk_start_offset)
            buf = f.read(ci.chunk_length)
            if len(buf) != ci.chunk_length:
                raise ValueError("the file ends inside the chunk")
            opcode, rec_len = _HEAD.unpack_from(buf)
            if opcode != Opcode.CHUNK or 9 + rec_len != ci.chunk_length:
                raise ValueError("no chunk record at the offset of its index")
            raw, _, _ = chunk_records(path, memoryview(buf)[9:])
            _walk_chunk(raw, scan, topics, raw_topics)
            scan.n_chunks += 1
        except LogReadError:
            raise
        except Exception as exc:
            scan.damaged.append((ci.chunk_start_offset, ci.message_start_time,
                                 ci.message_end_time, _why(exc)))


def _add_record(scan: _Scan, rec: Any) -> None:
    if isinstance(rec, Metadata):
        scan.metadata[rec.name] = dict(rec.metadata)
    elif isinstance(rec, Attachment):
        scan.attachments[rec.name] = rec.data


class RecordWalk:
    """The records of an MCAP file one after the other, without any index.

    Iterating yields ``(offset, opcode, length)`` of each record from the first after the
    magic, with the file positioned at the record's body; it stops after the footer, or
    before a record that runs past the end of the file (a killed writer). Then
    :attr:`complete` tells whether the footer was reached, :attr:`end` is the offset
    where the readable records end and :attr:`stop_reason` says why it stopped.
    """

    def __init__(self, f: Any, size: int) -> None:
        self.f = f
        self.size = size
        self.complete = False
        self.end = len(MAGIC)
        self.stop_reason = ""

    def __iter__(self) -> Iterator[tuple[int, int, int]]:
        pos = len(MAGIC)
        while True:
            self.end = pos
            self.f.seek(pos)
            head = self.f.read(9)
            if len(head) < 9:
                self.stop_reason = ("the file ends inside a record header" if head
                                    else "no summary or footer")
                return
            opcode, length = _HEAD.unpack_from(head)
            if pos + 9 + length > self.size:
                self.stop_reason = f"the record at offset {pos} runs past the end of the file"
                return
            yield pos, opcode, length
            pos += 9 + length
            if opcode == Opcode.FOOTER:
                self.end = pos
                self.complete = True
                return


def _scan_stream(f: Any, path: Path, size: int, scan: _Scan, topics: Container[str],
                 raw_topics: set[str], attachments: bool) -> None:
    """A file without a (usable) summary: its records one after the other, up to the first
    that runs past the end of the file (a killed writer). A chunk whose data is damaged
    but whose record length is intact is skipped."""
    walk = RecordWalk(f, size)
    for pos, opcode, length in walk:
        if opcode == Opcode.DATA_END:
            walk.complete = True
            break
        if opcode == Opcode.CHUNK:
            body = f.read(length)
            try:
                raw, _, _ = chunk_records(path, memoryview(body))
                _walk_chunk(raw, scan, topics, raw_topics)
                scan.n_chunks += 1
            except LogReadError:
                raise
            except Exception as exc:
                start, end = _CHUNK_FIXED.unpack_from(body)[:2] if length >= 32 else (0, 0)
                scan.damaged.append((pos, start, end, _why(exc)))
        elif opcode in (Opcode.SCHEMA, Opcode.CHANNEL, Opcode.METADATA) or (
                opcode == Opcode.ATTACHMENT and attachments):
            try:
                rec = _RECORDS[opcode].read(_stream(f.read(length)))
            except Exception as exc:
                warnings.warn(f"{path}: record at offset {pos} damaged ({_why(exc)}), skipped",
                              RuntimeWarning, stacklevel=4)
            else:
                if isinstance(rec, Schema):
                    scan.schemas.setdefault(rec.id, rec.name)
                elif isinstance(rec, Channel):
                    scan.channels.setdefault(rec.id, (rec.topic, scan.schemas.get(rec.schema_id,
                                                                                  "")))
                else:
                    _add_record(scan, rec)
    if not walk.complete:
        scan.truncated = True
        warnings.warn(
            f"{path}: truncated run log (writer killed?): read {scan.n_chunks} complete chunks "
            f"({walk.stop_reason}); `jointid recover` rewrites it with an index",
            RuntimeWarning, stacklevel=4)


_RECORDS: dict[int, Any] = {Opcode.SCHEMA: Schema, Opcode.CHANNEL: Channel,
                            Opcode.METADATA: Metadata, Opcode.ATTACHMENT: Attachment}


def _report_damage(path: Path, scan: _Scan) -> None:
    """Warn once per damaged chunk, with the cycles it held; fill ``scan.lost_cycles``."""
    if not scan.damaged:
        return
    cycle_ns = 0
    try:
        cycle_ns = int(round(float(scan.metadata["campaign"]["cycle_s"]) * 1e9))
    except (KeyError, ValueError):
        pass
    anchors = sorted(set(scan.anchors), key=lambda a: a[1])
    if not cycle_ns and len(anchors) >= 2 and anchors[-1][1] != anchors[0][1]:
        (t0, c0), (t1, c1) = anchors[0], anchors[-1]
        cycle_ns = int(round((t1 - t0) / (c1 - c0)))
    for offset, start, end, why in scan.damaged:
        if cycle_ns > 0 and anchors:
            t0, c0 = anchors[0]
            a = c0 + int(round((start - t0) / cycle_ns))
            b = c0 + int(round((end - t0) / cycle_ns))
            scan.lost_cycles.append((a, b))
            lost = f"cycles {a}..{b} lost"
        else:
            lost = f"log times {start}..{end} ns lost"
        warnings.warn(f"{path}: chunk at offset {offset} damaged ({why}): {lost}",
                      RuntimeWarning, stacklevel=4)


def _concat(parts: list[np.ndarray], dtype: np.dtype) -> np.ndarray:
    if not parts:
        return np.zeros(0, dtype)
    a = np.concatenate(parts)
    order = np.argsort(a["cycle"], kind="stable")
    return a[order]


def read_run(path: str | Path, axis: int = 0) -> RunArrays:
    """Read one axis of one payload run.

    Parameters
    ----------
    path : path-like
        A ``*.mcap`` file written by :class:`daq.runtime.mcaplog.RunLog`.
    axis : int
        Drive index (channel ``/joint/<axis>/state``).

    Returns
    -------
    RunArrays

    Raises
    ------
    LogReadError
        If the file is missing, not MCAP, or has no state of that axis.
    """
    path = Path(path)  # scanned here, not through read_runs: the warnings' stacklevel
    scan = _scan(path, {"/setpoint", f"/joint/{axis}/state", f"/joint/{axis}/setpoint"})
    return _run_arrays(path, scan, axis)


class _EveryAxis:
    """The topics filter of every axis's state and setpoint and the shared ``/setpoint``."""

    _TOPIC = re.compile(r"/setpoint|/joint/\d+/(state|setpoint)")

    def __contains__(self, topic: object) -> bool:
        return isinstance(topic, str) and self._TOPIC.fullmatch(topic) is not None


def read_runs(path: str | Path, axes: Sequence[int] | None = None) -> list[RunArrays]:
    """Read several axes of one payload run in one scan of the file, each as
    :func:`read_run` reads it (a damaged chunk or a truncated tail warned about once).

    Parameters
    ----------
    path : path-like
        A ``*.mcap`` file written by :class:`daq.runtime.mcaplog.RunLog`.
    axes : sequence of int or None
        Drive indices (channels ``/joint/<axis>/state``); None: every axis of the log,
        ``/joint/0/state``, ``/joint/1/state``... up to the first channel missing.

    Returns
    -------
    list of RunArrays
        One per axis, in the order of ``axes``.

    Raises
    ------
    LogReadError
        If the file is missing, not MCAP, or has no state of one of the axes (of axis 0
        with ``axes`` None).
    """
    path = Path(path)
    if axes is None:
        scan = _scan(path, _EveryAxis())
        present = {t for t, _ in scan.channels.values()}
        n = 0
        while f"/joint/{n}/state" in present:
            n += 1
        axes = range(max(n, 1))
    else:
        wanted = {"/setpoint"}
        for axis in axes:
            wanted |= {f"/joint/{axis}/state", f"/joint/{axis}/setpoint"}
        scan = _scan(path, wanted)
    return [_run_arrays(path, scan, axis) for axis in axes]


def _run_arrays(path: Path, scan: _Scan, axis: int) -> RunArrays:
    """The arrays of axis ``axis`` from a scan that read its topics."""
    topic = f"/joint/{axis}/state"
    sp_topic = f"/joint/{axis}/setpoint"
    topics = {t for t, _ in scan.channels.values()}
    if topic not in topics:
        raise LogReadError(f"{path}: no channel {topic} (not a jointid run log, or no data)")
    st = _concat(scan.parts.get(topic, []), STATE_DTYPE)
    # a robot campaign's log has each axis's own reference; a single joint's, one shared
    sp = _concat(scan.parts.get(sp_topic if sp_topic in topics else "/setpoint", []),
                 SETPOINT_DTYPE)
    n = st.shape[0]
    q_ref = np.full(n, np.nan)
    dq_ref = np.full(n, np.nan)
    ddq_ref = np.full(n, np.nan)
    segment = np.full(n, -1, np.int32)
    if sp.shape[0] and n:
        pos = np.searchsorted(sp["cycle"], st["cycle"])
        pos_c = np.minimum(pos, sp.shape[0] - 1)
        ok = sp["cycle"][pos_c] == st["cycle"]
        q_ref[ok] = sp["q_ref"][pos_c[ok]]
        dq_ref[ok] = sp["dq_ref"][pos_c[ok]]
        ddq_ref[ok] = sp["ddq_ref"][pos_c[ok]]
        segment[ok] = sp["segment"][pos_c[ok]]
    payload = scan.metadata.get("payload", {})
    campaign = scan.metadata.get("campaign", {})
    events = sorted(scan.events, key=lambda e: e.get("cycle", 0))
    return RunArrays(
        t=np.ascontiguousarray(st["t"]),
        cycle=st["cycle"].astype(np.int64),
        q=np.ascontiguousarray(st["q"]),
        dq=np.ascontiguousarray(st["dq"]),
        counts=st["counts"].astype(np.int64),
        tau_ref=np.ascontiguousarray(st["tau_ref"]),
        tau_actual=np.ascontiguousarray(st["tau_actual"]),
        statusword=st["statusword"].astype(np.uint16),
        flags=st["flags"].astype(np.uint8),
        q_ref=q_ref,
        dq_ref=dq_ref,
        ddq_ref=ddq_ref,
        segment=segment,
        payload_mass_kg=float(payload.get("mass_kg", "nan")),
        payload_arm_m=float(payload.get("arm_m", "nan")),
        revolute=campaign.get("joint_kind", "revolute") != "prismatic",
        metadata={name: dict(rec) for name, rec in scan.metadata.items()},
        events=events,
        truncated=scan.truncated,
        lost_cycles=tuple(scan.lost_cycles),
    )


def read_attachments(path: str | Path) -> dict[str, bytes]:
    """The attachments of a run log (name -> bytes): campaign file, EDS, plant file."""
    return _scan(Path(path), set(), attachments=True).attachments


def read_metadata(path: str | Path) -> dict[str, dict[str, str]]:
    """The metadata records of a run log (name -> map), without reading its chunks.

    A closed file is read through its metadata index; a file without a usable summary
    (killed writer) record after record, skipping the chunks (the ``campaign``, ``payload``
    and ``plant`` records precede them; ``result`` is written on close). Damaged metadata
    records are skipped (no warning: what is missing stays missing).

    Raises
    ------
    LogReadError
        The file cannot be opened or is not an MCAP file.
    """
    path = Path(path)
    out: dict[str, dict[str, str]] = {}
    with _opened(path) as (f, size, summary):
        if summary is not None:
            places = [(m.offset, m.length) for m in summary.metadata_indexes]
        else:
            places = [(pos, 9 + length) for pos, opcode, length in RecordWalk(f, size)
                      if opcode == Opcode.METADATA]
        for offset, length in places:
            try:
                rec = _record_at(f, offset, length, Opcode.METADATA)
            except Exception:  # a damaged record: skipped
                continue
            out[rec.name] = dict(rec.metadata)
    return out


@dataclass(frozen=True)
class TopicData:
    """Raw messages of some topics of a run log, with the log's events and metadata."""

    #: topic -> message data in log order (topics not in the log are absent)
    raw: dict[str, list[bytes]]
    #: the ``/events`` records (dicts with ``cycle``, ``kind``...)
    events: list[dict[str, Any]]
    #: metadata name -> map
    metadata: dict[str, dict[str, str]]
    #: True when chunks were damaged or the tail truncated (their messages are missing)
    damaged: bool


def read_topics(path: str | Path, topics: set[str]) -> TopicData:
    """The raw message data of the given topics, the events and the metadata of a run log.
    Damaged chunks and a truncated tail are skipped with a warning, as by :func:`read_run`."""
    scan = _scan(Path(path), set(), set(topics))
    return TopicData(scan.raw, scan.events, scan.metadata,
                     bool(scan.truncated or scan.damaged))


def read_frames(path: str | Path) -> np.ndarray:
    """Every logged CAN frame, as a structured array with fields ``cycle``, ``timestamp``,
    ``id``, ``dlc``, ``data`` (uint8 x 8), in cycle order. Damaged chunks and a truncated
    tail are skipped with a warning, as by :func:`read_run`."""
    path = Path(path)
    scan = _scan(path, set(), {"/can/raw"})
    out: list[np.ndarray] = []
    for msg in scan.raw.get("/can/raw", []):
        cycle, n = struct.unpack_from("<qI", msg, 4)
        fr = np.frombuffer(msg, FRAME_DTYPE, count=n, offset=20)
        rec = np.zeros(n, _FRAMES_DTYPE)
        rec["cycle"] = cycle
        for k in ("timestamp", "id", "dlc", "data"):
            rec[k] = fr[k]
        out.append(rec)
    if not out:
        return np.zeros(0, _FRAMES_DTYPE)
    a = np.concatenate(out)
    return a[np.argsort(a["cycle"], kind="stable")]


_FRAMES_DTYPE = np.dtype([("cycle", "<i8"), ("timestamp", "<f8"), ("id", "<u4"), ("dlc", "u1"),
                          ("data", "u1", (8,))])


def list_runs(directory: str | Path) -> list[Path]:
    """The run logs (``*.mcap``) of an output directory, sorted by payload index then name."""
    d = Path(directory)
    if not d.is_dir():
        raise LogReadError(f"{d}: not a directory")

    def key(p: Path) -> tuple[int, str]:
        stem = p.stem
        k = stem.rfind("_payload")
        try:
            return (int(stem[k + 8 :]) if k >= 0 else 1 << 30, p.name)
        except ValueError:
            return (1 << 30, p.name)

    return sorted(d.glob("*.mcap"), key=key)
