"""The single-joint campaign format (``[joint]``): its schema, limits and excitation segments.

(Past 600 lines: one file format -- its documented dataclasses, schema, size check and quick
form; the robot format reuses its limits, segment fields and size check.)

There is one campaign type, :class:`~trajectories.robot_campaign.RobotCampaign`: a file of
this format is read by :func:`trajectories.campaign_file.load_campaign`
(:func:`~trajectories.robot_campaign.campaign_from_dict`) into a robot campaign with one
moving joint named ``joint``, without loss. This module validates the format (pure:
dictionaries in, frozen dataclasses out; the validated file, ``_JointCampaign``, is private
to :mod:`trajectories`) and holds what both formats share: :class:`JointLimits`, the
``trapezoid`` and ``sine`` segments, the sanity bounds, the plan-size check and the
shortening of quick runs (:func:`shorten_segments`). Every
mistake raises :class:`trajectories.SchemaError` with one line naming the source, the dotted
key and the expected value, e.g.::

    campaign.toml: segments[1].amplitude: expected center +/- amplitude within
    joint.limits.position [-1.2, 1.4] rad, got 1.5

File format (units: [rad] or [m] for prismatic joints, seconds)::

    name = "rx130l-joint3"
    [joint]
    kind = "revolute"                 # or "prismatic"
    start = 0.1                       # optional rest position where every run starts and ends;
                                      # default: the centre of joint.limits.position
    [joint.limits]
    position = [-1.2, 1.4]            # [rad], min < max
    max_velocity = 1.2                # [rad/s]
    max_acceleration = 4.0            # [rad/s^2]
    max_jerk = 40.0                   # [rad/s^3]
    max_torque = 700.0                # [N m]
    [control]
    cycle_s = 0.001                   # [s]
    kp = 6000.0                       # [N m/rad]
    kd = 200.0                        # [N m s/rad]
    velocity_cutoff_hz = 100.0        # optional [Hz]
    [control.feedforward]             # optional, each default 0: J, MX, MY, Fc, Fv
    J = 30.0
    [[payloads]]                      # one run per payload, in order
    mass_kg = 0.0
    arm_m = 1.277
    [[segments]]                      # ordered; repeated identically for every payload
    kind = "trapezoid"
    speeds = [0.08, 0.2, 0.5, 1.0]    # fractions of max_velocity, in (0, 1]
    range = [-1.1, 1.3]               # within joint.limits.position
    dwell_s = 0.3
    cycles = 1
    [[segments]]
    kind = "sine"
    amplitude = 1.1
    frequency_hz = 0.15
    center = 0.1
    periods = 2
    [daq]                             # optional, kept raw for daq/

Sanity bounds (:data:`SANE_LIMITS`, :data:`MAX_PLAN_CYCLES`): a joint limit beyond them
(|position| > 1e4, max_velocity > 1e3, max_acceleration > 1e5, max_jerk > 1e8, max_torque >
1e6, joint side, SI units) is refused: such a value is a typo or switches a supervision check
off (``max_velocity = 1e300`` makes the runner's velocity watchdog never fire). So is a plan
of more than ``MAX_PLAN_CYCLES`` cycles per payload (estimated from the segments before
anything is planned; the refusal names the segment's ``periods`` or ``cycles``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Literal

from . import SchemaError
from .schema import ArrayOfTables, Field, Table, TaggedTable, fail

#: upper bounds of the joint limits (joint side; rad or m based): beyond them a value is a
#: typo or turns a supervision check off; ``position`` bounds |min| and |max|
SANE_LIMITS = {"position": 1e4, "max_velocity": 1e3, "max_acceleration": 1e5,
               "max_jerk": 1e8, "max_torque": 1e6}
#: the most cycles one payload run may plan (1 h at 1 kHz): the plan and the runner's
#: per-cycle references are held in memory (about 150 bytes per cycle)
MAX_PLAN_CYCLES = 3_600_000

__all__ = [
    "FEEDFORWARD_KEYS",
    "Joint",
    "JointLimits",
    "Segment",
    "SineSegment",
    "TrapezoidSweep",
    "shorten_segments",
]

#: feed-forward keys of ``[control.feedforward]`` and the matching ControllerGains fields
FEEDFORWARD_KEYS = {"J": "J_ff", "MX": "MX_ff", "MY": "MY_ff", "Fc": "Fc_ff", "Fv": "Fv_ff"}


# --------------------------------------------------------------------------- dataclasses
@dataclass(frozen=True)
class JointLimits:
    """Joint limits, joint side.

    Attributes
    ----------
    position : tuple of float
        ``(min, max)`` [rad] (revolute) or [m] (prismatic), ``min < max``.
    max_velocity : float
        [rad/s] or [m/s], > 0.
    max_acceleration : float
        [rad/s^2] or [m/s^2], > 0.
    max_jerk : float
        [rad/s^3] or [m/s^3], > 0.
    max_torque : float
        [N m] or [N], > 0.
    """

    position: tuple[float, float]
    max_velocity: float
    max_acceleration: float
    max_jerk: float
    max_torque: float

    @property
    def span(self) -> float:
        """Width of the position range [rad] or [m]."""
        return self.position[1] - self.position[0]


@dataclass(frozen=True)
class Joint:
    """The identified joint.

    Attributes
    ----------
    kind : {"revolute", "prismatic"}
    limits : JointLimits
    start : float
        Rest position [rad] or [m] where each payload run starts and ends (default: the
        centre of ``limits.position``).
    """

    kind: Literal["revolute", "prismatic"]
    limits: JointLimits
    start: float

    @property
    def revolute(self) -> bool:
        return self.kind == "revolute"

    @property
    def unit(self) -> str:
        """Position unit, ``"rad"`` or ``"m"``."""
        return "rad" if self.revolute else "m"


@dataclass(frozen=True)
class _ControlSettings:
    """``[control]`` of a ``[joint]`` file (the robot campaign's joint carries the gains and
    feed-forward, :class:`~trajectories.robot_campaign.RobotJoint`).

    Attributes
    ----------
    cycle_s : float
        Control cycle [s]; the plan is sampled at this period.
    kp : float
        Proportional gain [N m/rad] or [N/m].
    kd : float
        Derivative gain [N m s/rad] or [N s/m].
    feedforward : dict
        ``{"J", "MX", "MY", "Fc", "Fv"}`` -> value (all keys present, default 0): inertia
        [kg m^2], first moments [kg m], Coulomb [N m], viscous [N m s/rad].
    velocity_cutoff_hz : float
        Cut-off of the controller's velocity-estimate low-pass [Hz].
    """

    cycle_s: float
    kp: float
    kd: float
    feedforward: Mapping[str, float] = field(default_factory=dict)
    velocity_cutoff_hz: float = 100.0


@dataclass(frozen=True)
class _Payload:
    """``[[payloads]]`` of a ``[joint]`` file: an additional mass fixed on the arm (paper
    IV.C, eq. 32-34; a :class:`~trajectories.robot_campaign.RobotPayload` with ``arm_m``).

    Attributes
    ----------
    mass_kg : float
        Mass M_a [kg], >= 0.
    arm_m : float
        Lever arm L_a [m] from the joint axis, >= 0.
    """

    mass_kg: float
    arm_m: float


@dataclass(frozen=True)
class TrapezoidSweep:
    """Jerk-limited trapezoidal-velocity moves of one joint while others sweep or hold: the
    trapezoid of both campaign formats.

    The segment first goes to ``range[0]`` at the positioning speed (the sweeping joints to
    the low end of their sweep range), dwells unless nothing moved before, then for each
    speed, ``cycles`` times: ``joint`` moves to ``range[1]``, dwell, back to ``range[0]``,
    dwell, each move at ``speed * max_velocity`` (its own time-optimal Ruckig profile). In
    the same synchronised Ruckig move every joint of ``sweep`` goes to the other end of its
    sweep range at up to ``sweep_speed * max_velocity`` (so the gravity load on ``joint``
    changes along the move); the other joints hold their start position.

    Attributes
    ----------
    joint : str
        The joint doing the trapezoids; ``""``: the only moving joint (a ``[joint]``
        campaign).
    speeds : tuple of float
        Cruise speeds as fractions of the joint's ``max_velocity``, each in (0, 1].
    range : tuple of float
        ``(low, high)`` [rad] or [m] within the joint's position limits.
    sweep : mapping of str to (float, float)
        Joint name -> ``(low, high)`` sweep range (robot campaigns; empty: none).
    sweep_speed : float
        Fraction of each sweeping joint's max_velocity, in (0, 1].
    dwell_s : float
        Rest after each move [s], >= 0.
    cycles : int
        Back-and-forth repetitions per speed, >= 1.
    """

    joint: str
    speeds: tuple[float, ...]
    range: tuple[float, float]
    sweep: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    sweep_speed: float = 0.25
    dwell_s: float = 0.3
    cycles: int = 1
    kind: Literal["trapezoid"] = "trapezoid"


@dataclass(frozen=True)
class SineSegment:
    """``periods`` periods of ``q = center - amplitude * cos(2 pi f tau)``.

    Ruckig blends the joint from rest to the sinusoid's state at its start phase (lowest
    point: ``q = center - amplitude``, ``dq = 0``, ``ddq = amplitude (2 pi f)^2``) and back
    to rest after the last period, so the segment is continuous in q, dq and ddq.

    Attributes
    ----------
    amplitude : float
        [rad] or [m], > 0.
    frequency_hz : float
        [Hz], > 0. Peaks: velocity A w, acceleration A w^2, jerk A w^3 (w = 2 pi f).
    center : float
        [rad] or [m].
    periods : int
        Number of full periods, >= 1.
    joint : str
        The moving joint that plays the sinusoid, in a robot campaign (the others hold their
        position); ``""``: the only moving joint (a ``[joint]`` campaign).
    """

    amplitude: float
    frequency_hz: float
    center: float
    periods: int = 1
    kind: Literal["sine"] = "sine"
    joint: str = ""

    @property
    def omega(self) -> float:
        """Angular frequency w = 2 pi f [rad/s]."""
        return 2.0 * math.pi * self.frequency_hz

    def peaks(self) -> tuple[float, float, float]:
        """Peak velocity, acceleration and jerk of the sinusoid ``(A w, A w^2, A w^3)``."""
        w = self.omega
        a = self.amplitude
        return a * w, a * w * w, a * w**3


Segment = TrapezoidSweep | SineSegment


@dataclass(frozen=True)
class _JointCampaign:
    """A validated ``[joint]`` file (immutable), private: read into the one campaign type,
    a :class:`~trajectories.robot_campaign.RobotCampaign` with one moving joint, by
    :func:`~trajectories.robot_campaign.campaign_from_dict`.

    Attributes
    ----------
    name : str
    joint : Joint
    control : _ControlSettings
    payloads : tuple of _Payload
        One run per payload, in file order.
    segments : tuple of Segment
        The excitation, repeated identically in every run.
    daq : dict
        The raw ``[daq]`` table (validated by :mod:`daq`), ``{}`` when absent.
    source : str
        Where the campaign came from (file name), used in messages.
    """

    name: str
    joint: Joint
    control: _ControlSettings
    payloads: tuple[_Payload, ...]
    segments: tuple[Segment, ...]
    daq: Mapping[str, Any] = field(default_factory=dict)
    source: str = ""

    @property
    def cycle_s(self) -> float:
        """Control cycle [s]."""
        return self.control.cycle_s

    @property
    def limits(self) -> JointLimits:
        return self.joint.limits

    @classmethod
    def from_dict(cls, raw: Mapping[str, Any], source: str = "") -> _JointCampaign:
        """Validate a parsed TOML mapping and build the campaign.

        Parameters
        ----------
        raw : mapping
            Output of ``tomllib.load``.
        source : str
            File name shown at the start of error messages.

        Raises
        ------
        trajectories.SchemaError
            Unknown key, wrong type, missing field, non-positive limit, segment outside the
            position range...; the one-line message names the key and the expected value.
        """
        top = _CAMPAIGN.validate(raw, "", source)
        j = top["joint"]
        lim = j["limits"]
        limits = JointLimits(
            position=(lim["position"][0], lim["position"][1]),
            max_velocity=lim["max_velocity"],
            max_acceleration=lim["max_acceleration"],
            max_jerk=lim["max_jerk"],
            max_torque=lim["max_torque"],
        )
        lo, hi = limits.position
        unit = "rad" if j["kind"] == "revolute" else "m"
        if len(lim["position"]) != 2 or not lo < hi:
            raise fail(source, "joint.limits.position", "[min, max] with min < max",
                       list(lim["position"]))
        rng = f"joint.limits.position [{lo:g}, {hi:g}] {unit}"
        start = j["start"] if j["start"] is not None else 0.5 * (lo + hi)
        if not lo <= start <= hi:
            raise fail(source, "joint.start", f"a position within {rng}", start)
        joint = Joint(kind=j["kind"], limits=limits, start=float(start))

        c = top["control"]
        ff = c["feedforward"] or {k: 0.0 for k in FEEDFORWARD_KEYS}
        control = _ControlSettings(
            cycle_s=c["cycle_s"],
            kp=c["kp"],
            kd=c["kd"],
            feedforward={k: float(ff[k]) for k in FEEDFORWARD_KEYS},
            velocity_cutoff_hz=c["velocity_cutoff_hz"],
        )
        payloads = tuple(_Payload(p["mass_kg"], p["arm_m"]) for p in top["payloads"])

        segments: list[Segment] = []
        for i, s in enumerate(top["segments"]):
            segments.append(_segment(s, f"segments[{i}]", source, limits, rng))
        check_plan_size(segments, [min_duration_s(s, limits) for s in segments],
                        control.cycle_s, source)
        daq = top["daq"] if isinstance(top["daq"], dict) else {}
        return cls(
            name=top["name"],
            joint=joint,
            control=control,
            payloads=payloads,
            segments=tuple(segments),
            daq=daq,
            source=source,
        )


def min_duration_s(seg: Segment, limits: JointLimits) -> float:
    """A lower bound of a sine's or a trapezoid's duration [s], cheap (before planning): a
    sine's periods, a trapezoid's cruise moves (both directions at every speed) and dwells
    (``limits``: those of the joint that plays it)."""
    if isinstance(seg, SineSegment):
        return seg.periods / seg.frequency_hz
    span = seg.range[1] - seg.range[0]
    per_cycle = sum(2.0 * span / (v * limits.max_velocity) + 2.0 * seg.dwell_s
                    for v in seg.speeds)
    return seg.cycles * per_cycle


def check_plan_size(segments: Sequence[Any], durations: Sequence[float], cycle_s: float,
                    source: str) -> None:
    """Refuse a campaign whose plan would exceed :data:`MAX_PLAN_CYCLES` cycles per payload
    (before anything is planned or allocated), either format.

    Parameters
    ----------
    segments : sequence of segments
    durations : sequence of float
        A lower bound of each segment's duration [s] (:func:`min_duration_s`).
    cycle_s : float
    source : str

    Raises
    ------
    trajectories.SchemaError
        Naming the longest segment's ``periods`` (sine, multi-sine), ``cycles`` (trapezoid)
        or ``poses`` (move) and the bound.
    """
    n = sum(durations) / cycle_s
    if n <= MAX_PLAN_CYCLES or not durations:
        return
    i = max(range(len(durations)), key=durations.__getitem__)
    seg = segments[i]
    key = next(k for k in ("periods", "cycles", "poses") if hasattr(seg, k))
    value = getattr(seg, key)
    raise fail(source, f"segments[{i}].{key}",
               f"a plan of at most {MAX_PLAN_CYCLES} cycles per payload "
               f"({MAX_PLAN_CYCLES * cycle_s:g} s at cycle_s {cycle_s:g} s; this one: at "
               f"least {n:.3g} cycles)", len(value) if key == "poses" else value)


# --------------------------------------------------------------------------- schema
class _RawTable:
    """Any TOML table, kept as is (validated elsewhere)."""

    required = False

    def validate(self, value: Any, key: str, source: str = "") -> dict:
        if not isinstance(value, Mapping):
            raise fail(source, key, "a table", value)
        return dict(value)


def _nonempty(value: str) -> str | None:
    return None if value.strip() else "a non-empty string"


_LIMITS = Table(
    {
        "position": Field(float, list_of=True, min_len=2, ge=-SANE_LIMITS["position"],
                          le=SANE_LIMITS["position"], unit="rad or m"),
        "max_velocity": Field(float, gt=0, le=SANE_LIMITS["max_velocity"],
                              unit="rad/s or m/s"),
        "max_acceleration": Field(float, gt=0, le=SANE_LIMITS["max_acceleration"],
                                  unit="rad/s^2 or m/s^2"),
        "max_jerk": Field(float, gt=0, le=SANE_LIMITS["max_jerk"], unit="rad/s^3 or m/s^3"),
        "max_torque": Field(float, gt=0, le=SANE_LIMITS["max_torque"], unit="N m or N"),
    }
)

_JOINT = Table(
    {
        "kind": Field(str, choices=("revolute", "prismatic")),
        "start": Field(float, required=False, default=None, unit="rad or m"),
        "limits": _LIMITS,
    }
)

_FEEDFORWARD = Table(
    {k: Field(float, required=False, default=0.0) for k in FEEDFORWARD_KEYS},
    required=False,
)

_CONTROL = Table(
    {
        "cycle_s": Field(float, gt=0, le=0.1, unit="s"),
        "kp": Field(float, gt=0, unit="N m/rad"),
        "kd": Field(float, ge=0, unit="N m s/rad"),
        "velocity_cutoff_hz": Field(float, required=False, default=100.0, gt=0, unit="Hz"),
        "feedforward": _FEEDFORWARD,
    }
)

_PAYLOAD = Table(
    {
        "mass_kg": Field(float, ge=0, unit="kg"),
        "arm_m": Field(float, ge=0, unit="m"),
    }
)

_TRAPEZOID = Table(
    {
        "kind": Field(str, choices=("trapezoid", "sine")),
        "speeds": Field(float, list_of=True, gt=0, le=1, unit="fraction of max_velocity"),
        "range": Field(float, list_of=True, min_len=2, unit="rad or m"),
        "dwell_s": Field(float, required=False, default=0.3, ge=0, unit="s"),
        "cycles": Field(int, required=False, default=1, ge=1),
    }
)

_SINE = Table(
    {
        "kind": Field(str, choices=("trapezoid", "sine")),
        "amplitude": Field(float, gt=0, unit="rad or m"),
        "frequency_hz": Field(float, gt=0, unit="Hz"),
        "center": Field(float, unit="rad or m"),
        "periods": Field(int, required=False, default=1, ge=1),
    }
)

_KINDS = {"trapezoid": _TRAPEZOID, "sine": _SINE}


_CAMPAIGN = Table(
    {
        "name": Field(str, check=_nonempty),
        "joint": _JOINT,
        "control": _CONTROL,
        "payloads": ArrayOfTables(_PAYLOAD),
        "segments": ArrayOfTables(TaggedTable(_KINDS)),  # type: ignore[arg-type]
        "daq": _RawTable(),
    }
)


def _segment(s: dict, key: str, source: str, limits: JointLimits, rng: str) -> Segment:
    tol = 1e-9 * max(1.0, limits.span)  # float rounding of center +/- amplitude
    lo, hi = limits.position[0] - tol, limits.position[1] + tol
    if s["kind"] == "trapezoid":
        r = s["range"]
        if len(r) != 2 or not r[0] < r[1]:
            raise fail(source, f"{key}.range", "two numbers [low, high] with low < high",
                       list(r))
        if r[0] < lo or r[1] > hi:
            raise fail(source, f"{key}.range", f"[low, high] within {rng}", list(r))
        return TrapezoidSweep(
            joint="",
            speeds=tuple(s["speeds"]),
            range=(r[0], r[1]),
            dwell_s=s["dwell_s"],
            cycles=s["cycles"],
        )
    c, a = s["center"], s["amplitude"]
    if not lo <= c <= hi:
        raise fail(source, f"{key}.center", f"a position within {rng}", c)
    if c - a < lo or c + a > hi:
        raise fail(source, f"{key}.amplitude", f"center +/- amplitude within {rng}", a)
    return SineSegment(amplitude=a, frequency_hz=s["frequency_hz"], center=c,
                       periods=s["periods"])


# --------------------------------------------------------------------------- quick runs
#: factor of :meth:`trajectories.robot_campaign.RobotCampaign.quick`
QUICK_FACTOR = 0.12


def shorten_segments(segments: Sequence[Segment], limits: JointLimits,
                     factor: float) -> tuple[Segment, ...]:
    """Scale the segments of one joint with ``limits`` down for quick runs
    (:meth:`trajectories.robot_campaign.RobotCampaign.quick`); the result stays within the
    limits.

    - trapezoid segments: only the lowest speed is kept (low-velocity moves in both
      directions, where dry friction changes), across the range span x ``factor`` around
      its centre, one cycle, dwell x ``factor``;
    - sine segments: the full amplitude and centre (the whole position range stays covered,
      so gravity and position-dependent effects remain identifiable), one period, the
      frequency raised until A w, A w^2 or A w^3 reaches 90 % of its limit (never lowered).

    Parameters
    ----------
    segments : sequence of TrapezoidSweep or SineSegment
    limits : JointLimits
    factor : float
        In (0, 1]: the share of each trapezoid's range kept.

    Returns
    -------
    tuple of segments

    Raises
    ------
    trajectories.SchemaError
        ``factor`` outside (0, 1], or a segment that is neither a trapezoid nor a sine.
    """
    if not 0.0 < factor <= 1.0:
        raise SchemaError(f"shorten: factor: expected a number in (0, 1], got {factor!r}")
    lim = limits
    out: list[Segment] = []
    for seg in segments:
        if isinstance(seg, TrapezoidSweep):
            mid = 0.5 * (seg.range[0] + seg.range[1])
            half = 0.5 * (seg.range[1] - seg.range[0]) * factor
            out.append(replace(seg, range=(mid - half, mid + half), speeds=(min(seg.speeds),),
                               cycles=1, dwell_s=seg.dwell_s * factor))
        elif isinstance(seg, SineSegment):
            a = seg.amplitude
            w = min(0.9 * lim.max_velocity / a, math.sqrt(0.9 * lim.max_acceleration / a),
                    (0.9 * lim.max_jerk / a) ** (1.0 / 3.0))
            w = max(w, seg.omega)  # never slower than the original (its peaks fit already)
            out.append(replace(seg, frequency_hz=w / (2.0 * math.pi), periods=1))
        else:
            raise SchemaError(f"shorten: {getattr(seg, 'kind', type(seg).__name__)} segment: "
                              f"expected trapezoid and sine segments only")
    return tuple(out)
