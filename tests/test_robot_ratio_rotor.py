"""The payload ratio (``payload_ratio=True``, eq. 35) with known rotor inertias
(``RobotRegressor(known_rotor_inertia=True)``) on the columns chain (``design_runs``).

The columns chain's known torque ``RobotColumns.p`` is the payload's plus the known rotors'
Ia_j ddq_j, filtered and decimated with the columns. With the payload ratio the payload's
torque is the ratio's column: the rotors' torque must be taken out of it and subtracted as a
known torque, as on the path that evaluates the regressor on the decimated states. (It once
landed in the ratio's column, scaled by the estimated ratio: ZZ2R 59 sigma off the truth.)

Data: the simulated 3-dof arm of tests/test_robot_fit.py (usual friction, payloads 0, 5 kg,
10 kg with inertia); the payloads are declared at 0.8 times their true inertial parameters,
so the true ratio M_ae / M_aw is 1 / 0.8 = 1.25.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import scipy.stats
from test_robot_fit import NOISE, PAYLOADS, _check_recovery, _simulate, _z

from ident.preprocess import TORQUE_DELAY
from ident.robot.base import base_parameters
from ident.robot.design import design_runs, resolve_design
from ident.robot.estimate import RATIO, RobotModel
from ident.robot.loaders import RawRobotRun
from ident.robot.regressor import RobotRegressor
from ident.robot.signals import RobotPayloadData, RobotSignals
from sim_drivers.arm import ArmParams
from trajectories.robot import load_robot

ROOT = Path(__file__).resolve().parents[1]
SCALE = 0.8  # declared payload = SCALE x the true one: true ratio 1 / SCALE


@pytest.fixture(scope="module")
def arm3_ratio():
    robot = load_robot(ROOT / "examples" / "robots" / "arm3.toml")
    c = ArmParams.from_robot(robot).friction.c_m
    friction = dict(a_m=1.0, b_m=0.0, a_g=1.0, b_g=0.0, d_m=0.0, d_g=0.0, c_g=c)
    return _simulate("arm3", friction, duration_s=12.0, seed=3)


def _design(params, runs, regressor, seed: int) -> RobotSignals:
    """The columns chain on the true positions and the applied torque plus 1 % noise, each
    payload declared at SCALE times its true mass and inertia (same centre of mass)."""
    rng = np.random.default_rng(seed)
    noise = NOISE * params.drive.torque_noise_std_Nm / 0.01
    raw = []
    for r, p in zip(runs, PAYLOADS, strict=True):
        pay = RobotPayloadData() if p is None else RobotPayloadData(
            SCALE * p.mass, p.com, None if p.inertia is None else SCALE * np.asarray(p.inertia))
        tau = r.tau_applied + rng.standard_normal(r.tau_applied.shape) * noise
        raw.append(RawRobotRun(f"payload {r.payload_mass_kg} kg", r.t, r.q_true, tau,
                               q_ref=r.q_ref, payload=pay))
    settings = resolve_design(raw, torque_delay=TORQUE_DELAY)
    return design_runs(raw, regressor, settings)[0]


def test_ratio_with_known_rotors_on_both_chains(arm3_ratio):
    """Known rotors and the payload ratio: on the columns chain the ratio and every parameter
    are recovered within the stated sigma (tests/test_robot_fit.py's criterion), the ratio
    within 3 sigma on each seed; the columns and the states paths (regressor on the same
    decimated states) agree on the rigid-body parameters and the ratio within their
    combined sigma (family-wise bound)."""
    params, reg, _, runs = arm3_ratio
    known = RobotRegressor(reg.robot, known_rotor_inertia=True)
    assert np.all(known.known_Ia > 0)
    kbase = base_parameters(known)
    truth = params.truth(None)
    for j in reg.numbers:
        truth[f"FC{j}"] = truth[f"c_m{j}"]
    truth[RATIO] = 1.0 / SCALE
    seeds = (0, 1)
    cols, states = [], []
    for s in seeds:
        sig = _design(params, runs, known, s)
        assert sig.columns is not None
        cols.append(RobotModel(known, "usual", base=kbase, payload_ratio=True).fit(sig))
        states.append(RobotModel(known, "usual", base=kbase, payload_ratio=True).fit(
            replace(sig, columns=None)))
    _check_recovery(cols, truth)
    for m in cols:
        i = m.names_.index(RATIO)
        z, _ = _z(m, truth)
        assert abs(z[i]) <= 3, (m.coef_[i], m.std_[i])
    nb = cols[0].n_base_ + 1  # base parameters, then the ratio
    assert cols[0].names_[nb - 1] == RATIO
    z_fw = max(3.0, float(scipy.stats.norm.ppf(1 - 0.01 / (2 * nb * len(seeds)))))
    for a, b in zip(cols, states, strict=True):
        assert a.names_[:nb] == b.names_[:nb]
        d = (a.coef_[:nb] - b.coef_[:nb]) / np.hypot(a.std_[:nb], b.std_[:nb])
        worst = int(np.argmax(np.abs(d)))
        assert abs(d[worst]) <= z_fw, (a.names_[worst], float(d[worst]))
