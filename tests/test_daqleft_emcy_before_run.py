"""An EMCY received while no payload runs (left by the acquisition sweep): the runner cleared
the EMCYs queued since the start-up or the last payload before each payload started, so a
drive's report of a fault between runs (here an over-voltage, 0x3210, sent when the operator
is asked to mount the next payload) was in no log and no summary. It is now an ``emcy`` event
at cycle 0 of the next payload's log, as the in-run EMCYs are, and a warning of the run's
summary."""

from __future__ import annotations

import time
from dataclasses import replace

import can
from daq_campaigns import sine_campaign

from daq.protocol.reader import read_run
from daq.runtime.runner import run_campaign
from sim_drivers.plant_config import default_plant

#: EMCY of node 1: 0x3210 (DC link over-voltage), error register 0x05 (generic + voltage)
EMCY = bytes([0x10, 0x32, 0x05, 0, 0, 0, 0, 0])


def test_an_emcy_between_payloads_is_logged_and_reported(tmp_path):
    c = sine_campaign("emcyb")
    c = replace(c, payloads=(c.payloads[0], replace(c.payloads[0], mass_kg=1.0)))
    channel = c.daq["channel"]
    sender = can.Bus(interface="virtual", channel=channel)

    def prompt(index, payload, n) -> bool:
        if index == 1:  # the drive reports a fault while the operator mounts payload 1
            sender.send(can.Message(arbitration_id=0x81, data=EMCY, is_extended_id=False))
            time.sleep(0.3)  # the listener takes it (its notifier polls every 50 ms)
        return True

    try:
        r = run_campaign(c, out_dir=tmp_path, simulate=default_plant(), prompt=prompt)
        assert r.ok, r.reason
        after = "node 1: EMCY 0x3210 (error register 0x05) before the run of payload 1"
        assert f"  warning: {after} (logged at cycle 0 of emcyb_payload1.mcap)" in \
            r.summary().splitlines()
        ev1 = read_run(tmp_path / "emcyb_payload1.mcap").events
        assert [(e["cycle"], e["axis"], e["message"]) for e in ev1 if e["kind"] == "emcy"] \
            == [(0, 0, after)]
        ev0 = read_run(tmp_path / "emcyb_payload0.mcap").events
        assert not [e for e in ev0 if e["kind"] == "emcy"]
    finally:
        sender.shutdown()
