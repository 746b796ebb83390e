"""The one campaign type: a robot -- its moving joints, drives, limits, payloads and excitation.

(Past 600 lines: one file format -- its documented dataclasses, schema and cross-checks,
and the reading of a ``[joint]`` campaign as a robot with one moving joint; split, the format
would be scattered.)

A campaign file has either a ``[joint]`` table (the single-joint format, validated by
:mod:`trajectories.campaign`) or a ``[robot]`` table (this module); both are read into a
:class:`RobotCampaign`. :func:`campaign_from_dict` (:meth:`RobotCampaign.from_dict`)
dispatches on which one is present (pure: dictionaries in, frozen dataclasses out). Every mistake
raises :class:`trajectories.SchemaError` with one line naming the source and the dotted key::

    arm.toml: robot.joints.j2.limits.max_velocity: expected a number > 0 <= 1000 [rad/s or m/s],
    got -1

File format (units: SI joint side, [rad] or [m] for prismatic joints, seconds; full
description in docs/campaign-robot.md)::

    name = "arm3-excitation"
    [robot]
    file = "robots/arm3.toml"         # URDF or MDH TOML robot file (docs: ROBOT_FORMAT),
                                      # relative to the campaign file (resolved by the caller)
    moving = ["j1", "j2", "j3"]       # the joints that move, base to tip
    start = [0.0, -1.2, 1.4]          # optional rest pose [rad]; default: centres of limits
    locked = { j4 = 0.0 }             # optional, joints of the robot file held still [rad]
    [robot.joints.j1]                 # one table per moving joint
    kind = "revolute"                 # optional, or "prismatic"
    drive = { node_id = 1, bus = "can0" }
    limits = { position = [-2.8, 2.8], max_velocity = 2.0, max_acceleration = 6.0,
               max_jerk = 60.0, max_torque = 300.0 }
    [control]
    cycle_s = 0.001                   # [s]
    velocity_cutoff_hz = 100.0        # optional [Hz]
    gains = { j1 = { kp = 6000.0, kd = 200.0 }, ... }   # one entry per moving joint
    [[payloads]]                      # one run per payload, in order
    mass_kg = 2.0                     # [kg]
    com = [0.0, 0.0, 0.05]            # [m] centre of mass in the flange frame
    inertia = [0.01, 0.0, 0.0, 0.01, 0.0, 0.005]   # [kg m^2] XX XY XZ YY YZ ZZ at the CoM
    [[segments]]
    kind = "trapezoid"                # joint j2 back and forth at each speed ...
    joint = "j2"
    speeds = [0.03, 0.08, 0.3, 1.0]   # fractions of its max_velocity, in (0, 1]
    range = [-2.0, -0.4]
    sweep = { j3 = [0.3, 2.4] }       # ... while j3 sweeps its range (gravity on j2 changes);
                                      # joints not listed hold their start position
    sweep_speed = 0.25                # fraction of each sweeping joint's max_velocity
    dwell_s = 0.3
    cycles = 1
    [[segments]]
    kind = "multisine"                # q_j(t) = q0_j + sum_l a_jl/(w l) sin(w l t)
    period_s = 10.0                   #                  - b_jl/(w l) cos(w l t), w = 2 pi/T
    periods = 2
    harmonics = 5                     # when a and b are not given
    # center = [...]                  # q0, default: robot.start
    # a = [[...] x harmonics] x joints, b = ... : explicit coefficients [rad/s]
    fill = 0.8                        # default coefficients use 80 % of the tightest limit
    seed = 0                          # default coefficients are seeded random
    optimise = true                   # `jointid plan` may optimise the coefficients
    [[segments]]
    kind = "sine"                     # exact periods of q = center - amplitude cos(2 pi f t)
    joint = "j2"                      # of one joint, the others hold
    amplitude = 0.5
    frequency_hz = 0.3
    center = -1.3
    periods = 2
    [[segments]]
    kind = "move"                     # point-to-point moves between rest poses
    poses = [[0.5, -1.0, 1.0], [0.0, -1.2, 1.4]]
    speed = 0.5
    dwell_s = 0.5
    [daq]                             # optional, kept raw for daq/

There is one campaign type: a ``[joint]`` file is read by :func:`campaign_from_dict` (and
:meth:`RobotCampaign.from_dict`) into a :class:`RobotCampaign` with one moving joint, without
loss -- the joint named ``joint``, without a drive of its own (its drives are those of
``[daq]``), carrying the gains and ``[control.feedforward]``; payloads with their lever arm
``arm_m``; no robot file (:attr:`RobotCampaign.plant` ``"joint"``). The one planner,
:func:`trajectories.multi.plan_robot_campaign`, and the runtime (:mod:`daq.runtime`) take
only this type.

The payload inertia is given about the payload's centre of mass, in the flange frame, and
must be physically valid (principal moments >= 0, triangle inequality).
The robot file itself is read by :func:`trajectories.robot.load_robot` (not here: this
module never touches files).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numpy as np

# the single-joint schema's pieces: the same limits table, raw tables, name check, segment
# fields and plan-size check
from .campaign import (
    _LIMITS,
    FEEDFORWARD_KEYS,
    QUICK_FACTOR,
    JointLimits,
    SineSegment,
    TrapezoidSweep,
    _JointCampaign,
    _nonempty,
    _RawTable,
    check_plan_size,
    min_duration_s,
    shorten_segments,
)
from .campaign import _SINE as _JOINT_SINE
from .campaign import _TRAPEZOID as _JOINT_TRAPEZOID
from .schema import ArrayOfTables, Field, Table, TaggedTable, fail, unknown

__all__ = [
    "DriveSpec",
    "MoveSegment",
    "MultisineSegment",
    "RobotCampaign",
    "RobotControl",
    "RobotJoint",
    "RobotPayload",
    "RobotSegment",
    "JOINT_NAME",
    "SineSegment",
    "TrapezoidSweep",
    "campaign_from_dict",
]


# --------------------------------------------------------------------------- dataclasses
@dataclass(frozen=True)
class DriveSpec:
    """The CANopen drive of a joint.

    Attributes
    ----------
    node_id : int
        CANopen node ID, 1..127, unique on its bus.
    bus : str
        Bus name or channel (e.g. ``"can0"``), as known to :mod:`daq`.
    """

    node_id: int
    bus: str = "can0"


@dataclass(frozen=True)
class RobotJoint:
    """A moving joint of the robot campaign.

    Attributes
    ----------
    name : str
        Joint name in the robot file.
    kind : {"revolute", "prismatic"}
    limits : JointLimits
        Joint-side limits (position [rad] or [m], velocity, acceleration, jerk, torque).
    drive : DriveSpec or None
        None for the joint of a ``[joint]`` campaign (its drive is in ``[daq]``).
    kp : float
        Position-loop gain [N m/rad] or [N/m].
    kd : float
        Velocity gain [N m s/rad] or [N s/m].
    feedforward : mapping of str to float
        A ``[joint]`` campaign's ``[control.feedforward]`` (``J`` [kg m^2], ``MX``, ``MY``
        [kg m], ``Fc`` [N m], ``Fv`` [N m s/rad], every key present); empty for a robot
        file's joint (its model is the robot file).
    table : str
        Dotted key of the joint's table in the campaign file, used in messages: ``"joint"``
        for a ``[joint]`` campaign; ``""``: ``robot.joints.<name>``.
    """

    name: str
    kind: Literal["revolute", "prismatic"]
    limits: JointLimits
    drive: DriveSpec | None
    kp: float
    kd: float
    feedforward: Mapping[str, float] = field(default_factory=dict)
    table: str = ""

    @property
    def unit(self) -> str:
        """Position unit, ``"rad"`` or ``"m"``."""
        return "rad" if self.kind == "revolute" else "m"

    @property
    def key(self) -> str:
        """Dotted key of the joint's table (``joint`` or ``robot.joints.<name>``)."""
        return self.table or f"robot.joints.{self.name}"

    @property
    def revolute(self) -> bool:
        return self.kind == "revolute"

    def gains_kwargs(self, velocity_cutoff_hz: float) -> dict[str, float]:
        """Keyword arguments for ``daq.protocol.control.ControllerGains(**kwargs)``: the
        joint's gains, the cut-off [Hz] and its feed-forward model (0 where not given)."""
        out = {"kp": self.kp, "kd": self.kd, "velocity_cutoff_hz": velocity_cutoff_hz}
        for key, name in FEEDFORWARD_KEYS.items():
            out[name] = float(self.feedforward.get(key, 0.0))
        return out


