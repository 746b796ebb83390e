"""Robot description: a URDF or an MDH TOML robot file -> :class:`Robot` (pinocchio model).

(Past 600 lines: one file format -- its dataclasses, reader, builders and the checks that name
each element; split, the format would be scattered.)

File format (docs/robot-format.md, ROBOT_FORMAT): either a URDF (``*.urdf``: every joint moves,
no drive data) or a TOML file with a ``[robot]`` table and EITHER ``urdf = "..."`` (a path
relative to the TOML file, or ``"example-robot-data:ur10"`` for the packaged UR10) OR a
modified Denavit-Hartenberg table (Khalil-Kleinfinger) in ``[[joints]]``, per-joint drive
data and limits, and an optional ``[motion]`` table (moving and locked joints).

Frame convention of an MDH table: joint ``j`` of the pinocchio model has the MDH frame ``j``
as its joint frame, so that frame ``j-1 -> j`` is ``Rot(x, alpha) Trans(x, d) Rot(z, theta)
Trans(z, r)`` with the joint variable added to ``theta`` (revolute) or ``r`` (prismatic), and
pinocchio's body inertia of joint ``j`` (first moments and inertia about the joint-frame
origin) is Khalil's set of standard parameters of link ``j``.

Every mistake raises :class:`RobotError` with one line naming the file and the element::

    arm3.toml: joints[j2].drive.gear_ratio: expected a number > 0, got -3

This module (with :mod:`trajectories.campaign_file` and :mod:`trajectories.cli`) reads files;
everything else in :mod:`trajectories` is pure.
"""

from __future__ import annotations

import contextlib
import importlib.metadata as metadata
import math
import os
import tempfile
import tomllib
import xml.etree.ElementTree as ET
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np
import pinocchio as pin

from . import RobotError

__all__ = [
    "RobotError",
    "JointDrive",
    "RobotLimits",
    "MDHJoint",
    "Robot",
    "load_robot",
    "example_robot_urdf",
    "example_robot_names",
    "EXAMPLE_ROBOTS",
    "mdh_placement",
]

#: Packaged robots: ``"example-robot-data:<name>"`` -> URDF inside the example-robot-data share.
EXAMPLE_ROBOTS: dict[str, str] = {
    "ur10": "robots/ur_description/urdf/ur10_robot.urdf",
    "ur5": "robots/ur_description/urdf/ur5_robot.urdf",
    "ur3": "robots/ur_description/urdf/ur3_robot.urdf",
}
_LOCATOR = "example-robot-data:"
_DISTRIBUTIONS = ("example-robot-data", "cmeel-example-robot-data")
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


# --------------------------------------------------------------------------- locating URDFs
def _packaged_urdfs() -> dict[str, Path]:
    """Every URDF of the installed example-robot-data share: path relative to the share
    (``robots/<pkg>/<dir>/<file>.urdf``) -> file. Empty when the package is not installed."""
    out: dict[str, Path] = {}
    for dist_name in _DISTRIBUTIONS:
        try:
            dist = metadata.distribution(dist_name)
        except metadata.PackageNotFoundError:
            continue
        for f in dist.files or ():
            s = str(f).replace("\\", "/")
            key = "example-robot-data/robots/"
            if s.endswith(".urdf") and key in s:
                rel = "robots/" + s.split(key, 1)[1]
                out.setdefault(rel, Path(dist.locate_file(f)))
    return out


def example_robot_names() -> list[str]:
    """Names ``load_robot("example-robot-data:<name>")`` accepts: ``EXAMPLE_ROBOTS`` and the
    file name (without ``.urdf``) of every URDF of the installed share that no other file
    shares."""
    stems: dict[str, int] = {}
    for rel in _packaged_urdfs():
        stem = rel.rsplit("/", 1)[1][:-len(".urdf")]
        stems[stem] = stems.get(stem, 0) + 1
    return sorted(set(EXAMPLE_ROBOTS) | {n for n, c in stems.items() if c == 1})


