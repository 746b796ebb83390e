"""Physically consistent estimate of a fitted n-dof model (a convex LMI fit, cvxpy + Clarabel).

The free fit (:class:`~ident.robot.estimate.RobotModel`) gives base parameters theta_hat with
covariance C; nothing forces them to be the regrouping ``beta chi_St`` of physical links
(:mod:`ident.robot.consistency` only says whether some are within the uncertainty). This
module finds the standard parameters chi_St that

* make every moving link physically consistent: pseudo-inertia (Wensing, Kim & Slotine 2017)
  ``J_j = [[tr(I_j)/2 1_3 - I_j, h_j], [h_j^T, m_j]] >= MARGIN 1_4`` (I_j inertia about the
  joint-frame origin, h_j = m_j c_j the first moments, m_j the mass: mass > 0, inertia about the
  centre of mass positive definite and the triangle inequalities) and rotor inertia
  Ia_j >= MARGIN (fixed at the robot file's value when the rotor inertias are known);
* are closest to the free fit in the metric of its uncertainty: minimise the Mahalanobis
  distance ``d^2 = (beta chi - theta_hat)^T M (beta chi - theta_hat)``;
* among those, are closest to the robot file's (CAD) values ``chi_0`` in the directions the data
  do not see: the term ``PRIOR_WEIGHT ||(chi - chi_0) / s||^2`` (s = max(|chi_0|, median
  |theta_hat|); the completion of the unidentifiable standard parameters; minimum norm when the
  robot file has no inertias).

The problem is a semidefinite program (one 4x4 LMI per link), convex, solved to its global
optimum by Clarabel (no starts, no local minima, unlike the Cholesky-factor search of
:func:`~ident.robot.consistency.check_consistency`). Its matrices are handed to Clarabel
directly: built through cvxpy the same program took ~0.15-0.4 s of canonicalisation a model
(and cvxpy's import) against ~0.01 s for the solve (7 links); cvxpy remains the way to the
other solvers (``solver="SCS"``, or ``"cvxpy-clarabel"`` for Clarabel through cvxpy).

Friction (``friction=``):

* ``"profile"`` (default for the usual model, where the fit is linear): the friction and offset
  parameters follow theta by their regression on it,
  ``x_F = x_F_hat + C_F,theta C_theta,theta^-1 (theta - theta_hat)``, and ``M = C_theta,theta^-1``:
  this is exactly the least-squares fit constrained to consistent links (the sum of the weighted
  squared residuals grows by sigma^2 d^2).
* ``"fixed"`` (default for the paper model, bilinear in theta and friction): the friction is the
  free fit's and ``M = (C^-1)_theta,theta`` (the curvature in theta at fixed friction); the model
  is linear in theta at fixed friction, so sigma^2 d^2 is again exactly the growth of the weighted
  sum of squares.

The cost of consistency is reported as ``d2`` against the 99 % chi-square quantile (the estimate
"stays within the data's uncertainty" when below), as the predicted relative growth of the
weighted residual sum of squares ``d2 / dof``, and, when signals are given, as the measured
relative errors ||rho|| / ||tau|| before and after.

(Past 600 lines: one semidefinite program, built once and handed to Clarabel directly or
through cvxpy -- the two builders side by side so that they stay the same program --, with its
friction profile, its measured errors and the record ``jointid export-model`` reads
(:func:`consistent_record`).)
"""

from __future__ import annotations

import copy
import time
import warnings
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import scipy.linalg
import scipy.stats

from . import RobotIdentError
from .friction_bounds import bound_rows, met
from .paper import require_theta

__all__ = ["ConsistentFit", "fit_consistent", "consistent_model", "link_validity",
           "consistent_record", "format_record", "add_consistent", "MARGIN", "PRIOR_WEIGHT"]

#: Pseudo-inertia lower bound J >= MARGIN 1_4 [kg, kg m^2]: strict physical consistency
#: (mass > 0, inertia about the CoM positive definite) without changing any fit visibly.
MARGIN = 1e-6
#: Weight of the pull towards the robot file's standard values, relative to d^2 (in units of
#: the free fit's variances): it raises d^2 by at most PRIOR_WEIGHT ||(chi_d - chi_0) / s||^2
#: (chi_d: the distance-optimal set), far below one variance.
PRIOR_WEIGHT = 1e-6
_LINK = 11  # XX XY XZ YY YZ ZZ MX MY MZ M Ia