@dataclass(frozen=True)
class RobotControl:
    """Control cycle (per-joint gains are in :class:`RobotJoint`).

    Attributes
    ----------
    cycle_s : float
        Control cycle [s]; plans are sampled at this period.
    velocity_cutoff_hz : float
        Cut-off of the controllers' velocity-estimate low-pass [Hz].
    """

    cycle_s: float
    velocity_cutoff_hz: float = 100.0


@dataclass(frozen=True)
class RobotPayload:
    """A payload fixed on the flange.

    Attributes
    ----------
    mass_kg : float
        Mass [kg], >= 0.
    com : tuple of float, shape (3,)
        Centre of mass in the flange frame [m].
    inertia : tuple of float, shape (6,)
        ``(XX, XY, XZ, YY, YZ, ZZ)`` about the centre of mass, flange axes [kg m^2].
    arm_m : float or None
        A ``[joint]`` campaign's lever arm L_a [m] (paper eq. 32-34): the point mass sits at
        ``com = (arm_m, 0, 0)`` of the one joint's frame; None for a robot campaign.
    """

    mass_kg: float
    com: tuple[float, float, float] = (0.0, 0.0, 0.0)
    inertia: tuple[float, float, float, float, float, float] = (0.0,) * 6
    arm_m: float | None = None

    @property
    def label(self) -> str:
        """``"3.5 kg"`` or, with a lever arm, ``"3.5 kg at 1.277 m"`` (for messages)."""
        if self.arm_m is None:
            return f"{self.mass_kg:g} kg"
        return f"{self.mass_kg:g} kg at {self.arm_m:g} m"


