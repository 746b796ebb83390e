"""The robot of a robot campaign as the callables :mod:`trajectories.excitation` takes.

``jointid plan`` and ``jointid run`` predict the excitation quality, check torques and optimise
multi-sines before anything moves; they need the robot model's regressor and inverse dynamics.
The regressor is the robot model's one n-dof regressor
(:class:`trajectories.robot.regressor.RobotRegressor`, vectorised, the one identification
fits with), so the planner predicts the condition number of the fit's base columns:

    tau = W_rigid(q, dq, ddq) chi_St + Ia ddq + FC sign(dq) + FV dq + OFF   (paper eq. 9, 5-6)

Columns per moving joint j (chain number j, ROBOT_FORMAT names): the 10 standard parameters
of link j (``XX{j} ... M{j}``), ``Ia{j}``, then ``FC{j} FV{j} OFF{j}`` (the usual friction
model; ``friction=False`` leaves them out). ``sign(dq)`` is 0 below ``MOVING_FRACTION`` of the
joint's max velocity (``deadband``), so that samples at rest -- exactly 0 in a plan, encoder
noise in a log -- enter the Coulomb column alike.

Also :func:`robot_for_campaign` (the campaign's robot file, with its moving and locked
joints) and :func:`prepare_robot_campaign` (optimise the ``optimise = true`` multi-sines
deterministically: ``jointid plan`` and ``jointid run`` play the same plan).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from .excitation import OptimisedMultisine, optimise_campaign
from .multi import MOVING_FRACTION, G
from .robot import (
    Robot,
    RobotError,
    RobotLimits,
    RobotPayloadData,
    RobotRegressor,
    load_robot,
    one_joint_robot,
)
from .robot_campaign import MultisineSegment, RobotCampaign

__all__ = ["RobotDynamics", "check_limits_within_robot", "joint_robot",
           "prepare_robot_campaign", "robot_for_campaign", "robot_file_path",
           "OPTIMISE_EVALUATIONS"]

#: objective evaluations of the multi-sine optimisation in ``jointid plan`` / ``jointid run``
#: (deterministic for a given seed: both play the same coefficients)
OPTIMISE_EVALUATIONS = 600


def robot_file_path(campaign: RobotCampaign) -> str:
    """The campaign's ``robot.file`` resolved against the campaign file's folder (kept as is
    for ``example-robot-data:<name>`` and absolute paths)."""
    f = campaign.robot_file
    if f.startswith("example-robot-data:") or Path(f).is_absolute() or not campaign.source:
        return f
    return str(Path(campaign.source).parent / f)


def robot_for_campaign(campaign: RobotCampaign) -> Robot:
    """Load the campaign's robot file with the campaign's moving and locked joints.

    A ``[joint]`` campaign read as a robot (``robot_file == ""``) has no robot file: its
    robot is built in memory (:func:`joint_robot`).

    Raises
    ------
    trajectories.RobotError
        Unreadable robot file, or a campaign joint the robot file does not have (one line
        naming the campaign, the key and the robot file).
    """
    if campaign.plant == "joint":
        return joint_robot(campaign)
    path = robot_file_path(campaign)
    robot = load_robot(path)
    for i, n in enumerate(campaign.moving):
        if n not in robot.joint_names:
            raise RobotError(f"{campaign.source}: robot.moving[{i}]: expected a joint of "
                             f"{path} ({', '.join(robot.joint_names)}), got {n!r}")
    check_limits_within_robot(campaign, robot, path)
    locked = {n: float(robot.locked.get(n, 0.0)) for n in robot.joint_names
              if n not in campaign.moving}
    locked.update({n: float(v) for n, v in campaign.locked.items()})
    try:
        return robot.with_motion(campaign.moving, locked)
    except RobotError as exc:
        raise RobotError(f"{campaign.source}: robot.locked: {exc}") from None


#: campaign limit key -> the robot file's limit (``RobotLimits`` attribute, file key)
_LIMIT_PAIRS = (("max_velocity", "dq_max"), ("max_acceleration", "ddq_max"),
                ("max_jerk", "dddq_max"), ("max_torque", "tau_max"))


def check_limits_within_robot(campaign: RobotCampaign, robot: Robot, path: object) -> None:
    """Refuse a moving joint whose campaign limits go beyond the robot file's own limits.

    The campaign's limits are the ones the plan and the runner's watchdogs use; a robot
    file's limits (``q_min``, ``q_max``, ``dq_max``, ... or the URDF's) describe what the
    joint can take, so a campaign may be tighter, never wider. Limits the robot file does
    not give (infinite) are not checked.

    Raises
    ------
    trajectories.RobotError
        One line naming the campaign, the key, its value and the robot file's limit.
    """
    tol = 1e-9
    for j in campaign.joints:
        lim = robot.limits.get(j.name)
        if lim is None:
            continue
        key = f"{campaign.source}: robot.joints.{j.name}.limits"
        lo, hi = j.limits.position
        if lo < lim.q_min - tol * abs(lim.q_min) or hi > lim.q_max + tol * abs(lim.q_max):
            raise RobotError(f"{key}.position: expected a range within the robot file's "
                             f"[q_min, q_max] = [{lim.q_min:g}, {lim.q_max:g}] ({path}), got "
                             f"[{lo:g}, {hi:g}]")
        for ours, theirs in _LIMIT_PAIRS:
            v, top = float(getattr(j.limits, ours)), float(getattr(lim, theirs))
            if math.isfinite(top) and v > top * (1 + tol):
                raise RobotError(f"{key}.{ours}: expected at most the robot file's {theirs} = "
                                 f"{top:g} ({path}), got {v:g}")


def joint_robot(campaign: RobotCampaign) -> Robot:
    """The robot of a ``[joint]`` campaign, built in memory: one moving joint, no robot file.

    The joint (named as in the campaign, ``"joint"``) turns about (revolute) or slides along
    (prismatic) the z axis of the base frame; gravity is ``(0, -g, 0)``, perpendicular to
    the axis, so the robot model's gravity torque of the revolute joint is
    ``g (MX1 cos q - MY1 sin q)`` -- the ``[control.feedforward]`` model's
    ``g (MX cos q + MY sin q)`` with ``MX1 = MX``, ``MY1 = -MY`` (and ``ZZ1 + Ia1 = J``) --
    and a prismatic joint carries no gravity load, as in that model. The campaign's limits
    are the robot's; it has no inertial parameters (``inertial = False``: the planner's
    torque estimate is the feed-forward model, :func:`trajectories.multi.feedforward_dynamics`).

    Parameters
    ----------
    campaign : RobotCampaign
        With one moving joint and no robot file (a ``[joint]`` file).

    Returns
    -------
    trajectories.robot.Robot
    """
    if len(campaign.joints) != 1:
        raise RobotError(f"{campaign.source or campaign.name}: a robot built from the campaign "
                         f"needs one moving joint, got {len(campaign.joints)} (robot.file)")
    (j,) = campaign.joints
    lim = j.limits
    limits = RobotLimits(lim.position[0], lim.position[1], lim.max_velocity,
                         lim.max_acceleration, lim.max_jerk, lim.max_torque)
    robot = one_joint_robot(j.kind, j.name, limits=limits, gravity=G, source=campaign.source)
    return replace(robot, name=campaign.name)


@dataclass(frozen=True, eq=False)
class RobotDynamics:
    """Regressor and inverse dynamics of the moving joints of a robot (module docstring).

    Parameters
    ----------
    robot : trajectories.robot.Robot
    friction : bool
        Add the usual friction columns ``FC FV OFF`` per joint.

    Attributes
    ----------
    robot_regressor : trajectories.robot.RobotRegressor
        The robot model's regressor of ``robot`` (the one identification uses).
    deadband : ndarray, shape (k,)
        ``MOVING_FRACTION`` of each joint's max velocity [rad/s] (Coulomb column).
    """

    robot: Robot
    friction: bool = True

    def __post_init__(self) -> None:
        reg = RobotRegressor(self.robot)
        object.__setattr__(self, "robot_regressor", reg)
        model = pin.Model(reg.model)
        model.gravity = pin.Motion(np.concatenate([np.asarray(self.robot.gravity, float),
                                                   np.zeros(3)]))
        object.__setattr__(self, "model", model)
        lim = self.robot.limits
        vmax = np.array([lim[n].dq_max if np.isfinite(lim[n].dq_max) else 1.0
                         for n in self.robot.moving])
        object.__setattr__(self, "deadband", MOVING_FRACTION * vmax)
        ia = [self.robot.drives[n].Ia if n in self.robot.drives else None
              for n in self.robot.moving]
        object.__setattr__(self, "Ia", np.array([0.0 if v is None else v for v in ia]))

    @property
    def k(self) -> int:
        return len(self.robot.moving)

    @property
    def names(self) -> tuple[str, ...]:
        """Column names, ROBOT_FORMAT (per joint: link parameters, Ia; then [FC FV OFF] per
        joint): ``RobotRegressor.standard_names`` [+ ``friction_names``]."""
        reg = self.robot_regressor
        return reg.standard_names + (reg.friction_names if self.friction else ())

    def regressor(self, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray) -> np.ndarray:
        """``W`` of shape (n * k, p), rows sample-major (``trajectories.excitation``):
        ``RobotRegressor.rows`` with the Coulomb deadband.

        Parameters
        ----------
        q, dq, ddq : ndarray, shape (n, k)
            Joint-side position [rad], velocity [rad/s], acceleration [rad/s^2].
        """
        return self.robot_regressor.rows(q, dq, ddq, friction=self.friction, deadband=self.deadband)

    def inverse_dynamics(self, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray,
                         payload: Any = None) -> np.ndarray:
        """Rigid-body + rotor torque ``tau_out + Ia ddq`` (n, k) [N m] of the robot file's
        inertial parameters, with a payload (``mass_kg``, ``com`` [m], ``inertia`` about the
        CoM [kg m^2]) fixed in the frame of the last moving joint (the robot model's payload
        torque, ``RobotRegressor.payload_torque``); friction not included."""
        data = self.model.createData()
        q, dq, ddq = (np.ascontiguousarray(x, dtype=float) for x in (q, dq, ddq))
        tau = np.array([pin.rnea(self.model, data, q[i], dq[i], ddq[i])
                        for i in range(len(q))]).reshape(q.shape) + self.Ia * ddq
        if payload is not None and float(payload.mass_kg) > 0:
            tau += self.robot_regressor.payload_torque(q, dq, ddq, RobotPayloadData(
                float(payload.mass_kg), payload.com, payload.inertia))
        return tau


def prepare_robot_campaign(campaign: RobotCampaign, *, robot: Robot | None = None,
                           optimise: bool = True,
                           max_evaluations: int = OPTIMISE_EVALUATIONS
                           ) -> tuple[RobotCampaign, RobotDynamics,
                                      tuple[OptimisedMultisine, ...]]:
    """The campaign to play: its ``optimise = true`` multi-sines optimised for the condition
    number of :class:`RobotDynamics`' regressor (deterministic: same seed and evaluations,
    same coefficients), with the dynamics used.

    Returns
    -------
    (campaign, dynamics, results)
    """
    robot = robot if robot is not None else robot_for_campaign(campaign)
    dyn = RobotDynamics(robot)
    results: tuple[OptimisedMultisine, ...] = ()
    if optimise and any(isinstance(s, MultisineSegment) and s.optimise
                        for s in campaign.segments):
        campaign, results = optimise_campaign(campaign, dyn.regressor,
                                              max_evaluations=max_evaluations)
    return campaign, dyn, results
