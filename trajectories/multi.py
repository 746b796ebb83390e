"""The one planner: coordinated multi-joint excitation plans, from one moving joint to n.

(Past 600 lines: the builder, its segment kinds, its sampled limit and torque checks and the
public planning functions belong together; the result types live in
:mod:`trajectories.sampled`, the Fourier numerics in :mod:`trajectories.fourier`.)

A :class:`~trajectories.robot_campaign.RobotCampaign` -- of either file format: a ``[joint]``
file is read as a robot with one moving joint -- becomes one sampled reference of every
moving joint, run once per payload:

- every run starts at rest at the campaign's start pose and ends there at rest (a final
  ``return`` move at ``POSITIONING_SPEED``);
- ``trapezoid`` (:class:`TrapezoidSweep`): joint j goes to ``range[0]`` (the sweeping joints
  to the low end of their sweep range, the others to their start position), dwells (unless
  nothing moved before), then at each speed and cycle moves to ``range[1]``, dwells, back,
  dwells, with a jerk-limited trapezoidal-velocity profile whose cruise speed is
  ``speed * max_velocity_j``. Each move is ONE multi-DoF Ruckig trajectory: joint j is
  time-optimal on its own (``Synchronization.No``, so its cruise speed is exactly the
  requested one), the sweeping joints go to the other end of their sweep range
  time-synchronised to the same duration (``Synchronization.Time``), at most
  ``sweep_speed * max_velocity``. Sweep directions alternate with every move and shift by
  one move at every other speed, so joint j moves both ways under both gravity ends;
- ``sine`` (:class:`~trajectories.campaign.SineSegment`): ``periods`` exact periods of
  ``q_j = center - amplitude cos(2 pi f tau)`` of one joint, the others holding; Ruckig
  blends from rest to the sinusoid's state at its lowest point (``dq = 0``,
  ``ddq = amplitude (2 pi f)^2``) and back to rest, at the positioning speed, so the
  reference is continuous in q, dq and ddq;
- ``multisine`` (:class:`MultisineSegment`, Swevers et al. 1997 / FloBaRoID)::

      q_j(t) = q0_j + sum_l a_jl/(w l) sin(w l t) - b_jl/(w l) cos(w l t),   l = 1..L

  entered from rest by a synchronised Ruckig blend to the series' state at t = 0 and left,
  after ``periods`` periods, by a blend back to rest. Default coefficients (seeded) satisfy
  ``sum_l a_jl = 0`` and ``sum_l l b_jl = 0`` (L >= 2), i.e. dq(0) = ddq(0) = 0: the series
  starts and ends at rest and the blends are rest-to-rest moves;
- ``move`` (:class:`MoveSegment`): synchronised rest-to-rest moves through poses.

Every joint's reference is piecewise cubic (Ruckig phases from ``Trajectory.profiles``,
dwells), a sinusoid or a Fourier series, evaluated vectorised on ``t = k * cycle_s``. Before a
plan is returned, every sample of every joint is checked against that joint's position,
velocity, acceleration and (finite-difference) jerk limits, plus the torque limits for every
payload when a torque model is known (an inverse-dynamics callable; for a ``[joint]``
campaign its ``[control.feedforward]`` model plus the payload, paper eq. 31, 34); a violation
raises :class:`trajectories.LimitError` naming the segment, the joint's table (``joint`` or
``robot.joints.<name>``) and the limit.

Arrays follow ``RobotSignals``: shape (n samples, k joints). Pure: no files, clocks, buses.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np
import ruckig

from . import LimitError, TrajectoryError
from .campaign import JointLimits, SineSegment
from .fourier import (
    _ratios,
    default_coefficients,
    fit_coefficients,
    fourier_eval,
    multisine_ratio,
    rest_projection,
)
from .robot_campaign import (
    MoveSegment,
    MultisineSegment,
    RobotCampaign,
    RobotJoint,
    RobotPayload,
    RobotSegment,
    TrapezoidSweep,
)
from .sampled import (
    BANDS,
    MOVING_FRACTION,
    POSITIONING_SPEED,
    FourierBlock,
    Reference,
    RobotPiece,
    RobotPlan,
    RobotPlanSummary,
    band_shares,
)

__all__ = [
    "BANDS",
    "FourierBlock",
    "G",
    "MOVING_FRACTION",
    "POSITIONING_SPEED",
    "Reference",
    "RobotPiece",
    "RobotPlan",
    "RobotPlanSummary",
    "band_shares",
    "check_torques",
    "default_coefficients",
    "feedforward_dynamics",
    "fit_coefficients",
    "fourier_eval",
    "multisine_ratio",
    "plan_robot",
    "plan_robot_campaign",
    "rest_projection",
]

G = 9.81  # [m/s^2], as in daq.protocol.control

# relative tolerances of the sampled limit check (float rounding only)
_REL_TOL = 1e-9
_JERK_REL_TOL = 1e-6
# absolute position tolerance relative to the span of the position range
_POS_TOL = 1e-9
# a row of a joint's piecewise reference: t0, duration, p, v, a, jerk (cubic), Fourier block
# (-1: none), segment, sine centre, amplitude, omega (nan: no sine)
_NAN3 = (math.nan, math.nan, math.nan)

#: an inverse-dynamics model: (q, dq, ddq) each (n, k), payload -> tau (n, k) [N m]
InverseDynamics = Callable[[np.ndarray, np.ndarray, np.ndarray, RobotPayload], np.ndarray]


# --------------------------------------------------------------------------- builder
class _Builder:
    """Accumulates per-joint cubic phases, sinusoids and Fourier blocks of one run."""

    def __init__(self, names: Sequence[str], limits: Sequence[JointLimits],
                 start: Sequence[float], seg_names: list[str], units: tuple[str, ...],
                 keys: tuple[str, ...]) -> None:
        self.names = tuple(names)
        self.limits = tuple(limits)
        self.k = len(self.names)
        self.seg_names = seg_names
        self.units = units
        self.keys = keys
        self.start = np.asarray(start, dtype=np.float64)
        self.p = self.start.copy()
        self.v = np.zeros(self.k)
        self.a = np.zeros(self.k)
        self.t = 0.0
        # per joint rows: t0, duration, p, v, a, jerk, Fourier block (-1: none), segment,
        # sine centre, amplitude, omega
        self.rows: list[list[tuple[float, ...]]] = [[] for _ in range(self.k)]
        self.blocks: list[FourierBlock] = []
        self.pieces: list[RobotPiece] = []
        self.otg = ruckig.Ruckig(self.k)
        self.vmax = np.array([lim.max_velocity for lim in self.limits])

    def who(self, j: int) -> str:
        return "" if self.keys[j] == "joint" else f"joint {self.names[j]}: "

    def ruckig(self, seg: int, kind: str, p1, v1, a1, vmax, *, free: int = -1,
               speed: float = math.nan) -> None:
        """One multi-DoF Ruckig trajectory from the current state to (p1, v1, a1).

        ``free``: index of a joint planned time-optimally on its own (Synchronization.No);
        the others are time-synchronised to the whole trajectory's duration.
        """
        k = self.k
        p1, v1, a1 = (np.array(x, dtype=np.float64) for x in (p1, v1, a1))  # copies
        if np.array_equal(p1, self.p) and not self.v.any() and not self.a.any() \
                and not v1.any() and not a1.any():
            return
        inp = ruckig.InputParameter(k)
        inp.current_position = self.p.tolist()
        inp.current_velocity = self.v.tolist()
        inp.current_acceleration = self.a.tolist()
        inp.target_position = p1.tolist()
        inp.target_velocity = v1.tolist()
        inp.target_acceleration = a1.tolist()
        inp.max_velocity = [float(x) for x in vmax]
        # a sine's state at exactly the limit can be one ulp above it: accept the rounding
        inp.max_acceleration = [max(lim.max_acceleration, abs(x), abs(y))
                                for lim, x, y in zip(self.limits, self.a, a1, strict=True)]
        inp.max_jerk = [lim.max_jerk for lim in self.limits]
        if free >= 0:
            sync = [ruckig.Synchronization.Time] * k
            sync[free] = ruckig.Synchronization.No
            inp.per_dof_synchronization = sync
        traj = ruckig.Trajectory(k)
        label = self.seg_names[seg]
        try:
            result = self.otg.calculate(inp, traj)
        except (RuntimeError, ruckig.RuckigError) as exc:
            raise TrajectoryError(f"{label}: Ruckig cannot plan the {kind}: {exc}") from exc
        if result not in (ruckig.Result.Working, ruckig.Result.Finished):
            raise TrajectoryError(f"{label}: Ruckig cannot plan the {kind} ({result.name})")
        for j, lim in enumerate(self.limits):
            ext = traj.position_extrema[j]
            lo, hi = lim.position
            tol = _POS_TOL * max(1.0, hi - lo)
            if ext.min < lo - tol or ext.max > hi + tol:
                bad = ext.min if ext.min < lo - tol else ext.max
                u = self.units[j]
                raise LimitError(
                    f"{label}: {self.who(j)}the {kind} reaches position {bad:.4g} {u}, "
                    f"outside {self.keys[j]}.limits.position [{lo:g}, {hi:g}] {u}")
        t0 = self.t
        if traj.duration <= 1e-12:  # already there (up to rounding)
            self.p, self.v, self.a = p1, v1, a1
            return
        ends = []
        for j in range(k):
            prof = traj.profiles[0][j]
            tj = t0
            phases = []
            if prof.brake.duration > 0.0:
                br = prof.brake
                phases += [(br.t[i], br.p[i], br.v[i], br.a[i], br.j[i]) for i in range(2)]
            phases += [(prof.t[i], prof.p[i], prof.v[i], prof.a[i], prof.j[i]) for i in range(7)]
            for d, p, v, a, jk in phases:
                if d > 0.0:
                    self.rows[j].append((tj, d, p, v, a, jk, -1.0, seg, *_NAN3))
                    tj += d
            ends.append(tj)
        # when the move ends, to the last bit: one joint, the sum of its phases (as the
        # single-joint planner had it); several, Ruckig's duration (as the robot planner had
        # it). The two differ by rounding only; either keeps the plans of before bit for bit.
        end = ends[0] if k == 1 else t0 + traj.duration
        for j in range(k):
            if end - ends[j] > 0.0:  # a joint that finished early holds its final state
                prof = traj.profiles[0][j]
                self.rows[j].append((ends[j], end - ends[j], prof.pf, prof.vf, prof.af, 0.0,
                                     -1.0, seg, *_NAN3))
        self.t = end
        self.p, self.v, self.a = p1, v1, a1
        self.pieces.append(RobotPiece(kind, seg, t0, end, free, speed))

    def move(self, seg: int, target, speed: np.ndarray | float, kind: str, *,
             free: int = -1, piece_speed: float = math.nan) -> None:
        """Rest-to-rest move; ``speed`` scalar or per joint (fractions of max_velocity)."""
        z = np.zeros(self.k)
        vmax = np.broadcast_to(np.asarray(speed, dtype=np.float64), (self.k,)) * self.vmax
        self.ruckig(seg, kind, target, z, z, vmax, free=free, speed=piece_speed)

    def dwell(self, seg: int, duration: float) -> None:
        if duration > 0.0:
            for j in range(self.k):
                self.rows[j].append((self.t, duration, self.p[j], 0.0, 0.0, 0.0, -1.0, seg,
                                     *_NAN3))
            self.pieces.append(RobotPiece("dwell", seg, self.t, self.t + duration))
            self.t += duration

    def sine(self, seg: int, j: int, s: SineSegment) -> None:
        """Blend to the lowest point of joint j's sinusoid, play its periods, blend to rest."""
        w = s.omega
        z = np.zeros(self.k)
        p1 = self.p.copy()
        p1[j] = s.center - s.amplitude
        a1 = z.copy()
        a1[j] = s.amplitude * w * w
        vb = POSITIONING_SPEED * self.vmax
        self.ruckig(seg, "blend_in", p1, z, a1, vb, speed=POSITIONING_SPEED)
        d = s.periods / s.frequency_hz
        for i in range(self.k):
            if i == j:
                self.rows[i].append((self.t, d, math.nan, math.nan, math.nan, math.nan, -1.0,
                                     seg, s.center, s.amplitude, w))
            else:
                self.rows[i].append((self.t, d, self.p[i], 0.0, 0.0, 0.0, -1.0, seg, *_NAN3))
        self.pieces.append(RobotPiece("sine", seg, self.t, self.t + d, j))
        self.t += d
        self.ruckig(seg, "blend_out", p1, z, z, vb, speed=POSITIONING_SPEED)

    def multisine(self, seg: int, q0, a, b, omega: float, periods: int) -> None:
        q0 = np.asarray(q0, dtype=np.float64)
        qs, dqs, ddqs, _ = fourier_eval(q0, a, b, omega, np.zeros(1))
        amax = np.array([lim.max_acceleration for lim in self.limits])
        # a series at rest (rest_projection) has dq(0), ddq(0) at rounding level: snap to 0
        dq0 = np.where(np.abs(dqs[0]) < 1e-12 * self.vmax, 0.0, dqs[0])
        ddq0 = np.where(np.abs(ddqs[0]) < 1e-12 * amax, 0.0, ddqs[0])
        state = (qs[0], dq0, ddq0)
        # blends into a moving state may use the full velocity range
        vb = self.vmax if np.any(state[1] != 0.0) else POSITIONING_SPEED * self.vmax
        self.ruckig(seg, "blend_in", *state, vb)
        blk = FourierBlock(seg, self.t, periods, q0, np.asarray(a, dtype=np.float64),
                           np.asarray(b, dtype=np.float64), omega)
        bi = len(self.blocks)
        self.blocks.append(blk)
        d = blk.duration_s
        for j in range(self.k):
            self.rows[j].append((self.t, d, math.nan, math.nan, math.nan, math.nan, bi, seg,
                                 *_NAN3))
        self.pieces.append(RobotPiece("multisine", seg, self.t, self.t + d))
        self.t += d
        self.p, self.v, self.a = state
        z = np.zeros(self.k)
        self.ruckig(seg, "blend_out", state[0], z, z, vb)

    def sample(self, cycle_s: float) -> tuple[np.ndarray, ...]:
        total = self.t
        n = int(math.ceil(total / cycle_s - 1e-9)) + 1
        t = np.arange(n, dtype=np.float64) * cycle_s
        cols = []
        segment = np.zeros(n, dtype=np.int32)
        for j in range(self.k):
            rows = np.array(self.rows[j], dtype=np.float64).reshape(-1, 11)
            if rows.shape[0] == 0:  # nothing moves
                rows = np.array([[0.0, 0.0, self.p[j], 0.0, 0.0, 0.0, -1.0, 0.0, *_NAN3]])
            start, dur, p0, v0, a0, j0, blk, seg, cen, amp, om = rows.T
            idx = np.clip(np.searchsorted(start, t, side="right") - 1, 0, rows.shape[0] - 1)
            tau = np.minimum(t - start[idx], dur[idx])
            p, v, a, jk = p0[idx], v0[idx], a0[idx], j0[idx]
            q = p + tau * (v + tau * (a / 2.0 + tau * jk / 6.0))
            dq = v + tau * (a + tau * jk / 2.0)
            ddq = a + tau * jk
            if (blk >= 0).any():
                bsel = blk[idx]
                for bi in np.unique(bsel[bsel >= 0]).astype(int):
                    m = bsel == bi
                    fb = self.blocks[bi]
                    fq, fdq, fddq, _ = fourier_eval(fb.q0[j:j + 1], fb.a[j:j + 1],
                                                    fb.b[j:j + 1], fb.omega, tau[m])
                    q[m], dq[m], ddq[m] = fq[:, 0], fdq[:, 0], fddq[:, 0]
            if not np.isnan(om).all():
                is_sine = ~np.isnan(om[idx])
                ks = idx[is_sine]
                w = om[ks]
                wt = w * tau[is_sine]
                c, amp_s = cen[ks], amp[ks]
                q[is_sine] = c - amp_s * np.cos(wt)
                dq[is_sine] = amp_s * w * np.sin(wt)
                ddq[is_sine] = amp_s * w * w * np.cos(wt)
            last = t >= total  # the run ends at rest exactly (Ruckig's end: exact to ~1e-15)
            dq[last] = 0.0
            ddq[last] = 0.0
            cols.append((q, dq, ddq))
            if j == 0:
                segment = seg[idx].astype(np.int32)
        if self.k == 1:  # (n, 1) views of the one joint's arrays, no copy
            q, dq, ddq = (x.reshape(n, 1) for x in cols[0])
        else:
            q, dq, ddq = (np.stack(x, axis=1) for x in zip(*cols, strict=True))
        return t, q, dq, ddq, segment


