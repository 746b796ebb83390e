"""The n-dof refit: the terms a refinement found, refitted inside the n-dof model.

(Past 600 lines: one function and its one stacked system -- the rows of every model form
and their IV instruments, the solve, the record of before/after -- read the same fitted
model's private layout; split, each part would need all of it.)

:func:`ident.robot.refine_joint.refine_joint` looks for an effect in one joint's residual
after the n-dof fit; on its own the found term is fitted on that residual (two stages), so
the n-dof parameters have already absorbed the part of its column that lies in their span
and its coefficients are biased towards zero (docs/refinement.md, section 8.7).
:func:`refit_robot` removes that bias: every found term becomes extra columns of its
joint's rows of the stacked n-dof system, and the whole model -- base parameters, every
joint's friction, the extra coefficients -- is fitted again in one estimation::

    tau_j = (the n-dof model of joint j: usual eq. 5/8, paper eq. 30 or its products
             form eq. 42) + X_j e_j

X_j (:func:`ident.robot.design.joint_columns`) is computed from the states only: the term
sees joint j's signals of the refinement through :meth:`ident.signals.Signals.states` (the
other joints' ``q<m>``, ``dq<m>``, and the first n-dof fit's prediction as the load
variable ``tau_hat``), never the measured torque. The extra terms enter additively with
their own coefficients (not scaled by the paper model's a, b).

Estimation: the rows of each joint are those the n-dof fit used (|dq_j| > ``dq_min``, finite,
``RobotColumns.keep`` or the given ``keep``, the paper model's quadrant band); the quadrants
of the paper model are those of the first fit's prediction (its ``predict``), held fixed;
Gauss-Newton from the first fit (one step for the usual model, which is linear), LS, WLS or
IDIM-IV as the model (WLS: per-joint weights 1/sigma_j^2 of an LS refit); the parameters the
first fit held fixed stay fixed, and so do the paper model's pruned ones (``pruned_``, at 0:
re-estimated, they would move the "after" error without any found term).

IDIM-IV (``method="iv"``). The bilinear paper form is refitted as the model fits it:
Gauss-Newton whose steps are IV solves, Z^T J dx = Z^T r with Z the Jacobian on the
instrument rows (below), full steps (IV minimises no cost: no line search), the quadrants
the fit's, held (tests/test_robot_refit_iv.py ``test_bilinear_iv``). The linear forms (the
usual model and the products form): one IV solve, the model's estimator's
(:class:`ident.estimators.IV` ``solve_normal`` on Z^T W, its covariance the IV sandwich
sigma^2 (Z^T W)^-1 Z^T Z (W^T Z)^-1 as the model's fit computes it), on the stacked rows
W = [the model's columns on the fit's rows, X_j] with the instruments Z = [the model's own
instrument rows of those columns, X_j's instruments]. The model's are what its IV fit read:
the columns chain's ``Wz``, ``pz`` (the regressor on the reference's acceleration; the
states chain: the regressor on q_ref differentiated twice), through
``RobotModel._fitted_rows(..., instruments=True)``; on full-rate products the products'
``loads_z`` (``products_rows(..., instruments=True)``). X_j's follow the single-joint rule
(:meth:`ident.preprocess.Design.with_term`): a term's columns are their own instruments
unless they read the acceleration, then they are the term's columns with the reference's
acceleration instead of the measured one. The single-joint design forms those at full rate
(the reference differentiated there, then low-passed and decimated with the columns); the
signals here carry only the decimated, filtered q_ref, so the reference's acceleration is
that differentiated twice per experiment by central differences (as the model's states
chain does) -- 1.2 % from the design's on the example campaign, which moves the refit's
error by ~1e-5 relative (tests/test_robot_refit_iv.py). Signals without q_ref: the terms
that do not read the acceleration are their own instruments, the others are refused in one
line. On a one-joint robot with the design's own term columns and instruments the IV refit
is the single-joint IV refit of the design with the term, to round-off. The held-out error
is, as for LS, the least-squares fit on the other folds (what
:func:`ident.unseen.heldout_error` gives the single-joint fits, IV included).

The paper model's products form (``form="products"``, eq. 42: the products of the load
columns with a_m, b_m, a_g, b_g free, no base parameters) is linear in its parameters: the
refit is one (weighted) least-squares solve, the same code with one step. On the products
formed at full rate (``full_rate_products_``, what :class:`ident.one_joint.OneJointProblem`
fits a joint with) each joint's rows are the model's own
(:meth:`~ident.robot.estimate.RobotModel.products_rows`: its products and its row rule, the
quadrants already in the products), ``[u_j, X_j]``; on the decimated columns, the model's
rows with the quadrants of the usual fit's theta that decided them (``quadrant_from_``, as
its ``predict``). The products the first fit fixed at 0 (zero or dependent load columns,
eliminated ones) stay at 0. On a one-joint robot, with a term's columns as the single-joint
design forms them (filtered at full rate), the refit is the single-joint refit of the design
with that term (tests/test_robot_refit_products.py); ``joint_columns`` evaluates the term on
the decimated states instead, which moves the error by ~1e-4 relative.

Reported before (the n-dof fit as it is) and after (the refit), per joint and for the whole
robot: the relative error ||rho_j|| / ||tau_j|| on the rows used, the error on unseen data
(:func:`ident.unseen.heldout_error`'s folds: leave one run out with two runs or more, else
five blocks; the refit linearised at the solution; under WLS "before" weights the joints of
its folds as the fit did, ``model.weights_``, "after" as the refit does), the noise floor
(:func:`ident.unseen.noise_floor` of each joint's residual), and the validation error when
validation samples are given. Whether the found terms are kept is decided on these held-out
errors by :func:`ident.robot.refit_accept.accept_refit` (``refused``, ``acceptance``).

Memory: the rows of every joint (their base columns, friction and extra columns) are held
while iterating: ~8 (p_j + 10 + c_j) bytes per row (products form on full-rate products:
~8 (4 p_j + 11 + c_j)), twice that with IDIM-IV (the instruments' rows); meant for the
decimated rows of a fit.
Pure numerics (no file access).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import scipy.linalg
import scipy.stats

from trajectories.friction import quadrant_weights, stribeck_exp

from ..estimators import RankDeficientError, get_estimator
from ..terms import Term
from ..unseen import N_BLOCKS, heldout_kind, noise_floor
from . import RobotIdentError
from .design import joint_columns
from .estimate import QUADRANT_TOL, _ref_acceleration
from .paper import rows_coefficients
from .signals import RobotSignals

__all__ = ["RobotRefit", "refit_robot", "extra_name", "model_at_qs"]

#: Gauss-Newton iterations at most (paper model) and relative step tolerance.
MAX_ITER = 50
TOL = 1e-10
#: Relative step of q_s for the derivative of the products formed at full rate (``std_qs_``).
QS_STEP = 1e-4
#: Level of the Wald test that tells whether a found term stays significant in the refit.
WALD_ALPHA = 0.05


def extra_name(joint: str, name: str) -> str:
    """Name of an extra parameter in the refitted n-dof model: ``<joint>:<term name>``."""
    return f"{joint}:{name}"


@dataclass
class _Rows:
    """Joint j's rows of the stacked system (the rows the n-dof fit used)."""

    idx: np.ndarray  # row indices in the signals
    V: np.ndarray  # (m, nv): base columns, p, sign, dq, 1, 0 (ident.robot.moments)
    pp: np.ndarray  # P+ (model quadrant, fixed; P- = 1 - P+: no band here)
    E: np.ndarray  # exp(-|dq| / q_s)
    X: np.ndarray  # (m, c) extra columns
    tau: np.ndarray  # measured torque [N m]
    experiment: np.ndarray
    Vz: np.ndarray | None = None  # IDIM-IV: the instruments' rows of V (the model's own)
    Xz: np.ndarray | None = None  # IDIM-IV: the extra columns' instruments
    Vq: np.ndarray | None = None  # rows given whole: d V / d q_s of the joint (std_qs_)


