"""Honest standard deviations of a fitted :class:`~ident.robot.estimate.RobotModel`: a block
jackknife beside the analytic sigma of eq. 14-15, the IDIM-IV estimate as a check of errors in
variables, the paper's pruning of parameters whose relative deviation (eq. 16) exceeds the
threshold, and eq. 15 in a robust form (per-joint residual variances, residual long-run
variance: :func:`robust_covariance`). (Past 600 lines: all four read the fit through the same
hooks into ``RobotModel`` -- its moments, its coefficients, its free parameters -- which a split
would have to share across modules.)

Why
---
Eq. 13-15 assume a deterministic W and white errors. On filtered, decimated logs the errors are
correlated, and in closed loop the measured motion carries the response to the drive's torque
noise, which then enters the regressor and -- through sign(tau_out dq) -- the friction's
quadrant decision (errors in variables). The analytic sigma then understates the spread of the
estimate; a joint whose friction is larger than its load is the extreme case.

Jackknife over blocks
---------------------
The rows are cut into units: each experiment (run) is one unit when there are at least
``n_blocks`` experiments; otherwise each experiment is cut into ``ceil(n_blocks /
experiments)`` contiguous blocks (at least 2). Each unit's moments (:mod:`ident.robot.moments`)
are accumulated once, with the quadrants the fit ended on (``RobotModel.quadrant_from_``); the
replicate u leaves unit u out (delete-one-block jackknife: a bootstrap that draws blocks with
replacement loses, on a friction-dominated joint, the few blocks where it visits the generator
quadrant, and the replicate is then not identifiable) and re-runs the same Gauss-Newton (LS,
WLS with the fit's weights, or IV; the same fixed parameters), started at the fit::

    sigma_jack = sqrt(U - 1) * 1.4826 MAD_u(chi_(u))

over the U replicates that could be fitted (``n_failed`` could not: singular normal
equations): the delete-one jackknife's sqrt((U - 1) / U sum_u (chi_(u) - mean)^2) with a
robust deviation, so that one replicate that ends elsewhere on a weak direction does not
decide it. Correlated errors within a block and errors in variables that vary along the data
widen it; a bias common to every block does not (the IV check is for that).

IV check
--------
When the data carry instruments (``q_ref``, or the instrument columns) and the fit is not
itself IDIM-IV, the same model is refitted by IDIM-IV on the same quadrants; per parameter
``z_iv = (chi_fit - chi_iv) / sqrt(sigma_iv^2 + sigma^2)`` (sigma: the larger of the analytic
and the jackknife one). Instruments built on the reference trajectory are not correlated with
the torque noise, so a large |z_iv| says the fit is biased by errors in variables.

Honest sigma and the flag
-------------------------
``std = max(std_robust, std_jackknife, std_leverage)`` per parameter (``std_robust``: eq. 15
in its robust form, :func:`robust_covariance`, its long-run factors at least
:data:`LONG_RUN_FLOOR`; soft quadrants: eq. 15 itself, ``std_analytic``, the only
sigma they have; ``std_leverage``: each joint's friction block's HC3 sandwich,
:mod:`ident.robot.leverage`, for the directions a few rows decide alone, which neither of the
other two sees -- the simulated UR10's wrist 3 on campaign seed 3: b_m6 33.6 against 0.25,
sigma 4.6 without it, 108 with it), and ``|chi_fit - chi_iv|`` where |z_iv| > ``Z_IV``
(a bias of that size is then within one sigma). ``RobotModel.std_`` and ``cov_`` stay
eq. 15. A joint is flagged ``errors_in_variables`` when one of its parameters has a jackknife
sigma above ``RATIO_FLAG`` times the analytic one, or |z_iv| > ``Z_IV``; the flag gives the
numbers.

Robust eq. 15
-------------
:func:`robust_covariance` is eq. 15 without two of its assumptions: one residual variance for
all joints (eq. 14 pools it; LS and IV then give the parameters the noisiest joint decides
its share of the average) and white errors between rows (the decimation's anti-alias filter
correlates them: :func:`long_run_factor`). On the simulated 3-dof arm it removes the 1.3-1.4x
that eq. 15 misses (``benchmarks/robot_sigma_calibration.py``). :func:`assess` takes its
diagonal as the analytic side of the honest sigma, on the fit's moments (those of the
jackknife's units summed) and with the long-run factors of the unpruned fit's residual (one
pass predicting it; the pruning removes only parameters whose removal leaves the residual
within its noise, so the pruned model reuses them), each at least :data:`LONG_RUN_FLOOR`.

Pruning (eq. 14-16)
-------------------
Paper model: the prunable parameter with the largest relative sigma
max(robust eq. 15, jackknife) above the threshold (not the honest sigma's HC3 side: with it
the KUKA KR300's paper model cross-validated at 12.5 % instead of 7.7 %, docs/robot-data.md)
(:data:`ident.estimate.DEFAULT_THRESHOLD_PCT`) is removed -- held at 0, so the prediction
does not use it -- and the model refitted on the same moments (the fit's quadrants and
weights); repeated until every remaining one is below the threshold (the sigma
of a refit: its analytic sigma times the first fit's ratio max(robust, jackknife) / eq. 15),
then the jackknife is re-run on the pruned model. A removal after which the joint's residual
sum of squares exceeds the unpruned fit's by more than the chi-square(k) quantile at 99 %
times the joint's residual variance (k parameters removed on that joint: :data:`PRUNE_ALPHA`)
or the whole robot's weighted one by more than the chi-square(K) quantile times the fit's
residual variance (K removed in all; the base parameters are shared), is undone: the
parameter is not negligible, only poorly separated from another (e.g. b_m and b_g of a joint
that stays in one quadrant), and is reported ``unidentified``.
The IV check does not prune: it suggests a
bias, not a spread, and on a friction-dominated joint the IV estimate itself can be far off.
Removable: b_m, b_g, c_m, d_m, c_g, d_g, F_V, tau_off of every joint. a_m, a_g (the load's
gain: 0 would delete the load torque) and the base parameters above the threshold are
reported ``unidentified`` only.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from scipy.stats import chi2

from ..estimate import DEFAULT_THRESHOLD_PCT
from . import RobotIdentError
from .leverage import leverage_sigma
from .moments import JointMoments
from .paper import PAPER_BLOCK, paper_coefficients, require_theta, usual_coefficients
from .signals import RobotColumns, RobotSignals

__all__ = ["Uncertainty", "assess", "jackknife_rows", "jackknife_spread", "jackknife_units",
           "long_run_factor", "parameter_records", "robust_covariance", "N_BLOCKS", "Z_IV",
           "RATIO_FLAG", "PRUNABLE", "LONG_RUN_FLOOR"]

#: Default number of jackknife units (experiments, or blocks of them).
N_BLOCKS = 10
#: |z_iv| above which the fit and the IV estimate disagree (a two-sided 0.1 % level over a
#: few tens of parameters).
Z_IV = 4.0
#: Jackknife sigma above this multiple of the analytic one: the analytic sigma understates
#: (on white errors the largest ratio of a joint reaches about 2.3 with 20 blocks).
RATIO_FLAG = 3.0
#: Per-joint parameters of the paper model that pruning may remove (held at 0).
PRUNABLE = ("b_m", "b_g", "c_m", "d_m", "c_g", "d_g", "FV", "OFF")
#: Relative step tolerance of the jackknife's Gauss-Newton refits (the fit's: ``tol``).
REPLICATE_TOL = 1e-7
#: Progress lines only once the assessment has run this long [s], then at most this often.
PROGRESS_AFTER_S = 10.0
#: The honest sigma's robust eq. 15 takes each joint's long-run factor at least this (white
#: errors): the factor is the residual's spectrum at zero frequency, the regressor's columns
#: are at the motion's frequencies; a residual whose spectrum falls toward 0 (measured: arm3,
#: usual friction, the paper model at 1 kHz, seed 2 of tests/test_robot_selection_shift.py:
#: factors 0.11-0.12 on every joint, the sum of z^2 to the truth 93 over 36 unpruned
#: parameters against the 99.9 % quantile 68 without the floor, 8.4 over 34 with it) is not
#: that much weaker where the regressor is.
LONG_RUN_FLOOR = 1.0


@dataclass
class Uncertainty:
    """Honest standard deviations of a fitted model (module doc).

    Attributes
    ----------
    names : tuple of str
        The model's parameter names (``RobotModel.names_``).
    std_analytic, std_jackknife, std : ndarray (b,)
        Eq. 15, the jackknife spread (NaN when not run) and the honest sigma.
    std_robust : ndarray (b,) or None
        Eq. 15 in its robust form (:func:`robust_covariance`); None with soft quadrants.
    long_run : dict or None
        Per joint the residual's long-run factor (:func:`long_run_factor`; the robust sigma
        takes it at least :data:`LONG_RUN_FLOOR`).
    std_leverage : ndarray (b,) or None
        The friction blocks' leverage-robust (HC3) sigma
        (:func:`ident.robot.leverage.leverage_sigma`); NaN on the base parameters, and
        everywhere with IDIM-IV or soft quadrants.
    coef_iv, std_iv, z_iv : ndarray (b,) or None
        The IDIM-IV check (None when not made: no instruments, or the fit is IV).
    n_replicates, n_failed : int
        Jackknife replicates made and left out (singular normal equations).
    units : str
        What was resampled, e.g. ``"20 blocks of 1 experiment"``.
    flags : dict
        Per joint: ``{"errors_in_variables": bool, "sigma_ratio": max jackknife/analytic,
        "sigma_ratio_parameter": name, "z_iv": max |z_iv| or None, "z_iv_parameter": name,
        "reason": text}``.
    pruned : list of str
        Parameters removed by the pruning (held at 0).
    unidentified : list of str
        Remaining parameters whose relative honest sigma exceeds ``threshold_pct``.
    threshold_pct : float
        Pruning threshold on 100 sigma / |value| [%] (eq. 16).
    iv_note : str
        Why the IV check was not made (empty when it was).
    """

    names: tuple[str, ...]
    std_analytic: np.ndarray
    std_jackknife: np.ndarray
    std: np.ndarray
    coef_iv: np.ndarray | None = None
    std_iv: np.ndarray | None = None
    z_iv: np.ndarray | None = None
    n_replicates: int = 0
    n_failed: int = 0
    units: str = ""
    flags: dict[str, dict[str, Any]] = field(default_factory=dict)
    pruned: list[str] = field(default_factory=list)
    unidentified: list[str] = field(default_factory=list)
    threshold_pct: float = DEFAULT_THRESHOLD_PCT
    iv_note: str = ""
    std_robust: np.ndarray | None = None
    long_run: dict[str, float] | None = None
    std_leverage: np.ndarray | None = None

    def to_json(self) -> dict[str, Any]:
        """The JSON block ``models.<m>.uncertainty`` of docs/robot-data.md (the per-parameter
        sigmas are in :func:`parameter_records`)."""
        analytic = ("analytic eq. 15 (soft quadrants)" if self.std_robust is None else
                    "max(robust eq. 15, block jackknife, friction HC3)" if self.n_replicates
                    else "max(robust eq. 15, friction HC3)")
        return {
            "method": analytic + (", IDIM-IV check" if self.z_iv is not None else ""),
            "robust": None if self.std_robust is None else
            "eq. 15 with each joint's residual variance times its residual long-run factor "
            "(at least 1)",
            "long_run_factor": self.long_run,
            "n_replicates": int(self.n_replicates), "n_failed": int(self.n_failed),
            "units": self.units,
            "iv": None if self.z_iv is None else {
                n: {"value": _num(v), "std": _num(s), "z": _num(z)}
                for n, v, s, z in zip(self.names, self.coef_iv, self.std_iv, self.z_iv,
                                      strict=True)},
            "iv_note": self.iv_note,
            "joints": self.flags,
            "pruned": list(self.pruned),
            "unidentified": list(self.unidentified),
            "threshold_pct": float(self.threshold_pct),
        }


def _num(v: float) -> float | None:
    v = float(v)
    return v if math.isfinite(v) else None


# ------------------------------------------------------------------------------ units
def _take(sig: RobotSignals, rows: np.ndarray) -> RobotSignals:
    """The samples ``rows`` of ``sig`` (contiguous rows of one experiment)."""
    c = sig.columns
    cols = None if c is None else RobotColumns(
        W=c.W[:, :, rows], p=c.p[rows], sign=c.sign[rows], keep=c.keep[rows],
        Wz=None if c.Wz is None else c.Wz[:, :, rows], pz=None if c.pz is None else c.pz[rows],
        products=None if c.products is None else c.products.take(rows))
    return replace(sig, t=sig.t[rows], q=sig.q[rows], dq=sig.dq[rows], ddq=sig.ddq[rows],
                   tau=sig.tau[rows], experiment=sig.experiment[rows],
                   q_ref=None if sig.q_ref is None else sig.q_ref[rows], columns=cols,
                   sign=None if sig.sign is None else sig.sign[rows])


def jackknife_rows(groups: Sequence[np.ndarray], n_blocks: int = N_BLOCKS
                   ) -> tuple[list[tuple[int, np.ndarray]], str]:
    """The jackknife's units (module doc) as rows: ``groups`` holds the rows of each
    experiment; each is one unit when there are at least ``n_blocks`` of them, otherwise
    each is cut into ``ceil(n_blocks / experiments)`` contiguous blocks (at least 2).

    Returns
    -------
    (list of (int, ndarray), str)
        Per unit the index of its experiment in ``groups`` and its rows; what they are.
    """
    if len(groups) >= n_blocks:
        return [(g, np.asarray(r)) for g, r in enumerate(groups)], f"{len(groups)} experiments"
    per = max(2, math.ceil(n_blocks / len(groups)))
    units = [(g, part) for g, rows in enumerate(groups) for part in np.array_split(rows, per)
             if part.size]
    return units, (f"{per} contiguous blocks of each of {len(groups)} experiment"
                   + ("s" if len(groups) > 1 else ""))


def jackknife_spread(replicates: np.ndarray) -> np.ndarray:
    """The jackknife's sigma of the U replicates (rows of ``replicates``, shape (U, p)):
    ``sqrt(U - 1) * 1.4826 MAD`` per column (module doc), the delete-one jackknife's
    sqrt((U - 1) / U sum_u (x_u - mean)^2) with a robust deviation, so that one replicate
    that ends elsewhere (a weak direction) does not decide it."""
    X = np.asarray(replicates, dtype=float)
    mad = 1.4826 * np.median(np.abs(X - np.median(X, axis=0)), axis=0)
    return np.sqrt(X.shape[0] - 1) * mad


def jackknife_units(signals: RobotSignals | Sequence[RobotSignals],
                    n_blocks: int = N_BLOCKS) -> tuple[list[RobotSignals], str]:
    """Cut the data into the jackknife's units (module doc, :func:`jackknife_rows`); (units,
    what they are)."""
    items = [signals] if isinstance(signals, RobotSignals) else list(signals)
    exps = [(s, np.flatnonzero(s.experiment == e)) for s in items
            for e in np.unique(s.experiment)]
    if not exps:
        raise RobotIdentError("uncertainty: no samples")
    units, text = jackknife_rows([r for _, r in exps], n_blocks)
    return [_take(exps[g][0], rows) for g, rows in units], text


def _sum(moms: list[list[JointMoments]], counts: np.ndarray) -> list[JointMoments]:
    """sum_u counts[u] moms[u] per joint."""
    out = []
    for j, m0 in enumerate(moms[0]):
        m = type(m0)(m0.cols, iv=m0.iv, powers=m0.powers)  # (rows given whole: RowMoments)
        for c, mu in zip(counts, moms, strict=True):
            if c == 0:
                continue
            mj = mu[j]
            m.vv += c * mj.vv
            if hasattr(m, "quadrant_n"):
                m.quadrant_n += c * mj.quadrant_n
            if m.iv:
                m.zv += c * mj.zv
                m.zz += c * mj.zz
            m.n += int(c) * mj.n
        out.append(m)
    return out


# ------------------------------------------------------------------------------ model hooks
def _coeffs(model: Any):
    if model.model == "usual":
        return usual_coefficients
    return model._coefficients if getattr(model, "full_rate_paper_", False) else (
        paper_coefficients)


def _full_rate(model: Any, signals: Any) -> Any:
    """``signals`` carrying the fitted bilinear paper model's products formed at full rate
    on the fit's quadrants (``quadrant_from_``; ``RobotModel(full_rate=True)``), so that
    every unit's moments are the fit's rows (:func:`_moments`); ``signals`` otherwise."""
    if not getattr(model, "full_rate_paper_", False) or not isinstance(signals, RobotSignals):
        return signals
    try:
        return model._banded(model._products_at(signals, model.quadrant_from_))
    except RobotIdentError:
        return signals


def _moments(model: Any, sig: Any, theta: Any, powers: int) -> list[JointMoments]:
    """The fit's moments on ``sig``: the full-rate products' rows when the model was fitted
    on them and ``sig`` carries them, else the model's pass with the quadrants of
    ``theta``."""
    if getattr(model, "full_rate_paper_", False) and isinstance(sig, RobotSignals) and (
            sig.columns is not None and sig.columns.products is not None):
        return model._pass_rows(sig)
    return model._pass(sig, theta, powers)[0]


def _free(model: Any, pruned: Sequence[str] = ()) -> np.ndarray:
    held = set(model.fixed_) | set(pruned)
    return np.array([n not in held for n in model.names_])


def _unit_moments(model: Any, units: list[RobotSignals]) -> list[list[JointMoments]]:
    """Each unit's moments with the quadrants the fit ended on."""
    powers = 1 if model.model == "usual" else 3
    theta = getattr(model, "quadrant_from_", None)
    return [_moments(model, u, theta, powers) for u in units]


