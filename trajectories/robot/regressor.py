"""Vectorised Newton-Euler regressor of the standard parameters (paper eq. 9), n samples: the
one n-dof regressor of planning (:mod:`trajectories.robot_model`) and identification
(:mod:`ident.robot`).

(Past 600 lines: one class -- the vectorised Newton-Euler recursion, the column
bookkeeping it needs to stay fast and the payload's columns read from the last link's belong
together.)

For the k moving joints of a :class:`trajectories.robot.Robot`, the joint-side torque is
linear in the standard parameters of every moving link (Khalil's convention, frame j of the
reduced pinocchio model, eq. 9)::

    tau_out + Ia ddq = W(q, dq, ddq) chi_St,    chi_St = [XX_j XY_j XZ_j YY_j YZ_j ZZ_j
                                                          MX_j MY_j MZ_j M_j Ia_j]_j

Links that are locked are rigidly attached to the moving link that carries them (or to the
base): the reduced model (``Robot.reduced()``, ``pin.buildReducedModel``) merges their
inertias, so the standard parameters of moving link j are those of link j plus every locked
link it carries, in frame j; they are named by the 1-based index of joint j in the full chain
(ROBOT_FORMAT: RX130L joint 3 alone gives XX3 ... M3, Ia3).

Algorithm: one forward recursion per sample block for the link velocities, accelerations and
the unit screws of the joint axes expressed in every link frame, then the rows
``tau_j += s_j(i) . A_i(omega_i, domega_i, a_i) chi_i`` (s_j(i): unit motion of joint j at
the origin of frame i; A_i: body regressor of link i about its origin, gravity entered as a
base acceleration -g). Every operation is on contiguous arrays over samples; constant
rotations skip their zero entries. Rotor inertias Ia_j (= N_j^2 J_m) enter as ``Ia_j ddq_j``
on joint j only (the paper's model; rotor gyroscopic terms neglected).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from .. import RobotError
from .description import Robot
from .payload import RobotPayloadData

__all__ = ["RobotRegressor", "LINK_NAMES", "FRICTION_NAMES", "PIN_ORDER", "from_pinocchio_order"]

#: Standard parameters of one link, ROBOT_FORMAT order (then ``Ia`` in the regressor).
LINK_NAMES = ("XX", "XY", "XZ", "YY", "YZ", "ZZ", "MX", "MY", "MZ", "M")
#: Usual friction of one joint (eq. 5-6): FC sign(dq), FV dq, OFF.
FRICTION_NAMES = ("FC", "FV", "OFF")
#: Index in pinocchio's [m, mx, my, mz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz] of each LINK_NAMES entry.
PIN_ORDER = (4, 5, 7, 6, 8, 9, 1, 2, 3, 0)
_P = len(LINK_NAMES) + 1  # columns per moving joint (10 inertial + Ia)
_TOL = 1e-14  # constant entries this close to 0 or +-1 are taken as exact (cos(pi/2) ~ 6e-17)
_CHUNK = 4096  # samples per block: the working set stays in cache


def from_pinocchio_order(phi: np.ndarray) -> np.ndarray:
    """Reorder pinocchio dynamic parameters [m, mx, my, mz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz]
    (last axis, 10 per link) to ROBOT_FORMAT's XX XY XZ YY YZ ZZ MX MY MZ M."""
    a = np.asarray(phi)
    blocks = a.reshape(*a.shape[:-1], -1, 10)
    return blocks[..., list(PIN_ORDER)].reshape(a.shape)


def _clean(x: np.ndarray) -> np.ndarray:
    x = np.array(x, dtype=float)
    x[np.abs(x) < _TOL] = 0.0
    x[np.abs(x - 1.0) < _TOL] = 1.0
    x[np.abs(x + 1.0) < _TOL] = -1.0
    return x


# --------------------------------------------------------------------------- 3-vector algebra
# A vector is a tuple of 3 entries, each an ndarray over samples or None (an exact zero).
def _add(a, b):
    if a is None:
        return b
    if b is None:
        return a
    return a + b


