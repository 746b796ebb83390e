"""Base parameters by QR decomposition of the regressor at random states (paper eq. 10,
refs. [12]-[13]: Gautier 1990-1991, numerical calculation of the base inertial parameters).

The standard parameters chi_St (eq. 9) are not all identifiable: some have no effect on the
joint torques (zero columns of W) and others act only in fixed linear combinations. The
regressor W_St is sampled at random positions, velocities and accelerations within the joint
limits; its columns (unit-norm scaled) are decomposed ``W_St = Q R`` in the order of the
standard parameters (link 1 to link n, XX XY XZ YY YZ ZZ MX MY MZ M Ia within a link, then the
friction columns if asked). A column whose ``|R_ii|`` is below ``rtol * max |R_jj|`` is a
linear combination of the columns before it; the others are kept. With W1 the kept and W2
the dependent columns, ``W2 = W1 beta2`` (least squares, exact up to rounding), so

    tau = W_St chi_St = W1 (chi_1 + beta2 chi_2) = W_b chi_b       (eq. 10)

and ``chi_b = beta chi_St`` with ``beta = [I beta2]`` (columns back in the standard order).
Processing the standard parameters from the base to the tip keeps, like Khalil's symbolic
rules, the parameters of the lower link: e.g. ``ZZ2R = ZZ2 + YY3 + 0.36*M3 + ...``.

Rank tolerance: ``rtol = 1e-8`` on unit-norm columns, many orders of magnitude above the
rounding of a structural dependence (~1e-15) and below any real one at random states; the
result is deterministic for a given seed (the seed only chooses the states).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from ..signals import G
from . import RobotIdentError
from .regressor import RobotRegressor
from .signals import RobotPayloadData

__all__ = ["BaseParameters", "base_parameters", "qr_rule", "SingleJointMap", "single_joint_map",
           "lever_arm_payload", "placed_payload", "PayloadBase", "payload_base",
           "PAYLOAD_NAMES",
           "DEFAULT_RTOL"]

#: Relative rank tolerance on |R_ii| of the unit-norm columns.
DEFAULT_RTOL = 1e-8
_ZERO_COEF = 1e-9  # regrouping coefficients below this (relative) are rounding: set to 0


@dataclass(frozen=True, eq=False)
class BaseParameters:
    """The base parameters of a regressor (eq. 10).

    Attributes
    ----------
    standard_names : tuple of str
        The standard parameters decomposed (the regressor's ``standard_names``, plus its
        ``friction_names`` when asked), p names.
    names : tuple of str
        Base parameter names, p_b: the kept standard name, with suffix ``R`` when other
        parameters are regrouped into it (``ZZ2R``).
    columns : ndarray of int, shape (p_b,)
        Index into ``standard_names`` of each kept column (W_b = W[..., columns]).
    beta : ndarray, shape (p_b, p)
        Regrouping matrix: chi_b = beta @ chi_St.
    expressions : tuple of str
        One per base parameter, e.g. ``"ZZ2R = ZZ2 + YY3 + 0.36*M3"``.
    unidentifiable : tuple of str
        Standard parameters with no effect at all (zero columns).
    rtol : float
        Rank tolerance used.
    seed, n_samples : int
        The random states used.
    """

    standard_names: tuple[str, ...]
    names: tuple[str, ...]
    columns: np.ndarray
    beta: np.ndarray
    expressions: tuple[str, ...]
    unidentifiable: tuple[str, ...]
    rtol: float
    seed: int
    n_samples: int

    @property
    def p_b(self) -> int:
        """Number of base parameters."""
        return len(self.names)

    def reduce(self, W: np.ndarray) -> np.ndarray:  # noqa: N803
        """Base regressor W_b = the kept columns of W (last axis: ``standard_names``)."""
        W = np.asarray(W)
        if W.shape[-1] != len(self.standard_names):
            raise RobotIdentError(f"reduce: expected {len(self.standard_names)} columns "
                                  f"(standard parameters), got {W.shape[-1]}")
        return W[..., self.columns]

    def values(self, standard: Mapping[str, float] | np.ndarray) -> np.ndarray:
        """Base parameter values chi_b = beta chi_St from standard values (an array in
        ``standard_names`` order, or a mapping name -> value with every needed name)."""
        if isinstance(standard, Mapping):
            need = [n for n, c in zip(self.standard_names, np.any(self.beta != 0, axis=0),
                                      strict=True) if c]
            missing = [n for n in need if n not in standard]
            if missing:
                raise RobotIdentError(f"base values: missing standard parameters {missing}")
            chi = np.array([float(standard.get(n, 0.0)) for n in self.standard_names])
        else:
            chi = np.asarray(standard, dtype=float).reshape(-1)
            if chi.shape != (len(self.standard_names),):
                raise RobotIdentError(f"base values: expected {len(self.standard_names)} "
                                      f"standard values, got {chi.shape}")
        return self.beta @ chi


def _states(reg: RobotRegressor, limits: object, n: int, seed: int
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    k = reg.k
    lo, hi, vmax, amax = np.empty(k), np.empty(k), np.empty(k), np.empty(k)
    for i, name in enumerate(reg.joints):
        lim = None
        if limits is None:
            lim = reg.robot.limits.get(name)
        elif isinstance(limits, Mapping):
            lim = limits.get(name)
        if lim is None and limits is not None and not isinstance(limits, Mapping):
            arr = np.asarray(limits, dtype=float)
            if arr.shape != (k, 2):
                raise RobotIdentError(f"limits: expected a mapping joint -> RobotLimits or a "
                                      f"({k}, 2) array of position ranges, got {arr.shape}")
            q0, q1, v, a = arr[i, 0], arr[i, 1], math.inf, math.inf
        elif lim is None:
            q0, q1, v, a = -math.inf, math.inf, math.inf, math.inf
        else:
            q0, q1, v, a = lim.q_min, lim.q_max, lim.dq_max, lim.ddq_max
        span = math.pi if reg.revolute[i] else 1.0
        lo[i] = q0 if math.isfinite(q0) else -span
        hi[i] = q1 if math.isfinite(q1) else span
        vmax[i] = v if math.isfinite(v) else 2.0
        amax[i] = a if math.isfinite(a) else 5.0
    q = lo + (hi - lo) * rng.random((n, k))
    dq = vmax * rng.uniform(-1.0, 1.0, (n, k))
    ddq = amax * rng.uniform(-1.0, 1.0, (n, k))
    return q, dq, ddq


def _format(coef: float) -> str:
    return f"{coef:.6g}"


def qr_rule(W: np.ndarray, names: tuple[str, ...], rtol: float = DEFAULT_RTOL,  # noqa: N803
            ) -> tuple[np.ndarray, np.ndarray, list[str], list[str], np.ndarray]:
    """The base-parameter rule (module doc) on the rows ``W`` (r, p) of the columns ``names``.

    Returns
    -------
    kept : ndarray of int
        Indices of the kept columns.
    beta : ndarray (len(kept), p)
        Regrouping matrix (chi_b = beta chi).
    base_names, expressions : list of str
        ``names[kept]`` with suffix ``R`` where others are regrouped, and ``"XXR = XX - YY"``.
    zero : ndarray of bool (p,)
        Columns with no effect at all.
    """
    p = len(names)
    norms = np.linalg.norm(W, axis=0)
    scale = norms.max() if norms.size else 1.0
    zero = norms <= 1e-12 * scale
    Ws = W[:, ~zero] / norms[~zero]
    idx = np.flatnonzero(~zero)
    r = scipy.linalg.qr(Ws, mode="r")[0]
    diag = np.abs(np.diag(r))
    keep_mask = diag > rtol * diag.max()
    kept = idx[keep_mask]
    dep = idx[~keep_mask]
    beta = np.zeros((kept.size, p))
    beta[np.arange(kept.size), kept] = 1.0
    if dep.size:
        b2 = np.linalg.lstsq(W[:, kept], W[:, dep], rcond=None)[0]  # W2 = W1 b2
        b2[np.abs(b2) < _ZERO_COEF * max(1.0, float(np.abs(b2).max()))] = 0.0
        beta[:, dep] = b2
    base_names, exprs = [], []
    for row, c in enumerate(kept):
        others = [(names[j], beta[row, j]) for j in range(p) if j != c and beta[row, j] != 0]
        nm = names[c] + ("R" if others else "")
        base_names.append(nm)
        terms = [names[c]]
        for on, coef in others:
            if abs(coef - 1.0) < 1e-9:
                terms.append(f"+ {on}")
            elif abs(coef + 1.0) < 1e-9:
                terms.append(f"- {on}")
            elif coef < 0:
                terms.append(f"- {_format(-coef)}*{on}")
            else:
                terms.append(f"+ {_format(coef)}*{on}")
        exprs.append(f"{nm} = " + " ".join(terms))
    return kept, beta, base_names, exprs, zero


def base_parameters(
    regressor: RobotRegressor,
    limits: object = None,
    seed: int = 0,
    *,
    friction: bool = False,
    n_samples: int | None = None,
    rtol: float = DEFAULT_RTOL,
) -> BaseParameters:
    """Base parameters of a robot regressor, numerically (QR of W at random states).

    Parameters
    ----------
    regressor : RobotRegressor
    limits : mapping or array, optional
        Joint name -> ``trajectories.robot.RobotLimits``, or a (k, 2) array of position
        ranges; default the robot's limits (infinite ranges: [-pi, pi] rad or [-1, 1] m;
        velocities and accelerations: dq_max, ddq_max, else 2 and 5).
    seed : int
        Seed of the random states (the result is deterministic for a seed).
    friction : bool
        Also decompose the usual friction columns (FC, FV, OFF of each moving joint, after
        the rigid-body and rotor columns); ``reduce`` then expects ``W`` with
        ``regressor.friction(dq)`` appended on the last axis.
    n_samples : int, optional
        Random states; default ``max(60, 3 p)``.
    rtol : float
        Rank tolerance (see the module docstring).

    Returns
    -------
    BaseParameters
    """
    if not isinstance(regressor, RobotRegressor):
        raise RobotIdentError(f"base_parameters: expected a RobotRegressor, got "
                              f"{type(regressor).__name__}")
    names = regressor.standard_names + (regressor.friction_names if friction else ())
    p = len(names)
    n = int(n_samples) if n_samples is not None else max(60, 3 * p)
    q, dq, ddq = _states(regressor, limits, n, seed)
    W = regressor.rigid(q, dq, ddq)
    if friction:
        W = np.concatenate([W, regressor.friction(dq)], axis=-1)
    kept, beta, base_names, exprs, zero = qr_rule(W.reshape(-1, p), names, rtol)
    return BaseParameters(tuple(names), tuple(base_names), kept, beta, tuple(exprs),
                          tuple(names[j] for j in np.flatnonzero(zero)), float(rtol),
                          int(seed), n)


# --------------------------------------------------------------------------- unknown payload
#: Names of a payload's parameters with its mass known: first moments m c and inertia about the
#: flange origin, flange frame (``RobotRegressor.flange_parameters`` without its mass).
PAYLOAD_NAMES = ("XXpay", "XYpay", "XZpay", "YYpay", "YZpay", "ZZpay",
                 "MXpay", "MYpay", "MZpay")


@dataclass(frozen=True, eq=False)
class PayloadBase:
    """The identifiable combinations of a payload's nine parameters (``PAYLOAD_NAMES``, mass
    known) by the base-parameter rule on its columns (``RobotRegressor.payload_columns``).

    Attributes
    ----------
    names : tuple of str
        Base names (``XXpayR`` when others regroup into it), r <= 9.
    columns : ndarray of int (r,)
        Kept columns, indices into ``PAYLOAD_NAMES``.
    beta : ndarray (r, 9)
        theta_pay = beta @ phi (phi: the nine parameters).
    expressions : tuple of str
        ``"XXpayR = XXpay - YYpay"``, one per base name.
    unidentifiable : tuple of str
        Parameters with no effect on any joint.
    """

    names: tuple[str, ...]
    columns: np.ndarray
    beta: np.ndarray
    expressions: tuple[str, ...]
    unidentifiable: tuple[str, ...]

    def values(self, regressor: RobotRegressor, payload: RobotPayloadData) -> np.ndarray:
        """theta_pay (r,) of a payload given in full (mass, CoM, inertia about the CoM)."""
        return self.beta @ regressor.flange_parameters(payload)[:9]


def payload_base(regressor: RobotRegressor, limits: object = None, seed: int = 0, *,
                 n_samples: int = 120, rtol: float = DEFAULT_RTOL) -> PayloadBase:
    """The base-parameter rule on a payload's nine columns (mass known) at random states
    (as :func:`base_parameters`). They are separable from the last link's own parameters only
    on data with runs without that payload: its columns are the last link's columns times an
    indicator of the runs carrying it."""
    if not hasattr(regressor, "payload_columns"):
        raise RobotIdentError(f"payload_base: expected a RobotRegressor, got "
                              f"{type(regressor).__name__}")
    q, dq, ddq = _states(regressor, limits, int(n_samples), seed)
    Y = regressor.payload_columns(q, dq, ddq)[:, :9, :]  # (k, 9, n)
    kept, beta, names, exprs, zero = qr_rule(Y.transpose(2, 0, 1).reshape(-1, 9),
                                             PAYLOAD_NAMES, rtol)
    return PayloadBase(tuple(names), kept, beta, tuple(exprs),
                       tuple(n for n, z in zip(PAYLOAD_NAMES, zero, strict=True) if z))


# --------------------------------------------------------------------------- 1-dof mapping
@dataclass(frozen=True, eq=False)
class SingleJointMap:
    """Base parameters of a one-joint robot -> today's single-joint model (eq. 31).

    Attributes
    ----------
    names : tuple of str
        ``("J", "MX", "MY")`` (revolute) or ``("J",)`` (prismatic), then ``("F_C", "F_V",
        "tau_off")`` when the base parameters include friction.
    matrix : ndarray, shape (len(names), p_b)
        chi_single = matrix @ chi_b.
    expressions : tuple of str
        e.g. ``"J = ZZ3R"``, ``"MX = -MY3"``.
    residual : float
        Largest relative residual of ``W_b = W_single matrix`` at random states (same
        column space when ~1e-12).
    """

    names: tuple[str, ...]
    matrix: np.ndarray
    expressions: tuple[str, ...]
    residual: float

    def values(self, base_values: np.ndarray) -> dict[str, float]:
        """Single-joint parameter values from base parameter values (p_b,)."""
        v = self.matrix @ np.asarray(base_values, dtype=float)
        return dict(zip(self.names, (float(x) for x in v), strict=True))


def single_joint_map(base: BaseParameters, regressor: RobotRegressor,
                     seed: int = 0) -> SingleJointMap:
    """Express the base parameters of a robot with one moving joint as the single-joint
    model of :mod:`ident.models` (eq. 31, ``RigidBody``: J ddq + MX g cos q + MY g sin q,
    g = 9.81; usual friction F_C, F_V, tau_off).

    The gravity columns of the robot rotate with the locked joints; the map is the least
    squares fit ``W_b = W_single T`` at random states (exact when the column spaces agree,
    see ``residual``), e.g. RX130L joint 3: ``J = ZZ3R`` (ZZ3 + Ia3), ``MX = -MY3``.

    Raises
    ------
    RobotIdentError
        More than one moving joint, or the column spaces differ (gravity not of magnitude
        9.81 m/s^2, or a base parameter the single-joint model lacks).
    """
    if regressor.k != 1:
        raise RobotIdentError(f"single_joint_map: expected one moving joint, got "
                              f"{regressor.joints}")
    rev = regressor.revolute[0]
    q, dq, ddq = _states(regressor, None, max(60, 6 * base.p_b), seed)
    W = regressor.rigid(q, dq, ddq)[:, 0, :]
    friction = len(base.standard_names) > regressor.p
    if friction:
        W = np.concatenate([W, regressor.friction(dq)[:, 0, :]], axis=-1)
    Wb = base.reduce(W)
    cols = [ddq[:, 0]] + ([G * np.cos(q[:, 0]), G * np.sin(q[:, 0])] if rev else [])
    names = ["J"] + (["MX", "MY"] if rev else [])
    if friction:
        cols += [np.sign(dq[:, 0]), dq[:, 0], np.ones_like(dq[:, 0])]
        names += ["F_C", "F_V", "tau_off"]
    S = np.column_stack(cols)
    T, *_ = np.linalg.lstsq(S, Wb, rcond=None)  # Wb = S T
    res = float(np.abs(S @ T - Wb).max() / max(np.abs(Wb).max(), 1e-300))
    if res > 1e-8:
        raise RobotIdentError(f"single_joint_map: the base regressor of {regressor.joints} "
                              f"is not in the span of the single-joint columns {names} "
                              f"(relative residual {res:.2g})")
    T[np.abs(T) < 1e-10] = 0.0
    exprs = []
    for i, nm in enumerate(names):
        terms = []
        for b in np.flatnonzero(T[i]):
            c = T[i, b]
            sign = "-" if c < 0 else "+"
            mag = "" if abs(abs(c) - 1) < 1e-9 else f"{_format(abs(c))}*"
            terms.append(f"{sign} {mag}{base.names[b]}")
        if terms:
            terms[0] = terms[0].removeprefix("+ ").replace("- ", "-", 1)
        text = " ".join(terms) if terms else "0"
        exprs.append(f"{nm} = {text}")
    return SingleJointMap(tuple(names), T, tuple(exprs), res)


def lever_arm_payload(payload: RobotPayloadData, regressor: RobotRegressor,
                      base: BaseParameters, smap: SingleJointMap | None = None
                      ) -> RobotPayloadData:
    """Place a single-joint log's payload (mass M_a at lever arm L_a, eq. 34-35) on a robot
    with one moving revolute joint: the point mass in the flange frame whose base parameters
    add ``M_a L_a^2`` to J, ``M_a L_a`` to MX and nothing to MY of :func:`single_joint_map`.

    Parameters
    ----------
    payload : RobotPayloadData
        Returned unchanged when ``payload.arm_m`` is None.
    regressor, base
        The one-joint robot and its base parameters.
    smap : SingleJointMap, optional
        ``single_joint_map(base, regressor)`` (computed when not given).

    Returns
    -------
    RobotPayloadData
        Same mass, ``com`` [m] in the flange frame, no inertia about the CoM, ``arm_m`` None.

    Raises
    ------
    RobotIdentError
        More than one moving joint (the arm has no direction there), a prismatic joint, or no
        point mass gives the single-joint payload columns.
    """
    if payload.arm_m is None:
        return payload
    if regressor.k != 1:
        raise RobotIdentError(f"payload of {payload.mass} kg with a single-joint lever arm "
                              f"(arm_m = {payload.arm_m} m): on {regressor.k} moving joints "
                              "the arm has no direction; give the payload's CoM in the flange "
                              "frame (metadata payload.com_m)")
    smap = single_joint_map(base, regressor) if smap is None else smap
    if smap.names[:3] != ("J", "MX", "MY"):
        raise RobotIdentError(f"payload lever arm (arm_m = {payload.arm_m} m): joint "
                              f"{regressor.joints[0]} is not revolute")
    m, arm = payload.mass, payload.arm_m
    if m == 0.0:
        return RobotPayloadData()
    n_std = len(base.standard_names)

    def single(c: np.ndarray) -> np.ndarray:
        chi = np.zeros(n_std)  # the one moving link's XX..M come first
        chi[:10] = regressor.payload_parameters(RobotPayloadData(m, c))
        return smap.matrix[:3] @ base.values(chi)  # (J, MX, MY) of the point mass at c

    f0 = single(np.zeros(3))
    A = np.column_stack([single(e)[1:] - f0[1:] for e in np.eye(3)])
    com, *_ = np.linalg.lstsq(A, np.array([m * arm, 0.0]) - f0[1:], rcond=None)
    got = single(com)
    want = np.array([m * arm**2, m * arm, 0.0])
    if not np.allclose(got, want, rtol=1e-9, atol=1e-9 * max(1.0, float(np.abs(want).max()))):
        raise RobotIdentError(f"payload lever arm (arm_m = {arm} m): no point mass on the "
                              f"flange of {regressor.joints[0]} adds (J, MX, MY) = "
                              f"{tuple(want)}")
    return RobotPayloadData(m, com)


def placed_payload(payload: RobotPayloadData, regressor: RobotRegressor,
                   base: BaseParameters | None, source: str,
                   cache: dict[tuple[float, float], RobotPayloadData]) -> RobotPayloadData:
    """``payload`` placed by :func:`lever_arm_payload` when it is a single-joint log's lever
    arm (else unchanged), cached in ``cache`` by (mass, lever arm); ``base`` None:
    ``base_parameters(regressor)``, computed only then. Errors name ``source``."""
    if payload.arm_m is None:
        return payload
    key = (payload.mass, payload.arm_m)
    if key not in cache:
        try:
            cache[key] = lever_arm_payload(payload, regressor, base if base is not None
                                           else base_parameters(regressor))
        except RobotIdentError as err:
            raise RobotIdentError(f"{source}: {err}") from None
    return cache[key]
