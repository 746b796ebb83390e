"""Physically consistent estimates (ident.robot.consistent_fit) and the model export
(ident.robot.export_model, ``jointid export-model``): on the arm simulator's data (UR10 and the
3-dof arm, payload runs: see tests/test_robot_fit.py), the exported URDF read back by pinocchio
plus the friction file evaluated by the reference function give jointid's predicted torques."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from robot_campaigns import write_arm_csv
from test_robot_fit import _signals, _simulate

from daq.app.cli import main
from ident.robot.consistency import check_consistency
from ident.robot.consistent_fit import (
    MARGIN,
    PRIOR_WEIGHT,
    add_consistent,
    consistent_model,
    consistent_record,
    fit_consistent,
    format_record,
    link_validity,
)
from ident.robot.estimate import RobotModel
from ident.robot.export_model import export_model, exported_torque, urdf_text
from ident.robot.friction_bounds import bound_rows, torque_peak
from ident.robot.regressor import RobotRegressor
from sim_drivers.arm import ArmGains, ArmParams, Payload, model_reference, simulate_arm
from trajectories.robot import load_robot

ROOT = Path(__file__).resolve().parents[1]
ARM3 = ROOT / "examples" / "robots" / "arm3.toml"
#: |tau_out| below this fraction of its largest value: the quadrant of eq. 30 is decided by
#: rounding (tau_out = 0 exactly, e.g. the vertical joint at rest); excluded from the round
#: trip of the paper model and counted.
TIE = 1e-9


def _rnea(urdf: Path, gravity, sig, ratio: float = 1.0) -> np.ndarray:
    """Inverse dynamics of the exported URDF on a RobotSignals, its payload attached to the
    last link (flange = joint frame of the last moving joint, the regressor's default)."""
    model = pin.buildModelFromUrdf(str(urdf))
    model.gravity = pin.Motion(np.r_[np.asarray(gravity, float), 0.0, 0.0, 0.0])
    pay = sig.payloads[0]
    if pay.mass > 0:
        xx, xy, xz, yy, yz, zz = (ratio * v for v in pay.inertia)
        ic = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
        last = model.njoints - 1
        model.inertias[last] = model.inertias[last] + pin.Inertia(
            ratio * pay.mass, np.asarray(pay.com, float), ic)
    data = model.createData()
    return np.array([pin.rnea(model, data, q, v, a) for q, v, a in
                     zip(sig.q, sig.dq, sig.ddq, strict=True)])


def _round_trip(est, fit, robot, sigs, tmp_path: Path) -> tuple[float, int]:
    """Largest |exported - predicted| / max |predicted| over the signals, and the number of
    rows at a rounding-level quadrant tie left out (paper model)."""
    files = export_model(robot, consistent_record(est, fit), tmp_path, est.fixed_)
    fr = json.loads(files[1].read_text())
    cm = consistent_model(est, fit)
    worst, ties = 0.0, 0
    for s in sigs:
        tr = _rnea(files[0], fr["gravity"], s, fr.get("payload_ratio", 1.0))
        ex = exported_torque(fr, tr, s.dq, s.ddq)
        pr = cm.predict(s)
        ok = np.ones(pr.shape, dtype=bool)
        if est.model == "paper":
            tout = cm.load_torque(s)
            ok = np.abs(tout) > TIE * np.abs(tout).max(axis=0)
            ties += int((~ok).sum())
        worst = max(worst, float((np.abs(ex - pr) * ok).max() / np.abs(pr).max()))
    return worst, ties


# --------------------------------------------------------------------------- URDF writer
@pytest.mark.parametrize("name", ["ur10", "arm3"])
def test_urdf_of_the_robot_file_inertias_is_the_robot(tmp_path, name):
    """The robot file's own standard parameters written as a URDF: pinocchio reads back the
    same link inertias and the same inverse dynamics as the robot's reduced model."""
    robot = load_robot(ROOT / "examples" / "robots" / f"{name}.toml")
    reg = RobotRegressor(robot)
    std = dict(zip(reg.standard_names, reg.standard_values(), strict=True))
    path = tmp_path / "r.urdf"
    path.write_text(urdf_text(robot.reduced(), std, robot.numbers, name))
    got = pin.buildModelFromUrdf(str(path))
    ref = robot.reduced()
    assert [got.names[i] for i in range(1, got.njoints)] == list(robot.moving)
    for i in range(1, ref.njoints):
        np.testing.assert_allclose(got.inertias[i].toDynamicParameters(),
                                   ref.inertias[i].toDynamicParameters(), atol=1e-12)
    got.gravity = ref.gravity
    rng = np.random.default_rng(0)
    dg, dr = got.createData(), ref.createData()
    for _ in range(20):
        q, v, a = (rng.uniform(-2, 2, ref.nv) for _ in range(3))
        np.testing.assert_allclose(pin.rnea(got, dg, q, v, a), pin.rnea(ref, dr, q, v, a),
                                   rtol=1e-10, atol=1e-9)


def test_link_validity_flags_each_physical_condition():
    good = np.array([0.3, 0.0, 0.0, 0.3, 0.0, 0.2, 0.1, 0.0, 0.0, 2.0, 1e-3])
    assert link_validity(good, 1)[0]["valid"]
    # about the CoM (0.05, 0, 0): Ixx = 0.3, Iyy = Izz - ... ; a thin rod beyond the triangle
    rod = np.array([0.01, 0.0, 0.0, 0.5, 0.0, 0.5, 0.0, 0.0, 0.0, 1.0, 0.0])
    lv = link_validity(rod, 1)[0]
    assert lv["triangle"] == pytest.approx(0.01 + 0.5 - 0.5)
    assert lv["valid"]
    bad = rod.copy()
    bad[0] = -0.01  # Ixx < 0: also J not PSD
    assert not link_validity(bad, 1)[0]["valid"]
    tri = np.array([0.1, 0.0, 0.0, 0.1, 0.0, 0.5, 0.0, 0.0, 0.0, 1.0, 0.0])  # 0.1 + 0.1 < 0.5
    lt = link_validity(tri, 1)[0]
    assert lt["triangle"] < 0 and lt["min_eig_J"] < 0 and not lt["valid"]
    neg_mass = good.copy()
    neg_mass[9] = -1.0
    assert not link_validity(neg_mass, 1)[0]["valid"]
    neg_ia = good.copy()
    neg_ia[10] = -1e-3
    assert not link_validity(neg_ia, 1)[0]["valid"]


# --------------------------------------------------------------------------- 3-dof arm
@pytest.fixture(scope="module")
def arm3():
    return _simulate("arm3", duration_s=10.0, seed=2)


def test_consistent_usual_ls_is_the_constrained_least_squares(arm3):
    """Usual model, LS: the residual sum of squares grows by exactly sigma^2 d^2 (the
    profile metric is the exact cost of the constraint), every link is valid, and a link
    made unphysical by hand (Ia3 = -1) is brought back."""
    params, reg, base, runs = arm3
    sigs = _signals(params, reg, runs, 0)
    m = RobotModel(reg, "usual", "ls", base=base).fit(sigs)
    m.coef_ = m.coef_.copy()
    m.coef_[m.names_.index("Ia3")] = -1.0  # far outside its uncertainty
    assert check_consistency(m).feasible is False
    fit = fit_consistent(m, sigs)
    assert fit.valid and fit.status == "optimal", fit.links
    assert fit.standard["Ia3"] >= 0
    assert fit.d2 > fit.d2_limit  # the free estimate was not realisable
    cm = consistent_model(m, fit)

    def ssr(model):
        return sum(float(np.nansum(model.residual(s) ** 2)) for s in sigs)

    # the hand-made Ia3 costs more than the constraint: the consistent set fits better
    assert ssr(cm) < ssr(m)
    # the cost of consistency around the free LS optimum is sigma^2 d^2
    free = RobotModel(reg, "usual", "ls", base=base).fit(sigs)
    s_free = ssr(free)
    fit_free = fit_consistent(free, sigs)
    grow = ssr(consistent_model(free, fit_free)) - s_free
    assert grow == pytest.approx(free.sigma_ ** 2 * fit_free.d2, rel=1e-3, abs=1e-9 * s_free)
    assert fit_free.cost_ratio == pytest.approx(grow / s_free, rel=1e-3, abs=1e-12)


def test_consistency_check_lmi_is_the_global_minimum(arm3):
    """check_consistency's convex program finds a d^2 no larger than the Cholesky-factor
    local search, with the same verdicts, on a realisable fit and on one made unrealisable."""
    params, reg, base, runs = arm3
    m = RobotModel(reg, "paper", "ls", base=base).fit(_signals(params, reg, runs, 2))
    good = check_consistency(m)
    assert good.method == "lmi" and good.feasible, good.format()
    m.coef_ = m.coef_.copy()
    m.coef_[m.names_.index("Ia3")] = -1.0
    lmi, chol = check_consistency(m), check_consistency(m, method="cholesky")
    assert (lmi.method, chol.method) == ("lmi", "cholesky")
    assert lmi.feasible is False and chol.feasible is False
    assert lmi.d2 <= chol.d2 * (1 + 1e-6), (lmi.d2, chol.d2)
    assert "export-model" in lmi.format()
    # the paper model's consistent estimate: rigid body constrained, friction the free fit's
    fit = fit_consistent(m)
    assert fit.friction == "fixed" and fit.valid and fit.d2 > fit.d2_limit
    assert fit.standard["Ia3"] >= 0
    nb = m.n_base_
    np.testing.assert_array_equal(fit.coef[nb:], m.coef_[nb:])


def test_export_model_cli(tmp_path, capfd):
    """jointid fit --robot (CSV payload runs) then jointid export-model: URDF, friction file
    and consistent.json; pinocchio loads the URDF; the friction file holds the consistent
    estimate's coefficients; a record with the hook's ``consistent`` block is exported as it
    is (same files, no refit); bad inputs are one line naming the file, nothing written."""
    robot = load_robot(ARM3)
    params = ArmParams.from_robot(robot)
    ref = model_reference(params.model, center=[0.0, -1.9, 0.6], fraction=0.9,
                          duration_s=8.0, seed=1)
    pays = (None, Payload(5.0, [0.0, 0.0, 0.05]),
            Payload(10.0, [0.02, 0.0, 0.1], [0.02, 0.0, 0.0, 0.02, 0.0, 0.03]))
    files = []
    for i, pay in enumerate(pays):
        run = simulate_arm(params, ref, ArmGains.for_params(params, payload=pay),
                           payload=pay, seed=10 + i)
        files.append(write_arm_csv(run, tmp_path / f"p{i}.csv"))
    fit_json = tmp_path / "fit.json"
    assert main(["fit", "--robot", str(ARM3), *map(str, files), "--model", "both",
                 "--json", str(fit_json), "--no-consistency"]) == 0
    capfd.readouterr()
    rec = json.loads(fit_json.read_text())
    for name in ("paper", "usual"):
        out = tmp_path / name
        assert main(["export-model", str(fit_json), "--model", name, "-o", str(out)]) == 0
        text = capfd.readouterr().out
        assert "d^2 =" in text and "arm3.urdf" in text
        model = pin.buildModelFromUrdf(str(out / "arm3.urdf"))
        assert [model.names[i] for i in range(1, model.njoints)] == list(robot.moving)
        fr = json.loads((out / "friction.json").read_text())
        cons = json.loads((out / "consistent.json").read_text())
        assert fr["model"] == name and cons["valid"]
        assert all(lk["valid"] and lk["mass"] >= MARGIN for lk in cons["links"])
        for jr in fr["joints"]:
            for key in ("FC", "FV", "OFF") if name == "usual" else ("a_m", "c_g", "FV"):
                assert jr[key] == cons["parameters"][f"{key}{jr['number']}"]
            if name == "paper":  # friction fixed at the free fit's
                assert jr["a_m"] == pytest.approx(
                    rec["models"]["paper"]["parameters"][f"a_m{jr['number']}"]["value"],
                    rel=1e-6)
        for i in range(1, model.njoints):
            n = robot.numbers[i - 1]
            assert model.inertias[i].mass == pytest.approx(cons["standard"][f"M{n}"],
                                                           rel=1e-12)
    # the hook's block: exported without a refit, same files
    rec2 = dict(rec)
    rec2["models"] = dict(rec["models"])
    rec2["models"]["paper"] = dict(rec["models"]["paper"],
                                   consistent=json.loads((tmp_path / "paper" /
                                                          "consistent.json").read_text()))
    rec2["inputs"] = [str(tmp_path / "gone.csv")]  # a refit would fail
    j2 = tmp_path / "fit2.json"
    j2.write_text(json.dumps(rec2))
    assert main(["export-model", str(j2), "-o", str(tmp_path / "again")]) == 0
    capfd.readouterr()
    for f in ("arm3.urdf", "friction.json"):
        assert (tmp_path / "again" / f).read_text() == (tmp_path / "paper" / f).read_text()
    # the same record in the older spelling (jointid-robot-fit/1: "qs", model "new"; ident.vocab)
    old = json.loads(json.dumps(rec2).replace('"q_s"', '"qs"').replace('"paper"', '"new"'))
    assert old["models"].keys() == {"usual", "new"}
    j_old = tmp_path / "fit_old.json"
    j_old.write_text(json.dumps(dict(old, format="jointid-robot-fit/1")))
    assert main(["export-model", str(j_old), "--model", "new", "-o", str(tmp_path / "old")]) == 0
    capfd.readouterr()
    for f in ("arm3.urdf", "friction.json"):
        assert (tmp_path / "old" / f).read_text() == (tmp_path / "paper" / f).read_text()
    # `jointid fit --robot --consistent` stores the block itself: exported with no refit
    j4 = tmp_path / "fit4.json"
    assert main(["fit", "--robot", str(ARM3), *map(str, files), "--model", "usual",
                 "--json", str(j4), "--no-consistency", "--consistent"]) == 0
    rec4 = json.loads(j4.read_text())
    assert rec4["models"]["usual"]["consistent"]["valid"]
    # ... and prints it: the record's figures, as format_record writes them
    printed = capfd.readouterr().out
    summary = format_record(rec4["models"]["usual"]["consistent"])
    assert "usual model: " + summary in printed and "d^2 = " in summary
    j4.write_text(json.dumps(dict(rec4, inputs=[str(tmp_path / "gone.csv")])))
    assert main(["export-model", str(j4), "-o", str(tmp_path / "from_fit")]) == 0
    capfd.readouterr()
    # the robot file by its absolute path: a record read from another folder than the fit's
    # (its "source" as given does not resolve there; the "path" does)
    assert rec["robot"]["path"] == str(Path(ARM3).resolve())
    j5 = tmp_path / "fit5.json"
    j5.write_text(json.dumps(dict(rec2, robot=dict(rec2["robot"], source="elsewhere/arm3.toml"))))
    assert main(["export-model", str(j5), "-o", str(tmp_path / "moved")]) == 0
    capfd.readouterr()
    # bad inputs
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "something/1"}')
    cases = [(bad, "format"), (tmp_path / "missing.json", "missing.json")]
    j3 = tmp_path / "fit3.json"
    j3.write_text(json.dumps(dict(rec, inputs=[str(tmp_path / "gone.csv")])))
    cases.append((j3, "gone.csv"))
    for path, what in cases:
        out = tmp_path / "never"
        code = main(["export-model", str(path), "-o", str(out)])
        err = capfd.readouterr().err.strip()
        assert code == 2 and len(err.splitlines()) == 1 and what in err, err
        assert not out.exists()