def _sub(a, b):
    if b is None:
        return a
    if a is None:
        return -b
    return a - b


def _mul(a, b):
    if a is None or b is None:
        return None
    return a * b


def _vadd(u, v):
    if u is None:
        return v
    if v is None:
        return u
    return tuple(_add(x, y) for x, y in zip(u, v, strict=True))


def _vscale(u, s):
    """u (constant 3-vector or arrays) times s (array)."""
    return tuple(None if (x is None or (np.isscalar(x) and x == 0)) else x * s for x in u)


def _cross(u, v):
    if u is None or v is None:
        return None
    ux, uy, uz = u
    vx, vy, vz = v
    return (_sub(_mul(uy, vz), _mul(uz, vy)),
            _sub(_mul(uz, vx), _mul(ux, vz)),
            _sub(_mul(ux, vy), _mul(uy, vx)))


def _dot(u, v):
    if u is None or v is None:
        return None
    return _add(_add(_mul(u[0], v[0]), _mul(u[1], v[1])), _mul(u[2], v[2]))


def _const_cross(c, v):
    """c x v with c a constant (3,) vector (zeros skipped)."""
    if v is None:
        return None
    cx, cy, cz = c
    vx, vy, vz = v

    def t(a, x, b, y):  # a x - b y with scalars a, b
        return _sub(_smul(a, x), _smul(b, y))

    return (t(cy, vz, cz, vy), t(cz, vx, cx, vz), t(cx, vy, cy, vx))


def _smul(a: float, x):
    if x is None or a == 0.0:
        return None
    if a == 1.0:
        return x
    if a == -1.0:
        return -x
    return a * x


def _matT(rot: np.ndarray, v):
    """rot^T v for a constant rotation (zero entries skipped)."""
    if v is None:
        return None
    out = []
    for c in range(3):
        acc = None
        for r in range(3):
            acc = _add(acc, _smul(rot[r, c], v[r]))
        out.append(acc)
    return tuple(out)


@dataclass(frozen=True)
class _Joint:
    parent: int  # index of the parent moving joint (-1: base)
    rot: np.ndarray  # (3, 3) placement rotation, parent joint frame -> this joint frame
    pos: np.ndarray  # (3,) placement translation in the parent frame
    axis: np.ndarray  # (3,) unit axis in this joint frame
    revolute: bool
    coord: int  # axis index when the axis is +-e_coord, else -1
    sign: float

    def rot_t(self, c, s, v):
        """Rot(axis, q)^T v, with c = cos q, s = sin q (arrays)."""
        if v is None:
            return None
        if self.coord >= 0:
            s = s if self.sign > 0 else -s
            i, j = (self.coord + 1) % 3, (self.coord + 2) % 3
            out = list(v)
            vi, vj = v[i], v[j]
            out[i] = _add(_mul(c, vi), _mul(s, vj))
            out[j] = _sub(_mul(c, vj), _mul(s, vi))
            return tuple(out)
        a = self.axis  # Rodrigues: c v - s (a x v) + (1 - c)(a . v) a
        axv = _const_cross(a, v)
        adv = None
        for r in range(3):
            adv = _add(adv, _smul(a[r], v[r]))
        out = []
        for r in range(3):
            t = _sub(_mul(c, v[r]), _mul(s, axv[r]))
            out.append(_add(t, _mul(_smul(a[r], adv), 1.0 - c)))
        return tuple(out)


