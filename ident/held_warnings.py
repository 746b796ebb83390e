"""Warnings held back while a block runs, then shown once each: the one helper of ``jointid
fit``/``export-model`` (around the reading and fitting, :func:`ident.cli.warnings_held`) and
of the robot MCAP loader (:func:`ident.loaders.read_file`, around the reading of a log's
axes and their checks).

A refusal is then its one line, without the warnings said before it; a warning raised twice
in the block (the same text and category: the same damaged chunk met by two readings) is
said once; none is lost when the block ends normally or by an interrupt (Ctrl-C).
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["warnings_held"]


@contextmanager
def warnings_held() -> Iterator[None]:
    """Hold the warnings of the block; show each distinct one once when it ends.

    Each warning passes the caller's filters where it is raised, as without the block (an
    ``ignore`` filter drops it, an ``error`` filter raises it there, a module's filter
    matches its module); the ones kept are recorded. When the block ends normally or by a
    :class:`BaseException` that is not an :class:`Exception` (``KeyboardInterrupt``,
    ``SystemExit``), they are shown in the order raised, one per (text, category) -- the
    first one's file and line --, through :func:`warnings.showwarning` (which the jointid
    console script formats as one line, and which an enclosing block or
    ``catch_warnings(record=True)`` records again). When it ends in an
    :class:`Exception` (a refusal), they are dropped: the refusal is said alone.

    Yields
    ------
    None
    """
    failed = False
    seen: list[warnings.WarningMessage] = []
    try:
        with warnings.catch_warnings(record=True) as seen:
            try:
                yield
            except Exception:
                failed = True
                raise
    finally:
        if not failed:  # shown after catch_warnings gave showwarning back
            shown: set[tuple[str, type[Warning]]] = set()
            for w in seen:
                key = (str(w.message), w.category)
                if key not in shown:
                    shown.add(key)
                    warnings.showwarning(w.message, w.category, w.filename, w.lineno,
                                         w.file, w.line)
