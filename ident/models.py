"""Regressor terms of the paper's two models and the estimator wrapper :class:`IdentModel`.

Every effect is a :class:`~ident.terms.Term` (columns linear in its parameters); the usual
model (eq. 38-39) and the new load- and velocity-dependent model (eq. 42-44) are two
compositions of the same terms::

    usual = RigidBody() + Payload() + Coulomb() + Viscous() + Offset()
    new = LoadDependent(RigidBody() + Payload(), q_s) + QuadrantCoulomb(q_s) + Viscous() + Offset()

Parameter names follow ``docs/architecture.md``. Pure numerics: no file access.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from trajectories import RobotError
from trajectories.friction import DEFAULT_Q_S, quadrant_products, quadrant_weights, stribeck_exp
from trajectories.robot import (
    BaseParameters,
    RobotPayloadData,
    RobotRegressor,
    base_parameters,
    one_joint_robot,
)

from . import DataError
from .estimate import DEFAULT_THRESHOLD_PCT, LSResult, fit_least_squares
from .results import DEFAULT_BANDS, band_errors
from .robot import RobotIdentError
from .robot.base import SingleJointMap, lever_arm_payload, single_joint_map
from .signals import G, Signals
from .terms import Library, Term

if TYPE_CHECKING:  # pragma: no cover
    from .preprocess import Design

__all__ = [
    "RigidBody",
    "Payload",
    "Coulomb",
    "Viscous",
    "Offset",
    "LoadDependent",
    "QuadrantCoulomb",
    "usual_model",
    "new_model",
    "IdentModel",
    "power_split",
    "exp_velocity",
]


def power_split(s: Signals, load: Term | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Diagonals of P+ and P- (eq. 27-28, 44).

    Parameters
    ----------
    s : Signals
        Samples.
    load : Term or callable, optional
        A load prediction τ̂_out(s) [N m] (e.g. :class:`ident.effects.Prediction`): the
        quadrant is then the model's, sign(τ̂_out q̇), and the columns read no measured
        torque. Without it, the paper's proxy sign(P) = sign(tau dq) of eq. 26.

    Returns
    -------
    p_plus, p_minus : ndarray, shape (n,)
        (1 + sign P)/2 and (1 - sign P)/2 (:func:`trajectories.friction.quadrant_weights`);
        both 0.5 where the product is 0.
    """
    return quadrant_weights(s.sign_power if load is None else load(s) * s.dq)


def exp_velocity(s: Signals, q_s: float) -> np.ndarray:
    """E_xp = exp(-|dq| / q_s) (eq. 29, 44), shape (n,); q_s in [rad/s] or [m/s]."""
    return stribeck_exp(s.dq, q_s)


def _check_qs(q_s: float) -> float:
    q_s = float(q_s)
    if not np.isfinite(q_s) or q_s <= 0:
        raise DataError(f"q_s: expected a positive velocity constant [rad/s], got {q_s!r}")
    return q_s


_MAX_RUNS = 64  # payload runs evaluated as slices; more (interleaved rows): one gather each


