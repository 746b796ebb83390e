"""The simulated n-dof arm: rigid body (pinocchio) + the paper's friction on every joint.

Pure numerics, no bus; joint side SI units ([rad], [rad/s], [N m]; prismatic [m], [N]), motor
convention (a positive torque drives a positive velocity). The friction, stiction, integration
and effects are :mod:`sim_drivers.dynamics` (the one plant computation, shared with the
single joint); this module gives them the arm's rigid body, :class:`PinocchioBody`, and the
arm's inverse model.

Inverse model (:func:`inverse_arm_torque`)
------------------------------------------
Output (load) torque of the drive chain of joint j (eq. 1-2, 6), by RNEA on the model whose
``armature`` holds the rotor inertias Ia (so J = Ia + ZZ as in eq. 31)::

    tau_out = M(q) ddq + C(q, dq) dq + Q(q)        (M includes diag(Ia); payload in link k)

then the friction of every joint, :func:`sim_drivers.dynamics.friction_torque` (eq. 30 +
effects).

Forward dynamics (:class:`ArmPlant`)
------------------------------------
:class:`sim_drivers.dynamics.ChainDynamics` on a :class:`PinocchioBody`: ``ddq = ABA(q, dq,
tau_out)`` for the sliding joints, and for the stuck set S (joints with dq_j = 0), with
``a0 = ABA(q, dq, tau_out)`` (tau_out,S = 0) and ``Minv = M^-1`` (``pin.computeMinverse``),
the holding torques ``tau_l,S = -(Minv_SS)^-1 a0_S`` and ``ddq = a0 + Minv_:S tau_l,S`` (one
division when one joint is stuck): ``M_FF ddq_F = tau_out,F - h_F`` without factorising M_FF.
An external force (:mod:`sim_drivers.arm_push`, the plant's ``pushes``) adds its ``J^T F`` to
tau_out: it acts on the links, not through the drive chains and their friction.

Joint numbering: joints are numbered 1..k in the chain of MOVING joints (the pinocchio model
given to :class:`ArmParams`), unless ``joint_numbers`` maps them to other labels (e.g. their
index in the full chain, as ROBOT_FORMAT's parameter names use).
"""
from __future__ import annotations

from typing import Any

import numpy as np
import pinocchio as pin

from .arm_params import ArmParams, Payload
from .arm_push import Push, push_torque
from .dynamics import (  # re-exported: the arm's names
    REGIME_REST,
    REGIME_SLIDING,
    REGIME_ZERO_LOAD,
    ChainDynamics,
    Constrained,
    RigidBody,
    friction_torque,
)

__all__ = ["REGIME_REST", "REGIME_SLIDING", "REGIME_ZERO_LOAD", "ArmPlant", "PinocchioBody",
           "friction_torque", "inverse_arm_torque", "output_arm_torque"]


# --------------------------------------------------------------------------- inverse model
def output_arm_torque(
    params: ArmParams,
    q: Any,
    dq: Any,
    ddq: Any,
    payload: Payload | None = None,
) -> np.ndarray:
    """Output (load) torque tau_out of every drive chain: RNEA with the rotor inertias
    (armature) and the payload, eq. 1-2 and 31/34 generalised.

    Parameters
    ----------
    params : ArmParams
    q, dq, ddq : array_like, shape (n, k) or (k,)
        Joint positions [rad], velocities [rad/s], accelerations [rad/s^2].
    payload : Payload, optional

    Returns
    -------
    ndarray, shape of ``q``
        tau_out [N m].
    """
    model = params.dynamics_model(payload)
    data = model.createData()
    q2, dq2, ddq2 = (np.atleast_2d(np.asarray(a, dtype=float)) for a in (q, dq, ddq))
    out = np.empty_like(q2)
    rnea = pin.rnea
    for i in range(q2.shape[0]):
        out[i] = rnea(model, data, q2[i], dq2[i], ddq2[i])
    return out.reshape(np.shape(q))


def inverse_arm_torque(
    params: ArmParams,
    q: Any,
    dq: Any,
    ddq: Any,
    payload: Payload | None = None,
    t: Any = 0.0,
    *,
    effects: bool = True,
) -> np.ndarray:
    """The applied motor torque of the simulator's inverse model (module docstring).

    ``tau = friction_torque(q, dq, output_arm_torque(q, dq, ddq, payload), t)``: RNEA with
    rotor inertias and payload, eq. 30 per joint with sign(P_out) from tau_out, plus the
    undeclared effects (torque lag excluded: it is dynamic). On sliding samples it reproduces
    ``ArmRun.tau_applied`` from the true states.

    Returns
    -------
    ndarray, shape of ``q``
        tau [N m].
    """
    tau_out = output_arm_torque(params, q, dq, ddq, payload)
    return friction_torque(params, q, dq, tau_out, t, effects=effects)