@dataclass
class ConsistentFit:
    """Result of :func:`fit_consistent`.

    Attributes
    ----------
    names : tuple of str
        The free fit's parameter names (``RobotModel.names_``).
    coef : ndarray
        The consistent estimate in ``names`` order (base parameters = beta chi_St).
    standard : dict
        Standard parameters name -> value (``XX{j}`` ... ``M{j}``, ``Ia{j}``; about the joint
        frame origin, ROBOT_FORMAT), every link physically consistent.
    friction : {"profile", "fixed"}
        How the friction parameters were treated (module doc).
    d2, d2_limit : float
        Mahalanobis distance of the consistent base set from the free fit and the 99 %
        chi-square quantile (number of free theta entries).
    cost_ratio : float
        Predicted relative growth of the weighted residual sum of squares, d2 / dof.
    rel_error_before, rel_error_after : dict
        ||rho_j|| / ||tau_j|| and "all" of the free and of the consistent model on the
        fitted rows of the signals given (empty when none were).
    links : list of dict
        :func:`link_validity` of the consistent standard set.
    solve_s : float
        Wall time of the convex solve [s]; ``solver`` its name and ``status`` cvxpy's status
        names ("optimal", "optimal_inaccurate"; Clarabel's Solved / AlmostSolved).
    friction_violated : tuple of str
        The friction bounds (:mod:`ident.robot.friction_bounds`) the friction violated after
        the links were made consistent (empty: the friction was kept as it was).
    friction_moved : tuple of str
        The friction parameters the projection onto those bounds changed.
    friction_d2 : float
        What the projection added to the Mahalanobis distance from the free fit (in the
        metric of all the free parameters, theta held).
    friction_left : tuple of str
        Bounds still violated: those on parameters held fixed (pruned), which no projection
        can move.
    """

    names: tuple[str, ...]
    coef: np.ndarray
    standard: dict[str, float]
    friction: str
    d2: float
    d2_limit: float
    cost_ratio: float
    rel_error_before: dict[str, float] = field(default_factory=dict)
    rel_error_after: dict[str, float] = field(default_factory=dict)
    links: list[dict[str, Any]] = field(default_factory=list)
    solve_s: float = float("nan")
    solver: str = ""
    status: str = ""
    friction_violated: tuple[str, ...] = ()
    friction_moved: tuple[str, ...] = ()
    friction_d2: float = 0.0
    friction_left: tuple[str, ...] = ()

    @property
    def within_uncertainty(self) -> bool:
        """d2 below the 99 % chi-square quantile."""
        return bool(self.d2 <= self.d2_limit)

    @property
    def valid(self) -> bool:
        """Every link physically consistent (:func:`link_validity`) and every friction bound
        met."""
        return all(lk["valid"] for lk in self.links) and not self.friction_left

    def format(self) -> str:
        """Plain-text summary (:func:`format_record` of its record's fields)."""
        return format_record({
            "solver": self.solver, "solve_s": self.solve_s, "friction": self.friction,
            "valid": self.valid, "d2": self.d2, "d2_limit": self.d2_limit,
            "within_uncertainty": self.within_uncertainty, "cost_ratio": self.cost_ratio,
            "friction_bounds": {"violated": list(self.friction_violated),
                                "moved": list(self.friction_moved), "d2": self.friction_d2,
                                "still_violated": list(self.friction_left)},
            "rel_error_before": self.rel_error_before, "rel_error_after": self.rel_error_after})