@pytest.mark.parametrize("model,param", [("paper", "d_m2"), ("usual", "FV2")])
def test_consistent_estimate_meets_the_friction_bounds(arm3, model, param):
    """A friction parameter moved beyond a physical bound (c_m + d_m >= 0, FV >= 0) is brought
    back onto it by the consistent estimate, at a Mahalanobis cost no larger than the naive
    repair (that parameter alone put on the bound); a fit meeting every bound keeps its
    friction (the paper model's: exactly the free fit's)."""
    params, reg, base, runs = arm3
    sigs = _signals(params, reg, runs, 0)
    m = RobotModel(reg, model, "ls", base=base).fit(sigs)
    nt = m.n_theta_
    fine = fit_consistent(m)
    assert fine.friction_violated == () and fine.friction_d2 == 0.0 and fine.valid
    if model == "paper":
        np.testing.assert_array_equal(fine.coef[nt:], m.coef_[nt:])
    i = m.names_.index(param)
    rows = bound_rows(m.names_, m.numbers_)
    m.coef_ = m.coef_.copy()
    # beyond its bound by 0.5 N m (c_m2 + d_m2 = -0.5, FV2 = -0.5 N m s/rad)
    m.coef_[i] -= 0.5 + next(g @ m.coef_ for w, g, _, _ in rows
                             if w.startswith(("c_m + d_m", "FV")) and g[i] != 0)
    bad = [w for w, g, _, _ in rows if g @ m.coef_ < 0]
    assert len(bad) == 1, bad
    fit = fit_consistent(m, sigs)
    assert fit.friction_violated == tuple(bad) and param in fit.friction_moved
    assert fit.valid and fit.friction_left == () and fit.friction_d2 > 0
    for w, g, _, _ in rows:
        assert g @ fit.coef >= -1e-7 * (1 + np.abs(g) @ np.abs(fit.coef)), w
    assert "friction bounds violated" in fit.format()
    # the naive repair: the same theta, the friction before the bounds (the free fit's for
    # the paper model, profiled on theta for the usual one), the parameter alone on its bound
    free = np.flatnonzero(np.diag(m.cov_) > 0)
    naive = fit.coef.copy()
    if model == "paper":
        naive[nt:] = m.coef_[nt:]
    else:
        th, oth = free[free < nt], free[free >= nt]
        gain = m.cov_[np.ix_(oth, th)] @ np.linalg.inv(m.cov_[np.ix_(th, th)])
        naive[oth] = m.coef_[oth] + gain @ (fit.coef[th] - m.coef_[th])
    g = next(g for w, g, _, _ in rows if w == bad[0])
    naive[i] -= min(g @ naive, 0.0) / g[i]
    assert all(g @ naive >= -1e-12 for _, g, _, _ in rows)
    prec = np.linalg.inv(m.cov_[np.ix_(free, free)])

    def d2(x):
        dx = (x - m.coef_)[free]
        return float(dx @ prec @ dx)

    assert d2(fit.coef) <= d2(naive) * (1 + 1e-6) + 1e-9, (d2(fit.coef), d2(naive))


