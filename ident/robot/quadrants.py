"""Incremental re-decision of the model quadrants (``RobotModel(quadrant="model")``) without
new passes over the data.

With ``quadrant="model"`` the quadrant of row i of joint j is sign(P_out) =
sign(tau_out_hat_ij dq_ij), tau_out_hat_ij = W_ij theta + p_ij (eq. 27-28 with the model's
output torque), so it moves with the estimate of theta. Instead of re-evaluating the regressor
on every sample at each re-decision, one pass with a reference theta_0 keeps, per joint, the
rows closest to their quadrant boundary in theta-space::

    r_ij = |W_ij theta_0 + p_ij| / ||L^-1 W_ij^T||     (distance of theta_0 to the hyperplane
                                                      W_ij theta + p_ij = 0 in the metric G)

with G = L L^T = sum_i W_ij^T W_ij / m_j the joint's Gram matrix of the base columns (from the
previous pass; any symmetric positive definite G gives a valid bound, this one makes it scale-
invariant: ||L^T (theta - theta_0)|| is the RMS change of tau_out_hat over the joint's rows).
For any theta, |W_ij (theta - theta_0)| <= ||L^-1 W_ij^T|| ||L^T (theta - theta_0)||
(Cauchy-Schwarz), so a row with r_ij > ||L^T (theta_j - theta_0,j)|| (theta_j: the joint's base
columns) keeps its quadrant. The store keeps the rows of smallest r (at most ``capacity``) and
R_j = the smallest r of the rows it dropped: while ||L^T (theta_j - theta_0,j)|| < R_j (with a
rounding margin) every row outside the store provably keeps its quadrant, and the quadrants of
the stored rows are re-decided exactly; the moments are updated by the flipped rows only
(:meth:`JointMoments.move`). When the bound fails the caller makes a new full pass (a new
theta_0). The result is the same as with full passes at every re-decision, up to rounding.
"""

from __future__ import annotations

import numpy as np

from trajectories.friction import quadrant_weights

from ..quadrant_band import band_edge, band_step
from .moments import IDQ, IP, JointMoments

__all__ = ["QuadrantStore", "MARGIN"]

#: Relative safety margin on the bound (rounding of tau_out_hat in the two evaluations).
MARGIN = 1e-6


