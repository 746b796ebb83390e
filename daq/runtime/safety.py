"""Safety supervision of the cycle loop: the stop sequence's controlwords and lengths, the
supervision limits, the fault latch and the heartbeat watchdog (see :mod:`daq.runtime.engine`
for where they act in a cycle); the signals that stop a run (:class:`StopSignals`) and what
tells a failing log from a failing bus (:func:`log_failed`).

Signals
-------
SIGINT (Ctrl-C), SIGTERM (``kill``, ``timeout``, ``systemctl stop``) and SIGHUP (the
terminal closed) all stop a run the same way: while a payload runs, the engine finishes the
cycle, quick-stops and disables the drives and closes the log (status "interrupted", the
signal named); before or between payloads (start-up, the operator prompt) they raise
:class:`RunInterrupted` at once (no drive is enabled then), which the runner's ``finally``
cleans up after. The ``jointid`` exit code is 128 + the signal number (130, 143, 129).

Start-up lateness check
-----------------------
A busy host answers late: the drive's answer to SYNC k misses cycle k's deadline and comes in
cycle k+1 (which takes it as its own, or with its own, the newest winning); past a few in a
row the TPDO watchdog stops the run mid-plan, or the drives' own RPDO deadline faults them.
A drive, bridge or host that answers *every* SYNC after the master's wait makes every cycle
run on the state one cycle old without a missing answer: a steady lag (for identification a
constant time shift of the log, for the loop a phase lag). So before the plan moves (drives
enabled, holding the start position, limits checked) the engine holds for ``[daq]
lateness_check_s`` (0.5 s on the paced clock, none in lockstep unless given) and counts per
drive the cycles that did not run on their own SYNC's answer: missing at the deadline, come
with an older one (two TPDO1 in the cycle), or the only answer already queued before the
cycle's SYNC was sent (an answer to an earlier SYNC). During the hold the engine takes what is
queued before each SYNC, and a set so taken does not end the wait for this SYNC's answers;
without a fresher one by the deadline it is used and the cycle counts. One late answer counts
twice (the cycle without, the cycle with two), a lost one once, a steady lag on every cycle
it lasts (until 2026-11-29 only at its ends: 0 % on a hold inside it, a 25-cycle lag in the
hold 2 cycles instead of 26, ``tests/test_late_answers.py``). :func:`lateness_verdict`: per
bus, the share of its drives' cycles so counted; the worst bus above ``lateness_stop`` refuses
the run (a ``watchdog`` event, the stop sequence: drives disabled, log closed; the line names
the bus, each drive's share and how many of its cycles ran on an earlier SYNC's answer),
above ``lateness_warn`` the run goes on with a warning (log event, run summary). A share
within two binomial sigmas of ``lateness_stop`` is measured again, at most
:data:`LATENESS_MAX_ROUNDS` holds in all.

Measured (``tests/test_late_answers.py``; two drives, lockstep 2 ms, 200-cycle hold): node 2
answering every SYNC after the master's wait, node 1 on time: node 2 100 %, node 1 0 %, the
bus 50 %, refused (before: 0 %, the run went on); on the paced clock (10 ms, 0.5 s hold, one
drive, beside 4 busy loops at a load average of 8-10) such a drive 70 and 74 % (the cycles
where the drive's thread answered after the next SYNC look on time), an on-time one 0-6 %.
The wait past a queued set matters: without it, an on-time drive beside 4 busy loops counted
44 and 50 % in two of four such holds, the master itself staying a cycle behind after one
late answer, the fresh answer always arriving just after its wait had stopped.

What it cannot see: an answer a whole cycle old that arrives after the next SYNC was sent
(a latency between one cycle and the next deadline, or a drive reporting the state latched at
the SYNC before): a TPDO carries no SYNC number, so it looks on time
(``FaultInjector.late_tpdo_*`` with share 1 is such a drive: 0 % counted). With
``sync_source = "periodic"`` the SYNC comes from a timer and nothing is taken before it: a
steady lag counts at its ends only. In lockstep (virtual channels only) the master waits for
every answer up to ``lockstep_wait_s`` and the simulated drives answer inside the SYNC's
send, so only an injected lag, or an answer later than ``lockstep_wait_s``, makes a cycle run
on an earlier answer; there is no hold unless ``lateness_check_s`` is given, and with it the
count is deterministic (a steady lag costs ``lockstep_wait_s`` per held cycle). The run
itself (the plan) waits past a queued set the same way on the paced clock
(``Engine._exchange``): before, the master's wait stopped at a queued set, so one late
answer kept the loop a cycle behind until an answer came in time to be drained with it
(``benchmarks/bench_late_answers.py``, ``plan_stale``: 1 ms through the loopback bridge, no
busy loop, a load average of 7-11 from other work: 46-97 % of the plan's cycles ran on the
answer before; with the wait in every paced cycle 0.1-2.1 %; the same bench beside a CI
copy of the test suite: 48, 67, 53 % before, 1.7, 5.1, 3.5 % after).

Calibration (``benchmarks/bench_late_answers.py --periods 2 --runs 3``, the drive behind a
loopback python-can-remote bridge in another process, the master paced, on the project's
shared 2-core host at a load average of 13-16 from other work; busy: 4 ``nice -n 10 python
-c 'while 1: pass'`` beside, the bench itself under ``nice -n 10``), share measured:

==========  ===============  ==================================================
 cycle       no busy loop     4 busy loops
==========  ===============  ==================================================
 1 ms        2.8, 5.8, 15.8   44.6, 47.0, 63.0 (two of three runs then stopped
                              mid-plan: TPDO missing for 50 cycles)
 4 ms        0.8, 2.4, 18.4   43.2, 48.0, 48.8 (27-32 % of the plan's cycles
                              without an answer)
==========  ===============  ==================================================

and 26.4, 35.2, 40.0 at 4 ms beside 2 busy loops; the master and a simulated drive in one
process on python-can's virtual bus, no busy loop: 2.4-4.8 at 1 ms, 7.6-14.0 at 2 ms. Hence
``lateness_stop = 0.3`` (above every run without busy loops, below every run beside 4) and
``lateness_warn = 0.1`` (above the usual runs without busy loops, which a host loaded by
others exceeds now and then). On real drives on socketcan the share should be near 0.

The count that waits past a queued set and counts an earlier SYNC's answer (2026-11-29, the
same bench at 1 ms, ``--periods 2 --runs 3``, a load average of 7-11 from other work) measured
more for the same host: no busy loop 2.2, 26.8, 34.4 and 1.4, 7.2, 29.0 % (the old count in
the same hour: 0.8, 2.4, 19.6), 4 busy loops 44.4, 66.0, 72.2 %. The limits are unchanged, so
on such a host a start without busy loops is now refused now and then (one hold in six).
With the paced wait in every cycle, beside a CI copy of the test suite and two helpers' work:
22.6, 27.6, 12.4 % (15.0, 3.0, 34.8 % without it, the same hour).
"""