def _seg_name(i: int, seg: RobotSegment) -> str:
    return f"segments[{i}] ({seg.kind})"


def _check_multisine(bld: _Builder, label: str, q0, a, b, omega) -> None:
    r = _ratios(a, b, q0, omega, bld.limits)
    what = (("position excursion", "position"), ("peak velocity", "max_velocity"),
            ("peak acceleration", "max_acceleration"), ("peak jerk", "max_jerk"))
    for j in range(bld.k):
        for c in range(4):
            if r[j, c] > 1.0 + 1e-9:  # fill = 1 reaches 1 up to rounding
                raise LimitError(f"{label}: {bld.who(j)}{what[c][0]} reaches "
                                 f"{100 * r[j, c]:.1f} % of {bld.keys[j]}.limits."
                                 f"{what[c][1]}")


def _check_sine(bld: _Builder, label: str, j: int, s: SineSegment) -> None:
    """Analytic peaks of a sine segment against joint j's limits (before planning)."""
    lim, u, key, who = bld.limits[j], bld.units[j], bld.keys[j], bld.who(j)
    v, a, jk = s.peaks()
    for what, val, lk, lv, unit in (
        ("peak velocity", v, "max_velocity", lim.max_velocity, f"{u}/s"),
        ("peak acceleration", a, "max_acceleration", lim.max_acceleration, f"{u}/s^2"),
        ("peak jerk", jk, "max_jerk", lim.max_jerk, f"{u}/s^3"),
    ):
        if val > lv * (1.0 + _REL_TOL):
            raise LimitError(f"{label}: {who}{what} {val:.4g} {unit} exceeds "
                             f"{key}.limits.{lk} {lv:g} {unit}")
    _check_range(bld, label, j, (s.center - s.amplitude, s.center + s.amplitude))


