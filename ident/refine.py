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
3. accept the best candidate only if (a) the nested-model F test, with the effective
   sample size of the autocorrelated residual and one extra degree of freedom per scanned
   hyper-parameter, rejects "noise only" at level ``alpha`` / number of candidates,
   (b) it lowers the relative error by at least ``min_gain`` (relative), and (c) where
   validation data exist, it lowers the validation relative error too; otherwise the next
   best candidate is tried (at most ``max_tries``);
4. add the term (:meth:`~ident.preprocess.Design.with_term`: columns filtered and decimated
   like the others), refit, report; stop when nothing is accepted or after ``max_steps``.

Pure numerics (no file access); plots are in :mod:`ident.refine_plots`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy import optimize, stats

from . import DataError
from .describe import MATCH_SHARE, name_torque_lag
from .diagnose import Diagnosis, diagnose, effective_n
from .effects import (
    DirectionalViscous,
    Effect,
    GenericBasis,
    PositionRipple,
    PositionSmooth,
    Prediction,
    QuadrantCoulomb,
    QuadrantLoad,
    QuadrantLoadStribeck,
    QuadraticViscous,
    Spring,
    Stribeck,
    TorqueLag,
    WarmUp,
    variable_values,
)
from .models import IdentModel
from .refine_library import LibraryStep, library_step
from .signals import Signals
from .terms import Library, Term

if TYPE_CHECKING:  # pragma: no cover
    from .preprocess import Design

#: A named effect is preferred to a generic basis when it removes at least this share of
#: what the best generic basis removes.
GENERIC_MARGIN = 0.5
#: Continuous variables a generic basis may expand.
CONTINUOUS = ("position", "velocity", "acceleration", "load", "time")


# ----------------------------------------------------------------------------- results
@dataclass
class Step:
    """One accepted refinement step.

    Attributes
    ----------
    variable : str
        Candidate variable of the added effect (one of the seven).
    strength : float
        Share of the residual sum of squares the added effect removes, in [0, 1] (how
        strongly the residual depended on the variable through this effect).
    statistic, p_value : float
        Binned dependence of the residual on the variable before the step (diagnosis
        table row: F statistic and p-value; ``binned_explained`` its η²). Effects odd in
        a sign variable (direction, quadrant) interact with other variables and may show
        little binned dependence although the effect itself is strong.
    binned_explained : float
        η² of the diagnosis row of the variable.
    leading_variable : str
        The top variable of the diagnosis table before the step.
    effect : str
        Effect name (``"position_ripple"``, ``"generic_velocity"``, ...).
    term : Effect
        The added term (with its hyper-parameters).
    parameters : dict
        ``{name: {"value": v, "std2": 2σ}}`` of the effect, hyper-parameters included.
    f_statistic, f_p_value : float
        Nested-model F test of the acceptance.
    rel_error_before, rel_error_after : float
        ||ρ|| / ||Y|| on the identification samples.
    low_before, low_after, high_before, high_after : float
        The same in the low- and high-velocity bands (paper Table III).
    validation_rel_error_before, validation_rel_error_after : float or None
        On the validation design (``None`` without one).
    diagnosis : Diagnosis
        The diagnosis that led to the step.
    generic : bool
        ``True`` when no named effect fitted and a generic basis was added.
    """

    variable: str
    strength: float
    statistic: float
    p_value: float
    leading_variable: str
    effect: str
    term: Effect
    parameters: dict[str, dict[str, float]]
    f_statistic: float
    f_p_value: float
    rel_error_before: float
    rel_error_after: float
    low_before: float
    low_after: float
    high_before: float
    high_after: float
    validation_rel_error_before: float | None
    validation_rel_error_after: float | None
    diagnosis: Diagnosis = field(repr=False)
    generic: bool = False
    binned_explained: float = math.nan
    #: every variable the effect involves (two for an interaction), then its modifier
    variables: tuple[str, ...] = ()
    #: named physical effect (``"position_periodic_dry_friction"``, ``"zero_order_hold"``...)
    #: or None for a library basis described in words
    named_effect: str | None = None
    #: one line a mechanical engineer reads
    structure: str = ""
    heldout_rel_error_before: float = math.nan
    heldout_rel_error_after: float = math.nan
    library: LibraryStep | None = field(default=None, repr=False)

    def to_json(self) -> dict[str, Any]:
        """The step as in ``refinement.steps[]`` of the fit JSON."""
        lib = self.library
        return {
            "effect": self.effect,
            "variable": self.variable,
            "variables": list(self.variables or (self.variable,)),
            "named_effect": self.named_effect,
            "structure": self.structure or self.term.describe(),
            "heldout_rel_error_before": _num(self.heldout_rel_error_before),
            "heldout_rel_error_after": _num(self.heldout_rel_error_after),
            "interactions": [t.to_json() for t in lib.interactions.significant[:10]]
            if lib is not None else [],
            "description": self.term.describe(),
            "generic": self.generic,
            "parameters": self.parameters,
            "strength": {
                "explained": _num(self.strength),
                "binned_explained": _num(self.binned_explained),
                "binned_statistic": _num(self.statistic),
                "binned_p_value": _num(self.p_value),
            },
            "leading_variable": self.leading_variable,
            "test": {"F": _num(self.f_statistic), "p_value": _num(self.f_p_value)},
            "rel_error_before": _num(self.rel_error_before),
            "rel_error_after": _num(self.rel_error_after),
            "low_velocity_rel_error_before": _num(self.low_before),
            "low_velocity_rel_error_after": _num(self.low_after),
            "high_velocity_rel_error_before": _num(self.high_before),
            "high_velocity_rel_error_after": _num(self.high_after),
            "validation_rel_error_before": _num(self.validation_rel_error_before),
            "validation_rel_error_after": _num(self.validation_rel_error_after),
            "diagnosis": self.diagnosis.to_json(),
        }