@dataclass(frozen=True)
class MultisineSegment:
    """A periodic Fourier-series excitation of every moving joint (Swevers et al. 1997).

    ``q_j(t) = q0_j + sum_l a_jl/(w l) sin(w l t) - b_jl/(w l) cos(w l t)``, ``w = 2 pi /
    period_s``, ``l = 1..L``. Ruckig blends from rest to the state at t = 0 and from the
    state after ``periods`` periods (the same) back to rest.

    Attributes
    ----------
    period_s : float
        Base period T [s].
    periods : int
        Number of periods played.
    center : tuple of float or None
        ``q0`` per moving joint [rad]; None: the campaign's start pose.
    a, b : tuple of tuple of float or None
        Coefficients, shape (k joints, L harmonics) [rad/s]; None: seeded defaults
        (see :func:`trajectories.multi.default_coefficients`).
    harmonics : int
        L when ``a`` and ``b`` are None; >= 2 in campaign files, so that the default
        coefficients start and end at rest.
    fill : float
        In (0, 1]: default coefficients reach this fraction of each joint's tightest limit.
    seed : int
        Seed of the default coefficients (and of the optimiser's start).
    optimise : bool
        The coefficients may be optimised for the excitation quality before planning
        (:func:`trajectories.excitation.optimise_campaign`).
    """

    period_s: float
    periods: int = 1
    center: tuple[float, ...] | None = None
    a: tuple[tuple[float, ...], ...] | None = None
    b: tuple[tuple[float, ...], ...] | None = None
    harmonics: int = 5
    fill: float = 0.8
    seed: int = 0
    optimise: bool = False
    kind: Literal["multisine"] = "multisine"

    @property
    def omega(self) -> float:
        """Base angular frequency w = 2 pi / T [rad/s]."""
        return 2.0 * math.pi / self.period_s

    @property
    def n_harmonics(self) -> int:
        """L: number of harmonics."""
        return len(self.a[0]) if self.a is not None else self.harmonics


@dataclass(frozen=True)
class MoveSegment:
    """Synchronised point-to-point moves through rest poses.

    Attributes
    ----------
    poses : tuple of tuple of float
        Rest poses, shape (m, k) [rad], in order.
    speed : float
        Fraction of each joint's max_velocity, in (0, 1].
    dwell_s : float
        Rest at each pose [s].
    """

    poses: tuple[tuple[float, ...], ...]
    speed: float = 0.5
    dwell_s: float = 0.3
    kind: Literal["move"] = "move"


RobotSegment = TrapezoidSweep | MultisineSegment | MoveSegment | SineSegment


