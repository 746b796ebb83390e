"""MCAP run log: one file per payload run, written as data arrives.

Channels (see ``docs/log-format.md`` for the full description):

``/joint/<axis>/state``
    One message per cycle and drive, ``ros2msg`` schema ``jointid_msgs/msg/JointState``,
    ``cdr`` encoding (little endian). The record has a fixed size (68 bytes) so that the
    reader decodes whole chunks with one numpy structured dtype, and Foxglove plots every
    field without a custom decoder.
``/setpoint``
    One message per cycle: the planned reference (``jointid_msgs/msg/Setpoint``, cdr).
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
about ``chunk_seconds`` of data: a killed process loses at most that much.
"""

from __future__ import annotations

import json
import struct
import time
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from mcap.writer import CompressionType, Writer

from . import DaqError, __version__

CDR_HEADER = b"\x00\x01\x00\x00"  # CDR, little endian, no options

STATE_SCHEMA_NAME = "jointid_msgs/msg/JointState"
STATE_SCHEMA = """\
# One control cycle of one drive (joint side, SI units)
float64 t            # [s] campaign time of the cycle (cycle * cycle period)
int64 cycle          # cycle counter from 0, no gaps
float64 q            # [rad] or [m] joint position from the encoder (0x6064)
float64 dq           # [rad/s] or [m/s] joint velocity from 0x606C
float64 tau_ref      # [N m] or [N] joint-side torque of the current reference sent
float64 tau_actual   # [N m] or [N] joint-side torque actual (0x6077)
int32 counts         # position actual value (0x6064) [encoder counts]
int32 velocity_raw   # velocity actual value (0x606C) [counts/s]
int16 tau_ref_raw    # target torque sent (0x6071) [per mille of rated torque]
int16 tau_actual_raw # torque actual (0x6077) [per mille of rated torque]
uint16 statusword    # 0x6041
uint8 flags          # bit 0: TPDO missing this cycle (values repeated); bit 1: stopping
uint8 reserved
"""
_STATE = struct.Struct("<4sdqddddiihhHBB")
STATE_SIZE = _STATE.size  # 68
STATE_DTYPE = np.dtype(
    [
        ("hdr", "V4"),
        ("t", "<f8"),
        ("cycle", "<i8"),
        ("q", "<f8"),
        ("dq", "<f8"),
        ("tau_ref", "<f8"),
        ("tau_actual", "<f8"),
        ("counts", "<i4"),
        ("velocity_raw", "<i4"),
        ("tau_ref_raw", "<i2"),
        ("tau_actual_raw", "<i2"),
        ("statusword", "<u2"),
        ("flags", "u1"),
        ("reserved", "u1"),
    ]
)
assert STATE_DTYPE.itemsize == STATE_SIZE
FLAG_TPDO_MISSING = 1
FLAG_STOPPING = 2

SETPOINT_SCHEMA_NAME = "jointid_msgs/msg/Setpoint"
SETPOINT_SCHEMA = """\
# The planned reference of one cycle (joint side, SI units)
float64 t          # [s] campaign time
int64 cycle        # cycle counter
float64 q_ref      # [rad] or [m]
float64 dq_ref     # [rad/s] or [m/s]
float64 ddq_ref    # [rad/s^2] or [m/s^2]
int32 segment      # index of the plan segment (names in metadata "campaign".segments)
int32 target_raw   # CSP: target position sent (0x607A) [counts]; CST: 0
"""
_SETPOINT = struct.Struct("<4sdqdddii")
SETPOINT_DTYPE = np.dtype(
    [
        ("hdr", "V4"),
        ("t", "<f8"),
        ("cycle", "<i8"),
        ("q_ref", "<f8"),
        ("dq_ref", "<f8"),
        ("ddq_ref", "<f8"),
        ("segment", "<i4"),
        ("target_raw", "<i4"),
    ]
)
assert SETPOINT_DTYPE.itemsize == _SETPOINT.size

CAN_SCHEMA_NAME = "jointid_msgs/msg/CanFrames"
CAN_SCHEMA = """\
# Every CAN frame sent or received during one cycle
int64 cycle
CanFrame[] frames
================================================================================
MSG: jointid_msgs/CanFrame
float64 timestamp   # [s] python-can timestamp (monotonic or epoch, as the interface gives)
uint32 id           # arbitration id (11-bit)
uint8 dlc
uint8[8] data       # zero-padded
"""
FRAME = struct.Struct("<dIB8s3x")  # one CanFrame element in the CDR sequence (24 bytes)
FRAME_DTYPE = np.dtype(
    [("timestamp", "<f8"), ("id", "<u4"), ("dlc", "u1"), ("data", "u1", (8,)), ("pad", "V3")]
)
assert FRAME_DTYPE.itemsize == FRAME.size
_CAN_HEAD = struct.Struct("<4sqI4x")  # header, cycle, sequence length, pad to 8

EVENT_SCHEMA = json.dumps(
    {
        "title": "jointid event",
        "type": "object",
        "properties": {
            "t": {"type": "number", "description": "campaign time [s]"},
            "cycle": {"type": "integer"},
            "kind": {
                "type": "string",
                "description": "state, emcy, fault, stop, operator, info, limit, watchdog",
            },
            "axis": {"type": "integer", "description": "drive index, -1 for the whole run"},
            "message": {"type": "string"},
        },
    }
).encode()


def chunk_size_for(n_axes: int, frames_per_cycle: int, cycle_s: float, seconds: float) -> int:
    """Chunk size [byte] holding about ``seconds`` of data at the given cycle."""
    per_cycle = (
        n_axes * (STATE_SIZE + 31) + (_SETPOINT.size + 31) + 47 + frames_per_cycle * FRAME.size
    )
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
        w = Writer(
            self._file,
            chunk_size=chunk_size_for(n_axes, frames_per_cycle, cycle_s, chunk_seconds),
            compression=CompressionType.ZSTD,
        )
        self._w = w
        w.start(profile="", library=f"jointid {__version__}")
        sid = w.register_schema(STATE_SCHEMA_NAME, "ros2msg", STATE_SCHEMA.encode())
        self._state_ch = [
            w.register_channel(f"/joint/{k}/state", "cdr", sid) for k in range(n_axes)
        ]
        sid = w.register_schema(SETPOINT_SCHEMA_NAME, "ros2msg", SETPOINT_SCHEMA.encode())
        self._setpoint_ch = w.register_channel("/setpoint", "cdr", sid)
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
            _STATE.pack(
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
        self._add(
            self._setpoint_ch,
            self.start_ns + cycle * self.cycle_ns,
            _SETPOINT.pack(CDR_HEADER, t, cycle, q_ref, dq_ref, ddq_ref, segment, target_raw),
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
            _CAN_HEAD.pack(CDR_HEADER, cycle, n_frames) + packed,
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
            self._file.close()

    def __enter__(self) -> RunLog:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
