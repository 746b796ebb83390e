"""IDIM-IV: instrumental variables (Janot, Vandanjon & Gautier, IEEE TCST 2014).

With instruments Z (m x b, column for column with W) correlated with W but not with the
error: theta = (Z^T W)^-1 Z^T y; sigma^2 = ||y - W theta||^2 / (m - b) and
C = sigma^2 (Z^T W)^-1 Z^T Z (W^T Z)^-1, which is the LS covariance when Z = W. Z enters only
through its column space: with Z = Q_z R_z (thin QR of the unit-norm Z), A = Q_z^T W_s,
theta_s = A^-1 Q_z^T y and the covariance factor is A^-1 A^-T.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from .. import DataError
from .base import RCOND, Estimator, RankDeficientError, dependency_message, dependent_columns
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
        Qz, Rz = scipy.linalg.qr(Zs, mode="economic")
        dz = np.abs(np.diag(Rz))
        if b and (dz.max() == 0 or dz.min() <= RCOND * dz.max()):
            deps = dependent_columns(Z, names) or [(names[int(np.argmin(dz))], [])]
            raise RankDeficientError("instruments: " + dependency_message(deps),
                                     [n for n, _ in deps])
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