from __future__ import annotations

import inspect
import re
import signal
import threading
from types import TracebackType
from typing import Any

from daq import ConfigError
from daq.protocol.cia402 import State, state_from_statusword

from .config import DaqConfig
from .mcaplog import RunLog

CW_RUN = 0x0F
CW_QUICK_STOP = 0x02
CW_DISABLE = 0x00
CW_SHUTDOWN = 0x06
DISABLE_MAX_CYCLES = 5
SHUTDOWN_CYCLES = 3

_URL_SECRET = re.compile(r"\b(wss?://[^/\s]+)/[^\s:+]+")


def redact_url_secret(text: str) -> str:
    """``text`` with the path of every ``ws://``/``wss://`` URL replaced by ``<token>``.

    A python-can-remote bridge's URL carries its access token as its path
    (``ws://127.0.0.1:<port>/<token>``, :mod:`sim_drivers.bridge`); the log keeps host and
    port, never the token. The same URL always gives the same text, so the bus mapping of
    ``jointid export`` is unchanged.
    """
    return _URL_SECRET.sub(r"\1/<token>", text)


#: the start-up lateness check's hold: at most this many rounds of ``lateness_check_s`` (a
#: share within two binomial sigmas of ``lateness_stop`` is measured again, up to the bound;
#: module docstring)
LATENESS_MAX_ROUNDS = 3

