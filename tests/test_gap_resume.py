"""The master's torque loop resuming after a gap in the drive's answers (run safety).

During a gap (cycles flagged ``FLAG_TPDO_MISSING``) ``daq.protocol.control.PDLaw`` holds the
feedback torque of the last fresh cycle; the joint runs on it meanwhile, and the law's value
at the first fresh cycle after the gap differs from the held one by about ``kp`` times the
error the gap let grow. Applied at once, that was a torque step of 42 N m on the loaded joint
(45-cycle gap; 1.5-3.5 N m is the largest cycle-to-cycle change of the run without gaps) and
52 N m on the arm's shoulder. Now the feedback blends from the held value to the law's over
``min(gap, RESUME_S / cycle_s)`` fresh cycles, and the velocity estimate after a gap starts
from the drive's own velocity (0x606C).

The bus tests run the real master against simulated drives on python-can's virtual bus,
lockstep (deterministic), the gap made by the drive's own fault injector (its TPDOs dropped).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import os

import numpy as np
import pytest
from daq_campaigns import joint_campaign

from daq.protocol.control import RESUME_MIN_GAP, RESUME_S, PDLaw
from daq.protocol.reader import read_run
from daq.runtime.robot_rig import arm_truth
from daq.runtime.runner import run_campaign
from sim_drivers.faults import FaultInjector
from sim_drivers.plant_config import default_plant
from tests.robot_campaigns import arm3_campaign

_chan = itertools.count()
GAP = 45  # [cycles] the gap of the bus tests (below their watchdog's 60)
WINDOW = 30  # [cycles] after the gap in which the torque steps are looked at


# ------------------------------------------------------------------ the law alone
def _old_torque(state: dict, ff, q_ref, dq_ref, q, dt, kp, kd, alpha):
    """The law as it was for fresh cycles without a gap (reference for bit-for-bit)."""
    if state["q_prev"] is not None:
        raw = (q - state["q_prev"]) / (dt * (0 + 1))
        state["dq"] = state["dq"] + alpha * (raw - state["dq"])
    state["q_prev"] = q
    p, d = kp * (q_ref - q), kd * (dq_ref - state["dq"])
    return ff + p + d


@pytest.mark.parametrize("seed", [1, 2])
def test_fresh_cycles_without_a_gap_compute_what_they_did(seed):
    """Without a gap the law's torque is the same float as before the blend existed (the
    offline simulators and the demo figures rest on it)."""
    rng = np.random.default_rng(seed)
    dt, kp, kd, fc = 0.001, 6000.0, 200.0, 100.0
    wc = 2.0 * math.pi * fc * dt
    law, st = PDLaw(kp, kd, fc, dt), {"q_prev": None, "dq": 0.0}
    for _ in range(500):
        ff, q_ref, dq_ref, q = rng.standard_normal(4)
        assert law.torque(ff, q_ref, dq_ref, q) == _old_torque(
            st, ff, q_ref, dq_ref, q, dt, kp, kd, wc / (1.0 + wc))


@pytest.mark.parametrize("gap,dt", [(2, 0.001), (3, 0.001), (40, 0.001), (40, 0.002)])
def test_resume_blends_from_the_held_feedback_to_the_law(gap, dt):
    """After ``gap`` cycles without a measurement the applied feedback goes from the held
    value to the law's in ``N = min(gap, RESUME_S / dt)`` equal parts, then is the law's; a
    gap shorter than RESUME_MIN_GAP (3) resumes at once. Here the joint is 20 mrad from
    the reference after the gap (120 N m of kp x error)."""
    kp, kd = 6000.0, 200.0
    law, twin = PDLaw(kp, kd, 100.0, dt), PDLaw(kp, kd, 100.0, dt, resume_s=0.0)
    for _ in range(20):  # settled at rest on the reference
        law.torque(0.0, 0.0, 0.0, 0.0)
        twin.torque(0.0, 0.0, 0.0, 0.0)
    held = law.torque(0.0, 0.0, 0.0, 0.0)
    for _ in range(gap):
        assert law.torque(1.0, 0.0, 0.0, 0.0, fresh=False) == 1.0 + held
        twin.torque(1.0, 0.0, 0.0, 0.0, fresh=False)
    n = min(gap, math.ceil(RESUME_S / dt - 1e-9)) if gap >= RESUME_MIN_GAP else 1
    for k in range(1, n + 3):
        tau = law.torque(1.0, 0.02, 0.0, 0.0, dq_meas=0.0)
        full = twin.torque(1.0, 0.02, 0.0, 0.0, dq_meas=0.0)  # the law's own value
        w = min(k / n, 1.0)
        assert tau == pytest.approx(1.0 + held + w * (full - 1.0 - held), abs=1e-9)
    assert tau == full


def test_a_gap_inside_the_blend_holds_the_blended_value():
    """A new gap during the blend holds what was applied, not the law's value; after a
    short gap the blend goes on, after a long one it restarts from the held value."""
    law = PDLaw(6000.0, 200.0, 100.0, 0.001)
    law.torque(0.0, 0.0, 0.0, 0.0)
    for _ in range(30):
        law.torque(0.0, 0.0, 0.0, 0.0, fresh=False)
    applied = law.torque(0.0, 0.01, 0.0, 0.0, dq_meas=0.0)  # 1/20 of 60 N m
    assert applied == pytest.approx(3.0)
    assert law.torque(0.0, 0.01, 0.0, 0.0, fresh=False) == applied  # a 1-cycle gap
    assert law.torque(0.0, 0.01, 0.0, 0.0, dq_meas=0.0) == pytest.approx(6.0)  # 2/20
    for _ in range(5):  # a 5-cycle gap: the blend restarts from 6 N m over 5 cycles
        assert law.torque(0.0, 0.01, 0.0, 0.0, fresh=False) == pytest.approx(6.0)
    assert law.torque(0.0, 0.01, 0.0, 0.0, dq_meas=0.0) == pytest.approx(6.0 + 54.0 / 5)


def test_velocity_after_a_gap_is_the_drives_own():
    """After a gap the velocity estimate is the drive's velocity, not the difference over
    the gap: a sample that answers an earlier SYNC (late through a loaded bridge) made that
    difference assume a span it did not have (here half the speed, the kd term off by
    kd x 0.25 rad/s = 50 N m)."""
    dt, v = 0.001, 0.5
    law = PDLaw(6000.0, 200.0, 100.0, dt)
    for k in range(50):
        law.torque(0.0, v * k * dt, v, v * k * dt)
    for _ in range(10):  # cycles 50..59 missing
        law.torque(0.0, 0.0, v, 0.0, fresh=False)
    q_late = v * 54 * dt  # cycle 60's "fresh" sample is the answer to SYNC 55
    law.torque(0.0, v * 60 * dt, v, q_late, dq_meas=v)
    assert law._dq_est == v
    old = PDLaw(6000.0, 200.0, 100.0, dt)
    for k in range(50):
        old.torque(0.0, v * k * dt, v, v * k * dt)
    for _ in range(10):
        old.torque(0.0, 0.0, v, 0.0, fresh=False)
    old.torque(0.0, v * 60 * dt, v, q_late)  # without dq_meas: the difference over the gap
    assert old._dq_est < 0.8 * v


# ------------------------------------------------------------------ on the bus
def _joint_log(out_root, seed: int, inj: FaultInjector | None, **daq):
    """A lockstep run of the loaded joint (6 kg at 1 m, a 0.3 rad 0.5 Hz sine, 1 ms) with
    plant seed ``seed``, the drive's fault injector ``inj`` and ``daq`` keys over these
    (``tests/test_late_answers.py`` runs it too); its log (axis 0)."""
    c = joint_campaign(
        "gap", cycle_s=0.001, sine={"amplitude": 0.3, "frequency_hz": 0.5, "periods": 1},
        payload_masses=(6.0,),
        daq={"channel": f"gap_{os.getpid()}_{next(_chan)}", "tpdo_timeout_cycles": GAP + 15,
             "lockstep_wait_s": 0.02, **daq})
    p = default_plant()
    p = dataclasses.replace(p, drive=dataclasses.replace(p.drive, seed=seed))
    r = run_campaign(c, out_dir=out_root / f"run{next(_chan)}", simulate=p, yes=True,
                     fault_injectors={1: inj} if inj else None)
    assert r.status == "done", r.reason
    return read_run(r.runs[0].path)


def _resume(a, clean) -> tuple[float, float, float, float]:
    """(largest cycle-to-cycle torque change from the last cycle of the gap to WINDOW
    cycles after it [N m]; the largest of the run without the gap while the plan runs
    [N m]; rms of the position's difference to that run from 300 to 800 cycles after the
    gap [rad]; that run's rms tracking error [rad]), of one axis."""
    valid = np.asarray(a.valid, bool)
    run = np.asarray(a.segment) >= 0
    miss = np.flatnonzero(~valid & run)
    assert len(miss) == GAP and miss[-1] - miss[0] == GAP - 1, miss  # the gap happened
    r = miss[-1] + 1  # the first fresh cycle after it
    step = float(np.abs(np.diff(np.asarray(a.tau_ref)[r - 1:r + WINDOW])).max())
    crun = np.asarray(clean.segment) >= 0
    ctau = np.asarray(clean.tau_ref)[crun]
    after = np.arange(r + 300, r + 800)
    dev = np.asarray(a.q)[after] - np.asarray(clean.q)[after]
    err = (np.asarray(clean.q_ref) - np.asarray(clean.q))[crun]
    return (step, float(np.abs(np.diff(ctau)).max()), float(np.sqrt(np.mean(dev ** 2))),
            float(np.sqrt(np.mean(err ** 2))))


@pytest.mark.parametrize("seed,start", [(1, 700), (2, 1100)])
def test_the_loaded_joint_resumes_without_a_torque_step(tmp_path, seed, start):
    """The drive's TPDOs lost for 45 cycles: at the resume the torque changes per cycle no
    more than the largest change of the run without the gap (3.5 N m), where the law's
    value at once made a 42 N m step (start 700) / 8.5 N m (1100); and 300 cycles later
    the joint is where it is in that run (within 5 % of its rms tracking error)."""
    clean = _joint_log(tmp_path, seed, None)
    a = _joint_log(tmp_path, seed, FaultInjector(drop_tpdo_from_cycle=start,
                                                 drop_tpdo_cycles=GAP))
    step, step_ok, dev, err = _resume(a, clean)
    assert step <= step_ok, (step, step_ok)
    assert dev <= 0.05 * err, (dev, err)


def _arm_logs(out_root, inj: FaultInjector | None):
    """arm3 (3 joints on 2 buses, 2 ms, the 5 kg payload), j2 (node 2) with the fault
    injector ``inj``: the three axes' logs."""
    c = arm3_campaign(payloads=[{"mass_kg": 5.0, "com": [0.1, 0.0, 0.0],
                                 "inertia": [0.015, 0.0, 0.0, 0.015, 0.0, 0.01]}],
                      daq={"tpdo_timeout_cycles": GAP + 15, "lockstep_wait_s": 0.02})
    r = run_campaign(c, out_dir=out_root / f"arm{next(_chan)}", simulate=arm_truth(c),
                     yes=True, fault_injectors={2: inj} if inj else None)
    assert r.status == "done", r.reason
    return [read_run(r.runs[0].path, axis=j) for j in range(3)]


@pytest.fixture(scope="module")
def arm_clean(tmp_path_factory):
    return _arm_logs(tmp_path_factory.mktemp("gaparm"), None)


@pytest.mark.parametrize("start", [400, 900])
def test_the_arm_shoulder_resumes_without_a_torque_step(tmp_path, arm_clean, start):
    """The same on the simulated 3-dof arm: j2 (the shoulder carrying the arm and the 5 kg
    payload, kp 15000, 2 ms) loses its TPDOs for 45 cycles (90 ms). Its torque changes per
    cycle at the resume no more than the largest change of the run without the gap (7.9 N m;
    the law's value at once: 52 N m at start 900, 19.5 N m at 400), and 300 cycles later
    every joint is where it is in that run (within 5 % of its rms tracking error)."""
    logs = _arm_logs(tmp_path, FaultInjector(drop_tpdo_from_cycle=start,
                                             drop_tpdo_cycles=GAP))
    step, step_ok, dev, err = _resume(logs[1], arm_clean[1])
    assert step <= step_ok, (step, step_ok)
    run = np.asarray(logs[1].segment) >= 0
    r = np.flatnonzero(~np.asarray(logs[1].valid, bool) & run)[-1] + 1
    for j in range(3):
        after = np.arange(r + 300, r + 800)
        d = np.asarray(logs[j].q)[after] - np.asarray(arm_clean[j].q)[after]
        crun = np.asarray(arm_clean[j].segment) >= 0
        e = (np.asarray(arm_clean[j].q_ref) - np.asarray(arm_clean[j].q))[crun]
        assert np.sqrt(np.mean(d ** 2)) <= 0.05 * np.sqrt(np.mean(e ** 2)), j


# ------------------------------------------------------------------ late answers
@pytest.mark.parametrize("seed", [1, 2])
def test_late_answers_with_the_drives_velocity_make_no_torque_spikes(seed):
    """A joint at 0.3 rad/s whose answers are, at random cycles (one in three), those of
    the SYNC before (late through a loaded bridge, taken as this cycle's): the backward
    difference sees a zero step then a double one, and the kd term turns them into torque
    spikes (34 N m at most here); filtering the drive's own velocity instead
    (``drive_velocity``, the runner's paced clock) the torque changes per cycle by no more
    than the reference's own kp x v x dt (1.8 N m) plus 10 %."""
    rng = np.random.default_rng(seed)
    dt, v, kp, kd = 0.001, 0.3, 6000.0, 200.0
    diff_law, drive_law = PDLaw(kp, kd, 100.0, dt), PDLaw(kp, kd, 100.0, dt,
                                                           drive_velocity=True)
    taus: dict[str, list[float]] = {"diff": [], "drive": []}
    for k in range(600):
        lag = 1 if k > 100 and rng.random() < 1 / 3 else 0
        q = v * (k - lag) * dt  # the sample the master takes as this cycle's
        q_ref = v * k * dt
        taus["diff"].append(diff_law.torque(0.0, q_ref, v, q, dq_meas=v))
        taus["drive"].append(drive_law.torque(0.0, q_ref, v, q, dq_meas=v))
    d_diff = np.abs(np.diff(taus["diff"][100:])).max()
    d_drive = np.abs(np.diff(taus["drive"][100:])).max()
    assert d_drive <= 1.1 * kp * v * dt, d_drive
    assert d_diff > 5 * kp * v * dt, d_diff  # the spikes the difference made