@dataclass
class Rejected:
    """A candidate that was the best of its round but failed a test."""

    step: int
    effect: str
    variable: str
    reason: str
    rel_error_after: float
    heldout_rel_error_after: float = math.nan
    variables: tuple[str, ...] = ()

    def to_json(self) -> dict[str, Any]:
        return {
            "step": self.step,
            "effect": self.effect,
            "variable": self.variable,
            "variables": list(self.variables or (self.variable,)),
            "reason": self.reason,
            "rel_error_after": _num(self.rel_error_after),
            "heldout_rel_error_after": _num(self.heldout_rel_error_after),
        }


@dataclass
class Refinement:
    """Outcome of :func:`refine`.

    Attributes
    ----------
    steps : list of Step
        Accepted steps, in order.
    rejected : list of Rejected
        Best candidates that failed the tests (why the loop stopped).
    initial_model, final_model : IdentModel
        Fits of the declared and of the refined library.
    final_design : Design
        The design with every added term's columns.
    final_diagnosis : Diagnosis
        Diagnosis of the final residual (what is left).
    rel_error_initial, rel_error_final : float
        ||ρ|| / ||Y|| before and after.
    validation_rel_error_initial, validation_rel_error_final : float or None
    stop_reason : str
    """

    steps: list[Step]
    rejected: list[Rejected]
    initial_model: IdentModel
    final_model: IdentModel
    final_design: Design
    final_diagnosis: Diagnosis
    rel_error_initial: float
    rel_error_final: float
    validation_rel_error_initial: float | None
    validation_rel_error_final: float | None
    stop_reason: str
    #: per step, every structure of the library search with its held-out error and the
    #: reason it was not selected (see :meth:`ident.library_search.Tried.to_json`)
    library_tried: list[dict] = field(default_factory=list)

    @property
    def terms(self) -> list[Effect]:
        """The added terms, in order."""
        return [s.term for s in self.steps]

    def to_json(self) -> dict[str, Any]:
        """The ``refinement`` object of the fit JSON (see docs/refinement.md)."""
        return {
            "steps": [s.to_json() for s in self.steps],
            "rejected": [r.to_json() for r in self.rejected],
            "rel_error_initial": _num(self.rel_error_initial),
            "rel_error_final": _num(self.rel_error_final),
            "validation_rel_error_initial": _num(self.validation_rel_error_initial),
            "validation_rel_error_final": _num(self.validation_rel_error_final),
            "stop_reason": self.stop_reason,
            "library_tried": self.library_tried,
            "final_parameters": {
                n: {
                    "value": float(self.final_model.coef_[n]),
                    "std2": float(2 * self.final_model.std_[n]),
                }
                for n in self.final_model.names_
            },
            "final_diagnosis": self.final_diagnosis.to_json(),
        }

    def format_table(self) -> str:
        """Alias of :meth:`format_report` (what ``jointid fit --refine`` prints)."""
        return self.format_report()

    def format_report(self) -> str:
        """Human-readable report of every step."""
        out = [
            f"Refinement: relative error {_pct(self.rel_error_initial)} -> "
            f"{_pct(self.rel_error_final)}"
            + (
                f" (validation {_pct(self.validation_rel_error_initial)} -> "
                f"{_pct(self.validation_rel_error_final)})"
                if self.validation_rel_error_initial is not None
                else ""
            )
        ]
        for i, s in enumerate(self.steps, 1):
            out.append("")
            out.append(
                f"step {i}: residual depends on {' x '.join(s.variables or (s.variable,))}: "
                f"the effect explains {100 * s.strength:.1f} % of it (binned on {s.variable}: "
                f"{100 * s.binned_explained:.1f} %, p={s.p_value:.1e}; leading variable of "
                f"the diagnosis: {s.leading_variable})"
            )
            if s.library is not None and s.library.interactions.significant:
                t = s.library.interactions.significant[0]
                out.append(
                    f"  leading interaction test: {t.label} ({t.kind}, "
                    f"{100 * t.explained:.1f} %, Holm p={t.p_adjusted:.1e}; "
                    f"{len(s.library.interactions.tests)} tests)"
                )
            out.append(
                f"  added {s.named_effect or s.effect}: {s.term.describe()}"
                + ("  [generic basis: no named effect fitted]" if s.generic else "")
            )
            if s.structure:
                out.append(f"    {s.structure}")
            for n, v in s.parameters.items():
                out.append(f"    {n:<18} = {v['value']:.6g} ± {v['std2']:.2g} (2σ)")
            out.append(
                f"  F test {s.f_statistic:.3g} (p={s.f_p_value:.1e}); relative error "
                f"{_pct(s.rel_error_before)} -> {_pct(s.rel_error_after)}, "
                f"low velocity {_pct(s.low_before)} -> {_pct(s.low_after)}, "
                f"high velocity {_pct(s.high_before)} -> {_pct(s.high_after)}"
            )
            if math.isfinite(s.heldout_rel_error_before):
                out.append(
                    f"  held-out (blocked CV) {_pct(s.heldout_rel_error_before)} -> "
                    f"{_pct(s.heldout_rel_error_after)}"
                )
            if s.validation_rel_error_before is not None:
                out.append(
                    f"  validation {_pct(s.validation_rel_error_before)} -> "
                    f"{_pct(s.validation_rel_error_after)}"
                )
        for r in self.rejected:
            v = " x ".join(r.variables or (r.variable,))
            out.append(f"rejected at step {r.step}: {r.effect} ({v}): {r.reason}")
        if self.library_tried:
            out.append("library search (best five structures per step; all in the JSON):")
            for st in self.library_tried:
                tried = sorted(st["tried"], key=lambda t: t["heldout_rel_error_after"])
                for t in tried[:5]:
                    out.append(
                        f"  step {st['step']}: {t['structure']} ({t['columns']} columns): "
                        f"{t['reason']}"
                    )
                if len(tried) > 5:
                    out.append(f"  step {st['step']}: ... and {len(tried) - 5} more structures")
        out.append(f"stopped: {self.stop_reason}")
        out.append("remaining residual:")
        out.append(self.final_diagnosis.format_table())
        return "\n".join(out)


