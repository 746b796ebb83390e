"""Unknown payload, mass known (``RobotModel(payload_params=True)``, ``--payload mass``).

Data as tests/test_robot_fit.py: the offline arm simulator (sim_drivers.arm) with the usual
friction on every joint, runs without payload, with 5 kg (CoM on the flange axis) and with
10 kg (CoM off the axis, inertia), exact states, white noise of 1 % of the load. The fit is
told only the payloads' masses; their first moments and inertia at the flange (and the arm's
base parameters and friction) must be recovered within their standard deviations.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest
import scipy.io
import scipy.stats
from test_robot_cli import ARM3, api_signals, run_cli
from test_robot_fit import PAYLOADS, ROOT, _check_recovery, _signals, _simulate, arm3_usual_data

from ident.loaders import parse_mapping
from ident.robot import RobotIdentError
from ident.robot.base import PAYLOAD_NAMES, payload_base
from ident.robot.estimate import RobotModel
from ident.robot.loaders import load_robot_runs
from ident.robot.payload import format_misfit, payload_misfit
from ident.robot.regressor import RobotRegressor
from ident.robot.signals import RobotPayloadData
from sim_drivers.arm import ArmGains, ArmParams, Payload, model_reference, simulate_arm
from trajectories.robot import load_robot

SEEDS = (0, 1, 2)


@pytest.fixture(scope="module")
def arm3_usual():
    return arm3_usual_data()


def _truth(params, reg, model: RobotModel) -> dict[str, float]:
    """Standard values, usual friction and the payloads' base values by ``names_``."""
    truth = params.truth(None)
    for j in reg.numbers:
        truth[f"FC{j}"] = truth[f"c_m{j}"]
    if model.payload_merged_:
        return truth
    pb = model.payload_base_
    g = len(model.payload_masses_)
    for i, mass in enumerate(model.payload_masses_):
        p = next(p for p in PAYLOADS if p is not None and p.mass == mass)
        vals = pb.values(reg, RobotPayloadData(p.mass, p.com, p.inertia))
        for n, v in zip(pb.names, vals, strict=True):
            truth[f"{n}{i + 1 if g > 1 else ''}"] = float(v)
    return truth


def test_flange_transform_matches_payload_parameters():
    """phi_link = T phi_flange for a flange placed anywhere on the last link; the payload
    columns times the flange parameters are the payload torque."""
    reg = RobotRegressor(load_robot(ROOT / "examples" / "robots" / "arm3.toml"))
    reg.flange_placement = pin.SE3(pin.rpy.rpyToMatrix(0.3, -0.7, 1.1),
                                   np.array([0.05, -0.02, 0.12]))
    pay = RobotPayloadData(7.0, [0.03, -0.01, 0.08], [0.02, 0.001, -0.002, 0.03, 0.0, 0.01])
    phi = reg.flange_parameters(pay)
    assert phi[9] == 7.0 and np.allclose(phi[6:9], 7.0 * pay.com)
    assert np.allclose(reg.flange_transform() @ phi, reg.payload_parameters(pay))
    rng = np.random.default_rng(3)
    q, dq, ddq = rng.normal(size=(3, 40, reg.k))
    tau = np.einsum("jcn,c->nj", reg.payload_columns(q, dq, ddq), phi)
    assert np.allclose(tau, reg.payload_torque(q, dq, ddq, pay))


def test_payload_base_rule():
    """The QR rule on the payload's nine columns: all nine act on the 3-dof arm; on one
    revolute joint only ZZ, MX, MY do (the others are named unidentifiable)."""
    arm = payload_base(RobotRegressor(load_robot(ROOT / "examples" / "robots" / "arm3.toml")))
    assert arm.names == PAYLOAD_NAMES and arm.unidentifiable == ()
    one = load_robot(ROOT / "examples" / "robots" / "rx130l.toml")  # joint 3 moves alone
    assert len(one.moving) == 1
    pb = payload_base(RobotRegressor(one))
    assert set(pb.names) == {"ZZpay", "MXpay", "MYpay"}, pb.expressions
    assert set(pb.unidentifiable) == {"XXpay", "XYpay", "XZpay", "YYpay", "YZpay", "MZpay"}


