"""Excitation planning with Ruckig: pure functions and immutable sampled plans.

Nothing in this package touches clocks or buses; files only in :mod:`trajectories.campaign_file`
(reads the campaign TOML), :mod:`trajectories.robot.formats` (reads robot files) and
:mod:`trajectories.cli` (``jointid plan``, writes the plot).
Campaigns: ``campaign`` (the ``[joint]`` schema), ``robot_campaign`` (the ``[robot]`` schema;
a ``[joint]`` campaign read as a robot with one moving joint). One planner for both: ``multi``
(Ruckig trapezoids, exact sines, multi-sines, moves) and one plan type, ``sampled``
(``RobotPlan``, its one-joint 1-D ``Reference``, the summary); ``plan`` keeps the single-joint
names (``plan_campaign``, ``plan_segment``). ``excitation`` (regressor condition number,
band and quadrant shares, multi-sine optimisation). The robot model, the ground floor below
every other module (docs/architecture.md): ``robot`` (robot files behind a suffix table ->
``Robot``, the n-dof regressor, the base-parameter rule, payloads; docs/robot-format.md).
Exception tree: every error raised on purpose derives from :class:`TrajectoryError`.
"""


class TrajectoryError(Exception):
    """Root of every error raised on purpose by :mod:`trajectories`."""


class SchemaError(TrajectoryError, ValueError):
    """A configuration mapping does not match its schema; the message names the key."""


class CampaignFileError(TrajectoryError, ValueError):
    """A campaign file is not readable TOML (not UTF-8, syntax error); the message names the
    file, line and column."""


class LimitError(TrajectoryError):
    """A plan would exceed a joint limit; the message names the segment and the limit."""


class RobotError(TrajectoryError, ValueError):
    """A robot file, description or robot-model input is unusable (:mod:`trajectories.robot`);
    the message names the file, object or element."""