# --------------------------------------------------------------------------- rigid body
class PinocchioBody(RigidBody):
    """A serial chain through pinocchio: ABA, and ``M^-1`` for the held joints.

    Parameters
    ----------
    model : pinocchio.Model
        Dynamics model (armature = rotor inertias, gravity, payload).
    """

    def __init__(self, model: pin.Model) -> None:
        self.model = model
        self.data = model.createData()
        self.k = int(model.nv)
        self._il = np.tril_indices(self.k, -1)

    def forward(self, q: list, v: list, tau: list) -> list:
        return pin.aba(self.model, self.data, np.array(q), np.array(v), np.array(tau)).tolist()

    def constrained(self, q: list, v: list, tau: list) -> _MinvConstrained:
        qa = np.array(q)
        a0 = pin.aba(self.model, self.data, qa, np.array(v), np.array(tau))
        minv = np.array(pin.computeMinverse(self.model, self.data, qa))
        minv[self._il] = minv.T[self._il]  # some pinocchio versions fill the upper triangle only
        return _MinvConstrained(a0, minv)


class _MinvConstrained(Constrained):
    """With ``a0 = ABA(q, dq, tau_out)`` and ``Minv = M^-1``: holding S needs
    ``lam_S = -(Minv_SS)^-1 a0_S``, then ``ddq = a0 + Minv_:S lam_S``; releasing j with x adds
    ``Minv_:j x`` to a0."""

    def __init__(self, a0: np.ndarray, minv: np.ndarray) -> None:
        self.a0, self.minv = a0, minv

    def hold(self, stuck: list) -> tuple[list, list]:
        a0, minv = self.a0, self.minv
        if len(stuck) == 1:
            j = stuck[0]
            lam = np.array([-a0[j] / minv[j, j]])
        else:
            lam = -np.linalg.solve(minv[np.ix_(stuck, stuck)], a0[stuck])
        ddq = a0 + minv[:, stuck] @ lam
        ddq[stuck] = 0.0
        return ddq.tolist(), lam.tolist()

    def release(self, j: int, x: float) -> None:
        self.a0 = self.a0 + self.minv[:, j] * x

    def free(self) -> list:
        return self.a0.tolist()



