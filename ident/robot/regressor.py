"""The n-dof regressor is the robot model's (:mod:`trajectories.robot.regressor`); re-exported
for the callers that import it from here."""

from trajectories.robot.regressor import (  # noqa: F401 (re-exported)
    FRICTION_NAMES,
    LINK_NAMES,
    PIN_ORDER,
    RobotRegressor,
    from_pinocchio_order,
)
