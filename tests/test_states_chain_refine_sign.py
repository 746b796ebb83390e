"""The refinement of one joint of an n-dof fit reads the fit's Coulomb column
(``jointid fit --robot [--chain states] --refine``).

The n-dof fit's rows are decimated samples. Their torque's dry friction is the low-pass of
c sign(dq) (the decimation's anti-alias filter): near a reversal a ramp over a few rows,
which the fit's Coulomb column follows (``RobotSignals.sign``: sign(dq) formed at full rate
and decimated with the torque; tests/test_robot_states_chain.py). The refinement's
single-joint design and the n-dof refit's extra columns are evaluated on those decimated
rows (:func:`ident.robot.refine_joint.fit_rows_design`, ``joint_term_columns``): they carry
the same column as :attr:`Signals.sign <ident.signals.Signals.sign>`, read through
:attr:`Signals.direction <ident.signals.Signals.direction>` (the library's Coulomb and
quadrant Coulomb columns, and any term that reads the direction).

Data: the simulated 3-dof arm (examples/robots/arm3.toml) with a symmetric Stribeck dry
friction the usual model lacks, (c + d exp(-|dq|/q_s)) sign(dq) (c_g = c_m, d_g = d_m,
a = 1, b = 0), three payload runs, 1 % torque noise, two noise seeds, the columns and the
states chain. Measured (seeds 0, 1), the n-dof refit with the Stribeck column at the true q_s
on every joint: its sign read from the carried column, the shoulder's FC2 is +1.13 / +2.08
sigma off the truth on the states chain (-1.72 / -0.26 on the columns chain); from the sign
of the decimated dq (what the refit's columns were), +11.54 / +12.37 sigma, and F_S2 -18.7
sigma (-4.2 / -4.4 with the carried sign: what is left is exp(-|dq|/q_s) of the decimated
dq, not the product decimated; docs/robot-identification.md).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.stats
from robot_campaigns import ARM3, ARM3_CENTRE, ARM3_PAYLOADS

from ident.models import Coulomb, QuadrantCoulomb
from ident.preprocess import TORQUE_DELAY
from ident.robot.base import base_parameters
from ident.robot.design import design_runs, resolve_design
from ident.robot.estimate import RobotModel
from ident.robot.loaders import RawRobotRun, RobotPreprocessing, preprocess_runs
from ident.robot.refine_joint import joint_term_columns, refine_joint
from ident.robot.refit import extra_name, refit_robot
from ident.robot.regressor import RobotRegressor
from ident.robot.signals import RobotPayloadData
from ident.signals import Signals
from ident.terms import Term
from sim_drivers.arm import ArmGains, ArmParams, model_reference, simulate_arm
from trajectories.friction import stribeck_exp
from trajectories.robot import load_robot

SEEDS = (0, 1)
NOISE = 0.01  # fraction of each joint's load


class _Stribeck(Term):
    """F_S exp(-|dq|/q_s) times the direction: the samples' :attr:`Signals.direction`
    (``step=False``, the carried column) or the sign of their dq (``step=True``)."""

    effect = "stribeck"
    variable = "velocity"

    def __init__(self, q_s: float, step: bool = False) -> None:
        self.q_s, self.step = q_s, step

    def names(self) -> tuple[str, ...]:
        return ("F_S",)

    def columns(self, s: Signals) -> np.ndarray:
        d = np.sign(s.dq) if self.step else s.direction
        return (stribeck_exp(s.dq, self.q_s) * d)[:, None]


@pytest.fixture(scope="module")
def stribeck_arm():
    """Per noise seed the columns chain's and the states chain's signals, with the usual LS
    fit on each; the regressor and the true c, d, q_s."""
    robot = load_robot(ARM3)
    f0 = ArmParams.from_robot(robot).friction
    params = ArmParams.from_robot(robot, dict(a_m=1.0, b_m=0.0, a_g=1.0, b_g=0.0,
                                              c_g=f0.c_m, d_g=f0.d_m))
    ref = model_reference(params.model, center=ARM3_CENTRE, fraction=0.9, duration_s=12.0,
                          seed=3)
    runs = [simulate_arm(params, ref, ArmGains.for_params(params, payload=p), payload=p,
                         seed=30 + i) for i, p in enumerate(ARM3_PAYLOADS)]
    reg = RobotRegressor(robot)
    base = base_parameters(reg)
    out = []
    for seed in SEEDS:
        rng = np.random.default_rng(seed)
        sd = NOISE * params.drive.torque_noise_std_Nm / 0.01
        raw = [RawRobotRun(f"payload {r.payload_mass_kg} kg", r.t, r.q_true,
                           r.tau_applied + rng.standard_normal(r.tau_applied.shape) * sd,
                           q_ref=r.q_ref,
                           payload=RobotPayloadData() if p is None
                           else RobotPayloadData(p.mass, p.com, p.inertia))
               for r, p in zip(runs, ARM3_PAYLOADS, strict=True)]
        with warnings.catch_warnings():  # (the cut-off at its lower bound: the arm's motion)
            warnings.simplefilter("ignore", UserWarning)
            chains = {
                "columns": design_runs(raw, reg, resolve_design(
                    raw, torque_delay=TORQUE_DELAY))[0],
                "states": preprocess_runs(raw, reg.joints,
                                          RobotPreprocessing(torque_delay=TORQUE_DELAY))}
        out.append({name: (sig, RobotModel(reg, "usual", "ls", base=base).fit(sig))
                    for name, sig in chains.items()})
    truth = (params.friction.c_m, params.friction.d_m, float(params.friction.q_s[0]))
    return reg, truth, out


@pytest.mark.parametrize("chain", ["columns", "states"])
def test_refinement_design_reads_the_fits_coulomb_column(stribeck_arm, chain):
    """The refinement's design (the fit's kept rows) has the fit's Coulomb column as its
    F_C column and as its signals' direction (what the candidates are scored on), and the
    refit's term columns read it: RobotSignals.sign on those rows, fractional at the
    reversals -- not the step sign of the decimated dq."""
    _, _, out = stribeck_arm
    sig, fit = out[0][chain]
    assert sig.sign is not None and np.all(np.diff(sig.experiment) >= 0)  # rows in order
    keep, pred = fit.fitted_rows(sig), fit.predict(sig)
    for j in range(sig.k):
        ref = refine_joint(sig, pred, j, max_steps=0, keep=keep)
        d = ref.final_design
        want = sig.sign[keep[:, j], j]
        np.testing.assert_array_equal(d.W[:, d.names.index("F_C")], want)
        np.testing.assert_array_equal(d.signals.direction, want)
        assert np.any(np.abs(want) < 0.99), j  # fractional at its reversals: not the step
        np.testing.assert_array_equal(joint_term_columns(sig, pred, j, Coulomb())[:, 0],
                                      sig.sign[:, j])
        qc = QuadrantCoulomb(0.03).columns(d.signals)  # P+ sign + P- sign = the direction
        np.testing.assert_allclose(qc[:, 0] + qc[:, 2], want, rtol=0, atol=1e-12)


@pytest.mark.parametrize("chain", ["columns", "states"])
def test_refit_recovers_coulomb_with_the_carried_sign(stribeck_arm, chain):
    """The n-dof refit with a Stribeck column on every joint (the true q_s), its sign read
    from the refinement's signals (``Signals.direction``): every FC_j within the family-wise
    bound of its stated sigma of the truth, two seeds, both chains. On the states chain with
    the sign of the decimated dq instead (``step=True``: the refit's columns before the
    fit's sign was carried) the shoulder's FC2 falls outside that bound (module docstring:
    +11.5 / +12.4 sigma), the bias this guards against."""
    reg, (c, d_true, q_s), out = stribeck_arm
    k = len(reg.joints)
    S = len(out)
    z_fw = max(3.0, float(scipy.stats.norm.ppf(1 - 0.01 / (2 * k * S))))
    z_step = []
    for by_chain in out:
        sig, fit = by_chain[chain]
        keep, pred = fit.fitted_rows(sig), fit.predict(sig)
        for step in (False, True):
            rf = refit_robot(fit, sig, [(j, _Stribeck(q_s, step)) for j in range(k)],
                             prediction=pred, keep=keep)
            z = _z(rf, [f"FC{n}" for n in reg.numbers], c)
            zs = _z(rf, [extra_name(joint, "F_S") for joint in reg.joints], d_true)
            print(f"\n{chain} {'step sign' if step else 'carried'}: FC z "
                  f"{np.round(z, 2).tolist()}, F_S z {np.round(zs, 2).tolist()} (F_S: not "
                  "asserted, exp(-|dq|/q_s) of the decimated dq)")
            if not step:
                assert np.all(np.abs(z) <= z_fw), (chain, z, z_fw)
            else:
                z_step.append(z[1])
    if chain == "states":
        assert min(abs(z) for z in z_step) > z_fw, (z_step, z_fw)


def _z(rf, names: list[str], truth) -> np.ndarray:
    """(estimate - truth) / std of the refit's parameters ``names``."""
    i = [rf.names_.index(n) for n in names]
    return (rf.coef_[i] - np.asarray(truth, dtype=float)) / rf.std_[i]