@dataclass(frozen=True, eq=False)
class _OneJoint:
    """The joint of a single-joint log as a 1-dof robot (:func:`one_joint_robot`): the robot
    model's regressor, its base parameters and the constant map of those to the single-joint
    parameters (:func:`ident.robot.base.single_joint_map`), ``chi_single = T chi_b``."""

    regressor: RobotRegressor
    base: BaseParameters
    smap: SingleJointMap
    to_single: np.ndarray  # (p_b, len(smap.names)): W_single = W_b to_single (T inverse)
    pick: list[tuple[int, float]] | None  # to_single as (base column, +-1) per column
    payloads: dict[tuple[float, float], RobotPayloadData]

    def rigid(self, s: Signals) -> np.ndarray:
        """Columns ``smap.names`` (J[, MX, MY]) of eq. 31 on ``s``, shape (n, 1 or 3)."""
        w = self.regressor.rigid_kpn(s.q, s.dq, s.ddq, columns=self.base.columns)[0]
        if self.pick is None:
            return w.T @ self.to_single
        out = np.empty((w.shape[1], len(self.pick)))
        for c, (b, sign) in enumerate(self.pick):  # each column one base column times +-1
            np.multiply(w[b], sign, out=out[:, c])
        return out

    def payload(self, s: Signals) -> np.ndarray:
        """Torque (n,) of each sample's known payload (eq. 34-35): the regressor's payload
        torque of the lever-arm payload placed on the 1-dof robot (revolute), of the mass at
        the flange (prismatic: no arm). Runs of one payload are evaluated as slices."""
        n = len(s)
        out = np.zeros(n)
        mass = np.asarray(s.payload_mass, dtype=float)
        if not mass.any():
            return out
        arm = (np.asarray(s.payload_arm, dtype=float) if self.regressor.revolute[0]
               else np.zeros(n))  # a prismatic joint's payload has no arm
        cut = np.flatnonzero((mass[1:] != mass[:-1]) | (arm[1:] != arm[:-1])) + 1
        if len(cut) < _MAX_RUNS:
            runs = zip(np.concatenate([[0], cut]), np.concatenate([cut, [n]]), strict=True)
            for a, b in runs:
                if mass[a] != 0.0:
                    out[a:b] = self._torque(s, slice(a, b), mass[a], arm[a])
            return out
        loaded = np.flatnonzero(mass != 0.0)  # interleaved payloads: one gather per payload
        keys, inverse = np.unique(np.column_stack([mass[loaded], arm[loaded]]), axis=0,
                                  return_inverse=True)
        for i, (m, la) in enumerate(keys):
            rows = loaded[inverse.reshape(-1) == i]
            out[rows] = self._torque(s, rows, m, la)
        return out

    def _torque(self, s: Signals, rows: slice | np.ndarray, mass: float, arm: float
                ) -> np.ndarray:
        return self.regressor.payload_torque(s.q[rows], s.dq[rows], s.ddq[rows],
                                             self._placed(float(mass), float(arm)))[:, 0]

    def _placed(self, mass: float, arm: float) -> RobotPayloadData:
        key = (mass, arm)
        if key not in self.payloads:
            if self.regressor.revolute[0] and not np.isfinite(arm):
                raise DataError(f"payload_arm: expected a finite lever arm [m] for the "
                                f"payload of {mass} kg, got {arm}")
            try:
                self.payloads[key] = (  # prismatic: at the flange, on the axis: M_aw ddq
                    lever_arm_payload(RobotPayloadData(mass, arm_m=arm), self.regressor,
                                      self.base, self.smap)
                    if self.regressor.revolute[0] else RobotPayloadData(mass))
            except (RobotError, RobotIdentError) as err:
                raise DataError(f"payload_mass: {err}") from None
        return self.payloads[key]


def _signed_selection(m: np.ndarray, tol: float = 1e-9) -> list[tuple[int, float]] | None:
    """(row, sign) per column of ``m`` when each column is one entry +-1 (within ``tol``: the
    map is a least-squares fit, exact up to rounding) and zeros, else None."""
    out = []
    for col in m.T:
        nz = np.flatnonzero(np.abs(col) > tol)
        if len(nz) != 1 or abs(abs(col[nz[0]]) - 1.0) > tol:
            return None
        out.append((int(nz[0]), float(np.sign(col[nz[0]]))))
    return out


@functools.cache
def _one_joint(kind: str) -> _OneJoint:
    """The 1-dof robot of a joint kind, its base parameters and map (computed once)."""
    reg = RobotRegressor(one_joint_robot(kind, gravity=G))
    base = base_parameters(reg)
    smap = single_joint_map(base, reg)
    to_single = np.linalg.inv(smap.matrix)
    return _OneJoint(reg, base, smap, to_single, _signed_selection(to_single), {})