def example_robot_urdf(name: str, source: str = "") -> Path:
    """Path of the URDF of a robot packaged by ``example-robot-data`` (e.g. ``"ur10"``,
    ``"panda"``).

    ``name`` is one of ``EXAMPLE_ROBOTS`` (the UR arms without gripper), else the file name of
    a packaged URDF without ``.urdf`` (``panda``, ``xarm7``, ``kinova``, ``ur5_gripper``), or
    its path under the share (``robots/panda_description/urdf/panda.urdf``) when the file name
    is not unique. The PyPI wheel ships the files under its ``cmeel.prefix`` folder and may not
    ship the ``example_robot_data`` module, so the file is found through the installed
    distribution's file list (:mod:`importlib.metadata`), never through a hard-coded path.

    Raises
    ------
    RobotError
        Unknown or ambiguous name, or the package (or the file) is not installed.
    """
    where = f"{source}: robot.urdf: " if source else ""
    files = _packaged_urdfs()
    if not files:
        raise RobotError(f"{where}example robot {name!r}: expected the PyPI package "
                         f"'example-robot-data' to be installed")
    if name in EXAMPLE_ROBOTS:
        found = [EXAMPLE_ROBOTS[name]] if EXAMPLE_ROBOTS[name] in files else []
    elif name.endswith(".urdf"):
        found = [r for r in files if r == name or r.endswith("/" + name)]
    else:
        found = [r for r in files if r.rsplit("/", 1)[1] == name + ".urdf"]
    if len(found) > 1:
        raise RobotError(f"{where}example robot {name!r}: several packaged URDFs "
                         f"{sorted(found)}; expected one of these paths")
    if not found:
        raise RobotError(f"{where}example robot {name!r}: expected one of "
                         f"{example_robot_names()}")
    p = files[found[0]]
    if not p.is_file():
        raise RobotError(f"{where}example robot {name!r}: {found[0]} is listed by the "
                         f"package but missing on disk")
    return p


# --------------------------------------------------------------------------- loading
def load_robot(path: str | Path) -> Robot:
    """Read a robot file: a URDF (``*.urdf``) or a TOML file (MDH table or ``urdf = ...``).

    Parameters
    ----------
    path : str or Path
        The file; ``"example-robot-data:ur10"`` loads the packaged UR10 URDF directly.

    Returns
    -------
    Robot

    Raises
    ------
    RobotError
        Unreadable file, URDF that does not parse, both or neither of ``urdf`` and an MDH
        table, unknown joint, invalid drive data or limits, locked value missing, ... (one
        line naming the file and the element).
    """
    text_path = str(path)
    if text_path.startswith(_LOCATOR):
        short = text_path[len(_LOCATOR):]
        return _from_urdf(example_robot_urdf(short, text_path), short, {}, [], text_path)
    p = Path(path)
    src = str(p)
    if p.suffix.lower() == ".urdf":
        return _from_urdf(p, p.stem, {}, [], src)
    try:
        raw = tomllib.loads(p.read_text(encoding="utf-8"))
    except OSError as e:
        raise RobotError(f"{src}: cannot read the robot file ({e.strerror or e})") from None
    except UnicodeDecodeError:
        raise RobotError(f"{src}: expected a UTF-8 TOML or URDF robot file") from None
    except tomllib.TOMLDecodeError as e:
        raise RobotError(f"{src}: not valid TOML ({e})") from None
    return robot_from_dict(raw, src, base_dir=p.parent)


def robot_from_dict(raw: Mapping[str, Any], source: str = "",
                    base_dir: str | Path | None = None) -> Robot:
    """Validate a parsed robot TOML mapping (see :func:`load_robot`); a relative ``urdf`` is
    resolved against ``base_dir`` (default: the current directory)."""
    _keys(source, "", raw, {"robot", "joints", "motion"})
    r = raw.get("robot")
    if not isinstance(r, Mapping):
        raise _err(source, "robot", "a [robot] table (name, gravity, urdf)")
    _keys(source, "robot", r, {"name", "gravity", "urdf"})
    name = r.get("name", Path(source).stem if source else "")
    if not isinstance(name, str):
        raise _err(source, "robot.name", "a string", name)
    g = _vector(source, "robot.gravity", r.get("gravity", [0.0, 0.0, -9.81]), 3)
    joints = raw.get("joints", [])
    if not isinstance(joints, list) or not all(isinstance(j, Mapping) for j in joints):
        raise _err(source, "joints", "an array of tables [[joints]]")
    labels = []
    for i, j in enumerate(joints):
        n = j.get("name")
        if not isinstance(n, str) or not n:
            raise _err(source, f"joints[{i}].name", "a non-empty string", n)
        labels.append(n)
    dup = sorted({n for n in labels if labels.count(n) > 1})
    if dup:
        raise _err(source, f"joints[{dup[0]}]", "distinct joint names", "a duplicate")
    motion = raw.get("motion", {})
    if not isinstance(motion, Mapping):
        raise _err(source, "motion", "a table (moving, locked)")
    _keys(source, "motion", motion, {"moving", "locked"})
    mdh_keys = {"alpha", "d", "theta", "r", "type"}
    has_table = any(mdh_keys & set(j) for j in joints)
    if "urdf" in r:
        if has_table:
            raise _err(source, "robot.urdf", "either a URDF or an MDH table ([[joints]] with "
                       "type/alpha/d/theta/r), not both")
        loc = r["urdf"]
        if not isinstance(loc, str) or not loc:
            raise _err(source, "robot.urdf", "a URDF path or 'example-robot-data:<name>'", loc)
        if loc.startswith(_LOCATOR):
            urdf = example_robot_urdf(loc[len(_LOCATOR):], source)
        else:
            urdf = Path(base_dir or ".") / loc
        return _from_urdf(urdf, name, motion, joints, source, g)
    if not joints:
        raise _err(source, "robot", "either robot.urdf or an MDH table ([[joints]] with "
                   "type/alpha/d/theta/r)")
    return _from_mdh(name, g, joints, motion, source)


