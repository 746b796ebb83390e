"""IDIM estimators of an n-dof robot: :class:`RobotModel` (usual or paper friction on every

(Past 600 lines: one estimator class -- setup, the chunked data pass, the Gauss-Newton
solver on the moments, the statistics and prediction share its fitted state; the moments, the
paper's coefficients and the quadrant store are their own modules.)
joint; LS, WLS or IV), scikit-learn style.

Model (eq. 8-10 on every joint j, base parameters theta shared by all joints)::

    usual:  tau_j = W_j theta + p_j + FC_j sign(dq_j) + FV_j dq_j + OFF_j          (eq. 5, 8)
    paper:  eq. 30 with tau_out,j = W_j theta + p_j       (see :mod:`ident.robot.paper`)

The paper model is bilinear in (theta, per-joint a, b, c, d) by default; ``form="products"``
identifies instead eq. 42's free products per joint (a_m theta_i, b_m theta_i, ... as
independent linear parameters, no theta: the single-joint model on each joint, linear
least squares; :mod:`ident.robot.paper`, "Products form"), on the columns formed at full
rate when the signals carry them (:func:`ident.robot.design.products_columns`). With
``full_rate=True`` (opt-in), on the columns chain's signals the bilinear form too reads its
quadrant and E products formed at full rate, with its own load deciding the quadrants
(docs/refinement.md 8.9).

W_j is the joint's row of the base regressor (rigid body + rotor inertias, ``RobotRegressor``
reduced by ``BaseParameters.reduce``), p_j the known payload torque of the sample's experiment
(subtracted as the paper's eq. 34 does with the weighed mass).

Estimators (the sums are accumulated per chunk, :mod:`ident.robot.moments`, so memory does not
grow with the number of samples; iterations reuse the moments). They are the objects of
:mod:`ident.estimators` (``METHODS`` is its table): each Gauss-Newton step is the estimator's
``solve_normal`` (its rank rule), the covariance its ``normal_covariance``, the WLS weights its
``weights``:

* ``"ls"``  IDIM-LS, eq. 12; sigma^2 = ||rho||^2 / (r - b) (eq. 14), C = sigma^2 (W^T W)^-1
  (eq. 15; for the paper model W is the Jacobian at the solution).
* ``"wls"`` IDIM-WLS (Gautier's practice): sigma_j^2 = ||rho_j||^2 / (r_j - b_j) from a first
  LS fit, the rows of joint j scaled by 1/sigma_j, refitted; C = (sum_j W_j^T W_j / sigma_j^2)^-1
  times the weighted residual variance (~1).
* ``"iv"``  IDIM-IV (as :func:`ident.estimate.fit_instrumental`): instruments = the same
  columns with the measured acceleration replaced by the reference trajectory's
  (``RobotSignals.q_ref`` differentiated twice); chi = (Z^T W)^-1 Z^T Y,
  C = sigma^2 (Z^T W)^-1 Z^T Z (W^T Z)^-1. Needs ``q_ref``.

Samples with |dq_j| <= ``dq_min`` (the stiction area, eq. 26) or non-finite values are left
out of joint j's rows only; with ``RobotSignals.columns`` (the single-joint chain,
:mod:`ident.robot.design`) the decimated columns are read instead of evaluating the regressor,
and the rows their ``keep`` mask rejects are left out too. The Coulomb column is sign(dq)
formed at full rate and decimated with the torque when the signals carry it (the columns'
``sign``, else ``RobotSignals.sign``), else the sign of the decimated dq.

``payload_ratio=True``: p_j is one more column of every joint's row, its parameter
``Ma_ratio`` = M_ae / M_aw (eq. 35) identified after the base parameters.

``payload_params=True`` (mass known, CoM and inertia unknown): p_j is the torque of the
payload's mass alone at the flange origin, and the payload's other nine parameters (first
moments m c and inertia about the flange origin, flange frame, ``PAYLOAD_NAMES``) reduced by
:func:`ident.robot.base.payload_base` are more columns after the base parameters: the last
link's columns (``RobotRegressor.payload_columns``) on the rows of the experiments carrying
that payload, zero elsewhere. One set per distinct payload mass (suffix 1, 2, ... when there
are several); separable from the last link's own parameters only with experiments without a
payload; with one and the same payload in every experiment (``payload_merged_``) they merge
into the last link's base parameters instead (only the mass at the flange origin subtracted).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np
import scipy.linalg

from trajectories.friction import DEFAULT_Q_S, quadrant_weights, stribeck_exp

from .. import DataError
from ..estimate import DEFAULT_THRESHOLD_PCT
from ..estimators import (
    DEPENDENT_PREFIX,
    ESTIMATORS,
    PARTNER_TOL,
    RCOND,
    ZERO_COLUMN,
    Estimator,
    RankDeficientError,
    dependent_reason,
    rank_rule,
)
from ..hyperparams import HyperParameters
from ..quadrant_band import (  # the passes' one rule; the tolerances re-exported
    BAND_LEAVE,
    MAX_PASSES,
    band_out,
    never_redecided,
    unsettled_reason,
)
from ..quadrant_band import QUADRANT_TOL as QUADRANT_TOL
from ..quadrant_band import THETA_TOL as THETA_TOL
from ..vocab import renamed_keywords
from . import RobotIdentError
from .base import base_parameters, payload_base, placed_payload
from .moments import IDQ, IP, ISG, N_EXTRA, ONE, JointMoments, RowMoments
from .packed import PackedMoments
from .paper import (
    PAPER_BLOCK,
    USUAL_BLOCK,
    bilinear_rows_coefficients,
    paper_coefficients,
    paper_start,
    products_coefficients,
    products_names,
    products_size,
    products_start,
    require_theta,
    rows_coefficients,
    usual_coefficients,
)
from .quadrants import QuadrantStore
from .regressor import RobotRegressor
from .signals import ProductsTooLarge, RobotSignals
from .soft_fit import check_soft, fit_soft, predict_soft

__all__ = ["RobotModel", "MODELS", "METHODS", "FORMS"]

MODELS = ("usual", "paper")
#: Forms of the paper model: theta shared by the joints times per-joint (a, b) (bilinear), or
#: eq. 42's free products per joint (``form="products"``).
FORMS = ("bilinear", "products")
#: Name of the identified payload ratio M_ae / M_aw (eq. 35; ``payload_ratio=True``).
RATIO = "Ma_ratio"
#: The estimators (:data:`ident.estimators.ESTIMATORS`: "ls", "wls", "iv").
METHODS = tuple(ESTIMATORS)
#: Smallest eigenvalue / largest of the column-scaled normal matrix below which the
#: parameters are not identifiable on the data: the one rank rule of every estimator,
#: RCOND on the singular values of the scaled regressor, squared on its normal matrix.
RANK_TOL = RCOND**2

#: QUADRANT_TOL, THETA_TOL, BAND_LEAVE: the model-quadrant passes' one rule, from one joint to
#: n (:mod:`ident.quadrant_band`: the band's hysteresis, when the passes stop).

#: ``quadrant="model"`` on more samples than this: the starting fit reads every stride-th
#: row (stride = samples // START_ROWS); it only gives the first theta: the quadrants are then
#: re-decided on every row until fewer than QUADRANT_TOL of them change.
START_ROWS = 100_000

#: Rows kept per joint to re-decide the model quadrants without a pass
#: (:mod:`ident.robot.quadrants`): at most this fraction of the samples (and one chunk).
STORE_FRACTION = 0.05

#: sum_j ||W_j delta - p_j||^2 / sum_j ||p_j||^2 below this: the known torques lie in the span of
#: the base columns and do not fix the scale of theta against a, b (``_payload_fixes_scale``).
SCALE_TOL = 1e-9

#: A joint with fewer than this fraction of its rows in one quadrant is named as the likely
#: cause when the paper model is not identifiable.
THIN_QUADRANT = 0.02


#: Levenberg-Marquardt damping (relative to the column-scaled normal matrix) of the fits made
#: while the model quadrants are still being decided and leave a direction unexcited.
DAMPING = 1e-6

Coeffs = Callable[..., tuple[np.ndarray, ...]]  # (theta, blk, s, jacobian=True)


class _Unidentifiable(RobotIdentError):
    """The normal matrix is singular: ``names`` (zero columns or the weakest direction), the
    smallest and largest singular values of the column-scaled matrix; ``at`` and ``weights``
    the Gauss-Newton iterate and the joints' weights of the refused matrix (set by
    :meth:`RobotModel._gauss_newton`: the rank rule judges that matrix)."""

    def __init__(self, msg: str, names: list[str], lo: float, hi: float,
                 zero: bool = False) -> None:
        super().__init__(msg)
        self.names, self.lo, self.hi, self.zero = names, lo, hi, zero
        self.at: np.ndarray | None = None
        self.weights: np.ndarray | None = None


def renamed_reason(why: str, names: Mapping[str, str]) -> str:
    """``why`` (a ``removed_`` reason) with the partners of a dependent column renamed by
    ``names`` (others kept as they are); any other reason unchanged."""
    if not why.startswith(DEPENDENT_PREFIX):
        return why
    return dependent_reason([names.get(n, n) for n in why[len(DEPENDENT_PREFIX):].split(", ")])


def _near_dependent(Gs: np.ndarray, kept: np.ndarray,
                    first: int) -> tuple[dict[int, list[int]], float]:
    """Step 2 of :meth:`RobotModel._rank_fix`: the columns of the unit-diagonal Gram matrix
    ``Gs`` to leave out of ``kept`` (indices into ``Gs``) until the kept block passes the
    solver's test lambda_min > RANK_TOL lambda_max, each with its partners (indices into
    ``Gs``). A column is left out when it lies within RCOND sigma_max of the span of the
    other kept columns by the weakest eigenvector v (residual sqrt(lambda_min) / |v_i|),
    the one with the largest |v_i| of the columns ``>= first`` that qualify, else of all that
    qualify; none qualifies: stops (the solver's refusal stands). Empty when the block
    passes. The partners, as :func:`ident.estimators.rank_rule`'s: the kept columns whose
    coefficients in the left-out column's least-squares expression on them exceed
    PARTNER_TOL times the largest. Also returns lambda_max / lambda_min of the kept block
    before the first column left out (nan when none is)."""
    out: dict[int, list[int]] = {}
    cond = float("nan")
    kept = list(int(k) for k in kept)
    while len(kept) > 1:
        ev, vec = np.linalg.eigh(Gs[np.ix_(kept, kept)])
        lo, hi = float(ev[0]), float(ev[-1])
        if lo > RANK_TOL * hi:
            break
        v = np.abs(vec[:, 0])
        qualify = np.maximum(lo, 0.0) <= RANK_TOL * hi * v**2  # lo / v_i^2 <= RANK_TOL hi
        if not qualify.any():
            break
        if not out:
            cond = hi / lo if lo > 0 else float("inf")
        later = qualify & (np.array(kept) >= first)
        pool = later if later.any() else qualify
        i = int(np.argmax(np.where(pool, v, -np.inf)))
        out[kept[i]] = []
        del kept[i]
    if out and kept:  # partners as rank_rule's: the LS expression on the columns kept
        K = Gs[np.ix_(kept, kept)]
        for c in out:
            coef = np.abs(scipy.linalg.solve(K, Gs[kept, c], assume_a="sym"))
            big = coef > PARTNER_TOL * max(float(coef.max(initial=0.0)), 1e-300)
            out[c] = [kept[t] for t in np.flatnonzero(big)]
    return out, cond


def _ref_acceleration(t: np.ndarray, q_ref: np.ndarray) -> np.ndarray:
    """d^2 q_ref / dt^2 (n, k) by central differences (np.gradient twice)."""
    if t.size < 3:
        return np.zeros_like(q_ref)
    return np.gradient(np.gradient(q_ref, t, axis=0), t, axis=0)



class RobotModel(HyperParameters):
    """Identification of an n-dof robot with the usual or the paper friction (module doc).

    Parameters
    ----------
    regressor : RobotRegressor or Robot
        The rigid-body regressor (``.rigid``, ``.payload_torque``, ``.joints``, ``.numbers``);
        a ``trajectories.robot.Robot`` is wrapped in ``RobotRegressor``.
    model : {"usual", "paper"}
        Friction model on every joint (eq. 5 or eq. 30).
    method : {"ls", "wls", "iv"}
        Estimator (module doc).
    q_s : float, sequence or mapping
        q_s of E = exp(-|dq|/q_s) [rad/s] (eq. 29), one value, one per joint or by joint name.
    base : BaseParameters or None
        Base parameters (``.names``, ``.reduce``); default ``base_parameters(regressor)``.
    quadrant : {"model", "measured"}
        How P+/P- are decided (paper model): sign(tau_out_hat dq) -- from the usual fit's
        theta first, then the paper fit's, iterated --, or sign(tau dq) (eq. 26).
    quadrant_theta : array_like or None
        With ``quadrant="model"``: the theta (``names_[:n_theta]``, e.g. a CAD model's or a
        simulator's truth) that decides sign(tau_out dq) once and for all, instead of the fit's
        own; None (default): decided by the fit.
    dq_min : float
        Samples of joint j with |dq_j| <= dq_min are not used in its rows [rad/s].
    chunk_size : int
        Samples per chunk of the regressor evaluation (memory ~ chunk_size k p_std floats).
    max_iter, tol : int, float
        Gauss-Newton iterations and relative step tolerance (paper model).
    quadrant_band : float
        With ``quadrant="model"``: rows of joint j with |tau_out_hat| < quadrant_band x the
        RMS of the usual fit's tau_out_hat of joint j are left out of its rows (``band_``
        [N m]): their quadrant is uncertain, and a wrong one costs the jump c_m - c_g of the
        dry friction (eq. 30) -- the paper's stiction-area rectangle (Fig. 2.b) around
        P_out = 0; the band itself is this package's (the paper's quadrants are sign(P) on
        every row, eq. 26-28). With hysteresis over the passes: a row left out returns only
        where |tau_out_hat| reaches ``BAND_LEAVE`` (1.5) x ``band_`` (``band_from_``). 0:
        every row.
    max_passes : int
        Quadrant decisions at most (``quadrant="model"``): the usual fit's, then re-decisions
        with the paper fit's theta; they stop earlier, settled, once at most ``QUADRANT_TOL``
        of the rows moved -- changed quadrant, or entered or left the quadrant band (a row
        leaving the fit changes theta as a flip does; with a band rows cross it long before
        they flip) -- or once no parameter moved by ``THETA_TOL`` (0.1) of its sigma since the
        previous re-decision. Stopped at ``max_passes`` otherwise: ``converged_`` False (without
        the band's hysteresis rows near its edges cycled in and out on the 3-dof arm; with it 8
        of 10 of its fits settle on a fixed point, docs/robot-identification.md "Quadrants").
    payload_ratio : bool
        Identify the payload ratio M_ae / M_aw (``Ma_ratio``, eq. 35) instead of taking the
        payload torque as known; needs an experiment with a payload.
    form : {"bilinear", "products"}
        Paper model only. ``"bilinear"`` (default): theta shared by every joint times the
        per-joint a, b (p_b + 10 k parameters, Gauss-Newton). ``"products"``: eq. 42's
        products free per joint, sum_j (4 (p_j + 1) + 6) parameters named after the
        single-joint ones with the joint number (``a_m_ZZ3R_3``, ``b_m_MX3_3``, ...,
        ``a_m3`` ... for the payload torque, ``c_m3`` ... ``OFF3``;
        :func:`~ident.robot.paper.products_names`), one linear least squares (one step);
        on a one-joint robot the single-joint paper model. No base parameters are
        identified (``load_torque``, the consistency check, the uncertainty assessment and
        the refit refuse it). With ``quadrant="model"`` the quadrants are decided ONCE, by
        the usual fit's theta on every row (or ``quadrant_theta``): there is no theta of its
        own to re-decide them with (the single-joint fit decides them by its first usual
        fit too). The products of a load column that is zero on a joint's rows (no payload
        torque) or a combination of its other columns there (the single-joint rank rule)
        are fixed at 0 (``fixed_``); ``payload_ratio`` is refused (the payload's products
        are free already). On signals carrying the products formed at full rate
        (``RobotColumns.products``, :func:`ident.robot.design.products_columns`: the
        single-joint chain's columns) it reads those rows whole instead
        (``full_rate_products_``): their quadrants are the load model's they were formed
        with, so ``quadrant="measured"``, ``quadrant_theta``, ``method="iv"`` without their
        instruments (``products_columns(instruments=True)``) and ``payload_params`` are
        refused, ``quadrant_band`` does not apply (``band_`` 0) and :meth:`predict` needs
        signals carrying them.
    payload_params : bool
        The payload's mass known, its first moments and inertia identified (module doc;
        ``payload_base_``, ``payload_masses_``); needs experiments without a payload to
        separate them from the last link's parameters. When every experiment carries one
        and the same payload (``payload_merged_``), only its mass at the flange origin is
        subtracted and its first moments and inertia merge into the last link's base
        parameters (no payload columns).
    eliminate : bool
        The linear forms only (``model="usual"``, or ``"paper"`` with ``form="products"``):
        the single-joint elimination of :func:`ident.estimate.fit_least_squares` -- the
        parameters whose columns are zero or dependent (the rank rule, before the first
        solve, base parameters pivoted first: a payload's ratio or products go before the
        parameters they combine; the reason names the partners) are fixed at 0, then,
        while the largest relative deviation (eq. 16) of a free parameter exceeds
        ``threshold_pct``, that parameter is fixed at 0 and the model refitted (``fixed_``,
        ``removed_``); ``threshold_pct=inf``: the rank rule alone. Default False: nothing is
        eliminated (dependent columns are an error naming the weakest direction).
    threshold_pct : float
        Relative-deviation threshold [%] of ``eliminate``
        (:data:`ident.estimate.DEFAULT_THRESHOLD_PCT`).
    quadrants : {"hard", "soft"}
        Paper model, bilinear form only. ``"hard"`` (default): each row in one quadrant
        (eq. 27-28). ``"soft"``: after the hard fit, theta, every joint's paper parameters
        and a load jitter RMS sigma_j per joint [N m] are fitted together with each row's
        quadrant weights replaced by their expectation under that jitter
        (:mod:`ident.robot.soft_fit`; every usable row, no quadrant band); sigma_j bounded
        by a fraction of the RMS of the model's own load (``quadrant_sigma_bounds_``).
        Standard deviations analytic only (eq. 15 at the solution): no block jackknife, no
        IDIM-IV check and no pruning (:func:`ident.robot.uncertainty.assess`).
    full_rate : bool
        The bilinear paper model with model quadrants on the columns chain's signals
        (``RobotColumns.source``, :func:`ident.robot.design.design_runs`): its quadrant and E
        products P_s E^e w are formed at FULL rate -- P_s from the model's own full-rate
        load W theta + p (the usual fit's theta first, then the paper fit's at each
        re-decision), E at q_s, fixed during a solve -- and then low-passed and decimated
        like the torque (:func:`ident.robot.design.products_columns`), and the fit reads
        those rows whole (:func:`~ident.robot.paper.bilinear_rows_coefficients`): the
        measured torque is the decimation of the full-rate product, not the product of the
        decimated factors (docs/refinement.md section 8.9). Default False (opt-in: on the
        simulated arm it removes the drag's bias at the true q_s, but the KUKA's fit of the
        README no longer converges with it, and each quadrant pass forms the products
        again; docs/refinement.md 8.9); ``full_rate_paper_`` says whether it applied. The
        quadrant band then applies at full rate, decided once by the usual fit's load (a
        row whose full-rate sample's load is within ``band_`` is left out; no hysteresis:
        the band does not move). Not with
        ``payload_ratio``, ``payload_params``, ``quadrants="soft"``, ``quadrant="measured"``,
        a base without standard columns, signals without ``columns.source`` (the states
        chain) nor IDIM-IV without the instruments: there, and where a run's full-rate rows
        exceed :data:`ident.robot.design.MAX_BYTES` (one warning), the decimated columns'
        P and E as before. :meth:`predict` and the n-dof refit read the products too, formed
        again from the signals' source (the decimated rows on signals without one).
    **deprecated
        ``qs=``: the older spelling of ``q_s`` (accepted with a DeprecationWarning,
        :mod:`ident.vocab`).

    Attributes (after :meth:`fit`)
    ------------------------------
    names_ : tuple of str
        Parameter names: base parameters, then per joint FC/FV/OFF (usual) or
        a_m..OFF (paper), suffixed with the joint's number; ``form="products"``: per joint
        its products block only (``form`` above).
    theta_names_ : tuple of str
        Names of theta's entries (base parameters, ``Ma_ratio``, payload parameters): the
        first entries of ``names_`` except in the products form.
    coef_, std_ : ndarray (b,)
        Estimate and standard deviations (eq. 15).
    rel_std_ : ndarray (b,)
        100 std / |coef| [%] (eq. 16).
    params_ : dict
        name -> value.
    cov_ : ndarray (b, b)
    sigma_ : float
        Residual standard deviation (eq. 14; weighted for WLS).
    sigma_joint_ : ndarray (k,)
        Per-joint residual standard deviations [N m].
    rel_error_ : dict
        ``{joint name: ||rho_j||/||tau_j||, ..., "all": ||rho||/||tau||}`` on the fit data.
    n_samples_ : ndarray (k,)
        Rows used per joint.
    fixed_ : dict
        Parameters held fixed (paper model without payload torque; products form: the
        products of a joint's load columns that are zero or dependent on its rows, at 0).
    removed_ : list of (str, str)
        Parameters fixed at 0 and why: the products form's zero or dependent load columns,
        and with ``eliminate`` the zero, dependent and non-significant parameters in the
        order they were removed (the reasons of :func:`ident.estimate.fit_least_squares`).
    cond_, cond_raw_ : float
        Condition numbers of the column-scaled and of the raw regressor (the Jacobian at
        the solution for the bilinear form) of the free parameters, from its Gram matrix
        (as ``LSResult.cond`` and ``cond_raw``).
    n_passes_, n_iter_ : int
        Data passes (the start pass counted as one, even on every ``start_stride_``-th row)
        and Gauss-Newton iterations of the final fit.
    converged_ : bool
        False when the paper model's final Gauss-Newton stopped at ``max_iter`` instead of
        its step tolerance (the parameters still moving; see :meth:`quadrant_drift`), or its
        quadrant passes at ``max_passes`` before they settled (``max_passes`` above).
    convergence_ : str
        Why ``converged_`` is False, one line naming the cap reached and the figures (rows
        still moving, the last step in sigma); "" when it is True.
    start_stride_ : int
        Rows read by the start pass: every start_stride_-th (``START_ROWS``).
    n_store_updates_ : int
        Quadrant re-decisions made on the stored near-boundary rows instead of a pass
        (:mod:`ident.robot.quadrants`).
    quadrant_changes_ : list of int
        Rows that moved at each re-decision (``quadrant="model"``): into another quadrant, or
        into or out of the quadrant band.
    quadrant_steps_ : list of float
        At each re-decision, the largest change of a parameter of the paper fit since the
        previous one, in its standard deviation (eq. 15; inf while a direction is unexcited).
    band_share_ : ndarray (k,)
        Share of each joint's rows (after ``dq_min`` and the columns' ``keep``) left out by
        the quadrant band at the last full pass (0 without a band). Large on a joint that
        cruises at zero load, where the quadrant is decided by noise
        (docs/robot-identification.md, "quadrants blended by the low-pass").
    full_rate_products_ : bool
        The products form read the products formed at full rate (``form`` above).
    full_rate_paper_ : bool
        The bilinear paper model read its products formed at full rate (``full_rate``).
    quadrant_sigma_, quadrant_sigma_std_ : ndarray (k,)
        ``quadrants="soft"``: the fitted load jitter RMS per joint [N m] and its std (NaN
        where it sits on a bound: not identified, ``quadrant_sigma_at_bound_``);
        ``quadrant_sigma_bounds_`` (k, 2) its bounds [N m].
    band_from_ : ndarray (m, p_b) or None
        The thetas that decided the quadrant passes, in order (the usual fit's first), whose
        loads decide with the band's hysteresis which rows the band leaves out
        (:meth:`fitted_rows`); None without a band.
    quadrant_from_ : ndarray or None
        The theta whose sign(tau_out_hat dq) decided the final quadrants (``quadrant="model"``
        of the paper model), else None: :mod:`ident.robot.uncertainty` rebuilds the moments of
        parts of the data on the same quadrants; the products form's :meth:`predict` decides
        with it.
    """

    def __init__(
        self,
        regressor: Any,
        model: str = "usual",
        method: str = "ls",
        *,
        q_s: float | Sequence[float] | Mapping[str, float] = DEFAULT_Q_S,
        base: Any = None,
        quadrant: str = "model",
        dq_min: float = 0.0,
        chunk_size: int = 20000,
        max_iter: int = 50,
        tol: float = 1e-10,
        max_passes: int = MAX_PASSES,
        payload_ratio: bool = False,
        quadrant_theta: Any = None,
        quadrant_band: float = 0.03,
        payload_params: bool = False,
        form: str = "bilinear",
        eliminate: bool = False,
        threshold_pct: float = DEFAULT_THRESHOLD_PCT,
        quadrants: str = "hard",
        full_rate: bool = False,
        **deprecated: Any,
    ) -> None:
        q_s = renamed_keywords("RobotModel", deprecated).get("q_s", q_s)
        self.regressor = regressor
        self.model = model
        self.method = method
        self.q_s = q_s
        self.base = base
        self.quadrant = quadrant
        self.dq_min = dq_min
        self.chunk_size = chunk_size
        self.max_iter = max_iter
        self.tol = tol
        self.max_passes = max_passes
        self.payload_ratio = payload_ratio
        self.quadrant_theta = quadrant_theta
        self.quadrant_band = quadrant_band
        self.payload_params = payload_params
        self.form = form
        self.eliminate = eliminate
        self.threshold_pct = threshold_pct
        self.quadrants = quadrants
        self.full_rate = full_rate

    def get_params(self, deep: bool = False) -> dict[str, Any]:
        """Hyper-parameters (scikit-learn convention; ``set_params`` sets them by name,
        :class:`~ident.hyperparams.HyperParameters`)."""
        return {n: getattr(self, n) for n in (
            "regressor", "model", "method", "q_s", "base", "quadrant", "dq_min", "chunk_size",
            "max_iter", "tol", "max_passes", "payload_ratio", "quadrant_theta",
            "quadrant_band", "payload_params", "form", "eliminate", "threshold_pct",
            "quadrants", "full_rate")}

    def __repr__(self) -> str:
        form = "" if self.form == "bilinear" else f", form={self.form!r}"
        return (f"RobotModel(model={self.model!r}, method={self.method!r}, "
                f"q_s={self.q_s!r}{form})")

    # ------------------------------------------------------------------ setup
    def _setup(self) -> None:
        if self.model not in MODELS:
            raise RobotIdentError(f"RobotModel.model: expected one of {MODELS}, got "
                                  f"{self.model!r}")
        if self.method not in METHODS:
            raise RobotIdentError(f"RobotModel.method: expected one of {METHODS}, got "
                                  f"{self.method!r}")
        if self.form not in FORMS:
            raise RobotIdentError(f"RobotModel.form: expected one of {FORMS}, got "
                                  f"{self.form!r}")
        if self.form == "products" and self.model != "paper":
            raise RobotIdentError(f"RobotModel.form: 'products' is a form of the paper model "
                                  f"(model='paper'), got model={self.model!r}")
        if self.form == "products" and self.payload_ratio:
            raise RobotIdentError("RobotModel.payload_ratio: form='products' identifies the "
                                  "payload torque's products (a_m{j} = a_m M_ae/M_aw, eq. 42) "
                                  "freely, so there is no ratio to identify; use "
                                  "payload_ratio=False")
        if self.eliminate and self.model == "paper" and self.form != "products":
            raise RobotIdentError("RobotModel.eliminate: the elimination of non-significant "
                                  "parameters applies to the linear forms (model='usual', "
                                  "or model='paper' with form='products'), not to the "
                                  "bilinear paper model")
        if not float(self.threshold_pct) > 0:
            raise RobotIdentError(f"RobotModel.threshold_pct: expected a relative deviation "
                                  f"> 0 [%], got {self.threshold_pct!r}")
        if self.quadrant not in ("model", "measured"):
            raise RobotIdentError(f"RobotModel.quadrant: expected 'model' or 'measured', got "
                                  f"{self.quadrant!r}")
        check_soft(self)
        if int(self.chunk_size) < 1:
            raise RobotIdentError(f"RobotModel.chunk_size: expected >= 1, got "
                                  f"{self.chunk_size!r}")
        reg = self.regressor
        if not hasattr(reg, "rigid"):
            reg = RobotRegressor(reg)
        self.regressor_ = reg
        base = self.base
        if base is None:
            base = base_parameters(reg)
        self.base_ = base
        joints = tuple(reg.joints)
        k = len(joints)
        q_s = self.q_s
        if isinstance(q_s, Mapping):
            missing = [j for j in joints if j not in q_s]
            if missing:
                raise RobotIdentError(f"RobotModel.q_s: no value for joint(s) {missing}")
            q_s = [q_s[j] for j in joints]
        qs_arr = np.broadcast_to(np.asarray(q_s, dtype=float), (k,)).copy()
        if not np.all(np.isfinite(qs_arr) & (qs_arr > 0)):
            raise RobotIdentError(f"RobotModel.q_s: expected positive velocities [rad/s], got "
                                  f"{qs_arr}")
        self.q_s_ = qs_arr
        self.joints_ = joints
        self.numbers_ = tuple(int(n) for n in reg.numbers)
        self._pay_cols = None
        self.cols_ = self._structure()
        self._placed: dict[tuple[float, float], Any] = {}  # lever-arm payloads, placed
        self.n_base_ = len(tuple(base.names))
        ratio = bool(self.payload_ratio)
        # theta = base parameters, then the payload ratio when it is identified: the known
        # payload torque p_j is then one more column of every joint's row (eq. 35)
        self.n_theta_ = self.n_base_ + int(ratio)
        if ratio:
            self.cols_ = [np.append(c, self.n_base_) for c in self.cols_]
        pay_names: tuple[str, ...] = ()
        if self.payload_params:
            pay_names = self._setup_payload(reg)
        block = USUAL_BLOCK if self.model == "usual" else PAPER_BLOCK
        self.block_ = block
        self.theta_names_ = tuple(base.names) + (RATIO,) * ratio + pay_names
        self.names_ = self.theta_names_ + tuple(
            f"{p}{n}" for n in self.numbers_ for p in block)
        self._layout(self.form == "products")
        self._damp = 0.0
        self._band_h = np.zeros(k)
        self.band_from_: np.ndarray | None = None
        if not (np.isfinite(float(self.quadrant_band)) and float(self.quadrant_band) >= 0):
            raise RobotIdentError(f"RobotModel.quadrant_band: expected a fraction >= 0, got "
                                  f"{self.quadrant_band!r}")
        self.quadrant_theta_ = None
        if self.quadrant_theta is not None:
            qt = np.asarray(self.quadrant_theta, dtype=float).ravel()
            if qt.size != self.n_theta_ or not np.all(np.isfinite(qt)):
                raise RobotIdentError(f"RobotModel.quadrant_theta: expected {self.n_theta_} "
                                      f"finite values (the base parameters"
                                      f"{' and ' + RATIO if ratio else ''}), got {qt.size}")
            if self.quadrant != "model":
                raise RobotIdentError("RobotModel.quadrant_theta: needs quadrant='model'")
            self.quadrant_theta_ = qt

    def _layout(self, products: bool) -> None:
        """The parameter vector's layout: theta (``n_theta_``) then one block of
        ``len(block_)`` per joint; or, ``products``, no theta and per joint its products
        block (:func:`~ident.robot.paper.products_names`: its size depends on the joint's
        base columns), ``names_`` set accordingly."""
        k = len(self.cols_)
        if products:
            sizes = np.array([products_size(len(c)) for c in self.cols_])
            self._theta_x = False
            self.names_ = tuple(n for c, num in zip(self.cols_, self.numbers_, strict=True)
                                for n in products_names([self.theta_names_[i] for i in c],
                                                        num))
        else:
            sizes = np.full(k, len(self.block_))
            self._theta_x = True
        self._bsize = sizes
        self._bstart = np.r_[0, np.cumsum(sizes)[:-1]].astype(int)

    def _nt(self, j: int) -> int:
        """Entries of joint j's local parameters (:meth:`_local`) that are theta."""
        return len(self.cols_[j]) if self._theta_x else 0

    def _setup_payload(self, reg: Any) -> tuple[str, ...]:
        """``payload_params``: the payload's base columns after the base parameters, one set
        per distinct mass of ``payload_masses_`` (set by :meth:`fit`); returns their names."""
        if self.payload_ratio:
            raise RobotIdentError("RobotModel: payload_ratio and payload_params exclude each "
                                  "other (a ratio of a known payload torque, or its unknown "
                                  "CoM and inertia)")
        if not hasattr(reg, "payload_columns"):
            raise RobotIdentError(f"RobotModel.payload_params: the regressor "
                                  f"{type(reg).__name__} has no payload_columns")
        self.payload_base_ = payload_base(reg)
        masses = tuple(getattr(self, "payload_masses_", ()))
        r = len(self.payload_base_.names)
        g = 0 if getattr(self, "payload_merged_", False) else len(masses)
        self.n_theta_ = self.n_base_ + g * r
        # rows of the regressor block _rows appends: after the standard (or base) columns
        width = len(reg.standard_names) if self._kpn else self.n_base_
        self._pay_cols = width + np.arange(g * r)
        extra = self.n_base_ + np.arange(g * r)
        self.cols_ = [np.append(c, extra) for c in self.cols_]
        self.std_cols_ = [np.append(c, self._pay_cols) for c in self.std_cols_]
        return tuple(f"{n}{i + 1 if g > 1 else ''}" for i in range(g)
                     for n in self.payload_base_.names)

    def _payload_block(self, W: np.ndarray, q, dq, ddq, pay, std: np.ndarray | None
                       ) -> tuple[np.ndarray, np.ndarray]:
        """``payload_params``: W (k, P, m) with the payload's base columns of the chunk's
        payload group appended (zero for the other groups), and the known torque of its
        mass alone (m, k). ``std``: the standard regressor (k, p, m) when at hand."""
        reg, pbase = self.regressor_, self.payload_base_
        mass = float(getattr(pay, "mass", 0.0)) if pay is not None else 0.0
        m = W.shape[2]
        block = np.zeros((W.shape[0], self._pay_cols.size, m))
        p = np.zeros((m, W.shape[0]))
        if mass > 0:
            Y = reg.payload_columns(q, dq, ddq, W=std)  # (k, 10, m)
            p = mass * Y[:, 9, :].T
            if mass not in self.payload_masses_:
                raise RobotIdentError(f"payload of {mass} kg: not one of the fitted "
                                      f"payloads {list(self.payload_masses_)} kg")
            r = len(pbase.names)
            g = self.payload_masses_.index(mass)
            if block.shape[1]:  # (none when the payload is merged into the last link)
                block[:, g * r:(g + 1) * r, :] = Y[:, pbase.columns, :]
        return np.concatenate([W, block], axis=1), p

    def _structure(self) -> list[np.ndarray]:
        """Base columns that are not structurally zero in each joint's row (probed at random
        states, seeded)."""
        k = len(self.regressor_.joints)
        rng = np.random.default_rng(12345)
        m = 32
        q = rng.uniform(-np.pi, np.pi, (m, k))
        self._kpn = False
        W, _, _ = self._rows(q, rng.normal(size=(m, k)), rng.normal(size=(m, k)), None, None)
        mag = np.abs(W).max(axis=2)  # (k, pb)
        tol = 1e-10 * max(float(mag.max()), 1e-300)
        cols = [np.flatnonzero(mag[j] > tol) for j in range(k)]
        # gather each joint's base columns straight from the standard (k, p, m) regressor
        self._kpn = hasattr(self.regressor_, "rigid_kpn") and hasattr(self.base_, "columns")
        base_cols = np.asarray(self.base_.columns) if self._kpn else None
        self.std_cols_ = [base_cols[c] if self._kpn else c for c in cols]
        return cols

    # ------------------------------------------------------------------ data pass
    def _chunks(self, signals: Any, stride: int = 1, iv: bool | None = None):
        """Yield (sig, rows, q, dq, ddq, tau, ddq_ref or None, payload, columns or None) per
        chunk; every ``stride``-th row of each experiment only when ``stride`` > 1.
        ``columns``: the chunk's (W, p, sign, keep, Wz, pz, products) of
        ``RobotSignals.columns`` (products: its ``FullRateProducts`` of the chunk, or None).
        ``iv``: whether the instruments are needed (default: ``method == "iv"``)."""
        iv = self.method == "iv" if iv is None else iv
        items = [signals] if isinstance(signals, RobotSignals) else list(signals)
        if not items:
            raise RobotIdentError("RobotModel.fit: no signals")
        for sig in items:
            if not isinstance(sig, RobotSignals):
                raise RobotIdentError(f"RobotModel: expected RobotSignals, got "
                                      f"{type(sig).__name__}")
            if tuple(sig.joints) != self.joints_:
                raise RobotIdentError(f"{sig.source or 'RobotSignals'}: joints {sig.joints}, "
                                      f"expected the regressor's {self.joints_}")
            given = sig.columns
            if given is not None and iv and given.Wz is None:
                raise RobotIdentError(f"{sig.source or 'RobotSignals'}: method 'iv' needs "
                                      "the instruments' columns (design_runs(..., "
                                      "instruments=True))")
            for e in np.unique(sig.experiment):
                rows = np.flatnonzero(sig.experiment == e)
                zr = None
                if iv and given is None:
                    if sig.q_ref is None:
                        raise RobotIdentError(f"{sig.source or 'RobotSignals'}: method 'iv' "
                                              f"needs q_ref (reference trajectory)")
                    zr = _ref_acceleration(sig.t[rows], sig.q_ref[rows])[::stride]
                rows = rows[::stride]
                pay = sig.payloads[int(e)]
                if given is None and not self.payload_params:
                    # (columns carry the payload torque already)
                    pay = placed_payload(pay, self.regressor_, self.base_,
                                         sig.source or "RobotSignals", self._placed)
                contiguous = rows.size and rows[-1] - rows[0] + 1 == rows.size
                for a in range(0, rows.size, int(self.chunk_size)):
                    if contiguous:  # views, no copies
                        r = slice(int(rows[0]) + a, int(rows[0]) + min(a + int(self.chunk_size),
                                                                       rows.size))
                    else:
                        r = rows[a:a + int(self.chunk_size)]
                    cc = None
                    if given is not None:
                        cc = (given.W[:, :, r], given.p[r], given.sign[r], given.keep[r],
                              None if given.Wz is None else given.Wz[:, :, r],
                              None if given.pz is None else given.pz[r],
                              None if given.products is None else given.products.take(r))
                    yield (sig, r, sig.q[r], sig.dq[r], sig.ddq[r], sig.tau[r],
                           None if zr is None else zr[a:a + int(self.chunk_size)], pay, cc)

    def _rows(self, q, dq, ddq, tau, pay, given=None) -> tuple:
        """Regressor (k, p or pb, m) -- row j's base columns are ``W[j, std_cols_[j]]`` --
        the payload torque (m, k) and, with ``RobotRegressor(known_rotor_inertia=True)``, the
        known rotors' torque Ia_j ddq_j (m, k), else None, of a chunk (see :meth:`_joint`).
        ``given``: the standard regressor (k, p, m) and payload torque (m, k) already built
        (``RobotSignals.columns``) instead of evaluated on (q, dq, ddq)."""
        reg = self.regressor_
        std = None
        if given is not None:
            W, p = given
            std = W
            if not self._kpn:
                W = np.asarray(self.base_.reduce(np.transpose(W, (2, 0, 1))), dtype=float)
                W = np.ascontiguousarray(W.transpose(1, 2, 0))
        elif self._kpn:  # standard columns, (k, p, m): joint j reads W[j, self.std_cols_[j]]
            W = np.asarray(reg.rigid_kpn(q, dq, ddq))
            std = W
        else:
            W = np.asarray(self.base_.reduce(reg.rigid(q, dq, ddq)), dtype=float)
            W = np.ascontiguousarray(W.transpose(1, 2, 0))
        if given is not None:
            p = np.asarray(p, dtype=float)
        elif pay is not None and float(getattr(pay, "mass", 0.0)) > 0:
            p = np.asarray(reg.payload_torque(q, dq, ddq, pay), dtype=float)
        else:
            p = np.zeros(q.shape)
        if self._pay_cols is not None:  # payload_params: its mass known, the rest columns
            W, p = self._payload_block(W, q, dq, ddq, pay, std)
        known = getattr(reg, "known_Ia", None)
        kn = None
        if known is not None and np.any(known) and (given is None or (
                self.payload_ratio and ddq is not None)):
            # known rotor inertias (RobotRegressor). The columns chain carries them in p:
            # with payload_ratio they are taken out of it (p is then the ratio's column, the
            # payload's torque alone). The chain's decimated ddq went through the same linear
            # filter as p, so Ia_j ddq_j is p's rotor part (to rounding). (IDIM-IV on the
            # columns: no decimated reference acceleration; the instruments' ratio column
            # keeps the rotors' torque of the reference, still an instrument: without it
            # the fit moves by at most 0.19 sigma, seeds 0-9, tests/test_robot_ratio_rotor.py)
            kn = reg.known_torque(ddq)
            if given is not None:
                p = p - kn
        return W, p, kn

    def _joint(self, W: np.ndarray, p: np.ndarray, kn: np.ndarray | None,
               j: int) -> tuple[np.ndarray, np.ndarray]:
        """Joint j's theta columns (nt, m) and known torque (m,) of a chunk from
        :meth:`_rows`: its base columns and the payload torque plus the known rotors' torque;
        with ``payload_ratio`` the payload torque is the ratio's column instead."""
        WjT = W[j, self.std_cols_[j], :]
        if self.payload_ratio:
            WjT = np.concatenate([WjT, p[None, :, j]], axis=0)
            return WjT, (np.zeros(p.shape[0]) if kn is None else kn[:, j])
        return WjT, (p[:, j] if kn is None else p[:, j] + kn[:, j])

    @staticmethod
    def _v(WjT: np.ndarray, pj, dqj, tauj, sg=None) -> np.ndarray:
        """Rows v (module doc of :mod:`ident.robot.moments`) transposed, (nv, m); ``sg``: the
        Coulomb column when given (decimated sign(dq)), else sign(dq_j)."""
        nt, m = WjT.shape
        VT = np.empty((nt + N_EXTRA, m))
        VT[:nt] = WjT
        VT[nt + IP] = pj
        VT[nt + ISG] = np.sign(dqj) if sg is None else sg
        VT[nt + IDQ] = dqj
        VT[nt + ONE] = 1.0
        VT[-1] = tauj
        return VT

    def _pass(self, signals: Any, theta: np.ndarray | None, powers: int,
              theta_prev: np.ndarray | None = None, capacity: int = 0,
              gram_from: list[JointMoments] | None = None, stride: int = 1,
              ) -> tuple[list[JointMoments], int, int, list[QuadrantStore] | None]:
        """One pass: the moments of every joint; quadrants from ``theta`` (model) or tau.

        Returns the moments, the number of rows, how many rows moved with respect to
        ``theta_prev`` -- into another quadrant, or into or out of the quadrant band (counted
        on the fly: nothing of size n is kept) --, and with
        ``theta`` and ``capacity`` > 0 the per-joint :class:`QuadrantStore` of the rows
        nearest to their quadrant boundary (:mod:`ident.robot.quadrants`), in the metric of
        the base columns' Gram matrices of ``gram_from`` (moments of the same rows).
        ``stride`` > 1: every stride-th row only (the start of ``quadrant="model"``)."""
        iv = self.method == "iv"
        moms = [JointMoments(c, iv=iv, powers=powers) for c in self.cols_]
        stores = None
        if theta is not None and capacity > 0:
            grams = [None] * len(self.cols_) if gram_from is None else [
                (m.vv[0, 0, :len(c), :len(c)] + m.vv[1, 0, :len(c), :len(c)]) / max(m.n, 1)
                for m, c in zip(gram_from, self.cols_, strict=True)]
            stores = [QuadrantStore(theta[c], capacity, g, h, BAND_LEAVE) for c, g, h in
                      zip(self.cols_, grams, self._band_h, strict=True)]
        rows = changed = 0
        in_band, considered = np.zeros(len(self.cols_)), np.zeros(len(self.cols_))
        for sig, r, q, dq, ddq, tau, zdd, pay, cc in self._chunks(signals, stride):
            sgn = self._sign(sig, r, cc)
            W, p, kn = self._rows(q, dq, ddq, tau, pay, None if cc is None else cc[:2])
            Wz = pz = knz = None
            if iv:
                Wz, pz, knz = self._rows(q, dq, zdd, tau, pay, None if cc is None else cc[4:6])
            for j, cols in enumerate(self.cols_):
                dqj = dq[:, j]
                WjT, pj = self._joint(W, p, kn, j)
                ok = self._usable(dqj, tau[:, j], WjT, None if cc is None else cc[3][:, j])
                every = bool(ok.all())
                if not every:
                    WjT = WjT[:, ok]
                dqo, tauo, po = dqj[ok], tau[ok, j], pj[ok]
                sgo = None if sgn is None else sgn[ok, j]
                VT = self._v(WjT, po, dqo, tauo, sgo)
                VzT = None
                if iv:
                    WzT, pzj = self._joint(Wz, pz, knz, j)
                    VzT = self._v(WzT if every else WzT[:, ok], pzj[ok], dqo, tauo, sgo)
                h = 0.0 if theta is None else self._band_h[j]
                inb = inb_prev = None
                if theta is None:
                    sp = tauo * dqo
                else:
                    tout = theta[cols] @ WjT + po
                    if h > 0:  # the band, with hysteresis over the deciding thetas
                        inb, inb_prev = self._in_band(cols, WjT, po, h)
                    sp = tout * dqo if inb is None else np.where(inb, 0.0, tout * dqo)
                pplus, pminus = quadrant_weights(sp)
                rows += sp.size
                if theta_prev is not None:
                    spp = (theta_prev[cols] @ WjT + po) * dqo
                    if inb_prev is not None:
                        spp = np.where(inb_prev, 0.0, spp)
                    # rows that moved: changed quadrant, or entered or left the band (sign
                    # 0); either changes the moments (a row crossing the band flips only later)
                    changed += int(np.count_nonzero(np.sign(sp) != np.sign(spp)))
                E = stribeck_exp(dqo, self.q_s_[j])
                if inb is not None:  # rows in the band around the quadrant boundary: left out
                    in_band[j] += np.count_nonzero(inb)
                    considered[j] += inb.size
                    pplus[inb] = 0.0
                    pminus[inb] = 0.0
                    keep = ~inb
                    moms[j].add(VT[:, keep], (pplus[keep], pminus[keep]), E[keep],
                                None if VzT is None else VzT[:, keep])
                else:
                    moms[j].add(VT, (pplus, pminus), E, VzT)
                if stores is not None:
                    stores[j].offer(VT, VzT, E, (pplus, pminus), tout, inb)
        if theta is not None and stride == 1:
            # the share of each joint's rows the quadrant band leaves out, at this pass
            self._pass_band_share = in_band / np.maximum(considered, 1)
        return moms, rows, changed, stores

    @staticmethod
    def _sign(sig: RobotSignals, r: slice | np.ndarray, cc: tuple | None) -> np.ndarray | None:
        """The Coulomb column (m, k) of a chunk: the columns' decimated sign(dq), else the
        signals' (``RobotSignals.sign``, the states chain's), else None (sign of the
        decimated dq)."""
        if cc is not None:
            return cc[2]
        return None if sig.sign is None else sig.sign[r]

    def _usable(self, dqj: np.ndarray, tauj: np.ndarray, WjT: np.ndarray,
                keep: np.ndarray | None) -> np.ndarray:
        """The row rule of joint j (before the quadrant band): |dq_j| > ``dq_min``, finite
        torque and regressor, and the columns' ``keep`` mask when given; shape (n,)."""
        ok = (np.abs(dqj) > self.dq_min) & np.isfinite(tauj) & np.all(np.isfinite(WjT), axis=0)
        return ok if keep is None else ok & keep

    @staticmethod
    def _n_samples(signals: Any) -> int:
        items = [signals] if isinstance(signals, RobotSignals) else list(signals)
        return sum(int(np.shape(getattr(s, "t", ()))[0]) for s in items
                   if isinstance(s, RobotSignals))

    def _store_capacity(self, signals: Any) -> int:
        """Rows kept per joint for the incremental quadrant updates: at most
        ``STORE_FRACTION`` of the samples and one chunk (memory ~ one chunk's rows)."""
        n = self._n_samples(signals)
        return int(min(np.ceil(STORE_FRACTION * n), int(self.chunk_size)))

    # ------------------------------------------------------------------ solver
    def _local(self, j: int) -> np.ndarray:
        """Indices in x of joint j's parameters: its theta entries (none in the products
        form), then its block."""
        if not self._theta_x:
            return self._bstart[j] + np.arange(self._bsize[j])
        pb = self.n_theta_
        return np.concatenate([self.cols_[j], pb + self._bstart[j] + np.arange(self._bsize[j])])

    @property
    def _estimator(self) -> Estimator:
        """The estimator object of ``method`` (:mod:`ident.estimators`)."""
        return ESTIMATORS[self.method]()

    def _normal(self, moms, coeffs: Coeffs, x: np.ndarray, weights: np.ndarray):
        nx = x.size
        A = np.zeros((nx, nx))
        g = np.zeros(nx)
        C = np.zeros((nx, nx)) if self._estimator.needs_instruments else None
        rr = np.zeros(len(moms))
        yy = np.zeros(len(moms))
        for j, mom in enumerate(moms):
            idx = self._local(j)
            nt = self._nt(j)
            th, blk = x[idx[:nt]], x[idx[nt:]]
            cf = [coeffs(th, blk, 0), coeffs(th, blk, 1)]
            Aj, gj, rrj, Cj, yyj = mom.normal(cf)
            w = weights[j]
            A[np.ix_(idx, idx)] += w * Aj
            g[idx] += w * gj
            if C is not None:
                C[np.ix_(idx, idx)] += w * w * Cj
            rr[j], yy[j] = rrj, yyj
        return A, g, rr, C, yy

    def _cost(self, moms, coeffs: Coeffs, x: np.ndarray) -> np.ndarray:
        """Per-joint ||r||^2 at ``x`` (the ``rr`` of :meth:`_normal`, to the last bit) without
        the Jacobian: the line search's and the reweighting's evaluations."""
        rr = np.zeros(len(moms))
        for j, mom in enumerate(moms):
            idx = self._local(j)
            nt = self._nt(j)
            th, blk = x[idx[:nt]], x[idx[nt:]]
            rr[j] = mom.cost([coeffs(th, blk, 0, jacobian=False),
                              coeffs(th, blk, 1, jacobian=False)])
        return rr

    def _line_cost(self, moms, coeffs: Coeffs, x: np.ndarray, step: np.ndarray,
                   weights: np.ndarray) -> np.ndarray:
        """Weighted ||r||^2 at x + lam step as polynomial coefficients in lam (lowest
        first): the prediction coefficients are quadratic in lam (the models are bilinear),
        so those at x and x +- step give them exactly, and the line search's trial points
        cost nothing more (:meth:`JointMoments.cost_polynomial`)."""
        out = np.zeros(5)
        for j, mom in enumerate(moms):
            idx = self._local(j)
            nt = self._nt(j)
            xs = (x[idx], x[idx] + step[idx], x[idx] - step[idx])
            ey = np.zeros(mom.nv)
            ey[-1] = 1.0
            dpoly = []
            for s in (0, 1):
                c = [coeffs(v[:nt], v[nt:], s, jacobian=False) for v in xs]
                d = []
                for e in (0, 1):
                    mid, plus, minus = (ci[e] for ci in c)
                    first = 0.5 * (plus - minus)
                    second = 0.5 * (plus + minus) - mid
                    d.append(np.stack([(ey if e == 0 else 0.0) - mid, -first, -second]))
                dpoly.append(tuple(d))
            out += weights[j] * mom.cost_polynomial(dpoly)
        return out

    def _packed(self, moms, coeffs: Coeffs) -> PackedMoments | None:
        """The joints' moments padded to one size for the Gauss-Newton sums of all joints at
        once (:class:`~ident.robot.packed.PackedMoments`); None for IDIM-IV or another
        coefficient function."""
        model = {paper_coefficients: "paper", usual_coefficients: "usual"}.get(coeffs)
        if model is None or self._estimator.needs_instruments:
            return None
        k, nb, nx = len(moms), len(self.block_), self.n_theta_ + len(self.block_) * len(moms)
        m = max(len(c) for c in self.cols_)
        nv = m + N_EXTRA
        Mz = np.zeros((k, 2, 2 * nv, 2 * nv))
        tidx = np.full((k, m), nx)  # padding: the slot nx, a zero
        for j, (mom, cols) in enumerate(zip(moms, self.cols_, strict=True)):
            nt = len(cols)
            pos = np.r_[np.arange(nt), m + np.arange(N_EXTRA)]
            for s in (0, 1):
                for e, f in ((0, 0), (0, 1), (1, 0), (1, 1)):
                    Mz[j, s][np.ix_(e * nv + pos, f * nv + pos)] = mom.vv[s, e + f]
            tidx[j, :nt] = cols
        bidx = self.n_theta_ + nb * np.arange(k)[:, None] + np.arange(nb)[None, :]
        return PackedMoments(model, Mz, tidx, bidx, np.concatenate([tidx, bidx], axis=1), m, nx)

    def _solve_step(self, A: np.ndarray, g: np.ndarray, free: np.ndarray) -> np.ndarray:
        Af = A[np.ix_(free, free)]
        d = np.sqrt(np.abs(np.diag(Af)))
        zero = d == 0
        if self._damp > 0:  # Levenberg-Marquardt: unexcited directions stay where they are
            d[zero] = 1.0
            As = Af / d[:, None] / d[None, :] + self._damp * np.eye(d.size)
            step = np.zeros_like(g)
            step[free] = scipy.linalg.solve(As, g[free] / d) / d
            return step
        if zero.any():
            names = [self.names_[i] for i in np.flatnonzero(free)[zero]]
            nz = ~zero
            sv = np.linalg.svd(Af[np.ix_(nz, nz)] / d[nz, None] / d[None, nz],
                               compute_uv=False) if nz.any() else np.zeros(1)
            raise _Unidentifiable(f"parameters not identifiable on these data: {names} have "
                                  "no excitation (their columns are zero)", names, 0.0,
                                  float(sv[0]) if sv.size else 0.0, zero=True)
        As = Af / d[:, None] / d[None, :]
        # the estimator's rank rule and solve (IDIM-IV: A = Z^T W is not symmetric)
        try:
            sol = self._estimator.solve_normal(
                As, g[free] / d, [self.names_[i] for i in np.flatnonzero(free)])
        except RankDeficientError as e:
            raise _Unidentifiable(str(e), e.names, e.lo, e.hi) from None
        step = np.zeros_like(g)
        step[free] = sol / d
        return step

    def _gauss_newton(self, moms, coeffs: Coeffs, x0: np.ndarray, free: np.ndarray,
                      weights: np.ndarray, linear: bool) -> tuple[np.ndarray, int]:
        x = x0.copy()
        cost = float(weights @ self._cost(moms, coeffs, x))
        packed = self._packed(moms, coeffs)
        no_search = not self._estimator.symmetric  # IV minimises no cost: full steps
        it = 0
        for it in range(1, int(self.max_iter) + 1):
            if packed is not None:  # every joint at once
                A, g = packed.normal(x, weights)
            else:
                A, g, _, _, _ = self._normal(moms, coeffs, x, weights)
            try:
                step = self._solve_step(A, g, free)
            except _Unidentifiable as e:  # the rank rule judges the matrix refused here
                e.at, e.weights = x.copy(), np.array(weights, dtype=float)
                raise
            if packed is not None:
                poly = packed.line_cost(x, step, weights)[::-1]
            else:
                poly = self._line_cost(moms, coeffs, x, step, weights)[::-1]
            lam = 1.0
            while True:  # step halving; the trial costs from the polynomial in lam
                cn = max(float(np.polyval(poly, lam)), 0.0)
                if linear or no_search or cn <= cost * (1 + 1e-12) or lam < 1e-6:
                    break
                lam *= 0.5
            x, cost = x + lam * step, cn
            if linear and it >= 2:
                break
            scale = np.sqrt(np.abs(np.diag(A)))
            if np.linalg.norm((lam * step * scale)[free]) <= self.tol * max(
                    np.linalg.norm((x * scale)[free]), 1e-300):
                break
        return x, it

    def _covariance(self, moms, coeffs: Coeffs, x: np.ndarray, free: np.ndarray,
                    weights: np.ndarray) -> tuple:
        """(cov (b, b), sigma^2, rr, yy, rows per joint) of the fit ``x`` (eq. 14-15; 0 on
        the fixed parameters); cov None without a degree of freedom."""
        A, _, rr, C, yy = self._normal(moms, coeffs, x, weights)
        n_rows = np.array([m.n for m in moms])
        dof = int(n_rows.sum()) - int(free.sum())
        if dof <= 0:
            return None, np.nan, rr, yy, n_rows
        sigma2 = float(weights @ rr) / dof
        cov_f = self._estimator.normal_covariance(
            A[np.ix_(free, free)], None if C is None else C[np.ix_(free, free)], sigma2)
        cov = np.zeros((x.size, x.size))
        cov[np.ix_(free, free)] = cov_f
        return cov, sigma2, rr, yy, n_rows

    def _statistics(self, moms, coeffs: Coeffs, x: np.ndarray, free: np.ndarray,
                    weights: np.ndarray) -> None:
        cov, sigma2, rr, yy, n_rows = self._covariance(moms, coeffs, x, free, weights)
        if cov is None:
            raise RobotIdentError(f"RobotModel.fit: {int(n_rows.sum())} rows for "
                                  f"{int(free.sum())} parameters")
        self._store_solution(x, cov, sigma2, self._joint_sigma(moms, rr, free), n_rows, rr, yy)

    def _store_solution(self, x: np.ndarray, cov: np.ndarray, sigma2: float,
                        sigma_joint: np.ndarray, n: int, rr: np.ndarray,
                        yy: np.ndarray) -> None:
        """Set the fitted attributes of a solution ``x`` with covariance ``cov``: ``coef_``,
        ``cov_``, ``std_``, ``rel_std_`` (eq. 16), ``params_``, ``sigma_`` (sqrt of the
        residual variance ``sigma2``), ``sigma_joint_``, ``n_samples_`` and ``rel_error_``
        (per joint sqrt(rr_j / yy_j), ``rr`` the residual and ``yy`` the torque sums of squares
        [N^2 m^2]; "all" over every joint). Shared by the hard fit and
        :func:`ident.robot.soft_fit.fit_soft`."""
        self.coef_ = x
        self.cov_ = cov
        self.std_ = np.sqrt(np.clip(np.diag(cov), 0, None))
        with np.errstate(divide="ignore", invalid="ignore"):
            self.rel_std_ = np.where(x != 0, 100.0 * self.std_ / np.abs(x), np.inf)
        self.params_ = dict(zip(self.names_, x.tolist(), strict=True))
        self.sigma_ = float(np.sqrt(sigma2))
        self.sigma_joint_ = sigma_joint
        self.n_samples_ = n
        rel = {name: float(np.sqrt(rr[j] / yy[j])) if yy[j] > 0 else float("nan")
               for j, name in enumerate(self.joints_)}
        rel["all"] = float(np.sqrt(rr.sum() / yy.sum()))
        self.rel_error_ = rel

    def _joint_sigma(self, moms, rr: np.ndarray, free: np.ndarray) -> np.ndarray:
        out = np.empty(len(moms))
        for j, m in enumerate(moms):
            bj = int(free[self._local(j)].sum())
            out[j] = np.sqrt(rr[j] / max(m.n - bj, 1))
        return out

    def _fit_on(self, moms, coeffs: Coeffs, x0: np.ndarray, free: np.ndarray,
                linear: bool) -> tuple[np.ndarray, np.ndarray, int]:
        """LS (or IV) fit, then WLS reweighting when asked; returns (x, weights, iterations)."""
        k = len(moms)
        w = np.ones(k)
        x, it = self._gauss_newton(moms, coeffs, x0, free, w, linear)
        est = self._estimator
        if est.reweights:  # WLS: the joints' weights from the first fit's residuals
            sj = self._joint_sigma(moms, self._cost(moms, coeffs, x), free)
            # a joint without rows (at this quadrant decision) adds nothing to the normal
            # equations: its weight is irrelevant, not undefined
            sj = np.where([m.n == 0 for m in moms], 1.0, sj)
            try:
                w = est.weights(sj)
            except DataError as e:
                bad = [j for j, s in enumerate(sj) if not s > 0]
                if not bad:
                    raise RobotIdentError(f"RobotModel: {e}") from None
                j = bad[0]
                nj, bj = moms[j].n, int(free[self._local(j)].sum())
                raise RobotIdentError(
                    f"RobotModel (WLS): joint {self.joints_[j]} has zero residual on its "
                    f"{nj} rows at this step of the fit ({bj} parameters involve them), so "
                    f"its weight 1/sigma^2 is undefined; use LS (method='ls', --method ls)"
                ) from None
            x, it = self._gauss_newton(moms, coeffs, x, free, w, linear)
        return x, w, it

    def _payload_fixes_scale(self, moms: list[JointMoments]) -> bool:
        """Whether the known torques p_j fix the scale of theta against the paper's a, b: not
        when sum_j ||W_j delta - p_j||^2 = 0 for some delta (p in the span of the base
        columns: no payload, or one and the same payload in every experiment, whose torque is
        W (its base parameters)); then tau = a_j W_j (theta + delta) gives only products."""
        pb = self.n_theta_
        A = np.zeros((pb, pb))
        b = np.zeros(pb)
        pp = 0.0
        for m, c in zip(moms, self.cols_, strict=True):
            nt = len(c)
            M = m.vv[0, 0] + m.vv[1, 0]
            A[np.ix_(c, c)] += M[:nt, :nt]
            b[c] += M[:nt, nt + IP]
            pp += float(M[nt + IP, nt + IP])
        if not pp > 0:
            return False
        d = np.sqrt(np.abs(np.diag(A)))
        d[d == 0] = 1.0
        delta, *_ = np.linalg.lstsq(A / d[:, None] / d[None, :], b / d, rcond=1e-12)
        resid = pp - float((b / d) @ delta)
        return resid > SCALE_TOL * pp

    def _rms_load(self, moms: list[JointMoments], theta: np.ndarray) -> np.ndarray:
        """RMS of tau_out = W_j theta + p_j over each joint's rows of ``moms`` [N m]."""
        out = np.zeros(len(moms))
        for j, (m, c) in enumerate(zip(moms, self.cols_, strict=True)):
            nt = len(c)
            M = m.vv[0, 0] + m.vv[1, 0]
            idx = np.r_[np.arange(nt), nt + IP]
            u = np.r_[theta[c], 1.0]
            out[j] = np.sqrt(max(float(u @ M[np.ix_(idx, idx)] @ u), 0.0) / max(m.n, 1))
        return out

    def _gauge(self, moms: list[JointMoments]) -> int:
        """Index of the coefficient fixed to 1 when the payloads do not fix the scale: a_m of
        the first joint with rows in the motor quadrant (else a_g of the first with rows in
        the generator quadrant)."""
        pb, nb = self.n_theta_, len(PAPER_BLOCK)
        rows = self._quadrant_rows(moms)
        for s, off in ((0, PAPER_BLOCK.index("a_m")), (1, PAPER_BLOCK.index("a_g"))):
            for j, joint in enumerate(self.joints_):
                if rows[joint][s] > 0:
                    return pb + nb * j + off
        return pb

    def _quadrant_rows(self, moms: list[JointMoments]) -> dict[str, tuple[int, int]]:
        """Rows of every joint in the motor and the generator quadrant (P = 0: half each)."""
        out = {}
        for joint, m in zip(self.joints_, moms, strict=True):
            if isinstance(m, RowMoments):  # rows given whole: their low-passed P+
                out[joint] = (int(round(m.quadrant_n[0])), int(round(m.quadrant_n[1])))
                continue
            i = m.nv - N_EXTRA + ONE
            out[joint] = (int(round(m.vv[0, 0, i, i])), int(round(m.vv[1, 0, i, i])))
        return out

    def _fit_paper(self, moms: list[JointMoments], x: np.ndarray, free: np.ndarray,
                   damped_ok: bool = False) -> tuple[np.ndarray, np.ndarray, int, Any]:
        """The paper model on ``moms``; returns (x, weights, iterations, None), or with
        ``damped_ok`` and singular normal equations a Levenberg-Marquardt fit (the unexcited
        directions stay at ``x``) and the error (quadrants still being decided: the next
        ones may excite them). A failure names its evidence (rows per quadrant and load sign
        of the joints involved, singular values) and what data would fix it, in one line."""
        try:
            return (*self._fit_on(moms, self._paper_cf, x, free, linear=False), None)
        except _Unidentifiable as e:
            if not damped_ok:
                return self._drop_unidentifiable(moms, x, free, e)
            self._damp = DAMPING
            try:
                out = self._fit_on(moms, self._paper_cf, x, free, linear=False)
            finally:
                self._damp = 0.0
            err = RobotIdentError(self._evidence(e, moms))
            err.cause = e  # type: ignore[attr-defined]  (for _drop_unidentifiable)
            return (*out, err)

    def _drop_unidentifiable(self, moms: list[JointMoments], x: np.ndarray, free: np.ndarray,
                             e: _Unidentifiable) -> tuple[np.ndarray, np.ndarray, int, None]:
        """The paper fit's normal equations are singular (``e``) on the final quadrants: the
        rank rule (:meth:`_rank_fix`, the single-joint fit's and the usual fit's, with the
        solver's criterion and tolerance; with the weights ``e.weights`` of the refused
        matrix, at ``x``, where the fit goes on from, and where it names nothing there at the
        refused iterate ``e.at``) fixes the zero, dependent or nearly dependent columns at 0
        (``fixed_``, their reasons in ``removed_``, the refusal's evidence, rows per quadrant
        and load sign, in ``dropped_evidence_``) and the fit is made without them (``free``
        and ``x`` changed in place); repeated while the rule finds columns. Refused in one
        line (the evidence: the cond and the columns of the weakest direction) when it names
        none (no column lies within the rule's tolerance of the others' span) or when a joint
        keeps neither a_m nor a_g (nothing of its load model left). Returns (x, weights,
        iterations, None)."""
        evidence = self._evidence(e, moms)
        before = [n for n, v in self.fixed_.items() if v == 0.0]
        if before:  # an earlier refusal's columns already dropped: say so in this one
            evidence += f" (after {', '.join(before)} were dropped as not identifiable)"
        nb = len(PAPER_BLOCK)
        ia, ig = PAPER_BLOCK.index("a_m"), PAPER_BLOCK.index("a_g")
        for _ in range(x.size):
            # the columns at the point the fit goes on from; else at the refused matrix's
            dep = self._rank_fix(moms, self._paper_cf, x, free, e.weights)
            if not dep and e.at is not None:
                dep = self._rank_fix(moms, self._paper_cf, e.at, free, e.weights)
            if not dep:
                raise RobotIdentError(evidence + (
                    " (the rank rule names no column to drop: none lies within RCOND "
                    "sigma_max of the others' span)" if self._estimator.symmetric else
                    " (the rank rule names no column of the regressor to drop: the singular "
                    "matrix is the instruments' Z^T W)"))
            for i, why in dep:
                self._drop(i, why, free, x)
            if self._near_evidence:
                evidence += f" ({self._near_evidence})"
            self.dropped_evidence_.append(evidence)
            for j, joint in enumerate(self.joints_):
                b = self.n_theta_ + nb * j
                if not (free[b + ia] or self.fixed_.get(self.names_[b + ia]) == 1.0) and \
                        not (free[b + ig] or self.fixed_.get(self.names_[b + ig]) == 1.0):
                    raise RobotIdentError(f"{evidence} (nothing of {joint}'s load model "
                                          "is left: its a_m and a_g are both unexcited)")
            if not free.any():
                raise RobotIdentError(evidence)
            try:
                return (*self._fit_on(moms, self._paper_cf, x, free, linear=False), None)
            except _Unidentifiable as e2:
                e = e2
                evidence = (self._evidence(e2, moms) + " (after "
                            + ", ".join(n for n, v in self.fixed_.items() if v == 0.0)
                            + " were dropped as not identifiable)")
        raise RobotIdentError(evidence)

    def _drop(self, i: int, why: str, free: np.ndarray, x: np.ndarray) -> None:
        """Fix parameter ``i`` at 0 (``free`` and ``x`` changed in place) with its reason:
        ``fixed_`` and the reason that ``removed_`` reports (the rank rule's drops, the
        elimination's)."""
        free[i] = False
        x[i] = 0.0
        self.fixed_[self.names_[i]] = 0.0
        self._fixed_why[self.names_[i]] = why

    @staticmethod
    def _load_signs(m: JointMoments) -> tuple[int, int]:
        """Rows with a positive and a negative load (sign(P) sign(dq)): motor rows with
        dq > 0 and generator rows with dq < 0 have tau_out > 0 (rows given whole: not
        counted, (0, 0))."""
        if isinstance(m, RowMoments):
            return 0, 0
        i, sg = m.nv - N_EXTRA + ONE, m.nv - N_EXTRA + ISG
        pos = 0.5 * (m.vv[0, 0, i, i] + m.vv[0, 0, sg, i] + m.vv[1, 0, i, i] - m.vv[1, 0, sg, i])
        return int(round(pos)), int(round(m.vv[0, 0, i, i] + m.vv[1, 0, i, i] - pos))

    def _evidence(self, e: _Unidentifiable, moms: list[JointMoments]) -> str:
        rows = self._quadrant_rows(moms)
        loads = {j: self._load_signs(m) for j, m in zip(self.joints_, moms, strict=True)}
        of_name = {self.names_[i]: joint for j, joint in enumerate(self.joints_)
                   for i in self._local(j)[self._nt(j):]}
        named = []
        for n in e.names:
            j = of_name.get(n)
            if j is not None and j not in named:
                named.append(j)
        frac = {j: min(r) / max(sum(r), 1) for j, r in rows.items()}
        # rows given whole (full-rate products): their load signs are not counted
        whole = any(isinstance(m, RowMoments) for m in moms)
        lfrac = {j: 1.0 if whole else min(r) / max(sum(r), 1) for j, r in loads.items()}
        thin = [j for j in self.joints_ if frac[j] < THIN_QUADRANT]
        one_sign = [j for j in self.joints_ if lfrac[j] < THIN_QUADRANT and j not in thin]
        show = named + [j for j in thin + one_sign if j not in named] or list(self.joints_)
        how = ("model quadrant sign(tau_out_hat dq) of the fit" if self.quadrant == "model"
               else "measured quadrant sign(tau dq)")
        if whole:
            how = "quadrant of the load model the full-rate products were formed with"
        ev = "; ".join(f"{j}: {rows[j][0]} rows motor, {rows[j][1]} generator"
                       + ("" if whole else f", load > 0 on {loads[j][0]}, < 0 on "
                          f"{loads[j][1]}") for j in show)
        sv = (f"scaled normal matrix singular values {e.lo:.3g} .. {e.hi:.3g}" if not e.zero
              else f"largest singular value {e.hi:.3g}, zero columns")
        fixes = []
        if thin:
            fixes.append(f"a trajectory on which the load of {', '.join(thin)} changes sign "
                         "against its velocity (rows in both quadrants), e.g. through the "
                         "configurations where its gravity torque changes sign, or a payload "
                         "that makes its load exceed its dry friction")
        if one_sign:
            fixes.append(f"a trajectory on which the load of {', '.join(one_sign)} changes "
                         "sign (c_m, c_g and the offset are not separable otherwise)")
        if not self._theta_x and not fixes:
            fixes.append("a trajectory that excites these columns on the joint's rows")
        elif self._theta_x and any(n.startswith(("a_m", "a_g", "b_m", "b_g"))
                                   for n in e.names) or not fixes:
            fixes.append("experiments with different payloads (they fix the scale of the "
                         "base parameters against a_m, a_g)")
        if self.quadrant == "measured":
            fixes.append("quadrant='model'")
        return (f"paper model: {e} -- evidence ({how}): {ev}; {sv}. Fix: "
                + "; or ".join(fixes))

    # ------------------------------------------------------------------ public
    def fit(self, signals: RobotSignals | Sequence[RobotSignals]) -> RobotModel:
        """Identify the parameters on one or several :class:`RobotSignals` (all experiments
        in one global estimation, as the paper's eq. 36-40).

        Returns
        -------
        self
        """
        if self.payload_params:
            self._payload_groups(signals)
        self._setup()
        k, pb = len(self.joints_), self.n_theta_
        # the share of each joint's rows in the quadrant band, set by every full pass
        self._pass_band_share = np.zeros(k)
        self.band_share_ = np.zeros(k)
        if self.payload_ratio:
            items = [signals] if isinstance(signals, RobotSignals) else list(signals)
            if not any(pl.mass > 0 for sig in items if isinstance(sig, RobotSignals)
                       for pl in sig.payloads):
                raise RobotIdentError("RobotModel.payload_ratio: no experiment carries a "
                                      "payload (mass > 0), so the ratio M_ae / M_aw (eq. 35) "
                                      "cannot be identified")
        paper = self.model == "paper"
        model_q = paper and self.quadrant == "model"
        self.full_rate_products_ = self._full_rate(signals)
        self.full_rate_paper_ = False
        self._paper_cf: Coeffs = paper_coefficients
        self._fr_pp: list | None = None
        # quadrant="model": the start (the usual fit) only needs a first theta; on large data
        # it is taken on every stride-th row, and the full pass with the model quadrants
        # follows (module constant START_ROWS)
        stride = 1
        if model_q and self.form != "products":  # (products: the usual fit decides for good)
            stride = max(1, self._n_samples(signals) // int(START_ROWS))
        moms, _, _, _ = self._pass(signals, None, 3 if paper and not model_q else 1,
                                   stride=stride)
        passes = 1
        self.start_stride_ = stride
        # usual model (also the paper model's starting point)
        nbu = len(USUAL_BLOCK)
        saved = self.block_, self.names_
        self.block_ = USUAL_BLOCK
        self._layout(False)
        self.names_ = tuple(self.theta_names_) + tuple(
            f"{p}{n}" for n in self.numbers_ for p in USUAL_BLOCK)
        xu0 = np.zeros(pb + nbu * k)
        free_u = np.ones(xu0.size, dtype=bool)
        self._fixed_why = {}
        if self.eliminate:
            # the single-joint rank rule before the first solve (fit_least_squares drops
            # zero and dependent columns first): e.g. one payload in every run, whose
            # ratio's column is a combination of J and MX, is removed, not an error
            for c, why in self._rank_fix(moms, usual_coefficients, xu0, free_u):
                free_u[c] = False
                self._fixed_why[self.names_[c]] = why
        xu, wu, it = self._fit_on(moms, usual_coefficients, xu0, free_u, linear=True)
        self.block_ = saved[0]
        self._layout(self.form == "products")
        self.names_ = saved[1]
        self.fixed_: dict[str, float] = {}
        self.quadrant_changes_: list[int] = []
        self.quadrant_steps_: list[float] = []
        # why the quadrant passes did not settle ("" when they did, or made none)
        self._unsettled = ""
        self.n_store_updates_ = 0
        # the theta that decided the final moments' quadrants (ident.robot.uncertainty)
        self.quadrant_from_ = None
        if not paper:
            self.fixed_ = {self.names_[c]: 0.0 for c in np.flatnonzero(~free_u)}
            return self._finish(moms, usual_coefficients, xu, free_u, wu, passes, it, None)
        if self.form == "products":
            return self._fit_products(signals, moms, xu, passes)
        nb = len(PAPER_BLOCK)
        x = np.zeros(pb + nb * k)
        x[:pb] = xu[:pb]
        for j in range(k):
            x[pb + nb * j: pb + nb * (j + 1)] = paper_start(xu[pb + nbu * j: pb + nbu * (j + 1)])
        scale_fixed = self._payload_fixes_scale(moms)
        stores = None
        rows = 0
        cap = self._store_capacity(signals)
        # the theta that decides the moments' quadrants
        given = self.quadrant_theta_ is not None
        theta_q = self.quadrant_theta_.copy() if given else xu[:pb].copy()
        fr_moms = None
        if model_q and self._full_rate_ok(signals):
            try:  # the quadrant and E products at full rate (``full_rate``)
                fr_moms, rows, _ = self._rows_pass(signals, theta_q)
            except ProductsTooLarge as e:
                warnings.warn(f"paper model: {e}; its quadrant and E products are taken on "
                              "the decimated columns instead (docs/refinement.md 8.9)",
                              stacklevel=2)
        fr = self.full_rate_paper_ = fr_moms is not None
        self._set_band(moms, theta_q, model_q)
        if fr:
            self._paper_cf = bilinear_rows_coefficients
            if self.band_from_ is not None:  # the band at full rate, decided once: again
                fr_moms, rows, _ = self._rows_pass(signals, theta_q)
            moms = fr_moms
            passes += 1
        elif model_q:
            # the model quadrant sign(tau_out_hat dq) of the usual fit, never the measured
            # torque's: on a joint whose dry friction exceeds its load, sign(tau dq) is
            # "motor" on every row whatever the load does
            moms, rows, _, stores = self._pass(signals, theta_q, 3,
                                               capacity=0 if given else cap, gram_from=moms)
            passes += 1
        free = np.ones(x.size, dtype=bool)
        if not scale_fixed:
            # no payload torque outside the span of the base columns (no payload, or one
            # and the same payload in every experiment): theta * a only (paper module doc)
            i = self._gauge(moms)
            free[i] = False
            x[i] = 1.0
            self.fixed_ = {self.names_[i]: 1.0}
        self.quadrant_rows_ = self._quadrant_rows(moms)
        # the refusals' evidence where the rank rule dropped columns (_drop_unidentifiable)
        self.dropped_evidence_: list[str] = []
        loop = model_q and not given
        x, w, it, pending = self._fit_paper(moms, x, free, damped_ok=loop)
        for _ in range(x.size):
            if loop:
                self._unsettled = never_redecided(self.max_passes)
                for _ in range(int(self.max_passes) - 1):
                    theta, x_prev = x[:pb].copy(), x
                    if self.band_from_ is not None and not fr:  # the band's hysteresis
                        self.band_from_ = np.vstack([self.band_from_, theta])
                    if stores is not None and all(
                            st.covers(theta[c])
                            for st, c in zip(stores, self.cols_, strict=True)):
                        # no row outside the stores can move: update by the moved rows only
                        changed = sum(self._store_update(st, theta[c], m) for st, c, m in
                                      zip(stores, self.cols_, moms, strict=True))
                        self.n_store_updates_ += 1
                    elif fr:  # the products formed again with this theta's quadrants
                        moms, rows, changed = self._rows_pass(signals, theta)
                        passes += 1
                    else:
                        moms, rows, changed, stores = self._pass(
                            signals, theta, 3, theta_q, capacity=cap, gram_from=moms)
                        passes += 1
                    theta_q = theta
                    self.quadrant_rows_ = self._quadrant_rows(moms)
                    x, w, it, pending = self._fit_paper(moms, x, free, damped_ok=True)
                    self.quadrant_changes_.append(changed)
                    step = (np.inf if pending is not None
                            else self._step_sigma(moms, x_prev, x, free, w))
                    self.quadrant_steps_.append(step)
                    # settled: (almost) no row changed quadrant or crossed the band, or the
                    # parameters moved by a small fraction of their sigma
                    self._unsettled = unsettled_reason(changed, rows, step, self.max_passes)
                    if not self._unsettled:
                        break
            if pending is None:
                break
            # the last quadrants still leave a direction unexcited: the rank rule drops its
            # columns (held at 0, reported; else the refusal), and the quadrants are settled
            # again without them
            x, w, it, pending = self._drop_unidentifiable(moms, x, free, pending.cause)
        self._finish(moms, self._paper_cf, x, free, w, passes, it,
                     theta_q if model_q else None)
        if self.quadrants == "soft":  # the hard fit is the start (ident.robot.soft_fit)
            fit_soft(self, signals)
            self.convergence_ = "" if self.converged_ else (
                "the soft quadrants' least squares stopped at its evaluation limit")
        return self

    def _fit_products(self, signals: Any, moms: list[JointMoments], xu: np.ndarray,
                      passes: int) -> RobotModel:
        """The products form (``form="products"``) after the usual fit ``xu`` on ``moms``:
        linear least squares (or IV, WLS) on the moments of the final quadrants. With
        ``quadrant="model"`` they are decided once, by the usual fit's theta (or
        ``quadrant_theta``): the products form has no theta of its own to re-decide them
        with. The products of a load column that is zero on every row of the joint (its
        payload torque without payload or known rotor, a payload parameter not acting on
        it) or a linear combination of its other load columns there (UR10 shoulder pan:
        MX2 and XY2) are fixed at 0 (``fixed_``): the rank rule of every model
        (:meth:`ident.estimators.Estimator.rank_drops` on the load columns' Gram matrix,
        and for IDIM-IV then on what it solves, the load columns projected on their
        instruments: a load column the instruments do not determine, e.g. nearly a
        duplicate of another on the reference trajectory, is left out with
        :data:`ident.estimators.WEAK_PREFIX`'s reason); ``removed_`` names as a product's
        partners the same products of the load column's partners.
        With ``eliminate``, the rank rule on every free column (:meth:`_rank_fix`) follows,
        before the first solve, as in the usual fit: the single-joint fit's dependent
        friction columns are dropped and reported, not an error."""
        pb, nbu = self.n_theta_, len(USUAL_BLOCK)
        model_q = self.quadrant == "model"
        theta_q = self.quadrant_theta_.copy() if self.quadrant_theta_ is not None else xu[:pb]
        coeffs: Coeffs = products_coefficients
        if self.full_rate_products_:
            # the rows formed at full rate (products_columns) carry their own quadrants
            self.band_ = self._band_h = np.zeros(len(moms))
            moms = self._pass_rows(signals)
            passes += 1
            coeffs, model_q = rows_coefficients, False
        else:
            self._set_band(moms, theta_q, model_q)
            if model_q:
                moms, _, _, _ = self._pass(signals, theta_q, 3)
                passes += 1
        x = np.concatenate([products_start(xu[c], xu[pb + nbu * j: pb + nbu * (j + 1)])
                            for j, c in enumerate(self.cols_)])
        free = np.ones(x.size, dtype=bool)
        self._fixed_why: dict[str, str] = {}
        est = self._estimator
        for j, m in enumerate(moms):
            nl = len(self.cols_[j]) + 1
            # the load columns (theta's, then p) on the joint's rows: W^T W, and for IDIM-IV
            # Z^T W and Z^T Z (what it solves on them)
            gram, A, C = self._load_moments(m, nl)
            # load column 0's a_m, b_m, a_g, b_g (products_names' order); column c's: + 2 c
            off = self._bstart[j] + np.array([0, 1, 2 * nl, 2 * nl + 1])
            # the rule once per product, so that each reason names the same product of the
            # partners (the columns left out do not depend on the names)
            drops = [est.rank_drops(gram, [self.names_[o + 2 * q] for q in range(nl)],
                                    A=A, C=C, first=nl - 1) for o in off]
            for t, (c, _) in enumerate(drops[0]):
                for o, d in zip(off, drops, strict=True):
                    free[o + 2 * c] = False
                    x[o + 2 * c] = 0.0
                    self._fixed_why[self.names_[o + 2 * c]] = d[t][1]
        if self.eliminate:
            # the rank rule before the first solve, as the usual fit's (module doc,
            # ``eliminate``): e.g. a load of one sign on every row, whose motor and generator
            # rows make OFF a combination of c_m and c_g, is removed, not an error
            for i, why in self._rank_fix(moms, coeffs, x, free):
                self._drop(i, why, free, x)
        self.fixed_ = {self.names_[i]: 0.0 for i in np.flatnonzero(~free)}
        self.quadrant_rows_ = self._quadrant_rows(moms)
        try:
            x, w, it = self._fit_on(moms, coeffs, x, free, linear=True)
        except _Unidentifiable as e:
            raise RobotIdentError(self._evidence(e, moms)) from None
        return self._finish(moms, coeffs, x, free, w, passes, it,
                            theta_q if model_q else None)

    @staticmethod
    def _load_moments(m: JointMoments, nl: int
                      ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """W^T W, Z^T W and Z^T Z (nl, nl) of a joint's load columns W (its base columns,
        then p) and their instruments Z on its rows (None, None without instruments): from
        the quadrant moments, or, rows given whole (:class:`RowMoments`), from the products'
        moments: P+ w + P- w = w (the low-pass is linear), so the sum of the a_m and a_g
        columns of each load column (of each instrument column alike)."""
        if not isinstance(m, RowMoments):
            out = [None if M is None else M[0, 0, :nl, :nl] + M[1, 0, :nl, :nl]
                   for M in (m.vv, m.zv, m.zz)]
        else:
            S = np.zeros((m.nv, nl))
            S[2 * np.arange(nl), np.arange(nl)] = 1.0
            S[2 * nl + 2 * np.arange(nl), np.arange(nl)] = 1.0
            out = [None if M is None else S.T @ M[0, 0] @ S for M in (m.vv, m.zv, m.zz)]
        return out[0], out[1], out[2]

    def _full_rate(self, signals: Any) -> bool:
        """Whether the fit reads the paper model's products formed at full rate
        (``RobotColumns.products``, :func:`ident.robot.design.products_columns`): the
        products form on signals that carry them (all of them, else a one-line error), and
        the options that would re-decide their quadrants refused."""
        if self.model != "paper" or self.form != "products":
            return False
        items = [signals] if isinstance(signals, RobotSignals) else list(signals)
        has = [isinstance(s, RobotSignals) and s.columns is not None
               and s.columns.products is not None for s in items]
        if not any(has):
            return False
        what = "the full-rate products (columns.products)"
        if not all(has):
            bad = next(s for s, h in zip(items, has, strict=True) if not h)
            raise RobotIdentError(f"{getattr(bad, 'source', '') or 'RobotSignals'}: no "
                                  f"{what}, which other signals of the fit carry; form them "
                                  "on every one (products_columns)")
        for s in items:
            fr = s.columns.products
            if not np.allclose(fr.q_s, self.q_s_, rtol=1e-12, atol=0.0):
                raise RobotIdentError(f"{s.source or 'RobotSignals'}: {what} were formed "
                                      f"with q_s {fr.q_s.tolist()} rad/s, the model's is "
                                      f"{self.q_s_.tolist()}")
            for j, c in enumerate(self.std_cols_ if self._kpn else [None] * len(self.cols_)):
                if c is None or not np.all(np.isin(c, fr.cols[j])):
                    raise RobotIdentError(f"{s.source or 'RobotSignals'}: {what} lack "
                                          f"base columns of joint {self.joints_[j]}: formed "
                                          "with another base (products_columns(base=...))")
        for bad, why in ((self.quadrant != "model", f"quadrant={self.quadrant!r}"),
                         (self.quadrant_theta_ is not None, "quadrant_theta"),
                         (self.method == "iv" and any(s.columns.products.loads_z is None
                                                      for s in items),
                          "method='iv' (no instruments formed: products_columns("
                          "instruments=True))"),
                         (self.payload_params, "payload_params")):
            if bad:
                raise RobotIdentError(f"RobotModel: {why} does not apply to {what}: their "
                                      "quadrants are the load model's they were formed with; "
                                      "fit without them or without that option")
        return True

    def _row_block(self, fr, j: int, dqj: np.ndarray, iv: bool = False) -> np.ndarray:
        """Joint j's rows u (nx_j, m) of a chunk's full-rate products ``fr`` in
        :func:`~ident.robot.paper.products_names`'s order: per load column (its base
        columns, then p) the a_m, b_m columns, then the a_g, b_g ones, the four quadrant
        Coulomb columns, dq (F_V) and 1 (OFF). ``iv``: the instruments' rows (the load
        columns' instruments ``loads_z``, the rest the same)."""
        where = {int(c): i for i, c in enumerate(fr.cols[j])}
        pos = np.array([where[int(c)] for c in self.std_cols_[j]] + [fr.cols[j].size], int)
        L = (fr.loads_z if iv else fr.loads)[j][:, pos]  # (4, nl, m)
        nl, m = pos.size, dqj.size
        U = np.empty((4 * nl + 6, m))
        U[0:2 * nl:2], U[1:2 * nl:2] = L[0], L[1]
        U[2 * nl:4 * nl:2], U[2 * nl + 1:4 * nl:2] = L[2], L[3]
        U[4 * nl:4 * nl + 4] = fr.coulomb[:, :, j]
        U[4 * nl + 4] = dqj
        U[4 * nl + 5] = 1.0
        return U

    def _row_chunks(self, signals: Any):
        """Per chunk and joint j: (rows, j, the chunk's full-rate products, dq_j, tau_j, U,
        ok): joint j's rows U (nx_j, m) (:meth:`_row_block`) and the rows :meth:`_pass`
        keeps (dq_min, finite, ``keep``), ok (m,) bool."""
        for _sig, r, _q, dq, _ddq, tau, _z, _pay, cc in self._chunks(signals, iv=False):
            fr = cc[6]
            for j in range(len(self.cols_)):
                U = self._row_block(fr, j, dq[:, j])
                ok = (np.abs(dq[:, j]) > self.dq_min) & np.isfinite(tau[:, j]) & np.all(
                    np.isfinite(U), axis=0) & cc[3][:, j]
                yield r, j, fr, dq[:, j], tau[:, j], U, ok

    def _pass_rows(self, signals: Any) -> list[RowMoments]:
        """One pass over the full-rate products' rows (:meth:`_row_block`, tau appended) of
        every joint, with the rows :meth:`_pass` keeps (dq_min, finite, ``keep``)."""
        iv = self.method == "iv"
        moms = [RowMoments(np.arange(products_size(len(c))), iv=iv) for c in self.cols_]
        for _r, j, fr, dqj, tauj, U, ok in self._row_chunks(signals):
            VzT = None
            if iv:
                Uz = self._row_block(fr, j, dqj, iv=True)
                VzT = np.vstack([Uz[:, ok], tauj[ok]])
            moms[j].add_rows(np.vstack([U[:, ok], tauj[ok]]), fr.pplus[ok, j], VzT)
        return moms

    def products_rows(self, signals: RobotSignals, instruments: bool = False):
        """The rows a fit on the full-rate products (``full_rate_products_``) reads: per chunk
        and joint, (rows, j, U, ok) with ``rows`` the chunk's samples of ``signals`` (slice or
        indices), U (nx_j, m) joint j's products in ``names_``' order of its block
        (:meth:`_local`; :func:`~ident.robot.paper.products_names`) and ok (m,) the fit's row
        rule (|dq_j| > ``dq_min``, finite torque and products, ``keep``). The prediction on
        them is ``coef_[_local(j)] @ U``. For the n-dof refit (:mod:`ident.robot.refit`).
        ``instruments``: (rows, j, U, ok, Uz) with Uz (nx_j, m) the IDIM-IV instruments' rows
        an IV fit reads (:meth:`_row_block` ``iv=True``: the products' ``loads_z``).

        Raises
        ------
        RobotIdentError
            The model was not fitted on full-rate products, or ``signals`` do not carry
            them (or carry them formed otherwise: :meth:`fit`'s checks); ``instruments``
            and products formed without them.
        """
        self._check_fitted()
        if not getattr(self, "full_rate_products_", False):
            raise RobotIdentError("RobotModel.products_rows: the model was not fitted on "
                                  "full-rate products (columns.products)")
        if not isinstance(signals, RobotSignals) or signals.columns is None or (
                signals.columns.products is None):
            raise RobotIdentError(f"{getattr(signals, 'source', '') or 'RobotSignals'}: the "
                                  "model was fitted on full-rate products (columns.products); "
                                  "its rows need signals carrying them (products_columns)")
        self._full_rate(signals)  # the same checks as the fit's
        if not instruments:
            return ((r, j, U, ok) for r, j, _fr, _dqj, _tauj, U, ok in
                    self._row_chunks(signals))
        if signals.columns.products.loads_z is None:
            raise RobotIdentError(f"{signals.source or 'RobotSignals'}: no IDIM-IV instruments "
                                  "formed with the full-rate products (products_columns("
                                  "instruments=True))")
        return ((r, j, U, ok, self._row_block(fr, j, dqj, iv=True)) for
                r, j, fr, dqj, _tauj, U, ok in self._row_chunks(signals))

    # ------------------------------------------------------------------ full rate (bilinear)
    def _full_rate_ok(self, signals: Any) -> bool:
        """Whether the bilinear paper fit can form its products at full rate
        (``full_rate``): the option on, hard model quadrants, no payload ratio or payload
        parameters, standard columns in the base, and every signal carrying the columns
        chain's ``source`` (with its instruments for IDIM-IV)."""
        if not (self.full_rate and self.model == "paper" and self.form == "bilinear"
                and self.quadrant == "model" and self.quadrants == "hard"
                and not self.payload_ratio and not self.payload_params and self._kpn):
            return False
        items = [signals] if isinstance(signals, RobotSignals) else list(signals)
        return bool(items) and all(
            isinstance(s, RobotSignals) and s.columns is not None
            and s.columns.source is not None
            and (self.method != "iv" or s.columns.source.instruments) for s in items)

    def _load_at(self, theta: np.ndarray) -> Callable[[RobotSignals], np.ndarray]:
        """signals -> W_j theta + p_j (n, k) [N m] at ``theta`` (:meth:`load_torque`
        before the fit has one): the load that decides the full-rate quadrants."""
        theta = np.array(theta, dtype=float)

        def load(sig: RobotSignals) -> np.ndarray:
            out = np.full(sig.tau.shape, np.nan)
            for _s, r, q, dq, ddq, tau, _z, pay, cc in self._chunks(sig, iv=False):
                W, p, kn = self._rows(q, dq, ddq, tau, pay, None if cc is None else cc[:2])
                for j, cols in enumerate(self.cols_):
                    WjT, pj = self._joint(W, p, kn, j)
                    out[r, j] = theta[cols] @ WjT + pj
            return out

        return load

    def _products_at(self, sig: RobotSignals, theta: np.ndarray) -> RobotSignals:
        """``sig`` carrying the products formed at full rate (``sig.columns.source``) with
        the load at ``theta`` deciding the quadrants and E at ``q_s_``. The source keeps, for
        its last few thetas (:meth:`~ident.robot.design.FullRateSource.cache`, shared by every
        model fitted on these signals: a q_s scan's fits start from the same usual fit), the
        q_s-free part and the products of the last q_s, so that another q_s
        (:func:`~ident.robot.refit.model_at_qs`, a rescan) forms only the E products again."""
        src = sig.columns.source
        iv = self.method == "iv"
        key = (np.asarray(theta, dtype=float).tobytes(), self.base_.columns.tobytes()
               if hasattr(self.base_.columns, "tobytes") else tuple(self.base_.columns), iv)
        cache, formed = src.cache(key)
        qb = np.asarray(self.q_s_, dtype=float).tobytes()
        prod = formed.get(qb)
        if prod is None:
            prod = src.products(sig, self._load_at(theta), np.array(self.q_s_, dtype=float),
                                base=self.base_, instruments=iv, cache=cache).columns.products
            formed.clear()
            formed[qb] = prod
        return replace(sig, columns=replace(sig.columns, products=prod))

    def _rows_pass(self, signals: Any, theta: np.ndarray) -> tuple[list[RowMoments], int, int]:
        """The full-rate products' rows of every joint (:meth:`_pass_rows`) with the
        quadrants of the load at ``theta``; returns the moments, the rows used and how many
        rows' low-passed P+ moved since the previous such pass (0 at the first)."""
        items = [signals] if isinstance(signals, RobotSignals) else list(signals)
        prods = [self._products_at(s, theta) for s in items]
        k = len(self.cols_)
        in_band, considered = np.zeros(k), np.zeros(k)
        for i, s in enumerate(prods):
            band = self._full_band(s)
            if band is None:
                continue
            ok = s.columns.keep & (np.abs(s.dq) > self.dq_min) & np.isfinite(s.tau)
            considered += ok.sum(axis=0)
            in_band += (ok & ~band).sum(axis=0)
            prods[i] = replace(s, columns=replace(s.columns, keep=s.columns.keep & band))
        # the share of each joint's rows the band leaves out (band_share_, as _pass's)
        self._pass_band_share = in_band / np.maximum(considered, 1)
        moms = self._pass_rows(prods)
        pp = [p.columns.products.pplus for p in prods]
        prev = self._fr_pp
        changed = 0 if prev is None else sum(
            int(np.count_nonzero(np.abs(a - b) > 1e-9)) for a, b in zip(pp, prev, strict=True))
        self._fr_pp = pp
        return moms, sum(m.n for m in moms), changed

    def _full_band(self, sig: RobotSignals) -> np.ndarray | None:
        """The rows (n, k) of ``sig`` outside the quadrant band at full rate
        (:meth:`~ident.robot.design.FullRateSource.band`: the load of the theta that decided
        the first quadrants, ``band_from_[0]``, against ``band_``; decided once, so no
        hysteresis); None without a band."""
        if getattr(self, "band_from_", None) is None or not np.any(self.band_ > 0):
            return None
        theta = self.band_from_[0]
        key = ("band", theta.tobytes(), np.asarray(self.band_, dtype=float).tobytes())
        _, formed = sig.columns.source.cache(key)
        if "rows" not in formed:
            formed["rows"] = sig.columns.source.band(sig, self._load_at(theta), self.band_)
        return formed["rows"]

    def _banded(self, sig: RobotSignals) -> RobotSignals:
        """``sig`` with the full-rate band's rows (:meth:`_full_band`) out of its ``keep``."""
        rows = self._full_band(sig)
        if rows is None:
            return sig
        return replace(sig, columns=replace(sig.columns, keep=sig.columns.keep & rows))

    def full_rate_signals(self, signals: RobotSignals) -> RobotSignals | None:
        """``signals`` carrying the products formed at full rate as the fitted bilinear paper
        model predicts on them (``full_rate_paper_``: the quadrants of its final theta, as
        :meth:`predict` decides them on the decimated rows, or ``quadrant_theta``; E at
        ``q_s_``); None when the model did not fit on them or ``signals`` cannot form them
        (no ``columns.source``, or not that design's full set of rows: then the decimated
        rows serve, :meth:`predict`)."""
        if not getattr(self, "full_rate_paper_", False) or not self._full_rate_ok(signals):
            return None
        theta = (self.quadrant_theta_ if self.quadrant_theta_ is not None
                 else self.coef_[:self.n_theta_])
        try:
            return self._banded(self._products_at(signals, theta))
        except ProductsTooLarge:
            return None
        except RobotIdentError:  # not the design's rows (a part of them)
            return None

    def _predict_full_rate(self, psig: RobotSignals) -> np.ndarray:
        """:meth:`predict` of the bilinear form on the products formed at full rate."""
        out = np.full(psig.tau.shape, np.nan)
        for _s, r, _q, dq, _ddq, _tau, _z, _pay, cc in self._chunks(psig, iv=False):
            for j in range(len(self.cols_)):
                idx = self._local(j)
                nt = self._nt(j)
                c0 = bilinear_rows_coefficients(self.coef_[idx[:nt]], self.coef_[idx[nt:]], 0,
                                                jacobian=False)[0]
                out[r, j] = c0[:-1] @ self._row_block(cc[6], j, dq[:, j])
        return out

    def _set_band(self, moms: list[JointMoments], theta_q: np.ndarray, model_q: bool) -> None:
        """``band_`` [N m] (``quadrant_band`` x each joint's RMS predicted load with
        ``theta_q``, with model quadrants; else 0), the band the passes leave out, and
        ``band_from_`` = [``theta_q``] (None without a band): the thetas whose load decides
        the band's rows (:meth:`_in_band`)."""
        self.band_ = np.zeros(len(moms))
        self.band_from_ = None
        if model_q and float(self.quadrant_band) > 0:
            self.band_ = float(self.quadrant_band) * self._rms_load(moms, theta_q)
            self.band_from_ = np.array(theta_q, dtype=float)[None, :]
        self._band_h = self.band_

    def _in_band(self, cols: np.ndarray, WjT: np.ndarray, pj: np.ndarray,
                 h: float) -> tuple[np.ndarray, np.ndarray]:
        """The rows of a joint's chunk (columns ``cols``, WjT (nt, m), p_j (m,), band ``h``
        [N m]) the quadrant band leaves out, with hysteresis over the thetas that decided
        the passes' quadrants (``band_from_``, in order): a row enters the band where
        |W_j theta + p_j| < h and leaves it only where it reaches ``BAND_LEAVE`` x h. Returns
        that mask at the last theta and at the one before (the previous decision's; the
        same with one theta), (m,) bool each."""
        return band_out(self.band_from_[:, cols] @ WjT + pj, h)

    def _finish(self, moms: list[JointMoments], coeffs: Coeffs, x: np.ndarray,
                free: np.ndarray, w: np.ndarray, passes: int, it: int,
                quadrant_from: np.ndarray | None) -> RobotModel:
        """The fitted attributes of the final fit ``x`` (weights ``w``) on ``moms``; with
        ``eliminate`` (linear forms) after the single-joint elimination (:meth:`_eliminate`)."""
        self.quadrant_from_ = quadrant_from
        self.band_share_ = self._pass_band_share.copy()
        if not hasattr(self, "_fixed_why"):
            self._fixed_why = {}
        bilinear = coeffs in (paper_coefficients, bilinear_rows_coefficients)
        if self.eliminate and not bilinear:
            x, free, w, it = self._eliminate(moms, coeffs, x, free.copy(), w, it)
        why = self._fixed_why
        self.removed_ = [(n, why[n]) for n in self.fixed_ if n in why]
        self._statistics(moms, coeffs, x, free, w)
        self._condition(moms, coeffs, x, free)
        self.weights_ = w
        self.n_passes_, self.n_iter_ = passes, it
        # Gauss-Newton stopped by its step tolerance (linear forms: always), and the quadrant
        # passes settled (fit's loop: rows no longer moving, or theta no longer)
        why = [] if not bilinear or it < int(self.max_iter) else [
            f"the last Gauss-Newton stopped at max_iter={int(self.max_iter)} with the "
            "parameters still moving"]
        if getattr(self, "_unsettled", ""):
            why.append(self._unsettled)
        self.convergence_ = "; ".join(why)
        self.converged_ = not why
        return self

    def _store_update(self, store: QuadrantStore, theta: np.ndarray, mom: JointMoments) -> int:
        """Re-decide the stored rows at ``theta`` (:meth:`QuadrantStore.update`); returns the
        rows that moved: into another quadrant, or into or out of the quadrant band (where
        both weights are 0), as :meth:`_pass` counts them."""
        before = store.pplus, store.pminus  # update() replaces the arrays, never writes them
        store.update(theta, mom)
        return int(np.count_nonzero((store.pplus != before[0]) | (store.pminus != before[1])))

    def _step_sigma(self, moms, x_prev: np.ndarray, x: np.ndarray, free: np.ndarray,
                    w: np.ndarray) -> float:
        """Largest |x - x_prev| / sigma over the free parameters with a sigma > 0, sigma
        the standard deviations (eq. 15) of the paper fit ``x`` (weights ``w``) on ``moms``;
        inf when they are not defined (no degree of freedom)."""
        cov, *_ = self._covariance(moms, self._paper_cf, x, free, w)
        if cov is None:
            return float("inf")
        sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))[free]
        d = np.abs(x - x_prev)[free]
        ok = np.isfinite(sd) & (sd > 0)
        return float(np.max(d[ok] / sd[ok], initial=0.0))

    def _w_gram(self, moms, coeffs: Coeffs, x: np.ndarray,
                weights: np.ndarray | None = None) -> np.ndarray:
        """J^T J (nx, nx) of the regressor (the Jacobian at ``x``: the regressor itself for a
        linear form) from the moments sum v v^T, whatever the estimator (IDIM-IV's normal
        matrix is Z^T W: not this); with ``weights`` (one per joint, WLS) sum_j w_j J_j^T J_j,
        the normal matrix of LS and WLS."""
        nx = x.size
        G = np.zeros((nx, nx))
        for j, mom in enumerate(moms):
            wj = 1.0 if weights is None else float(weights[j])
            idx = self._local(j)
            nt = self._nt(j)
            th, blk = x[idx[:nt]], x[idx[nt:]]
            for s in (0, 1):
                _, _, D0, D1 = coeffs(th, blk, s)
                D = (D0, D1)
                for e in (0, 1):
                    for f in (0, 1):
                        if np.any(D[e]) and np.any(D[f]):
                            G[np.ix_(idx, idx)] += wj * (D[e].T @ mom.vv[s, e + f] @ D[f])
        return G

    def _condition(self, moms, coeffs: Coeffs, x: np.ndarray, free: np.ndarray) -> None:
        """``cond_``, ``cond_raw_``: the condition numbers of the column-scaled and of the raw
        regressor of the free parameters (as :func:`ident.estimate.solve_ls`' ``cond`` and
        ``cond_raw``: the singular values of R and of R D, R^T R the scaled Gram matrix, D
        the column norms), R here the Cholesky factor of the scaled Gram matrix."""
        G = self._w_gram(moms, coeffs, x)[np.ix_(free, free)]
        d = np.sqrt(np.clip(np.diagonal(G), 0.0, None))
        d = np.where(d > 0, d, 1.0)
        self.cond_ = self.cond_raw_ = float("inf")
        if not G.size:
            return
        try:
            R = scipy.linalg.cholesky(G / d[:, None] / d[None, :], lower=False)
        except np.linalg.LinAlgError:
            return
        for attr, M in (("cond_", R), ("cond_raw_", R * d[None, :])):
            sv = np.linalg.svd(M, compute_uv=False)
            setattr(self, attr, float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf"))

    def _eliminate(self, moms, coeffs: Coeffs, x: np.ndarray, free: np.ndarray,
                   w: np.ndarray, it: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
        """The single-joint elimination (:func:`ident.estimate.fit_least_squares`) on a
        linear form's fit ``x``: the free parameters whose columns are zero or dependent (the
        rank rule, :func:`ident.estimators.rank_rule` on their Gram matrix; the reason names
        the partners) are fixed at 0, then, while the largest relative deviation of a free
        parameter exceeds ``threshold_pct``, that one is fixed at 0 and the model refitted.
        Each goes to ``fixed_`` (at 0) and ``removed_`` (name, reason). Returns the final (x,
        free, weights, iterations)."""
        thr = float(self.threshold_pct)
        dep = self._rank_fix(moms, coeffs, x, free, w)
        for i, why in dep:
            self._drop(i, why, free, x)
        if dep:
            try:
                x, w, it = self._fit_on(moms, coeffs, x, free, linear=True)
            except _Unidentifiable as e:
                raise RobotIdentError(self._evidence(e, moms)) from None
        while int(free.sum()) > 1:
            self._statistics(moms, coeffs, x, free, w)
            rel = np.where(free, self.rel_std_, -np.inf)
            k = int(np.argmax(rel))
            if not rel[k] > thr:
                break
            self._drop(k, f"not significant: relative deviation {rel[k]:.3g} % > {thr:g} %",
                       free, x)
            try:
                x, w, it = self._fit_on(moms, coeffs, x, free, linear=True)
            except _Unidentifiable as e:
                raise RobotIdentError(self._evidence(e, moms)) from None
        return x, free, w, it

    def _rank_fix(self, moms, coeffs: Coeffs, x: np.ndarray, free: np.ndarray,
                  weights: np.ndarray | None = None) -> list[tuple[int, str]]:
        """The rank rule of the n-dof fit on the normal matrix of the free parameters at ``x``
        (``weights``: the joints' WLS weights; None: ones), with the criterion and tolerance
        of the solver's refusal (``Estimator.solve_normal``): the column-scaled matrix is
        rank deficient when lambda_min <= RANK_TOL lambda_max (RANK_TOL = RCOND^2: a
        singular value of the unit-norm regressor at most RCOND sigma_max; RCOND = 1e-6,
        relative to the columns' scale, so independent of the units, and RANK_TOL = 1e-12
        well above the rounding of the summed moments, ~b * 1e-16 for b columns). Returns
        the free parameters whose columns are zero, dependent or nearly dependent, each with
        its reason (the partners named), such that the kept columns pass that test; changes
        nothing but ``_near_evidence`` (the columns step 2 left out and the cond, or ""). It
        names nothing only when the matrix passes, or when the dependence is spread so that
        no column alone lies within RCOND sigma_max of the others' span (then the caller's
        refusal stands, naming the weakest direction and the cond).

        1. :func:`ident.estimators.rank_rule` (the pivoted Cholesky of the single-joint fit,
           unchanged): a column whose residual on the columns pivoted before it is at most
           RCOND (zero and exactly dependent columns). Each such drop is one the criterion
           calls for: the pivot bounds lambda_min from above and lambda_max >= 1.
        2. While the kept columns still fail the criterion (a near-dependence the greedy
           pivots miss: the real KUKA KR300 at trim 73, MY4R and MY6 nearly collinear on
           A4's rows at cond 6.2e13, smallest pivot 7.3e-13 after the first columns taken
           in their order), the column of the weakest eigenvector v with the largest
           |v_i| (:func:`_near_dependent`): it lies within sqrt(lambda_min) / |v_i| of the
           others' span (||W_s v|| = sqrt(lambda_min)) and is taken when that is at most
           RCOND sigma_max; a later column (friction, payload) before a base parameter, as
           in step 1. Its partners: the columns whose coefficients -v_k / v_i exceed
           :data:`ident.estimators.PARTNER_TOL` times the largest.

        Base parameters are pivoted first where ``x`` holds them (the usual form); the
        products form holds none (its payload column's products are left out by the load
        columns' own rule), so its columns are pivoted in their order, as the single-joint
        least squares pivots its design's columns (the offset last: of c_m, c_g and the
        offset made dependent by a load of one sign, the offset is left out there too)."""
        idx = np.flatnonzero(free)
        G = self._w_gram(moms, coeffs, x, weights)[np.ix_(idx, idx)]
        first = int(np.sum(idx < self.n_base_)) if self._theta_x else 0
        self._near_evidence = ""
        dep, partners = rank_rule(G, first=first)
        d = np.sqrt(np.clip(np.diagonal(G), 0.0, None))
        if np.all(np.isfinite(G)) and (d > 0).any():
            kept = np.setdiff1d(np.flatnonzero(d > 0), dep)
            ds = np.where(d > 0, d, 1.0)
            near, cond = _near_dependent(G / ds[:, None] / ds[None, :], kept, first)
            dep = np.array(sorted([*dep.tolist(), *near]), dtype=int)
            partners.update(near)
            if near:
                self._near_evidence = (
                    f"the rank rule left out {', '.join(self.names_[idx[k]] for k in near)} as "
                    f"nearly dependent (scaled normal matrix cond {cond:.2g} > 1 / RANK_TOL "
                    f"= {1 / RANK_TOL:.0e} after the pivoted columns)")
        out = [(int(idx[k]), ZERO_COLUMN if not G[k, k] > 0 else dependent_reason(
            [self.names_[idx[q]] for q in partners[k]])) for k in dep]
        if self._estimator.needs_instruments:  # IDIM-IV: the rule on what it solves
            A, _, _, C, _ = self._normal(moms, coeffs, x, np.ones(len(moms)))
            kept = np.setdiff1d(np.arange(idx.size), dep)
            sub = np.ix_(idx[kept], idx[kept])
            out += [(int(idx[kept[k]]), why) for k, why in self._estimator.rank_drops(
                G[np.ix_(kept, kept)], [self.names_[i] for i in idx[kept]], A=A[sub],
                C=C[sub], first=int(np.sum(kept < first)))]
        return sorted(out)

    def _payload_groups(self, signals: Any) -> None:
        """``payload_params``: the distinct payload masses of the experiments
        (``payload_masses_`` [kg]); errors when no experiment carries a payload or every one
        does (then its columns are the last link's: not separable)."""
        items = [signals] if isinstance(signals, RobotSignals) else list(signals)
        masses: list[float] = []
        empty = False
        for sig in items:
            if not isinstance(sig, RobotSignals):
                continue
            for e in np.unique(sig.experiment):
                m = float(sig.payloads[int(e)].mass)
                if m > 0 and m not in masses:
                    masses.append(m)
                empty |= not m > 0
        if not masses:
            raise RobotIdentError("RobotModel.payload_params: no experiment carries a payload "
                                  "(mass > 0): nothing to identify")
        if not empty and len(masses) > 1:
            raise RobotIdentError(f"RobotModel.payload_params: every experiment carries a "
                                  f"payload ({masses} kg), so their parameters are not "
                                  "separable from the last link's (their columns are that "
                                  "link's); add an experiment without payload")
        # one payload in every experiment: its columns are the last link's own, so its
        # first moments and inertia merge into the last link's base parameters (only its
        # mass at the flange origin is subtracted)
        self.payload_merged_ = not empty
        self.payload_masses_ = tuple(masses)

    @property
    def _coefficients(self) -> Coeffs:
        """The coefficient function of the fitted model and form (:mod:`ident.robot.paper`)."""
        if self.model == "usual":
            return usual_coefficients
        if self.form == "products":
            return products_coefficients
        return (bilinear_rows_coefficients if getattr(self, "full_rate_paper_", False)
                else paper_coefficients)

    def _check_fitted(self) -> None:
        if not hasattr(self, "coef_"):
            raise RobotIdentError("RobotModel is not fitted; call fit(signals) first")

    def _fitted_rows(self, signals: RobotSignals, what: str, instruments: bool = False):
        """Check ``signals``, then a generator of (rows, j, cols, WjT, pj, dq_j, tau_j, sign
        column or None) per chunk and joint (no instruments): the pass of :meth:`predict`
        and :meth:`load_torque`. ``instruments``: one more item, (WzT, pz_j), the IDIM-IV
        instruments' columns and known torque as :meth:`_pass` forms them (the columns'
        ``Wz``, ``pz``, or the regressor on the reference's acceleration; the same errors
        when the signals lack them)."""
        self._check_fitted()
        if not isinstance(signals, RobotSignals):
            raise RobotIdentError(f"{what}: expected RobotSignals, got "
                                  f"{type(signals).__name__}")

        def rows():
            for sig, r, q, dq, ddq, tau, zdd, pay, cc in self._chunks(signals,
                                                                      iv=instruments):
                sgn = self._sign(sig, r, cc)
                W, p, kn = self._rows(q, dq, ddq, tau, pay, None if cc is None else cc[:2])
                if instruments:
                    Wz, pz, knz = self._rows(q, dq, zdd, tau, pay,
                                             None if cc is None else cc[4:6])
                for j, cols in enumerate(self.cols_):
                    WjT, pj = self._joint(W, p, kn, j)
                    item = (r, j, cols, WjT, pj, dq[:, j], tau[:, j],
                            None if sgn is None else sgn[:, j])
                    yield (item + (self._joint(Wz, pz, knz, j),)) if instruments else item

        return rows()

    def predict(self, signals: RobotSignals) -> np.ndarray:
        """Predicted joint torques tau_hat (n, k) [N m] on the samples of ``signals``."""
        if getattr(self, "full_rate_products_", False):
            return self._predict_rows(signals)
        psig = self.full_rate_signals(signals)
        if psig is not None:
            return self._predict_full_rate(psig)
        if self.quadrants == "soft":
            return predict_soft(self, signals)
        passes = self._fitted_rows(signals, "predict")
        out = np.full(signals.tau.shape, np.nan)
        coeffs = self._coefficients
        if not self._theta_x:  # products: the quadrants of the fit (the usual fit's theta)
            theta = self.quadrant_from_
        else:
            theta = self.coef_[:self.n_theta_]
        if self.quadrant_theta_ is not None:
            theta = self.quadrant_theta_
        for r, j, cols, WjT, pj, dqj, tauj, sg in passes:
            idx = self._local(j)
            nt = self._nt(j)
            th, blk = self.coef_[idx[:nt]], self.coef_[idx[nt:]]
            V = self._v(WjT, pj, dqj, np.zeros(dqj.size), sg).T
            if self.quadrant == "model" or self.model == "usual":
                sp = (theta[cols] @ WjT + pj) * dqj
            else:
                sp = tauj * dqj
            E = stribeck_exp(dqj, self.q_s_[j])
            pred = np.zeros(dqj.size)
            for s, ws in enumerate(quadrant_weights(sp)):
                c0, c1, _, _ = coeffs(th, blk, s)
                pred += ws * (V @ c0 + E * (V @ c1))
            out[r, j] = pred
        return out

    def _predict_rows(self, signals: RobotSignals) -> np.ndarray:
        """:meth:`predict` of a fit on the full-rate products: u_j^T x_j on the products the
        signals carry (their quadrants: the model has no theta to decide others)."""
        self._check_fitted()
        if not isinstance(signals, RobotSignals):
            raise RobotIdentError(f"predict: expected RobotSignals, got "
                                  f"{type(signals).__name__}")
        if signals.columns is None or signals.columns.products is None:
            raise RobotIdentError(f"{signals.source or 'RobotSignals'}: the model was fitted "
                                  "on full-rate products (columns.products); predict needs "
                                  "signals carrying them (products_columns)")
        self._full_rate(signals)  # the same checks as the fit's
        out = np.full(signals.tau.shape, np.nan)
        for _sig, r, _q, dq, _ddq, _tau, _z, _pay, cc in self._chunks(signals, iv=False):
            for j in range(len(self.cols_)):
                out[r, j] = self.coef_[self._local(j)] @ self._row_block(cc[6], j, dq[:, j])
        return out

    def fitted_rows(self, signals: RobotSignals) -> np.ndarray:
        """Which samples of ``signals`` the fit's row rule takes into each joint's rows,
        shape (n, k) bool: |dq_j| > ``dq_min``, finite torque and regressor, the columns'
        ``keep`` mask, and (paper model, model quadrants) outside the quadrant band as the
        passes left it (|tau_out_hat_j| against ``band_[j]`` with the hysteresis over
        ``band_from_``, :meth:`_in_band`) -- the rows ``rel_error_`` is measured on."""
        passes = self._fitted_rows(signals, "fitted_rows")
        out = np.zeros(signals.tau.shape, dtype=bool)
        keep = None if signals.columns is None else signals.columns.keep
        psig = self.full_rate_signals(signals)
        if psig is not None:  # the full-rate products' rows, their band (keep) included
            for r, j, _fr, _dq, _tau, _U, ok in self._row_chunks(psig):
                out[r, j] = ok
            return out
        for r, j, cols, WjT, pj, dqj, tauj, _sg in passes:
            out[r, j] = self._row_rule(j, cols, WjT, pj, dqj, tauj,
                                       None if keep is None else keep[r, j])
        return out

    def _row_rule(self, j: int, cols: np.ndarray, WjT: np.ndarray, pj: np.ndarray,
                  dqj: np.ndarray, tauj: np.ndarray, keep: np.ndarray | None) -> np.ndarray:
        """Joint j's rows of a chunk after the fit (:meth:`fitted_rows`, the n-dof refit's
        rows): :meth:`_usable`, and outside the quadrant band as the passes left it
        (:meth:`_in_band` over ``band_from_``); shape (m,)."""
        ok = self._usable(dqj, tauj, WjT, keep)
        band = float(np.asarray(getattr(self, "band_", np.zeros(len(self.cols_))))[j])
        if band > 0 and getattr(self, "band_from_", None) is not None:
            ok &= ~self._in_band(cols, WjT, pj, band)[0]
        return ok

    def quadrant_drift(self, signals: RobotSignals) -> np.ndarray:
        """Per joint, the share of its fitted rows (:meth:`fitted_rows`) whose model quadrant
        sign(tau_out_hat dq) with the final theta differs from the one the fit used
        (``quadrant_from_``), shape (k,); zeros without model quadrants. Above
        :data:`QUADRANT_TOL` the joint's ``rel_error_`` is not the error of the fitted
        parameters on their own quadrants (what :meth:`predict` gives): the quadrant passes
        stopped before the fit settled (``converged_`` False: Gauss-Newton at ``max_iter``, or
        the passes at ``max_passes``). Rows the final theta would move into or out of the band
        are not counted: :meth:`predict` uses no band."""
        k = len(self.cols_)
        out = np.zeros(k)
        if (self.quadrant_from_ is None or not self._theta_x or self.quadrant_theta_ is not None
                or self.quadrants == "soft"):  # (soft: no hard quadrant to drift from)
            return out
        rows = self.fitted_rows(signals)
        theta, used = self.coef_[:self.n_theta_], self.quadrant_from_
        changed = np.zeros(k)
        for r, j, cols, WjT, pj, dqj, _tau, _sg in self._fitted_rows(signals, "quadrant_drift"):
            ok = rows[r, j]
            now = np.sign((theta[cols] @ WjT + pj) * dqj)
            then = np.sign((used[cols] @ WjT + pj) * dqj)
            changed[j] += np.count_nonzero((now != then) & ok)
        n = rows.sum(axis=0)
        return np.where(n > 0, changed / np.maximum(n, 1), 0.0)

    def load_torque(self, signals: RobotSignals) -> np.ndarray:
        """tau_out_hat (n, k) [N m]: the rigid-body, rotor and payload torque of the fitted
        model, W_j theta + p_j (the load of eq. 17-30, before friction), on ``signals``."""
        passes = self._fitted_rows(signals, "load_torque")
        require_theta(self, "RobotModel.load_torque")
        out = np.full(signals.tau.shape, np.nan)
        theta = self.coef_[:self.n_theta_]
        for r, j, cols, WjT, pj, _dq, _tau, _sg in passes:
            out[r, j] = theta[cols] @ WjT + pj
        return out

    def residual(self, signals: RobotSignals) -> np.ndarray:
        """rho = tau - tau_hat (n, k) [N m]."""
        return signals.tau - self.predict(signals)

    def rel_error(self, signals: RobotSignals | Sequence[RobotSignals]) -> dict[str, float]:
        """||rho_j|| / ||tau_j|| per joint and ``"all"`` on ``signals`` (Table III, all);
        samples with a non-finite torque (left out of the fit) are ignored."""
        items = [signals] if isinstance(signals, RobotSignals) else list(signals)
        k = len(self.joints_)
        r2, y2 = np.zeros(k), np.zeros(k)
        for sig in items:
            rho = self.residual(sig)
            ok = np.isfinite(rho)
            r2 += (np.where(ok, rho, 0.0) ** 2).sum(0)
            y2 += (np.where(ok, sig.tau, 0.0) ** 2).sum(0)
        out = {n: float(np.sqrt(r2[j] / y2[j])) for j, n in enumerate(self.joints_)}
        out["all"] = float(np.sqrt(r2.sum() / y2.sum()))
        return out

    def score(self, signals: RobotSignals | Sequence[RobotSignals]) -> float:
        """1 - ||rho|| / ||tau|| over all joints (as ``ident.api.JointModel.score``)."""
        return 1.0 - self.rel_error(signals)["all"]

    def truth_vector(self, std_values: Mapping[str, float]) -> np.ndarray:
        """Map true standard parameters and friction (ROBOT_FORMAT names) onto ``names_``:
        base parameters through ``base_.beta``, friction by name (``FC{j}`` of the usual model
        is not a paper parameter and is NaN). ``form="products"``: the true products (a_m
        theta_i, b_m theta_i, ... of each base column, a_m ... of the payload torque, then
        the true c, d, FV, OFF); NaN where a column's true value is not known (the payload's
        base parameters of ``payload_params``)."""
        self._check_fitted()
        std_names = tuple(self.regressor_.standard_names)
        s = np.array([float(std_values.get(n, 0.0)) for n in std_names])
        out = np.full(len(self.names_), np.nan)
        theta = np.asarray(self.base_.beta, dtype=float) @ s
        if not self._theta_x:
            th = np.full(self.n_theta_, np.nan)
            th[:self.n_base_] = theta
            for j, (cols, n) in enumerate(zip(self.cols_, self.numbers_, strict=True)):
                f = [float(std_values.get(f"{p}{n}", np.nan)) for p in PAPER_BLOCK]
                load = np.r_[th[cols], 1.0]
                nl = load.size
                blk = np.empty(4 * nl + 6)
                blk[0:2 * nl:2], blk[1:2 * nl:2] = f[0] * load, f[1] * load
                blk[2 * nl:4 * nl:2], blk[2 * nl + 1:4 * nl:2] = f[2] * load, f[3] * load
                blk[4 * nl:] = f[4:]
                out[self._local(j)] = blk
            return out
        out[:self.n_base_] = theta
        for i, name in enumerate(self.names_[self.n_base_:], start=self.n_base_):
            if name in std_values:
                out[i] = float(std_values[name])
        return out
