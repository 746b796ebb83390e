"""Physical consistency of identified robot parameters.

Base parameters are combinations of standard ones (``BaseParameters.beta``), so the usual
checks -- link mass > 0, inertia positive definite, triangle inequalities -- cannot be applied
to them one by one. This module does two things:

1. **Direct checks** on base parameters that are exactly one standard parameter of a kind
   with a sign (M{j} > 0, Ia{j} >= 0, diagonal inertia XX/YY/ZZ{j} > 0 about the origin) and
   on the paper's friction coefficients (a_m > 0, a_m + b_m > 0, a_g > 0, a_g - b_g > 0,
   c >= 0, c + d >= 0, FV >= 0; usual FC >= 0, FV >= 0), each "violated" only when the bound
   is passed by more than 3 standard deviations.
2. **Feasibility of the regrouped set**: is there a standard parameter vector chi_St whose
   links all have a positive semi-definite pseudo-inertia (Wensing, Kim & Slotine 2017:
   J = [[tr(I)/2 1_3 - I, h], [h^T, m]] with I the inertia about the link origin, h the first
   moments, m the mass; J >= 0 is mass >= 0, inertia PSD and the triangle inequalities)
   and Ia >= 0, with beta chi_St within the identified uncertainty of the base estimate
   (Mahalanobis distance d^2 = r^T C^-1 r below the 99 % chi-square quantile)? The smallest
   d^2 is the semidefinite program of :func:`~ident.robot.consistent_fit.fit_consistent`
   (one LMI per link, convex: its global minimum, well under a second for 6 axes); should the
   conic solver fail, least squares over Cholesky factors of the pseudo-inertias (J = L L^T,
   Ia = s^2, a few seeded starts: a local minimum, an upper bound of d^2). Standard
   parameters that do not enter any base parameter are free in that search: nothing can be
   said about them (listed as ``unchecked``). When the set is not realisable,
   ``fit_consistent`` (``jointid export-model``, docs/model-export.md) gives the nearest
   consistent estimate and its cost.

A paper model fitted with soft quadrants (:mod:`ident.robot.soft_fit`) is checked alike: the
direct checks read its values and covariance, and the d^2 of the convex program reads only
its theta and covariance (no prediction, no quadrant), so it is its own. Its nearest
consistent estimate is not offered: ``fit_consistent`` and ``jointid export-model`` refuse a
soft model (their friction and prediction use hard quadrants).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.linalg
import scipy.optimize
import scipy.stats

from . import RobotIdentError
from .consistent_fit import fit_consistent
from .friction_bounds import bound_rows, met
from .paper import require_theta

__all__ = ["ConsistencyReport", "check_consistency"]

_LINK = ("XX", "XY", "XZ", "YY", "YZ", "ZZ", "MX", "MY", "MZ", "M", "Ia")
_POSITIVE = {"M": "link mass M > 0", "XX": "XX > 0", "YY": "YY > 0", "ZZ": "ZZ > 0"}


@dataclass
class ConsistencyReport:
    """Result of :func:`check_consistency`.

    Attributes
    ----------
    checks : list of (str, float, float, str)
        (what, value, std, "ok" | "violated" | "marginal") of the direct checks.
    feasible : bool or None
        A physically consistent standard set reproduces the base estimate within its
        uncertainty (None: not evaluated).
    d2, d2_limit : float
        Smallest Mahalanobis distance found and the 99 % chi-square quantile.
    standard : dict
        The consistent standard set found (name -> value), one of many.
    unchecked : tuple of str
        Standard parameters absent from every base parameter (no information).
    """

    checks: list[tuple[str, float, float, str]] = field(default_factory=list)
    feasible: bool | None = None
    d2: float = float("nan")
    d2_limit: float = float("nan")
    standard: dict[str, float] = field(default_factory=dict)
    unchecked: tuple[str, ...] = ()
    method: str = ""
    soft: bool = False

    @property
    def ok(self) -> bool:
        """No violated direct check and (when evaluated) a feasible regrouped set."""
        return all(c[3] != "violated" for c in self.checks) and self.feasible is not False

    def format(self) -> str:
        """Plain-text report."""
        lines = ["Physical consistency"]
        for what, v, s, status in self.checks:
            lines.append(f"  {status:9s} {what:28s} {v:12.5g} +- {s:.3g}")
        if self.feasible is not None:
            verdict = "yes" if self.feasible else "NO"
            lines.append(f"  regrouped base set realisable by physical links: {verdict} "
                         f"(d^2 = {self.d2:.3g}, 99 % limit {self.d2_limit:.3g})")
            if not self.feasible and self.soft:
                lines.append("  nearest consistent estimate: not for a soft-quadrant fit "
                             "(jointid export-model and --consistent use hard quadrants)")
            elif not self.feasible:
                lines.append("  nearest consistent estimate and its cost: jointid export-model "
                             "(ident.robot.consistent_fit, docs/model-export.md)")
        if self.unchecked:
            lines.append("  cannot be checked (in no base parameter): "
                         + ", ".join(self.unchecked))
        return "\n".join(lines)


def _status(margin: float, std: float) -> str:
    if margin > 0:
        return "ok"
    return "violated" if margin < -3 * std else "marginal"


def _standard_from_factors(z: np.ndarray, k: int) -> np.ndarray:
    """Standard parameters (11 k) from per-link Cholesky entries (10) and sqrt(Ia) (1)."""
    out = np.empty(11 * k)
    tril = np.tril_indices(4)
    for j in range(k):
        L = np.zeros((4, 4))
        L[tril] = z[11 * j:11 * j + 10]
        J = L @ L.T
        S = J[:3, :3]
        inertia = np.trace(S) * np.eye(3) - S
        h = J[:3, 3]
        out[11 * j:11 * j + 11] = [inertia[0, 0], inertia[0, 1], inertia[0, 2], inertia[1, 1],
                                   inertia[1, 2], inertia[2, 2], h[0], h[1], h[2], J[3, 3],
                                   z[11 * j + 10] ** 2]
    return out


def _linear_map(J: np.ndarray) -> np.ndarray:
    """The 10 standard parameters of a link from its pseudo-inertia J (linear in J)."""
    S = J[:3, :3]
    tr = S[0, 0] + S[1, 1] + S[2, 2]
    return np.array([tr - S[0, 0], -S[0, 1], -S[0, 2], tr - S[1, 1], -S[1, 2], tr - S[2, 2],
                     J[0, 3], J[1, 3], J[2, 3], J[3, 3]])


def _standard_jacobian(z: np.ndarray, k: int) -> np.ndarray:
    """d(standard parameters)/dz of :func:`_standard_from_factors`, (11 k, 11 k), block
    diagonal: dJ/dL_ab = e_a L_b^T + L_b e_a^T (L_b: column b of L), mapped linearly."""
    out = np.zeros((11 * k, 11 * k))
    rows, cols = np.tril_indices(4)
    for j in range(k):
        L = np.zeros((4, 4))
        L[rows, cols] = z[11 * j:11 * j + 10]
        for i, (a, b) in enumerate(zip(rows, cols, strict=True)):
            dJ = np.zeros((4, 4))
            dJ[a, :] += L[:, b]
            dJ[:, a] += L[:, b]
            out[11 * j:11 * j + 10, 11 * j + i] = _linear_map(dJ)
        out[11 * j + 10, 11 * j + 10] = 2.0 * z[11 * j + 10]
    return out


def _d2_view(model: Any) -> Any:
    """A shallow copy of a soft-quadrant ``model`` that ``fit_consistent`` takes: without
    signals it reads only ``coef_``, ``cov_``, the names and the base (module doc), which
    are the soft fit's; its refusal guards the consistent model's hard-quadrant friction and
    prediction, neither of which :func:`check_consistency` reads."""
    view = copy.copy(model)
    view.quadrants = "hard"
    return view


def check_consistency(model: Any, *, feasibility: bool = True, starts: int = 3,
                      seed: int = 0, method: str = "lmi",
                      tau_peak: Any = None) -> ConsistencyReport:
    """Physical consistency of a fitted :class:`~ident.robot.estimate.RobotModel` (module doc).

    ``method``: "lmi" (the convex program; the Cholesky search if its solver fails) or
    "cholesky" (the local search only, ``starts`` seeded starts). ``tau_peak`` (k,) [N m]:
    the largest measured |tau| per joint (:func:`~ident.robot.friction_bounds.torque_peak`),
    which adds the bounds no static friction may exceed
    (:data:`~ident.robot.friction_bounds.PEAK_BOUNDS`).

    Returns
    -------
    ConsistencyReport
    """
    if method not in ("lmi", "cholesky"):
        raise RobotIdentError(f"check_consistency: method {method!r}: expected 'lmi' or "
                              "'cholesky'")
    require_theta(model, "check_consistency")
    rep = ConsistencyReport(soft=getattr(model, "quadrants", "hard") == "soft")
    base = model.base_
    pb = len(base.names)
    std_names = tuple(base.standard_names)
    beta = np.asarray(base.beta, dtype=float)
    coef, std = np.asarray(model.coef_), np.asarray(model.std_)
    # 1. direct checks
    for i in range(pb):
        nz = np.flatnonzero(beta[i])
        if nz.size != 1 or abs(beta[i, nz[0]] - 1.0) > 1e-12:
            continue
        sname = std_names[nz[0]]
        kind = sname.rstrip("0123456789")
        if kind in _POSITIVE:
            rep.checks.append((f"{_POSITIVE[kind]} ({sname})", coef[i], std[i],
                               _status(coef[i], std[i])))
        elif kind == "Ia":
            rep.checks.append((f"Ia >= 0 ({sname})", coef[i], std[i],
                               "ok" if coef[i] >= 0 else _status(coef[i], std[i])))
    cov_all = np.asarray(model.cov_)
    for what, g, h, strict in bound_rows(model.names_, model.numbers_, tau_peak):
        v = float(g @ coef) + h
        s = float(np.sqrt(max(g @ cov_all @ g, 0.0)))
        rep.checks.append((what, v, s, "ok" if met(v, strict) else _status(v, s)))
    used = np.any(beta != 0, axis=0)
    rep.unchecked = tuple(n for n, u in zip(std_names, used, strict=True) if not u)
    if not feasibility:
        return rep
    # 2. feasibility of the regrouped set
    k = len(std_names) // 11
    if len(std_names) != 11 * k:  # friction columns decomposed too: not handled
        return rep
    rep.d2_limit = float(scipy.stats.chi2.ppf(0.99, pb))
    cf = None
    if method == "lmi":
        try:  # the convex program: global minimum of d^2 (profile metric C_bb^-1, module doc)
            cf = fit_consistent(_d2_view(model) if rep.soft else model, friction="profile",
                                tau_peak=tau_peak)
        except (RobotIdentError, np.linalg.LinAlgError, ValueError):
            cf = None
    if cf is not None:
        rep.d2, rep.method = cf.d2, "lmi"
        rep.feasible = bool(rep.d2 <= rep.d2_limit)
        rep.standard = dict(cf.standard)
        return rep
    cov = np.asarray(model.cov_)[:pb, :pb]
    try:
        Lc = scipy.linalg.cholesky(cov + 1e-18 * np.eye(pb) * max(np.trace(cov), 1e-300),
                                   lower=True)
    except np.linalg.LinAlgError:
        return rep
    chi_b = coef[:pb]

    def resid(z: np.ndarray) -> np.ndarray:
        r = beta @ _standard_from_factors(z, k) - chi_b
        return scipy.linalg.solve_triangular(Lc, r, lower=True)

    def jac(z: np.ndarray) -> np.ndarray:  # analytic: 11 k times fewer residual evaluations
        return scipy.linalg.solve_triangular(Lc, beta @ _standard_jacobian(z, k), lower=True)

    rng = np.random.default_rng(seed)
    best = None
    for _ in range(max(int(starts), 1)):
        z0 = np.zeros(11 * k)
        for j in range(k):
            L0 = np.eye(4) * rng.uniform(0.3, 1.5) + np.tril(rng.normal(0, 0.1, (4, 4)), -1)
            z0[11 * j:11 * j + 10] = L0[np.tril_indices(4)]
            z0[11 * j + 10] = rng.uniform(0.1, 1.0)
        sol = scipy.optimize.least_squares(resid, z0, jac=jac, method="trf", max_nfev=600)
        if best is None or sol.cost < best.cost:
            best = sol
        if 2.0 * best.cost <= scipy.stats.chi2.ppf(0.99, pb):
            break  # a consistent set is found: no need for other starts
    rep.d2, rep.method = float(2.0 * best.cost), "cholesky"
    rep.feasible = bool(rep.d2 <= rep.d2_limit)
    rep.standard = dict(zip(std_names, _standard_from_factors(best.x, k).tolist(),
                            strict=True))
    return rep
