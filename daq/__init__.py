"""jointid data acquisition: protocol (:mod:`daq.protocol`), runtime (:mod:`daq.runtime`:
CANopen master, campaign runner, MCAP writer) and the application (:mod:`daq.app`: the
``jointid`` command line and the demo). This module holds only the version and exceptions.

Exception tree: every error this package raises on purpose derives from :class:`DaqError`.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("jointid")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"


class DaqError(Exception):
    """Root of every error raised on purpose by :mod:`daq` (one-line, user-facing message)."""


class ConfigError(DaqError):
    """A configuration file or value is invalid; the message names the file and key."""
