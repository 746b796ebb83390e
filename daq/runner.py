"""Campaign runner: the engine that executes a planned campaign on CANopen drives.

The campaign and its plan say *what* to do (:mod:`trajectories`); this engine executes it:
start-up (presence, mode, PDO layout read back, bus load), then per payload run one MCAP
file, cycle by cycle:

1. SYNC (the drives latch the RPDOs of the previous cycle, step, and answer with TPDOs);
2. wait for every drive's TPDO1/TPDO2 (``lockstep``: as long as needed, deterministic;
   ``paced``: until 80 % of the period has elapsed);
3. per drive: decode (struct), the position controller :class:`daq.control.PositionController`
   (CST) or the position target (CSP), limits and watchdog, RPDO out;
4. log the joint states, the setpoint and every CAN frame of the cycle.

Several drives (``[[daq.drives]]``) all follow the campaign's one plan, each with its own
controller; drive k logs on ``/joint/<k>/state``. With ``--simulate`` each gets its own plant.

Clocks
------
``lockstep``
    The next cycle starts as soon as the drives answered: with simulated drives on the
    virtual bus this runs as fast as the machine allows, and the result does not depend on
    the machine's speed.
``paced``
    SYNC every ``cycle_s`` from the runner's own loop (sleep to 200 µs before the deadline,
    then spin), the lateness of every SYNC is logged on ``/timing``; a SYNC more than half a
    period late counts as a missed cycle, and after a whole period of delay the schedule is
    re-anchored instead of sending a catch-up burst.

Safety (every cycle)
--------------------
Position, velocity, torque limits (``[daq.limits]``, else the campaign's joint limits with
5 % of the range / 20 % of the speed and torque as margins; the command itself is saturated
at the torque limit), following error, TPDO missing for ``tpdo_timeout_cycles`` consecutive
cycles, heartbeat silent for ``heartbeat_timeout_s``, EMCY, a drive leaving OPERATION ENABLED,
SIGINT. On any of them the runner sends quick stop (controlword 0x0002) for
``quick_stop_cycles`` cycles, then disable voltage (0x0000) until the drive reports SWITCH ON
DISABLED (at most 5 more cycles). A command takes effect at the SYNC after it is sent, so the
drive is quick-stopping (or off) from the 2nd SYNC after the detection and SWITCH ON DISABLED
by the ``quick_stop_cycles + 2``-th (tested against the simulated drive's own record).
Detection itself takes: the same cycle for limits, following error, EMCY and state changes;
``tpdo_timeout_cycles`` cycles for missing TPDOs; ``heartbeat_timeout_s`` of wall time for a
lost heartbeat (checked every 16 cycles); at most one cycle for SIGINT. The run's log is
closed properly and the result says why, in one line.

A dead master
-------------
The runner cannot stop the drives once it is dead, so it makes the drives watch it
(:mod:`daq.master`): its own heartbeat (``daq.master_node_id``, ``daq.master_heartbeat_ms``,
python-can ``send_periodic``) runs from before the drives' start-up to the end of the
campaign, each drive with 0x1016 watches it (consumer time 3 periods + 100 ms), and 0x1006
is written with the cycle in paced mode (0 in lockstep), arming the drive's SYNC-loss
reaction against a hung main loop. After a normal end the runner clears 0x1016.1 before it
stops its heartbeat. What could not be configured (no 0x1016 in the EDS, 0x1006 refused) is a
``warning`` event at cycle 0 of every run's log, a log warning and a line of the summary.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import os
import queue
import re
import signal
import struct
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import can
import canopen
import numpy as np

from . import ConfigError, DaqError, __version__
from .busload import BusLoad, check_load, cycle_load
from .cia402 import Mode, State, path, state_from_statusword
from .config import DaqConfig, Scaling, parse_daq, with_scaling
from .control import ControllerGains, PositionController
from .master import TPDO1_STRUCT, TPDO2_STRUCT, MasterDrive, MasterHeartbeat, pdo_lengths
from .mcaplog import FLAG_STOPPING, FLAG_TPDO_MISSING, FRAME, RunLog

logger = logging.getLogger(__name__)

CW_RUN = 0x0F
CW_QUICK_STOP = 0x02
CW_DISABLE = 0x00
CW_SHUTDOWN = 0x06
ENABLE_MAX_CYCLES = 200
DISABLE_MAX_CYCLES = 5
SHUTDOWN_CYCLES = 3
SETTLE_CYCLES = 20

_TIMING = struct.Struct("<4sqddd")
TIMING_SCHEMA = """\
# Paced clock: timing of one cycle
int64 cycle
float64 wall_s       # [s] time.perf_counter() when the SYNC was sent
float64 lateness_s   # [s] SYNC send time minus its deadline
float64 busy_s       # [s] time from the SYNC to the end of the cycle's work
"""


@dataclass(frozen=True)
class Progress:
    """What the progress display shows (built every ~250 cycles)."""

    payload: int  # 0-based index into campaign.payloads
    n_payloads: int
    segment: str
    cycle: int
    n_cycles: int
    bus_load: float  # share of the bit rate
    missed: int  # paced: late SYNCs; lockstep: cycles with a missing TPDO
    phase: str  # "enable", "run", "stop"

    def text(self) -> str:
        """The progress-bar text: payload, segment, cycles, bus load, missed cycles."""
        return (f"payload {self.payload + 1}/{self.n_payloads} | {self.segment} | "
                f"cycle {self.cycle}/{self.n_cycles} | bus {100 * self.bus_load:.0f}% | "
                f"missed {self.missed}")


@dataclass(frozen=True)
class PayloadResult:
    """The outcome of one payload run.

    Attributes
    ----------
    index : int
        Index into ``campaign.payloads``.
    mass_kg, arm_m : float
        The payload [kg], [m].
    path : Path
        Its MCAP file.
    cycles : int
        Cycles logged.
    status : str
        ``"done"``, ``"stopped"`` (fault) or ``"interrupted"`` (SIGINT).
    reason : str
        One line naming the cause when not done.
    fault_cycle, stop_cycle : int
        Cycle the fault was detected, cycle every drive reported disabled (-1 if none).
    missed : int
        Paced: SYNCs later than half a period; lockstep: cycles with a missing TPDO.
    wall_s : float
        Wall time of the run [s].
    lateness_s : ndarray
        Paced: lateness of each SYNC [s] (empty in lockstep).
    """

    index: int
    mass_kg: float
    arm_m: float
    path: Path
    cycles: int
    status: str
    reason: str = ""
    fault_cycle: int = -1
    stop_cycle: int = -1
    missed: int = 0
    wall_s: float = 0.0
    lateness_s: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def cycles_per_s(self) -> float:
        return self.cycles / self.wall_s if self.wall_s > 0 else float("nan")


@dataclass(frozen=True)
class CampaignResult:
    """The outcome of a campaign: one :class:`PayloadResult` per payload run executed."""

    name: str
    out_dir: Path
    runs: tuple[PayloadResult, ...]
    status: str  # "done", "stopped", "interrupted", "aborted" (operator)
    reason: str
    bus_load: BusLoad
    skipped: tuple[int, ...] = ()  # payload indices already completed (resume)
    sim_records: tuple[dict[str, np.ndarray], ...] = ()  # simulated drives' own records
    notes: tuple[str, ...] = ()  # start-up warnings (e.g. a drive without 0x1016)

    @property
    def ok(self) -> bool:
        return self.status == "done"

    def summary(self) -> str:
        """A few lines for the end of ``jointid run``."""
        lines = [f"campaign {self.name}: {self.status}" + (f" ({self.reason})" if self.reason
                                                             else "")]
        for r in self.runs:
            rate = f"{r.cycles_per_s:,.0f} cycles/s" if r.wall_s else ""
            lines.append(
                f"  payload {r.index} ({r.mass_kg:g} kg at {r.arm_m:g} m): {r.status}, "
                f"{r.cycles} cycles in {r.wall_s:.1f} s {rate}, missed {r.missed}"
                f" -> {r.path}" + (f"\n    {r.reason}" if r.reason else "")
            )
        lines.extend(f"  warning: {n}" for n in self.notes)
        if self.skipped:
            lines.append(f"  skipped (already completed): payloads {list(self.skipped)}")
        lines.append(f"  bus load: {self.bus_load}")
        return "\n".join(lines)


# ------------------------------------------------------------------------------- bus I/O
class CycleIO(can.Listener):
    """Receives every frame in the notifier thread: TPDOs into slots, heartbeats, EMCY, and
    the raw-frame record of the cycle (struct-packed, no per-frame object kept)."""

    def __init__(self, node_ids: Sequence[int]) -> None:
        self.n = len(node_ids)
        self.tpdo: dict[int, tuple[int, int, int]] = {}
        for d, nid in enumerate(node_ids):
            self.tpdo[0x180 + nid] = (d, 0, 1 << (2 * d))
            self.tpdo[0x280 + nid] = (d, 1, 1 << (2 * d + 1))
        self.hb_index = {0x700 + nid: d for d, nid in enumerate(node_ids)}
        self.emcy_index = {0x80 + nid: d for d, nid in enumerate(node_ids)}
        self.full = (1 << (2 * self.n)) - 1
        self.mask = 0
        self.data: list[list[bytes]] = [[b"", b""] for _ in node_ids]
        self.q: queue.SimpleQueue = queue.SimpleQueue()
        self.lock = threading.Lock()
        self.frames = bytearray()
        self.n_frames = 0
        now = time.monotonic()
        self.hb_time = [now] * self.n
        self.hb_state = [-1] * self.n
        self.emcy: list[tuple[int, int, int]] = []  # (drive, code, register)
        self.log_frames = True
        self.direct = False  # True: the main thread pumps the bus itself (see pump)

    def on_message_received(self, msg: can.Message) -> None:
        cid = msg.arbitration_id
        data = msg.data
        if self.log_frames:
            rec = FRAME.pack(msg.timestamp, cid, msg.dlc, bytes(data))
            if self.direct:
                self.frames += rec
                self.n_frames += 1
            else:
                with self.lock:
                    self.frames += rec
                    self.n_frames += 1
        slot = self.tpdo.get(cid)
        if slot is not None:
            d, s, bit = slot
            self.data[d][s] = bytes(data)
            m = self.mask | bit
            self.mask = m
            if m == self.full and not self.direct:
                self.q.put(True)
            return
        d = self.hb_index.get(cid)
        if d is not None:
            self.hb_time[d] = time.monotonic()
            self.hb_state[d] = data[0] & 0x7F if data else -1
            return
        d = self.emcy_index.get(cid)
        if d is not None and len(data) >= 3:
            code = data[0] | data[1] << 8
            if code:  # 0 = error reset / no error
                self.emcy.append((d, code, data[2]))

    def sent(self, ts: float, cid: int, data: bytes) -> None:
        rec = FRAME.pack(ts, cid, len(data), data)
        if self.direct:  # no notifier thread: nobody else appends
            self.frames += rec
            self.n_frames += 1
            return
        with self.lock:
            self.frames += rec
            self.n_frames += 1

    def take_frames(self) -> tuple[bytes, int]:
        with self.lock:
            buf, n = bytes(self.frames), self.n_frames
            self.frames.clear()
            self.n_frames = 0
        return buf, n

    def begin_cycle(self) -> None:
        self.mask = 0
        q = self.q
        while not q.empty():
            q.get_nowait()

    def pump(self, bus: can.BusABC, timeout: float) -> bool:
        """Receive on the calling thread until every TPDO of the cycle arrived or ``timeout``
        [s] passed; True when complete. Used while the notifier is stopped (one thread
        hand-off less per cycle than notifier + queue)."""
        perf = time.perf_counter
        end = perf() + timeout
        recv = bus.recv
        on = self.on_message_received
        full = self.full
        while self.mask != full:
            remaining = end - perf()
            msg = recv(remaining if remaining > 0 else 0.0)
            if msg is None:
                return False
            on(msg)
        return True

    def wait(self, timeout: float) -> bool:
        try:
            self.q.get(timeout=timeout) if timeout > 0 else self.q.get_nowait()
            return True
        except queue.Empty:
            return self.mask == self.full


# ------------------------------------------------------------------------- simulation rig
@dataclass
class _Sim:
    drives: list[Any]
    buses: list[can.BusABC]

    def close(self) -> None:
        for d in self.drives:
            with contextlib.suppress(Exception):
                d.stop()
        for b in self.buses:
            with contextlib.suppress(Exception):
                b.shutdown()


def _start_sim(cfg: DaqConfig, plant_params: Any, campaign: Any, fault_injectors: dict) -> _Sim:
    from sim_drivers.drive import SimulatedDrive
    from sim_drivers.plant import JointPlant

    sim = _Sim([], [])
    try:
        for k, dcfg in enumerate(cfg.drives):
            bus = can.Bus(interface="virtual", channel=cfg.channel)
            sim.buses.append(bus)
            plant = JointPlant(plant_params, campaign.cycle_s,
                               seed=int(plant_params.drive.seed) + k)
            plant.reset(campaign.joint.start)
            drive = SimulatedDrive(bus, dcfg.node_id, plant, dcfg.eds,
                                   fault_injector=fault_injectors.get(dcfg.node_id),
                                   cycle_s=campaign.cycle_s)
            drive.start()
            sim.drives.append(drive)
    except Exception:
        sim.close()
        raise
    return sim


def plant_scaling(plant_params: Any) -> Scaling:
    """The drive scaling of a plant's ``[drive]`` table."""
    d = plant_params.drive
    return Scaling(float(d.rated_torque_Nm), float(d.gear_ratio), int(d.encoder_counts_per_rev),
                   float(d.rated_current_A))