def test_static_friction_above_every_measured_torque_is_refused(arm3):
    """The joint moved, so its static friction is below the largest torque measured on it
    (friction_bounds.PEAK_BOUNDS): the simulator's friction meets the data's bounds (a fit
    of its data too); a Stribeck term pushed above the peak is reported violated by the
    consistency check and put back onto T_j - c_m by the consistent estimate; without the
    peaks neither knows the bound."""
    params, reg, base, runs = arm3
    sigs = _signals(params, reg, runs, 0)
    peak = torque_peak(sigs)
    assert peak.shape == (3,) and np.all(peak > 0)
    m = RobotModel(reg, "paper", "ls", base=base).fit(sigs)
    f = params.friction
    for j in range(3):  # the truth: c_m + d_m well below the joint's peak torque
        assert f.c_m[j] + f.d_m[j] < peak[j]
    rows = bound_rows(m.names_, m.numbers_, peak)
    assert sum("max|tau|" in w for w, *_ in rows) == 3
    for w, g, h, _ in rows:
        if "max|tau|" in w:
            assert g @ m.coef_ + h > 0, w  # the free fit meets them
    m.coef_ = m.coef_.copy()
    i = m.names_.index("d_m2")
    m.coef_[i] = peak[1] + 5.0 - m.coef_[m.names_.index("c_m2")]  # 5 N m above the peak
    label = next(w for w, *_ in rows if w.startswith("max|tau| - c_m - d_m >= 0 (joint 2,"))
    cons = check_consistency(m, feasibility=False, tau_peak=peak)
    row = next(c for c in cons.checks if c[0] == label)
    assert row[1] == pytest.approx(-5.0) and row[3] != "ok"
    assert not any("max|tau|" in c[0] for c in check_consistency(m, feasibility=False).checks)
    fit = fit_consistent(m, sigs, tau_peak=peak)
    assert label in fit.friction_violated and "d_m2" in fit.friction_moved and fit.valid
    c2, d2 = (fit.coef[m.names_.index(n)] for n in ("c_m2", "d_m2"))
    assert c2 + d2 <= peak[1] + 1e-6 * peak[1]
    assert label not in fit_consistent(m, sigs).friction_violated


