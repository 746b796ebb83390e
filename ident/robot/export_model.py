"""Export an identified robot model: a URDF with the identified inertials and a friction file.

Format and reference function: docs/model-export.md. In short, ``export_model`` writes

* ``<name>.urdf``: the moving joints of the robot's reduced model (locked joints merged into the
  placements, as the regressor sees them), each child link carrying the consistent standard
  parameters of :func:`~ident.robot.consistent_fit.fit_consistent` as a URDF ``<inertial>``
  (mass, centre of mass, inertia about the CoM in the link axes); the other frames of the model
  (``tool0``, ``ee_link`` ...) as massless links on fixed joints. URDF has no gravity and no
  rotor inertia: both are in the friction file.
* ``friction.json`` (``"format": "jointid-friction/2"``): the friction model (``usual`` or
  ``paper``), gravity, and per joint its rotor inertia Ia (identified or known), q_s and the
  coefficients (usual: FC, FV, OFF; paper: a_m, b_m, a_g, b_g, c_m, d_m, c_g, d_g, FV, OFF).

:func:`exported_torque` is the reference evaluation: with ``tau_rigid`` the inverse dynamics
of the URDF (pinocchio RNEA, payload attached to the last link), it returns the joint torques
jointid predicts (``RobotModel.predict`` of the consistent model).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any
from xml.sax.saxutils import quoteattr

import numpy as np
import pinocchio as pin

from trajectories.friction import quadrant_weights, stribeck_exp

from . import RobotIdentError
from .confounded import physical_friction
from .paper import PAPER_BLOCK, USUAL_BLOCK

__all__ = ["FRICTION_FORMAT", "urdf_text", "friction_record", "exported_torque",
           "export_model", "inertial_from_standard"]

FRICTION_FORMAT = "jointid-friction/2"  # /1 spelled q_s "qs" (still read)
_KINDS = ("XX", "XY", "XZ", "YY", "YZ", "ZZ", "MX", "MY", "MZ", "M")
_AXES = {"X": (1.0, 0.0, 0.0), "Y": (0.0, 1.0, 0.0), "Z": (0.0, 0.0, 1.0)}


def inertial_from_standard(p: Sequence[float]) -> tuple[float, np.ndarray, np.ndarray]:
    """(mass [kg], CoM (3,) [m], inertia about the CoM (3, 3) [kg m^2]) of a link from its
    standard parameters XX XY XZ YY YZ ZZ MX MY MZ M (about the joint-frame origin)."""
    xx, xy, xz, yy, yz, zz, mx, my, mz, m = (float(v) for v in p[:10])
    if not m > 0:
        raise RobotIdentError(f"export: link mass {m} [kg]: expected > 0 (a consistent "
                              "estimate, ident.robot.consistent_fit)")
    c = np.array([mx, my, mz]) / m
    i_o = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
    i_c = i_o - m * (float(c @ c) * np.eye(3) - np.outer(c, c))
    return m, c, i_c


def _f(x: float) -> str:
    return repr(float(x))


def _origin(se3: pin.SE3) -> str:
    xyz = " ".join(_f(v) for v in se3.translation)
    rpy = " ".join(_f(v) for v in pin.rpy.matrixToRpy(se3.rotation))
    return f'<origin xyz="{xyz}" rpy="{rpy}"/>'


def _joint_kind(jm: Any) -> tuple[str, tuple[float, float, float]]:
    """URDF type and axis of a pinocchio 1-dof joint model."""
    name = jm.shortname()
    for prefix, kind in (("JointModelRUB", "continuous"), ("JointModelR", "revolute"),
                         ("JointModelP", "prismatic")):
        if name.startswith(prefix):
            tail = name[len(prefix):]
            if tail in _AXES:
                return kind, _AXES[tail]
            if "Unaligned" in name or "Unbounded" in name:
                axis = np.asarray(jm.axis, dtype=float)
                return kind, tuple(float(a) for a in axis)
    raise RobotIdentError(f"export: joint model {name}: expected a revolute or prismatic "
                          "1-dof joint")


def urdf_text(model: pin.Model, standard: Mapping[str, float], numbers: Sequence[int],
              name: str = "robot") -> str:
    """URDF of a reduced pinocchio ``model`` (k 1-dof joints) whose moving links carry the
    standard parameters ``standard`` (``XX{n}`` ... ``M{n}`` for each chain number n of
    ``numbers``); other frames become massless links on fixed joints."""
    k = model.njoints - 1
    if len(numbers) != k:
        raise RobotIdentError(f"export: {len(numbers)} joint numbers for {k} moving joints")
    bodies: dict[int, str] = {}
    extra: list[tuple[int, str, pin.SE3]] = []
    used: set[str] = set()
    for f in model.frames:
        if f.type != pin.FrameType.BODY or f.name in used:
            continue
        if f.parentJoint not in bodies and f.placement.isIdentity():
            bodies[f.parentJoint] = f.name
        else:
            extra.append((f.parentJoint, f.name, pin.SE3(f.placement)))
        used.add(f.name)
    for i in range(k + 1):
        if i not in bodies:
            nm = "base" if i == 0 else f"link_{model.names[i]}"
            while nm in used:
                nm += "_"
            bodies[i] = nm
            used.add(nm)
    lines = ['<?xml version="1.0"?>',
             "<!-- written by jointid export-model: identified inertials (physically "
             "consistent); gravity and rotor inertias are in friction.json -->",
             f"<robot name={quoteattr(name)}>",
             f"  <link name={quoteattr(bodies[0])}/>"]
    for i in range(1, k + 1):
        n = numbers[i - 1]
        try:
            p = [float(standard[f"{kind}{n}"]) for kind in _KINDS]
        except KeyError as e:
            raise RobotIdentError(f"export: standard parameter {e.args[0]} missing") from None
        m, c, ic = inertial_from_standard(p)
        lines += [f"  <link name={quoteattr(bodies[i])}>",
                  "    <inertial>",
                  f'      <origin xyz="{" ".join(_f(v) for v in c)}" rpy="0 0 0"/>',
                  f'      <mass value="{_f(m)}"/>',
                  f'      <inertia ixx="{_f(ic[0, 0])}" ixy="{_f(ic[0, 1])}" '
                  f'ixz="{_f(ic[0, 2])}" iyy="{_f(ic[1, 1])}" iyz="{_f(ic[1, 2])}" '
                  f'izz="{_f(ic[2, 2])}"/>',
                  "    </inertial>",
                  "  </link>"]
        jm = model.joints[i]
        kind, axis = _joint_kind(jm)
        lo = float(model.lowerPositionLimit[jm.idx_q])
        hi = float(model.upperPositionLimit[jm.idx_q])
        eff = float(model.effortLimit[jm.idx_v])
        vel = float(model.velocityLimit[jm.idx_v])
        eff = eff if math.isfinite(eff) else 1e9
        vel = vel if math.isfinite(vel) else 1e9
        if kind == "revolute" and not (math.isfinite(lo) and math.isfinite(hi)):
            kind = "continuous"
        # URDF has no infinity (urdfdom refuses "inf" and pinocchio cannot load the file):
        # an unbounded side of a prismatic joint is written +-1e9 [m], like effort and
        # velocity (a revolute joint without both bounds is "continuous", above)
        lo = lo if math.isfinite(lo) else -1e9
        hi = hi if math.isfinite(hi) else 1e9
        lim = (f'    <limit effort="{_f(eff)}" velocity="{_f(vel)}"'
               + (f' lower="{_f(lo)}" upper="{_f(hi)}"/>' if kind != "continuous" else "/>"))
        lines += [f"  <joint name={quoteattr(model.names[i])} type=\"{kind}\">",
                  f"    <parent link={quoteattr(bodies[int(model.parents[i])])}/>",
                  f"    <child link={quoteattr(bodies[i])}/>",
                  f"    {_origin(model.jointPlacements[i])}",
                  f'    <axis xyz="{" ".join(_f(a) for a in axis)}"/>',
                  lim,
                  "  </joint>"]
    for parent, fname, placement in extra:
        lines += [f"  <link name={quoteattr(fname)}/>",
                  f"  <joint name={quoteattr(fname + '_fixed_joint')} type=\"fixed\">",
                  f"    <parent link={quoteattr(bodies[parent])}/>",
                  f"    <child link={quoteattr(fname)}/>",
                  f"    {_origin(placement)}",
                  "  </joint>"]
    lines.append("</robot>")
    return "\n".join(lines) + "\n"


def friction_record(model_name: str, joints: Sequence[str], numbers: Sequence[int],
                    parameters: Mapping[str, float], standard: Mapping[str, float],
                    q_s: Sequence[float], gravity: Sequence[float],
                    known_rotor_inertia: Mapping[str, float] | None = None,
                    fixed: Mapping[str, float] | None = None,
                    regrouped: Mapping[str, Mapping[str, float]] | None = None
                    ) -> dict[str, Any]:
    """The friction file's content (docs/model-export.md): per joint its rotor inertia
    (``Ia{n}`` of ``standard``, or the known value), q_s and the friction coefficients of
    ``parameters`` (the consistent estimate's, ROBOT_FORMAT names), less the weights
    ``regrouped`` says a fitted one carries (``{"OFF2": {"M2": 9.81}}``: the URDF's
    inverse dynamics has that weight already; :func:`ident.robot.confounded.physical_friction`
    with the ``standard`` values)."""
    if model_name not in ("usual", "paper"):
        raise RobotIdentError(f"export: model {model_name!r}: expected 'usual' or 'paper'")
    block = USUAL_BLOCK if model_name == "usual" else PAPER_BLOCK
    known = dict(known_rotor_inertia or {})
    values = physical_friction({**(fixed or {}), **parameters}, dict(standard), regrouped)
    out_joints = []
    for j, n, q in zip(joints, numbers, q_s, strict=True):
        coef = {}
        for pfx in block:
            key = f"{pfx}{n}"
            if key not in values:
                raise RobotIdentError(f"export: friction parameter {key} missing")
            coef[pfx] = float(values[key])
        kn = float(known.get(j, 0.0))
        ia = kn if kn > 0 else float(standard.get(f"Ia{n}", 0.0))
        out_joints.append({"name": j, "number": int(n), "rotor_inertia": ia,
                           "rotor_inertia_known": kn > 0, "q_s": float(q), **coef})
    rec: dict[str, Any] = {"format": FRICTION_FORMAT, "model": model_name,
                           "gravity": [float(g) for g in gravity], "joints": out_joints}
    if "Ma_ratio" in values:
        rec["payload_ratio"] = float(values["Ma_ratio"])
    if fixed:
        rec["fixed"] = {k: float(v) for k, v in fixed.items()}
    return rec


def exported_torque(friction: Mapping[str, Any], tau_rigid: np.ndarray, dq: np.ndarray,
                    ddq: np.ndarray) -> np.ndarray:
    """Reference evaluation of an exported model (docs/model-export.md).

    Parameters
    ----------
    friction : mapping
        The friction file (``json.load``).
    tau_rigid : ndarray (n, k)
        Inverse dynamics of the exported URDF (pinocchio ``rnea`` with the friction file's
        gravity; a payload attached to the last link, its mass scaled by ``payload_ratio``
        when given) [N m or N].
    dq, ddq : ndarray (n, k)
        Joint velocities [rad/s] and accelerations [rad/s^2], the URDF's joint order.

    Returns
    -------
    ndarray (n, k)
        Joint torques [N m or N]: usual ``tau_out + FC sign(dq) + FV dq + OFF``; paper eq. 30
        with P+ = (1 + sign(tau_out dq)) / 2, P- = 1 - P+
        (:func:`trajectories.friction.quadrant_weights`), E = exp(-|dq| / q_s); tau_out =
        tau_rigid + Ia ddq.
    """
    tau_rigid, dq, ddq = (np.atleast_2d(np.asarray(a, dtype=float)) for a in
                          (tau_rigid, dq, ddq))
    out = np.empty_like(tau_rigid)
    paper = friction["model"] == "paper"
    for j, jr in enumerate(friction["joints"]):
        v = dq[:, j]
        t_out = tau_rigid[:, j] + jr["rotor_inertia"] * ddq[:, j]
        s = np.sign(v)
        if not paper:
            out[:, j] = t_out + jr["FC"] * s + jr["FV"] * v + jr["OFF"]
            continue
        e = stribeck_exp(v, jr["q_s"] if "q_s" in jr else jr["qs"])  # "qs": jointid-friction/1
        pp, pm = quadrant_weights(t_out * v)
        motor = (jr["a_m"] + jr["b_m"] * e) * t_out + (jr["c_m"] + jr["d_m"] * e) * s
        gen = (jr["a_g"] - jr["b_g"] * e) * t_out + (jr["c_g"] + jr["d_g"] * e) * s
        out[:, j] = pp * motor + pm * gen + jr["FV"] * v + jr["OFF"]
    return out


def export_model(robot: Any, consistent: Mapping[str, Any], outdir: str | Path,
                 fixed: Mapping[str, float] | None = None) -> list[Path]:
    """Write ``<robot name>.urdf`` and ``friction.json`` into ``outdir``.

    Parameters
    ----------
    robot : trajectories.robot.Robot
        The identified robot (its reduced model gives the kinematics).
    consistent : mapping
        A consistent estimate's record (:func:`~ident.robot.consistent_fit.consistent_record`:
        ``model``, ``parameters``, ``standard``, ``q_s``, ``known_rotor_inertia``).
    fixed : mapping, optional
        Parameters the fit held fixed (``RobotModel.fixed_``).

    Returns
    -------
    list of Path
        The files written (both built before either is written).
    """
    model = robot.reduced()
    numbers = robot.numbers
    joints = tuple(robot.moving)
    name = robot.name or "robot"
    text = urdf_text(model, consistent["standard"], numbers, name)
    fr = friction_record(consistent["model"], joints, numbers, consistent["parameters"],
                         consistent["standard"], consistent["q_s"], robot.gravity,
                         consistent.get("known_rotor_inertia"), fixed,
                         consistent.get("friction_regrouped"))
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    stem = "".join(c if c.isalnum() or c in "-_." else "_" for c in name)
    urdf, fric = out / f"{stem}.urdf", out / "friction.json"
    urdf.write_text(text)
    fric.write_text(json.dumps(fr, indent=2) + "\n")
    return [urdf, fric]
