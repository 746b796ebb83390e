"""Identification of n-dof serial robots (paper eq. 1-17 and 30 applied to every joint).

Modules: :mod:`~ident.robot.signals` (multi-axis signals, the data every estimator takes).
The rigid-body regressor, base parameters, estimators (usual and paper friction on every
joint), tables and loaders join this package as they land (docs/architecture.md).
"""

from .. import IdentError


class RobotIdentError(IdentError, ValueError):
    """A robot identification input is unusable; the message names the object and element."""
