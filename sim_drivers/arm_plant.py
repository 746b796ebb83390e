"""The simulated n-dof arm: rigid body (pinocchio) + the paper's friction on every joint.

Pure numerics, no bus; joint side SI units ([rad], [rad/s], [N m]; prismatic [m], [N]), motor
convention (a positive torque drives a positive velocity). This is the n-dof generalisation of
:mod:`sim_drivers.plant` (read its module docstring first): same friction, same stiction
rectangle, same integration with event detection, one set of coefficients per joint.

Inverse model (:func:`inverse_arm_torque`)
------------------------------------------
Output (load) torque of the drive chain of joint j (eq. 1-2, 6), by RNEA on the model whose
``armature`` holds the rotor inertias Ia (so J = Ia + ZZ as in eq. 31)::

    tau_out = M(q) ddq + C(q, dq) dq + Q(q)        (M includes diag(Ia); payload in link k)

Friction of joint j, eq. 30 with E_j = exp(-|dq_j| / q_s,j), P_j = sign(tau_out,j dq_j)::

    tau_j = P+ (a_m + b_m E) tau_out,j + P- (a_g - b_g E) tau_out,j
          + P+ (c_m + d_m E) sign(dq_j) + P- (c_g + d_g E) sign(dq_j) + F_V dq_j + tau_off
          + effects_j(q_j, dq_j, t)                          (sim_drivers.arm_effects)

Forward dynamics (:class:`ArmPlant`)
------------------------------------
Friction is per joint: tau_out,j depends only on joint j's own applied torque and velocity.
So for a sliding joint (dq_j != 0) tau_out,j comes first, by the quadrant choice of
``sim_drivers.plant`` (motor candidate ``(r - s D_m)/A_m`` if consistent with sign(P_out) > 0,
else generator ``(r - s D_g)/A_g``, else zero load, ties kept in the previous quadrant), and
then ``ddq = ABA(q, dq, tau_out)``.

Stiction: joints with dq_j = 0 form the stuck set S. With ddq_S = 0 and the free joints' tau_out
known, ``M_FF ddq_F = tau_out,F - h_F`` (h = C dq + Q, from ``pin.nonLinearEffects``, M from
``pin.crba``), and the torque needed to hold joint j in S is ``tau_l,j = M_jF ddq_F + h_j``.
Joint j stays stuck while its driving torque ``r0 = tau - tau_off - ripple - spring`` lies in
the static band of section III.B (limit E = 1) at load tau_l,j::

    tau_l > 0:  A_g1 tau_l - D_g1 <= r0 <= A_m1 tau_l + D_m1
    tau_l < 0:  A_m1 tau_l - D_m1 <= r0 <= A_g1 tau_l + D_g1

(A_m1 = a_m + b_m, A_g1 = a_g - b_g, D_m1 = c_m + d_m, D_g1 = c_g + d_g, times the warm-up
factor). Joints outside their band break away one at a time, the largest excess (relative to
|tau_l| + D) first, with tau_out,j from the E = 1 quadrant choice; the holding torques of the
others are recomputed after each release. A released joint must accelerate in its breakaway
direction (true for one release: sign(ddq_j) = sign(tau_out,j - tau_l,j) because the Schur
complement of M is positive definite); if coupling between simultaneous releases breaks that,
the joint is held again (an approximation of the exact complementarity problem, flagged
nowhere: it needs two joints breaking away in the same sub-step).

Integration: fixed sub-steps per control cycle; in each the acceleration is evaluated at the
start and held (velocity explicit, position exact for constant acceleration). When a joint's
velocity would reach zero or change sign inside the sub-step, the sub-step is split at the
earliest zero crossing (event detection): that joint stops exactly, the dynamics are
re-evaluated (stiction test) and the rest of the sub-step is integrated, with further events
if needed. For one joint this is exactly ``sim_drivers.plant.JointPlant``.

Joint numbering: joints are numbered 1..k in the chain of MOVING joints (the pinocchio model
given to :class:`ArmParams`), unless ``joint_numbers`` maps them to other labels (e.g. their
index in the full chain, as ROBOT_FORMAT's parameter names use).
"""
from __future__ import annotations

from typing import Any

import numpy as np
import pinocchio as pin

from .arm_params import ArmParams, Payload

