"""Excitation quality of a robot plan, and multi-sine optimisation for it.

(Just past 600 lines: prediction, optimisation and the assessment ``jointid plan`` prints
share the base-column and condition-number conventions defined here.)

Before anything moves, ``jointid plan`` predicts whether a plan will identify the robot's
parameters:

- the condition number of the regressor over the plan, restricted to the base columns
  (Gautier 1991: the columns of a regressor built at random states that the robot model's one
  base-parameter rule keeps, :func:`trajectories.robot.base.independent_columns`, see
  :func:`base_columns`: the columns the fit estimates); a large condition number means some
  base parameters will have large standard deviations;
- per joint, the share of moving samples in each velocity band (0-10 %, 10-35 %, 35-100 %
  of max velocity; the paper's dry friction changes in the lowest band) and in each
  quadrant of the (dq, tau_out) plane (paper section III.B, Fig. 2: quadrants 1 and 3 motor,
  2 and 4 generator), with ``tau_out`` from an inverse-dynamics callable.

:func:`optimise_multisine` minimises that condition number over the Fourier coefficients of
a multi-sine (as FloBaRoID, BIRDy and FIGAROH do), within every joint's position, velocity,
acceleration and jerk limits, with scipy.optimize.

The regressor and the inverse dynamics are callables (:class:`trajectories.robot_model.
RobotDynamics` builds them from the robot model, :mod:`trajectories.robot`; tests pass their
own): this module is numerics only.

Regressor convention: ``regressor(q, dq, ddq) -> W`` with q, dq, ddq of shape (n, k) and
W of shape (n * k, p), rows sample-major (row ``i * k + j`` is joint j at sample i) --
the row order does not change the condition number or the base columns; the columns in the
robot model's standard order (``RobotRegressor.standard_names`` then ``friction_names``), so
that the base rule keeps the lower link's parameters as the fit does.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np
import scipy.optimize

from . import TrajectoryError
from .campaign import JointLimits
from .fourier import (
    default_coefficients,
    fit_coefficients,
    fourier_eval,
    multisine_ratio,
    rest_projection,
)
from .multi import (
    BANDS,
    MOVING_FRACTION,
    RobotPlan,
    _resolve_multisine,
    band_shares,
    plan_robot,
    plan_robot_campaign,
)
from .multi import InverseDynamics as PayloadDynamics
from .robot.base import DEFAULT_RTOL, independent_columns, uniform_states
from .robot_campaign import MultisineSegment, RobotCampaign

__all__ = [
    "Assessment",
    "BASE_RTOL",
    "OptimisedMultisine",
    "assess_robot_campaign",
    "QUADRANTS",
    "Quality",
    "TAU_RTOL",
    "base_columns",
    "condition_number",
    "optimise_campaign",
    "optimise_multisine",
    "quadrant_shares",
    "quality",
    "random_states",
    "zero_load_share",
    "ZERO_LOAD_SHARE",
]

#: (n, k) x 3 -> (n * k, p)
Regressor = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]
#: (n, k) x 3 -> tau_out (n, k) [N m]
InverseDynamics = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]

#: the robot model's one rank tolerance of the base-parameter rule
#: (:data:`trajectories.robot.base.DEFAULT_RTOL`)
BASE_RTOL = DEFAULT_RTOL
#: relative torque below which a sample counts in no quadrant (see quadrant_shares)
TAU_RTOL = 1e-6
#: quadrants of the (dq, tau_out) plane (paper Fig. 2.a): 1 motor (dq > 0, tau > 0),
#: 2 generator (dq < 0, tau > 0), 3 motor (dq < 0, tau < 0), 4 generator (dq > 0, tau < 0)
#: Share of a joint's moving samples at zero output torque above which the plan's table warns:
#: there the paper model's quadrant (eq. 27-28) is decided by noise, and a gravity-free joint
#: cruising slowly gets biased dry-friction terms. Measured on the simulated UR10 demo
#: campaign's shoulder pan (docs/robot-identification.md): 59.9 % (slow trapezoids) gave
#: Stribeck terms 6-9 sigma off; 1.6 % (sines) within 2.4 sigma.
ZERO_LOAD_SHARE = 0.2
QUADRANTS = ("Q1 dq+ tau+", "Q2 dq- tau+", "Q3 dq- tau-", "Q4 dq+ tau-")


# --------------------------------------------------------------------------- base columns
def random_states(limits: Sequence[JointLimits], n: int, seed: int = 0
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Uniform random states within the limits, each of shape (n, k).

    q in the position range, dq in +/- max_velocity, ddq in +/- max_acceleration.
    """
    lo = np.array([lim.position[0] for lim in limits])
    hi = np.array([lim.position[1] for lim in limits])
    v = np.array([lim.max_velocity for lim in limits])
    a = np.array([lim.max_acceleration for lim in limits])
    return uniform_states(lo, hi, v, a, n, seed)


