"""The n-dof paper fit drops the columns the data do not excite instead of refusing the model.

``jointid fit --robot`` refused the whole paper model when some of its columns were zero on
the data (a joint with no row in one quadrant: "parameters not identifiable on these data:
['a_m4', 'b_m4', 'c_m4', 'd_m4'] have no excitation", the real KUKA KR300 at ``--trim 67``),
where the single-joint fit drops them (the rank rule of every fit,
:func:`ident.estimators.rank_rule`). The bilinear Gauss-Newton fit now applies the same rule
when its normal equations are singular: those columns are held at 0 (``fixed_``), their
reason in ``removed_``, the refusal's evidence (rows per quadrant and load sign, what
trajectory would fix it) in ``dropped_evidence_``, and the fit goes on.

Synthetic case: the 3-dof arm with the usual friction written as the paper's (a_m = a_g = 1,
b = d = 0, c_g = c_m), the elbow's rows kept only where its true load tau_out (the applied
torque minus the true friction) is of the velocity's sign by more than 5 noise sigmas (chosen
on noise-free quantities: no selection on the noise). With the model quadrants (the default)
the elbow then has no generator row: a_g3, b_g3, c_g3, d_g3 have zero columns, are dropped,
and every other parameter is recovered within its stated sigma of the truth (the family-wise
bound of tests/test_robot_fit.py's criterion). On main this fit was refused.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.stats
from test_robot_fit import NOISE, PAYLOADS, _signals, arm3_usual_data

from ident.estimators import ZERO_COLUMN
from ident.robot.estimate import RobotModel
from ident.robot.signals import RobotPayloadData, RobotSignals

ELBOW = 2  # the joint left without generator rows (arm3's third)
MARGIN = 5.0  # noise sigmas between the kept rows' true torque and zero


@pytest.fixture(scope="module")
def arm3_usual():
    """tests/test_robot_fit.py's ``arm3_usual``: the usual friction in the paper's form."""
    return arm3_usual_data()


def _motor_only_signals(params, reg, runs, seed: int) -> list[RobotSignals]:
    """tests/test_robot_fit.py's ``_signals`` with the elbow's rows kept only where its true
    load is of the dq's sign by MARGIN noise sigmas (motor quadrant)."""
    rng = np.random.default_rng(seed)
    sd = NOISE * params.drive.torque_noise_std_Nm / 0.01
    truth = params.truth(None)
    n = reg.numbers[ELBOW]
    out = []
    for r, p in zip(runs, PAYLOADS, strict=True):
        tau = r.tau_applied + rng.standard_normal(r.tau_applied.shape) * sd
        dq = r.dq_true[:, ELBOW]
        # the usual friction (a = 1, b = d = 0): tau = tau_out + c sign(dq) + FV dq + OFF
        load = r.tau_applied[:, ELBOW] - (truth[f"c_m{n}"] * np.sign(dq)
                                          + truth[f"FV{n}"] * dq + truth[f"OFF{n}"])
        keep = r.sliding.copy()
        keep[:, ELBOW] &= load * np.sign(dq) > MARGIN * np.broadcast_to(
            sd, r.tau_applied.shape)[:, ELBOW]
        tau = np.where(keep, tau, np.nan)
        pay = RobotPayloadData() if p is None else RobotPayloadData(p.mass, p.com, p.inertia)
        out.append(RobotSignals(t=r.t, q=r.q_true, dq=r.dq_true, ddq=r.ddq_true, tau=tau,
                                joints=reg.joints, payloads=(pay,), q_ref=r.q_ref,
                                source=f"sim payload {r.payload_mass_kg} kg"))
    return out


def test_joint_without_generator_rows_drops_its_generator_columns(arm3_usual):
    params, reg, base, runs = arm3_usual
    truth = params.truth(None)
    seeds = (0, 1, 2)  # as test_robot_fit.py's paper recovery
    fits = [RobotModel(reg, "paper", base=base).fit(
        _motor_only_signals(params, reg, runs, s)) for s in seeds]
    gen = [f"{p}{reg.numbers[ELBOW]}" for p in ("a_g", "b_g", "c_g", "d_g")]
    z_all, rel_all = [], []
    for m in fits:
        # the elbow's generator columns are zero: dropped with the reason, held at 0
        assert m.quadrant_rows_[reg.joints[ELBOW]][1] == 0, m.quadrant_rows_
        assert dict(m.removed_) == {n: ZERO_COLUMN for n in gen}, m.removed_
        assert all(m.fixed_[n] == 0.0 and m.params_[n] == 0.0 for n in gen)
        ev = " ".join(m.dropped_evidence_)
        assert f"{reg.joints[ELBOW]}: " in ev and " 0 generator" in ev and "Fix:" in ev, ev
        # every other parameter: the truth within its stated sigma (family-wise bound, as
        # tests/test_robot_fit.py's _check_recovery)
        free = np.array([n not in m.fixed_ for n in m.names_])
        assert free.sum() == len(m.names_) - len(gen)
        tv = m.truth_vector(truth)
        err = m.coef_[free] - tv[free]
        z = err / m.std_[free]
        assert np.all(np.isfinite(z))
        z_all.append(z)
        rel_all.append(np.abs(err) / np.maximum(np.abs(tv[free]), 1e-300))
    z, rel = np.concatenate(z_all), np.concatenate(rel_all)
    # "within 3 sigma or 1 %", the family-wise bound for the worst (as _check_recovery)
    z_fw = max(3.0, float(scipy.stats.norm.ppf(1 - 0.01 / (2 * z.size))))
    # (not its "95 % within 3 sigma": the paper model on these usual-friction data misses it
    # without any row left out too, measured: 91 % on seed 1, 87 % on seed 3; the shoulder's
    # MX2R, MY2, c_g2, OFF2 at 3.2-3.4 sigma on both)
    assert np.all((np.abs(z) <= z_fw) | (rel <= 0.01)), np.max(np.abs(z))


def test_untouched_data_drop_nothing(arm3_usual):
    """With both quadrants on every joint nothing is dropped (the rule runs only where the
    fit was refused)."""
    params, reg, base, runs = arm3_usual
    m = RobotModel(reg, "paper", base=base).fit(
        _signals(params, reg, runs, 0))
    assert m.removed_ == [] and m.dropped_evidence_ == [] and m.fixed_ == {}
