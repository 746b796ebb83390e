"""The residual of a full-rank least-squares (or IDIM-IV) fit, the same floats as
:func:`ident.estimate.fit_least_squares` gives, without its statistics.

The exact refits of the refinement (:func:`ident.refine.refine`) need only the residual of
most of their fits: the covariance, the deviations and the condition numbers of a fit that
is then discarded are wasted, and so is the second column-pivoted QR that
:func:`~ident.estimate.solve_ls` repeats after :func:`~ident.estimate.dependent_columns`.
:func:`quick_residual` follows the same operations on the same arrays as
:func:`~ident.estimate.fit_least_squares` (``eliminate=False``) up to the residual, so the
estimate and the residual are bit for bit the same, and returns None whenever that function
would drop a column or raise (zero or dependent columns, singular instruments, too few
samples, non-finite values): the caller then fits as usual.

Full rank without the pivoted QR (instruments): for the column-scaled ``Ws`` (unit
columns) and ``A = Q_z^T Ws`` (``Q_z`` orthonormal), every singular value of A is at most
the matching one of Ws, and the smallest |diagonal entry| of the triangular factor of the
pivoted QR of Ws is at least its smallest singular value; the first is the largest column
norm, 1. So ``σ_min(A) > RANK_TOL`` (with a margin of :data:`MARGIN`) guarantees that the
pivoted QR would find full rank.

Pure numerics.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from .estimate import RANK_TOL
from .estimators import get_estimator
from .estimators.base import scaled as _scaled

__all__ = ["MARGIN", "quick_residual"]

#: Margin on RANK_TOL for the full-rank guarantee of the instrument path (rounding of the
#: orthonormal factor and of the unit column norms, ~1e-15, is far below).
MARGIN = 100.0


def quick_residual(
    W: np.ndarray, Y: np.ndarray, Z: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, float] | None:
    """``(chi, residual, rel_error)`` of ``fit_least_squares(W, Y, names, eliminate=False,
    Z=Z)``, or None when that fit would drop a column or raise.

    Parameters
    ----------
    W : ndarray, shape (m, b)
        Observation matrix.
    Y : ndarray, shape (m,)
        Measurements [N m].
    Z : ndarray, shape (m, b), optional
        Instruments (IDIM-IV), column for column with W; None: OLS.

    Returns
    -------
    (ndarray, ndarray, float) or None
        The estimate, the residual Y - W chi [N m] and ||rho|| / ||Y||.
    """
    W = np.asarray(W, dtype=float)
    Y = np.asarray(Y, dtype=float).ravel()
    if W.ndim != 2 or W.shape[0] != Y.shape[0]:
        return None
    m, b = W.shape
    if m <= b or b == 0:
        return None
    if not (np.all(np.isfinite(W)) and np.all(np.isfinite(Y))):
        return None
    norms = np.linalg.norm(W, axis=0)
    scale = max(float(norms.max(initial=0.0)), 1e-300)
    if np.any(norms <= 1e-12 * scale):
        return None
    cols = list(range(b))
    Wc = W[:, cols]  # the copy fit_least_squares hands to solve_ls (same layout)
    Ws, norms = _scaled(Wc)
    if Z is None:
        Q, R, piv = scipy.linalg.qr(Ws, mode="economic", pivoting=True)
        d = np.abs(np.diag(R))
        if d[0] == 0 or d[-1] <= RANK_TOL * d[0]:
            return None
        z = scipy.linalg.solve_triangular(R, Q.T @ Y)
        chi_s = np.empty(b)
        chi_s[piv] = z
    else:
        Z = np.asarray(Z, dtype=float)
        if Z.shape != W.shape or not np.all(np.isfinite(Z)):
            return None
        Zs, _ = _scaled(Z[:, cols])
        Qz, Rz = scipy.linalg.qr(Zs, mode="economic")
        dz = np.abs(np.diag(Rz))
        if dz.max() == 0 or dz.min() <= RANK_TOL * dz.max():
            return None
        if get_estimator("iv").rank_drops(Ws.T @ Ws, [str(k) for k in range(b)],
                                          A=Zs.T @ Ws, C=Zs.T @ Zs):
            return None  # IV's rank rule leaves a column out (fit_least_squares would)
        A = Qz.T @ Ws
        try:
            lu = scipy.linalg.lu_factor(A, check_finite=False)
        except (np.linalg.LinAlgError, ValueError):  # pragma: no cover
            return None
        sv = np.linalg.svd(A, compute_uv=False)
        if sv[-1] <= RANK_TOL * sv[0] or sv[-1] <= MARGIN * RANK_TOL:
            return None
        chi_s = scipy.linalg.lu_solve(lu, Qz.T @ Y)
    chi = chi_s / norms
    rho = Y - Wc @ chi
    ny = float(np.linalg.norm(Y))
    return chi, rho, float(np.linalg.norm(rho) / ny) if ny > 0 else float("nan")