#: signals that stop a run with the stop sequence (the SIGINT path)
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


class RunInterrupted(KeyboardInterrupt):
    """A stop signal arrived while no payload was running (start-up, operator prompt).

    A :class:`KeyboardInterrupt`, so that every path that handles Ctrl-C handles it;
    ``signum`` is the signal (the exit code is 128 + it).
    """

    def __init__(self, signum: int, detail: str = "") -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum
        #: what was left behind, for the one line of the entry point (``jointid:
        #: interrupted (SIGINT): <detail>``; "" for none)
        self.detail = detail


def interrupt_signal(reason: str) -> int:
    """The signal named in the reason of a run "interrupted" (:func:`interrupt_reason`):
    SIGTERM or SIGHUP when it names one, else SIGINT."""
    for s in (signal.SIGTERM, signal.SIGHUP):
        if s.name in reason:
            return int(s)
    return int(signal.SIGINT)


def interrupt_reason(name: str) -> str:
    """The one-line reason of a run stopped by signal ``name`` ("SIGINT", "SIGTERM"...)."""
    if name == "SIGINT":
        return "interrupted by the operator (SIGINT)"
    return f"interrupted by {name}"


class StopSignals:
    """SIGINT, SIGTERM and SIGHUP handlers for the duration of a campaign (main thread only;
    elsewhere nothing is installed and Python's defaults stay).

    While :attr:`engine` is set (a payload runs) a signal sets ``engine.interrupted`` to
    its name and the engine stops the drives at the end of the cycle; while :attr:`closing`
    (the runner's clean-up) it is only noted; otherwise it raises :class:`RunInterrupted` in
    the main thread.
    """

    def __init__(self) -> None:
        self.engine: Any = None
        self.closing = False  # cleaning up: a signal is noted, nothing raised
        self.received = ""
        self._old: dict[int, Any] = {}

    def install(self) -> None:
        if threading.current_thread() is not threading.main_thread():
            return
        for s in STOP_SIGNALS:
            self._old[s] = signal.signal(s, self._on_signal)

    def restore(self) -> None:
        old, self._old = self._old, {}
        for s, h in old.items():
            signal.signal(s, h)

    def _on_signal(self, signum: int, frame: Any) -> None:
        self.received = self.received or signal.Signals(signum).name
        if self.closing:
            return
        if self.engine is not None:
            if not self.engine.interrupted:
                self.engine.interrupted = signal.Signals(signum).name
            return
        raise RunInterrupted(signum)


_LOG_FILE = inspect.getfile(RunLog)


def log_failed(exc: BaseException) -> bool:
    """Whether ``exc`` (an OSError) was raised while writing the run log's file rather than
    by the bus: its traceback passes through the log writer's module."""
    tb: TracebackType | None = exc.__traceback__
    while tb is not None:
        if tb.tb_frame.f_code.co_filename == _LOG_FILE:
            return True
        tb = tb.tb_next
    return False


class NullLog:
    """Stands in for a run log whose file failed (disk full, file-size limit): the stop
    sequence runs the same cycles and logs nothing."""

    start_ns = 0
    cycle_ns = 0

    def __init__(self, path: Any) -> None:
        self.path = path

    def _discard(self, *args: Any, **kwargs: Any) -> None:
        return None

    state = setpoint = setpoint_axis = frames = event = _add = _discard


