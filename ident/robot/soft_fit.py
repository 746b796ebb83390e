"""The paper model with soft quadrant weights on the robot path (``RobotModel(quadrants="soft")``).

Eq. 30 gives each row one quadrant, P+ = [tau_out dq > 0]. Where the true load jitters across
zero within the chain's filter window (a gravity-free joint under a closed loop), the
low-passed friction is a blend of both quadrants (docs/robot-identification.md, "quadrants
blended by the low-pass"). The soft weight replaces each row's hard weights by their
expectation under a Gaussian load jitter x = s + n, n ~ N(0, sigma_j^2), mu = s sign(dq)
(:func:`trajectories.friction.soft_quadrant_weights`)::

    E[P+] = Phi(mu / sigma_j),  r = sigma_j phi(mu / sigma_j) sign(dq)
    E[P+ x] = E[P+] s + r,  E[P- x] = E[P-] s - r

    tau_j = E[P+ x] (a_m + b_m E) + E[P- x] (a_g - b_g E)
          + sgn (E[P+] (c_m + d_m E) + E[P-] (c_g + d_g E)) + F_V dq + OFF

with s = W_j theta + p_j the model's own load (never the measured torque), sgn the row's
Coulomb column (as the hard fit's) and sigma_j [N m] one more parameter per joint. As
sigma_j -> 0 the model is eq. 30 with the model quadrants.

The fit: the usual hard bilinear fit gives the start's theta; each sigma_j starts at the
lowest point of a 1-D profile (``SIGMA_START_GRID`` values log-spaced over its bounds, theta
held, the joint's ten paper parameters refitted by linear least squares at each: for fixed
theta and sigma_j they are linear), its block at that point's refit (a fixed start fraction
of the load RMS fell, on one simulated seed, into a shallow local minimum near the hard
limit; the profile is cheap: 13 linear fits per joint); then theta, every joint's ten paper
parameters and the sigma_j are fitted together on the same decimated rows (the joints' row
rule, without the quadrant band: the soft weight is what the band approximated) by nonlinear
least squares (``scipy.optimize.least_squares``, analytic Jacobian), with the WLS weights of
the hard fit, then once more with the joints' weights from the soft residuals (WLS). The
gauge of the hard fit (``fixed_``) is kept.

sigma_j is bounded by numbers of the model, never of the measured torque: within
[``SIGMA_MIN_FRACTION``, ``SIGMA_MAX_FRACTION``] x the RMS of the hard fit's load s_j on its
rows. For sigma much larger than the load the rectification column becomes a constant times
sign(dq), confounded with the Coulomb terms (on the real EMPS an unbounded sigma ran away to
500-750 N); a sigma_j on its bound is not identified (``quadrant_sigma_at_bound_``) and is
held there for the standard deviations.

Standard deviations: eq. 15 with the Jacobian at the solution (weighted), over the free
parameters and the sigma_j not on a bound (``cov_`` is the block of ``names_``). No block
jackknife and no pruning in soft mode (:func:`ident.robot.uncertainty.assess` reports the
analytic sigma only).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import least_squares
from scipy.special import ndtr

from trajectories.friction import soft_quadrant_weights, stribeck_exp

from . import RobotIdentError

__all__ = ["QUADRANTS", "SIGMA_MAX_FRACTION", "SIGMA_MIN_FRACTION", "SIGMA_START_GRID",
           "fit_soft", "predict_soft", "check_soft",
           "load_signs", "soft_record"]

#: ``RobotModel(quadrants=...)``: the hard model quadrants of eq. 27-28, or their expectation
#: under a fitted Gaussian load jitter.
QUADRANTS = ("hard", "soft")
#: Upper bound of sigma_j: this fraction of the RMS of the hard fit's load s_j on its rows.
SIGMA_MAX_FRACTION = 1.0
#: Lower bound of sigma_j (the hard limit, kept positive): this fraction of that RMS.
SIGMA_MIN_FRACTION = 1e-4
#: Points of the start's profile of sigma_j, log-spaced over its bounds (a factor 2.2 apart
#: for the bounds' 1e4).
SIGMA_START_GRID = 13
#: A sigma_j within this fraction of its bounds' span (hi - lo) of a bound is reported on it
#: (near the lower bound that is up to about 10 x lo: a sigma of 0.0129 N m for a lower bound
#: of 0.0046 and an upper of 45.9 is reported on the lower bound).
AT_BOUND_TOL = 1e-3

_SQRT_2PI = float(np.sqrt(2.0 * np.pi))


@dataclass
class _JointRows:
    """Joint j's rows: theta columns (nt, m), known torque p, dq [rad/s], Coulomb column,
    measured torque [N m] and E = exp(-|dq| / q_s)."""

    WT: np.ndarray
    p: np.ndarray
    dq: np.ndarray
    sgc: np.ndarray
    tau: np.ndarray
    E: np.ndarray


def check_soft(model: Any) -> None:
    """Refuse, in one line, what the soft quadrants cannot be (``RobotModel._setup``)."""
    q = model.quadrants
    if q not in QUADRANTS:
        raise RobotIdentError(f"RobotModel.quadrants: expected one of {QUADRANTS}, got {q!r}")
    if q == "hard":
        return
    if model.model != "paper" or model.form != "bilinear":
        raise RobotIdentError("RobotModel.quadrants: 'soft' is a weight of the paper model's "
                              f"bilinear form (model='paper'), got model={model.model!r}, "
                              f"form={model.form!r}")
    if model.method == "iv":
        raise RobotIdentError("RobotModel.quadrants: 'soft' is a least-squares fit (method "
                              "'ls' or 'wls'), got method='iv'")
    if model.quadrant != "model" or model.quadrant_theta is not None:
        raise RobotIdentError("RobotModel.quadrants: 'soft' weighs the quadrants by the "
                              "fitted model's own load: needs quadrant='model' without "
                              "quadrant_theta")


def _rows(model: Any, signals: Any) -> list[_JointRows]:
    """Every joint's rows under its row rule (``RobotModel._usable``; no quadrant band)."""
    k = len(model.cols_)
    parts: list[list[tuple]] = [[] for _ in range(k)]
    for sig, r, q, dq, ddq, tau, _z, pay, cc in model._chunks(signals, iv=False):
        W, p, kn = model._rows(q, dq, ddq, tau, pay, None if cc is None else cc[:2])
        sgs = model._sign(sig, r, cc)  # the chain's decimated sign(dq), as the hard fit's
        for j in range(k):
            WjT, pj = model._joint(W, p, kn, j)
            ok = model._usable(dq[:, j], tau[:, j], WjT, None if cc is None else cc[3][:, j])
            dqj = dq[ok, j]
            sgc = np.sign(dqj) if sgs is None else sgs[ok, j]
            parts[j].append((WjT[:, ok], pj[ok], dqj, sgc, tau[ok, j]))
    out = []
    for j, pj in enumerate(parts):
        WT = np.concatenate([a[0] for a in pj], axis=1)
        dq = np.concatenate([a[2] for a in pj])
        out.append(_JointRows(WT, np.concatenate([a[1] for a in pj]), dq,
                              np.concatenate([a[3] for a in pj]),
                              np.concatenate([a[4] for a in pj]),
                              stribeck_exp(dq, model.q_s_[j])))
    return out