@dataclass(frozen=True)
class RobotCampaign:
    """A validated robot campaign (immutable).

    Attributes
    ----------
    name : str
    robot_file : str
        The robot file as written in the campaign (resolve it relative to the campaign file);
        ``""`` for a ``[joint]`` campaign (no robot file): a robot with one
        moving joint, described by the campaign itself (limits, ``[control.feedforward]``).
    joints : tuple of RobotJoint
        The moving joints, in the order of ``robot.moving``.
    start : tuple of float
        Rest pose [rad] where every run starts and ends, one value per moving joint.
    locked : mapping of str to float
        Joints of the robot file held at a value [rad] (may be empty).
    control : RobotControl
    payloads : tuple of RobotPayload
    segments : tuple of RobotSegment
    daq : dict
        The raw ``[daq]`` table, ``{}`` when absent.
    source : str
        Where the campaign came from, used in messages.
    """

    name: str
    robot_file: str
    joints: tuple[RobotJoint, ...]
    start: tuple[float, ...]
    locked: Mapping[str, float]
    control: RobotControl
    payloads: tuple[RobotPayload, ...]
    segments: tuple[RobotSegment, ...]
    daq: Mapping[str, Any] = field(default_factory=dict)
    source: str = ""

    @property
    def moving(self) -> tuple[str, ...]:
        """Names of the moving joints."""
        return tuple(j.name for j in self.joints)

    @property
    def limits(self) -> tuple[JointLimits, ...]:
        """Per moving joint limits."""
        return tuple(j.limits for j in self.joints)

    @property
    def cycle_s(self) -> float:
        return self.control.cycle_s

    @classmethod
    def from_dict(cls, raw: Mapping[str, Any], source: str = "") -> RobotCampaign:
        """Validate a parsed TOML mapping of either format: a ``[robot]`` table, or a
        ``[joint]`` table read as a robot with one moving joint (no robot file).

        Parameters
        ----------
        raw : mapping
            Output of ``tomllib.load``.
        source : str
            File name shown at the start of error messages.

        Raises
        ------
        trajectories.SchemaError
            One line naming the source, the dotted key and what was expected; neither or
            both of ``[joint]`` and ``[robot]``.
        """
        return campaign_from_dict(raw, source)

    def gains_kwargs(self, k: int = 0) -> dict[str, float]:
        """Keyword arguments for ``daq.protocol.control.ControllerGains(**kwargs)`` of moving
        joint ``k``: its gains and feed-forward model, the campaign's velocity cut-off."""
        return self.joints[k].gains_kwargs(self.control.velocity_cutoff_hz)

    @property
    def plant(self) -> Literal["arm", "joint"]:
        """The simulated plant this campaign asks for (``jointid run --simulate``).

        ``"arm"``: one simulated arm of the robot file behind all the drives
        (``--simulate`` alone); ``"joint"``: no robot file -- the campaign describes its one
        joint itself, and each drive runs its own simulated joint plant of a plant file
        (``--simulate PLANT.toml``).
        """
        return "arm" if self.robot_file else "joint"

    def quick(self) -> RobotCampaign:
        """A short version for smoke runs and demos (about 25 s per payload run of the
        example), same joints, control and payloads
        (:func:`trajectories.campaign.shorten_segments`).

        Raises
        ------
        trajectories.SchemaError
            More than one moving joint, or a multi-sine or move segment: such campaigns
            have no shortened form.
        """
        if len(self.joints) != 1:
            raise fail(self.source, "robot.moving", "one moving joint for a shortened "
                       "campaign (--quick)", list(self.moving))
        for i, seg in enumerate(self.segments):
            if not isinstance(seg, TrapezoidSweep | SineSegment):
                raise fail(self.source, f"segments[{i}].kind", "'trapezoid' or 'sine' in a "
                           "shortened campaign (--quick)", seg.kind)
        segs = shorten_segments(self.segments, self.joints[0].limits, QUICK_FACTOR)
        return replace(self, segments=segs, name=f"{self.name} (quick)")


#: name of the moving joint of a ``[joint]`` campaign read as a robot
JOINT_NAME = "joint"


def _from_joint_file(campaign: _JointCampaign) -> RobotCampaign:
    """A ``[joint]`` file as a robot with one moving joint, without loss.

    The joint is named ``"joint"`` (its table; messages name ``joint.limits...``), has no
    drive of its own (its drives are those of ``[daq]``) and carries the gains and
    ``[control.feedforward]``; each payload's lever arm becomes ``arm_m`` and
    ``com = (arm_m, 0, 0)``; the segments are the same (their ``joint`` ``""`` is the only
    moving joint). No robot file: ``robot_file`` is ``""``.
    """
    j = campaign.joint
    c = campaign.control
    joint = RobotJoint(JOINT_NAME, j.kind, j.limits, None, c.kp, c.kd,
                       feedforward=dict(c.feedforward), table="joint")
    return RobotCampaign(
        name=campaign.name,
        robot_file="",
        joints=(joint,),
        start=(j.start,),
        locked={},
        control=RobotControl(c.cycle_s, c.velocity_cutoff_hz),
        payloads=tuple(RobotPayload(p.mass_kg, (p.arm_m, 0.0, 0.0), arm_m=p.arm_m)
                       for p in campaign.payloads),
        segments=campaign.segments,
        daq=campaign.daq,
        source=campaign.source,
    )