class Supervisor:
    """Mixin of :class:`daq.runtime.engine.Engine`: supervision limits, the fault latch (the
    first cause wins), the heartbeat watchdog and the "all drives off" check.

    The per-cycle limit and following-error checks stay inline in the engine's cycle (hot
    path); the values they compare against are set here by :meth:`_init_limits`.
    """

    _stall: tuple[int, float] = (-2, 0.0)  # (cycle, lateness [s]) of the last stall seen
    #: per drive, the dotted key of its joint's table (``joint``, ``robot.joints.<name>``)
    joint_keys: list[str]

    def _init_limits(self, limits: Any, cfg: DaqConfig) -> None:
        """Per drive: ``[daq.limits]``, else that drive's joint limits (``limits``, one
        :class:`trajectories.campaign.JointLimits` per drive) with 5 % of the range / 20 % of
        the speed and torque as margins. Sets lists ``q_lo``, ``q_hi``, ``v_max``,
        ``tau_max``, ``tau_act_max`` (one entry per drive)."""
        self.q_lo, self.q_hi, self.v_max, self.tau_max, self.tau_act_max = [], [], [], [], []
        for lim in limits:
            span = lim.position[1] - lim.position[0]
            if cfg.position_limits is not None:
                lo, hi = cfg.position_limits
            else:
                lo, hi = lim.position[0] - 0.05 * span, lim.position[1] + 0.05 * span
            tau = cfg.max_torque if cfg.max_torque is not None else lim.max_torque
            self.q_lo.append(lo)
            self.q_hi.append(hi)
            self.v_max.append(cfg.max_velocity if cfg.max_velocity is not None
                              else 1.2 * lim.max_velocity)
            self.tau_max.append(tau)
            self.tau_act_max.append(tau * 1.2)

    def check_drive_limits(self) -> None:
        """Refuse a velocity watchdog no drive could ever trip: ``v_max`` of a drive above its
        max motor speed 0x6080 [rpm] (the EDS default) seen at the joint (rpm / 60 x 2 pi /
        gear ratio), unless ``daq.allow_beyond_drive_limits``. Called after the start-up
        (scaling known), before any drive is enabled.

        Raises
        ------
        daq.ConfigError
            Naming the key that set the limit (``daq.limits.max_velocity``,
            ``joint.limits.max_velocity`` or ``robot.joints.<name>.limits.max_velocity``),
            the drive and its 0x6080.
        """
        if self.cfg.allow_beyond_drive_limits:
            return
        for k, (d, sc) in enumerate(zip(self.drives, self.scalings, strict=True)):
            rpm = d.max_motor_speed_rpm()
            if rpm is None:
                continue
            joint_max = rpm / 60.0 * sc.rad_per_count * sc.encoder_counts_per_rev  # [rad/s]
            if self.v_max[k] <= joint_max:
                continue
            key = ("daq.limits.max_velocity" if self.cfg.max_velocity is not None
                   else f"{self.joint_keys[k]}.limits.max_velocity")
            raise ConfigError(
                f"{self.cfg.source or 'campaign'}: {key}: the velocity watchdog at "
                f"{self.v_max[k]:.4g} rad/s is beyond {d.name}'s max motor speed 0x6080 = "
                f"{rpm} rpm in {d.cfg.eds.name} ({joint_max:.4g} rad/s at the joint, gear ratio "
                f"{sc.gear_ratio:g}) and could never trip; lower it or set "
                f"daq.allow_beyond_drive_limits = true")

    def _drain(self) -> int:
        """Take every frame already received (the main thread receives during a run): after
        a stall of the master they wait in the queue, heartbeats among them; the newest
        values win. Returns the number of frames taken."""
        if not self.io.direct:
            return 0
        recv, on = self.bus.recv, self.io.on_message_received
        n = 0
        while (msg := recv(0.0)) is not None:
            on(msg)
            n += 1
        return n

    def _check_heartbeats(self, cycle: int, t: float, log: RunLog) -> None:
        """Fault on the first drive whose heartbeat has been silent for more than
        ``daq.heartbeat_timeout_s`` (the engine calls this every 16 cycles) on the heartbeat
        clock of :class:`~daq.runtime.cycle_io.CycleIO`: wall time, or simulated time with
        simulated drives in lockstep. Before blaming a drive, the frames waiting in the
        receive queue are taken (:meth:`_drain`): a master that stalled has not read the
        heartbeats that came meanwhile."""
        now = self.io.clock()
        if any(self.drives[dd].cfg.heartbeat_ms and now - self.io.hb_time[dd]
               > self.cfg.heartbeat_timeout_s for dd in range(len(self.drives))):
            self._drain()
            now = self.io.clock()
        for dd in range(len(self.drives)):
            if self.drives[dd].cfg.heartbeat_ms and (
                    now - self.io.hb_time[dd] > self.cfg.heartbeat_timeout_s):
                self._fault(f"{self.drives[dd].name}: heartbeat lost (none for "
                            f"{now - self.io.hb_time[dd]:.2f} s > "
                            f"{self.cfg.heartbeat_timeout_s:g} s)", cycle, t, log, dd,
                            kind="watchdog")
                break

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
        stall_cycle, late = self._stall
        if kind == "emcy" and 0 <= cycle - stall_cycle <= 1:
            # a drive's reaction to the master's stall (SYNC loss, RPDO timeout) read when
            # the master woke up: the stall is the cause
            why = f"master stalled for {late:.3f} s, then {why}"
        self._stop_reason = ("stopped", why)
        self._fault_cycle = cycle
        log.event(cycle, t, kind, why, axis)


