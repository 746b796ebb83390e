"""Read jointid MCAP run logs back into numpy arrays (for :mod:`ident`).

Chunk-wise: each compressed chunk is decompressed once; the offsets of the fixed-size
state and setpoint records are collected by a walk over the record headers and the
records are decoded with one numpy structured dtype per chunk, so no Python object is
created per message beyond that walk. A file truncated by a killed writer (no summary, a
partial last chunk) is read up to its last complete chunk, with a warning.
"""

from __future__ import annotations

import json
import struct
import warnings
from dataclasses import dataclass, field, replace
from io import BytesIO
from pathlib import Path
from typing import Any

import numpy as np
import zstandard
from mcap.records import Attachment, Channel, Chunk, Metadata, Opcode, Schema
from mcap.stream_reader import StreamReader

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
        Planned reference at the same cycles [rad], [rad/s], [rad/s^2] (NaN if absent).
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
_MSG_HEAD = struct.Struct("<HIQQ")  # channel id, sequence, log time, publish time


@dataclass
class _Scan:
    channels: dict[int, tuple[str, str]] = field(default_factory=dict)  # id -> (topic, schema)
    schemas: dict[int, str] = field(default_factory=dict)
    parts: dict[str, list[np.ndarray]] = field(default_factory=dict)
    events: list[dict[str, Any]] = field(default_factory=list)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    attachments: dict[str, bytes] = field(default_factory=dict)
    truncated: bool = False


def _walk_chunk(data: bytes, scan: _Scan, topics: set[str]) -> None:
    """Collect the records of one decompressed chunk into ``scan``."""
    offsets: dict[int, list[int]] = {}
    n = len(data)
    pos = 0
    unpack_head = _HEAD.unpack_from
    unpack_cid = struct.Struct("<H").unpack_from
    channels = scan.channels
    while pos + 9 <= n:
        opcode, length = unpack_head(data, pos)
        body = pos + 9
        if opcode == Opcode.MESSAGE:
            (cid,) = unpack_cid(data, body)
            lst = offsets.get(cid)
            if lst is None:
                lst = offsets[cid] = []
            lst.append(body + 22)
        elif opcode == Opcode.CHANNEL:
            rec = Channel.read(_stream(data[body : body + length]))
            channels[rec.id] = (rec.topic, scan.schemas.get(rec.schema_id, ""))
        elif opcode == Opcode.SCHEMA:
            rec = Schema.read(_stream(data[body : body + length]))
            scan.schemas[rec.id] = rec.name
        pos = body + length
    buf = np.frombuffer(data, np.uint8)
    for cid, offs in offsets.items():
        topic, schema = channels.get(cid, ("", ""))
        if topic == "/events":
            for o in offs:
                end = _message_end(data, o)
                scan.events.append(json.loads(data[o:end]))
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


def _stream(b: bytes):
    from mcap.data_stream import ReadDataStream

    return ReadDataStream(BytesIO(b))


def _scan(path: Path, topics: set[str]) -> _Scan:
    scan = _Scan()
    try:
        f = open(path, "rb")  # noqa: SIM115
    except OSError as exc:
        raise LogReadError(f"{path}: cannot open the run log: {exc.strerror}") from exc
    with f:
        reader = StreamReader(f, emit_chunks=True)
        complete = False
        n_chunks = 0
        try:
            for rec in reader.records:
                if isinstance(rec, Chunk):
                    if rec.compression == "zstd":
                        data = zstandard.ZstdDecompressor().decompress(
                            rec.data, max_output_size=rec.uncompressed_size
                        )
                    elif rec.compression == "":
                        data = rec.data
                    else:
                        raise LogReadError(
                            f"{path}: unsupported chunk compression {rec.compression!r}"
                        )
                    _walk_chunk(data, scan, topics)
                    n_chunks += 1
                elif isinstance(rec, Metadata):
                    scan.metadata[rec.name] = dict(rec.metadata)
                elif isinstance(rec, Attachment):
                    scan.attachments[rec.name] = rec.data
                elif isinstance(rec, Channel):
                    scan.channels.setdefault(
                        rec.id, (rec.topic, scan.schemas.get(rec.schema_id, ""))
                    )
                elif isinstance(rec, Schema):
                    scan.schemas.setdefault(rec.id, rec.name)
            complete = True
        except LogReadError:
            raise
        except Exception as exc:  # truncated or damaged tail: keep what is complete
            if n_chunks == 0 and not scan.metadata:
                if isinstance(exc, (ValueError,)) and "magic" in str(exc).lower():
                    raise LogReadError(f"{path}: not an MCAP file") from exc
            scan.truncated = True
            warnings.warn(
                f"{path}: truncated run log (writer killed?): read {n_chunks} complete chunks "
                f"({type(exc).__name__})",
                RuntimeWarning,
                stacklevel=3,
            )
        if not complete:
            scan.truncated = True
    return scan


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
    path = Path(path)
    topic = f"/joint/{axis}/state"
    scan = _scan(path, {topic, "/setpoint"})
    if topic not in {t for t, _ in scan.channels.values()}:
        raise LogReadError(f"{path}: no channel {topic} (not a jointid run log, or no data)")
    st = _concat(scan.parts.get(topic, []), STATE_DTYPE)
    sp = _concat(scan.parts.get("/setpoint", []), SETPOINT_DTYPE)
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
        metadata=scan.metadata,
        events=events,
        truncated=scan.truncated,
    )


def read_attachments(path: str | Path) -> dict[str, bytes]:
    """The attachments of a run log (name -> bytes): campaign file, EDS, plant file."""
    return _scan(Path(path), set()).attachments


def read_frames(path: str | Path) -> np.ndarray:
    """Every logged CAN frame, as a structured array with fields ``cycle``, ``timestamp``,
    ``id``, ``dlc``, ``data`` (uint8 x 8)."""
    path = Path(path)
    out: list[np.ndarray] = []
    with open(path, "rb") as f:
        from mcap.reader import make_reader

        try:
            for _, channel, msg in make_reader(f).iter_messages(topics=["/can/raw"]):
                del channel
                cycle, n = struct.unpack_from("<qI", msg.data, 4)
                fr = np.frombuffer(msg.data, FRAME_DTYPE, count=n, offset=20)
                rec = np.zeros(n, [("cycle", "<i8")] + [(k, FRAME_DTYPE[k]) for k in
                                                       ("timestamp", "id", "dlc", "data")])
                rec["cycle"] = cycle
                for k in ("timestamp", "id", "dlc", "data"):
                    rec[k] = fr[k]
                out.append(rec)
        except Exception as exc:  # truncated file
            warnings.warn(f"{path}: CAN frames read up to a damaged tail ({exc})",
                          RuntimeWarning, stacklevel=2)
    if not out:
        return np.zeros(0, [("cycle", "<i8"), ("timestamp", "<f8"), ("id", "<u4"),
                            ("dlc", "u1"), ("data", "u1", (8,))])
    return np.concatenate(out)


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