def _joint_model(th: np.ndarray, blk: np.ndarray, sigma: float, WT: np.ndarray, p: np.ndarray,
                 dq: np.ndarray, sgc: np.ndarray, E: np.ndarray, jacobian: bool = True):
    """Prediction (m,) of one joint's soft eq. 30 and, with ``jacobian``, its derivatives
    on theta's entries (m, nt), on the block (m, 10) and on sigma (m,)."""
    s = th @ WT + p
    sg = np.sign(dq)
    z = s * sg / sigma
    pp = ndtr(z)
    pm = 1.0 - pp
    phi = np.exp(-0.5 * z * z) / _SQRT_2PI
    r = sigma * phi * sg
    xp, xm = pp * s + r, pm * s - r
    a_m, b_m, a_g, b_g, c_m, d_m, c_g, d_g, fv, off = blk
    A, G = a_m + b_m * E, a_g - b_g * E
    Cm, Cg = c_m + d_m * E, c_g + d_g * E
    pred = A * xp + G * xm + sgc * (pp * Cm + pm * Cg) + fv * dq + off
    if not jacobian:
        return pred
    # d xp / ds = E[P+], d xm / ds = E[P-]; d xp / d sigma = sg phi = - d xm / d sigma
    ds = A * pp + G * pm + sgc * (Cm - Cg) * phi * sg / sigma
    dsig = (A - G) * sg * phi - sgc * (Cm - Cg) * phi * z / sigma
    return pred, ds[:, None] * WT.T, _columns(xp, xm, pp, pm, E, sgc, dq), dsig


