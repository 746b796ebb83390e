"""An external force on the simulated arm: a push on a link for a given time.

A :class:`Push` is a force ``force`` [N] (world axes) applied at a point ``point`` [m] of the
link carried by moving joint ``joint`` (0-based index in the chain of moving joints; the
point in that joint's frame) from the arm's simulated time ``t0_s`` [s] for ``duration_s``
[s]. Its joint torques are ``J_p(q)^T F`` with ``J_p`` the linear Jacobian of the point
(pinocchio, world-aligned axes): :func:`push_torque`. :class:`~sim_drivers.arm_plant.ArmPlant`
adds them to the rigid-body dynamics (``ddq = ABA(q, dq, tau_out + tau_ext)``), not to the
drives' torques: the drives' ``torque actual`` does not see the push, only its effect on the
motion, as with a collision on a real arm. The torques are evaluated at the start of each
control cycle and held over it.

:func:`staged_push` builds the push a monitor test stages: by default at the link's centre
of mass moved 0.1 m along the x axis of the joint frame (a point on the link's surface, off
the joint axis), in the direction the point moves when joint ``joint`` turns (a tangential
hit, the largest torque on the link's own joint); if that joint does not move the point, the
direction of the largest joint-torque norm. The offset is the part of the frame's x axis
perpendicular to the joint axis, the y axis's for a joint turning about (nearly) x
(:func:`offset_direction`): it moves the point off the joint axis whatever axis convention
the robot file uses (an offset along x would put it on an x axis: no torque on that joint).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from sim_drivers import SimError

__all__ = ["Push", "push_torque", "staged_push", "offset_direction", "DEFAULT_OFFSET_M"]

#: Default offset of the push point from the link's CoM along the joint frame's x axis [m].
DEFAULT_OFFSET_M = 0.1


@dataclass(frozen=True)
class Push:
    """A force on a link of the simulated arm over a time window (module docstring).

    Attributes
    ----------
    joint : int
        Moving joint whose child link is pushed (0-based).
    force : tuple of 3 floats
        Force [N], world axes.
    point : tuple of 3 floats
        Application point [m] in the frame of ``joint``.
    t0_s, duration_s : float
        Start [s] (the arm's simulated time) and duration [s].
    """

    joint: int
    force: tuple[float, float, float]
    point: tuple[float, float, float]
    t0_s: float
    duration_s: float

    def active(self, t: float) -> bool:
        """Whether the push acts at the arm's time ``t`` [s] (``t0 <= t < t0 + duration``)."""
        return self.t0_s <= t < self.t0_s + self.duration_s


def _point_jacobian(model: pin.Model, data: pin.Data, q: np.ndarray, joint: int,
                    point: np.ndarray) -> np.ndarray:
    """Linear Jacobian (3, k) of ``point`` (in joint ``joint``'s frame), world axes."""
    jid = joint + 1
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    jac = np.asarray(pin.getJointJacobian(model, data, jid,
                                          pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
                     ).reshape(6, model.nv)  # (6,) for a 1-dof model
    r = data.oMi[jid].rotation @ point  # joint origin -> point, world axes
    # v_p = v_o + w x r = J_lin dq - [r]x J_ang dq
    return jac[:3] - pin.skew(r) @ jac[3:]


def offset_direction(model: pin.Model, joint: int) -> np.ndarray:
    """Unit vector (joint frame) along which the default push point is moved from the link's
    centre of mass: the frame's x axis, or its y axis when x is within about 25 degrees of
    the joint's rotation axis, made perpendicular to that axis (x for a joint that does not
    rotate, e.g. prismatic)."""
    data = model.createData()
    q = pin.neutral(model)
    pin.computeJointJacobians(model, data, q)
    jid = joint + 1
    jac = np.asarray(pin.getJointJacobian(model, data, jid, pin.ReferenceFrame.LOCAL)
                     ).reshape(6, model.nv)  # (6,) for a 1-dof model
    w = jac[3:, model.joints[jid].idx_v]  # the rotation axis in the joint's own frame
    n = float(np.linalg.norm(w))
    ex, ey = np.eye(3)[0], np.eye(3)[1]
    if n < 1e-9:
        return ex
    a = w / n
    d = ex if abs(float(ex @ a)) < 0.9 else ey
    d = d - float(d @ a) * a
    return d / float(np.linalg.norm(d))


def push_torque(model: pin.Model, data: pin.Data, q: Any, push: Push) -> np.ndarray:
    """Joint torques [N m] of ``push`` at configuration ``q`` [rad]: ``J_p(q)^T F``."""
    q = np.asarray(q, dtype=float)
    jac = _point_jacobian(model, data, q, push.joint, np.asarray(push.point, dtype=float))
    return jac.T @ np.asarray(push.force, dtype=float)


def staged_push(model: pin.Model, q: Any, joint: int, force_N: float, t0_s: float,
                duration_s: float, *, point: Any = None, direction: Any = None) -> Push:
    """A push of ``force_N`` [N] on the link of moving joint ``joint`` (module docstring for
    the default point and direction), at configuration ``q`` [rad].

    Raises
    ------
    SimError
        A joint index out of range, a force or duration not > 0, a zero direction.
    """
    k = model.njoints - 1
    if not 0 <= joint < k:
        raise SimError(f"push: joint index {joint}: expected 0..{k - 1}")
    if not force_N > 0 or not duration_s > 0:
        raise SimError(f"push: force {force_N} N and duration {duration_s} s: expected > 0")
    data = model.createData()
    if point is None:
        p = (np.array(model.inertias[joint + 1].lever, dtype=float)
             + DEFAULT_OFFSET_M * offset_direction(model, joint))
    else:
        p = np.asarray(point, dtype=float).reshape(3)
    if direction is None:
        jac = _point_jacobian(model, data, np.asarray(q, dtype=float), joint, p)
        d = jac[:, joint]
        if np.linalg.norm(d) < 1e-6:
            u, _, _ = np.linalg.svd(jac)
            d = u[:, 0]
    else:
        d = np.asarray(direction, dtype=float).reshape(3)
    n = float(np.linalg.norm(d))
    if not n > 0:
        raise SimError("push: direction: expected a non-zero vector")
    f = d / n * float(force_N)
    return Push(int(joint), (float(f[0]), float(f[1]), float(f[2])),
                (float(p[0]), float(p[1]), float(p[2])), float(t0_s), float(duration_s))
