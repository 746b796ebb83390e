"""A single-line progress bar on stderr (no dependency), reusable by every subcommand."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class ProgressLine:
    """Redraws one line (``\\r``) at most every ``interval_s``; :meth:`close` ends the line.

    Parameters
    ----------
    stream : text stream
        Default ``sys.stderr``. When it is not a terminal, a line is printed at most every
        ``quiet_interval_s`` instead of being redrawn.
    width : int
        Bar width in characters.
    """

    def __init__(self, stream: TextIO | None = None, width: int = 24, interval_s: float = 0.1,
                 quiet_interval_s: float = 5.0) -> None:
        self.stream = stream if stream is not None else sys.stderr
        self.width = width
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.interval = interval_s if self.tty else quiet_interval_s
        self._last = -1e9
        self._len = 0

    @staticmethod
    def bar(fraction: float, width: int) -> str:
        """``[#####.....]`` for a fraction in [0, 1]."""
        f = min(max(fraction, 0.0), 1.0)
        n = int(round(f * width))
        return "[" + "#" * n + "." * (width - n) + "]"

    def update(self, fraction: float, text: str, force: bool = False) -> None:
        """Show ``[bar] pct text`` (rate limited unless ``force``)."""
        now = time.monotonic()
        if not force and now - self._last < self.interval:
            return
        self._last = now
        line = f"{self.bar(fraction, self.width)} {100 * min(max(fraction, 0), 1):5.1f}% {text}"
        if self.tty:
            pad = max(0, self._len - len(line))
            self.stream.write("\r" + line + " " * pad)
            self._len = len(line)
        else:
            self.stream.write(line + "\n")
        self.stream.flush()

    def close(self) -> None:
        """Finish the line (terminal) so that the next output starts on its own line."""
        if self.tty and self._len:
            self.stream.write("\n")
            self.stream.flush()
        self._len = 0
