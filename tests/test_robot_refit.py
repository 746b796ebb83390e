"""Issue 24 item 4: the terms a robot's refinement finds are refitted inside the n-dof model.

Data: the offline 3-dof arm simulator (sim_drivers.arm, examples/robots/arm3.toml) with the
usual friction on every joint (as tests/test_refine_crossjoint.py) plus two undeclared
effects: a cross-joint "dry coupling" -- joint 1's dry friction x (1 - 1.2 (q3 - 0.6)), the
case whose two-stage amplitude came out at -0.794 ± 0.039 against -0.99 N m/rad
(docs/refinement.md, section 8.7) -- and a per-joint quadratic viscous friction F_VV dq|dq|
on joint 3 (sim_drivers.arm_effects). Three payload runs, true states every 5 ms, 1 % torque
noise; the usual n-dof model (``RobotModel``), then joints 1 and 3 refined
(``refine_joint``), then every found term refitted in the n-dof model with all its
parameters (``ident.robot.refit.refit_robot``).

Asserted, per excitation/noise seed:

* the refinement names the coupling (``linear_q3_direction``) on joint 1 and the quadratic
  viscous friction on joint 3;
* after the n-dof refit both coefficients lie within 2σ of the truth (c_1 x -1.2 for the
  coupling, F_VV for the drag);
* the refit's relative error, per refined joint and for the whole robot, is at most 1.1 x
  that of the TRUE structure (the declared n-dof model plus the true columns, refitted by the
  same function on the same data), and not above the n-dof fit's;
* without extra terms the refit reproduces the n-dof fit (usual and paper models), and a
  term reading the measured torque is refused (columns from the states only);
* its held-out error is leave-one-run-out on the explicit stacked regressor;
* through ``jointid fit --robot --refine``: the refit's record and table (coupling alone).
"""

from __future__ import annotations

import copy
import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from robot_campaigns import ARM3_CENTRE, ARM3_PAYLOADS, arm3_true_state_signals, write_arm_csv

from daq.app.cli import main
from ident import OutputLeakError
from ident.cli_robot import fit_files, format_refit
from ident.loaders import parse_mapping
from ident.robot import RobotIdentError
from ident.robot.base import base_parameters
from ident.robot.estimate import QUADRANT_TOL, RobotModel
from ident.robot.paper import usual_coefficients
from ident.robot.refine_joint import joint_coulomb, refine_joint
from ident.robot.refit import _rows, _System, extra_name, refit_robot
from ident.robot.uncertainty import assess
from ident.signals import Signals
from ident.terms import Term
from ident.unseen import heldout_error
from sim_drivers.arm import ArmEffects, ArmGains, ArmParams, model_reference, simulate_arm
from trajectories.robot import load_robot

ROOT = Path(__file__).resolve().parents[1]
NOISE = 0.01  # fraction of each joint's load
STRIDE = 5
DQ_MIN = 0.02  # [rad/s]
#: joint 1 (index 0) follows joint 3's position (index 2)
COUPLING = {"slope_per_rad": -1.2, "rest_position_rad": 0.6}
F_VV = 3.0  # [N m s^2/rad^2] on joint 3 (index 2)
WITHIN = 1.10


class _TrueLine(Term):
    """The true coupling column (q3 - q0) sign(dq1)."""

    effect = "true_coupling"
    variable = "other"

    def names(self) -> tuple[str, ...]:
        return ("true_c",)

    def columns(self, s: Signals) -> np.ndarray:
        return ((s.extra["q3"] - COUPLING["rest_position_rad"]) * np.sign(s.dq))[:, None]


class _TrueDrag(Term):
    """The true drag column dq|dq|."""

    effect = "true_drag"
    variable = "velocity"

    def names(self) -> tuple[str, ...]:
        return ("true_F_VV",)

    def columns(self, s: Signals) -> np.ndarray:
        return (s.dq * np.abs(s.dq))[:, None]


class _Leak(Term):
    """A column read from the measured torque: never allowed."""

    effect = "leak"

    def names(self) -> tuple[str, ...]:
        return ("leak",)

    def columns(self, s: Signals) -> np.ndarray:
        return np.asarray(s.tau, dtype=float)[:, None]