@dataclass
class RobotRefit:
    """The n-dof model refitted with extra per-joint terms (module doc).

    Attributes
    ----------
    model : RobotModel
        The first n-dof fit (unchanged).
    terms : list of (int, Term)
        The extra terms, (joint index, term).
    names_ : tuple of str
        The model's ``names_`` then the extra parameters (:func:`extra_name`).
    coef_, std_ : ndarray
        Estimates and standard deviations (eq. 15, sigma^2 (J^T J)^-1 at the solution;
        IDIM-IV: the sandwich sigma^2 (Z^T J)^-1 Z^T Z (J^T Z)^-1).
    std_qs_ : ndarray
        The standard deviations with every joint's q_s of the paper model (bilinear form on
        the decimated rows) estimated beside the parameters, eq. 15 on the Jacobian with
        the columns d pred_j / d q_s,j = sum over quadrants of P (V c1) dE/dq_s (E =
        exp(-|dq|/q_s)): what the parameters' spread is when q_s is chosen from the same data
        (``--q-s scan-joints``, :func:`ident.qs_scan.rescan_qs_joints`), which ``std_``, at
        q_s fixed, leaves out (docs/refinement.md, section 8.9). ``std_`` itself for the
        usual model (no q_s), the products form (q_s fixed with its products) and IDIM-IV
        (its covariance is not eq. 15's).
    cov_ : ndarray
    params_ : dict
        name -> value.
    extras : list of dict
        Per extra term: ``joint``, ``effect``, ``names`` (the term's), ``values``, ``std``,
        ``parameters`` (the term's derived values ``{name: (value, 2 sigma)}`` when it has a
        ``parameters`` method, e.g. amplitude and phase), ``wald`` (x^T C^-1 x of its
        coefficients) and ``significant`` (the Wald test at ``WALD_ALPHA`` passes).
    rel_error, heldout, noise_floor, validation : dict
        ``{"before": {joint: value, ..., "all": value}, "after": {...}}`` (validation: None
        without validation samples).
    heldout_kind : str
    n_rows : dict
        Rows used per joint.
    n_iter : int
    unsettled : dict
        ``{joint: share}``: the joints of a paper fit that had not settled, whose final
        values put that share of their rows in another model quadrant than the fit used
        (:meth:`~ident.robot.estimate.RobotModel.quadrant_drift` above ``QUADRANT_TOL``).
        Then "before" is the model refitted on the refit's quadrants WITHOUT the terms
        (same rows, same held parameters), not the fit as it is, so that before -> after is
        what the terms add; empty otherwise.
    refused : list of dict
        The found terms the held-out check refused (:func:`ident.robot.refit_accept.
        accept_refit`), each with its one-line reason and figures; empty when every term
        was kept or the refit was not checked.
    acceptance : dict or None
        The check's rule and per-joint tolerances (``accept_refit``); None when the refit
        was not checked (a bare :func:`refit_robot`).
    """

    model: Any
    terms: list[tuple[int, Term]]
    names_: tuple[str, ...] = ()
    coef_: np.ndarray = field(default_factory=lambda: np.zeros(0))
    std_: np.ndarray = field(default_factory=lambda: np.zeros(0))
    std_qs_: np.ndarray = field(default_factory=lambda: np.zeros(0))
    cov_: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    params_: dict[str, float] = field(default_factory=dict)
    extras: list[dict[str, Any]] = field(default_factory=list)
    rel_error: dict[str, dict[str, float]] = field(default_factory=dict)
    heldout: dict[str, dict[str, float]] = field(default_factory=dict)
    noise_floor: dict[str, dict[str, float]] = field(default_factory=dict)
    validation: dict[str, dict[str, float]] | None = None
    heldout_kind: str = ""
    n_rows: dict[str, int] = field(default_factory=dict)
    n_iter: int = 0
    unsettled: dict[str, float] = field(default_factory=dict)
    refused: list[dict[str, Any]] = field(default_factory=list)
    acceptance: dict[str, Any] | None = None

    def to_json(self) -> dict[str, Any]:
        """The ``refit`` record of docs/fit-json.md (plain floats; NaN as None)."""
        def num(v: float) -> float | None:
            return float(v) if np.isfinite(v) else None

        def ba(d: dict[str, dict[str, float]] | None) -> dict | None:
            if d is None:
                return None
            return {w: {j: num(v) for j, v in d[w].items()} for w in ("before", "after")}

        return {
            "parameters": {n: {"value": num(v), "std": num(s)} for n, v, s in
                           zip(self.names_, self.coef_, self.std_, strict=True)},
            "extras": [{**{k: v for k, v in x.items() if k != "parameters"},
                        "parameters": {n: {"value": num(a), "two_sigma": num(b)}
                                       for n, (a, b) in x["parameters"].items()}}
                       for x in self.extras],
            "rel_error": ba(self.rel_error),
            "heldout_kind": self.heldout_kind,
            "heldout_rel_error": ba(self.heldout),
            "noise_floor": ba(self.noise_floor),
            "validation_rel_error": ba(self.validation),
            "rows": dict(self.n_rows),
            "iterations": int(self.n_iter),
            "unsettled": dict(self.unsettled),
            "refused": [{**r, "heldout_rel_error": {w: {j: num(v) for j, v in d.items()}
                                                    for w, d in r["heldout_rel_error"].items()}}
                        for r in self.refused],
            "acceptance": self.acceptance,
        }