#: The joint slides and eq. 30 (+ effects) holds exactly (same values as sim_drivers.plant).
REGIME_SLIDING = 0
#: The joint is at rest (dq == 0): stuck, or breaking away during the next sub-step.
REGIME_REST = 1
#: The joint slides with tau_out == 0 and the dry friction inside the quadrant band.
REGIME_ZERO_LOAD = 2


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


def friction_torque(
    params: ArmParams,
    q: Any,
    dq: Any,
    tau_out: Any,
    t: Any = 0.0,
    *,
    effects: bool = True,
) -> np.ndarray:
    """Motor torque of eq. 30 (+ the enabled effects) for given output torques.

    Parameters
    ----------
    params : ArmParams
    q, dq, tau_out : array_like, shape (n, k) or (k,)
        Positions [rad], velocities [rad/s], output torques [N m].
    t : array_like, shape (n,) or scalar
        Time since the run start [s] (warm-up effect only).
    effects : bool
        Add the undeclared effects (default) or return eq. 30 alone.

    Returns
    -------
    ndarray
        tau [N m]; sign(0) = 0 as in eq. 27-28.
    """
    f, e = params.friction, params.effects
    q = np.asarray(q, dtype=float)
    dq = np.asarray(dq, dtype=float)
    tau_out = np.asarray(tau_out, dtype=float)
    ex = np.exp(-np.abs(dq) / f.q_s)
    p = np.sign(tau_out * dq)
    pp, pm = 0.5 * (1.0 + p), 0.5 * (1.0 - p)
    s = np.sign(dq)
    dry = pp * (f.c_m + f.d_m * ex) + pm * (f.c_g + f.d_g * ex)
    tau = pp * (f.a_m + f.b_m * ex) * tau_out + pm * (f.a_g - f.b_g * ex) * tau_out + f.tau_off
    if not effects:
        return tau + dry * s + f.F_V * dq
    scale = e.dry_scale(t)
    if np.ndim(t) == 0:
        scale = scale[0]
    return tau + scale * dry * s + e.viscous_torque(f.F_V, dq) + e.position_torque(q)


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