def _arm(seed: int, duration_s: float = 12.0, model: str = "usual", effects: bool = True):
    eff = (ArmEffects.make(3, dry_coupling={(0, 2): COUPLING},
                           quadratic_viscous={2: {"F_VV": F_VV}}) if effects else None)
    reg, sig, params = arm3_true_state_signals(eff, seed, duration_s, noise=NOISE,
                                               stride=STRIDE)
    fit = RobotModel(reg, model, base=base_parameters(reg), dq_min=DQ_MIN).fit(sig)
    return sig, fit, float(params.friction.c_m[0])


def _refine(sig, fit, pred, j):
    vmax = float(np.max(np.abs(sig.dq[:, j])))
    return refine_joint(sig, pred, j, vmax=vmax, dq_min=DQ_MIN, max_steps=2,
                        coulomb=joint_coulomb(fit, j))


def _value(rf, joint: str, name: str) -> tuple[float, float]:
    i = rf.names_.index(extra_name(joint, name))
    return float(rf.coef_[i]), float(rf.std_[i])


def _check(seed: int) -> None:
    sig, fit, c1 = _arm(seed)
    pred = fit.predict(sig)
    refs = {j: _refine(sig, fit, pred, j) for j in (0, 2)}
    named = {j: [s.named_effect for s in r.steps] for j, r in refs.items()}
    assert "linear_q3_direction" in named[0], named
    assert "quadratic_viscous" in named[2], named
    terms = [(j, s.term) for j, r in refs.items() for s in r.steps]
    rf = refit_robot(fit, sig, terms, prediction=pred)
    true = refit_robot(fit, sig, [(0, _TrueLine()), (2, _TrueDrag())], prediction=pred)
    # the two-stage estimates (the refinement's own fit on the n-dof residual)
    step = next(s for s in refs[0].steps if s.named_effect == "linear_q3_direction")
    (cname,) = step.term.names()
    two_stage = refs[0].final_model.coef_[cname]
    coupling, sd_c = _value(rf, "j1", cname)
    drag_name = next(s.term.names()[0] for s in refs[2].steps
                     if s.named_effect == "quadratic_viscous")
    drag, sd_d = _value(rf, "j3", drag_name)
    truth_c = c1 * COUPLING["slope_per_rad"]
    print(f"\nseed {seed}: steps {named}; coupling {coupling:.4f} ± {2 * sd_c:.4f} (2σ; "
          f"two-stage {two_stage:.4f}, true {truth_c:.4f}), F_VV {drag:.4f} ± {2 * sd_d:.4f} "
          f"(true {F_VV}); error all {rf.rel_error['before']['all']:.4%} -> "
          f"{rf.rel_error['after']['all']:.4%} (true structure "
          f"{true.rel_error['after']['all']:.4%}); per joint "
          f"{ {j: round(v, 5) for j, v in rf.rel_error['after'].items()} } vs true "
          f"{ {j: round(v, 5) for j, v in true.rel_error['after'].items()} }; held-out "
          f"{rf.heldout['before']['all']:.4%} -> {rf.heldout['after']['all']:.4%}")
    assert abs(coupling - truth_c) <= 2 * sd_c, (coupling, sd_c, truth_c)
    assert abs(drag - F_VV) <= 2 * sd_d, (drag, sd_d, F_VV)
    for key in ("j1", "j3", "all"):
        assert rf.rel_error["after"][key] <= WITHIN * true.rel_error["after"][key], key
        assert rf.rel_error["after"][key] <= rf.rel_error["before"][key] + 1e-12, key
    assert rf.heldout["after"]["all"] < rf.heldout["before"]["all"]
    # the record the CLI writes
    js = rf.to_json()
    assert js["rel_error"]["after"]["all"] == pytest.approx(rf.rel_error["after"]["all"])
    assert {x["effect"] for x in js["extras"]} >= {"linear_q3_direction", "quadratic_viscous"}
    for x in js["extras"]:  # both true effects stay significant inside the n-dof model
        if x["effect"] in ("linear_q3_direction", "quadratic_viscous"):
            assert x["significant"] and x["wald"] > 20, x


