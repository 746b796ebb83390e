"""The q_s rescan after a refinement goes through the robot model (issue 24): at each q_s the
fit is the n-dof refit of the found terms (:func:`ident.robot.refit.refit_robot` on the model
at that q_s), a joint its 1-dof instance (:meth:`ident.fitting.FitReport.rescan_found_terms`,
on the joint's full-rate products formed at each q_s).

Asserted: the single joint's scan errors are the single-joint least-squares fits of the
design with the found term at those q_s (an independent path: ``fit_models(q_s=q)``'s design,
``IdentModel.fit``), the chosen q_s's whole refit is the scan's best, two threads give the
floats of one; on the simulated 3-dof arm (paper friction, true q_s 0.03 rad/s, a quadratic
viscous drag on joint 3 that no model declares) fitted at q_s = 0.06, the rescan with the drag
brings q_s back within 10 % of the truth and the drag's coefficient within 2 sigma of it,
over seeds."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest
from robot_campaigns import ARM3, ARM3_CENTRE, ARM3_PAYLOADS

from daq.protocol.control import ControllerGains
from ident import DataError, qs_scan
from ident.effects.position_ripple import PositionRipple
from ident.effects.quadratic_viscous import QuadraticViscous
from ident.fitting import fit_models, rescan_qs
from ident.loaders import make_experiment
from ident.models import IdentModel
from ident.robot.base import base_parameters
from ident.robot.estimate import RobotModel
from ident.robot.refit import refit_robot
from ident.robot.signals import RobotSignals
from ident.terms import Library
from sim_drivers.arm import ArmEffects, ArmGains, ArmParams, model_reference, simulate_arm
from sim_drivers.offline import simulate
from sim_drivers.plant_config import load_plant
from trajectories.plan import plan_campaign
from trajectories.robot import RobotPayloadData, RobotRegressor, load_robot
from trajectories.robot_campaign import RobotCampaign

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def runs():
    """Two payload runs of the quick example campaign, simulated offline, and their
    reference positions."""
    with open(ROOT / "examples" / "campaign.toml", "rb") as f:
        campaign = RobotCampaign.from_dict(tomllib.load(f), "examples/campaign.toml").quick()
    plan = plan_campaign(campaign)
    plant = load_plant(ROOT / "examples" / "plant_rx130l.toml")
    gains = ControllerGains(**campaign.gains_kwargs())
    exps = []
    for i, p in enumerate(plan.payloads[:2]):
        r = simulate(plant, plan.reference, gains, payload_mass=p.mass_kg,
                     payload_arm=p.arm_m, seed=3 + i)
        exps.append(make_experiment(f"payload{i}", r.t, r.q, r.tau_ref,
                                    payload_mass=p.mass_kg, payload_arm=p.arm_m))
    return exps, [plan.reference.q] * 2


@pytest.fixture(scope="module")
def fitted(runs):
    """The paper model (with its ripple-free library) fitted with instruments on the runs."""
    exps, refs = runs
    return fit_models(exps, ("paper",), q_s=0.04, references=refs, table_iv=False,
                      torque_delay=0.5)


def test_refit_like_an_earlier_report_is_the_same_fit(runs, fitted):
    """fit_models(like=report) (the demo's refit with the adjusted q_s) takes the settled
    preprocessing and the sign check's load model from the report: the same fit as from
    scratch; a report on other data is refused."""
    exps, refs = runs
    kw = dict(references=refs, table_iv=False, torque_delay=0.5)
    a = fit_models(exps, ("usual", "paper"), q_s=0.031, **kw)
    b = fit_models(exps, ("usual", "paper"), q_s=0.031, like=fitted, **kw)
    assert "load_model" in fitted.settings  # the sign check ran
    for name in ("usual", "paper"):
        assert a.models[name].coef_ == b.models[name].coef_
        assert np.array_equal(a.designs[name].W, b.designs[name].W)
        assert np.array_equal(a.designs[name].Z, b.designs[name].Z)
    assert a.notes == b.notes and a.vmax == b.vmax
    with pytest.raises(DataError, match="like="):
        fit_models(exps[:1], ("paper",), q_s=0.031, like=fitted, **{**kw, "references": refs[:1]})


def _ripple() -> PositionRipple:
    """The plant's undeclared effect as a single-joint term, at its true period."""
    plant = load_plant(ROOT / "examples" / "plant_rx130l.toml")
    return PositionRipple(plant.truth_effects()["position_ripple"]["period_rad"])


@pytest.fixture(scope="module")
def rescanned(fitted):
    """The rescan of the fitted paper model with the ripple term (its columns the design's)."""
    term = _ripple()
    design = fitted.designs["paper"].with_term(term, states_only=True)
    return term, fitted.rescan_found_terms("paper", [term], design)


def test_scan_errors_are_the_single_joint_fits(runs, fitted, rescanned):
    """At two scanned q_s, the scan's error is the relative error of the single-joint
    least squares (IDIM-IV, no elimination) on fit_models' design at that q_s with the term:
    another path to the same fit (its E columns built by the design at that q_s, its
    estimate by QR, not the normal equations). The design path of the former rescan gave the
    same errors to 1e-14 on the demo's logs (benchmarks/qs_rescan_robot.py)."""
    exps, refs = runs
    term, rs = rescanned
    scan = dict(rs.scan)
    for q in (min(scan), max(scan, key=scan.get)):  # (the smallest q_s, the largest error)
        rep = fit_models(exps, ("paper",), q_s=q, like=fitted, references=refs,
                         table_iv=False, torque_delay=0.5)
        d = rep.designs["paper"].with_term(term, states_only=True)
        lib = Library(*rep.models["paper"].library.terms(), term)
        single = IdentModel(lib, "paper").fit(d, eliminate=False)
        assert scan[q] == pytest.approx(single.rel_error_, rel=1e-9, abs=0), q


def test_the_chosen_qs_is_refitted_whole(rescanned):
    term, rs = rescanned
    assert [q for q, _ in rs.scan] == sorted(q for q, _ in rs.scan)
    best = min(e for _, e in rs.scan)
    assert rs.refit.rel_error["after"]["all"] == best
    assert rs.record["rel_error"]["after"]["all"] == best
    assert rs.joints == rs.refit.model.joints_ and rs.refit.model.q_s_[0] == rs.q_s
    pars = rs.record["parameters"]  # by the single-joint names; the term's by the robot's
    assert {"a_m_J", "b_m_MX", "c_m", "F_V"} <= set(pars)
    assert any(n.endswith(":" + term.names()[0]) for n in pars)


def test_two_threads_give_the_floats_of_one(fitted, rescanned, monkeypatch):
    term, rs = rescanned
    monkeypatch.setattr(qs_scan, "QS_WORKERS", 1)
    design = fitted.designs["paper"].with_term(term, states_only=True)
    one = fitted.rescan_found_terms("paper", [term], design)
    assert one.scan == rs.scan and one.q_s == rs.q_s


def test_refused_in_one_line(fitted, rescanned):
    term, _ = rescanned
    with pytest.raises(DataError, match="usual model: no paper model") as e:
        fitted.rescan_found_terms("usual", [term])
    assert "\n" not in str(e.value)
    with pytest.raises(DataError, match="q_s is a parameter of the paper model"):
        rescan_qs(RobotModel(fitted.models["paper"].robot_.regressor_, "usual")
                  .fit(fitted.robot_signals["paper"]), fitted.robot_signals["paper"], [],
                  vmax=fitted.vmax)


#: The arm's quadratic viscous drag on joint 3 [N m s^2/rad^2] (sim_drivers.arm_effects).
F_VV = 3.0
#: The a-priori q_s of the arm's paper fit [rad/s]: twice the truth.
QS_FIT = 0.06


def _arm(seed: int, duration_s: float = 12.0, noise: float = 0.01, stride: int = 5):
    """The 3-dof arm with the load-dependent friction (b_m, b_g of eq. 29: q_s 0.03 rad/s on
    every joint; c_g = c_m and no d terms, as tests/robot_campaigns.py's usual friction, so
    the paper model stays identifiable on joints whose load keeps its sign) and the drag on
    joint 3, simulated on a model multi-sine for each payload; the true states every
    ``stride``-th cycle with the applied torque plus white noise of ``noise`` x each joint's
    load (as ``robot_campaigns.arm3_true_state_signals``)."""
    robot = load_robot(ARM3)
    c = ArmParams.from_robot(robot).friction.c_m
    params = ArmParams.from_robot(
        robot, dict(a_m=1.0, b_m=0.25, a_g=1.0, b_g=0.27, d_m=0.0, d_g=0.0, c_g=c),
        effects=ArmEffects.make(3, quadratic_viscous={2: {"F_VV": F_VV}}))
    ref = model_reference(params.model, center=ARM3_CENTRE, fraction=0.9,
                          duration_s=duration_s, seed=seed)
    rng = np.random.default_rng(seed)
    sd = noise * params.drive.torque_noise_std_Nm / 0.01
    parts: dict[str, list] = {k: [] for k in ("t", "q", "dq", "ddq", "tau", "experiment")}
    for i, p in enumerate(ARM3_PAYLOADS):
        r = simulate_arm(params, ref, ArmGains.for_params(params, payload=p), payload=p,
                         seed=10 * seed + i)
        tau = r.tau_applied + rng.standard_normal(r.tau_applied.shape) * sd
        for k, v in (("t", r.t), ("q", r.q_true), ("dq", r.dq_true), ("ddq", r.ddq_true),
                     ("tau", tau), ("experiment", np.full(r.t.size, i))):
            parts[k].append(v[::stride])
    reg = RobotRegressor(robot)
    pays = tuple(RobotPayloadData() if p is None else RobotPayloadData(p.mass, p.com, p.inertia)
                 for p in ARM3_PAYLOADS)
    sig = RobotSignals(**{k: np.concatenate(v) for k, v in parts.items()}, joints=reg.joints,
                       payloads=pays, source=f"arm3 seed {seed}")
    return reg, sig, params


@pytest.mark.parametrize("seed", [11, pytest.param(4, marks=pytest.mark.slow)])
def test_robot_rescan_recovers_qs_and_the_drag(seed):
    """The n-dof case: the paper model fitted with q_s twice the truth, the drag as the found
    term of joint 3; one q_s for every joint scanned with the n-dof refit. Measured (seeds
    11, 4, 7; ``seed 4`` is slow): q_s 0.0285, 0.0313, 0.0299 rad/s (-5 %, +4 %, -0.3 %), the
    drag 3.03 +- 0.49, 2.97 +- 0.54, 2.97 +- 0.50 (2 sigma)."""
    reg, sig, params = _arm(seed)
    truth = float(params.friction.q_s[0])
    assert np.all(params.friction.q_s == truth)
    fit = RobotModel(reg, "paper", base=base_parameters(reg), dq_min=0.02, q_s=QS_FIT).fit(sig)
    rs = rescan_qs(fit, sig, [(2, QuadraticViscous())], vmax=float(np.abs(sig.dq).max()))
    assert rs.joints == fit.joints_
    assert abs(rs.q_s / truth - 1) < 0.1, rs.q_s
    i = rs.refit.names_.index("j3:F_VV")
    assert abs(rs.refit.coef_[i] - F_VV) <= 2 * rs.refit.std_[i], rs.refit.coef_[i]
    # the scan's best is below the refit at the fit's own q_s
    at_fit = refit_robot(fit, sig, [(2, QuadraticViscous())], errors_only=True)
    assert min(e for _, e in rs.scan) < at_fit.rel_error["after"]["all"]
