"""Offline closed-loop simulation: the position controller driving the plant, without a bus.

The loop is :func:`sim_drivers.closed_loop.run_closed_loop`, the same as the arm's: each
control cycle does exactly what the bus path does (``daq`` runner + simulated drive), minus
CANopen: the measured position comes from the encoder counts, the torque reference of
:class:`daq.protocol.control.PositionController` (this joint's control law) is quantised to the
per-mille target torque (int16) that object 0x6071 would carry, and the plant is stepped one
cycle with the joint-side torque of that target, ``tau_ref = N rated_torque x / 1000``. It is
the fast path for identification tests: a 60 s run at 1 kHz takes well under a second.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Any

from daq.protocol.control import ControllerGains, PositionController

from .closed_loop import (
    LoopRecord,
    cycle_period,
    per_payload,
    reference_arrays,
    run_closed_loop,
)
from .plant import JointPlant
from .plant_config import PlantParams


@dataclass(frozen=True)
class SimRun(LoopRecord):
    """One simulated run of one joint: the :class:`sim_drivers.closed_loop.LoopRecord` (arrays
    of shape ``(n,)``: ``t, cycle, counts, q, x, tau_ref, tau_applied, tau_noise, q_true,
    dq_true, ddq_true, regime, cycle_s``; ``stuck``, ``sliding``) plus the run's payload.

    ``inverse_torque(params, q_true, dq_true, ddq_true, M_a, L_a, t) == tau_applied`` on
    sliding samples.

    Attributes
    ----------
    payload_mass_kg, payload_arm_m : float
        Payload of the run.
    revolute : bool
    """

    payload_mass_kg: float
    payload_arm_m: float
    revolute: bool


def simulate(
    params: PlantParams,
    reference: Any,
    gains: ControllerGains,
    *,
    payload_mass: float = 0.0,
    payload_arm: float = 0.0,
    cycle_s: float | None = None,
    seed: int = 0,
    q0: float | None = None,
    substeps: int = 10,
) -> SimRun:
    """Run the closed loop (controller + plant) over a reference trajectory.

    Parameters
    ----------
    params : PlantParams
        The plant.
    reference : object
        Anything with equal-length float arrays ``q`` [rad], ``dq`` [rad/s], ``ddq``
        [rad/s^2] (and ``t`` [s] when ``cycle_s`` is not given), sampled once per cycle, e.g.
        ``trajectories.plan.plan_campaign(c).reference``.
    gains : daq.protocol.control.ControllerGains
        Controller gains and feed-forward.
    payload_mass, payload_arm : float
        Payload M_a [kg] at lever arm L_a [m] for the whole run.
    cycle_s : float, optional
        Control cycle [s]; default: the reference's sampling step.
    seed : int
        Seed of the applied-torque noise (same seed, same arrays).
    q0 : float, optional
        Initial position [rad]; default ``reference.q[0]``. The joint starts at rest.
    substeps : int
        Plant integration sub-steps per cycle.

    Returns
    -------
    SimRun

    Raises
    ------
    SimError
        The reference arrays are missing, of unequal length, not finite or non-uniformly
        sampled, or ``reference.t`` is missing and ``cycle_s`` not given.
    """
    ref_q, ref_dq, ref_ddq = reference_arrays(reference)
    n = ref_q.shape[0]
    cycle_s = cycle_period(reference, cycle_s)

    plant = JointPlant(params, cycle_s, substeps=substeps, seed=seed)
    plant.set_payload(payload_mass, payload_arm)
    plant.reset(float(ref_q[0]) if q0 is None else float(q0))
    update = PositionController(gains, cycle_s, revolute=params.revolute).update
    rq, rdq, rddq = ref_q.tolist(), ref_dq.tolist(), ref_ddq.tolist()

    def law(k: int, q_measured: float) -> float:
        return update(rq[k], rdq[k], rddq[k], q_measured)

    record = partial(SimRun, payload_mass_kg=float(payload_mass),
                     payload_arm_m=float(payload_arm), revolute=params.revolute)
    return run_closed_loop(plant, law, plant.permille_from_torque, n, joints=None,
                           counts_per_rad=params.drive.counts_per_joint_rad,
                           torque_per_permille=params.drive.torque_per_permille,
                           record=record)


def simulate_payloads(
    params: PlantParams,
    reference: Any,
    gains: ControllerGains,
    payloads: Any,
    *,
    cycle_s: float | None = None,
    seed: int = 0,
    q0: float | None = None,
    substeps: int = 10,
) -> list[SimRun]:
    """One :func:`simulate` run per payload, as a campaign does (paper IV.B).

    Parameters
    ----------
    payloads : iterable
        Payloads, each either an object with ``mass_kg`` and ``arm_m`` (e.g.
        ``CampaignPlan.payloads``) or a ``(mass_kg, arm_m)`` pair.
    seed : int
        Run i uses seed ``seed + i`` (independent noise per run, reproducible).

    Other parameters are those of :func:`simulate`.

    Returns
    -------
    list of SimRun
        In the order of ``payloads``; each run starts at rest with a fresh plant (warm-up
        clock at 0).
    """
    def run_one(pay: Any, seed_i: int) -> SimRun:
        mass, arm = (pay.mass_kg, pay.arm_m) if hasattr(pay, "mass_kg") else pay
        return simulate(params, reference, gains, payload_mass=float(mass),
                        payload_arm=float(arm), cycle_s=cycle_s, seed=seed_i, q0=q0,
                        substeps=substeps)

    return per_payload(run_one, payloads, seed)
