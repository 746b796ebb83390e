"""The plant computation, one for one joint and for n: the paper's friction per joint, the
stiction rectangle, the integration with event detection and the undeclared effects, on a
rigid body given as a strategy object.

Pure numerics, no bus; joint side SI units ([rad], [rad/s], [N m]; prismatic [m], [N]), motor
convention (a positive torque drives a positive velocity). :class:`ChainDynamics` runs on a
:class:`RigidBody`: :class:`sim_drivers.arm_plant.PinocchioBody` (the arm, any serial chain)
or :class:`sim_drivers.plant.JointBody` (the single joint, a robot with one moving joint:
eq. 31/34 in closed form). :class:`sim_drivers.arm_plant.ArmPlant` and
:class:`sim_drivers.plant.JointPlant` step it; :func:`friction_torque` is the inverse model
of both (:func:`sim_drivers.arm_plant.inverse_arm_torque`,
:func:`sim_drivers.plant.inverse_torque`). :mod:`sim_drivers.plant`'s docstring writes the
equations for one joint.

Friction of joint j, eq. 30 with E_j = exp(-|dq_j| / q_s,j), P_j = sign(tau_out,j dq_j)::

    tau_j = P+ (a_m + b_m E) tau_out,j + P- (a_g - b_g E) tau_out,j
          + P+ (c_m + d_m E) sign(dq_j) + P- (c_g + d_g E) sign(dq_j) + F_V dq_j + tau_off
          + effects_j(q_j, dq_j, t)                          (sim_drivers.arm_effects)

(effects_j: every effect of the plant-effect registry, :mod:`sim_drivers.effects`, on that
joint, with the registry's formulas: the native ones through
:meth:`~sim_drivers.arm_effects.ArmEffects.position_torque`, ``viscous_torque`` and
``warm_up_torque``, the others through ``registered_torque``.)

The dry terms (c, d) of joint j are multiplied by the warm-up factor and by the dry-coupling
factor of :meth:`~sim_drivers.arm_effects.ArmEffects.coupling_scale` (the position of other
joints: the arm's one cross-joint effect), in the inverse model, the sliding friction and the
stiction band alike.

Forward dynamics (:class:`ChainDynamics`)
-----------------------------------------
Friction is per joint: tau_out,j depends only on joint j's own applied torque and velocity.
So for a sliding joint (dq_j != 0) tau_out,j comes first, by the quadrant choice of
the single joint (motor candidate ``(r - s D_m)/A_m`` if consistent with sign(P_out) > 0,
else generator ``(r - s D_g)/A_g``, else zero load, ties kept in the previous quadrant), and
then ``ddq = body.forward(q, dq, tau_out)`` (ABA for the arm). An external force
(:mod:`sim_drivers.arm_push`, the arm's ``pushes``, :attr:`ChainDynamics.ext`) adds its
``J^T F`` to tau_out there (and in the stiction step below): it acts on the links, not
through the drive chains and their friction.

Stiction: joints with dq_j = 0 form the stuck set S. With ddq_S = 0 and the free joints' tau_out
known, ``M_FF ddq_F = tau_out,F - h_F`` (h = C dq + Q), and the torque needed to hold joint j
in S is ``tau_l,j = M_jF ddq_F + h_j``. Computed without factorising M_FF: with
``a0 = ABA(q, dq, tau_out)`` (tau_out,S = 0) and ``Minv = M^-1`` (``pin.computeMinverse``;
the body's :meth:`RigidBody.constrained`),
``tau_l,S = -(Minv_SS)^-1 a0_S`` and ``ddq = a0 + Minv_:S tau_l,S`` (one division when one
joint is stuck). A load within 1e-9 D of zero (round-off at a vertical axis) counts as zero:
the band is then +-max(D_m1, D_g1) (as for an exact zero). Joint j stays stuck while its
driving torque ``r0 = tau - tau_off - ripple - spring`` lies in the static band of section
III.B (limit E = 1) at load tau_l,j::

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
if needed. ``sim_drivers.plant.JointPlant`` is this with k = 1 on a ``JointBody``.

Forward-dynamics form of the effects: :meth:`ChainDynamics.accel` subtracts the native
effects' torques (viscous slopes per direction, quadratic viscous, ripple, spring) from the
driving torque and scales the dry terms by the warm-up and coupling factors, in scalar form
per joint (the hot path); the torque lag filters the command in :meth:`ChainDynamics.advance`.

"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from trajectories.friction import stribeck_exp

_TWO_PI = 2.0 * math.pi

#: The joint slides and eq. 30 (+ effects) holds exactly.
REGIME_SLIDING = 0
#: The joint is at rest (dq == 0): stuck, or breaking away during the next sub-step.
REGIME_REST = 1
#: The joint slides with tau_out == 0 and the dry friction inside the quadrant band.
REGIME_ZERO_LOAD = 2


# --------------------------------------------------------------------------- inverse model
def friction_torque(
    params: Any,
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
    params : ArmParams or alike
        Anything with ``friction`` (:class:`~sim_drivers.arm_params.ArmFriction`) and
        ``effects`` (:class:`~sim_drivers.arm_effects.ArmEffects`).
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
    ex = stribeck_exp(dq, f.q_s)
    p = np.sign(tau_out * dq)
    pp, pm = 0.5 * (1.0 + p), 0.5 * (1.0 - p)
    s = np.sign(dq)
    dry = pp * (f.c_m + f.d_m * ex) + pm * (f.c_g + f.d_g * ex)
    tau = pp * (f.a_m + f.b_m * ex) * tau_out + pm * (f.a_g - f.b_g * ex) * tau_out + f.tau_off
    if not effects:
        return tau + dry * s + f.F_V * dq
    # effects (formulas of the plant-effect registry, sim_drivers/effects/): warm-up W and
    # dry coupling C scale the dry terms, (1 + W) C dry = dry + W dry + (C - 1)(1 + W) dry
    dry = dry * s
    warm = e.warm_up_torque(f, dq, t, tau_out)
    tau = (tau + dry + f.F_V * dq + warm + e.viscous_torque(f, dq) + e.position_torque(q, f))
    if np.any(e.coupled()):
        tau = tau + (e.coupling_scale(q) - 1.0) * (dry + warm)
    if any(e.registered):  # the registry's other effects (sim_drivers.arm_effects)
        tau = tau + e.registered_torque(f, q, dq, t, tau_out)
    return tau


# --------------------------------------------------------------------------- rigid bodies
class RigidBody:
    """The rigid-body part of the forward dynamics a :class:`ChainDynamics` integrates.

    Subclasses: :class:`sim_drivers.arm_plant.PinocchioBody` (any serial chain, through
    pinocchio) and
    :class:`sim_drivers.plant.JointBody` (one joint: eq. 31/34 in closed form, exact and fast).

    Attributes
    ----------
    k : int
        Number of joints.
    """

    k: int

    def forward(self, q: list, v: list, tau: list) -> list:
        """Accelerations [rad/s^2] of the free chain under output torques ``tau`` [N m]
        (lists of floats, length k)."""
        raise NotImplementedError

    def constrained(self, q: list, v: list, tau: list) -> Constrained:
        """The same chain with some joints held (stiction step), output torques ``tau``."""
        raise NotImplementedError

    def hold_one(self, q: list, v: list, tau: list, j: int) -> tuple[list, float]:
        """``constrained(q, v, tau).hold([j])`` for one held joint j: (ddq, holding torque
        [N m]); a body may answer it faster (the stiction test of a joint at rest)."""
        ddq, lam = self.constrained(q, v, tau).hold([j])
        return ddq, lam[0]


class Constrained:
    """Dynamics of a chain some of whose joints are held at rest (stiction, module docstring).

    ``hold(stuck)`` gives ``(ddq, lam)``: the accelerations (0 at the held joints) and the
    holding torques of the held joints (their loads) [N m]; ``release(j, x)`` adds the output
    torque x [N m] at joint j (``release(j, -x)`` takes it back); ``free()`` the accelerations
    with no joint held.
    """

    def hold(self, stuck: list) -> tuple[list, list]:
        raise NotImplementedError

    def release(self, j: int, x: float) -> None:
        raise NotImplementedError

    def free(self) -> list:
        raise NotImplementedError


# --------------------------------------------------------------------------- forward model
class ChainDynamics:
    """Friction, stiction and integration of a chain of k joints on a :class:`RigidBody`:
    the forward model of the module docstring, on lists of floats (the hot path).

    Used by :class:`ArmPlant` (pinocchio body) and :class:`sim_drivers.plant.JointPlant`
    (the one-joint body): one computation for one joint and for n.

    Parameters
    ----------
    friction : ArmFriction
    effects : ArmEffects
    body : RigidBody
    h : float
        Integration sub-step [s].

    Attributes
    ----------
    quad : list of int
        Quadrant each joint was last in (+1 motor, -1 generator, 0 none): ties are kept in it.
    ext : list of float or None
        External joint torques added to the output torques (pushes) [N m].
    t0 : float
        Time origin of the warm-up effect [s].
    """

    def __init__(self, friction: Any, effects: Any, body: RigidBody, h: float) -> None:
        f, e = friction, effects
        k = body.k
        self.k, self.h = k, float(h)
        self.body = body
        fv_pos, fv_neg = e.viscous_coefficients(f.F_V)

        def rows(*cols: Any) -> list[tuple]:
            return list(zip(*(np.asarray(c, dtype=float).tolist() for c in cols), strict=True))

        # dry coupling: per joint j, (m, c, 2 pi / P, phase, slope, q0) of its driving joints
        cpl = [tuple((m, *(float(a[j, m]) for a in (
            e.coupling_amplitude, _TWO_PI / e.coupling_period_rad, e.coupling_phase_rad,
            e.coupling_slope_per_rad, e.coupling_rest_rad))) for m in range(k)
            if e.coupling_amplitude[j, m] or e.coupling_slope_per_rad[j, m]) for j in range(k)]
        # the registry's other effects: static torques f(q_j, dq_j, t) per joint
        xf = e.forward_extra(f)
        # position, time and cross-joint effects of each joint (None: none on that joint);
        # 0 = off
        eff = [(ra, rk, rp, sk, sq, ww, wt, x or None, c or None)
               if ra or sk or ww or x or c else None
               for (ra, rk, rp, sk, sq, ww, wt), x, c in zip(rows(
                   e.ripple_amplitude_Nm, _TWO_PI / e.ripple_period_rad, e.ripple_phase_rad,
                   e.spring_stiffness_Nm_per_rad, e.spring_rest_rad,
                   e.warm_up_fraction, 1.0 / e.warm_up_time_constant_s), xf, cpl, strict=True)]
        # one tuple per joint (the hot loop unpacks it): eq. 30, viscous effects, the others
        self._jp = [(*fr, x) for fr, x in zip(rows(
            f.tau_off, 1.0 / f.q_s, fv_pos, fv_neg, e.F_VV,
            f.c_m, f.d_m, f.a_m, f.b_m, f.c_g, f.d_g, f.a_g, f.b_g), eff, strict=True)]
        # static band (E = 1): (A_m1, A_g1, D_m1, D_g1) per joint
        self._band_coef = rows(f.a_m + f.b_m, f.a_g - f.b_g, f.c_m + f.d_m, f.c_g + f.d_g)
        tl = np.asarray(e.lag_time_constant_s, dtype=float).tolist()
        keep = [math.exp(-self.h / x) if x > 0 else 0.0 for x in tl]
        self.keep = keep if any(keep) else None
        # whether the dynamics are time-invariant over a cycle (no lag, warm-up, extra torque):
        # then an arm held at rest stays so for the rest of the cycle, exactly
        self._static = self.keep is None and all(
            x is None or (not x[5] and x[7] is None) for x in eff)
        self._max_events = 2 * k + 2
        self.quad = [0] * k
        self._sliding = (REGIME_SLIDING,) * k  # shared regime of an all-sliding evaluation
        self.ext: list | None = None
        self.t0 = 0.0

    @property
    def body(self) -> RigidBody:
        """The rigid body (replaceable, e.g. a new payload)."""
        return self._body

    @body.setter
    def body(self, body: RigidBody) -> None:
        if body.k != self.k:
            raise ValueError(f"body: expected {self.k} joints, got {body.k}")
        self._body = body
        self._forward = body.forward

    def accel(self, tau: list, q: list, v: list, t: float) -> tuple[list, Any]:
        """Forward dynamics ``(ddq, regime)`` for applied torques ``tau`` [N m] at state
        (q [rad], dq [rad/s], t [s]), lists of floats; updates :attr:`quad` (ties). The
        regimes are a sequence of k ints (a shared tuple when every joint slides)."""
        k = self.k
        out = [0.0] * k
        reg = None  # all sliding unless a joint is at rest or at zero load
        r_rest = None
        quad = self.quad
        exp = math.exp
        j = -1
        for off, qsi, fvp, fvn, fvv, cm, dm, am, bm, cg, dg, ag, bg, eff in self._jp:
            j += 1
            vj = v[j]
            r = tau[j] - off
            if vj > 0.0:
                r -= fvp * vj
                if fvv:
                    r -= fvv * vj * vj
            elif vj < 0.0:
                r -= fvn * vj
                if fvv:
                    r += fvv * vj * vj
            if eff is None:
                wf = 1.0
            else:
                rip_a, rip_k, rip_ph, spr_k, spr_q0, wu_w, wu_tinv, xf, cpl = eff
                if rip_a:
                    r -= rip_a * math.sin(rip_k * q[j] + rip_ph)
                if spr_k:
                    r -= spr_k * (q[j] - spr_q0)
                if xf is not None:
                    for fx in xf:
                        r -= fx(q[j], vj, t - self.t0)
                wf = 1.0 + wu_w * exp(-(t - self.t0) * wu_tinv) if wu_w else 1.0
                if cpl is not None:
                    cf = 1.0
                    for m, c, kp, ph, a, q0 in cpl:
                        cf += c * math.sin(kp * q[m] + ph) + a * (q[m] - q0)
                    wf *= cf if cf > 0.0 else 0.0
            if vj > 0.0:
                s = wf  # sign(dq) times the warm-up (and coupling) factor
                ex = exp(-vj * qsi)  # stribeck_exp inlined (scalar, per step)
            elif vj < 0.0:
                s = -wf
                ex = exp(vj * qsi)
            else:
                if reg is None:
                    reg = [REGIME_SLIDING] * k
                if r_rest is None:
                    r_rest = []
                reg[j] = REGIME_REST
                r_rest.append((j, r, wf))
                continue
            # quadrant choice: motor if consistent, ties kept in the previous quadrant
            xm = (r - s * (cm + dm * ex)) / (am + bm * ex)
            if xm * s > 0.0:
                if quad[j] < 0:  # was generator: keep it if it is still consistent
                    xg = (r - s * (cg + dg * ex)) / (ag - bg * ex)
                    if xg * s < 0.0:
                        out[j] = xg
                        continue
                quad[j] = 1
                out[j] = xm
            else:
                xg = (r - s * (cg + dg * ex)) / (ag - bg * ex)
                if xg * s < 0.0:
                    quad[j] = -1
                    out[j] = xg
                else:
                    if reg is None:
                        reg = [REGIME_SLIDING] * k
                    reg[j] = REGIME_ZERO_LOAD
        if self.ext is not None:  # a push: on the rigid body, not through the drive chain
            out = [o + e for o, e in zip(out, self.ext, strict=True)]
        if not r_rest:
            return self._forward(q, v, out), self._sliding if reg is None else reg
        return self._stiction(out, r_rest, q, v), reg

    def _band(self, j: int, load: float, r: float, w: float) -> tuple[float, float, float]:
        """Static band of joint j at holding torque ``load`` [N m] (E = 1, times the warm-up
        factor ``w``) against its driving torque ``r`` [N m]: ``(excess, direction, load)``,
        excess <= 0 inside the band (relative to |load| + D, so that the largest breaks
        first), direction +1/-1 of the breakaway; a load within 1e-9 D of zero (round-off, e.g.
        a vertical axis) counts as zero."""
        am1, ag1, dm1, dg1 = self._band_coef[j]
        dm1, dg1 = w * dm1, w * dg1
        dmax = dm1 if dm1 > dg1 else dg1
        if abs(load) <= 1e-9 * dmax:
            load = 0.0
        if load > 0.0:
            upper, lower = am1 * load + dm1, ag1 * load - dg1
        elif load < 0.0:
            upper, lower = ag1 * load + dg1, am1 * load - dm1
        else:
            upper, lower = dmax, -dmax
        if r > upper:
            return (r - upper) / (abs(load) + dmax + 1e-300), 1.0, load
        if r < lower:
            return (lower - r) / (abs(load) + dmax + 1e-300), -1.0, load
        return 0.0, 0.0, load

    def _breakaway(self, j: int, load: float, r: float, w: float, s: float) -> float:
        """Output torque [N m] of joint j leaving rest in direction s: the E = 1 quadrant
        choice, the quadrant first taken from the continuity of tau_out with the static load
        (stored in :attr:`quad`); NaN when it would not move in direction s (cannot happen
        with a valid plant: the joint stays at rest)."""
        am1, ag1, dm1, dg1 = self._band_coef[j]
        quad = 1 if load * s > 0 else -1 if load * s < 0 else 0
        xm = (r - s * (w * dm1)) / am1
        xg = (r - s * (w * dg1)) / ag1
        mot, gen = xm * s > 0.0, xg * s < 0.0
        if mot and (not gen or quad >= 0):
            quad, x = 1, xm
        elif gen:
            quad, x = -1, xg
        else:
            x = 0.0
        self.quad[j] = quad
        return x if (x - load) * s > 0.0 else math.nan

    def _stiction(self, tau_out: list, r_rest: list, q: list, v: list) -> list:
        """Accelerations with the joints at rest stuck unless they break away (module
        docstring). ``tau_out``: output torques, 0 at the joints at rest; ``r_rest``: (joint,
        driving torque r0 [N m], warm-up factor) per joint at rest."""
        body = self._body
        if len(r_rest) == 1:  # one joint at rest: hold it, or release it
            j, r, w = r_rest[0]
            ddq, load = body.hold_one(q, v, tau_out, j)
            ex, s, load = self._band(j, load, r, w)
            if not s:
                return ddq
            x = self._breakaway(j, load, r, w, s)
            if x != x:  # NaN: stays at rest
                return ddq
            con = body.constrained(q, v, tau_out)
            con.release(j, x)
            ddq = con.free()
            if ddq[j] * s <= 0.0:
                con.release(j, -x)
                ddq = con.hold([j])[0]
            return ddq
        con = body.constrained(q, v, tau_out)
        stuck = [j for j, _, _ in r_rest]
        band = {j: (r, w) for j, r, w in r_rest}
        blocked: set = set()
        released: list = []  # (joint, direction, output torque)
        for _ in range(len(stuck) + 1):
            if not stuck:
                ddq = con.free()
                break
            ddq, lam = con.hold(stuck)
            best, best_ex = -1, 0.0
            for i, j in enumerate(stuck):
                if j in blocked:
                    continue
                ex, sj, load = self._band(j, lam[i], *band[j])
                if ex > best_ex:
                    best, best_ex, s, rel = i, ex, sj, load
            if best < 0:
                break
            j = stuck[best]
            r, w = band[j]
            x = self._breakaway(j, rel, r, w, s)
            if x != x:  # cannot happen with a valid plant: stay at rest
                blocked.add(j)
                continue
            con.release(j, x)
            stuck.pop(best)
            released.append((j, s, x))
        else:
            ddq = con.hold(stuck)[0] if stuck else con.free()
        wrong = [(j, x) for j, s, x in released if ddq[j] * s <= 0.0]
        if wrong:  # coupled releases pulled a joint back: hold it (see docstring)
            for j, x in wrong:
                con.release(j, -x)
                stuck.append(j)
            ddq = con.hold(stuck)[0]
        return ddq

    def _events(self, tau: list, q: list, v: list, t: float, a: list) -> None:
        """One sub-step from (q, v) (updated in place) with event detection, ``a`` the
        accelerations at its start: split at the earliest zero crossing of a velocity, that
        joint stops exactly, the dynamics are re-evaluated (stiction test) and the rest of the
        sub-step integrated, with further events if needed."""
        rem, tt = self.h, t
        rng_k = range(self.k)
        for ev in range(self._max_events):
            if ev:
                a, _ = self.accel(tau, q, v, tt)
            # earliest zero crossing of a velocity within the rest of the sub-step
            th = rem
            hit = None
            for j in rng_k:
                vj = v[j]
                if vj != 0.0 and (vj + a[j] * rem) * vj <= 0.0:
                    aj = a[j]
                    tj = -vj / aj if aj != 0.0 else rem
                    if tj > rem:
                        tj = rem
                    if hit is None or tj < th:
                        th, hit = tj, [j]
                    elif tj == th:
                        hit.append(j)
            if hit is None:
                th = rem
            # stop there (exactly), re-test stiction, integrate the rest of the sub-step
            for j in rng_k:
                vj = v[j]
                wj = 0.0 if hit is not None and j in hit else vj + a[j] * th
                q[j] += 0.5 * (vj + wj) * th
                v[j] = wj
            rem -= th
            tt += th
            if hit is None or rem <= 0.0:
                return
        # too many events in one sub-step: finish it without detection
        a, _ = self.accel(tau, q, v, tt)
        for j in rng_k:
            vj = v[j]
            wj = vj + a[j] * rem
            q[j] += 0.5 * (vj + wj) * rem
            v[j] = wj

    def advance(self, q: list, v: list, t: float, lag: list, cmd: list, noise: list,
                substeps: int) -> tuple:
        """Integrate ``substeps`` sub-steps from (q, v, t) with the command ``cmd`` [N m] held
        and the noise sample ``noise`` [N m] (lists of floats).

        Returns
        -------
        tuple
            ``(q, v, t, lag, ddq_start, tau_start, regime_start)``: the state at the end, the
            lagged command, and the acceleration, applied torque and regime just after the
            command was applied.
        """
        h = self.h
        keep = self.keep
        accel = self.accel
        rng_k = range(self.k)
        static, sliding = self._static, self._sliding
        q, v = list(q), list(v)  # updated in place below
        if keep is None:
            tau = [c + n for c, n in zip(cmd, noise, strict=True)]
        else:
            lag = [lg if kp > 0.0 else c for lg, kp, c in zip(lag, keep, cmd, strict=True)]
            tau = [0.0] * self.k
        for i in range(substeps):
            if keep is not None:
                if i == 1:
                    tau = list(tau)  # the first sub-step's torques are returned
                for j in rng_k:
                    tau[j] = lag[j] + noise[j]
            a, regime = accel(tau, q, v, t)
            if i == 0:
                a0, tau0, reg0 = a, tau, regime
            if static and regime is not sliding and not any(a) and not any(v):
                # every joint held at rest and nothing changes with time: so are the other
                # sub-steps (same inputs, same answer)
                for _ in range(i, substeps):
                    t += h
                break
            for j in rng_k:  # a velocity reaching zero within the sub-step: an event
                vj = v[j]
                if vj != 0.0 and (vj + a[j] * h) * vj <= 0.0:
                    self._events(tau, q, v, t, a)
                    break
            else:
                for j in rng_k:
                    vj = v[j]
                    wj = vj + a[j] * h
                    q[j] += 0.5 * (vj + wj) * h
                    v[j] = wj
            t += h
            if keep is not None:
                for j in rng_k:
                    lag[j] = cmd[j] + (lag[j] - cmd[j]) * keep[j]
        if keep is None:
            lag = cmd
        return q, v, t, lag, a0, tau0, reg0