def lateness_verdict(late: list[int], cycles: int, buses: list[str], names: list[str],
                     cfg: DaqConfig, cycle_s: float,
                     stale: list[int] | None = None) -> tuple[str, str, bool]:
    """The start-up lateness check's verdict on a hold of ``cycles`` cycles.

    ``late[d]``: the cycles of drive ``d`` (named ``names[d]``, on bus ``buses[d]``) whose
    answer was missing at the cycle's deadline, came with an older one, or was there before
    the cycle's SYNC was sent (an answer to an earlier SYNC: a steady lag counts on every
    cycle). ``stale[d]`` (optional, named in the line): of those, the cycles whose only
    answer came before their SYNC. Per bus, the share of its drives' answers that were late
    or missing; the worst bus decides: above ``cfg.lateness_stop`` the run is refused, above
    ``cfg.lateness_warn`` it goes on with a warning.

    Returns
    -------
    (str, str, bool)
        The level (``"stop"``, ``"warning"`` or ``""``: within the limits), one line naming
        the bus and what was measured (``""`` within the limits), and whether the share is
        within two binomial sigmas of ``lateness_stop`` above the warning limit (measure
        longer to decide).
    """
    worst, bus = -1.0, ""
    for b in dict.fromkeys(buses):
        ds = [d for d in range(len(late)) if buses[d] == b]
        share = sum(late[d] for d in ds) / max(1, cycles * len(ds))
        if share > worst:
            worst, bus = share, b
    ds = [d for d in range(len(late)) if buses[d] == bus]
    n = max(1, cycles * len(ds))
    stop, warn = cfg.lateness_stop, cfg.lateness_warn
    sigma = (max(stop * (1.0 - stop), 1.0 / n) / n) ** 0.5
    unsure = worst > warn and abs(worst - stop) < 2.0 * sigma
    if worst <= warn:
        return "", "", unsure
    level = "stop" if worst > stop else "warning"
    per = ", ".join(f"{names[d]} {late[d] / max(1, cycles):.0%}" + (
        f" of which {stale[d]} on an earlier SYNC's answer" if stale and stale[d] else "")
        for d in ds)
    what = (f"bus {bus}: {worst:.1%} of the drives' answers late or missing over the "
            f"{cycles} cycles ({cycles * cycle_s:.2f} s) of the start-up hold ({per})")
    if level == "stop":
        return level, (f"start-up lateness check: {what}, above daq.lateness_stop "
                       f"({stop:.0%}): the host answers too late for a {cycle_s * 1e3:g} ms "
                       f"cycle (free the CPU, lengthen control.cycle_s, or raise "
                       f"daq.lateness_stop)"), unsure
    return level, (f"start-up lateness check: {what}, above daq.lateness_warn "
                   f"({warn:.0%}, refused above {stop:.0%})"), unsure