# ------------------------------------------------------------------------------ the engine
def _pin_cpu(cpu: int) -> set[int] | None:
    if cpu == -2 or not hasattr(os, "sched_setaffinity"):
        return None
    old = os.sched_getaffinity(0)
    target = max(old) if cpu == -1 else cpu
    if target not in old:
        raise ConfigError(f"daq.cpu: expected one of the allowed CPUs {sorted(old)}, got {cpu}")
    os.sched_setaffinity(0, {target})
    return old


def _set_realtime(cfg: DaqConfig) -> tuple[int, int] | None:
    """SCHED_FIFO at ``cfg.realtime_priority`` for this thread and the threads it starts."""
    if not cfg.realtime_priority:
        return None
    old = (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority)
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(cfg.realtime_priority))
    except (PermissionError, OSError) as exc:
        raise ConfigError(f"{cfg.source}: daq.realtime_priority: cannot set SCHED_FIFO "
                          f"{cfg.realtime_priority} ({exc.strerror}; needs CAP_SYS_NICE)"
                          ) from None
    return old


def _quintic(q0: float, q1: float, vmax: float, amax: float, cycle_s: float):
    """Rest-to-rest quintic from q0 to q1 at <= 50 % of vmax/amax: (q, dq, ddq) arrays."""
    d = q1 - q0
    if abs(d) < 1e-4:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    T = max(0.2, 1.875 * abs(d) / (0.5 * vmax), math.sqrt(5.7735 * abs(d) / (0.5 * amax)))
    n = int(math.ceil(T / cycle_s)) + 1
    s = np.minimum(np.arange(n) * cycle_s / T, 1.0)
    p = 10 * s**3 - 15 * s**4 + 6 * s**5
    v = (30 * s**2 - 60 * s**3 + 30 * s**4) / T
    a = (60 * s - 180 * s**2 + 120 * s**3) / T**2
    return q0 + d * p, d * v, d * a


