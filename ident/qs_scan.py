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
fit with (one q_s shared by every joint); :func:`scan_qs_joints` chooses one q_s per joint
(``--q-s scan-joints``): the shared grid, then coordinate sweeps of :func:`_scan` on each
joint's q_s with the others held, on the same score; :func:`rescan_qs_joints` is that per-joint
scan again after a refinement, each point the n-dof refit of the found terms (what
``--q-s scan-joints --refine`` reports, as :func:`rescan_qs` for ``--q-s scan``).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Mapping, Sequence
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

__all__ = ["QsScan", "QsJointsScan", "qs_grid", "rescan_qs", "rescan_qs_joints", "scan_qs",
           "scan_qs_joints", "model_at_qs_joints", "QS_XTOL", "QS_SEARCH_EVALS", "QS_WORKERS",
           "QS_MAX_SWEEPS"]

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
    _check_paper(model, "rescan_qs")
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

    refit = _refitter("rescan_qs", lambda q: model_at_qs(model, q, scanned), at, terms,
                      prediction=prediction, keep=keep, revolute=revolute, columns=columns,
                      instrument_columns=instrument_columns,
                      refit_eliminated=refit_eliminated)

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


#: Cap on the coordinate sweeps of :func:`scan_qs_joints` after its shared-grid pass.
QS_MAX_SWEEPS = 4


@dataclass
class QsJointsScan:
    """Result of :func:`scan_qs_joints`.

    Attributes
    ----------
    q_s : dict of str to float
        The chosen q_s of each joint [rad/s].
    scan : dict of str to list of (q_s, error, sweep)
        Per joint, every evaluated q_s of that joint [rad/s] with the score that chose it
        (dimensionless) and its pass: 0 the shared grid (every joint at the same fraction of
        its own largest |dq|), 1.. the coordinate sweeps (the other joints held at their
        values then); in evaluation order, a point evaluated again (the same q_s_j and
        score) once.
    fits : int
        Distinct fits evaluated (a q_s vector evaluated twice is fitted once).
    sweeps : int
        Coordinate sweeps that searched at least one joint.
    converged : bool
        The last sweep moved no joint's q_s by more than :data:`QS_XTOL` on log q_s (False:
        stopped at :data:`QS_MAX_SWEEPS`).
    error : dict of str to float
        The scores (every joint's and ``"all"``) of the fit at the chosen q_s.
    """

    q_s: dict[str, float]
    scan: dict[str, list[tuple[float, float, int]]]
    fits: int
    sweeps: int
    converged: bool
    error: dict[str, float]


