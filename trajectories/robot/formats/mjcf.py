"""MuJoCo MJCF robot files (``*.xml``, ``*.mjcf``) through pinocchio's MJCF parser: every joint
moves, no drive data (as a URDF). A row of :data:`trajectories.robot.formats.FORMATS`."""

from __future__ import annotations

from pathlib import Path

import pinocchio as pin

from .. import RobotError
from ..description import Robot

__all__ = ["read"]


def read(path: Path) -> Robot:
    """A robot from an MJCF file (a chain of 1-dof revolute or prismatic joints)."""
    src = str(path)
    if not path.is_file():
        raise RobotError(f"{src}: cannot read the robot file (no such file)")
    try:
        model = pin.buildModelFromMJCF(src)
    except (RuntimeError, ValueError, OSError) as e:
        msg = next((ln.strip() for ln in str(e).splitlines() if ln.strip()), type(e).__name__)
        raise RobotError(f"{src}: MJCF does not parse ({msg})") from None
    return Robot.from_pinocchio(model, name=model.name or path.stem, source=src)