@pytest.mark.parametrize("method", ["ls", "wls", "iv"])
def test_unknown_com_payload_recovered_within_sigma(arm3_usual, method):
    params, reg, base, runs = arm3_usual
    fits = [RobotModel(reg, "usual", method, base=base, payload_params=True).fit(
        _signals(params, reg, runs, s)) for s in SEEDS]
    m = fits[0]
    assert m.payload_masses_ == (5.0, 10.0)
    assert m.names_[m.n_base_:m.n_theta_] == tuple(
        f"{n}{g}" for g in (1, 2) for n in PAYLOAD_NAMES)
    _check_recovery(fits, _truth(params, reg, m))
    # the payload block alone, no 1 % escape: every comparison within the family-wise
    # bound, 95 % within 3 sigma (as _check_recovery)
    zs = []
    for f in fits:
        sl = slice(f.n_base_, f.n_theta_)
        zs.append((f.coef_[sl] - f.truth_vector(_truth(params, reg, f))[sl]) / f.std_[sl])
    z = np.concatenate(zs)
    z_fw = max(3.0, float(scipy.stats.norm.ppf(1 - 0.01 / (2 * z.size))))
    assert np.all(np.abs(z) < z_fw), np.round(zs, 2)
    assert np.mean(np.abs(z) <= 3) >= 0.95, np.round(zs, 2)
    # the 10 kg payload's CoM offset is resolved: MX = m c_x = 0.2 far above its sigma
    i = m.names_.index("MXpay2")
    assert m.coef_[i] / m.std_[i] > 20


@pytest.mark.slow
def test_unknown_com_payload_recovered_on_ur10():
    """The same on the 6-axis UR10 (usual friction, 0 / 5 / 10 kg runs, 3 seeds)."""
    robot = load_robot(ROOT / "examples" / "robots" / "ur10.toml")
    c = ArmParams.from_robot(robot).friction.c_m
    params, reg, base, runs = _simulate("ur10", dict(a_m=1.0, b_m=0.0, a_g=1.0, b_g=0.0,
                                                     d_m=0.0, d_g=0.0, c_g=c),
                                        duration_s=12.0, seed=3)
    fits = [RobotModel(reg, "usual", base=base, payload_params=True).fit(
        _signals(params, reg, runs, s)) for s in SEEDS]
    _check_recovery(fits, _truth(params, reg, fits[0]))


def test_misfit_flags_guessed_com_not_identified_one(arm3_usual):
    """A guessed CoM (the payloads taken as point masses at the flange, --payload known)
    leaves a payload-run residual the check flags; the identified payload leaves none."""
    params, reg, base, runs = arm3_usual
    sigs = _signals(params, reg, runs, 0)
    good = RobotModel(reg, "usual", base=base, payload_params=True).fit(sigs)
    check = payload_misfit(good, sigs)
    assert not any(c["misfit"] for c in check.values()), format_misfit(check)
    assert all(c["ratio"] < 1.1 for c in check.values()), format_misfit(check)
    guessed = [replace(s, payloads=tuple(RobotPayloadData(p.mass) for p in s.payloads))
               for s in sigs]
    wrong = RobotModel(reg, "usual", base=base).fit(guessed)
    bad = payload_misfit(wrong, guessed)
    flagged = [j for j, c in bad.items() if c["misfit"]]
    assert flagged, format_misfit(bad)
    assert all(bad[j]["ratio"] > check[j]["ratio"] for j in flagged)


def test_payload_params_errors_name_the_problem(arm3_usual):
    params, reg, base, runs = arm3_usual
    sigs = _signals(params, reg, runs, 0)
    with pytest.raises(RobotIdentError, match="every experiment carries a payload"):
        RobotModel(reg, base=base, payload_params=True).fit(sigs[1:])  # 5 and 10 kg
    with pytest.raises(RobotIdentError, match="no experiment carries a payload"):
        RobotModel(reg, base=base, payload_params=True).fit(sigs[:1])
    with pytest.raises(RobotIdentError, match="exclude each other"):
        RobotModel(reg, base=base, payload_params=True, payload_ratio=True).fit(sigs)
    m = RobotModel(reg, base=base, payload_params=True).fit(sigs[:2])
    with pytest.raises(RobotIdentError, match="not one of the fitted payloads"):
        m.predict(sigs[2])


