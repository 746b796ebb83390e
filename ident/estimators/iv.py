"""IDIM-IV: instrumental variables (Janot, Vandanjon & Gautier, IEEE TCST 2014).

With instruments Z (m x b, column for column with W) correlated with W but not with the
error: theta = (Z^T W)^-1 Z^T y; sigma^2 = ||y - W theta||^2 / (m - b) and
C = sigma^2 (Z^T W)^-1 Z^T Z (W^T Z)^-1, which is the LS covariance when Z = W. Z enters only
through its column space: with Z = Q_z R_z (thin QR of the unit-norm Z), A = Q_z^T W_s,
theta_s = A^-1 Q_z^T y and the covariance factor is A^-1 A^-T.

Rank rule (:meth:`~ident.estimators.base.Estimator.rank_drops`): IV is least squares on the
projected regressor P_Z W (P_Z the projector on Z's columns), so the rule judges P_Z W_s (W's
columns at unit norm) after the rows' rule on W_s: a column whose instrumented part lies within
RCOND times the longest one of the others' span is not determined
(:func:`~ident.estimators.base.weak_instruments`), even when W^T W alone would keep it (weak
instruments in that direction: a column nearly constant on the reference trajectory, or nearly
the same as another one there, while the measured one varies).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from .. import DataError
from .base import RCOND, Estimator, RankDeficientError
from .base import scaled as _scaled

__all__ = ["IV"]


class IV(Estimator):
    """Instrumental variables (module doc); ``solve`` needs ``instruments``."""

    name = "iv"
    needs_instruments = True
    symmetric = False

    def _solve_scaled(self, Ws, y, Q, R, piv, Z, names):
        m, b = Ws.shape
        if Z is None or Z.shape != (m, b):
            shape = None if Z is None else Z.shape
            raise DataError(f"instruments have shape {shape}, expected {(m, b)} like W")
        if not np.all(np.isfinite(Z)):
            raise DataError("instruments Z hold NaN or infinite values")
        Zs, _ = _scaled(Z)
        # the rank rule of what IV solves (least squares on P_Z W_s; W_s passed it already)
        weak = self.rank_drops(Ws.T @ Ws, names, A=Zs.T @ Ws, C=Zs.T @ Zs)
        if weak:
            raise RankDeficientError(
                "instruments: " + "; ".join(f"{names[i]}: {why}" for i, why in weak),
                [names[i] for i, _ in weak])
        Qz, _ = scipy.linalg.qr(Zs, mode="economic")
        A = Qz.T @ Ws
        try:
            lu = scipy.linalg.lu_factor(A, check_finite=False)
        except (np.linalg.LinAlgError, ValueError) as exc:  # pragma: no cover
            raise RankDeficientError(
                f"instruments uncorrelated with the regressor ({exc})") from None
        sv = np.linalg.svd(A, compute_uv=False)
        if sv[-1] <= RCOND * sv[0]:
            raise RankDeficientError(
                "instruments: Z^T W is singular (some column's instrument is uncorrelated "
                "with it)", lo=float(sv[-1]), hi=float(sv[0]))
        theta_s = scipy.linalg.lu_solve(lu, Qz.T @ y)
        Ainv = scipy.linalg.lu_solve(lu, np.eye(b))
        return theta_s, Ainv @ Ainv.T