def format_record(rec: Any) -> str:
    """Plain-text summary of a consistent estimate's record (:func:`consistent_record`, the
    ``consistent`` block of ``jointid fit --robot --consistent``), as ``jointid fit`` prints
    it."""
    lines = [f"Consistent estimate (LMI fit, {rec['solver']}, {rec['solve_s']:.3g} s, friction "
             f"{rec['friction']}): every link physically valid and every friction bound met: "
             f"{'yes' if rec['valid'] else 'NO'}",
             f"  links: distance from the free fit d^2 = {rec['d2']:.4g} (99 % limit "
             f"{rec['d2_limit']:.4g}: {'within' if rec['within_uncertainty'] else 'OUTSIDE'} "
             f"its uncertainty); weighted residual sum of squares +{100 * rec['cost_ratio']:.3g}"
             " %"]
    fb = rec.get("friction_bounds") or {}
    if fb.get("violated"):
        lines.append(f"  friction bounds violated by the free friction: "
                     f"{', '.join(fb['violated'])}; moved onto them: "
                     f"{', '.join(fb['moved']) or 'none'} (d^2 {fb['d2']:+.4g})" + (
                         f"; still violated (fixed parameters): "
                         f"{', '.join(fb['still_violated'])}" if fb.get("still_violated")
                         else ""))
    before, after = rec.get("rel_error_before") or {}, rec.get("rel_error_after") or {}
    if before and after:
        b, a = before["all"], after["all"]
        lines.append(f"  relative error ||rho|| / ||tau||: free {100 * b:.4f} %, consistent "
                     f"{100 * a:.4f} % (x {a / b:.4f})")
    return "\n".join(lines)


def _pseudo_inertia(p: Any) -> list[list[Any]]:
    """4x4 pseudo-inertia of a link from its 10 standard parameters (XX XY XZ YY YZ ZZ MX MY
    MZ M, about the origin): Sigma = tr(I)/2 1 - I, linear in the parameters (numpy or cvxpy)."""
    xx, xy, xz, yy, yz, zz, mx, my, mz, m = (p[i] for i in range(10))
    half = 0.5 * (xx + yy + zz)
    return [[half - xx, -xy, -xz, mx],
            [-xy, half - yy, -yz, my],
            [-xz, -yz, half - zz, mz],
            [mx, my, mz, m]]


def link_validity(standard: np.ndarray, k: int, tol: float = 0.0) -> list[dict[str, Any]]:
    """Physical checks of k links' standard parameters (11 per link, ROBOT_FORMAT order).

    Returns, per link: ``mass`` [kg], ``min_eig_J`` (pseudo-inertia), ``min_eig_Ic`` (inertia
    about the CoM) [kg m^2], ``triangle`` (smallest of I1 + I2 - I3 over the principal moments
    about the CoM) [kg m^2], ``Ia`` and ``valid`` (mass > tol, both eigenvalues > -tol,
    triangle >= -tol, Ia >= -tol)."""
    out = []
    chi = np.asarray(standard, dtype=float)
    for j in range(k):
        p = chi[_LINK * j:_LINK * (j + 1)]
        J = np.array(_pseudo_inertia(p), dtype=float)
        m = float(p[9])
        i_o = np.array([[p[0], p[1], p[2]], [p[1], p[3], p[4]], [p[2], p[4], p[5]]])
        if m > 0:
            c = p[6:9] / m
            i_c = i_o - m * (float(c @ c) * np.eye(3) - np.outer(c, c))
        else:
            i_c = i_o
        ev = np.sort(np.linalg.eigvalsh(i_c))
        tri = float(ev[0] + ev[1] - ev[2])
        eig_j = float(np.linalg.eigvalsh(J).min())
        out.append({"mass": m, "min_eig_J": eig_j, "min_eig_Ic": float(ev[0]),
                    "triangle": tri, "Ia": float(p[10]),
                    "valid": bool(m > tol and eig_j > -tol and ev[0] > -tol and tri >= -tol
                                  and p[10] >= -tol)})
    return out


def _inv_spd(a: np.ndarray) -> np.ndarray:
    d = np.sqrt(np.diag(a))
    s = a / d[:, None] / d[None, :]
    return scipy.linalg.inv(s, check_finite=True) / d[:, None] / d[None, :]


