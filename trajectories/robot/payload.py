"""A payload fixed at the flange (eq. 32-35 generalised): the data the regressor's payload
columns (:meth:`trajectories.robot.regressor.RobotRegressor.payload_torque`,
``payload_parameters``, ``flange_parameters``) and the payload base
(:func:`trajectories.robot.base.payload_base`) take."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .. import RobotError

__all__ = ["RobotPayloadData"]


@dataclass(frozen=True)
class RobotPayloadData:
    """Payload fixed at the flange for one experiment (eq. 34-35 generalised).

    Attributes
    ----------
    mass : float
        [kg]
    com : ndarray, shape (3,)
        Centre of mass in the flange frame [m].
    inertia : ndarray, shape (6,)
        XX, XY, XZ, YY, YZ, ZZ about the centre of mass, flange axes [kg m^2].
    arm_m : float or None
        Lever arm L_a [m] of a single-joint log (eq. 34-35: a point mass at L_a along the
        single-joint model's arm, ``J += M_a L_a^2``, ``MX += M_a L_a``) when the CoM is not
        known in the flange frame; :func:`ident.robot.base.lever_arm_payload` places it on a
        one-joint robot (``com`` and ``inertia`` zero). None: ``com`` places the payload.
    """

    mass: float = 0.0
    com: np.ndarray = field(default_factory=lambda: np.zeros(3))
    inertia: np.ndarray = field(default_factory=lambda: np.zeros(6))
    arm_m: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "mass", float(self.mass))
        object.__setattr__(self, "com", np.asarray(self.com, dtype=float).reshape(3))
        object.__setattr__(self, "inertia", np.asarray(self.inertia, dtype=float).reshape(6))
        if self.mass < 0:
            raise RobotError(f"payload.mass: expected >= 0 [kg], got {self.mass}")
        if self.arm_m is not None:
            object.__setattr__(self, "arm_m", float(self.arm_m))
            if not np.isfinite(self.arm_m) or np.any(self.com) or np.any(self.inertia):
                raise RobotError(f"payload.arm_m: expected a finite lever arm [m] and "
                                 f"no com/inertia, got arm_m={self.arm_m}")
