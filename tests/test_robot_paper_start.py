"""Issue 22 item 1: the paper model on a 6-axis arm whose wrists are friction-dominated, from
ONE experiment (one payload).

Data: the offline n-dof simulator (sim_drivers.arm, examples/robots/ur10.toml, as
tests/test_robot_fit.py) with the paper's friction on every joint, the wrists' dry friction
raised above their loads (c_m, c_g of the order of the largest |tau_out| of the wrist), one
run with a 5 kg payload. On such wrists sign(tau dq) is "motor" on (nearly) every row, so a
start from the measured quadrant leaves a_g ... d_g without excitation, while the model
quadrant sign(tau_out dq) puts about half the rows in the generator quadrant.

Asserted: the measured quadrant leaves the wrists without generator rows: their a_g ... d_g
are dropped (zero columns, held at 0, the rank rule of every fit; until 2026-11-28 the whole
model was refused) with the evidence (rows per quadrant) and the fix (quadrant='model'); the
default (model quadrant from the usual fit) identifies the model; one payload does not fix the
scale of theta against a, b (its torque is in the span of the base columns), so a_m of the
first joint is fixed; the fitted theta puts (nearly) every row in the quadrant the true theta
puts it in, and per joint the error on the rows both fits take is within 5 % of the TRUE
structure's (the same estimator with the quadrants decided by the true theta).
"""

from __future__ import annotations

import copy

import numpy as np
import pytest
from sigma_cases import PAYLOAD, wrist_arm
from test_robot_fit import _signals

from ident.robot.estimate import RobotModel
from sim_drivers.arm import ArmGains, model_reference, simulate_arm

WITHIN = 1.05


@pytest.fixture(scope="module")
def ur10_wrists():
    params, reg, base = wrist_arm(noise=None)  # the wrists' friction above their loads
    ref = model_reference(params.model, center=[0.0, -1.9, 0.6, -1.0, 0.5, 0.0],
                          fraction=0.9, duration_s=20.0, seed=1)
    run = simulate_arm(params, ref, ArmGains.for_params(params, payload=PAYLOAD),
                       payload=PAYLOAD, seed=10)
    import test_robot_fit
    saved = test_robot_fit.PAYLOADS
    test_robot_fit.PAYLOADS = (PAYLOAD,)
    try:
        sigs = _signals(params, reg, [run], 0)
    finally:
        test_robot_fit.PAYLOADS = saved
    return params, reg, base, sigs


def test_measured_quadrant_drops_the_wrists_generator_columns_with_evidence(ur10_wrists):
    params, reg, base, sigs = ur10_wrists
    s = sigs[0]
    ok = np.isfinite(s.tau[:, 3:])
    motor = np.mean((s.tau[:, 3:] * s.dq[:, 3:] > 0)[ok])
    assert motor > 0.99  # friction-dominated: the measured power is "motor"
    m = RobotModel(reg, "paper", "wls", base=base, quadrant="measured").fit(sigs)
    empty = [j for j, (_, gen) in m.quadrant_rows_.items() if gen == 0]
    assert empty and set(empty) <= {"wrist_1_joint", "wrist_2_joint", "wrist_3_joint"}
    # the generator columns of exactly the joints without generator rows: held at 0
    nums = [n for j, n in zip(reg.joints, reg.numbers, strict=True) if j in empty]
    want = {f"{p}{n}" for n in nums for p in ("a_g", "b_g", "c_g", "d_g")}
    assert {n for n, _ in m.removed_} == want, m.removed_
    assert all(m.fixed_[n] == 0.0 for n in want)
    msg = " ".join(m.dropped_evidence_)
    assert "\n" not in msg
    assert "rows motor" in msg and "generator" in msg and "Fix:" in msg, msg
    assert "quadrant='model'" in msg and all(j in msg for j in empty), msg


def test_paper_model_identified_within_true_structure(ur10_wrists):
    """IDIM-WLS (the CLI's default): with LS the wrists' rows, whose noise is far below the
    shoulder's, weigh nothing in the shared theta, which is then decided by the big joints
    (on the wrists both LS fits, ours and the true structure's, are far above the noise).

    Two claims. (1) The model quadrant recovers the true quadrants: per joint, every row whose
    sign(tau_out_hat dq) with the fitted theta differs from the one with the TRUE theta has a
    true load inside the fit's quadrant band ``band_`` (|tau_out| ~ 0, where the sign is
    decided by noise; on this machine 0 to 26 rows of about 19 000 per joint).
    (2) On the rows both fits take (their ``fitted_rows``), our error is within 5 % of the
    true structure's. Not on every sample: there the true structure's prediction decides the
    band's rows by the true theta (an oracle), and on a friction-dominated joint one row with
    |tau_out| = 1e-4 N m on the other side of the boundary costs the jump c_m - c_g (one such
    row made 1.65x on wrist_2 while both fits' parameters give the same error on their rows).
    """
    params, reg, base, sigs = ur10_wrists
    method = "wls"
    m = RobotModel(reg, "paper", method, base=base).fit(sigs)
    assert m.fixed_ == {"a_m1": 1.0}  # one payload: its torque is W (its base parameters)
    for joint in reg.joints[3:]:  # both quadrants visited by the model quadrant
        motor, gen = m.quadrant_rows_[joint]
        assert min(motor, gen) > 0.2 * (motor + gen), (joint, motor, gen)
    truth = params.truth(None)
    theta = m.truth_vector(truth)[:m.n_theta_]
    true = RobotModel(reg, "paper", method, base=base, quadrant_theta=theta).fit(sigs)
    s = sigs[0]
    # (1) quadrants: the fitted theta's against the true theta's (the load with the true theta
    # is the true structure's model with its theta replaced by the truth)
    oracle = copy.copy(true)
    oracle.coef_ = true.coef_.copy()
    oracle.coef_[:true.n_theta_] = theta
    load_hat, load_true = m.load_torque(s), oracle.load_torque(s)
    usable = (np.isfinite(load_hat) & np.isfinite(load_true) & np.isfinite(s.tau)
              & (np.abs(s.dq) > m.dq_min))
    for j, joint in enumerate(reg.joints):
        ok = usable[:, j]
        flip = ok & (np.sign(load_hat[:, j] * s.dq[:, j]) != np.sign(load_true[:, j] * s.dq[:, j]))
        assert np.all(np.abs(load_true[flip, j]) < m.band_[j]), (
            joint, np.abs(load_true[flip, j]).max(), m.band_[j])
    # (2) the error on the rows both fits take
    both = m.fitted_rows(s) & true.fitted_rows(s)
    ours = _rel_on(m.residual(s), s.tau, both)
    ref = _rel_on(true.residual(s), s.tau, both)
    ratio = ours / ref
    print(f"\n{method}: ours {ours}\n true structure {ref}\n ratio {ratio}")
    bad = {j: round(float(r), 3) for j, r in zip(reg.joints, ratio, strict=True) if r > WITHIN}
    assert not bad, (bad, ours, ref)


def _rel_on(rho: np.ndarray, tau: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """||rho_j|| / ||tau_j|| per joint on ``rows`` (n, k) bool, shape (k,)."""
    r2 = np.where(rows, rho, 0.0) ** 2
    y2 = np.where(rows, tau, 0.0) ** 2
    return np.sqrt(r2.sum(0) / y2.sum(0))
