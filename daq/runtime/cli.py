"""``jointid run CAMPAIGN.toml [--simulate PLANT.toml] [--out DIR]``: execute a campaign.

Exit codes: 0 done, 2 configuration error or refusal (nothing moved), 3 a run stopped on a
fault (the message names the cause; the log is kept), 130 interrupted (Ctrl-C), 1 the
operator declined a payload.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sim_drivers.plant_config import load_plant
from trajectories.campaign_file import load_campaign

from .progress import ProgressLine
from .runner import Progress, prompt_payload, run_campaign


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "run",
        help="run a campaign on CANopen drives (or simulated ones) and log it to MCAP",
        description="Run the campaign's plan once per payload: one MCAP log per payload run.",
    )
    p.add_argument("campaign", type=Path, help="campaign file (TOML)")
    p.add_argument("--simulate", type=Path, metavar="PLANT.toml", default=None,
                   help="run against simulated drives of this plant on a virtual bus")
    p.add_argument("--out", type=Path, default=Path("runs"), metavar="DIR",
                   help="output directory (default: ./runs)")
    p.add_argument("--yes", "-y", action="store_true",
                   help="do not ask the operator to confirm each payload")
    p.add_argument("--resume", action="store_true",
                   help="skip the payloads already completed in DIR")
    p.add_argument("--payload", type=int, action="append", default=None, metavar="K",
                   help="run only payload K (0-based; repeatable)")
    p.add_argument("--quick", action="store_true",
                   help="shortened campaign (about 10-15 s per payload) for smoke runs")
    p.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    campaign = load_campaign(args.campaign)
    if args.quick:
        campaign = campaign.quick()
    plant = None
    if args.simulate is not None:
        plant = load_plant(args.simulate)
    bar = ProgressLine()

    def show(p: Progress) -> None:
        frac = p.cycle / p.n_cycles if p.n_cycles else 0.0
        bar.update(frac, p.text())

    def ask(index, payload, n) -> bool:
        bar.close()
        return prompt_payload(index, payload, n)

    try:
        result = run_campaign(campaign, out_dir=args.out, simulate=plant, yes=args.yes,
                              progress=show, payloads=args.payload, resume=args.resume,
                              prompt=None if args.yes else ask)
    finally:
        bar.close()
    print(result.summary(), file=sys.stderr)
    if result.status == "done":
        return 0
    print(f"jointid run: {result.status}: {result.reason}", file=sys.stderr)
    return {"stopped": 3, "interrupted": 130, "aborted": 1}.get(result.status, 3)
