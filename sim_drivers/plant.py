"""The simulated joint: rigid body + load- and velocity-dependent friction + undeclared effects.

Pure numerics, no bus. Joint side SI units: q [rad], dq [rad/s], torques [N m] (prismatic:
[m], [m/s], [N]); positive torque drives positive velocity (motor convention).

Inverse model (what :func:`inverse_torque` computes)
----------------------------------------------------
Output (load) torque, paper eq. 31/34, with payload mass M_a [kg] at lever arm L_a [m]::

    revolute:   tau_out = J ddq + MX g cos q + MY g sin q + M_a L_a (L_a ddq + g cos q)
    prismatic:  tau_out = J ddq + M_a ddq          (no gravity; L_a is ignored)

Friction, eq. 30, with E = exp(-|dq| / q_s) (eq. 29), P = sign(tau_out dq) and
P+ = (1 + P)/2, P- = (1 - P)/2 (eq. 27-28, sign(0) = 0)::

    tau = P+ (a_m + b_m E) tau_out + P- (a_g - b_g E) tau_out
        + P+ (c_m + d_m E) sign(dq) + P- (c_g + d_g E) sign(dq) + F_V dq + tau_off
        + tau_effects

The undeclared effects (each off unless enabled in the plant file; one module each in
:mod:`sim_drivers.effects`, found by its registry) add ``tau_effects``:

* position ripple   ``A sin(2 pi q / period + phase)``
* spring            ``k (q - q0)``
* warm-up           ``w exp(-t / T_w) [P+ (c_m + d_m E) + P- (c_g + d_g E)] sign(dq)``
  (the dry terms c, d of eq. 30 scaled by 1 + w exp(-t/T_w); t = time since the run start)
* asymmetric viscous ``(F_V+ - F_V) dq`` for dq > 0, ``(F_V- - F_V) dq`` for dq < 0
* quadratic viscous ``F_VV dq |dq|``
* torque lag        dynamic: the torque acting on the joint follows the command with
  ``d tau_applied / dt = (tau_cmd - tau_applied) / T_lag``; it is not a term of the balance
  (the balance holds with tau = tau_applied, not tau_cmd).

Forward dynamics (what :class:`JointPlant` integrates)
------------------------------------------------------
The joint is a robot with one moving joint: :class:`JointPlant` steps the n-dof plant's
:class:`~sim_drivers.dynamics.ChainDynamics` (the friction, stiction and integration below,
written once for k joints) on :class:`JointBody`, the rigid body above in closed form; and
:func:`inverse_torque` is :func:`sim_drivers.dynamics.friction_torque` with k = 1. For one
joint the n-dof equations read:

Given the applied torque tau, q, dq and t, the balance above is piecewise linear in ddq through
tau_out. With s = sign(dq) and ``r = tau - tau_off - viscous - ripple - spring``:

* motor candidate ``tau_out = (r - s D_m) / A_m`` (A_m = a_m + b_m E, D_m = (c_m + d_m E)(1 +
  warm-up)), consistent when ``tau_out s > 0``;
* generator candidate ``tau_out = (r - s D_g) / A_g`` (A_g = a_g - b_g E), consistent when
  ``tau_out s < 0``;
* when both are consistent (possible only if D_g > D_m) the joint keeps the quadrant it was in
  (tau_out is continuous in time); when neither is (|r| between D_g and D_m, as when the joint
  coasts through tau_out = 0), the joint moves with ``tau_out = 0`` and the dry friction takes any
  value in the band between the two quadrants' values, like a set-valued Coulomb law. Eq. 30
  then does not hold exactly (it would average the quadrants); such instants are flagged with
  ``regime == REGIME_ZERO_LOAD``.

Then ``ddq = (tau_out - gravity) / (J + M_a L_a^2)``.

Stiction (eq. 21-23): at dq = 0 the joint stays stuck (ddq = 0) while the driving torque
``r0 = tau - tau_off - ripple - spring`` lies in the static band at the current load
``tau_l = MX g cos q + MY g sin q + M_a L_a g cos q`` — the limit of eq. 30 as dq -> 0 (E = 1),
i.e. the rectangle of section III.B::

    tau_l > 0:  A_g1 tau_l - D_g1 <= r0 <= A_m1 tau_l + D_m1
    tau_l < 0:  A_m1 tau_l - D_m1 <= r0 <= A_g1 tau_l + D_g1

with A_m1 = a_m + b_m, A_g1 = a_g - b_g, D_m1 = c_m + d_m, D_g1 = c_g + d_g (times the warm-up
factor); at a load within 1e-9 D of zero (round-off at the vertical, e.g. cos q ~ 6e-17 at
q = pi/2) the band is ``+-max(D_m1, D_g1)``, as at an exact zero (the n-dof rule; the plant
before issue 24 used the tau_l > 0 or < 0 band there). Above the band it breaks away in the
positive direction, below in the negative one.

Integration: ``substeps`` fixed sub-steps per control cycle; in each, the acceleration is
evaluated at the start and held (velocity explicit, position exact for constant acceleration).
A sub-step in which the velocity would change sign is split at the zero crossing (event
detection): the joint stops there, the stiction test decides whether it sticks or reverses for
the rest of the sub-step. There is thus no sign chattering: a velocity reversal always passes
through an exact rest state.
"""

