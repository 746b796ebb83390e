"""What a robot campaign (``[robot]``, :mod:`trajectories.robot_campaign`) changes in a run:
the drives come from the joints, the plan has one column per joint, and ``--simulate`` puts
one simulated arm behind all the drives.

- :func:`robot_daq_config`: the ``[daq]`` table with one drive per moving joint, in the
  order of ``robot.moving`` -- node id and bus (channel) from ``[robot.joints.<name>].drive``;
  ``[[daq.drives]]`` entries, when given, are matched by node id and add the drive's EDS,
  mode, heartbeat and scaling (one naming a node id of no joint is refused). Node ids must be
  unique over all buses (the master routes frames by node id).
- :func:`arm_truth`: the simulated ground truth, ``ArmParams.from_robot`` of the campaign's
  robot file with its moving and locked joints; :func:`arm_scalings` its drive chains.
- :func:`start_arm_sim`: :class:`sim_drivers.arm_bus.ArmOnBus` -- one arm behind k
  simulated CiA 402 drives (real canopen nodes) on the simulated channels of the joints'
  buses, stepping together on SYNC, at the campaign's start pose.
- :func:`robot_metadata`: the ``robot`` metadata record (robot file, joints, buses).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

from daq import ConfigError
from sim_drivers.arm import ArmParams, Payload
from sim_drivers.arm_bus import TORQUE_DELAY_CYCLES as ARM_TORQUE_DELAY
from sim_drivers.arm_bus import ArmOnBus
from trajectories.robot_campaign import RobotCampaign
from trajectories.robot_model import robot_file_path, robot_for_campaign

from .config import DaqConfig, Scaling, parse_daq
from .simrig import SimRig

__all__ = ["arm_scalings", "arm_truth", "robot_daq_config", "robot_metadata",
           "start_arm_sim"]


def robot_daq_config(campaign: RobotCampaign, *, use_can_config: bool = True) -> DaqConfig:
    """``[daq]`` of a robot campaign with one drive per moving joint (module docstring).

    Raises
    ------
    daq.ConfigError
        A node id used on two buses, a ``[[daq.drives]]`` entry of no joint (or on another
        bus than its joint's), or any ``[daq]`` error (one line naming the file and key).
    """
    src = str(campaign.source)
    raw = dict(campaign.daq or {})
    given = raw.pop("drives", None) or []
    if not isinstance(given, list) or not all(isinstance(d, dict) for d in given):
        raise ConfigError(f"{src}: daq.drives: expected an array of tables [[daq.drives]]")
    by_node: dict[int, tuple[int, dict]] = {}
    for i, d in enumerate(given):
        by_node[d.get("node_id")] = (i, d)  # type: ignore[index]
    seen: dict[int, str] = {}
    drives = []
    for j in campaign.joints:
        nid, bus = j.drive.node_id, j.drive.bus
        if nid in seen:
            raise ConfigError(f"{src}: robot.joints.{j.name}.drive.node_id: expected a node id "
                              f"unique over all buses (the master routes by node id), got "
                              f"{nid}, also the node of {seen[nid]}")
        seen[nid] = j.name
        entry = {"node_id": nid, "channel": bus}
        if nid in by_node:
            i, d = by_node.pop(nid)
            if d.get("channel", bus) != bus:
                raise ConfigError(f"{src}: daq.drives[{i}].channel: expected {bus!r} (the bus "
                                  f"of robot.joints.{j.name}.drive), got {d['channel']!r}")
            entry = {**d, **entry}
        drives.append(entry)
    for nid, (i, _) in by_node.items():
        raise ConfigError(f"{src}: daq.drives[{i}].node_id: expected the node id of a moving "
                          f"joint ({', '.join(str(n) for n in seen)}), got {nid!r}")
    raw["drives"] = drives
    raw.setdefault("channel", campaign.joints[0].drive.bus)
    return parse_daq(raw, src, use_can_config=use_can_config)


def arm_truth(campaign: RobotCampaign, seed: int = 0) -> ArmParams:
    """Ground truth of a simulated run: ``ArmParams.from_robot`` of the campaign's robot
    (default friction, drives and rotor inertias of the robot file; ``seed`` for the
    configurations the default loads are computed on)."""
    return ArmParams.from_robot(robot_for_campaign(campaign), seed=seed)


def arm_scalings(params: ArmParams) -> list[Scaling]:
    """The drive scaling of each joint of a simulated arm (``ArmParams.drive``)."""
    d = params.drive
    return [Scaling(float(d.rated_torque_Nm[j]), float(d.gear_ratio[j]),
                    int(d.encoder_counts_per_rev[j])) for j in range(params.k)]


def with_scalings(cfg: DaqConfig, scalings: Sequence[Scaling]) -> DaqConfig:
    """The same configuration with drive k's scaling replaced by ``scalings[k]``."""
    return replace(cfg, drives=tuple(replace(d, scaling=s)
                                     for d, s in zip(cfg.drives, scalings, strict=True)))


class ArmRig(SimRig):
    """The ``--simulate`` rig of a robot campaign: one :class:`ArmOnBus`."""

    def __init__(self, arm: ArmOnBus) -> None:
        super().__init__(drives=list(arm.drives), networks=dict(arm.sims),
                         torque_delay_cycles=ARM_TORQUE_DELAY)
        self.arm = arm

    def set_payload(self, payload: Any) -> None:
        """Mount a campaign payload (``RobotPayload``) on the flange (frame of the last
        moving joint); the arm keeps its state."""
        p = Payload.coerce(payload)
        self.arm.set_payload(p if p is not None and p.mass > 0 else None)

    def close(self) -> None:
        self.arm.close()


def start_arm_sim(cfg: DaqConfig, params: ArmParams, campaign: RobotCampaign,
                  fault_injectors: dict, *, seed: int = 0) -> ArmRig:
    """One :class:`ArmOnBus` behind the drives of ``cfg`` (one per joint, each on its
    channel), at the campaign's start pose; ``"inline"`` dispatch and simulated time (drives
    and heartbeats paced by SYNC, :mod:`daq.runtime.simrig`) for the lockstep clock."""
    if params.k != len(cfg.drives):
        raise ConfigError(f"{campaign.source}: --simulate: the arm has {params.k} moving "
                          f"joints, the campaign {len(cfg.drives)} drives")
    dispatch = "inline" if cfg.clock == "lockstep" else "thread"
    if fault_injectors:
        raise ConfigError(f"{campaign.source}: --simulate: fault injectors are not supported "
                          f"with a simulated arm")
    arm = ArmOnBus(params, cfg.drives[0].channel or cfg.channel,
                   [d.node_id for d in cfg.drives],
                   channels=[d.channel or cfg.channel for d in cfg.drives],
                   cycle_s=campaign.cycle_s, eds=cfg.drives[0].eds, seed=seed,
                   q0=list(campaign.start), dispatch=dispatch)
    return ArmRig(arm)


def robot_metadata(campaign: RobotCampaign) -> dict[str, str]:
    """The ``robot`` metadata record of a robot campaign's run log (the payload is in the
    ``payload`` record: ``mass_kg``, ``com_m``, ``inertia_kgm2``)."""
    return {
        "file": robot_file_path(campaign),
        "joints": json.dumps(list(campaign.moving)),
        "locked": json.dumps(dict(campaign.locked)),
        "kinds": json.dumps([j.kind for j in campaign.joints]),
        "node_ids": json.dumps([j.drive.node_id for j in campaign.joints]),
        "buses": json.dumps([j.drive.bus for j in campaign.joints]),
        "start": json.dumps(list(campaign.start)),
        "position_limits": json.dumps([list(j.limits.position) for j in campaign.joints]),
        "gains": json.dumps({j.name: {"kp": j.kp, "kd": j.kd} for j in campaign.joints}),
    }
