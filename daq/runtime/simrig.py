"""The ``--simulate`` rig: one simulated CiA 402 drive (:mod:`sim_drivers`) per configured
drive, all the drives of a channel on ONE :class:`sim_drivers.simbus.SimNetwork`.

Why one shared network per channel: python-can's ``VirtualBus`` deep-copies every frame to every
other bus object of the channel and each bus object has its own notifier thread, so one bus per
drive made a lockstep cycle O(n^2) in the number of drives (copies and thread wake-ups). With the
lockstep clock the drives run inline in the master's ``send`` (no thread hand-off at all); with
the paced clock one notifier thread serves all the drives of a channel, like real drives
answering in parallel with the master. The master's side (``daq.runtime.buses.open_buses``) is
its ordinary code on a queued bus of the same channel.

With the lockstep clock the rig runs on simulated time (:mod:`sim_drivers.simbus`, "Simulated
time"): each channel is clocked by the master's SYNCs (``sync_cycle_s`` = the campaign's
cycle), the drives' watchdogs run on that time (``clock="sync"``) and every heartbeat on the
channel -- the drives' and the master's -- is sent every so many SYNCs, so a loaded host
cannot make a heartbeat late and the run does not depend on the machine's speed.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from sim_drivers.drive import TORQUE_DELAY_CYCLES as DRIVE_TORQUE_DELAY
from sim_drivers.drive import SimulatedDrive
from sim_drivers.plant import JointPlant
from sim_drivers.simbus import SimNetwork

from .config import DaqConfig, Scaling


@dataclass
class SimRig:
    """The simulated drives (in ``cfg.drives`` order) and their networks (one per channel)."""

    drives: list[Any] = field(default_factory=list)
    networks: dict[str, SimNetwork] = field(default_factory=dict)
    #: the timing of the logs of these drives [cycles] (``DaqConfig.torque_delay_cycles``)
    torque_delay_cycles: float = DRIVE_TORQUE_DELAY

    def set_payload(self, payload: Any) -> None:
        """Mount a campaign payload (its mass [kg] at its lever arm ``arm_m`` [m]) on every
        drive's joint plant."""
        for d in self.drives:
            d.set_payload(payload.mass_kg, payload.arm_m)

    def close(self) -> None:
        """Stop every drive, then every network's notifier and bus (idempotent)."""
        for net in self.networks.values():
            net.close()


def start_sim(cfg: DaqConfig, plant_params: Any, campaign: Any, fault_injectors: dict) -> SimRig:
    """Start one simulated drive per ``cfg.drives`` entry, each with its own
    :class:`~sim_drivers.plant.JointPlant` (seed ``plant.drive.seed + k``) at the start
    position of the campaign's one moving joint (its ``plant`` is ``"joint"``), on the
    :class:`SimNetwork` of its channel (lockstep clock: ``"inline"`` dispatch, the channel
    clocked by SYNC and the drives on the ``"sync"`` clock; paced clock: one notifier thread
    per channel, wall-clock drives)."""
    lockstep = cfg.clock == "lockstep"
    sim = SimRig()
    try:
        for ch in cfg.channels:
            sim.networks[ch] = (SimNetwork(ch, dispatch="inline", sync_cycle_s=campaign.cycle_s)
                                if lockstep else SimNetwork(ch, dispatch="thread"))
        for k, dcfg in enumerate(cfg.drives):
            plant = JointPlant(plant_params, campaign.cycle_s,
                               seed=int(plant_params.drive.seed) + k)
            plant.reset(campaign.start[0])
            net = sim.networks[dcfg.channel or cfg.channel]
            drive = SimulatedDrive(net.network, dcfg.node_id, plant, dcfg.eds,
                                   fault_injector=fault_injectors.get(dcfg.node_id),
                                   cycle_s=campaign.cycle_s,
                                   clock="sync" if lockstep else "wall")
            sim.drives.append(net.add(drive))
    except Exception:
        sim.close()
        raise
    return sim


def plant_scaling(plant_params: Any) -> Scaling:
    """The drive scaling of a plant's ``[drive]`` table."""
    d = plant_params.drive
    return Scaling(float(d.rated_torque_Nm), float(d.gear_ratio), int(d.encoder_counts_per_rev),
                   float(d.rated_current_A))