def _check_range(bld: _Builder, label: str, j: int, ext: tuple[float, float]) -> None:
    lim, u = bld.limits[j], bld.units[j]
    lo, hi = lim.position
    tol = _POS_TOL * max(1.0, lim.span)  # e.g. 0.1 - 1.3 = -1.2000000000000002 is fine
    if ext[0] < lo - tol or ext[1] > hi + tol:
        raise LimitError(f"{label}: {bld.who(j)}positions [{ext[0]:.4g}, {ext[1]:.4g}] {u} "
                         f"leave {bld.keys[j]}.limits.position [{lo:g}, {hi:g}] {u}")


def _joint_index(bld: _Builder, label: str, name: str) -> int:
    if not name and bld.k == 1:
        return 0
    if name not in bld.names:
        raise TrajectoryError(f"{label}: joint {name!r} is not a moving joint")
    return bld.names.index(name)


def _resolve_multisine(seg: MultisineSegment, limits, start) -> tuple[np.ndarray, ...]:
    q0 = np.asarray(seg.center if seg.center is not None else start, dtype=np.float64)
    if seg.a is not None:
        a = np.asarray(seg.a, dtype=np.float64)
        b = np.asarray(seg.b, dtype=np.float64)
    else:
        a, b = default_coefficients(limits, q0, seg.omega, seg.harmonics, fill=seg.fill,
                                    seed=seg.seed)
    return q0, a, b


