"""A joint is a 1-dof robot (issue 24): ``ident.fitting.fit_models``, whose fit is
:class:`ident.one_joint.OneJointProblem`'s -- the one-joint robot, the columns chain, the
sign check, the products formed at full rate and ``RobotModel`` with the single-joint
elimination -- gives the single-joint least squares' numbers (``IdentModel.fit``: QR on
the decimated columns of :func:`ident.preprocess.build_design`, the fit of ``fit_models``
before the switch): values, standard deviations, relative deviations, covariance,
sigma_rho, residual, relative error, condition numbers, removed parameters and rows, to 1e-8
(measured: 5e-12 at worst on the example campaign, 4e-13 on EMPS, 1.5e-12 on the quick
demo's MCAP logs)."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
from example_campaign import simulate_example_campaign

from daq.app.demo import run_demo
from ident import DataError
from ident.fitting import fit_models
from ident.loaders import concat, load_experiment, make_experiment
from ident.models import IdentModel
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


def _assert_same(report, eliminate: bool = True, threshold_pct: float | None = None) -> None:
    """Every number of each model of ``report`` (fit_models, whose fit is the robot model's)
    is the single-joint least squares (:meth:`ident.models.IdentModel.fit`, QR on the
    columns) on ``report``'s design of that model (built on the columns chain's full-rate
    signals, :func:`ident.preprocess.design_on_full_rate`), to ``RTOL``."""
    for name, fitted in report.models.items():
        design = report.designs[name]
        ref = IdentModel(fitted.library, name).fit(design, eliminate=eliminate,
                                                   threshold_pct=threshold_pct)
        o = _as_fit(fitted)
        assert o.names == ref.names_, name
        assert o.removed == ref.removed_, name
        assert o.estimator == ref.estimator_ and o.m == ref.result_.m == len(design)
        for n in ref.names_:
            assert o.values[n] == pytest.approx(ref.coef_[n], rel=RTOL), (name, n)
            assert o.std[n] == pytest.approx(ref.std_[n], rel=RTOL), (name, n)
            assert o.rel_std_pct[n] == pytest.approx(ref.rel_std_pct_[n], rel=RTOL)
        np.testing.assert_allclose(o.cov, ref.cov_, rtol=RTOL,
                                   atol=RTOL * np.abs(ref.cov_).max())
        for a, b in ((o.sigma_rho, ref.sigma_rho_), (o.rel_error, ref.rel_error_),
                     (o.cond, ref.cond_), (o.cond_raw, ref.result_.cond_raw)):
            assert a == pytest.approx(b, rel=RTOL), name
        # the same rows in the same order: the residual sample for sample
        np.testing.assert_allclose(o.residual, ref.residual_, rtol=0,
                                   atol=RTOL * np.abs(ref.residual_).max())
        assert fitted.robot_ is not None and fitted.predict(design) == pytest.approx(
            ref.predict(design), rel=RTOL, abs=RTOL * np.abs(design.Y).max())


def _sign_checked(report) -> bool:
    """Whether the sign check's rows (the first usual fit's load model) were applied (the
    check skipped: the load model decides the quadrant only, ``sign_check`` False)."""
    return "load_model" in report.settings and report.settings.get("sign_check", True)


def _as_fit(m: IdentModel) -> SimpleNamespace:
    """A fitted IdentModel under OneJointModel's attribute names."""
    return SimpleNamespace(names=m.names_, removed=m.removed_, estimator=m.estimator_,
                           m=m.result_.m, values=m.coef_, std=m.std_,
                           rel_std_pct=m.rel_std_pct_, cov=m.cov_, sigma_rho=m.sigma_rho_,
                           rel_error=m.rel_error_, cond=m.cond_, cond_raw=m.result_.cond_raw,
                           residual=m.residual_)


@pytest.mark.parametrize("suffix, with_ref", [("csv", False), ("mcap", True)])
def test_example_campaign_is_fit_models(campaign, suffix, with_ref):
    """LS on CSV-named runs (torque delay 0), IDIM-IV with the half-cycle torque delay on
    MCAP-named runs with their references (the demo's settings)."""
    exps = _experiments(campaign, suffix, with_ref)
    report = fit_models(exps)
    assert _sign_checked(report)  # the campaign crosses zero load at low velocity
    assert report.settings["torque_delay"] == (0.5 if with_ref else 0.0)
    assert {m.estimator_ for m in report.models.values()} == {"iv" if with_ref else "ls"}
    _assert_same(report)


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
    _assert_same(report, threshold_pct=threshold)
    assert all(not m.removed_ for m in full.models.values())
    _assert_same(full, eliminate=False)