def refit_robot(
    model: Any,
    signals: RobotSignals,
    terms: Sequence[tuple[int, Term]],
    *,
    prediction: np.ndarray | None = None,
    keep: np.ndarray | None = None,
    revolute: Sequence[bool] | None = None,
    validation: tuple[RobotSignals, np.ndarray | None, np.ndarray | None] | None = None,
    columns: Sequence[np.ndarray] | None = None,
    instrument_columns: Sequence[np.ndarray] | None = None,
    refit_eliminated: bool = False,
    errors_only: bool = False,
) -> RobotRefit:
    """Refit the n-dof ``model`` with the extra per-joint ``terms`` (module doc).

    Parameters
    ----------
    model : RobotModel
        A fitted n-dof model (method ``"ls"``, ``"wls"`` or ``"iv"``; usual, paper, or the
        paper model's ``form="products"``; with ``"iv"``, signals carrying the instruments
        the fit read).
    signals : RobotSignals
        The samples it was fitted on (or any with the same joints); a products-form fit on
        the full-rate products needs signals carrying them (``columns.products``).
    terms : sequence of (int, Term)
        (joint index, single-joint term), e.g. every step of
        :func:`~ident.robot.refine_joint.refine_joint` on each joint. Empty: the refit is
        the first fit to rounding, unless its final theta moves rows of a paper fit to
        another quadrant (``unsettled``; docs/refinement.md section 8.8).
    prediction : ndarray, shape (n, k), optional
        ``model.predict(signals)`` when already computed: the terms' load variable.
    keep : ndarray of bool, shape (n, k), optional
        Rows the fit used (``RobotColumns.keep`` by default when the signals carry columns);
        |dq_j| > ``model.dq_min`` and finite samples are required too.
    revolute : sequence of bool, optional
        Per joint, whether it is revolute (default all).
    validation : (RobotSignals, ndarray or None, ndarray or None), optional
        Validation samples, the first fit's prediction on them (None: computed) and their
        kept rows (None: as ``keep``'s default).
    columns : sequence of ndarray, optional
        Per joint j, shape (n, c_j): the terms' columns already formed (joint j's terms side
        by side, in the order given), instead of :func:`~ident.robot.design.joint_columns`
        on the decimated states -- e.g. a single-joint design's term columns, formed at full
        rate and decimated with the torque (:meth:`ident.fitting.FitReport.
        refit_found_terms`); only the rows the fit uses are read. Not with ``validation``.
    instrument_columns : sequence of ndarray, optional
        With ``columns`` and IDIM-IV: the terms' instruments, shaped as ``columns`` (e.g.
        the design's Z columns of the terms); default the columns themselves.
    refit_eliminated : bool
        Estimate again the parameters the first fit's elimination fixed at 0 as not
        significant (``removed_`` reasons "not significant ...", the linear forms' single-
        joint elimination) and those the paper model's uncertainty step pruned (``pruned_``,
        :mod:`ident.robot.uncertainty`): the refinement refits without elimination. The zero
        and dependent columns stay at 0. Default False: every parameter the fit held stays
        held, the pruned ones included.
    errors_only : bool
        Only the estimate (``coef_``, ``params_``, ``names_``, ``n_iter``, ``n_rows``) and
        the relative error after the refit (``rel_error["after"]``): no covariance, "before",
        held-out errors, noise floors, Wald tests nor validation. What a q_s scan scores
        each q_s with (:func:`ident.qs_scan.rescan_qs`): the same estimate and error as the
        whole refit, in less time.

    Returns
    -------
    RobotRefit

    Raises
    ------
    RobotIdentError
        An unfitted model, an unknown method, IDIM-IV without the model's
        instruments or (a term reading the acceleration) without q_ref, bad shapes,
        parameters not identifiable with the terms, a fit on full-rate products and
        signals without them.
    """
    model._check_fitted()
    if getattr(model, "quadrants", "hard") == "soft":  # its rows weigh the quadrants softly
        raise RobotIdentError("refit_robot: the model was fitted with soft quadrants "
                              "(quadrants='soft'); the refit uses hard quadrants")
    linear = model.model == "usual" or model.form == "products"
    if model.method not in ("ls", "wls", "iv"):
        raise RobotIdentError(f"refit_robot: method {model.method!r} is not supported; "
                              "expected 'ls', 'wls' or 'iv'")
    iv = model.method == "iv"
    if tuple(signals.joints) != tuple(model.joints_):
        raise RobotIdentError(f"refit_robot: joints {signals.joints}, expected the model's "
                              f"{model.joints_}")
    terms = [(int(j), t) for j, t in terms]
    k = len(model.joints_)
    pred = model.predict(signals) if prediction is None else np.asarray(prediction, float)
    if pred.shape != signals.tau.shape:
        raise RobotIdentError(f"refit_robot: prediction of shape {pred.shape}, expected "
                              f"{signals.tau.shape}")
    if columns is None:
        X = joint_columns(signals, pred, terms, revolute)
        Xz = _extra_instruments(signals, pred, terms, revolute, X) if iv else None
    else:
        if validation is not None:
            raise RobotIdentError("refit_robot: columns= and validation= together (the "
                                  "validation samples' columns would be missing)")
        want = [sum(len(t.names()) for jj, t in terms if jj == j) for j in range(k)]

        def given(cols: Sequence[np.ndarray], what: str) -> list[np.ndarray]:
            out = [np.asarray(c, dtype=float) for c in cols]
            if len(out) != k or any(x.shape != (signals.n, c)
                                    for x, c in zip(out, want, strict=False)):
                raise RobotIdentError(f"refit_robot: {what} of shapes {[x.shape for x in out]}"
                                      f", expected {[(signals.n, c) for c in want]} (samples, "
                                      "the terms' parameters of each joint)")
            return out

        X = given(columns, "columns")
        Xz = None
        if iv:  # the given instruments, else the columns are their own
            Xz = X if instrument_columns is None else given(instrument_columns,
                                                             "instrument_columns")
    nx0 = len(model.coef_)
    # extra parameters after the model's, joint by joint in the order given
    names = list(model.names_)
    ext_idx: list[list[int]] = [[] for _ in range(k)]
    extras: list[dict[str, Any]] = []
    for j, t in terms:
        own = [extra_name(model.joints_[j], n) for n in t.names()]
        clash = set(own) & set(names)
        if clash:
            raise RobotIdentError(f"refit_robot: parameters {sorted(clash)} appear twice")
        extras.append({"joint": model.joints_[j], "effect": t.effect, "names": list(t.names()),
                       "index": list(range(len(names), len(names) + len(own)))})
        ext_idx[j] += extras[-1]["index"]
        names += own
    # X[j]'s columns are in the order of the terms on joint j, as ext_idx[j]
    rows = _rows(model, signals, X, keep, Xz, qs_deriv=not (errors_only or linear or iv))
    # held at 0 as the first fit held them; with refit_eliminated, not those its elimination
    # found not significant (eq. 14-16): they are estimated again, as the refinement's refits
    # do (no elimination)
    # and the paper model's pruned parameters (ident.robot.uncertainty: removed above the
    # relative-deviation threshold, held at 0 but not in fixed_) stay pruned
    pruned = set(getattr(model, "pruned_", ()))
    held = set(model.fixed_) | pruned
    again = {n for n, why in getattr(model, "removed_", [])
             if refit_eliminated and why.startswith("not significant")}
    if refit_eliminated:
        again |= pruned
    free = np.array([n not in held or n in again for n in names])
    x0 = np.concatenate([model.coef_, np.zeros(len(names) - nx0)])
    coeffs = _coefficients(model)
    sys = _System(model, rows, ext_idx, coeffs, len(names), names)
    x, it, w = _estimate(sys, x0, free, linear, model.method)
    out = RobotRefit(model=model, terms=terms, names_=tuple(names), n_iter=it)
    if errors_only:  # a q_s scan's score: the estimate and its error, nothing else
        out.coef_ = x
        out.params_ = dict(zip(names, x.tolist(), strict=True))
        out.n_rows = {model.joints_[j]: int(rw.V.shape[0]) for j, rw in enumerate(rows)}
        out.rel_error = {"after": _rel(model.joints_, sys.residuals(x)[0], rows)}
        return out
    # the model's own parameters (the extra ones come after them)
    base = np.array([i < nx0 for i in range(len(names))])
    drift = model.quadrant_drift(signals) if hasattr(model, "quadrant_drift") else np.zeros(k)
    out.unsettled = {jn: float(d) for jn, d in zip(model.joints_, drift, strict=True)
                     if d > QUADRANT_TOL}
    # before: the n-dof fit as it is, on the same rows, without the extra columns; a paper
    # fit that had not settled is refitted on the refit's quadrants without the terms first
    # (else "after" would credit the terms with the settling); its held-out folds weighted
    # as the fit weighted its joints (WLS: not the refit's weights, which the terms move)
    xb, wb = x0, w
    if model.method == "wls" and np.shape(getattr(model, "weights_", None)) == (k,):
        wb = np.asarray(model.weights_, dtype=float)
    if out.unsettled:
        xb, _, wb = _estimate(sys, x0, free & base, linear, model.method)
    A, _, C = sys.normal(x, free, w)
    rr, _, _ = sys.residuals(x)
    n_rows = sum(rw.V.shape[0] for rw in rows)
    dof = n_rows - int(free.sum())
    if dof <= 0:
        raise RobotIdentError(f"refit_robot: {n_rows} rows for {int(free.sum())} parameters")
    sigma2 = float(sum(wj * float(r @ r) for wj, r in zip(w, rr, strict=True))) / dof
    cov = np.zeros((len(names), len(names)))
    # the estimator's covariance, as the model's fit: sigma^2 A^-1, or IV's sandwich
    cov[np.ix_(free, free)] = sys.est.normal_covariance(A, C, sigma2)
    out.coef_, out.cov_ = x, cov
    out.std_ = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    out.std_qs_ = out.std_.copy() if linear or iv else _qs_free_std(sys, x, free, w, sigma2)
    out.params_ = dict(zip(names, x.tolist(), strict=True))
    for ex, (_, t) in zip(extras, terms, strict=True):
        i = np.array(ex.pop("index"))
        ex["values"] = x[i].tolist()
        ex["std"] = out.std_[i].tolist()
        ex["std_qs"] = out.std_qs_[i].tolist()
        ex["wald"], ex["significant"] = _wald(x[i], cov[np.ix_(i, i)])
        ex["parameters"] = {}
        if hasattr(t, "parameters"):
            try:
                got = t.parameters(x[i], cov[np.ix_(i, i)])
            except (ValueError, TypeError, IndexError):
                got = {}
            ex["parameters"] = {n: (float(v[0]), float(v[1])) for n, v in got.items()}
    out.extras = extras
    out.n_rows = {model.joints_[j]: int(rw.V.shape[0]) for j, rw in enumerate(rows)}
    r0, _, _ = sys.residuals(xb)
    out.rel_error = {"before": _rel(model.joints_, r0, rows), "after": _rel(model.joints_, rr,
                                                                            rows)}
    out.noise_floor = {"before": _floors(model.joints_, r0, rows),
                       "after": _floors(model.joints_, rr, rows)}
    exp_all = np.concatenate([rw.experiment for rw in rows])
    out.heldout_kind = heldout_kind(exp_all)
    out.heldout = {"before": sys.heldout(xb, free & base, wb),
                   "after": sys.heldout(x, free, w)}
    if validation is not None:
        vsig, vpred, vkeep = validation
        if vpred is None:
            vpred = model.predict(vsig)
        vX = joint_columns(vsig, vpred, terms, revolute)
        vrows = _rows(model, vsig, vX, vkeep)  # (the errors only: no instruments)
        vsys = _System(model, vrows, ext_idx, coeffs, len(names), names)
        out.validation = {"before": _rel(model.joints_, vsys.residuals(xb)[0], vrows),
                          "after": _rel(model.joints_, vsys.residuals(x)[0], vrows)}
    return out