from __future__ import annotations

import math
import random
from types import SimpleNamespace
from typing import Any

import numpy as np

from .arm_effects import ArmEffects
from .arm_params import ArmFriction
from .dynamics import (  # the regimes are re-exported: the single joint's names
    REGIME_REST,
    REGIME_SLIDING,  # noqa: F401
    REGIME_ZERO_LOAD,  # noqa: F401
    ChainDynamics,
    Constrained,
    RigidBody,
    friction_torque,
)
from .effects import Inputs
from .effects import registry as effect_registry
from .plant_config import G, PlantParams

_INT16_MIN, _INT16_MAX = -32768, 32767


# --------------------------------------------------------------------------- inverse model
def output_torque(
    params: PlantParams,
    q: Any,
    ddq: Any,
    payload_mass: Any = 0.0,
    payload_arm: Any = 0.0,
) -> np.ndarray:
    """Output (load) torque tau_out of the drive chain, paper eq. 31/34.

    Parameters
    ----------
    params : PlantParams
    q, ddq : array_like, shape (n,) or scalar
        Position [rad] and acceleration [rad/s^2] (prismatic: [m], [m/s^2]).
    payload_mass, payload_arm : array_like or float
        Payload M_a [kg] and lever arm L_a [m] (arm ignored for prismatic joints).

    Returns
    -------
    ndarray
        tau_out [N m] (prismatic [N]), broadcast shape of the inputs.
    """
    q = np.asarray(q, dtype=float)
    ddq = np.asarray(ddq, dtype=float)
    ma = np.asarray(payload_mass, dtype=float)
    la = np.asarray(payload_arm, dtype=float)
    b = params.body
    if params.revolute:
        c = np.cos(q)
        return (b.J * ddq + b.MX * G * c + b.MY * G * np.sin(q)
                + ma * la * (la * ddq + G * c))
    return (b.J + ma) * ddq


def effect_torques(
    params: PlantParams,
    q: Any,
    dq: Any,
    ddq: Any,
    payload_mass: Any = 0.0,
    payload_arm: Any = 0.0,
    t: Any = 0.0,
) -> dict[str, np.ndarray]:
    """Torque of each enabled undeclared effect (torque lag excluded: it is dynamic).

    Returns
    -------
    dict
        Effect name -> torque [N m], broadcast shape of the inputs; formulas in the module
        docstring. Empty when no static effect is enabled.
    """
    q = np.asarray(q, dtype=float)
    dq = np.asarray(dq, dtype=float)
    x = Inputs(params, q, dq, ddq, payload_mass, payload_arm, t, output_torque)
    out: dict[str, np.ndarray] = {}
    for spec in effect_registry():
        cfg = getattr(params.effects, spec.name)
        if cfg.enabled and spec.torque is not None:
            out[spec.name] = spec.torque(cfg, x)
    return out


