"""Plan execution: the engine that runs a planned campaign on CANopen drives, cycle by cycle.

(Past 600 lines: the cycle loop, the per-cycle exchange it drives and the stop paths of a
run, one closure scope; orchestration is runner.py, supervision safety.py.)

Orchestration (bus, start-up, payload loop, operator) is :mod:`daq.runtime.runner`; the stop
sequence and the watchdogs are :mod:`daq.runtime.safety`; the frame bookkeeping is
:mod:`daq.runtime.cycle_io`.

The campaign and its plan say *what* to do (:mod:`trajectories`); this engine executes it:
start-up (presence, mode, PDO layout read back, bus load), then per payload run one MCAP
file, cycle by cycle:

1. SYNC (the drives latch the RPDOs of the previous cycle, step, and answer with TPDOs);
2. wait for every drive's TPDO1/TPDO2 (``lockstep``: as long as needed, deterministic;
   ``paced``: until 80 % of the period has elapsed), then take every frame already queued,
   so that the newest values win (a burst of late answers is never used one set per cycle);
3. per drive: decode (struct), the position controller
   :class:`daq.protocol.control.PositionController` (CST; on a cycle without the drive's
   TPDO it holds the last fresh feedback torque, then blends back to the law; its velocity
   the drive's own or the position's difference, ``[daq] velocity_source``, left out the
   drive's on the paced clock) or the position target (CSP), limits and watchdog, RPDO out;
4. log the joint states, the setpoint and every CAN frame of the cycle.

The campaign is a :class:`~trajectories.robot_campaign.RobotCampaign` (either file format)
and its plan a :class:`~trajectories.sampled.RobotPlan`, one column per moving joint. Each
drive follows the column of its joint (:func:`drive_joints`) with that joint's gains
(feed-forward included) and limits, and logs on ``/joint/<k>/state``; the safety checks
below are per drive, each against its own joint's limits. With one drive per moving joint
(``[robot]``: each joint names its drive) drive k follows joint k and logs its own reference
on ``/joint/<k>/setpoint``. A joint without a drive of its own (a ``[joint]`` file, one
moving joint) is followed by every drive of ``[[daq.drives]]``, each with its own
controller (and, with ``--simulate``, its own plant); their one reference is logged once on
``/setpoint``.

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
    re-anchored instead of sending a catch-up burst. The run log's full chunks are compressed
    and written by a worker thread (:meth:`daq.runtime.mcaplog.RunLog.background_chunks`,
    one real-time priority below the loop under ``realtime_priority``): in the loop a chunk
    costs a copy of its buffer (~25 µs) instead of 0.3-1.5 ms of zstd and write.
    During a paced payload run Python's GIL switch interval is ``daq.switch_interval_s``
    (default 0.2 ms instead of 5 ms; restored after the run).

Safety (every cycle)
--------------------
Position, velocity, torque limits (``[daq.limits]``, else the campaign's joint limits with
5 % of the range / 20 % of the speed and torque as margins; the command itself is saturated
at the torque limit), following error, TPDO missing for ``tpdo_timeout_cycles`` consecutive
cycles, heartbeat silent for ``heartbeat_timeout_s`` (the frames waiting in the receive queue
are taken first: a stalled master has not read them), EMCY, a drive leaving OPERATION ENABLED,
SIGINT/SIGTERM/SIGHUP, the start-up lateness check (before the plan moves, drives enabled
and holding: a bus whose share of late or missing answers is above ``[daq] lateness_stop``
refuses the run, :mod:`daq.runtime.safety`), a torque-monitor crossing with ``stop``
(``jointid monitor``, :mod:`daq.runtime.monitor`: checked each cycle of the run phase, event
kind ``collision``), the master's own stall (paced: a cycle later than the RPDO deadline
the drives were given, 3 cycles + 100 ms: "master stalled for X s"; a shorter stall of more
than a cycle is named in the reason of an EMCY read right after it; with periodic SYNC the
TPDOs queued meanwhile are taken at once, not logged as cycles), the run log's file failing
(disk full, file-size limit: "log write failed: FILE: ...", the stop sequence then runs
without a log). On any of them the runner sends quick stop (controlword 0x0002) for
``quick_stop_cycles`` cycles, then disable voltage (0x0000) until the drive reports SWITCH ON
DISABLED (at most 5 more cycles). A command takes effect at the SYNC after it is sent, so the
drive is quick-stopping (or off) from the 2nd SYNC after the detection and SWITCH ON DISABLED
by the ``quick_stop_cycles + 2``-th (tested against the simulated drive's own record).
Detection itself takes: the same cycle for limits, following error, EMCY and state changes;
``tpdo_timeout_cycles`` cycles for missing TPDOs; ``heartbeat_timeout_s`` of wall time for a
lost heartbeat (checked every 16 cycles); at most one cycle for a signal. The run's log is
closed properly and the result says why, in one line. EMCYs that arrive during the stop
sequence are ``emcy`` events of the log (the first cause stays the reason).

A dead master
-------------
The runner cannot stop the drives once it is dead, so it makes the drives watch it
(:mod:`daq.runtime.master`): its own heartbeat (``daq.master_node_id``, ``daq.master_heartbeat_ms``,
python-can ``send_periodic``) runs from before the drives' start-up to the end of the
campaign, each drive with 0x1016 watches it (consumer time 3 periods + 100 ms), and 0x1006
is written with the cycle in paced mode (0 in lockstep), arming the drive's SYNC-loss
reaction against a hung main loop. After a normal end the runner clears 0x1016.1 before it
stops its heartbeat. What could not be configured (no 0x1016 in the EDS, 0x1006 refused) is a
``warning`` event at cycle 0 of every run's log, a log warning and a line of the summary.
"""