class _Stop(Exception):
    def __init__(self, status: str, reason: str) -> None:
        super().__init__(reason)
        self.status = status
        self.reason = reason


class Engine:
    """Executes the payload runs of one campaign on an open bus (built by :func:`run_campaign`).

    Not thread-safe; one instance per campaign.
    """

    def __init__(self, campaign: Any, cfg: DaqConfig, network: canopen.Network,
                 io: CycleIO, drives: list[MasterDrive], scalings: list[Scaling],
                 load: BusLoad, progress: Callable[[Progress], None] | None) -> None:
        self.c = campaign
        self.cfg = cfg
        self.net = network
        self.bus = network.bus
        self.io = io
        self.drives = drives
        self.scalings = scalings
        self.load = load
        self.progress = progress
        self.cycle_s = campaign.cycle_s
        self.paced = cfg.clock == "paced"
        self.periodic = self.paced and cfg.sync_source == "periodic"
        self.interrupted = False
        lim = campaign.joint.limits
        span = lim.position[1] - lim.position[0]
        if cfg.position_limits is not None:
            self.q_lo, self.q_hi = cfg.position_limits
        else:
            self.q_lo, self.q_hi = lim.position[0] - 0.05 * span, lim.position[1] + 0.05 * span
        self.v_max = cfg.max_velocity if cfg.max_velocity is not None else 1.2 * lim.max_velocity
        self.tau_max = cfg.max_torque if cfg.max_torque is not None else lim.max_torque
        self.tau_act_max = self.tau_max * 1.2
        self.gains = ControllerGains(**campaign.control.gains_kwargs())
        self.revolute = campaign.joint.revolute
        self.sync_msg = can.Message(arbitration_id=0x80, data=b"", is_extended_id=False)
        self.rpdo_msgs = [can.Message(arbitration_id=0x200 + d.node_id, data=bytes(
            d.specs[0].n_bytes), is_extended_id=False) for d in drives]
        self.sync_count = 0
        self._resync = False
        self.notes: list[str] = []  # start-up warnings, logged at cycle 0 of every run

    # -- one cycle ------------------------------------------------------------------------
    def _exchange(self, cycle: int, deadline: float) -> int:
        """SYNC and wait for the TPDOs; returns the bit mask of TPDOs received."""
        io = self.io
        io.begin_cycle()
        now = time.time()
        self.bus.send(self.sync_msg)
        io.sent(now, 0x80, b"")
        self.sync_count += 1
        timeout = deadline - time.perf_counter() if self.paced else self.cfg.lockstep_wait_s
        ok = io.pump(self.bus, timeout) if io.direct else io.wait(timeout)
        if self._resync and io.direct:
            # the previous cycle timed out: its TPDOs may have arrived since and been taken
            # for this cycle's; take whatever is queued so that the newest values win
            recv, on = self.bus.recv, io.on_message_received
            while (msg := recv(0.0)) is not None:
                on(msg)
        self._resync = not ok
        return io.full if ok else io.mask

    def run_payload(self, index: int, payload: Any, ref: Any, log: RunLog,
                    sim_drive_cycle0: int) -> PayloadResult:
        """Execute one payload run and close its log.

        Phases (one cycle counter, no gaps): read the drives' state; enable them (CiA 402
        path, fault reset by a rising edge of bit 7) while holding the measured position;
        approach the plan's start with a quintic (segment -1) if needed; the plan; settle
        (``SETTLE_CYCLES``); shutdown (controlword 0x0006). On a fault, SIGINT or a watchdog:
        quick stop for ``quick_stop_cycles``, then disable voltage until the drives report
        it (at most ``DISABLE_MAX_CYCLES`` more cycles).

        Parameters
        ----------
        index : int
            Payload index in the campaign.
        payload : trajectories.campaign.Payload
        ref : trajectories.plan.Reference
            The planned reference, sampled every cycle: ``q`` [rad], ``dq`` [rad/s],
            ``ddq`` [rad/s^2], ``segment``, ``segment_names``.
        log : RunLog
            Open log; closed here on every path with the ``result`` metadata.
        sim_drive_cycle0 : int
            Cycle counter of the simulated drive at our cycle 0 (-1: no simulation).

        Returns
        -------
        PayloadResult
        """
        c, cfg, io = self.c, self.cfg, self.io
        n_dr = len(self.drives)
        cycle_s = self.cycle_s
        kq = [s.rad_per_count for s in self.scalings]
        cpr = [1.0 / k for k in kq]
        tpu = [s.torque_per_unit for s in self.scalings]
        xmax = [min(32767, int(self.tau_max / t)) for t in tpu]
        csp = [d.cfg.mode is Mode.CYCLIC_SYNC_POSITION for d in self.drives]
        ctrls = [PositionController(self.gains, cycle_s, self.revolute) for _ in self.drives]
        packs = [d.rpdo_struct.pack for d in self.drives]
        unpack1, unpack2 = TPDO1_STRUCT.unpack, TPDO2_STRUCT.unpack
        send = self.bus.send
        msgs = self.rpdo_msgs
        io_sent = io.sent
        data = io.data
        log_state, log_sp, log_frames = log.state, log.setpoint, log.frames
        seg_names = list(ref.segment_names)
        timing: list[tuple[float, float, float]] = []
        lateness = np.zeros(0)
        # per-drive live values (kept when a TPDO is missing)
        sw = [0] * n_dr
        counts = [0] * n_dr
        tq = [0] * n_dr
        vel = [0] * n_dr
        prev_state: list[State | None] = [None] * n_dr
        prev_sw = [-1] * n_dr
        missing_run = [0] * n_dr
        missed = 0
        cycle = 0
        fault_cycle = -1
        stop_cycle = -1
        status, reason = "done", ""
        t_wall0 = time.perf_counter()
        next_deadline = t_wall0 + cycle_s
        hb_check = 0
        ch_timing = None
        if self.paced:
            w = log._w
            sid = w.register_schema("jointid_msgs/msg/CycleTiming", "ros2msg",
                                    TIMING_SCHEMA.encode())
            ch_timing = w.register_channel("/timing", "cdr", sid)

        def do_cycle(q_ref: float, dq_ref: float, ddq_ref: float, seg: int, mode: str) -> None:
            """One full cycle; ``mode`` is "enable", "run", "quick_stop", "disable", "shutdown"."""
            nonlocal cycle, missed, next_deadline, hb_check
            t = cycle * cycle_s
            if self.paced and not self.periodic:
                target = next_deadline
                now = time.perf_counter()
                if target - now > 0.0003:
                    time.sleep(target - now - 0.0002)
                while time.perf_counter() < target:
                    pass
                t_sync = time.perf_counter()
                late = t_sync - target
                if late > 0.5 * cycle_s:
                    missed += 1
                if late > cycle_s:
                    next_deadline = t_sync  # re-anchor: no catch-up burst
                mask = self._exchange(cycle, next_deadline + 0.8 * cycle_s)
                next_deadline += cycle_s
            elif self.periodic:
                # SYNC comes from the periodic task: a cycle is the arrival of the TPDOs
                io.mask = 0
                ok = io.pump(self.bus, 2.0 * cycle_s)
                mask = io.full if ok else io.mask
                t_sync = time.perf_counter()
                late = t_sync - next_deadline
                if late > 0.5 * cycle_s or late < -0.5 * cycle_s:
                    missed += 1
                    next_deadline = t_sync  # re-anchor on the SYNC train
                    late = 0.0 if cycle == 0 else late
                next_deadline += cycle_s
            else:
                t_sync = late = 0.0
                mask = self._exchange(cycle, 0.0)
            stopping = mode != "run" and mode != "enable"
            tpdo_fault = ""
            if io.emcy and not stopping:  # before the state checks: name the first cause
                dd, code, reg = io.emcy.pop(0)
                self._fault(f"{self.drives[dd].name}: EMCY 0x{code:04X} (error register "
                            f"0x{reg:02X})", cycle, t, log, dd, kind="emcy")
            for d in range(n_dr):
                flags = FLAG_STOPPING if stopping else 0
                b1 = 1 << (2 * d)
                if mask & (b1 | b1 << 1) == (b1 | b1 << 1):
                    sw[d], counts[d], tq[d] = unpack1(data[d][0])
                    vel[d] = unpack2(data[d][1])[0]
                    missing_run[d] = 0
                else:
                    flags |= FLAG_TPDO_MISSING
                    missing_run[d] += 1
                    if mode == "run" or mode == "enable":
                        missed += 0 if self.paced else 1
                    if missing_run[d] >= cfg.tpdo_timeout_cycles and not tpdo_fault:
                        tpdo_fault = (f"{self.drives[d].name}: TPDO missing for "
                                      f"{missing_run[d]} cycles (watchdog)")
                q = counts[d] * kq[d]
                dq = vel[d] * kq[d]
                tau_act = tq[d] * tpu[d]
                s = sw[d]
                if mode == "run" or mode == "enable":
                    if csp[d]:
                        x = 0
                        target_raw = round(q_ref * cpr[d])
                    else:
                        tau = ctrls[d].update(q_ref, dq_ref, ddq_ref, q)
                        x = round(tau / tpu[d])
                        if x > xmax[d]:
                            x = xmax[d]
                        elif x < -xmax[d]:
                            x = -xmax[d]
                        target_raw = 0
                    if mode == "run":
                        cw = CW_RUN
                    else:
                        try:
                            st = (state_from_statusword(s) if flags == 0
                                  else State.SWITCH_ON_DISABLED)
                        except ValueError:
                            st = State.NOT_READY_TO_SWITCH_ON
                        if st is State.OPERATION_ENABLED:
                            cw = CW_RUN
                        elif st is State.FAULT:
                            cw = 0x80 if cycle % 2 else 0x00  # rising edge of bit 7
                        elif st in (State.NOT_READY_TO_SWITCH_ON, State.FAULT_REACTION_ACTIVE):
                            cw = CW_DISABLE
                        else:
                            cw = path(st, State.OPERATION_ENABLED)[0][1]
                else:
                    x = 0
                    target_raw = round(q_ref * cpr[d]) if csp[d] else 0
                    cw = (CW_QUICK_STOP if mode == "quick_stop" else
                          CW_DISABLE if mode == "disable" else CW_SHUTDOWN)
                payload_bytes = packs[d](cw, target_raw if csp[d] else x)
                m = msgs[d]
                m.data = payload_bytes
                send(m)
                io_sent(time.time(), m.arbitration_id, payload_bytes)
                log_state(d, cycle, t, q, dq, x * tpu[d] if not csp[d] else math.nan, tau_act,
                          counts[d], vel[d], x, tq[d], s, flags)
                # state change events (decode only when the statusword changed)
                if flags & FLAG_TPDO_MISSING:
                    st_now = None
                elif s == prev_sw[d]:
                    st_now = prev_state[d]
                else:
                    prev_sw[d] = s
                    try:
                        st_now = state_from_statusword(s)
                    except ValueError:
                        st_now = None
                    if st_now is not prev_state[d]:
                        log.event(cycle, t, "state", f"{self.drives[d].name}: "
                                  f"{st_now.name if st_now else hex(s)}", d)
                        prev_state[d] = st_now
                # limits and following error (only while driving)
                if mode == "run" and not self._stop_reason:
                    why = ""
                    if not self.q_lo <= q <= self.q_hi and not flags:
                        why = (f"position limit: q = {q:.4f} outside [{self.q_lo:.4g}, "
                               f"{self.q_hi:.4g}]")
                    elif (dq > self.v_max or -dq > self.v_max) and not flags:
                        why = f"velocity limit: |dq| = {abs(dq):.4f} > {self.v_max:.4g}"
                    elif (tau_act > self.tau_act_max or -tau_act > self.tau_act_max) and not flags:
                        why = (f"torque limit: |torque actual| = {abs(tau_act):.1f} > "
                               f"{self.tau_act_max:.4g}")
                    elif abs(q_ref - q) > cfg.max_following_error and not flags:
                        why = (f"following error: |q_ref - q| = {abs(q_ref - q):.4f} > "
                               f"{cfg.max_following_error:g}")
                    elif st_now is not None and st_now is not State.OPERATION_ENABLED:
                        why = f"drive left OPERATION_ENABLED (now {st_now.name})"
                    if why:
                        self._fault(f"{self.drives[d].name}: {why}", cycle, t, log, d)
            if tpdo_fault and not stopping:
                self._fault(tpdo_fault, cycle, t, log, -1)
            log_sp(cycle, t, q_ref, dq_ref, ddq_ref, seg,
                   round(q_ref * cpr[0]) if csp[0] else 0)
            buf, nf = io.take_frames()
            log_frames(cycle, buf, nf)
            if self.paced:
                busy = time.perf_counter() - t_sync
                timing.append((t_sync - t_wall0, late, busy))
                log._add(ch_timing, log.start_ns + cycle * log.cycle_ns,
                         _TIMING.pack(b"\x00\x01\x00\x00", cycle, t_sync - t_wall0, late, busy),
                         time.time_ns(), cycle)
            # watchdogs that do not depend on the drive's answer of this cycle
            if not stopping:
                hb_check += 1
                if hb_check >= 16:
                    hb_check = 0
                    now = time.monotonic()
                    for dd in range(n_dr):
                        if self.drives[dd].cfg.heartbeat_ms and (
                                now - io.hb_time[dd] > cfg.heartbeat_timeout_s):
                            self._fault(f"{self.drives[dd].name}: heartbeat lost (none for "
                                        f"{now - io.hb_time[dd]:.2f} s > "
                                        f"{cfg.heartbeat_timeout_s:g} s)", cycle, t, log, dd,
                                        kind="watchdog")
                            break
                if self.interrupted and not self._stop_reason:
                    self._stop_reason = ("interrupted", "interrupted by the operator (SIGINT)")
                    self._fault_cycle = cycle
                    log.event(cycle, t, "operator", "SIGINT: stopping")
            cycle += 1

        def enabled_all() -> bool:
            for d in range(n_dr):
                try:
                    if state_from_statusword(sw[d]) is not State.OPERATION_ENABLED:
                        return False
                except ValueError:
                    return False
            return True

        def report(phase: str, seg: int, n_total: int) -> None:
            if self.progress is not None:
                name = seg_names[seg] if 0 <= seg < len(seg_names) else phase
                self.progress(Progress(index, len(c.payloads), name, cycle, n_total,
                                       self.load.share, missed, phase))

        self._stop_reason: tuple[str, str] | None = None
        self._fault_cycle = -1
        net = self.net
        if net.notifier is not None:  # the main thread receives itself during the run
            net.notifier.stop(1.0)
            net.notifier = None
        io.direct = True
        sync_task = None
        if self.periodic:
            # first cycle's deadline: one period after the periodic task starts
            sync_task = self.bus.send_periodic(self.sync_msg, cycle_s)
            next_deadline = time.perf_counter() + cycle_s
            log.event(0, 0.0, "info", f"SYNC from send_periodic ({type(sync_task).__name__})")
        for note in self.notes:
            log.event(0, 0.0, "warning", note)
        try:
            # 1. enable, holding the position measured at the first answer
            do_cycle(0.0, 0.0, 0.0, -1, "disable")  # first SYNC: read the drives' state
            q_hold = counts[0] * kq[0]
            log.event(cycle, cycle * cycle_s, "info", f"start position {q_hold:.5f}")
            for _ in range(ENABLE_MAX_CYCLES):
                if enabled_all() or self._stop_reason:
                    break
                do_cycle(q_hold, 0.0, 0.0, -1, "enable")
            if not enabled_all() and not self._stop_reason:
                names = ", ".join(f"{d.name} {state_from_statusword(sw[k]).name}"
                                  for k, d in enumerate(self.drives))
                self._fault(f"drives not enabled after {ENABLE_MAX_CYCLES} cycles ({names})",
                            cycle, cycle * cycle_s, log, -1)
            if not self._stop_reason:
                log.event(cycle, cycle * cycle_s, "info", "operation enabled")
                # 2. approach the plan start, then the plan, then settle
                lim = c.joint.limits
                aq, adq, addq = _quintic(q_hold, float(ref.q[0]), lim.max_velocity,
                                         lim.max_acceleration, cycle_s)
                rq = np.concatenate([aq, ref.q, np.full(SETTLE_CYCLES, ref.q[-1])]).tolist()
                rdq = np.concatenate([adq, ref.dq, np.zeros(SETTLE_CYCLES)]).tolist()
                rddq = np.concatenate([addq, ref.ddq, np.zeros(SETTLE_CYCLES)]).tolist()
                rseg = np.concatenate([np.full(len(aq), -1), ref.segment,
                                       np.full(SETTLE_CYCLES, -1)]).astype(int).tolist()
                n_total = cycle + len(rq)
                report("run", -1, n_total)
                for i in range(len(rq)):
                    do_cycle(rq[i], rdq[i], rddq[i], rseg[i], "run")
                    if self._stop_reason:
                        break
                    if i % 250 == 0:
                        report("run", rseg[i], n_total)
            # 3. stop: normal shutdown or quick stop + disable
            q_last = counts[0] * kq[0]
            if self._stop_reason:
                status, reason = self._stop_reason
                fault_cycle = self._fault_cycle
                report("stop", -1, cycle)
                for _ in range(cfg.quick_stop_cycles):
                    do_cycle(q_last, 0.0, 0.0, -1, "quick_stop")
                for _ in range(DISABLE_MAX_CYCLES + 1):
                    do_cycle(q_last, 0.0, 0.0, -1, "disable")
                    if self._all_off(sw):
                        break
            else:
                for _ in range(SHUTDOWN_CYCLES):
                    do_cycle(q_last, 0.0, 0.0, -1, "shutdown")
            off = self._all_off(sw)
            stop_cycle = cycle - 1 if off else -1
            msg = ("drives disabled" if off else "drives did not confirm the stop: "
                   + ", ".join(f"{d.name} sw=0x{sw[k]:04X}" for k, d in enumerate(self.drives)))
            log.event(stop_cycle if off else cycle - 1, (cycle - 1) * cycle_s,
                      "stop" if status != "done" else "info", msg)
        finally:
            wall = time.perf_counter() - t_wall0
            if sync_task is not None:
                sync_task.stop()
            io.direct = False
            net.notifier = can.Notifier(net.bus, net.listeners, net.NOTIFIER_CYCLE)
            if timing:
                lateness = np.array([x[1] for x in timing])
            log.close({
                "status": status, "reason": reason, "cycles": str(cycle),
                "fault_cycle": str(fault_cycle), "stop_cycle": str(stop_cycle),
                "missed": str(missed), "wall_s": f"{wall:.3f}",
                "sync_offset": str(sim_drive_cycle0),
            })
        return PayloadResult(index, float(payload.mass_kg), float(payload.arm_m), log.path,
                             cycle, status, reason, fault_cycle, stop_cycle, missed, wall,
                             lateness)

    def _all_off(self, sw: list[int]) -> bool:
        for s in sw:
            try:
                st = state_from_statusword(s)
            except ValueError:
                return False
            if st in (State.OPERATION_ENABLED, State.QUICK_STOP_ACTIVE):
                return False
        return True

    def _fault(self, why: str, cycle: int, t: float, log: RunLog, axis: int,
               kind: str = "fault") -> None:
        if self._stop_reason:
            return
        self._stop_reason = ("stopped", why)
        self._fault_cycle = cycle
        log.event(cycle, t, kind, why, axis)