# --------------------------------------------------------------------------- builders
_JOINT_KEYS_URDF = {"name", "drive", "limits"}
_JOINT_KEYS_MDH = {"name", "type", "alpha", "d", "theta", "r", "mass", "com", "inertia",
                   "limits", "drive"}


def _from_mdh(name: str, g: np.ndarray, joints: list, motion: Mapping, src: str) -> Robot:
    model = pin.Model()
    model.name = name
    table: list[MDHJoint] = []
    limits: dict[str, RobotLimits] = {}
    drives: dict[str, JointDrive] = {}
    inertial = True
    parent = 0
    for j in joints:
        n = j["name"]
        key = f"joints[{n}]"
        _keys(src, key, j, _JOINT_KEYS_MDH)
        kind = j.get("type", "revolute")
        if kind not in ("revolute", "prismatic"):
            raise _err(src, f"{key}.type", "'revolute' or 'prismatic'", kind)
        row = MDHJoint(n, kind, *(_number(src, f"{key}.{k}", j.get(k, 0.0))
                                  for k in ("alpha", "d", "theta", "r")))
        table.append(row)
        jm = pin.JointModelRZ() if kind == "revolute" else pin.JointModelPZ()
        lim = _limits(src, f"{key}.limits", j.get("limits", {}))
        limits[n] = lim
        jid = model.addJoint(parent, jm, mdh_placement(row.alpha, row.d, row.theta, row.r), n,
                             np.array([lim.tau_max]), np.array([lim.dq_max]),
                             np.array([lim.q_min]), np.array([lim.q_max]))
        if "mass" not in j and any(k in j for k in ("com", "inertia")):
            raise _err(src, f"{key}.mass", "the link mass [kg] with com and inertia")
        inertial = inertial and "mass" in j
        model.appendBodyToJoint(jid, _inertia(src, key, j), pin.SE3.Identity())
        fid = model.addJointFrame(jid)
        model.addBodyFrame(f"{n}_link", jid, pin.SE3.Identity(), fid)
        if "drive" in j:
            drives[n] = _drive(src, f"{key}.drive", j["drive"])
        parent = jid
    model.gravity = pin.Motion(np.concatenate([g, np.zeros(3)]))
    names = tuple(t.name for t in table)
    types = tuple(t.type for t in table)
    mv, lk = _motion(src, names, motion.get("moving"), motion.get("locked"), "motion")
    dr = {n: drives.get(n, JointDrive()) for n in mv}
    return Robot(name, model, names, mv, lk, dr, limits, g, types, src, tuple(table), inertial)


@contextlib.contextmanager
def _captured_stderr_fd(out: list[str]) -> Iterator[None]:
    """Capture what C++ code writes on file descriptor 2 (urdfdom prints its parser errors
    there before pinocchio raises), so that a bad URDF gives our one line only; the text is
    appended to ``out``."""
    try:
        fd = os.dup(2)
    except OSError:  # no fd 2 (embedded interpreter): nothing to capture
        yield
        return
    with tempfile.TemporaryFile(mode="w+b") as tmp:
        os.dup2(tmp.fileno(), 2)
        try:
            yield
        finally:
            os.dup2(fd, 2)
            os.close(fd)
            tmp.seek(0)
            out.append(tmp.read().decode("utf-8", "replace"))


