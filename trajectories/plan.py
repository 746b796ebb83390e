"""Single-joint names of the one planner: a ``[joint]`` campaign is a robot with one moving joint.

There is one plan path (:func:`trajectories.multi.plan_robot_campaign`) and one plan type
(:class:`~trajectories.sampled.RobotPlan`); this module keeps the names single-joint callers
use:

- :func:`plan_campaign` plans a campaign of one moving joint (a ``[joint]`` file's
  :class:`~trajectories.robot_campaign.RobotCampaign`) through it; the result's
  ``.reference`` is the joint's 1-D :class:`~trajectories.sampled.Reference`;
- :func:`plan_segment` plans one segment of a joint alone (tests, diagnostics).

The plans are those of the former single-joint planner sample for sample (regression test:
``tests/test_plan_single_joint.py``). Pure: no files, clocks or buses.
"""

from __future__ import annotations

from .campaign import Joint, Segment
from .multi import G, plan_robot, plan_robot_campaign
from .robot_campaign import JOINT_NAME, RobotCampaign
from .sampled import (
    BANDS,
    MOVING_FRACTION,
    POSITIONING_SPEED,
    Piece,
    Reference,
    RobotPlan,
    RobotPlanSummary,
)

__all__ = [
    "BANDS",
    "CampaignPlan",
    "G",
    "MOVING_FRACTION",
    "POSITIONING_SPEED",
    "Piece",
    "PlanSummary",
    "Reference",
    "plan_campaign",
    "plan_segment",
]

#: the plan of a ``[joint]`` campaign is the one plan type
CampaignPlan = RobotPlan
PlanSummary = RobotPlanSummary


def plan_campaign(campaign: RobotCampaign) -> RobotPlan:
    """Plan a campaign of one moving joint (a ``[joint]`` file) as the robot it is.

    Parameters
    ----------
    campaign : RobotCampaign

    Returns
    -------
    RobotPlan
        One joint; ``.reference`` sampled every ``campaign.cycle_s`` from t = 0, at rest at
        ``campaign.start`` at both ends; run once per payload.

    Raises
    ------
    trajectories.LimitError
        Any segment would exceed a position, velocity, acceleration or jerk limit, or the
        feed-forward torque estimate of a payload run exceeds ``max_torque``; the message
        names the segment (and payload) and the limit (``joint.limits.<key>``).
    """
    return plan_robot_campaign(campaign)


def plan_segment(
    segment: Segment,
    joint: Joint,
    cycle_s: float,
    *,
    start: float | None = None,
    index: int = 0,
    return_to_start: bool = False,
) -> Reference:
    """Plan and sample one segment of a joint alone, from rest at ``start``.

    Parameters
    ----------
    segment : TrapezoidSweep or SineSegment
        Of the one joint (``joint`` ``""``).
    joint : Joint
        Kind and limits; ``joint.start`` is the default start position.
    cycle_s : float
        Sampling period [s].
    start : float, optional
        Rest position [rad] where the segment starts (default ``joint.start``).
    index : int
        Segment index used in names and messages (``segments[index]``).
    return_to_start : bool
        Append a move back to ``start`` (as :func:`plan_campaign` does after the last
        segment).

    Returns
    -------
    Reference
        Starts and ends at rest; ``segment_names`` has ``index + 1`` entries (earlier
        indices unused) plus ``"return"``.

    Raises
    ------
    trajectories.LimitError
        The segment would exceed a joint limit.
    """
    s0 = joint.start if start is None else float(start)
    plan = plan_robot([segment], (JOINT_NAME,), (joint.limits,), (s0,), cycle_s,
                      units=(joint.unit,), keys=("joint",), first_index=index,
                      return_to_start=return_to_start)
    return plan.reference