# ----------------------------------------------------------------------------- campaign
def file_stem(name: str) -> str:
    """A campaign name made safe for file names (``"rx130l (quick)"`` -> ``"rx130l_quick"``)."""
    stem = re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("_")
    return stem or "campaign"


def _state_path(out_dir: Path, name: str) -> Path:
    return out_dir / f"{file_stem(name)}.state.json"


def _read_state(p: Path) -> set[int]:
    try:
        raw = json.loads(p.read_text())
        return {int(i) for i in raw.get("completed", [])}
    except (OSError, ValueError, TypeError):
        return set()


def _write_state(p: Path, name: str, completed: set[int]) -> None:
    tmp = p.with_suffix(".tmp")
    tmp.write_text(json.dumps({"campaign": name, "completed": sorted(completed)}))
    os.replace(tmp, p)


def _metadata(campaign: Any, cfg: DaqConfig, plan: Any, index: int, payload: Any,
              scalings: list[Scaling], plant_params: Any,
              bus_info: str = "", drives: Sequence[MasterDrive] = ()
              ) -> dict[str, dict[str, str]]:
    ref = plan.reference
    md: dict[str, dict[str, str]] = {
        "campaign": {
            "name": campaign.name, "source": str(campaign.source),
            "joint_kind": campaign.joint.kind, "cycle_s": repr(campaign.cycle_s),
            "clock": cfg.clock, "interface": cfg.interface, "channel": cfg.channel,
            "bitrate": str(cfg.bitrate), "bus": bus_info,
            "n_payloads": str(len(campaign.payloads)),
            "segments": json.dumps(list(ref.segment_names)),
            "position_limits": json.dumps(list(campaign.joint.limits.position)),
            "gains": json.dumps(campaign.control.gains_kwargs()),
        },
        "payload": {"index": str(index), "mass_kg": repr(float(payload.mass_kg)),
                    "arm_m": repr(float(payload.arm_m))},
        "software": {"jointid": __version__, "python-can": can.__version__,
                     "canopen": getattr(canopen, "__version__", "?"),
                     "python": sys.version.split()[0]},
    }
    for k, (d, s) in enumerate(zip(cfg.drives, scalings, strict=True)):
        md[f"drive{k}"] = {"node_id": str(d.node_id), "eds": d.eds.name, "mode": d.mode_name,
                           **s.as_dict()}
        if k < len(drives):
            v = drives[k].consumer_value
            md[f"drive{k}"]["heartbeat_consumer"] = ("" if v is None else f"0x{v:08X}")
    md["safety"] = {
        "master_node_id": str(cfg.master_node_id),
        "master_heartbeat_ms": str(cfg.master_heartbeat_ms),
        "heartbeat_consumer_ms": str(cfg.heartbeat_consumer_ms),
        "sync_period_us": str(_sync_period_us(cfg, campaign.cycle_s)),
    }
    if plant_params is not None:
        md["plant"] = {"name": str(getattr(plant_params, "name", "")),
                       "source": str(getattr(plant_params, "source", "")),
                       "simulated": "true"}
        with contextlib.suppress(Exception):
            md["plant"]["truth"] = json.dumps(plant_params.truth())
    return md