class RobotRegressor:
    """Standard-parameter regressor of the moving joints of a robot (paper eq. 9).

    Parameters
    ----------
    robot : trajectories.robot.Robot
        The robot; its ``reduced()`` model (moving joints, locked ones merged) and gravity.
    flange : str, optional
        Pinocchio frame of the reduced model the payload is fixed to (a frame on the last
        moving link, e.g. the name of a locked joint after it, or ``"tool0"`` of a URDF);
        default: the joint frame of the last moving joint (the simulator's default).
    known_rotor_inertia : bool
        Take the rotor inertias the robot file gives (``rotor_inertia``: Ia_j = N_j^2 J_m) as
        known: their columns are zero (no ``Ia{j}`` among the base parameters) and their
        torque ``Ia_j ddq_j`` is :meth:`known_torque`, which the estimator subtracts like a
        known payload. Default False: every Ia_j is identified (regrouped with ZZ_j where
        the structure demands it).

    Attributes
    ----------
    joints : tuple of str
        Moving joint names (column order of q, dq, ddq, tau).
    numbers : tuple of int
        1-based index of each moving joint in the full chain.
    standard_names : tuple of str
        ``XX{j} XY{j} XZ{j} YY{j} YZ{j} ZZ{j} MX{j} MY{j} MZ{j} M{j} Ia{j}`` per moving joint
        j (chain number), p = 11 k names.
    friction_names : tuple of str
        ``FC{j} FV{j} OFF{j}`` per moving joint.
    model : pinocchio.Model
        The reduced model.
    gravity : ndarray, shape (3,)
        [m/s^2] base frame.
    flange_placement : pinocchio.SE3
        Payload frame in the frame of the last moving joint.
    """

    def __init__(self, robot: Robot, flange: str | None = None, *,
                 known_rotor_inertia: bool = False) -> None:
        self.robot = robot
        self.model = robot.reduced()
        self.joints = tuple(robot.moving)
        self.numbers = tuple(robot.number(n) for n in self.joints)
        self.gravity = np.asarray(robot.gravity, dtype=float).copy()
        self.k = len(self.joints)
        if self.model.nv != self.k or self.model.njoints != self.k + 1:
            raise RobotError(f"{robot.source or robot.name}: expected {self.k} 1-dof "
                             f"moving joints in the reduced model")
        self.standard_names = tuple(f"{p}{j}" for j in self.numbers for p in (*LINK_NAMES,
                                                                             "Ia"))
        self.friction_names = tuple(f"{p}{j}" for j in self.numbers for p in FRICTION_NAMES)
        self.revolute = tuple(t == "revolute" for n, t in zip(robot.joint_names, robot.types,
                                                              strict=True)
                              if n in self.joints)
        self._joints = self._structure()
        self.flange_placement = self._flange(flange)
        z = np.zeros((self.k, 1))
        self._written = {(j, _P * i + c) for j, i, vals in self._pairs(z, z, z)
                         for c, v in enumerate(vals) if v is not None}
        # rotor inertias given by the robot file (N^2 J_m) are known with
        # known_rotor_inertia: their torque Ia ddq goes to known_torque, their column is 0
        self.known_Ia = np.zeros(self.k)
        if known_rotor_inertia:
            for i, name in enumerate(self.joints):
                d = robot.drives.get(name)
                if d is not None and d.Ia is not None:
                    self.known_Ia[i] = float(d.Ia)
        self._written |= {(i, _P * i + 10) for i in range(self.k) if self.known_Ia[i] == 0.0}

    @property
    def p(self) -> int:
        """Number of standard parameters (11 k)."""
        return len(self.standard_names)

    # ------------------------------------------------------------------ public evaluation
    def rigid(self, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray,
              columns: Sequence[int] | None = None) -> np.ndarray:
        """Regressor rows of the rigid body and the rotors (eq. 9): tau_out + Ia ddq = W chi.

        Parameters
        ----------
        q, dq, ddq : ndarray, shape (n, k)
            Joint positions [rad or m], velocities, accelerations of the moving joints.
        columns : sequence of int, optional
            Only these columns (indices into :attr:`standard_names`, in this order), e.g. a
            base-parameter set's ``columns`` (then ``W`` is the base regressor directly).

        Returns
        -------
        W : ndarray, shape (n, k, p) (p = len(columns) when given)
            ``W[t, j, :] @ chi`` is the torque of moving joint j at sample t [N m or N].
            Returned as a transposed view of a (k, p, n) array, contiguous over samples
            (``W[:, j, :]`` is Fortran-ordered, fast for ``W[:, j].T @ W[:, j]``);
            ``W.reshape(-1, p)`` copies. Use :meth:`rigid_kpn` for the (k, p, n) array.
        """
        return self.rigid_kpn(q, dq, ddq, columns=columns).transpose(2, 0, 1)

    def rigid_kpn(self, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray,
                  out: np.ndarray | None = None,
                  columns: Sequence[int] | None = None) -> np.ndarray:
        """:meth:`rigid` as a C-contiguous (k, p, n) array (joint, parameter, sample).

        ``out``: optional C-contiguous float64 (k, p, n) array to fill (overwritten; reusing
        it across blocks of a long log avoids paging in fresh memory every block).
        """
        q, dq, ddq = self._check(q, dq, ddq)
        n = q.shape[0]
        if columns is None:
            cols = np.arange(self.p)
        else:
            cols = np.asarray(columns, dtype=int).reshape(-1)
            if cols.size and (cols.min() < 0 or cols.max() >= self.p):
                raise RobotError(f"columns: expected indices in [0, {self.p}), got "
                                 f"{cols.tolist()}")
        pos = np.full(self.p, -1)
        pos[cols] = np.arange(cols.size)
        shape = (self.k, cols.size, n)
        if out is None:
            out = np.empty(shape)
        elif out.shape != shape or out.dtype != np.float64 or not out.flags.c_contiguous:
            raise RobotError(f"out: expected a C-contiguous float64 array of shape "
                             f"{shape}, got {out.shape} {out.dtype}")
        for j in range(self.k):  # entries that are structurally zero are never written
            zero = [pos[c] for c in cols if (j, int(c)) not in self._written]
            if zero:
                out[j, zero, :] = 0.0
        for s in range(0, n, _CHUNK):
            e = min(s + _CHUNK, n)
            for j, i, vals in self._pairs(q[s:e].T, dq[s:e].T, ddq[s:e].T):
                for c, v in enumerate(vals):
                    pc = pos[_P * i + c]
                    if v is not None and pc >= 0:
                        out[j, pc, s:e] = v
            for i in range(self.k):
                pc = pos[_P * i + 10]
                if pc >= 0 and self.known_Ia[i] == 0.0:
                    out[i, pc, s:e] = ddq[s:e, i]
        return out

    def known_torque(self, ddq: np.ndarray) -> np.ndarray:
        """Torque of the known rotor inertias, ``Ia_j ddq_j`` (n, k) [N m] (zero for the
        joints whose Ia is identified; all zero without ``known_rotor_inertia``)."""
        ddq = np.asarray(ddq, dtype=float)
        if ddq.ndim == 1 and self.k == 1:
            ddq = ddq[:, None]
        return ddq * self.known_Ia

    def friction(self, dq: np.ndarray, deadband: np.ndarray | None = None) -> np.ndarray:
        """Usual friction columns (eq. 5-6) ``FC sign(dq) + FV dq + OFF`` per joint.

        Parameters
        ----------
        dq : ndarray, shape (n, k)
        deadband : ndarray, shape (k,), optional
            sign(dq_j) is 0 where |dq_j| <= deadband_j [rad/s or m/s] (the planner's
            ``MOVING_FRACTION`` of max velocity: samples at rest, 0 in a plan and encoder noise
            in a log, enter the Coulomb column alike); default: plain sign(dq).

        Returns
        -------
        ndarray, shape (n, k, 3 k)
            Columns in the order of :attr:`friction_names`.
        """
        dq = np.asarray(dq, dtype=float)
        if dq.ndim == 1 and self.k == 1:
            dq = dq[:, None]
        if dq.ndim != 2 or dq.shape[1] != self.k:
            raise RobotError(f"dq: expected shape (n, {self.k}), got {dq.shape}")
        sign = np.sign(dq)
        if deadband is not None:
            sign = sign * (np.abs(dq) > np.asarray(deadband, dtype=float).reshape(self.k))
        n = dq.shape[0]
        out = np.zeros((n, self.k, 3 * self.k))
        for i in range(self.k):
            out[:, i, 3 * i] = sign[:, i]
            out[:, i, 3 * i + 1] = dq[:, i]
            out[:, i, 3 * i + 2] = 1.0
        return out

    def rows(self, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray, *, friction: bool = True,
             deadband: np.ndarray | None = None) -> np.ndarray:
        """Regressor rows ``W`` (n k, p [+ 3 k]), sample-major (row ``i k + j``: joint j at
        sample i): :meth:`rigid` then, with ``friction``, :meth:`friction` -- the columns
        ``standard_names + friction_names`` that :func:`trajectories.robot.base.base_parameters`
        (``friction=True``) decomposes; the planner's regressor convention."""
        w = self.rigid(q, dq, ddq)
        if friction:
            w = np.concatenate([w, self.friction(dq, deadband)], axis=-1)
        return w.reshape(-1, w.shape[-1])

    def standard_values(self, Ia: np.ndarray | None = None) -> np.ndarray:  # noqa: N803
        """The standard parameters of the robot's reduced model (the file's inertias merged),
        (p,), with ``Ia`` from the drives (N^2 J_m; 0 where unknown) unless given (k,)."""
        out = np.zeros(self.p)
        for i in range(self.k):
            phi = self.model.inertias[i + 1].toDynamicParameters()
            out[_P * i:_P * i + 10] = from_pinocchio_order(phi)
            if Ia is not None:
                out[_P * i + 10] = float(np.asarray(Ia, dtype=float).reshape(-1)[i])
            else:
                d = self.robot.drives.get(self.joints[i])
                out[_P * i + 10] = (d.Ia if d is not None and d.Ia is not None else 0.0)
        return out

    def payload_parameters(self, payload: RobotPayloadData) -> np.ndarray:
        """Standard parameters (XX..M, (10,)) of a payload in the frame of the last moving
        joint, about its origin (eq. 32-33 generalised: rotation to the link axes, Huygens)."""
        if payload.arm_m is not None:
            raise RobotError(f"payload of {payload.mass} kg: a single-joint lever arm "
                             f"(arm_m = {payload.arm_m} m) has no place on the robot; "
                             "place it with ident.robot.base.lever_arm_payload (one "
                             "moving joint) or give its CoM in the flange frame")
        xx, xy, xz, yy, yz, zz = payload.inertia
        i_c = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
        pl = self.flange_placement
        if payload.mass == 0:
            if np.any(i_c) or np.any(payload.com):
                raise RobotError("payload: a payload of mass 0 must have zero com and "
                                 "inertia")
            return np.zeros(10)
        inert = pl.act(pin.Inertia(payload.mass, np.asarray(payload.com, dtype=float), i_c))
        return from_pinocchio_order(inert.toDynamicParameters())

    @property
    def last_link_columns(self) -> np.ndarray:
        """Indices into :attr:`standard_names` of the last moving link's XX..M (10,): the
        columns a payload fixed to the flange multiplies."""
        return _P * (self.k - 1) + np.arange(10)

    def flange_transform(self) -> np.ndarray:
        """T (10, 10): standard parameters of a body in the last moving link's frame about its
        origin from the same body's in the flange frame about the flange origin,
        ``phi_link = T phi_flange`` (ROBOT_FORMAT order; linear: rotation and parallel axes,
        first moments included). Identity without a flange placement."""
        R = np.asarray(self.flange_placement.rotation, dtype=float)
        t = np.asarray(self.flange_placement.translation, dtype=float)
        kt = pin.skew(t)
        out = np.empty((10, 10))
        for c in range(10):
            e = np.zeros(10)
            e[c] = 1.0
            xx, xy, xz, yy, yz, zz, mx, my, mz, m = e
            i_f = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
            h = R @ np.array([mx, my, mz])  # first moment, link axes, about the flange origin
            kh = pin.skew(h)
            # I_link = R I_F R^T - ([h]x [t]x + [t]x [h]x) - m [t]x^2 ; h_link = h + m t
            i_l = R @ i_f @ R.T - (kh @ kt + kt @ kh) - m * kt @ kt
            h_l = h + m * t
            out[:, c] = [i_l[0, 0], i_l[0, 1], i_l[0, 2], i_l[1, 1], i_l[1, 2], i_l[2, 2],
                         *h_l, m]
        return out

    def flange_parameters(self, payload: RobotPayloadData) -> np.ndarray:
        """Standard parameters (XX..M, (10,)) of a payload in the flange frame about the flange
        origin (first moments m c, inertia by the parallel axes from the one about the CoM):
        the unknowns of ``RobotModel(payload_params=True)``."""
        xx, xy, xz, yy, yz, zz = payload.inertia
        c = np.asarray(payload.com, dtype=float)
        i_o = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]]) - payload.mass * (
            pin.skew(c) @ pin.skew(c))
        return np.array([i_o[0, 0], i_o[0, 1], i_o[0, 2], i_o[1, 1], i_o[1, 2], i_o[2, 2],
                         *(payload.mass * c), payload.mass])

    def payload_columns(self, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray,
                        W: np.ndarray | None = None) -> np.ndarray:
        """Regressor columns (k, 10, n) of a payload's flange-frame parameters
        (:meth:`flange_parameters`): the last link's columns times :meth:`flange_transform`;
        ``payload_torque = payload_columns @ flange_parameters``.

        ``W``: the standard regressor (k, p, n) already evaluated (``rigid_kpn``) to read the
        last link's columns from instead of evaluating them on (q, dq, ddq)."""
        if W is None:
            W = self.rigid_kpn(q, dq, ddq, columns=self.last_link_columns)
        else:
            W = np.asarray(W)[:, self.last_link_columns, :]
        return np.einsum("jan,ac->jcn", W, self.flange_transform())

    def payload_torque(self, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray,
                       payload: RobotPayloadData) -> np.ndarray:
        """Joint torques of a known payload fixed to the flange (eq. 34-35 generalised).

        The payload (mass, CoM in the flange frame, inertia about the CoM in flange axes) is
        moved to the frame of the last moving link (:attr:`flange_placement`) and multiplies
        that link's regressor columns.

        Parameters
        ----------
        q, dq, ddq : ndarray, shape (n, k)
        payload : RobotPayloadData

        Returns
        -------
        ndarray, shape (n, k)
            [N m or N].
        """
        q, dq, ddq = self._check(q, dq, ddq)
        n = q.shape[0]
        phi = self.payload_parameters(payload)
        out = np.zeros((n, self.k))
        if not np.any(phi):
            return out
        last = self.k - 1
        for s in range(0, n, _CHUNK):
            e = min(s + _CHUNK, n)
            for j, _i, cols in self._pairs(q[s:e].T, dq[s:e].T, ddq[s:e].T, links=(last,)):
                acc = out[s:e, j]
                for c, v in enumerate(cols):
                    if v is not None and phi[c] != 0.0:
                        acc += phi[c] * v
        return out

    def chunks(self, n: int, size: int = 65536) -> Iterator[slice]:
        """Slices of ``range(n)`` of at most ``size`` samples (to build W block by block)."""
        for s in range(0, n, size):
            yield slice(s, min(s + size, n))

    # ------------------------------------------------------------------ internals
    def _check(self, q, dq, ddq):
        out = []
        shape = None
        for name, a in (("q", q), ("dq", dq), ("ddq", ddq)):
            a = np.asarray(a, dtype=float)
            if a.ndim == 1 and self.k == 1:
                a = a[:, None]
            if a.ndim != 2 or a.shape[1] != self.k or (shape is not None and a.shape != shape):
                raise RobotError(f"{name}: expected shape (n, {self.k}) for joints "
                                 f"{self.joints}, got {a.shape}")
            shape = a.shape
            out.append(a)
        return out

    def _structure(self) -> tuple[_Joint, ...]:
        m = self.model
        out = []
        for i in range(1, m.njoints):
            jm = m.joints[i]
            jd = jm.createData()
            jm.calc(jd, np.zeros(1))
            s = np.array(jd.S).reshape(6)
            lin, ang = s[:3], s[3:]
            revolute = bool(np.linalg.norm(ang) > 0.5)
            axis = _clean(ang if revolute else lin)
            nz = np.flatnonzero(axis)
            coord, sign = (int(nz[0]), float(np.sign(axis[nz[0]]))) if (
                len(nz) == 1 and abs(abs(axis[nz[0]]) - 1) < _TOL) else (-1, 1.0)
            pl = m.jointPlacements[i]
            out.append(_Joint(int(m.parents[i]) - 1, _clean(pl.rotation),
                              _clean(pl.translation), axis, revolute, coord, sign))
        return tuple(out)

    def _flange(self, flange: str | None) -> pin.SE3:
        if flange is None:
            return pin.SE3.Identity()
        m = self.model
        if not m.existFrame(flange):
            names = [f.name for f in m.frames]
            raise RobotError(f"{self.robot.source or self.robot.name}: flange "
                             f"{flange!r}: expected a frame of the reduced model {names}")
        f = m.frames[m.getFrameId(flange)]
        if f.parentJoint != m.njoints - 1:
            raise RobotError(f"{self.robot.source or self.robot.name}: flange "
                             f"{flange!r}: expected a frame on the last moving link "
                             f"({self.joints[-1]}), it is on joint {m.names[f.parentJoint]}")
        return pin.SE3(f.placement)

    def _pairs(self, q, dq, ddq, links=None):
        """Yield (j, i, cols): the 10 columns (ROBOT_FORMAT order, arrays or None) of the
        parameters of link i in the torque of joint j, for i in ``links`` (default all) and
        every j supporting i. q, dq, ddq are (k, m) blocks."""
        js = self._joints
        g = self.gravity
        base_acc = tuple(None if x == 0 else np.full(q.shape[1], -x) for x in g)
        kin = []  # per link: omega, domega, acc (frame i)
        screws = []  # per link: {j: (v, u)} unit screws of supporting joints at origin i
        wanted = set(range(self.k)) if links is None else set(links)
        last = max(wanted)
        for i in range(last + 1):
            J = js[i]
            if J.parent < 0:
                w_p, dw_p, a_p, sc_p = None, None, base_acc, {}
            else:
                w_p, dw_p, a_p = kin[J.parent]
                sc_p = screws[J.parent]
            # accelerations of the origin of frame i in the parent frame
            a_o = _vadd(a_p, _vadd(_const_cross_v(dw_p, J.pos),
                                   _cross(w_p, _const_cross_v(w_p, J.pos))))
            w_pre = _matT(J.rot, w_p)
            dw_pre = _matT(J.rot, dw_p)
            a_pre = _matT(J.rot, a_o)
            qi, dqi, ddqi = q[i], dq[i], ddq[i]
            if J.revolute:
                c, s = np.cos(qi), np.sin(qi)
                wp = J.rot_t(c, s, w_pre)
                w = _vadd(wp, _vscale(J.axis, dqi))
                dw = _vadd(_vadd(J.rot_t(c, s, dw_pre), _vscale(J.axis, ddqi)),
                           _cross(wp, _vscale(J.axis, dqi)))
                a = J.rot_t(c, s, a_pre)
                sc = {}
                for jj, (v_p, u_p) in sc_p.items():
                    v_o = _vadd(v_p, _neg_const_cross(J.pos, u_p))  # screw moved to O_i
                    sc[jj] = (J.rot_t(c, s, _matT(J.rot, v_o)),
                              J.rot_t(c, s, _matT(J.rot, u_p)))
                sc[i] = (None, tuple(None if x == 0 else np.full(qi.shape, x)
                                     for x in J.axis))
            else:
                w, dw = w_pre, dw_pre
                d = _vscale(J.axis, qi)  # offset along the axis
                dv = _vscale(J.axis, dqi)
                a = _vadd(a_pre, _vadd(_vadd(_cross(dw, d), _cross(w, _cross(w, d))),
                                       _vadd(_vscale2(_cross(w, dv), 2.0),
                                             _vscale(J.axis, ddqi))))
                sc = {}
                for jj, (v_p, u_p) in sc_p.items():
                    v_o = _vadd(v_p, _neg_const_cross(J.pos, u_p))
                    u = _matT(J.rot, u_p)
                    v = _vadd(_matT(J.rot, v_o), _cross(u, d))
                    sc[jj] = (v, u)
                sc[i] = (tuple(None if x == 0 else np.full(qi.shape, x) for x in J.axis),
                         None)
            kin.append((w, dw, a))
            screws.append(sc)
            if i in wanted:
                mat = _first_moment_matrix(w, dw) if any(
                    v is not None for v, _u in sc.values()) else None
                for jj, (v, u) in sc.items():
                    yield jj, i, _columns(v, u, w, dw, a, mat)


