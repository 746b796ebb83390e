"""A single-line progress bar on stderr (no dependency), reusable by every subcommand, and a
heartbeat that prints a line when a long step has been silent for a while."""

from __future__ import annotations

import sys
import threading
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


class _Tracked:
    """A text stream proxy that records when it was last written to (for :class:`Heartbeat`)."""

    def __init__(self, stream: TextIO, beat: Heartbeat) -> None:
        self._stream = stream
        self._beat = beat

    def write(self, text: str) -> int:
        with self._beat._lock:
            n = self._stream.write(text)
            if text:
                self._beat._last = time.monotonic()
                self._beat._open = not text.endswith("\n")
        return n

    def flush(self) -> None:
        self._stream.flush()

    def isatty(self) -> bool:
        return bool(getattr(self._stream, "isatty", lambda: False)())

    def __getattr__(self, name: str):  # encoding, fileno, ...
        return getattr(self._stream, name)


class Heartbeat:
    """A line on the stream at least every ``interval_s`` while a long step runs.

    Work written to :attr:`stream` (step lines, a :class:`ProgressLine`) resets the clock;
    when nothing was written for ``interval_s`` [s], a background thread writes the current
    :meth:`status` text with the time spent in it, so that a step that prints nothing for a
    long time (a fit, a refinement step, a joint of the robot refinement) still shows it is
    alive. No line is written while the status is ``None``. A heartbeat writing to another
    one's :attr:`stream` (a step that runs its own, inside a command that runs one) counts the
    silence from the last line written to that stream, not from its own start.

    Parameters
    ----------
    stream : text stream
        Where to write (default ``sys.stderr``).
    interval_s : float
        Longest silence [s].
    indent : str
        Prefix of the heartbeat lines.

    Examples
    --------
    >>> import io
    >>> with Heartbeat(io.StringIO(), interval_s=5.0) as hb:
    ...     hb.status("fitting")        # work here; hb.stream is the stream to print to
    """

    def __init__(self, stream: TextIO | None = None, interval_s: float = 5.0,
                 indent: str = "      ") -> None:
        self._raw = stream if stream is not None else sys.stderr
        self.interval = float(interval_s)
        self.indent = indent
        self._lock = threading.Lock()
        self._last = time.monotonic()
        self._open = False
        self._text: str | None = None
        self._since = time.monotonic()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        #: the stream to write to (a proxy that resets the clock)
        self.stream: TextIO = _Tracked(self._raw, self)  # type: ignore[assignment]

    def status(self, text: str | None, restart: bool = True, say: bool = False) -> None:
        """What is running now (None: say nothing, e.g. while a progress bar runs); the time
        shown counts from the last call with ``restart`` (a new step, not a new detail).
        ``say``: write its line at once, without the time (``"      ... loading the
        pipeline's modules"``: a command's first line, before a step that may be silent for
        seconds)."""
        with self._lock:
            if restart:
                self._since = time.monotonic()
            self._text = text
        if say and text is not None:
            self.stream.write(f"{self.indent}... {text}\n")
            self.stream.flush()

    def _beat(self) -> None:
        while not self._stop.wait(min(1.0, self.interval / 4)):
            with self._lock:
                now = time.monotonic()
                if self._text is None or now - self._last < self.interval:
                    continue
                line = (f"{self.indent}... {self._text} ({now - self._since:.0f} s)\n")
                self._raw.write(("\n" if self._open else "") + line)
                self._raw.flush()
                self._last, self._open = now, False

    def __enter__(self) -> Heartbeat:
        self._stop.clear()
        self._last = time.monotonic()
        if isinstance(self._raw, _Tracked):  # on another heartbeat's stream: the silence
            self._last = self._raw._beat._last  # counts from the last line written to it
        self._thread = threading.Thread(target=self._beat, name="heartbeat", daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
