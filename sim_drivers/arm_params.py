"""Ground truth of the simulated n-dof arm: rigid body, rotor inertias, the paper's friction
per joint, drive chains, undeclared effects, payload; and the true parameters by name.

The dynamics that use them are in :mod:`sim_drivers.arm_plant` (its docstring gives the
equations). Joint numbering: joints are numbered 1..k in the chain of MOVING joints (the
pinocchio model given to :class:`ArmParams`), unless ``joint_numbers`` maps them to other
labels (e.g. their index in the full chain, as ROBOT_FORMAT's parameter names use).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np
import pinocchio as pin

from trajectories.friction import DEFAULT_Q_S
from trajectories.robot import LINK_NAMES, from_pinocchio_order

from . import SimError
from .arm_effects import ArmEffects

_INT16_MIN, _INT16_MAX = -32768, 32767
#: Names of the standard parameters of a link, in ROBOT_FORMAT order (the robot model's).
STANDARD_NAMES = LINK_NAMES
#: Friction coefficient attribute -> parameter name prefix (ROBOT_FORMAT).
FRICTION_NAMES = {"a_m": "a_m", "b_m": "b_m", "a_g": "a_g", "b_g": "b_g", "c_m": "c_m",
                  "d_m": "d_m", "c_g": "c_g", "d_g": "d_g", "F_V": "FV", "tau_off": "OFF",
                  "q_s": "qs"}


class ArmParamsError(SimError, ValueError):
    """Invalid arm parameters; the message names the object, field and joint."""


def _vec(name: str, value: Any, k: int | None) -> np.ndarray:
    a = np.array(value, dtype=float)
    if a.ndim == 0 and k is not None:
        a = np.full(k, float(a))
    a = a.reshape(-1)
    if k is not None and a.shape != (k,):
        raise ArmParamsError(f"{name}: expected {k} values (one per moving joint), "
                             f"got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ArmParamsError(f"{name}: expected finite values, got {a}")
    a.setflags(write=False)
    return a


# --------------------------------------------------------------------------- parameters
@dataclass(frozen=True, eq=False)
class ArmFriction:
    """Friction of eq. 25/30 per joint; every attribute is an array of shape (k,).

    Attributes
    ----------
    a_m, b_m, a_g, b_g : ndarray
        Load coefficients [-] (a_m = 1 + alpha_m, a_g = 1 - alpha_g, eq. 24-25).
    c_m, d_m, c_g, d_g : ndarray
        Load-independent dry friction: sliding part c and stiction excess d [N m].
    F_V : ndarray
        Viscous coefficient [N m s/rad].
    tau_off : ndarray
        Offset torque (eq. 6) [N m].
    q_s : ndarray
        Velocity constant of E = exp(-|dq| / q_s) (eq. 29) [rad/s].
    """

    a_m: np.ndarray
    b_m: np.ndarray
    a_g: np.ndarray
    b_g: np.ndarray
    c_m: np.ndarray
    d_m: np.ndarray
    c_g: np.ndarray
    d_g: np.ndarray
    F_V: np.ndarray
    tau_off: np.ndarray
    q_s: np.ndarray

    def __post_init__(self) -> None:
        k = max(np.size(getattr(self, f.name)) for f in fields(self))
        for f in fields(self):
            object.__setattr__(self, f.name, _vec(f"ArmFriction.{f.name}",
                                                  getattr(self, f.name), k))
        checks = (
            (self.a_m > 0, "a_m > 0"), (self.a_m + self.b_m > 0, "a_m + b_m > 0"),
            (self.a_g > 0, "a_g > 0"), (self.a_g - self.b_g > 0, "a_g - b_g > 0"),
            (self.a_g - self.b_g <= self.a_m + self.b_m, "a_g - b_g <= a_m + b_m"),
            (self.c_m >= 0, "c_m >= 0"), (self.c_g >= 0, "c_g >= 0"),
            (self.c_m + self.d_m >= 0, "c_m + d_m >= 0"), (self.c_g + self.d_g >= 0,
                                                           "c_g + d_g >= 0"),
            (self.F_V >= 0, "F_V >= 0"), (self.q_s > 0, "q_s > 0"),
        )
        for ok, what in checks:
            if not np.all(ok):
                j = int(np.flatnonzero(~ok)[0])
                raise ArmParamsError(f"ArmFriction: expected {what} on every joint, "
                                     f"violated on joint index {j + 1}")

    @property
    def k(self) -> int:
        return int(self.a_m.shape[0])

    @classmethod
    def from_dict(cls, d: dict[str, Any], k: int) -> ArmFriction:
        """From a mapping of attribute name -> scalar (all joints) or (k,) values."""
        names = [f.name for f in fields(cls)]
        unknown = sorted(set(d) - set(names))
        if unknown:
            raise ArmParamsError(f"friction: unknown key(s) {unknown}; expected {names}")
        missing = [n for n in names if n not in d]
        if missing:
            raise ArmParamsError(f"friction: missing key(s) {missing}")
        return cls(**{n: _vec(f"friction.{n}", d[n], k) for n in names})


@dataclass(frozen=True, eq=False)
class ArmDrive:
    """Drive chains: gear, rated torque, encoder, ripple noise; arrays of shape (k,).

    The target torque x (0x6071) is an int16 in per-mille of the rated torque; the joint-side
    torque is ``tau = N rated_torque_Nm x / 1000`` (like :mod:`sim_drivers.offline`); the
    encoder reads ``counts = round(q N counts_per_rev / 2 pi)``.

    Attributes
    ----------
    gear_ratio : ndarray
        N [-].
    rated_torque_Nm : ndarray
        Motor rated torque [N m] (motor side).
    encoder_counts_per_rev : ndarray
        Counts per motor revolution.
    torque_noise_std_Nm : ndarray
        Standard deviation of the applied-torque ripple noise, joint side [N m]; one Gaussian
        sample per joint and control cycle, held over the cycle.
    """

    gear_ratio: np.ndarray
    rated_torque_Nm: np.ndarray
    encoder_counts_per_rev: np.ndarray
    torque_noise_std_Nm: np.ndarray

    def __post_init__(self) -> None:
        k = max(np.size(getattr(self, f.name)) for f in fields(self))
        for f in fields(self):
            v = _vec(f"ArmDrive.{f.name}", getattr(self, f.name), k)
            bad = (v < 0) if f.name == "torque_noise_std_Nm" else (v <= 0)
            if np.any(bad):
                raise ArmParamsError(f"ArmDrive.{f.name}: expected values "
                                     f"{'>= 0' if f.name.startswith('torque') else '> 0'}, "
                                     f"got {v}")
            object.__setattr__(self, f.name, v)

    @property
    def torque_per_permille(self) -> np.ndarray:
        """Joint-side torque of one per-mille of rated torque, N rated / 1000 [N m], (k,)."""
        return self.gear_ratio * self.rated_torque_Nm / 1000.0

    @property
    def counts_per_rad(self) -> np.ndarray:
        """Encoder counts per joint radian [counts/rad], (k,)."""
        return self.gear_ratio * self.encoder_counts_per_rev / (2.0 * math.pi)

    def quantise(self, tau: np.ndarray) -> np.ndarray:
        """Per-mille target torque (int16) of joint-side torques [N m], (..., k)."""
        x = np.rint(np.asarray(tau, dtype=float) / self.torque_per_permille)
        return np.clip(x, _INT16_MIN, _INT16_MAX).astype(np.int16)


@dataclass(frozen=True, eq=False)
class Payload:
    """Payload fixed to the flange (paper IV.C, eq. 32-35 generalised).

    Same convention as ``trajectories``' campaign payloads (``RobotPayload``): inertia about
    the centre of mass, flange axes (eq. 32); :attr:`inertia_origin` and
    :meth:`dynamic_parameters` give it about the flange origin (Huygens, eq. 33), as the
    standard parameters are.

    Attributes
    ----------
    mass : float
        M_a [kg].
    com : ndarray, shape (3,)
        Centre of mass in the flange frame [m].
    inertia : ndarray, shape (6,)
        XX, XY, XZ, YY, YZ, ZZ [kg m^2] about the centre of mass, axes of the flange frame
        (default 0: a point mass).
    frame : str or None
        Pinocchio frame the payload is fixed to; None: the frame of the last moving joint.
    """

    mass: float
    com: np.ndarray = field(default_factory=lambda: np.zeros(3))
    inertia: np.ndarray = field(default_factory=lambda: np.zeros(6))
    frame: str | None = None

    def __post_init__(self) -> None:
        m = float(self.mass)
        if not (math.isfinite(m) and m >= 0):
            raise ArmParamsError(f"Payload.mass: expected a finite mass >= 0 [kg], got {m!r}")
        object.__setattr__(self, "mass", m)
        object.__setattr__(self, "com", _vec("Payload.com", self.com, 3))
        object.__setattr__(self, "inertia", _vec("Payload.inertia", self.inertia, 6))
        if m == 0 and (np.any(self.inertia) or np.any(self.com)):
            raise ArmParamsError("Payload: a payload of mass 0 must have zero com and inertia")

    @classmethod
    def coerce(cls, payload: Any) -> Payload | None:
        """A Payload from None, a Payload, or any object with ``mass_kg`` (or ``mass``),
        ``com`` and ``inertia`` about the centre of mass (e.g. a campaign's ``RobotPayload``),
        and optionally ``frame``."""
        if payload is None or isinstance(payload, Payload):
            return payload
        mass = getattr(payload, "mass_kg", getattr(payload, "mass", None))
        if mass is None:
            raise ArmParamsError(f"payload: expected a Payload or an object with mass_kg, com "
                                 f"and inertia, got {type(payload).__name__}")
        return cls(float(mass), getattr(payload, "com", np.zeros(3)),
                   getattr(payload, "inertia", np.zeros(6)), getattr(payload, "frame", None))

    @property
    def inertia_origin(self) -> np.ndarray:
        """XX, XY, XZ, YY, YZ, ZZ about the flange frame origin [kg m^2] (eq. 33)."""
        xx, xy, xz, yy, yz, zz = self.inertia
        c = self.com
        i_o = (np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
               + self.mass * (c @ c * np.eye(3) - np.outer(c, c)))
        return np.array([i_o[0, 0], i_o[0, 1], i_o[0, 2], i_o[1, 1], i_o[1, 2], i_o[2, 2]])

    def dynamic_parameters(self) -> np.ndarray:
        """Pinocchio order [m, mc_x, mc_y, mc_z, Ixx, Ixy, Iyy, Ixz, Iyz, Izz] (inertia about
        the frame origin)."""
        xx, xy, xz, yy, yz, zz = self.inertia_origin
        mc = self.mass * self.com
        return np.array([self.mass, *mc, xx, xy, yy, xz, yz, zz])


def _inertia_from_dyn(v: np.ndarray) -> pin.Inertia:
    """pin.Inertia of [m, mc, I about origin]; a massless body with zero inertia is Zero."""
    if v[0] == 0:
        if np.any(v):
            raise ArmParamsError("inertia: a massless body must have zero first moments")
        return pin.Inertia.Zero()
    return pin.Inertia.FromDynamicParameters(np.asarray(v, dtype=float))


def _check_model(model: Any) -> int:
    if not isinstance(model, pin.Model):
        raise ArmParamsError(f"ArmParams.model: expected a pinocchio.Model, got "
                             f"{type(model).__name__}")
    k = model.nv
    if k < 1 or model.nq != k or model.njoints != k + 1:
        raise ArmParamsError(f"ArmParams.model {model.name!r}: expected a serial chain of k "
                             f"one-dof joints (nq == nv == njoints - 1), got nq={model.nq}, "
                             f"nv={model.nv}, njoints={model.njoints}")
    for i in range(1, model.njoints):
        if model.parents[i] != i - 1:
            raise ArmParamsError(f"ArmParams.model: joint {model.names[i]!r} is not a child of "
                                 f"the previous joint (expected a serial chain)")
    return k


@dataclass(frozen=True, eq=False)
class ArmParams:
    """Ground truth of a simulated arm (moving joints only).

    Attributes
    ----------
    model : pinocchio.Model
        Rigid body of the MOVING joints, joint-side SI (reduce locked joints with
        ``pin.buildReducedModel``); k one-dof joints in a serial chain. Its armature and
        gravity are ignored (``Ia`` and ``gravity`` are used).
    Ia : ndarray, shape (k,)
        Rotor inertia of each drive chain, joint side [kg m^2] (J = Ia + ZZ, eq. 31).
    friction : ArmFriction
    drive : ArmDrive
    effects : ArmEffects
        Undeclared effects (default: none).
    gravity : ndarray, shape (3,)
        Gravity in the base frame [m/s^2].
    joint_numbers : tuple of int
        Labels of the joints in parameter names (default 1..k).
    name : str
    """

    model: pin.Model
    Ia: np.ndarray
    friction: ArmFriction
    drive: ArmDrive
    effects: ArmEffects | None = None
    gravity: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, -9.81]))
    joint_numbers: tuple[int, ...] | None = None
    name: str = ""

    def __post_init__(self) -> None:
        k = _check_model(self.model)
        object.__setattr__(self, "Ia", _vec("ArmParams.Ia", self.Ia, k))
        if np.any(self.Ia < 0):
            raise ArmParamsError(f"ArmParams.Ia: expected values >= 0 [kg m^2], got {self.Ia}")
        object.__setattr__(self, "gravity", _vec("ArmParams.gravity", self.gravity, 3))
        if self.friction.k != k:
            raise ArmParamsError(f"ArmParams.friction: expected {k} joints, got "
                                 f"{self.friction.k}")
        if self.drive.gear_ratio.shape != (k,):
            raise ArmParamsError(f"ArmParams.drive: expected {k} joints, got "
                                 f"{self.drive.gear_ratio.shape[0]}")
        eff = ArmEffects.none(k) if self.effects is None else self.effects
        if eff.k != k:
            raise ArmParamsError(f"ArmParams.effects: expected {k} joints, got {eff.k}")
        object.__setattr__(self, "effects", eff)
        nums = tuple(range(1, k + 1)) if self.joint_numbers is None else tuple(
            int(j) for j in self.joint_numbers)
        if len(nums) != k or len(set(nums)) != k:
            raise ArmParamsError(f"ArmParams.joint_numbers: expected {k} distinct labels, "
                                 f"got {nums}")
        object.__setattr__(self, "joint_numbers", nums)
        object.__setattr__(self, "name", self.name or self.model.name)
        # private copy: the caller's model is never modified
        object.__setattr__(self, "model", pin.Model(self.model))

    @property
    def k(self) -> int:
        """Number of moving joints."""
        return int(self.model.nv)

    # ------------------------------------------------------------------ models
    def payload_inertia(self, payload: Payload | None) -> tuple[int, pin.Inertia]:
        """(pinocchio joint id, inertia in that joint's frame) of a payload."""
        payload = Payload.coerce(payload)
        if payload is None or payload.mass == 0:
            return self.k, pin.Inertia.Zero()
        model = self.model
        inertia = _inertia_from_dyn(payload.dynamic_parameters())
        if payload.frame is None:
            return self.k, inertia
        if not model.existFrame(payload.frame):
            raise ArmParamsError(f"Payload.frame: {payload.frame!r} is not a frame of model "
                                 f"{model.name!r}")
        fr = model.frames[model.getFrameId(payload.frame)]
        return int(fr.parentJoint), fr.placement.act(inertia)

    def dynamics_model(self, payload: Payload | None = None) -> pin.Model:
        """Copy of the model with ``armature = Ia``, the gravity, and the payload added to
        the inertia of the body it is fixed to (pinocchio Inertia addition)."""
        m = pin.Model(self.model)
        m.armature = np.array(self.Ia, dtype=float)
        m.gravity = pin.Motion(np.array(self.gravity), np.zeros(3))
        jid, inertia = self.payload_inertia(payload)
        m.inertias[jid] = m.inertias[jid] + inertia
        return m

    def truth(self, payload: Payload | None = None) -> dict[str, float]:
        """The true parameters by the names of ROBOT_FORMAT (n-dof).

        Standard parameters of link j in the pinocchio frame of joint j (= MDH frame j when the
        model is built from an MDH table), about its origin (Khalil): ``XX{j} XY{j} XZ{j} YY{j}
        YZ{j} ZZ{j} MX{j} MY{j} MZ{j} M{j}`` (with the payload added to the link it is fixed
        to, eq. 34-35 generalised), ``Ia{j}`` and the paper friction ``a_m{j} b_m{j} a_g{j}
        b_g{j} c_m{j} d_m{j} c_g{j} d_g{j} FV{j} OFF{j} qs{j}``; j from ``joint_numbers``.
        """
        model = self.dynamics_model(payload)
        out: dict[str, float] = {}
        for i, j in enumerate(self.joint_numbers):
            phi = from_pinocchio_order(model.inertias[i + 1].toDynamicParameters())
            for n, v in zip(STANDARD_NAMES, phi, strict=True):
                out[f"{n}{j}"] = float(v)
            out[f"Ia{j}"] = float(self.Ia[i])
            for attr, prefix in FRICTION_NAMES.items():
                out[f"{prefix}{j}"] = float(getattr(self.friction, attr)[i])
        return out

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_model(
        cls,
        model: pin.Model,
        friction: ArmFriction | dict[str, Any] | None = None,
        *,
        Ia: Any = None,
        drive: ArmDrive | None = None,
        effects: ArmEffects | None = None,
        gravity: Any = None,
        q_s: float = DEFAULT_Q_S,
        gear_ratio: Any = 100.0,
        acceleration_scale: float = 3.0,
        joint_numbers: Any = None,
        name: str = "",
        seed: int = 0,
    ) -> ArmParams:
        """A plausible truth for a given rigid body.

        Each joint's load L_j [N m] is its largest gravity torque plus its largest diagonal
        inertia times ``acceleration_scale`` [rad/s^2] over 64 configurations within the joint
        limits (seeded); the defaults then follow the RX130L joint of
        ``sim_drivers/data/plant_default.toml`` scaled by L: a_m 1.05, b_m 0.25, a_g 0.92,
        b_g 0.27, c_m 5 % L, d_m 2 % L, c_g 4 % L, d_g 1.5 % L, F_V 8 % L per rad/s, tau_off
        2 % L, q_s 0.03 rad/s; Ia = half the largest diagonal inertia of the link (at least
        0.05 kg m^2); drive N = ``gear_ratio``, rated torque such that 1 per-mille = 0.2 % L,
        4096 counts per motor revolution, ripple noise 1 % L.

        Parameters
        ----------
        model : pinocchio.Model
            Rigid body of the moving joints.
        friction : ArmFriction or dict, optional
            Friction to use instead of the default; a dict (attribute name -> scalar or (k,)
            values) overrides only the coefficients it names.
        Ia : array_like (k,), optional
            Rotor inertias [kg m^2]; NaN entries (or None) take the default.
        gear_ratio : float or array_like (k,)
            N of the default drive (ignored when ``drive`` is given).
        drive, effects, gravity, joint_numbers, name
            As the attributes; defaults as above (gravity: the model's).
        """
        k = _check_model(model)
        load, diag = cls._loads(model, acceleration_scale, seed)
        ia_default = np.maximum(0.5 * diag, 0.05)
        if Ia is None:
            Ia = ia_default
        else:
            Ia = np.array([np.nan if v is None else v for v in np.broadcast_to(
                np.asarray(Ia, dtype=object), (k,))], dtype=float)
            Ia = np.where(np.isnan(Ia), ia_default, Ia)
        if not isinstance(friction, ArmFriction):
            default = dict(
                a_m=np.full(k, 1.05), b_m=np.full(k, 0.25), a_g=np.full(k, 0.92),
                b_g=np.full(k, 0.27), c_m=0.05 * load, d_m=0.02 * load, c_g=0.04 * load,
                d_g=0.015 * load, F_V=0.08 * load, tau_off=0.02 * load, q_s=np.full(k, q_s))
            unknown = sorted(set(friction or {}) - set(default))
            if unknown:
                raise ArmParamsError(f"friction: unknown key(s) {unknown}; expected "
                                     f"{sorted(default)}")
            default.update({n: _vec(f"friction.{n}", v, k) for n, v in (friction or {}).items()})
            friction = ArmFriction(**default)
        if drive is None:
            n = _vec("gear_ratio", gear_ratio, k)
            drive = ArmDrive(gear_ratio=n, rated_torque_Nm=2.0 * load / n,
                             encoder_counts_per_rev=np.full(k, 4096.0),
                             torque_noise_std_Nm=0.01 * load)
        if gravity is None:
            gravity = np.array(model.gravity.linear)
        return cls(model=model, Ia=Ia, friction=friction, drive=drive, effects=effects,
                   gravity=gravity, joint_numbers=joint_numbers, name=name)

    @classmethod
    def from_robot(cls, robot: Any, friction: Any = None, **kw: Any) -> ArmParams:
        """A plausible truth for a robot description (``trajectories.robot.Robot``, ROBOT_FORMAT).

        Uses ``robot.reduced()`` (the moving joints, locked ones at their values), labels the
        joints by their 1-based index in the full chain (``robot.joint_names``), and takes from
        ``robot.drives`` (per moving joint, by name or in order; entries may be None) the gear
        ratio N (default 100) and the rotor inertia J_m, ``Ia = N^2 J_m`` (default: as
        :meth:`from_model`). Other keywords go to :meth:`from_model`.
        """
        model = robot.reduced()
        names = list(robot.joint_names)
        moving = list(robot.moving)
        drives = getattr(robot, "drives", None) or {}
        per = [drives.get(n) if hasattr(drives, "get") else drives[i]
               for i, n in enumerate(moving)]
        gear = np.array([float(getattr(d, "gear_ratio", None) or 100.0) for d in per])
        jm = [getattr(d, "rotor_inertia", None) for d in per]
        ia = [g * g * float(j) if isinstance(j, (int, float)) else None
              for g, j in zip(gear, jm, strict=True)]
        kw.setdefault("joint_numbers", [names.index(n) + 1 for n in moving])
        kw.setdefault("name", getattr(robot, "name", ""))
        kw.setdefault("Ia", ia)
        kw.setdefault("gear_ratio", gear)
        return cls.from_model(model, friction, **kw)

    @staticmethod
    def _loads(model: pin.Model, acc: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
        """(load L_j [N m], largest M_jj [kg m^2]) over sampled configurations."""
        m = pin.Model(model)
        m.armature = np.zeros(m.nv)
        data = m.createData()
        lo = np.where(np.isfinite(m.lowerPositionLimit), m.lowerPositionLimit, -np.pi)
        hi = np.where(np.isfinite(m.upperPositionLimit), m.upperPositionLimit, np.pi)
        lo, hi = np.maximum(lo, -np.pi), np.minimum(hi, np.pi)
        rng = np.random.default_rng(seed)
        qs = np.vstack([np.zeros(m.nq), lo + (hi - lo) * rng.random((63, m.nq))])
        grav = np.zeros(m.nv)
        diag = np.zeros(m.nv)
        for q in qs:
            grav = np.maximum(grav, np.abs(pin.computeGeneralizedGravity(m, data, q)))
            diag = np.maximum(diag, np.diag(pin.crba(m, data, q)))
        inertia = np.maximum(diag, 0.05)  # at least the default rotor inertia
        return grav + acc * inertia, diag
