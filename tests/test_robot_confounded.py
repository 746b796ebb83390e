"""A vertical prismatic axis: the weight of its link is a constant force, the column of the
joint's offset, and its inertia is the rotor inertia's (ident.robot.confounded).

On a 3-axis cylindrical robot (revolute base, vertical prismatic column, horizontal prismatic
arm), ``jointid fit --robot`` ended in "parameters not identifiable on these data (cond
3e+300); the weakest direction involves ['OFF2', 'M2', 'Ia2', 'M3']", with no hint of why or
what to do. Now M2 is regrouped (Ia2R = Ia2 + M2, the fitted OFF2 = OFF2 + 9.81 M2), one note
line says so and what separates them (the rotor inertias given), the paper model, whose load
must carry that weight, is refused with one line, and the exported model takes the weight
out of OFF2 (the URDF's inverse dynamics has it)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from robot_campaigns import write_arm_csv

from daq.app.cli import main
from ident.cli_robot import fit_files, load_runs
from ident.robot import RobotIdentError
from ident.robot.confounded import physical_friction, regroup_friction
from ident.robot.consistent_fit import consistent_model, consistent_record, fit_consistent
from ident.robot.design import design_runs, resolve_design
from ident.robot.estimate import RobotModel
from ident.robot.export_model import export_model, exported_torque
from sim_drivers.arm import ArmGains, ArmParams, Payload, model_reference, simulate_arm
from trajectories.robot import RobotRegressor, base_parameters, load_robot
from trajectories.robot.base import random_states

ROOT = Path(__file__).resolve().parents[1]
G = 9.81  # [m/s^2], the robot file's gravity

CYLINDRICAL = """
[robot]
name = "cyl3"
gravity = [0.0, 0.0, -9.81]

[[joints]]                # base yaw, vertical axis
name = "j1"
type = "revolute"
r = 0.4
mass = 15.0
com = [0.0, 0.0, -0.1]
inertia = [0.40, 0.0, 0.0, 0.40, 0.0, 0.20]
[joints.limits]
q_min = -2.5
q_max = 2.5
dq_max = 1.2
ddq_max = 4.0
dddq_max = 40.0
tau_max = 300.0
[joints.drive]
gear_ratio = 100.0
rotor_inertia = 1.0e-4

[[joints]]                # vertical column, z2 = z1
name = "j2"
type = "prismatic"
mass = 8.0
com = [0.05, 0.0, 0.0]
inertia = [0.08, 0.0, 0.0, 0.10, 0.0, 0.08]
[joints.limits]
q_min = 0.1
q_max = 0.7
dq_max = 0.4
ddq_max = 2.0
dddq_max = 20.0
tau_max = 600.0
[joints.drive]
gear_ratio = 314.159      # ball screw of 20 mm lead [rad/m]
rotor_inertia = 5.0e-5

