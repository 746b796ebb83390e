"""Campaign files: the shipped example loads; every kind of mistake is one line naming the key."""

from __future__ import annotations

import dataclasses

import pytest
from daq.examples import path as example_path

from daq.protocol.control import ControllerGains
from trajectories import CampaignFileError, SchemaError
from trajectories.campaign import SineSegment, TrapezoidSweep
from trajectories.campaign_file import load_campaign

EXAMPLE = example_path("campaign.toml")
TEXT = EXAMPLE.read_text()


def test_example_loads_with_the_paper_joint_3_figures():
    c = load_campaign(EXAMPLE)
    assert c.name == "rx130l-joint3" and c.source == str(EXAMPLE)
    # a [joint] file: a robot with one moving joint, no robot file, its plant a joint's
    assert c.robot_file == "" and c.plant == "joint" and c.moving == ("joint",)
    (j,) = c.joints
    assert j.kind == "revolute" and j.revolute and j.unit == "rad" and j.key == "joint"
    assert j.drive is None  # its drives are those of [daq]
    assert j.limits.max_velocity == 1.2
    assert j.limits.position == (-1.0, 2.4)
    assert c.start == (pytest.approx(0.7),)  # default: centre of the position range
    assert [(p.mass_kg, p.arm_m, p.com) for p in c.payloads] == [
        (0.0, 1.277, (1.277, 0.0, 0.0)), (3.4584, 1.277, (1.277, 0.0, 0.0)),
        (6.970, 1.277, (1.277, 0.0, 0.0))]
    assert c.cycle_s == c.control.cycle_s == 0.001
    assert [type(s) for s in c.segments] == [TrapezoidSweep] * 3 + [SineSegment]
    assert {s.joint for s in c.segments} == {""}  # the only moving joint
    assert c.segments[0].speeds == (0.03,) and c.segments[0].range == (1.0, 2.1)
    assert c.segments[1].speeds == (0.08,) and c.segments[1].range == (-0.9, 2.3)
    assert c.daq == {}
    with pytest.raises(dataclasses.FrozenInstanceError):
        c.name = "other"  # type: ignore[misc]


def test_control_settings_convert_to_controller_gains():
    c = load_campaign(EXAMPLE)
    g = ControllerGains(**c.joints[0].gains_kwargs(c.control.velocity_cutoff_hz))
    assert (g.kp, g.kd, g.J_ff, g.MX_ff, g.MY_ff, g.Fc_ff, g.Fv_ff) == (
        20000.0, 1000.0, 31.0, 21.1, 0.0, 25.0, 40.0)
    assert g.velocity_cutoff_hz == 100.0


def test_optional_keys_start_daq_and_feedforward(tmp_path):
    daq = '[daq]\nbus = { interface = "virtual" }\n\n'
    text = TEXT.replace("# start = 0.7 ", "start = -0.5 ").replace(
        "[control.feedforward]", daq + "[control.feedforward]")
    text = text.replace("J = 31.0", "MY = -0.8").replace("Fc = 25.0", "Fc = 12.5")
    f = tmp_path / "c.toml"
    f.write_text(text)
    c = load_campaign(f)
    assert c.start == (-0.5,)
    assert c.daq == {"bus": {"interface": "virtual"}}
    assert c.joints[0].feedforward == {"J": 0.0, "MX": 21.1, "MY": -0.8, "Fc": 12.5,
                                       "Fv": 40.0}


# (what to replace in the example, replacement, key named in the message, expected text)
MISTAKES = {
    "unknown top-level key": ('name = "rx130l-joint3"', 'name = "x"\ncolour = "red"',
                              "colour", "unknown key"),
    "unknown nested key": ("J = 31.0 ", "Jm = 31.0 ", "control.feedforward.Jm", "unknown key"),
    "wrong type": ("max_velocity = 1.2 ", 'max_velocity = "fast" ',
                   "joint.limits.max_velocity", "a number > 0"),
    "boolean as number": ("cycle_s = 0.001 ", "cycle_s = true ", "control.cycle_s", "a number"),
    "float for integer": ("periods = 2", "periods = 2.5", "segments[3].periods", "an integer"),
    "missing field": ("max_torque = 700.0 ", "", "joint.limits.max_torque", "missing"),
    "missing payload field": ("mass_kg = 0.0\narm_m = 1.277", "mass_kg = 0.0",
                              "payloads[0].arm_m", "missing"),
    "negative limit": ("max_velocity = 1.2 ", "max_velocity = -1.2 ",
                       "joint.limits.max_velocity", "> 0"),
    "zero limit": ("max_jerk = 40.0 ", "max_jerk = 0 ", "joint.limits.max_jerk", "> 0"),
    "negative mass": ("mass_kg = 3.4584", "mass_kg = -3.4584", "payloads[1].mass_kg", ">= 0"),
    "inverted position range": ("position = [-1.0, 2.4]", "position = [2.4, -1.0]",
                                "joint.limits.position", "min < max"),
    "speed above 1": ("speeds = [0.08]", "speeds = [0.08, 1.5]", "segments[1].speeds[1]", "<= 1"),
    "trapezoid outside range": ("range = [-0.9, 2.3]", "range = [-1.3, 2.3]",
                                "segments[1].range", "within joint.limits.position [-1, 2.4]"),
    "inverted trapezoid range": ("range = [-0.9, 2.3]", "range = [2.3, -0.9]",
                                 "segments[1].range", "low < high"),
    "sine outside range": ("amplitude = 1.6", "amplitude = 1.8", "segments[3].amplitude",
                           "center +/- amplitude within joint.limits.position"),
    "unknown segment kind": ('kind = "sine"', 'kind = "square"', "segments[3].kind",
                             "'trapezoid', 'sine'"),
    "start outside range": ("# start = 0.7 ", "start = 2.6 ", "joint.start", "within"),
    "empty name": ('name = "rx130l-joint3"', 'name = ""', "name", "non-empty"),
}


@pytest.mark.parametrize("mistake", list(MISTAKES))
def test_each_kind_of_mistake_is_one_line_naming_the_key(tmp_path, mistake):
    old, new, key, expected = MISTAKES[mistake]
    assert old in TEXT
    f = tmp_path / "bad.toml"
    f.write_text(TEXT.replace(old, new, 1))
    with pytest.raises(SchemaError) as err:
        load_campaign(f)
    msg = str(err.value)
    assert "\n" not in msg
    assert msg.startswith(f"{f}: {key}: expected ")
    assert expected in msg


def test_toml_syntax_error_names_file_and_line(tmp_path):
    f = tmp_path / "broken.toml"
    f.write_text(TEXT.replace("kind = \"revolute\"", "kind = revolute", 1))
    line = TEXT.splitlines().index('kind = "revolute"') + 1
    with pytest.raises(CampaignFileError) as err:
        load_campaign(f)
    msg = str(err.value)
    assert msg.startswith(f"{f}: invalid TOML: ") and f"line {line}" in msg and "\n" not in msg


def test_missing_file_is_an_oserror_with_the_name(tmp_path):
    with pytest.raises(FileNotFoundError) as err:
        load_campaign(tmp_path / "nope.toml")
    assert err.value.filename == str(tmp_path / "nope.toml")