def _num(x: float | None) -> float | None:
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def _pct(x: float | None) -> str:
    return "n/a" if x is None or not math.isfinite(x) else f"{100 * x:.2f} %"


# ------------------------------------------------------------------------ scoring
class _Scorer:
    """RSS removed by extra columns C from the current fit: with Q an orthonormal basis of
    the current (kept) regressor and r the residual (r ⟂ Q), the gain is
    (Cᵀr)ᵀ (CᵀC - (QᵀC)ᵀ(QᵀC))⁻¹ (Cᵀr)."""

    def __init__(self, W: np.ndarray, r: np.ndarray) -> None:
        norms = np.linalg.norm(W, axis=0)
        Ws = W / np.where(norms > 0, norms, 1.0)
        self.Q, _ = np.linalg.qr(Ws)
        self.r = r
        self.rss = float(r @ r)

    def gain(self, C: np.ndarray) -> float:
        C = np.asarray(C, dtype=float)
        if C.ndim == 1:
            C = C[:, None]
        if not np.all(np.isfinite(C)):
            return 0.0
        cn = np.linalg.norm(C, axis=0)
        ok = cn > 0
        if not ok.any():
            return 0.0
        C = C[:, ok] / cn[ok]
        QC = self.Q.T @ C
        M = C.T @ C - QC.T @ QC
        b = C.T @ self.r
        w, V = np.linalg.eigh(M)
        keep = w > 1e-9 * max(float(w.max()), 1e-300)
        z = (V[:, keep].T @ b) / np.sqrt(w[keep])
        return float(min(z @ z, self.rss))

    def n_eff_after(self, C: np.ndarray) -> float:
        """Effective sample size of the residual once C is fitted too: the noise that is
        left, not the structure C explains, sets the autocorrelation of the F test."""
        C = np.asarray(C, dtype=float)
        if C.ndim == 1:
            C = C[:, None]
        if not np.all(np.isfinite(C)):
            return effective_n(self.r)
        Cp = C - self.Q @ (self.Q.T @ C)
        beta, *_ = np.linalg.lstsq(Cp, self.r, rcond=None)
        return effective_n(self.r - Cp @ beta)