def campaign_from_dict(raw: Mapping[str, Any], source: str = "") -> RobotCampaign:
    """Validate either campaign format into a :class:`RobotCampaign`: a ``[robot]`` table, or
    a ``[joint]`` table read as a robot with one moving joint (no robot file).

    Raises
    ------
    trajectories.SchemaError
        Neither or both of ``[joint]`` and ``[robot]``, or any schema error of the format.
    """
    if not isinstance(raw, Mapping):
        raise fail(source, "<top level>", "a table", raw)
    has_joint, has_robot = "joint" in raw, "robot" in raw
    if has_joint and has_robot:
        raise fail(source, "robot", "either a [joint] or a [robot] table, not both")
    if has_robot:
        return _build(raw, source)
    return _from_joint_file(_JointCampaign.from_dict(raw, source))


# --------------------------------------------------------------------------- schema pieces
class _NamedTables:
    """A table whose keys are joint names and whose values follow ``item``."""

    def __init__(self, item: Any, required: bool = True) -> None:
        self.item = item
        self.required = required

    def validate(self, value: Any, key: str, source: str = "") -> dict:
        if not isinstance(value, Mapping):
            raise fail(source, key, "a table keyed by joint name", value)
        return {str(n): self.item.validate(v, f"{key}.{n}", source) for n, v in value.items()}


class _Matrix:
    """A list of equal-length lists of numbers (rows)."""

    def __init__(self, unit: str, required: bool = False) -> None:
        self.unit = unit
        self.required = required
        self.default = None

    def validate(self, value: Any, key: str, source: str = "") -> tuple[tuple[float, ...], ...]:
        what = f"a list of equal-length lists of numbers [{self.unit}]"
        if not isinstance(value, list) or not value:
            raise fail(source, key, what, value)
        rows = []
        for i, row in enumerate(value):
            rows.append(Field(float, list_of=True, unit=self.unit).validate(
                row, f"{key}[{i}]", source))
        if len({len(r) for r in rows}) != 1:
            raise fail(source, key, what + " (rows of different lengths)")
        return tuple(rows)


