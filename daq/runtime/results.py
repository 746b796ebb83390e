"""What a campaign run returns: progress snapshots, payload and campaign results."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .busload import BusLoad


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


#: a paced run with more than this share of its cycles late gets a note in the summary:
#: five times the ~1 % an idle 2-core VM misses without real-time priority (README, "Timing")
LATE_NOTE_SHARE = 0.05


def late_note(r: PayloadResult, cycle_s: float) -> str:
    """One line when a paced run missed more than :data:`LATE_NOTE_SHARE` of its cycles (the
    host did not keep up: a TPDO or heartbeat watchdog that stops such a run is the load's
    doing as much as the drive's), else ``""``. Lockstep runs (no lateness) get none."""
    if r.lateness_s.size == 0 or r.cycles <= 0 or r.missed <= LATE_NOTE_SHARE * r.cycles:
        return ""
    worst = 1000.0 * float(np.max(r.lateness_s))
    return (f"note: {r.missed} of {r.cycles} cycles late ({100.0 * r.missed / r.cycles:.1f} %, "
            f"worst {worst:.1f} ms at a {1000.0 * cycle_s:g} ms cycle): the host did not keep "
            f"up with the paced clock (other load?); give [daq] realtime_priority or a longer "
            f"control.cycle_s")


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
                f"  payload {r.index} ({r.mass_kg:g} kg"
                f"{'' if math.isnan(r.arm_m) else f' at {r.arm_m:g} m'}): {r.status}, "
                f"{r.cycles} cycles in {r.wall_s:.1f} s {rate}, missed {r.missed}"
                f" -> {r.path}" + (f"\n    {r.reason}" if r.reason else "")
            )
            if note := late_note(r, self.bus_load.cycle_s):
                lines.append(f"    {note}")
        lines.extend(f"  warning: {n}" for n in self.notes)
        if self.skipped:
            lines.append(f"  skipped (already completed): payloads {list(self.skipped)}")
        lines.append(f"  bus load: {self.bus_load}")
        return "\n".join(lines)
