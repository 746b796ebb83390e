"""``jointid recover LOG [-o OUT]``: rewrite a run log with message indexes and a summary.

A log whose writer was killed has no summary: ``read_run`` reads it, but indexed readers
(Foxglove, ``@mcap/core``, the ``mcap`` library's seeking reader) need the index. This copies
every intact record (:func:`daq.runtime.mcaprecover.recover_log`). Without ``-o`` the log is
replaced in place and the original kept as ``LOG.orig`` (a name ``*.mcap`` globs do not
match, so ``jointid fit DIR`` reads the recovered run once). ``-o OUT`` is refused when OUT
exists (it may be another run's log). Logs written before message
indexes were written (Foxglove could not play them) are re-indexed the same way.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import TYPE_CHECKING

from daq import DaqError

if TYPE_CHECKING:
    from .mcaprecover import Recovered


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``recover`` subcommand to the ``jointid`` parser."""
    p = sub.add_parser(
        "recover", help="rewrite a killed (or old) run log with indexes for Foxglove",
        description="Copy the intact records of a run log (schemas, channels, metadata, "
        "attachments, every chunk whose data checks out) to a new MCAP file with message "
        "indexes, a summary and a footer, so that Foxglove and the mcap indexed readers open "
        "it. Without -o, LOG is replaced and the original kept as LOG.orig; -o never replaces an "
        "existing file.")
    p.add_argument("log", type=Path, metavar="LOG.mcap", help="a run log written by jointid run")
    p.add_argument("-o", "--output", type=Path, metavar="OUT.mcap",
                   help="write here instead of replacing LOG (refused if it exists)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from .mcaprecover import recover_log  # mcap: imported when run, not at `jointid --help`

    src: Path = args.log
    if not src.is_file():
        raise DaqError(f"{src}: no such run log")
    if args.output is not None:
        if args.output.exists():  # a mistyped -o must not replace another run's log
            raise DaqError(f"{args.output}: already exists; recover writes a new file "
                           f"(remove it first or give another -o)")
        res = recover_log(src, args.output)
        kept = ""
    else:
        backup = src.with_name(src.name + ".orig")
        if backup.exists():
            raise DaqError(f"{backup}: already exists (a previous recover?); give -o OUT")
        os.replace(src, backup)
        try:
            res = recover_log(backup, src)
        except BaseException:
            os.replace(backup, src)
            raise
        kept = f"; original kept as {backup}"
    print(summary_line(res) + kept)
    return 0


def summary_line(res: Recovered) -> str:
    """One line: what was copied and what was left out."""
    notes = []
    if res.dropped_bytes:
        notes.append(f"{res.dropped_bytes} bytes of an incomplete last record dropped")
    if res.damaged:
        notes.append(f"{res.damaged} damaged chunk{'s' * (res.damaged != 1)} skipped")
    if not notes:
        notes.append("nothing lost" if res.had_summary else "no partial record at the end")
    return (f"recover: {res.chunks} chunks, {res.messages} messages -> {res.path} "
            f"({', '.join(notes)})")