_DRIVE = Table(
    {
        "node_id": Field(int, ge=1, le=127),
        "bus": Field(str, required=False, default="can0", check=_nonempty),
    }
)
_JOINT = Table(
    {
        "kind": Field(str, required=False, default="revolute", choices=("revolute", "prismatic")),
        "drive": _DRIVE,
        "limits": _LIMITS,
    }
)
_ROBOT = Table(
    {
        "file": Field(str, check=_nonempty),
        "moving": Field(str, list_of=True, check=_nonempty),
        "start": Field(float, required=False, list_of=True, unit="rad or m"),
        "locked": _NamedTables(Field(float, unit="rad or m"), required=False),
        "joints": _NamedTables(_JOINT),
    }
)
_GAINS = Table(
    {
        "kp": Field(float, gt=0, unit="N m/rad"),
        "kd": Field(float, ge=0, unit="N m s/rad"),
    }
)
_CONTROL = Table(
    {
        "cycle_s": Field(float, gt=0, le=0.1, unit="s"),
        "velocity_cutoff_hz": Field(float, required=False, default=100.0, gt=0, unit="Hz"),
        "gains": _NamedTables(_GAINS),
    }
)
_PAYLOAD = Table(
    {
        "mass_kg": Field(float, ge=0, unit="kg"),
        "com": Field(float, required=False, default=(0.0, 0.0, 0.0), list_of=True, min_len=3,
                     unit="m"),
        "inertia": Field(float, required=False, default=(0.0,) * 6, list_of=True, min_len=6,
                         unit="kg m^2"),
    }
)
_KIND_NAMES = ("trapezoid", "multisine", "move", "sine")
_KIND = Field(str, choices=_KIND_NAMES)
# the [joint] format's trapezoid, of one named joint, with an optional sweep of others
_TRAPEZOID = Table(
    {
        "kind": _KIND,
        "joint": Field(str, check=_nonempty),
        "speeds": _JOINT_TRAPEZOID.fields["speeds"],
        "range": _JOINT_TRAPEZOID.fields["range"],
        "sweep": _NamedTables(Field(float, list_of=True, min_len=2, unit="rad or m"),
                              required=False),
        "sweep_speed": Field(float, required=False, default=0.25, gt=0, le=1,
                             unit="fraction of max_velocity"),
        "dwell_s": _JOINT_TRAPEZOID.fields["dwell_s"],
        "cycles": _JOINT_TRAPEZOID.fields["cycles"],
    }
)
_MULTISINE = Table(
    {
        "kind": _KIND,
        "period_s": Field(float, gt=0, unit="s"),
        "periods": Field(int, required=False, default=1, ge=1),
        "center": Field(float, required=False, list_of=True, unit="rad or m"),
        "a": _Matrix("rad/s"),
        "b": _Matrix("rad/s"),
        "harmonics": Field(int, required=False, default=5, ge=2, le=50),
        "fill": Field(float, required=False, default=0.8, gt=0, le=1,
                      unit="fraction of the tightest limit"),
        "seed": Field(int, required=False, default=0, ge=0),
        "optimise": Field(bool, required=False, default=False),
    }
)
_MOVE = Table(
    {
        "kind": _KIND,
        "poses": _Matrix("rad or m", required=True),
        "speed": Field(float, required=False, default=0.5, gt=0, le=1,
                       unit="fraction of max_velocity"),
        "dwell_s": Field(float, required=False, default=0.3, ge=0, unit="s"),
    }
)
# the [joint] format's sine, of one named joint
_SINE = Table({"kind": _KIND, "joint": Field(str, check=_nonempty),
               **{k: f for k, f in _JOINT_SINE.fields.items() if k != "kind"}})
_KINDS = {"trapezoid": _TRAPEZOID, "multisine": _MULTISINE, "move": _MOVE, "sine": _SINE}


_CAMPAIGN = Table(
    {
        "name": Field(str, check=_nonempty),
        "robot": _ROBOT,
        "control": _CONTROL,
        "payloads": ArrayOfTables(_PAYLOAD),
        "segments": ArrayOfTables(TaggedTable(_KINDS)),  # type: ignore[arg-type]
        "daq": _RawTable(),
    }
)


# --------------------------------------------------------------------------- builder
def _within(source: str, key: str, values: tuple[float, ...], joints: tuple[RobotJoint, ...],
            names: tuple[str, ...] | None = None) -> None:
    """Each value within its joint's position limits (names: which joints, default all)."""
    by_name = {j.name: j for j in joints}
    names = names if names is not None else tuple(j.name for j in joints)
    for i, (n, v) in enumerate(zip(names, values, strict=True)):
        j = by_name[n]
        lo, hi = j.limits.position
        tol = 1e-9 * max(1.0, hi - lo)
        if not lo - tol <= v <= hi + tol:
            raise fail(source, f"{key}[{i}]", f"a position of {n} within robot.joints.{n}."
                       f"limits.position [{lo:g}, {hi:g}] {j.unit}", v)


def _range(source: str, key: str, r: tuple[float, ...], j: RobotJoint) -> tuple[float, float]:
    if len(r) != 2 or not r[0] < r[1]:
        raise fail(source, key, "two numbers [low, high] with low < high", list(r))
    _within(source, key, r, (j,), (j.name, j.name))
    return (r[0], r[1])


def _joint_key(source: str, key: str, name: str, moving: tuple[str, ...]) -> None:
    if name not in moving:
        raise fail(source, key, f"a moving joint (one of {', '.join(moving)})", name)


def _precheck(raw: Mapping[str, Any], source: str) -> None:
    """Joint-keyed tables naming a joint that does not move: report that before the rest."""
    r = raw.get("robot") if isinstance(raw, Mapping) else None
    if not isinstance(r, Mapping) or "moving" not in r:
        return
    moving = _ROBOT.fields["moving"].validate(r["moving"], "robot.moving", source)
    dup = sorted({n for n in moving if moving.count(n) > 1})
    if dup:
        raise fail(source, "robot.moving", "distinct joint names", dup[0])
    control = raw.get("control")
    for key, table in (("robot.joints", r.get("joints")),
                       ("control.gains", control.get("gains")
                        if isinstance(control, Mapping) else None)):
        if isinstance(table, Mapping):
            for n in table:
                if n not in moving:
                    raise unknown(source, f"{key}.{n}", "the robot.moving joints: "
                                  + ", ".join(moving))


