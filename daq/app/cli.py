"""The ``jointid`` command line: one entry point, one module per subcommand.

Each subcommand module exposes ``register(subparsers)``, which adds its parser and sets
``func`` (a callable ``args -> int`` exit code). Errors raised on purpose by any of the
packages (their exception roots) print one line on stderr and exit 2; Ctrl-C exits 130
(SIGTERM 143, SIGHUP 129: ``jointid run`` stops the drives first).
"""

# ruff: noqa: E402 - the imports after _quiet_sigint() are meant to follow it
from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
import warnings
from typing import NoReturn


def _interrupted_at_start(signum: int, frame: object) -> None:
    """SIGINT while the subcommand modules below are still importing: one line and exit 130,
    as any other interrupt, not a traceback. (The heavy imports, scipy, pinocchio..., come
    later, inside each subcommand's run function, where :func:`main` catches the interrupt.)"""
    print("jointid: interrupted (SIGINT)", file=sys.stderr)
    raise SystemExit(128 + signum)


def _quiet_sigint() -> object:
    """Install :func:`_interrupted_at_start` for the imports; returns the handler to restore
    (``None``: left alone, outside the main thread or where SIGINT is ignored)."""
    if threading.current_thread() is not threading.main_thread():
        return None
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        return None
    return signal.signal(signal.SIGINT, _interrupted_at_start)


_sigint_before = _quiet_sigint()

from threadpoolctl import threadpool_limits

import daq.protocol.cli_export
import daq.runtime.cli
import daq.runtime.cli_plan
import daq.runtime.cli_recover
import ident.cli
import ident.cli_export_model
import ident.cli_report
from daq import DaqError, __version__
from ident import IdentError
from sim_drivers import SimError
from trajectories import TrajectoryError

from . import demo, monitor

if _sigint_before is not None:  # imports done: Ctrl-C is main()'s again
    signal.signal(signal.SIGINT, _sigint_before)

# subcommand modules, in the order of `jointid --help`; each sits with the package it drives
SUBCOMMANDS = (
    daq.runtime.cli_plan,  # jointid plan (trajectories.cli + the [daq] checks of run)
    daq.runtime.cli,  # jointid run
    ident.cli,  # jointid fit
    demo,  # jointid demo
    ident.cli_report,  # jointid report
    daq.protocol.cli_export,  # jointid export
    daq.runtime.cli_recover,  # jointid recover
    ident.cli_export_model,  # jointid export-model
    monitor,  # jointid monitor
)

#: errors raised on purpose by our packages (their exception roots) and I/O errors
USER_ERRORS: tuple[type[BaseException], ...] = (DaqError, TrajectoryError, IdentError, SimError,
                                                 OSError)


class OneLineParser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line, ``jointid CMD: error: ...``, like
    every other refusal (argparse prints the usage first: six lines for ``jointid fit``).
    The subcommands' parsers are of this class too (``add_subparsers`` uses the parent's)."""

    def error(self, message: str) -> NoReturn:
        """Print ``PROG: error: MESSAGE (PROG --help)`` on stderr and exit 2."""
        self.exit(2, f"{self.prog}: error: {message} ({self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog="jointid",
        description="Dynamic identification of robot joints over CANopen "
        "(plan the excitation, run it, log to MCAP, fit and refine friction models).",
    )
    parser.add_argument("--version", action="version", version=f"jointid {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for module in SUBCOMMANDS:
        module.register(sub)
    return parser


#: environment variables by which a user sets the BLAS thread count (honoured as given)
BLAS_THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def limit_blas_threads() -> None:
    """One BLAS thread, unless the user chose a count (:data:`BLAS_THREAD_VARS`).

    numpy is imported (and its BLAS started) long before ``main`` runs, so setting
    ``OPENBLAS_NUM_THREADS`` here does nothing in this process: threadpoolctl changes the
    loaded BLAS's own setting. The many small solves of jointid lose time to BLAS threads
    (``jointid demo --quick`` took about twice as long with them). The variable is still
    set for the child processes (imported afresh, they read it at start)."""
    if any(v in os.environ for v in BLAS_THREAD_VARS):
        return
    threadpool_limits(limits=1, user_api="blas")
    os.environ["OPENBLAS_NUM_THREADS"] = "1"


def _one_line_warnings(command: str) -> None:
    """Warnings (resampling, a cut-off at its bound...) as one line each,
    ``jointid CMD: warning: ...``, without Python's file, line and source echo."""

    def show(message, category, filename, lineno, file=None, line=None) -> None:
        print(f"jointid {command}: warning: {message}", file=file or sys.stderr)

    warnings.showwarning = show


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``jointid`` console script."""
    limit_blas_threads()
    parser = build_parser()
    args = parser.parse_args(argv)
    _one_line_warnings(getattr(args, "command", None) or "")
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt as exc:  # Ctrl-C, or SIGTERM/SIGHUP outside a payload run
        signum = getattr(exc, "signum", signal.SIGINT)
        detail = getattr(exc, "detail", "")  # what was left behind (a demo's run)
        print(f"jointid: interrupted ({signal.Signals(signum).name})"
              + (f": {detail}" if detail else ""), file=sys.stderr)
        return 128 + int(signum)
    except BrokenPipeError:  # `jointid plan ... | head`: the reader left; not an error
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 0
    except USER_ERRORS as exc:
        if isinstance(exc, OSError) and exc.filename:
            msg = f"{exc.filename}: {exc.strerror or exc}"
        else:
            msg = str(exc)
        print(f"jointid {args.command}: error: {msg}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