def _add(bld: _Builder, i: int, seg: RobotSegment) -> None:
    label = bld.seg_names[i]
    if isinstance(seg, TrapezoidSweep):
        _add_trapezoid(bld, i, seg)
    elif isinstance(seg, SineSegment):
        j = _joint_index(bld, label, seg.joint)
        _check_sine(bld, label, j, seg)
        bld.sine(i, j, seg)
    elif isinstance(seg, MoveSegment):
        for pose in seg.poses:
            bld.move(i, pose, seg.speed, "pose")
            bld.dwell(i, seg.dwell_s)
    else:
        q0, a, b = _resolve_multisine(seg, bld.limits, bld.start)
        _check_multisine(bld, label, q0, a, b, seg.omega)
        bld.multisine(i, q0, a, b, seg.omega, seg.periods)


def _add_trapezoid(bld: _Builder, i: int, seg: TrapezoidSweep) -> None:
    label = bld.seg_names[i]
    names = bld.names
    jj = _joint_index(bld, label, seg.joint)
    if any(not 0.0 < s <= 1.0 for s in seg.speeds):
        raise LimitError(f"{label}: speeds must be fractions of max_velocity in (0, 1], "
                         f"got {list(seg.speeds)}")
    _check_range(bld, label, jj, seg.range)
    lo, hi = seg.range
    sweepers = [(names.index(n), r) for n, r in seg.sweep.items()]
    target = bld.start.copy()
    target[jj] = lo
    for s, r in sweepers:
        target[s] = r[0]
    bld.move(i, target, POSITIONING_SPEED, "position")
    bld.dwell(i, seg.dwell_s if bld.t > 0.0 else 0.0)
    up = False  # sweepers at their low end
    speed_vec = np.full(bld.k, seg.sweep_speed)
    for si, speed in enumerate(seg.speeds):
        if si % 2 == 1:  # shift the pairing of directions at every other speed
            up = not up
            for s, r in sweepers:
                target[s] = r[1] if up else r[0]
        for _ in range(seg.cycles):
            for end in (hi, lo):
                up = not up
                target[jj] = end
                for s, r in sweepers:
                    target[s] = r[1] if up else r[0]
                speed_vec[jj] = speed
                bld.move(i, target, speed_vec, "move", free=jj, piece_speed=speed)
                bld.dwell(i, seg.dwell_s)