def _const_cross_v(v, c: np.ndarray):
    """v x c with c a constant (3,) vector."""
    if v is None or not np.any(c):
        return None
    neg = _const_cross(c, v)
    return tuple(None if x is None else -x for x in neg)


def _neg_const_cross(c: np.ndarray, u):
    """u x c = -(c x u): the velocity at the offset c of a unit rotation u."""
    return _const_cross_v(u, c)


def _vscale2(u, s: float):
    if u is None:
        return None
    return tuple(None if x is None else s * x for x in u)


def _first_moment_matrix(w, dw):
    """Rows of T = K(w)^2 - K(dw) = w w^T - |w|^2 I - K(dw), so that T v = v x dw + w x (w x v)
    (the first-moment coefficients of a force screw v); entries None when exactly zero."""
    w = (None, None, None) if w is None else w
    dw = (None, None, None) if dw is None else dw
    w2 = _add(_add(_mul(w[0], w[0]), _mul(w[1], w[1])), _mul(w[2], w[2]))
    rows = []
    for r in range(3):
        row = []
        for c in range(3):
            e = _mul(w[r], w[c])
            if r == c:
                e = _sub(e, w2)
            else:  # -K(dw)[r, c]: K(x) = [[0, -z, y], [z, 0, -x], [-y, x, 0]]
                k = 3 - r - c
                sign = 1.0 if (r, c) in ((0, 1), (1, 2), (2, 0)) else -1.0
                e = _add(e, _smul(sign, dw[k]))
            row.append(e)
        rows.append(row)
    return rows