def fit_consistent(model: Any, signals: Any = None, *, friction: str | None = None,
                   prior: np.ndarray | None = None, solver: str = "CLARABEL",
                   tau_peak: Any = None) -> ConsistentFit:
    """Physically consistent estimate of a fitted :class:`~ident.robot.estimate.RobotModel`
    (module doc).

    Parameters
    ----------
    model : RobotModel
        Fitted (usual or paper model).
    signals : RobotSignals or sequence, optional
        Data to measure the relative errors of the free and the consistent model on (the fit
        data: ``rel_error_before`` / ``rel_error_after``), on the rows the fit used
        (``RobotModel.fitted_rows``: the free model's error is then its fit's, when its
        quadrants settled).
    friction : {"profile", "fixed"} or None
        None: "profile" for the usual model, "fixed" for the paper model.
    prior : ndarray (11 k,), optional
        Standard values the unidentifiable directions are pulled to; default the robot file's
        (``RobotRegressor.standard_values()``).
    solver : str
        "CLARABEL" (direct), "cvxpy-clarabel" (Clarabel through cvxpy), or another cvxpy
        solver name ("SCS").
    tau_peak : array_like, shape (k,), optional
        The largest measured |tau| of each joint [N m]
        (:func:`~ident.robot.friction_bounds.torque_peak` of the identification data): the
        static friction is also kept below it (:data:`~ident.robot.friction_bounds.PEAK_BOUNDS`).

    Returns
    -------
    ConsistentFit
    """
    if not hasattr(model, "coef_"):
        raise RobotIdentError("fit_consistent: the RobotModel is not fitted")
    if getattr(model, "quadrants", "hard") == "soft":
        raise RobotIdentError("fit_consistent: the model was fitted with soft quadrants "
                              "(quadrants='soft'); the consistent estimate and the exported "
                              "friction use hard quadrants")
    require_theta(model, "fit_consistent")
    if friction is None:
        friction = "profile" if model.model == "usual" else "fixed"
    if friction not in ("profile", "fixed"):
        raise RobotIdentError(f"fit_consistent: friction {friction!r}: expected 'profile' or "
                              "'fixed'")
    base = model.base_
    beta = np.asarray(base.beta, dtype=float)
    std_names = tuple(base.standard_names)
    p = len(std_names)
    k = p // _LINK
    if p != _LINK * k:
        raise RobotIdentError("fit_consistent: the base parameters decompose friction columns "
                              "too; expected 11 standard parameters per link")
    nb, nt = int(model.n_base_), int(model.n_theta_)
    x_hat = np.asarray(model.coef_, dtype=float)
    cov = np.asarray(model.cov_, dtype=float)
    free = np.diag(cov) > 0
    theta_idx = np.flatnonzero(free[:nt])
    other = np.flatnonzero(free & (np.arange(x_hat.size) >= nt))
    allf = np.flatnonzero(free)
    if friction == "profile":
        metric = _inv_spd(cov[np.ix_(theta_idx, theta_idx)])
    else:
        prec = _inv_spd(cov[np.ix_(allf, allf)])
        pos = np.searchsorted(allf, theta_idx)
        metric = prec[np.ix_(pos, pos)]
    metric = 0.5 * (metric + metric.T)
    sd = np.sqrt(np.diag(cov)[theta_idx])
    ms = metric * sd[:, None] * sd[None, :]  # metric on theta / std
    w, v = np.linalg.eigh(ms)
    root = (v * np.sqrt(np.clip(w, 0.0, None))).T  # root^T root = ms

    reg = model.regressor_
    if prior is None:
        prior = np.asarray(reg.standard_values(), dtype=float)
    prior = np.asarray(prior, dtype=float).reshape(-1)
    if prior.shape != (p,):
        raise RobotIdentError(f"fit_consistent: prior: expected {p} standard values, got "
                              f"{prior.shape}")
    known = np.asarray(getattr(reg, "known_Ia", np.zeros(k)), dtype=float)

    # variables scaled by the typical size of the base parameters (a 1 t robot and a 1 kg arm
    # alike give the conic solver numbers near 1)
    scale = max(float(np.median(np.abs(x_hat[:nb]))), 1e-2)
    ps = np.maximum(np.abs(prior), scale)
    t0 = time.perf_counter()
    if solver.upper() == "CLARABEL":
        z_v, extra_v, status = _solve_clarabel(
            beta, scale, nt - nb, theta_idx, x_hat[theta_idx] / sd, root, sd, prior, ps,
            known, k)
    else:  # "cvxpy-clarabel": Clarabel through cvxpy (the same program, canonicalised)
        z_v, extra_v, status = _solve_cvxpy(
            beta, scale, nt - nb, theta_idx, x_hat[theta_idx] / sd, root, sd, prior, ps,
            known, k, "CLARABEL" if solver.lower() == "cvxpy-clarabel" else solver)
    if status != "optimal" and not all(lk["valid"] for lk in link_validity(scale * z_v, k)):
        raise RobotIdentError(f"fit_consistent: solver {solver}: status {status}, and the "
                              "links it gives are not all physically valid")
    solve_s = time.perf_counter() - t0
    chi_v = scale * z_v
    coef = x_hat.copy()
    coef[:nb] = beta @ chi_v
    if extra_v is not None:
        coef[nb:nt] = extra_v
    return _finish(model, signals, friction, solver, status, solve_s, chi_v, coef, cov,
                   metric, theta_idx, other, free, std_names, k, tau_peak)


