"""``jointid export LOG.mcap --can OUT.blf|.asc|.log|.csv|.trc``: the raw CAN frames of a run
log as a CAN trace (:func:`daq.protocol.export.export_can`; the format follows the extension).

Replay it with ``python -m can.player OUT.blf -i socketcan -c vcan0`` (any python-can
interface), or open it in CANalyzer/CANoe (``.asc``, ``.blf``), PCAN-View (``.trc``),
``canplayer`` (``.log``).
"""

from __future__ import annotations

import argparse
import datetime
from pathlib import Path

from .logformat import EXPORT_FORMATS


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``export`` subcommand to the ``jointid`` parser."""
    p = sub.add_parser(
        "export", help="export the raw CAN frames of a run log (.blf, .asc, .log, .csv, .trc)",
        description="Write the CAN frames logged in a run's MCAP file (channel /can/raw) to a "
        "CAN trace file python-can's player and the usual CAN tools read. The format follows "
        f"the extension: {', '.join(EXPORT_FORMATS)} (text formats also with .gz).")
    p.add_argument("log", type=Path, metavar="LOG.mcap", help="a run log written by jointid run")
    p.add_argument("--can", type=Path, required=True, metavar="OUT",
                   help="output trace file (.blf, .asc, .log, .csv, .trc)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from .export import export_can  # python-can, mcap: imported when run

    res = export_can(args.log, args.can)
    if res.frames:
        t0 = datetime.datetime.fromtimestamp(res.first_s, datetime.UTC)
        span = f", {res.last_s - res.first_s:.3f} s from {t0:%Y-%m-%d %H:%M:%S} UTC"
    else:
        span = ""
    chans = [f"{c} = {b}" if c is not None else b for c, b in res.channels]
    on = f" on channel{'s' if len(chans) > 1 else ''} {', '.join(chans)}" if chans else ""
    print(f"export: {res.frames} CAN frames ({res.transmitted} sent by the master{span}){on} "
          f"-> {res.path}")
    return 0