def _sync_period_us(cfg: DaqConfig, cycle_s: float) -> int:
    """0x1006 for the drives [µs]: the cycle when paced, 0 (SYNC monitoring off) in
    lockstep, where SYNCs may be far apart in wall time on a loaded host."""
    return int(round(cycle_s * 1e6)) if cfg.clock == "paced" else 0


def _attachments(campaign: Any, cfg: DaqConfig, plant_params: Any) -> list[tuple[str, str,
                                                                                    bytes]]:
    out = []
    src = Path(str(campaign.source)) if campaign.source else None
    if src is not None and src.is_file():
        out.append((src.name, "application/toml", src.read_bytes()))
    seen = set()
    for d in cfg.drives:
        if d.eds not in seen:
            seen.add(d.eds)
            out.append((d.eds.name, "text/plain", d.eds.read_bytes()))
    if plant_params is not None:
        p = Path(str(getattr(plant_params, "source", "")))
        if p.suffix == ".toml" and p.is_file():
            out.append((p.name, "application/toml", p.read_bytes()))
    return out


def _prompt(index: int, payload: Any, n: int) -> bool:
    """Ask the operator to mount a payload; False to abort the campaign."""
    try:
        answer = input(f"Mount payload {index + 1}/{n}: {payload.mass_kg:g} kg at "
                       f"{payload.arm_m:g} m, then press Enter (q to quit): ")
    except EOFError:
        return False
    return answer.strip().lower() not in ("q", "quit", "n", "no")


