"""A joint that moves at about zero load: the paper model's quadrant band says how much of it
(``RobotModel.band_share_``) and ``jointid fit --robot`` notes the joint (docs/robot-
identification.md, "quadrants blended by the low-pass"). Signals from the simulated arm's
inverse model on given trajectories (true states, torque noise): no bus needed."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ident.cli_robot import fit_files
from ident.loaders import RawRobotRun
from ident.robot.base import base_parameters
from ident.robot.estimate import RobotModel
from ident.robot.regressor import RobotRegressor
from ident.robot.signals import RobotPayloadData, RobotSignals
from sim_drivers.arm import ArmParams, Payload
from sim_drivers.arm_plant import inverse_arm_torque
from trajectories.excitation import ZERO_LOAD_SHARE
from trajectories.robot import load_robot

ROOT = Path(__file__).resolve().parents[1]
DT = 0.002  # [s]
PAYLOADS = (None, Payload(5.0, [0.0, 0.0, 0.05]))


def _yaw_cruise(t: np.ndarray, cruise: bool) -> tuple[np.ndarray, ...]:
    """The first 60 %: j1 (vertical axis, no gravity) alone, the others held -- a slow
    back-and-forth cruise (about 0.1 rad/s, smooth turns; ``cruise``) or a sum of two sines
    (always accelerated), as the demo campaigns' base yaw before and after 2026-11-27; then
    every joint a sum of sines (the multi-sine), ramped in from where the first part ended."""
    w = 2 * np.pi
    tm = 0.6 * t[-1]
    first = t < tm
    if cruise:
        ph = (t % 10.0) / 10.0
        tri = np.where(ph < 0.5, 4 * ph - 1, 3 - 4 * ph)  # -1..1, period 10 s
        box = np.ones(int(0.4 / DT)) / int(0.4 / DT)  # turns smoothed over 0.4 s, twice
        alone = 0.25 * np.convolve(np.convolve(tri, box, "same"), box, "same")
    else:
        alone = 0.4 * np.sin(w * 0.3 * t) + 0.1 * np.sin(w * 0.8 * t)
    ramp = np.where(first, 0.0, 1.0 - np.exp(-(t - tm) / 0.5))
    q1 = np.where(first, alone, np.interp(tm, t, alone)) + ramp * (
        0.3 * np.sin(w * 0.2 * t) + 0.1 * np.sin(w * 0.55 * t))
    # around the configurations where the shoulder's and the elbow's gravity torques change
    # sign (forearm vertical at q2 + q3 = -pi/2, tests/test_robot_fit.py CENTRES)
    q2 = -1.9 + ramp * (0.4 * np.sin(w * 0.25 * t + 0.3) + 0.1 * np.sin(w * 0.7 * t))
    q3 = 0.6 + ramp * (0.5 * np.sin(w * 0.35 * t + 1.0) + 0.1 * np.sin(w * 0.9 * t))
    q = np.stack([q1, q2, q3], axis=1)
    dq = np.gradient(q, DT, axis=0)
    ddq = np.gradient(dq, DT, axis=0)
    return q[5:-5], dq[5:-5], ddq[5:-5]


def _signals(cruise: bool, seed: int) -> tuple[list[RobotSignals], RobotRegressor]:
    robot = load_robot(ROOT / "examples" / "robots" / "arm3.toml")
    params = ArmParams.from_robot(robot)
    reg = RobotRegressor(robot)
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 60.0, DT)
    q, dq, ddq = _yaw_cruise(t, cruise)
    t = t[5:-5]
    out = []
    for p in PAYLOADS:
        tau = inverse_arm_torque(params, q, dq, ddq, p, effects=False)
        tau = tau + 0.01 * np.std(tau, axis=0) * rng.standard_normal(tau.shape)
        pay = RobotPayloadData() if p is None else RobotPayloadData(p.mass, p.com, p.inertia)
        out.append(RobotSignals(t=t, q=q, dq=dq, ddq=ddq, tau=tau, joints=reg.joints,
                                payloads=(pay,), source=f"yaw cruise={cruise}"))
    return out, reg


@pytest.mark.parametrize("seed", [1, 2])
def test_a_joint_at_zero_load_is_measured_by_the_quadrant_band(seed):
    """The cruising yaw puts most of its rows in the quadrant band; accelerated, few; the
    other joints (gravity) never reach the note's share."""
    shares = {}
    for cruise in (True, False):
        sigs, reg = _signals(cruise, seed)
        m = RobotModel(reg, "paper", "wls", base=base_parameters(reg)).fit(sigs)
        shares[cruise] = m.band_share_
        assert m.band_share_.shape == (3,) and np.all(m.band_share_ >= 0)
        assert np.all(m.band_share_[1:] < ZERO_LOAD_SHARE), (cruise, m.band_share_)
    assert shares[True][0] > 2 * ZERO_LOAD_SHARE, shares
    assert shares[False][0] < ZERO_LOAD_SHARE / 2, shares


def test_no_band_no_share():
    sigs, reg = _signals(True, 1)
    m = RobotModel(reg, "paper", base=base_parameters(reg), quadrant_band=0.0).fit(sigs)
    assert np.all(m.band_share_ == 0.0)
    u = RobotModel(reg, "usual", base=base_parameters(reg)).fit(sigs)
    assert np.all(u.band_share_ == 0.0)


def test_the_fit_notes_the_joint_at_zero_load():
    """``jointid fit --robot`` (``fit_files``, the CLI's function) on the same runs, through
    the columns chain: the cruising yaw gets a note naming it, the accelerated one none; the
    share is in the paper model's record."""
    robot = load_robot(ROOT / "examples" / "robots" / "arm3.toml")
    for cruise in (True, False):
        sigs, _ = _signals(cruise, 1)
        runs = [RawRobotRun(f"p{i}.csv", s.t, s.q, s.tau, payload=s.payloads[0])
                for i, s in enumerate(sigs)]
        out = fit_files(robot, runs, model="paper", method="wls", sigma_blocks=0,
                        feasibility=False)
        notes = [n for n in out["notes"] if "quadrant band" in n]
        share = out["models"]["paper"]["quadrant_band_share"]
        if cruise:
            assert len(notes) == 1 and notes[0].startswith("paper model, j1: "), notes
            assert share["j1"] > ZERO_LOAD_SHARE
        else:
            assert notes == [] and share["j1"] < ZERO_LOAD_SHARE
