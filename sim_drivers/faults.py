"""Fault codes of the simulated drive and the configurable fault injector used by tests.

Error codes (0x603F, EMCY) follow CiA 301 / CiA 402's error-code table:

==========  ==========================================================================
 code        meaning
==========  ==========================================================================
 0x8611      following error (CSP: ``|0x607A - 0x6064| > 0x6065``)
 0x8311      excess torque (CST: ``|0x6071 + 0x60B2| > 0x6072``)
 0x8612      reference limit (``0x6064`` outside the software limits ``0x607D``)
 0x8210      RPDO shorter than its mapping (EMCY only: a warning, the drive keeps running)
 0x8130      heartbeat consumer timeout (CiA 301 "life guard error or heartbeat error"): a
             node listed in 0x1016 (the master) fell silent for longer than its consumer
             time; FAULT when OPERATION ENABLED or QUICK STOP ACTIVE, else EMCY only
 0x8100      SYNC lost in a cyclic mode (CiA 301 "communication, generic"; CiA 301 has no
             code of its own for a SYNC timeout, CANopenNode reports it with 0x8100 too;
             0x8240 is a SYNC of the wrong *length*): FAULT
 0x8250      RPDO timeout (CiA 301 "RPDO timeout"): with the event timer 0x1400+n sub 5
             non-zero, no RPDO n received for that long while OPERATION ENABLED in a
             cyclic mode (deadline monitoring of a hung master that still sends SYNC): FAULT
 0xFF01      injected fault (device specific; :class:`FaultInjector` default)
 0xFF02      plant-detected fault (the plant raised or its state became non-finite)
==========  ==========================================================================
"""

from __future__ import annotations

import random
from dataclasses import dataclass, field

FOLLOWING_ERROR = 0x8611
EXCESS_TORQUE = 0x8311
POSITION_LIMIT = 0x8612
PDO_LENGTH_ERROR = 0x8210
HEARTBEAT_LOST = 0x8130
SYNC_LOST = 0x8100
RPDO_TIMEOUT = 0x8250
INJECTED_FAULT = 0xFF01
PLANT_FAULT = 0xFF02

FAULT_NAMES: dict[int, str] = {
    FOLLOWING_ERROR: "following error",
    EXCESS_TORQUE: "excess torque",
    POSITION_LIMIT: "software position limit",
    PDO_LENGTH_ERROR: "PDO length error",
    HEARTBEAT_LOST: "heartbeat consumer timeout",
    SYNC_LOST: "SYNC lost",
    RPDO_TIMEOUT: "RPDO timeout",
    INJECTED_FAULT: "injected fault",
    PLANT_FAULT: "plant fault",
}


def error_register(code: int) -> int:
    """0x1001 error register for an error code: bit 0 (generic) plus the class bit.

    Bit 1 current (0x2xxx), bit 2 voltage (0x3xxx), bit 3 temperature (0x4xxx), bit 4
    communication (0x81xx, 0x82xx of CiA 301), bit 5 device profile (the other 0x8xxx: motion
    errors of CiA 402), bit 7 manufacturer (0xFFxx).
    """
    reg = 0x01 if code else 0x00
    top = code >> 12
    if top == 0x2:
        reg |= 0x02
    elif top == 0x3:
        reg |= 0x04
    elif top == 0x4:
        reg |= 0x08
    elif code >> 8 in (0x81, 0x82):
        reg |= 0x10
    elif top == 0x8:
        reg |= 0x20
    elif code >> 8 == 0xFF:
        reg |= 0x80
    return reg