def scan_qs_joints(score: Callable[[np.ndarray], Mapping[str, float]],
                   vmax: float | Sequence[float], joints: Sequence[str], *,
                   n_grid: int = 13, criterion: str = "all",
                   max_sweeps: int = QS_MAX_SWEEPS) -> QsJointsScan:
    """One q_s per joint: the paper fit at a vector of q_s, scored per joint, minimised one
    joint at a time with the others held (``jointid fit --robot --q-s scan-joints``).

    1. The shared grid: :func:`qs_grid` of each joint's own ``vmax`` (so every joint at the
       same fraction of its largest |dq|), one fit per grid point; each joint starts at its
       grid point of the smallest score (with ``criterion="all"``, the same point for all).
    2. Coordinate sweeps: for each joint in turn, :func:`_scan` of its score over q_s_j, the
       others held -- in the first sweep on the joint's grid point and its two neighbours
       (the bounded search between them, as :func:`scan_qs`), later on the current value
       and one grid step either side (a minimum at the window's edge moves there, the next
       sweep goes on from it). A joint is searched again only when another joint moved by
       more than :data:`QS_XTOL` (log q_s) since its last search. The sweeps stop when one
       moves no joint by more than :data:`QS_XTOL`, or after ``max_sweeps``.

    For one joint this is :func:`scan_qs` exactly: the same fits, the same q_s.

    Parameters
    ----------
    score : callable
        q_s vector [rad/s] (one per joint, in ``joints``' order) -> the fit's relative
        errors by joint name and ``"all"`` (every joint's rows); ``inf`` where it failed.
    vmax : float or sequence of float
        Largest |dq| of each joint's fitted rows [rad/s], for its grid.
    joints : sequence of str
        The joints, in the order of the q_s vectors.
    n_grid : int
        Grid points.
    criterion : {"all", "joint"}
        Score of joint j's q_s: the error over every joint's rows (default: the shared
        scan's score, so the sweeps are a coordinate descent on one objective and end no
        higher than the shared grid's best point), or the error of joint j's rows alone
        (no common objective: on the KUKA KR300 its sweeps did not converge and ended above
        the shared scan's error; docs/robot-identification.md, 'One q_s per joint').
    max_sweeps : int
        Cap on the coordinate sweeps.

    Returns
    -------
    QsJointsScan

    Raises
    ------
    DataError
        A ``vmax`` not positive and finite, or the fit failing at every point of the grid.
    """
    names = tuple(joints)
    k = len(names)
    vm = np.broadcast_to(np.asarray(vmax, dtype=float), (k,))
    if not np.all(np.isfinite(vm) & (vm > 0)):
        raise DataError(f"q_s scan per joint: the fitted rows' largest |dq| per joint is "
                        f"{vm.tolist()} rad/s; expected velocities > 0")
    if criterion not in ("joint", "all"):
        raise DataError(f"q_s scan per joint: criterion {criterion!r}: expected 'joint' or "
                        "'all'")
    grids = [qs_grid(float(v), n_grid) for v in vm]
    step = grids[0][1] / grids[0][0]  # the grid's ratio, the same for every joint
    cache: dict[tuple[float, ...], dict[str, float]] = {}

    def errors(q: np.ndarray) -> dict[str, float]:
        key = tuple(float(x) for x in q)
        if key not in cache:
            got = score(np.array(key))
            cache[key] = {n: _finite(got.get(n, math.inf)) for n in (*names, "all")}
        return cache[key]

    def read(e: dict[str, float], j: int) -> float:
        return e[names[j] if criterion == "joint" else "all"]

    scan: dict[str, list[tuple[float, float, int]]] = {n: [] for n in names}
    first = [errors(np.array([g[i] for g in grids])) for i in range(n_grid)]
    if not any(np.isfinite(e["all"]) for e in first):
        raise DataError("q_s scan per joint: the paper model could not be fitted at any point "
                        "of the shared grid")
    start = np.empty(k, dtype=int)
    for j, n in enumerate(names):
        row = [read(e, j) for e in first]
        scan[n] += [(float(grids[j][i]), row[i], 0) for i in range(n_grid)]
        start[j] = int(np.argmin(row))
    current = np.array([grids[j][start[j]] for j in range(k)])
    held: list[np.ndarray | None] = [None] * k  # the others' q_s at each joint's last search
    sweeps, converged = 0, False
    for sweep in range(1, max_sweeps + 1):
        moved, searched = False, False
        for j in range(k):
            others = np.delete(current, j)
            if held[j] is not None and np.all(np.abs(np.log(others / held[j])) <= QS_XTOL):
                continue  # nothing it depends on moved since its last search
            searched = True
            if sweep == 1:
                window = grids[j][max(start[j] - 1, 0):start[j] + 2]
            else:
                window = current[j] * step ** np.array([-1.0, 0.0, 1.0])
            tried: list[tuple[float, float]] = []

            def err(q: float, j: int = j, tried: list = tried, sweep: int = sweep) -> float:
                v = current.copy()
                v[j] = q
                e = read(errors(v), j)
                tried.append((q, e))
                if not any(p[:2] == (q, e) for p in scan[names[j]]):  # not a point again
                    scan[names[j]].append((q, e, sweep))
                return e

            _scan(err, window)
            # the smallest score of the search, kept only if below the current value's (a
            # search where every fit failed leaves the joint where it was)
            best, low = float(current[j]), read(errors(current), j)
            for q, e in sorted(tried):
                if e < low:
                    best, low = q, e
            if abs(math.log(best / current[j])) > QS_XTOL:
                moved = True
            current[j] = best
            held[j] = np.delete(current, j)
        if not searched:
            converged = True
            break
        sweeps = sweep
        if not moved:
            converged = True
            break
    return QsJointsScan(q_s={n: float(q) for n, q in zip(names, current, strict=True)},
                        scan=scan, fits=len(cache), sweeps=sweeps, converged=converged,
                        error=dict(errors(current)))


