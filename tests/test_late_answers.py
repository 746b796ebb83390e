"""Late answers on the bus: the real master against a simulated drive that answers late.

A busy machine (or a loaded bridge) makes a drive's answer to SYNC k arrive after the
master's deadline of cycle k: cycle k has no answer, and cycle k+1 takes the answer to SYNC k
as its own (a TPDO carries no sequence number). The drive's fault injector
(``FaultInjector.late_tpdo_*``) does exactly that on chosen cycles, deterministically, so the
master's loop can be run in lockstep against it: a late run of k cycles is one missing answer,
then k - 1 answers carrying the previous cycle's state, then the on-time answer with the late
one before it.

The master's position loop (``daq.protocol.control.PDLaw``) filtering the drive's own
velocity (``[daq] velocity_source = "drive"``, the paced clock's default) keeps the torque
reference smooth through it: its largest change per cycle stays within the same run's
without lateness plus ``kp x |dq_ref| x cycle`` (what a position one cycle old moves the P
term by, which no velocity estimate can remove). Measured (seeds 1-3, 1 ms, 6 kg at 1 m,
0.3 rad 0.5 Hz sine, 30 % of the plan's cycles late in runs of 1-4): 6.5 N m against 2.5
without lateness and a bound of 8.2; the position's difference (the lockstep default, and
the law before ``drive_velocity``) made 79.5-80 N m (the kd term of a double step divided by
one cycle), and the law before the gap and late handling (``PDLaw`` of 4b98034, the hold
only; checked by putting it back locally) 91-92 N m.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from test_gap_resume import _joint_log

from sim_drivers.faults import FaultInjector

_chan = itertools.count()
KP = 6000.0  # [N m/rad] joint_campaign's gain
CYCLE = 0.001  # [s]


def _run(out_root, seed: int, inj: FaultInjector | None, velocity: str):
    """A lockstep run of the loaded joint (6 kg at 1 m, a 0.3 rad 0.5 Hz sine, 1 ms) with
    plant seed ``seed``, the drive's fault injector ``inj`` and the master's
    ``velocity_source``; its log (``test_gap_resume``'s run, another watchdog)."""
    return _joint_log(out_root, seed, inj, tpdo_timeout_cycles=60, velocity_source=velocity)


def _late(seed: int) -> FaultInjector:
    """30 % of the drive's cycles 100-1999 (in the plan: the first half of the sine) late,
    in runs of 1 to 4."""
    return FaultInjector(late_tpdo_from_cycle=100, late_tpdo_cycles=1900,
                         late_tpdo_share=0.3, late_tpdo_run=4, late_tpdo_seed=seed)


def _dtau_max(a) -> float:
    """The torque reference's largest change per cycle while the plan runs [N m]."""
    run = np.asarray(a.segment) >= 0
    return float(np.abs(np.diff(np.asarray(a.tau_ref)[run])).max())


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_late_answers_keep_the_torque_smooth(tmp_path, seed):
    """With the drive's velocity the torque changes per cycle at most as much as in the run
    without lateness plus kp |dq_ref| cycle; with the position's difference far more (the
    injected lateness is real: one missing answer per late run, as drawn)."""
    inj = _late(seed)
    runs = sum(1 for k in inj.late_cycles if k - 1 not in inj.late_cycles)
    clean = _run(tmp_path, seed, None, "drive")
    late = _run(tmp_path, seed, _late(seed), "drive")
    assert late.metadata["campaign"]["velocity_source"] == "drive"  # the key, recorded
    missing = int((~np.asarray(late.valid, bool)).sum())
    assert missing == runs + int((~np.asarray(clean.valid, bool)).sum())  # each run's first
    bound = _dtau_max(clean) + KP * float(np.abs(clean.dq_ref).max()) * CYCLE
    assert _dtau_max(late) <= bound, (_dtau_max(late), _dtau_max(clean), bound)
    diff = _run(tmp_path, seed, _late(seed), "difference")
    assert _dtau_max(diff) > 3 * bound, (_dtau_max(diff), bound)


def test_late_injector_draws_the_asked_share():
    """The late cycles are about the share asked (within 3 binomial sigmas over a long
    window), in runs of at most ``late_tpdo_run``, and the same for the same seed."""
    n = 20000
    for share, run in ((0.05, 1), (0.3, 4), (0.6, 3)):
        inj = FaultInjector(late_tpdo_from_cycle=0, late_tpdo_cycles=n, late_tpdo_share=share,
                            late_tpdo_run=run, late_tpdo_seed=7)
        got = len(inj.late_cycles) / n
        assert abs(got - share) <= 3 * np.sqrt(share * (1 - share) / n) + 0.02, (share, got)
        ks = sorted(inj.late_cycles)
        longest, cur = 1, 1
        for a, b in itertools.pairwise(ks):
            cur = cur + 1 if b == a + 1 else 1
            longest = max(longest, cur)
        assert longest <= run
        assert inj.late_cycles == FaultInjector(
            late_tpdo_from_cycle=0, late_tpdo_cycles=n, late_tpdo_share=share,
            late_tpdo_run=run, late_tpdo_seed=7).late_cycles


@pytest.mark.parametrize("kw,msg", [
    ({"late_tpdo_share": 0.0}, "late_tpdo_share: expected in (0, 1]"),
    ({"late_tpdo_run": 0}, "late_tpdo_run: expected >= 1"),
    ({"late_tpdo_cycles": -1}, "late_tpdo_cycles: expected >= 0"),
    ({"late_tpdo_share": 0.6, "late_tpdo_run": 1}, "late_tpdo_share: expected 1 or at most"),
])
def test_late_injector_refuses_bad_values(kw, msg):
    with pytest.raises(ValueError, match=msg.replace("(", r"\(").replace(")", r"\)")):
        FaultInjector(late_tpdo_from_cycle=0, **kw)
