"""A paced run on a loaded host (found by the acquisition sweep: two busy loops beside a paced
``--simulate`` run on the 2-core VM) missed 3436 of 13394 cycles, up to 26 ms late, and was
stopped by "node 1: TPDO missing for 3 cycles (watchdog)": the summary named the drive and
said nothing of the load. It now adds a note when more than 5 % of a paced run's cycles were
late; a lockstep run or a paced run within that share gets none."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from daq.runtime.busload import cycle_load
from daq.runtime.results import LATE_NOTE_SHARE, CampaignResult, PayloadResult


def _result(missed: int, cycles: int, lateness: np.ndarray) -> CampaignResult:
    run = PayloadResult(0, 0.0, 1.277, Path("out/c_payload0.mcap"), cycles, "stopped",
                        "node 1: TPDO missing for 3 cycles (watchdog)", 13389, 13393, missed,
                        24.5, lateness)
    return CampaignResult("c", Path("out"), (run,), "stopped", run.reason,
                          cycle_load([(4, 8, 5)], 0.001, 1_000_000))


def test_a_paced_run_that_missed_many_cycles_says_the_host_was_late():
    lateness = np.zeros(13394)
    lateness[::4] = 0.002  # one cycle in four 2 ms late
    lateness[100] = 0.0259
    text = _result(3436, 13394, lateness).summary()
    notes = [ln.strip() for ln in text.splitlines() if ln.strip().startswith("note:")]
    assert notes == ["note: 3436 of 13394 cycles late (25.7 %, worst 25.9 ms at a 1 ms cycle): "
                     "the host did not keep up with the paced clock (other load?); give [daq] "
                     "realtime_priority or a longer control.cycle_s"]


def test_no_note_within_the_share_or_in_lockstep():
    n = 10000
    within = int(LATE_NOTE_SHARE * n)
    assert "note:" not in _result(within, n, np.full(n, 1e-4)).summary()
    assert "note:" not in _result(n // 2, n, np.zeros(0)).summary()  # lockstep: no lateness