def test_add_consistent_hook(arm3):
    """The hook for ``fit_robot``'s record adds a consistent block per fitted model."""
    params, reg, base, runs = arm3
    sigs = _signals(params, reg, runs, 1)
    est = RobotModel(reg, "usual", "ls", base=base).fit(sigs)
    out = {"models": {"usual": {}}, "_estimators": {"usual": est}, "_signals": (sigs, None)}
    add_consistent(out)
    block = out["models"]["usual"]["consistent"]
    assert block["valid"] and set(block["parameters"]) == set(est.names_)
    json.dumps(block)  # serialisable as it is


# --------------------------------------------------------------------------- UR10 acceptance
@pytest.fixture(scope="module")
def ur10():
    return _simulate("ur10", duration_s=12.0)


@pytest.mark.slow
@pytest.mark.parametrize("model", ["usual", "paper"])
def test_ur10_consistent_estimate_and_round_trip(ur10, model, tmp_path):
    """Simulated UR10, payload runs (0, 5 kg, 10 kg), WLS: the consistent estimate has every
    link physically valid, its relative error is within 1.05 x the free fit's, its inertial
    base parameters are no further from the truth than the free fit's (in the metric of the
    free fit's uncertainty), and the exported URDF + friction file reproduce its predicted
    torques to 1e-6."""
    params, reg, base, runs = ur10
    sigs = _signals(params, reg, runs, 3)
    est = RobotModel(reg, model, "wls", base=base).fit(sigs)
    fit = fit_consistent(est, sigs)
    assert fit.valid, fit.links
    assert fit.rel_error_after["all"] <= 1.05 * fit.rel_error_before["all"], fit.format()
    nb = est.n_base_
    truth = est.truth_vector(params.truth(None))[:nb]
    # the metric of the projection (consistent_fit module doc): C_theta^-1 with the friction
    # profiled (usual), (C^-1)_theta at fixed friction (paper); free parameters only
    free = np.flatnonzero(np.diag(est.cov_) > 0)
    if fit.friction == "profile":
        prec = np.linalg.inv(est.cov_[:nb, :nb])
    else:
        prec = np.linalg.inv(est.cov_[np.ix_(free, free)])[:nb, :nb]
    d_free = (est.coef_[:nb] - truth) @ prec @ (est.coef_[:nb] - truth)
    d_cons = (fit.coef[:nb] - truth) @ prec @ (fit.coef[:nb] - truth)
    assert d_cons <= d_free * (1 + 1e-6), (d_cons, d_free)
    worst, ties = _round_trip(est, fit, reg.robot, sigs, tmp_path)
    assert worst <= 1e-6, worst
    assert ties <= 1e-3 * sum(s.n for s in sigs) * len(reg.joints)