def _check_samples(plan: RobotPlan) -> None:
    """Sampled limit check of every joint (position, velocity, acceleration, jerk)."""
    jerk = plan.jerk()
    for j, lim in enumerate(plan.limits):
        lo, hi = lim.position
        u, key, who = plan.unit(j), plan.key(j), plan.who(j)
        tol_q = _POS_TOL * max(1.0, hi - lo)
        q, dq, ddq = plan.q[:, j], plan.dq[:, j], plan.ddq[:, j]
        checks = [
            ("position", (q < lo - tol_q) | (q > hi + tol_q), q, "position",
             f"[{lo:g}, {hi:g}]", u),
            ("velocity", np.abs(dq) > lim.max_velocity * (1 + _REL_TOL), dq, "max_velocity",
             f"{lim.max_velocity:g}", f"{u}/s"),
            ("acceleration", np.abs(ddq) > lim.max_acceleration * (1 + _REL_TOL), ddq,
             "max_acceleration", f"{lim.max_acceleration:g}", f"{u}/s^2"),
        ]
        if len(jerk):
            jj = jerk[:, j]
            checks.append(("jerk", np.abs(jj) > lim.max_jerk * (1 + _JERK_REL_TOL) + 1e-9, jj,
                           "max_jerk", f"{lim.max_jerk:g}", f"{u}/s^3"))
        for what, bad, values, lk, limit, unit in checks:
            if bad.any():
                i = int(np.argmax(bad))
                raise LimitError(
                    f"{plan.segment_names[plan.segment[i]]}: {who}{what} "
                    f"{values[i]:.4g} {unit} at t = {plan.t[i]:.3f} s exceeds "
                    f"{key}.limits.{lk} {limit} {unit}")


