"""The robot model is the ground floor (trajectories.robot): the planner predicts the condition
number of the base the fit estimates, and robot files load through one suffix table (a new
format is one module and one row)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from ident.robot.estimate import RobotModel
from ident.robot.signals import RobotSignals
from tests.robot_campaigns import ROOT
from trajectories.campaign_file import load_any_campaign
from trajectories.excitation import condition_number, quality
from trajectories.multi import plan_robot_campaign
from trajectories.robot import FORMATS, RobotError, RobotRegressor, load_robot
from trajectories.robot_model import RobotDynamics, robot_for_campaign

pin = pytest.importorskip("pinocchio")
EXAMPLE = ROOT / "examples" / "campaign_robot3.toml"


def test_the_planners_condition_number_is_the_fits_on_the_same_samples():
    """jointid plan's prediction and the n-dof fit use one regressor and one base rule: the
    fit on the plan's samples estimates the base columns the planner conditions on, and the
    condition number of the fit's base regressor on those samples is the planner's."""
    campaign = load_any_campaign(EXAMPLE)
    robot = robot_for_campaign(campaign)
    dyn = RobotDynamics(robot)
    plan = plan_robot_campaign(campaign)
    pred = quality(plan, dyn.regressor, max_samples=3000)
    s = pred.stride
    q, dq, ddq = plan.q[::s], plan.dq[::s], plan.ddq[::s]
    tau = dyn.inverse_dynamics(q, dq, ddq)  # noise-free rigid body + rotors
    reg = RobotRegressor(robot)
    fit = RobotModel(reg, "usual", "ls").fit(RobotSignals(
        t=np.arange(len(q)) * s * campaign.cycle_s, q=q, dq=dq, ddq=ddq, tau=tau,
        joints=reg.joints))
    # the fit recovers the robot file's base parameters: it estimates this base
    truth = fit.base_.values(reg.standard_values(dyn.Ia))
    got = np.array([fit.params_[n] for n in fit.base_.names])
    np.testing.assert_allclose(got, truth, rtol=1e-6, atol=1e-8 * np.abs(truth).max())
    # ... and the planner's base columns are the fit's rigid base plus the friction columns
    p = reg.p
    assert [dyn.names[c] for c in pred.base_columns if c < p] == [
        reg.standard_names[c] for c in fit.base_.columns]
    assert [dyn.names[c] for c in pred.base_columns if c >= p] == list(reg.friction_names)
    # the fit's base regressor (its base columns, then the friction columns) on the samples
    w_fit = np.concatenate([fit.base_.reduce(reg.rigid(q, dq, ddq)),
                            reg.friction(dq, dyn.deadband)], axis=-1)
    w_fit = w_fit.reshape(-1, w_fit.shape[-1])
    cond_fit = condition_number(w_fit, np.arange(w_fit.shape[1]))
    assert pred.cond == pytest.approx(cond_fit, rel=1e-9)
    assert 1.0 < pred.cond < 1e4


_MJCF = """<mujoco model="two_link">
  <worldbody>
    <body name="l1" pos="0 0 0.1">
      <joint name="a" type="hinge" axis="0 0 1"/>
      <inertial pos="0.2 0 0" mass="2.0" diaginertia="0.01 0.02 0.03"/>
      <body name="l2" pos="0.4 0 0">
        <joint name="b" type="hinge" axis="0 1 0"/>
        <inertial pos="0.15 0 0.01" mass="1.0" diaginertia="0.004 0.005 0.006"/>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def test_a_format_is_a_row_of_the_suffix_table(tmp_path: Path):
    assert {".toml", ".urdf", ".xml", ".mjcf"} <= set(FORMATS)
    f = tmp_path / "two_link.xml"
    f.write_text(_MJCF, encoding="utf-8")
    robot = load_robot(f)
    assert robot.joint_names == ("a", "b") and robot.types == ("revolute", "revolute")
    # the MJCF robot goes through the same regressor: W chi_St = pinocchio's inverse dynamics
    reg = RobotRegressor(robot)
    rng = np.random.default_rng(3)
    q, dq, ddq = (rng.uniform(-2, 2, (20, 2)) for _ in range(3))
    tau = reg.rigid(q, dq, ddq) @ reg.standard_values(np.zeros(2))
    model = robot.reduced()
    data = model.createData()
    ref = np.array([pin.rnea(model, data, *x) for x in zip(q, dq, ddq, strict=True)])
    np.testing.assert_allclose(tau, ref, rtol=1e-10, atol=1e-10)


def test_an_unknown_suffix_names_the_file_and_the_table(tmp_path: Path):
    f = tmp_path / "arm.yaml"
    f.write_text("robot: {}\n", encoding="utf-8")
    with pytest.raises(RobotError) as e:
        load_robot(f)
    msg = str(e.value)
    assert "arm.yaml" in msg and ".toml" in msg and ".urdf" in msg and "\n" not in msg
    bad = tmp_path / "broken.xml"
    bad.write_text("<mujoco><worldbody>", encoding="utf-8")
    with pytest.raises(RobotError, match="broken.xml: MJCF does not parse"):
        load_robot(bad)
