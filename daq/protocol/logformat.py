"""The jointid MCAP log format: schemas, record layouts, numpy dtypes and flags.

Shared by the writer (:mod:`daq.runtime.mcaplog`) and the reader (:mod:`daq.protocol.reader`);
pure data, no I/O. Channels (see ``docs/log-format.md`` for the full description):

``/joint/<axis>/state``
    One message per cycle and drive, ``ros2msg`` schema ``jointid_msgs/msg/JointState``,
    ``cdr`` encoding (little endian), fixed size (68 bytes): the reader decodes whole chunks
    with one numpy structured dtype (:data:`STATE_DTYPE`).
``/setpoint``
    One message per cycle: the planned reference (``jointid_msgs/msg/Setpoint``, cdr).
``/can/raw``
    One message per cycle with every CAN frame sent or received during the cycle
    (``jointid_msgs/msg/CanFrames``, cdr; a sequence of fixed 24-byte :data:`FRAME` records).
``/events``
    State changes, EMCY, faults, operator actions: JSON described by :data:`EVENT_SCHEMA`.
"""

from __future__ import annotations

import json
import struct

import numpy as np

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
STATE_STRUCT = struct.Struct("<4sdqddddiihhHBB")
STATE_SIZE = STATE_STRUCT.size  # 68
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
SETPOINT_STRUCT = struct.Struct("<4sdqdddii")
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
assert SETPOINT_DTYPE.itemsize == SETPOINT_STRUCT.size

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
CAN_HEAD_STRUCT = struct.Struct("<4sqI4x")  # header, cycle, sequence length, pad to 8

#: The residuals a torque monitor checks: the low-passed measured torque minus the model's
#: prediction, or the generalized-momentum observer's. The "residual" of a log's "monitor"
#: metadata and of a thresholds file (``ident.monitor``) is one of them.
MONITOR_RESIDUALS = ("filtered", "observer")
#: default gain K_O [1/s] of the momentum observer: time constant 1 / K_O = 20 ms (a push's
#: torque reaches 1 - e^-1 of its value in 20 ms, 92 % in 50 ms: the issue's delay), while
#: the noise of p = M dq reaches r multiplied by K_O (used by :mod:`daq.runtime.monitor`;
#: here so that ``jointid monitor --help`` needs neither scipy nor pinocchio)
MONITOR_OBSERVER_GAIN = 50.0
#: default regime bins of a thresholds file (:mod:`ident.monitor`): edges [s] on a joint's
#: moving time (time since its filtered velocity was last inside the rest band or changed
#: sign, daq.runtime.monitor): bin 0 below the first edge (reversals, breakaway, rest), the
#: last bin from the last edge on (steady motion)
MONITOR_EDGES_S = (0.03, 0.1, 0.3, 1.0)

#: The CAN trace formats ``jointid export`` writes (:mod:`daq.protocol.export`), by extension;
#: here, not there, so that the command's help needs neither python-can nor mcap
EXPORT_FORMATS = (".blf", ".asc", ".log", ".csv", ".trc")

EVENT_SCHEMA = json.dumps(
    {
        "title": "jointid event",
        "type": "object",
        "properties": {
            "t": {"type": "number", "description": "campaign time [s]"},
            "cycle": {"type": "integer"},
            "kind": {
                "type": "string",
                "description": "state, emcy, fault, stop, operator, info, warning, limit, "
                               "watchdog",
            },
            "axis": {"type": "integer", "description": "drive index, -1 for the whole run"},
            "message": {"type": "string"},
        },
    }
).encode()
