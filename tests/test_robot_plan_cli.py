"""``jointid plan`` on a robot campaign: per-joint summary, peak torques, the predicted condition
number of the robot model's regressor, band and quadrant shares, multi-sine optimisation."""

from __future__ import annotations

import re

import numpy as np
import pytest

from daq.app.cli import main
from tests.robot_campaigns import ROOT, arm3_campaign
from trajectories.campaign_file import load_any_campaign
from trajectories.excitation import base_columns, condition_number, quality
from trajectories.multi import plan_robot_campaign
from trajectories.robot import load_robot
from trajectories.robot_model import RobotDynamics, prepare_robot_campaign, robot_for_campaign

EXAMPLE = ROOT / "examples" / "campaign_robot3.toml"
pin = pytest.importorskip("pinocchio")


def _plan(capsys, *args: str) -> tuple[int, str, str]:
    code = main(["plan", *args])
    out, err = capsys.readouterr()
    return code, out, err


def test_robot_plan_prints_summary_condition_number_bands_and_quadrants(capsys):
    code, out, err = _plan(capsys, str(EXAMPLE))
    assert code == 0, err
    assert "robot campaign 'arm3-excitation': 2 payload run(s)" in out
    for j in ("j1", "j2", "j3"):
        assert re.search(rf"^{j}\s+-?\d", out, re.M)  # a row per joint
    assert "0-10 % of vmax" in out and "j2 moving" in out  # shares and coverage per band
    assert out.count("quadrants of (dq, tau_out), payload") == 2  # per payload
    assert "peak |tau| [N m] (max_torque)" in out
    m = re.search(r"multi-sine optimised: condition number ([\d.]+) -> ([\d.]+)", out)
    assert m and float(m.group(2)) < float(m.group(1))
    cond = float(re.search(r"excitation: condition number ([\d.e+]+)", out).group(1))
    # the same figure computed here from the pieces
    c = load_any_campaign(EXAMPLE)
    played, dyn, _ = prepare_robot_campaign(c)
    q = quality(plan_robot_campaign(played), dyn.regressor)
    assert cond == pytest.approx(q.cond, rel=1e-3)


def test_no_optimise_plays_the_coefficients_as_written(capsys):
    code, out, _ = _plan(capsys, str(EXAMPLE), "--no-optimise")
    assert code == 0 and "multi-sine optimised" not in out
    plain = float(re.search(r"excitation: condition number ([\d.e+]+)", out).group(1))
    code, out, _ = _plan(capsys, str(EXAMPLE))
    opt = float(re.search(r"excitation: condition number ([\d.e+]+)", out).group(1))
    assert opt < plain  # the optimiser improved the whole plan's figure too


def test_optimisation_is_deterministic_so_run_plays_what_plan_showed():
    c = arm3_campaign(segments=[{"kind": "multisine", "period_s": 4.0, "harmonics": 4,
                                 "fill": 0.6, "seed": 2, "optimise": True}])
    a, _, r1 = prepare_robot_campaign(c)
    b, _, r2 = prepare_robot_campaign(c)
    assert r1 and r1[0].cond_end < r1[0].cond_start
    assert a.segments[0].a == b.segments[0].a and a.segments[0].b == b.segments[0].b
    assert a.segments[0].a is not None and c.segments[0].a is None


def test_regressor_is_pinocchio_s_standard_parameters_plus_rotor_and_friction():
    """tau = W chi with chi from the robot file reproduces pinocchio's RNEA + Ia ddq + friction."""
    robot = load_robot(ROOT / "examples" / "robots" / "arm3.toml")
    dyn = RobotDynamics(robot)
    rng = np.random.default_rng(0)
    n, k = 50, 3
    q = rng.uniform(-1, 1, (n, k))
    dq = rng.uniform(-1, 1, (n, k))
    ddq = rng.uniform(-3, 3, (n, k))
    w = dyn.regressor(q, dq, ddq)
    assert w.shape == (n * k, len(dyn.names)) and dyn.names[:11] == (
        "XX1", "XY1", "XZ1", "YY1", "YZ1", "ZZ1", "MX1", "MY1", "MZ1", "M1", "Ia1")
    chi = []
    model = robot.reduced()
    for j in range(1, k + 1):
        p = model.inertias[j].toDynamicParameters()  # m, mx, my, mz, Ixx, Ixy, Iyy, Ixz, ...
        chi += [p[4], p[5], p[7], p[6], p[8], p[9], p[1], p[2], p[3], p[0], dyn.Ia[j - 1]]
    fc, fv, off = 3.0, 2.0, -0.5
    chi += [fc, fv, off] * k
    tau = (w @ np.array(chi)).reshape(n, k)
    moving = np.abs(dq) > dyn.deadband
    expected = (dyn.inverse_dynamics(q, dq, ddq) + fc * np.sign(dq) * moving + fv * dq + off)
    np.testing.assert_allclose(tau, expected, atol=1e-9)
    # 25 base columns for this arm (a 3R arm with j1 vertical: Khalil's regrouping leaves 25
    # with rotors and friction)
    assert base_columns(dyn.regressor, arm3_campaign().limits).size == 25


def test_campaign_joints_must_exist_in_the_robot_file(capsys, tmp_path):
    text = EXAMPLE.read_text().replace('moving = ["j1", "j2", "j3"]',
                                       'moving = ["j1", "j2", "elbow"]')
    text = text.replace("[robot.joints.j3]", "[robot.joints.elbow]")
    text = text.replace("j3 = { kp", "elbow = { kp").replace('file = "robots/arm3.toml"',
                                                            f'file = "{EXAMPLE.parent}/robots/'
                                                            f'arm3.toml"')
    text = text.replace('sweep = { j3 = [0.3, 2.5] }', 'sweep = { elbow = [0.3, 2.5] }')
    text = text.replace('joint = "j3"', 'joint = "elbow"')
    bad = tmp_path / "bad.toml"
    bad.write_text(text)
    code, out, err = _plan(capsys, str(bad))
    assert code == 2
    assert len(err.strip().splitlines()) == 1
    assert "robot.moving[2]: expected a joint of" in err and "'elbow'" in err


def test_robot_file_for_campaign_keeps_its_moving_and_locked_joints():
    c = arm3_campaign()
    r = robot_for_campaign(c)
    assert r.moving == ("j1", "j2", "j3") and not r.locked
    assert robot_for_campaign(c).reduced().nv == 3


def test_condition_number_is_inf_for_a_plan_that_excites_nothing():
    c = arm3_campaign(segments=[{"kind": "move", "poses": [[0.0, -1.2, 1.2]]}])
    played, dyn, _ = prepare_robot_campaign(c)
    plan = plan_robot_campaign(played)
    w = dyn.regressor(plan.q, plan.dq, plan.ddq)
    base = base_columns(dyn.regressor, c.limits)
    assert condition_number(w, base) > 1e8  # a plan at rest identifies almost nothing
