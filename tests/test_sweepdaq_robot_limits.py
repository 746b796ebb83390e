"""A robot campaign whose joint limits go beyond the robot file's own limits (found by the
acquisition sweep): ``jointid plan`` planned j1 at 3 rad/s over [-3.5, 3.5] rad on the 3-dof
arm whose file gives dq_max = 1.5 rad/s and [-2.8, 2.8] rad, and ``jointid run`` would have
driven it there (its watchdogs use the campaign's limits). Each such limit is now refused
in one line naming the campaign key, the robot file's limit and the file; limits within the
robot file's (the examples) still plan."""

from __future__ import annotations

import pytest
from robot_campaigns import arm3_raw

from trajectories import TrajectoryError
from trajectories.robot_campaign import RobotCampaign
from trajectories.robot_model import robot_for_campaign

CASES = [
    # (joint, campaign limit key, value, robot file limit named in the message)
    ("j1", "position", [-3.5, 3.5], "[q_min, q_max] = [-2.8, 2.8]"),
    ("j2", "position", [-2.5, -0.3], "[q_min, q_max] = [-2.4, -0.3]"),
    ("j1", "max_velocity", 3.0, "dq_max = 1.5"),
    ("j3", "max_acceleration", 6.0, "ddq_max = 5"),
    ("j2", "max_jerk", 41.0, "dddq_max = 40"),
    ("j1", "max_torque", 300.0, "tau_max = 250"),
]


@pytest.mark.parametrize(("joint", "key", "value", "theirs"), CASES)
def test_campaign_limits_beyond_the_robot_file_are_refused(joint, key, value, theirs):
    raw = arm3_raw()
    raw["robot"]["joints"][joint]["limits"][key] = value
    c = RobotCampaign.from_dict(raw, "wide.toml")  # the campaign alone is consistent
    with pytest.raises(TrajectoryError) as exc:
        robot_for_campaign(c)
    msg = str(exc.value)
    assert msg.startswith(f"wide.toml: robot.joints.{joint}.limits.{key}: expected ")
    assert theirs in msg and "arm3.toml" in msg and "\n" not in msg


def test_limits_within_the_robot_file_load():
    raw = arm3_raw()
    raw["robot"]["joints"]["j1"]["limits"]["max_velocity"] = 1.0  # tighter: fine
    raw["robot"]["joints"]["j2"]["limits"]["position"] = [-2.0, -0.5]
    robot = robot_for_campaign(RobotCampaign.from_dict(raw, "tight.toml"))
    assert list(robot.moving) == ["j1", "j2", "j3"]
