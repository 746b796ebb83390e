"""An EMCY received after the last payload's log closed (left by the EMCY-between-payloads
fix): the runner logged an EMCY between payloads at cycle 0 of the next payload's log, but
one that came while the run wound down after the last payload (the drives set
pre-operational, the master heartbeat cleared) had no next log and was dropped without a
word. It is now a warning of the run's summary (stderr) and an entry of the state file's
``emcy_outside_logs``, kept from run to run; the closed log is not rewritten."""

from __future__ import annotations

import json
import time

import can
from daq_campaigns import sine_campaign

from daq.protocol.reader import read_run
from daq.runtime.runner import run_campaign
from sim_drivers.plant_config import default_plant

#: EMCY of node 1: 0x3210 (DC link over-voltage), error register 0x05 (generic + voltage)
EMCY = bytes([0x10, 0x32, 0x05, 0, 0, 0, 0, 0])


class _EmcyOnStop(can.Listener):
    """Node 1 reporting an over-voltage as the master sets it pre-operational after a run:
    armed by the NMT start of node 1 (a payload's run begins), the EMCY is sent on the next
    NMT pre-operational of node 1 (its run ended, its log closed)."""

    def __init__(self, bus: can.BusABC) -> None:
        self.bus = bus
        self.armed = False
        self.sent = 0

    def on_message_received(self, msg: can.Message) -> None:
        if msg.arbitration_id != 0x000 or bytes(msg.data[1:2]) != b"\x01":
            return
        if msg.data[0] == 0x01:  # NMT start node 1
            self.armed = True
        elif msg.data[0] == 0x80 and self.armed:  # NMT pre-operational node 1
            self.armed = False
            self.bus.send(can.Message(arbitration_id=0x81, data=EMCY, is_extended_id=False))
            self.sent += 1


def test_an_emcy_after_the_last_payload_is_reported_and_recorded(tmp_path):
    c = sine_campaign("emcyl")
    bus = can.Bus(interface="virtual", channel=c.daq["channel"])
    drive = _EmcyOnStop(bus)
    notifier = can.Notifier(bus, [drive], timeout=0.01)
    try:
        r = run_campaign(c, out_dir=tmp_path, simulate=default_plant(), yes=True)
    finally:
        notifier.stop()
        bus.shutdown()
    assert r.ok, r.reason
    assert drive.sent == 1
    text = "node 1: EMCY 0x3210 (error register 0x05) after the run of payload 0 (its log closed)"
    assert f"  warning: {text} (in no log: recorded in emcyl.state.json)" in \
        r.summary().splitlines()
    # the closed log is as it was: no emcy event
    assert not [e for e in read_run(tmp_path / "emcyl_payload0.mcap").events
                if e["kind"] == "emcy"]
    state = json.loads((tmp_path / "emcyl.state.json").read_text())
    assert state["completed"] == [0]
    (rec,) = state["emcy_outside_logs"]
    assert {k: rec[k] for k in ("text", "node_id", "code", "error_register", "after_payload")} \
        == {"text": text, "node_id": 1, "code": "0x3210", "error_register": "0x05",
            "after_payload": 0}
    assert rec["utc"].endswith("+00:00")
    # kept from run to run: a --resume with nothing left to run keeps it, adds nothing
    again = run_campaign(c, out_dir=tmp_path, simulate=default_plant(), yes=True, resume=True)
    assert again.ok and again.skipped == (0,) and again.runs == ()
    assert not [n for n in again.notes if "EMCY" in n]
    assert json.loads((tmp_path / "emcyl.state.json").read_text())["emcy_outside_logs"] \
        == [rec]


def test_an_emcy_before_a_declined_first_payload_is_recorded(tmp_path):
    """The operator declines the first payload after the drive reported a fault at the
    prompt: no payload ran, no log was opened; the EMCY is in the summary and the state."""
    c = sine_campaign("emcyd")
    sender = can.Bus(interface="virtual", channel=c.daq["channel"])

    def prompt(index, payload, n) -> bool:
        sender.send(can.Message(arbitration_id=0x81, data=EMCY, is_extended_id=False))
        time.sleep(0.3)  # the listener takes it (its notifier polls every 50 ms)
        return False

    try:
        r = run_campaign(c, out_dir=tmp_path, simulate=default_plant(), prompt=prompt)
    finally:
        sender.shutdown()
    assert r.status == "aborted" and r.runs == ()
    text = "node 1: EMCY 0x3210 (error register 0x05) before any payload ran"
    assert f"  warning: {text} (in no log: recorded in emcyd.state.json)" in \
        r.summary().splitlines()
    assert not list(tmp_path.glob("*.mcap"))
    state = json.loads((tmp_path / "emcyd.state.json").read_text())
    assert state["completed"] == []
    assert [(e["text"], e["after_payload"]) for e in state["emcy_outside_logs"]] == \
        [(text, None)]
