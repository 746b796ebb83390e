"""The loopback bridge of ``sim_drivers.serve --bridge-port`` (:mod:`sim_drivers.bridge`): a token
in the URL, no browser pages, no files; python-can's ``remote`` client with the token works.

Everything over 127.0.0.1: raw HTTP requests (``http.client``) for what must be refused, a
python-can ``remote`` bus for what must work.
"""

from __future__ import annotations

import base64
import http.client
import os
import re

import can
import pytest

from sim_drivers.bridge import Bridge, BridgeHandler, new_token
from sim_drivers.remote import ServeProcess
from sim_drivers.testing import unique_channel

KEY = base64.b64encode(os.urandom(16)).decode()


@pytest.fixture
def bridge():
    ch = unique_channel("bridge")
    b = Bridge(0, interface="virtual", channel=ch).start()
    local = can.Bus(interface="virtual", channel=ch)
    yield b, local
    local.shutdown()
    b.close()


def _request(port: int, path: str, *, method: str = "GET", upgrade: bool = False,
             origin: str | None = None) -> tuple[int, bytes, dict[str, str]]:
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
    headers = {}
    if upgrade:
        headers.update({"Upgrade": "websocket", "Connection": "Upgrade",
                        "Sec-WebSocket-Key": KEY, "Sec-WebSocket-Version": "13",
                        "Sec-WebSocket-Protocol": "can.json.v1"})
    if origin is not None:
        headers["Origin"] = origin
    try:
        conn.request(method, path, headers=headers)
        r = conn.getresponse()
        body = r.read() if r.status != 101 else b""
        return r.status, body, dict(r.getheaders())
    finally:
        conn.close()


def test_plain_http_is_404_and_no_file_is_served(bridge):
    b, _ = bridge
    port = b.server_port
    for path in ("/../../../../etc/passwd", "/%2e%2e/%2e%2e/%2e%2e/%2e%2e/etc/passwd", "/",
                 "/index.html", f"/{b.token}", f"/{b.token}/../../../../../etc/passwd"):
        status, body, _ = _request(port, path)
        assert status == 404, path
        assert b"root:" not in body and b"<html" not in body.lower()
    for method in ("HEAD", "POST", "PUT", "DELETE", "OPTIONS"):
        assert _request(port, f"/{b.token}", method=method)[0] == 404, method


def test_upgrade_needs_the_token_and_no_origin(bridge):
    b, _ = bridge
    port = b.server_port
    assert _request(port, "/", upgrade=True)[0] == 403  # no token
    assert _request(port, f"/{new_token()}", upgrade=True)[0] == 403  # wrong token
    assert _request(port, f"/{b.token[:-1]}", upgrade=True)[0] == 403  # a prefix
    assert _request(port, f"/{b.token}x", upgrade=True)[0] == 403
    # a browser page: its Origin, even with the right token
    for origin in ("http://evil.example", "null", "http://127.0.0.1:8000"):
        assert _request(port, f"/{b.token}", upgrade=True, origin=origin)[0] == 403, origin
    # python-can's client refuses to open a bus without the token
    with pytest.raises(AssertionError, match="Unexpected response status"):  # (its check)
        can.Bus(interface="remote", channel=f"ws://127.0.0.1:{port}/")
    assert b.clients == []


def test_the_right_token_bridges_both_ways(bridge):
    b, local = bridge
    assert re.fullmatch(r"ws://127\.0\.0\.1:\d+/[A-Za-z0-9_-]{22}", b.url)
    remote = can.Bus(interface="remote", channel=b.url)
    try:
        remote.send(can.Message(arbitration_id=0x123, data=b"\x01\x02", is_extended_id=False))
        m = local.recv(5.0)
        assert m is not None and (m.arbitration_id, bytes(m.data)) == (0x123, b"\x01\x02")
        local.send(can.Message(arbitration_id=0x456, data=b"\x03", is_extended_id=False))
        m = remote.recv(5.0)
        assert m is not None and (m.arbitration_id, bytes(m.data)) == (0x456, b"\x03")
    finally:
        remote.shutdown()
    # a trailing slash is the same path
    remote = can.Bus(interface="remote", channel=b.url + "/")
    remote.shutdown()


def test_each_bridge_has_its_own_token():
    a = Bridge(0, interface="virtual", channel=unique_channel("bridge"))
    c = Bridge(0, interface="virtual", channel=unique_channel("bridge"))
    try:
        assert a.token != c.token and len(a.token) >= 22
        assert a.RequestHandlerClass is BridgeHandler and a.server_address[0] == "127.0.0.1"
    finally:
        a.close()
        c.close()


@pytest.mark.slow  # a serve subprocess
def test_serve_prints_the_url_with_its_token_and_only_that_url_opens_the_bus():
    with ServeProcess((), channel="bridge_cli") as served:
        assert re.fullmatch(r"ws://127\.0\.0\.1:\d+/[A-Za-z0-9_-]{22}", served.url)
        port = int(served.url.split(":")[2].split("/")[0])
        assert _request(port, "/../../../../etc/passwd")[0] == 404
        assert _request(port, "/", upgrade=True)[0] == 403
        bus = can.Bus(interface="remote", channel=served.url)
        bus.shutdown()
