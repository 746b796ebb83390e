"""The runner tests' single-joint campaign (``joint_campaign``: one joint, one sine segment),
and the log tests' short one (``sine_campaign``: one payload, 2 ms cycle, one period of a
20 mrad sine at 2 Hz, about 1.4 s with the approach and return, on a virtual channel of its
own)."""

from __future__ import annotations

import itertools
from typing import Any

from trajectories.robot_campaign import RobotCampaign

_chan = itertools.count()


def joint_campaign(name: str, *, cycle_s: float, sine: dict[str, float],
                   daq: dict[str, Any], payload_masses: tuple[float, ...] = (0.0,),
                   source: str | None = None) -> RobotCampaign:
    """The single-joint test campaign ``name`` (``source``, default ``<name>.toml``, in
    messages): the same joint
    and PD gains in every runner test, payloads of ``payload_masses`` [kg] at 1 m, one sine
    segment (``sine``: amplitude [rad], frequency_hz, periods; centred on 0) and the
    ``[daq]`` table ``daq`` as given."""
    raw = {
        "name": name,
        "joint": {"kind": "revolute", "limits": {
            "position": [-1.0, 1.0], "max_velocity": 1.0, "max_acceleration": 4.0,
            "max_jerk": 40.0, "max_torque": 700.0}},
        "control": {"cycle_s": cycle_s, "kp": 6000.0, "kd": 200.0,
                    "feedforward": {"J": 30.0, "MX": 21.0}},
        "payloads": [{"mass_kg": m, "arm_m": 1.0} for m in payload_masses],
        "segments": [{"kind": "sine", "center": 0.0, **sine}],
        "daq": daq,
    }
    return RobotCampaign.from_dict(raw, source or f"{name}.toml")


def joint_toml(name: str, *, cycle_s: float) -> str:
    """The head of ``joint_campaign``'s file as TOML (name, the joint and its limits, the PD
    gains, no feed-forward), for tests of the CLI; the payloads, segments and ``[daq]``
    tables follow it."""
    return (f'name = "{name}"\n[joint]\nkind = "revolute"\n[joint.limits]\n'
            'position = [-1.0, 1.0]\nmax_velocity = 1.0\nmax_acceleration = 4.0\n'
            'max_jerk = 40.0\nmax_torque = 700.0\n'
            f'[control]\ncycle_s = {cycle_s}\nkp = 6000.0\nkd = 200.0\n')


def sine_toml(name: str, channel: str, *, masses: tuple[float, ...] = (0.0,),
              periods: int = 1) -> str:
    """A whole CLI campaign file: :func:`joint_toml` (2 ms cycle), one payload per mass [kg]
    at 1 m, a 0.02 rad 2 Hz sine of ``periods`` periods, the ``[daq]`` ``channel``."""
    pays = "".join(f"[[payloads]]\nmass_kg = {m}\narm_m = 1.0\n" for m in masses)
    return (joint_toml(name, cycle_s=0.002) + pays
            + '[[segments]]\nkind = "sine"\namplitude = 0.02\nfrequency_hz = 2.0\n'
            f'center = 0.0\nperiods = {periods}\n[daq]\nchannel = "{channel}"\n')


def sine_campaign(name: str, **daq: Any) -> RobotCampaign:
    """The campaign ``name`` (its file name ``<name>.toml`` in messages); ``daq`` keys are
    added to (or replace) the defaults: a channel ``test_<name>_<n>``, a 50-cycle TPDO
    timeout, a 2 s heartbeat timeout, a 1 rad following-error limit."""
    return joint_campaign(
        name, cycle_s=0.002, sine={"amplitude": 0.02, "frequency_hz": 2.0, "periods": 1},
        daq={"channel": f"test_{name}_{next(_chan)}", "tpdo_timeout_cycles": 50,
             "heartbeat_timeout_s": 2.0, "max_following_error": 1.0, **daq})
