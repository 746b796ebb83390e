"""``jointid plan CAMPAIGN.toml [--plot FILE.png] [--quick]``: check and summarise a campaign.

Loads and validates the campaign, plans it with Ruckig (rejecting anything beyond the joint
limits before anything moves), prints the summary table (durations, share of moving time
per velocity band, position coverage, peaks against limits) and, with ``--plot``, draws
q, dq and ddq of one payload run against time with the segments marked.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from trajectories.plan import BANDS, CampaignPlan, plan_campaign

from .campaign_file import load_campaign

__all__ = ["plot_plan", "register", "run"]


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
                   help="plan the shortened campaign used by quick runs (Campaign.quick)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Execute ``jointid plan``; returns the exit code."""
    campaign = load_campaign(args.campaign)
    if args.quick:
        campaign = campaign.quick()
    plan = plan_campaign(campaign)
    print(plan.summary().format_table())
    if args.plot is not None:
        path = plot_plan(plan, args.plot)
        print(f"plot: {path}")
    return 0


def plot_plan(plan: CampaignPlan, path: str | Path) -> Path:
    """Draw q, dq, ddq of one run with segment boundaries and labels; save as PNG.

    Parameters
    ----------
    plan : CampaignPlan
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

    ref = plan.reference
    lim = plan.campaign.limits
    u = plan.campaign.joint.unit
    path = Path(path)
    fig, axes = plt.subplots(3, 1, sharex=True, figsize=(12, 7.5), constrained_layout=True)
    series = (
        (ref.q, f"q [{u}]", lim.position),
        (ref.dq, f"dq [{u}/s]", (-lim.max_velocity, lim.max_velocity)),
        (ref.ddq, f"ddq [{u}/s²]", (-lim.max_acceleration, lim.max_acceleration)),
    )
    for ax, (y, label, (lo, hi)) in zip(axes, series, strict=True):
        ax.plot(ref.t, y, lw=0.9, color="C0")
        for bound in (lo, hi):
            ax.axhline(bound, color="C3", ls="--", lw=0.8)
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
    low = BANDS[1] * lim.max_velocity
    axes[1].axhspan(-low, low, color="C2", alpha=0.15, lw=0,
                    label=f"|dq| < {100 * BANDS[1]:.0f} % of vmax")
    axes[1].legend(loc="upper right", fontsize=8)
    # segment boundaries and labels
    seg = ref.segment
    starts = [0, *(int(i) + 1 for i in (seg[1:] != seg[:-1]).nonzero()[0])]
    for k, i0 in enumerate(starts):
        t0 = ref.t[i0]
        t1 = ref.t[starts[k + 1]] if k + 1 < len(starts) else ref.t[-1]
        for ax in axes:
            ax.axvline(t0, color="0.4", lw=0.8)
        name = ref.segment_names[seg[i0]]
        axes[0].text(0.5 * (t0 + t1), 1.02, name.replace(" (", "\n("), ha="center",
                     va="bottom", fontsize=8, transform=axes[0].get_xaxis_transform())
    axes[-1].set_xlabel("t [s]")
    c = plan.campaign
    fig.suptitle(
        f"{c.name}: one run of {ref.duration_s:.1f} s, x {len(plan.payloads)} payload(s) "
        f"(limits dashed)", fontsize=10
    )
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
