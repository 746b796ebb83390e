"""The example campaign (examples/campaign.toml) simulated offline on the default plant, one
run per payload: the shared ground truth of the single-joint identification tests."""

from __future__ import annotations

import tomllib
from pathlib import Path

from daq.protocol.control import ControllerGains
from ident.loaders import Experiment, make_experiment
from sim_drivers.offline import SimRun, simulate
from sim_drivers.plant_config import PlantParams, load_plant
from trajectories.plan import CampaignPlan, plan_campaign
from trajectories.robot_campaign import RobotCampaign

ROOT = Path(__file__).resolve().parents[1]


def _campaign() -> RobotCampaign:
    with open(ROOT / "examples" / "campaign.toml", "rb") as fh:
        return RobotCampaign.from_dict(tomllib.load(fh), "examples/campaign.toml")


def example_gains() -> ControllerGains:
    """The example campaign's controller gains (what :func:`simulate_example_campaign` runs)."""
    return ControllerGains(**_campaign().gains_kwargs())


def simulate_example_campaign(seed0: int = 11) -> tuple[PlantParams, CampaignPlan, list[SimRun]]:
    """The default plant, the planned example campaign and one simulated run per payload
    (noise seeds seed0, seed0 + 1, ...)."""
    campaign = _campaign()
    plan = plan_campaign(campaign)
    plant = load_plant(ROOT / "sim_drivers" / "data" / "plant_default.toml")
    gains = ControllerGains(**campaign.gains_kwargs())
    runs = [simulate(plant, plan.reference, gains, payload_mass=p.mass_kg,
                     payload_arm=p.arm_m, seed=seed0 + i) for i, p in enumerate(plan.payloads)]
    return plant, plan, runs


def payload_experiments(plant: PlantParams, plan: CampaignPlan, gains: ControllerGains,
                        seed0: int, name: str = "payload{i}") -> list[Experiment]:
    """One experiment per payload of ``plan``, simulated offline on ``plant`` (noise seeds
    seed0, seed0 + 1, ...): what the measured log holds (q, tau_ref), named
    ``name.format(i=i)`` (its suffix decides the default torque delay, as a file's would)."""
    exps = []
    for i, p in enumerate(plan.payloads):
        r = simulate(plant, plan.reference, gains, payload_mass=p.mass_kg,
                     payload_arm=p.arm_m, seed=seed0 + i)
        exps.append(make_experiment(name.format(i=i), r.t, r.q, r.tau_ref,
                                    payload_mass=p.mass_kg, payload_arm=p.arm_m))
    return exps
