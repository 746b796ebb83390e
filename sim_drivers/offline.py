"""Offline closed-loop simulation: the position controller driving the plant, without a bus.

Each control cycle does exactly what the bus path does (``daq`` runner + simulated drive),
minus CANopen: the measured position comes from the encoder counts, the torque reference of
:class:`daq.protocol.control.PositionController` is quantised to the per-mille target torque (int16)
that object 0x6071 would carry, and the plant is stepped one cycle with the joint-side torque
of that target, ``tau_ref = N rated_torque x / 1000``. It is the fast path for identification
tests: a 60 s run at 1 kHz takes well under a second.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from daq.protocol.control import ControllerGains, PositionController

from . import SimError
from .plant import REGIME_REST, JointPlant
from .plant_config import PlantParams


@dataclass(frozen=True)
class SimRun:
    """One simulated run, one record per control cycle (shape ``(n,)`` arrays).

    Record k holds the measurement the controller used at the start of cycle k and the
    command it sent for that cycle, like the MCAP reader's ``RunArrays``, plus the plant's truth.

    Attributes
    ----------
    t : ndarray of float
        Time of the measurement, k * cycle_s [s].
    cycle : ndarray of int64
        Cycle index k.
    counts : ndarray of int64
        Encoder reading [counts] (motor side, what 0x6064 carries).
    q : ndarray of float
        Measured joint position from the counts [rad].
    x : ndarray of int16
        Target torque sent [per-mille of rated torque] (0x6071).
    tau_ref : ndarray of float
        Joint-side torque reference of x, tau = g_f v_f (eq. 7) [N m]: what the master logs.
    tau_applied : ndarray of float
        Torque acting on the joint at the start of cycle k, after the command was applied
        (lagged command + ripple noise) [N m].
    tau_noise : ndarray of float
        Ripple-noise sample of cycle k [N m].
    q_true, dq_true, ddq_true : ndarray of float
        True state at time t [rad, rad/s, rad/s^2]; ddq_true is the acceleration right after
        the command of cycle k is applied, so that
        ``inverse_torque(params, q_true, dq_true, ddq_true, M_a, L_a, t) == tau_applied`` on
        sliding samples.
    regime : ndarray of int8
        Plant regime at time t (``sim_drivers.plant.REGIME_*``): 0 sliding, 1 at rest,
        2 sliding with zero load.
    payload_mass_kg, payload_arm_m : float
        Payload of the run.
    revolute : bool
    cycle_s : float
        Control cycle [s].
    """

    t: np.ndarray
    cycle: np.ndarray
    counts: np.ndarray
    q: np.ndarray
    x: np.ndarray
    tau_ref: np.ndarray
    tau_applied: np.ndarray
    tau_noise: np.ndarray
    q_true: np.ndarray
    dq_true: np.ndarray
    ddq_true: np.ndarray
    regime: np.ndarray
    payload_mass_kg: float
    payload_arm_m: float
    revolute: bool
    cycle_s: float

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def stuck(self) -> np.ndarray:
        """Boolean mask of the samples where the joint is at rest (dq_true == 0)."""
        return self.regime == REGIME_REST


def _cycle_from_reference(t: np.ndarray) -> float:
    if t.shape[0] < 2:
        raise SimError("reference.t: expected at least 2 samples to infer the cycle")
    dt = np.diff(t)
    c = float(np.median(dt))
    if not c > 0 or np.max(np.abs(dt - c)) > 1e-6 * c + 1e-12:
        raise SimError(f"reference.t: expected uniform sampling, got steps from "
                       f"{float(dt.min())!r} to {float(dt.max())!r} s")
    return c


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
        The reference arrays are missing, of unequal length or non-uniformly sampled.
    """
    try:
        ref_q = np.asarray(reference.q, dtype=float)
        ref_dq = np.asarray(reference.dq, dtype=float)
        ref_ddq = np.asarray(reference.ddq, dtype=float)
    except AttributeError as exc:
        raise SimError(f"reference: expected arrays q, dq, ddq ({exc})") from None
    n = ref_q.shape[0]
    if ref_dq.shape != (n,) or ref_ddq.shape != (n,) or ref_q.ndim != 1:
        raise SimError(f"reference: expected 1-D q, dq, ddq of equal length, got shapes "
                       f"{ref_q.shape}, {ref_dq.shape}, {ref_ddq.shape}")
    if cycle_s is None:
        cycle_s = _cycle_from_reference(np.asarray(reference.t, dtype=float))

    plant = JointPlant(params, cycle_s, substeps=substeps, seed=seed)
    plant.set_payload(payload_mass, payload_arm)
    plant.reset(float(ref_q[0]) if q0 is None else float(q0))
    ctrl = PositionController(gains, cycle_s, revolute=params.revolute)

    counts = np.empty(n, dtype=np.int64)
    xs = np.empty(n, dtype=np.int16)
    tau_applied = np.empty(n)
    tau_noise = np.empty(n)
    q_true = np.empty(n)
    dq_true = np.empty(n)
    ddq_true = np.empty(n)
    regime = np.empty(n, dtype=np.int8)

    cpr = params.drive.counts_per_joint_rad
    per_mille = params.drive.torque_per_permille
    update, step = ctrl.update, plant.step
    permille = plant.permille_from_torque
    rq, rdq, rddq = ref_q.tolist(), ref_dq.tolist(), ref_ddq.tolist()
    for k in range(n):
        c = round(plant.q * cpr)
        counts[k] = c
        q_true[k] = plant.q
        dq_true[k] = plant.dq
        x = permille(update(rq[k], rdq[k], rddq[k], c / cpr))
        xs[k] = x
        step(x * per_mille)
        ddq_true[k] = plant.ddq_start
        tau_applied[k] = plant.tau_applied_start
        tau_noise[k] = plant.tau_noise
        regime[k] = plant.regime_start

    cycle = np.arange(n, dtype=np.int64)
    return SimRun(
        t=cycle * cycle_s,
        cycle=cycle,
        counts=counts,
        q=counts / cpr,
        x=xs,
        tau_ref=xs.astype(float) * per_mille,
        tau_applied=tau_applied,
        tau_noise=tau_noise,
        q_true=q_true,
        dq_true=dq_true,
        ddq_true=ddq_true,
        regime=regime,
        payload_mass_kg=float(payload_mass),
        payload_arm_m=float(payload_arm),
        revolute=params.revolute,
        cycle_s=float(cycle_s),
    )


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
    runs = []
    for i, pay in enumerate(payloads):
        if hasattr(pay, "mass_kg"):
            mass, arm = pay.mass_kg, pay.arm_m
        else:
            mass, arm = pay
        runs.append(simulate(params, reference, gains, payload_mass=float(mass),
                             payload_arm=float(arm), cycle_s=cycle_s, seed=seed + i, q0=q0,
                             substeps=substeps))
    return runs
