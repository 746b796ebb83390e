"""``jointid demo`` and ``jointid report``: the whole product on the embedded default.

The demo runs ``examples/campaign.toml`` on the simulated drive loaded with
``examples/plant_rx130l.toml`` (three payloads, one undeclared effect) over python-can's
virtual bus through the real master code, writes the MCAP logs, fits the usual and the new
model on all payloads, refines the new model from its residual, and writes
``DIR/report.html`` (self-contained), the figures as PNG files and ``DIR/fit.json``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demo",
        help="run the whole campaign on the simulated joint and write a report",
        description="Plan the example campaign, run it on the simulated CiA 402 drive over a "
        "virtual CAN bus, log to MCAP, fit the usual and the new model, refine from the "
        "residual, and write DIR/report.html.",
    )
    p.add_argument("--out", type=Path, default=Path("jointid-demo"),
                   help="output folder (default: ./jointid-demo)")
    p.add_argument("--quick", action="store_true",
                   help="a shortened campaign (under a minute on 2 cores)")
    p.add_argument("--max-steps", type=int, default=3, help="refinement steps (default 3)")
    p.set_defaults(func=_demo)

    r = sub.add_parser("report", help="rebuild DIR/report.html from a run's logs and fit results",
                       description="Rebuild DIR/report.html from DIR/fit.json, DIR/demo.json and "
                       "the figures in DIR.")
    r.add_argument("dir", type=Path, help="folder written by jointid demo or jointid fit --report")
    r.set_defaults(func=_report)


def _report(args: argparse.Namespace) -> int:
    from .report_build import build_report

    out = build_report(args.dir)
    print(f"report: {out}")
    return 0


def _demo(args: argparse.Namespace) -> int:
    from .demo import run_demo

    t0 = time.perf_counter()
    result = run_demo(args.out, quick=args.quick, max_steps=args.max_steps,
                      stream=sys.stderr)
    print(result.summary)
    print(f"report: {result.report}  ({time.perf_counter() - t0:.0f} s)")
    return 0

