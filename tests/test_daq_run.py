"""Full campaigns through the whole stack on python-can's virtual bus (simulated drives)."""

from __future__ import annotations

import itertools
import math

import can
import numpy as np
import pytest
from daq_campaigns import joint_campaign

from daq import ConfigError
from daq.protocol.cia402 import State, state_from_statusword
from daq.protocol.reader import list_runs, read_attachments, read_frames, read_run
from daq.runtime.runner import run_campaign
from sim_drivers.plant_config import default_plant
from tests.conftest import VENDOR_EDS, shared_path
from trajectories.plan import plan_campaign

_chan = itertools.count()


def small_campaign(n_payloads=3, daq=None, periods=1, freq=0.5, amplitude=0.3, name="small",
                   cycle_s=0.001):
    return joint_campaign(
        name, cycle_s=cycle_s,
        sine={"amplitude": amplitude, "frequency_hz": freq, "periods": periods},
        payload_masses=tuple(3.0 * k for k in range(n_payloads)),
        daq={"channel": f"test_run_{next(_chan)}", **(daq or {})}, source="small.toml")


def drive_cycles(result, run):
    """Index into the simulated drive's record of every logged cycle of ``run``."""
    a = read_run(run.path)
    c0 = int(a.metadata["result"]["sync_offset"])
    rec = result.sim_records[0]
    idx = np.searchsorted(rec["cycle"], c0 + a.cycle)
    assert np.array_equal(rec["cycle"][idx], c0 + a.cycle)
    assert not np.any(a.flags & 1), f"TPDO missing at cycles {a.cycle[(a.flags & 1) > 0]}"
    return a, rec, idx


def test_three_payload_campaign_logs_every_cycle_and_matches_the_drive(tmp_path):
    c = small_campaign()
    result = run_campaign(c, out_dir=tmp_path, simulate=default_plant(), yes=True)
    assert result.ok, result.reason
    paths = list_runs(tmp_path)
    assert [p.name for p in paths] == [f"small_payload{k}.mcap" for k in range(3)]
    plant = default_plant()
    per_unit = plant.drive.torque_per_permille
    for k, run in enumerate(result.runs):
        a, rec, idx = drive_cycles(result, run)
        assert not a.truncated
        assert a.cycle[0] == 0 and np.array_equal(a.cycle, np.arange(len(a)))  # no gaps
        assert len(a) == run.cycles
        assert a.payload_mass_kg == 3.0 * k and a.payload_arm_m == 1.0
        # positions: exactly the counts the drive sent, scaled as in docs/architecture.md
        assert np.array_equal(a.counts, rec["counts"][idx])
        assert np.array_equal(a.q, a.counts * (2 * math.pi / (4096 * 100.0)))
        # current reference of cycle k is what the drive latched and applied at SYNC k+1
        x = np.round(a.tau_ref / per_unit).astype(np.int64)
        assert np.array_equal(x[:-1], rec["target_torque"][idx[1:]])
        assert np.allclose(a.tau_ref, x * per_unit)
        # it tracked the plan: the setpoint channel lines up with the reference
        moving = a.segment >= 0
        c_ref = plan_campaign(c).reference.q
        assert moving.sum() == len(c_ref)
        assert np.array_equal(a.q_ref[moving], c_ref)
        assert np.max(np.abs(a.q - a.q_ref)[moving]) < 0.05
        # valid cycles: the drive was enabled; they cover the whole plan
        v = a.valid_only()
        assert len(v) < len(a) and np.all(v.statusword & 0x6F == 0x27)
        assert np.all(moving <= a.valid) and np.array_equal(v.cycle, a.cycle[a.valid])
        # ended disabled, said so
        assert state_from_statusword(int(a.statusword[-1])) is State.READY_TO_SWITCH_ON
        assert any(e["message"] == "drives disabled" for e in a.events)
        md = a.metadata
        assert md["campaign"]["name"] == "small" and md["drive0"]["mode"] == "cst"
        assert md["software"]["jointid"]
        assert md["result"]["status"] == "done"
    frames = read_frames(result.runs[0].path)
    ids = set(frames["id"].tolist())
    assert {0x80, 0x201, 0x181, 0x281} <= ids  # SYNC, RPDO1, TPDO1, TPDO2
    assert (frames["id"] == 0x80).sum() == result.runs[0].cycles
    att = read_attachments(result.runs[0].path)
    assert "jointid_cia402.eds" in att