from __future__ import annotations

import gc
import logging
import math
import struct
import sys
import time
from collections.abc import Callable
from typing import Any

import can
import canopen
import numpy as np

from daq.protocol.cia402 import Mode, State, path, state_from_statusword
from daq.protocol.control import ControllerGains, PositionController
from daq.protocol.logformat import FLAG_STOPPING, FLAG_TPDO_MISSING
from trajectories.robot_campaign import RobotCampaign

from .busload import BusLoad
from .config import DaqConfig, Scaling
from .cycle_io import BUS_ERRORS, CycleIO
from .master import TPDO1_STRUCT, TPDO2_STRUCT, MasterDrive, rpdo_timeout_ms
from .mcaplog import RunLog
from .results import PayloadResult, Progress
from .safety import (
    CW_DISABLE,
    CW_QUICK_STOP,
    CW_RUN,
    CW_SHUTDOWN,
    DISABLE_MAX_CYCLES,
    LATENESS_MAX_ROUNDS,
    SHUTDOWN_CYCLES,
    NullLog,
    Supervisor,
    interrupt_reason,
    lateness_verdict,
    log_failed,
    redact_url_secret,
)

logger = logging.getLogger(__name__)

ENABLE_MAX_CYCLES = 200
SETTLE_CYCLES = 20

_TIMING = struct.Struct("<4sqddd")
TIMING_SCHEMA = """\
# Paced clock: timing of one cycle
int64 cycle
float64 wall_s       # [s] time.perf_counter() when the SYNC was sent
float64 lateness_s   # [s] SYNC send time minus its deadline
float64 busy_s       # [s] time from the SYNC to the end of the cycle's work
"""




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


