"""The Gauss-Newton sums of the n-dof estimator (ident.robot.moments.JointMoments): the cost
alone equals the normal equations' residual to the last bit, and the structured normal
equations (the theta block of the Jacobian a scaled identity) equal the dense products of
the module doc, for least squares and IDIM-IV, in both quadrants; the sums of all joints at
once (ident.robot.packed.PackedMoments) equal the per-joint ones, and the fit is the same
with either."""

from __future__ import annotations

import numpy as np
import pytest

from ident.robot import estimate
from ident.robot.estimate import RobotModel
from ident.robot.moments import N_EXTRA, JointMoments
from ident.robot.paper import paper_coefficients, usual_coefficients
from tests.test_robot_fit import _signals, _simulate
from trajectories.friction import quadrant_weights


def _moments(rng, nt: int, m: int, iv: bool) -> JointMoments:
    scale = 10.0 ** rng.uniform(-3, 2, nt)
    VT = np.empty((nt + N_EXTRA, m))
    VT[:nt] = rng.standard_normal((nt, m)) * scale[:, None]
    dq = rng.standard_normal(m)
    VT[nt:] = [rng.standard_normal(m), np.sign(dq), dq, np.ones(m), rng.standard_normal(m)]
    mom = JointMoments(np.arange(nt), iv=iv)
    VzT = VT + 0.1 * rng.standard_normal(VT.shape) if iv else None
    mom.add(VT, quadrant_weights(rng.standard_normal(m)), np.exp(-np.abs(dq) / 0.3), VzT)
    return mom


def _dense(mom: JointMoments, coeffs):
    """The normal equations as the module doc writes them: sum over (e, f) of
    D_e^T M[e + f] D_f, every product dense."""
    nv = mom.nv
    ey = np.zeros(nv)
    ey[-1] = 1.0
    nx = coeffs[0][2].shape[1]
    A, g, C = np.zeros((nx, nx)), np.zeros(nx), np.zeros((nx, nx))
    mz = mom.zv if mom.iv else mom.vv
    for s in (0, 1):
        c0, c1, D0, D1 = coeffs[s]
        d, D = (ey - c0, -c1), (D0, D1)
        for e in (0, 1):
            for f in (0, 1):
                A += D[e].T @ mz[s, e + f] @ D[f]
                g += D[e].T @ mz[s, e + f] @ d[f]
                if mom.iv:
                    C += D[e].T @ mom.zz[s, e + f] @ D[f]
    return A, g, C


@pytest.mark.parametrize("iv", [False, True])
@pytest.mark.parametrize("model", ["paper", "usual", "paper-start"])
def test_structured_normal_equals_dense_products(model, iv):
    rng = np.random.default_rng(3 + iv)
    nt = 9
    mom = _moments(rng, nt, 4000, iv)
    theta = rng.standard_normal(nt)
    if model == "usual":
        blk = rng.standard_normal(3)
        cf = [usual_coefficients(theta, blk, s) for s in (0, 1)]
    else:
        blk = rng.standard_normal(10)
        if model == "paper-start":  # b = d = 0: c1 = 0, D1 not
            blk[[1, 3, 5, 7]] = 0.0
        cf = [paper_coefficients(theta, blk, s) for s in (0, 1)]
    A, g, rr, C, _ = mom.normal(cf)
    A0, g0, C0 = _dense(mom, cf)
    scale = np.sqrt(np.abs(np.diag(A0)))
    np.testing.assert_allclose(A / np.outer(scale, scale), A0 / np.outer(scale, scale),
                               rtol=0, atol=1e-12)
    np.testing.assert_allclose(g / scale, g0 / scale, rtol=0,
                               atol=1e-12 * np.abs(g0 / scale).max())
    if iv:
        np.testing.assert_allclose(C, C0, rtol=1e-12, atol=1e-12 * np.abs(C0).max())
    else:
        assert C is None
    coarse = [(c0, c1) for c0, c1, _, _ in cf]
    assert mom.cost(coarse) == rr  # the same sums in the same order: to the last bit
    # the Jacobian-free coefficients are the full ones' c0, c1
    fn = usual_coefficients if model == "usual" else paper_coefficients
    for s in (0, 1):
        c0, c1 = fn(theta, blk, s, jacobian=False)
        assert np.array_equal(c0, cf[s][0]) and np.array_equal(c1, cf[s][1])


