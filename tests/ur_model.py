"""UR10 test robots from example-robot-data (pinocchio): 6-dof and 3-dof (wrist locked).

Builds the regressor and inverse-dynamics callables that trajectories.excitation takes, the
way ident will provide them (joint-side torques, standard inertial parameters; no friction).
"""

from __future__ import annotations

import importlib.metadata
import math
from dataclasses import dataclass
from functools import cache

import numpy as np
import pytest

from trajectories.campaign import JointLimits

pin = pytest.importorskip("pinocchio")


def ur10_urdf() -> str:
    """Path of the packaged UR10 URDF, found through the distribution's file list."""
    dist = importlib.metadata.distribution("example-robot-data")
    for f in dist.files or ():
        if str(f).endswith("ur_description/urdf/ur10_robot.urdf"):
            return str(dist.locate_file(f))
    pytest.skip("example-robot-data has no ur10_robot.urdf")
    raise AssertionError  # unreachable


@dataclass(frozen=True)
class TestRobot:
    model: object
    names: tuple[str, ...]
    limits: tuple[JointLimits, ...]
    start: tuple[float, ...]

    def regressor(self, q, dq, ddq) -> np.ndarray:
        """(n, k) x 3 -> (n * k, 10 * k), rows sample-major."""
        data = self.model.createData()
        n, k = q.shape
        out = np.empty((n * k, 10 * k))
        for i in range(n):
            out[i * k:(i + 1) * k] = pin.computeJointTorqueRegressor(
                self.model, data, q[i], dq[i], ddq[i])
        return out

    def inverse_dynamics(self, q, dq, ddq) -> np.ndarray:
        data = self.model.createData()
        return np.array([pin.rnea(self.model, data, q[i], dq[i], ddq[i])
                         for i in range(q.shape[0])])

    def inverse_dynamics_payload(self, q, dq, ddq, payload) -> np.ndarray:
        """With a payload at the last link (mass, CoM in its frame, inertia at the CoM)."""
        model = self.model.copy()
        xx, xy, xz, yy, yz, zz = payload.inertia
        inertia = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
        extra = pin.Inertia(payload.mass_kg, np.array(payload.com), inertia)
        model.inertias[model.njoints - 1] = model.inertias[model.njoints - 1] + extra
        data = model.createData()
        return np.array([pin.rnea(model, data, q[i], dq[i], ddq[i])
                         for i in range(q.shape[0])])


# limits typical of a UR10 (joint side): position, velocity, acceleration, jerk, torque
_LIMITS6 = (
    JointLimits((-math.pi, math.pi), 2.0, 6.0, 60.0, 330.0),
    JointLimits((-2.6, -0.5), 2.0, 6.0, 60.0, 330.0),
    JointLimits((-2.6, 2.6), 3.0, 8.0, 80.0, 150.0),
    JointLimits((-math.pi, math.pi), 3.0, 10.0, 100.0, 54.0),
    JointLimits((-math.pi, math.pi), 3.0, 10.0, 100.0, 54.0),
    JointLimits((-math.pi, math.pi), 3.0, 10.0, 100.0, 54.0),
)
_START6 = (0.0, -1.55, 1.2, -1.2, -1.57, 0.0)


@cache
def ur10(dof: int = 6) -> TestRobot:
    """UR10 with all 6 joints (dof=6) or shoulder pan, shoulder lift, elbow (dof=3)."""
    full = pin.buildModelFromUrdf(ur10_urdf())
    names = tuple(full.names[1:])
    if dof == 6:
        return TestRobot(full, names, _LIMITS6, _START6)
    q_lock = pin.neutral(full)
    q_lock[3:] = _START6[3:]
    model = pin.buildReducedModel(full, [4, 5, 6], q_lock)
    return TestRobot(model, names[:3], _LIMITS6[:3], _START6[:3])