def _refit(model: Any, moms: list[JointMoments], free: np.ndarray,
           tol: float | None = None, max_iter: int | None = None) -> np.ndarray:
    """The model's Gauss-Newton on ``moms`` from its estimate (held parameters at their value,
    pruned ones at 0), with the fit's weights (WLS: not re-estimated), to ``tol``."""
    held = np.isin(model.names_, list(model.fixed_))
    x0 = np.where(free | held, model.coef_, 0.0)
    w = getattr(model, "weights_", None)
    w = np.ones(len(moms)) if w is None else np.asarray(w, dtype=float)
    saved = model.tol, model.max_iter
    model.tol = saved[0] if tol is None else tol
    model.max_iter = saved[1] if max_iter is None else min(int(saved[1]), max_iter)
    try:
        x, _ = model._gauss_newton(moms, _coeffs(model), x0, free, w,
                                   linear=model.model == "usual")
    finally:
        model.tol, model.max_iter = saved
    return x


def _replicates(model: Any, moms: list[list[JointMoments]], free: np.ndarray,
                say: Callable[[str], None]) -> tuple[np.ndarray, int]:
    """Delete-one-unit jackknife (module doc); (sigma, replicates left out)."""
    n = len(moms)
    xs, failed = [], 0
    for u in range(n):
        counts = np.ones(n, dtype=int)
        counts[u] = 0
        try:
            x = _refit(model, _sum(moms, counts), free, REPLICATE_TOL)
        except RobotIdentError:
            failed += 1
            continue
        if np.all(np.isfinite(x)):
            xs.append(x)
        else:
            failed += 1
        say(f"sigma: jackknife replicate {u + 1} of {n}")
    m = len(xs)
    if m < 3:
        return np.full(model.coef_.size, np.nan), failed
    return jackknife_spread(np.asarray(xs)), failed