def _build(raw: Mapping[str, Any], source: str) -> RobotCampaign:
    _precheck(raw, source)
    top = _CAMPAIGN.validate(raw, "", source)
    r = top["robot"]
    moving = tuple(r["moving"])  # distinct, and the joint tables name only these (_precheck)
    gains = top["control"]["gains"]
    joints = []
    for n in moving:
        if n not in r["joints"]:
            raise fail(source, f"robot.joints.{n}", "a table (drive, limits) for every moving "
                       "joint, it is missing")
        if n not in gains:
            raise fail(source, f"control.gains.{n}", "a table (kp, kd) for every moving joint, "
                       "it is missing")
        jt = r["joints"][n]
        lim = jt["limits"]
        pos = lim["position"]
        if len(pos) != 2 or not pos[0] < pos[1]:
            raise fail(source, f"robot.joints.{n}.limits.position", "[min, max] with min < max",
                       list(pos))
        limits = JointLimits((pos[0], pos[1]), lim["max_velocity"], lim["max_acceleration"],
                             lim["max_jerk"], lim["max_torque"])
        drive = DriveSpec(jt["drive"]["node_id"], jt["drive"]["bus"])
        joints.append(RobotJoint(n, jt["kind"], limits, drive, gains[n]["kp"], gains[n]["kd"]))
    joints_t = tuple(joints)
    seen: dict[tuple[str, int], str] = {}
    for j in joints_t:
        k = (j.drive.bus, j.drive.node_id)
        if k in seen:
            raise fail(source, f"robot.joints.{j.name}.drive.node_id",
                       f"a node ID not used by {seen[k]} on bus {j.drive.bus!r}", j.drive.node_id)
        seen[k] = j.name

    k = len(moving)
    if r["start"] is None:
        start = tuple(0.5 * (j.limits.position[0] + j.limits.position[1]) for j in joints_t)
    else:
        start = tuple(r["start"])
        if len(start) != k:
            raise fail(source, "robot.start", f"{k} positions (one per moving joint)",
                       list(start))
        _within(source, "robot.start", start, joints_t)
    locked = dict(r["locked"] or {})
    for n in locked:
        if n in moving:
            raise fail(source, f"robot.locked.{n}", "a joint that is not in robot.moving", n)

    payloads = tuple(
        RobotPayload(p["mass_kg"], _fixed(source, f"payloads[{i}].com", p["com"], 3),
                     _inertia(source, f"payloads[{i}].inertia", p["inertia"]))
        for i, p in enumerate(top["payloads"])
    )
    segments = tuple(_segment(s, f"segments[{i}]", source, joints_t, start)
                     for i, s in enumerate(top["segments"]))
    c = top["control"]
    check_plan_size(segments, _min_durations(segments, joints_t), c["cycle_s"], source)
    return RobotCampaign(
        name=top["name"],
        robot_file=r["file"],
        joints=joints_t,
        start=start,
        locked=locked,
        control=RobotControl(c["cycle_s"], c["velocity_cutoff_hz"]),
        payloads=payloads,
        segments=segments,
        daq=top["daq"] if isinstance(top["daq"], dict) else {},
        source=source,
    )


def _min_durations(segments: tuple[RobotSegment, ...],
                   joints: tuple[RobotJoint, ...]) -> list[float]:
    """A lower bound of each segment's duration [s], before anything is planned (multisine:
    its periods; sine, trapezoid: :func:`~trajectories.campaign.min_duration_s`; move: its
    dwells)."""
    by_name = {j.name: j for j in joints}
    out = []
    for seg in segments:
        if isinstance(seg, MultisineSegment):
            out.append(seg.periods * seg.period_s)
        elif isinstance(seg, SineSegment | TrapezoidSweep):
            out.append(min_duration_s(seg, by_name[seg.joint].limits))
        else:
            out.append(len(seg.poses) * seg.dwell_s)
    return out


def _fixed(source: str, key: str, values: tuple[float, ...], n: int) -> tuple:
    if len(values) != n:
        raise fail(source, key, f"exactly {n} numbers", list(values))
    return tuple(values)


