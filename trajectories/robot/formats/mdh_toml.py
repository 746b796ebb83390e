"""MDH TOML robot files (``*.toml``): a ``[robot]`` table and EITHER ``urdf = "..."`` (a path
relative to the TOML file, or ``"example-robot-data:ur10"``) OR a modified Denavit-Hartenberg
table (Khalil-Kleinfinger) in ``[[joints]]``, per-joint drive data and limits, and an optional
``[motion]`` table (moving and locked joints). A row of
:data:`trajectories.robot.formats.FORMATS` (docs/robot-format.md).
"""

from __future__ import annotations

import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from .. import RobotError
from ..description import (
    JointDrive,
    MDHJoint,
    Robot,
    RobotLimits,
    _drive,
    _err,
    _keys,
    _limits,
    _motion,
    _number,
    _vector,
    mdh_placement,
)
from ..file_kinds import mixup_hint
from .urdf import LOCATOR, _from_urdf, example_robot_urdf

__all__ = ["read", "robot_from_dict"]

_JOINT_KEYS_MDH = {"name", "type", "alpha", "d", "theta", "r", "mass", "com", "inertia",
                   "limits", "drive"}


def read(path: Path) -> Robot:
    """A robot from a TOML robot file (see the module docstring)."""
    src = str(path)
    try:
        raw = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as e:
        raise RobotError(f"{src}: cannot read the robot file ({e.strerror or e})") from None
    except UnicodeDecodeError:
        raise RobotError(f"{src}: expected a UTF-8 TOML robot file") from None
    except tomllib.TOMLDecodeError as e:
        raise RobotError(f"{src}: not valid TOML ({e})") from None
    return robot_from_dict(raw, src, base_dir=path.parent)


def robot_from_dict(raw: Mapping[str, Any], source: str = "",
                    base_dir: str | Path | None = None) -> Robot:
    """Validate a parsed robot TOML mapping (see :func:`load_robot`); a relative ``urdf`` is
    resolved against ``base_dir`` (default: the current directory)."""
    try:
        _keys(source, "", raw, {"robot", "joints", "motion"})
    except RobotError as exc:  # a campaign or plant file given as the robot file: say so
        hint = mixup_hint(raw, "robot")
        raise RobotError(f"{exc}; {hint}" if hint else str(exc)) from None
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
        if loc.startswith(LOCATOR):
            urdf = example_robot_urdf(loc[len(LOCATOR):], source)
        else:
            urdf = Path(base_dir or ".") / loc
        return _from_urdf(urdf, name, motion, joints, source, g)
    if not joints:
        raise _err(source, "robot", "either robot.urdf or an MDH table ([[joints]] with "
                   "type/alpha/d/theta/r)")
    return _from_mdh(name, g, joints, motion, source)


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
        com = np.zeros(3)
        i_c = i_o
    else:
        i_c = i_o - m * (com @ com * np.eye(3) - np.outer(com, com))  # Huygens, about the CoM
    try:  # pinocchio refuses a non-positive one with a RuntimeError (was a traceback)
        return pin.Inertia(m, com, i_c)
    except RuntimeError as exc:
        raise _err(src, f"{key}.inertia", "XX XY XZ YY YZ ZZ about the link's origin [kg m^2] "
                   f"of a real body: about its CoM positive ({exc})",
                   [float(v) for v in (xx, xy, xz, yy, yz, zz)]) from None