def test_coupling_and_drag_recovered_inside_the_ndof_model():
    _check(11)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [4, 7])
def test_coupling_and_drag_recovered_other_seeds(seed):
    _check(seed)


@pytest.mark.parametrize("model", ["usual", "paper"])
def test_refit_without_terms_is_the_ndof_fit(model):
    """Without terms the refit is the fit: the same rows (the paper model's quadrant band
    decided as ``fitted_rows`` decides it), its error before and after, its coefficients and
    deviations, to rounding."""
    sig, fit, _ = _arm(2, duration_s=6.0, model=model, effects=False)
    rf = refit_robot(fit, sig, [])
    assert rf.names_ == fit.names_
    rows = np.array([rf.n_rows[j] for j in fit.joints_])
    np.testing.assert_array_equal(rows, fit.n_samples_)
    np.testing.assert_array_equal(rows, fit.fitted_rows(sig).sum(axis=0))
    want = np.array([fit.rel_error_[j] for j in fit.joints_])
    for when in ("before", "after"):
        errs = np.array([rf.rel_error[when][j] for j in fit.joints_])
        np.testing.assert_allclose(errs, want, rtol=1e-9)
    np.testing.assert_allclose(rf.coef_, fit.coef_, rtol=0, atol=1e-6 * fit.std_.min())
    np.testing.assert_allclose(rf.std_, fit.std_, rtol=1e-6, atol=1e-12)


def test_pruned_parameters_stay_pruned():
    """The paper model's pruned parameters (ident.robot.uncertainty, held at 0 outside
    ``fixed_``) stay at 0 in the refit: without terms it is the pruned fit (rows equal,
    errors within 1e-4, coefficients within half a sigma; measured 6e-6 and 0.16 sigma on
    seed 2: the pruning's last refit stops at the fit's step tolerance). Re-estimated
    (``refit_eliminated=True``, what the refit did before), they moved a coefficient by ~39
    sigma and lowered the error without any term."""
    sig, fit, _ = _arm(2, duration_s=6.0, model="paper", effects=False)
    assess(fit, sig, n_blocks=0, prune=True)
    assert fit.pruned_ and not fit.fixed_
    rf = refit_robot(fit, sig, [])
    i = [fit.names_.index(n) for n in fit.pruned_]
    assert np.all(rf.coef_[i] == 0) and np.all(rf.std_[i] == 0)
    want = np.array([fit.rel_error_[j] for j in fit.joints_])
    for when in ("before", "after"):
        errs = np.array([rf.rel_error[when][j] for j in fit.joints_])
        np.testing.assert_allclose(errs, want, rtol=1e-4)
    np.testing.assert_array_equal([rf.n_rows[j] for j in fit.joints_], fit.n_samples_)
    free = np.ones(len(fit.names_), dtype=bool)
    free[i] = False
    assert np.all(np.abs(rf.coef_ - fit.coef_)[free] <= 0.5 * fit.std_[free])
    again = refit_robot(fit, sig, [], refit_eliminated=True)
    assert np.any(again.coef_[i] != 0)


def test_a_term_without_effect_is_flagged_not_significant():
    """A quadratic drag on joint 3 of an arm that has none: refitted, its coefficient is
    within noise of 0, and the record and the table say it is not significant."""
    sig, fit, _ = _arm(2, duration_s=6.0, effects=False)
    rf = refit_robot(fit, sig, [(2, _TrueDrag())])
    (x,) = rf.to_json()["extras"]
    v, sd = _value(rf, "j3", _TrueDrag().names()[0])
    assert abs(v) < 3 * sd
    assert x["significant"] is False and x["wald"] == pytest.approx((v / sd) ** 2, rel=1e-6)
    text = "\n".join(format_refit(rf.to_json(), "usual"))
    assert "not significant inside the n-dof model" in text