def _estimate(sys: _System, x0: np.ndarray, free: np.ndarray, linear: bool,
              method: str) -> tuple[np.ndarray, int, np.ndarray]:
    """The refit's estimate from x0 on the ``free`` parameters: the solve, and for WLS the
    per-joint weights 1/sigma_j^2 of that first (LS) solve and the solve again. Returns
    (x, iterations, weights)."""
    k = len(sys.rows)
    w = np.ones(k)
    x, it = sys.solve(x0, free, w, linear)
    if method == "wls":
        rr, _, _ = sys.residuals(x)
        nfree = [int(free[sys.local(j)].sum()) for j in range(k)]
        sj = np.array([math.sqrt(float(r @ r) / max(rw.V.shape[0] - b, 1))
                       for r, rw, b in zip(rr, sys.rows, nfree, strict=True)])
        if np.any(sj <= 0):
            raise RobotIdentError("refit_robot: a joint has zero residual; WLS weights "
                                  "undefined (use method='ls')")
        w = 1.0 / sj**2
        x, it = sys.solve(x, free, w, linear)
    return x, it, w


def _qs_columns(sys: _System, x: np.ndarray) -> list[np.ndarray]:
    """Per joint j, d pred_j / d q_s,j at x on its rows: sum_s P_s (V c1_s) dE/dq_s, with
    dE/dq_s = E |dq| / q_s^2 = -E ln(E) / q_s (the paper model's bilinear form)."""
    m = sys.model
    out = []
    for j, rw in enumerate(sys.rows):
        nt = m._nt(j)
        li = m._local(j)
        th, blk = x[li[:nt]], x[li[nt:]]
        if rw.Vq is not None:  # rows given whole (products at full rate): d u / d q_s
            out.append(rw.Vq @ sys.coeffs(th, blk, 0)[0])
            continue
        with np.errstate(divide="ignore", invalid="ignore"):
            dE = np.where(rw.E > 0, -rw.E * np.log(rw.E) / float(m.q_s_[j]), 0.0)
        col = np.zeros(rw.E.size)
        for s, ws in ((0, rw.pp), (1, 1.0 - rw.pp)):
            col = col + ws * dE * (rw.V @ sys.coeffs(th, blk, s)[1])
        out.append(col)
    return out


