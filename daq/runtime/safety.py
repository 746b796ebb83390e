"""Safety supervision of the cycle loop: the stop sequence's controlwords and lengths, the
supervision limits, the fault latch and the heartbeat watchdog (see :mod:`daq.runtime.engine`
for where they act in a cycle)."""

from __future__ import annotations

from typing import Any

from daq.protocol.cia402 import State, state_from_statusword

from .config import DaqConfig
from .mcaplog import RunLog

CW_RUN = 0x0F
CW_QUICK_STOP = 0x02
CW_DISABLE = 0x00
CW_SHUTDOWN = 0x06
DISABLE_MAX_CYCLES = 5
SHUTDOWN_CYCLES = 3


class Supervisor:
    """Mixin of :class:`daq.runtime.engine.Engine`: supervision limits, the fault latch (the
    first cause wins), the heartbeat watchdog and the "all drives off" check.

    The per-cycle limit and following-error checks stay inline in the engine's cycle (hot
    path); the values they compare against are set here by :meth:`_init_limits`.
    """

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

    def _check_heartbeats(self, cycle: int, t: float, log: RunLog) -> None:
        """Fault on the first drive whose heartbeat has been silent for more than
        ``daq.heartbeat_timeout_s`` (the engine calls this every 16 cycles) on the heartbeat
        clock of :class:`~daq.runtime.cycle_io.CycleIO`: wall time, or simulated time with
        simulated drives in lockstep."""
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
        self._stop_reason = ("stopped", why)
        self._fault_cycle = cycle
        log.event(cycle, t, kind, why, axis)
