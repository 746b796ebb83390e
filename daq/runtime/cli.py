"""``jointid run CAMPAIGN.toml [--simulate [PLANT.toml]] [--out DIR]``: execute a campaign.

Either file format is read into one campaign type (a ``[joint]`` file is a robot with one
moving joint, its drives those of ``[daq]``) and run by one path. ``--simulate`` puts the
plant the campaign asks for behind the drives (:mod:`daq.runtime.robot_rig`): a robot file's
campaign (``[robot]``) a simulated arm built from the robot file (``--simulate``, no file);
a ``[joint]`` file one simulated joint plant per drive (``--simulate PLANT.toml``).
``--quick`` shortens a campaign of one moving joint with trapezoid and sine segments.

Exit codes: 0 done, 2 configuration error or refusal (nothing moved), 3 a run stopped on a
fault (the message names the cause; the log is kept), 130 / 143 / 129 interrupted by SIGINT
(Ctrl-C) / SIGTERM / SIGHUP (the drives are quick-stopped and disabled first), 1 the
operator declined a payload.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from daq import ConfigError

if TYPE_CHECKING:
    from .runner import Progress


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "run",
        help="run a campaign on CANopen drives (or simulated ones) and log it to MCAP",
        description="Run the campaign's plan once per payload: one MCAP log per payload run, "
        "DIR/<name>_payload<k>.mcap, and DIR/<name>.state.json listing the completed payloads.",
        epilog="One run per folder: DIR is locked (DIR/.jointid-run.lock) and a second run "
        "into it is refused. One campaign per folder: a DIR/*.mcap of another campaign "
        "(another name; the same name with other joints, limits, payloads or segments, or "
        "another robot file; another simulated plant; [daq] may differ), or a state file of "
        "another campaign (it records the campaign as the logs do), makes the run "
        "refuse, with or without --resume, naming the file and what differs. A log is "
        "never replaced without a word: a log left in DIR "
        "makes the run refuse unless --resume (completed payloads are skipped, once their "
        "logs are checked: a completed payload's log missing or changed since, by the size "
        "the state file records, is refused, naming it; --payload K --overwrite runs it "
        "again; the log of "
        "one that did not complete is moved to DIR/partial/<name>_payload<k>.partial-<n>.mcap "
        "before it runs again) or --overwrite. The state file only grows; it also keeps the "
        "EMCYs received after the last payload's log closed and the warnings of the run's "
        "wind-down (the bus lost, a drive no longer answering) (in no log; warnings of the "
        "summary). Before each "
        "payload the free space is checked against the log's expected size. Every end runs "
        "the stop sequence (quick stop, disable): a fault, a failing log file (disk full: "
        "'log write failed: FILE: ...', exit 3), SIGINT, SIGTERM or SIGHUP (exit 128 + "
        "signal). A run that ends before its first log removes the folders it created (--out "
        "a/b/c: c, b and a when it created them). Exit codes: 0 done, 1 the operator declined "
        "a payload, 2 refusal (nothing moved), 3 stopped on a fault, 130/143/129 interrupted.",
    )
    p.add_argument("campaign", type=Path, help="campaign file (TOML)")
    p.add_argument("--simulate", type=Path, metavar="PLANT.toml", default=None, nargs="?",
                   const=True,
                   help="run against simulated drives of this plant on a virtual bus; for a "
                   "robot campaign, no file: a simulated arm of the campaign's robot file")
    p.add_argument("--out", type=Path, default=Path("runs"), metavar="DIR",
                   help="output directory (default: ./runs)")
    p.add_argument("--yes", "-y", action="store_true",
                   help="do not ask the operator to confirm each payload")
    p.add_argument("--resume", action="store_true",
                   help="skip the payloads already completed in DIR (refused when the log of "
                   "one is missing or changed); keep the log of a payload "
                   "that did not complete under DIR/partial/ and run it again")
    p.add_argument("--overwrite", action="store_true",
                   help="replace the logs of the payloads run (default: refuse)")
    p.add_argument("--payload", type=int, action="append", default=None, metavar="K",
                   help="run only payload K (0-based; repeatable)")
    p.add_argument("--quick", action="store_true",
                   help="shortened campaign (about 10-15 s per payload) for smoke runs")
    p.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    # imported here, not at the top: `jointid --help` must not wait for them (seconds)
    from sim_drivers.plant_config import load_plant
    from trajectories.campaign_file import load_campaign
    from trajectories.cli import file_named

    from .progress import ProgressLine
    from .runfolder import missing_folders, remove_unused_folders
    from .runner import prompt_payload, run_campaign
    from .safety import interrupt_signal

    if args.out.exists() and not args.out.is_dir():  # "run.csv: File exists" before
        raise ConfigError(f"--out {args.out}: is a file, expected a folder (created if absent)")
    campaign = load_campaign(args.campaign)
    if args.quick:  # one moving joint, trapezoids and sines (else a one-line SchemaError)
        campaign = campaign.quick()
    plant = None
    if campaign.plant == "arm" and args.simulate not in (None, True):
        raise ConfigError(f"{campaign.source}: --simulate {args.simulate}: a robot campaign "
                          f"is simulated from its robot file; give --simulate alone")
    if args.simulate is True:
        plant = True
    elif args.simulate is not None:
        plant = load_plant(args.simulate)
    bar = ProgressLine()

    def show(p: Progress) -> None:
        frac = p.cycle / p.n_cycles if p.n_cycles else 0.0
        bar.update(frac, p.text())

    def ask(index, payload, n) -> bool | None:
        bar.close()
        return prompt_payload(index, payload, n)

    created = missing_folders(args.out)  # --out a/b/c: the folders this run creates
    try:
        with file_named(campaign.source):  # a limit the plan exceeds: named with the file
            result = run_campaign(campaign, out_dir=args.out, simulate=plant, yes=args.yes,
                                  progress=show, payloads=args.payload, resume=args.resume,
                                  prompt=None if args.yes else ask, overwrite=args.overwrite)
    except BaseException:
        remove_unused_folders(created)
        raise
    finally:
        bar.close()
    print(result.summary(), file=sys.stderr)
    if result.status == "done":
        return 0
    remove_unused_folders(created)  # ended before its first log (declined, interrupted)
    print(f"jointid run: {result.status}: {result.reason}", file=sys.stderr)
    if result.status == "interrupted":
        return 128 + interrupt_signal(result.reason)
    return {"stopped": 3, "aborted": 1}.get(result.status, 3)
