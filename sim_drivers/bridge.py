"""The loopback CAN bridge of ``python -m sim_drivers.serve --bridge-port``: python-can-remote's
WebSocket server with its open doors closed.

python-can-remote 0.3's own server (``can_remote.server.RemoteServer``) answers any HTTP GET
with a file read relative to its package (``GET /../../../../etc/passwd`` returns that file),
and opens a bus for any WebSocket client, including a web page in the user's browser (a
cross-site WebSocket carries the page's ``Origin``; browsers let any site connect to
127.0.0.1). Here, with no change to the installed package (:class:`BridgeHandler` subclasses
its request handler):

- the bridge listens on 127.0.0.1 only;
- a WebSocket upgrade is accepted only on the path ``/<token>``, ``token`` a random
  URL-safe string (:func:`new_token`, 128 bits) made when the bridge starts and printed in
  its URL ``ws://127.0.0.1:<port>/<token>``: a client presents it by opening that URL (the
  daq side's ``[daq] channel``, ``can.Bus(interface="remote", channel=url)``); a missing or
  wrong token is refused with 403;
- a request with a non-empty ``Origin`` header -- what browsers send, and python-can's
  client does not -- is refused with 403;
- everything else (plain HTTP: the trace web page, any file path, other methods) is 404.

Refusals are logged at INFO level by the ``sim_drivers.bridge`` logger, without the token.
"""

from __future__ import annotations

import hmac
import logging
import secrets
import threading
from typing import Any

from can_remote.server import ClientRequestHandler, RemoteServer

logger = logging.getLogger(__name__)

__all__ = ["Bridge", "BridgeHandler", "new_token"]

HOST = "127.0.0.1"


def new_token() -> str:
    """A random URL-safe token (16 random bytes, 22 characters)."""
    return secrets.token_urlsafe(16)


class BridgeHandler(ClientRequestHandler):
    """python-can-remote's request handler, answering only an authorised WebSocket upgrade
    (module docstring); ``self.server`` is a :class:`Bridge`."""

    server: Bridge
    error_content_type = "text/plain"
    error_message_format = "%(code)d %(message)s\n"

    def do_GET(self) -> None:
        why = self._refusal()
        if why is not None:
            code, reason = why
            logger.info("bridge: refused %s from %s: %s", self.command,
                        self.address_string(), reason)
            self.send_error(code)
            return
        self.start_websocket()

    def _refusal(self) -> tuple[int, str] | None:
        """(HTTP status, reason) when the request is not an authorised WebSocket upgrade."""
        if self.headers.get("Origin", "").strip():
            return 403, "Origin header (a browser page)"
        if self.headers.get("Upgrade", "").lower() != "websocket":
            return 404, "not a WebSocket upgrade"
        if not self.headers.get("Sec-WebSocket-Key"):
            return 400, "no Sec-WebSocket-Key"
        given = self.path.split("?", 1)[0].strip("/")
        if not hmac.compare_digest(given.encode(), self.server.token.encode()):
            return 403, "missing or wrong token"
        return None

    def _not_found(self) -> None:
        logger.info("bridge: refused %s from %s: not a WebSocket upgrade", self.command,
                    self.address_string())
        self.send_error(404)

    do_HEAD = do_POST = do_PUT = do_DELETE = do_PATCH = do_OPTIONS = _not_found

    def send_trace_webpage(self) -> None:
        """Never serve files (python-can-remote's page reads any path)."""
        self.send_error(404)


class Bridge(RemoteServer):
    """python-can-remote's server on 127.0.0.1:``port`` with :class:`BridgeHandler`.

    Parameters
    ----------
    port : int
        TCP port (0: any free port; :attr:`server_port` is the one listened on).
    token : str or None
        The token clients must present (None: :func:`new_token`).
    **config
        The bus each client gets, opened in this process (``interface``, ``channel``,
        ``bitrate``), as for ``RemoteServer``.

    Attributes
    ----------
    token : str
    url : str
        ``ws://127.0.0.1:<port>/<token>``: the channel a client opens.
    """

    def __init__(self, port: int = 0, *, token: str | None = None, **config: Any) -> None:
        self.token = token or new_token()
        self._serving = False
        super().__init__(HOST, port, **config)
        self.RequestHandlerClass = BridgeHandler  # (no request is handled before start)

    @property
    def url(self) -> str:
        return f"ws://{HOST}:{self.server_port}/{self.token}"

    def start(self) -> Bridge:
        """Serve in a daemon thread; stop with :meth:`close`."""
        self._serving = True
        threading.Thread(target=self.serve_forever, kwargs={"poll_interval": 0.1},
                         name="can-remote-bridge", daemon=True).start()
        return self

    def close(self) -> None:
        """Stop serving and close the listening socket (client connections end with their
        threads). Idempotent."""
        if self._serving:
            self._serving = False
            self.shutdown()
        self.server_close()