def run_campaign(
    campaign: Any,
    *,
    out_dir: str | Path,
    simulate: Any = None,
    yes: bool = False,
    progress: Callable[[Progress], None] | None = None,
    payloads: Sequence[int] | None = None,
    resume: bool = False,
    fault_injectors: dict[int, Any] | None = None,
    prompt: Callable[[int, Any, int], bool] | None = None,
) -> CampaignResult:
    """Run a campaign: one MCAP file per payload run in ``out_dir``.

    Parameters
    ----------
    campaign : trajectories.campaign.Campaign
    out_dir : path-like
        Created if needed; receives ``<name>_payload<k>.mcap`` and ``<name>.state.json``.
    simulate : sim_drivers.plant_config.PlantParams or None
        Run against simulated drives (one plant per drive) on python-can's virtual bus; the
        drive scaling comes from the plant's ``[drive]`` table.
    yes : bool
        Do not ask the operator between payloads (unattended).
    progress : callable or None
        Called with a :class:`Progress` every ~250 cycles.
    payloads : sequence of int or None
        Indices of the payloads to run (default: all).
    resume : bool
        Skip the payloads the state file lists as completed.
    fault_injectors : dict node_id -> sim_drivers.faults.FaultInjector, optional
        For tests with simulated drives.
    prompt : callable or None
        ``(index, payload, n) -> bool`` replacing the interactive prompt.

    Returns
    -------
    CampaignResult
        ``status`` "done", "stopped" (a fault; ``reason`` names it), "interrupted" (SIGINT)
        or "aborted" (the operator declined a payload).

    Raises
    ------
    daq.ConfigError
        Refusals before any motion: invalid ``[daq]``, bus load over the limit, unknown node,
        EDS or drive without the requested mode, PDO read-back mismatch.
    trajectories.TrajectoryError
        The plan violates a limit.
    """
    from trajectories.plan import plan_campaign

    cfg = parse_daq(campaign.daq, str(campaign.source))
    if simulate is not None:
        cfg = with_scaling(cfg, plant_scaling(simulate))
        if cfg.interface != "virtual":
            raise ConfigError(f"{campaign.source}: daq.interface: expected 'virtual' with "
                              f"--simulate, got {cfg.interface!r}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    plan = plan_campaign(campaign)
    load = cycle_load([pdo_lengths(d.mode) for d in cfg.drives], campaign.cycle_s, cfg.bitrate)
    check_load(load, cfg.max_bus_load, str(campaign.source) or "campaign")
    n_pay = len(campaign.payloads)
    todo = list(range(n_pay)) if payloads is None else list(payloads)
    for i in todo:
        if not 0 <= i < n_pay:
            raise ConfigError(f"payload index {i}: expected 0..{n_pay - 1}")
    state_file = _state_path(out, campaign.name)
    done_before = _read_state(state_file) if resume else set()
    skipped = tuple(i for i in todo if i in done_before)
    todo = [i for i in todo if i not in done_before]
    completed = set(done_before)

    old_affinity = _pin_cpu(cfg.cpu)
    old_sched = _set_realtime(cfg) if cfg.clock == "paced" else None
    sim: _Sim | None = None
    network: canopen.Network | None = None
    old_handler = None
    engine: Engine | None = None
    runs: list[PayloadResult] = []
    sim_records: tuple[dict[str, np.ndarray], ...] = ()
    heartbeat: MasterHeartbeat | None = None
    drives: list[MasterDrive] = []
    notes: list[str] = []
    clean = False
    status, reason = "done", ""
    try:
        if simulate is not None:
            sim = _start_sim(cfg, simulate, campaign, fault_injectors or {})
        kwargs: dict[str, Any] = {"interface": cfg.interface, "channel": cfg.channel}
        if cfg.interface == "config":  # python-can's own configuration decides everything
            kwargs = {}
        elif cfg.interface != "virtual":
            kwargs["bitrate"] = cfg.bitrate
        try:
            bus = can.Bus(**kwargs)
        except (can.CanError, OSError, ValueError, ImportError) as exc:
            raise ConfigError(f"{campaign.source}: daq.interface: cannot open "
                              f"{cfg.interface} {cfg.channel}: {exc}") from None
        io = CycleIO([d.node_id for d in cfg.drives])
        network = canopen.Network(bus)
        network.NOTIFIER_CYCLE = 0.05
        network.listeners.append(io)
        network.connect()
        drives = [MasterDrive(network, d) for d in cfg.drives]
        if cfg.master_heartbeat_ms:
            heartbeat = MasterHeartbeat(bus, cfg.master_node_id, cfg.master_heartbeat_ms)
            heartbeat.start()
        else:
            notes.append("daq.master_heartbeat_ms = 0: the master sends no heartbeat, the "
                         "drives do not watch it")
        tau_max = cfg.max_torque if cfg.max_torque is not None else (
            campaign.joint.limits.max_torque)
        scalings = [d.start_up(campaign.cycle_s, tau_max, master_id=cfg.master_node_id,
                               consumer_ms=cfg.heartbeat_consumer_ms,
                               sync_period_us=_sync_period_us(cfg, campaign.cycle_s))
                    for d in drives]
        if heartbeat is not None:
            heartbeat.beat()  # the drives watch the master from now on, not a period later
        for d in drives:
            notes.extend(d.notes)
        for note in notes:
            logger.warning("%s", note)
        engine = Engine(campaign, cfg, network, io, drives, scalings, load, progress)
        engine.notes = notes
        if threading.current_thread() is threading.main_thread():
            def on_sigint(signum: int, frame: Any) -> None:
                if engine is not None:
                    engine.interrupted = True
            old_handler = signal.signal(signal.SIGINT, on_sigint)
        ask = prompt or _prompt
        for n_done, i in enumerate(todo):
            p = campaign.payloads[i]
            if sim is not None:
                for d in sim.drives:
                    d.set_payload(p.mass_kg, p.arm_m)
            if not yes and (n_done > 0 or sim is None or prompt is not None):
                if old_handler is not None:  # Ctrl-C at the prompt interrupts it at once
                    signal.signal(signal.SIGINT, signal.default_int_handler)
                try:
                    accepted = ask(i, p, n_pay)
                except KeyboardInterrupt:
                    status, reason = "interrupted", "interrupted by the operator (SIGINT)"
                    break
                finally:
                    if old_handler is not None:
                        signal.signal(signal.SIGINT, on_sigint)
                if not accepted:
                    status, reason = "aborted", f"operator declined payload {i}"
                    break
            if engine.interrupted:
                status, reason = "interrupted", "interrupted by the operator (SIGINT)"
                break
            io.emcy.clear()
            io.hb_time = [time.monotonic()] * len(drives)
            for d in drives:
                d.nmt_start()
            drive_cycle0 = sim.drives[0].cycle if sim is not None else -1
            log = RunLog(out / f"{file_stem(campaign.name)}_payload{i}.mcap", n_axes=len(drives),
                         cycle_s=campaign.cycle_s,
                         metadata=_metadata(campaign, cfg, plan, i, p, scalings, simulate,
                                            str(getattr(bus, "channel_info", "")), drives),
                         attachments=_attachments(campaign, cfg, simulate),
                         chunk_seconds=cfg.chunk_seconds,
                         frames_per_cycle=1 + 3 * len(drives))
            r = engine.run_payload(i, p, plan.reference, log, drive_cycle0)
            runs.append(r)
            for d in drives:
                with contextlib.suppress(DaqError):
                    d.nmt_preop()
            if r.status != "done":
                status, reason = r.status, r.reason
                break
            completed.add(i)
            _write_state(state_file, campaign.name, completed)
        clean = True
    finally:
        if clean:  # normal end, drives disabled: stop watching the master, then go silent
            for d in drives:
                d.clear_master_heartbeat()
        if heartbeat is not None:
            heartbeat.stop()
        if sim is not None:
            sim_records = tuple(d.record for d in sim.drives)
        if old_handler is not None:
            signal.signal(signal.SIGINT, old_handler)
        if network is not None:
            with contextlib.suppress(Exception):
                network.disconnect()
        if sim is not None:
            sim.close()
        if old_affinity is not None:
            with contextlib.suppress(OSError):
                os.sched_setaffinity(0, old_affinity)
        if old_sched is not None:
            with contextlib.suppress(OSError):
                os.sched_setscheduler(0, old_sched[0], os.sched_param(old_sched[1]))
    return CampaignResult(campaign.name, out, tuple(runs), status, reason, load, skipped,
                          sim_records, tuple(notes))
