"""Refinement loop: diagnose the residual, add the effect it points to, refit, repeat.

This automates the paper's own method (section III): the usual model's residual at low
velocity and varying load points to the load- and velocity-dependent dry friction.

One step of :func:`refine`:

1. fit the current library on the design (least squares, eq. 12, no elimination) and
   diagnose its residual against the seven candidate variables (:mod:`ident.diagnose`);
2. score every candidate effect (:mod:`ident.effects`) by the residual sum of squares it
   removes, with its nonlinear hyper-parameter (ripple period, q_s, T_w) scanned then
   refined by a 1-D bounded search; a generic basis in each significantly implicated
   continuous variable competes, and is chosen only when it removes clearly more than
   every named effect (named effects win within :data:`GENERIC_MARGIN`);
   with ``library=True`` (default) the interaction diagnosis and the library search
   (:mod:`ident.refine_library`) offer one more candidate, named when it matches a physical
   form (:mod:`ident.describe`), and the generic bases compete on the held-out (blocked
   cross-validation) error; a registered effect that explains as much as the library's
   named form (:data:`ident.describe.MATCH_SHARE`) keeps its place ahead of it;
3. accept the best candidate only if (a) the nested-model F test, with the effective
   sample size of the noise left after the candidate and one extra degree of freedom per
   scanned hyper-parameter, rejects "noise only" at level ``alpha`` / number of candidates,
   (b) it lowers the relative error by at least ``min_gain`` (relative), (c) with the
   library search, it lowers the held-out error (a basis: by ``min_gain``), and (d) where
   validation data exist, it lowers the validation relative error too (up to three bases
   that pass are then compared on it), and (e) a torque lag passes (b) again with its
   column on the motion band (:class:`_MotionPart`: the applied-torque noise the measured
   motion carries is also in the residual); otherwise the next best candidate is tried (at
   most ``max_tries``);
4. add the term (:meth:`~ident.preprocess.Design.with_term`: columns filtered and decimated
   like the others), refit, report; stop when nothing is accepted or after ``max_steps``.

The candidates come from the effect modules of :mod:`ident.effects`, asked in registry
order; the results (:class:`Step`, :class:`Rejected`, :class:`Refinement`) are in
:mod:`ident.refine_result`.

Pure numerics (no file access); plots are in :mod:`ident.refine_plots`.

(Past 600 lines: :func:`refine` is one loop whose steps share the current library, design,
noise floor, held-out scores and rejection list; the helpers above it are its scoring, F test
and refits, used nowhere else. The step and report types are already in
:mod:`ident.refine_result`.)
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np
from scipy import stats

from . import DataError
from .chain import choose_cutoff, lowpass
from .describe import MATCH_SHARE, name_torque_lag
from .diagnose import Diagnosis, diagnose
from .effects import (
    Candidate,
    Columns,
    Context,
    Effect,
    Scorer,
    Setting,
    TorqueLag,
    effective_n,
    model_quadrant,
    registry,
    rigid_prediction,
    unique_tag,
)
from .effects.torque_lag import time_derivative
from .models import IdentModel
from .refine_library import LibraryStep, library_step
from .refine_lsq import quick_residual
from .refine_result import Refinement, Rejected, Step, _pct
from .signals import Signals
from .terms import Library, Term
from .unseen import LEAK_RATIO, heldout_error, heldout_kind, noise_floor, one_trajectory

if TYPE_CHECKING:  # pragma: no cover
    from .preprocess import Design

__all__ = ["GENERIC_MARGIN", "Refinement", "Rejected", "Step", "quadrant_drift", "refine"]

#: A named effect is preferred to a generic basis when it removes at least this share of
#: what the best generic basis removes.
GENERIC_MARGIN = 0.5

#: Effects that are eq. 24's load-dependent dry friction (the paper model's, or a step's): a
#: model holding one is not offered the library's named form of it again.
LOAD_DEPENDENT = ("load_dependent", "quadrant_load", "quadrant_load_velocity")
#: Declared terms whose columns read the quadrant fixed in the design (``Signals.sign_power``):
#: the paper model's load-dependent and quadrant-dependent dry friction (eq. 42).
FIXED_QUADRANT = ("load_dependent", "quadrant_coulomb")


# ------------------------------------------------------------------------ scoring
def _unscaled(design: Design) -> Signals:
    """``design.signals`` (kept for :mod:`ident.refine_plots`). The decimation filter has unit
    DC gain (:func:`ident.preprocess.decimate`), so the decimated q, dq, ddq, tau need no
    rescaling before nonlinear functions of them are evaluated."""
    return design.signals


def _candidates(
    cols: Columns,
    diag: Diagnosis,
    lib: Library,
    coef: dict[str, float],
    alpha: float,
    generic_knots: int,
) -> list[Candidate]:
    """Every registered effect module's candidates, in registry order
    (:func:`ident.effects.registry`)."""
    ctx = Context(cols, diag, lib, coef, alpha, generic_knots)
    out: list[Candidate] = []
    for reg in registry():
        out.extend(reg.propose(ctx))
    return out


def _f_test(rss0: float, rss1: float, k: int, p: int, n: int, n_eff: float) -> tuple[float, float]:
    """Nested-model F test, degrees of freedom from the effective sample size."""
    d2 = max(min(n_eff, n) - p - k, 1.0)
    if rss1 <= 0 or k < 1:
        return float("inf"), 0.0
    if rss1 >= rss0:  # the larger model fits no better (its rows or q_s differ): no evidence,
        return 0.0, 1.0  # and an F statistic is never negative
    F = ((rss0 - rss1) / k) / (rss1 / max(n - p - k, 1)) * (min(n_eff, n) / n)
    return float(F), float(stats.f.sf(F, k, d2))


def _best_band_gain(before: dict[str, float], after: dict[str, float], rel0: float,
                    rel1: float) -> float:
    """Largest relative decrease of the relative error, overall or in a velocity band."""
    gains = [1.0 - rel1 / rel0 if rel0 > 0 else 0.0]
    for band in ("low", "high"):
        b, a = before.get(band, math.nan), after.get(band, math.nan)
        if math.isfinite(b) and math.isfinite(a) and b > 0:
            gains.append(1.0 - a / b)
    return max(gains)


def _pretest(
    c: Candidate,
    rss0: float,
    p: int,
    n: int,
    n_eff: float,
    rel: float,
    level: float,
    min_gain: float,
) -> str | None:
    """Acceptance tests predicted from the scoring gain; the reason of a failure or None."""
    k_fast = len(c.effect.names()) + c.n_hyper
    F0, p0 = _f_test(rss0, rss0 - c.gain, k_fast, p, n, max(n_eff, c.n_eff))
    rel_fast = rel * math.sqrt(max(rss0 - c.gain, 0.0) / rss0) if rss0 > 0 else rel
    if p0 >= level:
        return (f"F test not significant (F={F0:.3g}, p={p0:.2e} >= level {level:.2g}: "
                "alpha / candidates)")
    if rel_fast > rel * (1 - min_gain):
        return (
            f"relative error {_pct(rel)} -> {_pct(rel_fast)}: less than {100 * min_gain:g} % better"
        )
    return None


def _effect_parameters(
    term: Effect, model: IdentModel, design: Design, all_coef: dict[str, float]
) -> dict[str, dict[str, float]]:
    """Term parameters with 2σ; hyper-parameters via the linearised model (Jacobian column
    d(W_term χ_term)/dh appended to the kept regressor), raised to the term's block
    jackknife where it makes one (:meth:`~ident.effects.Effect.jackknife`: the ripple)."""
    names = list(model.names_)
    tnames = [n for n in term.names() if n in model.coef_]
    s = design.signals.states()
    W = design.W[:, [design.names.index(n) for n in names]]
    extra = []
    if term.hyper_names and len(tnames) == len(term.names()):
        c = np.array([model.coef_[n] for n in term.names()])
        for h in term.hyper_names:
            h0 = getattr(term, h)
            dh = 1e-6 * h0
            up = term.with_hyper(**{h: h0 + dh}).columns(s) @ c
            dn = term.with_hyper(**{h: h0 - dh}).columns(s) @ c
            extra.append((up - dn) / (2 * dh))
    A = np.column_stack([W, *extra]) if extra else W
    norms = np.linalg.norm(A, axis=0)
    norms = np.where(norms > 0, norms, 1.0)
    As = A / norms
    n, p = A.shape
    rss = float(model.residual_ @ model.residual_)
    sigma2 = rss / max(n - len(names), 1)
    try:
        cov = sigma2 * np.linalg.pinv(As.T @ As) / np.outer(norms, norms)
    except np.linalg.LinAlgError:  # pragma: no cover
        cov = np.full((p, p), np.nan)
    idx = [names.index(n) for n in tnames] + list(range(len(names), p))
    coef = np.array(
        [model.coef_[n] for n in tnames]
        + [getattr(term, h) for h in (term.hyper_names if extra else ())]
    )
    sub = cov[np.ix_(idx, idx)]
    if len(tnames) < len(term.names()):
        # some columns were dropped as unidentifiable: report what is left as it is
        sd = np.sqrt(np.clip(np.diag(sub), 0, None))
        return {
            n: {"value": float(v), "std2": float(2 * d)}
            for n, v, d in zip(tnames, coef, sd, strict=False)
        }
    par = term.parameters(coef, sub)
    # the honest 2σ: the larger of the linearised one and the block jackknife's (the scan
    # redone per replicate, Effect.jackknife), as the robot fit's sigma
    jack = term.jackknife(design, names) or {}
    out = {k: {"value": float(v), "std2": max(float(e), jack.get(k, 0.0))}
           for k, (v, e) in par.items()}
    out.update(term.extra_parameters(all_coef, names, cov, out))
    return out


def _bands(model: IdentModel, design: Design, vmax: float | None) -> dict[str, float]:
    try:
        return model.rel_error_bands(design, vmax)
    except Exception:  # noqa: BLE001 - bands are informative only
        return {"all": model.rel_error_on(design), "low": float("nan"), "high": float("nan")}


def _fit(lib: Library, design: Design, name: str) -> IdentModel:
    return IdentModel(lib, name).fit(design, eliminate=False, drop_unidentifiable=True)


class _Refit:
    """The exact refit of a candidate (:func:`_fit` of ``lib`` on ``design``), its residual
    first: ``residual_``, ``rel_error_`` and ``names_`` from
    :func:`ident.refine_lsq.quick_residual` (the same floats as the fit's), the fitted
    :class:`~ident.models.IdentModel` by :meth:`model` when a test needs more (most
    rejected candidates fail the F test on the residual alone). When the fit would drop a
    column, the model is fitted at once."""

    def __init__(self, lib: Library, design: Design, name: str) -> None:
        self.lib, self.design, self.name = lib, design, name
        self._model: IdentModel | None = None
        names = lib.names()
        missing = [n for n in names if n not in design.names]
        quick = None
        if not missing:
            idx = [design.names.index(n) for n in names]
            quick = quick_residual(design.W[:, idx], design.Y,
                                   None if design.Z is None else design.Z[:, idx])
        if quick is None:
            m = self.model()
            self.residual_, self.rel_error_, self.names_ = m.residual_, m.rel_error_, m.names_
        else:
            self.residual_, self.rel_error_, self.names_ = quick[1], quick[2], tuple(names)

    def model(self) -> IdentModel:
        if self._model is None:
            self._model = _fit(self.lib, self.design, self.name)
        return self._model


def _library_variables(lstep: LibraryStep) -> tuple[str, ...]:
    """Variables of the selected library group, then its modifier (if any)."""
    g = lstep.group
    return g.variables + (() if g.modifier == "none" else (g.modifier,))


def _cycle(design: Design) -> float | None:
    """Raw sampling period of the design's first run [s]."""
    try:
        t = design._blocks[0].sub.t
    except (AttributeError, IndexError):
        return None
    return float(np.median(np.diff(t))) if t.shape[0] > 1 else None


def _setting(design: Design, cycle_s: float | None = None) -> Setting:
    """Sampling period (``cycle_s`` when given, else :func:`_cycle`), longest run and
    excitation time scale of the design's data."""
    s = design.signals
    run_s = 0.0
    gaps = []
    for e in np.unique(s.experiment):
        m = s.experiment == e
        t, dq = s.t[m], s.dq[m]
        if t.size:
            run_s = max(run_s, float(t.max() - t.min()))
        sg = np.sign(dq)
        flips = t[1:][(sg[1:] != sg[:-1]) & (sg[1:] != 0)]
        if flips.size >= 2:
            gaps.append(np.diff(flips))
    exc = float(np.median(np.concatenate(gaps))) if gaps else 0.0
    return Setting(cycle_s or _cycle(design), run_s, exc)


def _naming(
    e: Effect,
    c: Candidate,
    lstep: LibraryStep | None,
    parameters: dict[str, dict[str, float]],
    design: Design,
    cycle_s: float | None = None,
) -> tuple[str | None, str, str | None]:
    """Named effect, one-line structure and the physical-range verdict (None: in range) of
    an accepted candidate. A named effect whose parameters leave the range where its physics
    holds is reported as the generic structure of its variables, with the reason."""
    out_of_range = e.physical_range(parameters, _setting(design, cycle_s))
    if out_of_range is not None:
        kind = "time-derivative of the model" if isinstance(e, TorqueLag) else e.variable
        return (None, f"a term in {kind} ({e.describe()}), not named {e.effect}: "
                f"outside its physical range: {out_of_range}", out_of_range)
    if lstep is not None and lstep.candidate is not None and (
        e is lstep.candidate or e.effect == lstep.candidate.effect
    ) and lstep.description is not None:
        return lstep.description.name, lstep.description.sentence, None
    if isinstance(e, TorqueLag):
        key = next((k for k in parameters if k.startswith("T_lag")), None)
        if key is not None:
            return (*name_torque_lag(parameters[key]["value"], parameters[key]["std2"],
                                     cycle_s or _cycle(design)), None)
    return (None if c.generic else e.effect), e.describe(), None


def _scored(c: Candidate, rel: float, rss0: float, floor: float) -> str:
    """The relative error a candidate's scoring predicts, for the short-list line: an estimate
    below the noise floor (the scoring's projection assumes a least-squares residual; an IV
    residual is not orthogonal to the regressor) is shown as such, not as a result."""
    est = rel * math.sqrt(max(1 - c.gain / rss0, 0)) if rss0 > 0 else rel
    if math.isfinite(floor) and est < floor:
        return f"(scored below the noise floor {_pct(floor)}: leak? the exact refit decides)"
    return _pct(est)


def _kept(design: Design, model: IdentModel) -> np.ndarray:
    return design.W[:, [design.names.index(n) for n in model.names_]]


def quadrant_drift(design: Design, lib: Library, coef: Mapping[str, float]) -> float | None:
    """Share of the design's rows whose quadrant sign(P), fixed in its columns when it was
    built (``Signals.quadrant``: the load model of a first usual fit, ``build_design``'s
    ``load_model``), differs from the model's own, sign(τ̂_out q̇) of
    :func:`~ident.effects.rigid_prediction` with ``coef``.

    A share above 0 means the fit has not settled on its quadrants (the robot refit's
    ``quadrant_drift``): on those rows the declared model's quadrant-dependent friction acts
    with the other quadrant's coefficients, and a term the refinement adds may stand in for
    that instead of an effect of the joint.

    Parameters
    ----------
    design : Design
        The design the model is fitted on (its blocks' full-rate signals and rows).
    lib : Library
        The model's library.
    coef : mapping of str to float
        The model's coefficients.

    Returns
    -------
    float or None
        The share in [0, 1]; None where no quadrant was fixed (a design built without a load
        model), the library has no term whose columns read it (:data:`FIXED_QUADRANT`: the
        usual model has none) or the model has no load prediction.
    """
    if not any(t.effect in FIXED_QUADRANT for t in lib.terms()):
        return None
    pred = rigid_prediction(lib, dict(coef))
    if pred is None:
        return None
    blocks = getattr(design, "_blocks", None) or ()
    if not blocks:
        return None
    n = moved = 0
    for b in blocks:
        if b.full.quadrant is None:
            return None
        rows = b.index[b.mask]
        full = b.full.take(rows)
        own = model_quadrant(full.states(), pred)
        moved += int(np.count_nonzero(own != full.quadrant))
        n += rows.size
    return moved / n if n else None


class _MotionPart(Term):
    """The torque-lag candidate's column on the band of the motion: d/dt of the model
    prediction after a zero-phase low-pass (:func:`ident.chain.lowpass`) at ``cutoff_hz``
    [Hz], per experiment, on full-rate or decimated states alike.

    The lag's own column, dτ̂/dt on the measured (filtered) motion, also carries the torque
    noise that moved the joint: in closed loop the applied-torque noise is in the residual
    and, through the measured acceleration, in dτ̂/dt (its derivative, the jerk, is
    broadband). That shared noise correlates the two whatever the joint does; its motion
    band does not (see :func:`_motion_check`)."""

    effect = "torque_lag"
    variable = "acceleration"

    def __init__(self, lag: TorqueLag, cutoff_hz: float) -> None:
        self.lag, self.cutoff_hz = lag, float(cutoff_hz)

    def names(self) -> tuple[str, ...]:
        return tuple(n + "_motion" for n in self.lag.names())

    def columns(self, s: Signals) -> np.ndarray:
        x = self.lag.tau_model(s)
        out = np.empty_like(x)
        for e in np.unique(s.experiment):
            k = s.experiment == e
            t = s.t[k]
            fs = 1.0 / float(np.median(np.diff(t))) if t.size > 1 else 0.0
            # a run too short for the filter's padding, or a cut-off above its Nyquist
            # frequency, keeps its prediction as it is
            ok = t.size > 12 and self.cutoff_hz < 0.5 * fs
            out[k] = lowpass(x[k], self.cutoff_hz, fs, order=2) if ok else x[k]
        return time_derivative(out, s)[:, None]


def _motion_band(design: Design) -> float | None:
    """5 x the motion bandwidth [Hz] of the design's runs (:func:`ident.chain.choose_cutoff`
    without its lower bound f_s/20: the trajectory's own band, the paper's "5 times the
    bandwidth of the dynamics"), the largest over the runs; None when it is not below the
    design's cut-off (the columns are filtered no further than the motion) or unknown."""
    cut = getattr(design, "cutoff_hz", None)
    bands = []
    for b in getattr(design, "_blocks", None) or ():
        sub = getattr(b, "sub", None)
        if sub is None:
            continue
        t, q = np.asarray(sub.t, dtype=float), np.asarray(sub.q, dtype=float)
        if q.ndim != 1 or t.size < 16:
            continue
        # its bound warnings are the chain's, given there; no catch_warnings, which would
        # reset the once-per-location registry and repeat other warnings in the process
        bands.append(choose_cutoff(q, float(np.median(np.diff(t))), min_fraction=1e-9,
                                   warn=False))
    if not bands or cut is None:
        return None
    fc = max(bands)
    return fc if fc < cut else None


def _motion_check(e: TorqueLag, lib: Library, design: Design, name: str, cur: IdentModel,
                  before: dict[str, float], vmax: float | None, min_gain: float,
                  cutoff_hz: float | None) -> str | None:
    """Why a torque lag that passed the relative-error rule is refused, or None: its column
    on the motion band (:class:`_MotionPart` at ``cutoff_hz``, 5 x the motion bandwidth) must
    pass the same rule (``min_gain`` overall, or twice it in a velocity band). A lag of the
    joint delays the torque of the motion; a gain its band does not keep came from the noise
    the column shares with the residual (measured on the friction-dominated joint of
    ``tests/test_refine_quadrant_drift.py``: 13 % of the residual's sum of squares explained,
    T_lag 4 ms, with the applied-torque noise; nothing without it; docs/refinement.md)."""
    if cutoff_hz is None:
        return None
    part = _MotionPart(e, cutoff_hz)
    try:
        d_s = design.with_term(part, states_only=True)
        m_s = _fit(Library(*lib.terms(), part), d_s, name)
    except DataError:
        return None
    overall = 1.0 - m_s.rel_error_ / cur.rel_error_ if cur.rel_error_ > 0 else 0.0
    best = _best_band_gain(before, _bands(m_s, d_s, vmax), cur.rel_error_, m_s.rel_error_)
    if overall < min_gain and best < 2 * min_gain:
        return (f"its column on the motion band (below {cutoff_hz:.3g} Hz, 5 x the motion "
                f"bandwidth) lowers the relative error {_pct(cur.rel_error_)} -> "
                f"{_pct(m_s.rel_error_)} only: less than {100 * min_gain:g} % better overall "
                f"and {200 * min_gain:g} % in the low- and high-velocity bands; the rest is the "
                "noise the measured motion shares with the residual, not a lag")
    return None


# ------------------------------------------------------------------------ the loop
def refine(
    design: Design,
    model: IdentModel | Term,
    *,
    validation: Design | None = None,
    max_steps: int = 5,
    vmax: float | None = None,
    progress: Callable[[str], None] | None = None,
    alpha: float = 1e-3,
    min_gain: float = 0.05,
    max_tries: int = 2,
    generic_knots: int = 12,
    library: bool = True,
    others: Sequence[str] | None = None,
    reference: Mapping[str, float] | None = None,
    cycle_s: float | None = None,
) -> Refinement:
    """Refine a declared model by adding the effects its residual points to.

    Parameters
    ----------
    design : Design
        Identification samples built with the declared model's library
        (:func:`ident.preprocess.build_design`).
    model : IdentModel or Term
        The declared model (its library is used; it is refitted without elimination so
        that every step compares nested least-squares fits).
    validation : Design, optional
        Validation samples built with the same library and preprocessing settings; a step
        is accepted only if it lowers their relative error too.
    max_steps : int
        Maximum number of added effects.
    vmax : float, optional
        Maximum velocity for the low/high-velocity bands [rad/s] (default max |q̇|).
    progress : callable, optional
        Receives one line per step (for the CLI).
    alpha : float
        Family-wise level of the acceptance F test (divided by the number of candidates).
    min_gain : float
        Minimum relative decrease of the relative error for a step to count (0.05: 5 %).
    max_tries : int
        Candidates tried per step, best first, before giving up.
    generic_knots : int
        Knots of a generic basis expansion.
    library : bool
        Also run the interaction diagnosis and the library search
        (:mod:`ident.refine_library`) and require every candidate to lower the held-out
        (blocked cross-validation) error.
    others : sequence of str, optional
        Variables of ``design.signals.extra`` (other joints' states, :attr:`Signals.extra
        <ident.signals.Signals.extra>`) the library search also expands (default: all of
        them); a selected group in them is added as a term that reads them by name
        (validation data without them reject it).
    reference : mapping, optional
        Coefficients that scale the descriptions of the library search (``F_C``: "±x % of
        F_C") in place of the current fit's, when those are not the physical ones (a joint
        of an n-dof fit, whose F_C is in the n-dof model: :mod:`ident.robot.refine_joint`).
    cycle_s : float, optional
        Sampling period of the raw log [s], for the zero-order hold's half cycle and the
        physical ranges, when the design's first run is not the raw log (a design built on
        decimated samples, :mod:`ident.robot.refine_joint`); default: that run's period.

    Returns
    -------
    Refinement
    """
    if max_steps < 0:
        raise DataError(f"max_steps must be >= 0, got {max_steps}")
    say = progress or (lambda _m: None)
    lib = model.library if isinstance(model, IdentModel) else Library(model)
    name = model.name if isinstance(model, IdentModel) else "declared"
    missing = [n for n in lib.names() if n not in design.names]
    if missing:
        raise DataError(f"design has no column for parameters {missing}; build it with the model")
    extra = design.signals.extra or {}
    unknown = [v for v in (others or ()) if v not in extra]
    if unknown:
        raise DataError(f"refine: others {unknown} are not in the design's signals.extra "
                        f"({sorted(extra) or 'none'})")
    other_values = {v: extra[v] for v in (extra if others is None else others)} or None
    cur_design = design
    cur_val = validation
    cur = _fit(lib, cur_design, name)
    initial = cur
    runs = cur_design.signals.experiment
    unseen = heldout_kind(runs)
    # leave one run out on runs of one trajectory cannot reject a term locked to it
    one_path = unseen == "leave one run out" and one_trajectory(
        cur_design.signals.t, cur_design.signals.q, runs)
    floor = noise_floor(cur.residual_, cur_design.Y, runs)
    floor_initial = floor
    drift_initial = quadrant_drift(cur_design, lib, cur.coef_)
    motion_hz = _motion_band(cur_design)
    h_cur = heldout_error(_kept(cur_design, cur), cur_design.Y, runs)
    h_initial = h_cur
    val_err = cur.rel_error_on(cur_val) if cur_val is not None else None
    val_initial = val_err
    steps: list[Step] = []
    rejected: list[Rejected] = []
    library_tried: list[dict] = []
    lib_variables: dict[int, tuple[str, ...]] = {}
    stop = f"step limit ({max_steps}) reached"
    # candidates (terms, variables, bases) see the states only: none can read the torque
    s = cur_design.signals.states()
    # an IV fit's diagnosis bins the acceleration on the reference's (diagnose's doc)
    ref_acc = cur_design.reference_acceleration()
    diag = None
    for k in range(1, max_steps + 1):
        r = cur.residual_
        tau_out = rigid_prediction(lib, cur.coef_)
        diag = diagnose(r, s, Y=cur_design.Y, tau_out=tau_out, alpha=alpha,
                        acceleration=ref_acc)
        kept = [cur_design.names.index(n) for n in cur.names_]
        scorer = Scorer(cur_design.W[:, kept], r)
        cols = Columns(s, scorer)
        cands = _candidates(cols, diag, lib, cur.coef_, alpha, generic_knots)
        lstep = None
        if library:
            lstep = library_step(cur_design.Y, cur_design.W[:, kept], s, r, tau_out=tau_out,
                                 reference={**cur.coef_, **(reference or {})}, others=other_values,
                                 min_gain=min_gain,
                                 alpha=alpha,
                                 load_dependent=any(t.effect in LOAD_DEPENDENT
                                                    for t in lib.terms()))
            library_tried.append({"step": k, "tried": lstep.tried_json()})
            if lstep.candidate is not None:
                e = lstep.candidate
                tag = unique_tag(e.names(), set(lib.names()))
                if tag:
                    e = e.with_tag(tag)
                lc = Candidate(e, cols.gain(e), lstep.n_hyper, lstep.generic)
                lib_variables[id(e)] = _library_variables(lstep)
                cands.append(lc)
        n_cand = max(len(cands), 1)
        before_bands = _bands(cur, cur_design, vmax)
        p_cur = len(cur.names_)
        rss0 = float(cur.residual_ @ cur.residual_)

        # 1. pre-test on the scoring columns (no full-rate rebuild for hopeless candidates)
        ctx = (rss0, p_cur, len(cur_design), diag.n_eff, cur.rel_error_, alpha / n_cand,
               min_gain / 3)
        why_not = {}
        for c in cands:
            why = _pretest(c, *ctx)
            if why is not None and why.startswith("F test") and c.gain > 0:
                # the F test uses the noise left after the candidate, not the structure it fits
                c.n_eff = scorer.n_eff_after(c.effect.columns(s))
                why = _pretest(c, *ctx)
            why_not[id(c)] = why

        def pretest(c: Candidate, _w=why_not) -> str | None:
            return _w[id(c)]

        named = sorted((c for c in cands if not c.generic), key=lambda c: -c.gain)
        generic = sorted((c for c in cands if c.generic), key=lambda c: -c.gain)
        if lstep is not None:
            # a registered effect that explains as much as the library's named form (the
            # naming rule's share) keeps its place ahead of it
            lib_named = [c for c in named if id(c.effect) in lib_variables]
            if lib_named and any(c.gain >= MATCH_SHARE * lib_named[0].gain for c in named
                                 if c is not lib_named[0]):
                named = [c for c in named if c is not lib_named[0]] + lib_named
            # generic bases and the library basis compete on the held-out error
            s_cv = s.take(slice(None, None, lstep.stride))
            generic.sort(key=lambda c: lstep.heldout(c.effect.columns(s_cv), strided=True))
        short = [c for c in named if pretest(c) is None][:max_tries]
        # with the library, two bases (three with validation data, which picks among those
        # that pass) may be tried
        n_gen = 1 if lstep is None else 3 if cur_val is not None else 2
        top_generic = [c for c in generic if pretest(c) is None][:n_gen]
        # the generic basis only competes when it could win the exact comparison
        if top_generic and (
            not short or short[0].gain < top_generic[0].gain * GENERIC_MARGIN * 1.5
        ):
            short += top_generic
        if not short:
            for c in (named + generic)[:max_tries]:
                why = pretest(c) or "not better than the others"
                rejected.append(Rejected(k, c.effect.effect, c.effect.variable, why, math.nan))
                say(f"step {k}: {c.effect.effect} rejected: {why}")
        # 2. order the short list by the scoring gains (columns on the decimated signals match
        # the exact ones closely); named effects are preferred unless a basis removes clearly
        # more; the generic bases keep their held-out order
        best_named = max((c.gain for c in short if not c.generic), default=0.0)
        best_generic = max((c.gain for c in short if c.generic), default=0.0)
        prefer_generic = best_generic > 0 and best_named < GENERIC_MARGIN * best_generic
        named_first = sorted((c for c in short if not c.generic), key=lambda c: -c.gain)
        generic_first = [c for c in short if c.generic]
        order = generic_first + named_first if prefer_generic else named_first + generic_first
        say(
            f"step {k}: short list "
            + ", ".join(f"{c.effect.effect} {_scored(c, cur.rel_error_, rss0, floor)}"
                        for c in order
            )
        )

        def exact_refits(order=order, lib=lib, cur_design=cur_design, k=k):
            """Exact refits (columns filtered and decimated like the others), on demand: the
            residual first (:class:`_Refit`), the fit's statistics when a test needs them."""
            for c in order:
                e = c.effect
                try:
                    d1 = cur_design.with_term(e, states_only=True)
                    m1 = _Refit(Library(*lib.terms(), e), d1, name)
                except DataError as exc:
                    rejected.append(Rejected(k, e.effect, e.variable, f"not fitted: {exc}",
                                             math.nan))
                    continue
                yield c, d1, m1

        # 3. acceptance tests, best first; with validation data, the bases that pass (at
        # most three) are compared on the validation error, which none was fitted on
        accepted = None
        pending: list[tuple] = []
        for c, d1, m1 in exact_refits():
            e = c.effect
            if pending and not c.generic:
                break
            kk = sum(1 for n in e.names() if n in m1.names_) + c.n_hyper
            F, pval = _f_test(
                rss0,
                float(m1.residual_ @ m1.residual_),
                max(kk, 1),
                p_cur,
                len(cur_design),
                max(diag.n_eff, effective_n(m1.residual_)),
            )
            reason = None
            if pval >= alpha / n_cand:
                reason = (f"F test not significant (F={F:.3g}, p={pval:.2e} >= level "
                          f"{alpha / n_cand:.2g}: alpha / candidates)")
            else:
                try:
                    m1 = m1.model()
                except DataError as exc:  # pragma: no cover - the residual's fit succeeded
                    rejected.append(Rejected(k, e.effect, e.variable, f"not fitted: {exc}",
                                             math.nan))
                    continue
                after_try = _bands(m1, d1, vmax)
                overall = 1.0 - m1.rel_error_ / cur.rel_error_ if cur.rel_error_ > 0 else 0.0
                best = _best_band_gain(before_bands, after_try, cur.rel_error_, m1.rel_error_)
                # a band counts at twice the threshold; a generic basis must gain overall
                if c.generic and overall < 2 * min_gain:
                    reason = (
                        f"relative error {_pct(cur.rel_error_)} -> {_pct(m1.rel_error_)}: "
                        f"a generic basis must be {200 * min_gain:g} % better overall"
                    )
                elif overall < min_gain and best < 2 * min_gain:
                    reason = (
                        f"relative error {_pct(cur.rel_error_)} -> {_pct(m1.rel_error_)}: "
                        f"less than {100 * min_gain:g} % better overall and "
                        f"{200 * min_gain:g} % in the low- and high-velocity bands"
                    )
                elif isinstance(e, TorqueLag):
                    reason = _motion_check(e, lib, cur_design, name, cur, before_bands, vmax,
                                           min_gain, motion_hz)
            # data the candidate was not fitted on: other runs, or other blocks of one run
            h1 = heldout_error(_kept(d1, m1), d1.Y, runs)
            low = min(m1.rel_error_, h1)
            if math.isfinite(floor) and low < LEAK_RATIO * floor:
                reason = (
                    f"leak: error {_pct(low)} below the noise floor {_pct(floor)} "
                    f"(x{low / floor:.2f}): the candidate explains the noise, a column "
                    "built from the output"
                )
            need = h_cur * (1 - min_gain) if c.generic else h_cur
            if reason is None and not h1 < need:
                reason = (
                    f"{unseen} error {_pct(h_cur)} -> {_pct(h1)}"
                    + (f": a basis must lower it by {100 * min_gain:g} %" if c.generic
                       else ": not lowered")
                )
            v1 = val1 = None
            if reason is None and cur_val is not None:
                try:
                    val1 = cur_val.with_term(e, states_only=True)
                except DataError as exc:  # e.g. a term in other joints the validation lacks
                    reason = f"not computable on the validation data: {exc}"
                else:
                    v1 = m1.rel_error_on(val1)
                if reason is None and not v1 < val_err:
                    reason = f"validation error not lowered ({_pct(val_err)} -> {_pct(v1)})"
            if reason is not None:
                rejected.append(Rejected(k, e.effect, e.variable, reason, m1.rel_error_, h1,
                                         lib_variables.get(id(e), ())))
                say(f"step {k}: {e.effect} rejected: {reason}")
                continue
            accepted = (c, d1, m1, F, pval, v1, val1, h1)
            if c.generic and cur_val is not None:
                pending.append(accepted)
                accepted = None
                if len(pending) < 3:
                    continue
            break
        if pending:
            accepted = min(pending, key=lambda a: a[5])
            for a in pending:
                if a is not accepted:
                    rejected.append(Rejected(
                        k, a[0].effect.effect, a[0].effect.variable,
                        f"validation error {_pct(a[5])} above {accepted[0].effect.effect}'s "
                        f"{_pct(accepted[5])}", a[2].rel_error_, a[7],
                        lib_variables.get(id(a[0].effect), ())))
        if accepted is None:
            stop = "no candidate effect passed the tests"
            break
        c, d1, m1, F, pval, v1, val1, h1 = accepted
        e = c.effect
        try:
            dep = diag.get(e.variable)
        except KeyError:  # a variable of the interaction diagnosis only (reversal)
            dep = None
        after_bands = _bands(m1, d1, vmax)
        parameters = _effect_parameters(e, m1, d1, m1.coef_)
        named_effect, structure, out_of_range = _naming(e, c, lstep, parameters, cur_design,
                                                         cycle_s)
        step = Step(
            variable=e.variable,
            strength=1.0 - float(m1.residual_ @ m1.residual_) / rss0 if rss0 > 0 else 0.0,
            binned_explained=dep.explained if dep is not None else math.nan,
            statistic=dep.statistic if dep is not None else math.nan,
            p_value=dep.p_value if dep is not None else math.nan,
            leading_variable=diag.table[0].variable,
            effect=e.effect,
            term=e,
            parameters=parameters,
            f_statistic=F,
            f_p_value=pval,
            rel_error_before=cur.rel_error_,
            rel_error_after=m1.rel_error_,
            low_before=before_bands.get("low", math.nan),
            low_after=after_bands.get("low", math.nan),
            high_before=before_bands.get("high", math.nan),
            high_after=after_bands.get("high", math.nan),
            validation_rel_error_before=val_err,
            validation_rel_error_after=v1,
            diagnosis=diag,
            generic=c.generic,
            variables=lib_variables.get(id(e), (e.variable,)),
            named_effect=named_effect,
            structure=structure,
            heldout_rel_error_before=h_cur,
            heldout_rel_error_after=h1,
            library=lstep,
            heldout_kind=unseen,
            noise_floor=floor,
            noise_floor_tested=floor,
            physical_range=out_of_range,
        )
        steps.append(step)
        say(
            f"step {k}: added {e.effect} ({e.variable}); relative error "
            f"{_pct(cur.rel_error_)} -> {_pct(m1.rel_error_)}"
        )
        lib = Library(*lib.terms(), e)
        cur_design, cur, h_cur = d1, m1, h1
        # the floor estimate only falls as effects leave the residual
        floor = min(floor, noise_floor(m1.residual_, d1.Y, runs))
        if cur_val is not None:
            cur_val, val_err = val1, v1
    if diag is None or steps and diag is steps[-1].diagnosis:
        diag = diagnose(
            cur.residual_, s, Y=cur_design.Y, tau_out=rigid_prediction(lib, cur.coef_),
            alpha=alpha, acceleration=ref_acc,
        )
    for st in steps:  # every error is reported against the final (lowest) floor estimate
        st.noise_floor = floor
    return Refinement(
        steps=steps,
        rejected=rejected,
        initial_model=initial,
        final_model=cur,
        final_design=cur_design,
        final_diagnosis=diag,
        rel_error_initial=initial.rel_error_,
        rel_error_final=cur.rel_error_,
        validation_rel_error_initial=val_initial,
        validation_rel_error_final=val_err,
        stop_reason=stop,
        final_validation_design=cur_val,
        library_tried=library_tried,
        heldout_kind=unseen,
        heldout_one_trajectory=one_path,
        heldout_rel_error_initial=h_initial,
        heldout_rel_error_final=h_cur,
        noise_floor=floor,
        noise_floor_initial=floor_initial,
        quadrant_drift_initial=drift_initial,
        quadrant_drift_final=(None if drift_initial is None
                              else quadrant_drift(cur_design, lib, cur.coef_)),
    )