def _solve_cvxpy(beta: np.ndarray, scale: float, n_extra: int, theta_idx: np.ndarray,
                 r0: np.ndarray, root: np.ndarray, sd: np.ndarray, prior: np.ndarray,
                 ps: np.ndarray, known: np.ndarray, k: int,
                 solver: str) -> tuple[np.ndarray, np.ndarray | None, str]:
    """The program of :func:`fit_consistent` through cvxpy (any of its solvers); returns
    (z, the theta entries beyond the base set or None, status)."""
    # cvxpy takes seconds to import: only when asked for (the rule against imports in
    # functions is for our packages)
    import cvxpy as cp

    p = beta.shape[1]
    z = cp.Variable(p)
    chi = scale * z
    extra = cp.Variable(n_extra) if n_extra > 0 else None
    theta_b = beta @ chi
    theta = theta_b if extra is None else cp.hstack([theta_b, extra])
    r = cp.multiply(theta[theta_idx], 1.0 / sd) - r0
    d2_expr = cp.sum_squares(root @ r)
    cons = []
    for j in range(k):
        J = cp.bmat(_pseudo_inertia(chi[_LINK * j:_LINK * j + 10]))
        cons.append(0.5 * (J + J.T) / scale >> (MARGIN / scale) * np.eye(4))
        ia = z[_LINK * j + 10]
        cons.append(ia == known[j] / scale if known[j] > 0 else ia >= MARGIN / scale)
    # the completion: a pull towards the robot file's values, PRIOR_WEIGHT relative to d^2
    objective = d2_expr + PRIOR_WEIGHT * cp.sum_squares(cp.multiply(chi - prior, 1.0 / ps))
    prob = cp.Problem(cp.Minimize(objective), cons)
    _solve(cp, prob, solver, "consistent fit")
    return (np.asarray(z.value, dtype=float),
            None if extra is None else np.asarray(extra.value, dtype=float), str(prob.status))


def _svec_map() -> np.ndarray:
    """(10, 10) map from a link's 10 standard parameters to the svec of its pseudo-inertia
    (Clarabel's PSD triangle: the upper triangle column by column, off-diagonal entries
    times sqrt 2)."""
    out = np.zeros((10, 10))
    rows = [(i, j) for j in range(4) for i in range(j + 1)]
    for c in range(10):
        J = np.array(_pseudo_inertia(np.eye(10)[c]), dtype=float)
        out[:, c] = [J[i, j] * (1.0 if i == j else np.sqrt(2.0)) for i, j in rows]
    return out


