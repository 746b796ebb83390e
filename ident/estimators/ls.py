"""IDIM-LS: ordinary least squares through the column-pivoted QR (paper eq. 12-15).

theta = (W^T W)^-1 W^T y computed as R^-1 Q^T y on the unit-norm columns (the conditioning
is not squared); C = sigma^2 (W^T W)^-1 with sigma^2 = ||rho||^2 / (m - b) (eq. 14-15).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from .base import Estimator

__all__ = ["LS"]


class LS(Estimator):
    """Ordinary least squares (module doc)."""

    name = "ls"

    def _solve_scaled(self, Ws, y, Q, R, piv, Z, names):
        b = Ws.shape[1]
        z = scipy.linalg.solve_triangular(R, Q.T @ y)
        theta_s = np.empty(b)
        theta_s[piv] = z
        Rinv = scipy.linalg.solve_triangular(R, np.eye(b))
        cov_p = Rinv @ Rinv.T  # (Ws[:, piv]^T Ws[:, piv])^-1
        cov_s = np.empty_like(cov_p)
        cov_s[np.ix_(piv, piv)] = cov_p
        return theta_s, cov_s