def _qs_free_std(sys: _System, x: np.ndarray, free: np.ndarray, w: np.ndarray,
                 sigma2: float) -> np.ndarray:
    """Eq. 15's standard deviations with each joint's q_s estimated too (``RobotRefit.
    std_qs_``): sigma^2 (J_q^T W J_q)^-1 on the free parameters and the joints' q_s, J_q the
    system's Jacobian at x with one more column per joint (:func:`_qs_columns`). A joint
    whose column is zero (no Stribeck term on its rows) adds nothing. The paper model's
    bilinear form, LS or WLS (``refit_robot`` gives ``std_`` itself for the others)."""
    nx, k = sys.nx, len(sys.rows)
    A = np.zeros((nx + k, nx + k))
    cols = _qs_columns(sys, x)
    has_q = np.array([bool(np.any(c != 0)) for c in cols])
    for j, qcol in enumerate(cols):
        li = sys.local(j)
        _, J = sys.joint(j, x)
        J = np.where(free[li][None, :], J, 0.0)
        idx = np.append(li, nx + j)
        Jq = np.concatenate([J, qcol[:, None]], axis=1)
        A[np.ix_(idx, idx)] += w[j] * (Jq.T @ Jq)
    fi = np.flatnonzero(np.concatenate([free, has_q]))
    Af = A[np.ix_(fi, fi)]
    d = np.sqrt(np.abs(np.diag(Af)))
    d[d == 0] = 1.0
    std = np.zeros(nx + k)
    try:  # the estimator's eq. 15 (no silent truncation: a singular matrix has no sigma)
        cov = sys.est.normal_covariance(Af / d[:, None] / d[None, :], None, sigma2)
    except np.linalg.LinAlgError:
        std[fi] = np.nan
        return std[:nx]
    std[fi] = np.sqrt(np.clip(np.diag(cov), 0.0, None)) / d
    return std[:nx]


def _wald(x: np.ndarray, cov: np.ndarray) -> tuple[float | None, bool]:
    """Wald test of a found term's coefficients against 0 inside the refit (eq. 15's
    covariance): ``W = x^T C^-1 x`` and whether it passes the chi^2(len(x)) quantile at
    ``1 - WALD_ALPHA``. A term the per-joint refinement accepted can lose its significance
    once the whole model is refitted around it; the report says so rather than keep it
    silently. ``(None, False)`` when the covariance is singular (held parameters)."""
    try:
        w = float(x @ np.linalg.solve(cov, x))
    except np.linalg.LinAlgError:
        return None, False
    if not math.isfinite(w):
        return None, False
    return w, bool(w > scipy.stats.chi2.ppf(1.0 - WALD_ALPHA, len(x)))


def _rel(joints: Sequence[str], rr: list[np.ndarray], rows: list[_Rows]) -> dict[str, float]:
    out = {}
    r2 = y2 = 0.0
    for joint, r, rw in zip(joints, rr, rows, strict=True):
        a, b = float(r @ r), float(rw.tau @ rw.tau)
        out[joint] = math.sqrt(a / b) if b > 0 else math.nan
        r2, y2 = r2 + a, y2 + b
    out["all"] = math.sqrt(r2 / y2) if y2 > 0 else math.nan
    return out


def _floors(joints: Sequence[str], rr: list[np.ndarray], rows: list[_Rows]) -> dict[str, float]:
    """Per joint :func:`ident.unseen.noise_floor`; ``all``: their quadratic mean weighted by
    ||tau_j||^2 (the floor of the stacked residual)."""
    out = {}
    num = den = 0.0
    for joint, r, rw in zip(joints, rr, rows, strict=True):
        f = noise_floor(r, rw.tau, rw.experiment)
        out[joint] = f
        y2 = float(rw.tau @ rw.tau)
        if np.isfinite(f):
            num, den = num + f * f * y2, den + y2
    out["all"] = math.sqrt(num / den) if den > 0 else math.nan
    return out


def _full_rate(model: Any) -> bool:
    """Whether ``model`` was fitted on the products formed at full rate (its rows given
    whole: :meth:`~ident.robot.estimate.RobotModel.products_rows`)."""
    return bool(getattr(model, "full_rate_products_", False))


def _coefficients(model: Any) -> Any:
    """The coefficient function of the model's rows (:mod:`ident.robot.paper`): the model's
    own, or :func:`~ident.robot.paper.rows_coefficients` on full-rate products."""
    return rows_coefficients if _full_rate(model) else model._coefficients