class RigidBody(Term):
    """Rigid-body regressor of one joint (eq. 31): ``[ddq, g cos q, g sin q]`` -> J, MX, MY.

    The columns are the robot model's regressor
    (:class:`trajectories.robot.RobotRegressor`) of the joint as a 1-dof robot
    (:func:`trajectories.robot.one_joint_robot`), reduced to its base parameters and mapped
    to J, MX, MY by the constant map of :func:`ident.robot.base.single_joint_map`
    (``J = ZZ1R``, ``MX = MX1``, ``MY = -MY1``; prismatic ``J = M1R``).

    Parameters
    ----------
    revolute : bool or None
        ``True``: columns J, MX, MY. ``False`` (prismatic, no gravity): column J only
        (J is then the moving mass [kg]). ``None``: names J, MX, MY and the gravity columns
        follow ``Signals.revolute`` (zero on prismatic data, reported by the estimator).
    """

    effect = "rigid_body"
    variable = "model"

    def __init__(self, revolute: bool | None = None) -> None:
        self.revolute = revolute

    def names(self) -> tuple[str, ...]:
        return ("J",) if self.revolute is False else ("J", "MX", "MY")

    def columns(self, s: Signals) -> np.ndarray:
        w = _one_joint("revolute" if s.revolute else "prismatic").rigid(s)
        k = len(self.names())
        if w.shape[1] >= k:
            return np.ascontiguousarray(w[:, :k])
        out = np.zeros((len(s), k))  # J, MX, MY named on prismatic data: no gravity
        out[:, : w.shape[1]] = w
        return out

    def describe(self) -> str:
        if self.revolute is False:
            return "rigid body J ddq (prismatic)"
        return "rigid body J ddq + MX g cos q + MY g sin q (eq. 31)"


class Payload(Term):
    """Known additional mass (eq. 34-35): ``M_aw L_a (L_a ddq + g cos q)`` -> ``Ma_ratio``.

    The parameter is M_ae/M_aw, the identified over the weighed mass (1 for an exact
    weighing). On prismatic data the column is ``M_aw ddq`` (no lever arm, no gravity).
    The column is the robot model's payload torque
    (:meth:`trajectories.robot.RobotRegressor.payload_torque`) of the joint as a 1-dof robot
    carrying a point mass M_aw placed so that it adds M_aw L_a^2 to J and M_aw L_a to MX
    (:func:`ident.robot.base.lever_arm_payload`; prismatic: the mass at the flange).
    """

    effect = "payload"
    variable = "load"

    def names(self) -> tuple[str, ...]:
        return ("Ma_ratio",)

    def columns(self, s: Signals) -> np.ndarray:
        one = _one_joint("revolute" if s.revolute else "prismatic")
        return one.payload(s).reshape(-1, 1)

    def describe(self) -> str:
        return "payload (M_ae/M_aw) M_aw L_a (L_a ddq + g cos q) (eq. 35)"


class Coulomb(Term):
    """Symmetric dry friction ``F_C sign(dq)`` (eq. 5) -> ``F_C`` [N m].

    sign(dq) is :attr:`Signals.direction <ident.signals.Signals.direction>`: on decimated
    samples that carry it (a robot fit's rows), sign(dq) formed at full rate and decimated
    with the torque; else the sign of the samples' dq.
    """

    effect = "coulomb"
    variable = "direction"

    def names(self) -> tuple[str, ...]:
        return ("F_C",)

    def columns(self, s: Signals) -> np.ndarray:
        # the decimated full-rate sign(dq) on samples that carry it (Signals.direction)
        return np.asarray(s.direction, dtype=float).reshape(-1, 1).copy()

    def describe(self) -> str:
        return "Coulomb F_C sign(dq)"


class Viscous(Term):
    """Viscous friction ``F_V dq`` (eq. 5) -> ``F_V`` [N m s/rad]."""

    effect = "viscous"
    variable = "velocity"

    def names(self) -> tuple[str, ...]:
        return ("F_V",)

    def columns(self, s: Signals) -> np.ndarray:
        return np.asarray(s.dq, dtype=float).reshape(-1, 1).copy()

    def describe(self) -> str:
        return "viscous F_V dq"


