"""The robot model, jointid's ground floor: what planning (:mod:`trajectories`), simulation
(:mod:`sim_drivers`) and identification (:mod:`ident`) share about a serial robot.

- :mod:`.description`: :class:`Robot` (pinocchio model of the full chain, moving and locked
  joints, drives, limits), :class:`JointDrive`, :class:`RobotLimits`, :class:`MDHJoint`,
  :func:`one_joint_robot` (a single joint as a 1-dof robot, built in memory);
- :mod:`.formats`: robot files behind a suffix table (:data:`FORMATS`, :func:`load_robot`:
  MDH TOML, URDF, MJCF; a new format is one module and one row, docs/robot-format.md);
- :mod:`.regressor`: the one n-dof regressor (:class:`RobotRegressor`, vectorised Newton-Euler,
  paper eq. 9, usual friction columns, payload columns);
- :mod:`.base`: the one base-parameter rule (:func:`base_parameters`, QR in the standard
  order, one rank tolerance ``DEFAULT_RTOL``) and a payload's base (:func:`payload_base`);
- :mod:`.payload`: :class:`RobotPayloadData`, a payload fixed at the flange.

Imports nothing of ours but the :mod:`trajectories` exception tree (contract ``robot-floor``
in pyproject.toml); reads files only in :mod:`.formats`. Every error is a :class:`RobotError`.
"""

from .. import RobotError
from .base import (
    DEFAULT_RTOL,
    PAYLOAD_NAMES,
    BaseParameters,
    PayloadBase,
    base_parameters,
    independent_columns,
    payload_base,
    qr_rule,
    random_states,
)
from .description import (
    STANDARD_GRAVITY,
    JointDrive,
    MDHJoint,
    Robot,
    RobotLimits,
    mdh_placement,
    one_joint_robot,
)
from .formats import FORMATS, load_robot
from .formats.mdh_toml import robot_from_dict
from .formats.urdf import EXAMPLE_ROBOTS, example_robot_names, example_robot_urdf
from .payload import RobotPayloadData
from .regressor import FRICTION_NAMES, LINK_NAMES, RobotRegressor, from_pinocchio_order

__all__ = [
    "RobotError",
    "JointDrive",
    "RobotLimits",
    "MDHJoint",
    "Robot",
    "mdh_placement",
    "one_joint_robot",
    "STANDARD_GRAVITY",
    "FORMATS",
    "load_robot",
    "robot_from_dict",
    "EXAMPLE_ROBOTS",
    "example_robot_names",
    "example_robot_urdf",
    "RobotPayloadData",
    "RobotRegressor",
    "LINK_NAMES",
    "FRICTION_NAMES",
    "from_pinocchio_order",
    "BaseParameters",
    "base_parameters",
    "qr_rule",
    "independent_columns",
    "random_states",
    "DEFAULT_RTOL",
    "PayloadBase",
    "payload_base",
    "PAYLOAD_NAMES",
]
