"""Scoring and hyper-parameter scans shared by the candidate effects.

A candidate is scored by the residual sum of squares its columns remove from the current
fit (:class:`Scorer`), on columns computed from the decimated signals (:class:`Columns`);
a nonlinear hyper-parameter (a ripple period, q_s, T_w) is chosen by a grid then a bounded
1-D search (:func:`scan_log`, :func:`refine_1d`) on at most ~8000 samples
(:attr:`Columns.fast`), the chosen value's gain being computed on every sample; a ripple's
period only takes its bracket from the subsample's grid, the bounded search reads every
sample (:func:`ident.effects.position_ripple.scan_period`). The F tests'
effective sample size of an autocorrelated residual (:func:`effective_n`) lives here too,
beside the scorer that needs it (re-exported by :mod:`ident.diagnose`). Pure numerics.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from scipy import optimize

from ..signals import Signals
from ._base import Effect

__all__ = ["Scorer", "Columns", "effective_n", "fast_rows", "refine_1d", "scan_log"]


def effective_n(residual: np.ndarray) -> float:
    """Effective number of independent samples of an AR(1)-like residual.

    n_eff = n (1 - ρ1) / (1 + ρ1), ρ1 the lag-1 autocorrelation (clipped to [0, 0.999]).
    """
    r = np.asarray(residual, dtype=float)
    n = r.shape[0]
    if n < 3:
        return float(n)
    r = r - r.mean()
    den = float(r @ r)
    rho = float(r[1:] @ r[:-1]) / den if den > 0 else 0.0
    rho = min(max(rho, 0.0), 0.999)
    return max(n * (1 - rho) / (1 + rho), 2.0)


class Scorer:
    """RSS removed by extra columns C from the current fit: with Q an orthonormal basis of
    the current (kept) regressor and r the residual (r ⟂ Q), the gain is
    (Cᵀr)ᵀ (CᵀC - (QᵀC)ᵀ(QᵀC))⁻¹ (Cᵀr).

    Parameters
    ----------
    W : ndarray, shape (m, b)
        Current kept regressor (eq. 11).
    r : ndarray, shape (m,)
        Its residual ρ = Y - W χ̂ (eq. 12-13).
    """

    def __init__(self, W: np.ndarray, r: np.ndarray) -> None:
        norms = np.linalg.norm(W, axis=0)
        Ws = W / np.where(norms > 0, norms, 1.0)
        self.Q, _ = np.linalg.qr(Ws)
        self.r = r
        self.rss = float(r @ r)

    def gain(self, C: np.ndarray) -> float:
        """RSS removed by the columns ``C``, shape (m,) or (m, k) [N² m²]."""
        C = np.asarray(C, dtype=float)
        if C.ndim == 1:
            C = C[:, None]
        if not np.all(np.isfinite(C)):
            return 0.0
        cn = np.linalg.norm(C, axis=0)
        ok = cn > 0
        if not ok.any():
            return 0.0
        C = C[:, ok] / cn[ok]
        QC = self.Q.T @ C
        M = C.T @ C - QC.T @ QC
        b = C.T @ self.r
        w, V = np.linalg.eigh(M)
        keep = w > 1e-9 * max(float(w.max()), 1e-300)
        z = (V[:, keep].T @ b) / np.sqrt(w[keep])
        return float(min(z @ z, self.rss))

    def n_eff_after(self, C: np.ndarray) -> float:
        """Effective sample size of the residual once C is fitted too: the noise that is
        left, not the structure C explains, sets the autocorrelation of the F test.

        Parameters
        ----------
        C : ndarray, shape (m,) or (m, k)
            Extra columns.
        """
        C = np.asarray(C, dtype=float)
        if C.ndim == 1:
            C = C[:, None]
        if not np.all(np.isfinite(C)):
            return effective_n(self.r)
        Cp = C - self.Q @ (self.Q.T @ C)
        beta, *_ = np.linalg.lstsq(Cp, self.r, rcond=None)
        return effective_n(self.r - Cp @ beta)


class Columns:
    """Scores candidates on columns computed on the decimated signals:
    smooth functions of slowly varying signals commute with the anti-alias filter, so these
    match :meth:`Design.with_term`'s columns closely and cost no full-rate pass. The exact
    columns are used only for the acceptance refit."""

    def __init__(self, s: Signals, scorer: Scorer, fast_rows: np.ndarray | None = None) -> None:
        self.scorer, self.s = scorer, s
        self._fast: Columns | None = None
        self._fast_rows = fast_rows

    def gain(self, e: Effect) -> float:
        """RSS removed by the effect's columns on the decimated signals."""
        return self.scorer.gain(e.columns(self.s))

    @property
    def fast(self) -> Columns:
        """The same scorer on at most ~8000 samples (:func:`fast_rows`, or the rows given
        as ``fast_rows``), for hyper-parameter scans; the gain of the chosen value is then
        computed on every sample."""
        sub = fast_rows(len(self.s)) if self._fast_rows is None else self._fast_rows
        if sub is None:
            return self
        if self._fast is None:
            self._fast = Columns(self.s.take(sub), Scorer(self.scorer.Q[sub], self.scorer.r[sub]))
        return self._fast


def fast_rows(n: int) -> np.ndarray | None:
    """Rows of :attr:`Columns.fast` among ``n`` samples: every ``ceil(n / 8000)``-th above
    12000 samples, None (all) below."""
    if n <= 12000:
        return None
    return np.arange(0, n, math.ceil(n / 8000))


def refine_1d(
    cols: Columns,
    make: Callable[[float], Effect],
    a: float,
    b: float,
    x0: float,
    g0: float,
    xtol: float,
) -> tuple[Effect, float]:
    """Bounded 1-D maximisation of the gain over x in [a, b] (x0, g0: coarse best)."""
    if not b > a:
        return make(x0), g0
    res = optimize.minimize_scalar(
        lambda x: -cols.gain(make(x)),
        bounds=(a, b),
        method="bounded",
        options={"xatol": xtol, "maxiter": 40},
    )
    if -res.fun > g0:
        return make(float(res.x)), float(-res.fun)
    return make(x0), g0


def scan_log(
    cols: Columns, make: Callable[[float], Effect], lo: float, hi: float, n: int = 24
) -> tuple[Effect, float]:
    """Best hyper-parameter: log grid, then a bounded 1-D search between the grid
    neighbours of the best point (both on :attr:`Columns.fast`; the returned gain is on
    every sample)."""
    fast = cols.fast
    grid = np.geomspace(lo, hi, n)
    gains = np.array([fast.gain(make(h)) for h in grid])
    i = int(np.argmax(gains))
    a, b = math.log(grid[max(i - 1, 0)]), math.log(grid[min(i + 1, n - 1)])
    e, g = refine_1d(
        fast, lambda lh: make(math.exp(lh)), a, b, math.log(grid[i]), float(gains[i]), 1e-4
    )
    return (e, g) if fast is cols else (e, cols.gain(e))