class Offset(Term):
    """Offset ``tau_off`` (amplifier offset + asymmetric Coulomb, eq. 6) -> ``tau_off`` [N m]."""

    effect = "offset"
    variable = "direction"

    def names(self) -> tuple[str, ...]:
        return ("tau_off",)

    def columns(self, s: Signals) -> np.ndarray:
        return np.ones((len(s), 1))

    def describe(self) -> str:
        return "offset tau_off"


class LoadDependent(Term):
    """Load- and velocity-dependent dry friction on tau_out (eq. 30, 42-44).

    With W_in the columns of ``inner`` (the rigid body and payload, tau_out = W_in chi_in),
    the columns are ``[P+ W_in, P+ Exp W_in, P- W_in, -P- Exp W_in]``, arranged as in
    eq. 43: for each inner column n, ``a_m_<n>, b_m_<n>``, then for each, ``a_g_<n>, b_g_<n>``.
    The payload column keeps the bare names ``a_m, b_m, a_g, b_g`` (its coefficient is
    a_m M_ae/M_aw, i.e. a_m for an exact weighing).

    Parameters
    ----------
    inner : Term
        The terms whose sum is tau_out (usually ``RigidBody() + Payload()``).
    q_s : float
        Velocity constant q_s of E_xp = exp(-|dq|/q_s) [rad/s] (eq. 29), fixed a priori.
    load : callable, optional
        Load prediction τ̂_out(s) deciding the quadrant (:func:`power_split`); default the
        paper's sign(tau dq) of eq. 26.
    """

    effect = "load_dependent"
    variable = "quadrant"

    def __init__(self, inner: Term, q_s: float, load: Term | None = None) -> None:
        self.inner = inner
        self.q_s = _check_qs(q_s)
        self.load = load

    def _suffixes(self) -> list[str]:
        out = []
        for t in self.inner.terms():
            for n in t.names():
                out.append("" if isinstance(t, Payload) else "_" + n)
        return out

    def names(self) -> tuple[str, ...]:
        suf = self._suffixes()
        m = [f"{p}{x}" for x in suf for p in ("a_m", "b_m")]
        g = [f"{p}{x}" for x in suf for p in ("a_g", "b_g")]
        return tuple(m + g)

    def columns(self, s: Signals) -> np.ndarray:
        w = self.inner.columns(s)
        pp, pm = power_split(s, self.load)
        e = exp_velocity(s, self.q_s)
        pp, pm, e = pp[:, None], pm[:, None], e[:, None]
        n, k = w.shape
        out = np.empty((n, 4 * k))
        out[:, 0 : 2 * k : 2], out[:, 2 * k :: 2] = quadrant_products(w, pp, pm)
        out[:, 1 : 2 * k : 2], out[:, 2 * k + 1 :: 2] = quadrant_products(w, pp, pm, e)
        return out

    def describe(self) -> str:
        return (
            f"load-dependent friction P+(a_m + b_m Exp) tau_out + P-(a_g - b_g Exp) tau_out, "
            f"q_s={self.q_s:g} (eq. 30, 42)"
        )

    def __repr__(self) -> str:
        return f"LoadDependent({self.inner!r}, q_s={self.q_s:g})"


class QuadrantCoulomb(Term):
    """Quadrant dry friction (eq. 30): ``[P+ sign, P+ Exp sign, P- sign, P- Exp sign]``.

    Parameters c_m, d_m, c_g, d_g [N m]; ``q_s`` and ``load`` as in :class:`LoadDependent`.
    """

    effect = "quadrant_coulomb"
    variable = "quadrant"

    def __init__(self, q_s: float, load: Term | None = None) -> None:
        self.q_s = _check_qs(q_s)
        self.load = load

    def names(self) -> tuple[str, ...]:
        return ("c_m", "d_m", "c_g", "d_g")

    def columns(self, s: Signals) -> np.ndarray:
        pp, pm = power_split(s, self.load)
        e = exp_velocity(s, self.q_s)
        sg = np.asarray(s.direction, dtype=float)  # (Signals.direction: as Coulomb's)
        m, g = quadrant_products(sg, pp, pm)
        me, ge = quadrant_products(sg, pp, pm, e, load=False)
        return np.column_stack([m, me, g, ge])

    def describe(self) -> str:
        return (
            "quadrant dry friction P+(c_m + d_m Exp) sign + P-(c_g + d_g Exp) sign, "
            f"q_s={self.q_s:g}"
        )

    def __repr__(self) -> str:
        return f"QuadrantCoulomb(q_s={self.q_s:g})"


