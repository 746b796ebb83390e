"""Excitation planning with Ruckig: pure functions and immutable sampled plans.

Nothing in this package touches files, clocks or buses. Single joint: ``campaign`` (schema),
``plan`` (Ruckig plans). Robots: ``robot_campaign`` (``[robot]`` schema), ``multi`` (multi-DoF
plans), ``excitation`` (regressor condition number, band and quadrant shares, multi-sine
optimisation).
Exception tree: every error raised on purpose derives from :class:`TrajectoryError`.
"""


class TrajectoryError(Exception):
    """Root of every error raised on purpose by :mod:`trajectories`."""


class SchemaError(TrajectoryError, ValueError):
    """A configuration mapping does not match its schema; the message names the key."""


class LimitError(TrajectoryError):
    """A plan would exceed a joint limit; the message names the segment and the limit."""
