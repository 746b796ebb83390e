"""``[daq]`` without interface/channel/bitrate: python-can's own configuration fills them."""

from __future__ import annotations

import itertools

import can
import can.util
import numpy as np
import pytest
from daq_campaigns import joint_campaign

from daq import ConfigError
from daq.protocol.reader import read_run
from daq.runtime.config import parse_daq
from daq.runtime.runner import run_campaign

_chan = itertools.count()


def test_defaults_without_python_can_configuration():
    cfg = parse_daq({})
    assert (cfg.interface, cfg.channel, cfg.bitrate) == ("virtual", "jointid", 1_000_000)
    assert cfg.clock == "lockstep" and cfg.from_can_config == ()


def test_environment_fills_what_daq_leaves_out(monkeypatch):
    monkeypatch.setenv("CAN_INTERFACE", "socketcan")
    monkeypatch.setenv("CAN_CHANNEL", "can3")
    monkeypatch.setenv("CAN_BITRATE", "500000")
    cfg = parse_daq({})
    assert (cfg.interface, cfg.channel, cfg.bitrate) == ("socketcan", "can3", 500_000)
    assert cfg.clock == "paced"  # a real interface: never lockstep
    assert cfg.from_can_config == ("interface", "channel", "bitrate")
    # what the table gives wins, key by key
    cfg = parse_daq({"channel": "can0"})
    assert (cfg.interface, cfg.channel, cfg.bitrate) == ("socketcan", "can0", 500_000)
    assert cfg.from_can_config == ("interface", "bitrate")
    # another interface named in the table: python-can's channel/bitrate are not its own
    cfg = parse_daq({"interface": "pcan"})
    assert (cfg.interface, cfg.channel, cfg.bitrate) == ("pcan", "jointid", 1_000_000)
    assert cfg.from_can_config == ()
    # simulated runs do not look at it
    cfg = parse_daq({}, use_can_config=False)
    assert (cfg.interface, cfg.channel) == ("virtual", "jointid")


def test_config_file_fills_what_daq_leaves_out(tmp_path, monkeypatch):
    ini = tmp_path / "can.conf"
    ini.write_text("[default]\ninterface = virtual\nchannel = from_file\nbitrate = 250000\n")
    monkeypatch.setattr(can.util, "CONFIG_FILES", [str(ini)])
    cfg = parse_daq({})
    assert (cfg.interface, cfg.channel, cfg.bitrate) == ("virtual", "from_file", 250_000)
    monkeypatch.setenv("CAN_CHANNEL", "from_env")  # the environment wins over the file
    assert parse_daq({}).channel == "from_env"


@pytest.mark.parametrize(("env", "match"), [
    ({"CAN_INTERFACE": "no_such_bus"}, r"c.toml: daq.interface: left out, and python-can's "
                                       r"configuration names an unusable interface"),
    ({"CAN_INTERFACE": "virtual", "CAN_BITRATE": "2000000"},
     r"c.toml: daq.bitrate: left out, and python-can's configuration gives 2000000"),
    ({"CAN_INTERFACE": "virtual", "CAN_CONFIG": "{not json"},
     r"c.toml: daq.interface: left out, and python-can's configuration cannot be read"),
])
def test_bad_python_can_configuration_is_one_line(monkeypatch, env, match):
    for k, v in env.items():
        monkeypatch.setenv(k, v)
    with pytest.raises(ConfigError, match=match) as ei:
        parse_daq({}, "c.toml")
    assert "\n" not in str(ei.value)


def test_campaign_without_bus_keys_runs_on_the_configured_bus(tmp_path, monkeypatch):
    """End to end: no interface/channel in [daq]; the environment names a virtual channel on
    which a simulated drive (started here, like a drive on a real bus) answers."""
    from sim_drivers.drive import SimulatedDrive
    from sim_drivers.plant import JointPlant
    from sim_drivers.plant_config import default_plant
    from sim_drivers.simbus import SimNetwork

    channel = f"fallback_{next(_chan)}"
    monkeypatch.setenv("CAN_INTERFACE", "virtual")
    monkeypatch.setenv("CAN_CHANNEL", channel)
    campaign = joint_campaign(
        "fallback", cycle_s=0.001, sine={"amplitude": 0.1, "frequency_hz": 1.0, "periods": 1},
        daq={"drives": [{"node_id": 5, "scaling": {
            "rated_torque_Nm": 5.0, "gear_ratio": 100.0, "encoder_counts_per_rev": 4096}}]})
    plant = JointPlant(default_plant(), 0.001)
    plant.reset(0.0)
    # the drive on simulated time, its channel clocked by the master's SYNCs (heartbeats
    # paced by SYNC: a loaded host is no lost heartbeat)
    sim = SimNetwork(channel, dispatch="inline", sync_cycle_s=0.001)
    drive = sim.add(SimulatedDrive(sim.network, 5, plant, cycle_s=0.001, clock="sync"))
    try:
        r = run_campaign(campaign, out_dir=tmp_path, prompt=lambda *a: True)
    finally:
        sim.close()
    assert r.ok, r.reason
    a = read_run(r.runs[0].path)
    assert a.metadata["campaign"]["interface"] == "virtual"
    assert a.metadata["campaign"]["channel"] == channel
    assert channel in a.metadata["campaign"]["bus"]
    assert drive.record["counts"].shape[0] >= r.runs[0].cycles - 2
    moving = np.flatnonzero(a.segment >= 0)
    assert np.max(np.abs(a.q - a.q_ref)[moving]) < 0.05


def test_simulated_run_ignores_python_can_configuration(tmp_path, monkeypatch):
    """--simulate runs on the virtual bus even when python-can's configuration names a
    real one (it would otherwise be refused: 'expected virtual with --simulate')."""
    from sim_drivers.plant_config import default_plant

    monkeypatch.setenv("CAN_INTERFACE", "socketcan")
    monkeypatch.setenv("CAN_CHANNEL", "can0")
    c = joint_campaign("simcfg", cycle_s=0.001,
                       sine={"amplitude": 0.1, "frequency_hz": 1.0, "periods": 1},
                       daq={"channel": f"simcfg_{next(_chan)}"})
    r = run_campaign(c, out_dir=tmp_path,
                     simulate=default_plant(), yes=True)
    assert r.ok, r.reason
    assert read_run(r.runs[0].path).metadata["campaign"]["interface"] == "virtual"
