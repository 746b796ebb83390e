"""The exported URDF of a robot with a prismatic joint and no position limits loads in
pinocchio (found by the identification sweep: the EMPS axis as a one-joint robot file was
exported with ``lower="-inf" upper="inf"``, which urdfdom refuses) and gives the reduced
model's inverse dynamics."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin

from ident.robot.export_model import urdf_text
from ident.robot.regressor import RobotRegressor
from trajectories.robot import load_robot

#: A vertical prismatic axis without limits carrying a revolute one, inertial parameters
#: given.
ROBOT = """
[robot]
name = "lift"
[[joints]]
name = "z1"
type = "prismatic"
mass = 6.0
com = [0.1, 0.0, 0.0]
inertia = [0.05, 0.0, 0.0, 0.12, 0.0, 0.12]
[[joints]]
name = "j2"
type = "revolute"
alpha = -1.5707963267948966
d = 0.3
mass = 4.0
com = [0.2, 0.0, 0.0]
inertia = [0.01, 0.0, 0.0, 0.2, 0.0, 0.2]
limits = { q_min = -2.0, q_max = 2.0 }
"""


def test_unbounded_prismatic_joint_exports_a_loadable_urdf(tmp_path: Path) -> None:
    path = tmp_path / "lift.toml"
    path.write_text(ROBOT)
    robot = load_robot(path)
    reg = RobotRegressor(robot)
    std = dict(zip(reg.standard_names, reg.standard_values(), strict=True))
    ref = robot.reduced()
    assert not np.isfinite(ref.upperPositionLimit[0])  # the case: no limits in the file
    urdf = tmp_path / "lift.urdf"
    urdf.write_text(urdf_text(ref, std, robot.numbers, "lift"))
    got = pin.buildModelFromUrdf(str(urdf))  # raised ValueError with "-inf"
    assert [got.names[i] for i in (1, 2)] == ["z1", "j2"]
    assert got.lowerPositionLimit[0] == -1e9 and got.upperPositionLimit[0] == 1e9
    got.gravity = ref.gravity
    dg, dr = got.createData(), ref.createData()
    rng = np.random.default_rng(1)
    for _ in range(10):
        q, v, a = rng.normal(size=(3, 2))
        np.testing.assert_allclose(pin.rnea(got, dg, q, v, a), pin.rnea(ref, dr, q, v, a),
                                   rtol=1e-12, atol=1e-9)
