"""Run a campaign with a progress bar on a stream: the step both demos share."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any, TextIO

from daq.runtime.progress import ProgressLine
from daq.runtime.runner import Progress, run_campaign
from daq.runtime.safety import RunInterrupted, interrupt_signal


def run_with_bar(campaign: Any, logs_dir: Path, simulate: Any,
                 stream: TextIO, **kwargs: Any) -> tuple[Any, float]:
    """``run_campaign(campaign, simulate=...)`` into ``logs_dir`` without prompts, showing
    progress over all payloads on ``stream``; returns (result, wall time [s]).

    The demos regenerate their folder: the logs of an earlier demo in ``logs_dir`` are
    replaced (``overwrite=True``); the folder is still locked against a second run.
    ``kwargs`` go to ``run_campaign`` (``payloads``, ``monitor``)."""
    bar = ProgressLine(stream)

    def show(p: Progress) -> None:
        done = (p.payload + (p.cycle / p.n_cycles if p.n_cycles else 0.0)) / p.n_payloads
        bar.update(done, p.text())

    t0 = time.perf_counter()
    try:
        result = run_campaign(campaign, out_dir=logs_dir, simulate=simulate, yes=True,
                              progress=show, overwrite=True, **kwargs)
    finally:
        bar.close()
    return result, time.perf_counter() - t0


def stop_if_interrupted(result: Any, logs_dir: Path) -> None:
    """A demo's campaign ended by a stop signal (Ctrl-C, SIGTERM, SIGHUP during a payload:
    the runner quick-stopped and disabled the drives and closed the log): raise
    :class:`~daq.runtime.safety.RunInterrupted`, so that the entry point exits 128 + the
    signal (130 for Ctrl-C) with one line, as for any other interrupt, instead of a
    failed demo's exit 2.

    Raises
    ------
    daq.runtime.safety.RunInterrupted
        When ``result.status`` is "interrupted"; its ``detail`` says where the campaign
        stopped and where its logs are.
    """
    if result.status != "interrupted":
        return
    last = result.runs[-1] if result.runs else None
    where = f"in payload {last.index}" if last is not None else "before its first payload"
    drives = ("drives disabled" if last is None or last.stop_cycle >= 0
              else "the drives did not confirm the stop")
    raise RunInterrupted(interrupt_signal(result.reason),
                         f"the demo campaign stopped {where} ({drives}); its logs are "
                         f"closed in {logs_dir}")
