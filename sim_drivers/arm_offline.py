"""Offline closed-loop simulation of the n-dof arm: position controller + drives + plant.

The loop is :func:`sim_drivers.closed_loop.run_closed_loop`, the same as the single joint's
(:mod:`sim_drivers.offline`); only the plant (:class:`sim_drivers.arm_plant.ArmPlant`) and the
control law differ. Each control cycle, per joint: the measured position comes from the encoder
counts, the torque reference of ``daq.protocol.control.PDLaw`` (the PD law of the single
joint's ``PositionController``, on arrays (k,): velocity from the backward difference of the
measured position, low-passed at ``velocity_cutoff_hz``) around a model feed-forward is
quantised to the int16 per-mille target torque of object 0x6071, and the
plant is stepped one cycle with the joint-side torque of that target.

Feed-forward (computed torque at the reference, computed once for the whole run): by default
RNEA of the TRUE rigid body with rotor inertias and payload, no friction; or RNEA of a nominal
pinocchio model you pass; or none; plus optional per-joint friction terms of the gains
(``Fc_ff sign(dq_ref) + Fv_ff dq_ref``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np
import pinocchio as pin

from daq.protocol.control import PDLaw

from . import SimError
from .arm_params import ArmParams, Payload, _vec
from .arm_plant import ArmPlant
from .closed_loop import (
    LoopRecord,
    cycle_period,
    per_payload,
    reference_arrays,
    run_closed_loop,
)


@dataclass(frozen=True, eq=False)
class ArmGains:
    """PD gains and friction feed-forward of the joint position loops; arrays of shape (k,).

    Attributes
    ----------
    kp : ndarray
        Proportional gains [N m/rad].
    kd : ndarray
        Derivative gains [N m s/rad].
    Fc_ff, Fv_ff : ndarray
        Coulomb [N m] and viscous [N m s/rad] feed-forward (default 0).
    velocity_cutoff_hz : float
        Cut-off of the velocity-estimate low-pass [Hz].
    """

    kp: np.ndarray
    kd: np.ndarray
    Fc_ff: Any = 0.0
    Fv_ff: Any = 0.0
    velocity_cutoff_hz: float = 100.0

    def __post_init__(self) -> None:
        k = np.size(self.kp)
        for name in ("kp", "kd", "Fc_ff", "Fv_ff"):
            object.__setattr__(self, name, _vec(f"ArmGains.{name}", getattr(self, name), k))
        if not self.velocity_cutoff_hz > 0:
            raise SimError(f"ArmGains.velocity_cutoff_hz: expected a number > 0 [Hz], got "
                           f"{self.velocity_cutoff_hz!r}")

    @property
    def k(self) -> int:
        return int(self.kp.shape[0])

    @classmethod
    def for_params(
        cls,
        params: ArmParams,
        *,
        payload: Payload | None = None,
        bandwidth_hz: float = 6.0,
        damping: float = 0.9,
        friction_ff: bool = True,
        velocity_cutoff_hz: float = 100.0,
    ) -> ArmGains:
        """Gains for a second-order loop per joint: ``kp = J w^2``, ``kd = 2 zeta J w`` with
        w = 2 pi bandwidth_hz and J the joint's largest diagonal inertia (rotor included) over
        64 sampled configurations; friction feed-forward from the true coefficients (the
        motor-quadrant sliding dry friction c_m and F_V) when ``friction_ff``."""
        model = params.dynamics_model(payload)
        data = model.createData()
        rng = np.random.default_rng(0)
        lo = np.maximum(np.where(np.isfinite(model.lowerPositionLimit),
                                 model.lowerPositionLimit, -np.pi), -np.pi)
        hi = np.minimum(np.where(np.isfinite(model.upperPositionLimit),
                                 model.upperPositionLimit, np.pi), np.pi)
        j = np.zeros(params.k)
        for q in np.vstack([np.zeros(params.k), lo + (hi - lo) * rng.random((63, params.k))]):
            j = np.maximum(j, np.diag(pin.crba(model, data, q)))
        w = 2.0 * math.pi * bandwidth_hz
        f = params.friction
        return cls(kp=j * w * w, kd=2.0 * damping * j * w,
                   Fc_ff=f.c_m if friction_ff else 0.0, Fv_ff=f.F_V if friction_ff else 0.0,
                   velocity_cutoff_hz=velocity_cutoff_hz)


@dataclass(frozen=True, eq=False)
class ArmRun(LoopRecord):
    """One simulated run of the arm: the :class:`sim_drivers.closed_loop.LoopRecord` (arrays
    (n, k), ``t`` and ``cycle`` (n,): ``t, cycle, counts, q, x, tau_ref, tau_applied,
    tau_noise, q_true, dq_true, ddq_true, regime, cycle_s``; ``stuck``, ``sliding``) plus the
    reference tracked, the payload and the joint labels.

    ``inverse_arm_torque(params, q_true, dq_true, ddq_true, payload, t) == tau_applied`` on
    the sliding entries.

    Attributes
    ----------
    q_ref, dq_ref, ddq_ref : ndarray, (n, k)
        The reference tracked [rad, rad/s, rad/s^2].
    payload : Payload or None
    joint_numbers : tuple of int
        Labels of the joints (``ArmParams.joint_numbers``).
    """

    q_ref: np.ndarray
    dq_ref: np.ndarray
    ddq_ref: np.ndarray
    payload: Payload | None
    joint_numbers: tuple[int, ...]

    @property
    def k(self) -> int:
        return int(self.q.shape[1])

    @property
    def tau(self) -> np.ndarray:
        """The logged torque, ``tau_ref`` (n, k) [N m]."""
        return self.tau_ref

    @property
    def dq(self) -> np.ndarray:
        """TRUE velocity ``dq_true`` (n, k) [rad/s]; an identification estimates its own
        from ``q``."""
        return self.dq_true

    @property
    def ddq(self) -> np.ndarray:
        """TRUE acceleration ``ddq_true`` (n, k) [rad/s^2]."""
        return self.ddq_true

    @property
    def payload_mass_kg(self) -> float:
        return 0.0 if self.payload is None else self.payload.mass

    def columns(self) -> dict[str, np.ndarray]:
        """The logged signals as multi-axis columns (ROBOT_FORMAT): ``t``, ``q1..qk``
        (measured), ``tau1..tauk`` (torque references), ``q_ref1..q_refk``; i = 1..k is the
        index in the moving chain."""
        out = {"t": self.t}
        for name, arr in (("q", self.q), ("tau", self.tau_ref), ("q_ref", self.q_ref)):
            for i in range(self.k):
                out[f"{name}{i + 1}"] = arr[:, i]
        return out

    def to_csv(self, path: Any) -> None:
        """Write :meth:`columns` as a comma-separated file with a header line, plus the
        constant payload columns of docs/robot-data.md when the run carries a payload (mass
        [kg], CoM in the flange frame [m], inertia about the CoM [kg m^2]): without them
        the file reads as a run without payload."""
        write_robot_csv(path, self.columns(), self.payload)


def write_robot_csv(path: Any, cols: dict[str, np.ndarray], payload: Any = None) -> None:
    """Write equal-length columns (name -> (n,) array) as a robot CSV with a header line
    (docs/robot-data.md), plus the constant payload columns when ``payload`` (``mass``
    [kg], ``com`` (3,) in the flange frame [m], ``inertia`` (6,) about the CoM [kg m^2]:
    xx, xy, xz, yy, yz, zz) is given."""
    cols = dict(cols)
    if payload is not None:
        n = len(next(iter(cols.values())))
        cols["payload_mass_kg"] = np.full(n, payload.mass)
        for a, v in zip("xyz", payload.com, strict=True):
            cols[f"payload_com_{a}_m"] = np.full(n, v)
        for a, v in zip(("xx", "xy", "xz", "yy", "yz", "zz"), payload.inertia, strict=True):
            cols[f"payload_i{a}_kgm2"] = np.full(n, v)
    np.savetxt(path, np.column_stack(list(cols.values())), delimiter=",",
               header=",".join(cols), comments="", fmt="%.17g")


def feedforward_torque(
    params: ArmParams,
    q: np.ndarray,
    dq: np.ndarray,
    ddq: np.ndarray,
    feedforward: Any = "rnea",
    payload: Payload | None = None,
) -> np.ndarray:
    """Model feed-forward at the reference, (n, k) [N m].

    Parameters
    ----------
    feedforward : "rnea", None, "none", pinocchio.Model or array_like (n, k)
        "rnea": RNEA of the true rigid body (rotor inertias and payload, no friction); a
        Model: RNEA of that nominal model (its own armature and gravity); None / "none": 0;
        an array: used as given.
    """
    n, k = q.shape
    if feedforward is None or (isinstance(feedforward, str) and feedforward == "none"):
        return np.zeros((n, k))
    if isinstance(feedforward, str):
        if feedforward != "rnea":
            raise SimError(f"feedforward: expected 'rnea', 'none', None, a pinocchio.Model "
                           f"or an (n, k) array, got {feedforward!r}")
        model = params.dynamics_model(payload)
    elif isinstance(feedforward, pin.Model):
        model = feedforward
        if model.nv != k or model.nq != k:
            raise SimError(f"feedforward: nominal model has nv={model.nv}, expected {k}")
    else:
        ff = np.asarray(feedforward, dtype=float)
        if ff.shape != (n, k):
            raise SimError(f"feedforward: expected an array of shape ({n}, {k}), got "
                           f"{ff.shape}")
        return ff
    data = model.createData()
    out = np.empty((n, k))
    rnea = pin.rnea
    for i in range(n):
        out[i] = rnea(model, data, q[i], dq[i], ddq[i])
    return out


def simulate_arm(
    params: ArmParams,
    reference: Any,
    gains: ArmGains,
    *,
    payload: Payload | None = None,
    seed: int = 0,
    cycle_s: float | None = None,
    substeps: int = 10,
    q0: Any = None,
    feedforward: Any = "rnea",
) -> ArmRun:
    """Run the closed loop (controllers + drives + arm) over a multi-joint reference.

    Parameters
    ----------
    params : ArmParams
    reference : object
        Float arrays ``q, dq, ddq`` of shape (n, k) [rad, rad/s, rad/s^2] sampled once per
        cycle (optionally ``t`` (n,) [s], uniformly sampled), e.g.
        :func:`sim_drivers.arm_reference.sine_reference`.
    gains : ArmGains
    payload : Payload or RobotPayload-like, optional
        Payload at the flange for the whole run (see ``Payload.coerce``).
    seed : int
        Seed of the ripple noise (same seed, same run).
    cycle_s : float, optional
        Control cycle [s]; default: the sampling step of ``reference.t``, or 0.001 s when the
        reference has no ``t``.
    substeps : int
        Plant integration sub-steps per cycle.
    q0 : array_like (k,), optional
        Initial position [rad]; default ``reference.q[0]``. The arm starts at rest.
    feedforward : see :func:`feedforward_torque`

    Returns
    -------
    ArmRun

    Raises
    ------
    SimError
        Malformed reference, gains of the wrong size, unknown feed-forward.
    """
    k = params.k
    payload = Payload.coerce(payload)
    ref_q, ref_dq, ref_ddq = reference_arrays(reference, k)
    n = ref_q.shape[0]
    if gains.k != k:
        raise SimError(f"gains: expected {k} joints, got {gains.k}")
    cycle_s = cycle_period(reference, cycle_s, default=0.001)
    ff = feedforward_torque(params, ref_q, ref_dq, ref_ddq, feedforward, payload)
    ff = ff + gains.Fc_ff * np.sign(ref_dq) + gains.Fv_ff * ref_dq

    plant = ArmPlant(params, cycle_s, substeps=substeps, seed=seed, payload=payload)
    plant.reset(ref_q[0] if q0 is None else q0)
    rng = np.random.default_rng(seed)
    noise = rng.standard_normal((n, k)) * params.drive.torque_noise_std_Nm

    torque = PDLaw(gains.kp, gains.kd, gains.velocity_cutoff_hz, cycle_s).torque

    def law(i: int, q_measured: np.ndarray) -> np.ndarray:
        return torque(ff[i], ref_q[i], ref_dq[i], q_measured)

    drive = params.drive
    record = partial(ArmRun, q_ref=ref_q, dq_ref=ref_dq, ddq_ref=ref_ddq, payload=payload,
                     joint_numbers=params.joint_numbers)
    return run_closed_loop(plant, law, drive.quantise, n, joints=k,
                           counts_per_rad=drive.counts_per_rad,
                           torque_per_permille=drive.torque_per_permille, rnd=np.rint,
                           noise=noise, record=record)


def simulate_arm_payloads(
    params: ArmParams,
    reference: Any,
    gains: ArmGains,
    payloads: Any,
    *,
    seed: int = 0,
    **kw: Any,
) -> list[ArmRun]:
    """One :func:`simulate_arm` run per payload, as a campaign does (paper IV.B).

    Parameters
    ----------
    payloads : iterable of Payload or None
        None (or a Payload of mass 0) is the run without payload.
    seed : int
        Run i uses seed ``seed + i`` (independent noise per run, reproducible).
    **kw
        Other keywords of :func:`simulate_arm` (cycle_s, substeps, q0, feedforward).

    Returns
    -------
    list of ArmRun
        In the order of ``payloads``; each run starts at rest with a fresh plant.
    """
    return per_payload(
        lambda pay, seed_i: simulate_arm(params, reference, gains, payload=pay, seed=seed_i,
                                         **kw), payloads, seed)