class ArmPlant:
    """The simulated arm, stepped once per control cycle.

    The dynamics are a :class:`ChainDynamics` on a :class:`PinocchioBody`: plain Python over
    the joints (per-joint friction) plus one ``pin.aba`` call per evaluation (small numpy
    arrays cost more per operation than scalar floats at k <= 6).

    Parameters
    ----------
    params : ArmParams
    cycle_s : float
        Control cycle [s]; :meth:`step` integrates over one cycle.
    substeps : int
        Fixed integration sub-steps per cycle.
    seed : int
        Seed of the applied-torque ripple noise (used when :meth:`step` gets no noise).
    payload : Payload, optional
        Payload for the whole life of the plant.

    Attributes
    ----------
    q, dq : ndarray, shape (k,)
        Position [rad] and velocity [rad/s] at time :attr:`t`.
    ddq : ndarray, shape (k,)
        Acceleration [rad/s^2] at time ``t`` under the torque applied during the last cycle.
    t : float
        Simulated time [s].
    tau_cmd : ndarray, shape (k,)
        Commanded joint-side torques of the last cycle [N m].
    tau_applied : ndarray, shape (k,)
        Torque acting on the joints at time ``t`` (lagged command + noise) [N m].
    tau_noise : ndarray, shape (k,)
        Ripple-noise sample of the last cycle [N m].
    pushes : list of sim_drivers.arm_push.Push
        External forces to apply (each while active; dropped once over).
    tau_ext : ndarray, shape (k,)
        Joint torques of the pushes acting over the last cycle [N m] (``J^T F`` at its start).
    regime : ndarray of int8, shape (k,)
        ``REGIME_*`` of each joint at time ``t``.
    q_start, dq_start, ddq_start, tau_applied_start, regime_start
        The same at the start of the last cycle, acceleration and torque taken just after the
        cycle's command was applied (what an offline record aligned with the measured position
        of that cycle needs; as ``sim_drivers.plant.JointPlant``).
    model, data : pinocchio.Model, pinocchio.Data
        The dynamics model (rotor inertias as armature, gravity, payload) and its workspace.
    """

    def __init__(
        self,
        params: ArmParams,
        cycle_s: float,
        *,
        substeps: int = 10,
        seed: int = 0,
        payload: Payload | None = None,
    ) -> None:
        if not cycle_s > 0:
            raise ValueError(f"cycle_s: expected a number > 0 [s], got {cycle_s!r}")
        if int(substeps) < 1:
            raise ValueError(f"substeps: expected an integer >= 1, got {substeps!r}")
        self.params = params
        self.payload = payload
        self.k = params.k
        self.cycle_s = float(cycle_s)
        self.substeps = int(substeps)
        self._h = self.cycle_s / self.substeps
        body = PinocchioBody(params.dynamics_model(payload))
        self.model, self.data = body.model, body.data
        self._dyn = ChainDynamics(params.friction, params.effects, body, self._h)
        self._rng = np.random.default_rng(seed)
        self._noise_std = np.array(params.drive.torque_noise_std_Nm)
        #: external forces (sim_drivers.arm_push): their J^T F enters the rigid-body dynamics
        self.pushes: list[Push] = []
        self._push_data = self.model.createData()
        self.reset()

    # ----------------------------------------------------------------- state
    def reset(self, q0: Any = None, t0: float = 0.0) -> None:
        """Put the arm at rest at ``q0`` [rad] (default zeros), time ``t0`` [s] (warm-up time
        origin), with zero applied torque. The noise generator is not reseeded."""
        k = self.k
        self.q = np.zeros(k) if q0 is None else np.array(q0, dtype=float).reshape(k)
        self.dq = np.zeros(k)
        self.ddq = np.zeros(k)
        self.t = float(t0)
        self._dyn.t0 = float(t0)
        self.tau_cmd = np.zeros(k)
        self.tau_applied = np.zeros(k)
        self.tau_noise = np.zeros(k)
        self.tau_ext = np.zeros(k)
        self._dyn.ext = None
        self._lag = [0.0] * k
        self._dyn.quad[:] = [0] * k
        self.regime = np.full(k, REGIME_REST, dtype=np.int8)
        self.q_start = self.q.copy()
        self.dq_start = np.zeros(k)
        self.ddq_start = np.zeros(k)
        self.tau_applied_start = np.zeros(k)
        self.regime_start = self.regime.copy()

    @property
    def t0(self) -> float:
        """Time origin of the warm-up effect [s] (set by :meth:`reset`)."""
        return self._dyn.t0

    # ----------------------------------------------------------------- dynamics
    def acceleration(self, tau: Any, q: Any, dq: Any, t: float | None = None
                     ) -> tuple[np.ndarray, np.ndarray]:
        """Forward dynamics ``(ddq, regime)`` for applied torques ``tau`` (k,) [N m] at state
        (q [rad], dq [rad/s], t [s]); see the module docstring. Does not change the state
        except the remembered quadrants used to break ties."""
        k = self.k
        a, reg = self._dyn.accel(np.asarray(tau, dtype=float).reshape(k).tolist(),
                                 np.asarray(q, dtype=float).reshape(k).tolist(),
                                 np.asarray(dq, dtype=float).reshape(k).tolist(),
                                 self.t if t is None else float(t))
        return np.array(a), np.array(reg, dtype=np.int8)

    def step(self, tau_cmd: Any, noise: Any = None) -> None:
        """Advance one control cycle with the commanded joint-side torques ``tau_cmd`` (k,)
        [N m] held over the cycle.

        Parameters
        ----------
        tau_cmd : array_like, shape (k,)
        noise : array_like, shape (k,), optional
            Ripple-noise sample of this cycle [N m]; default: drawn from the plant's generator
            with the drive's standard deviations.
        """
        k = self.k
        cmd = np.asarray(tau_cmd, dtype=float).reshape(k)
        if noise is None:
            noise = self._rng.standard_normal(k) * self._noise_std
        noise = np.asarray(noise, dtype=float).reshape(k)
        self.tau_cmd, self.tau_noise = cmd, noise
        self._update_pushes()
        noise_l = noise.tolist()
        self.q_start, self.dq_start = self.q, self.dq
        q, v, t, lag, a0, tau0, reg0 = self._dyn.advance(
            self.q.tolist(), self.dq.tolist(), self.t, self._lag, cmd.tolist(), noise_l,
            self.substeps)
        self.ddq_start = np.array(a0)
        self.tau_applied_start = np.array(tau0)
        self.regime_start = np.array(reg0, dtype=np.int8)
        self.q, self.dq, self.t = np.array(q), np.array(v), t
        self._lag = lag
        tau = [lg + n for lg, n in zip(lag, noise_l, strict=True)]
        self.tau_applied = np.array(tau)
        a, regime = self._dyn.accel(tau, q, v, t)
        self.ddq = np.array(a)
        self.regime = np.array(regime, dtype=np.int8)

    def _update_pushes(self) -> None:
        """``tau_ext`` [N m] of the pushes acting at the cycle's start (held over the cycle);
        pushes that ended are dropped."""
        if not self.pushes:
            if self._dyn.ext is not None:
                self.tau_ext = np.zeros(self.k)
                self._dyn.ext = None
            return
        t = self.t
        self.pushes = [p for p in self.pushes if t < p.t0_s + p.duration_s]
        ext = np.zeros(self.k)
        for p in self.pushes:
            if p.active(t):
                ext += push_torque(self.model, self._push_data, self.q, p)
        self.tau_ext = ext
        self._dyn.ext = ext.tolist() if np.any(ext) else None

    # ----------------------------------------------------------------- drive chain
    def encoder_counts(self) -> np.ndarray:
        """Encoder positions [counts] (int64, (k,)), motor side."""
        return np.rint(self.q * self.params.drive.counts_per_rad).astype(np.int64)
