"""The ``--simulate`` rig: one simulated CiA 402 drive (:mod:`sim_drivers`) per configured
drive, each on its own python-can virtual bus of the campaign's channel."""

from __future__ import annotations

import contextlib
from dataclasses import dataclass
from typing import Any

import can

from sim_drivers.drive import SimulatedDrive
from sim_drivers.plant import JointPlant

from .config import DaqConfig, Scaling


@dataclass
class SimRig:
    drives: list[Any]
    buses: list[can.BusABC]

    def close(self) -> None:
        for d in self.drives:
            with contextlib.suppress(Exception):
                d.stop()
        for b in self.buses:
            with contextlib.suppress(Exception):
                b.shutdown()


def start_sim(cfg: DaqConfig, plant_params: Any, campaign: Any, fault_injectors: dict) -> SimRig:
    sim = SimRig([], [])
    try:
        for k, dcfg in enumerate(cfg.drives):
            bus = can.Bus(interface="virtual", channel=cfg.channel)
            sim.buses.append(bus)
            plant = JointPlant(plant_params, campaign.cycle_s,
                               seed=int(plant_params.drive.seed) + k)
            plant.reset(campaign.joint.start)
            drive = SimulatedDrive(bus, dcfg.node_id, plant, dcfg.eds,
                                   fault_injector=fault_injectors.get(dcfg.node_id),
                                   cycle_s=campaign.cycle_s)
            drive.start()
            sim.drives.append(drive)
    except Exception:
        sim.close()
        raise
    return sim


def plant_scaling(plant_params: Any) -> Scaling:
    """The drive scaling of a plant's ``[drive]`` table."""
    d = plant_params.drive
    return Scaling(float(d.rated_torque_Nm), float(d.gear_ratio), int(d.encoder_counts_per_rev),
                   float(d.rated_current_A))