def _extra_instruments(signals: RobotSignals, pred: np.ndarray,
                       terms: Sequence[tuple[int, Term]], revolute: Sequence[bool] | None,
                       X: list[np.ndarray]) -> list[np.ndarray]:
    """The IDIM-IV instruments of the extra columns, by the single-joint rule
    (:meth:`ident.preprocess.Design.with_term`): a term's columns are their own instruments
    unless they read the acceleration; those are evaluated again with the reference's
    acceleration instead of the measured one -- here d^2 q_ref / dt^2 of the signals'
    (decimated) ``q_ref`` by central differences per experiment, as the model's states chain
    forms its instruments (:func:`~ident.robot.estimate._ref_acceleration`). Without
    ``q_ref`` a term that reads the acceleration is refused (one line)."""
    if signals.q_ref is not None:
        zdd = np.empty_like(signals.ddq)
        for e in np.unique(signals.experiment):
            m = signals.experiment == e
            zdd[m] = _ref_acceleration(signals.t[m], signals.q_ref[m])
        return joint_columns(replace(signals, ddq=zdd), pred, terms, revolute)
    # which terms read the acceleration: their columns move with another ddq
    other = replace(signals, ddq=2.0 * signals.ddq + 1.0)
    for j, t in terms:
        a = joint_columns(signals, pred, [(j, t)], revolute)[j]
        b = joint_columns(other, pred, [(j, t)], revolute)[j]
        if not np.array_equal(a, b):
            raise RobotIdentError(f"refit_robot: term {t.effect} ({', '.join(t.names())}) of "
                                  f"joint {signals.joints[j]} reads the acceleration, and its "
                                  "IDIM-IV instruments need the reference's: signals without "
                                  "q_ref")
    return X


def _rows(model: Any, signals: RobotSignals, X: list[np.ndarray],
          keep: np.ndarray | None, Xz: list[np.ndarray] | None = None,
          qs_deriv: bool = False) -> list[_Rows]:
    """Every joint's rows of the stacked system, as the model's own pass selects them; with
    ``Xz`` (IDIM-IV) their instruments too: the model's own (:meth:`RobotModel._pass`'s
    ``Wz``, ``pz``; the products' ``loads_z``) and ``Xz``. The bilinear paper model fitted
    on its products formed at full rate (``full_rate_paper_``) reads them again
    (:meth:`~ident.robot.estimate.RobotModel.full_rate_signals`, at its ``q_s_``), with
    ``qs_deriv`` their derivative in each joint's q_s too (``std_qs_``)."""
    k = len(model.joints_)
    if keep is None and signals.columns is not None:
        keep = signals.columns.keep
    if keep is not None:
        keep = np.asarray(keep, dtype=bool)
        if keep.shape != signals.tau.shape:
            raise RobotIdentError(f"refit_robot: keep of shape {keep.shape}, expected "
                                  f"{signals.tau.shape}")
    if _full_rate(model):
        return _product_rows(model, signals, X, keep, Xz)
    psig = model.full_rate_signals(signals) if hasattr(model, "full_rate_signals") else None
    if psig is not None:
        return _bilinear_rows(model, psig, X, keep, Xz, qs_deriv)
    # the theta that decided the fit's quadrants (products form: the usual fit's, as predict)
    theta_q = model.coef_[:model.n_theta_] if model._theta_x else model.quadrant_from_
    if model.quadrant_theta_ is not None:
        theta_q = model.quadrant_theta_
    parts = _parts(k)
    iv = Xz is not None
    for r, j, cols, WjT, pj, dqj, tauj, sg, *z in model._fitted_rows(signals, "refit_robot",
                                                                      instruments=iv):
        idx = np.arange(signals.n)[r]
        # the fit's row rule (RobotModel.fitted_rows: its band decided by the theta that
        # decided the final quadrants, so the "before" error is the fit's)
        ok = model._row_rule(j, cols, WjT, pj, dqj, tauj, None if keep is None else keep[idx, j])
        V = model._v(WjT, pj, dqj, np.zeros(dqj.size), sg).T
        if model.model == "paper" and (model.quadrant == "model"):
            sp = (theta_q[cols] @ WjT + pj) * dqj
        elif model.model == "paper":
            sp = tauj * dqj
        else:
            sp = np.ones(dqj.size)
        p = parts[j]
        p["idx"].append(idx[ok])
        p["V"].append(V[ok])
        p["pp"].append(quadrant_weights(sp[ok])[0])
        p["E"].append(stribeck_exp(dqj[ok], model.q_s_[j]))
        p["tau"].append(tauj[ok])
        if iv:  # the instruments' rows: Wz, pz with the same sign, dq, 1 (as _pass)
            (WzT, pzj), = z
            p["Vz"].append(model._v(WzT, pzj, dqj, np.zeros(dqj.size), sg).T[ok])
    return _assemble(parts, [len(c) + 5 for c in model.cols_], signals, X, Xz)


def _product_rows(model: Any, signals: RobotSignals, X: list[np.ndarray],
                  keep: np.ndarray | None, Xz: list[np.ndarray] | None = None) -> list[_Rows]:
    """The rows of a products-form fit on the full-rate products, as the fit read them
    (:meth:`~ident.robot.estimate.RobotModel.products_rows`: the columns and the row rule
    of the model's own pass, ``keep`` too when given): V = [u, 0] (the tau slot of
    :func:`~ident.robot.paper.rows_coefficients`), one quadrant slot (P+ = 1, P- = 0, E = 0): the
    quadrants are in the products already. With ``Xz`` (IDIM-IV) Vz = [u_z, 0], the
    instruments' rows of the fit (``products_rows(..., instruments=True)``)."""
    parts = _parts(len(model.joints_))
    iv = Xz is not None
    for r, j, U, ok, *z in model.products_rows(signals, instruments=iv):
        idx = np.arange(signals.n)[r]
        p = parts[j]
        ok = _add_product_rows(p, idx, U, ok, keep, j)
        if iv:
            p["Vz"].append(_tau_slot(z[0][:, ok].T))
        p["tau"].append(signals.tau[idx[ok], j])
    return _assemble(parts, [int(b) + 1 for b in model._bsize], signals, X, Xz)


def _tau_slot(V: np.ndarray) -> np.ndarray:
    """``V`` (m, p) with the zero tau slot of :func:`~ident.robot.paper.rows_coefficients`
    appended: (m, p + 1)."""
    return np.concatenate([V, np.zeros((V.shape[0], 1))], axis=1)


def _add_product_rows(p: dict, idx: np.ndarray, U: np.ndarray, ok: np.ndarray,
                      keep: np.ndarray | None, j: int) -> np.ndarray:
    """Append one chunk's kept rows of products of joint ``j`` (``U`` (p, rows), ``ok`` the
    fit's kept ones, and ``keep[idx, j]`` too when given) to its part ``p``: V = [u, 0], one
    quadrant slot P+ = 1, E = 0 (the quadrants, and E, are in the products already);
    returns the rows kept."""
    if keep is not None:
        ok = ok & keep[idx, j]
    m = int(ok.sum())
    p["idx"].append(idx[ok])
    p["V"].append(_tau_slot(U[:, ok].T))
    p["pp"].append(np.ones(m))
    p["E"].append(np.zeros(m))
    return ok


