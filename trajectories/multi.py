"""Coordinated multi-joint excitation plans: multi-DoF Ruckig moves and Fourier series.

(Past 600 lines: the plan's result types, its builder and its sampled limit checks belong
together; the Fourier numerics live in :mod:`trajectories.fourier`.)

A :class:`~trajectories.robot_campaign.RobotCampaign` (or a list of segments with per-joint
limits) becomes one sampled reference of every moving joint, run once per payload:

- every run starts at rest at the campaign's start pose and ends there at rest (a final
  ``return`` move at ``POSITIONING_SPEED``);
- ``trapezoid`` (:class:`TrapezoidSweep`): joint j goes to ``range[0]`` (the sweeping joints
  to the low end of their sweep range, the others to their start position), then at each
  speed moves to ``range[1]`` and back with a jerk-limited trapezoidal-velocity profile whose
  cruise speed is ``speed * max_velocity_j``. Each move is ONE multi-DoF Ruckig trajectory:
  joint j is time-optimal on its own (``Synchronization.No``, so its cruise speed is exactly
  the requested one), the sweeping joints go to the other end of their sweep range
  time-synchronised to the same duration (``Synchronization.Time``), at most
  ``sweep_speed * max_velocity``. Sweep directions alternate with every move and shift by
  one move at every other speed, so joint j moves both ways under both gravity ends;
- ``multisine`` (:class:`MultisineSegment`, Swevers et al. 1997 / FloBaRoID)::

      q_j(t) = q0_j + sum_l a_jl/(w l) sin(w l t) - b_jl/(w l) cos(w l t),   l = 1..L

  entered from rest by a synchronised Ruckig blend to the series' state at t = 0 and left,
  after ``periods`` periods, by a blend back to rest. Default coefficients (seeded) satisfy
  ``sum_l a_jl = 0`` and ``sum_l l b_jl = 0`` (L >= 2), i.e. dq(0) = ddq(0) = 0: the series
  starts and ends at rest and the blends are rest-to-rest moves;
- ``move`` (:class:`MoveSegment`): synchronised rest-to-rest moves through poses.

Every joint's reference is piecewise cubic (Ruckig phases, dwells) or a Fourier series,
evaluated vectorised on ``t = k * cycle_s`` (Ruckig phase data from ``Trajectory.profiles``,
as in :mod:`trajectories.plan`). Before a plan is returned, every sample of every joint is
checked against that joint's position, velocity, acceleration and (finite-difference) jerk
limits, plus, if an inverse-dynamics callable is given, the torque limits for every
payload; a violation raises :class:`trajectories.LimitError` naming the segment, the joint
and the limit.

Arrays follow ``RobotSignals``: shape (n samples, k joints). Pure: no files, clocks, buses.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import ruckig

from . import LimitError, TrajectoryError
from .campaign import JointLimits
from .fourier import (
    _ratios,
    default_coefficients,
    fit_coefficients,
    fourier_eval,
    multisine_ratio,
    rest_projection,
)

# the same speeds, velocity bands and limit-check tolerances as the single-joint plans
from .plan import (  # noqa: F401 (BANDS, MOVING_FRACTION: part of this module's API)
    _JERK_REL_TOL,
    _POS_TOL,
    _REL_TOL,
    BANDS,
    MOVING_FRACTION,
    POSITIONING_SPEED,
)
from .robot_campaign import (
    MoveSegment,
    MultisineSegment,
    RobotCampaign,
    RobotPayload,
    RobotSegment,
    TrapezoidSweep,
)

__all__ = [
    "BANDS",
    "FourierBlock",
    "MOVING_FRACTION",
    "POSITIONING_SPEED",
    "RobotPiece",
    "RobotPlan",
    "RobotPlanSummary",
    "default_coefficients",
    "fit_coefficients",
    "fourier_eval",
    "multisine_ratio",
    "plan_robot",
    "plan_robot_campaign",
    "rest_projection",
]


#: an inverse-dynamics model: (q, dq, ddq) each (n, k), payload -> tau (n, k) [N m]
InverseDynamics = Callable[[np.ndarray, np.ndarray, np.ndarray, RobotPayload], np.ndarray]


# --------------------------------------------------------------------------- results
@dataclass(frozen=True)
class RobotPiece:
    """One piece of a robot plan.

    Attributes
    ----------
    kind : str
        ``"position"``, ``"move"`` (trapezoid move at a speed), ``"dwell"``, ``"blend_in"``,
        ``"multisine"``, ``"blend_out"``, ``"pose"`` (move segment) or ``"return"``.
    segment : int
        Index into ``RobotPlan.segment_names``.
    t0, t1 : float
        Start and end [s].
    joint : int
        Index of the joint doing a trapezoid move (-1 otherwise).
    speed : float
        Cruise speed of that joint, fraction of max_velocity (nan otherwise).
    """

    kind: str
    segment: int
    t0: float
    t1: float
    joint: int = -1
    speed: float = math.nan


@dataclass(frozen=True)
class FourierBlock:
    """A multi-sine as played in a plan.

    Attributes
    ----------
    segment : int
    t0 : float
        Time of its t = 0 in the plan [s].
    periods : int
    q0 : ndarray, shape (k,)
    a, b : ndarray, shape (k, L)
    omega : float
        [rad/s].
    """

    segment: int
    t0: float
    periods: int
    q0: np.ndarray
    a: np.ndarray
    b: np.ndarray
    omega: float

    @property
    def duration_s(self) -> float:
        return self.periods * 2.0 * math.pi / self.omega


@dataclass(frozen=True, eq=False)
class RobotPlan:
    """A sampled multi-joint reference for one payload run (read-only arrays).

    Attributes
    ----------
    t : ndarray, shape (n,)
        Time [s], ``t[i] = i * cycle_s``.
    q, dq, ddq : ndarray, shape (n, k)
        Joint-side position [rad], velocity [rad/s], acceleration [rad/s^2].
    segment : ndarray, shape (n,), int32
        Index into ``segment_names``.
    segment_names : tuple of str
        ``"segments[i] (kind)"`` per segment, then ``"return"``.
    pieces : tuple of RobotPiece
    fourier : tuple of FourierBlock
        The multi-sines played, with their coefficients.
    joint_names : tuple of str
    limits : tuple of JointLimits
    cycle_s : float
    name : str
    payloads : tuple of RobotPayload
    """

    t: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    segment: np.ndarray
    segment_names: tuple[str, ...]
    pieces: tuple[RobotPiece, ...]
    fourier: tuple[FourierBlock, ...]
    joint_names: tuple[str, ...]
    limits: tuple[JointLimits, ...]
    cycle_s: float
    name: str = ""
    payloads: tuple[RobotPayload, ...] = ()

    def __post_init__(self) -> None:
        for arr in (self.t, self.q, self.dq, self.ddq, self.segment):
            arr.flags.writeable = False

    def __len__(self) -> int:
        return int(self.t.size)

    @property
    def n_joints(self) -> int:
        return len(self.joint_names)

    @property
    def duration_s(self) -> float:
        return float(self.t[-1])

    def jerk(self) -> np.ndarray:
        """Finite-difference jerk ``diff(ddq) / cycle_s``, shape (n-1, k) [rad/s^3]."""
        return np.diff(self.ddq, axis=0) / self.cycle_s

    def band_shares(self) -> np.ndarray:
        """Per joint, share of its moving samples in each band of ``BANDS``, shape (k, 3)."""
        return band_shares(self.dq, self.limits)

    def summary(self) -> RobotPlanSummary:
        """Durations, segment times, per-joint peaks against limits and velocity bands."""
        seg_rows = []
        for s, nm in enumerate(self.segment_names):
            idx = np.flatnonzero(self.segment == s)
            if idx.size:
                t0 = float(self.t[idx[0]])
                seg_rows.append((nm, t0, float(self.t[idx[-1]]) - t0 + self.cycle_s))
        jerk = self.jerk()
        peaks = tuple(
            (float(self.q[:, j].min()), float(self.q[:, j].max()),
             float(np.abs(self.dq[:, j]).max()), float(np.abs(self.ddq[:, j]).max()),
             float(np.abs(jerk[:, j]).max()) if len(jerk) else 0.0)
            for j in range(self.n_joints)
        )
        return RobotPlanSummary(
            name=self.name, n_payloads=max(1, len(self.payloads)),
            run_duration_s=self.duration_s, segments=tuple(seg_rows),
            joint_names=self.joint_names, limits=self.limits, peaks=peaks,
            band_share=tuple(tuple(float(x) for x in row) for row in self.band_shares()),
        )


def band_shares(dq: np.ndarray, limits: Sequence[JointLimits]) -> np.ndarray:
    """Share of each joint's moving samples (|dq| > MOVING_FRACTION vmax) per velocity band.

    Parameters
    ----------
    dq : ndarray, shape (n, k)
    limits : sequence of JointLimits, length k

    Returns
    -------
    ndarray, shape (k, len(BANDS) - 1); rows sum to 1 (0 for a joint that never moves).
    """
    vmax = np.array([lim.max_velocity for lim in limits])
    speed = np.abs(np.asarray(dq)) / vmax
    moving = speed > MOVING_FRACTION
    n_mov = moving.sum(axis=0)
    edges = np.array(BANDS[1:-1])
    band = np.searchsorted(edges, speed, side="right")  # 0..nb-1, speed == edge -> upper
    out = np.zeros((len(limits), len(BANDS) - 1))
    for i in range(len(BANDS) - 1):
        cnt = ((band == i) & moving).sum(axis=0)
        out[:, i] = np.where(n_mov > 0, cnt / np.maximum(n_mov, 1), 0.0)
    return out


@dataclass(frozen=True)
class RobotPlanSummary:
    """Figures of a robot plan; ``str(summary)`` is the table ``jointid plan`` prints.

    Attributes
    ----------
    peaks : tuple of (q_min, q_max, |dq|, |ddq|, |jerk|) per joint
    band_share : tuple of tuples, (k, 3)
        Share of moving samples per velocity band (``BANDS``) per joint.
    """

    name: str
    n_payloads: int
    run_duration_s: float
    segments: tuple[tuple[str, float, float], ...]
    joint_names: tuple[str, ...]
    limits: tuple[JointLimits, ...]
    peaks: tuple[tuple[float, float, float, float, float], ...]
    band_share: tuple[tuple[float, ...], ...]

    def format_table(self) -> str:
        lines = [
            f"robot campaign {self.name!r}: {self.n_payloads} payload run(s) x "
            f"{self.run_duration_s:.1f} s = {self.n_payloads * self.run_duration_s:.1f} s, "
            f"{len(self.joint_names)} joints",
            "",
            f"{'segment':<26} {'start [s]':>10} {'duration [s]':>13}",
        ]
        lines += [f"{n:<26} {t0:>10.2f} {d:>13.2f}" for n, t0, d in self.segments]
        w = max(8, *(len(n) for n in self.joint_names))
        lines += ["", f"{'joint':<{w}} {'q min/max (limit) [rad]':>34} {'|dq| (vmax)':>18} "
                  f"{'|ddq| (amax)':>18} {'|jerk| (jmax)':>18}"]
        for nm, lim, (qa, qb, v, a, j) in zip(self.joint_names, self.limits, self.peaks,
                                              strict=True):
            lo, hi = lim.position
            qtxt = f"{qa:.3f}/{qb:.3f} ({lo:.3g}/{hi:.3g})"
            lines.append(f"{nm:<{w}} {qtxt:>34} {f'{v:.3g} ({lim.max_velocity:.3g})':>18} "
                         f"{f'{a:.3g} ({lim.max_acceleration:.3g})':>18} "
                         f"{f'{j:.3g} ({lim.max_jerk:.3g})':>18}")
        heads = [f"{100 * lo:.0f}-{100 * hi:.0f} % vmax" for lo, hi in zip(BANDS[:-1], BANDS[1:],
                                                                           strict=True)]
        lines += ["", "share of moving samples per velocity band",
                  f"{'joint':<{w}} " + " ".join(f"{h:>14}" for h in heads)]
        for nm, row in zip(self.joint_names, self.band_share, strict=True):
            lines.append(f"{nm:<{w}} " + " ".join(f"{100 * x:>13.1f}%" for x in row))
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.format_table()


# --------------------------------------------------------------------------- builder
class _Builder:
    """Accumulates per-joint cubic phases and Fourier blocks of one run."""

    def __init__(self, names: Sequence[str], limits: Sequence[JointLimits],
                 start: Sequence[float], seg_names: list[str]) -> None:
        self.names = tuple(names)
        self.limits = tuple(limits)
        self.k = len(self.names)
        self.seg_names = seg_names
        self.start = np.asarray(start, dtype=np.float64)
        self.p = self.start.copy()
        self.v = np.zeros(self.k)
        self.a = np.zeros(self.k)
        self.t = 0.0
        # per joint rows: t0, duration, p, v, a, jerk, fourier block (-1: cubic), segment
        self.rows: list[list[tuple[float, ...]]] = [[] for _ in range(self.k)]
        self.blocks: list[FourierBlock] = []
        self.pieces: list[RobotPiece] = []
        self.otg = ruckig.Ruckig(self.k)
        self.vmax = np.array([lim.max_velocity for lim in self.limits])

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
        # a series' state at exactly the limit can be one ulp above it: accept the rounding
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
                raise LimitError(
                    f"{label}: joint {self.names[j]}: the {kind} reaches position {bad:.4g}, "
                    f"outside robot.joints.{self.names[j]}.limits.position [{lo:g}, {hi:g}]")
        t0 = self.t
        end = t0 + traj.duration
        if traj.duration <= 1e-12:  # already there (up to rounding)
            self.p, self.v, self.a = p1, v1, a1
            return
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
                    self.rows[j].append((tj, d, p, v, a, jk, -1.0, seg))
                    tj += d
            if end - tj > 0.0:  # a joint that finished early holds its final state
                self.rows[j].append((tj, end - tj, prof.pf, prof.vf, prof.af, 0.0, -1.0, seg))
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
                self.rows[j].append((self.t, duration, self.p[j], 0.0, 0.0, 0.0, -1.0, seg))
            self.pieces.append(RobotPiece("dwell", seg, self.t, self.t + duration))
            self.t += duration

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
            self.rows[j].append((self.t, d, math.nan, math.nan, math.nan, math.nan, bi, seg))
        self.pieces.append(RobotPiece("multisine", seg, self.t, self.t + d))
        self.t += d
        self.p, self.v, self.a = state
        z = np.zeros(self.k)
        self.ruckig(seg, "blend_out", state[0], z, z, vb)

    def sample(self, cycle_s: float) -> tuple[np.ndarray, ...]:
        total = self.t
        n = int(math.ceil(total / cycle_s - 1e-9)) + 1
        t = np.arange(n, dtype=np.float64) * cycle_s
        q = np.empty((n, self.k))
        dq = np.empty((n, self.k))
        ddq = np.empty((n, self.k))
        segment = np.zeros(n, dtype=np.int32)
        for j in range(self.k):
            rows = np.array(self.rows[j], dtype=np.float64).reshape(-1, 8)
            if rows.shape[0] == 0:  # nothing moves
                rows = np.array([[0.0, 0.0, self.p[j], 0.0, 0.0, 0.0, -1.0, 0.0]])
            start, dur, p0, v0, a0, j0, blk, seg = rows.T
            idx = np.clip(np.searchsorted(start, t, side="right") - 1, 0, rows.shape[0] - 1)
            tau = np.minimum(t - start[idx], dur[idx])
            p, v, a, jk = p0[idx], v0[idx], a0[idx], j0[idx]
            q[:, j] = p + tau * (v + tau * (a / 2.0 + tau * jk / 6.0))
            dq[:, j] = v + tau * (a + tau * jk / 2.0)
            ddq[:, j] = a + tau * jk
            bsel = blk[idx]
            for bi in np.unique(bsel[bsel >= 0]).astype(int):
                m = bsel == bi
                fb = self.blocks[bi]
                fq, fdq, fddq, _ = fourier_eval(fb.q0[j:j + 1], fb.a[j:j + 1], fb.b[j:j + 1],
                                                fb.omega, tau[m])
                q[m, j], dq[m, j], ddq[m, j] = fq[:, 0], fdq[:, 0], fddq[:, 0]
            if j == 0:
                segment = seg[idx].astype(np.int32)
        last = t >= total  # the run ends at rest exactly (Ruckig's end is exact to ~1e-15)
        dq[last] = 0.0
        ddq[last] = 0.0
        return t, q, dq, ddq, segment


def _seg_name(i: int, seg: RobotSegment) -> str:
    return f"segments[{i}] ({seg.kind})"


def _check_multisine(label: str, names, limits, q0, a, b, omega) -> None:
    r = _ratios(a, b, q0, omega, limits)
    what = (("position excursion", "position"), ("peak velocity", "max_velocity"),
            ("peak acceleration", "max_acceleration"), ("peak jerk", "max_jerk"))
    for j, nm in enumerate(names):
        for c in range(4):
            if r[j, c] > 1.0 + 1e-9:  # fill = 1 reaches 1 up to rounding
                raise LimitError(f"{label}: joint {nm}: {what[c][0]} reaches "
                                 f"{100 * r[j, c]:.1f} % of robot.joints.{nm}.limits."
                                 f"{what[c][1]}")


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
    names, limits = bld.names, bld.limits
    label = bld.seg_names[i]
    if isinstance(seg, TrapezoidSweep):
        if seg.joint not in names:
            raise TrajectoryError(f"{label}: joint {seg.joint!r} is not a moving joint")
        jj = names.index(seg.joint)
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
        return
    if isinstance(seg, MoveSegment):
        for pose in seg.poses:
            bld.move(i, pose, seg.speed, "pose")
            bld.dwell(i, seg.dwell_s)
        return
    q0, a, b = _resolve_multisine(seg, limits, bld.start)
    _check_multisine(label, names, limits, q0, a, b, seg.omega)
    bld.multisine(i, q0, a, b, seg.omega, seg.periods)


def _check_samples(plan: RobotPlan) -> None:
    """Sampled limit check of every joint (position, velocity, acceleration, jerk)."""
    jerk = plan.jerk()
    for j, (nm, lim) in enumerate(zip(plan.joint_names, plan.limits, strict=True)):
        lo, hi = lim.position
        tol_q = _POS_TOL * max(1.0, hi - lo)
        q, dq, ddq = plan.q[:, j], plan.dq[:, j], plan.ddq[:, j]
        checks = [
            ("position", (q < lo - tol_q) | (q > hi + tol_q), q, "position", f"[{lo:g}, {hi:g}]"),
            ("velocity", np.abs(dq) > lim.max_velocity * (1 + _REL_TOL), dq, "max_velocity",
             f"{lim.max_velocity:g}"),
            ("acceleration", np.abs(ddq) > lim.max_acceleration * (1 + _REL_TOL), ddq,
             "max_acceleration", f"{lim.max_acceleration:g}"),
        ]
        if len(jerk):
            jj = jerk[:, j]
            checks.append(("jerk", np.abs(jj) > lim.max_jerk * (1 + _JERK_REL_TOL) + 1e-9, jj,
                           "max_jerk", f"{lim.max_jerk:g}"))
        for what, bad, values, key, limit in checks:
            if bad.any():
                i = int(np.argmax(bad))
                raise LimitError(
                    f"{plan.segment_names[plan.segment[i]]}: joint {nm}: {what} "
                    f"{values[i]:.4g} at t = {plan.t[i]:.3f} s exceeds "
                    f"robot.joints.{nm}.limits.{key} {limit}")


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
        for j, (nm, lim) in enumerate(zip(plan.joint_names, plan.limits, strict=True)):
            bad = np.abs(tau[:, j]) > lim.max_torque
            if bad.any():
                i = int(np.argmax(bad))
                raise LimitError(
                    f"payloads[{p_i}] ({pay.mass_kg:g} kg): "
                    f"{plan.segment_names[plan.segment[i]]}: joint {nm}: torque "
                    f"{tau[i, j]:.4g} N m at t = {plan.t[i]:.3f} s exceeds "
                    f"robot.joints.{nm}.limits.max_torque {lim.max_torque:g} N m")
    return peaks


# --------------------------------------------------------------------------- public API
def plan_robot(segments: Sequence[RobotSegment], names: Sequence[str],
               limits: Sequence[JointLimits], start: Sequence[float], cycle_s: float, *,
               name: str = "", payloads: Sequence[RobotPayload] = ()) -> RobotPlan:
    """Plan segments in order from rest at ``start``, then back to ``start``.

    Parameters
    ----------
    segments : sequence of TrapezoidSweep, MultisineSegment, MoveSegment
    names : sequence of str, length k
        Moving joint names (trapezoid ``joint`` and ``sweep`` keys refer to them).
    limits : sequence of JointLimits, length k
    start : sequence of float, length k
        Rest pose [rad].
    cycle_s : float
        Sampling period [s].

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
    seg_names = [_seg_name(i, s) for i, s in enumerate(segments)] + ["return"]
    bld = _Builder(names, limits, start, seg_names)
    for i, seg in enumerate(segments):
        _add(bld, i, seg)
    bld.move(len(segments), bld.start, POSITIONING_SPEED, "return")
    t, q, dq, ddq, segment = bld.sample(cycle_s)
    plan = RobotPlan(t=t, q=q, dq=dq, ddq=ddq, segment=segment,
                     segment_names=tuple(seg_names), pieces=tuple(bld.pieces),
                     fourier=tuple(bld.blocks), joint_names=tuple(names),
                     limits=tuple(limits), cycle_s=cycle_s, name=name,
                     payloads=tuple(payloads))
    _check_samples(plan)
    return plan


def plan_robot_campaign(campaign: RobotCampaign, *,
                        inverse_dynamics: InverseDynamics | None = None) -> RobotPlan:
    """Plan a robot campaign (one reference, run once per payload).

    Parameters
    ----------
    campaign : RobotCampaign
    inverse_dynamics : callable, optional
        ``(q, dq, ddq, payload) -> tau (n, k)`` [N m] of the robot model; when given, every
        payload run's torque is checked against ``max_torque`` (:func:`check_torques`).

    Returns
    -------
    RobotPlan
    """
    plan = plan_robot(campaign.segments, campaign.moving, campaign.limits, campaign.start,
                      campaign.cycle_s, name=campaign.name, payloads=campaign.payloads)
    if inverse_dynamics is not None:
        check_torques(plan, inverse_dynamics, campaign.payloads)
    return plan
