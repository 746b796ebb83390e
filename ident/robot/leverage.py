"""Leverage-robust sigma of each joint's friction block: the HC3 sandwich of a fitted
:class:`~ident.robot.estimate.RobotModel` (one of the three sides of the honest sigma,
:mod:`ident.robot.uncertainty`).

Why
---
Eq. 15 (and its robust form: each joint's residual variance, its long-run factor) gives
every row of a joint the joint's average error variance. A direction of the parameters that
a few rows decide alone -- a Stribeck term E b tau_out of a joint none of whose kept rows
is slow (the stiction area and its guard leave the simulated UR10's wrist 3 no row below
2.2-3.5 q_s, E <= 0.11), so that one row with E = 5e-4 carries it -- then gets the sigma of
an average row,
while its estimate moves by that row's own error, which the fit has absorbed (leverage h
near 1, residual near 0). The block jackknife cannot see it either: those rows sit in one
or two of its units, and its robust spread (MAD over the units) ignores them. Measured on
the simulated UR10 (campaign seed 3, ``benchmarks/ur10_wrist3.py``): wrist 3's b_m6 rests
on one row of leverage 0.96 whose deleted residual is 26 times the joint's residual sigma;
b_m6 = 33.6 against the truth 0.25, honest sigma 4.6 (robust eq. 15; jackknife 0.06).

What
----
Per joint j, with theta held at the fit and the fit's quadrants (``quadrant_from_``, the
rows of :meth:`RobotModel.fitted_rows`: the row rule and the quadrant band), the prediction
is linear in the joint's friction block x_j (a_m ... OFF, or FC, FV, OFF); its rows
J_i = d tau_hat_i / d x_j (the coefficients' Jacobian ``D0 + E D1`` applied to the row's
columns) give G = sum J_i J_i^T, the leverages h_i = J_i^T G^-1 J_i and MacKinnon and
White's HC3 covariance::

    cov_j = G^-1 (sum_i J_i J_i^T e_i^2 / (1 - h_i)^2) G^-1

(e_i the fit's residual; e_i / (1 - h_i) is the error of the prediction of row i by the fit
without it). Free parameters only (the gauge and pruned ones held); the theta columns get
NaN (the robust eq. 15 and the jackknife carry theta's share). Two passes over the rows,
nothing of their size kept. Not for IDIM-IV (its covariance is not a least-squares one) nor
soft quadrants: NaN there.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from trajectories.friction import quadrant_weights, stribeck_exp

from .paper import paper_coefficients, usual_coefficients
from .signals import RobotSignals

__all__ = ["leverage_sigma", "LEVERAGE_FLOOR"]

#: 1 - h_i is taken at least this: a row of leverage 1 (it alone decides a direction, its
#: residual 0) then gives a finite, very large sigma instead of 0/0.
LEVERAGE_FLOOR = 1e-9


def _rows(model: Any, signals: Any, free: np.ndarray):
    """Per chunk and joint: (j, block indices, J (m, nb) on the free block, residual (m,))
    on the joint's fitted rows (module doc): the model's own pass and row rule
    (:meth:`RobotModel.fitted_rows`: the usable rows, the quadrant band)."""
    coeffs = usual_coefficients if model.model == "usual" else paper_coefficients
    theta_q = model.quadrant_theta_ if getattr(model, "quadrant_theta_", None) is not None \
        else getattr(model, "quadrant_from_", None)
    x = model.coef_
    for sig in [signals] if isinstance(signals, RobotSignals) else signals:
        yield from _joint_rows(model, sig, free, coeffs, theta_q, x)


def _joint_rows(model: Any, signals: RobotSignals, free: np.ndarray, coeffs: Any,
                theta_q: np.ndarray | None, x: np.ndarray):
    """:func:`_rows` on one :class:`RobotSignals`."""
    keep = None if signals.columns is None else signals.columns.keep
    for r, j, cols, WjT, pj, dqj, tj, sg in model._fitted_rows(signals, "leverage_sigma"):
        idx = model._local(j)
        nt = model._nt(j)
        bi = idx[nt:][free[idx[nt:]]]
        if bi.size == 0:
            continue
        sel = np.isin(idx[nt:], bi)
        ok = model._row_rule(j, cols, WjT, pj, dqj, tj, None if keep is None else keep[r, j])
        if not ok.any():
            continue
        WjT, pj, dqj, tj = WjT[:, ok], pj[ok], dqj[ok], tj[ok]
        sg = None if sg is None else sg[ok]
        V = model._v(WjT, pj, dqj, tj, sg).T[:, :-1]  # (m, nv) without the torque
        sp = tj * dqj if theta_q is None else (theta_q[cols] @ WjT + pj) * dqj
        E = stribeck_exp(dqj, model.q_s_[j])
        th, blk = x[idx[:nt]], x[idx[nt:]]
        Jr = np.zeros((tj.size, bi.size))
        pred = np.zeros(tj.size)
        for s, ws in enumerate(quadrant_weights(sp)):
            c0, c1, D0, D1 = coeffs(th, blk, s)
            nv = V.shape[1]
            pred += ws * (V @ c0[:nv] + E * (V @ c1[:nv]))
            Jr += ws[:, None] * (V @ D0[:nv, nt:][:, sel]
                                 + E[:, None] * (V @ D1[:nv, nt:][:, sel]))
        yield j, bi, Jr, tj - pred


def leverage_sigma(model: Any, signals: RobotSignals | Sequence[RobotSignals],
                   free: np.ndarray | None = None) -> np.ndarray:
    """HC3 sigma of every joint's free friction parameters (module doc).

    Parameters
    ----------
    model : RobotModel
        Fitted (hard quadrants, LS or WLS) on ``signals``.
    signals : RobotSignals or sequence
        The data of the fit.
    free : ndarray of bool (b,) or None
        The parameters free in the fit (default: all but ``fixed_``); the others get 0.

    Returns
    -------
    ndarray (b,)
        Sigma [parameter unit]; NaN on the base parameters, and everywhere for IDIM-IV or
        soft quadrants.
    """
    b = len(model.names_)
    out = np.full(b, np.nan)
    if model.method == "iv" or getattr(model, "quadrants", "hard") == "soft":
        return out
    if free is None:
        held = set(model.fixed_)
        free = np.array([n not in held for n in model.names_])
    free = np.asarray(free, dtype=bool)
    k = len(model.cols_)
    G: list[np.ndarray | None] = [None] * k
    for j, _bi, Jr, _e in _rows(model, signals, free):
        G[j] = Jr.T @ Jr if G[j] is None else G[j] + Jr.T @ Jr
    Gi = [None if g is None else np.linalg.pinv(g) for g in G]
    meat: list[np.ndarray | None] = [None] * k
    index: list[np.ndarray | None] = [None] * k
    for j, bi, Jr, e in _rows(model, signals, free):
        h = np.einsum("ij,jk,ik->i", Jr, Gi[j], Jr)
        u = Jr * (e / np.maximum(1.0 - h, LEVERAGE_FLOOR))[:, None]
        meat[j] = u.T @ u if meat[j] is None else meat[j] + u.T @ u
        index[j] = bi
    for j in range(k):
        if meat[j] is None:
            continue
        cov = Gi[j] @ meat[j] @ Gi[j]
        out[index[j]] = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    out[(~free) & np.isfinite(out)] = 0.0
    return out