def test_refit_refuses_the_measured_torque_and_bad_input():
    sig, fit, _ = _arm(2, duration_s=6.0, effects=False)
    with pytest.raises(OutputLeakError):
        refit_robot(fit, sig, [(0, _Leak())])
    with pytest.raises(RobotIdentError, match="joint index 5"):
        refit_robot(fit, sig, [(5, _TrueDrag())])
    with pytest.raises(RobotIdentError, match="appear twice"):
        refit_robot(fit, sig, [(1, _TrueDrag()), (1, _TrueDrag())])
    iv = copy.copy(fit)  # IDIM-IV needs the reference (the model's own instruments)
    iv.method = "iv"
    with pytest.raises(RobotIdentError, match="method 'iv' needs q_ref") as e:
        refit_robot(iv, sig, [])
    assert "\n" not in str(e.value)


def test_cli_refine_refits_inside_the_ndof_model(tmp_path, capfd):
    """``jointid fit --robot ... --refine``: the found terms refitted in the n-dof model,
    before/after per joint and for the robot in the JSON record and on stdout."""
    robot = load_robot(ROOT / "examples" / "robots" / "arm3.toml")
    c = ArmParams.from_robot(robot).friction.c_m
    usual = dict(a_m=1.0, b_m=0.0, a_g=1.0, b_g=0.0, d_m=0.0, d_g=0.0, c_g=c)
    params = dataclasses.replace(ArmParams.from_robot(robot, usual), effects=ArmEffects.make(
        3, dry_coupling={(0, 2): COUPLING}))
    ref = model_reference(params.model, center=ARM3_CENTRE, fraction=0.9, duration_s=10.0, seed=11)
    files = []
    for i, pay in enumerate(ARM3_PAYLOADS):
        run = simulate_arm(params, ref, ArmGains.for_params(params, payload=pay), payload=pay,
                           seed=110 + i)
        files.append(write_arm_csv(run, tmp_path / f"p{i}.csv"))
    js = tmp_path / "fit.json"
    code = main(["fit", "--robot", str(ROOT / "examples" / "robots" / "arm3.toml"),
                 *map(str, files), "--model", "usual", "--method", "ls", "--no-consistency",
                 "--refine", "--max-steps", "1", "--json", str(js)])
    text, err = capfd.readouterr()
    assert code == 0, err
    rec = json.loads(js.read_text())
    fit = rec["refinement"]["refit"]
    assert "error" not in fit, fit
    joints = [*robot.moving, "all"]
    for key in ("rel_error", "heldout_rel_error", "noise_floor"):
        for when in ("before", "after"):
            assert list(fit[key][when]) == joints
            assert all(v is not None and v > 0 for v in fit[key][when].values())
    # the n-dof fit's own figures before, the refit's lower or equal after
    for j in robot.moving:
        assert fit["rel_error"]["before"][j] == pytest.approx(
            rec["models"]["usual"]["rel_error"][j], rel=1e-6)
        assert fit["rows"][j] == rec["models"]["usual"]["samples"][j]
        assert fit["rel_error"]["after"][j] <= fit["rel_error"]["before"][j] + 1e-12
    added = [(x["joint"], x["effect"]) for x in fit["extras"]]
    assert ("j1", "linear_q3_direction") in added, added
    # every n-dof parameter and the extra ones, with standard deviations
    names = list(fit["parameters"])
    assert names[:len(rec["models"]["usual"]["parameters"])] == list(
        rec["models"]["usual"]["parameters"])
    assert "j1:q3_c1" in names and fit["parameters"]["j1:q3_c1"]["std"] > 0
    assert "n-dof refit of the usual model" in text and "linear_q3_direction" in text
    own = rec["refinement"]["joints"]["j1"]["fit"]
    c1 = fit["parameters"]["j1:q3_c1"]
    print(f"\nj1 {own['before']:.4%} -> {own['after']:.4%} (own refinement) -> "
          f"{fit['rel_error']['after']['j1']:.4%} (n-dof refit), held-out "
          f"{fit['heldout_rel_error']['before']['j1']:.4%} -> "
          f"{fit['heldout_rel_error']['after']['j1']:.4%}; j1:q3_c1 {c1['value']:.4f} ± "
          f"{2 * c1['std']:.4f} (2 sigma)")