def test_resume_skips_completed_payloads(tmp_path):
    c = small_campaign(n_payloads=2, periods=1, freq=1.0, amplitude=0.1)
    first = run_campaign(c, out_dir=tmp_path, simulate=default_plant(), yes=True, payloads=[0])
    assert first.ok and [r.index for r in first.runs] == [0]
    again = run_campaign(c, out_dir=tmp_path, simulate=default_plant(), yes=True, resume=True)
    assert again.ok and [r.index for r in again.runs] == [1] and again.skipped == (0,)


def test_operator_prompt_between_payloads_can_abort(tmp_path):
    c = small_campaign(n_payloads=2, periods=1, freq=1.0, amplitude=0.1)
    asked = []

    def prompt(i, p, n):
        asked.append(i)
        return i == 0

    r = run_campaign(c, out_dir=tmp_path, simulate=default_plant(), prompt=prompt)
    assert asked == [0, 1]
    assert r.status == "aborted" and "payload 1" in r.reason and len(r.runs) == 1


def test_three_drives_lockstep(tmp_path):
    # 3 drives x (SYNC share + RPDO + 2 TPDOs) need 106 % of 1 Mbit/s at 1 kHz: 500 Hz
    c = small_campaign(n_payloads=1, periods=1, freq=1.0, amplitude=0.1, cycle_s=0.002, daq={
        "drives": [{"node_id": n} for n in (1, 2, 3)]})
    r = run_campaign(c, out_dir=tmp_path, simulate=default_plant(), yes=True)
    assert r.ok, r.reason
    axes = [read_run(r.runs[0].path, axis=k) for k in range(3)]
    for k, a in enumerate(axes):
        rec = r.sim_records[k]
        c0 = int(a.metadata["result"]["sync_offset"])
        idx = np.searchsorted(rec["cycle"], c0 + a.cycle)
        assert np.array_equal(a.counts, rec["counts"][idx])
        assert np.array_equal(a.cycle, np.arange(len(a)))


def test_bus_load_over_the_limit_is_refused(tmp_path):
    c = small_campaign(n_payloads=1, daq={"bitrate": 250000})
    with pytest.raises(ConfigError, match=r"daq.max_bus_load: cyclic traffic needs .*156\.0 %"):
        run_campaign(c, out_dir=tmp_path, simulate=default_plant(), yes=True)
    assert not list(tmp_path.glob("*.mcap"))


def test_unknown_node_is_refused(tmp_path):
    # a virtual bus with nobody on it: the start-up sequence refuses at the first SDO
    c = small_campaign(n_payloads=1, daq={"drives": [{"node_id": 7}]})
    with pytest.raises(ConfigError, match="node 7: no answer to SDO"):
        run_campaign(c, out_dir=tmp_path, yes=True)
    assert not list(tmp_path.glob("*.mcap"))


@pytest.mark.parametrize("name", VENDOR_EDS)
def test_vendor_eds_campaign(tmp_path, name):
    """Three payloads against the simulated drive serving each vendor file (CST ones)."""
    eds = shared_path("eds", name)
    c = small_campaign(n_payloads=3, periods=1, freq=1.0, amplitude=0.1,
                       daq={"drives": [{"node_id": 1, "eds": str(eds)}]})
    if name.startswith("ingenia"):
        with pytest.raises(ConfigError, match="does not support cyclic_sync_torque"):
            run_campaign(c, out_dir=tmp_path, simulate=default_plant(), yes=True)
        return
    r = run_campaign(c, out_dir=tmp_path, simulate=default_plant(), yes=True)
    assert r.ok, r.reason
    assert len(r.runs) == 3
    per_unit = default_plant().drive.torque_per_permille
    for run in r.runs:
        a, rec, idx = drive_cycles(r, run)
        assert np.array_equal(a.cycle, np.arange(len(a)))
        assert np.array_equal(a.counts, rec["counts"][idx])
        x = np.round(a.tau_ref / per_unit).astype(np.int64)
        assert np.array_equal(x[:-1], rec["target_torque"][idx[1:]])
        assert read_attachments(run.path).keys() >= {eds.name}