def _iv_check(model: Any, signals: Any) -> tuple[Any, str]:
    """The IDIM-IV refit on the fit's quadrants, or (None, why not)."""
    if model.method == "iv":
        return None, "the fit is IDIM-IV"
    items = [signals] if isinstance(signals, RobotSignals) else list(signals)
    if not all(s.q_ref is not None or (s.columns is not None and s.columns.Wz is not None)
               for s in items):
        return None, "no reference trajectory q_ref (instruments)"
    if not all(s.columns is None or s.columns.Wz is not None for s in items):
        return None, "the columns were built without the instruments' columns"
    params = model.get_params()
    params["method"] = "iv"
    theta = getattr(model, "quadrant_from_", None)
    if model.model == "paper" and model.quadrant == "model" and theta is not None:
        params["quadrant_theta"] = theta
    iv = type(model)(**params)
    try:
        iv.fit(signals)
    except RobotIdentError as exc:
        return None, f"IDIM-IV not identifiable on these data ({exc})"
    return iv, ""


def _joint_of(model: Any) -> list[int | None]:
    """Joint index of each parameter (None for the shared base parameters)."""
    nb, pb = len(model.block_), model.n_theta_
    return [None if i < pb else (i - pb) // nb for i in range(len(model.names_))]


def _flags(model: Any, std_a: np.ndarray, std_b: np.ndarray,
           z_iv: np.ndarray | None) -> dict[str, dict[str, Any]]:
    owner = _joint_of(model)
    out = {}
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(std_a > 0, std_b / std_a, np.nan)
    for j, joint in enumerate(model.joints_):
        idx = [i for i, o in enumerate(owner) if o == j]
        r = ratio[idx]
        ir = idx[int(np.nanargmax(r))] if np.any(np.isfinite(r)) else None
        rmax = float(ratio[ir]) if ir is not None else math.nan
        zi = zmax = None
        if z_iv is not None and np.any(np.isfinite(z_iv[idx])):
            zi = idx[int(np.nanargmax(np.abs(z_iv[idx])))]
            zmax = float(abs(z_iv[zi]))
        reasons = []
        if ir is not None and rmax > RATIO_FLAG:
            reasons.append(f"jackknife sigma of {model.names_[ir]} is {rmax:.3g} x the "
                           f"analytic one")
        if zmax is not None and zmax > Z_IV:
            reasons.append(f"{model.names_[zi]}: fit and IDIM-IV differ by {zmax:.3g} sigma")
        out[joint] = {
            "errors_in_variables": bool(reasons),
            "sigma_ratio": _num(rmax), "sigma_ratio_parameter": (
                None if ir is None else model.names_[ir]),
            "z_iv": zmax, "z_iv_parameter": None if zi is None else model.names_[zi],
            "reason": ("errors-in-variables: the fit and IV/jackknife disagree: "
                       + "; ".join(reasons)) if reasons else ""}
    return out


def _rel(x: np.ndarray, s: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(x != 0, 100.0 * s / np.abs(x), np.inf)


def _prunable(model: Any, free: np.ndarray) -> np.ndarray:
    owner = _joint_of(model)
    ok = np.zeros(len(model.names_), dtype=bool)
    if model.model != "paper":
        return ok
    for i, o in enumerate(owner):
        if o is not None and free[i] and PAPER_BLOCK[(i - model.n_theta_) % len(PAPER_BLOCK)] \
                in PRUNABLE:
            ok[i] = True
    return ok


# ------------------------------------------------------------------------------ entry point
def assess(model: Any, signals: RobotSignals | Sequence[RobotSignals], *,
           n_blocks: int = N_BLOCKS,
           iv: bool = True, prune: bool = True,
           threshold_pct: float = DEFAULT_THRESHOLD_PCT,
           progress: Callable[[str], None] | None = None) -> Uncertainty:
    """Honest sigma, the errors-in-variables flags and the pruning of a fitted model (module
    doc). With pruning the model is refitted in place (``coef_``, ``std_``, ``cov_``, ... of
    the pruned model; ``pruned_`` names what was removed).

    Parameters
    ----------
    model : RobotModel
        Fitted on ``signals``.
    signals : RobotSignals or sequence
        The data of the fit.
    n_blocks : int
        Units of the jackknife wanted (module doc); 0: no jackknife (the honest sigma is the
        robust eq. 15, raised by the IV check), else at least 2.
    iv : bool
        Make the IDIM-IV check when the data carry instruments.
    prune : bool
        Paper model: prune (module doc); otherwise only report ``unidentified``.
    threshold_pct : float
        Pruning threshold [%] (eq. 16).
    progress : callable or None
        Called with a progress line, only once the assessment has run for
        ``PROGRESS_AFTER_S`` and then at most that often.

    Returns
    -------
    Uncertainty
        Also set as ``model.uncertainty_``; ``model.std_honest_`` and ``model.pruned_``.
    """
    if not hasattr(model, "coef_"):
        raise RobotIdentError("uncertainty: the model is not fitted")
    require_theta(model, "uncertainty")  # (the jackknife and the pruning are bilinear's)
    n_blocks = int(n_blocks)
    if n_blocks < 0 or n_blocks == 1:
        raise RobotIdentError(f"uncertainty: n_blocks (--sigma-blocks): expected 0 (no "
                              f"jackknife) or >= 2, got {n_blocks!r}")
    soft = getattr(model, "quadrants", "hard") == "soft"
    if soft:  # (ident.robot.soft_fit: the jackknife and the pruning refit hard moments)
        n_blocks, iv, prune = 0, False, False
    t0 = time.monotonic()
    last = [t0]

    def say(msg: str) -> None:
        now = time.monotonic()
        if progress is not None and now - t0 > PROGRESS_AFTER_S and \
                now - last[0] > PROGRESS_AFTER_S:
            last[0] = now
            progress(f"{msg} ({now - t0:.0f} s)")

    units, text = jackknife_units(_full_rate(model, signals), max(n_blocks, 2))
    moms = _unit_moments(model, units) if n_blocks or prune else []
    say("sigma: unit moments done")
    ivm, note = _iv_check(model, signals) if iv else (
        None, "soft quadrants: analytic sigma only" if soft else "not asked")
    say("sigma: IDIM-IV check done")
    robust = None if soft else _robust_sigma(model, signals, moms)
    say("sigma: robust eq. 15 done")
    std_l = leverage_sigma(model, signals, _free(model))
    std_a, std_b, std_r, std, z, failed = _honest(model, moms, ivm, _free(model), n_blocks,
                                                  robust, say, std_l)
    pruned: list[str] = []
    if prune and model.model == "paper" and moms:
        # the spread decides (eq. 16 with the jackknife), not a bias the IV check suggests:
        # on a friction-dominated joint the IV estimate itself can be far off
        # the pruning's order reads max(robust eq. 15, jackknife), not the HC3 side: with
        # it, the KUKA KR300's paper model (docs/robot-data.md) pruned 19 other parameters
        # and cross-validated at 12.5 % instead of 7.7 % (A3 9.2 against 2.8 %, A4 176
        # against 79 %); which sigma the greedy pruning should read is left open
        inflate = (np.fmax(np.nan_to_num(std_r, nan=0.0) if std_r is not None else std_a,
                           np.nan_to_num(std_b)) / np.where(std_a > 0, std_a, 1.0))
        inflate = np.where(inflate > 0, inflate, 1.0)
        pruned = _prune(model, moms, _free(model), inflate, threshold_pct)
        if pruned:
            say(f"sigma: pruned {', '.join(pruned)}; jackknife of the pruned model")
            std_l = leverage_sigma(model, signals, _free(model, pruned))
            std_a, std_b, std_r, std, z, failed = _honest(
                model, moms, ivm, _free(model, pruned), n_blocks, robust, say, std_l)
    free = _free(model, pruned)
    rel = _rel(model.coef_, std)
    unid = [n for n, r, f in zip(model.names_, rel, free, strict=True)
            if f and not r <= threshold_pct]
    out = Uncertainty(names=tuple(model.names_), std_analytic=std_a, std_jackknife=std_b,
                      std=std, coef_iv=None if ivm is None else ivm.coef_.copy(),
                      std_iv=None if ivm is None else ivm.std_.copy(), z_iv=z,
                      n_replicates=len(units) if n_blocks else 0, n_failed=failed,
                      units=text if n_blocks else "",
                      flags=_flags(model, std_a, std_b, z), pruned=pruned, unidentified=unid,
                      threshold_pct=float(threshold_pct), iv_note=note, std_robust=std_r,
                      long_run=None if robust is None else {
                          j: float(f) for j, f in zip(model.joints_, robust[1], strict=True)},
                      std_leverage=std_l)
    model.uncertainty_ = out
    model.std_honest_ = std
    model.pruned_ = list(pruned)
    return out


def _robust_sigma(model: Any, signals: Any, moms: list[list[JointMoments]]
                  ) -> tuple[list[JointMoments], np.ndarray]:
    """The fit's moments (the units' summed, else one pass) and its residual's long-run factor
    per joint: what :func:`_honest` needs for the robust eq. 15 at any estimate."""
    if moms:
        full = _sum(moms, np.ones(len(moms), dtype=int))
    else:
        powers = 1 if model.model == "usual" else 3
        full = _moments(model, _full_rate(model, signals),
                        getattr(model, "quadrant_from_", None), powers)
    return full, long_run_factor(model, signals)


def _honest(model: Any, moms: list[list[JointMoments]], ivm: Any, free: np.ndarray,
            n_blocks: int, robust: tuple[list[JointMoments], np.ndarray] | None,
            say: Callable[[str], None], std_l: np.ndarray | None = None) -> tuple:
    """(analytic, jackknife, robust or None, honest sigma, z_iv or None, replicates left out)
    at the model's current estimate (module doc); ``robust``: :func:`_robust_sigma`'s (None:
    soft quadrants, the honest sigma's analytic side is eq. 15); ``std_l``: the friction
    blocks' leverage-robust sigma (:func:`ident.robot.leverage.leverage_sigma`; NaN where
    not made), also a lower bound of the honest sigma."""
    std_a = model.std_.copy()
    std_b, failed = np.full(std_a.size, np.nan), 0
    if n_blocks:
        std_b, failed = _replicates(model, moms, free, say)
    std_r = None
    side = std_a
    if robust is not None:
        try:
            cov = _robust_cov(model, robust[0], np.fmax(robust[1], LONG_RUN_FLOOR), free)
            std_r = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        except np.linalg.LinAlgError:
            std_r = np.full(std_a.size, np.nan)
        std_r = np.where(free, std_r, 0.0)
        side = np.where(np.isfinite(std_r), std_r, std_a)  # (singular: eq. 15's)
    std = np.fmax(side, std_b)
    if std_l is not None:
        std = np.fmax(std, std_l)
    z = None
    if ivm is not None:
        d = model.coef_ - ivm.coef_
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.where(free, d / np.sqrt(ivm.std_**2 + std**2), np.nan)
        big = np.abs(np.nan_to_num(z)) > Z_IV
        std = np.where(big, np.fmax(std, np.abs(d)), std)
    return std_a, std_b, std_r, np.where(free, std, 0.0), z, failed


#: significance level of the partial test that keeps a parameter whose removal raises its
#: joint's residual: the cumulative rise of a joint's residual sum of squares over the
#: unpruned fit must stay below the chi-square(k) quantile at 1 - PRUNE_ALPHA times the
#: joint's residual variance, k the parameters removed on that joint
PRUNE_ALPHA = 0.01

#: Gauss-Newton tolerance of the candidate refits of the pruning (relative step; the cost is
#: then within ~1e-12 relative of its minimum); the pruned model is refitted to the fit's own
PRUNE_TOL = 1e-6
#: and at most this many steps (from the current estimate, one parameter less)
PRUNE_MAX_ITER = 10


def _prune(model: Any, moms: list[list[JointMoments]], free: np.ndarray, inflate: np.ndarray,
           threshold_pct: float) -> list[str]:
    """Remove the worst prunable parameter above the threshold and refit (the fit's
    quadrants and weights), repeatedly, with the honest sigma estimated as the refit's
    analytic sigma times ``inflate``; the model is left refitted without them. A removal
    after which the joint's (or the whole robot's weighted) residual sum of squares exceeds
    the unpruned fit's by a significant amount (:data:`PRUNE_ALPHA`: the removed parameters
    are large relative sigma but not negligible, e.g. one of two correlated Coulomb terms) is
    undone and the parameter kept (reported ``unidentified``). Returns the names removed, in
    order."""
    full = _sum(moms, np.ones(len(moms), dtype=int))
    out: list[str] = []
    free = free.copy()
    can = _prunable(model, free)
    owner = _joint_of(model)
    w = np.asarray(model.weights_, dtype=float)
    coeffs = _coeffs(model)
    rr0 = model._cost(full, coeffs, model.coef_)
    var0 = np.asarray(model.sigma_joint_, dtype=float) ** 2
    s2 = float(model.sigma_) ** 2  # weighted residual variance of the unpruned fit
    removed = np.zeros(len(rr0), dtype=int)
    while True:
        rel = _rel(model.coef_, model.std_ * inflate)
        cand = np.where(can & free, rel, -np.inf)
        i = int(np.argmax(cand))
        if not cand[i] > threshold_pct:
            if out:  # the candidates were refitted to PRUNE_TOL: the last one to the fit's
                model._statistics(full, coeffs, _refit(model, full, free), free, w)
            return out
        j = owner[i]
        x_before = model.coef_.copy()
        free[i] = False
        x = _refit(model, full, free, tol=max(model.tol, PRUNE_TOL), max_iter=PRUNE_MAX_ITER)
        rise = model._cost(full, coeffs, x) - rr0
        if (rise[j] > chi2.ppf(1.0 - PRUNE_ALPHA, removed[j] + 1) * var0[j]
                or float(w @ rise) > chi2.ppf(1.0 - PRUNE_ALPHA, len(out) + 1) * s2):
            free[i] = True  # not negligible: kept, reported unidentified
            can[i] = False
            model._statistics(full, coeffs, x_before, free, w)
            continue
        removed[j] += 1
        out.append(model.names_[i])
        model._statistics(full, coeffs, x, free, w)


# ------------------------------------------------------------------- eq. 15, robust form
def long_run_factor(model: Any, signals: RobotSignals | Sequence[RobotSignals],
                    lags: int | None = None) -> np.ndarray:
    """Per joint: the long-run variance of the fit's residual over its variance,
    ``1 + 2 sum_{k=1..L} (1 - k / (L + 1)) rho_k`` (Bartlett weights, so never negative),
    rho_k the residual's autocorrelation at lag k over the rows the fit took
    (:meth:`~ident.robot.estimate.RobotModel.fitted_rows`), pairs within one experiment.

    1 on white errors. The anti-alias filter of the decimation (:func:`ident.chain.decimate`)
    leaves white full-rate noise correlated between kept rows, its spectrum flat up to 0.8
    of the decimated Nyquist frequency and falling above: at low frequency, where the
    regressor is, the noise is 1.18 times the average its variance per row measures
    (Chebyshev, r = 8 or 20).

    Parameters
    ----------
    model : RobotModel
        Fitted on ``signals``.
    signals : RobotSignals or sequence
        The data of the fit.
    lags : int or None
        L; None: the Newey-West rule floor(4 (n_j / 100)^(2/9)), n_j the joint's rows.

    Returns
    -------
    ndarray (k,)
        The factor per joint [-].
    """
    items = [signals] if isinstance(signals, RobotSignals) else list(signals)
    k = len(model.joints_)
    pieces: list[list[tuple[np.ndarray, np.ndarray]]] = [[] for _ in range(k)]
    for sig in items:
        rho = np.asarray(model.residual(sig), dtype=float)
        rows = np.asarray(model.fitted_rows(sig), dtype=bool) & np.isfinite(rho)
        for e in np.unique(sig.experiment):
            sel = sig.experiment == e
            for j in range(k):
                pieces[j].append((rho[sel, j], rows[sel, j]))
    out = np.ones(k)
    for j in range(k):
        n = sum(int(ok.sum()) for _, ok in pieces[j])
        if n < 3:
            continue
        mean = sum(float(x[ok].sum()) for x, ok in pieces[j]) / n
        xs = [(np.where(ok, x - mean, 0.0), ok) for x, ok in pieces[j]]
        g0 = sum(float(x @ x) for x, _ in xs) / n
        if g0 <= 0:
            continue
        L = int(4 * (n / 100) ** (2 / 9)) if lags is None else int(lags)
        f = 1.0
        for lag in range(1, L + 1):
            num = sum(float(x[lag:] @ x[:-lag]) for x, _ in xs if x.size > lag)
            cnt = sum(int((ok[lag:] & ok[:-lag]).sum()) for _, ok in xs if ok.size > lag)
            if cnt:
                f += 2.0 * (1.0 - lag / (L + 1)) * num / cnt / g0
        out[j] = max(f, 0.0)
    return out


def robust_covariance(model: Any, signals: RobotSignals | Sequence[RobotSignals], *,
                      long_run: bool = True, lags: int | None = None) -> np.ndarray:
    """Eq. 15 without its two assumptions that fail on the robot's data: one residual
    variance for every joint, and errors white between the rows.

    ``C = A^-1 (sum_j w_j^2 f_j sigma_j^2 B_j) A^-T`` on the fit's rows and quadrants, with
    ``A = sum_j w_j W_j^T W_j`` (IV: ``Z_j^T W_j``; the paper model: its Jacobian at the
    solution), ``B_j = W_j^T W_j`` (IV: ``Z_j^T Z_j``), w_j the fit's weights (1 but for
    WLS), ``sigma_j^2 = ||rho_j||^2 / (r_j - b_j)`` joint j's residual variance and f_j its
    :func:`long_run_factor` (1 with ``long_run=False``). With one sigma for all joints and
    f_j = 1 it is eq. 15.

    Why: IDIM-LS and IDIM-IV pool the residual variance over the joints (eq. 14), so the
    parameters that the noisiest joint decides are given its share of the average; and the
    decimation leaves the noise correlated between rows (:func:`long_run_factor`). Measured
    on the simulated 3-dof arm (usual friction, payload ratio, known rotors, 1 % torque noise,
    40 seeds, ``benchmarks/robot_sigma_calibration.py``), the spread of the estimate over
    seeds against the covariance, tr(C^-1 S) / p on the columns chain: eq. 15 LS 1.39, IV
    1.34, WLS 1.09; this covariance 0.96, 0.97, 0.95 (states chain, whose residual carries
    model error too: 0.88-0.92). The factor f_j scales the whole of B_j: exact when the
    noise's spectrum is flat where the regressor's columns are. :func:`assess` takes its
    diagonal, with the factors taken at least :data:`LONG_RUN_FLOOR`, into the honest sigma;
    ``cov_`` stays eq. 15.

    Parameters
    ----------
    model : RobotModel
        Fitted (hard quadrants) on ``signals``.
    signals : RobotSignals or sequence
        The data of the fit.
    long_run : bool
        Apply :func:`long_run_factor` (one pass predicting the residual).
    lags : int or None
        Its L.

    Returns
    -------
    ndarray (b, b)
        Covariance of ``model.coef_`` (zero rows and columns for held parameters).
    """
    if not hasattr(model, "coef_"):
        raise RobotIdentError("robust_covariance: the model is not fitted")
    if getattr(model, "quadrants", "hard") == "soft":
        raise RobotIdentError("robust_covariance: soft quadrants are not supported (hard "
                              "quadrants only)")
    powers = 1 if model.model == "usual" else 3
    moms = _moments(model, _full_rate(model, signals), getattr(model, "quadrant_from_", None),
                    powers)
    f = long_run_factor(model, signals, lags) if long_run else np.ones(len(moms))
    return _robust_cov(model, moms, f, _free(model, getattr(model, "pruned_", ())))


def _robust_cov(model: Any, moms: list[JointMoments], f: np.ndarray,
                free: np.ndarray) -> np.ndarray:
    """:func:`robust_covariance` on the fit's moments ``moms`` with the long-run factors
    ``f`` and the free parameters ``free``."""
    coeffs = _coeffs(model)
    w = getattr(model, "weights_", None)
    w = np.ones(len(moms)) if w is None else np.asarray(w, dtype=float)
    x = model.coef_
    nx = x.size
    A = np.zeros((nx, nx))
    M = np.zeros((nx, nx))
    for j, mom in enumerate(moms):
        idx = model._local(j)
        nt = model._nt(j)
        th, blk = x[idx[:nt]], x[idx[nt:]]
        Aj, _, rrj, Cj, _ = mom.normal([coeffs(th, blk, 0), coeffs(th, blk, 1)])
        s2 = rrj / max(mom.n - int(free[idx].sum()), 1)
        A[np.ix_(idx, idx)] += w[j] * Aj
        M[np.ix_(idx, idx)] += w[j] ** 2 * f[j] * s2 * (Aj if Cj is None else Cj)
    fi = np.flatnonzero(free)
    Ainv = np.linalg.inv(A[np.ix_(fi, fi)])
    cov = np.zeros((nx, nx))
    cov[np.ix_(fi, fi)] = Ainv @ M[np.ix_(fi, fi)] @ Ainv.T
    return cov


def parameter_records(model: Any) -> dict[str, dict[str, Any]]:
    """``{name: {"value", "std", "rel_std_pct", "std_analytic", "std_robust",
    "std_jackknife", "std_leverage", "pruned"[, "removed"]}}`` of a fitted model: ``std`` the
    honest sigma when :func:`assess` ran (else eq. 15), ``rel_std_pct`` 100 std / |value|
    (None when the value is 0), ``std_robust`` the robust eq. 15 (None when not computed: soft
    quadrants, or no assessment), ``std_leverage`` the friction blocks' HC3 sigma (None on the
    base parameters, with IDIM-IV, soft quadrants or no assessment), ``removed`` (only on the
    parameters the fit's rank rule held at 0, ``removed_``) its reason."""
    u = getattr(model, "uncertainty_", None)
    std = model.std_ if u is None else u.std
    lev = (np.full(std.size, np.nan) if u is None or u.std_leverage is None
           else u.std_leverage)
    jack = np.full(std.size, np.nan) if u is None else u.std_jackknife
    rob = (np.full(std.size, np.nan) if u is None or u.std_robust is None
           else u.std_robust)
    pruned = set(getattr(model, "pruned_", ()))
    # the columns the rank rule dropped before the fit (zero or exactly dependent on these
    # data, held at 0): "removed" with the reason, only on them
    removed = dict(getattr(model, "removed_", ()))
    return {p: {"value": float(v), "std": float(s),
                "rel_std_pct": float(100.0 * s / abs(v)) if v != 0 else None,
                "std_analytic": float(sa), "std_robust": _num(sr), "std_jackknife": _num(sj),
                "std_leverage": _num(sl), "pruned": p in pruned,
                **({"removed": removed[p]} if p in removed else {})}
            for p, v, s, sa, sr, sj, sl in zip(model.names_, model.coef_, std, model.std_,
                                               rob, jack, lev, strict=True)}