def test_heldout_is_leave_one_run_out_of_the_stacked_system():
    """The refit's held-out error (folds subtracted from the normal equations) equals
    :func:`ident.unseen.heldout_error` on the explicit stacked regressor of the usual model
    (every joint's rows, theta shared, the extra column on joint 3's rows), and validation
    samples are evaluated with the refitted parameters."""
    sig, fit, _ = _arm(2, duration_s=6.0, effects=False)
    rf = refit_robot(fit, sig, [(2, _TrueDrag())], validation=(sig, None, None))
    rows = _rows(fit, sig, [np.zeros((sig.n, 0)), np.zeros((sig.n, 0)),
                            (sig.dq[:, 2] * np.abs(sig.dq[:, 2]))[:, None]], None)
    system = _System(fit, rows, [[], [], [len(rf.names_) - 1]], usual_coefficients,
                     len(rf.names_), rf.names_)
    W, y, exp = [], [], []
    for j, rw in enumerate(rows):
        r, J = system.joint(j, np.zeros(len(rf.names_)))  # r = tau - p at x = 0
        full = np.zeros((J.shape[0], len(rf.names_)))
        full[:, system.local(j)] = J
        W.append(full)
        y.append(r)
        exp.append(rw.experiment)
    W, y, exp = np.concatenate(W), np.concatenate(y), np.concatenate(exp)
    tau2 = sum(float(rw.tau @ rw.tau) for rw in rows)
    want = heldout_error(W, y, exp) * float(np.linalg.norm(y))
    assert rf.heldout["after"]["all"] * np.sqrt(tau2) == pytest.approx(want, rel=1e-6)
    assert rf.heldout_kind == "leave one run out"
    for j in fit.joints_:
        assert rf.validation["after"][j] == pytest.approx(rf.rel_error["after"][j], rel=1e-9)
        assert rf.validation["before"][j] == pytest.approx(rf.rel_error["before"][j], rel=1e-9)



KUKA = ROOT / "examples" / "robots" / "kuka_kr300_r2500.toml"
KUKA_DATA = ROOT.parent / "shared" / "data" / "kuka_kr300_weigand2021"
KUKA_MAP = "t=rec.time_cont,q=rec.act_pos_mot_deg,tau=rec.act_torque_abs_nm,q_ref=rec.ref_pos_deg"


@pytest.mark.skipif(not KUKA_DATA.is_dir(), reason="../shared/data/kuka_kr300_weigand2021 absent")
def test_unsettled_paper_fit_before_is_the_model_refitted_without_the_terms():
    """Real data: the paper model's fit on the KUKA's file A does not settle on A4 (at the
    default trim of 60 its final values put 34 % of A4's rows in another quadrant, the other
    joints' none, README; 2026-11-28). Its refit's "before" is the model refitted on the
    refit's quadrants without the terms, so that before -> after is what the terms add:
    without terms before = after, while the fit as it is (what "before" was) reads far off on
    the joints that moved (A4 117 % against 4.9 %)."""
    robot = load_robot(KUKA)
    out = fit_files(robot, [KUKA_DATA / "recorded_2020-10-21_FF_A_08ms.mat"], model="paper",
                    mapping=parse_mapping(KUKA_MAP, robot=True), q_unit="deg")
    est, sig = out["_estimators"]["paper"], out["_identification"]
    drift = est.quadrant_drift(sig)
    moved = {j for j, d in zip(est.joints_, drift, strict=True) if d > QUADRANT_TOL}
    assert moved  # the real data's unsettled fit
    rows = est.fitted_rows(sig)
    rf = refit_robot(est, sig, [], keep=rows)
    assert set(rf.unsettled) == moved
    for j in [*est.joints_, "all"]:
        assert rf.rel_error["before"][j] == pytest.approx(rf.rel_error["after"][j], rel=1e-9)
    pred = est.predict(sig)
    for i, j in enumerate(est.joints_):
        r = rows[:, i]
        as_is = np.linalg.norm(sig.tau[r, i] - pred[r, i]) / np.linalg.norm(sig.tau[r, i])
        if j in moved:
            assert as_is > 1.1 * rf.rel_error["before"][j], (j, as_is, rf.rel_error)
    text = "\n".join(format_refit(rf.to_json(), "paper"))
    assert "had not settled on" in text and all(j in text for j in moved)
    assert rf.to_json()["unsettled"] == rf.unsettled