def test_csp_mode_sends_position_targets(tmp_path):
    c = small_campaign(n_payloads=1, periods=1, freq=1.0, amplitude=0.1,
                       daq={"drives": [{"node_id": 1, "mode": "csp"}]})
    r = run_campaign(c, out_dir=tmp_path, simulate=default_plant(), yes=True)
    assert r.ok, r.reason
    a, rec, idx = drive_cycles(r, r.runs[0])
    assert a.metadata["drive0"]["mode"] == "csp"
    assert np.all(np.isnan(a.tau_ref))  # the drive computes the torque in CSP
    assert np.all(rec["mode"] == 8)
    # the target of cycle k (planned position in counts) is what the drive applied at k+1
    cpr = 4096 * 100.0 / (2 * math.pi)
    moving = np.flatnonzero(a.segment >= 0)
    target = np.round(a.q_ref[moving] * cpr).astype(np.int64)
    assert np.array_equal(rec["target_position"][idx[moving + 1]], target)
    assert np.max(np.abs(a.q - a.q_ref)[moving]) < 0.05


def test_hardware_path_with_python_can_configuration(tmp_path, monkeypatch):
    """No --simulate: the bus comes from python-can's own configuration (environment), the
    scaling from [daq.drives.scaling], the operator confirms every payload, and the drive is
    whatever answers on the bus (here a simulated drive started by the test)."""
    from sim_drivers.drive import SimulatedDrive
    from sim_drivers.plant import JointPlant

    channel = f"test_hw_{next(_chan)}"
    monkeypatch.setenv("CAN_INTERFACE", "virtual")
    monkeypatch.setenv("CAN_CHANNEL", channel)
    plant = JointPlant(default_plant(), 0.001)
    plant.reset(0.0)
    bus = can.Bus(interface="virtual", channel=channel)
    drive = SimulatedDrive(bus, 4, plant, cycle_s=0.001)
    drive.start()
    try:
        # no heartbeats: a drive in its own right (wall clock) in this process, watched by a
        # lockstep master, could time out on a loaded host; the watchdogs are tested in
        # test_safety_drive.py, test_safety_run.py and test_sim_clock.py
        c = small_campaign(n_payloads=2, periods=1, freq=1.0, amplitude=0.1, daq={
            "interface": "config", "clock": "lockstep", "master_heartbeat_ms": 0,
            "drives": [{"node_id": 4, "heartbeat_ms": 0, "scaling": {
                "rated_torque_Nm": 5.0, "gear_ratio": 100.0,
                "encoder_counts_per_rev": 4096}}]})
        asked = []

        def prompt(i, p, n):
            asked.append(i)
            drive.set_payload(p.mass_kg, p.arm_m)  # the operator mounts it
            return True

        r = run_campaign(c, out_dir=tmp_path, prompt=prompt)
    finally:
        drive.stop()
        bus.shutdown()
    assert r.ok, r.reason
    assert asked == [0, 1]  # on hardware the first payload is confirmed too
    rec = drive.record
    for run in r.runs:
        a = read_run(run.path)
        assert a.metadata["drive0"]["node_id"] == "4"
        assert "plant" not in a.metadata
        assert channel in a.metadata["campaign"]["bus"]  # the bus python-can's config opened
        c0 = int(a.metadata["result"]["sync_offset"])
        assert c0 == -1  # unknown without a simulated drive of our own
        # align on the drive's record by the counts sequence of the moving part
        moving = np.flatnonzero(a.segment >= 0)
        assert np.max(np.abs(a.q - a.q_ref)[moving]) < 0.05
    assert rec["counts"].shape[0] >= sum(run.cycles for run in r.runs) - 2