@dataclass
class _Candidate:
    effect: Effect
    gain: float
    n_hyper: int
    generic: bool = False
    n_eff: float = 0.0  # effective sample size after the candidate (0: unknown)


def _unscaled(design: Design) -> Signals:
    """``design.signals`` (kept for :mod:`ident.refine_plots`). The decimation filter has unit
    DC gain (:func:`ident.preprocess.decimate`), so the decimated q, dq, ddq, tau need no
    rescaling before nonlinear functions of them are evaluated."""
    return design.signals


class _Columns:
    """Scores candidates on columns computed on the decimated signals:
    smooth functions of slowly varying signals commute with the anti-alias filter, so these
    match :meth:`Design.with_term`'s columns closely and cost no full-rate pass. The exact
    columns are used only for the acceptance refit."""

    def __init__(self, s: Signals, scorer: _Scorer) -> None:
        self.scorer, self.s = scorer, s
        self._fast: _Columns | None = None

    def gain(self, e: Effect) -> float:
        return self.scorer.gain(e.columns(self.s))

    @property
    def fast(self) -> _Columns:
        """The same scorer on at most ~8000 samples (regular stride), for hyper-parameter
        scans; the gain of the chosen value is then computed on every sample."""
        n = len(self.s)
        if n <= 12000:
            return self
        if self._fast is None:
            st = math.ceil(n / 8000)
            sub = slice(None, None, st)
            self._fast = _Columns(self.s.take(sub), _Scorer(self.scorer.Q[sub], self.scorer.r[sub]))
        return self._fast


def _refine_1d(
    cols: _Columns,
    make: Callable[[float], Effect],
    a: float,
    b: float,
    x0: float,
    g0: float,
    xtol: float,
) -> tuple[Effect, float]:
    """Bounded 1-D maximisation of the gain over x in [a, b] (x0, g0: coarse best)."""
    if not b > a:
        return make(x0), g0
    res = optimize.minimize_scalar(
        lambda x: -cols.gain(make(x)),
        bounds=(a, b),
        method="bounded",
        options={"xatol": xtol, "maxiter": 40},
    )
    if -res.fun > g0:
        return make(float(res.x)), float(-res.fun)
    return make(x0), g0


def _scan_log(
    cols: _Columns, make: Callable[[float], Effect], lo: float, hi: float, n: int = 24
) -> tuple[Effect, float]:
    """Best hyper-parameter: log grid, then a bounded 1-D search between the grid
    neighbours of the best point."""
    fast = cols.fast
    grid = np.geomspace(lo, hi, n)
    gains = np.array([fast.gain(make(h)) for h in grid])
    i = int(np.argmax(gains))
    a, b = math.log(grid[max(i - 1, 0)]), math.log(grid[min(i + 1, n - 1)])
    e, g = _refine_1d(
        fast, lambda lh: make(math.exp(lh)), a, b, math.log(grid[i]), float(gains[i]), 1e-4
    )
    return (e, g) if fast is cols else (e, cols.gain(e))