def base_columns(regressor: Regressor, limits: Sequence[JointLimits], *, n_samples: int = 200,
                 seed: int = 0, rtol: float = BASE_RTOL) -> np.ndarray:
    """Indices of the base (independent) regressor columns (Gautier 1991), by the robot
    model's one base-parameter rule (:func:`trajectories.robot.base.independent_columns`).

    The regressor is built at ``n_samples`` random states (:func:`random_states`); its
    unit-norm columns are decomposed by QR in their order and a column is kept when its
    ``|R_ii| > rtol * max |R_jj|``. With the columns in the robot model's standard order
    the kept set is structural (the seed only chooses the states) and is the set
    :func:`trajectories.robot.base.base_parameters` gives the fit.

    Returns
    -------
    ndarray of int, shape (r,), increasing
    """
    q, dq, ddq = random_states(limits, n_samples, seed)
    w = _call(regressor, q, dq, ddq)
    if not np.any(w):
        raise TrajectoryError("base_columns: the regressor is zero at random states")
    return independent_columns(w, rtol)[0]


def condition_number(w: np.ndarray, columns: np.ndarray) -> float:
    """2-norm condition number of ``w[:, columns]`` (ratio of extreme singular values).

    Returns inf when the selected columns are rank deficient (smallest singular value 0).
    """
    s = np.linalg.svd(np.asarray(w)[:, columns], compute_uv=False)
    return float(s[0] / s[-1]) if s[-1] > 0.0 else math.inf


def _call(regressor: Regressor, q, dq, ddq) -> np.ndarray:
    w = np.asarray(regressor(q, dq, ddq), dtype=np.float64)
    n, k = q.shape
    if w.ndim != 2 or w.shape[0] != n * k:
        raise TrajectoryError(f"regressor returned shape {w.shape}, expected ({n * k}, p)")
    return w


# --------------------------------------------------------------------------- quality
def quadrant_shares(dq: np.ndarray, tau: np.ndarray, limits: Sequence[JointLimits], *,
                    tau_rtol: float = TAU_RTOL) -> np.ndarray:
    """Per joint, share of moving samples in each quadrant of the (dq, tau_out) plane.

    Parameters
    ----------
    dq, tau : ndarray, shape (n, k)
        Velocity [rad/s] and output torque [N m].
    limits : sequence of JointLimits
        A sample is moving when |dq| > MOVING_FRACTION * max_velocity.
    tau_rtol : float
        |tau| <= tau_rtol * max|tau| of the joint counts as zero torque (rounding of a
        model without friction, e.g. a joint without gravity load cruising).

    Returns
    -------
    ndarray, shape (k, 4), in the order of ``QUADRANTS``; moving samples with zero torque
    count in no quadrant (rows sum to 1 minus their share).
    """
    dq = np.asarray(dq)
    tau = np.asarray(tau)
    vmax = np.array([lim.max_velocity for lim in limits])
    moving = np.abs(dq) > MOVING_FRACTION * vmax
    n_mov = np.maximum(moving.sum(axis=0), 1)
    pos, neg = dq > 0, dq < 0
    eps = tau_rtol * np.abs(tau).max(axis=0) if tau.size else 0.0
    tp, tn = tau > eps, tau < -eps
    masks = (pos & tp, neg & tp, neg & tn, pos & tn)
    return np.stack([(m & moving).sum(axis=0) / n_mov for m in masks], axis=1)


def zero_load_share(row: np.ndarray) -> float:
    """The share of a joint's moving samples at zero output torque: what its row of
    :func:`quadrant_shares` (the four quadrants) leaves to 1."""
    return max(0.0, 1.0 - float(np.sum(row)))


