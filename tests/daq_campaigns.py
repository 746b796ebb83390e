"""A short single-joint campaign for the runner's log tests: one payload, 2 ms cycle, one
period of a 20 mrad sine at 2 Hz (about 1.4 s with the approach and return), on a virtual
channel of its own."""

from __future__ import annotations

import itertools
from typing import Any

from trajectories.robot_campaign import RobotCampaign

_chan = itertools.count()


def sine_campaign(name: str, **daq: Any) -> RobotCampaign:
    """The campaign ``name`` (its file name ``<name>.toml`` in messages); ``daq`` keys are
    added to (or replace) the defaults: a channel ``test_<name>_<n>``, a 50-cycle TPDO
    timeout, a 2 s heartbeat timeout, a 1 rad following-error limit."""
    raw = {
        "name": name,
        "joint": {"kind": "revolute", "limits": {
            "position": [-1.0, 1.0], "max_velocity": 1.0, "max_acceleration": 4.0,
            "max_jerk": 40.0, "max_torque": 700.0}},
        "control": {"cycle_s": 0.002, "kp": 6000.0, "kd": 200.0,
                    "feedforward": {"J": 30.0, "MX": 21.0}},
        "payloads": [{"mass_kg": 0.0, "arm_m": 1.0}],
        "segments": [{"kind": "sine", "amplitude": 0.02, "frequency_hz": 2.0, "center": 0.0,
                      "periods": 1}],
        "daq": {"channel": f"test_{name}_{next(_chan)}", "tpdo_timeout_cycles": 50,
                "heartbeat_timeout_s": 2.0, "max_following_error": 1.0, **daq},
    }
    return RobotCampaign.from_dict(raw, f"{name}.toml")