def _solve_clarabel(beta: np.ndarray, scale: float, n_extra: int, theta_idx: np.ndarray,
                    r0: np.ndarray, root: np.ndarray, sd: np.ndarray, prior: np.ndarray,
                    ps: np.ndarray, known: np.ndarray,
                    k: int) -> tuple[np.ndarray, np.ndarray | None, str]:
    """The program of :func:`fit_consistent` handed to Clarabel directly (the same problem
    cvxpy builds, without its canonicalisation, most of the time of a solve through it):
    variables v = (z, extra) and y, minimise ||y||^2 + PRIOR_WEIGHT ||Q v - e||^2 subject to
    y = R v - c, svec(J_j(z)) - MARGIN / scale svec(1_4) in the PSD cone and Ia_j fixed or
    >= MARGIN / scale."""
    import clarabel  # with cvxpy's solvers; imported only when a consistent fit is asked for
    import scipy.sparse as sp

    p = beta.shape[1]
    n = p + max(n_extra, 0)
    T = np.zeros((beta.shape[0] + max(n_extra, 0), n))  # theta = T v
    T[:beta.shape[0], :p] = scale * beta
    T[beta.shape[0]:, p:] = np.eye(max(n_extra, 0))
    R = root @ (T[theta_idx] / sd[:, None])
    c = root @ r0
    q_diag = np.zeros(n)
    q_diag[:p] = scale / ps
    e = np.zeros(n)
    e[:p] = prior / ps
    # y = R v - c as variables of their own (as cvxpy does: the Hessian stays diagonal, not
    # R^T R with the squared condition number): x = (v, y)
    m = R.shape[0]
    P = 2.0 * np.diag(np.r_[PRIOR_WEIGHT * q_diag**2, np.ones(m)])
    q = np.r_[-2.0 * PRIOR_WEIGHT * q_diag * e, np.zeros(m)]
    svec = _svec_map()
    eye_svec = np.array([1.0 if i == j else 0.0 for j in range(4) for i in range(j + 1)])
    A_rows, b, cones = [np.hstack([R, -np.eye(m)])], [c], [clarabel.ZeroConeT(m)]
    n_v, n = n, n + m
    fixed = [j for j in range(k) if known[j] > 0]
    if fixed:  # zero cone: Ia_j = known_j / scale
        Z = np.zeros((len(fixed), n))
        for r, j in enumerate(fixed):
            Z[r, _LINK * j + 10] = 1.0
        A_rows.append(Z)
        b.append(known[fixed] / scale)
        cones.append(clarabel.ZeroConeT(len(fixed)))
    free_ia = [j for j in range(k) if not known[j] > 0]
    if free_ia:  # Ia_j - MARGIN / scale >= 0
        N = np.zeros((len(free_ia), n))
        for r, j in enumerate(free_ia):
            N[r, _LINK * j + 10] = -1.0
        A_rows.append(N)
        b.append(np.full(len(free_ia), -MARGIN / scale))
        cones.append(clarabel.NonnegativeConeT(len(free_ia)))
    for j in range(k):  # s = svec(J_j(z)) - MARGIN / scale svec(1) in the PSD cone
        S = np.zeros((10, n))
        S[:, _LINK * j:_LINK * j + 10] = -svec
        A_rows.append(S)
        b.append(-(MARGIN / scale) * eye_svec)
        cones.append(clarabel.PSDTriangleConeT(4))
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    sol = clarabel.DefaultSolver(sp.csc_matrix(np.triu(P)), q,
                                 sp.csc_matrix(np.vstack(A_rows)), np.concatenate(b), cones,
                                 settings).solve()
    status = str(sol.status)
    if status.endswith("AlmostSolved"):
        warnings.warn("fit_consistent: Clarabel: solution may be inaccurate (status "
                      "AlmostSolved)", stacklevel=3)
        status = "optimal_inaccurate"
    elif status.endswith("Solved"):
        status = "optimal"
    else:
        raise RobotIdentError(f"fit_consistent: solver CLARABEL: status {status} on the "
                              "consistent fit")
    v = np.asarray(sol.x, dtype=float)[:n_v]
    return v[:p], (v[p:] if n_extra > 0 else None), status


def _finish(model: Any, signals: Any, friction: str, solver: str, status: str,
            solve_s: float, chi_v: np.ndarray, coef: np.ndarray, cov: np.ndarray,
            metric: np.ndarray, theta_idx: np.ndarray, other: np.ndarray, free: np.ndarray,
            std_names: tuple[str, ...], k: int, tau_peak: Any = None) -> ConsistentFit:
    """The :class:`ConsistentFit` of a solved program."""
    x_hat = np.asarray(model.coef_, dtype=float)
    dth = coef[theta_idx] - x_hat[theta_idx]
    d2 = float(dth @ metric @ dth)
    if friction == "profile" and other.size:
        gain = cov[np.ix_(other, theta_idx)] @ _inv_spd(cov[np.ix_(theta_idx, theta_idx)])
        coef[other] = x_hat[other] + gain @ dth
    violated, moved, fd2, left = _project_friction(model, coef, cov, free, theta_idx, other,
                                                   tau_peak)
    dof = max(int(np.sum(model.n_samples_)) - int(free.sum()), 1)
    out = ConsistentFit(
        names=tuple(model.names_), coef=coef,
        standard=dict(zip(std_names, chi_v.tolist(), strict=True)), friction=friction,
        d2=d2, d2_limit=float(scipy.stats.chi2.ppf(0.99, theta_idx.size)),
        cost_ratio=(d2 + fd2) / dof, links=link_validity(chi_v, k), solve_s=solve_s,
        solver=solver, status=status, friction_violated=violated, friction_moved=moved,
        friction_d2=fd2, friction_left=left)
    if signals is not None:
        rows = _on_fitted_rows(model, signals)
        out.rel_error_before = model.rel_error(rows)
        out.rel_error_after = consistent_model(model, out).rel_error(rows)
    return out