def test_general_jacobian_falls_back_to_dense_products():
    """A Jacobian whose theta block is not a scaled identity (any other model) still gets
    the dense products."""
    rng = np.random.default_rng(5)
    nt = 6
    mom = _moments(rng, nt, 2000, False)
    cf = []
    for s in (0, 1):
        c0, c1, D0, D1 = paper_coefficients(rng.standard_normal(nt), rng.standard_normal(10), s)
        D0 = D0.copy()
        D0[0, 1] = 0.7  # off the diagonal
        cf.append((c0, c1, D0, D1))
    A, g, _, _, _ = mom.normal(cf)
    A0, g0, _ = _dense(mom, cf)
    np.testing.assert_allclose(A, A0, rtol=1e-12, atol=1e-12 * np.abs(A0).max())
    np.testing.assert_allclose(g, g0, rtol=1e-12, atol=1e-12 * np.abs(g0).max())


@pytest.fixture(scope="module")
def arm3_fit():
    params, reg, base, runs = _simulate("arm3", duration_s=8.0, seed=2)
    return reg, base, _signals(params, reg, runs, 5)


@pytest.mark.parametrize("model", ["paper", "usual"])
def test_packed_sums_equal_the_per_joint_sums(arm3_fit, model):
    """At the fitted point and along a random step: J^T W J, J^T W r and the line cost's
    polynomial of all joints at once equal the per-joint evaluation (module doc)."""
    reg, base, sigs = arm3_fit
    m = RobotModel(reg, model, "wls", base=base).fit(sigs)
    moms = m._pass(sigs, m.coef_[:m.n_theta_] if model == "paper" else None, 3)[0]
    coeffs = paper_coefficients if model == "paper" else usual_coefficients
    packed = m._packed(moms, coeffs)
    assert packed is not None
    rng = np.random.default_rng(0)
    x = m.coef_ * (1 + 0.01 * rng.standard_normal(m.coef_.size))
    step = 0.1 * m.coef_ * rng.standard_normal(m.coef_.size)
    w = np.array([0.5, 2.0, 1.0])
    A, g = packed.normal(x, w)
    A0, g0, _, _, _ = m._normal(moms, coeffs, x, w)
    s = np.sqrt(np.abs(np.diag(A0)))
    np.testing.assert_allclose(A / np.outer(s, s), A0 / np.outer(s, s), rtol=0, atol=1e-12)
    np.testing.assert_allclose(g / s, g0 / s, rtol=0, atol=1e-12 * np.abs(g0 / s).max())
    poly = packed.line_cost(x, step, w)
    poly0 = m._line_cost(moms, coeffs, x, step, w)
    np.testing.assert_allclose(poly, poly0, rtol=1e-10, atol=1e-12 * np.abs(poly0).max())
    for lam in (0.0, 0.3, 1.0):  # and the polynomial is the cost at x + lam step
        cost = float(w @ m._cost(moms, coeffs, x + lam * step))
        assert np.polyval(poly[::-1], lam) == pytest.approx(cost, rel=1e-9)


def test_packed_and_per_joint_fits_agree(arm3_fit, monkeypatch):
    """The paper model fitted with the sums of all joints at once and joint by joint: the
    same estimate and standard deviations (rounding apart)."""
    reg, base, sigs = arm3_fit
    a = RobotModel(reg, "paper", "wls", base=base).fit(sigs)
    monkeypatch.setattr(estimate.RobotModel, "_packed", lambda self, moms, coeffs: None)
    b = RobotModel(reg, "paper", "wls", base=base).fit(sigs)
    assert a.n_iter_ == b.n_iter_ and a.n_passes_ == b.n_passes_
    np.testing.assert_allclose(a.coef_, b.coef_, rtol=1e-8, atol=1e-10 * np.abs(b.coef_).max())
    np.testing.assert_allclose(a.std_, b.std_, rtol=1e-6)
