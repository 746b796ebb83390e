"""Results of the refinement loop (:func:`ident.refine.refine`): accepted steps, rejected
candidates, and the :class:`Refinement` with its report and JSON (docs/refinement.md,
section 4). Pure data and formatting.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from .diagnose import Diagnosis
from .effects import Effect
from .models import IdentModel

if TYPE_CHECKING:  # pragma: no cover
    from .preprocess import Design
    from .refine_library import LibraryStep

__all__ = ["Step", "Rejected", "Refinement"]

#: What the report says when every run replays one trajectory and no validation data were
#: given (:attr:`Refinement.heldout_one_trajectory`).
ONE_TRAJECTORY_NOTE = (
    "note: the runs replay one trajectory, so leaving one out cannot reject a term locked to "
    "it (time since the start, position along the path); validate the added terms on a run "
    "of another trajectory (jointid fit --validate FILE)")


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
    variables : tuple of str
        Every variable the effect involves (two for an interaction), then its modifier.
    named_effect : str or None
        Named physical effect (``"position_periodic_dry_friction"``, ``"zero_order_hold"``...)
        or None for a library basis described in words.
    structure : str
        One line a mechanical engineer reads.
    heldout_rel_error_before, heldout_rel_error_after : float
        Relative error on data the fit never saw (:func:`ident.unseen.heldout_error`: leave
        one run out, or blocked folds of a single run) before and after the step.
    library : LibraryStep or None
        The library-search step of this round (:mod:`ident.refine_library`).
    heldout_kind : str
        ``"leave one run out"`` or ``"blocked folds"``.
    noise_floor : float
        Estimated noise floor (relative error no model can go below,
        :func:`ident.unseen.noise_floor`): the refinement's final estimate, the lowest over
        the residuals of the accepted models; errors are reported as ratios to it.
    noise_floor_tested : float
        The estimate the step's leak test used (the lowest before the step).
    physical_range : str or None
        Why the fitted parameters leave the effect's physical range (the step is then
        reported as a generic structure), None when inside it or undeclared.
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
    heldout_kind: str = "blocked folds"
    noise_floor: float = math.nan
    physical_range: str | None = None
    noise_floor_tested: float = math.nan

    def to_json(self) -> dict[str, Any]:
        """The step as in ``refinement.steps[]`` of the fit JSON."""
        lib = self.library
        fl = self.noise_floor
        return {
            "heldout_kind": self.heldout_kind,
            "noise_floor": _num(fl),
            "noise_floor_tested": _num(self.noise_floor_tested),
            "floor_ratio": {
                "fit_after": _ratio(self.rel_error_after, fl),
                "heldout_after": _ratio(self.heldout_rel_error_after, fl),
                "validation_after": _ratio(self.validation_rel_error_after, fl),
            },
            "leak_warning": leak_note(min(self.rel_error_after, self.heldout_rel_error_after),
                                      fl) or None,
            "physical_range": {"inside": self.physical_range is None,
                               "reason": self.physical_range},
            "sigma_note": self.term.sigma_note(),
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


#: Quadrant drift the report mentions: its printed precision, 0.1 % of the rows (below it the
#: few rows where the load is near zero, e.g. 0.004 % on the example joint).
QUADRANT_DRIFT_SHOWN = 1e-3


def quadrant_drift_note(initial: float, final: float | None) -> str:
    """The report's line when the declared model's fixed quadrants are not its own."""
    after = "" if final is None else f" ({100 * final:.1f} % for the final model)"
    return (f"note: the declared model's quadrants were fixed by a first usual fit's load; its "
            f"own fitted load puts {100 * initial:.1f} % of the rows in the other quadrant"
            f"{after}: there its quadrant-dependent friction acts with the other quadrant's "
            "values, and an added term may stand in for that rather than for an effect of "
            "the joint")


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
    final_validation_design : Design or None
        The validation design with every added term's columns (None without one).
    library_tried : list of dict
        Per step, every structure of the library search with its held-out error and the
        reason it was not selected (see :meth:`ident.library_search.Tried.to_json`).
    heldout_one_trajectory : bool
        Every run replays one trajectory (:func:`ident.unseen.one_trajectory`): leaving a
        run out then cannot reject a term locked to that trajectory; the report says so when
        no validation data were given.
    quadrant_drift_initial, quadrant_drift_final : float or None
        Share of the rows whose quadrant, fixed in the declared model's columns by a first
        usual fit's load, differs from the initial (final) model's own sign(τ̂_out q̇)
        (:func:`ident.refine.quadrant_drift`); None where no quadrant was fixed. Above 0, the
        report says that an added term may stand in for those rows (from
        :data:`QUADRANT_DRIFT_SHOWN`, its printed precision).
    refit : dict or None
        The found terms refitted inside the joint's robot model, every parameter together
        (:meth:`ident.fitting.FitReport.refit_found_terms`; the ``refit`` record of
        ``jointid fit --robot --refine``), set by the callers that hold the fit report
        (``JointModel.refine``, ``jointid fit --refine``, ``jointid demo``); None: not made.
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
    final_validation_design: Design | None = None
    library_tried: list[dict] = field(default_factory=list)
    heldout_kind: str = "blocked folds"
    heldout_rel_error_initial: float = math.nan
    heldout_rel_error_final: float = math.nan
    noise_floor: float = math.nan
    noise_floor_initial: float = math.nan
    heldout_one_trajectory: bool = False
    quadrant_drift_initial: float | None = None
    quadrant_drift_final: float | None = None
    refit: dict[str, Any] | None = None

    @property
    def terms(self) -> list[Effect]:
        """The added terms, in order."""
        return [s.term for s in self.steps]

    def to_json(self) -> dict[str, Any]:
        """The ``refinement`` object of the fit JSON (see docs/refinement.md)."""
        fl = self.noise_floor
        return {
            "steps": [s.to_json() for s in self.steps],
            "rejected": [r.to_json() for r in self.rejected],
            "noise_floor": _num(fl),
            "noise_floor_initial": _num(self.noise_floor_initial),
            "heldout_kind": self.heldout_kind,
            "heldout_one_trajectory": self.heldout_one_trajectory,
            "quadrant_drift_initial": _num(self.quadrant_drift_initial),
            "quadrant_drift_final": _num(self.quadrant_drift_final),
            "heldout_rel_error_initial": _num(self.heldout_rel_error_initial),
            "heldout_rel_error_final": _num(self.heldout_rel_error_final),
            "floor_ratio_final": {"fit": _ratio(self.rel_error_final, fl),
                                  "heldout": _ratio(self.heldout_rel_error_final, fl)},
            "leak_warning": leak_note(min(self.rel_error_final, self.heldout_rel_error_final),
                                      fl) or None,
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
            **({} if self.refit is None else {"refit": self.refit}),
        }

    def format_table(self) -> str:
        """Alias of :meth:`format_report` (what ``jointid fit --refine`` prints)."""
        return self.format_report()

    def format_report(self) -> str:
        """Human-readable report of every step."""
        fl = self.noise_floor
        out = [
            f"Refinement: relative error {_pct(self.rel_error_initial)} -> "
            f"{_pct(self.rel_error_final)}{leak_note(self.rel_error_final, fl)}"
            + (
                f" (validation {_pct(self.validation_rel_error_initial)} -> "
                f"{_pct(self.validation_rel_error_final)})"
                if self.validation_rel_error_initial is not None
                else ""
            ),
            f"  {self.heldout_kind}: {_pct(self.heldout_rel_error_initial)} -> "
            f"{_pct(self.heldout_rel_error_final)}"
            f"{leak_note(self.heldout_rel_error_final, fl)}; noise floor {_pct(fl)} "
            f"(fit / floor x{_ratio_s(self.rel_error_final, fl)}, held-out / floor "
            f"x{_ratio_s(self.heldout_rel_error_final, fl)})",
        ]
        if self.heldout_one_trajectory and self.validation_rel_error_initial is None:
            out.append(f"  {ONE_TRAJECTORY_NOTE}")
        drift = self.quadrant_drift_initial
        if drift is not None and drift >= QUADRANT_DRIFT_SHOWN:
            out.append(f"  {quadrant_drift_note(drift, self.quadrant_drift_final)}")
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
            note = s.term.sigma_note()
            if note:
                out.append(f"    note: {note}")
            out.append(
                f"  F test {s.f_statistic:.3g} (p={s.f_p_value:.1e}); relative error "
                f"{_pct(s.rel_error_before)} -> {_pct(s.rel_error_after)}, "
                f"low velocity {_pct(s.low_before)} -> {_pct(s.low_after)}, "
                f"high velocity {_pct(s.high_before)} -> {_pct(s.high_after)}"
            )
            if s.physical_range is not None:
                out.append(f"  outside the physical range: {s.physical_range}")
            if math.isfinite(s.heldout_rel_error_before):
                out.append(
                    f"  held-out ({s.heldout_kind}) {_pct(s.heldout_rel_error_before)} -> "
                    f"{_pct(s.heldout_rel_error_after)}"
                    f"{leak_note(s.heldout_rel_error_after, s.noise_floor)}; noise floor "
                    f"{_pct(s.noise_floor)} (fit x{_ratio_s(s.rel_error_after, s.noise_floor)},"
                    f" held-out x{_ratio_s(s.heldout_rel_error_after, s.noise_floor)})"
                    f"{leak_note(s.rel_error_after, s.noise_floor)}"
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


def _ratio(x: float | None, floor: float) -> float | None:
    """x / noise floor (None when either is unknown)."""
    if x is None or not (math.isfinite(x) and math.isfinite(floor) and floor > 0):
        return None
    return float(x) / floor


def _ratio_s(x: float | None, floor: float) -> str:
    r = _ratio(x, floor)
    return "n/a" if r is None else f"{r:.2f}"


def leak_note(x: float | None, floor: float) -> str:
    """``" [below the noise floor: leak?]"`` when an error is below the estimated noise
    floor (no model explains noise: a column built from the output), else ``""``."""
    r = _ratio(x, floor)
    return " [below the noise floor: leak?]" if r is not None and r < 1.0 else ""


def _num(x: float | None) -> float | None:
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def _pct(x: float | None) -> str:
    return "n/a" if x is None or not math.isfinite(x) else f"{100 * x:.2f} %"
