"""Simulated CiA 402 joint drive: a canopen ``LocalNode`` on a python-can bus around a plant.

What canopen's ``LocalNode`` does not do and this class adds (``/work/shared/notes/canopen.md``):

- NMT slave: boot-up frame (0x700+id, data 0x00) on :meth:`SimulatedDrive.start`, on reset
  node and on reset communication, then PRE-OPERATIONAL; heartbeat producer per 0x1017;
  PRE-OPERATIONAL / OPERATIONAL / STOPPED (no SDO while STOPPED, PDOs only while OPERATIONAL).
  Reset node restores every object to its EDS/DCF value and the CiA 402 state machine to
  SWITCH ON DISABLED; reset communication restores 0x1000-0x1FFF.
- PDOs: mapping writes over SDO are validated (mappable objects only 0x06040041, at most 64
  bits 0x06040042, only while the PDO is disabled and sub 0 is 0 0x08000022); the layouts
  are rebuilt from the dictionary on NMT start (and on the next SYNC after a communication
  object changed) into ``struct.Struct`` objects. Synchronous RPDOs (types 0-240) are
  latched and applied on SYNC; event RPDOs (254/255) are applied on reception. On each SYNC
  the drive applies the latched RPDOs, steps the plant one cycle and sends the synchronous
  TPDOs (type n in 1-240: every n-th SYNC; 0: every SYNC); event TPDOs (254/255) are sent when
  their content changed (after a SYNC cycle or an SDO/RPDO write).
- CiA 402: the state machine of :mod:`daq.protocol.cia402` driven by 0x6040 (SDO or RPDO),
  0x6041 with bit 12 set in OPERATION ENABLED in a cyclic mode and bit 13 on a CSP following error,
  0x6060/0x6061 restricted to the modes 0x6502 advertises (abort 0x06090030 otherwise).

Modes and units
---------------
- CST (10): joint-side torque command ``tau = plant.torque_from_permille(0x6071 + 0x60B2)``
  [N m] (0x6071 and 0x60B2 in per-mille of the rated torque 0x6076); a demand beyond 0x6072
  (per-mille) is a fault 0x8311.
- CSP (8): a cycle-synchronous PD position loop on the joint angle decoded from counts,
  ``tau = kp (q_target - q) + kd (dq_target - dq) + torque_from_permille(0x60B2)`` with
  0x607A [counts] and dq_target the target's difference over one cycle,
  clamped to 0x6072 (bit 11 "internal limit" set while clamped); a following error larger
  than 0x6065 [counts] is a fault 0x8611 (0xFFFFFFFF disables the check, and so does 0,
  the default of several vendor files). Enabling operation (transitions 4, 16) sets 0x607A
  to the actual position, so the loop starts where the joint is.
- CSV (9): a PI velocity loop ``tau = kd e + ki int(e) + torque_from_permille(0x60B2)``,
  ``e = v_target - dq``, ``ki = kd 2 pi 3 Hz``, ``v_target`` from 0x60FF + 0x60B1
  [counts/s], clamped to 0x6072 like CSP (no integration while clamped).
- Other advertised modes are accepted but produce no torque in the simulation.
- 0x6064 position actual [counts] = ``plant.encoder_counts`` (wrapped to int32); 0x606C
  velocity actual [counts/s] = ``round(dq * counts_per_rad)``; 0x6077 torque actual and 0x6074
  torque demand [per-mille of rated torque]; 0x6078 current actual [per-mille of rated
  current]; 0x6076 [mN m] is served from the plant's rated motor torque and cannot be changed.
- Software position limits 0x607D (min, max) [counts]: outside -> fault 0x8612 (off while
  min >= max).
- Outside OPERATION ENABLED and QUICK STOP ACTIVE the power stage is off and the holding
  brake engaged: the plant is not stepped (the joint does not fall under gravity).
- Quick stop (0x605A): option 0 switches off at once (transition 12); 1-4 brake with a
  viscous torque then transition 12 when ``|dq|`` < 1e-3 rad/s; 5-8 brake and stay in QUICK
  STOP ACTIVE (enable operation returns, transition 16).

Faults (codes in :mod:`sim_drivers.faults`) go through FAULT REACTION ACTIVE to FAULT at once
(transitions 13, 14), set 0x603F and 0x1001 and send one EMCY frame; a rising edge of
controlword bit 7 resets them (transition 15, EMCY "error reset" frame). The fault reaction
is immediate (0x605E = 0 semantics: power stage off at once; the simulation engages the
brake, the plant is no longer stepped), with no quick-stop ramp first.

Losing the master
-----------------
- Heartbeat consumer 0x1016 (CiA 301): each sub-index ``(node id << 16) | time [ms]`` with
  node id and time non-zero makes the drive watch that node's heartbeat (COB-ID 0x700 + id;
  a boot-up frame counts). Monitoring starts at the first heartbeat received after the entry
  was written (or after boot), and a timeout is reported once until the next heartbeat
  restarts it. On a timeout the drive sends EMCY 0x8130 ("life guard error or heartbeat
  error", error register 0x11); in OPERATION ENABLED or QUICK STOP ACTIVE it is a fault
  0x8130 (FAULT, power off). Two entries with the same node id abort 0x06040043. The NMT
  reaction of 0x1029 (error behaviour) is not modelled: the NMT state does not change.
- SYNC watchdog: with 0x1006 (communication cycle period [µs]) non-zero, a drive in
  OPERATION ENABLED in a cyclic mode (CSP, CSV, CST) in NMT OPERATIONAL faults with 0x8100
  (see :mod:`sim_drivers.faults`) when no SYNC arrived for
  ``max(SYNC_LOSS_PERIODS * 0x1006, sync_loss_floor_s)`` of wall time, counted from the
  last SYNC or from enabling, whichever is later. ``SYNC_LOSS_PERIODS`` = 3; the floor
  (default ``SYNC_LOSS_FLOOR_S`` = 0.1 s) is there because this drive is a Python thread on
  a shared host: ``benchmarks/bench_daq.py`` measured single stalls of 30-50 ms even for a C
  ``clock_nanosleep`` loop on the 2-core CI machine, so 3 ms at 1 kHz would trip in healthy
  paced runs. 0x1006 = 0 (the EDS default) turns the watchdog off: the master writes 0 in
  lockstep (SYNCs may be far apart in wall time on a loaded host, and that is not a fault)
  and the cycle in paced mode.
- Both run in one daemon thread per drive that sleeps until the earliest deadline (about
  one wake-up per timeout, none while nothing is armed); on the hot path a SYNC costs one
  ``time.monotonic()`` and an uncontended lock.

Threading: every bus callback (SDO, NMT, RPDO, SYNC) runs in the drive network's notifier
thread, so they are serialised, and serialised with the watchdog thread by a lock; the
heartbeat producer is python-can's periodic-send task.
"""

from __future__ import annotations

