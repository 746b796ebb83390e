"""Simulated CiA 402 joint drive: a canopen ``LocalNode`` on a python-can bus around a plant.

(Just past 600 lines: the composition of :mod:`~sim_drivers.nmt`, :mod:`~sim_drivers.pdo` and
:mod:`~sim_drivers.device402` with the object-dictionary callbacks that tie them together.)

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
- RPDO deadline monitoring (CiA 301 event timer of a receive PDO, 0x1400+n sub 5 [ms], when
  the EDS has it): in NMT OPERATIONAL, OPERATION ENABLED, in a cyclic mode, an RPDO with a
  non-zero timer that was received at least once faults with 0x8250 ("RPDO timeout") when
  no frame of it arrived for the timer, counted from its last reception or from enabling,
  whichever is later. It catches a hung master whose SYNC (and heartbeat) keep coming from
  elsewhere (``send_periodic`` in the kernel or a bridge); the SYNC watchdog does not. The
  timer is taken as written, with no floor: the master adds its own margin
  (:func:`daq.runtime.master.rpdo_timeout_ms`: 3 cycles + 100 ms in paced mode, 0 in
  lockstep). 0 (the EDS default) is off. Read when the PDO layouts are built (NMT start, or
  the SYNC after a write to 0x14xx).
- All three run in one daemon thread per drive that sleeps until the earliest deadline
  (about one wake-up per timeout, none while nothing is armed); on the hot path a SYNC
  costs one ``time.monotonic()`` and an uncontended lock, an RPDO one ``time.monotonic()``.

Clock
-----
``clock="wall"`` (the default, a drive in its own right: paced runs, ``sim_drivers.serve``,
the cross-process tests) judges the three watchdogs above on ``time.monotonic()`` in the
watchdog thread. ``clock="sync"`` (the lockstep rigs: ``daq.runtime.simrig``,
:class:`~sim_drivers.arm_bus.ArmOnBus` with inline dispatch) runs them on simulated time
instead: the drive's time is the number of SYNCs it received times ``cycle_s``, nothing else
makes it pass, and they are checked when a SYNC arrives (no watchdog thread). So a host
stall between two lockstep cycles is no lost heartbeat, and a heartbeat loss is detected at
a reproducible cycle: a consumer times out at the first SYNC more than its consumer time
after the last heartbeat, in simulated time. The SYNC watchdog cannot fire on that clock
(time only passes with SYNCs). The heartbeats must then be sent on the same clock: on a
clocked :class:`~sim_drivers.simbus.SimNetwork` (``sync_cycle_s``) every periodic send of the
channel -- this drive's heartbeat producer and the master's heartbeat -- is paced by SYNC
(:mod:`sim_drivers.simbus`, "Simulated time").

Code layout: this module holds :class:`SimulatedDrive` (construction, object dictionary,
life cycle, SDO server, SYNC entry, record); the protocol parts are mixins in
:mod:`sim_drivers.nmt` (NMT slave, heartbeat consumer, SYNC watchdog, RPDO deadlines),
:mod:`sim_drivers.pdo` (mapping checks, layouts, RPDO/TPDO) and
:mod:`sim_drivers.device402` (CiA 402 state machine, faults, the drive cycle); fault codes
and the fault injector are :mod:`sim_drivers.faults`.

Threading: every bus callback (SDO, NMT, RPDO, SYNC) runs in the drive network's notifier
thread, so they are serialised, and serialised with the watchdog thread by a lock; the
heartbeat producer is python-can's periodic-send task.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import can
import canopen
import numpy as np
from canopen.sdo.exceptions import SdoAbortedError

from daq.protocol.cia402 import Mode, State
from sim_drivers import SimError
from sim_drivers.device402 import Device402Mixin
from sim_drivers.faults import FaultInjector
from sim_drivers.nmt import (
    CLOCKS,
    NMT_INITIALISING,
    NMT_OPERATIONAL,
    NMT_STATE_NAMES,
    NMT_STOPPED,
    SYNC_LOSS_FLOOR_S,
    SYNC_LOSS_PERIODS,
    HbConsumer,
    NmtMixin,
)
from sim_drivers.od import DriveOD, load_drive_od
from sim_drivers.pdo import PdoMixin, RxPdo, TxPdo

logger = logging.getLogger(__name__)

__all__ = ["CLOCKS", "DriveError", "SimulatedDrive", "open_virtual_bus", "NMT_STATE_NAMES",
           "SYNC_LOSS_FLOOR_S", "SYNC_LOSS_PERIODS", "TORQUE_DELAY_CYCLES"]

#: The timing of a log of this drive around a single-joint plant [cycles]: on SYNC k it applies
#: the latched torque, steps the plant over the coming cycle at once and its TPDO reports the
#: position at the end of that cycle; the torque a master computes from that position acts
#: over the next cycle, whose middle is half a cycle after it (``daq.runtime.runner`` writes
#: it in the log, ``ident`` aligns q with it).
TORQUE_DELAY_CYCLES = 0.5

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

_RECORD_CHUNK = 65536

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


class SimulatedDrive(NmtMixin, PdoMixin, Device402Mixin):
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
    clock : {"wall", "sync"}
        What the watchdogs run on (module docstring, "Clock"): ``time.monotonic()`` in a
        watchdog thread, or simulated time (SYNCs received x ``cycle_s``) checked on SYNC.

    Attributes
    ----------
    heartbeat_timeouts, sync_losses, rpdo_timeouts : int
        Heartbeat-consumer timeouts, SYNC losses and RPDO timeouts detected so far.
    fault_time : float
        ``time.monotonic()`` when the drive last entered FAULT [s] (0: never).
    syncs : int
        SYNC frames received since :meth:`start` (the ``"sync"`` clock's time in cycles).
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
        clock: str = "wall",
    ) -> None:
        if clock not in CLOCKS:
            raise DriveError(f"SimulatedDrive: clock: expected one of {CLOCKS}, got {clock!r}")
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
        self._rx: list[RxPdo] = []
        self._rx_sync: list[RxPdo] = []
        self._rx_timed: list[RxPdo] = []  # RPDOs with a non-zero event timer (0x1400+n.5)
        self._tx_sync: list[TxPdo] = []
        self._tx_event: list[TxPdo] = []
        self._extra_names: dict[tuple[int, int], str] = {}
        self._live = {k: v for k, v in _LIVE.items() if self._has(*k)}
        self.rx_length_errors = 0
        self.rx_rejected_modes = 0
        self.tpdo_sent = 0
        self._n = 0
        self._chunk = int(record_chunk)
        self._rec = {name: np.zeros(self._chunk, dtype=dtyp) for name, dtyp in _RECORD_FIELDS}
        self._started = False
        self._send = self.network.send_message  # frames of the cycle (see start)
        # master-loss watchdogs (heartbeat consumer 0x1016, SYNC loss per 0x1006)
        self._lock = threading.RLock()
        self.clock = clock
        self.syncs = 0
        # the watchdogs' time [s]: wall, or simulated (SYNCs received x cycle)
        self._now: Callable[[], float] = (time.monotonic if clock == "wall"
                                          else self._sync_time)
        self._wd_due = 0.0  # "sync" clock: simulated time of the next watchdog check [s]
        self._consumers: dict[int, HbConsumer] = {}
        self.sync_loss_floor_s = float(sync_loss_floor_s)
        self._sync_timeout_s = 0.0
        self._last_sync = 0.0  # clock time of the last SYNC received [s]
        self._enabled_at = 0.0  # clock time when OPERATION ENABLED was entered [s]
        self._was_enabled = False
        self._wd_wake = threading.Event()
        self._wd_thread: threading.Thread | None = None
        self._wd_run = False
        self.heartbeat_timeouts = 0
        self.sync_losses = 0
        self.rpdo_timeouts = 0
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
        # the cycle's frames: the bus's own fast path when it has one (SimBus)
        self._send = getattr(net.bus, "send_frame", None) or net.send_message
        self._reset_state_machine()
        self._boot()
        if self.clock == "wall":  # (the "sync" clock checks them on SYNC)
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

    # ------------------------------------------------------------------ SDO handlers
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

    # ------------------------------------------------------------------ cycle
    def _sync_time(self) -> float:
        """The ``"sync"`` clock: SYNCs received x ``cycle_s`` [s]."""
        return self.syncs * self.cycle_s

    def _on_sync(self, can_id: int, data: bytes, timestamp: float) -> None:
        self.syncs += 1
        if self.clock == "wall":
            self._last_sync = time.monotonic()
        else:  # simulated time passed: the watchdogs' turn when due or re-armed
            self._last_sync = now = self._sync_time()
            if now >= self._wd_due or self._wd_wake.is_set():
                self._wd_wake.clear()
                self._wd_due = now + self._check_watchdogs()
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

    # ------------------------------------------------------------------ record

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