def test_emps_is_fit_models():
    """The real EMPS data (prismatic, no payload): the reference script's settings (no sign
    check, every sample) and the defaults (the sign check skipped with its note: every
    sample, the quadrant of the first usual fit's load), the exponential terms eliminated."""
    d = shared_path("data", "emps")
    exp = load_experiment(d / "DATA_EMPS.mat", mapping={"q": "qm", "tau": "vir"},
                          gain="gtau", joint="prismatic")
    for opts in ({"cutoff_hz": 100.0, "decimation": 10, "dq_min": 0.0, "sign_check": False},
                 {}):
        report = fit_models([exp], **opts)
        assert report.models["paper"].removed_  # d_m, ... not significant
        assert not report.revolute and not _sign_checked(report)
        _assert_same(report)


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
        fit_models([make_experiment("a.csv", np.arange(100) * 1e-3, np.zeros(100),
                                    np.zeros(100))], models=["x"])


def test_tau_min_is_fit_models(campaign):
    """``tau_min``: the rows near a low-passed |tau| below it are left out by both paths
    (with the sign check and its kept fraction on the remaining rows)."""
    exps = _experiments(campaign, "csv", False)
    tau = np.concatenate([e.tau for e in exps])
    tau_min = float(np.quantile(np.abs(tau), 0.2))  # a fifth of the samples and more out
    report = fit_models(exps, tau_min=tau_min, table_iv=False)
    every = fit_models(exps, models=["usual"], table_iv=False)
    assert report.models["usual"].result_.m < every.models["usual"].result_.m
    _assert_same(report)


@pytest.mark.slow
def test_demo_logs_are_the_single_joint_fit(tmp_path):
    """The quick demo's MCAP logs (simulated CiA 402 drive, real master, jointid logs):
    IDIM-IV with the half-cycle torque delay, the sign check, and several terms of the paper
    model eliminated -- the same numbers as the single-joint least squares (measured
    1.5e-12)."""
    run_demo(tmp_path, quick=True)
    exps = [load_experiment(p) for p in sorted((tmp_path / "logs").glob("*.mcap"))]
    report = fit_models(exps)
    assert _sign_checked(report) and report.settings["torque_delay"] == 0.5
    assert {m.estimator_ for m in report.models.values()} == {"iv"}
    assert report.models["paper"].removed_  # exponential terms not significant (quick run)
    _assert_same(report)


def test_payload_named_without_payload_is_fit_models(campaign):
    """``payload=True`` on a run without payload: Ma_ratio (usual) and the payload torque's
    products a_m, b_m, a_g, b_g (paper) are reported removed as zero columns, in the
    single-joint order, and the rest is the fit without them."""
    plan, sims, _ = campaign
    exps = [make_experiment("p.csv", sims[0].t, sims[0].q, sims[0].tau_ref)]
    report = fit_models(exps, payload=True, table_iv=False)
    assert [n for n, _ in report.models["usual"].removed_] == ["Ma_ratio"]
    assert [n for n, _ in report.models["paper"].removed_][:4] == ["a_m", "b_m", "a_g", "b_g"]
    _assert_same(report)


def test_bad_references_and_extra_signals_are_one_line_errors(campaign):
    """What the single-joint chain refused before the design was built on the robot chain is
    still refused in one line naming it: references with NaN (a log without setpoints for some
    cycles; the IV columns would otherwise be NaN and fail in the SVD) and non-finite extra
    signals (other joints' states) in concatenated signals."""
    exps = _experiments(campaign, "csv", False)
    refs = [np.array(e, dtype=float) for e in campaign[2]]
    refs[1][500:510] = np.nan
    with pytest.raises(DataError, match=r"references: 10 NaN/inf values \(first in "
                                        r"payload1\.csv") as err:
        fit_models(exps, references=refs, table_iv=False)
    assert "\n" not in str(err.value)
    s = concat(exps)
    extra = np.zeros(len(s))
    extra[7] = np.inf
    with pytest.raises(DataError, match=r"signals\.extra\['q2'\]: expected") as err:
        fit_models(replace(s, extra={"q2": extra}), table_iv=False)
    assert "\n" not in str(err.value)
    fine = fit_models(replace(s, extra={"q2": np.zeros(len(s))}), table_iv=False)
    assert np.all(fine.designs["paper"].signals.extra["q2"] == 0.0)  # carried to the design
