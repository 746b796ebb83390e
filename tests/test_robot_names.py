"""Issue 22 item 7: every robot of example-robot-data by name (``example-robot-data:<name>``),
not only the three UR arms of EXAMPLE_ROBOTS; unknown and ambiguous names are one-line
errors naming the choices."""

from __future__ import annotations

import pytest

from trajectories.robot import (
    EXAMPLE_ROBOTS,
    RobotError,
    example_robot_names,
    example_robot_urdf,
    load_robot,
)


def test_panda_and_ur10_by_name():
    panda = load_robot("example-robot-data:panda")
    assert panda.moving[:7] == tuple(f"panda_joint{i}" for i in range(1, 8))
    assert len(panda.moving) == 9  # two finger joints (prismatic)
    ur10 = load_robot("example-robot-data:ur10")
    assert len(ur10.moving) == 6
    assert example_robot_urdf("ur10").name == "ur10_robot.urdf"  # EXAMPLE_ROBOTS first
    names = example_robot_names()
    assert {"panda", "xarm7"} <= set(names) and set(EXAMPLE_ROBOTS) <= set(names)


def test_path_form_and_errors():
    p = example_robot_urdf("robots/panda_description/urdf/panda.urdf")
    assert p == example_robot_urdf("panda")
    with pytest.raises(RobotError, match="expected one of") as e:
        load_robot("example-robot-data:no_such_robot")
    assert "panda" in str(e.value) and "\n" not in str(e.value)
    with pytest.raises(RobotError, match="several packaged URDFs"):
        example_robot_urdf("anymal")  # anymal_b and anymal_c both ship anymal.urdf