class QuadrantStore:
    """Rows of one joint nearest to their quadrant boundary (module doc).

    Parameters
    ----------
    theta0 : ndarray (nt,)
        The joint's base parameters used to decide the quadrants of the pass.
    capacity : int
        Rows kept at most (memory: capacity x nv floats, twice for IDIM-IV).
    gram : ndarray (nt, nt) or None
        Metric G of the bound (module doc); None: the identity (Euclidean norm).
    band : float
        The joint's quadrant band [N m] (``RobotModel.band_``): rows with |tau_out| below it
        are left out; 0: none.
    leave : float
        A row left out by the band returns only where |tau_out| reaches ``leave`` x ``band``
        (the band's hysteresis, :data:`ident.quadrant_band.BAND_LEAVE`); 1: none.

    Attributes
    ----------
    radius : float
        R_j: smallest r of the rows not kept (inf while every row is kept).
    VT, VzT : ndarray (nv, m)
        Kept rows (transposed) and their instrument rows (IV) or None.
    r : ndarray (m,)
        The kept rows' r_ij (the distance of theta_0 to the row's quadrant boundary, module doc).
    E, pplus, pminus : ndarray (m,)
        Their E = exp(-|dq| / q_s) and current P+, P- (eq. 27-28).
    out : ndarray (m,) bool
        The kept rows the band leaves out at the last decision.
    """

    def __init__(self, theta0: np.ndarray, capacity: int,
                 gram: np.ndarray | None = None, band: float = 0.0,
                 leave: float = 1.0) -> None:
        self.theta0 = np.array(theta0, dtype=float)
        self.band = float(band)
        self.leave = float(leave)
        nt = self.theta0.size
        self.L = np.eye(nt)
        if gram is not None and nt:
            G = 0.5 * (gram + gram.T)
            dmax = float(np.max(np.abs(np.diag(G)), initial=0.0))
            # a ridge keeps G positive definite; it only loosens the bound
            G = G + max(1e-9 * dmax, 1e-300) * np.eye(nt)
            try:
                self.L = np.linalg.cholesky(G)
            except np.linalg.LinAlgError:
                self.L = np.eye(nt)
        self.Linv = np.linalg.inv(self.L) if nt else self.L
        self.capacity = max(int(capacity), 0)
        self.radius = np.inf
        self.r = np.empty(0)
        self.VT: np.ndarray | None = None
        self.VzT: np.ndarray | None = None
        self.E = np.empty(0)
        self.pplus = np.empty(0)
        self.pminus = np.empty(0)
        self.out = np.empty(0, dtype=bool)
        self.nt = self.theta0.size

    def offer(self, VT: np.ndarray, VzT: np.ndarray | None, E: np.ndarray,
              weights: tuple[np.ndarray, np.ndarray], tau_out: np.ndarray,
              out: np.ndarray | None = None) -> None:
        """Offer the rows of one chunk (VT (nv, m), tau_out = W theta_0 + p (m,)) with their
        quadrant weights ``weights`` = (P+, P-) (each (m,),
        :func:`trajectories.friction.quadrant_weights`; both 0 for the rows left out by the
        band, ``out`` (m,) bool, None: |tau_out| < ``band``); keeps the ``capacity`` rows of
        smallest r over everything offered so far. With a band the distance is to the edge
        where a row changes state: |tau_out| = band for a row in the fit (it enters the band
        there, and flips only beyond), = ``leave`` x band for a row left out (it returns
        there: the band's hysteresis, :func:`ident.quadrant_band.band_edge`)."""
        nt = self.nt
        pplus, pminus = weights
        U = self.Linv @ VT[:nt]
        wn = np.sqrt(np.einsum("im,im->m", U, U))
        if out is None:
            out = np.abs(tau_out) < self.band if self.band > 0 else np.zeros(
                tau_out.shape, dtype=bool)
        a = band_edge(tau_out, out, self.band, self.leave)  # the band's one rule
        # ||W|| = 0: tau_out = p does not depend on theta, the row never changes quadrant
        r = np.divide(a, wn, out=np.full(a.shape, np.inf), where=wn > 0)
        cand = r < self.radius
        if not cand.all():
            dropped = r[~cand]
            self.radius = min(self.radius, float(dropped.min()))
        if not cand.any():
            return
        idx = np.flatnonzero(cand)
        r_all = np.concatenate([self.r, r[idx]])
        V_all = VT[:, idx] if self.VT is None else np.concatenate([self.VT, VT[:, idx]], 1)
        Vz_all = None
        if VzT is not None:
            Vz_all = (VzT[:, idx] if self.VzT is None
                      else np.concatenate([self.VzT, VzT[:, idx]], 1))
        E_all = np.concatenate([self.E, E[idx]])
        o_all = np.concatenate([self.out, out[idx]])
        p_all = np.concatenate([self.pplus, pplus[idx]])
        m_all = np.concatenate([self.pminus, pminus[idx]])
        if r_all.size > self.capacity:
            keep = np.argpartition(r_all, self.capacity)[:self.capacity] if self.capacity \
                else np.empty(0, dtype=int)
            mask = np.ones(r_all.size, dtype=bool)
            mask[keep] = False
            self.radius = min(self.radius, float(r_all[mask].min()))
            r_all, V_all, E_all, p_all = r_all[keep], V_all[:, keep], E_all[keep], p_all[keep]
            m_all, o_all = m_all[keep], o_all[keep]
            if Vz_all is not None:
                Vz_all = Vz_all[:, keep]
        self.r, self.VT, self.VzT, self.E, self.pplus = r_all, V_all, Vz_all, E_all, p_all
        self.pminus, self.out = m_all, o_all

    def covers(self, theta: np.ndarray) -> bool:
        """True when no row outside the store can be in another quadrant at ``theta``."""
        dist = np.linalg.norm(self.L.T @ (theta - self.theta0))
        return bool(dist < self.radius * (1.0 - MARGIN))

    def update(self, theta: np.ndarray, mom: JointMoments) -> int:
        """Re-decide the stored rows' quadrants at ``theta``, move the flipped rows' terms in
        ``mom``; returns how many rows changed quadrant."""
        if self.VT is None or self.r.size == 0:
            return 0
        nt = self.nt
        VT = self.VT
        tau_out = theta @ VT[:nt] + VT[nt + IP]
        pnew, mnew = quadrant_weights(tau_out * VT[nt + IDQ])
        if self.band > 0:  # the band's hysteresis (ident.quadrant_band, its one rule)
            out = band_step(tau_out, self.out, self.band, self.leave)
            pnew[out] = 0.0
            mnew[out] = 0.0
            self.out = out
        changed = (pnew != self.pplus) | (mnew != self.pminus)
        # rows that changed quadrant (entering or leaving the band is no change)
        flipped = changed if self.band <= 0 else changed & (
            (pnew + mnew > 0) & (self.pplus + self.pminus > 0))
        n = int(np.count_nonzero(flipped))
        if np.any(changed):
            Vz = None if self.VzT is None else self.VzT[:, changed]
            mom.move(VT[:, changed], pnew[changed] - self.pplus[changed], self.E[changed], Vz,
                     None if self.band <= 0 else mnew[changed] - self.pminus[changed])
            self.pplus, self.pminus = pnew, mnew
        return n