def usual_model(revolute: bool | None = None, *, payload: bool = True) -> Library:
    """The usual model, eq. 38-39: J, MX, MY, Ma_ratio, F_C, F_V, tau_off.

    Parameters
    ----------
    revolute : bool or None
        See :class:`RigidBody`.
    payload : bool
        Include the :class:`Payload` term (drop it when no run carries a payload).
    """
    inner: list[Term] = [RigidBody(revolute)]
    if payload:
        inner.append(Payload())
    return Library(*inner, Coulomb(), Viscous(), Offset())


def new_model(
    q_s: float = DEFAULT_Q_S, revolute: bool | None = None, *, payload: bool = True
) -> Library:
    """The paper model, eq. 42-43, with q_s [rad/s] (the paper's 0.03 rad/s by default)."""
    inner: list[Term] = [RigidBody(revolute)]
    if payload:
        inner.append(Payload())
    return Library(LoadDependent(Library(*inner), q_s), QuadrantCoulomb(q_s), Viscous(), Offset())


class IdentModel:
    """A model (a :class:`~ident.terms.Library`) and its least-squares fit (sklearn style).

    Parameters
    ----------
    library : Term
        The regressor terms.
    name : str
        Label used in tables and JSON (``"usual"``, ``"paper"``).

    Attributes (after :meth:`fit`)
    ------------------------------
    coef_ : dict[str, float]
        Identified values of the kept parameters (eq. 12).
    names_ : tuple[str, ...]
        Kept parameter names, in column order; ``coef_array_`` the values as an array.
    std_, rel_std_pct_ : dict[str, float]
        Standard deviations sigma_chi (eq. 15) and relative deviations 100 sigma/|chi| (eq. 16).
    cov_ : ndarray, shape (b, b)
        Covariance of the estimate (eq. 15).
    sigma_rho_ : float
        Estimated residual standard deviation (eq. 14).
    residual_ : ndarray, shape (m,)
        rho = Y - W chi on the design's samples.
    rel_error_ : float
        ||rho|| / ||Y||.
    cond_ : float
        Condition number of the kept (column-scaled) regressor.
    removed_ : list[tuple[str, str]]
        Eliminated parameter names and why (unidentifiable, zero column, not significant).
    result_ : LSResult
        The final estimator result.
    estimator_ : {"ls", "iv"}
        Least squares (eq. 12) or IDIM-IV (when the design has instruments).
    converged_ : bool
        False when the paper model's quadrant passes (:func:`ident.fitting.fit_models`, the
        sign check skipped: model quadrants decided again by the fit's own load) stopped at
        their cap before they settled (:mod:`ident.quadrant_band`, the n-dof fit's one rule);
        True otherwise (a least-squares fit has nothing else to converge).
    convergence_ : str
        Why ``converged_`` is False, one line with the figures; "" when it is True.
    quadrant_changes_, quadrant_steps_ : list or None
        With those passes: the rows moved at each re-decision (into another quadrant, or
        across the quadrant band) and the largest parameter change, in its sigma; else None.
    """

    #: class defaults: a fit without quadrant passes (see the attributes above)
    converged_: bool = True
    convergence_: str = ""
    quadrant_changes_: list[int] | None = None
    quadrant_steps_: list[float] | None = None

    def __init__(self, library: Term, name: str = "usual") -> None:
        self.library = library if isinstance(library, Library) else Library(library)
        self.name = name

    def fit(
        self,
        design: Design,
        *,
        eliminate: bool = True,
        threshold_pct: float | None = None,
        drop_unidentifiable: bool = True,
    ) -> IdentModel:
        """Fit on a :class:`~ident.preprocess.Design` built with this model's library.

        Parameters
        ----------
        design : Design
            Y and W (decimated, selected). Its columns must include this library's names.
        eliminate : bool
            Iteratively remove the parameter with the largest relative deviation above
            ``threshold_pct`` and refit (the paper's Tables I-II keep significant values).
        threshold_pct : float or None
            Relative-deviation threshold [%]; default :data:`ident.estimate.DEFAULT_THRESHOLD_PCT`.
        drop_unidentifiable : bool
            Remove (and report) zero or linearly dependent columns instead of raising
            :class:`~ident.IdentifiabilityError`.

        Notes
        -----
        When the design carries instruments (``design.Z``, built from a reference
        trajectory), the estimator is IDIM-IV (:func:`ident.estimate.fit_instrumental`)
        instead of OLS; ``estimator_`` says which.
        """
        names = tuple(self.library.names())
        missing = [n for n in names if n not in design.names]
        if missing:
            raise DataError(f"design has no column for parameters {missing}; rebuild it")
        idx = [design.names.index(n) for n in names]
        W = design.W[:, idx]
        Z = getattr(design, "Z", None)
        res = fit_least_squares(
            W,
            design.Y,
            names,
            eliminate=eliminate,
            threshold_pct=DEFAULT_THRESHOLD_PCT if threshold_pct is None else threshold_pct,
            drop_unidentifiable=drop_unidentifiable,
            Z=None if Z is None else Z[:, idx],
        )
        self.estimator_ = "ls" if Z is None else "iv"
        self._set(res)
        return self

    def _set(self, res: LSResult) -> None:
        self.result_ = res
        self.names_ = res.names
        self.coef_array_ = res.chi
        self.coef_ = dict(zip(res.names, res.chi.tolist(), strict=True))
        self.std_ = dict(zip(res.names, res.std.tolist(), strict=True))
        self.rel_std_pct_ = dict(zip(res.names, res.rel_std_pct.tolist(), strict=True))
        self.cov_ = res.cov
        self.sigma_rho_ = res.sigma_rho
        self.residual_ = res.residual
        self.rel_error_ = res.rel_error
        self.cond_ = res.cond
        self.removed_ = list(res.removed)

    def _check_fitted(self) -> None:
        if not hasattr(self, "result_"):
            raise DataError(f"model {self.name!r} is not fitted; call fit(design) first")

    def predict(self, design: Design) -> np.ndarray:
        """W chi_hat on a design's samples [N m], shape (m,)."""
        self._check_fitted()
        missing = [n for n in self.names_ if n not in design.names]
        if missing:
            raise DataError(f"design has no column for parameters {missing}")
        idx = [design.names.index(n) for n in self.names_]
        return design.W[:, idx] @ self.coef_array_

    def rel_error_on(self, design: Design) -> float:
        """||Y - W chi_hat|| / ||Y|| on a design (e.g. cross-validation files)."""
        rho = design.Y - self.predict(design)
        return float(np.linalg.norm(rho) / np.linalg.norm(design.Y))

    def rel_error_bands(
        self,
        design: Design,
        vmax: float | None = None,
        bands: dict[str, tuple[float, float]] | None = None,
    ) -> dict[str, float]:
        """Relative error ||rho||/||Y|| per velocity band (Table III).

        Parameters
        ----------
        design : Design
            Samples to evaluate.
        vmax : float or None
            Maximum velocity [rad/s]; default max |dq| of the design.
        bands : dict or None
            name -> (low, high) fractions of vmax; default ``all`` (0-1), ``low`` (0-0.10),
            ``high`` (0.35-1), as in the paper.

        Returns
        -------
        dict
            name -> relative error (NaN when a band holds no sample).
        """
        rho = design.Y - self.predict(design)
        return band_errors(design.Y, rho, design.signals.dq, vmax, bands or DEFAULT_BANDS)

    def __repr__(self) -> str:
        return f"IdentModel({self.name!r}: {self.library!r})"