def _scan_period(cols: _Columns, p0: float, span: float, tag: str) -> tuple[Effect, float]:
    """Ripple period: grid over ±1.5 frequency bins (1/span) around the periodogram peak
    p0, then a bounded search (frequency resolution ~1e-7 f0)."""
    f0, df = 1 / p0, 1.5 / span
    lo, hi = max(f0 - df, 0.5 * f0), f0 + df
    fast = cols.fast
    fgrid = np.linspace(lo, hi, 31)
    gains = np.array([fast.gain(PositionRipple(1 / f, tag)) for f in fgrid])
    i = int(np.argmax(gains))
    a, b = fgrid[max(i - 1, 0)], fgrid[min(i + 1, len(fgrid) - 1)]
    e, g = _refine_1d(
        fast, lambda f: PositionRipple(1 / f, tag), a, b, fgrid[i], float(gains[i]), 1e-7 * f0
    )
    return (e, g) if fast is cols else (e, cols.gain(e))


def _unique_tag(effect_cls_names: tuple[str, ...], existing: set[str]) -> str:
    if not set(effect_cls_names) & existing:
        return ""
    k = 2
    while True:
        tag = f"_{k}"
        if not {n + tag for n in effect_cls_names} & existing:
            return tag
        k += 1


def _rigid_prediction(lib: Library, coef: dict[str, float]) -> Prediction | None:
    terms = [t for t in lib.terms() if t.effect in ("rigid_body", "payload")]
    if not terms:
        return None
    c = np.array([coef.get(n, 0.0) for t in terms for n in t.names()])
    if not np.any(c):
        return None
    return Prediction(terms, c)


def _candidates(
    cols: _Columns,
    diag: Diagnosis,
    lib: Library,
    coef: dict[str, float],
    alpha: float,
    generic_knots: int,
) -> list[_Candidate]:
    names = set(lib.names())
    effects = {t.effect for t in lib.terms()}
    out: list[_Candidate] = []

    s = cols.s

    def add(e: Effect, generic: bool = False):
        tag = _unique_tag(e.names(), names)
        if tag:
            e = e.with_tag(tag)
        out.append(_Candidate(e, cols.gain(e), 0, generic))

    q, dq, t = s.q, s.dq, s.t
    span = float(q.max() - q.min())
    vmax = float(np.max(np.abs(dq)))
    pp = diag.position_periodogram
    if span > 0 and math.isfinite(pp.peak_period) and pp.false_alarm < alpha:
        tag = _unique_tag(("ripple_sin", "ripple_cos"), names)
        e, g = _scan_period(cols, pp.peak_period, span, tag)
        out.append(_Candidate(e, g, 1))
    if span > 0 and "spring" not in effects:
        add(Spring(float(np.mean(q))))
    if span > 0 and "position_smooth" not in effects:
        add(PositionSmooth(float(q.min()), float(q.max()), 4))
    if "directional_viscous" not in effects:
        add(DirectionalViscous())
    if "quadratic_viscous" not in effects:
        add(QuadraticViscous())
    has_exp = any(t.effect in ("stribeck", "quadrant_coulomb") for t in lib.terms())
    if vmax > 0 and not has_exp:
        e, g = _scan_log(cols, Stribeck, vmax / 1000, vmax / 2)
        out.append(_Candidate(e, g, 1))
    tmax = float(t.max())
    if tmax > 0 and "warm_up" not in effects:
        e, g = _scan_log(cols, WarmUp, tmax / 300, tmax)
        out.append(_Candidate(e, g, 1))
    tau_out = _rigid_prediction(lib, coef)
    has_quadrant_dry = any(t.effect == "quadrant_coulomb" for t in lib.terms())
    has_quadrant = any(t.effect in ("quadrant_load", "load_dependent") for t in lib.terms())
    if tau_out is not None and not has_quadrant:
        add(QuadrantLoad(tau_out))
    if "quadrant_coulomb" not in effects and not has_quadrant_dry:
        add(QuadrantCoulomb())
    if (
        tau_out is not None
        and vmax > 0
        and "quadrant_load" in effects
        and "quadrant_load_stribeck" not in effects
    ):
        e, g = _scan_log(cols, lambda qs: QuadrantLoadStribeck(tau_out, qs), vmax / 1000, vmax / 2)
        out.append(_Candidate(e, g, 1))
    if "torque_lag" not in effects:
        c_all = np.array([coef.get(n, 0.0) for n in lib.names()])
        add(TorqueLag(Prediction(lib.terms(), c_all)))
    # generic expansions in the significantly implicated continuous variables
    for d in diag.significant:
        if d.variable not in CONTINUOUS:
            continue
        x = variable_values(d.variable, s, tau_out)
        lo, hi = np.quantile(x, [0.005, 0.995])
        if not hi > lo:
            continue
        for signed in (False, True):
            e = GenericBasis(d.variable, float(lo), float(hi), generic_knots, signed, tau_out)
            add(e, generic=True)
    return out


