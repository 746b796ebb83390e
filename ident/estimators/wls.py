"""IDIM-WLS: least squares weighted per group of rows (Gautier's practice, paper eq. 13-16).

A first LS fit gives each group g (e.g. the rows of one joint) its residual variance
sigma_g^2 = ||rho_g||^2 / (m_g - b_g), b_g the columns not zero on the group's rows; the rows
of group g are scaled by 1/sigma_g and the system refitted:
theta = (sum_g W_g^T W_g / sigma_g^2)^-1 sum_g W_g^T y_g / sigma_g^2, C = sigma_w^2 times that
inverse, sigma_w^2 the weighted residual variance (~1). One group (``groups=None``): LS.
"""

from __future__ import annotations

import numpy as np

from .. import DataError
from .base import Estimator, Solution
from .ls import LS

__all__ = ["WLS"]


class WLS(Estimator):
    """Per-group weighted least squares (module doc)."""

    name = "wls"
    reweights = True

    def weights(self, sigma_groups: np.ndarray) -> np.ndarray:
        """1 / sigma_g^2.

        Raises
        ------
        DataError
            A group has zero residual (its weight would be infinite).
        """
        s = np.asarray(sigma_groups, dtype=float)
        if np.any(s <= 0):
            raise DataError("a joint has zero residual; WLS weights undefined (use method='ls')")
        return 1.0 / s**2

    def _solve(self, W, y, Z, groups, names):
        m, b = W.shape
        labels = np.zeros(m, dtype=int) if groups is None else np.asarray(groups).ravel()
        if labels.shape != (m,):
            raise DataError(f"wls: groups has shape {np.shape(groups)}, expected ({m},)")
        first = LS()._solve(W, y, None, None, names)
        uniq, inv = np.unique(labels, return_inverse=True)
        sig = np.empty(uniq.size)
        for k in range(uniq.size):
            rows = inv == k
            bg = int(np.count_nonzero(np.any(W[rows] != 0, axis=0)))
            rg = first.residual[rows]
            sig[k] = np.sqrt(float(rg @ rg) / max(int(rows.sum()) - bg, 1))
        w = self.weights(sig)
        sw = np.sqrt(w)[inv]
        sol = LS()._solve(W * sw[:, None], y * sw, None, None, names)
        return Solution(theta=sol.theta, cov=sol.cov, sigma2=sol.sigma2, rank=sol.rank,
                        residual=y - W @ sol.theta, dof=sol.dof, cond=sol.cond,
                        cond_raw=sol.cond_raw, weights=w)