def _on_fitted_rows(model: Any, signals: Any) -> list[Any]:
    """``signals`` (one or a sequence) with the torque NaN outside the rows the model's fit
    used (``RobotModel.fitted_rows``), so that the free model's error is its fit's."""
    items = signals if isinstance(signals, list | tuple) else [signals]
    return [replace(s, tau=np.where(model.fitted_rows(s), s.tau, np.nan)) for s in items]


def _project_friction(model: Any, coef: np.ndarray, cov: np.ndarray, free: np.ndarray,
                      theta_idx: np.ndarray, other: np.ndarray, tau_peak: Any = None
                      ) -> tuple[tuple[str, ...], tuple[str, ...], float, tuple[str, ...]]:
    """Move the free friction parameters of ``coef`` (in place) onto the friction bounds
    (:mod:`ident.robot.friction_bounds`) when they violate one: the closest point in the
    metric of the free fit's precision (C^-1 over every free parameter, theta held at its
    consistent value), a quadratic program (Clarabel). Nothing changes when every bound is
    met. Returns (bounds violated before, parameters moved, the d^2 added, bounds still
    violated)."""
    rows = bound_rows(model.names_, model.numbers_, tau_peak)
    if not rows:
        return (), (), 0.0, ()
    G = np.array([g for _, g, _, _ in rows])
    h = np.array([hj for _, _, hj, _ in rows])
    strict = np.array([st for *_, st in rows])
    labels = [w for w, *_ in rows]
    bad = ~met(G @ coef + h, strict)
    if not bad.any():
        return (), (), 0.0, ()
    violated = tuple(lb for lb, b in zip(labels, bad, strict=True) if b)
    if other.size == 0:
        return violated, (), 0.0, violated
    import clarabel  # with cvxpy's solvers; imported only when a consistent fit is asked for
    import scipy.sparse as sp

    x_hat = np.asarray(model.coef_, dtype=float)
    allf = np.flatnonzero(free)
    prec = _inv_spd(cov[np.ix_(allf, allf)])
    pos_t, pos_f = np.searchsorted(allf, theta_idx), np.searchsorted(allf, other)
    sd = np.sqrt(np.diag(cov)[other])
    dth, dxf = coef[theta_idx] - x_hat[theta_idx], coef[other] - x_hat[other]
    pff = prec[np.ix_(pos_f, pos_f)]

    def d2_friction(dx: np.ndarray) -> float:
        """The friction's part of d^2 (theta held): 2 dth^T P_tf dx + dx^T P_ff dx."""
        return float(2.0 * dth @ prec[np.ix_(pos_t, pos_f)] @ dx + dx @ pff @ dx)

    # u = (x_F - coef_F) / sd: minimise d^2, subject to g . x >= margin for every bound
    # acting on a free parameter
    P = 2.0 * pff * sd[:, None] * sd[None, :]
    q = 2.0 * sd * (pff @ dxf + prec[np.ix_(pos_f, pos_t)] @ dth)
    movable = np.any(G[:, other] != 0, axis=1)
    A = -(G[np.ix_(movable, other)] * sd[None, :])
    b = G[movable] @ coef + h[movable] - np.where(strict[movable], MARGIN, 0.0)
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    sol = clarabel.DefaultSolver(sp.csc_matrix(np.triu(0.5 * (P + P.T))), q,
                                 sp.csc_matrix(A), b,
                                 [clarabel.NonnegativeConeT(int(movable.sum()))],
                                 settings).solve()
    if not str(sol.status).endswith("Solved"):
        raise RobotIdentError(f"fit_consistent: solver CLARABEL: status {sol.status} on the "
                              "friction bounds")
    before = d2_friction(dxf)
    step = sd * np.asarray(sol.x, dtype=float)
    coef[other] = coef[other] + step
    names = tuple(model.names_)
    moved = tuple(names[i] for i, st, sdi in zip(other, step, sd, strict=True)
                  if abs(st) > 1e-3 * sdi)
    tol = 1e-7 * (1.0 + np.abs(G) @ np.abs(coef))
    # met to the solver's accuracy
    left = tuple(lb for lb, v, t in zip(labels, G @ coef + h, tol, strict=True) if not v > -t)
    return violated, moved, d2_friction(coef[other] - x_hat[other]) - before, left


