"""Several simulated drives through the whole stack: one shared simulated network per bus,
drives over two buses, and the bus budget refused before anything moves."""

from __future__ import annotations

import itertools

import can
import numpy as np
import pytest
from can.interfaces import virtual
from daq_campaigns import joint_campaign

from daq import ConfigError
from daq.protocol.reader import read_frames, read_run
from daq.runtime.runner import run_campaign
from sim_drivers.plant_config import default_plant

_chan = itertools.count()


def campaign(drives, cycle_s=0.002, clock="lockstep", channel=None, **daq):
    return joint_campaign(
        "multi", cycle_s=cycle_s, sine={"amplitude": 0.1, "frequency_hz": 1.0, "periods": 1},
        daq={"channel": channel or f"multi_{next(_chan)}", "clock": clock, "drives": drives,
             **daq})


def check_axes_equal_records(r, n):
    """Every axis's log is exactly its drive's record, cycle by cycle, nothing missing."""
    path = r.runs[0].path
    for k in range(n):
        a = read_run(path, axis=k)
        rec = r.sim_records[k]
        c0 = int(a.metadata["result"]["sync_offset"])
        idx = np.searchsorted(rec["cycle"], c0 + a.cycle)
        assert np.array_equal(rec["cycle"][idx], c0 + a.cycle)
        assert np.array_equal(a.cycle, np.arange(len(a)))
        assert not np.any(a.flags & 1), "TPDO missing"
        assert np.array_equal(a.counts, rec["counts"][idx])
        assert np.array_equal(a.statusword, rec["statusword"][idx])
        # the torque sent at cycle c is the one the drive applied at SYNC c + 1
        tpu = default_plant().drive.torque_per_permille
        x = np.round(a.tau_ref / tpu).astype(np.int64)
        assert np.array_equal(x[:-1], rec["target_torque"][idx[1:]])
        assert len(rec["cycle"]) == idx[-1] + 1  # no cycle the log does not know of
    return read_frames(path)


def test_three_drives_on_one_shared_network_lose_and_duplicate_nothing(tmp_path):
    nodes = (1, 2, 3)
    r = run_campaign(campaign([{"node_id": n} for n in nodes]), out_dir=tmp_path,
                     simulate=default_plant(), yes=True)
    assert r.ok, r.reason
    frames = check_axes_equal_records(r, 3)
    cycles = r.runs[0].cycles
    ids = frames["id"]
    # per cycle: one SYNC, one RPDO and two TPDOs per drive; no other cyclic frame
    assert (ids == 0x80).sum() == cycles
    for n in nodes:
        for cob in (0x200 + n, 0x180 + n, 0x280 + n):
            assert (ids == cob).sum() == cycles, hex(cob)


def test_drives_over_two_buses(tmp_path):
    a, b = f"bus_a_{next(_chan)}", f"bus_b_{next(_chan)}"
    sniff = {ch: can.Bus(interface="virtual", channel=ch) for ch in (a, b)}
    try:
        c = campaign([{"node_id": 1, "channel": a}, {"node_id": 2, "channel": b},
                      {"node_id": 3, "channel": a}], cycle_s=0.001, channel=a,
                     max_bus_load=0.75)
        r = run_campaign(c, out_dir=tmp_path, simulate=default_plant(), yes=True)
        assert r.ok, r.reason
        # bus a (2 drives) is the busiest: 55 + 2 x 335 bit per ms
        assert r.bus_load.channel == a and r.bus_load.frames_per_cycle == 7
        check_axes_equal_records(r, 3)
        md = read_run(r.runs[0].path).metadata
        assert [md[f"drive{k}"]["channel"] for k in range(3)] == [a, b, a]
        seen = {}
        for ch, bus in sniff.items():
            ids = set()
            while (m := bus.recv(0.0)) is not None:
                ids.add(m.arbitration_id)
            seen[ch] = ids
        cyclic = {0x200, 0x180, 0x280}
        on = {ch: {cid & 0x7F for cid in ids if cid & 0x780 in cyclic} for ch, ids in
              seen.items()}
        assert on == {a: {1, 3}, b: {2}}  # each drive's PDOs on its own bus only
        assert 0x80 in seen[a] and 0x80 in seen[b]  # a SYNC on each bus
    finally:
        for bus in sniff.values():
            bus.shutdown()


@pytest.mark.parametrize("clock", ["lockstep", "paced"])
def test_campaign_over_the_bus_budget_is_refused_before_anything_moves(tmp_path, clock):
    ch = f"budget_{next(_chan)}"
    c = campaign([{"node_id": n} for n in range(1, 7)], cycle_s=0.001, clock=clock, channel=ch)
    with pytest.raises(ConfigError) as exc:
        run_campaign(c, out_dir=tmp_path / "logs", simulate=default_plant(), yes=True)
    msg = str(exc.value)
    assert "\n" not in msg
    assert msg == ("multi.toml: daq.max_bus_load: cyclic traffic needs 19 frames/cycle, 2065 "
                   f"bit/cycle, 206.5 % of 1000 kbit/s at 1 ms (bus '{ch}', 6 drives) > allowed"
                   " 60 %; lower the rate to <= 290 Hz (control.cycle_s >= 0.003442 s) or "
                   "spread the drives over 6 buses (1 drive per bus fit at 1000 Hz)")
    assert ch not in virtual.channels  # no bus was opened, no drive started
    assert not list(tmp_path.iterdir())  # no output folder, no log, no state file