def inverse_torque(
    params: PlantParams,
    q: Any,
    dq: Any,
    ddq: Any,
    payload_mass: Any = 0.0,
    payload_arm: Any = 0.0,
    t: Any = 0.0,
    *,
    effects: bool = True,
) -> np.ndarray:
    """Motor torque of the plant's inverse model: eq. 30 with eq. 34, plus enabled effects.

    This is the ground truth the identification is compared with: ``tau`` is the torque that
    acts on the joint (``JointPlant.tau_applied``). The torque-lag effect is dynamic and not
    part of it.

    Parameters
    ----------
    params : PlantParams
    q, dq, ddq : array_like, shape (n,) or scalar
        Position [rad], velocity [rad/s], acceleration [rad/s^2].
    payload_mass, payload_arm : array_like or float
        M_a [kg] and L_a [m] of the sample's experiment.
    t : array_like or float
        Time since the start of the run [s] (warm-up effect only).
    effects : bool
        Add the enabled undeclared effects (default) or return eq. 30 alone.

    Returns
    -------
    ndarray
        tau [N m], broadcast shape of the inputs. sign(0) = 0 as in eq. 27-28, so at dq = 0 or
        tau_out = 0 the quadrant weights are 1/2 each.
    """
    q, dq = np.broadcast_arrays(np.asarray(q, dtype=float), np.asarray(dq, dtype=float))
    tau_out = output_torque(params, q, ddq, payload_mass, payload_arm)
    q, dq, tau_out = np.broadcast_arrays(q, dq, tau_out)
    t = np.asarray(t, dtype=float)
    one = SimpleNamespace(friction=arm_friction(params),
                          effects=ArmEffects.from_plant_effects([params.effects]))
    return friction_torque(one, q[..., None], dq[..., None], tau_out[..., None],
                           np.broadcast_to(t, q.shape) if t.ndim else t, effects=effects)[..., 0]


# --------------------------------------------------------------------------- forward model
def arm_friction(params: PlantParams) -> ArmFriction:
    """The joint's eq. 30 coefficients as the n-dof plant's per-joint friction (k = 1)."""
    f = params.friction
    return ArmFriction(a_m=f.a_m, b_m=f.b_m, a_g=f.a_g, b_g=f.b_g, c_m=f.c_m, d_m=f.d_m,
                       c_g=f.c_g, d_g=f.d_g, F_V=f.F_V, tau_off=f.tau_off, q_s=params.joint.q_s)


class JointBody(RigidBody):
    """The joint's rigid body (eq. 31/34) as the one-joint :class:`RigidBody` of the n-dof
    plant: ``ddq = (tau_out - gravity(q)) / (J + M_a L_a^2)`` with
    ``gravity = (MX + M_a L_a) g cos q + MY g sin q`` (prismatic: ``J + M_a``, no gravity).

    Parameters
    ----------
    params : PlantParams
    payload_mass, payload_arm : float
        M_a [kg] and L_a [m] (arm ignored for prismatic joints).
    """

    k = 1

    def __init__(self, params: PlantParams, payload_mass: float = 0.0,
                 payload_arm: float = 0.0) -> None:
        b = params.body
        ma, la = payload_mass, payload_arm
        if params.revolute:
            self.J = b.J + ma * la * la
            self.gc = (b.MX + ma * la) * G
            self.gs = b.MY * G
        else:
            self.J = b.J + ma
            self.gc = 0.0
            self.gs = 0.0
        self.forward = self._make_forward(self.J, self.gc, self.gs)

    def gravity(self, q: float) -> float:
        """Gravity torque (the static load) at q [rad], [N m]."""
        return self.gc * math.cos(q) + self.gs * math.sin(q)


    @staticmethod
    def _make_forward(jtot: float, gc: float, gs: float) -> Any:
        """:meth:`RigidBody.forward` of this body, a closure over its constants (the hot
        path: one call per integration sub-step)."""
        cos, sin = math.cos, math.sin
        if gs:
            def forward(q: list, v: list, tau: list) -> list:
                x = q[0]
                return [(tau[0] - (gc * cos(x) + gs * sin(x))) / jtot]
        else:
            def forward(q: list, v: list, tau: list) -> list:
                return [(tau[0] - gc * cos(q[0])) / jtot]
        return forward

    def hold_one(self, q: list, v: list, tau: list, j: int) -> tuple[list, float]:
        return [0.0], self.gc * math.cos(q[0]) + self.gs * math.sin(q[0]) - tau[0]

    def constrained(self, q: list, v: list, tau: list) -> _JointConstrained:
        return _JointConstrained(self, self.gravity(q[0]), tau[0])