def test_cli_payload_mass(tmp_path, capfd):
    """``jointid fit --robot --payload mass`` on CSV files that give only the payload's mass:
    the columns chain, the same estimate as the Python estimator on the same files, the
    payload's CoM recovered, its combinations and per-joint check printed and recorded."""
    robot = load_robot(ARM3)
    c = ArmParams.from_robot(robot).friction.c_m
    params = ArmParams.from_robot(robot, dict(a_m=1.0, b_m=0.0, a_g=1.0, b_g=0.0, d_m=0.0,
                                              d_g=0.0, c_g=c))
    ref = model_reference(params.model, center=[0.0, -1.9, 0.6], fraction=0.9,
                          duration_s=10.0, seed=1)
    pay = Payload(10.0, [0.02, 0.0, 0.1], [0.02, 0.0, 0.0, 0.02, 0.0, 0.03])
    files = []
    for i, p in enumerate((None, pay)):
        run = simulate_arm(params, ref, ArmGains.for_params(params, payload=p), payload=p,
                           seed=20 + i)
        cols = run.columns()
        cols["payload_mass_kg"] = np.full(run.t.size, 0.0 if p is None else p.mass)
        files.append(tmp_path / f"p{i}.csv")
        np.savetxt(files[-1], np.column_stack(list(cols.values())), delimiter=",",
                   header=",".join(cols), comments="", fmt="%.17g")
    out_json = tmp_path / "fit.json"
    code, out, err = run_cli(capfd, "--robot", ARM3, *files, "--model", "usual", "--method",
                             "ls", "--payload", "mass", "--json", out_json)
    assert code == 0, err
    assert "payload check" in out, out
    rec = json.loads(out_json.read_text())
    assert rec["payload"] == "mass"
    usual = rec["models"]["usual"]
    assert set(usual["payload_misfit"]) == set(robot.moving)
    assert len(usual["payload_expressions"]) == 9
    reg = RobotRegressor(robot)
    sig, _ = api_signals(files, robot, rec, reg, "ls")
    assert [p.mass for p in sig.payloads] == [0.0, 10.0]
    assert not np.any(sig.payloads[1].com)  # the files give no CoM
    est = RobotModel(reg, "usual", "ls", payload_params=True).fit(sig)
    pars = usual["parameters"]
    assert list(pars) == list(est.names_)
    np.testing.assert_allclose([v["value"] for v in pars.values()], est.coef_, rtol=1e-6,
                               atol=1e-9)
    truth = dict(zip(est.payload_base_.names, est.payload_base_.values(
        reg, RobotPayloadData(pay.mass, pay.com, pay.inertia)), strict=True))
    for name in ("MXpay", "MYpay", "MZpay"):  # m c [kg m]
        v, s = pars[name]["value"], pars[name]["std"]
        assert abs(v - truth[name]) < max(4 * s, 0.01 * abs(truth[name])), (name, v, s,
                                                                              truth[name])


def test_one_payload_in_every_run_merges_into_the_last_link(arm3_usual):
    """Only the 10 kg runs: the payload's columns are the last link's own, so its first
    moments and inertia merge into the last link's standard parameters (its mass at the
    flange origin subtracted): recovered within sigma against that merged truth."""
    params, reg, base, runs = arm3_usual
    fits = [RobotModel(reg, "usual", base=base, payload_params=True).fit(
        _signals(params, reg, runs, s)[2:]) for s in SEEDS]
    m = fits[0]
    assert m.payload_merged_ and m.n_theta_ == m.n_base_
    assert not any("pay" in n for n in m.names_)
    p = PAYLOADS[2]
    phi = reg.flange_parameters(RobotPayloadData(p.mass, p.com, p.inertia))
    phi[9] = 0.0  # the mass is known: subtracted, not merged
    merged = reg.flange_transform() @ phi
    truth = _truth(params, reg, m)
    k = reg.numbers[-1]
    for name, v in zip(("XX", "XY", "XZ", "YY", "YZ", "ZZ", "MX", "MY", "MZ", "M"), merged,
                       strict=True):
        truth[f"{name}{k}"] = truth.get(f"{name}{k}", 0.0) + float(v)
    _check_recovery(fits, truth)


def test_mat_payload_mass_from_map(tmp_path):
    """MAT files: ``--map payload_kg=`` gives the file's payload mass (a number or a path to
    a scalar); a negative mass or a non-scalar path is refused naming the file and key."""
    k = 3
    t = np.arange(0.0, 1.0, 0.01)
    f = tmp_path / "run.mat"
    scipy.io.savemat(f, {"t": t, "q": np.zeros((t.size, k)), "tau": np.zeros((t.size, k)),
                         "rec": {"load": 12.5}})
    joints = load_robot(ARM3).moving
    base = {"t": "t", "q": "q", "tau": "tau"}
    assert load_robot_runs(f, joints, mapping=base)[0].payload.mass == 0.0
    assert load_robot_runs(f, joints, mapping={**base, "payload_kg": "7.5"})[0].payload.mass \
        == 7.5
    run = load_robot_runs(f, joints, mapping=parse_mapping(
        "t=t,q=q,tau=tau,payload_kg=rec.load", robot=True))[0]
    assert run.payload.mass == 12.5 and not np.any(run.payload.com)
    with pytest.raises(RobotIdentError, match=r"run.mat: payload_kg '-3'"):
        load_robot_runs(f, joints, mapping={**base, "payload_kg": "-3"})
    with pytest.raises(RobotIdentError, match=r"run.mat: payload_kg 't' has shape"):
        load_robot_runs(f, joints, mapping={**base, "payload_kg": "t"})