def _solve(cp: Any, prob: Any, solver: str, what: str) -> None:
    try:
        prob.solve(solver=solver)
    except cp.error.SolverError as e:
        raise RobotIdentError(f"fit_consistent: solver {solver} failed on the {what} "
                              f"({e})") from None
    if prob.status not in ("optimal", "optimal_inaccurate") or prob.value is None:
        raise RobotIdentError(f"fit_consistent: solver {solver}: status {prob.status} on the "
                              f"{what}")


def consistent_model(model: Any, fit: ConsistentFit) -> Any:
    """A copy of the fitted ``model`` whose coefficients are the consistent ones (``predict``,
    ``rel_error`` ... then evaluate the consistent model; ``cov_``/``std_`` stay the free
    fit's)."""
    if tuple(model.names_) != tuple(fit.names):
        raise RobotIdentError("consistent_model: the ConsistentFit is of another model "
                              f"({len(fit.names)} parameters, the model has "
                              f"{len(model.names_)})")
    out = copy.copy(model)
    out.coef_ = np.asarray(fit.coef, dtype=float).copy()
    out.params_ = dict(zip(out.names_, out.coef_.tolist(), strict=True))
    return out


def consistent_record(model: Any, fit: ConsistentFit) -> dict[str, Any]:
    """The JSON record of a consistent estimate (``models[name]["consistent"]`` of
    ``jointid fit --robot --json``, read by ``jointid export-model``; docs/model-export.md)."""
    return {
        "method": "lmi",
        "solver": fit.solver,
        "solve_s": fit.solve_s,
        "friction": fit.friction,
        "d2": fit.d2,
        "d2_limit": fit.d2_limit,
        "within_uncertainty": fit.within_uncertainty,
        "cost_ratio": fit.cost_ratio,
        "rel_error_before": fit.rel_error_before,
        "rel_error_after": fit.rel_error_after,
        "parameters": {n: float(v) for n, v in zip(fit.names, fit.coef, strict=True)},
        "standard": {n: float(v) for n, v in fit.standard.items()},
        "links": fit.links,
        "friction_bounds": {"violated": list(fit.friction_violated),
                            "moved": list(fit.friction_moved), "d2": fit.friction_d2,
                            "still_violated": list(fit.friction_left)},
        "valid": fit.valid,
        "q_s": [float(q) for q in model.q_s_],
        "model": model.model,
        "known_rotor_inertia": {j: float(v) for j, v in zip(
            model.joints_, getattr(model.regressor_, "known_Ia", np.zeros(len(model.joints_))),
            strict=True)},
        # fitted friction parameters that carry a weight (OFF2 = OFF2 + 9.81 M2 on a vertical
        # prismatic axis, ident.robot.confounded): the export takes it out with "standard"
        "friction_regrouped": dict(getattr(model.base_, "friction", {}) or {}),
    }


def add_consistent(out: dict[str, Any]) -> None:
    """Hook for the record of ``ident.cli_robot.fit_robot``: add ``models[name]["consistent"]``
    (:func:`consistent_record`, measured on the fit's selected signals) for every fitted model,
    so that ``jointid export-model`` exports without fitting again."""
    sig = out["_signals"][0]
    peak = out.get("_tau_peak")
    for name, est in out["_estimators"].items():
        out["models"][name]["consistent"] = consistent_record(
            est, fit_consistent(est, sig, tau_peak=peak))
