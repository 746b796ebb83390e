"""URDF robot files (``*.urdf``: every joint moves, no drive data), and the URDFs packaged by
example-robot-data (``"example-robot-data:ur10"``). A row of
:data:`trajectories.robot.formats.FORMATS`.
"""

from __future__ import annotations

import contextlib
import importlib.metadata as metadata
import math
import os
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Iterator, Mapping
from pathlib import Path

import numpy as np
import pinocchio as pin

from .. import RobotError
from ..description import (
    JointDrive,
    Robot,
    RobotLimits,
    _drive,
    _err,
    _joint_kinds,
    _keys,
    _limits,
    _model_limits,
    _motion,
)

__all__ = ["read", "read_example", "example_robot_urdf", "example_robot_names",
           "EXAMPLE_ROBOTS", "LOCATOR"]

_JOINT_KEYS_URDF = {"name", "drive", "limits"}

#: Packaged robots: ``"example-robot-data:<name>"`` -> URDF inside the example-robot-data share.
EXAMPLE_ROBOTS: dict[str, str] = {
    "ur10": "robots/ur_description/urdf/ur10_robot.urdf",
    "ur5": "robots/ur_description/urdf/ur5_robot.urdf",
    "ur3": "robots/ur_description/urdf/ur3_robot.urdf",
}
LOCATOR = "example-robot-data:"
_DISTRIBUTIONS = ("example-robot-data", "cmeel-example-robot-data")


def read(path: Path) -> Robot:
    """A robot from a URDF file: every joint moves, no drive data."""
    return _from_urdf(path, path.stem, {}, [], str(path))


def read_example(name: str, locator: str) -> Robot:
    """The packaged URDF ``name`` of example-robot-data (``locator``: the text the user gave,
    ``"example-robot-data:<name>"``, named in errors)."""
    return _from_urdf(example_robot_urdf(name, locator), name, {}, [], locator)


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
        except ValueError:  # (every entry, so the message below is reached, no traceback)
            xx = xy = xz = yy = yz = zz = math.nan
        i_c = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
        if not np.all(np.isfinite(i_c)):
            raise RobotError(f"{where}: link {name!r}: inertia: expected finite numbers "
                             f"[kg m^2], got {dict(tensor.attrib)}")
        low = float(np.linalg.eigvalsh(i_c).min())
        # tolerance: published URDFs round their tensors (tiago: -3.5e-8 on a tiny link)
        if low < -max(1e-6, 1e-3 * float(np.abs(i_c).max())):
            raise RobotError(f"{where}: link {name!r}: inertia has a negative principal moment "
                             f"({low:.6g} kg m^2): expected a positive semi-definite tensor")


