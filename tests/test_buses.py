"""MultiBus: drives over several buses as one python-can bus for the master; config keys."""

from __future__ import annotations

import time

import can
import pytest

from daq import ConfigError
from daq.runtime.buses import MultiBus
from daq.runtime.config import parse_daq
from sim_drivers.testing import unique_channel


def _m(cid: int, data: bytes = b"") -> can.Message:
    return can.Message(arbitration_id=cid, data=data, is_extended_id=False)


def _drain(bus: can.BusABC) -> list[tuple[int, bytes]]:
    out = []
    while (m := bus.recv(0.05)) is not None:
        out.append((m.arbitration_id, bytes(m.data)))
    return out


def test_frames_go_to_the_bus_of_their_node_and_broadcasts_to_all():
    a, b = unique_channel("mb"), unique_channel("mb")
    sniff = {a: can.Bus(interface="virtual", channel=a), b: can.Bus(interface="virtual", channel=b)}
    mb = MultiBus({a: can.Bus(interface="virtual", channel=a),
                   b: can.Bus(interface="virtual", channel=b)}, {1: a, 2: b, 3: b})
    try:
        mb.send(_m(0x201, b"\x0f\x00\x01\x00"))  # RPDO1 node 1
        mb.send(_m(0x602, bytes(8)))  # SDO request node 2
        mb.send(_m(0x80))  # SYNC
        mb.send(_m(0x000, b"\x01\x03"))  # NMT start node 3
        mb.send(_m(0x000, b"\x80\x00"))  # NMT pre-operational, all nodes
        mb.send(_m(0x77F, b"\x05"))  # the master's heartbeat (no drive 127)
        assert _drain(sniff[a]) == [(0x201, b"\x0f\x00\x01\x00"), (0x80, b""),
                                    (0x000, b"\x80\x00"), (0x77F, b"\x05")]
        assert _drain(sniff[b]) == [(0x602, bytes(8)), (0x80, b""), (0x000, b"\x01\x03"),
                                    (0x000, b"\x80\x00"), (0x77F, b"\x05")]
        # receive from both, in turn
        for i in range(3):
            sniff[a].send(_m(0x181, bytes([i])))
            sniff[b].send(_m(0x182, bytes([i])))
        got = [(m.arbitration_id, bytes(m.data)) for m in iter(lambda: mb.recv(0.05), None)]
        assert sorted(got) == sorted([(0x181, bytes([i])) for i in range(3)]
                                     + [(0x182, bytes([i])) for i in range(3)])
        assert {cid for cid, _ in got[:2]} == {0x181, 0x182}  # neither bus starves
        # waiting: a frame arriving later on the second bus ends the wait
        t0 = time.perf_counter()
        assert mb.recv(0.02) is None and time.perf_counter() - t0 >= 0.02
        # periodic send: one task per destination bus, stopped together
        task = mb.send_periodic(_m(0x77F, b"\x05"), 0.01)
        time.sleep(0.055)
        task.stop()
        time.sleep(0.02)
        na, nb = len(_drain(sniff[a])), len(_drain(sniff[b]))
        assert na >= 3 and nb >= 3  # both buses got the periodic frame
        assert _drain(sniff[a]) == []  # stopped
    finally:
        mb.shutdown()
        for s in sniff.values():
            s.shutdown()


def test_drive_channels_in_the_daq_table():
    cfg = parse_daq({"channel": "can0", "drives": [{"node_id": 1}, {"node_id": 2,
                                                                     "channel": "can1"},
                                                    {"node_id": 3, "channel": "can0"}]})
    assert [d.channel for d in cfg.drives] == ["can0", "can1", "can0"]
    assert cfg.channels == ("can0", "can1")
    assert [d.node_id for d in cfg.drives_on("can0")] == [1, 3]
    assert parse_daq({}).channels == ("jointid",)
    with pytest.raises(ConfigError, match=r"c.toml: daq.drives\[1\].node_id: expected a unique"):
        parse_daq({"drives": [{"node_id": 1}, {"node_id": 1, "channel": "other"}]}, "c.toml")
    with pytest.raises(ConfigError, match=r"c.toml: daq.drives\[0\].channel: expected no channel"
                                          r" with interface 'config'"):
        parse_daq({"interface": "config", "drives": [{"node_id": 1, "channel": "x"}]},
                  "c.toml")