def _f_test(rss0: float, rss1: float, k: int, p: int, n: int, n_eff: float) -> tuple[float, float]:
    """Nested-model F test, degrees of freedom from the effective sample size."""
    d2 = max(min(n_eff, n) - p - k, 1.0)
    if rss1 <= 0 or k < 1:
        return float("inf"), 0.0
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
    c: _Candidate,
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
        return f"F test not significant (F={F0:.3g}, p={p0:.2e})"
    if rel_fast > rel * (1 - min_gain):
        return (
            f"relative error {_pct(rel)} -> {_pct(rel_fast)}: less than {100 * min_gain:g} % better"
        )
    return None


def _effect_parameters(
    term: Effect, model: IdentModel, design: Design, all_coef: dict[str, float]
) -> dict[str, dict[str, float]]:
    """Term parameters with 2σ; hyper-parameters via the linearised model (Jacobian column
    d(W_term χ_term)/dh appended to the kept regressor)."""
    names = list(model.names_)
    tnames = [n for n in term.names() if n in model.coef_]
    s = design.signals
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
    out = {k: {"value": float(v), "std2": float(e)} for k, (v, e) in par.items()}
    if isinstance(term, DirectionalViscous) and "F_V" in model.coef_:
        i_fv, i_d = names.index("F_V"), names.index(tnames[0])
        fv, d = model.coef_["F_V"], model.coef_[tnames[0]]
        for key, sgn in (("F_V_pos", 0.5), ("F_V_neg", -0.5)):
            g = np.zeros(cov.shape[0])
            g[i_fv], g[i_d] = 1.0, sgn
            out[key] = {
                "value": float(fv + sgn * d),
                "std2": float(2 * math.sqrt(max(g @ cov @ g, 0.0))),
            }
    if isinstance(term, WarmUp) and all_coef.get("F_C"):
        out["w_warm"] = {
            "value": float(model.coef_[tnames[0]] / all_coef["F_C"]),
            "std2": float(out[tnames[0]]["std2"] / abs(all_coef["F_C"])),
        }
    return out


def _bands(model: IdentModel, design: Design, vmax: float | None) -> dict[str, float]:
    try:
        return model.rel_error_bands(design, vmax)
    except Exception:  # noqa: BLE001 - bands are informative only
        return {"all": model.rel_error_on(design), "low": float("nan"), "high": float("nan")}


def _fit(lib: Library, design: Design, name: str) -> IdentModel:
    return IdentModel(lib, name).fit(design, eliminate=False, drop_unidentifiable=True)


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


