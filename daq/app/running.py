"""Run a campaign with a progress bar on a stream: the step both demos share."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any, TextIO

from daq.runtime.progress import ProgressLine
from daq.runtime.runner import Progress, run_campaign


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