def _bilinear_rows(model: Any, psig: RobotSignals, X: list[np.ndarray],
                   keep: np.ndarray | None, Xz: list[np.ndarray] | None,
                   qs_deriv: bool) -> list[_Rows]:
    """The rows of the bilinear paper model fitted on its products formed at full rate, as
    the fit read them (``psig``: the signals carrying them, its row rule and ``keep``): V =
    [u, 0] in :func:`~ident.robot.paper.products_names`'s order, one quadrant slot (P+ = 1,
    E = 0: the quadrants and E are in the products), the coefficients
    :func:`~ident.robot.paper.bilinear_rows_coefficients`. With ``qs_deriv`` each row's
    d u / d q_s,j by central differences (relative step ``QS_STEP``; joint j's products
    depend on its own q_s only, so two formations serve every joint)."""
    parts = _parts(len(model.joints_))
    iv = Xz is not None
    dU = None
    if qs_deriv:
        up, dn = copy.copy(model), copy.copy(model)
        up.q_s_ = np.asarray(model.q_s_, dtype=float) * (1.0 + QS_STEP)
        dn.q_s_ = np.asarray(model.q_s_, dtype=float) * (1.0 - QS_STEP)
        sig_up, sig_dn = up.full_rate_signals(psig), dn.full_rate_signals(psig)
        if sig_up is not None and sig_dn is not None:
            dU = (sig_up, sig_dn, 2.0 * QS_STEP * np.asarray(model.q_s_, dtype=float))
    for r, j, fr, dqj, tauj, U, ok in model._row_chunks(psig):
        idx = np.arange(psig.n)[r]
        p = parts[j]
        ok = _add_product_rows(p, idx, U, ok, keep, j)
        if iv:
            p["Vz"].append(_tau_slot(model._row_block(fr, j, dqj, iv=True)[:, ok].T))
        if dU is not None:
            a = model._row_block(dU[0].columns.products.take(r), j, dqj)
            b = model._row_block(dU[1].columns.products.take(r), j, dqj)
            p["Vq"].append(_tau_slot(((a - b)[:, ok] / dU[2][j]).T))
        p["tau"].append(tauj[ok])
    return _assemble(parts, [int(b) + 1 for b in _widths(model)], psig, X, Xz)


def _widths(model: Any) -> list[int]:
    """Per joint, the width of the products' rows u (:func:`~ident.robot.paper.
    products_size` of its base columns)."""
    return [4 * (len(c) + 1) + 6 for c in model.cols_]


def _parts(k: int) -> list[dict[str, list[np.ndarray]]]:
    """Per joint, the chunks of its rows' fields (:class:`_Rows`) as a pass collects them."""
    return [{n: [] for n in ("idx", "V", "pp", "E", "tau", "Vz", "Vq")} for _ in range(k)]


def _assemble(parts: list[dict[str, list[np.ndarray]]], nv: Sequence[int],
              signals: RobotSignals, X: list[np.ndarray],
              Xz: list[np.ndarray] | None) -> list[_Rows]:
    """Each joint's :class:`_Rows` from its collected chunks (``nv[j]``: the width of its V,
    for a joint without rows), the extra columns ``X`` (and their instruments ``Xz``) on
    those rows."""
    def cat(chunks: list[np.ndarray], empty: tuple[int, ...], dtype: type = float
            ) -> np.ndarray:
        return np.concatenate(chunks) if chunks else np.zeros(empty, dtype=dtype)

    out = []
    for j, p in enumerate(parts):
        idx = cat(p["idx"], (0,), int)
        out.append(_Rows(idx=idx, V=cat(p["V"], (0, nv[j])), pp=cat(p["pp"], (0,)),
                         E=cat(p["E"], (0,)), X=X[j][idx], tau=cat(p["tau"], (0,)),
                         experiment=signals.experiment[idx],
                         Vz=None if Xz is None else cat(p["Vz"], (0, nv[j])),
                         Xz=None if Xz is None else Xz[j][idx],
                         Vq=cat(p["Vq"], (0, nv[j])) if p["Vq"] else None))
    return out