def check_torques(plan: RobotPlan, inverse_dynamics: InverseDynamics,
                  payloads: Sequence[RobotPayload]) -> np.ndarray:
    """Check the inverse-dynamics torque of every payload run against ``max_torque``.

    Parameters
    ----------
    plan : RobotPlan
    inverse_dynamics : callable
        ``(q, dq, ddq, payload) -> tau``, arrays (n, k), tau joint side [N m].
    payloads : sequence of RobotPayload

    Returns
    -------
    ndarray, shape (len(payloads), k)
        Peak |tau| per payload and joint [N m].

    Raises
    ------
    trajectories.LimitError
        Naming the payload, the segment, the joint and the limit.
    """
    peaks = np.zeros((len(payloads), plan.n_joints))
    for p_i, pay in enumerate(payloads):
        tau = np.asarray(inverse_dynamics(plan.q, plan.dq, plan.ddq, pay), dtype=np.float64)
        if tau.shape != plan.q.shape:
            raise TrajectoryError(f"inverse_dynamics returned shape {tau.shape}, expected "
                                  f"{plan.q.shape}")
        peaks[p_i] = np.abs(tau).max(axis=0)
        for j, lim in enumerate(plan.limits):
            bad = np.abs(tau[:, j]) > lim.max_torque
            if bad.any():
                i = int(np.argmax(bad))
                tu = "N m" if plan.unit(j) == "rad" else "N"
                label = getattr(pay, "label", f"{pay.mass_kg:g} kg")
                raise LimitError(
                    f"payloads[{p_i}] ({label}): "
                    f"{plan.segment_names[plan.segment[i]]}: {plan.who(j)}torque "
                    f"{tau[i, j]:.4g} {tu} at t = {plan.t[i]:.3f} s exceeds "
                    f"{plan.key(j)}.limits.max_torque {lim.max_torque:g} {tu}")
    return peaks


