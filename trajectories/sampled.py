"""What a plan is: :class:`RobotPlan` (the sampled reference of every moving joint), its pieces,
its one-joint view :class:`Reference` and its :class:`RobotPlanSummary`.

One plan type from one joint to n: a ``[joint]`` campaign is planned as a robot with one moving
joint (:func:`trajectories.multi.plan_robot_campaign`), and :attr:`RobotPlan.reference` gives
its joint's 1-D arrays to the single-joint consumers (the simulator, the runner's engine).
The planner is :mod:`trajectories.multi`. Pure: no files, clocks or buses.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from . import TrajectoryError
from .campaign import JointLimits

__all__ = [
    "BANDS",
    "FourierBlock",
    "MOVING_FRACTION",
    "POSITIONING_SPEED",
    "Piece",
    "Reference",
    "RobotPiece",
    "RobotPlan",
    "RobotPlanSummary",
    "band_shares",
    "coverage",
]

#: speed (fraction of max_velocity) of positioning moves, sine blends and the final return
POSITIONING_SPEED = 0.5
#: velocity bands of the summary, fractions of max_velocity (paper IV.B: 0-10 % is where
#: dry friction changes)
BANDS = (0.0, 0.1, 0.35, 1.0)
#: a sample is "moving" when |dq| > MOVING_FRACTION * max_velocity
MOVING_FRACTION = 1e-3


# --------------------------------------------------------------------------- pieces
@dataclass(frozen=True)
class RobotPiece:
    """One piece of a plan (for plots, tests and diagnostics).

    Attributes
    ----------
    kind : str
        ``"position"`` (to a trapezoid's start at the positioning speed), ``"move"``
        (trapezoid move at a speed), ``"dwell"``, ``"blend_in"``, ``"sine"``,
        ``"multisine"``, ``"blend_out"``, ``"pose"`` (move segment) or ``"return"``.
    segment : int
        Index into ``RobotPlan.segment_names``.
    t0, t1 : float
        Start and end [s].
    joint : int
        Index of the joint doing a trapezoid move or a sine (-1 otherwise).
    speed : float
        Cruise speed of that joint, fraction of max_velocity (nan otherwise).
    """

    kind: str
    segment: int
    t0: float
    t1: float
    joint: int = -1
    speed: float = math.nan


#: the pieces of a one-joint :class:`Reference` are the plan's
Piece = RobotPiece


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


# --------------------------------------------------------------------------- one joint
@dataclass(frozen=True, eq=False)
class Reference:
    """The sampled reference of a one-joint plan (read-only 1-D arrays): what the single-joint
    simulator and runner play. Made by :attr:`RobotPlan.reference`.

    Attributes
    ----------
    t : ndarray, shape (n,), float64
        Time [s], ``t[k] = k * cycle_s``.
    q, dq, ddq : ndarray, shape (n,), float64
        Position [rad], velocity [rad/s], acceleration [rad/s^2] ([m]... if prismatic).
    segment : ndarray, shape (n,), int32
        Index into ``segment_names`` of each sample.
    segment_names : tuple of str
        ``"segments[i] (kind)"`` for each campaign segment, then ``"return"``.
    pieces : tuple of Piece
        Moves, dwells, blends and sines in time order.
    cycle_s : float
        Sampling period [s].
    """

    t: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    segment: np.ndarray
    segment_names: tuple[str, ...]
    pieces: tuple[Piece, ...]
    cycle_s: float

    def __post_init__(self) -> None:
        for a in (self.t, self.q, self.dq, self.ddq, self.segment):
            a.flags.writeable = False

    @property
    def segments(self) -> tuple[str, ...]:
        """Alias of :attr:`segment_names`."""
        return self.segment_names

    @property
    def duration_s(self) -> float:
        """Time of the last sample [s]."""
        return float(self.t[-1])

    def __len__(self) -> int:
        return int(self.t.size)

    def jerk(self) -> np.ndarray:
        """Finite-difference jerk ``diff(ddq) / cycle_s`` [rad/s^3], shape (n-1,).

        Ruckig phases have constant jerk and ddq is continuous, so this is the mean jerk
        over each sampling interval: bounded by the true peak jerk.
        """
        return np.diff(self.ddq) / self.cycle_s


# --------------------------------------------------------------------------- the plan
@dataclass(frozen=True, eq=False)
class RobotPlan:
    """A sampled reference of every moving joint for one payload run (read-only arrays).

    Attributes
    ----------
    t : ndarray, shape (n,)
        Time [s], ``t[i] = i * cycle_s``.
    q, dq, ddq : ndarray, shape (n, k)
        Joint-side position [rad], velocity [rad/s], acceleration [rad/s^2] ([m]... for a
        prismatic joint).
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
    units : tuple of str
        ``"rad"`` or ``"m"`` per joint (empty: all ``"rad"``).
    keys : tuple of str
        Dotted key of each joint's table in the campaign file (``"joint"``,
        ``"robot.joints.j2"``; empty: ``robot.joints.<name>``), for messages.
    peak_torque : tuple of tuple of float
        Per payload and joint, peak |tau| of the torque model the plan was checked with
        [N m] (a ``[joint]`` campaign: its feed-forward model plus the payload, paper eq. 34;
        an estimate that ignores feedback and model error); empty when none was given.
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
    payloads: tuple = ()
    units: tuple[str, ...] = ()
    keys: tuple[str, ...] = ()
    peak_torque: tuple[tuple[float, ...], ...] = ()

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

    @property
    def run_duration_s(self) -> float:
        """Duration of one payload run [s] (alias of :attr:`duration_s`)."""
        return self.duration_s

    def unit(self, j: int) -> str:
        """Position unit of joint ``j``."""
        return self.units[j] if self.units else "rad"

    def key(self, j: int) -> str:
        """Dotted key of joint ``j``'s table in the campaign file."""
        return self.keys[j] if self.keys else f"robot.joints.{self.joint_names[j]}"

    def who(self, j: int) -> str:
        """``"joint <name>: "`` in messages, ``""`` for the joint of a ``[joint]`` campaign."""
        return "" if self.key(j) == "joint" else f"joint {self.joint_names[j]}: "

    @cached_property
    def reference(self) -> Reference:
        """The one joint's 1-D reference (a one-joint plan only)."""
        if self.n_joints != 1:
            raise TrajectoryError(f"plan {self.name!r}: a 1-D reference needs a plan of one "
                                  f"moving joint, this one has {self.n_joints}")
        return Reference(t=self.t, q=self.q[:, 0], dq=self.dq[:, 0], ddq=self.ddq[:, 0],
                         segment=self.segment, segment_names=self.segment_names,
                         pieces=self.pieces, cycle_s=self.cycle_s)

    def jerk(self) -> np.ndarray:
        """Finite-difference jerk ``diff(ddq) / cycle_s``, shape (n-1, k) [rad/s^3]."""
        return np.diff(self.ddq, axis=0) / self.cycle_s

    def band_shares(self) -> np.ndarray:
        """Per joint, share of its moving samples in each band of ``BANDS``, shape (k, 3)."""
        return band_shares(self.dq, self.limits)

    def summary(self) -> RobotPlanSummary:
        """Durations, segment times, per-joint peaks against limits, velocity bands (share of
        moving samples and of the position range covered) and peak torques per payload."""
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
        covs, moving_s = [], []
        for j, lim in enumerate(self.limits):
            speed = np.abs(self.dq[:, j]) / lim.max_velocity
            moving = speed > MOVING_FRACTION
            moving_s.append(float(moving.sum()) * self.cycle_s)
            row = []
            for i in range(len(BANDS) - 1):
                upper = speed < BANDS[i + 1] if i < len(BANDS) - 2 else np.ones_like(moving)
                band = moving & (speed >= BANDS[i]) & upper
                row.append(coverage(self.q[:, j], band) / lim.span)
            covs.append(tuple(row))
        return RobotPlanSummary(
            name=self.name, n_payloads=max(1, len(self.payloads)),
            run_duration_s=self.duration_s, segments=tuple(seg_rows),
            joint_names=self.joint_names, limits=self.limits, peaks=peaks,
            band_share=tuple(tuple(float(x) for x in row) for row in self.band_shares()),
            band_coverage=tuple(covs), moving_time_s=tuple(moving_s),
            units=tuple(self.unit(j) for j in range(self.n_joints)),
            payload_labels=tuple(getattr(p, "label", f"{p.mass_kg:g} kg")
                                 for p in self.payloads),
            peak_torque=self.peak_torque,
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


def coverage(q: np.ndarray, mask: np.ndarray) -> float:
    """Length [rad] of the union of the intervals [q_k, q_k+1] where both samples are in mask."""
    pair = mask[:-1] & mask[1:]
    if not pair.any():
        return 0.0
    a, b = q[:-1][pair], q[1:][pair]
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    order = np.argsort(lo, kind="stable")
    lo, hi = lo[order], hi[order]
    run_hi = np.maximum.accumulate(hi)
    new = np.empty(lo.size, dtype=bool)
    new[0] = True
    new[1:] = lo[1:] > run_hi[:-1]
    starts = np.flatnonzero(new)
    ends = np.append(starts[1:], lo.size) - 1
    return float(np.sum(run_hi[ends] - lo[starts]))


# --------------------------------------------------------------------------- summary
@dataclass(frozen=True)
class RobotPlanSummary:
    """Figures of a plan; ``str(summary)`` is the table ``jointid plan`` prints.

    Attributes
    ----------
    peaks : tuple of (q_min, q_max, |dq|, |ddq|, |jerk|) per joint
    band_share : tuple of tuples, (k, 3)
        Share of moving samples per velocity band (``BANDS``) per joint.
    band_coverage : tuple of tuples, (k, 3)
        Share of each joint's position range visited while in each band.
    moving_time_s : tuple of float
        Per joint, time with ``|dq| > MOVING_FRACTION * vmax`` in one run [s].
    units : tuple of str
        ``"rad"`` or ``"m"`` per joint.
    payload_labels : tuple of str
    peak_torque : tuple of tuples, (payloads, k)
        Peak |tau| of the plan's torque model [N m] (empty: none given).
    """

    name: str
    n_payloads: int
    run_duration_s: float
    segments: tuple[tuple[str, float, float], ...]
    joint_names: tuple[str, ...]
    limits: tuple[JointLimits, ...]
    peaks: tuple[tuple[float, float, float, float, float], ...]
    band_share: tuple[tuple[float, ...], ...]
    band_coverage: tuple[tuple[float, ...], ...] = ()
    moving_time_s: tuple[float, ...] = ()
    units: tuple[str, ...] = ()
    payload_labels: tuple[str, ...] = ()
    peak_torque: tuple[tuple[float, ...], ...] = ()

    @property
    def total_duration_s(self) -> float:
        """All payload runs [s]."""
        return self.n_payloads * self.run_duration_s

    def format_table(self) -> str:
        k = len(self.joint_names)
        units = self.units or ("rad",) * k
        u = units[0] if len(set(units)) == 1 else "rad or m"
        what = "campaign" if k == 1 else "robot campaign"
        moving = (f" (moving {max(self.moving_time_s):.1f} s per run)"
                  if self.moving_time_s else "")
        lines = [
            f"{what} {self.name!r}: {self.n_payloads} payload run(s) x "
            f"{self.run_duration_s:.1f} s = {self.total_duration_s:.1f} s, "
            f"{k} joint{'s' if k > 1 else ''}{moving}",
            "",
            f"{'segment':<26} {'start [s]':>10} {'duration [s]':>13}",
        ]
        lines += [f"{n:<26} {t0:>10.2f} {d:>13.2f}" for n, t0, d in self.segments]
        w = max(8, *(len(n) for n in self.joint_names))
        lines += ["", f"{'joint':<{w}} {f'q min/max (limit) [{u}]':>34} {'|dq| (vmax)':>18} "
                  f"{'|ddq| (amax)':>18} {'|jerk| (jmax)':>18}"]
        for nm, lim, (qa, qb, v, a, j) in zip(self.joint_names, self.limits, self.peaks,
                                              strict=True):
            lo, hi = lim.position
            qtxt = f"{qa:.3f}/{qb:.3f} ({lo:.3g}/{hi:.3g})"
            lines.append(f"{nm:<{w}} {qtxt:>34} {f'{v:.3g} ({lim.max_velocity:.3g})':>18} "
                         f"{f'{a:.3g} ({lim.max_acceleration:.3g})':>18} "
                         f"{f'{j:.3g} ({lim.max_jerk:.3g})':>18}")
        # one row per velocity band; per joint its share of moving samples and the share
        # of its position range covered in that band
        cov = self.band_coverage or tuple((math.nan,) * len(r) for r in self.band_share)
        head = f"{'velocity band':<18}"
        for nm in self.joint_names:
            head += f" {'moving time' if k == 1 else nm + ' moving':>14} {'coverage':>9}"
        lines += ["", head]
        for i, (lo, hi) in enumerate(zip(BANDS[:-1], BANDS[1:], strict=True)):
            row = f"{f'{100 * lo:.0f}-{100 * hi:.0f} % of vmax':<18}"
            for share, c in zip(self.band_share, cov, strict=True):
                row += f" {100 * share[i]:>13.1f}% {100 * c[i]:>8.1f}%"
            lines.append(row)
        if self.peak_torque:
            tu = "N m" if u == "rad" else "N" if u == "m" else "N m or N"
            lines += ["", f"peak |tau| [{tu}] (max_torque), per payload run",
                      f"{'payload':<20} " + " ".join(f"{nm:>18}" for nm in self.joint_names)]
            for lab, row in zip(self.payload_labels, self.peak_torque, strict=False):
                cells = [f"{f'{t:.4g} ({lim.max_torque:.4g})':>18}"
                         for t, lim in zip(row, self.limits, strict=True)]
                lines.append(f"{lab:<20} " + " ".join(cells))
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.format_table()