def _columns(xp: np.ndarray, xm: np.ndarray, pp: np.ndarray, pm: np.ndarray, E: np.ndarray,
             sgc: np.ndarray, dq: np.ndarray) -> np.ndarray:
    """The ten paper parameters' columns (m, 10) of the soft eq. 30 (a_m, b_m, a_g, b_g,
    c_m, d_m, c_g, d_g, F_V, OFF) from the load products E[P+ x], E[P- x], the weights
    E[P+], E[P-], E, the Coulomb column and dq [rad/s]."""
    return np.stack([xp, E * xp, xm, -E * xm, pp * sgc, pp * E * sgc, pm * sgc,
                     pm * E * sgc, dq, np.ones_like(dq)], axis=1)


def _block_columns(th: np.ndarray, sigma: float, rw: _JointRows) -> np.ndarray:
    """The columns (m, 10) of one joint's ten paper parameters in the soft eq. 30 at theta's
    entries ``th`` and ``sigma`` (the prediction is their product with the block)."""
    s = th @ rw.WT + rw.p
    pp, pm, r = soft_quadrant_weights(s, rw.dq, sigma)
    return _columns(pp * s + r, pm * s - r, pp, pm, rw.E, rw.sgc, rw.dq)


def _profile(th: np.ndarray, blk: np.ndarray, fb: np.ndarray, rw: _JointRows,
             sigmas: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unweighted ||r_j||^2 of one joint at each of ``sigmas`` [N m] with theta's entries
    ``th`` held and the block's free entries (``fb``) refitted by linear least squares (the
    others held at ``blk``); returns the squared residuals and the refitted blocks."""
    rr = np.empty(sigmas.size)
    blks = np.repeat(blk[None, :], sigmas.size, axis=0)
    for i, sg in enumerate(sigmas):
        D = _block_columns(th, float(sg), rw)
        y = rw.tau - D[:, ~fb] @ blk[~fb]
        b, *_ = np.linalg.lstsq(D[:, fb], y, rcond=None)
        blks[i, fb] = b
        e = y - D[:, fb] @ b
        rr[i] = float(e @ e)
    return rr, blks


def _start(model: Any, rows: list[_JointRows], x0: np.ndarray, free: np.ndarray,
           lo_s: np.ndarray, hi_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The start: theta of the hard fit; per joint the sigma_j of a 1-D profile (the lowest
    squared residual of :func:`_profile` on ``SIGMA_START_GRID`` points log-spaced over its
    bounds) and the joint's block refitted there. Returns (x, sigma)."""
    x = x0.copy()
    sigma = np.empty(len(rows))
    for j, rw in enumerate(rows):
        idx, nt = model._local(j), model._nt(j)
        grid = np.geomspace(lo_s[j], hi_s[j], SIGMA_START_GRID)
        rr, blks = _profile(x0[idx[:nt]], x0[idx[nt:]], free[idx[nt:]], rw, grid)
        i = int(np.argmin(rr))
        sigma[j] = grid[i]
        x[idx[nt:]] = blks[i]
    return x, sigma


