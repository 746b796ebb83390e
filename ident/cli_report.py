"""``jointid report DIR``: rebuild ``DIR/report.html`` from ``DIR/fit.json``, ``DIR/demo.json``
and the figures in ``DIR`` (written by ``jointid demo`` or ``jointid fit --report``)."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``report`` subcommand to the ``jointid`` parser."""
    r = sub.add_parser("report", help="rebuild DIR/report.html from a run's logs and fit results",
                       description="Rebuild DIR/report.html from DIR/fit.json, DIR/demo.json and "
                       "the figures in DIR.")
    r.add_argument("dir", type=Path, help="folder written by jointid demo or jointid fit --report")
    r.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from .report_build import build_report  # imported when run, not at `jointid --help`

    out = build_report(args.dir)
    print(f"report: {out}")
    return 0
