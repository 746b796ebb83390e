"""The estimator contract: :class:`Estimator`, its :class:`Solution`, and the one rank rule.

Every model's linear solve goes through an :class:`Estimator` (the single-joint fit,
:mod:`ident.estimate`; the n-dof fit, :mod:`ident.robot.estimate`, whose Gauss-Newton steps
are linear solves on its normal equations). An estimator answers two questions:

* :meth:`Estimator.solve` -- ``W theta = y`` from the rows (W, y), with optional instruments Z
  (column for column with W) and row groups (one label per row, e.g. the joint of the row);
* :meth:`Estimator.solve_normal` / :meth:`Estimator.normal_covariance` -- the same on normal
  equations already summed (A = W^T W or Z^T W, g = W^T y or Z^T y), for models that never
  hold W (the n-dof moments, :mod:`ident.robot.moments`).

Rank rule (one for every model): the columns are scaled to unit norm; a direction of the
scaled regressor whose singular value is at most ``RCOND`` times the largest is not
identifiable. On rows this is the diagonal of the column-pivoted QR (|R_kk| <= RCOND |R_00|);
on a symmetric normal matrix A = W^T W (scaled to unit diagonal), whose eigenvalues are the
squared singular values, it reads lambda_min <= RCOND^2 lambda_max; on an IV normal matrix
Z^T W (not symmetric) its singular values are compared with RCOND^2 too (the solver's
refusal). Which columns an estimator leaves out is :meth:`Estimator.rank_drops`: the pivots on
W^T W, and for IDIM-IV then on what it solves, the regressor projected on the instruments
(W^T P_Z W from Z^T W and Z^T Z, its columns at W's unit norm, the tolerance relative to the
longest: :func:`weak_instruments`), on rows and summed moments alike.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
import scipy.linalg

from .. import DataError, IdentifiabilityError

__all__ = ["DEPENDENT_PREFIX", "PARTNER_TOL", "RCOND", "WEAK_PREFIX", "ZERO_COLUMN", "Estimator",
           "Solution", "RankDeficientError", "scaled", "dependent_columns", "dependent_reason",
           "instrumented_gram", "rank_rule", "weak_instruments",
           "weak_reason"]

#: Relative singular-value tolerance of the column-scaled regressor (module doc). On normal
#: equations the threshold is RCOND**2 = 1e-12 (their eigenvalues are squared singular values;
#: summed moments hold ~1e-16 relative rounding, so a smaller one accepts noise: on the KUKA
#: file 1e-14 let the IDIM-IV check "identify" directions with sigma 1e8 times the value).
#: It was 1e-7 for the single-joint rows and 1e-12 for the n-dof normal matrix before.
RCOND = 1e-6


class RankDeficientError(IdentifiabilityError):
    """The regressor (or the instruments) is rank deficient on the data.

    Attributes
    ----------
    names : list of str
        The parameters involved: the dependent columns (rows given) or the largest entries of
        the weakest direction (normal equations).
    lo, hi : float
        Smallest and largest singular value (eigenvalue for a symmetric normal matrix) of the
        column-scaled matrix.
    zero : bool
        Some columns are exactly zero.
    """

    def __init__(self, msg: str, names: Sequence[str] = (), lo: float = 0.0,
                 hi: float = 0.0, zero: bool = False) -> None:
        super().__init__(msg)
        self.names, self.lo, self.hi, self.zero = list(names), lo, hi, zero


@dataclass
class Solution:
    """What every estimator returns.

    Attributes
    ----------
    theta : ndarray, shape (b,)
        The estimate.
    cov : ndarray, shape (b, b)
        Its covariance (symmetric).
    sigma2 : float
        Residual variance ||rho||^2 / (m - b) of the (weighted) rows (paper eq. 14).
    rank : int
        Numerical rank of the column-scaled regressor (``b`` when a solution is returned).
    residual : ndarray, shape (m,)
        rho = y - W theta (unweighted); empty for :meth:`Estimator.solve_normal`.
    dof : int
        m - b.
    cond : float
        Condition number of the column-scaled regressor.
    cond_raw : float
        Condition number of the unscaled regressor (MATLAB's ``cond(W)``).
    weights : ndarray or None
        Per-group weights 1/sigma_g^2 (WLS), None otherwise.
    """

    theta: np.ndarray
    cov: np.ndarray
    sigma2: float
    rank: int
    residual: np.ndarray = field(default_factory=lambda: np.empty(0))
    dof: int = 0
    cond: float = float("nan")
    cond_raw: float = float("nan")
    weights: np.ndarray | None = None

    @property
    def std(self) -> np.ndarray:
        """sqrt(diag(cov)) (paper eq. 15)."""
        return np.sqrt(np.clip(np.diag(self.cov), 0, None))


def scaled(W: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """W with unit-norm columns and the norms (zero columns left as they are)."""
    norms = np.linalg.norm(W, axis=0)
    safe = np.where(norms > 0, norms, 1.0)
    return W / safe, safe


#: Why a parameter is fixed at 0 (``removed_`` of every model): its column is zero on the
#: data, or it is a combination of kept columns -- DEPENDENT_PREFIX followed by its partners
#: (:func:`dependent_reason`).
ZERO_COLUMN = "zero column on these data: not excited (no payload, no gravity?)"
DEPENDENT_PREFIX = "not separable: linear combination of "


def dependent_reason(partners: Sequence[str]) -> str:
    """Why a dependent column is fixed at 0, naming its partners (``"not separable: linear
    combination of A, B"``)."""
    return DEPENDENT_PREFIX + ", ".join(partners)


#: A kept column is a dependent column's partner when its coefficient (unit-norm columns) in
#: the column's least-squares expression on the kept columns exceeds this fraction of the
#: largest one (:func:`rank_rule`).
PARTNER_TOL = 1e-3


def rank_rule(G: np.ndarray, tol: float = RCOND, first: int = 0,
              norms: np.ndarray | None = None) -> tuple[np.ndarray, dict[int, list[int]]]:
    """The rank rule (module doc) on a Gram matrix G = W^T W, shape (b, b): the columns of W
    left out and, for each nonzero one, its partners.

    The column-pivoted QR of the unit-norm columns (kept while |R_kk| > tol |R_00|) computed
    as a pivoted Cholesky of the scaled G (L's rows are R's columns): the same pivots, from
    the rows (:func:`dependent_columns`) or from moments summed chunk by chunk (the n-dof
    fit, :mod:`ident.robot.estimate`), so both decide alike. A column's partners are the kept
    columns whose coefficients in its least-squares expression on them (R11 a = R[:rank, c],
    unit-norm columns) exceed :data:`PARTNER_TOL` times the largest, in pivot order.

    The columns ``0 .. first - 1`` are pivoted before the others (while one of them is
    independent of those already taken): of a dependent group, a later column is left out
    -- the payload's ratio or products rather than the base parameters whose combination
    they are (one payload in every run). Without it the first pivot among unit columns is
    decided by rounding.

    Parameters
    ----------
    G : ndarray, shape (b, b)
        W^T W (any column scaling: the rule scales it to unit diagonal).
    tol : float
        RCOND of the module doc (on |R_kk| / |R_00|, i.e. sqrt of the scaled pivots).
    first : int
        Columns pivoted first (above).
    norms : ndarray, shape (b,), or None
        Scale the columns by these instead of sqrt(diag(G)): IDIM-IV's G = W^T P_Z W
        (:func:`instrumented_gram`) scaled by the norms of W's own columns, so that a column
        the instruments hardly predict has a short scaled column (:func:`weak_instruments`).
        The tolerance is then relative to the longest scaled column (|R_00| of the pivoted
        QR when nothing is pivoted first); None: unit columns, |R_00| = 1.

    Returns
    -------
    (ndarray of int, dict of int to list of int)
        The left-out columns (zero columns included), sorted; partners of each nonzero one.
    """
    d = np.sqrt(np.clip(np.diagonal(G), 0.0, None))
    live = np.flatnonzero(d > 0)
    out = [int(i) for i in np.flatnonzero(~(d > 0))]
    if not live.size:
        return np.array(out, dtype=int), {}
    if norms is not None:
        s = np.asarray(norms, dtype=float)
        s = np.where(s > 0, s, d)
    else:
        s = d
    Gs = G[np.ix_(live, live)] / s[live, None] / s[None, live]
    n = live.size
    L = np.zeros((n, n))
    r = np.diagonal(Gs).copy()
    # |R_00| (the longest scaled column): 1 for unit columns, so tol itself as before
    ref = tol * (1.0 if norms is None else float(np.sqrt(max(r.max(), 0.0))))
    left = np.ones(n, dtype=bool)
    piv: list[int] = []
    group = live < int(first)
    for k in range(n):
        i = int(np.argmax(np.where(left & group, r, -np.inf)))
        if not (group[i] and left[i] and np.sqrt(max(r[i], 0.0)) > ref):
            group[:] = False  # the first columns are all taken (or dependent)
            i = int(np.argmax(np.where(left, r, -np.inf)))
        if not np.sqrt(max(r[i], 0.0)) > ref:
            break
        col = (Gs[:, i] - L[:, :k] @ L[i, :k]) / np.sqrt(r[i])
        L[:, k] = col
        r = r - col**2
        left[i] = False
        piv.append(i)
    rank = len(piv)
    R11 = L[piv, :rank].T  # upper triangular: R11[a, b] = L[piv[b], a]
    partners: dict[int, list[int]] = {}
    for i in np.flatnonzero(left):
        coef = (np.abs(scipy.linalg.solve_triangular(R11, L[i, :rank], lower=False))
                if rank else np.zeros(0))  # rank 0: a non-finite G
        big = coef > PARTNER_TOL * max(float(coef.max(initial=0.0)), 1e-300)
        partners[int(live[i])] = [int(live[piv[t]]) for t in np.flatnonzero(big)]
    out += [int(live[i]) for i in np.flatnonzero(left)]
    return np.array(sorted(out), dtype=int), partners


def dependent_columns(
    W: np.ndarray, names: Sequence[str], tol: float = RCOND
) -> list[tuple[str, list[str]]]:
    """Columns that are (numerically) linear combinations of the others: :func:`rank_rule`
    on the rows' Gram matrix W^T W.

    Returns
    -------
    list of (name, partners)
        Each left-out column's name and the names of the kept columns it is a combination of
        (empty for a zero column); empty when W has full column rank.
    """
    W = np.asarray(W, dtype=float)
    out, partners = rank_rule(W.T @ W, tol)
    return [(names[i], [names[p] for p in partners.get(int(i), [])]) for i in out]


#: Why IDIM-IV leaves a column out that the rows alone would keep (:func:`weak_instruments`):
#: its part the instruments predict (P_Z w) is within RCOND of the kept columns' (or of 0).
WEAK_PREFIX = "not determined by the instruments (IDIM-IV): "


def weak_reason(partners: Sequence[str]) -> str:
    """Why IDIM-IV fixes a column at 0 that the rows alone would keep: its instrumented part
    is a combination of ``partners``' (or nearly zero: the instruments do not predict it)."""
    if partners:
        return (WEAK_PREFIX + "its instrumented column is a linear combination of those of "
                + ", ".join(partners))
    return WEAK_PREFIX + "its instrumented column is zero (the instruments do not predict it)"


def instrumented_gram(A: np.ndarray, C: np.ndarray, tol: float = RCOND) -> np.ndarray:
    """W^T P_Z W (b, b), the Gram matrix of the regressor projected on the instruments' column
    space, from A = Z^T W and C = Z^T Z (rows or moments summed chunk by chunk alike).

    IDIM-IV's estimate depends on Z only through that space (theta = (Z^T W)^-1 Z^T y and
    C_theta = sigma^2 (W^T P_Z W)^-1): it is IDIM-LS on P_Z W. The instruments' own rank rule
    (unit-norm columns of Z, a direction with a singular value at most ``tol`` times the
    largest spans nothing) truncates C's pseudo-inverse: nearly dependent instruments span
    fewer directions, so P_Z W loses rank and :func:`rank_rule` leaves a column out.

    Parameters
    ----------
    A : ndarray, shape (bz, b)
        Z^T W.
    C : ndarray, shape (bz, bz)
        Z^T Z.
    tol : float
        RCOND on the unit-norm instruments (eigenvalues of the scaled C against tol^2).
    """
    A = np.asarray(A, dtype=float)
    C = np.asarray(C, dtype=float)
    dz = np.sqrt(np.clip(np.diagonal(C), 0.0, None))
    dz = np.where(dz > 0, dz, 1.0)
    ev, V = np.linalg.eigh(C / dz[:, None] / dz[None, :])
    keep = ev > tol**2 * max(float(ev[-1]), 0.0) if ev.size else ev > 0
    B = V[:, keep].T @ (A / dz[:, None]) / np.sqrt(ev[keep])[:, None]  # L^-1 Z^T W
    return B.T @ B


def weak_instruments(G: np.ndarray, A: np.ndarray, C: np.ndarray, tol: float = RCOND,
                     first: int = 0) -> tuple[np.ndarray, dict[int, list[int]]]:
    """The rank rule of IDIM-IV: :func:`rank_rule` on W^T P_Z W (:func:`instrumented_gram`),
    its columns scaled by W's own norms sqrt(diag(G)), G = W^T W.

    A column is left out when the part of it the instruments predict lies within ``tol``
    times the longest such part (W's columns at unit norm) of the span of the other columns'
    parts: the column-pivoted QR of P_Z W_s, which is what IDIM-IV solves (the LS rule on
    W_s, relative to the largest). Callers run :func:`rank_rule` on G first and this on the
    columns it keeps, so that a column the rows already cannot separate keeps that reason.

    Parameters
    ----------
    G, A, C : ndarray
        W^T W (b, b), Z^T W (bz, b) and Z^T Z (bz, bz).
    tol, first
        As :func:`rank_rule`'s.

    Returns
    -------
    (ndarray of int, dict of int to list of int)
        As :func:`rank_rule`'s: the columns left out and the partners of each.
    """
    norms = np.sqrt(np.clip(np.diagonal(G), 0.0, None))
    return rank_rule(instrumented_gram(A, C, tol), tol, first, norms=norms)


def dependency_message(deps: list[tuple[str, list[str]]]) -> str:
    """One line naming every dependent column and its partners."""
    parts = []
    for name, partners in deps:
        if partners:
            parts.append(f"{name} is a linear combination of {', '.join(partners)}")
        else:
            parts.append(f"{name} has a zero column")
    hint = ""
    if any(n.startswith(("a_", "b_", "c_", "d_")) for n, _ in deps):
        hint = (
            " (quadrant terms need load variation: gravity or payload runs change the sign of "
            "tau_out at a given velocity; without them P+/P- follow the direction only)"
        )
    return "regressor is rank deficient: " + "; ".join(parts) + hint


class Estimator:
    """Base class of the estimators (module doc). Subclasses set ``name`` and implement
    :meth:`_solve_scaled`; one module each, registered in :data:`ident.estimators.ESTIMATORS`.

    Class attributes
    ----------------
    name : str
        Registry key (the CLI choice).
    needs_instruments : bool
        ``solve`` requires ``instruments``.
    reweights : bool
        The estimate is refitted with per-group weights from a first fit (:meth:`weights`).
    symmetric : bool
        Its normal matrix is symmetric (W^T W); False for Z^T W.
    """

    name: ClassVar[str] = ""
    needs_instruments: ClassVar[bool] = False
    reweights: ClassVar[bool] = False
    symmetric: ClassVar[bool] = True

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"

    # ------------------------------------------------------------------ rows
    def solve(self, W: np.ndarray, y: np.ndarray, *, instruments: np.ndarray | None = None,
              groups: np.ndarray | None = None,
              names: Sequence[str] | None = None) -> Solution:
        """Estimate theta of ``y = W theta + rho``.

        Parameters
        ----------
        W : ndarray, shape (m, b)
            Regressor (observation matrix).
        y : ndarray, shape (m,)
            Measurements.
        instruments : ndarray, shape (m, b), or None
            Instruments Z, column for column with W (IV only).
        groups : ndarray, shape (m,), or None
            A label per row (WLS: one variance per label; ignored by the others).
        names : sequence of str or None
            Column names for the error messages (default ``theta_0 ...``).

        Raises
        ------
        DataError
            Shapes, non-finite values, not more rows than columns, missing instruments.
        RankDeficientError
            W (or Z) is rank deficient by the rank rule; the message names the columns.
        """
        W = np.asarray(W, dtype=float)
        y = np.asarray(y, dtype=float).ravel()
        if W.ndim != 2 or W.shape[0] != y.shape[0]:
            raise DataError(f"{self.name}: W has shape {W.shape}, expected ({y.shape[0]}, b)")
        m, b = W.shape
        names = [f"theta_{i}" for i in range(b)] if names is None else list(names)
        if len(names) != b:
            raise DataError(f"{self.name}: {len(names)} names for {b} columns")
        if not (np.all(np.isfinite(W)) and np.all(np.isfinite(y))):
            raise DataError(f"{self.name}: W or y holds NaN or infinite values")
        if m <= b:
            raise DataError(f"{m} samples for {b} parameters: need more samples than parameters")
        if self.needs_instruments and instruments is None:
            raise DataError(f"estimator {self.name!r} needs instruments (shape {W.shape})")
        Z = None if instruments is None else np.asarray(instruments, dtype=float)
        return self._solve(W, y, Z, groups, names)

    def _solve(self, W: np.ndarray, y: np.ndarray, Z: np.ndarray | None,
               groups: np.ndarray | None, names: list[str]) -> Solution:
        Ws, norms = scaled(W)
        Q, R, piv = scipy.linalg.qr(Ws, mode="economic", pivoting=True)
        m, b = W.shape
        d = np.abs(np.diag(R))
        if b and (d[0] == 0 or d[-1] <= RCOND * d[0]):
            # the rule on W^T W names the columns (at the tolerance to ~1e-4 of it, the rows'
            # QR may see a deficiency the Gram matrix does not: its weakest pivot then)
            deps = dependent_columns(W, names) or [(names[int(piv[-1])], [])]
            raise RankDeficientError(dependency_message(deps), [n for n, _ in deps])
        theta_s, cov_s = self._solve_scaled(Ws, y, Q, R, piv, Z, names)
        theta = theta_s / norms
        rho = y - W @ theta
        sigma2 = float(rho @ rho) / (m - b)
        cov = sigma2 * cov_s / np.outer(norms, norms)
        sv = np.linalg.svd(R, compute_uv=False)
        sv_raw = np.linalg.svd(R * norms[piv][None, :], compute_uv=False)
        return Solution(
            theta=theta, cov=cov, sigma2=sigma2, rank=b, residual=rho, dof=m - b,
            cond=float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf"),
            cond_raw=float(sv_raw[0] / sv_raw[-1]) if sv_raw[-1] > 0 else float("inf"),
        )

    def _solve_scaled(self, Ws: np.ndarray, y: np.ndarray, Q: np.ndarray, R: np.ndarray,
                      piv: np.ndarray, Z: np.ndarray | None,
                      names: list[str]) -> tuple[np.ndarray, np.ndarray]:
        """(theta_s, cov_s) for the unit-norm columns Ws = Q R P^T (full rank): the estimate
        and the covariance factor, sigma^2 excluded."""
        raise NotImplementedError

    # ------------------------------------------------------------------ the rank rule
    def rank_drops(self, G: np.ndarray, names: Sequence[str], *, A: np.ndarray | None = None,
                   C: np.ndarray | None = None, first: int = 0,
                   tol: float = RCOND) -> list[tuple[int, str]]:
        """The columns this estimator cannot determine, each with its reason: the one rank
        rule on what it solves, for one joint's rows and the n-dof moments alike.

        :func:`rank_rule` on G = W^T W (zero and dependent columns: :data:`ZERO_COLUMN`,
        :func:`dependent_reason`); for an estimator with instruments given A = Z^T W and
        C = Z^T Z, then :func:`weak_instruments` on the columns kept (IDIM-IV solves
        Z^T W theta = Z^T y, i.e. least squares on P_Z W: a column whose instrumented part is
        within RCOND of the others' is left out, :func:`weak_reason`).

        Parameters
        ----------
        G : ndarray, shape (b, b)
            W^T W (WLS: weighted), any column scaling.
        names : sequence of str
            Column names, for the reasons.
        A, C : ndarray or None
            Z^T W (b, b) and Z^T Z (b, b) (IV: Z column for column with W, so a column left
            out takes its instrument along, and the rule is repeated on the rest until it
            leaves nothing out); ignored by estimators without instruments.
        first, tol
            As :func:`rank_rule`'s. ``first`` orders the rows' rule only: IV's step pivots by
            the instrumented length alone (:func:`weak_instruments` with ``first = 0``), so
            that the column the instruments predict least is left out -- with the base
            parameters pivoted first, a weak base column's dependence fell on a friction
            column's rounding and nothing was left out (tests/test_robot_iv_weak.py).

        Returns
        -------
        list of (int, str)
            Column index and reason, sorted by index.
        """
        G = np.asarray(G, dtype=float)
        dep, partners = rank_rule(G, tol, first)
        out = [(int(k), ZERO_COLUMN if not G[k, k] > 0 else
                dependent_reason([names[p] for p in partners[int(k)]])) for k in dep]
        if self.needs_instruments and A is not None and C is not None:
            A = np.asarray(A, dtype=float)
            C = np.asarray(C, dtype=float)
            kept = np.setdiff1d(np.arange(G.shape[0]), dep)
            while kept.size:  # a column left out takes its instrument along: until none
                sub = np.ix_(kept, kept)
                # pivoted by the instrumented length alone (first = 0): the column the
                # instruments predict least goes, not one pivoted after it (a base parameter
                # pivoted first would leave a friction column out in its place)
                weak, wp = weak_instruments(G[sub], A[sub], C[sub], tol)
                if not weak.size:
                    break
                out += [(int(kept[k]), weak_reason([names[kept[p]] for p in wp.get(int(k), [])]))
                        for k in weak]
                kept = np.delete(kept, weak)
        return sorted(out)

    # ------------------------------------------------------------------ normal equations
    def solve_normal(self, As: np.ndarray, gs: np.ndarray,
                     names: Sequence[str] | None = None) -> np.ndarray:
        """Solve the column-scaled normal equations ``As x = gs`` after the rank rule.

        Parameters
        ----------
        As : ndarray, shape (b, b)
            D^-1 A D^-1 with D = sqrt(diag(A)) (unit diagonal): W^T W for LS/WLS, Z^T W for IV.
        gs : ndarray, shape (b,)
            D^-1 g.
        names : sequence of str or None
            Column names for the error.

        Raises
        ------
        RankDeficientError
            lambda_min <= RCOND^2 lambda_max (singular values for IV); ``names`` are the four
            largest entries of the weakest direction.
        """
        if self.symmetric:
            ev = np.linalg.eigvalsh(As)  # the eigenvectors only when the check fails
            lo, hi, weak = ev[0], ev[-1], None
        else:
            _, sv, vt = np.linalg.svd(As)
            lo, hi, weak = sv[-1], sv[0], vt[-1]
        if not np.isfinite(hi) or lo <= RCOND**2 * hi:
            if weak is None:
                ev, evec = np.linalg.eigh(As)
                lo, hi, weak = ev[0], ev[-1], evec[:, 0]
            worst = np.argsort(-np.abs(weak))[:4]
            label = [f"theta_{i}" for i in range(len(gs))] if names is None else list(names)
            involved = [label[i] for i in worst]
            raise RankDeficientError(
                f"parameters not identifiable on these data (cond {hi / max(lo, 1e-300):.2g}); "
                f"the weakest direction involves {involved}", involved, float(lo), float(hi))
        return scipy.linalg.solve(As, gs)

    def normal_covariance(self, A: np.ndarray, C: np.ndarray | None,
                          sigma2: float) -> np.ndarray:
        """Covariance sigma^2 A^-1 (LS, WLS with A = sum_g W_g^T W_g / sigma_g^2) or the IV
        sandwich sigma^2 A^-1 C A^-T (A = Z^T W, C = Z^T Z)."""
        Ainv = np.linalg.inv(A)
        return sigma2 * Ainv if C is None else sigma2 * Ainv @ C @ Ainv.T

    def weights(self, sigma_groups: np.ndarray) -> np.ndarray:
        """Per-group weights for the refit (``reweights``); ones otherwise."""
        return np.ones(len(sigma_groups))
