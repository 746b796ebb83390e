"""A joint is a 1-dof robot (issue 24): :func:`ident.one_joint.fit_one_joint` -- the one-joint
robot, the columns chain, the sign check, the products formed at full rate and
``RobotModel`` with the single-joint elimination -- gives ``ident.fitting.fit_models``'
numbers: values, standard deviations, relative deviations, covariance, sigma_rho, residual,
relative error, condition number, removed parameters and rows, to 1e-8 (measured: 5e-12 at
worst on the example campaign, 4e-13 on EMPS; the raw condition number, from the Gram
matrix's eigenvalues, 4e-9)."""

from __future__ import annotations

import numpy as np
import pytest
from example_campaign import simulate_example_campaign

from ident import DataError
from ident.fitting import fit_models
from ident.loaders import load_experiment, make_experiment
from ident.one_joint import fit_one_joint
from ident.robot import RobotIdentError
from ident.robot.estimate import RobotModel
from tests.conftest import shared_path
from trajectories.robot import RobotRegressor, one_joint_robot

RTOL = 1e-8


@pytest.fixture(scope="module")
def campaign():
    """The example campaign simulated offline (seeds 11-13): its runs and each run's
    reference position (the planned trajectory at its cycles) [rad]."""
    _, plan, sims = simulate_example_campaign(11)
    refs = [plan.reference.q[np.minimum(r.cycle, plan.reference.q.size - 1)] for r in sims]
    return plan, sims, refs


def _experiments(campaign, suffix: str, with_ref: bool):
    plan, sims, refs = campaign
    return [make_experiment(f"payload{i}.{suffix}", r.t, r.q, r.tau_ref,
                            q_ref=q if with_ref else None, payload_mass=p.mass_kg,
                            payload_arm=p.arm_m)
            for i, (p, r, q) in enumerate(zip(plan.payloads, sims, refs, strict=True))]


def _assert_same(report, ours) -> None:
    """Every number of each model of ``report`` (fit_models) in ``ours`` (fit_one_joint)."""
    assert set(report.models) == set(ours.models)
    assert report.q_s == ours.q_s and report.revolute == ours.revolute
    assert [n for n in report.notes if "condition" not in n] == ours.notes
    d = next(iter(report.designs.values())).settings()
    for k in ("cutoff_hz", "decimation", "trim", "guard", "torque_delay", "dq_min"):
        assert ours.settings.as_dict()[k] == d[k], k
    for name, m in report.models.items():
        o = ours.models[name]
        assert o.names == m.names_, name
        assert o.removed == m.removed_, name
        assert o.estimator == m.estimator_ and o.m == m.result_.m == len(report.designs[name])
        for n in m.names_:
            assert o.values[n] == pytest.approx(m.coef_[n], rel=RTOL), (name, n)
            assert o.std[n] == pytest.approx(m.std_[n], rel=RTOL), (name, n)
            assert o.rel_std_pct[n] == pytest.approx(m.rel_std_pct_[n], rel=RTOL), (name, n)
        np.testing.assert_allclose(o.cov, m.cov_, rtol=RTOL, atol=RTOL * np.abs(m.cov_).max())
        for a, b in ((o.sigma_rho, m.sigma_rho_), (o.rel_error, m.rel_error_),
                     (o.cond, m.cond_), (o.cond_raw, m.result_.cond_raw)):
            assert a == pytest.approx(b, rel=RTOL), name
        # the same rows in the same order: the residual sample for sample
        np.testing.assert_allclose(o.residual, m.residual_, rtol=0,
                                   atol=RTOL * np.abs(m.residual_).max())
        np.testing.assert_array_equal(o.signals.t[o.rows], report.designs[name].signals.t)


@pytest.mark.parametrize("suffix, with_ref", [("csv", False), ("mcap", True)])
def test_example_campaign_is_fit_models(campaign, suffix, with_ref):
    """LS on CSV-named runs (torque delay 0), IDIM-IV with the half-cycle torque delay on
    MCAP-named runs with their references (the demo's settings)."""
    exps = _experiments(campaign, suffix, with_ref)
    report = fit_models(exps)
    ours = fit_one_joint(exps)
    assert ours.sign_checked  # the campaign crosses zero load at low velocity
    assert ours.settings.torque_delay == (0.5 if with_ref else 0.0)
    assert {m.estimator for m in ours.models.values()} == {"iv" if with_ref else "ls"}
    _assert_same(report, ours)


def test_elimination_is_fit_models(campaign):
    """The single-joint elimination (iteratively the largest relative deviation above the
    threshold) through RobotModel(eliminate=True): a threshold below the third largest
    relative deviation of the full paper model removes several parameters, in the same
    order, with the same reasons."""
    exps = _experiments(campaign, "csv", False)
    full = fit_models(exps, eliminate=False, table_iv=False)
    rel = sorted(full.models["paper"].rel_std_pct_.values(), reverse=True)
    threshold = 0.5 * (rel[2] + rel[3])
    report = fit_models(exps, threshold_pct=threshold, table_iv=False)
    assert len(report.models["paper"].removed_) >= 3
    _assert_same(report, fit_one_joint(exps, threshold_pct=threshold))
    off = fit_one_joint(exps, eliminate=False)
    assert all(not m.removed for m in off.models.values())
    _assert_same(full, off)


def test_emps_is_fit_models():
    """The real EMPS data (prismatic, no payload): the reference script's settings (no sign
    check, every sample) and the defaults (the sign check skipped with its note), the
    exponential terms eliminated."""
    d = shared_path("data", "emps")
    exp = load_experiment(d / "DATA_EMPS.mat", mapping={"q": "qm", "tau": "vir"},
                          gain="gtau", joint="prismatic")
    for opts in ({"cutoff_hz": 100.0, "decimation": 10, "dq_min": 0.0, "sign_check": False},
                 {}):
        report = fit_models([exp], **opts)
        ours = fit_one_joint([exp], **opts)
        assert report.models["paper"].removed_  # d_m, ... not significant
        assert not ours.revolute and not ours.sign_checked
        _assert_same(report, ours)


def test_robot_model_elimination_options():
    """Elimination is off by default and refused on the bilinear paper model."""
    assert RobotModel(None).get_params()["eliminate"] is False
    reg = RobotRegressor(one_joint_robot("revolute"))
    with pytest.raises(RobotIdentError, match="linear forms") as err:
        RobotModel(reg, "paper", eliminate=True)._setup()
    assert "\n" not in str(err.value)
    with pytest.raises(RobotIdentError, match="threshold_pct"):
        RobotModel(reg, "usual", eliminate=True, threshold_pct=0.0)._setup()
    with pytest.raises(DataError, match="model 'x'"):
        fit_one_joint([make_experiment("a.csv", np.arange(100) * 1e-3, np.zeros(100),
                                       np.zeros(100))], models=["x"])
