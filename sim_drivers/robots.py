"""Packaged test robots: find the URDFs of ``example-robot-data`` and build pinocchio models.

The URDFs are located by :func:`trajectories.robot.example_robot_urdf` (through the installed
distribution's file list, never a hard-coded path); the robot files themselves are read by
:func:`trajectories.robot.load_robot`. These helpers only serve the simulator's tests,
benchmarks and demos.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin

from trajectories.robot import EXAMPLE_ROBOTS, RobotError
from trajectories.robot import example_robot_urdf as _locate

from . import SimError

#: Robot name -> path of its URDF inside the example-robot-data share folder (the locator
#: lives with the robot description, :mod:`trajectories.robot`).
URDFS: dict[str, str] = EXAMPLE_ROBOTS


def example_robot_urdf(name: str) -> Path:
    """Path of the URDF of a robot packaged by ``example-robot-data``
    (:func:`trajectories.robot.example_robot_urdf`, errors as :class:`SimError`).

    Parameters
    ----------
    name : str
        A key of :data:`URDFS` (e.g. ``"ur10"``).

    Returns
    -------
    Path
        Existing URDF file.

    Raises
    ------
    SimError
        Unknown name, or the package (or the file) is not installed.
    """
    try:
        return _locate(name)
    except RobotError as e:
        raise SimError(str(e)) from None


def example_robot_model(
    name: str = "ur10",
    *,
    locked: dict[str, float] | None = None,
) -> pin.Model:
    """Pinocchio model (joint-side SI) of a packaged robot, with some joints locked.

    Parameters
    ----------
    name : str
        Robot name (see :data:`URDFS`).
    locked : dict, optional
        Joint name -> locked position [rad or m]; these joints are removed with
        ``pin.buildReducedModel`` (the others keep their order, base to tip).

    Returns
    -------
    pinocchio.Model
        Model of the moving joints.

    Raises
    ------
    SimError
        Unknown robot or joint name.
    """
    model = pin.buildModelFromUrdf(str(example_robot_urdf(name)))
    if not locked:
        return model
    q_ref = pin.neutral(model)
    ids = []
    for jname, value in locked.items():
        if not model.existJointName(jname):
            names = list(model.names)[1:]
            raise SimError(f"example robot {name!r}: locked joint {jname!r} not in {names}")
        jid = model.getJointId(jname)
        if model.joints[jid].nq != 1:
            raise SimError(f"example robot {name!r}: joint {jname!r} has nq != 1")
        q_ref[model.joints[jid].idx_q] = float(value)
        ids.append(jid)
    return pin.buildReducedModel(model, sorted(ids), q_ref)


def ur10(k: int = 6) -> pin.Model:
    """UR10 with its first ``k`` joints moving (k = 6: all; k = 3: the wrist joints locked at
    wrist_1 = -pi/2, wrist_2 = 0, wrist_3 = 0; k = 1: only the shoulder lift moves, the elbow and
    wrist locked, a heavy pendulum about a horizontal axis)."""
    wrist = {"wrist_1_joint": -np.pi / 2, "wrist_2_joint": 0.0, "wrist_3_joint": 0.0}
    if k == 6:
        return example_robot_model("ur10")
    if k == 3:
        return example_robot_model("ur10", locked=wrist)
    if k == 1:
        return example_robot_model("ur10", locked={"shoulder_pan_joint": 0.0,
                                                   "elbow_joint": 0.0, **wrist})
    raise SimError(f"ur10: expected k in (1, 3, 6) moving joints, got {k!r}")
