"""What the campaign (:class:`~trajectories.robot_campaign.RobotCampaign`, the one campaign
type) says about the drives and the simulated plant of a run.

- :func:`robot_daq_config`: the ``[daq]`` table with one drive per moving joint, in the
  order of ``robot.moving`` -- node id and bus (channel) from ``[robot.joints.<name>].drive``;
  ``[[daq.drives]]`` entries, when given, are matched by node id and add the drive's EDS,
  mode, heartbeat and scaling (one naming a node id of no joint is refused). Node ids must be
  unique over all buses (the master routes frames by node id). A joint without a drive of
  its own (a ``[joint]`` file: one moving joint, no robot file) is followed by every drive
  of ``[daq]`` as written (default one drive, node 1).
- :func:`sim_params`, :func:`sim_scalings`: the simulated plant the campaign asks for
  (:attr:`RobotCampaign.plant`): ``"arm"``, :func:`arm_truth` (``ArmParams.from_robot`` of
  the campaign's robot file with its moving and locked joints, the ground truth) and
  :func:`arm_scalings` its drive chains; ``"joint"``, the plant file's
  :class:`~sim_drivers.plant_config.PlantParams` and its ``[drive]`` scaling on every drive.
- :func:`start_arm_sim`: :class:`sim_drivers.arm_bus.ArmOnBus` -- one arm behind k
  simulated CiA 402 drives (real canopen nodes) on the simulated channels of the joints'
  buses, stepping together on SYNC, at the campaign's start pose (a ``"joint"`` plant:
  :func:`daq.runtime.simrig.start_sim`, one joint plant per drive).
- :func:`robot_metadata`: the ``robot`` metadata record (robot file, joints, buses).
"""

from __future__ import annotations

import json
from typing import Any

from daq import ConfigError
from sim_drivers.arm import ArmParams, Payload
from sim_drivers.arm_bus import TORQUE_DELAY_CYCLES as ARM_TORQUE_DELAY
from sim_drivers.arm_bus import ArmOnBus
from trajectories.robot_campaign import RobotCampaign
from trajectories.robot_model import robot_file_path, robot_for_campaign

from .config import DaqConfig, Scaling, parse_daq
from .simrig import SimRig, plant_scaling

__all__ = ["arm_scalings", "arm_truth", "robot_daq_config", "robot_metadata", "sim_params",
           "sim_scalings", "start_arm_sim"]


def robot_daq_config(campaign: RobotCampaign, *, use_can_config: bool = True) -> DaqConfig:
    """``[daq]`` of a campaign with one drive per moving joint, or every drive of ``[daq]``
    on a joint without a drive of its own (module docstring).

    Raises
    ------
    daq.ConfigError
        A node id used on two buses, a ``[[daq.drives]]`` entry of no joint (or on another
        bus than its joint's), or any ``[daq]`` error (one line naming the file and key).
    """
    src = str(campaign.source)
    if any(j.drive is None for j in campaign.joints):  # (a [joint] file: one joint)
        return parse_daq(campaign.daq, src, use_can_config=use_can_config)
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


def sim_params(campaign: RobotCampaign, simulate: Any) -> Any:
    """The parameters of the simulated plant the campaign asks for (:attr:`RobotCampaign.plant`).

    Parameters
    ----------
    campaign : RobotCampaign
    simulate : ArmParams, PlantParams or True
        ``run_campaign``'s ``simulate``: True for :func:`arm_truth` of the robot file.

    Raises
    ------
    daq.ConfigError
        A ``"joint"`` plant (no robot file) without a plant file, an ``"arm"`` with one.
    """
    if campaign.plant == "arm":
        if simulate is True:
            return arm_truth(campaign)
        if not isinstance(simulate, ArmParams):
            raise ConfigError(f"{campaign.source}: --simulate: a robot campaign is simulated "
                              f"from its robot file (ArmParams), got a plant file")
        return simulate
    if simulate is True or isinstance(simulate, ArmParams):
        raise ConfigError(f"{campaign.source}: --simulate: expected a plant file for a "
                          f"single-joint campaign")
    return simulate


def sim_scalings(campaign: RobotCampaign, params: Any, n_drives: int) -> list[Scaling]:
    """The drive scaling of each of ``n_drives`` drives of the simulated plant ``params``
    (:func:`sim_params`): the arm's drive chains, or the plant file's ``[drive]`` on each."""
    if campaign.plant == "arm":
        return arm_scalings(params)
    return [plant_scaling(params)] * n_drives


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
    nodes = [d.node_id for d in cfg.drives]
    if set(fault_injectors) - set(nodes):
        raise ConfigError(f"{campaign.source}: --simulate: fault injectors for nodes "
                          f"{sorted(set(fault_injectors) - set(nodes))}, not the campaign's "
                          f"drives {nodes}")
    arm = ArmOnBus(params, cfg.drives[0].channel or cfg.channel,
                   [d.node_id for d in cfg.drives],
                   channels=[d.channel or cfg.channel for d in cfg.drives],
                   cycle_s=campaign.cycle_s, eds=cfg.drives[0].eds, seed=seed,
                   q0=list(campaign.start), dispatch=dispatch,
                   fault_injectors=fault_injectors)
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