def _approach(q0: list[float], q1: list[float], vmax: list[float], amax: list[float],
              cycle_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Synchronised rest-to-rest quintics from ``q0`` to ``q1`` (one per column), each at <=
    50 % of its vmax/amax, all of the duration of the slowest: (q, dq, ddq), each (n, m)."""
    m = len(q0)
    if m == 1:  # one shared reference: the single-joint approach, unchanged
        a = _quintic(q0[0], q1[0], vmax[0], amax[0], cycle_s)
        return a[0][:, None], a[1][:, None], a[2][:, None]
    T = 0.0
    for a, b, v, acc in zip(q0, q1, vmax, amax, strict=True):
        d = abs(b - a)
        if d >= 1e-4:
            T = max(T, 0.2, 1.875 * d / (0.5 * v), math.sqrt(5.7735 * d / (0.5 * acc)))
    if T == 0.0:
        return np.zeros((0, m)), np.zeros((0, m)), np.zeros((0, m))
    n = int(math.ceil(T / cycle_s)) + 1
    s = np.minimum(np.arange(n) * cycle_s / T, 1.0)[:, None]
    p = 10 * s**3 - 15 * s**4 + 6 * s**5
    v = (30 * s**2 - 60 * s**3 + 30 * s**4) / T
    a = (60 * s - 180 * s**2 + 120 * s**3) / T**2
    d = np.asarray(q1, dtype=float) - np.asarray(q0, dtype=float)
    return np.asarray(q0, dtype=float) + d * p, d * v, d * a



def drive_joints(campaign: RobotCampaign, n_drives: int) -> list[int]:
    """The moving joint (index, column of the plan) each of ``n_drives`` drives follows: one
    drive per moving joint, in order; a campaign whose one joint has no drive of its own
    (a ``[joint]`` file) has all its ``[daq]`` drives follow that joint.

    Raises
    ------
    ValueError
        The drives do not match the joints.
    """
    k = len(campaign.joints)
    if any(j.drive is None for j in campaign.joints) and k == 1:
        return [0] * n_drives
    if k != n_drives:
        raise ValueError(f"Engine: {n_drives} drives for {k} joints")
    return list(range(k))


def emcy_text(drive: MasterDrive | str, code: int, register: int) -> str:
    """An EMCY in the words of the run's ``emcy`` events (in a run, and between runs:
    :mod:`daq.runtime.runner`); ``drive`` or its name (``"node 1"``)."""
    name = drive if isinstance(drive, str) else drive.name
    return f"{name}: EMCY 0x{code:04X} (error register 0x{register:02X})"


class Engine(Supervisor):
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
        self.interrupted = ""  # the name of the stop signal received (SIGINT, SIGTERM...)
        # paced: a SYNC later than this [s] is the master's own stall: the RPDO deadline it
        # gave the drives (0x1400.5, 3 cycles + rpdo_margin_ms), after which a drive faults anyway
        self.stall_s = rpdo_timeout_ms(campaign.cycle_s, True, cfg.rpdo_margin_ms) / 1000.0
        #: the moving joint each drive follows (its column of the plan)
        self.columns = drive_joints(campaign, len(drives))
        #: one reference for every drive, logged once on ``/setpoint``: the joint has no
        #: drive of its own (a [joint] file), the drives of [daq] all follow it
        self.shared_reference = any(j.drive is None for j in campaign.joints)
        joints = [campaign.joints[c] for c in self.columns]
        cut = campaign.control.velocity_cutoff_hz
        self.gains = [ControllerGains(**j.gains_kwargs(cut)) for j in joints]
        self.revolute = [j.revolute for j in joints]
        self.joint_limits = [j.limits for j in joints]
        #: the dotted key of each drive's joint table (messages: ``<key>.limits...``)
        self.joint_keys = [j.key for j in joints]
        self._init_limits(self.joint_limits, cfg)
        self.sync_msg = can.Message(arbitration_id=0x80, data=b"", is_extended_id=False)
        self.rpdo_msgs = [can.Message(arbitration_id=0x200 + d.node_id, data=bytes(
            d.specs[0].n_bytes), is_extended_id=False) for d in drives]
        self.sync_count = 0
        self.notes: list[str] = []  # start-up warnings, logged at cycle 0 of every run
        self.bus_lost = False  # a bus error ended a run: no more frames can be sent
        #: per-cycle torque monitor (daq.runtime.monitor.TorqueMonitor), None: none
        self.monitor: Any = None
        #: the last run's start-up lateness warning (one line), if any (the runner's summary)
        self.lateness_notes: list[str] = []
        #: while the start-up lateness check runs: take the frames already queued before each
        #: SYNC is sent (:meth:`_exchange`; every paced cycle does it too), and per drive
        #: count the TPDO1 frames so taken (the check only)
        self._peek = False
        self.pre_answers = [0] * len(drives)

    # -- one cycle ------------------------------------------------------------------------
    def _exchange(self, cycle: int, deadline: float) -> int:
        """SYNC and wait for the TPDOs; returns the bit mask of TPDOs received."""
        io = self.io
        io.begin_cycle()
        queued = 0
        if (self._peek or self.paced) and io.direct:
            # every paced cycle, and the start-up lateness check's (lockstep too): what is already
            # queued came before this SYNC, so it answers an earlier one (a drive one cycle behind,
            # every cycle: its answer misses the wait and waits for the next cycle). Taken here, it
            # is known for what it is, and it does not end the wait for this SYNC's answers: the
            # pump would take it as a full set and stop, and a master one cycle behind once (one
            # answer late) stayed behind for tens of cycles, the fresh answer always arriving after
            # the pump had stopped (paced, 10 ms, beside 4 busy loops: the check then counted 44-50
            # % on an on-time drive; daq.runtime.safety). Without a fresher one by the deadline it
            # is used (newest wins), and the cycle counts as late. During a paced plan the same:
            # taken as a full set, the queued answers had the loop run on the previous SYNC's
            # feedback on 46-97 % of the plan's cycles (1 ms, loopback bridge, no busy loop, load
            # 7-11), 0.1-2.1 % with this wait (benchmarks/bench_late_answers.py, plan_stale)
            self._drain()
            if self._peek:  # the check's tally only: not copied on every plan cycle
                self.pre_answers = io.answers.copy()
            queued, io.mask = io.mask, 0
        now = time.time()
        self.bus.send(self.sync_msg)
        io.sent(now, 0x80, b"")
        self.sync_count += 1
        timeout = deadline - time.perf_counter() if self.paced else self.cfg.lockstep_wait_s
        ok = io.pump(self.bus, timeout) if io.direct else io.wait(timeout)
        # every cycle, not only after one that timed out: take whatever else is queued, so
        # that the newest values win. The pump stops at the first full set, which may be late
        # answers to earlier SYNCs; after a stall of the drive's side they arrive as a burst
        # (through a bridge, spread over several cycles), and taken one set per cycle they
        # never cleared: the loop ran on TPDOs 55-124 ms old, flagged fresh, and oscillated
        # to the velocity limit (1 ms, loopback bridge, 4 busy loops;
        # tests/test_stale_feedback.py)
        self._drain()
        if queued and not ok:
            io.mask |= queued
            ok = io.mask == io.full
        return io.full if ok else io.mask

    def run_payload(self, index: int, payload: Any, ref: Any, log: RunLog,
                    sim_drive_cycle0: int) -> PayloadResult:
        """Execute one payload run and close its log.

        Phases (one cycle counter, no gaps): read the drives' state; enable them (CiA 402
        path, fault reset by a rising edge of bit 7) while holding the measured position;
        the start-up lateness check (``daq.lateness_check_s``, paced by default: hold that
        position, limits checked, counting the late or missing answers; refused above
        ``lateness_stop``, a warning above ``lateness_warn``:
        :func:`~daq.runtime.safety.lateness_verdict`); approach the plan's start with a
        quintic (segment -1) if needed; the plan; settle (``SETTLE_CYCLES``); shutdown
        (controlword 0x0006). On a fault, SIGINT or a watchdog: quick stop for
        ``quick_stop_cycles``, then disable voltage until the drives report it (at most
        ``DISABLE_MAX_CYCLES`` more cycles).

        Parameters
        ----------
        index : int
            Payload index in the campaign.
        payload : trajectories.robot_campaign.RobotPayload
        ref : trajectories.sampled.RobotPlan
            The planned reference, sampled every cycle, one column per moving joint:
            ``q`` [rad], ``dq`` [rad/s], ``ddq`` [rad/s^2], ``segment``, ``segment_names``.
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
        xmax = [min(32767, int(tm / t)) for tm, t in zip(self.tau_max, tpu, strict=True)]
        csp = [d.cfg.mode is Mode.CYCLIC_SYNC_POSITION for d in self.drives]
        drive_v = cfg.velocity_source == "drive"  # [daq] velocity_source (paced: drive)
        ctrls = [PositionController(g, cycle_s, rv, drive_velocity=drive_v)
                 for g, rv in zip(self.gains, self.revolute, strict=True)]
        q_lo, q_hi, v_max, tau_act_max = self.q_lo, self.q_hi, self.v_max, self.tau_act_max
        shared = self.shared_reference
        col = self.columns  # the plan's column each drive follows
        log_sp_axis = log.setpoint_axis
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
        last_cw = [CW_DISABLE] * n_dr  # controlword sent last cycle, per drive
        missed = 0
        cycle = 0
        fault_cycle = -1
        stop_cycle = -1
        status, reason = "done", ""
        t_wall0 = time.perf_counter()
        next_deadline = t_wall0 + cycle_s
        hb_check = 0
        ch_timing = None
        monitor = self.monitor
        if monitor is not None:
            monitor.begin(index, payload, log)
        mq, mdq, mtau = [0.0] * n_dr, [0.0] * n_dr, [0.0] * n_dr
        #: the start-up lateness check's tally while it runs: per drive, the cycles whose
        #: answer was missing at the deadline, came with an older one, or was queued before
        #: the SYNC (None: not counting)
        chk: list[int] | None = None
        #: of those, per drive, the cycles that ran on an answer queued before their SYNC
        stale = [0] * n_dr
        self.lateness_notes = []
        if self.paced:
            w = log._w
            sid = w.register_schema("jointid_msgs/msg/CycleTiming", "ros2msg",
                                    TIMING_SCHEMA.encode())
            ch_timing = w.register_channel("/timing", "cdr", sid)
            # a full chunk is compressed and written by a worker thread, not in the cycle
            # that filled it (0.3-1.5 ms at 0.1 s chunks: a missed cycle, bench_monitor.py)
            log.background_chunks()

        def do_cycle(q_refs: list[float], dq_refs: list[float], ddq_refs: list[float], seg: int,
                     mode: str) -> None:
            """One full cycle; ``mode`` is "enable", "run", "quick_stop", "disable", "shutdown";
            the references are one value per reference column (``col``)."""
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
                    stalled(late, t, mode)
                mask = self._exchange(cycle, next_deadline + 0.8 * cycle_s)
                next_deadline += cycle_s
            elif self.periodic:
                # SYNC comes from the periodic task: a cycle is the arrival of the TPDOs
                io.mask = 0
                io.answers = [0] * n_dr
                ok = io.pump(self.bus, 2.0 * cycle_s)
                mask = io.full if ok else io.mask
                t_sync = time.perf_counter()
                late = t_sync - next_deadline
                if late > 0.5 * cycle_s or late < -0.5 * cycle_s:
                    missed += 1
                    next_deadline = t_sync  # re-anchor on the SYNC train
                    late = 0.0 if cycle == 0 else late
                    if late > cycle_s:
                        # the TPDOs queued during the stall are old: take them all, the
                        # newest values win, and the next cycle waits for a fresh SYNC's
                        stalled(late, t, mode)
                        self._drain()
                        mask = io.full if io.mask == io.full else mask
                next_deadline += cycle_s
            else:
                t_sync = late = 0.0
                mask = self._exchange(cycle, 0.0)
            stopping = mode != "run" and mode != "enable"
            pre = self.pre_answers  # TPDO1 frames queued before the SYNC (the check only)
            m_ok = True  # every drive answered this cycle (the monitor's data are fresh)
            tpdo_fault = ""
            if io.emcy:  # before the state checks: the first one names the cause
                for dd, code, reg in io.emcy:  # every one is an event, also while stopping
                    why = emcy_text(self.drives[dd], code, reg)
                    if not stopping and not self._stop_reason:
                        self._fault(why, cycle, t, log, dd, kind="emcy")
                    else:
                        log.event(cycle, t, "emcy", why, dd)
                io.emcy.clear()
            for d in range(n_dr):
                flags = FLAG_STOPPING if stopping else 0
                b1 = 1 << (2 * d)
                if mask & (b1 | b1 << 1) == (b1 | b1 << 1):
                    sw[d], counts[d], tq[d] = unpack1(data[d][0])
                    vel[d] = unpack2(data[d][1])[0]
                    missing_run[d] = 0
                    if chk is not None and (io.answers[d] > 1 or pre[d]):
                        # an older answer came too, or the only one came before the SYNC:
                        # the cycle runs on the answer to an earlier SYNC (a steady lag)
                        chk[d] += 1
                        stale[d] += io.answers[d] == pre[d]
                else:
                    flags |= FLAG_TPDO_MISSING
                    if chk is not None:  # not there by the deadline: late or lost
                        chk[d] += 1
                    missing_run[d] += 1
                    if mode == "run" or mode == "enable":
                        missed += 0 if self.paced else 1
                    if missing_run[d] >= cfg.tpdo_timeout_cycles and not tpdo_fault:
                        tpdo_fault = (f"{self.drives[d].name}: TPDO missing for "
                                      f"{missing_run[d]} cycles (watchdog)")
                cd = col[d]
                q_ref = q_refs[cd]
                q = counts[d] * kq[d]
                dq = vel[d] * kq[d]
                tau_act = tq[d] * tpu[d]
                s = sw[d]
                if mode == "run" or mode == "enable":
                    if csp[d]:
                        x = 0
                        target_raw = round(q_ref * cpr[d])
                    else:
                        # no TPDO: the feedback held, then blended back (PDLaw.torque)
                        tau = ctrls[d].update(q_ref, dq_refs[cd], ddq_refs[cd], q,
                                              not flags & FLAG_TPDO_MISSING, dq)
                        x = round(tau / tpu[d])
                        if x > xmax[d]:
                            x = xmax[d]
                        elif x < -xmax[d]:
                            x = -xmax[d]
                        target_raw = 0
                    if mode == "run":
                        cw = CW_RUN
                    elif flags:
                        # no answer this cycle: the drive may already be one step further
                        # than its last statusword says; a step from the stale state (e.g.
                        # 0x06 to a drive that just reached OPERATION ENABLED) would undo
                        # it, so repeat the command it already has (level-triggered)
                        cw = last_cw[d]
                    else:
                        try:
                            st = state_from_statusword(s)
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
                last_cw[d] = cw
                payload_bytes = packs[d](cw, target_raw if csp[d] else x)
                m = msgs[d]
                m.data = payload_bytes
                send(m)
                io_sent(time.time(), m.arbitration_id, payload_bytes)
                log_state(d, cycle, t, q, dq, x * tpu[d] if not csp[d] else math.nan, tau_act,
                          counts[d], vel[d], x, tq[d], s, flags)
                mq[d], mdq[d], mtau[d] = q, dq, tau_act
                m_ok = m_ok and not flags & FLAG_TPDO_MISSING
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
                    if not q_lo[d] <= q <= q_hi[d] and not flags:
                        why = (f"position limit: q = {q:.4f} outside [{q_lo[d]:.4g}, "
                               f"{q_hi[d]:.4g}]")
                    elif (dq > v_max[d] or -dq > v_max[d]) and not flags:
                        why = f"velocity limit: |dq| = {abs(dq):.4f} > {v_max[d]:.4g}"
                    elif (tau_act > tau_act_max[d] or -tau_act > tau_act_max[d]) and not flags:
                        why = (f"torque limit: |torque actual| = {abs(tau_act):.1f} > "
                               f"{tau_act_max[d]:.4g}")
                    elif abs(q_ref - q) > cfg.max_following_error and not flags:
                        why = (f"following error: |q_ref - q| = {abs(q_ref - q):.4f} > "
                               f"{cfg.max_following_error:g}")
                    elif st_now is not None and st_now is not State.OPERATION_ENABLED:
                        why = f"drive left OPERATION_ENABLED (now {st_now.name})"
                    if why:
                        self._fault(f"{self.drives[d].name}: {why}", cycle, t, log, d)
            if tpdo_fault and not stopping:
                self._fault(tpdo_fault, cycle, t, log, -1)
            if monitor is not None and mode == "run" and not self._stop_reason:
                why, axis = monitor.step(cycle, t, mq, mdq, mtau, log, valid=m_ok)
                if why:  # a collision with stop configured: the stop sequence
                    self._fault(why, cycle, t, log, axis, kind="collision")
            if shared:
                log_sp(cycle, t, q_refs[0], dq_refs[0], ddq_refs[0], seg,
                       round(q_refs[0] * cpr[0]) if csp[0] else 0)
            else:
                for d in range(n_dr):
                    cd = col[d]
                    log_sp_axis(d, cycle, t, q_refs[cd], dq_refs[cd], ddq_refs[cd], seg,
                                round(q_refs[cd] * cpr[d]) if csp[d] else 0)
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
                    self._check_heartbeats(cycle, t, log)
                if self.interrupted and not self._stop_reason:
                    self._stop_reason = ("interrupted", interrupt_reason(self.interrupted))
                    self._fault_cycle = cycle
                    log.event(cycle, t, "operator", f"{self.interrupted}: stopping")
            cycle += 1

        def enabled_all() -> bool:
            for d in range(n_dr):
                try:
                    if state_from_statusword(sw[d]) is not State.OPERATION_ENABLED:
                        return False
                except ValueError:
                    return False
            return True

        def stalled(late: float, t: float, mode: str) -> None:
            """The master's own loop was late by ``late`` [s] (> 1 cycle): a stall (host,
            swap, SIGSTOP) during which the drives ran on their last command. Beyond the
            RPDO deadline the drives were given it stops the run; a shorter one names itself
            in the reason of an EMCY read in the same or the next cycle (a drive that
            faulted meanwhile, e.g. on SYNC loss: its EMCY waited in the queue)."""
            self._stall = (cycle, late)
            if late > self.stall_s and mode in ("run", "enable") and not self._stop_reason:
                self._fault(f"master stalled for {late:.3f} s (the cycle loop was late by more "
                            f"than the drives' RPDO deadline {self.stall_s:.3f} s)", cycle, t,
                            log, -1, kind="watchdog")

        def report(phase: str, seg: int, n_total: int) -> None:
            if self.progress is not None:
                name = seg_names[seg] if 0 <= seg < len(seg_names) else phase
                try:
                    self.progress(Progress(index, len(c.payloads), name, cycle, n_total,
                                           self.load.share, missed, phase))
                except Exception:  # noqa: BLE001 - e.g. EIO on a closed terminal (SIGHUP)
                    self.progress = None  # the display is gone; the run goes on

        self._stop_reason: tuple[str, str] | None = None
        self._fault_cycle = -1
        self._stall = (-2, 0.0)
        net = self.net
        if net.notifier is not None:  # the main thread receives itself during the run
            net.notifier.stop(1.0)
            net.notifier = None
        io.direct = True
        # the plan's columns as lists, before the schedule starts (at 600 000 cycles the
        # conversion takes ~0.15 s: between enabling and the first plan cycle it would be a
        # stall longer than the drives' RPDO deadline)
        ref_q = np.asarray(ref.q, dtype=float).reshape(len(ref.q), -1)
        plan_cols = (ref_q.T.tolist(),
                     np.asarray(ref.dq, dtype=float).reshape(ref_q.shape).T.tolist(),
                     np.asarray(ref.ddq, dtype=float).reshape(ref_q.shape).T.tolist(),
                     np.asarray(ref.segment).astype(int).tolist())
        gc_was = gc.isenabled()
        if cfg.gc_freeze:  # no 10-50 ms full collection inside the run (bench_daq.py)
            gc.collect()
            gc.freeze()
            gc.disable()
        # the schedule starts now, not before the notifier stopped (up to its poll period)
        # and the collection: either would make the first SYNC late (a missed cycle)
        t_wall0 = time.perf_counter()
        next_deadline = t_wall0 + cycle_s
        sync_task = None
        if self.periodic:
            # first cycle's deadline: one period after the periodic task starts
            sync_task = self.bus.send_periodic(self.sync_msg, cycle_s)
            next_deadline = time.perf_counter() + cycle_s
            log.event(0, 0.0, "info", f"SYNC from send_periodic ({type(sync_task).__name__})")
        for note in self.notes:
            log.event(0, 0.0, "warning", note)
        n_col = len(c.joints)
        zero = [0.0] * n_col
        run_log = log

        def stop_sequence() -> None:
            """Quick stop for ``quick_stop_cycles``, then disable voltage until every drive
            reports it (at most ``DISABLE_MAX_CYCLES`` + 1 cycles)."""
            q_last = [counts[d] * kq[d] for d in range(n_col)]
            report("stop", -1, cycle)
            for _ in range(cfg.quick_stop_cycles):
                do_cycle(q_last, zero, zero, -1, "quick_stop")
            for _ in range(DISABLE_MAX_CYCLES + 1):
                do_cycle(q_last, zero, zero, -1, "disable")
                if self._all_off(sw):
                    break

        def stopped_event() -> int:
            """Log whether the drives confirmed the stop; the stop cycle (-1: not confirmed)."""
            off = self._all_off(sw)
            msg = ("drives disabled" if off else "drives did not confirm the stop: "
                   + ", ".join(f"{d.name} sw=0x{sw[k]:04X}" for k, d in enumerate(self.drives)))
            log.event(cycle - 1, (cycle - 1) * cycle_s,
                      "stop" if status != "done" else "info", msg)
            return cycle - 1 if off else -1

        switch_was = sys.getswitchinterval()
        try:
            if self.paced and cfg.switch_interval_s > 0:
                # the loop, waking from its sleep, waits for the GIL at most about this long
                # when another thread holds it (simulated drives, the chunk writer), not 5 ms
                sys.setswitchinterval(cfg.switch_interval_s)
            try:
                # 1. enable, holding the position measured at the first answer
                z0 = [0.0] * n_dr
                do_cycle(z0, z0, z0, -1, "disable")  # first SYNC: read the drives' state
                q_hold = [counts[d] * kq[d] for d in range(n_col)]
                log.event(cycle, cycle * cycle_s, "info", "start position "
                          + ", ".join(f"{x:.5f}" for x in q_hold))
                for _ in range(ENABLE_MAX_CYCLES):
                    if enabled_all() or self._stop_reason:
                        break
                    do_cycle(q_hold, zero, zero, -1, "enable")
                if not enabled_all() and not self._stop_reason:
                    names = ", ".join(f"{d.name} {state_from_statusword(sw[k]).name}"
                                      for k, d in enumerate(self.drives))
                    self._fault(f"drives not enabled after {ENABLE_MAX_CYCLES} cycles "
                                f"({names})", cycle, cycle * cycle_s, log, -1)
                if not self._stop_reason:
                    log.event(cycle, cycle * cycle_s, "info", "operation enabled")
                if not self._stop_reason and cfg.lateness_check_s > 0:
                    # 1b. the start-up lateness check: hold the start position (limits and
                    # following error checked), count the late or missing answers per drive
                    n_chk = max(1, math.ceil(cfg.lateness_check_s / cycle_s - 1e-9))
                    chk = [0] * n_dr
                    self._peek, self.pre_answers = True, [0] * n_dr
                    done = 0
                    report("check", -1, cycle + n_chk)
                    for _ in range(LATENESS_MAX_ROUNDS):
                        for _ in range(n_chk):
                            do_cycle(q_hold, zero, zero, -1, "run")
                            if self._stop_reason:
                                break
                        done += n_chk
                        if self._stop_reason:
                            break
                        level, why, unsure = lateness_verdict(
                            chk, done, [redact_url_secret(d.cfg.channel or cfg.channel)
                                        for d in self.drives],
                            [d.name for d in self.drives], cfg, cycle_s, stale)
                        if not unsure:
                            break
                    shares = ", ".join(
                        f"{d.name} {chk[k] / max(1, done):.1%}"
                        + (f" of which {stale[k]} on an earlier SYNC's answer" if stale[k] else "")
                        for k, d in enumerate(self.drives))
                    chk = None
                    self._peek, self.pre_answers = False, [0] * n_dr
                    if not self._stop_reason:
                        log.event(cycle, cycle * cycle_s, "info", f"start-up lateness check: "
                                  f"late or missing answers over {done} cycles: {shares}")
                        if level == "stop":
                            self._fault(why, cycle, cycle * cycle_s, log, -1, kind="watchdog")
                        elif level == "warning":
                            log.event(cycle, cycle * cycle_s, "warning", why)
                            self.lateness_notes.append(why)
                            logger.warning("%s", why)
                if not self._stop_reason:
                    # 2. approach the plan start, then the plan, then settle (columns of
                    # the plan built before the schedule started: nothing long here)
                    lims = self.joint_limits[:n_col]
                    aq, adq, addq = _approach(q_hold, ref_q[0].tolist(),
                                              [lim.max_velocity for lim in lims],
                                              [lim.max_acceleration for lim in lims], cycle_s)
                    hold_end = [[x] * SETTLE_CYCLES for x in ref_q[-1].tolist()]
                    still = [[0.0] * SETTLE_CYCLES for _ in range(n_col)]
                    phases = ((aq.T.tolist(), adq.T.tolist(), addq.T.tolist(),
                               [-1] * len(aq)), plan_cols,
                              (hold_end, still, still, [-1] * SETTLE_CYCLES))
                    n_total = cycle + sum(len(ph[3]) for ph in phases)
                    report("run", -1, n_total)
                    i = 0
                    for cq, cdq, cddq, rseg in phases:
                        for k in range(len(rseg)):
                            do_cycle([x[k] for x in cq], [x[k] for x in cdq],
                                     [x[k] for x in cddq], rseg[k], "run")
                            if self._stop_reason:
                                break
                            if i % 250 == 0:
                                report("run", rseg[k], n_total)
                            i += 1
                        if self._stop_reason:
                            break
                # 3. stop: normal shutdown or quick stop + disable
                if self._stop_reason:
                    status, reason = self._stop_reason
                    fault_cycle = self._fault_cycle
                    stop_sequence()
                else:
                    q_last = [counts[d] * kq[d] for d in range(n_col)]
                    for _ in range(SHUTDOWN_CYCLES):
                        do_cycle(q_last, zero, zero, -1, "shutdown")
                stop_cycle = stopped_event()
            except BUS_ERRORS as exc:
                if not log_failed(exc):
                    raise
                # the log's file failed (disk full, file-size limit, I/O error), not the
                # bus: the drives still listen. Go on without a log, and stop them.
                err = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
                why = f"log write failed: {run_log.path}: {err}"
                log = NullLog(run_log.path)
                log_state = log_sp = log_sp_axis = log_frames = log.state
                status = "stopped"
                if self._stop_reason:  # a fault was being handled: keep its cause first
                    reason = f"{self._stop_reason[1]}; then {why}"
                else:
                    reason = why
                    self._fault_cycle = cycle
                self._stop_reason = (status, reason)
                fault_cycle = self._fault_cycle
                stop_sequence()
                stop_cycle = stopped_event()
            except Exception as exc:  # a bug in the loop: stop the drives, then let it out
                status = "stopped"
                reason = f"internal error: {type(exc).__name__}: {exc}".splitlines()[0]
                if self._fault_cycle < 0:
                    self._fault_cycle = cycle
                fault_cycle = self._fault_cycle
                self._stop_reason = (status, reason)
                try:
                    log.event(cycle, cycle * cycle_s, "fault", reason)
                    stop_sequence()
                    stop_cycle = stopped_event()
                except Exception:  # noqa: BLE001, S110 - the same bug again: the drives'
                    pass  # own watchdogs (RPDO timer, SYNC loss, heartbeat) remain
                raise
        except BUS_ERRORS as exc:  # the bus itself failed: nothing more can be sent
            status = "stopped"
            reason = f"bus lost: {type(exc).__name__}: {exc}".splitlines()[0]
            fault_cycle = self._fault_cycle if self._fault_cycle >= 0 else cycle
            self.bus_lost = True
            log.event(cycle, cycle * cycle_s, "fault", reason)
        finally:
            wall = time.perf_counter() - t_wall0
            self._peek = False
            sys.setswitchinterval(switch_was)
            if cfg.gc_freeze:
                gc.unfreeze()
                if gc_was:
                    gc.enable()
            if sync_task is not None and not self.bus_lost:
                sync_task.stop()
            io.direct = False
            if not self.bus_lost:
                net.notifier = can.Notifier(net.bus, net.listeners, net.NOTIFIER_CYCLE)
            if timing:
                lateness = np.array([x[1] for x in timing])
            try:
                run_log.close({
                    "status": status, "reason": reason, "cycles": str(cycle),
                    "fault_cycle": str(fault_cycle), "stop_cycle": str(stop_cycle),
                    "missed": str(missed), "wall_s": f"{wall:.3f}",
                    "sync_offset": str(sim_drive_cycle0),
                })
            except OSError:  # still failing (the reason says why): the file keeps its
                pass  # complete chunks, read back up to there with a "truncated" warning
        arm_m = getattr(payload, "arm_m", None)  # a robot payload's is None (com_m instead)
        return PayloadResult(index, float(payload.mass_kg),
                             math.nan if arm_m is None else float(arm_m), run_log.path,
                             cycle, status, reason, fault_cycle, stop_cycle, missed, wall,
                             lateness)
