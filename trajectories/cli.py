"""``jointid plan CAMPAIGN.toml [--plot FILE.png] [--quick]``: check and summarise a campaign.

Loads and validates the campaign, plans it with Ruckig (rejecting anything beyond the joint
limits before anything moves) and prints the summary: durations, per joint its peaks against
its limits, per velocity band its share of moving time and of its position range, the peak
torques per payload against ``max_torque``, the predicted condition number of the robot
model's regressor over the plan and the shares of each quadrant of (dq, tau) per payload
(:mod:`trajectories.excitation`, :mod:`trajectories.robot_model`). With ``--plot``, draws
one payload run against time: q, dq and ddq of every joint with its limits and the
segments.

One path for both formats: a ``[joint]`` campaign is a robot with one moving joint (its robot
built in memory, its torques the ``[control.feedforward]`` model plus the payload); a
``[robot]`` campaign's multi-sines with ``optimise = true`` are optimised first
(``--no-optimise``: as written), its torques come from the robot file's inertial parameters.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from . import LimitError, TrajectoryError

if TYPE_CHECKING:
    from .sampled import RobotPlan

# the planner's modules (scipy, pinocchio...) are imported by the functions that use them:
# `jointid --help` and `jointid plan --help` must not wait seconds for them

__all__ = ["check_plot_path", "file_named", "plot_plan", "plot_robot_plan", "register", "run"]


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``plan`` subcommand to the ``jointid`` parser."""
    p = subparsers.add_parser(
        "plan",
        help="validate a campaign file, plan it and print its summary",
        description=__doc__.split("\n\n")[1] if __doc__ else None,
    )
    p.add_argument("campaign", type=Path, help="campaign file (TOML)")
    p.add_argument("--plot", type=Path, metavar="FILE.png",
                   help="draw position, velocity and acceleration against time")
    p.add_argument("--quick", action="store_true",
                   help="plan the shortened campaign used by quick runs (RobotCampaign.quick; "
                   "one moving joint, trapezoids and sines)")
    p.add_argument("--no-optimise", action="store_true",
                   help="robot campaigns: play the multi-sines as written even where "
                   "optimise = true")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Execute ``jointid plan``; returns the exit code. A limit the plan exceeds is named
    with the campaign file, as every other mistake (:func:`file_named`)."""
    from .campaign_file import load_campaign

    if args.plot is not None:  # before the planning: a wrong name fails at once
        check_plot_path(args.plot)
    # one path: a [joint] campaign is a robot with one moving joint
    rc = load_campaign(args.campaign)
    with file_named(rc.source):
        return _plan(args, rc)


def check_plot_path(path: Path) -> None:
    """Refuse a ``--plot`` file matplotlib cannot write, before anything is planned.

    Parameters
    ----------
    path : Path
        The image file to write.

    Raises
    ------
    TrajectoryError
        Its extension is no image format matplotlib writes (``.txt``...), it names a
        folder, or its folder does not exist; the message names the file.
    """
    from matplotlib.backend_bases import FigureCanvasBase

    formats = FigureCanvasBase.get_supported_filetypes()
    ext = path.suffix.lower().lstrip(".")
    if ext not in formats:
        raise TrajectoryError(f"--plot {path}: expected an image file name ending in "
                              f"{', '.join('.' + f for f in sorted(formats))}, got "
                              f"{repr('.' + ext) if ext else 'no extension'}")
    if path.is_dir():
        raise TrajectoryError(f"--plot {path}: is a folder, expected an image file name")
    if not path.parent.is_dir():
        raise TrajectoryError(f"--plot {path}: folder {path.parent} does not exist")


@contextmanager
def file_named(source: str) -> Iterator[None]:
    """Re-raise a :class:`~trajectories.LimitError` (whose message names the segment, joint
    and limit but not the file) as ``"<source>: <message>"``."""
    try:
        yield
    except LimitError as exc:
        msg = str(exc)
        if source and not msg.startswith(f"{source}: "):
            raise LimitError(f"{source}: {msg}") from None
        raise


def _plan(args: argparse.Namespace, rc: Any) -> int:
    """``jointid plan`` on the loaded campaign ``rc``."""
    from .excitation import assess_robot_campaign
    from .multi import feedforward_dynamics
    from .robot_model import OPTIMISE_EVALUATIONS, prepare_robot_campaign, robot_for_campaign

    if args.quick:
        rc = rc.quick()
    robot = robot_for_campaign(rc)
    played, dyn, results = prepare_robot_campaign(rc, robot=robot,
                                                  optimise=not args.no_optimise)
    # a [joint] campaign's torques: its feed-forward model (its robot has no inertias),
    # without the friction for the quadrants of (dq, tau_out)
    if rc.plant == "joint":
        a = assess_robot_campaign(played, regressor=dyn.regressor,
                                  inverse_dynamics=feedforward_dynamics(rc.joints),
                                  tau_out=feedforward_dynamics(rc.joints, friction=False))
    else:
        a = assess_robot_campaign(played, regressor=dyn.regressor,
                                  inverse_dynamics=dyn.inverse_dynamics)
    if results:
        a = replace(a, optimised=results)
    where = robot.source if rc.plant == "arm" else "its [joint] table, no robot file"
    print(f"robot {robot.name!r} ({where}): moving {', '.join(robot.moving)}; "
          f"regressor: {len(dyn.names)} columns (standard parameters, Ia, FC FV OFF per "
          f"joint)")
    if results:
        print(f"multi-sines optimised for the condition number ({OPTIMISE_EVALUATIONS} "
              f"evaluations, deterministic: jointid run plays the same coefficients)")
    print(a)
    if args.plot is not None:
        path = plot_plan(a.plan, args.plot)
        print(f"plot: {path}")
    return 0


def plot_plan(plan: RobotPlan, path: str | Path) -> Path:
    """Draw q, dq, ddq of every joint of one run with each joint's limits (dashed) and the
    segment boundaries and labels; save as PNG. One joint: the low-velocity band shaded.

    Parameters
    ----------
    plan : RobotPlan
        Any plan (a ``[joint]`` campaign's has one joint).
    path : str or Path
        Output image file.

    Returns
    -------
    Path
        The written file.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .sampled import BANDS

    path = Path(path)
    units = {plan.unit(j) for j in range(plan.n_joints)}
    u = units.pop() if len(units) == 1 else "rad or m"
    fig, axes = plt.subplots(3, 1, sharex=True, figsize=(12, 7.5), constrained_layout=True)
    for j, (nm, lim) in enumerate(zip(plan.joint_names, plan.limits, strict=True)):
        color = "C0" if plan.n_joints == 1 else f"C{j % 10}"
        series = (
            (plan.q[:, j], lim.position),
            (plan.dq[:, j], (-lim.max_velocity, lim.max_velocity)),
            (plan.ddq[:, j], (-lim.max_acceleration, lim.max_acceleration)),
        )
        for ax, (y, (lo, hi)) in zip(axes, series, strict=True):
            ax.plot(plan.t, y, lw=0.9, color=color, label=nm if plan.n_joints > 1 else None)
            for bound in (lo, hi):
                ax.axhline(bound, color="C3" if plan.n_joints == 1 else color, ls="--",
                           lw=0.8)
    for ax, label in zip(axes, (f"q [{u}]", f"dq [{u}/s]", f"ddq [{u}/s²]"), strict=True):
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
    if plan.n_joints == 1:
        low = BANDS[1] * plan.limits[0].max_velocity
        axes[1].axhspan(-low, low, color="C2", alpha=0.15, lw=0,
                        label=f"|dq| < {100 * BANDS[1]:.0f} % of vmax")
    axes[1].legend(loc="upper right", fontsize=8)
    # segment boundaries and labels
    seg = plan.segment
    starts = [0, *(int(i) + 1 for i in (seg[1:] != seg[:-1]).nonzero()[0])]
    for k, i0 in enumerate(starts):
        t0 = plan.t[i0]
        t1 = plan.t[starts[k + 1]] if k + 1 < len(starts) else plan.t[-1]
        for ax in axes:
            ax.axvline(t0, color="0.4", lw=0.8)
        name = plan.segment_names[seg[i0]]
        axes[0].text(0.5 * (t0 + t1), 1.02, name.replace(" (", "\n("), ha="center",
                     va="bottom", fontsize=8, transform=axes[0].get_xaxis_transform())
    axes[-1].set_xlabel("t [s]")
    fig.suptitle(
        f"{plan.name}: one run of {plan.duration_s:.1f} s, x {max(1, len(plan.payloads))} "
        f"payload(s) (limits dashed)", fontsize=10
    )
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


#: the robot demo's name of :func:`plot_plan` (one plot for any plan)
plot_robot_plan = plot_plan
