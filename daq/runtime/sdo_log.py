"""canopen's own log lines of an SDO failure the master handles itself.

canopen's SDO client logs a timeout's abort ("Transfer aborted by client with code
0x05040000", ERROR) and each retry ("No SDO response received", WARNING) before it raises;
with no logging configured, Python prints them bare on the console, beside the master's own
one-line refusal. :func:`handled_sdo_failures` sends them to DEBUG on the
``daq.runtime.master`` logger around the master's SDO calls (:mod:`daq.runtime.master`).
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from contextlib import contextmanager

#: the master's logger, where the dropped canopen records are re-logged at DEBUG
logger = logging.getLogger("daq.runtime.master")

#: canopen's SDO client: it logs a timeout's abort itself ("Transfer aborted by client with
#: code 0x05040000", ERROR) and each retry ("No SDO response received", WARNING) before it
#: raises; with no logging configured, Python prints them bare on the console
_SDO_CLIENT_LOG = logging.getLogger("canopen.sdo.client")


class _ToDebug(logging.Filter):
    """Drop a canopen record, re-logged at DEBUG on this module's logger."""

    def filter(self, record: logging.LogRecord) -> bool:
        logger.debug("canopen: %s", record.getMessage())
        return False


@contextmanager
def handled_sdo_failures() -> Iterator[None]:
    """Around an SDO call whose failure the master handles itself -- a refusal in its own
    words (:class:`daq.ConfigError` naming the drive and object), a note, or a best-effort
    write -- canopen's own log lines of that failure go to DEBUG, not the console. SDO
    traffic outside (canopen's, another thread's) keeps its logging."""
    f = _ToDebug()
    _SDO_CLIENT_LOG.addFilter(f)
    try:
        yield
    finally:
        _SDO_CLIENT_LOG.removeFilter(f)