@dataclass
class FaultInjector:
    """Scripted misbehaviour of a :class:`sim_drivers.drive.SimulatedDrive`, by SYNC cycle.

    Cycle numbers are the drive's cycle counter (:attr:`SimulatedDrive.cycle`): 0 for the
    first SYNC it processes in NMT OPERATIONAL, counted over the drive's lifetime.

    Parameters
    ----------
    fault_at_cycle : int or None
        Raise ``fault_code`` at that cycle (FAULT state, 0x603F set, one EMCY frame).
    fault_code : int
        Error code of the injected fault (default 0xFF01, device specific).
    stop_heartbeat_at_cycle : int or None
        Stop the heartbeat producer from that cycle on (the node keeps working otherwise).
    drop_tpdo_from_cycle : int or None
        Send no TPDO at cycles ``drop_tpdo_from_cycle`` to
        ``drop_tpdo_from_cycle + drop_tpdo_cycles - 1``.
    drop_tpdo_cycles : int
        How many consecutive cycles lose their TPDOs.
    drop_tpdo_period : int
        0 (default): one window only. Else the window repeats every ``drop_tpdo_period``
        cycles from ``drop_tpdo_from_cycle`` on (a bus that loses frames again and again:
        ``drop_tpdo_cycles=2, drop_tpdo_period=3`` loses two cycles in three).
    delay_tpdo_from_cycle : int or None
        The TPDOs of cycles ``delay_tpdo_from_cycle`` to ``+ delay_tpdo_cycles - 1`` are
        held back and sent late: each later cycle sends the oldest held set before its own,
        until none is left (a drive's process that stalled and catches up: the master sees
        two sets a cycle, the first one old).
    delay_tpdo_cycles : int
        How many consecutive cycles' TPDOs are held back.
    late_tpdo_from_cycle : int or None
        Late answers (a busy machine, a loaded bridge): from this cycle on, for
        ``late_tpdo_cycles`` cycles, the cycles :meth:`late_tpdo` names answer one cycle late.
        A late cycle sends the set held back from the cycle before (the previous cycle's
        state: what a master that cannot tell an answer to an earlier SYNC from this one's
        takes as this cycle's), or nothing if the cycle before was on time (the first late
        answer of a run is not there by the deadline), and holds its own back; the next
        on-time cycle sends the held set before its own (both arrive, the newest last)
        without its last PDO, which its own supersedes: a master completes its set only with
        this cycle's (else, in lockstep, whether it took the old or the new values would
        depend on the threads' timing; every TPDO1, the answer a master counts, is sent).
    late_tpdo_cycles : int
        Length of the late window [cycles].
    late_tpdo_share : float
        Share of the window's cycles that answer late, in (0, 1]; 1: every one. The cycles
        are drawn once from ``late_tpdo_seed`` (the same seed, the same cycles).
    late_tpdo_run : int
        Late cycles come in runs of 1 to ``late_tpdo_run`` consecutive cycles (uniform), so
        that a late run of k cycles gives one missing answer and k - 1 previous-cycle states.
    late_tpdo_seed : int
        Seed of the late cycles' draw.
    lag_tpdo_from_cycle : int or None
        A steady lag (a host or bridge that delivers every answer just after the master
        stopped waiting for it): from this cycle on, for ``lag_tpdo_cycles`` cycles, the drive
        holds its answer to each SYNC back and sends it when the master's next RPDO arrives,
        i.e. after the master's wait for it (the master sends its RPDO once its wait is over)
        and before the next SYNC (the master sends the RPDO first). The master's cycle k+1
        then finds the answer to SYNC k waiting and takes it as its own: every cycle runs on
        the state one cycle old, and no cycle but the window's first lacks an answer. A set
        still held at the next SYNC (no RPDO came) is sent then, before anything else.
        Unlike ``late_tpdo_*`` (the previous cycle's set sent right after the next SYNC,
        which a master cannot tell from an on-time answer), the answers arrive before the
        SYNC of the cycle that takes them.
    lag_tpdo_cycles : int
        Length of the lag window [cycles].
    """

    fault_at_cycle: int | None = None
    fault_code: int = INJECTED_FAULT
    stop_heartbeat_at_cycle: int | None = None
    drop_tpdo_from_cycle: int | None = None
    drop_tpdo_cycles: int = 1
    drop_tpdo_period: int = 0
    delay_tpdo_from_cycle: int | None = None
    delay_tpdo_cycles: int = 1
    late_tpdo_from_cycle: int | None = None
    late_tpdo_cycles: int = 0
    late_tpdo_share: float = 1.0
    late_tpdo_run: int = 1
    late_tpdo_seed: int = 0
    lag_tpdo_from_cycle: int | None = None
    lag_tpdo_cycles: int = 0
    #: the set a lagging cycle held back until the next RPDO: list of (COB-ID, data)
    lag_held: list = field(default_factory=list, repr=False, compare=False)
    #: the sets held back, oldest first: lists of (COB-ID, data) (the drive's state)
    held_tpdos: list = field(default_factory=list, repr=False, compare=False)
    #: the set a late cycle held back: list of (COB-ID, data) (the drive's state)
    late_held: list = field(default_factory=list, repr=False, compare=False)
    #: the late window's late cycles (drawn in __post_init__)
    late_cycles: frozenset = field(default=frozenset(), repr=False, compare=False)

    def __post_init__(self) -> None:
        if not 0 < self.fault_code <= 0xFFFF:
            raise ValueError(
                f"FaultInjector.fault_code: expected 0x0001..0xFFFF, got {self.fault_code}"
            )
        for name in ("drop_tpdo_cycles", "delay_tpdo_cycles", "late_tpdo_cycles",
                     "lag_tpdo_cycles"):
            if getattr(self, name) < 0:
                raise ValueError(
                    f"FaultInjector.{name}: expected >= 0, got {getattr(self, name)}")
        if self.drop_tpdo_period < 0 or 0 < self.drop_tpdo_period <= self.drop_tpdo_cycles:
            raise ValueError(
                f"FaultInjector.drop_tpdo_period: expected 0 or > drop_tpdo_cycles "
                f"({self.drop_tpdo_cycles}), got {self.drop_tpdo_period}"
            )
        if not 0.0 < self.late_tpdo_share <= 1.0:
            raise ValueError(
                f"FaultInjector.late_tpdo_share: expected in (0, 1], got {self.late_tpdo_share}"
            )
        if self.late_tpdo_run < 1:
            raise ValueError(
                f"FaultInjector.late_tpdo_run: expected >= 1, got {self.late_tpdo_run}"
            )
        top = (1 + self.late_tpdo_run) / (3 + self.late_tpdo_run)  # on-time gaps of 1
        if top < self.late_tpdo_share < 1.0:
            raise ValueError(
                f"FaultInjector.late_tpdo_share: expected 1 or at most (late_tpdo_run + 1) / "
                f"(late_tpdo_run + 3) = {top:.3g} (late runs are apart), got "
                f"{self.late_tpdo_share}"
            )
        if self.late_tpdo_from_cycle is not None:
            self.late_cycles = frozenset(late_runs(
                self.late_tpdo_from_cycle, self.late_tpdo_cycles, self.late_tpdo_share,
                self.late_tpdo_run, self.late_tpdo_seed))

    def fault_now(self, cycle: int) -> bool:
        """True at the cycle the fault is injected."""
        return self.fault_at_cycle is not None and cycle == self.fault_at_cycle

    def stop_heartbeat_now(self, cycle: int) -> bool:
        """True at the cycle the heartbeat producer stops."""
        return self.stop_heartbeat_at_cycle is not None and cycle == self.stop_heartbeat_at_cycle

    def delay_tpdo(self, cycle: int) -> bool:
        """True when the TPDOs of ``cycle`` must be held back (sent late)."""
        start = self.delay_tpdo_from_cycle
        return start is not None and start <= cycle < start + self.delay_tpdo_cycles

    def late_tpdo(self, cycle: int) -> bool:
        """True when the answer of ``cycle`` is late: the drive sends the set held back from
        the cycle before (if any) and holds back its own (``late_tpdo_from_cycle``)."""
        return cycle in self.late_cycles

    def lag_tpdo(self, cycle: int) -> bool:
        """True when the answer of ``cycle`` is held back until the master's next RPDO (the
        steady lag, ``lag_tpdo_from_cycle``)."""
        start = self.lag_tpdo_from_cycle
        return start is not None and start <= cycle < start + self.lag_tpdo_cycles

    def drop_tpdo(self, cycle: int) -> bool:
        """True when the TPDOs of ``cycle`` must not be sent."""
        start = self.drop_tpdo_from_cycle
        if start is None or cycle < start:
            return False
        if self.drop_tpdo_period:
            return (cycle - start) % self.drop_tpdo_period < self.drop_tpdo_cycles
        return cycle < start + self.drop_tpdo_cycles


def late_runs(start: int, cycles: int, share: float, run: int, seed: int) -> list[int]:
    """The late cycles of a window of ``cycles`` cycles from ``start``: runs of 1 to ``run``
    consecutive cycles (uniform) separated by on-time runs of at least one cycle (one plus a
    geometric number, of the mean that makes ``share`` of the window late); every cycle when
    ``share`` is 1. Deterministic for a ``seed``."""
    if share >= 1.0:
        return list(range(start, start + cycles))
    rng = random.Random(seed)
    extra = (1 + run) / 2 * (1.0 - share) / share - 1.0  # mean on-time cycles beyond one
    p_more = extra / (1.0 + extra)

    def gap() -> int:
        n = 1
        while rng.random() < p_more:
            n += 1
        return n

    out: list[int] = []
    k = start + gap() - 1
    while k < start + cycles:
        n = rng.randint(1, run)
        out.extend(range(k, min(k + n, start + cycles)))
        k += n + gap()
    return out
