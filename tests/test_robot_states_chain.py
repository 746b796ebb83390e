"""The states chain's Coulomb column (``jointid fit --robot --chain states``).

The decimated torque's Coulomb part is the low-pass (the decimation's anti-alias filter) of
c sign(dq): near a velocity reversal a ramp over a few decimated samples. sign() of the
decimated velocity is a step there; fitted against it the Coulomb parameter came out biased
low (the shoulder's FC2 of the simulated arm 7-10 sigma off the truth, while the columns
chain, whose sign(dq) is formed at full rate and decimated with the torque, recovered it).
The states chain now carries sign(dq) formed at full rate and decimated with the torque
(``RobotSignals.sign``), and the estimator reads it.
"""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
import pytest
import scipy.stats
from test_robot_fit import ROOT, _check_recovery, _simulate, _z, noisy_raw_runs

from ident.preprocess import TORQUE_DELAY
from ident.robot.design import design_runs, resolve_design
from ident.robot.estimate import RobotModel
from ident.robot.loaders import RobotPreprocessing, preprocess_runs
from ident.robot.signals import RobotSignals
from sim_drivers.arm import ArmParams
from trajectories.robot import load_robot

SEEDS = (0, 1)


@pytest.fixture(scope="module")
def arm3_chains():
    """The simulated 3-dof arm with the usual friction model, payloads known; per noise seed
    the raw runs, the columns chain's signals and the states chain's."""
    robot = load_robot(ROOT / "examples" / "robots" / "arm3.toml")
    c = ArmParams.from_robot(robot).friction.c_m
    friction = dict(a_m=1.0, b_m=0.0, a_g=1.0, b_g=0.0, d_m=0.0, d_g=0.0, c_g=c)
    params, reg, base, runs = _simulate("arm3", friction, duration_s=12.0, seed=3)
    truth = params.truth(None)
    for j in reg.numbers:
        truth[f"FC{j}"] = truth[f"c_m{j}"]
    return reg, base, truth, [noisy_chains(params, reg, runs, seed) for seed in SEEDS]


def noisy_chains(params, reg, runs, seed: int) -> tuple[RobotSignals, RobotSignals]:
    """The runs' true positions and applied torque plus 1 % noise (noise seed ``seed``),
    payloads known, through the columns chain and the states chain (also
    benchmarks/refine_direction.py's data)."""
    raw = noisy_raw_runs(params, runs, seed)
    with warnings.catch_warnings():  # (the cut-off at its lower bound: the arm's motion)
        warnings.simplefilter("ignore", UserWarning)
        settings = resolve_design(raw, torque_delay=TORQUE_DELAY)
        columns = design_runs(raw, reg, settings)[0]
        states = preprocess_runs(raw, reg.joints, RobotPreprocessing(torque_delay=TORQUE_DELAY))
    return columns, states


def _fit(reg, base, sig) -> RobotModel:
    return RobotModel(reg, "usual", "ls", base=base).fit(sig)


def test_states_chain_carries_the_decimated_sign(arm3_chains):
    """The states chain's Coulomb column is sign(dq) low-passed with the torque: within
    [-1, 1] up to the anti-alias filter's overshoot, fractional at the reversals only."""
    _, _, _, out = arm3_chains
    for columns, states in out:
        for sig in (columns, states):
            assert sig.sign is not None and sig.sign.shape == sig.dq.shape
        # the columns chain hands its own decimated sign column to the states path
        assert columns.sign is columns.columns.sign
        s = states.sign
        frac = (np.abs(s) < 0.99) & (np.abs(s) > 0.01)
        assert 0 < np.count_nonzero(frac) < 0.1 * s.size  # reversals, a few rows each
        assert np.all(np.sign(s[np.abs(s) > 0.99]) == np.sign(states.dq[np.abs(s) > 0.99]))


@pytest.mark.parametrize("chain", ["states", "columns-states"])
def test_coulomb_recovered_on_the_states_path(arm3_chains, chain):
    """Every parameter within the family-wise bound of its stated sigma (``_check_recovery``)
    on the states chain (``preprocess_runs``) and on the states path over the columns chain's
    decimated states (``replace(signals, columns=None)``), two noise seeds, as on the columns
    chain; with the sign of the decimated dq instead (``sign=None``, the old Coulomb column)
    the shoulder's FC2 falls outside that bound (the bias this guards against)."""
    reg, base, truth, out = arm3_chains
    sigs = [s if chain == "states" else replace(c, columns=None) for c, s in out]
    fits = [_fit(reg, base, s) for s in sigs]
    _check_recovery(fits, truth)
    _check_recovery([_fit(reg, base, c) for c, _ in out], truth)  # the default chain
    P, S = len(fits[0].names_), len(fits)
    z_fw = max(3.0, float(scipy.stats.norm.ppf(1 - 0.01 / (2 * P * S))))
    for m in fits:
        z, _ = _z(m, truth)
        for j in reg.numbers:
            assert abs(z[m.names_.index(f"FC{j}")]) <= z_fw, (f"FC{j}", z)
    old = _fit(reg, base, replace(sigs[0], sign=None))
    z_old, _ = _z(old, truth)
    assert abs(z_old[old.names_.index("FC2")]) > z_fw, z_old


def test_soft_quadrants_take_the_states_chains_sign(arm3_chains):
    """The soft-quadrant fit's rows (``ident.robot.soft_fit._rows``, read on a fitted paper
    model as ``fit_soft`` does after its hard start) carry the same Coulomb column as the hard
    fit on the states chain: the decimated sign(dq), fractional near reversals, not the step
    sign of the decimated dq."""
    from ident.robot import soft_fit

    reg, base, _truth, out = arm3_chains
    states = out[0][1]
    model = RobotModel(reg, "paper", "ls", base=base).fit(states)
    for j, jr in enumerate(soft_fit._rows(model, states)):
        assert np.all(np.isin(jr.sgc, states.sign[:, j])), j  # the chain's column
        assert np.any(np.abs(jr.sgc) < 0.99), j  # fractional at its reversals: not the step