def _inertia(source: str, key: str, values: tuple[float, ...]) -> tuple:
    """A payload's XX XY XZ YY YZ ZZ about its CoM [kg m^2], physically valid: its principal
    moments >= 0 and each at most the sum of the other two (pinocchio refused a negative one
    with a traceback, after the file was read)."""
    xx, xy, xz, yy, yz, zz = _fixed(source, key, values, 6)
    ev = np.linalg.eigvalsh(np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]]))
    tol = 1e-9 * max(1.0, float(np.abs(ev).max()))
    if not (ev.min() >= -tol and 2 * ev.max() <= ev.sum() + tol):
        raise fail(source, key, "a physically valid inertia about the CoM [kg m^2] (XX XY XZ "
                   "YY YZ ZZ: principal moments >= 0, each at most the sum of the other two)",
                   list(values))
    return tuple(values)


def _segment(s: dict, key: str, source: str, joints: tuple[RobotJoint, ...],
             start: tuple[float, ...]) -> RobotSegment:
    moving = tuple(j.name for j in joints)
    by_name = {j.name: j for j in joints}
    k = len(moving)
    if s["kind"] == "trapezoid":
        _joint_key(source, f"{key}.joint", s["joint"], moving)
        j = by_name[s["joint"]]
        rng = _range(source, f"{key}.range", s["range"], j)
        sweep = {}
        for n, sr in (s["sweep"] or {}).items():
            _joint_key(source, f"{key}.sweep.{n}", n, moving)
            if n == s["joint"]:
                raise fail(source, f"{key}.sweep.{n}", f"another joint than {n} (the one "
                           "doing the trapezoids)", n)
            sweep[n] = _range(source, f"{key}.sweep.{n}", sr, by_name[n])
        return TrapezoidSweep(joint=s["joint"], speeds=tuple(s["speeds"]), range=rng,
                              sweep=sweep, sweep_speed=s["sweep_speed"], dwell_s=s["dwell_s"],
                              cycles=s["cycles"])
    if s["kind"] == "sine":
        _joint_key(source, f"{key}.joint", s["joint"], moving)
        j = by_name[s["joint"]]
        c, a = s["center"], s["amplitude"]
        lo, hi = j.limits.position
        tol = 1e-9 * max(1.0, hi - lo)
        rng = f"{j.key}.limits.position [{lo:g}, {hi:g}] {j.unit}"
        if not lo - tol <= c <= hi + tol:
            raise fail(source, f"{key}.center", f"a position of {j.name} within {rng}", c)
        if c - a < lo - tol or c + a > hi + tol:
            raise fail(source, f"{key}.amplitude", f"center +/- amplitude within {rng}", a)
        return SineSegment(amplitude=a, frequency_hz=s["frequency_hz"], center=c,
                           periods=s["periods"], joint=j.name)
    if s["kind"] == "move":
        poses = s["poses"]
        if len(poses[0]) != k:
            raise fail(source, f"{key}.poses", f"poses of {k} positions (one per moving joint)",
                       list(poses[0]))
        for i, p in enumerate(poses):
            _within(source, f"{key}.poses[{i}]", p, joints)
        return MoveSegment(poses=poses, speed=s["speed"], dwell_s=s["dwell_s"])
    center = s["center"]
    if center is not None:
        if len(center) != k:
            raise fail(source, f"{key}.center", f"{k} positions (one per moving joint)",
                       list(center))
        _within(source, f"{key}.center", center, joints)
    a, b = s["a"] or None, s["b"] or None  # absent: None (the validator gives ())
    if (a is None) != (b is None):
        missing = "b" if b is None else "a"
        raise fail(source, f"{key}.{missing}", "a value when "
                   f"{'a' if missing == 'b' else 'b'} is given (both or neither), it is missing")
    if a is not None:
        if len(a) != k:
            raise fail(source, f"{key}.a", f"{k} rows (one per moving joint)", len(a))
        if len(b) != k or len(b[0]) != len(a[0]):
            raise fail(source, f"{key}.b", f"the shape of a ({k} x {len(a[0])})",
                       f"{len(b)} x {len(b[0])}")
    return MultisineSegment(period_s=s["period_s"], periods=s["periods"],
                            center=tuple(center) if center is not None else None,
                            a=a, b=b, harmonics=len(a[0]) if a is not None else s["harmonics"],
                            fill=s["fill"], seed=s["seed"], optimise=s["optimise"])