def _columns(v, u, w, dw, a, mat):
    """The 10 regressor columns of one link's parameters for one joint's unit screw (v, u)
    at the link origin: v . f + u . n with f = M a + dw x c + w x (w x c) and
    n = I dw + w x (I w) + c x a (about the origin, frame of the link)."""
    cols = [None] * 10
    if u is not None:
        u2 = _cross(u, w)  # u . (w x I w) = (u x w) . I w
        ux, uy, uz = u
        dwx, dwy, dwz = (None, None, None) if dw is None else dw
        wx, wy, wz = (None, None, None) if w is None else w
        u2x, u2y, u2z = (None, None, None) if u2 is None else u2
        cols[0] = _add(_mul(ux, dwx), _mul(u2x, wx))
        cols[1] = _add(_add(_mul(ux, dwy), _mul(uy, dwx)), _add(_mul(u2x, wy), _mul(u2y, wx)))
        cols[2] = _add(_add(_mul(ux, dwz), _mul(uz, dwx)), _add(_mul(u2x, wz), _mul(u2z, wx)))
        cols[3] = _add(_mul(uy, dwy), _mul(u2y, wy))
        cols[4] = _add(_add(_mul(uy, dwz), _mul(uz, dwy)), _add(_mul(u2y, wz), _mul(u2z, wy)))
        cols[5] = _add(_mul(uz, dwz), _mul(u2z, wz))
    # first moments: a x u + T v  (T v = v x dw + w x (w x v))
    c = _cross(a, u)
    if v is not None:
        tv = tuple(_add(_add(_mul(row[0], v[0]), _mul(row[1], v[1])), _mul(row[2], v[2]))
                   for row in mat)
        c = _vadd(c, tv)
        cols[9] = _dot(v, a)
    if c is not None:
        cols[6], cols[7], cols[8] = c
    return cols