class _System:
    """The stacked system: per joint the model's prediction and Jacobian plus X_j e_j."""

    def __init__(self, model: Any, rows: list[_Rows], ext_idx: list[list[int]], coeffs: Any,
                 nx: int, names: Sequence[str]) -> None:
        self.model, self.rows, self.ext_idx, self.coeffs = model, rows, ext_idx, coeffs
        self.nx, self.names = nx, list(names)
        # the model's estimator (its rank rule, covariance); IDIM-IV when the rows carry
        # instruments (the validation rows never do: their errors only)
        self.est = get_estimator(model.method if rows and rows[0].Vz is not None else "ls")

    def local(self, j: int) -> np.ndarray:
        return np.concatenate([self.model._local(j), np.asarray(self.ext_idx[j], dtype=int)])

    def joint(self, j: int, x: np.ndarray, jac: bool = True, instruments: bool = False):
        """Residual (m,) and Jacobian (m, n_local) of joint j at x; ``instruments``: also
        the instruments' Jacobian Z (m, n_local), the same coefficients on the rows' ``Vz``
        and ``Xz`` (what the model's IV moments sum: Z^T J, Z^T Z)."""
        m, rw = self.model, self.rows[j]
        li = m._local(j)
        nt = m._nt(j)  # (products form: no theta)
        th, blk = x[li[:nt]], x[li[nt:]]
        e = x[np.asarray(self.ext_idx[j], dtype=int)]
        pred = rw.X @ e
        J = Z = None
        parts, zparts = [], []
        for s, ws in ((0, rw.pp), (1, 1.0 - rw.pp)):
            c0, c1, D0, D1 = self.coeffs(th, blk, s)
            pred = pred + ws * (rw.V @ c0 + rw.E * (rw.V @ c1))
            if jac:
                parts.append(ws[:, None] * (rw.V @ D0 + rw.E[:, None] * (rw.V @ D1)))
            if instruments:
                zparts.append(ws[:, None] * (rw.Vz @ D0 + rw.E[:, None] * (rw.Vz @ D1)))
        if jac:
            J = np.concatenate([parts[0] + parts[1], rw.X], axis=1)
        if instruments:
            Z = np.concatenate([zparts[0] + zparts[1], rw.Xz], axis=1)
        return (rw.tau - pred, J, Z) if instruments else (rw.tau - pred, J)

    def residuals(self, x: np.ndarray):
        rr = [self.joint(j, x, jac=False)[0] for j in range(len(self.rows))]
        return rr, None, None

    def normal(self, x: np.ndarray, free: np.ndarray, w: np.ndarray):
        """A = J^T W J, g = J^T W r (LS, WLS), or Z^T J, Z^T r and C = Z^T Z (IDIM-IV; C
        None otherwise), on the free parameters."""
        A = np.zeros((self.nx, self.nx))
        g = np.zeros(self.nx)
        iv = self.est.needs_instruments
        C = np.zeros((self.nx, self.nx)) if iv else None
        for j in range(len(self.rows)):
            li = self.local(j)
            if iv:
                r, J, Z = self.joint(j, x, instruments=True)
                A[np.ix_(li, li)] += w[j] * (Z.T @ J)
                g[li] += w[j] * (Z.T @ r)
                C[np.ix_(li, li)] += w[j] ** 2 * (Z.T @ Z)
                continue
            r, J = self.joint(j, x)
            A[np.ix_(li, li)] += w[j] * (J.T @ J)
            g[li] += w[j] * (J.T @ r)
        return A[np.ix_(free, free)], g[free], None if C is None else C[np.ix_(free, free)]

    def _step(self, A: np.ndarray, g: np.ndarray, free: np.ndarray) -> np.ndarray:
        """Gauss-Newton step on the column-scaled normal equations, through the model's
        estimator's ``solve_normal`` (the one rank rule, :data:`ident.estimators.RCOND`; the
        weights are already in A and g; IDIM-IV: A = Z^T J, not symmetric)."""
        d = np.sqrt(np.abs(np.diag(A)))
        zero = d == 0
        if zero.any():
            bad = [self.names[i] for i in np.flatnonzero(free)[zero]]
            raise RobotIdentError(f"refit_robot: parameters {bad} have no excitation on the "
                                  "rows used (zero columns)")
        names = [self.names[i] for i in np.flatnonzero(free)]
        try:
            sol = self.est.solve_normal(A / d[:, None] / d[None, :], g / d, names)
        except RankDeficientError as e:
            raise RobotIdentError(f"refit_robot: with the extra terms, {e}") from None
        step = np.zeros(free.size)
        step[free] = sol / d
        return step

    def cost(self, x: np.ndarray, w: np.ndarray) -> float:
        rr, _, _ = self.residuals(x)
        return float(sum(wj * float(r @ r) for wj, r in zip(w, rr, strict=True)))

    def solve(self, x0: np.ndarray, free: np.ndarray, w: np.ndarray,
              linear: bool) -> tuple[np.ndarray, int]:
        x = x0.copy()
        cost = self.cost(x, w)
        it = 0
        while it < MAX_ITER:
            it += 1
            A, g, _ = self.normal(x, free, w)
            step = self._step(A, g, free)
            lam = 1.0
            while True:  # IDIM-IV minimises no cost: full steps (as the model's fit)
                xn = x + lam * step
                cn = self.cost(xn, w)
                if (linear or not self.est.symmetric or cn <= cost * (1 + 1e-12)
                        or lam < 1e-6):
                    break
                lam *= 0.5
            x, cost = xn, cn
            scale = np.sqrt(np.abs(np.diag(A)))
            if linear or np.linalg.norm(lam * step[free] * scale) <= TOL * max(
                    np.linalg.norm(x[free] * scale), 1e-300):
                break
        return x, it

    def heldout(self, x: np.ndarray, free: np.ndarray, w: np.ndarray) -> dict[str, float]:
        """Relative error per joint (and ``all``) of each fold predicted by the fit on the
        others (linearised at x; exact for the usual model at its LS solution), folds as
        :func:`ident.unseen.heldout_error`'s."""
        k = len(self.rows)
        exp_all = np.concatenate([rw.experiment for rw in self.rows])
        runs = np.unique(exp_all)
        per_run = runs.size >= 2
        folds = []
        for rw in self.rows:
            if per_run:
                folds.append(np.searchsorted(runs, rw.experiment))
            else:  # contiguous blocks of the single run, by sample index
                n = 1 + max(int(r.idx.max(initial=0)) for r in self.rows)
                folds.append(np.minimum(rw.idx * N_BLOCKS // n, N_BLOCKS - 1))
        fvals = np.unique(np.concatenate(folds))
        res, jacs = [], []
        A = np.zeros((self.nx, self.nx))
        g = np.zeros(self.nx)
        Af = {f: np.zeros((self.nx, self.nx)) for f in fvals}
        gf = {f: np.zeros(self.nx) for f in fvals}
        for j in range(k):
            r, J = self.joint(j, x)
            li = self.local(j)
            keep_cols = free[li]
            J = np.where(keep_cols[None, :], J, 0.0)
            res.append(r)
            jacs.append((li, J))
            A[np.ix_(li, li)] += w[j] * (J.T @ J)
            g[li] += w[j] * (J.T @ r)
            for f in fvals:
                m = folds[j] == f
                if m.any():
                    Jm = J[m]
                    Af[f][np.ix_(li, li)] += w[j] * (Jm.T @ Jm)
                    gf[f][li] += w[j] * (Jm.T @ r[m])
        d = np.sqrt(np.abs(np.diag(A)))
        d[d == 0] = 1.0
        out_r = [np.array(r, copy=True) for r in res]
        for f in fvals:
            G = (A - Af[f]) / d[:, None] / d[None, :]
            step = np.linalg.lstsq(G, (g - gf[f]) / d, rcond=1e-10)[0] / d
            for j in range(k):
                m = folds[j] == f
                if m.any():
                    li, J = jacs[j]
                    out_r[j][m] = res[j][m] - J[m] @ step[li]
        return _rel(self.model.joints_, out_r, self.rows)


def model_at_qs(model: Any, q_s: float, joints: Sequence[str] | None = None) -> Any:
    """The fitted n-dof ``model`` with the velocity constant of ``joints`` (default every
    joint) set to ``q_s`` [rad/s], its estimates unchanged: what :func:`refit_robot` refits
    at another q_s (the paper model's E = exp(-|dq|/q_s) on the fit's rows, or, on the
    full-rate products, the products formed at that q_s, which the model's check then
    accepts). A shallow copy: ``model`` itself is not changed.

    Raises
    ------
    RobotIdentError
        A joint not of the model, or q_s not positive and finite.
    """
    model._check_fitted()
    q = float(q_s)
    if not (math.isfinite(q) and q > 0):
        raise RobotIdentError(f"model_at_qs: q_s must be a positive velocity [rad/s], got "
                              f"{q_s}")
    names = tuple(model.joints_)
    unknown = [j for j in (joints or ()) if j not in names]
    if unknown:
        raise RobotIdentError(f"model_at_qs: joints {unknown} are not the model's {names}")
    out = copy.copy(model)
    qs = np.array(model.q_s_, dtype=float)
    qs[[names.index(j) for j in (names if joints is None else joints)]] = q
    out.q_s_ = qs
    return out
