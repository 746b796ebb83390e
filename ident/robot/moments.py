"""Quadrant- and E-weighted moment matrices of the n-dof identification model, accumulated in
one pass over chunks, and the (Gauss-Newton) normal equations evaluated from them.

For joint j and sample i, the row vector of everything the models read is::

    v_ij = [W_ij (its non-zero base columns), p_ij, sign(dq_ij), dq_ij, 1, tau_ij]

(W: base rigid-body + rotor row, p: known payload torque, tau: measured torque). Every model of
this package predicts, in quadrant s (s = 0 motor P+, s = 1 generator P-, eq. 27-28)::

    tau_hat_ij = (c0_s + E_ij c1_s)^T v_ij      E_ij = exp(-|dq_ij| / q_s,j)  (eq. 29)

with coefficient vectors c0, c1 that depend on the parameters x (linearly for the usual model,
eq. 5/8; bilinearly for the paper's, eq. 30), and its Jacobian rows are (D0_s + E D1_s)^T v.
So every sum the estimators need -- J^T J, J^T r, ||r||^2, Z^T J, Z^T Z -- is a quadratic form
in the moments::

    M_s[e] = sum over samples in quadrant s of E^e v_z v^T,   e = 0, 1, 2

(v_z = v for least squares; v with the instrument's acceleration for IDIM-IV). One pass over
the data builds them (memory: k x 2 x 3 matrices of size (p_j + 5)^2, independent of the
number of samples); the iterations then cost nothing per sample. Only the samples where E is
not negligible (< :data:`E_TINY`) enter the e >= 1 moments, so the pass costs about one
Gram matrix per joint.

When the rows of a LINEAR model are given whole -- the paper model's products form on the
columns formed at full rate (:func:`ident.robot.design.products_columns`), whose low-pass
blends both quadrants near a quadrant change, so that no row belongs to one quadrant --
:class:`RowMoments` holds sum u u^T of the rows v = [u, tau] instead (one slot, no power of E),
and the same :meth:`JointMoments.normal` evaluates them with the coefficients
:func:`ident.robot.paper.rows_coefficients` (c0 = the parameters, D0 = the identity).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from trajectories.friction import quadrant_weights

from . import RobotIdentError

__all__ = ["E_TINY", "N_EXTRA", "JointMoments", "RowMoments"]

#: E below this is treated as 0 in the E-weighted moments (relative contribution < 1e-14).
E_TINY = 1e-14
#: Entries of v after the base columns: p, sign(dq), dq, 1, tau.
N_EXTRA = 5
#: Local indices (offsets after the base columns) of the entries of v.
IP, ISG, IDQ, ONE, IY = 0, 1, 2, 3, 4


@dataclass
class JointMoments:
    """Moments of one joint (module doc). ``cols``: the base columns present in this joint's
    rows (others are structurally zero); ``nv = len(cols) + 5``.

    Attributes
    ----------
    vv : ndarray, shape (2, 3, nv, nv)
        sum P^s E^e v v^T (s: 0 motor, 1 generator; e: power of E).
    zv, zz : ndarray, shape (2, 3, nv, nv), or None
        sum P^s E^e v_z v^T and v_z v_z^T (instrumental variables only).
    n : int
        Number of samples used.
    """

    cols: np.ndarray
    iv: bool = False
    powers: int = 3
    vv: np.ndarray = field(init=False)
    zv: np.ndarray | None = field(init=False, default=None)
    zz: np.ndarray | None = field(init=False, default=None)
    n: int = field(init=False, default=0)

    def __post_init__(self) -> None:
        nv = self.nv
        self.vv = np.zeros((2, 3, nv, nv))
        if self.iv:
            self.zv = np.zeros((2, 3, nv, nv))
            self.zz = np.zeros((2, 3, nv, nv))

    @property
    def nv(self) -> int:
        return len(self.cols) + N_EXTRA

    def add(self, VT: np.ndarray, weights: tuple[np.ndarray, np.ndarray], E: np.ndarray,
            VzT: np.ndarray | None = None) -> None:
        """Accumulate the rows given TRANSPOSED, VT (nv, m), with their quadrant weights
        ``weights`` = (P+, P-) (each (m,), :func:`trajectories.friction.quadrant_weights`)
        and E (m,); VzT the instrument rows (nv, m)."""
        if VT.shape[1] == 0:
            return
        if self.iv and VzT is None:
            raise RobotIdentError("JointMoments.add: instrument rows missing for IDIM-IV")
        self.n += VT.shape[1]
        for s, w in enumerate(weights):
            sel = w > 0
            if not sel.any():
                continue
            every = bool(sel.all())
            ws = w if every else w[sel]
            a = VT if every else VT[:, sel]
            az = None if VzT is None else (VzT if every else VzT[:, sel])
            es = E if every else E[sel]
            self._add(s, 0, a, az, ws)
            if self.powers > 1:
                big = es > E_TINY
                if big.any():
                    ab, eb, wb = a[:, big], es[big], ws[big]
                    azb = None if az is None else az[:, big]
                    for e in range(1, self.powers):
                        self._add(s, e, ab, azb, wb * eb**e)

    def move(self, VT: np.ndarray, dplus: np.ndarray, E: np.ndarray,
             VzT: np.ndarray | None = None, dminus: np.ndarray | None = None) -> None:
        """Move rows between the quadrants: P+ of the rows VT (nv, m) changed by ``dplus``
        (m,) (new - old), so their terms are added to s = 0 with weight dplus and to s = 1
        with -dplus (the row count does not change). ``dminus``: the change of P- when it is
        not -dplus (rows entering or leaving the fit: P+ = P- = 0 while left out)."""
        if VT.shape[1] == 0:
            return
        if self.iv and VzT is None:
            raise RobotIdentError("JointMoments.move: instrument rows missing for IDIM-IV")
        if dminus is None:
            dminus = -dplus
        else:
            self.n += int(round(float(np.sum(dplus + dminus))))
        for s, w in ((0, dplus), (1, dminus)):
            self._add(s, 0, VT, VzT, w)
            if self.powers > 1:
                big = E > E_TINY
                if big.any():
                    ab, eb, wb = VT[:, big], E[big], w[big]
                    azb = None if VzT is None else VzT[:, big]
                    for e in range(1, self.powers):
                        self._add(s, e, ab, azb, wb * eb**e)

    def _add(self, s: int, e: int, a: np.ndarray, az: np.ndarray | None,
             w: np.ndarray) -> None:
        aw = a * w
        self.vv[s, e] += aw @ a.T
        if az is not None:
            azw = az * w
            self.zv[s, e] += azw @ a.T
            self.zz[s, e] += azw @ az.T

    def normal(
        self, coeffs: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]
    ) -> tuple[np.ndarray, np.ndarray, float, np.ndarray | None, float]:
        """Normal equations of this joint at given coefficients.

        Parameters
        ----------
        coeffs : list of 2 tuples (c0, c1, D0, D1)
            Per quadrant: prediction coefficients c0, c1 (nv,) and Jacobian coefficients
            D0, D1 (nv, nx) (module doc).

        Returns
        -------
        A : ndarray (nx, nx)
            J^T J (least squares) or Z^T J (IV).
        g : ndarray (nx,)
            J^T r (or Z^T r), r = tau - tau_hat.
        rr : float
            ||r||^2.
        C : ndarray (nx, nx) or None
            Z^T Z (IV only).
        yy : float
            ||tau||^2 over the samples used.
        """
        nv = self.nv
        ey = np.zeros(nv)
        ey[nv - N_EXTRA + IY] = 1.0
        nx = coeffs[0][2].shape[1]
        A = np.zeros((nx, nx))
        g = np.zeros(nx)
        C = np.zeros((nx, nx)) if self.iv else None
        rr = 0.0
        mz = self.zv if self.iv else self.vv
        nt = len(self.cols)
        for s in (0, 1):
            c0, c1, D0, D1 = coeffs[s]
            d = (ey - c0, -c1)
            D = (D0, D1)
            lin = not (np.any(c1) or np.any(D1))
            terms = ((0, 0),) if lin else ((0, 0), (0, 1), (1, 0), (1, 1))
            for e, f in terms:  # the residual: the sums of cost(), in its order
                rr += float(d[e] @ self.vv[s, e + f] @ d[f])
            gam = _scaled_identity(D0, D1, nt, lin)
            if gam is None:  # general Jacobian coefficients: the dense products
                for e, f in terms:
                    M = mz[s, e + f]
                    A += D[e].T @ (M @ D[f])
                    g += D[e].T @ (M @ d[f])
                    if C is not None:
                        C += D[e].T @ self.zz[s, e + f] @ D[f]
                continue
            # every model here: the theta block of D_e is gam_e times the identity (theta
            # enters as (a + b E) W theta), so D^T M D needs dense products with the
            # per-joint block's columns only
            Dz, dz = _stack(D, lin), np.concatenate(d[:1] if lin else d)
            A += _sandwich(_stack_moments(mz[s], lin), Dz, gam, nt, nv)
            g += _apply_t(Dz, gam, nt, nv, _stack_moments(mz[s], lin) @ dz)
            if C is not None:
                C += _sandwich(_stack_moments(self.zz[s], lin), Dz, gam, nt, nv)
        yy = float(self.vv[0, 0, -1, -1] + self.vv[1, 0, -1, -1])
        return A, g, max(rr, 0.0), C, yy  # rr: quadratic form, clip rounding below 0

    def cost_polynomial(self, dpoly: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
        """||r||^2 along a line as a polynomial in its step length lam: the residual
        coefficients d_e(lam) = sum_i lam^i dpoly[s][e][i] (d_0 = e_tau - c0, d_1 = -c1 of
        :meth:`normal`; arrays (m, nv)) give ||r(lam)||^2 = sum_k lam^k out[k], out of
        shape (2 m - 1,). Every model here is bilinear in its parameters, so m = 3 (c
        quadratic in lam) gives the exact cost at every lam from one evaluation."""
        m = dpoly[0][0].shape[0]
        out = np.zeros(2 * m - 1)
        for s in (0, 1):
            d = dpoly[s]
            lin = not np.any(d[1])
            terms = ((0, 0),) if lin else ((0, 0), (0, 1), (1, 0), (1, 1))
            for e, f in terms:
                P = d[e] @ self.vv[s, e + f] @ d[f].T
                for i in range(m):
                    out[i:i + m] += P[i]
        return out

    def cost(self, coeffs: list[tuple[np.ndarray, np.ndarray]]) -> float:
        """||r||^2 of :meth:`normal` alone, from the prediction coefficients (c0, c1) per
        quadrant (the Jacobian not needed: a line search's trial points). The same sums in
        the same order as :meth:`normal` (terms with c1 = 0 add exact zeros there), so the
        two agree to the last bit."""
        nv = self.nv
        ey = np.zeros(nv)
        ey[nv - N_EXTRA + IY] = 1.0
        rr = 0.0
        for s in (0, 1):
            c0, c1 = coeffs[s][0], coeffs[s][1]
            d = (ey - c0, -c1)
            terms = ((0, 0),) if not np.any(c1) else ((0, 0), (0, 1), (1, 0), (1, 1))
            for e, f in terms:
                rr += float(d[e] @ self.vv[s, e + f] @ d[f])
        return max(rr, 0.0)


def _scaled_identity(D0: np.ndarray, D1: np.ndarray, nt: int,
                     lin: bool) -> tuple[float, float] | None:
    """(gam0, gam1) when the leading nt x nt blocks of D0, D1 are gam_e times the identity
    and the rest of their first nt columns is zero; else None."""
    out = []
    for De in (D0,) if lin else (D0, D1):
        lead = De[:, :nt]
        gam = float(lead[0, 0]) if nt else 0.0
        if np.count_nonzero(lead) > (nt if gam else 0) or np.any(np.diagonal(lead) != gam):
            return None
        out.append(gam)
    return (out[0], 0.0 if lin else out[1])


def _stack(D: tuple[np.ndarray, np.ndarray], lin: bool) -> np.ndarray:
    """[D0; D1] (2 nv, nx), or D0 alone for a linear model."""
    return D[0] if lin else np.vstack(D)


def _stack_moments(m: np.ndarray, lin: bool) -> np.ndarray:
    """[[M0, M1], [M1, M2]] of the moments m (3, nv, nv) of one quadrant, or M0 (linear)."""
    if lin:
        return m[0]
    nv = m.shape[1]
    out = np.empty((2 * nv, 2 * nv))
    out[:nv, :nv], out[:nv, nv:], out[nv:, :nv], out[nv:, nv:] = m[0], m[1], m[1], m[2]
    return out


def _apply_t(Dz: np.ndarray, gam: tuple[float, float], nt: int, nv: int,
             w: np.ndarray) -> np.ndarray:
    """Dz^T w with Dz's theta block gam_e I (rows e nv .. e nv + nt)."""
    out = np.empty((Dz.shape[1],) + w.shape[1:])
    top = gam[0] * w[:nt]
    if Dz.shape[0] > nv and gam[1]:
        top = top + gam[1] * w[nv:nv + nt]
    out[:nt] = top
    out[nt:] = Dz[:, nt:].T @ w
    return out


def _sandwich(Mz: np.ndarray, Dz: np.ndarray, gam: tuple[float, float], nt: int,
              nv: int) -> np.ndarray:
    """Dz^T Mz Dz with Dz's theta block gam_e I: the dense products only on its other
    columns."""
    MD = np.empty((Mz.shape[0], Dz.shape[1]))
    left = gam[0] * Mz[:, :nt]
    if Dz.shape[0] > nv and gam[1]:
        left = left + gam[1] * Mz[:, nv:nv + nt]
    MD[:, :nt] = left
    MD[:, nt:] = Mz @ Dz[:, nt:]
    return _apply_t(Dz, gam, nt, nv, MD)


@dataclass
class RowMoments(JointMoments):
    """Moments of one joint's rows given whole: v = [u, tau] with u the nu = ``len(cols)``
    columns of a linear model tau = u^T x (module doc). All in the slot s = 0, e = 0 (nothing
    in s = 1 nor e >= 1), so :meth:`JointMoments.normal` and :meth:`JointMoments.cost` give
    the linear least squares' sums; ``nv = nu + 1``.

    Attributes
    ----------
    quadrant_n : ndarray, shape (2,)
        Rows in the motor and the generator quadrant by their low-passed P+ (> 1/2: motor,
        = 1/2: half each), for reports.
    """

    powers: int = 1
    quadrant_n: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        super().__post_init__()
        self.quadrant_n = np.zeros(2)

    @property
    def nv(self) -> int:
        return len(self.cols) + 1

    def add_rows(self, VT: np.ndarray, pplus: np.ndarray,
                 VzT: np.ndarray | None = None) -> None:
        """Accumulate the rows given TRANSPOSED, VT (nu + 1, m) (u then tau), with their
        low-passed P+ (m,) (counted only); VzT the instrument rows (nu + 1, m)."""
        if VT.shape[1] == 0:
            return
        if self.iv and VzT is None:
            raise RobotIdentError("RowMoments.add_rows: instrument rows missing for IDIM-IV")
        self.n += VT.shape[1]
        self.vv[0, 0] += VT @ VT.T
        if VzT is not None and self.zv is not None and self.zz is not None:
            self.zv[0, 0] += VzT @ VT.T
            self.zz[0, 0] += VzT @ VzT.T
        w = quadrant_weights(pplus - 0.5)  # the low-passed P+ rounded: the quadrant counts
        self.quadrant_n += (float(w[0].sum()), float(w[1].sum()))

    def add(self, *args, **kwargs) -> None:  # noqa: D102 (the rows are given whole)
        raise RobotIdentError("RowMoments: rows are given whole (add_rows), not by quadrant")

    def move(self, *args, **kwargs) -> None:  # noqa: D102
        raise RobotIdentError("RowMoments: rows are given whole; no quadrant to move")