@pytest.mark.parametrize("model", ["usual", "paper"])
def test_direct_clarabel_program_is_cvxpys(arm3, model):
    """The program handed to Clarabel directly (the default) is the one cvxpy builds: the
    same optimum -- d^2 and the objective (d^2 + the prior term) equal to the solvers'
    tolerance or lower, every link valid -- on a realisable fit and on one made
    unrealisable (Ia3 = -1)."""
    params, reg, base, runs = arm3
    m = RobotModel(reg, model, "ls", base=base).fit(_signals(params, reg, runs, 2))
    prior = np.asarray(reg.standard_values(), dtype=float)
    scale = max(float(np.median(np.abs(m.coef_[:m.n_base_]))), 1e-2)
    ps = np.maximum(np.abs(prior), scale)

    def objective(fit):
        chi = np.array([fit.standard[n] for n in base.standard_names])
        return fit.d2 + PRIOR_WEIGHT * float(np.sum(((chi - prior) / ps) ** 2))

    for bad in (False, True):
        if bad:
            m.coef_ = m.coef_.copy()
            m.coef_[m.names_.index("Ia3")] = -1.0
        direct = fit_consistent(m)
        ref = fit_consistent(m, solver="cvxpy-clarabel")
        assert direct.valid and ref.valid, (direct.links, ref.links)
        assert direct.status == "optimal" and direct.solver == "CLARABEL"
        assert direct.d2 == pytest.approx(ref.d2, rel=1e-4, abs=1e-6)
        assert objective(direct) <= objective(ref) * (1 + 1e-5) + 1e-8
        np.testing.assert_allclose(direct.coef[:m.n_base_], ref.coef[:m.n_base_], rtol=1e-3,
                                   atol=1e-4 * np.abs(ref.coef[:m.n_base_]).max())