def feedforward_dynamics(joints: Sequence[RobotJoint], *,
                         friction: bool = True) -> InverseDynamics:
    """The torque estimate of a ``[joint]`` campaign as an inverse-dynamics callable.

    Per joint, its ``[control.feedforward]`` model plus a point payload of ``mass_kg`` at
    ``arm_m`` (paper eq. 31, 34)::

        revolute:  tau = Fc sign(dq) + Fv dq + g (MX cos q + MY sin q)
                         + (J + M L^2) ddq + M L g cos q
        prismatic: tau = Fc sign(dq) + Fv dq + (J + M) ddq

    An estimate that ignores feedback and model error (the planner's torque check and the
    summary's peak torques).

    Parameters
    ----------
    joints : sequence of RobotJoint
        Their ``feedforward`` mappings (missing keys: 0).
    friction : bool
        False: leave ``Fc`` and ``Fv`` out (the output torque ``tau_out`` of the quadrant
        shares, paper Fig. 2).

    Returns
    -------
    callable
        ``(q, dq, ddq, payload) -> tau``, arrays (n, k) [N m] or [N].
    """
    keep = ("J", "MX", "MY", "Fc", "Fv") if friction else ("J", "MX", "MY")
    models = [(j.kind == "revolute", {k: float(j.feedforward.get(k, 0.0)) if k in keep else 0.0
                                      for k in ("J", "MX", "MY", "Fc", "Fv")}) for j in joints]

    # the payload-free part of the last (q, dq) seen: the same plan for every payload
    last: list = [None, None, None]

    def parts(q: np.ndarray, dq: np.ndarray) -> list[tuple[np.ndarray, np.ndarray | None]]:
        if last[0] is not q or last[1] is not dq:
            out = []
            for j, (rev, ff) in enumerate(models):
                qj, dqj = q[:, j], dq[:, j]
                base = ff["Fc"] * np.sign(dqj) + ff["Fv"] * dqj
                cq = None
                if rev:
                    cq, sq = np.cos(qj), np.sin(qj)
                    base = base + G * (ff["MX"] * cq + ff["MY"] * sq)
                out.append((base, cq))
            last[:] = [q, dq, out]
        return last[2]

    def tau(q: np.ndarray, dq: np.ndarray, ddq: np.ndarray, payload: RobotPayload) -> np.ndarray:
        m = payload.mass_kg
        arm = payload.arm_m if payload.arm_m is not None else math.hypot(*payload.com[:2])
        out = np.empty_like(np.asarray(q, dtype=np.float64))
        for j, ((rev, ff), (base, cq)) in enumerate(zip(models, parts(q, dq), strict=True)):
            if rev:
                out[:, j] = base + (ff["J"] + m * arm**2) * ddq[:, j] + m * arm * G * cq
            else:
                out[:, j] = base + (ff["J"] + m) * ddq[:, j]
        return out

    return tau