def _from_urdf(urdf: Path, name: str, motion: Mapping, joints: list, src: str,
               g: np.ndarray | None = None) -> Robot:
    said: list[str] = []
    try:
        with _captured_stderr_fd(said):
            model = pin.buildModelFromUrdf(str(urdf))
    except (RuntimeError, ValueError, OSError) as e:
        lines = [ln.strip() for ln in (str(e) + "\n" + "".join(said)).splitlines()
                 if ln.strip()]
        msg = lines[0] if lines else type(e).__name__
        raise RobotError(f"{src}: URDF {str(urdf)!r} does not parse ({msg})") from None
    _check_urdf_inertials(urdf, src)
    names, types = _joint_kinds(model, src)
    if g is None:
        g = np.array(model.gravity.linear, dtype=float)
    model.gravity = pin.Motion(np.concatenate([g, np.zeros(3)]))
    limits = _model_limits(model, names)
    drives: dict[str, JointDrive] = {}
    for j in joints:
        n = j["name"]
        key = f"joints[{n}]"
        if n not in names:
            raise _err(src, f"{key}.name", f"a joint of the URDF {list(names)}", n)
        _keys(src, key, j, _JOINT_KEYS_URDF)
        if "limits" in j:
            old = limits[n]
            new = _limits(src, f"{key}.limits", j["limits"])
            limits[n] = RobotLimits(*(b if math.isfinite(b) else a for a, b in zip(
                (old.q_min, old.q_max, old.dq_max, old.ddq_max, old.dddq_max, old.tau_max),
                (new.q_min, new.q_max, new.dq_max, new.ddq_max, new.dddq_max, new.tau_max),
                strict=True)))
        if "drive" in j:
            drives[n] = _drive(src, f"{key}.drive", j["drive"])
    mv, lk = _motion(src, names, motion.get("moving"), motion.get("locked"), "motion")
    dr = {n: drives.get(n, JointDrive()) for n in mv}
    return Robot(name or model.name, model, names, mv, lk, dr, limits, g, types, src)


def _check_urdf_inertials(urdf: Path, src: str) -> None:
    """Refuse a link whose ``<inertial>`` no body can have (pinocchio builds it anyway and the
    simulator then integrates nonsense): a mass that is negative or not finite, an inertia
    that is not finite or has a negative principal moment."""
    try:
        root = ET.parse(urdf).getroot()
    except (ET.ParseError, OSError):  # pinocchio read it; a form ElementTree cannot is not ours
        return
    where = f"{src}: URDF {urdf.name!r}" if src else f"URDF {str(urdf)!r}"
    for link in root.iter("link"):
        inertial = link.find("inertial")
        if inertial is None:
            continue
        name = link.get("name", "?")
        mass = inertial.find("mass")
        if mass is not None:
            try:
                m = float(mass.get("value", "0"))
            except ValueError:
                m = math.nan
            if not (math.isfinite(m) and m >= 0):
                raise RobotError(f"{where}: link {name!r}: mass {mass.get('value')!r}: "
                                 "expected a number >= 0 [kg]")
        tensor = inertial.find("inertia")
        if tensor is None:
            continue
        keys = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
        try:
            xx, xy, xz, yy, yz, zz = (float(tensor.get(k, "0")) for k in keys)
        except ValueError:
            xx = math.nan
        i_c = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
        if not np.all(np.isfinite(i_c)):
            raise RobotError(f"{where}: link {name!r}: inertia: expected finite numbers "
                             f"[kg m^2], got {dict(tensor.attrib)}")
        low = float(np.linalg.eigvalsh(i_c).min())
        # tolerance: published URDFs round their tensors (tiago: -3.5e-8 on a tiny link)
        if low < -max(1e-6, 1e-3 * float(np.abs(i_c).max())):
            raise RobotError(f"{where}: link {name!r}: inertia has a negative principal moment "
                             f"({low:.6g} kg m^2): expected a positive semi-definite tensor")


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


def _inertia(src: str, key: str, j: Mapping) -> pin.Inertia:
    if "mass" not in j:
        return pin.Inertia.Zero()
    m = _number(src, f"{key}.mass", j["mass"])
    if m < 0:
        raise _err(src, f"{key}.mass", "a mass >= 0 [kg]", m)
    com = _vector(src, f"{key}.com", j.get("com", [0.0, 0.0, 0.0]), 3)
    xx, xy, xz, yy, yz, zz = _vector(src, f"{key}.inertia", j.get("inertia", [0.0] * 6), 6)
    i_o = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
    if m == 0:
        if np.any(com):
            raise _err(src, f"{key}.com", "zero for a massless link", list(com))
        return pin.Inertia(0.0, np.zeros(3), i_o)
    i_c = i_o - m * (com @ com * np.eye(3) - np.outer(com, com))  # Huygens, about the CoM
    return pin.Inertia(m, com, i_c)


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
