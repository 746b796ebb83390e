"""Robot description: :class:`Robot` (a pinocchio model of the full chain, moving and locked
joints, drives, limits) and the checks every robot file format shares.

The file formats that build a :class:`Robot` are in :mod:`trajectories.robot.formats` (one module
each, found by the file's suffix); this module reads no file.

Frame convention of an MDH table: joint ``j`` of the pinocchio model has the MDH frame ``j``
as its joint frame, so that frame ``j-1 -> j`` is ``Rot(x, alpha) Trans(x, d) Rot(z, theta)
Trans(z, r)`` with the joint variable added to ``theta`` (revolute) or ``r`` (prismatic), and
pinocchio's body inertia of joint ``j`` (first moments and inertia about the joint-frame
origin) is Khalil's set of standard parameters of link ``j``.

Every mistake raises :class:`RobotError` with one line naming the file and the element::

    arm3.toml: joints[j2].drive.gear_ratio: expected a number > 0, got -3
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np
import pinocchio as pin

from .. import RobotError

__all__ = [
    "RobotError",
    "JointDrive",
    "RobotLimits",
    "MDHJoint",
    "Robot",
    "mdh_placement",
    "one_joint_robot",
    "STANDARD_GRAVITY",
]

#: [m/s^2] gravity of :func:`one_joint_robot`, the paper's g (section IV.A).
STANDARD_GRAVITY = 9.81

_REVOLUTE = {"JointModelRX": (1, 0, 0), "JointModelRY": (0, 1, 0), "JointModelRZ": (0, 0, 1)}
_PRISMATIC = {"JointModelPX": (1, 0, 0), "JointModelPY": (0, 1, 0), "JointModelPZ": (0, 0, 1)}


# --------------------------------------------------------------------------- dataclasses
@dataclass(frozen=True)
class JointDrive:
    """Drive chain of one joint (paper eq. 4).

    Attributes
    ----------
    gear_ratio : float
        N (motor angle = N x joint angle), default 1.
    drive_gain : float or None
        [N m per unit of logged torque], joint side (g_f of eq. 4); None: torques logged in N m.
    torque_constant : float or None
        [N m/A] joint side, when currents are logged instead of torques.
    rotor_inertia : float or None
        Motor-side rotor inertia J_m [kg m^2]; None: unknown, identify ``Ia`` as a parameter.
    """

    gear_ratio: float = 1.0
    drive_gain: float | None = None
    torque_constant: float | None = None
    rotor_inertia: float | None = None

    @property
    def Ia(self) -> float | None:  # noqa: N802 (the paper's name)
        """Joint-side rotor inertia N^2 J_m [kg m^2], or None when unknown."""
        if self.rotor_inertia is None:
            return None
        return self.gear_ratio**2 * self.rotor_inertia


@dataclass(frozen=True)
class RobotLimits:
    """Limits of one joint, joint side; ``inf`` (or -inf) where the file gives none.

    Attributes: ``q_min, q_max`` [rad or m], ``dq_max`` [rad/s], ``ddq_max`` [rad/s^2],
    ``dddq_max`` [rad/s^3], ``tau_max`` [N m] (prismatic: m, m/s, ..., N).
    """

    q_min: float = -math.inf
    q_max: float = math.inf
    dq_max: float = math.inf
    ddq_max: float = math.inf
    dddq_max: float = math.inf
    tau_max: float = math.inf


@dataclass(frozen=True)
class MDHJoint:
    """One row of a modified Denavit-Hartenberg table (frame j-1 -> frame j).

    Attributes: ``name``, ``type`` ("revolute" or "prismatic"), ``alpha`` [rad], ``d`` [m],
    ``theta`` [rad] (offset of a revolute joint), ``r`` [m] (offset of a prismatic joint).
    """

    name: str
    type: str
    alpha: float
    d: float
    theta: float
    r: float


def mdh_placement(alpha: float, d: float, theta: float, r: float) -> pin.SE3:
    """``Rot(x, alpha) Trans(x, d) Rot(z, theta) Trans(z, r)`` (Khalil-Kleinfinger, q = 0)."""
    ca, sa, ct, st = math.cos(alpha), math.sin(alpha), math.cos(theta), math.sin(theta)
    rx = np.array([[1.0, 0.0, 0.0], [0.0, ca, -sa], [0.0, sa, ca]])
    rz = np.array([[ct, -st, 0.0], [st, ct, 0.0], [0.0, 0.0, 1.0]])
    rot = rx @ rz
    rot[np.abs(rot) < 1e-15] = 0.0  # cos(pi/2) is 6e-17: keep the table's exact zeros
    p = np.array([d, 0.0, 0.0]) + rot @ np.array([0.0, 0.0, r])
    return pin.SE3(rot, p)


@dataclass(frozen=True, eq=False)
class Robot:
    """A serial robot: pinocchio model of the full chain, moving/locked joints, drives, limits.

    Attributes
    ----------
    name : str
    model : pinocchio.Model
        Full chain, joint-side SI; one 1-dof joint per entry of ``joint_names`` (in order);
        ``model.gravity`` is the file's gravity.
    joint_names : tuple of str
        All joints, base to tip; the parameter names use their 1-based index (ROBOT_FORMAT).
    moving : tuple of str
        Moving joints, in chain order.
    locked : Mapping[str, float]
        Locked joint -> value [rad or m] (every joint not moving).
    drives : Mapping[str, JointDrive]
        Per moving joint.
    limits : Mapping[str, RobotLimits]
        Per joint (all joints).
    gravity : ndarray, shape (3,)
        [m/s^2] in the base frame.
    types : tuple of str
        "revolute" or "prismatic" per joint (``joint_names`` order).
    source : str
        File the robot was read from ("" when built in code).
    mdh : tuple of MDHJoint or None
        The MDH table, when the robot came from one.
    inertial : bool
        Whether the file gave the inertial parameters (needed to simulate, not to identify).
    """

    name: str
    model: pin.Model
    joint_names: tuple[str, ...]
    moving: tuple[str, ...]
    locked: Mapping[str, float]
    drives: Mapping[str, JointDrive]
    limits: Mapping[str, RobotLimits]
    gravity: np.ndarray
    types: tuple[str, ...]
    source: str = ""
    mdh: tuple[MDHJoint, ...] | None = None
    inertial: bool = True
    _q_lock: np.ndarray = field(default=None, repr=False)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        q = pin.neutral(self.model)
        for n, v in self.locked.items():
            q[self.model.joints[self.model.getJointId(n)].idx_q] = v
        q.setflags(write=False)
        object.__setattr__(self, "_q_lock", q)
        object.__setattr__(self, "locked", MappingProxyType(dict(self.locked)))
        object.__setattr__(self, "drives", MappingProxyType(dict(self.drives)))
        object.__setattr__(self, "limits", MappingProxyType(dict(self.limits)))

    # ------------------------------------------------------------------ queries
    def number(self, joint: str) -> int:
        """1-based index of a joint in the full chain (the number in parameter names)."""
        try:
            return self.joint_names.index(joint) + 1
        except ValueError:
            raise RobotError(f"{self._where()}joint {joint!r}: expected one of "
                             f"{list(self.joint_names)}") from None

    @property
    def numbers(self) -> tuple[int, ...]:
        """1-based chain indices of the moving joints."""
        return tuple(self.number(n) for n in self.moving)

    @property
    def k(self) -> int:
        """Number of moving joints."""
        return len(self.moving)

    def q_full(self, q_moving: Sequence[float]) -> np.ndarray:
        """Configuration of the full chain [rad or m]: the locked values plus ``q_moving``
        (k values, ``moving`` order)."""
        q = self._q_lock.copy()
        qm = np.asarray(q_moving, dtype=float).reshape(-1)
        if qm.shape != (self.k,):
            raise RobotError(f"{self._where()}q_full: expected {self.k} positions, "
                             f"got shape {qm.shape}")
        for n, v in zip(self.moving, qm, strict=True):
            q[self.model.joints[self.model.getJointId(n)].idx_q] = v
        return q

    def reduced(self) -> pin.Model:
        """Pinocchio model of the moving joints only; locked joints at their values
        (``pin.buildReducedModel``: the inertias of locked links are merged into the moving
        link that carries them, expressed in its joint frame)."""
        if not self.locked:
            return pin.Model(self.model)
        ids = sorted(self.model.getJointId(n) for n in self.locked)
        return pin.buildReducedModel(self.model, ids, self._q_lock)

    def with_motion(self, moving: Sequence[str] | None = None,
                    locked: Mapping[str, float] | None = None) -> Robot:
        """The same robot with other moving/locked joints (rules of the ``[motion]`` table)."""
        mv, lk = _motion(self.source or self.name, self.joint_names, moving, locked, "motion")
        drives = {n: self.drives.get(n, JointDrive()) for n in mv}
        return Robot(self.name, self.model, self.joint_names, mv, lk, drives, self.limits,
                     self.gravity, self.types, self.source, self.mdh, self.inertial)

    def _where(self) -> str:
        return f"{self.source or self.name}: " if (self.source or self.name) else ""

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_pinocchio(
        cls,
        model: pin.Model,
        *,
        name: str = "",
        moving: Sequence[str] | None = None,
        locked: Mapping[str, float] | None = None,
        drives: Mapping[str, JointDrive] | None = None,
        limits: Mapping[str, RobotLimits] | None = None,
        gravity: Sequence[float] | None = None,
        source: str = "",
    ) -> Robot:
        """A robot from a pinocchio model (tests, code-built arms).

        Parameters
        ----------
        model : pinocchio.Model
            Chain of 1-dof revolute/prismatic joints (copied; gravity set to ``gravity``).
        moving, locked : optional
            As the ``[motion]`` table; default every joint moves.
        drives, limits : optional
            Per joint name; defaults :class:`JointDrive` () and the model's limits.
        gravity : (3,), optional
            [m/s^2]; default the model's.
        """
        where = source or name or "pinocchio model"
        model = pin.Model(model)
        names, types = _joint_kinds(model, where)
        g = np.array(model.gravity.linear if gravity is None else gravity, dtype=float)
        if g.shape != (3,) or not np.all(np.isfinite(g)):
            raise RobotError(f"{where}: gravity: expected 3 finite values [m/s^2], got {g}")
        model.gravity = pin.Motion(np.concatenate([g, np.zeros(3)]))
        for n in (drives or {}):
            if n not in names:
                raise RobotError(f"{where}: drives.{n}: unknown joint, expected one of {names}")
        lim = _model_limits(model, names)
        for n, v in (limits or {}).items():
            if n not in names:
                raise RobotError(f"{where}: limits.{n}: unknown joint, expected one of {names}")
            lim[n] = v
        mv, lk = _motion(where, names, moving, locked, "motion")
        dr = {n: (drives or {}).get(n) or JointDrive() for n in mv}
        return cls(name, model, names, mv, lk, dr, lim, g, types, source)


def one_joint_robot(kind: str, name: str = "joint", *,
                    limits: RobotLimits | None = None, gravity: float = STANDARD_GRAVITY,
                    source: str = "") -> Robot:
    """A robot of one joint, built in memory: the single joint of jointid as a 1-dof robot.

    The joint ``name`` turns about (``"revolute"``) or slides along (``"prismatic"``) the z
    axis of the base frame; gravity is ``(0, -gravity, 0)``, perpendicular to the axis, so the
    regressor's gravity torque of the revolute joint is ``g (MX1 cos q - MY1 sin q)`` and
    ``(ZZ1 + Ia1) ddq`` its inertial torque -- the single-joint model's ``J ddq + g (MX cos q
    + MY sin q)`` (paper eq. 31) with ``J = ZZ1 + Ia1``, ``MX = MX1``, ``MY = -MY1`` -- and a
    prismatic joint carries ``(M1 + Ia1) ddq`` and no gravity load. The link has no
    inertial parameters (``inertial = False``).

    Parameters
    ----------
    kind : {"revolute", "prismatic"}
    name : str
        Joint name (parameter names use its chain number, 1).
    limits : RobotLimits, optional
        The joint's limits; default none.
    gravity : float
        Magnitude of gravity [m/s^2].
    source : str
        Where the joint comes from (error messages).

    Raises
    ------
    RobotError
        ``kind`` is neither revolute nor prismatic.
    """
    if kind not in ("revolute", "prismatic"):
        raise RobotError(f"{source + ': ' if source else ''}kind: expected 'revolute' or "
                         f"'prismatic', got {kind!r}")
    model = pin.Model()
    axis = pin.JointModelRZ() if kind == "revolute" else pin.JointModelPZ()
    jid = model.addJoint(0, axis, pin.SE3.Identity(), name)
    model.appendBodyToJoint(jid, pin.Inertia.Zero(), pin.SE3.Identity())
    robot = Robot.from_pinocchio(model, name=name, limits=None if limits is None else
                                 {name: limits}, gravity=(0.0, -float(gravity), 0.0),
                                 source=source)
    return Robot(robot.name, robot.model, robot.joint_names, robot.moving, robot.locked,
                 robot.drives, robot.limits, robot.gravity, robot.types, robot.source,
                 robot.mdh, inertial=False)


# --------------------------------------------------------------------------- shared checks
def _joint_kinds(model: pin.Model, src: str) -> tuple[tuple[str, ...], tuple[str, ...]]:
    names, types = [], []
    for i in range(1, model.njoints):
        jm = model.joints[i]
        short = jm.shortname()
        if short in _REVOLUTE or short == "JointModelRevoluteUnaligned":
            types.append("revolute")
        elif short in _PRISMATIC or short == "JointModelPrismaticUnaligned":
            types.append("prismatic")
        else:
            raise RobotError(f"{src}: joint {model.names[i]!r}: expected a 1-dof revolute or "
                             f"prismatic joint, got {short} (nq={jm.nq})")
        names.append(model.names[i])
    if not names:
        raise RobotError(f"{src}: expected at least one joint, the model has none")
    return tuple(names), tuple(types)


def _model_limits(model: pin.Model, names: tuple[str, ...]) -> dict[str, RobotLimits]:
    out = {}
    for n in names:
        iq = model.joints[model.getJointId(n)].idx_q
        iv = model.joints[model.getJointId(n)].idx_v

        def fin(x: float, default: float) -> float:
            return float(x) if math.isfinite(x) and abs(x) < 1e10 else default

        out[n] = RobotLimits(
            q_min=fin(model.lowerPositionLimit[iq], -math.inf),
            q_max=fin(model.upperPositionLimit[iq], math.inf),
            dq_max=fin(model.velocityLimit[iv], math.inf) or math.inf,
            tau_max=fin(model.effortLimit[iv], math.inf) or math.inf)
    return out


def _motion(src: str, names: tuple[str, ...], moving: Any, locked: Any,
            key: str) -> tuple[tuple[str, ...], dict[str, float]]:
    if locked is None:
        locked = {}
    if not isinstance(locked, Mapping):
        raise _err(src, f"{key}.locked", "a table joint = value [rad or m]", locked)
    lk: dict[str, float] = {}
    for n, v in locked.items():
        if n not in names:
            raise _err(src, f"{key}.locked.{n}", f"a joint of the robot {list(names)}", n)
        lk[n] = _number(src, f"{key}.locked.{n}", v)
    if moving is None:
        mv = [n for n in names if n not in lk]
    else:
        if isinstance(moving, str) or not isinstance(moving, Sequence):
            raise _err(src, f"{key}.moving", "a list of joint names", moving)
        for n in moving:
            if n not in names:
                raise _err(src, f"{key}.moving", f"joints of the robot {list(names)}", n)
            if n in lk:
                raise _err(src, f"{key}.moving", "joints that are not also locked", n)
        if len(set(moving)) != len(moving):
            raise _err(src, f"{key}.moving", "distinct joint names", list(moving))
        missing = [n for n in names if n not in moving and n not in lk]
        if missing:
            raise _err(src, f"{key}.locked.{missing[0]}", "a locked value for every joint "
                       "that does not move")
        mv = [n for n in names if n in moving]
    if not mv:
        raise _err(src, f"{key}.moving", "at least one moving joint")
    return tuple(mv), lk


def _drive(src: str, key: str, d: Any) -> JointDrive:
    if not isinstance(d, Mapping):
        raise _err(src, key, "a table (gear_ratio, drive_gain, rotor_inertia)", d)
    _keys(src, key, d, {"gear_ratio", "drive_gain", "torque_constant", "rotor_inertia"})
    vals: dict[str, Any] = {}
    for k in ("gear_ratio", "drive_gain", "torque_constant"):
        if k in d:
            v = _number(src, f"{key}.{k}", d[k])
            if not v > 0:
                raise _err(src, f"{key}.{k}", "a number > 0", d[k])
            vals[k] = v
    if "drive_gain" in vals and "torque_constant" in vals:
        raise _err(src, f"{key}.torque_constant", "either drive_gain or torque_constant, "
                   "not both")
    jm = d.get("rotor_inertia", "identify")
    if jm != "identify":
        v = _number(src, f"{key}.rotor_inertia", jm, "a number >= 0 [kg m^2] or 'identify'")
        if v < 0:
            raise _err(src, f"{key}.rotor_inertia", "a number >= 0 [kg m^2] or 'identify'", jm)
        vals["rotor_inertia"] = v
    return JointDrive(**vals)


_LIMIT_KEYS = ("q_min", "q_max", "dq_max", "ddq_max", "dddq_max", "tau_max")


def _limits(src: str, key: str, d: Any) -> RobotLimits:
    if not isinstance(d, Mapping):
        raise _err(src, key, "a table " + ", ".join(_LIMIT_KEYS), d)
    _keys(src, key, d, set(_LIMIT_KEYS))
    vals = {k: _number(src, f"{key}.{k}", d[k]) for k in _LIMIT_KEYS if k in d}
    for k in _LIMIT_KEYS[2:]:
        if k in vals and not vals[k] > 0:
            raise _err(src, f"{key}.{k}", "a number > 0", vals[k])
    lim = RobotLimits(**vals)
    if not lim.q_min < lim.q_max:
        raise _err(src, f"{key}.q_max", f"a value > q_min = {lim.q_min}", lim.q_max)
    return lim


# --------------------------------------------------------------------------- small checks
def _err(src: str, key: str, expected: str, got: Any = ...) -> RobotError:
    where = f"{src}: " if src else ""
    tail = "" if got is ... else f", got {got!r}"
    return RobotError(f"{where}{key}: expected {expected}{tail}")


def _keys(src: str, key: str, d: Mapping, allowed: set[str]) -> None:
    bad = sorted(set(d) - allowed)
    if bad:
        k = f"{key}.{bad[0]}" if key else bad[0]
        raise RobotError(f"{src + ': ' if src else ''}{k}: expected one of the known keys "
                         f"({', '.join(sorted(allowed))}), not this unknown key")


def _number(src: str, key: str, v: Any, expected: str = "a finite number") -> float:
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise _err(src, key, expected, v)
    return float(v)


def _vector(src: str, key: str, v: Any, n: int) -> np.ndarray:
    if not isinstance(v, list | tuple) or len(v) != n:
        raise _err(src, key, f"a list of {n} numbers", v)
    return np.array([_number(src, f"{key}[{i}]", x) for i, x in enumerate(v)])