class _JointConstrained(Constrained):
    """One joint held: its load is gravity minus the output torque; released with x, it
    accelerates with ``(tau_out + x - gravity) / J``."""

    __slots__ = ("body", "grav", "tau")

    def __init__(self, body: JointBody, grav: float, tau: float) -> None:
        self.body, self.grav, self.tau = body, grav, tau

    def hold(self, stuck: list) -> tuple[list, list]:
        return [0.0], [self.grav - self.tau]

    def release(self, j: int, x: float) -> None:
        self.tau += x

    def free(self) -> list:
        return [(self.tau - self.grav) / self.body.J]


class JointPlant:
    """One simulated joint, stepped once per control cycle: the n-dof plant's dynamics
    (:class:`sim_drivers.dynamics.ChainDynamics`) on the one-joint body :class:`JointBody`,
    with scalar state.

    Parameters
    ----------
    params : PlantParams
    cycle_s : float
        Control cycle [s]; :meth:`step` integrates over one cycle.
    substeps : int
        Fixed integration sub-steps per cycle (10 by default: 0.1 ms at 1 kHz).
    seed : int, optional
        Seed of the applied-torque noise; default ``params.drive.seed``.

    Attributes
    ----------
    q, dq : float
        Position [rad] and velocity [rad/s] at the end of the last cycle (time :attr:`t`).
    ddq : float
        Acceleration [rad/s^2] at time ``t`` under the torque applied during the last cycle.
    t : float
        Simulated time [s].
    tau_cmd : float
        Commanded joint-side torque of the last cycle [N m].
    tau_applied : float
        Torque acting on the joint at time ``t`` (lagged command + noise) [N m]; the
        balance ``inverse_torque(q, dq, ddq, t) == tau_applied`` holds in ``REGIME_SLIDING``.
    tau_noise : float
        Ripple-noise sample of the last cycle (held over the cycle) [N m].
    regime : int
        ``REGIME_SLIDING``, ``REGIME_REST`` or ``REGIME_ZERO_LOAD`` at time ``t``.
    q_start, dq_start, ddq_start, tau_applied_start, regime_start
        The same quantities at the start of the last cycle, with the acceleration and torque
        taken just after the cycle's command was applied (right limits): what an offline
        record aligned with the measured position of that cycle needs.
    """

    __slots__ = (
        "params", "cycle_s", "substeps", "_rng", "_noise_std", "_dyn",
        "q", "dq", "ddq", "t", "tau_cmd", "tau_applied", "tau_noise", "regime",
        "q_start", "dq_start", "ddq_start", "tau_applied_start", "regime_start",
        "payload_mass", "payload_arm", "_tau_lag", "_counts_per_rad", "_per_mille",
    )

    def __init__(
        self,
        params: PlantParams,
        cycle_s: float,
        *,
        substeps: int = 10,
        seed: int | None = None,
    ) -> None:
        if not cycle_s > 0:
            raise ValueError(f"cycle_s: expected a number > 0 [s], got {cycle_s!r}")
        if substeps < 1:
            raise ValueError(f"substeps: expected an integer >= 1, got {substeps!r}")
        self.params = params
        self.cycle_s = float(cycle_s)
        self.substeps = int(substeps)
        self._rng = random.Random(params.drive.seed if seed is None else seed)
        self._noise_std = params.drive.torque_noise_std_Nm
        self._dyn = ChainDynamics(arm_friction(params),
                                  ArmEffects.from_plant_effects([params.effects]),
                                  JointBody(params), self.cycle_s / self.substeps)
        d = params.drive
        self._counts_per_rad = d.counts_per_joint_rad
        self._per_mille = d.torque_per_permille
        self.payload_mass = 0.0
        self.payload_arm = 0.0
        self.reset()

    # ----------------------------------------------------------------- configuration
    def set_payload(self, mass_kg: float, arm_m: float) -> None:
        """Mount a payload M_a [kg] at lever arm L_a [m] (eq. 34; arm ignored if prismatic)."""
        if mass_kg < 0 or arm_m < 0 or not (math.isfinite(mass_kg) and math.isfinite(arm_m)):
            raise ValueError(f"payload: expected mass >= 0 [kg] and arm >= 0 [m], "
                             f"got {mass_kg!r}, {arm_m!r}")
        self.payload_mass = float(mass_kg)
        self.payload_arm = float(arm_m)
        self._dyn.body = JointBody(self.params, self.payload_mass, self.payload_arm)

    def reset(self, q0: float = 0.0, t0: float = 0.0) -> None:
        """Put the joint at rest at ``q0`` [rad], time ``t0`` [s] (warm-up time origin),
        with zero applied torque. The noise generator is not reseeded (see :meth:`reseed`)."""
        self.q = float(q0)
        self.dq = 0.0
        self.ddq = 0.0
        self.t = float(t0)
        self._dyn.t0 = float(t0)
        self._dyn.quad[0] = 0
        self.tau_cmd = 0.0
        self.tau_applied = 0.0
        self.tau_noise = 0.0
        self._tau_lag = 0.0
        self.regime = REGIME_REST
        self.q_start = self.q
        self.dq_start = 0.0
        self.ddq_start = 0.0
        self.tau_applied_start = 0.0
        self.regime_start = REGIME_REST

    @property
    def t0(self) -> float:
        """Time origin of the warm-up effect [s] (set by :meth:`reset`)."""
        return self._dyn.t0

    def reseed(self, seed: int) -> None:
        """Restart the applied-torque noise sequence from ``seed``."""
        self._rng.seed(seed)

    # ----------------------------------------------------------------- drive chain
    @property
    def encoder_counts(self) -> int:
        """Encoder position [counts], motor side: round(q N counts_per_rev / 2 pi)."""
        return round(self.q * self._counts_per_rad)

    @property
    def counts_per_rad(self) -> float:
        """Encoder counts per joint radian, N counts_per_rev / 2 pi [counts/rad]; velocity in
        counts/s (object 0x606C) is ``dq * counts_per_rad``."""
        return self._counts_per_rad

    @property
    def motor_current_A(self) -> float:
        """Motor current of the applied torque, tau_applied / (N K_t) [A] (ideal current loop;
        object 0x6078 is this in per-mille of the rated current)."""
        d = self.params.drive
        return self.tau_applied / (d.gear_ratio * d.torque_constant_Nm_per_A)

    def counts_to_rad(self, counts: int) -> float:
        """Joint position [rad] of an encoder reading: counts 2 pi / (counts_per_rev N)."""
        return counts / self._counts_per_rad

    def rad_to_counts(self, q: float) -> int:
        """Encoder reading [counts] of a joint position [rad] (rounded)."""
        return round(q * self._counts_per_rad)

    def torque_from_permille(self, x: int) -> float:
        """Joint-side torque [N m] of a target torque x [per-mille of rated torque]:
        N rated_torque_Nm x / 1000."""
        return x * self._per_mille

    def permille_from_torque(self, tau: float) -> int:
        """Target torque [per-mille of rated torque] of a joint-side torque [N m], rounded and
        clipped to int16."""
        x = round(tau / self._per_mille)
        return _INT16_MIN if x < _INT16_MIN else _INT16_MAX if x > _INT16_MAX else x

    # ----------------------------------------------------------------- dynamics
    def acceleration(self, tau: float, q: float, dq: float, t: float) -> tuple[float, int]:
        """Forward dynamics: ``(ddq, regime)`` for applied torque ``tau`` [N m] at state
        (q [rad], dq [rad/s], t [s]); see the module docstring. Does not change the state
        (except the remembered quadrant used to break ties)."""
        a, reg = self._dyn.accel([tau], [q], [dq], t)
        return a[0], reg[0]

    def step(self, tau_cmd: float) -> None:
        """Advance one control cycle with the commanded joint-side torque ``tau_cmd`` [N m]
        held over the cycle (what the drive applies from the per-mille target)."""
        self.tau_cmd = tau_cmd
        noise = self._rng.gauss(0.0, self._noise_std) if self._noise_std else 0.0
        self.tau_noise = noise
        self.q_start, self.dq_start = self.q, self.dq
        dyn = self._dyn
        q, v, t, lag, a0, tau0, reg0 = dyn.advance(
            [self.q], [self.dq], self.t, [self._tau_lag], [tau_cmd], [noise], self.substeps)
        self.ddq_start, self.tau_applied_start, self.regime_start = a0[0], tau0[0], reg0[0]
        self.q, self.dq, self.t = q[0], v[0], t
        self._tau_lag = lag = lag[0]
        tau = lag + noise
        self.tau_applied = tau
        a, reg = dyn.accel([tau], q, v, t)
        self.ddq, self.regime = a[0], reg[0]