[[joints]]                # horizontal arm
name = "j3"
type = "prismatic"
alpha = -1.5707963267948966
d = 0.1
mass = 5.0
com = [0.0, 0.0, -0.2]
inertia = [0.35, 0.0, 0.0, 0.35, 0.0, 0.01]
[joints.limits]
q_min = 0.0
q_max = 0.5
dq_max = 0.4
ddq_max = 2.0
dddq_max = 20.0
tau_max = 300.0
[joints.drive]
gear_ratio = 314.159
rotor_inertia = 5.0e-5
"""


def cylindrical_arm(folder: Path) -> tuple[Path, ArmParams]:
    """The robot file written in ``folder`` and the simulator's parameters: usual friction
    on every joint (no load-dependent terms, c_g = c_m)."""
    path = folder / "cyl3.toml"
    path.write_text(CYLINDRICAL)
    robot = load_robot(path)
    c = ArmParams.from_robot(robot).friction.c_m
    return path, ArmParams.from_robot(robot, dict(a_m=1.0, b_m=0.0, a_g=1.0, b_g=0.0,
                                                  d_m=0.0, d_g=0.0, c_g=c))


@pytest.fixture(scope="module")
def cylindrical(tmp_path_factory) -> tuple[Path, Path, dict[str, float]]:
    """The robot file, one simulated run as a robot CSV (usual friction on every joint, the
    simulator's drive noise) and the simulator's truth."""
    d = tmp_path_factory.mktemp("cyl3")
    path, params = cylindrical_arm(d)
    ref = model_reference(params.model, fraction=0.9, duration_s=12.0, seed=1)
    run = simulate_arm(params, ref, ArmGains.for_params(params), seed=0)
    return path, write_arm_csv(run, d / "run0.csv"), params.truth()


def test_regrouping_is_exact_and_only_where_needed(cylindrical):
    reg = RobotRegressor(load_robot(cylindrical[0]))
    rg = regroup_friction(reg)
    assert rg is not None and rg.removed == ("M2",)
    assert "Ia2R = Ia2 + M2" in rg.base.expressions and "M2" not in rg.base.names
    assert rg.base.friction.keys() == {"OFF2"}
    assert rg.base.friction["OFF2"] == {"M2": pytest.approx(G, rel=1e-12)}
    # the rigid torque plus the offsets, at random states: the regrouped base with the
    # fitted OFF2 = OFF2 + 9.81 M2 predicts the same torques as the standard parameters
    truth = reg.standard_values()
    off = np.array([0.1, 3.0, 0.2])
    q, dq, ddq = random_states(reg, None, 50, seed=7)
    tau = reg.rigid(q, dq, ddq) @ truth + off
    chi_b = rg.base.values(truth)
    fitted_off = off + np.array([0.0, G * truth[reg.standard_names.index("M2")], 0.0])
    np.testing.assert_allclose(rg.base.reduce(reg.rigid(q, dq, ddq)) @ chi_b + fitted_off, tau,
                               rtol=1e-12, atol=1e-9)
    # given the fitted OFF2 and M2, the physical offset comes back
    std = dict(zip(reg.standard_names, truth, strict=True))
    assert physical_friction({"OFF2": fitted_off[1]}, std, rg.base.friction)["OFF2"] == \
        pytest.approx(3.0, rel=1e-12)
    # the rotor inertias known: nothing to regroup; a revolute arm: nothing either
    assert regroup_friction(RobotRegressor(load_robot(cylindrical[0]),
                                           known_rotor_inertia=True)) is None
    arm3 = RobotRegressor(load_robot(ROOT / "examples" / "robots" / "arm3.toml"))
    assert regroup_friction(arm3, base_parameters(arm3)) is None
    # no rotor inertias in the robot file: no remedy offered, the sums are what is identified
    bare = cylindrical[0].with_name("cyl3_bare.toml")
    bare.write_text("\n".join(ln for ln in CYLINDRICAL.splitlines()
                              if not ln.startswith("rotor_inertia")))
    note = regroup_friction(RobotRegressor(load_robot(bare))).note
    assert "--known-rotor-inertia" not in note and "the regrouped sums are what is identified" \
        in note, note


def _value(rec: dict, name: str) -> tuple[float, float]:
    p = rec["models"]["usual"]["parameters"][name]
    return p["value"], p["std"]


def test_fit_cli_regroups_says_why_and_what_to_do(cylindrical, tmp_path, capfd):
    robot, csv, truth = cylindrical
    out = tmp_path / "fit.json"
    assert main(["fit", "--robot", str(robot), str(csv), "--model", "both", "--json", str(out),
                 "--no-consistency"]) == 0
    text = capfd.readouterr().out
    notes = [ln for ln in text.splitlines() if ln.startswith("note:") and "confounded" in ln]
    assert len(notes) == 1, text
    assert "M2 confounded with Ia2, OFF2" in notes[0]
    assert "prismatic axis j2" in notes[0] and "Ia2R = Ia2 + M2" in notes[0]
    assert "OFF2 (fitted) = OFF2 + 9.81*M2" in notes[0] and "--known-rotor-inertia" in notes[0]
    assert "== paper model: not identified: paper model not fitted" in text
    rec = json.loads(out.read_text())
    usual = rec["models"]["usual"]
    assert "Ia2R = Ia2 + M2" in usual["base_expressions"]
    assert "OFF2 (fitted) = OFF2 + 9.81*M2" in usual["base_expressions"]
    assert usual["friction_regrouped"]["OFF2"]["M2"] == pytest.approx(G)
    # the regrouped sums against the simulator's truth, within 3 standard deviations
    for name, want in (("Ia2R", truth["Ia2"] + truth["M2"]),
                       ("OFF2", truth["OFF2"] + G * truth["M2"]),
                       ("M3", truth["M3"])):
        v, sd = _value(rec, name)
        assert abs(v - want) <= 3 * sd, (name, v, sd, want)
    # the rotor inertias known: M2 and OFF2 apart, each at the truth
    out2 = tmp_path / "fit_known.json"
    assert main(["fit", "--robot", str(robot), str(csv), "--model", "usual", "--json",
                 str(out2), "--no-consistency", "--known-rotor-inertia"]) == 0
    assert "confounded" not in capfd.readouterr().out
    rec2 = json.loads(out2.read_text())
    for name in ("M2", "OFF2"):
        v, sd = _value(rec2, name)
        assert abs(v - truth[name]) <= 3 * sd, (name, v, sd, truth[name])
    # the paper model alone: one line, exit 2, nothing written
    out3 = tmp_path / "paper.json"
    assert main(["fit", "--robot", str(robot), str(csv), "--model", "paper", "--json",
                 str(out3)]) == 2
    err = capfd.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "paper model not fitted" in err[0] and "M2" in err[0], err
    assert not out3.exists()


def test_export_takes_the_weight_out_of_the_offset(cylindrical, tmp_path):
    """The exported URDF's inverse dynamics has M2's weight: the friction file's OFF2 is the
    fitted one less 9.81 M2 of the consistent standard parameters, so the exported model
    predicts the fit's torques (it predicted them 9.81 M2 = 79 N too high on j2)."""
    path, csv, _ = cylindrical
    robot = load_robot(path)
    out = fit_files(robot, [csv], model="usual", sigma_blocks=0, feasibility=False)
    est, sig = out["_estimators"]["usual"], out["_signals"][0]
    fit = fit_consistent(est, sig)
    files = export_model(robot, consistent_record(est, fit), tmp_path, est.fixed_)
    fr = json.loads(files[1].read_text())
    model = pin.buildModelFromUrdf(str(files[0]))
    model.gravity = pin.Motion(np.r_[np.asarray(fr["gravity"], float), 0.0, 0.0, 0.0])
    data = model.createData()
    rows = slice(None, None, 7)
    q, dq, ddq = sig.q[rows], sig.dq[rows], sig.ddq[rows]
    tr = np.array([pin.rnea(model, data, a, b, c) for a, b, c in zip(q, dq, ddq, strict=True)])
    ex = exported_torque(fr, tr, dq, ddq)
    sub = type(sig)(t=sig.t[rows], q=q, dq=dq, ddq=ddq, tau=sig.tau[rows],
                    experiment=sig.experiment[rows], joints=sig.joints, payloads=sig.payloads)
    pr = consistent_model(est, fit).predict(sub)
    assert np.max(np.abs(ex - pr)) <= 1e-6 * np.max(np.abs(pr))


def test_payload_runs_do_not_separate_the_weight(cylindrical, tmp_path):
    """What the note says: runs with payloads (0, 5, 10 kg at the arm's end) leave M2, Ia2
    and OFF2 dependent whatever the payload treatment (the base of the rigid body alone is
    singular: known payload torque, identified ratio M_ae/M_aw, identified first moments),
    and the regrouped fit recovers the sums in each."""
    path, _, truth = cylindrical
    robot = load_robot(path)
    c = ArmParams.from_robot(robot).friction.c_m
    params = ArmParams.from_robot(robot, dict(a_m=1.0, b_m=0.0, a_g=1.0, b_g=0.0, d_m=0.0,
                                              d_g=0.0, c_g=c))
    ref = model_reference(params.model, fraction=0.9, duration_s=8.0, seed=2)
    files = []
    for i, pay in enumerate((None, Payload(5.0, [0.0, 0.0, 0.05]),
                             Payload(10.0, [0.0, 0.0, 0.05]))):
        run = simulate_arm(params, ref, ArmGains.for_params(params, payload=pay), payload=pay,
                           seed=20 + i)
        files.append(write_arm_csv(run, tmp_path / f"p{i}.csv"))
    runs = load_runs(robot, files)
    reg = RobotRegressor(robot)
    design = resolve_design(runs, instruments=False, cutoff_hz=None, decimation=None,
                            trim=None, dq_min=None)
    sig, _ = design_runs(runs, reg, design)
    for kw in (dict(), dict(payload_ratio=True), dict(payload_params=True)):
        with pytest.raises(RobotIdentError, match="not identifiable") as exc:
            RobotModel(reg, model="usual", method="ls", **kw).fit(sig)
        assert {"M2", "OFF2"} <= set(exc.value.names), (kw, exc.value.names)
    for payload in ("known", "ratio", "mass"):
        out = fit_files(robot, runs, model="usual", payload=payload, sigma_blocks=0,
                        feasibility=False)
        pars = out["models"]["usual"]["parameters"]
        for name, want in (("Ia2R", truth["Ia2"] + truth["M2"]),
                           ("OFF2", truth["OFF2"] + G * truth["M2"])):
            v, sd = pars[name]["value"], pars[name]["std"]
            assert abs(v - want) <= 3 * sd, (payload, name, v, sd, want)