class _Problem:
    """The weighted residual and its Jacobian over u = (x[free], sigma[varied])."""

    def __init__(self, model: Any, rows: list[_JointRows], x0: np.ndarray, free: np.ndarray,
                 sigma0: np.ndarray, varied: np.ndarray) -> None:
        self.model, self.rows = model, rows
        self.x0, self.free, self.sigma0, self.varied = x0, free, sigma0, varied
        self.fi = np.flatnonzero(free)
        self.pos = np.full(x0.size, -1)
        self.pos[self.fi] = np.arange(self.fi.size)
        self.vi = np.flatnonzero(varied)
        self.spos = np.full(sigma0.size, -1)
        self.spos[self.vi] = self.fi.size + np.arange(self.vi.size)
        self.offsets = np.r_[0, np.cumsum([r.tau.size for r in rows])]
        self.sw = np.ones(len(rows))

    def unpack(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x, sg = self.x0.copy(), self.sigma0.copy()
        x[self.fi] = u[:self.fi.size]
        sg[self.vi] = u[self.fi.size:]
        return x, sg

    def residual(self, u: np.ndarray) -> np.ndarray:
        x, sg = self.unpack(u)
        out = np.empty(self.offsets[-1])
        m = self.model
        for j, rw in enumerate(self.rows):
            idx, nt = m._local(j), m._nt(j)
            pred = _joint_model(x[idx[:nt]], x[idx[nt:]], sg[j], rw.WT, rw.p, rw.dq, rw.sgc,
                                rw.E, jacobian=False)
            out[self.offsets[j]:self.offsets[j + 1]] = self.sw[j] * (pred - rw.tau)
        return out

    def jacobian(self, u: np.ndarray) -> np.ndarray:
        x, sg = self.unpack(u)
        J = np.zeros((self.offsets[-1], u.size))
        m = self.model
        for j, rw in enumerate(self.rows):
            idx, nt = m._local(j), m._nt(j)
            _, dth, dblk, dsig = _joint_model(x[idx[:nt]], x[idx[nt:]], sg[j], rw.WT, rw.p,
                                              rw.dq, rw.sgc, rw.E)
            rows = slice(self.offsets[j], self.offsets[j + 1])
            D = np.concatenate([dth, dblk], axis=1)
            cols = self.pos[idx]
            ok = cols >= 0
            J[rows, cols[ok]] += self.sw[j] * D[:, ok]
            if self.spos[j] >= 0:
                J[rows, self.spos[j]] = self.sw[j] * dsig
        return J

    def joint_rr(self, u: np.ndarray) -> np.ndarray:
        """Unweighted ||r_j||^2 per joint."""
        res = self.residual(u)
        return np.array([float(np.sum((res[a:b] / w) ** 2)) for a, b, w in
                         zip(self.offsets[:-1], self.offsets[1:], self.sw, strict=True)])


def _solve(pr: _Problem, u0: np.ndarray, lo: np.ndarray, hi: np.ndarray, max_nfev: int):
    u0 = np.clip(u0, lo, hi)
    return least_squares(pr.residual, u0, jac=pr.jacobian, bounds=(lo, hi), x_scale="jac",
                         method="trf", xtol=1e-12, ftol=1e-12, gtol=1e-10, max_nfev=max_nfev)


def fit_soft(model: Any, signals: Any) -> None:
    """Refit a hard-fitted paper ``model`` (bilinear) with soft quadrant weights on
    ``signals`` (module doc); sets its fitted attributes in place."""
    rows = _rows(model, signals)
    k = len(rows)
    n = np.array([r.tau.size for r in rows])
    x0 = np.asarray(model.coef_, dtype=float).copy()
    free = np.array([nm not in model.fixed_ for nm in model.names_])
    rms = np.empty(k)
    for j, rw in enumerate(rows):
        idx, nt = model._local(j), model._nt(j)
        s = x0[idx[:nt]] @ rw.WT + rw.p
        rms[j] = float(np.sqrt(np.mean(s * s))) if s.size else 0.0
    if not np.all(rms > 0) or np.any(n == 0):
        bad = [model.joints_[j] for j in range(k) if not (rms[j] > 0 and n[j] > 0)]
        raise RobotIdentError(f"RobotModel(quadrants='soft'): joint(s) {bad} have no rows or "
                              "no load on them: no jitter scale to bound sigma with")
    lo_s, hi_s = SIGMA_MIN_FRACTION * rms, SIGMA_MAX_FRACTION * rms
    xs, sigma0 = _start(model, rows, x0, free, lo_s, hi_s)
    varied = np.ones(k, dtype=bool)
    pr = _Problem(model, rows, x0, free, sigma0, varied)
    lo = np.r_[np.full(pr.fi.size, -np.inf), lo_s]
    hi = np.r_[np.full(pr.fi.size, np.inf), hi_s]
    u = np.r_[xs[pr.fi], sigma0]
    w = np.asarray(getattr(model, "weights_", np.ones(k)), dtype=float)
    max_nfev = 20 * int(model.max_iter)
    pr.sw = np.sqrt(w)
    sol = _solve(pr, u, lo, hi, max_nfev)
    nfev = sol.nfev
    est = model._estimator
    if est.reweights:  # WLS: the joints' weights from the soft residuals, refit
        sj = np.sqrt(pr.joint_rr(sol.x) / np.maximum(n - _joint_free(model, pr), 1))
        w = est.weights(sj)
        pr.sw = np.sqrt(w)
        sol = _solve(pr, sol.x, lo, hi, max_nfev)
        nfev += sol.nfev
    x, sigma = pr.unpack(sol.x)
    span = hi_s - lo_s
    at_bound = (sigma - lo_s <= AT_BOUND_TOL * span) | (hi_s - sigma <= AT_BOUND_TOL * span)
    # statistics: eq. 15 on the free parameters and the sigma_j off their bounds
    J = pr.jacobian(sol.x)
    keep = np.r_[np.ones(pr.fi.size, dtype=bool), ~at_bound]
    Jk = J[:, keep]
    rr = pr.joint_rr(sol.x)
    dof = int(n.sum()) - int(keep.sum())
    if dof <= 0:
        raise RobotIdentError(f"RobotModel.fit (soft quadrants): {int(n.sum())} rows for "
                              f"{int(keep.sum())} parameters")
    sigma2 = float(w @ rr) / dof
    d = np.sqrt(np.sum(Jk * Jk, axis=0))
    d[d == 0] = 1.0
    Js = Jk / d
    sv = np.linalg.svd(Js, compute_uv=False)
    if not sv[-1] > 1e-12 * sv[0]:
        raise RobotIdentError("RobotModel.fit (soft quadrants): the Jacobian at the solution "
                              f"is singular (scaled singular values {sv[-1]:.3g} .. "
                              f"{sv[0]:.3g}): parameters not identifiable with the soft weight")
    cov_k = sigma2 * np.linalg.inv(Js.T @ Js) / d[:, None] / d[None, :]
    nf = pr.fi.size
    cov = np.zeros((x.size, x.size))
    cov[np.ix_(pr.fi, pr.fi)] = cov_k[:nf, :nf]
    sstd = np.full(k, np.nan)
    sstd[~at_bound] = np.sqrt(np.clip(np.diag(cov_k)[nf:], 0, None))
    yy = np.array([float(r.tau @ r.tau) for r in rows])
    model._store_solution(x, cov, sigma2,
                          np.sqrt(rr / np.maximum(n - _joint_free(model, pr), 1)), n, rr, yy)
    model.weights_ = w
    model.cond_raw_ = float(np.linalg.cond(Jk)) if Jk.size else float("inf")
    model.cond_ = float(sv[0] / sv[-1])
    model.n_iter_ = int(nfev)
    model.converged_ = bool(sol.status > 0)
    model.band_ = np.zeros(k)  # no band: every row carries both quadrants
    model.quadrant_sigma_ = sigma
    model.quadrant_sigma_std_ = sstd
    model.quadrant_sigma_bounds_ = np.stack([lo_s, hi_s], axis=1)
    model.quadrant_sigma_at_bound_ = at_bound


def _joint_free(model: Any, pr: _Problem) -> np.ndarray:
    """Free parameters involving each joint's rows (its theta entries, block and sigma)."""
    return np.array([int(pr.free[model._local(j)].sum()) + 1 for j in range(len(pr.rows))])


def predict_soft(model: Any, signals: Any) -> np.ndarray:
    """:meth:`RobotModel.predict` of a soft fit: tau_hat (n, k) [N m] with the soft weights
    of the fitted theta's load and ``quadrant_sigma_``."""
    out = np.full(signals.tau.shape, np.nan)
    x = model.coef_
    for r, j, _cols, WjT, pj, dqj, _tau, sg in model._fitted_rows(signals, "predict"):
        idx, nt = model._local(j), model._nt(j)
        out[r, j] = _joint_model(x[idx[:nt]], x[idx[nt:]], float(model.quadrant_sigma_[j]),
                                 WjT, pj, dqj, np.sign(dqj) if sg is None else sg,
                                 stribeck_exp(dqj, model.q_s_[j]), jacobian=False)
    return out


def load_signs(model: Any, load: np.ndarray, j: int) -> tuple[float, float]:
    """Joint j's rows whose load is > 0 and < 0, given its model load tau_out_hat_j
    ``load`` (m,) [N m]: counted (hard quadrants), or expected under the fitted load jitter
    (soft: sum of Phi(s / sigma_j) and of Phi(-s / sigma_j), the weights the soft fit gives
    the load's sign; its hard count as sigma_j -> 0)."""
    if getattr(model, "quadrants", "hard") != "soft":
        return float((load > 0).sum()), float((load < 0).sum())
    p = ndtr(load / float(model.quadrant_sigma_[j]))
    return float(p.sum()), float((1.0 - p).sum())


def soft_record(model: Any, rec: dict[str, Any], joints: Any, notes: list[str]) -> None:
    """The paper model's JSON record (``jointid fit --robot``): ``quadrants`` and, fitted
    soft, ``quadrant_sigma`` per joint (``value``, ``std`` -- None on a bound --, ``bound``
    [N m], ``at_bound``) and the notes: a sigma_j on its bound is not identified; the
    standard deviations are analytic only, no parameter pruned."""
    rec["quadrants"] = getattr(model, "quadrants", "hard")
    if rec["quadrants"] != "soft":
        return
    rec["quadrant_sigma"] = {
        j: {"value": float(v), "std": None if not np.isfinite(s) else float(s),
            "bound": [float(lo), float(hi)], "at_bound": bool(b)}
        for j, v, s, (lo, hi), b in zip(joints, model.quadrant_sigma_,
                                        model.quadrant_sigma_std_,
                                        model.quadrant_sigma_bounds_,
                                        model.quadrant_sigma_at_bound_, strict=True)}
    for j, v, b, (lo, hi) in zip(joints, model.quadrant_sigma_,
                                 model.quadrant_sigma_at_bound_,
                                 model.quadrant_sigma_bounds_, strict=True):
        if b:
            side = "upper" if v > 0.5 * (lo + hi) else "lower"
            notes.append(f"paper model (soft quadrants), {j}: its load jitter sigma "
                         f"{v:.3g} N m sits on its {side} bound ({lo:.3g} .. {hi:.3g}, "
                         f"{SIGMA_MIN_FRACTION:g} .. {SIGMA_MAX_FRACTION:g} x the RMS of its "
                         "model load): not identified, held there")
    notes.append("paper model (soft quadrants): standard deviations analytic only (eq. 15 at "
                 "the solution; no block jackknife, no IDIM-IV check) and no parameter pruned")