def _naming(
    e: Effect,
    c: _Candidate,
    lstep: LibraryStep | None,
    parameters: dict[str, dict[str, float]],
    design: Design,
) -> tuple[str | None, str]:
    """Named effect and one-line structure of an accepted candidate."""
    if lstep is not None and lstep.candidate is not None and (
        e is lstep.candidate or e.effect == lstep.candidate.effect
    ) and lstep.description is not None:
        return lstep.description.name, lstep.description.sentence
    if isinstance(e, TorqueLag):
        key = next((k for k in parameters if k.startswith("T_lag")), None)
        if key is not None:
            return name_torque_lag(parameters[key]["value"], parameters[key]["std2"],
                                   _cycle(design))
    return (None if c.generic else e.effect), e.describe()


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
    cur_design = design
    cur_val = validation
    cur = _fit(lib, cur_design, name)
    initial = cur
    val_err = cur.rel_error_on(cur_val) if cur_val is not None else None
    val_initial = val_err
    steps: list[Step] = []
    rejected: list[Rejected] = []
    library_tried: list[dict] = []
    lib_variables: dict[int, tuple[str, ...]] = {}
    stop = f"step limit ({max_steps}) reached"
    s = cur_design.signals
    diag = None
    for k in range(1, max_steps + 1):
        r = cur.residual_
        tau_out = _rigid_prediction(lib, cur.coef_)
        diag = diagnose(r, s, Y=cur_design.Y, tau_out=tau_out, alpha=alpha)
        kept = [cur_design.names.index(n) for n in cur.names_]
        scorer = _Scorer(cur_design.W[:, kept], r)
        cols = _Columns(s, scorer)
        cands = _candidates(cols, diag, lib, cur.coef_, alpha, generic_knots)
        lstep = None
        if library:
            lstep = library_step(cur_design.Y, cur_design.W[:, kept], s, r, tau_out=tau_out,
                                 reference=cur.coef_, min_gain=min_gain, alpha=alpha)
            library_tried.append({"step": k, "tried": lstep.tried_json()})
            if lstep.candidate is not None:
                e = lstep.candidate
                tag = _unique_tag(e.names(), set(lib.names()))
                if tag:
                    e = e.with_tag(tag)
                lc = _Candidate(e, cols.gain(e), lstep.n_hyper, lstep.generic)
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

        def pretest(c: _Candidate, _w=why_not) -> str | None:
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
            + ", ".join(
                f"{c.effect.effect} {_pct(cur.rel_error_ * math.sqrt(max(1 - c.gain / rss0, 0)))}"
                for c in order
            )
        )

        def exact_refits(order=order, lib=lib, cur_design=cur_design, k=k):
            """Exact refits (columns filtered and decimated like the others), on demand."""
            for c in order:
                e = c.effect
                try:
                    d1 = cur_design.with_term(e)
                    m1 = _fit(Library(*lib.terms(), e), d1, name)
                except DataError as exc:
                    rejected.append(Rejected(k, e.effect, e.variable, f"not fitted: {exc}",
                                             math.nan))
                    continue
                yield c, d1, m1

        # 3. acceptance tests, best first; with validation data, the bases that pass (at
        # most two) are compared on the validation error, which neither was fitted on
        accepted = None
        pending: list[tuple] = []
        for c, d1, m1 in exact_refits():
            e = c.effect
            if pending and not c.generic:
                break
            kk = sum(1 for n in e.names() if n in m1.coef_) + c.n_hyper
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
                reason = f"F test not significant (F={F:.3g}, p={pval:.2e})"
            else:
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
            h1 = math.nan
            if lstep is not None:
                h0 = lstep.heldout_before
                h1 = lstep.heldout(d1.W[:, [d1.names.index(n) for n in m1.names_
                                            if n in e.names()]])
                need = h0 * (1 - min_gain) if c.generic else h0
                if reason is None and not h1 < need:
                    reason = (
                        f"held-out error {_pct(h0)} -> {_pct(h1)}"
                        + (f": a basis must lower it by {100 * min_gain:g} %" if c.generic
                           else ": not lowered")
                    )
            v1 = val1 = None
            if reason is None and cur_val is not None:
                val1 = cur_val.with_term(e)
                v1 = m1.rel_error_on(val1)
                if not v1 < val_err:
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
        named, structure = _naming(e, c, lstep, parameters, cur_design)
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
            named_effect=named,
            structure=structure,
            heldout_rel_error_before=lstep.heldout_before if lstep is not None else math.nan,
            heldout_rel_error_after=h1,
            library=lstep,
        )
        steps.append(step)
        say(
            f"step {k}: added {e.effect} ({e.variable}); relative error "
            f"{_pct(cur.rel_error_)} -> {_pct(m1.rel_error_)}"
        )
        lib = Library(*lib.terms(), e)
        cur_design, cur = d1, m1
        if cur_val is not None:
            cur_val, val_err = val1, v1
    if diag is None or steps and diag is steps[-1].diagnosis:
        diag = diagnose(
            cur.residual_, s, Y=cur_design.Y, tau_out=_rigid_prediction(lib, cur.coef_), alpha=alpha
        )
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
        library_tried=library_tried,
    )