# --------------------------------------------------------------------------- forward model
class ArmPlant:
    """The simulated arm, stepped once per control cycle.

    Parameters
    ----------
    params : ArmParams
    cycle_s : float
        Control cycle [s]; :meth:`step` integrates over one cycle.
    substeps : int
        Fixed integration sub-steps per cycle.
    seed : int
        Seed of the applied-torque ripple noise.
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
    tau_applied : ndarray, shape (k,)
        Torque acting on the joints at time ``t`` (lagged command + noise) [N m].
    tau_noise : ndarray, shape (k,)
        Ripple-noise sample of the last cycle [N m].
    regime : ndarray of int8, shape (k,)
        ``REGIME_*`` of each joint at time ``t``.
    q_start, dq_start, ddq_start, tau_applied_start, regime_start
        The same at the start of the last cycle, acceleration and torque taken just after the
        cycle's command was applied (what an offline record aligned with the measured position
        of that cycle needs; as ``sim_drivers.plant.JointPlant``).
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
        self.k = k = params.k
        self.cycle_s = float(cycle_s)
        self.substeps = int(substeps)
        self._h = self.cycle_s / self.substeps
        self.model = params.dynamics_model(payload)
        self.data = self.model.createData()
        self._rng = np.random.default_rng(seed)
        self._noise_std = np.array(params.drive.torque_noise_std_Nm)
        f, e = params.friction, params.effects
        self._am, self._bm, self._cm, self._dm = f.a_m, f.b_m, f.c_m, f.d_m
        self._ag, self._bg, self._cg, self._dg = f.a_g, f.b_g, f.c_g, f.d_g
        self._off = f.tau_off
        self._qs_inv = 1.0 / f.q_s
        self._am1, self._ag1 = f.a_m + f.b_m, f.a_g - f.b_g
        self._dm1, self._dg1 = f.c_m + f.d_m, f.c_g + f.d_g
        self._fv_pos, self._fv_neg = e.viscous_coefficients(f.F_V)
        self._asym = bool(np.any(self._fv_pos != self._fv_neg))
        self._fv = np.array(self._fv_pos)
        self._fvv = np.array(e.F_VV) if np.any(e.F_VV) else None
        self._eff = e
        self._pos = e.any_position
        self._wu = bool(np.any(e.warm_up_fraction))
        keep = e.lag_keep(self._h)
        self._keep = keep if np.any(keep) else None
        self._max_events = 2 * k + 2
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
        self.t0 = float(t0)
        self.tau_cmd = np.zeros(k)
        self.tau_applied = np.zeros(k)
        self.tau_noise = np.zeros(k)
        self._lag = np.zeros(k)
        self._quad = np.zeros(k, dtype=np.int8)
        self.regime = np.full(k, REGIME_REST, dtype=np.int8)
        self.q_start = self.q.copy()
        self.dq_start = np.zeros(k)
        self.ddq_start = np.zeros(k)
        self.tau_applied_start = np.zeros(k)
        self.regime_start = self.regime.copy()

    # ----------------------------------------------------------------- dynamics
    def acceleration(self, tau: Any, q: Any, dq: Any, t: float | None = None
                     ) -> tuple[np.ndarray, np.ndarray]:
        """Forward dynamics ``(ddq, regime)`` for applied torques ``tau`` [N m] at state
        (q [rad], dq [rad/s], t [s]); see the module docstring. Does not change the state
        except the remembered quadrants used to break ties."""
        return self._accel(np.asarray(tau, dtype=float), np.asarray(q, dtype=float),
                           np.asarray(dq, dtype=float), self.t if t is None else float(t))

    def _accel(self, tau: np.ndarray, q: np.ndarray, v: np.ndarray, t: float
               ) -> tuple[np.ndarray, np.ndarray]:
        r = tau - self._off
        if self._pos:
            r = r - self._eff.position_torque(q)
        wf = (1.0 + self._eff.warm_up_fraction
              * np.exp(-(t - self.t0) / self._eff.warm_up_time_constant_s)) if self._wu else None
        rest = v == 0.0
        n_rest = int(np.count_nonzero(rest))
        if n_rest < self.k:
            s = np.sign(v)
            ex = np.exp(-np.abs(v) * self._qs_inv)
            fv = np.where(v > 0.0, self._fv_pos, self._fv_neg) if self._asym else self._fv
            rs = r - fv * v
            if self._fvv is not None:
                rs = rs - self._fvv * v * np.abs(v)
            sw = s * wf if wf is not None else s
            xm = (rs - sw * (self._cm + self._dm * ex)) / (self._am + self._bm * ex)
            xg = (rs - sw * (self._cg + self._dg * ex)) / (self._ag - self._bg * ex)
            mot = xm * s > 0.0
            gen = xg * s < 0.0
            use_m = mot & ~(gen & (self._quad < 0))
            use_g = gen & ~use_m
            tau_out = np.where(use_m, xm, np.where(use_g, xg, 0.0))
            self._quad[use_m] = 1
            self._quad[use_g] = -1
            regime = np.where(use_m | use_g, REGIME_SLIDING, REGIME_ZERO_LOAD).astype(np.int8)
        else:
            tau_out = np.zeros(self.k)
            regime = np.empty(self.k, dtype=np.int8)
        if n_rest == 0:
            return pin.aba(self.model, self.data, q, v, tau_out).copy(), regime
        regime[rest] = REGIME_REST
        return self._stiction(tau_out, r, q, v, rest, wf), regime

    def _stiction(self, tau_out: np.ndarray, r: np.ndarray, q: np.ndarray, v: np.ndarray,
                  rest: np.ndarray, wf: np.ndarray | None) -> np.ndarray:
        """Constrained dynamics with the joints at rest stuck unless they break away."""
        k = self.k
        m = pin.crba(self.model, self.data, q)
        m = np.triu(m) + np.triu(m, 1).T
        h = pin.nonLinearEffects(self.model, self.data, q, v).copy()
        dm1 = self._dm1 if wf is None else wf * self._dm1
        dg1 = self._dg1 if wf is None else wf * self._dg1
        am1, ag1 = self._am1, self._ag1
        stuck = rest.copy()
        blocked = np.zeros(k, dtype=bool)
        direction = np.zeros(k)
        tau_out = tau_out.copy()

        def solve(stuck: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            ddq = np.zeros(k)
            free = ~stuck
            if free.any():
                ddq[free] = np.linalg.solve(m[np.ix_(free, free)], tau_out[free] - h[free])
            return ddq, m[stuck] @ ddq + h[stuck]

        for _ in range(k + 1):
            ddq, load = solve(stuck)
            idx = np.flatnonzero(stuck)
            r0 = r[idx]
            d_m, d_g = dm1[idx], dg1[idx]
            a_m, a_g = am1[idx], ag1[idx]
            dmax = np.maximum(d_m, d_g)
            upper = np.where(load > 0, a_m * load + d_m,
                             np.where(load < 0, a_g * load + d_g, dmax))
            lower = np.where(load > 0, a_g * load - d_g,
                             np.where(load < 0, a_m * load - d_m, -dmax))
            excess = np.maximum(r0 - upper, lower - r0)
            excess[blocked[idx]] = -np.inf
            if not np.any(excess > 0):
                break
            i = int(np.argmax(excess / (np.abs(load) + dmax + 1e-300)))
            j = int(idx[i])
            s = 1.0 if r0[i] > upper[i] else -1.0
            lj = load[i]
            quad = 1 if lj * s > 0 else -1 if lj * s < 0 else 0
            xm = (r0[i] - s * d_m[i]) / a_m[i]
            xg = (r0[i] - s * d_g[i]) / a_g[i]
            mot, gen = xm * s > 0.0, xg * s < 0.0
            if mot and (not gen or quad >= 0):
                quad, x = 1, xm
            elif gen:
                quad, x = -1, xg
            else:
                x = 0.0
            self._quad[j] = quad
            if (x - lj) * s <= 0.0:  # cannot happen with a valid plant: stay at rest
                blocked[j] = True
                continue
            tau_out[j] = x
            stuck[j] = False
            direction[j] = s
        else:
            ddq, _ = solve(stuck)
        wrong = (direction != 0) & (ddq * direction <= 0)
        if wrong.any():  # coupled releases pulled a joint back: hold it (see docstring)
            stuck |= wrong
            ddq, _ = solve(stuck)
        return ddq

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
        tau_cmd = np.asarray(tau_cmd, dtype=float)
        if noise is None:
            noise = self._rng.standard_normal(self.k) * self._noise_std
        self.tau_cmd = tau_cmd
        self.tau_noise = noise
        h = self._h
        keep = self._keep
        lag = tau_cmd if keep is None else np.where(keep > 0, self._lag, tau_cmd)
        q, v, t = self.q, self.dq, self.t
        self.q_start, self.dq_start = q, v
        accel = self._accel
        for i in range(self.substeps):
            tau = lag + noise
            rem, tt = h, t
            for ev in range(self._max_events):
                a, regime = accel(tau, q, v, tt)
                if i == 0 and ev == 0:
                    self.ddq_start = a
                    self.tau_applied_start = tau
                    self.regime_start = regime
                vn = v + a * rem
                cross = (vn * v <= 0.0) & (v != 0.0)
                if not cross.any():
                    q = q + 0.5 * (v + vn) * rem
                    v = vn
                    break
                # a velocity reaches zero inside the sub-step: stop at the earliest crossing
                ci = np.flatnonzero(cross)
                ac = a[ci]
                ths = np.where(ac != 0.0, -v[ci] / np.where(ac != 0.0, ac, 1.0), rem)
                ths = np.minimum(ths, rem)
                th = float(ths.min())
                vn = v + a * th
                vn[ci[ths <= th]] = 0.0
                q = q + 0.5 * (v + vn) * th
                v = vn
                rem -= th
                tt += th
                if rem <= 0.0:
                    break
            else:  # too many events in one sub-step: finish it without detection
                a, _ = accel(tau, q, v, tt)
                vn = v + a * rem
                q = q + 0.5 * (v + vn) * rem
                v = vn
            t += h
            if keep is not None:
                lag = tau_cmd + (lag - tau_cmd) * keep
        self.q, self.dq, self.t = q, v, t
        self._lag = lag
        tau = lag + noise
        self.tau_applied = tau
        self.ddq, self.regime = accel(tau, q, v, t)

    # ----------------------------------------------------------------- drive chain
    def encoder_counts(self) -> np.ndarray:
        """Encoder positions [counts] (int64, (k,)), motor side."""
        return np.rint(self.q * self.params.drive.counts_per_rad).astype(np.int64)
