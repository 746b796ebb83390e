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

This is the one base-parameter rule of jointid: the planner's predicted condition number
(:func:`trajectories.excitation.base_columns`, on any regressor callable with the columns in
this order) and the fit (:class:`ident.robot.estimate.RobotModel`) keep the same columns
(:func:`independent_columns`), so the planner predicts the condition number of the base the fit
estimates.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from .. import RobotError
from .payload import RobotPayloadData
from .regressor import RobotRegressor

__all__ = ["BaseParameters", "base_parameters", "qr_rule", "independent_columns",
           "random_states", "uniform_states", "PayloadBase", "payload_base", "PAYLOAD_NAMES",
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
            raise RobotError(f"reduce: expected {len(self.standard_names)} columns "
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
                raise RobotError(f"base values: missing standard parameters {missing}")
            chi = np.array([float(standard.get(n, 0.0)) for n in self.standard_names])
        else:
            chi = np.asarray(standard, dtype=float).reshape(-1)
            if chi.shape != (len(self.standard_names),):
                raise RobotError(f"base values: expected {len(self.standard_names)} "
                                 f"standard values, got {chi.shape}")
        return self.beta @ chi


def random_states(reg: RobotRegressor, limits: object, n: int, seed: int
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``n`` uniform random states (q, dq, ddq), each (n, k), within ``limits`` (see
    :func:`base_parameters`)."""
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
                raise RobotError(f"limits: expected a mapping joint -> RobotLimits or a "
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
    return uniform_states(lo, hi, vmax, amax, n, seed)


def uniform_states(lo: np.ndarray, hi: np.ndarray, vmax: np.ndarray, amax: np.ndarray, n: int,
                   seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``n`` uniform random states, each (n, k): q in [lo, hi] [rad or m], dq in +/- vmax,
    ddq in +/- amax (finite bounds, (k,) each); the states of the base rule."""
    rng = np.random.default_rng(seed)
    k = len(lo)
    q = lo + (hi - lo) * rng.random((n, k))
    dq = vmax * rng.uniform(-1.0, 1.0, (n, k))
    ddq = amax * rng.uniform(-1.0, 1.0, (n, k))
    return q, dq, ddq


def _format(coef: float) -> str:
    return f"{coef:.6g}"


def regroup_expression(lhs: str, first: str, others: list[tuple[str, float]]) -> str:
    """A regrouping as it is printed: ``"lhs = first + b - 2.5*c"``, ``others`` the
    (name, coefficient) pairs after ``first`` (coefficients +-1 written without a factor)."""
    terms = [first]
    for name, c in others:
        if abs(c - 1.0) < 1e-9:
            terms.append(f"+ {name}")
        elif abs(c + 1.0) < 1e-9:
            terms.append(f"- {name}")
        elif c < 0:
            terms.append(f"- {_format(-c)}*{name}")
        else:
            terms.append(f"+ {_format(c)}*{name}")
    return f"{lhs} = " + " ".join(terms)


def independent_columns(W: np.ndarray, rtol: float = DEFAULT_RTOL  # noqa: N803
                        ) -> tuple[np.ndarray, np.ndarray]:
    """The columns the rule (module doc) keeps: QR of the unit-norm nonzero columns of ``W``
    (r, p) in their order, kept where ``|R_ii| > rtol * max |R_jj|``.

    Returns
    -------
    kept : ndarray of int, increasing
    zero : ndarray of bool (p,)
        Columns with no effect at all (norm <= 1e-12 of the largest).
    """
    W = np.asarray(W, dtype=float)  # noqa: N806
    norms = np.linalg.norm(W, axis=0)
    scale = norms.max() if norms.size else 1.0
    zero = norms <= 1e-12 * scale
    idx = np.flatnonzero(~zero)
    if idx.size == 0:
        raise RobotError("base parameters: the regressor is zero at every state")
    r = scipy.linalg.qr(W[:, idx] / norms[idx], mode="r")[0]
    diag = np.abs(np.diag(r))
    if diag.size < idx.size:  # fewer rows than columns: the rest have no pivot
        diag = np.concatenate([diag, np.zeros(idx.size - diag.size)])
    return idx[diag > rtol * diag.max()], zero


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
    kept, zero = independent_columns(W, rtol)
    dep = np.flatnonzero(~zero & ~np.isin(np.arange(p), kept))
    beta = np.zeros((kept.size, p))
    beta[np.arange(kept.size), kept] = 1.0
    if dep.size:
        b2 = np.linalg.lstsq(W[:, kept], W[:, dep], rcond=None)[0]  # W2 = W1 b2
        b2[np.abs(b2) < _ZERO_COEF * max(1.0, float(np.abs(b2).max()))] = 0.0
        beta[:, dep] = b2
    base_names, exprs = regrouped_names(names, kept, beta)
    return kept, beta, base_names, exprs, zero


def regrouped_names(names: Sequence[str], kept: Sequence[int], beta: np.ndarray
                    ) -> tuple[list[str], list[str]]:
    """Names and printed regroupings of base parameters: row r of ``beta`` (chi_b = beta chi)
    is ``names[kept[r]]``, suffixed ``R`` where others are regrouped into it, and
    ``"XXR = XX - YY"`` (:func:`regroup_expression`)."""
    base_names, exprs = [], []
    for row, c in enumerate(kept):
        others = [(names[j], float(beta[row, j])) for j in range(len(names))
                  if j != c and beta[row, j] != 0]
        nm = names[c] + ("R" if others else "")
        base_names.append(nm)
        exprs.append(regroup_expression(nm, names[c], others))
    return base_names, exprs


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
        raise RobotError(f"base_parameters: expected a RobotRegressor, got "
                         f"{type(regressor).__name__}")
    names = regressor.standard_names + (regressor.friction_names if friction else ())
    p = len(names)
    n = int(n_samples) if n_samples is not None else max(60, 3 * p)
    q, dq, ddq = random_states(regressor, limits, n, seed)
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
        raise RobotError(f"payload_base: expected a RobotRegressor, got "
                         f"{type(regressor).__name__}")
    q, dq, ddq = random_states(regressor, limits, int(n_samples), seed)
    Y = regressor.payload_columns(q, dq, ddq)[:, :9, :]  # (k, 9, n)
    kept, beta, names, exprs, zero = qr_rule(Y.transpose(2, 0, 1).reshape(-1, 9),
                                             PAYLOAD_NAMES, rtol)
    return PayloadBase(tuple(names), kept, beta, tuple(exprs),
                       tuple(n for n, z in zip(PAYLOAD_NAMES, zero, strict=True) if z))
