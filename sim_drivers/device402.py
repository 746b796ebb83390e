"""CiA 402 device behaviour of :class:`sim_drivers.drive.SimulatedDrive`: the state machine of
:mod:`daq.protocol.cia402` driven by 0x6040, the statusword, faults, and one drive cycle
(:meth:`Device402Mixin.step`: fault injection, the CST/CSP/CSV control laws, the plant step,
the limit checks, the record and the synchronous TPDOs). Modes, units and fault codes: see
the module docstring of :mod:`sim_drivers.drive` and :mod:`sim_drivers.faults`.
"""

from __future__ import annotations

import logging
import math
import time

from daq.protocol.cia402 import (
    State,
    automatic_transition,
    next_state,
    statusword,
)
from sim_drivers import SimError
from sim_drivers.faults import (
    EXCESS_TORQUE,
    FOLLOWING_ERROR,
    PLANT_FAULT,
    POSITION_LIMIT,
    error_register,
)
from sim_drivers.nmt import CYCLIC_MODE_INTS
from sim_drivers.pdo import clip_int, wrap_i32

logger = logging.getLogger("sim_drivers.drive")  # one logger for the whole drive, as before

_QS_DONE_SPEED = 1e-3  # [rad/s]
_CSV_INTEGRAL_RATE = 2.0 * math.pi * 3.0  # CSV loop: ki = kd * this [1/s]


class Device402Mixin:
    """CiA 402 state machine, faults and the drive cycle (mixin of
    :class:`~sim_drivers.drive.SimulatedDrive`)."""

    @property
    def state(self) -> State:
        """CiA 402 state of the drive."""
        return self.cia_state

    def _reset_state_machine(self) -> None:
        """Power-on of the CiA 402 side: transitions 0 and 1 to SWITCH ON DISABLED."""
        self._last_eval = None
        self.cia_state = State.NOT_READY_TO_SWITCH_ON
        self.cia_state, _ = automatic_transition(self.cia_state, "self_test_done")
        self._update_statusword()

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
                self._enabled_at = self._now()
                if self._sync_timeout_s:
                    self._wd_wake.set()
        self.statusword = statusword(
            st,
            internal_limit=self._internal_limit,
            bit12=enabled and self.mode_display in CYCLIC_MODE_INTS,
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
        elif inj is not None and inj.late_tpdo(cycle):
            held = []  # this cycle's set, sent next cycle; the one held before goes now
            for tx in self._tx_sync:
                tx.count += 1
                if tx.count >= tx.every:
                    tx.count = 0
                    held.append((tx.cob_id, tx.payload(self)))
            for cob_id, data in inj.late_held:  # the previous cycle's state as this one's
                self._send(cob_id, data)
                self.tpdo_sent += 1
            inj.late_held = held
        elif inj is not None and inj.lag_tpdo(cycle):
            held = []  # this cycle's set, sent when the master's next RPDO arrives
            for tx in self._tx_sync:
                tx.count += 1
                if tx.count >= tx.every:
                    tx.count = 0
                    held.append((tx.cob_id, tx.payload(self)))
            for cob_id, data in inj.lag_held:  # no RPDO came since the last: that set first
                self._send(cob_id, data)
                self.tpdo_sent += 1
            inj.lag_held = held
            self._hook_lag_release()
        elif inj is not None and inj.delay_tpdo(cycle):
            held = []  # this cycle's set, sent late (FaultInjector.delay_tpdo_from_cycle)
            for tx in self._tx_sync:
                tx.count += 1
                if tx.count >= tx.every:
                    tx.count = 0
                    held.append((tx.cob_id, tx.payload(self)))
            inj.held_tpdos.append(held)
        else:
            send = self._send
            if inj is not None and inj.held_tpdos:  # catching up: one late set first
                for cob_id, data in inj.held_tpdos.pop(0):
                    send(cob_id, data)
                    self.tpdo_sent += 1
            if inj is not None and inj.lag_held:  # the lag window ended before an RPDO
                for cob_id, data in inj.lag_held:
                    send(cob_id, data)
                    self.tpdo_sent += 1
                inj.lag_held = []
            if inj is not None and inj.late_held:  # the late answer before this one's
                for cob_id, data in inj.late_held[:-1]:  # (FaultInjector.late_tpdo_cycles)
                    send(cob_id, data)
                    self.tpdo_sent += 1
                inj.late_held = []
            for tx in self._tx_sync:
                tx.count += 1
                if tx.count >= tx.every:
                    tx.count = 0
                    send(tx.cob_id, tx.payload(self))
                    self.tpdo_sent += 1
            if self._tx_event:
                self._send_event_tpdos()
        self.cycle = cycle + 1

    def _hook_lag_release(self) -> None:
        """Subscribe :meth:`_release_lagged` to this drive's synchronous RPDOs, once (the
        steady lag of :class:`~sim_drivers.faults.FaultInjector`, ``lag_tpdo_*``)."""
        hooked = self.__dict__.setdefault("_lag_hooked", set())
        for rx in self._rx_sync:
            if rx.cob_id not in hooked:
                hooked.add(rx.cob_id)
                self.network.subscribe(rx.cob_id, self._release_lagged)

    def _release_lagged(self, can_id: int, data: bytes, timestamp: float) -> None:
        """The master's RPDO arrived: send the answer held back since the last SYNC (after
        the master's wait for it, before the next SYNC: ``FaultInjector.lag_tpdo_*``)."""
        inj = self.injector
        if inj is None or not inj.lag_held:
            return
        with self._lock:
            held, inj.lag_held = inj.lag_held, []
            for cob_id, payload in held:
                self._send(cob_id, payload)
                self.tpdo_sent += 1

    def _update_actuals(self) -> None:
        plant = self.plant
        self.position_actual = wrap_i32(int(plant.encoder_counts))
        v = round(plant.dq * self._counts_per_rad)
        self.velocity_actual = clip_int(v, -0x80000000, 0x7FFFFFFF)
        ta = int(plant.permille_from_torque(plant.tau_applied))
        self.torque_actual = ta
        self.current_actual = clip_int(round(ta * self._current_scale), -0x8000, 0x7FFF)

