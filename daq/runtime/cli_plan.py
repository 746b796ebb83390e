"""``jointid plan``: :mod:`trajectories.cli`'s command, plus the ``[daq]`` checks of
``jointid run``.

The planner (:mod:`trajectories`) knows nothing of CANopen; ``jointid run`` refuses a
campaign whose ``[daq]`` table (or robot file's drives) is wrong, or whose cyclic traffic
exceeds a bus's budget, before anything moves. ``jointid plan`` makes the same checks with
the same function (:func:`daq.runtime.runner.check_daq`, for a hardware run: python-can's
configuration fills what ``[daq]`` leaves out), so a campaign that plans also runs.
"""

from __future__ import annotations

import argparse

import trajectories.cli


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``plan`` (:func:`trajectories.cli.register`) running :func:`main`."""
    trajectories.cli.register(subparsers)
    subparsers.choices["plan"].set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    """The ``[daq]`` checks of ``jointid run`` (:func:`~daq.runtime.runner.check_daq`), then
    :func:`trajectories.cli.run`; returns its exit code."""
    from trajectories.campaign_file import load_campaign  # heavy: not at `jointid --help`

    from .runner import check_daq

    check_daq(load_campaign(args.campaign))
    return trajectories.cli.run(args)
