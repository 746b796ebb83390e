"""The Gauss-Newton sums of every joint of the n-dof estimator at once.

``RobotModel._gauss_newton`` (:mod:`ident.robot.estimate`) needs, at every step, J^T W J and
J^T W r of all joints and the cost along the step; joint by joint (:meth:`JointMoments.normal`)
that is ~30 small numpy calls per joint and quadrant. Here the joints' moments are padded to
one number of base columns and stacked, so each sum is a few batched products for all joints
(the usual and the paper model; IDIM-IV and the paper model's products form -- a linear
model whose per-joint blocks differ in size, solved in one step -- keep the per-joint path).
Same sums, rounding apart (tests/test_robot_normal.py).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .moments import N_EXTRA
from .paper import batch_coefficients

__all__ = ["PackedMoments"]


@dataclass
class PackedMoments:
    """The Gauss-Newton sums of every joint at once (``RobotModel._gauss_newton``): joint j's
    moments padded to m base columns, stacked as Mz[j, s] = [[M0, M1], [M1, M2]] (rows of v
    and of E v, quadrant s); the Jacobian's theta block is gam_e times the identity and its
    friction block B (:func:`~ident.robot.paper.batch_coefficients`), so D^T Mz D needs dense
    products with B only. ``tidx``, ``bidx``: global indices of the padded theta entries (nx:
    a zero slot for the padding) and of the per-joint block; ``gidx`` both."""

    model: str
    Mz: np.ndarray
    tidx: np.ndarray
    bidx: np.ndarray
    gidx: np.ndarray
    m: int
    nx: int

    def _coeffs(self, x: np.ndarray, s: int, jacobian: bool = True) -> tuple[np.ndarray, ...]:
        xe = np.append(x, 0.0)
        return batch_coefficients(self.model, xe[self.tidx], x[self.bidx], s, jacobian)

    def normal(self, x: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(J^T W J, J^T W r) over all joints and both quadrants."""
        m, nv = self.m, self.m + N_EXTRA
        k = self.tidx.shape[0]
        nloc = self.gidx.shape[1]
        A_loc = np.zeros((k, nloc, nloc))
        g_loc = np.zeros((k, nloc))
        ey = np.zeros(nv)
        ey[-1] = 1.0
        for s in (0, 1):
            c0, c1, g0, g1, B = self._coeffs(x, s)
            Mz = self.Mz[:, s]
            dz = np.concatenate([ey - c0, -c1], axis=1)
            MD = np.empty((k, 2 * nv, nloc))
            a0, a1 = g0[:, None, None], g1[:, None, None]
            MD[:, :, :m] = a0 * Mz[:, :, :m] + a1 * Mz[:, :, nv:nv + m]
            MD[:, :, m:] = Mz @ B
            A_loc[:, :m] += a0 * MD[:, :m] + a1 * MD[:, nv:nv + m]
            A_loc[:, m:] += np.swapaxes(B, 1, 2) @ MD
            w = (Mz @ dz[:, :, None])[:, :, 0]
            g_loc[:, :m] += g0[:, None] * w[:, :m] + g1[:, None] * w[:, nv:nv + m]
            g_loc[:, m:] += (np.swapaxes(B, 1, 2) @ w[:, :, None])[:, :, 0]
        A_loc *= weights[:, None, None]
        g_loc *= weights[:, None]
        n1 = self.nx + 1
        lin = self.gidx[:, :, None] * n1 + self.gidx[:, None, :]
        A = np.bincount(lin.ravel(), A_loc.ravel(), n1 * n1).reshape(n1, n1)[:-1, :-1]
        g = np.bincount(self.gidx.ravel(), g_loc.ravel(), n1)[:-1]
        return A, g

    def line_cost(self, x: np.ndarray, step: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """Weighted ||r||^2 at x + lam step as polynomial coefficients in lam (lowest first),
        as ``RobotModel._line_cost``, every joint at once."""
        nv = self.m + N_EXTRA
        ey = np.zeros(nv)
        ey[-1] = 1.0
        out = np.zeros(5)
        for s in (0, 1):
            mid, plus, minus = (self._coeffs(v, s, jacobian=False)
                                for v in (x, x + step, x - step))
            d = []
            for e in (0, 1):
                first = 0.5 * (plus[e] - minus[e])
                second = 0.5 * (plus[e] + minus[e]) - mid[e]
                d.append(np.stack([(ey if e == 0 else 0.0) - mid[e], -first, -second], axis=1))
            Dp = np.concatenate(d, axis=2)  # (k, 3, 2 nv): lam^0, lam^1, lam^2
            P = Dp @ self.Mz[:, s] @ np.swapaxes(Dp, 1, 2)  # (k, 3, 3)
            P = np.tensordot(weights, P, axes=1)
            for i in range(3):
                out[i:i + 3] += P[i]
        return out