def rescan_qs_joints(
    model: Any,
    signals: RobotSignals,
    terms: Sequence[tuple[int, Term]],
    *,
    vmax: Sequence[float],
    revolute: Sequence[bool] | None = None,
    prediction: np.ndarray | None = None,
    keep: np.ndarray | None = None,
    n_grid: int = 13,
) -> tuple[QsJointsScan, RobotRefit]:
    """One q_s per joint chosen again after a refinement: :func:`scan_qs_joints` (the shared
    grid, then coordinate sweeps, on the error over every joint's rows) where the fit at each
    q_s vector is :func:`ident.robot.refit.refit_robot` of ``terms`` on the model with those
    q_s (:func:`model_at_qs_joints`, one copy per vector; scored with ``errors_only``),
    every parameter of every joint estimated together; the chosen vector is then refitted
    whole. The per-joint counterpart of :func:`rescan_qs` (``--q-s scan-joints`` then
    ``--refine``).

    Parameters
    ----------
    model : RobotModel
        The fitted n-dof paper model.
    signals : RobotSignals
        What it was fitted on.
    terms : sequence of (int, Term)
        (joint index, found term), as :func:`~ident.robot.refit.refit_robot`.
    vmax : sequence of float
        Largest |dq| of each joint's rows [rad/s] (the model's joints' order), its grid.
    revolute, prediction, keep
        As :func:`~ident.robot.refit.refit_robot`; ``prediction`` (the terms' load variable)
        is the model's at its own q_s whatever q_s is scanned (computed once when None).
    n_grid : int
        Grid points.

    Returns
    -------
    (QsJointsScan, RobotRefit)
        The scan (its ``error`` the refit's relative errors at the chosen q_s) and the whole
        refit there.

    Raises
    ------
    DataError
        Not a paper model, bad ``vmax``, or the refit failing at every point of the grid.
    """
    _check_paper(model, "rescan_qs_joints")
    names = tuple(model.joints_)
    if prediction is None:
        prediction = model.predict(signals)

    refit = _refitter("rescan_qs_joints", lambda q: model_at_qs_joints(model, q),
                      lambda _q: signals, terms, prediction=prediction, keep=keep,
                      revolute=revolute)

    def score(q: np.ndarray) -> dict[str, float]:
        try:
            return dict(refit(q).rel_error["after"])
        except _RefitFailed:
            return {}  # every score inf

    res = scan_qs_joints(score, vmax, names, n_grid=n_grid)
    return res, refit(np.array([res.q_s[n] for n in names]), errors_only=False)


def model_at_qs_joints(model: Any, q_s: Sequence[float]) -> Any:
    """The fitted n-dof ``model`` with joint j's velocity constant set to ``q_s[j]`` [rad/s]
    (the model's joints' order), its estimates unchanged: :func:`ident.robot.refit.model_at_qs`
    with one q_s per joint, in one shallow copy (``model`` itself is not changed).

    Raises
    ------
    RobotIdentError
        Not one q_s per joint, or a q_s not positive and finite.
    """
    model._check_fitted()
    names = tuple(model.joints_)
    q = np.array(q_s, dtype=float)
    if q.shape != (len(names),):
        raise RobotIdentError(f"model_at_qs_joints: {q.size} q_s for the model's joints "
                              f"{names}; expected one per joint")
    bad = [n for n, v in zip(names, q, strict=True) if not (math.isfinite(v) and v > 0)]
    if bad:
        raise RobotIdentError(f"model_at_qs_joints: q_s of {bad} must be positive velocities "
                              f"[rad/s], got {q.tolist()}")
    out = copy.copy(model)
    out.q_s_ = q
    return out


def _check_paper(model: Any, who: str) -> None:
    """Refuse, in one line naming ``who``, a model other than the paper model (the only one
    with a q_s to scan)."""
    if getattr(model, "model", None) != "paper":
        raise DataError(f"{who}: q_s is a parameter of the paper model; this model is "
                        f"{getattr(model, 'model', type(model).__name__)!r}")


class _RefitFailed(DataError):
    """The refit of a rescan failed at a q_s (:func:`_refitter`; the message names where)."""


def _refitter(who: str, model_at: Callable[[Any], Any],
              signals_at: Callable[[Any], RobotSignals], terms: Sequence[tuple[int, Term]],
              **kw: Any) -> Callable[..., RobotRefit]:
    """The refit of a rescan at a q_s: ``refit(q, errors_only=True)`` is
    :func:`~ident.robot.refit.refit_robot` of ``terms`` on ``model_at(q)`` with
    ``signals_at(q)`` and the options ``kw``; ``q`` a q_s [rad/s] (:func:`rescan_qs`) or one
    per joint (:func:`rescan_qs_joints`). A refit that cannot be made raises
    :class:`_RefitFailed` (a :class:`~ident.DataError`), one line naming ``who`` and q."""

    def refit(q: Any, errors_only: bool = True) -> RobotRefit:
        try:
            return refit_robot(model_at(q), signals_at(q), terms, errors_only=errors_only, **kw)
        except RobotIdentError as exc:
            at = f"{q:.4g}" if np.ndim(q) == 0 else f"{np.asarray(q).tolist()}"
            raise _RefitFailed(f"{who} at q_s = {at} rad/s: {exc}") from None

    return refit


def _finite(x: Any) -> float:
    """A score as a float, NaN (a failed fit) as inf."""
    x = float(x)
    return math.inf if math.isnan(x) else x