@dataclass(frozen=True)
class Quality:
    """Predicted excitation quality of a plan.

    Attributes
    ----------
    cond : float
        Condition number of the plan's regressor on the base columns.
    base_columns : ndarray of int
        Indices of the base columns (:func:`base_columns`).
    n_samples : int
        Plan samples the regressor was built on (every ``stride``-th sample).
    stride : int
    joint_names : tuple of str
    band_share : ndarray, shape (k, 3)
        Share of moving samples per velocity band (``BANDS``), all plan samples.
    quadrant_share : ndarray, shape (k, 4) or None
        Share of moving samples per quadrant (``QUADRANTS``) on the same samples as the
        regressor; None without an inverse-dynamics callable.
    """

    cond: float
    base_columns: np.ndarray
    n_samples: int
    stride: int
    joint_names: tuple[str, ...]
    band_share: np.ndarray
    quadrant_share: np.ndarray | None = None

    @property
    def rank(self) -> int:
        return int(self.base_columns.size)

    def format_table(self, bands: bool = True) -> str:
        """The table; ``bands=False`` leaves out the velocity bands (printed with the plan)."""
        lines = [f"excitation: condition number {self.cond:.4g} of the base regressor "
                 f"({self.rank} base columns, {self.n_samples} samples, every "
                 f"{self.stride}th)"]
        w = max(8, *(len(n) for n in self.joint_names))
        heads = [f"{100 * lo:.0f}-{100 * hi:.0f} % vmax"
                 for lo, hi in zip(BANDS[:-1], BANDS[1:], strict=True)]
        if bands:
            lines += ["", f"{'joint':<{w}} " + " ".join(f"{h:>14}" for h in heads)]
            for nm, row in zip(self.joint_names, self.band_share, strict=True):
                lines.append(f"{nm:<{w}} " + " ".join(f"{100 * x:>13.1f}%" for x in row))
        if self.quadrant_share is not None:
            lines += ["", "quadrants of (dq, tau_out): 1 and 3 motor, 2 and 4 generator",
                      f"{'joint':<{w}} " + " ".join(f"{h:>12}" for h in QUADRANTS)
                      + f" {'tau ~ 0':>12}"]
            for nm, row in zip(self.joint_names, self.quadrant_share, strict=True):
                lines.append(f"{nm:<{w}} " + " ".join(f"{100 * x:>11.1f}%" for x in row)
                             + f" {100 * zero_load_share(row):>11.1f}%")
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.format_table()


def quality(plan: RobotPlan, regressor: Regressor, *,
            inverse_dynamics: InverseDynamics | None = None,
            base: np.ndarray | None = None, max_samples: int = 4000, seed: int = 0,
            rtol: float = BASE_RTOL) -> Quality:
    """Predict the excitation quality of a plan.

    Parameters
    ----------
    plan : RobotPlan
    regressor : callable
        ``(q, dq, ddq) -> W (n * k, p)`` of the robot model (module docstring).
    inverse_dynamics : callable, optional
        ``(q, dq, ddq) -> tau_out (n, k)`` [N m] (with the payload of interest bound);
        gives the quadrant shares.
    base : ndarray of int, optional
        Base columns; default :func:`base_columns` with ``seed`` and ``rtol``.
    max_samples : int
        The regressor is built on every ``stride``-th sample, ``stride = ceil(n /
        max_samples)`` (memory: n * k * p floats).

    Returns
    -------
    Quality
    """
    if base is None:
        base = base_columns(regressor, plan.limits, seed=seed, rtol=rtol)
    stride = max(1, math.ceil(len(plan) / max_samples))
    q, dq, ddq = plan.q[::stride], plan.dq[::stride], plan.ddq[::stride]
    w = _call(regressor, q, dq, ddq)
    quad = None
    if inverse_dynamics is not None:
        tau = np.asarray(inverse_dynamics(q, dq, ddq), dtype=np.float64)
        if tau.shape != q.shape:
            raise TrajectoryError(f"inverse_dynamics returned shape {tau.shape}, expected "
                                  f"{q.shape}")
        quad = quadrant_shares(dq, tau, plan.limits)
    return Quality(cond=condition_number(w, base), base_columns=np.asarray(base),
                   n_samples=int(q.shape[0]), stride=stride, joint_names=plan.joint_names,
                   band_share=band_shares(plan.dq, plan.limits), quadrant_share=quad)