import logging
import math
import operator
import struct
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import can
import canopen
import numpy as np
from canopen.sdo.exceptions import SdoAbortedError

from daq.protocol.cia402 import (
    CYCLIC_MODES,
    Mode,
    State,
    automatic_transition,
    next_state,
    statusword,
)
from sim_drivers import SimError
from sim_drivers.faults import (
    EXCESS_TORQUE,
    FOLLOWING_ERROR,
    HEARTBEAT_LOST,
    PDO_LENGTH_ERROR,
    PLANT_FAULT,
    POSITION_LIMIT,
    SYNC_LOST,
    FaultInjector,
    error_register,
)
from sim_drivers.od import STRUCT_CODE, DriveConfigError, DriveOD, load_drive_od, struct_code

logger = logging.getLogger(__name__)

__all__ = ["DriveError", "SimulatedDrive", "open_virtual_bus", "NMT_STATE_NAMES"]

# NMT states (heartbeat byte values).
NMT_INITIALISING = 0
NMT_STOPPED = 4
NMT_OPERATIONAL = 5
NMT_PRE_OPERATIONAL = 127
NMT_STATE_NAMES = {
    NMT_INITIALISING: "INITIALISING",
    NMT_STOPPED: "STOPPED",
    NMT_OPERATIONAL: "OPERATIONAL",
    NMT_PRE_OPERATIONAL: "PRE-OPERATIONAL",
}

# Objects the drive keeps as attributes: served live over SDO, written by SDO or RPDO,
# packed into TPDOs. (index, subindex) -> attribute name.
_LIVE: dict[tuple[int, int], str] = {
    (0x1001, 0): "error_register",
    (0x603F, 0): "error_code",
    (0x6040, 0): "controlword",
    (0x6041, 0): "statusword",
    (0x605A, 0): "quick_stop_option",
    (0x6060, 0): "mode_request",
    (0x6061, 0): "mode_display",
    (0x6064, 0): "position_actual",
    (0x6065, 0): "following_window",
    (0x606C, 0): "velocity_actual",
    (0x6071, 0): "target_torque",
    (0x6072, 0): "max_torque",
    (0x6074, 0): "torque_demand",
    (0x6076, 0): "rated_torque_mNm",
    (0x6077, 0): "torque_actual",
    (0x6078, 0): "current_actual",
    (0x607A, 0): "target_position",
    (0x607D, 1): "position_limit_min",
    (0x607D, 2): "position_limit_max",
    (0x60B1, 0): "velocity_offset",
    (0x60B2, 0): "torque_offset",
    (0x60FF, 0): "target_velocity",
}
# Written by the master (SDO or RPDO); everything else in _LIVE is computed by the drive
# or is a parameter written over SDO only.
_RX_ATTRS = frozenset(
    {
        "controlword",
        "mode_request",
        "target_torque",
        "target_position",
        "velocity_offset",
        "torque_offset",
        "target_velocity",
    }
)
_PARAM_ATTRS = {
    "quick_stop_option": 2,
    "following_window": 0xFFFFFFFF,
    "max_torque": 0x7FFF,
    "position_limit_min": 0,
    "position_limit_max": 0,
}

_PDO_NOT_VALID = 0x80000000
_RECORD_CHUNK = 65536
_QS_DONE_SPEED = 1e-3  # [rad/s]
_CSV_INTEGRAL_RATE = 2.0 * math.pi * 3.0  # CSV loop: ki = kd * this [1/s]
SYNC_LOSS_PERIODS = 3  # SYNC watchdog: timeout in periods of 0x1006
SYNC_LOSS_FLOOR_S = 0.1  # SYNC watchdog: shortest timeout [s] (host stalls, see docstring)
_WD_IDLE_S = 0.5  # watchdog thread: re-check period while nothing is armed [s]

_RECORD_FIELDS: tuple[tuple[str, Any], ...] = (
    ("cycle", np.int64),  # drive cycle index
    ("counts", np.int64),  # 0x6064 sent [counts]
    ("target_torque", np.int32),  # 0x6071 received [per-mille]
    ("target_position", np.int64),  # 0x607A received [counts]
    ("torque_demand", np.int32),  # demand after offset / position loop [per-mille]
    ("tau_cmd", np.float64),  # joint-side torque command to the plant [N m]
    ("tau_applied", np.float64),  # plant's applied torque [N m]
    ("q", np.float64),  # plant's true joint position [rad]
    ("statusword", np.int32),  # 0x6041 sent
    ("mode", np.int8),  # 0x6061
)


class DriveError(SimError):
    """The simulated drive cannot be built or driven as asked; the message says why."""


def open_virtual_bus(channel: str) -> can.BusABC:
    """A python-can virtual bus on ``channel`` (each participant opens its own)."""
    return can.Bus(interface="virtual", channel=channel, receive_own_messages=False)


def _wrap_i32(x: int) -> int:
    return ((x + 0x80000000) & 0xFFFFFFFF) - 0x80000000


def _clip(x: int, lo: int, hi: int) -> int:
    return lo if x < lo else hi if x > hi else x


class _HbConsumer:
    """One entry of 0x1016: the heartbeat of ``node`` watched with ``time_s`` [s]."""

    __slots__ = ("sub", "node", "time_s", "last", "active", "timed_out", "received", "cb")

    def __init__(self, sub: int, node: int, time_s: float) -> None:
        self.sub = sub
        self.node = node
        self.time_s = time_s
        self.last = 0.0  # time.monotonic() of the last heartbeat [s]
        self.active = False  # a heartbeat was received since the entry was set
        self.timed_out = False
        self.received = 0
        self.cb: Callable | None = None


class _RxPdo:
    __slots__ = ("cob_id", "sync", "struct", "names", "latched", "number", "handler")

    def __init__(self, number: int, cob_id: int, sync: bool, st: struct.Struct, names: tuple):
        self.number = number
        self.cob_id = cob_id
        self.sync = sync
        self.struct = st
        self.names = names
        self.latched: bytes | None = None
        self.handler: Callable | None = None


class _TxPdo:
    __slots__ = ("cob_id", "every", "count", "struct", "getter", "single", "last", "number")

    def __init__(
        self, number: int, cob_id: int, every: int, st: struct.Struct, names: tuple[str, ...]
    ):
        self.number = number
        self.cob_id = cob_id
        self.every = every  # 0: event driven
        self.count = 0
        self.struct = st
        self.getter = operator.attrgetter(*names) if names else (lambda obj: ())
        self.single = len(names) == 1
        self.last: bytes | None = None

    def payload(self, drive: SimulatedDrive) -> bytes:
        values = self.getter(drive)
        try:
            return self.struct.pack(values) if self.single else self.struct.pack(*values)
        except struct.error:  # a value outside its mapped type: saturate, like a drive
            values = (values,) if self.single else values
            return self.struct.pack(*_saturate(self.struct.format, values))