# --------------------------------------------------------------------------- public API
def plan_robot(segments: Sequence[RobotSegment], names: Sequence[str],
               limits: Sequence[JointLimits], start: Sequence[float], cycle_s: float, *,
               name: str = "", payloads: Sequence[RobotPayload] = (),
               units: Sequence[str] = (), keys: Sequence[str] = (), first_index: int = 0,
               return_to_start: bool = True) -> RobotPlan:
    """Plan segments in order from rest at ``start``, then back to ``start``.

    Parameters
    ----------
    segments : sequence of TrapezoidSweep, SineSegment, MultisineSegment, MoveSegment
    names : sequence of str, length k
        Moving joint names (trapezoid ``joint``, sine ``joint`` and ``sweep`` keys refer to
        them; with k = 1 an empty name is the one joint).
    limits : sequence of JointLimits, length k
    start : sequence of float, length k
        Rest pose [rad].
    cycle_s : float
        Sampling period [s].
    units : sequence of str, optional
        ``"rad"`` or ``"m"`` per joint (default ``"rad"``), for messages and summaries.
    keys : sequence of str, optional
        Dotted key of each joint's table in the campaign (default ``robot.joints.<name>``;
        ``"joint"`` for a ``[joint]`` campaign), for messages.
    first_index : int
        Index of the first segment in names and messages (``segments[first_index]``); the
        names of the earlier indices are placeholders (planning one segment of a campaign).
    return_to_start : bool
        End with the ``return`` move to ``start`` (default); False: end where the last
        segment ends, at rest.

    Returns
    -------
    RobotPlan
        At rest at ``start`` at both ends, every sample within every joint's limits.

    Raises
    ------
    trajectories.LimitError
        A segment would leave a joint's position range or exceed its velocity,
        acceleration or jerk limit (message: segment, joint, limit).
    trajectories.TrajectoryError
        Ruckig cannot plan a move.
    """
    if not (len(names) == len(limits) == len(start)) or not names:
        raise TrajectoryError(f"plan_robot: names, limits and start must have the same "
                              f"length >= 1, got {len(names)}, {len(limits)}, {len(start)}")
    units_t = tuple(units) or ("rad",) * len(names)
    keys_t = tuple(keys) or tuple(f"robot.joints.{n}" for n in names)
    seg_names = ([f"segments[{i}]" for i in range(first_index)]
                 + [_seg_name(first_index + i, s) for i, s in enumerate(segments)]
                 + ["return"])
    bld = _Builder(names, limits, start, seg_names, units_t, keys_t)
    for i, seg in enumerate(segments):
        _add(bld, first_index + i, seg)
    if return_to_start:
        bld.move(first_index + len(segments), bld.start, POSITIONING_SPEED, "return")
    t, q, dq, ddq, segment = bld.sample(cycle_s)
    plan = RobotPlan(t=t, q=q, dq=dq, ddq=ddq, segment=segment,
                     segment_names=tuple(seg_names), pieces=tuple(bld.pieces),
                     fourier=tuple(bld.blocks), joint_names=tuple(names),
                     limits=tuple(limits), cycle_s=cycle_s, name=name,
                     payloads=tuple(payloads), units=units_t, keys=keys_t)
    _check_samples(plan)
    return plan


def plan_robot_campaign(campaign: RobotCampaign, *,
                        inverse_dynamics: InverseDynamics | None = None) -> RobotPlan:
    """Plan a campaign (one reference, run once per payload): the one plan path.

    Parameters
    ----------
    campaign : RobotCampaign
        Either file format (a ``[joint]`` file: a robot with one moving joint, no robot
        file); with one moving joint ``plan.reference`` is its 1-D view.
    inverse_dynamics : callable, optional
        ``(q, dq, ddq, payload) -> tau (n, k)`` [N m] of the robot model; when given, every
        payload run's torque is checked against ``max_torque`` (:func:`check_torques`) and
        its peaks go into ``plan.peak_torque``. Default for a ``[joint]`` campaign: its
        feed-forward model (:func:`feedforward_dynamics`).

    Returns
    -------
    RobotPlan

    Raises
    ------
    trajectories.LimitError
        A segment would exceed a position, velocity, acceleration or jerk limit, or a
        payload run's torque would exceed ``max_torque``; the message names the segment (and
        payload), the joint's table and the limit.
    """
    if inverse_dynamics is None and campaign.plant == "joint":
        inverse_dynamics = feedforward_dynamics(campaign.joints)
    c = campaign
    plan = plan_robot(c.segments, c.moving, c.limits, c.start, c.cycle_s, name=c.name,
                      payloads=c.payloads, units=tuple(j.unit for j in c.joints),
                      keys=tuple(j.key for j in c.joints))
    if inverse_dynamics is not None:
        peaks = check_torques(plan, inverse_dynamics, campaign.payloads)
        plan = replace(plan, peak_torque=tuple(tuple(float(x) for x in row) for row in peaks))
    return plan
