"""Excitation plans: Ruckig jerk-limited moves and exact sinusoids, sampled at the control cycle.

(Past 600 lines: one sampled plan -- its types, the Ruckig moves, the exact sinusoids and
the limit checks they share.)

The paper (Hamon, Gautier & Garrec, section IV.B) excites friction with trapezoidal-velocity
and sinusoidal trajectories, with and without payloads. Identification needs many samples at
low velocity (0-10 % of max speed, where dry friction changes), the whole position range
(where gravity changes), both directions and both power quadrants. This module turns a
:class:`~trajectories.campaign.Campaign` into one sampled reference per payload run:

- every run starts at rest at ``campaign.joint.start`` and ends there at rest (a final
  ``return`` move at the positioning speed);
- trapezoid segments: go to ``range[0]`` (positioning speed), then for each speed and cycle
  move to ``range[1]``, dwell, back to ``range[0]``, dwell; each move is an offline Ruckig
  rest-to-rest trajectory with ``max_velocity = speed * vmax``;
- sine segments: Ruckig blends from rest to the sinusoid's exact state at its start phase,
  ``periods`` analytic periods, Ruckig blend back to rest; continuous in q, dq, ddq.

Everything is piecewise cubic (Ruckig phases, dwells) or analytic (sines), so the whole
reference is evaluated vectorised on the time grid ``t = k * cycle_s``; the Ruckig phase
data come from ``Trajectory.profiles``. Any plan that would exceed a limit raises
:class:`trajectories.LimitError` naming the segment and the limit, before anything moves.

Pure: no files, clocks or buses.

Why one file of ~660 lines: the sampled :class:`Reference`, the segment planner that builds it,
the sampled limit check and the plan summary all work on the same piecewise representation
(:class:`_Phases`); splitting the summary out would need the reference type in a third module
for a ~150-line gain.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import ruckig

from . import LimitError, TrajectoryError
from .campaign import (
    Campaign,
    Joint,
    JointLimits,
    Payload,
    Segment,
    SineSegment,
)

__all__ = [
    "BANDS",
    "CampaignPlan",
    "MOVING_FRACTION",
    "POSITIONING_SPEED",
    "Piece",
    "PlanSummary",
    "Reference",
    "plan_campaign",
    "plan_segment",
    "summarize",
]

#: speed (fraction of max_velocity) of positioning moves, sine blends and the final return
POSITIONING_SPEED = 0.5
#: velocity bands of the summary, fractions of max_velocity (paper IV.B: 0-10 % is where
#: dry friction changes)
BANDS = (0.0, 0.1, 0.35, 1.0)
#: a sample is "moving" when |dq| > MOVING_FRACTION * max_velocity
MOVING_FRACTION = 1e-3
G = 9.81  # [m/s^2], as in daq.protocol.control

# relative tolerances of the sampled limit check (float rounding only)
_REL_TOL = 1e-9
_JERK_REL_TOL = 1e-6
# absolute position tolerance relative to the span of the position range
_POS_TOL = 1e-9


# --------------------------------------------------------------------------- results
@dataclass(frozen=True)
class Piece:
    """One piece of a plan (for plots, tests and diagnostics).

    Attributes
    ----------
    kind : str
        ``"position"`` (move to a trapezoid's range at the positioning speed), ``"move"``
        (a trapezoid move at one of its speeds), ``"dwell"``, ``"blend_in"``, ``"sine"``,
        ``"blend_out"`` or ``"return"``.
    segment : int
        Index into ``Reference.segment_names``.
    t0, t1 : float
        Start and end time [s] from the start of the run.
    speed : float
        Cruise speed of a move, fraction of max_velocity (nan otherwise).
    """

    kind: str
    segment: int
    t0: float
    t1: float
    speed: float = math.nan


@dataclass(frozen=True, eq=False)
class Reference:
    """A sampled reference trajectory for one payload run (read-only arrays).

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


@dataclass(frozen=True)
class PlanSummary:
    """Figures of a campaign plan.

    Attributes
    ----------
    name : str
    n_payloads : int
    run_duration_s, total_duration_s : float
        Duration of one payload run and of all runs [s].
    moving_time_s : float
        Time with ``|dq| > MOVING_FRACTION * vmax`` in one run [s].
    band_edges : tuple of float
        Velocity band edges, fractions of max_velocity (``BANDS``).
    band_share : tuple of float
        Fraction of moving time in each band.
    band_coverage : tuple of float
        Fraction of ``joint.limits.position`` visited while in each band.
    q_min, q_max, peak_dq, peak_ddq, peak_jerk : float
        Extremes of the reference (jerk: finite difference, see :meth:`Reference.jerk`).
    peak_torque : tuple of float
        Per payload, peak |tau| of the feed-forward model (``[control.feedforward]`` plus
        the payload, paper eq. 34) [N m]; an estimate that ignores feedback and model error.
    segments : tuple of (str, float, float)
        ``(name, start [s], duration [s])`` per segment.
    limits : JointLimits
    unit : str
        ``"rad"`` or ``"m"``.
    """

    name: str
    n_payloads: int
    run_duration_s: float
    total_duration_s: float
    moving_time_s: float
    band_edges: tuple[float, ...]
    band_share: tuple[float, ...]
    band_coverage: tuple[float, ...]
    q_min: float
    q_max: float
    peak_dq: float
    peak_ddq: float
    peak_jerk: float
    peak_torque: tuple[float, ...]
    segments: tuple[tuple[str, float, float], ...]
    limits: JointLimits
    unit: str = "rad"
    payloads: tuple[Payload, ...] = field(default=())

    @property
    def peak_abs_q(self) -> float:
        """max |q| [rad]."""
        return max(abs(self.q_min), abs(self.q_max))

    def format_table(self) -> str:
        """Human-readable multi-line table (what ``jointid plan`` prints)."""
        u = self.unit
        lim = self.limits
        torque_u = "N m" if u == "rad" else "N"
        lines = [
            f"campaign {self.name!r}: {self.n_payloads} payload run(s) x "
            f"{self.run_duration_s:.1f} s = {self.total_duration_s:.1f} s "
            f"(moving {self.moving_time_s:.1f} s per run)",
            "",
            f"{'segment':<24} {'start [s]':>10} {'duration [s]':>13}",
        ]
        for name, t0, d in self.segments:
            lines.append(f"{name:<24} {t0:>10.2f} {d:>13.2f}")
        lines += [
            "",
            f"{'velocity band':<24} {'moving time':>12} {'coverage':>10}",
        ]
        e = self.band_edges
        for i, (share, cov) in enumerate(zip(self.band_share, self.band_coverage, strict=True)):
            band = f"{100 * e[i]:.0f}-{100 * e[i + 1]:.0f} % of vmax"
            lines.append(f"{band:<24} {100 * share:>11.1f}% {100 * cov:>9.1f}%")
        lines += [
            "",
            f"{'peak':<24} {'plan':>12} {'limit':>12}",
            f"{'q min / max [' + u + ']':<24} {self.q_min:>5.3f}/{self.q_max:<6.3f} "
            f"{lim.position[0]:>5.3g}/{lim.position[1]:<6.3g}",
            f"{'|dq| [' + u + '/s]':<24} {self.peak_dq:>12.4g} {lim.max_velocity:>12.4g}",
            f"{'|ddq| [' + u + '/s^2]':<24} {self.peak_ddq:>12.4g} {lim.max_acceleration:>12.4g}",
            f"{'|jerk| [' + u + '/s^3]':<24} {self.peak_jerk:>12.4g} {lim.max_jerk:>12.4g}",
        ]
        for p, tau in zip(self.payloads, self.peak_torque, strict=False):
            label = f"|tau_ff| {p.mass_kg:g} kg [{torque_u}]"
            lines.append(f"{label:<24} {tau:>12.4g} {lim.max_torque:>12.4g}")
        return "\n".join(lines)


@dataclass(frozen=True, eq=False)
class CampaignPlan:
    """A planned campaign: one reference, run once per payload.

    Attributes
    ----------
    campaign : Campaign
    reference : Reference
        The sampled reference of one run (identical for every payload).
    payloads : tuple of Payload
    """

    campaign: Campaign
    reference: Reference
    payloads: tuple[Payload, ...]

    @property
    def run_duration_s(self) -> float:
        return self.reference.duration_s

    def summary(self) -> PlanSummary:
        """Durations, velocity-band shares and coverage, peaks (see :class:`PlanSummary`)."""
        return summarize(self.reference, self.campaign)


# --------------------------------------------------------------------------- builder
class _Phases:
    """Accumulates cubic phases (Ruckig, dwell) and sine phases of one run."""

    def __init__(self, joint: Joint, names: list[str]) -> None:
        self.joint = joint
        self.lim = joint.limits
        self.names = names
        self.t = 0.0
        self.q = joint.start
        # per phase: start time, duration, p0, v0, a0, jerk, sine centre/amplitude/omega, seg
        self.rows: list[tuple[float, ...]] = []
        self.pieces: list[Piece] = []
        self._otg = ruckig.Ruckig(1)

    # -- helpers
    def _label(self, seg: int) -> str:
        return self.names[seg]

    def _ruckig(self, seg: int, kind: str, state0, state1, vmax: float, speed: float) -> None:
        lim = self.lim
        inp = ruckig.InputParameter(1)
        inp.current_position = [state0[0]]
        inp.current_velocity = [state0[1]]
        inp.current_acceleration = [state0[2]]
        inp.target_position = [state1[0]]
        inp.target_velocity = [state1[1]]
        inp.target_acceleration = [state1[2]]
        inp.max_velocity = [vmax]
        # a sine at exactly the limit can have A w^2 one ulp above it: accept the rounding
        inp.max_acceleration = [max(lim.max_acceleration, abs(state0[2]), abs(state1[2]))]
        inp.max_jerk = [lim.max_jerk]
        traj = ruckig.Trajectory(1)
        try:
            result = self._otg.calculate(inp, traj)
        except (RuntimeError, ruckig.RuckigError) as exc:
            raise TrajectoryError(
                f"{self._label(seg)}: Ruckig cannot plan the {kind} from {state0} to {state1}: "
                f"{exc}"
            ) from exc
        if result not in (ruckig.Result.Working, ruckig.Result.Finished):
            raise TrajectoryError(
                f"{self._label(seg)}: Ruckig cannot plan the {kind} from {state0} to {state1} "
                f"({result.name})"
            )
        ext = traj.position_extrema[0]
        lo, hi = lim.position
        tol = _POS_TOL * max(1.0, lim.span)
        if ext.min < lo - tol or ext.max > hi + tol:
            bad = ext.min if ext.min < lo - tol else ext.max
            raise LimitError(
                f"{self._label(seg)}: the {kind} reaches position {bad:.4g} {self.joint.unit}, "
                f"outside joint.limits.position [{lo:g}, {hi:g}] {self.joint.unit}"
            )
        t_start = self.t
        prof = traj.profiles[0][0]
        brake = prof.brake
        if brake.duration > 0.0:
            for k in range(2):
                if brake.t[k] > 0.0:
                    self._cubic(seg, brake.t[k], brake.p[k], brake.v[k], brake.a[k], brake.j[k])
        for k in range(7):
            if prof.t[k] > 0.0:
                self._cubic(seg, prof.t[k], prof.p[k], prof.v[k], prof.a[k], prof.j[k])
        self.q = state1[0]
        if self.t > t_start:
            self.pieces.append(Piece(kind, seg, t_start, self.t, speed))

    def _cubic(self, seg: int, d: float, p: float, v: float, a: float, j: float) -> None:
        self.rows.append((self.t, d, p, v, a, j, math.nan, math.nan, math.nan, seg))
        self.t += d

    # -- pieces
    def move(self, seg: int, target: float, speed: float, kind: str = "move") -> None:
        """Rest-to-rest move at ``speed`` (fraction of max_velocity)."""
        if target == self.q:
            return
        vmax = speed * self.lim.max_velocity
        self._ruckig(seg, kind, (self.q, 0.0, 0.0), (target, 0.0, 0.0), vmax, speed)

    def dwell(self, seg: int, duration: float) -> None:
        if duration > 0.0:
            t0 = self.t
            self._cubic(seg, duration, self.q, 0.0, 0.0, 0.0)
            self.pieces.append(Piece("dwell", seg, t0, self.t))

    def sine(self, seg: int, s: SineSegment) -> None:
        w = s.omega
        q0 = s.center - s.amplitude
        a0 = s.amplitude * w * w
        vmax = self.lim.max_velocity * POSITIONING_SPEED
        self._ruckig(seg, "blend_in", (self.q, 0.0, 0.0), (q0, 0.0, a0), vmax,
                     POSITIONING_SPEED)
        d = s.periods / s.frequency_hz
        t0 = self.t
        self.rows.append((self.t, d, math.nan, math.nan, math.nan, math.nan,
                          s.center, s.amplitude, w, seg))
        self.t += d
        self.pieces.append(Piece("sine", seg, t0, self.t))
        self._ruckig(seg, "blend_out", (q0, 0.0, a0), (q0, 0.0, 0.0), vmax, POSITIONING_SPEED)

    # -- sampling
    def sample(self, cycle_s: float) -> Reference:
        rows = np.array(self.rows, dtype=np.float64).reshape(-1, 10)
        if rows.shape[0] == 0:  # nothing moves: one rest sample
            rows = np.array([[0.0, 0.0, self.q, 0.0, 0.0, 0.0, np.nan, np.nan, np.nan, 0]])
        start, dur, p0, v0, a0, j0, cen, amp, om, seg = rows.T
        total = float(start[-1] + dur[-1])
        n = int(math.ceil(total / cycle_s - 1e-9)) + 1
        t = np.arange(n, dtype=np.float64) * cycle_s
        k = np.clip(np.searchsorted(start, t, side="right") - 1, 0, rows.shape[0] - 1)
        tau = np.minimum(t - start[k], dur[k])
        is_sine = ~np.isnan(om[k])
        p, v, a, j = p0[k], v0[k], a0[k], j0[k]
        q = p + tau * (v + tau * (a / 2.0 + tau * j / 6.0))
        dq = v + tau * (a + tau * j / 2.0)
        ddq = a + tau * j
        if is_sine.any():
            ks = k[is_sine]
            wt = om[ks] * tau[is_sine]
            c, amp_s, w = cen[ks], amp[ks], om[ks]
            q[is_sine] = c - amp_s * np.cos(wt)
            dq[is_sine] = amp_s * w * np.sin(wt)
            ddq[is_sine] = amp_s * w * w * np.cos(wt)
        # the run ends at rest exactly (Ruckig's final state is exact to ~1e-15)
        last = t >= total
        dq[last] = 0.0
        ddq[last] = 0.0
        return Reference(
            t=t,
            q=q,
            dq=dq,
            ddq=ddq,
            segment=seg[k].astype(np.int32),
            segment_names=tuple(self.names),
            pieces=tuple(self.pieces),
            cycle_s=cycle_s,
        )


def _segment_name(i: int, seg: Segment) -> str:
    return f"segments[{i}] ({seg.kind})"


def _check_segment(i: int, seg: Segment, joint: Joint) -> None:
    """Analytic limit checks before planning (LimitError naming the segment and limit)."""
    lim = joint.limits
    u = joint.unit
    name = _segment_name(i, seg)
    lo, hi = lim.position
    if isinstance(seg, SineSegment):
        v, a, j = seg.peaks()
        for what, val, key, lv, unit in (
            ("peak velocity", v, "max_velocity", lim.max_velocity, f"{u}/s"),
            ("peak acceleration", a, "max_acceleration", lim.max_acceleration, f"{u}/s^2"),
            ("peak jerk", j, "max_jerk", lim.max_jerk, f"{u}/s^3"),
        ):
            if val > lv * (1.0 + _REL_TOL):
                raise LimitError(
                    f"{name}: {what} {val:.4g} {unit} exceeds joint.limits.{key} {lv:g} {unit}"
                )
        ext = (seg.center - seg.amplitude, seg.center + seg.amplitude)
    else:
        if any(not 0.0 < s <= 1.0 for s in seg.speeds):
            raise LimitError(f"{name}: speeds must be fractions of max_velocity in (0, 1], "
                             f"got {list(seg.speeds)}")
        ext = seg.range
    tol = _POS_TOL * max(1.0, lim.span)  # e.g. 0.1 - 1.3 = -1.2000000000000002 is fine
    if ext[0] < lo - tol or ext[1] > hi + tol:
        raise LimitError(
            f"{name}: positions [{ext[0]:.4g}, {ext[1]:.4g}] {u} leave joint.limits.position "
            f"[{lo:g}, {hi:g}] {u}"
        )


def _add_segment(ph: _Phases, i: int, seg: Segment) -> None:
    _check_segment(i, seg, ph.joint)
    if isinstance(seg, SineSegment):
        ph.sine(i, seg)
        return
    lo, hi = seg.range
    ph.move(i, lo, POSITIONING_SPEED, kind="position")
    ph.dwell(i, seg.dwell_s if ph.t > 0.0 else 0.0)
    for speed in seg.speeds:
        for _ in range(seg.cycles):
            ph.move(i, hi, speed)
            ph.dwell(i, seg.dwell_s)
            ph.move(i, lo, speed)
            ph.dwell(i, seg.dwell_s)


def _check_samples(ref: Reference, joint: Joint) -> None:
    """Sampled limit check (position, velocity, acceleration, finite-difference jerk)."""
    lim = joint.limits
    u = joint.unit
    lo, hi = lim.position
    tol_q = _POS_TOL * max(1.0, lim.span)
    checks = (
        ("position", (ref.q < lo - tol_q) | (ref.q > hi + tol_q), ref.q,
         "position", f"[{lo:g}, {hi:g}]", u),
        ("velocity", np.abs(ref.dq) > lim.max_velocity * (1 + _REL_TOL), ref.dq,
         "max_velocity", f"{lim.max_velocity:g}", f"{u}/s"),
        ("acceleration", np.abs(ref.ddq) > lim.max_acceleration * (1 + _REL_TOL), ref.ddq,
         "max_acceleration", f"{lim.max_acceleration:g}", f"{u}/s^2"),
    )
    for what, bad, values, key, limit, unit in checks:
        if bad.any():
            k = int(np.argmax(bad))
            raise LimitError(
                f"{ref.segment_names[ref.segment[k]]}: {what} {values[k]:.4g} {unit} at "
                f"t = {ref.t[k]:.3f} s exceeds joint.limits.{key} {limit} {unit}"
            )
    if len(ref) > 1:
        jerk = ref.jerk()
        bad = np.abs(jerk) > lim.max_jerk * (1 + _JERK_REL_TOL) + 1e-9
        if bad.any():
            k = int(np.argmax(bad))
            raise LimitError(
                f"{ref.segment_names[ref.segment[k]]}: jerk {jerk[k]:.4g} {u}/s^3 at "
                f"t = {ref.t[k]:.3f} s exceeds joint.limits.max_jerk {lim.max_jerk:g} {u}/s^3"
            )


# --------------------------------------------------------------------------- public API
def plan_segment(
    segment: Segment,
    joint: Joint,
    cycle_s: float,
    *,
    start: float | None = None,
    index: int = 0,
    return_to_start: bool = False,
) -> Reference:
    """Plan and sample one segment alone, from rest at ``start``.

    Parameters
    ----------
    segment : TrapezoidSegment or SineSegment
    joint : Joint
        Kind and limits; ``joint.start`` is the default start position.
    cycle_s : float
        Sampling period [s].
    start : float, optional
        Rest position [rad] where the segment starts (default ``joint.start``).
    index : int
        Segment index used in names and messages (``segments[index]``).
    return_to_start : bool
        Append a move back to ``start`` (as :func:`plan_campaign` does after the last
        segment).

    Returns
    -------
    Reference
        Starts and ends at rest; ``segment_names`` has ``index + 1`` entries (earlier
        indices unused) plus ``"return"``.

    Raises
    ------
    trajectories.LimitError
        The segment would exceed a joint limit.
    """
    if start is not None:
        joint = Joint(joint.kind, joint.limits, float(start))
    names = [f"segments[{i}]" for i in range(index)] + [_segment_name(index, segment), "return"]
    ph = _Phases(joint, names)
    _add_segment(ph, index, segment)
    if return_to_start:
        ph.move(index + 1, joint.start, POSITIONING_SPEED, kind="return")
    ref = ph.sample(cycle_s)
    _check_samples(ref, joint)
    return ref


def plan_campaign(campaign: Campaign) -> CampaignPlan:
    """Plan a campaign: its segments in order from ``joint.start``, then back to it.

    Parameters
    ----------
    campaign : Campaign

    Returns
    -------
    CampaignPlan
        ``.reference`` sampled every ``campaign.cycle_s`` from t = 0, at rest at
        ``campaign.joint.start`` at both ends; run once per payload.

    Raises
    ------
    trajectories.LimitError
        Any segment would exceed a position, velocity, acceleration or jerk limit, or the
        feed-forward torque estimate of a payload run exceeds ``max_torque``; the message
        names the segment (or payload) and the limit.
    """
    joint = campaign.joint
    names = [_segment_name(i, s) for i, s in enumerate(campaign.segments)] + ["return"]
    ph = _Phases(joint, names)
    for i, seg in enumerate(campaign.segments):
        _add_segment(ph, i, seg)
    ph.move(len(campaign.segments), joint.start, POSITIONING_SPEED, kind="return")
    ref = ph.sample(campaign.cycle_s)
    _check_samples(ref, joint)
    torques = _peak_torques(ref, campaign)
    for i, (p, tau) in enumerate(zip(campaign.payloads, torques, strict=True)):
        if tau > campaign.limits.max_torque:
            raise LimitError(
                f"payloads[{i}] ({p.mass_kg:g} kg at {p.arm_m:g} m): feed-forward torque "
                f"estimate {tau:.4g} N m exceeds joint.limits.max_torque "
                f"{campaign.limits.max_torque:g} N m"
            )
    return CampaignPlan(campaign=campaign, reference=ref, payloads=campaign.payloads)


def _peak_torques(ref: Reference, campaign: Campaign) -> tuple[float, ...]:
    """Peak |tau| of the feed-forward model plus each payload (paper eq. 31, 34) [N m]."""
    ff = campaign.control.feedforward
    J, MX, MY = ff.get("J", 0.0), ff.get("MX", 0.0), ff.get("MY", 0.0)
    Fc, Fv = ff.get("Fc", 0.0), ff.get("Fv", 0.0)
    rev = campaign.joint.revolute
    base = Fc * np.sign(ref.dq) + Fv * ref.dq
    if rev:
        cq, sq = np.cos(ref.q), np.sin(ref.q)
        base = base + G * (MX * cq + MY * sq)
    out = []
    for p in campaign.payloads:
        if rev:
            tau = base + (J + p.mass_kg * p.arm_m**2) * ref.ddq + p.mass_kg * p.arm_m * G * cq
        else:
            tau = base + (J + p.mass_kg) * ref.ddq
        out.append(float(np.max(np.abs(tau))))
    return tuple(out)


def _coverage(q: np.ndarray, mask: np.ndarray) -> float:
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


def summarize(ref: Reference, campaign: Campaign) -> PlanSummary:
    """Compute the :class:`PlanSummary` of a reference planned for ``campaign``."""
    lim = campaign.limits
    speed = np.abs(ref.dq) / lim.max_velocity
    moving = speed > MOVING_FRACTION
    n_moving = int(moving.sum())
    shares, covs = [], []
    for i in range(len(BANDS) - 1):
        lo, hi = BANDS[i], BANDS[i + 1]
        upper = speed < hi if i < len(BANDS) - 2 else np.ones_like(moving)
        band = moving & (speed >= lo) & upper
        shares.append(float(band.sum()) / n_moving if n_moving else 0.0)
        covs.append(_coverage(ref.q, band) / lim.span)
    seg_rows = []
    for s in range(len(ref.segment_names)):
        idx = np.flatnonzero(ref.segment == s)
        if idx.size:
            t0 = float(ref.t[idx[0]])
            seg_rows.append((ref.segment_names[s], t0, float(ref.t[idx[-1]]) - t0 + ref.cycle_s))
    jerk = ref.jerk()
    run = ref.duration_s
    return PlanSummary(
        name=campaign.name,
        n_payloads=len(campaign.payloads),
        run_duration_s=run,
        total_duration_s=run * len(campaign.payloads),
        moving_time_s=n_moving * ref.cycle_s,
        band_edges=BANDS,
        band_share=tuple(shares),
        band_coverage=tuple(covs),
        q_min=float(ref.q.min()),
        q_max=float(ref.q.max()),
        peak_dq=float(np.abs(ref.dq).max()),
        peak_ddq=float(np.abs(ref.ddq).max()),
        peak_jerk=float(np.abs(jerk).max()) if jerk.size else 0.0,
        peak_torque=_peak_torques(ref, campaign),
        segments=tuple(seg_rows),
        limits=lim,
        unit=campaign.joint.unit,
        payloads=campaign.payloads,
    )
