"""The q_s scan of the paper model (section III.D): the grid, the bounded search, and the
rescan of q_s after a refinement (:func:`rescan_qs`) through the robot model: the fit at each
q_s is the n-dof refit of the found terms (:func:`ident.robot.refit.refit_robot` on the model
at that q_s, :func:`ident.robot.refit.model_at_qs`), the path
``jointid fit --robot --refine`` and the single joint's
:func:`ident.one_joint.refit_found_terms` refit the terms with. A joint is the 1-dof
instance: :meth:`ident.fitting.FitReport.rescan_found_terms` (the demo's rescan) scans with
the joint's robot model on its full-rate products formed at each q_s
(:meth:`ident.one_joint.OneJointProblem.products`: only the E products formed and filtered
again), the found terms' columns those of the refinement's design.

:mod:`ident.fitting` re-exports the public names (``qs_grid``, ``rescan_qs``, ``QsScan``);
:func:`ident.fitting.fit_models` scans q_s with :func:`_scan` and :func:`qs_grid` on its own
fits; :func:`scan_qs` is the same scan of any fit given as a score, what
``jointid fit --robot --q-s scan`` (:func:`ident.cli_robot.fit_robot`) scans the n-dof paper
fit with (one q_s shared by every joint).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.optimize

from . import DataError
from .robot import RobotIdentError
from .robot.refit import RobotRefit, model_at_qs, refit_robot
from .robot.signals import RobotSignals
from .terms import Term

__all__ = ["QsScan", "qs_grid", "rescan_qs", "scan_qs", "QS_XTOL", "QS_SEARCH_EVALS",
           "QS_WORKERS"]

#: Resolution of the q_s scan after the grid, on log q_s (1 %).
QS_XTOL = 0.01


def qs_grid(vmax: float, n: int = 13) -> np.ndarray:
    """Candidate q_s for the scan [rad/s]: geometric, 0.5 %..20 % of the maximum velocity
    (the paper's 0.03-0.04 rad/s are 2.5-3.3 % of its 1.2 rad/s)."""
    return vmax * np.geomspace(0.005, 0.2, n)


#: Typical number of evaluations of the bounded search after the grid (for progress bars).
QS_SEARCH_EVALS = 10
#: Threads scoring the q_s grid of :func:`rescan_qs` (the VM has two cores).
QS_WORKERS = 2


def _scan(err: Any, grid: np.ndarray) -> None:
    """Evaluate ``err`` on ``grid``, then refine the minimum between its grid neighbours on
    log q_s (bounded 1-D search to :data:`QS_XTOL`)."""
    errs = [err(float(q)) for q in grid]
    k = int(np.argmin(errs))
    if 0 < k < grid.size - 1:
        scipy.optimize.minimize_scalar(
            lambda x: err(float(np.exp(x))),
            bounds=(float(np.log(grid[k - 1])), float(np.log(grid[k + 1]))),
            method="bounded",
            options={"xatol": QS_XTOL},
        )



@dataclass
class QsScan:
    """Result of :func:`rescan_qs`.

    Attributes
    ----------
    q_s : float
        Velocity constant with the smallest relative error of the refit [rad/s].
    refit : RobotRefit
        The n-dof refit of the found terms with the model at that q_s (the whole record:
        before / after, held-out errors, noise floors; "before" is the model's estimate at
        the scanned q_s, not refitted).
    scan : list of (q_s, rel_error)
        Every evaluated q_s, sorted, with the refit's relative error ``rel_error["after"]
        ["all"]`` (the stacked rows of every joint).
    joints : tuple of str
        The joints whose q_s was scanned.
    record : dict
        ``refit.to_json()`` (docs/fit-json.md's ``refit`` record); for a single joint
        (:meth:`ident.fitting.FitReport.rescan_found_terms`) its parameters by the
        single-joint names.
    """

    q_s: float
    refit: RobotRefit
    scan: list[tuple[float, float]]
    joints: tuple[str, ...] = ()
    record: dict[str, Any] = field(default_factory=dict)


def rescan_qs(
    model: Any,
    signals: RobotSignals | Callable[[float], RobotSignals],
    terms: Sequence[tuple[int, Term]],
    *,
    vmax: float,
    joints: Sequence[str] | None = None,
    revolute: Sequence[bool] | None = None,
    prediction: np.ndarray | None = None,
    keep: np.ndarray | None = None,
    columns: Sequence[np.ndarray] | None = None,
    instrument_columns: Sequence[np.ndarray] | None = None,
    refit_eliminated: bool = False,
    n_grid: int = 13,
    progress: Callable[[int, int, float, float], None] | None = None,
) -> QsScan:
    """Choose q_s again after a refinement: the q_s of the paper model whose n-dof refit
    with the found terms has the smallest relative error.

    The fit scans q_s with the declared model only; an undeclared effect left in the
    residual then shifts the minimum (the quick demo's position ripple: q_s 0.038 instead of
    0.030, the b terms of eq. 42 40-50 % off; with the ripple modelled the minimum is at
    0.031). This repeats the scan (grid of :func:`qs_grid`, then a bounded search on log q_s
    to :data:`QS_XTOL`) where the fit at each q_s is :func:`ident.robot.refit.refit_robot`
    of ``terms`` on the model at that q_s (:func:`ident.robot.refit.model_at_qs`; scored with
    ``errors_only``), every parameter of every joint estimated together; the chosen q_s is
    then refitted whole. The grid's refits run two at a time (:data:`QS_WORKERS`; the same
    floats as one at a time).

    Parameters
    ----------
    model : RobotModel
        The fitted paper model (``IdentModel.robot_`` for a single joint; a
        :func:`~ident.cli_robot.fit_robot` estimator for a robot).
    signals : RobotSignals or callable
        What it was fitted on; for a fit on the full-rate products (``full_rate_products_``),
        q_s [rad/s] -> the signals with the products formed at that q_s
        (:meth:`ident.one_joint.OneJointProblem.products`).
    terms : sequence of (int, Term)
        (joint index, found term), as :func:`~ident.robot.refit.refit_robot`.
    vmax : float
        Maximum |dq| [rad/s] of the scanned joints' rows, for the grid.
    joints : sequence of str, optional
        The joints whose q_s is scanned (one q_s for all of them); default every joint.
    revolute, prediction, keep, columns, instrument_columns, refit_eliminated
        As :func:`~ident.robot.refit.refit_robot`. ``prediction`` (the terms' load variable)
        is the model's at its own q_s whatever q_s is scanned: computed once when neither it
        nor ``columns`` is given.
    n_grid : int
        Grid points.
    progress : callable, optional
        Called after each refit as ``progress(done, expected, q_s, rel_error)``;
        ``expected`` is an estimate (the grid plus a typical bounded search).

    Returns
    -------
    QsScan

    Raises
    ------
    DataError
        Not a paper model, a q_s the refit cannot be made at (one line, the refit's reason).
    """
    if getattr(model, "model", None) != "paper":
        raise DataError("rescan_qs: q_s is a parameter of the paper model; this model is "
                        f"{getattr(model, 'model', type(model).__name__)!r}")
    at = signals if callable(signals) else (lambda _q: signals)
    scanned = tuple(model.joints_ if joints is None else joints)
    if prediction is None and columns is None:  # the terms' load: the model's own
        if isinstance(signals, RobotSignals):
            prediction = model.predict(signals)
        else:
            own = {float(model.q_s_[model.joints_.index(j)]) for j in scanned
                   if j in model.joints_}
            if len(own) != 1:
                raise DataError("rescan_qs: give the prediction (the scanned joints' q_s "
                                "differ, and the signals are formed per q_s)")
            prediction = model.predict(at(own.pop()))

    def refit(q: float, errors_only: bool = True) -> RobotRefit:
        try:
            return refit_robot(model_at_qs(model, q, scanned), at(q), terms,
                               prediction=prediction, keep=keep, revolute=revolute,
                               columns=columns, instrument_columns=instrument_columns,
                               refit_eliminated=refit_eliminated, errors_only=errors_only)
        except RobotIdentError as exc:
            raise DataError(f"rescan_qs at q_s = {q:.4g} rad/s: {exc}") from None

    def score(q: float) -> float:
        return float(refit(q).rel_error["after"]["all"])

    scan: list[tuple[float, float]] = []
    grid = qs_grid(vmax, n_grid)
    ahead: dict[float, Future] = {}

    def err(q: float) -> float:
        f = ahead.pop(q, None)
        e = f.result() if f is not None else score(q)
        scan.append((q, e))
        if progress is not None:
            progress(len(scan), n_grid + QS_SEARCH_EVALS, q, e)
        return e

    # the grid's refits are independent: two at a time (the filters and the factorisations
    # release the GIL), taken in grid order; the same floats as one at a time
    with ThreadPoolExecutor(max_workers=QS_WORKERS) as pool:
        ahead.update({float(q): pool.submit(score, float(q)) for q in grid})
        try:
            _scan(err, grid)
        finally:
            for f in ahead.values():
                f.cancel()
    scan.sort()
    best = min(scan, key=lambda x: x[1])[0]
    out = refit(best, errors_only=False)
    return QsScan(q_s=best, refit=out, scan=scan, joints=scanned, record=out.to_json())


def scan_qs(score: Callable[[float], float], vmax: float, *,
            n_grid: int = 13) -> tuple[float, list[tuple[float, float]]]:
    """The q_s scan of a fit given as a score: ``score(q_s)`` on the grid of :func:`qs_grid`,
    then the bounded search on log q_s between the best grid point's neighbours (to
    :data:`QS_XTOL`), as :func:`ident.fitting.fit_models` scans a joint. What
    ``jointid fit --robot --q-s scan`` (:func:`ident.cli_robot.fit_robot`) scans with, the
    score being the relative error of the n-dof paper fit at that q_s (one q_s shared by
    every joint).

    Parameters
    ----------
    score : callable
        q_s [rad/s] -> the fit's relative error at that q_s (dimensionless); ``inf`` for a
        q_s where the fit failed.
    vmax : float
        Maximum |dq| of the fitted rows [rad/s], for the grid.
    n_grid : int
        Grid points.

    Returns
    -------
    q_s : float
        The evaluated q_s of the smallest score [rad/s].
    scan : list of (q_s, score)
        Every evaluated q_s, sorted.

    Raises
    ------
    DataError
        ``vmax`` not positive and finite, or the fit failed at every q_s.
    """
    if not (np.isfinite(vmax) and vmax > 0):
        raise DataError(f"q_s scan: the fitted rows' largest |dq| is {vmax!r} rad/s; expected "
                        "a velocity > 0")
    scan: list[tuple[float, float]] = []

    def err(q: float) -> float:
        e = float(score(q))
        scan.append((q, e))
        return e

    _scan(err, qs_grid(vmax, n_grid))
    scan.sort()
    if not any(np.isfinite(e) for _, e in scan):
        raise DataError("q_s scan: the paper model could not be fitted at any q_s of the grid "
                        f"{qs_grid(vmax, n_grid)[0]:.4g}..{qs_grid(vmax, n_grid)[-1]:.4g} rad/s")
    return min(scan, key=lambda x: x[1])[0], scan