_INT_RANGES = {
    "b": (-0x80, 0x7F), "B": (0, 0xFF), "h": (-0x8000, 0x7FFF), "H": (0, 0xFFFF),
    "i": (-0x80000000, 0x7FFFFFFF), "I": (0, 0xFFFFFFFF),
    "q": (-(1 << 63), (1 << 63) - 1), "Q": (0, (1 << 64) - 1),
}


def _saturate(fmt: str, values: tuple) -> list:
    """Clip integer values to the ranges of their struct codes (padding codes skipped)."""
    codes = [c for c in fmt.lstrip("<") if not c.isdigit() and c != "x"]
    out = []
    for code, v in zip(codes, values, strict=True):
        rng = _INT_RANGES.get(code)
        out.append(_clip(int(v), *rng) if rng else v)
    return out


class SimulatedDrive:
    """One CiA 402 joint drive on a CAN bus, simulating its joint with a plant.

    Parameters
    ----------
    network_or_bus : canopen.Network or can.BusABC
        A bus (the drive builds its own ``canopen.Network`` and notifier on it and stops the
        notifier in :meth:`stop`, leaving the bus open) or a connected network of its own.
        On a virtual bus the master must use another bus object on the same channel.
    node_id : int
        CANopen node ID, 1-127.
    plant : sim_drivers.plant.JointPlant
        The joint (``step(tau)``, ``encoder_counts``, ``dq``, ``tau_applied``,
        ``torque_from_permille``, ``permille_from_torque``, ``counts_to_rad``,
        ``rad_to_counts``, ``set_payload``).
    eds : str or Path or DriveOD or None
        EDS/DCF (``None``: the generic ``jointid_cia402.eds``).
    fault_injector : FaultInjector or None
        Scripted faults for tests.
    cycle_s : float
        SYNC period the plant is stepped with [s] (the plant's own ``cycle_s`` decides its
        integration; this is used for the CSP loop tuning and records).
    csp_gains : (float, float) or None
        CSP position-loop gains ``(kp [N m/rad], kd [N m s/rad])``; default: critically damped
        at 15 Hz for the plant's rigid-body inertia when the plant exposes it, else for 1 kg m².
    record_chunk : int
        Rows the per-cycle record grows by (preallocated numpy arrays).
    sync_loss_floor_s : float
        Shortest SYNC-loss timeout [s] (module docstring, "Losing the master").

    Attributes
    ----------
    heartbeat_timeouts, sync_losses : int
        Heartbeat-consumer timeouts and SYNC losses detected so far.
    fault_time : float
        ``time.monotonic()`` when the drive last entered FAULT [s] (0: never).
    """

    def __init__(
        self,
        network_or_bus: canopen.Network | can.BusABC,
        node_id: int,
        plant: Any,
        eds: str | Path | DriveOD | None = None,
        *,
        fault_injector: FaultInjector | None = None,
        cycle_s: float = 0.001,
        csp_gains: tuple[float, float] | None = None,
        record_chunk: int = _RECORD_CHUNK,
        sync_loss_floor_s: float = SYNC_LOSS_FLOOR_S,
    ) -> None:
        self.dod = eds if isinstance(eds, DriveOD) else load_drive_od(eds, node_id)
        self.plant = plant
        self.injector = fault_injector
        self.cycle_s = float(cycle_s)
        if isinstance(network_or_bus, canopen.Network):
            self.network = network_or_bus
            self._own_notifier = False
        elif isinstance(network_or_bus, can.BusABC):
            self.network = canopen.Network(network_or_bus)
            self._own_notifier = True
        else:
            raise DriveError(
                f"SimulatedDrive: expected a canopen.Network or can.BusABC, "
                f"got {type(network_or_bus).__name__}"
            )
        self.node = canopen.LocalNode(node_id, self.dod.od)
        self.node_id = node_id
        self._supported = frozenset(int(m) for m in self.dod.supported)

        # plant-derived scales
        self._counts_per_rad = float(plant.rad_to_counts(1000.0)) / 1000.0
        self.rated_torque_mNm = int(round(self._rated_torque_nm() * 1000.0))
        self._current_scale = self._current_per_torque()
        if csp_gains is None:
            inertia = self._plant_inertia()
            w = 2.0 * math.pi * 15.0
            csp_gains = (inertia * w * w, 2.0 * inertia * w)
        self.kp, self.kd = float(csp_gains[0]), float(csp_gains[1])

        # live values
        self.cycle = 0
        self.nmt = NMT_INITIALISING
        self.cia_state = State.NOT_READY_TO_SWITCH_ON
        self.error_code = 0
        self.error_register = 0
        self.controlword = 0
        self._prev_cw = 0
        self.statusword = 0
        self.mode_request = 0
        self.mode_display = 0
        self.position_actual = 0
        self.velocity_actual = 0
        self.target_torque = 0
        self.target_position = 0
        self.velocity_offset = 0
        self.torque_offset = 0
        self.target_velocity = 0
        self.torque_demand = 0
        self.torque_actual = 0
        self.current_actual = 0
        self.tau_cmd = 0.0
        self._v_int = 0.0  # CSV integral term [N m]
        self._internal_limit = False
        self._following_error = False
        self._heartbeat_stopped = False
        self._layout_dirty = False
        self._sync_cob = 0x80
        self._rx: list[_RxPdo] = []
        self._rx_sync: list[_RxPdo] = []
        self._tx_sync: list[_TxPdo] = []
        self._tx_event: list[_TxPdo] = []
        self._extra_names: dict[tuple[int, int], str] = {}
        self._live = {k: v for k, v in _LIVE.items() if self._has(*k)}
        self.rx_length_errors = 0
        self.rx_rejected_modes = 0
        self.tpdo_sent = 0
        self._n = 0
        self._chunk = int(record_chunk)
        self._rec = {name: np.zeros(self._chunk, dtype=dtyp) for name, dtyp in _RECORD_FIELDS}
        self._started = False
        # master-loss watchdogs (heartbeat consumer 0x1016, SYNC loss per 0x1006)
        self._lock = threading.RLock()
        self._consumers: dict[int, _HbConsumer] = {}
        self.sync_loss_floor_s = float(sync_loss_floor_s)
        self._sync_timeout_s = 0.0
        self._last_sync = 0.0  # time.monotonic() of the last SYNC received [s]
        self._enabled_at = 0.0  # time.monotonic() when OPERATION ENABLED was entered [s]
        self._was_enabled = False
        self._wd_wake = threading.Event()
        self._wd_thread: threading.Thread | None = None
        self._wd_run = False
        self.heartbeat_timeouts = 0
        self.sync_losses = 0
        self.fault_time = 0.0  # time.monotonic() of the last fault [s] (tests)
        self._load_application()
        self._update_actuals()

        self.node.add_read_callback(self._on_sdo_read)
        self.node.add_write_callback(self._on_sdo_write)

    # ------------------------------------------------------------------ plant glue
    def _params_attr(self, *names: str) -> Any:
        params = getattr(self.plant, "params", None)
        for name in names:
            obj = params
            for part in name.split("."):
                obj = getattr(obj, part, None)
                if obj is None:
                    break
            if obj is not None:
                return obj
        return None

    def _rated_torque_nm(self) -> float:
        v = self._params_attr("drive.rated_torque_Nm", "rated_torque_Nm")
        if v is not None:
            return float(v)
        # torque_from_permille(1000) is the joint-side rated torque N * rated_torque
        gear = self._params_attr("drive.gear_ratio", "gear_ratio") or 1.0
        return float(self.plant.torque_from_permille(1000)) / float(gear)

    def _current_per_torque(self) -> float:
        """Per-mille of rated current per per-mille of rated torque (motor side)."""
        kt = self._params_attr("drive.torque_constant_Nm_per_A", "torque_constant_Nm_per_A")
        i_rated = self._params_attr("drive.rated_current_A", "rated_current_A")
        if kt and i_rated:
            return self._rated_torque_nm() / (float(kt) * float(i_rated))
        return 1.0

    def _plant_inertia(self) -> float:
        v = self._params_attr("J", "dynamics.J", "rigid.J", "body.J")
        try:
            return float(v) if v else 1.0
        except (TypeError, ValueError):
            return 1.0

    # ------------------------------------------------------------------ OD helpers
    def _has(self, index: int, subindex: int) -> bool:
        od = self.dod.od
        if index not in od:
            return False
        obj = od[index]
        if isinstance(obj, canopen.objectdictionary.ODVariable):
            return subindex == 0
        return subindex in obj

    def _var(self, index: int, subindex: int) -> canopen.objectdictionary.ODVariable:
        return self.node._find_object(index, subindex)

    def _stored(self, index: int, subindex: int) -> Any:
        """Value of a non-live object: stored by SDO, else DCF value, else EDS default."""
        var = self._var(index, subindex)
        try:
            return var.decode_raw(self.node.data_store[index][subindex])
        except KeyError:
            return var.value if var.value is not None else var.default

    def _load_application(self) -> None:
        """(Re)load the parameters and targets the drive keeps as attributes from the OD."""
        for attr, fallback in _PARAM_ATTRS.items():
            key = next((k for k, v in _LIVE.items() if v == attr), None)
            value = self._stored(*key) if key and self._has(*key) else None
            setattr(self, attr, fallback if value is None else int(value))
        for attr in _RX_ATTRS:
            key = next(k for k, v in _LIVE.items() if v == attr)
            value = self._stored(*key) if self._has(*key) else None
            setattr(self, attr, 0 if value is None else int(value))
        self._prev_target = self.target_position
        mode = self.mode_request
        self.mode_display = mode if mode in self._supported else 0
        self.mode_request = self.mode_display
        self._prev_cw = self.controlword
        self._last_eval: tuple | None = None

    # ------------------------------------------------------------------ life cycle
    @property
    def state(self) -> State:
        """CiA 402 state of the drive."""
        return self.cia_state

    @property
    def nmt_state(self) -> str:
        """NMT state name (``"PRE-OPERATIONAL"``, ``"OPERATIONAL"``, ``"STOPPED"``, ...)."""
        return NMT_STATE_NAMES[self.nmt]

    def start(self) -> None:
        """Attach to the bus, send boot-up, enter PRE-OPERATIONAL and start the heartbeat."""
        if self._started:
            raise DriveError(f"SimulatedDrive node {self.node_id}: already started")
        net = self.network
        net.add_node(self.node)
        # replace LocalNode's NMT and SDO subscriptions by gated ones
        net.unsubscribe(0, self.node.nmt.on_command)
        net.subscribe(0, self._on_nmt)
        net.unsubscribe(self.node.sdo.rx_cobid, self.node.sdo.on_request)
        net.subscribe(self.node.sdo.rx_cobid, self._on_sdo_request)
        if self._own_notifier:
            net.NOTIFIER_CYCLE = 0.05  # notifier poll period [s]: quick stop()
            net.connect()
        self._started = True
        self._reset_state_machine()
        self._boot()
        self._wd_run = True
        self._wd_thread = threading.Thread(target=self._watchdog_loop, daemon=True,
                                           name=f"sim-drive-{self.node_id}-watchdog")
        self._wd_thread.start()

    def stop(self) -> None:
        """Stop heartbeat and PDO traffic and detach from the bus (the bus stays open)."""
        if not self._started:
            return
        self._started = False
        self._wd_run = False
        self._wd_wake.set()
        if self._wd_thread is not None:
            self._wd_thread.join(2.0)
            self._wd_thread = None
        self.node.nmt.stop_heartbeat()
        self._unsubscribe_pdos()
        self._set_consumers({})
        net = self.network
        self._safe_unsubscribe(self._sync_cob, self._on_sync)
        self._safe_unsubscribe(0, self._on_nmt)
        self._safe_unsubscribe(self.node.sdo.rx_cobid, self._on_sdo_request)
        if self._own_notifier and net.notifier is not None:
            net.notifier.stop(1.0)
            net.notifier = None
        # give LocalNode its own subscriptions back so that it can detach itself
        net.subscribe(0, self.node.nmt.on_command)
        net.subscribe(self.node.sdo.rx_cobid, self.node.sdo.on_request)
        self.node.remove_network()
        net.nodes.pop(self.node_id, None)

    def __enter__(self) -> SimulatedDrive:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _safe_unsubscribe(self, cob: int, cb: Callable) -> None:
        try:
            self.network.unsubscribe(cob, cb)
        except (KeyError, ValueError):
            pass

    def _boot(self) -> None:
        """Initialisation -> boot-up frame -> PRE-OPERATIONAL, heartbeat per 0x1017."""
        self._set_nmt(NMT_INITIALISING)
        self._resubscribe_sync()
        self.network.send_message(0x700 + self.node_id, b"\x00")
        self._set_nmt(NMT_PRE_OPERATIONAL)
        self._load_watchdogs()
        hb = int(self._stored(0x1017, 0) or 0) if self._has(0x1017, 0) else 0
        self._heartbeat_stopped = False
        self.node.nmt.start_heartbeat(hb)

    def _reset_state_machine(self) -> None:
        """Power-on of the CiA 402 side: transitions 0 and 1 to SWITCH ON DISABLED."""
        self._last_eval = None
        self.cia_state = State.NOT_READY_TO_SWITCH_ON
        self.cia_state, _ = automatic_transition(self.cia_state, "self_test_done")
        self._update_statusword()

    def _set_nmt(self, state: int) -> None:
        was = self.nmt
        self.nmt = state
        if state != was:
            self._wd_wake.set()  # the SYNC watchdog is armed in OPERATIONAL only
        self.node.nmt._state = state
        if state == NMT_OPERATIONAL and was != NMT_OPERATIONAL:
            self._build_layouts()
        elif state != NMT_OPERATIONAL and was == NMT_OPERATIONAL:
            self._unsubscribe_pdos()
        if not self._heartbeat_stopped:
            self.node.nmt.update_heartbeat()

    def _reset(self, application: bool) -> None:
        self.node.nmt.stop_heartbeat()
        self._unsubscribe_pdos()
        store = self.node.data_store
        for index in list(store):
            if application or 0x1000 <= index <= 0x1FFF:
                del store[index]
        if application:
            for name in self._extra_names.values():
                self.__dict__.pop(name, None)
            self._extra_names.clear()
            self.error_code = 0
            self.error_register = 0
            self._internal_limit = self._following_error = False
            self._load_application()
            self._reset_state_machine()
        self._boot()

    # ------------------------------------------------------------------ NMT / SDO handlers
    def _on_nmt(self, can_id: int, data: bytes, timestamp: float) -> None:
        if len(data) < 2 or data[1] not in (0, self.node_id):
            return
        with self._lock:
            self._nmt_command(data[0])

    def _nmt_command(self, cmd: int) -> None:
        if cmd == 0x01 and self.nmt in (NMT_PRE_OPERATIONAL, NMT_STOPPED):
            self._set_nmt(NMT_OPERATIONAL)
        elif cmd == 0x02:
            self._set_nmt(NMT_STOPPED)
        elif cmd == 0x80:
            self._set_nmt(NMT_PRE_OPERATIONAL)
        elif cmd == 0x81:
            self._reset(application=True)
        elif cmd == 0x82:
            self._reset(application=False)

    def _on_sdo_request(self, can_id: int, data: bytes, timestamp: float) -> None:
        if self.nmt == NMT_STOPPED:
            return  # no SDO in STOPPED
        with self._lock:
            self.node.sdo.on_request(can_id, data, timestamp)

    def _on_sdo_read(self, index: int, subindex: int, od: Any) -> Any:
        name = self._live.get((index, subindex)) or self._extra_names.get((index, subindex))
        if name is None:
            return None
        return getattr(self, name)

    def _on_sdo_write(self, index: int, subindex: int, od: Any, data: bytes) -> None:
        if 0x1400 <= index <= 0x1BFF:
            self._check_pdo_write(index, subindex, od, data)
            self._layout_dirty = True
            return
        if index == 0x1005:
            self._layout_dirty = True
            return
        if index == 0x1016 and subindex > 0:
            self._write_consumer(subindex, od.decode_raw(data))
            return
        if index == 0x1006:
            self._set_sync_period(od.decode_raw(data))
            return
        key = (index, subindex)
        name = self._live.get(key)
        if name is None:
            name = self._extra_names.get(key)
            if name is not None:
                setattr(self, name, od.decode_raw(data))
            return
        value = od.decode_raw(data)
        if name == "controlword":
            self.controlword = value
            self._evaluate_controlword(from_sdo=True)
            self._send_event_tpdos()
        elif name == "mode_request":
            if value != 0 and value not in self._supported:
                raise SdoAbortedError(0x06090030)
            self.mode_request = value
            self.mode_display = value
            self._update_statusword()
            self._send_event_tpdos()
        elif name == "rated_torque_mNm":
            if value != self.rated_torque_mNm:
                raise SdoAbortedError(0x06090030)
        elif name in _RX_ATTRS or name in _PARAM_ATTRS:
            setattr(self, name, value)
        else:
            raise SdoAbortedError(0x06010002)  # computed by the drive: read only

    def _check_pdo_write(self, index: int, subindex: int, od: Any, data: bytes) -> None:
        """Validate a write to a PDO communication (14xx/18xx) or mapping (16xx/1Axx) object."""
        is_map = 0x1600 <= index <= 0x17FF or 0x1A00 <= index <= 0x1BFF
        comm = index - 0x200 if is_map else index
        cob = self._stored(comm, 1) if self._has(comm, 1) else _PDO_NOT_VALID
        enabled = not (int(cob) & _PDO_NOT_VALID)
        value = od.decode_raw(data)
        if not is_map:
            if subindex == 1 and enabled and not value & _PDO_NOT_VALID:
                if (value ^ int(cob)) & 0x1FFFFFFF:
                    raise SdoAbortedError(0x06090030)  # COB-ID change of a valid PDO
            if subindex == 2 and not (value <= 240 or value >= 252):
                raise SdoAbortedError(0x06090030)
            return
        if enabled:
            raise SdoAbortedError(0x08000022)  # mapping change while the PDO is valid
        receive = index < 0x1A00
        if subindex == 0:
            obj = self.dod.od[index]
            slots = max((s for s in getattr(obj, "subindices", ()) if s > 0), default=0)
            if isinstance(obj, canopen.objectdictionary.ODArray):
                slots = max(slots, int(obj[0].default or 0))
            if value > slots or value > 64:
                raise SdoAbortedError(0x06090031)
            bits = 0
            for s in range(1, value + 1):
                entry = int(self._stored(index, s) or 0)
                if entry >> 16:
                    self._check_entry(entry, receive)
                bits += entry & 0xFF
            if bits > 64:
                raise SdoAbortedError(0x06040042)
            return
        if int(self._stored(index, 0) or 0) != 0:
            raise SdoAbortedError(0x08000022)  # entries only while sub 0 is 0
        if value >> 16:
            self._check_entry(value, receive)

    def _check_entry(self, entry: int, receive: bool) -> None:
        index, subindex, bits = entry >> 16, (entry >> 8) & 0xFF, entry & 0xFF
        if 1 <= index <= 7:  # dummy entries: data type sizes
            if bits % 8:
                raise SdoAbortedError(0x06040041)
            return
        if not self._has(index, subindex):
            raise SdoAbortedError(0x06020000)
        var = self._var(index, subindex)
        if not var.pdo_mappable or var.data_type not in _STRUCT_TYPES:
            raise SdoAbortedError(0x06040041)
        if receive and not var.writable or not receive and not var.readable:
            raise SdoAbortedError(0x06040041)
        if bits != len(var):
            raise SdoAbortedError(0x06040041)
        if bits > 64:
            raise SdoAbortedError(0x06040042)

    # ------------------------------------------------------------------ PDO layouts
    def _resubscribe_sync(self) -> None:
        self._safe_unsubscribe(self._sync_cob, self._on_sync)
        cob = self._stored(0x1005, 0) if self._has(0x1005, 0) else 0x80
        self._sync_cob = int(cob if cob is not None else 0x80) & 0x7FF
        self.network.subscribe(self._sync_cob, self._on_sync)

    def _unsubscribe_pdos(self) -> None:
        for rx in self._rx:
            if rx.handler is not None:
                self._safe_unsubscribe(rx.cob_id, rx.handler)
        self._rx = []
        self._rx_sync = []
        self._tx_sync = []
        self._tx_event = []

    def _entries(self, map_index: int) -> tuple[struct.Struct, tuple]:
        count = int(self._stored(map_index, 0) or 0)
        codes: list[str] = []
        names: list[str] = []
        for s in range(1, count + 1):
            entry = int(self._stored(map_index, s) or 0)
            index, subindex, bits = entry >> 16, (entry >> 8) & 0xFF, entry & 0xFF
            if index == 0 or bits == 0:
                continue
            if 1 <= index <= 7:
                codes.append(f"{bits // 8}x")
                continue
            var = self._var(index, subindex)
            codes.append(struct_code(var))
            names.append(self._name_for(index, subindex))
        return struct.Struct("<" + "".join(codes)), tuple(names)

    def _name_for(self, index: int, subindex: int) -> str:
        name = self._live.get((index, subindex))
        if name is not None:
            return name
        name = self._extra_names.get((index, subindex))
        if name is None:
            name = f"_obj_{index:04X}_{subindex:02X}"
            self._extra_names[(index, subindex)] = name
            value = self._stored(index, subindex)
            setattr(self, name, 0 if value is None else value)
        return name

    def _build_layouts(self) -> None:
        """Read the PDO configuration from the dictionary into struct layouts and subscribe."""
        self._unsubscribe_pdos()
        self._layout_dirty = False
        self._resubscribe_sync()
        for n, cob, trans, (st, names) in self._valid_pdos(0x1400, 0x1600):
            rx = _RxPdo(n + 1, cob, trans <= 240, st, names)
            self._rx.append(rx)
            if rx.sync:
                self._rx_sync.append(rx)
            self.network.subscribe(rx.cob_id, self._make_rx_handler(rx))
        for n, cob, trans, (st, names) in self._valid_pdos(0x1800, 0x1A00):
            if trans <= 240:
                self._tx_sync.append(_TxPdo(n + 1, cob, max(trans, 1), st, names))
            elif trans >= 254:
                self._tx_event.append(_TxPdo(n + 1, cob, 0, st, names))
            # 252/253 (RTR only): not served, LocalNode drops remote frames

    def _valid_pdos(self, comm_base: int, map_base: int):
        """Yield ``(n, cob_id, transmission_type, layout)`` of each valid, non-empty PDO whose
        communication object is ``comm_base + n`` and mapping object ``map_base + n``."""
        od = self.dod.od
        for n in range(512):
            comm = comm_base + n
            if comm not in od:
                continue
            cob = int(self._stored(comm, 1) or _PDO_NOT_VALID)
            if cob & _PDO_NOT_VALID or map_base + n not in od:
                continue
            trans = int(self._stored(comm, 2) or 0) if self._has(comm, 2) else 255
            layout = self._layout_or_none(map_base + n)
            if layout is not None:
                yield n, cob & 0x7FF, trans, layout

    def _layout_or_none(self, map_index: int) -> tuple[struct.Struct, tuple] | None:
        """Layout of one mapping object; None for an empty mapping (sub 0 = 0: the PDO is not
        used) or, logged, when a file's own default mapping names an object the simulation
        cannot pack (missing, or no fixed-size type)."""
        try:
            st, names = self._entries(map_index)
        except (DriveConfigError, SdoAbortedError) as exc:
            logger.warning("node %d: PDO mapping 0x%04X not served: %s", self.node_id,
                           map_index, exc)
            return None
        return (st, names) if st.size else None

    def _make_rx_handler(self, rx: _RxPdo) -> Callable:
        if rx.sync:

            def handler(can_id: int, data: bytes, timestamp: float) -> None:
                rx.latched = data
        else:

            def handler(can_id: int, data: bytes, timestamp: float) -> None:
                if self.nmt == NMT_OPERATIONAL:
                    if self._apply_rpdo(rx, data):
                        self._after_rx()

        rx.handler = handler
        return handler

    def _apply_rpdo(self, rx: _RxPdo, data: bytes) -> bool:
        if len(data) < rx.struct.size:
            self.rx_length_errors += 1
            # CiA 301: "PDO not processed due to length error", a warning (no state change)
            self.node.emcy.send(PDO_LENGTH_ERROR, self.error_register | 0x11)
            return False
        self.__dict__.update(zip(rx.names, rx.struct.unpack_from(data), strict=False))
        return True

    def _after_rx(self) -> None:
        """Apply what RPDOs changed: mode request, controlword; then event TPDOs."""
        if self.mode_request != self.mode_display:
            self._apply_mode_request()
        self._evaluate_controlword()
        self._send_event_tpdos()

    def _apply_mode_request(self) -> None:
        """0x6060 arrived by RPDO: follow it if advertised, else keep the mode (no abort)."""
        if self.mode_request in self._supported or self.mode_request == 0:
            self.mode_display = self.mode_request
            self._update_statusword()
        else:
            self.rx_rejected_modes += 1
            self.mode_request = self.mode_display

    # ------------------------------------------------------------------ CiA 402
    def _evaluate_controlword(self, from_sdo: bool = False) -> None:
        """Run the state machine on 0x6040 (level-triggered, edge for the fault reset).

        The command is applied until it requests no further transition, so "enable
        operation" (0x0F) in READY TO SWITCH ON takes transitions 3 and 4 at once.
        ``next_state`` is pure: when the last evaluation with the same (state, controlword,
        previous controlword, quick stop option) changed nothing, this one returns at once.
        """
        cw = self.controlword
        key = (self.cia_state, cw, self._prev_cw, self.quick_stop_option)
        if key == self._last_eval:
            return
        for _ in range(4):
            new, number = next_state(
                self.cia_state, cw, self._prev_cw, quick_stop_option=self.quick_stop_option
            )
            self._prev_cw = cw
            if number is None:
                break
            self.cia_state = new
            if number == 15:
                self.error_code = 0
                self.error_register = 0
                self._following_error = False
                self.node.emcy.reset()
            elif number == 11:
                self._quick_stop_started()
            elif number in (4, 16) and from_sdo:
                # enabled over SDO: the position loop starts from where the joint is (an
                # RPDO enabling the drive carries its own 0x607A)
                self.target_position = self._prev_target = self.position_actual
        self._last_eval = (self.cia_state, cw, cw, self.quick_stop_option)
        self._update_statusword()

    def _quick_stop_started(self) -> None:
        if self.quick_stop_option == 0 or (
            1 <= self.quick_stop_option <= 4 and abs(self.plant.dq) < _QS_DONE_SPEED
        ):
            self.cia_state, _ = automatic_transition(self.cia_state, "quick_stop_done")

    def _update_statusword(self) -> None:
        st = self.cia_state
        enabled = st is State.OPERATION_ENABLED
        if enabled is not self._was_enabled:
            self._was_enabled = enabled
            if enabled:
                self._enabled_at = time.monotonic()
                if self._sync_timeout_s:
                    self._wd_wake.set()
        self.statusword = statusword(
            st,
            internal_limit=self._internal_limit,
            bit12=enabled and self.mode_display in _CYCLIC_INTS,
            bit13=self._following_error and self.mode_display == 8,
        )

    def fault(self, code: int) -> None:
        """Enter FAULT (transitions 13 and 14) with error ``code``: 0x603F, 0x1001, EMCY.

        The drive calls it from its bus thread; call it from elsewhere only while no SYNC
        cycle runs (tests, or through :class:`~sim_drivers.faults.FaultInjector`).
        """
        if self.cia_state in (State.FAULT, State.FAULT_REACTION_ACTIVE):
            return
        self.cia_state, _ = automatic_transition(self.cia_state, "fault")
        self.fault_time = time.monotonic()
        self.error_code = code
        self.error_register = error_register(code)
        self.node.emcy.send(code, self.error_register)
        self.cia_state, _ = automatic_transition(self.cia_state, "fault_reaction_done")
        self.tau_cmd = 0.0
        self._update_statusword()

    # ------------------------------------------------------------------ cycle
    def _on_sync(self, can_id: int, data: bytes, timestamp: float) -> None:
        self._last_sync = time.monotonic()
        if self.nmt != NMT_OPERATIONAL:
            return
        with self._lock:
            if self._layout_dirty:
                self._build_layouts()
            got = False
            for rx in self._rx_sync:
                latched = rx.latched
                if latched is not None:
                    rx.latched = None
                    got = self._apply_rpdo(rx, latched) or got
            if got:
                if self.mode_request != self.mode_display:
                    self._apply_mode_request()
                self._evaluate_controlword()
            self.step()

    # ------------------------------------------------------------------ master-loss watchdogs
    @property
    def last_sync_time(self) -> float:
        """``time.monotonic()`` when the last SYNC was received [s] (0: none yet)."""
        return self._last_sync

    @property
    def sync_timeout_s(self) -> float:
        """SYNC-loss timeout [s] from 0x1006 (0: the SYNC watchdog is off)."""
        return self._sync_timeout_s

    @property
    def heartbeat_consumers(self) -> dict[int, tuple[float, bool, int]]:
        """Watched nodes from 0x1016: node id -> (consumer time [s], monitoring started,
        heartbeats received)."""
        return {c.node: (c.time_s, c.active, c.received) for c in self._consumers.values()}

    def _set_sync_period(self, period_us: int) -> None:
        period = int(period_us) * 1e-6
        self._sync_timeout_s = (max(SYNC_LOSS_PERIODS * period, self.sync_loss_floor_s)
                                if period > 0 else 0.0)
        self._wd_wake.set()

    def _load_watchdogs(self) -> None:
        """(Re)read 0x1016 and 0x1006 from the dictionary (boot, reset communication)."""
        self._set_sync_period(int(self._stored(0x1006, 0) or 0) if self._has(0x1006, 0) else 0)
        entries: dict[int, _HbConsumer] = {}
        if 0x1016 in self.dod.od:
            for sub in range(1, 128):
                if not self._has(0x1016, sub):
                    continue
                value = int(self._stored(0x1016, sub) or 0)
                node, ms = (value >> 16) & 0xFF, value & 0xFFFF
                if node and ms:
                    entries[sub] = _HbConsumer(sub, node, ms / 1000.0)
        self._set_consumers(entries)

    def _write_consumer(self, sub: int, value: int) -> None:
        """SDO write to 0x1016.sub: validate (CiA 301), then watch the new entry."""
        node, ms = (value >> 16) & 0xFF, value & 0xFFFF
        if node and ms and any(c.node == node and c.sub != sub
                               for c in self._consumers.values()):
            raise SdoAbortedError(0x06040043)  # general parameter incompatibility
        entries = {s: c for s, c in self._consumers.items() if s != sub}
        if node and ms:
            entries[sub] = _HbConsumer(sub, node, ms / 1000.0)
        self._set_consumers(entries)

    def _set_consumers(self, entries: dict[int, _HbConsumer]) -> None:
        for c in self._consumers.values():
            if c.cb is not None:
                self._safe_unsubscribe(0x700 + c.node, c.cb)
        self._consumers = entries
        if self._started:
            for c in entries.values():
                c.cb = self._make_consumer_handler(c)
                self.network.subscribe(0x700 + c.node, c.cb)
        self._wd_wake.set()

    def _make_consumer_handler(self, c: _HbConsumer) -> Callable:
        wake = self._wd_wake

        def handler(can_id: int, data: bytes, timestamp: float) -> None:
            c.last = time.monotonic()
            c.received += 1
            if not c.active or c.timed_out:
                c.active = True
                c.timed_out = False
                wake.set()

        return handler

    def _watchdog_loop(self) -> None:
        """Sleep until the earliest deadline, check, repeat (the drive's timer thread)."""
        wake = self._wd_wake
        while self._wd_run:
            try:
                wait = self._check_watchdogs()
            except Exception:  # never let the safety thread die silently
                logger.exception("node %d: watchdog check failed", self.node_id)
                wait = _WD_IDLE_S
            wake.wait(wait)
            wake.clear()

    def _check_watchdogs(self) -> float:
        """Fire what timed out; return the time to the next deadline [s]."""
        wait = _WD_IDLE_S
        with self._lock:
            now = time.monotonic()
            for c in list(self._consumers.values()):
                if not c.active or c.timed_out:
                    continue
                left = c.last + c.time_s - now
                if left <= 0.0:
                    c.timed_out = True
                    self.heartbeat_timeouts += 1
                    logger.warning("node %d: heartbeat of node %d lost (none for %.3f s, "
                                   "consumer time %g s, %d received)", self.node_id, c.node,
                                   now - c.last, c.time_s, c.received)
                    if self.cia_state in (State.OPERATION_ENABLED, State.QUICK_STOP_ACTIVE):
                        self.fault(HEARTBEAT_LOST)
                    else:
                        self.node.emcy.send(HEARTBEAT_LOST,
                                            self.error_register | error_register(HEARTBEAT_LOST))
                elif left < wait:
                    wait = left
            timeout = self._sync_timeout_s
            if (timeout and self.nmt == NMT_OPERATIONAL
                    and self.cia_state is State.OPERATION_ENABLED
                    and self.mode_display in _CYCLIC_INTS):
                left = max(self._last_sync, self._enabled_at) + timeout - now
                if left <= 0.0:
                    self.sync_losses += 1
                    logger.warning("node %d: no SYNC for %.3f s (timeout %g s)", self.node_id,
                                   now - self._last_sync, timeout)
                    self.fault(SYNC_LOST)
                elif left < wait:
                    wait = left
            elif timeout and timeout < wait:
                wait = timeout  # configured, not armed: look again within one timeout
        return wait

    def step(self) -> None:
        """One drive cycle: injector, control law, plant step, checks, record, TPDOs.

        Called on every SYNC in OPERATIONAL; exposed for benchmarks and offline use.
        """
        cycle = self.cycle
        inj = self.injector
        if inj is not None:
            if inj.fault_now(cycle):
                self.fault(inj.fault_code)
            if inj.stop_heartbeat_now(cycle):
                self._heartbeat_stopped = True
                self.node.nmt.stop_heartbeat()
        plant = self.plant
        st = self.cia_state
        powered = st is State.OPERATION_ENABLED or st is State.QUICK_STOP_ACTIVE
        tau = 0.0
        demand = 0
        if st is State.OPERATION_ENABLED:
            mode = self.mode_display
            if mode == 10:
                demand = self.target_torque + self.torque_offset
                if demand > self.max_torque or -demand > self.max_torque:
                    self.fault(EXCESS_TORQUE)
                    powered = False
                    demand = 0
                else:
                    tau = plant.torque_from_permille(demand)
            elif mode == 8:
                err = self.target_position - self.position_actual
                window = self.following_window
                if 0 < window < 0xFFFFFFFF and (err > window or -err > window):
                    self._following_error = True
                    self.fault(FOLLOWING_ERROR)
                    powered = False
                else:
                    v_target = (self.target_position - self._prev_target) / self.cycle_s
                    tau = (
                        self.kp * err / self._counts_per_rad
                        + self.kd * (v_target / self._counts_per_rad - plant.dq)
                        + plant.torque_from_permille(self.torque_offset)
                    )
                    demand = plant.permille_from_torque(tau)
                    limit = self.max_torque
                    limited = demand > limit or -demand > limit
                    if limited:
                        demand = limit if demand > 0 else -limit
                        tau = plant.torque_from_permille(demand)
                    if limited != self._internal_limit:
                        self._internal_limit = limited
                        self._update_statusword()
            elif mode == 9:
                v_err = (
                    self.target_velocity + self.velocity_offset
                ) / self._counts_per_rad - plant.dq
                self._v_int += self.kd * _CSV_INTEGRAL_RATE * v_err * self.cycle_s
                tau = (
                    self.kd * v_err + self._v_int + plant.torque_from_permille(self.torque_offset)
                )
                demand = plant.permille_from_torque(tau)
                limit = self.max_torque
                limited = demand > limit or -demand > limit
                if limited:
                    demand = limit if demand > 0 else -limit
                    tau = plant.torque_from_permille(demand)
                    self._v_int -= self.kd * _CSV_INTEGRAL_RATE * v_err * self.cycle_s
                if limited != self._internal_limit:
                    self._internal_limit = limited
                    self._update_statusword()
        elif st is State.QUICK_STOP_ACTIVE:
            tau = -self.kd * plant.dq
            demand = plant.permille_from_torque(tau)
            if 1 <= self.quick_stop_option <= 4 and abs(plant.dq) < _QS_DONE_SPEED:
                self.cia_state, _ = automatic_transition(st, "quick_stop_done")
                self._update_statusword()
        if st is not State.OPERATION_ENABLED or self.mode_display != 9:
            self._v_int = 0.0
        self.tau_cmd = tau
        self.torque_demand = demand
        if powered:
            try:
                plant.step(tau)
                if not math.isfinite(plant.q):
                    raise SimError("plant state is not finite")
            except Exception:  # any plant failure is a drive fault, not a dead bus thread
                logger.exception("plant step failed at cycle %d", cycle)
                self.fault(PLANT_FAULT)
        self._prev_target = self.target_position
        self._update_actuals()
        lo, hi = self.position_limit_min, self.position_limit_max
        if lo < hi and not lo <= self.position_actual <= hi:
            self.fault(POSITION_LIMIT)
        self._record(cycle)
        if inj is not None and inj.drop_tpdo(cycle):
            for tx in self._tx_sync:
                tx.count += 1
                if tx.count >= tx.every:
                    tx.count = 0
        else:
            send = self.network.send_message
            for tx in self._tx_sync:
                tx.count += 1
                if tx.count >= tx.every:
                    tx.count = 0
                    send(tx.cob_id, tx.payload(self))
                    self.tpdo_sent += 1
            if self._tx_event:
                self._send_event_tpdos()
        self.cycle = cycle + 1

    def _update_actuals(self) -> None:
        plant = self.plant
        self.position_actual = _wrap_i32(int(plant.encoder_counts))
        v = round(plant.dq * self._counts_per_rad)
        self.velocity_actual = _clip(v, -0x80000000, 0x7FFFFFFF)
        ta = int(plant.permille_from_torque(plant.tau_applied))
        self.torque_actual = ta
        self.current_actual = _clip(round(ta * self._current_scale), -0x8000, 0x7FFF)

    def _send_event_tpdos(self) -> None:
        if self.nmt != NMT_OPERATIONAL:
            return
        send = self.network.send_message
        for tx in self._tx_event:
            payload = tx.payload(self)
            if payload != tx.last:
                tx.last = payload
                send(tx.cob_id, payload)
                self.tpdo_sent += 1

    def _record(self, cycle: int) -> None:
        n = self._n
        rec = self._rec
        if n >= rec["cycle"].shape[0]:
            for name in rec:
                rec[name] = np.concatenate([rec[name], np.zeros(self._chunk, rec[name].dtype)])
        rec["cycle"][n] = cycle
        rec["counts"][n] = self.position_actual
        rec["target_torque"][n] = self.target_torque
        rec["target_position"][n] = self.target_position
        rec["torque_demand"][n] = self.torque_demand
        rec["tau_cmd"][n] = self.tau_cmd
        rec["tau_applied"][n] = self.plant.tau_applied
        rec["q"][n] = self.plant.q
        rec["statusword"][n] = self.statusword
        rec["mode"][n] = self.mode_display
        self._n = n + 1

    @property
    def record(self) -> dict[str, np.ndarray]:
        """Per-cycle record (copies), one entry per SYNC processed in OPERATIONAL.

        Keys: ``cycle``, ``counts`` (0x6064 sent), ``target_torque`` (0x6071 received,
        per-mille), ``target_position`` (0x607A received, counts), ``torque_demand``
        (per-mille), ``tau_cmd`` and ``tau_applied`` [N m], ``q`` [rad] (true),
        ``statusword`` (sent), ``mode`` (0x6061).
        """
        n = self._n
        return {name: arr[:n].copy() for name, arr in self._rec.items()}

    def set_payload(self, mass_kg: float, arm_m: float) -> None:
        """Mount a payload of ``mass_kg`` [kg] at ``arm_m`` [m] on the joint (the operator)."""
        self.plant.set_payload(mass_kg, arm_m)

    @property
    def supported_modes(self) -> frozenset[Mode]:
        """Modes advertised by 0x6502."""
        return self.dod.supported


_CYCLIC_INTS = frozenset(int(m) for m in CYCLIC_MODES)
_STRUCT_TYPES = frozenset(STRUCT_CODE)