# --------------------------------------------------------------------------- optimisation
@dataclass(frozen=True)
class OptimisedMultisine:
    """Result of :func:`optimise_multisine`.

    Attributes
    ----------
    a, b : ndarray, shape (k, L)
        Optimised coefficients [rad/s], within every limit (ratio <= fill).
    q0 : ndarray, shape (k,)
    omega : float
        [rad/s].
    cond_start, cond_end : float
        Condition number of the base regressor at the start and at the end: over one period
        of the multi-sine, or, with a ``background``, over the whole plan.
    n_evaluations : int
        Objective evaluations (each builds the regressor on the period's grid).
    stopped : str
        Why it stopped: ``"converged"``, ``"max_evaluations"`` or ``"max_time"``.
    base_columns : ndarray of int
    """

    a: np.ndarray
    b: np.ndarray
    q0: np.ndarray
    omega: float
    cond_start: float
    cond_end: float
    n_evaluations: int
    stopped: str
    base_columns: np.ndarray


class _Stop(Exception):
    def __init__(self, why: str) -> None:
        self.why = why


def optimise_multisine(regressor: Regressor, limits: Sequence[JointLimits],
                       q0: Sequence[float], period_s: float, harmonics: int, *,
                       fill: float = 0.8, seed: int = 0, a0: np.ndarray | None = None,
                       b0: np.ndarray | None = None, rest: bool = True,
                       max_evaluations: int = 1500, max_time_s: float | None = None,
                       samples_per_period: int | None = None,
                       base: np.ndarray | None = None, periods: int = 1,
                       background: tuple[np.ndarray, float] | None = None
                       ) -> OptimisedMultisine:
    """Minimise the base-regressor condition number over a multi-sine's coefficients.

    The free variables are the 2 k L coefficients. Each evaluation maps them into the
    feasible set -- :func:`~trajectories.multi.rest_projection` when ``rest`` (the series
    starts and ends at rest, L >= 2), then each joint's row is shrunk until its tightest
    limit ratio is at most ``fill`` (:func:`~trajectories.multi.fit_coefficients`) -- so every
    iterate is within the position, velocity, acceleration and jerk limits, and minimises
    ``log10 cond(W[:, base])`` with W the regressor over one period sampled at
    ``samples_per_period`` points. scipy.optimize L-BFGS-B with finite-difference gradients
    from the seeded default coefficients (or ``a0, b0``); the best iterate is returned.

    Parameters
    ----------
    regressor : callable
        ``(q, dq, ddq) -> W (n * k, p)``.
    limits : sequence of JointLimits
    q0 : sequence of float
        Offsets [rad] (the centre of the motion).
    period_s : float
        Base period [s].
    harmonics : int
        L.
    fill : float
        In (0, 1]: bound on every limit ratio of the result.
    seed : int
        Seed of the start coefficients.
    max_evaluations : int
        Budget of objective evaluations (deterministic stop).
    max_time_s : float, optional
        Wall-clock budget; the result then depends on the machine's speed.
    samples_per_period : int, optional
        Default ``max(100, 20 L)``.
    base : ndarray of int, optional
        Base columns (default :func:`base_columns`, as :func:`quality`: the base
        columns of the robot model's rule, the ones the fit estimates).
    periods : int
        Periods the plan plays (weight of the multi-sine against ``background``).
    background : (ndarray, float), optional
        ``(W, seconds)``: regressor rows of the rest of the plan (all columns, sampled
        uniformly) and the time each row stands for [s]. The objective is then the condition
        number of the whole plan's regressor, computed from the time-weighted normal matrix
        ``W_bg' W_bg s_bg + W_ms' W_ms s_ms`` (cond = sqrt of its eigenvalue ratio), i.e.
        what :func:`quality` predicts for the plan with this multi-sine in it.

    Returns
    -------
    OptimisedMultisine
    """
    k = len(limits)
    q0 = np.asarray(q0, dtype=np.float64)
    omega = 2.0 * math.pi / period_s
    if base is None:  # seed 0 like quality(): the condition number depends on the choice
        base = base_columns(regressor, limits)
    if a0 is None or b0 is None:
        a0, b0 = default_coefficients(limits, q0, omega, harmonics, fill=fill, seed=seed)
    a0 = np.asarray(a0, dtype=np.float64)
    b0 = np.asarray(b0, dtype=np.float64)
    n_grid = samples_per_period or max(100, 20 * harmonics)
    tg = np.arange(n_grid, dtype=np.float64) * (period_s / n_grid)
    shape = (k, a0.shape[1])
    size = a0.size

    def feasible(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        a, b = x[:size].reshape(shape), x[size:].reshape(shape)
        if rest:
            a, b = rest_projection(a, b)
        return fit_coefficients(a, b, q0, omega, limits, fill, grow=False)

    gram_bg = None
    if background is not None:
        w_bg, sec_bg = background
        w_bg = np.asarray(w_bg, dtype=np.float64)[:, base]
        gram_bg = (w_bg.T @ w_bg) * sec_bg
    sec_ms = periods * period_s / n_grid

    def cond_of(a: np.ndarray, b: np.ndarray) -> float:
        q, dq, ddq, _ = fourier_eval(q0, a, b, omega, tg)
        w = _call(regressor, q, dq, ddq)
        if gram_bg is None:
            return condition_number(w, base)
        wb = w[:, base]
        ev = np.linalg.eigvalsh(gram_bg + (wb.T @ wb) * sec_ms)
        return float(math.sqrt(ev[-1] / ev[0])) if ev[0] > 0.0 else math.inf

    best = {"f": math.inf, "x": None, "n": 0}
    t_start = time.perf_counter()

    def objective(x: np.ndarray) -> float:
        if best["n"] >= max_evaluations:
            raise _Stop("max_evaluations")
        if max_time_s is not None and time.perf_counter() - t_start > max_time_s:
            raise _Stop("max_time")
        best["n"] += 1
        c = cond_of(*feasible(x))
        f = math.log10(c) if math.isfinite(c) else 300.0
        if f < best["f"]:
            best["f"], best["x"] = f, x.copy()
        return f

    x0 = np.concatenate([a0.ravel(), b0.ravel()])
    cond_start = cond_of(*feasible(x0))
    stopped = "converged"
    try:
        scipy.optimize.minimize(objective, x0, method="L-BFGS-B",
                                options={"maxiter": 10_000, "maxfun": 10**9})
    except _Stop as stop:
        stopped = stop.why
    x_best = best["x"] if best["x"] is not None else x0
    a, b = feasible(x_best)
    cond_end = cond_of(a, b)
    if cond_end > cond_start:  # never worse than the start
        a, b = feasible(x0)
        cond_end = cond_start
    ratio = multisine_ratio(a, b, q0, omega, limits)
    if np.any(ratio > 1.0):  # cannot happen: fit_coefficients bounds it by fill <= 1
        raise TrajectoryError(f"optimise_multisine: result beyond the limits ({ratio})")
    return OptimisedMultisine(a=a, b=b, q0=q0, omega=omega, cond_start=cond_start,
                              cond_end=cond_end, n_evaluations=best["n"], stopped=stopped,
                              base_columns=np.asarray(base))


def optimise_campaign(campaign: RobotCampaign, regressor: Regressor, *,
                      max_evaluations: int = 1500, max_time_s: float | None = None,
                      whole_plan: bool = False, max_samples: int = 4000
                      ) -> tuple[RobotCampaign, tuple[OptimisedMultisine, ...]]:
    """Optimise every multi-sine segment with ``optimise = true`` of a robot campaign.

    Each such segment starts from its own coefficients (given, or its seeded defaults) and
    is replaced by one with the optimised ``a`` and ``b``; other segments are unchanged.
    The objective is the condition number of the multi-sine alone, or with ``whole_plan``
    that of the whole plan (the other segments enter as ``background``, sampled like
    :func:`quality` with ``max_samples``; segments are optimised in order, each against the
    plan with the previous ones already optimised). Neither objective is better everywhere
    (UR10 3-dof standing in for examples/campaign_robot3.toml, 1500 evaluations, whole-plan
    condition number, measured on the base columns of a pivoted QR before the one base rule:
    full example 232 -> 117 with the multi-sine alone, -> 124 with the
    whole plan; base-yaw trapezoids + multi-sine 202 -> 89 and -> 72); the multi-sine alone
    is the default because it does not depend on the other segments.

    Returns
    -------
    campaign : RobotCampaign
        A new campaign (the input is frozen).
    results : tuple of OptimisedMultisine
        One per optimised segment, in segment order.
    """
    segments = list(campaign.segments)
    results = []
    base = None
    for i, seg in enumerate(segments):
        if not (isinstance(seg, MultisineSegment) and seg.optimise):
            continue
        q0, a0, b0 = _resolve_multisine(seg, campaign.limits, campaign.start)
        if base is None:
            base = base_columns(regressor, campaign.limits)
        background = None
        if whole_plan:
            # the current plan without this segment's Fourier samples (its blends stay)
            cur = plan_robot(segments, campaign.moving, campaign.limits, campaign.start,
                             campaign.cycle_s)
            (blk,) = [f for f in cur.fourier if f.segment == i]
            keep = (cur.t < blk.t0) | (cur.t >= blk.t0 + blk.duration_s)
            idx = np.flatnonzero(keep)
            stride = max(1, math.ceil(idx.size / max_samples))
            idx = idx[::stride]
            w_bg = _call(regressor, cur.q[idx], cur.dq[idx], cur.ddq[idx])
            background = (w_bg, stride * campaign.cycle_s)
        res = optimise_multisine(regressor, campaign.limits, q0, seg.period_s,
                                 a0.shape[1], fill=seg.fill, seed=seg.seed, a0=a0, b0=b0,
                                 rest=a0.shape[1] >= 2, max_evaluations=max_evaluations,
                                 max_time_s=max_time_s, base=base, periods=seg.periods,
                                 background=background)
        segments[i] = replace(seg, a=tuple(map(tuple, res.a.tolist())),
                              b=tuple(map(tuple, res.b.tolist())), center=tuple(q0.tolist()))
        results.append(res)
    return replace(campaign, segments=tuple(segments)), tuple(results)


# --------------------------------------------------------------------------- jointid plan
@dataclass(frozen=True, eq=False)
class Assessment:
    """Everything ``jointid plan`` prints for a robot campaign.

    Attributes
    ----------
    campaign : RobotCampaign
        The campaign planned (with optimised multi-sine coefficients when asked).
    plan : RobotPlan
    quality : Quality or None
        Without quadrant shares (those depend on the payload: ``quadrants``); None without
        a regressor.
    quadrants : tuple of ndarray, each (k, 4)
        Quadrant shares per payload run; empty without inverse dynamics.
    peak_torque : ndarray, shape (n_payloads, k), or None
        Peak |tau| per payload and joint [N m] (checked against ``max_torque``).
    optimised : tuple of OptimisedMultisine
    """

    campaign: RobotCampaign
    plan: RobotPlan
    quality: Quality | None
    quadrants: tuple[np.ndarray, ...]
    peak_torque: np.ndarray | None
    optimised: tuple[OptimisedMultisine, ...]

    def format_table(self) -> str:
        # the plan's summary: segments, peaks, bands and the peak torques per payload
        parts = [self.plan.summary().format_table()]
        names = self.plan.joint_names
        w = max(8, *(len(n) for n in names))
        for res in self.optimised:
            parts.append(f"\nmulti-sine optimised: condition number {res.cond_start:.4g} -> "
                         f"{res.cond_end:.4g} ({res.n_evaluations} evaluations, {res.stopped})")
        if self.quality is not None:
            parts.append("\n" + self.quality.format_table(bands=False))
        for pay, quad in zip(self.campaign.payloads, self.quadrants, strict=False):
            lines = ["", f"quadrants of (dq, tau_out), payload {pay.label}: 1 and 3 "
                     "motor, 2 and 4 generator",
                     f"{'joint':<{w}} " + " ".join(f"{h:>12}" for h in QUADRANTS)
                     + f" {'tau ~ 0':>12}"]
            for nm, row in zip(names, quad, strict=True):
                lines.append(f"{nm:<{w}} " + " ".join(f"{100 * x:>11.1f}%" for x in row)
                             + f" {100 * zero_load_share(row):>11.1f}%")
            parts.append("\n".join(lines))
        for name, share in self.zero_load_joints().items():
            parts.append(f"\nnote: {name}: {100 * share:.1f} % of its moving samples at zero "
                         f"output torque (no gravity on it, cruising): the paper model's "
                         f"quadrant is decided by noise there and its dry-friction terms come "
                         f"out biased; excite it with accelerated motion (sines, multi-sines) "
                         f"rather than slow cruises (docs/robot-identification.md)")
        return "\n".join(parts)

    def zero_load_joints(self, limit: float = ZERO_LOAD_SHARE) -> dict[str, float]:
        """Joints that move and whose share of moving samples at zero output torque exceeds
        ``limit`` in some payload run, with the largest share (``ZERO_LOAD_SHARE``)."""
        out: dict[str, float] = {}
        vmax = np.array([lim.max_velocity for lim in self.plan.limits])
        moves = np.any(np.abs(self.plan.dq) > MOVING_FRACTION * vmax, axis=0)
        for quad in self.quadrants:
            for name, row, moving in zip(self.plan.joint_names, quad, moves, strict=True):
                share = zero_load_share(row)
                if moving and share > limit:
                    out[name] = max(share, out.get(name, 0.0))
        return out

    def __str__(self) -> str:
        return self.format_table()


def assess_robot_campaign(campaign: RobotCampaign, *, regressor: Regressor | None = None,
                          inverse_dynamics: PayloadDynamics | None = None,
                          optimise: bool = False, max_evaluations: int = 1500,
                          max_time_s: float | None = None, max_samples: int = 4000,
                          tau_out: PayloadDynamics | None = None) -> Assessment:
    """Optimise (optionally), plan, check torques and predict the excitation quality.

    Parameters
    ----------
    campaign : RobotCampaign
    regressor : callable, optional
        ``(q, dq, ddq) -> W (n * k, p)``; needed for the condition number and ``optimise``.
    inverse_dynamics : callable, optional
        ``(q, dq, ddq, payload) -> tau (n, k)`` [N m]: torque check of every payload run
        and quadrant shares per payload.
    tau_out : callable, optional
        The output torque for the quadrant shares when ``inverse_dynamics`` includes more
        (a ``[joint]`` campaign's feed-forward model without its friction); default
        ``inverse_dynamics``.
    optimise : bool
        Optimise the ``optimise = true`` multi-sine segments first (:func:`optimise_campaign`).

    Raises
    ------
    trajectories.LimitError
        The plan (or a payload's torque) exceeds a joint limit.
    trajectories.TrajectoryError
        ``optimise`` without a regressor, or a callable returning the wrong shape.
    """
    results: tuple[OptimisedMultisine, ...] = ()
    if optimise:
        if regressor is None:
            raise TrajectoryError("optimising the multi-sines needs the robot's regressor")
        campaign, results = optimise_campaign(campaign, regressor,
                                              max_evaluations=max_evaluations,
                                              max_time_s=max_time_s)
    # the torques of every payload run checked (and their peaks kept) by the planner
    plan = plan_robot_campaign(campaign, inverse_dynamics=inverse_dynamics)
    peak = None
    quads: list[np.ndarray] = []
    stride = max(1, math.ceil(len(plan) / max_samples))
    if inverse_dynamics is not None:
        peak = np.array(plan.peak_torque, dtype=np.float64).reshape(len(campaign.payloads),
                                                                     plan.n_joints)
        q, dq, ddq = plan.q[::stride], plan.dq[::stride], plan.ddq[::stride]
        out = tau_out if tau_out is not None else inverse_dynamics
        for pay in campaign.payloads:
            tau = np.asarray(out(q, dq, ddq, pay), dtype=np.float64)
            quads.append(quadrant_shares(dq, tau, plan.limits))
    qual = None
    if regressor is not None:
        base = results[0].base_columns if results else None
        qual = quality(plan, regressor, base=base, max_samples=max_samples)
    return Assessment(campaign=campaign, plan=plan, quality=qual, quadrants=tuple(quads),
                      peak_torque=peak, optimised=results)
