"""The identification pipeline used by ``jointid fit`` and the demo.

(Past 600 lines: one pipeline -- fit both models on the same samples, validate, refine,
assemble the result -- whose stages share the preprocessing state; split by stage it would pass
that state between modules.)

:func:`fit_models` takes experiments (or concatenated signals) and fits the usual model
(eq. 38-39) and/or the paper model (eq. 42-43) on the same samples ("the two models are
compared using exactly the same identification method with the same measurements",
section IV.C), optionally scans q_s, evaluates Table III bands, Table IV and
cross-validation files, and returns a :class:`FitReport` (``.to_json()``,
``.format_tables()``). Pure numerics: loading belongs to :mod:`ident.loaders`.

The fit is the robot model's (issue 24, a joint is a 1-dof robot): every estimate -- the
first usual fit of the sign check, the q_s scan, the two models, Table IV -- is
:class:`ident.robot.estimate.RobotModel`'s through :class:`ident.one_joint.OneJointProblem`
(the columns chain, eq. 42's products formed at full rate per q_s, the single-joint
elimination), held in an :class:`~ident.models.IdentModel` by the single-joint names
(:func:`_fitted`). The decimated system of each model (:class:`ident.preprocess.Design`:
Table III's bands, the plots and the refinement (:mod:`ident.refine`) read it) is built on
the same chain's full-rate signals (:meth:`OneJointProblem.design`, the robot's load model:
the same rows, checked), so the data are filtered once; validation
files (and :meth:`FitReport.designs_for`) get theirs the same way (:func:`_other_designs`: a
problem on those files with the settled settings and the fit's first usual fit as load model,
as Table IV's; the 1-dof regressor evaluated once per validation run; the same floats as
:func:`ident.preprocess.build_design` with those settings).

The q_s scan -- the grid, the bounded search, and :func:`rescan_qs`, the rescan after a
refinement through the robot model's refit of the found terms
(:meth:`FitReport.rescan_found_terms` for a joint) -- is :mod:`ident.qs_scan`; its public
names (``qs_grid``, ``rescan_qs``, ``QsScan``, the ``QS_*`` constants) are re-exported here.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from trajectories.friction import DEFAULT_Q_S

from . import DataError
from .chain import check_torque_delay, default_torque_delay, iv_band_note
from .effects import rigid_prediction
from .loaders import Experiment, concat
from .models import (
    IdentModel,
    LoadDependent,
    Payload,
    QuadrantCoulomb,
    RigidBody,
    new_model,
    usual_model,
)
from .one_joint import (
    SIGN_CHECK_MIN_KEPT,
    SKIPPED_CHECK_BAND,
    OneJointModel,
    OneJointProblem,
    refit_found_terms,
    rescan_found_terms,
)
from .preprocess import Design, check_reference
from .qs_scan import (
    QS_SEARCH_EVALS,
    QS_WORKERS,
    QS_XTOL,
    QsScan,
    qs_grid,
    rescan_qs,
    scan_qs,
)
from .quadrant_band import MAX_PASSES, QuadrantPasses
from .quadrant_band import QUADRANT_TOL as QUADRANT_TOL
from .results import (
    band_errors,
    format_error_table,
    format_parameter_table,
    format_table_iv,
    json_float,
    parameters_json,
    position_split,
    position_split_json,
    position_split_notes,
    removed_json,
)
from .robot.design import DQ_MIN_FRACTION
from .robot.estimate import THIN_QUADRANT, RobotModel
from .robot.selection_shift import selection_shift, shift_note
from .robot.signals import RobotSignals
from .signals import Signals
from .terms import Library, Term
from .vocab import MODEL_NAMES, QS_WORDS, model_name, qs_value, renamed_keywords

__all__ = [
    "FitReport",
    "QsScan",
    "fit_models",
    "qs_grid",
    "rescan_qs",
    "QS_XTOL",
    "QS_SEARCH_EVALS",
    "QS_WORKERS",
    "FORMAT",
    "DEFAULT_QS",
    "DEFAULT_Q_S",
    "DQ_MIN_FRACTION",
    "SIGN_CHECK_MIN_KEPT",
]

FORMAT = "jointid-fit/2"
#: Older fit formats still read (:func:`ident.vocab.upgrade_record`): /1 spelled ``new``,
#: ``qs``, ``ols`` where /2 has ``paper``, ``q_s``, ``ls``.
OLD_FORMATS = ("jointid-fit/1",)
#: The paper's final a-priori velocity constant [rad/s] (section III.D); defined once, in
#: :mod:`trajectories.friction` (``DEFAULT_QS`` is the older spelling, kept for callers).
DEFAULT_QS = DEFAULT_Q_S
#: DQ_MIN_FRACTION (:mod:`ident.robot.design`): default stiction-area threshold, a fraction of the
#: maximum velocity (section III.D, eq. 26). SIGN_CHECK_MIN_KEPT (:mod:`ident.one_joint`):
#: the sign check (see :func:`fit_models`) is skipped when it would keep fewer samples than
#: this fraction: then tau_out is near zero most of the time and the check is meaningless.
#: Condition number (unit-norm columns) above which a note warns of poor excitation.
COND_WARN = 1e3




def _as_signals(data: Sequence[Experiment] | Signals, joint: str | bool | None) -> Signals:
    if isinstance(data, Signals):
        s = data
    else:
        if not data:
            raise DataError("no experiment given")
        s = concat(list(data))
    if joint is not None:
        rev = joint if isinstance(joint, bool) else str(joint).lower() == "revolute"
        if not isinstance(joint, bool) and str(joint).lower() not in ("revolute", "prismatic"):
            raise DataError(f"joint kind {joint!r}: expected 'revolute' or 'prismatic'")
        if rev != s.revolute:
            s = replace(s, revolute=rev)
    return s


#: Quadrant decisions of the single-joint paper model at most (the first usual fit's
#: included), the sign check skipped: the n-dof fit's cap (:mod:`ident.quadrant_band`, the
#: passes' one rule; ``QUADRANT_TOL``, ``THETA_TOL`` and ``BAND_LEAVE`` are its)
REQUADRANT_PASSES = MAX_PASSES


def paper_load_values(lib: Library, coef: dict[str, float]) -> dict[str, float] | None:
    """The paper model's own load parameters by the single-joint names (J, MX, MY): the
    mean of each inner column's motor and generator products, (a_m chi + a_g chi) / 2
    (:func:`ident.effects.rigid_prediction`); None without a load-dependent term."""
    pred = rigid_prediction(lib, dict(coef))
    if pred is None:
        return None
    names = [n for t in pred.terms for n in t.names()]
    return dict(zip(names, (float(c) for c in pred.coef), strict=True))


def _same_rows(name: str, m: IdentModel, d: Design) -> None:
    """Refuse a robot fit and a single-joint design of model ``name`` on other samples."""
    if m.result_.m != len(d):
        raise DataError(f"{name} model: the robot fit has {m.result_.m} rows, the design "
                        f"{len(d)}: not the same samples")


def _quadrant_loads(settings: dict[str, Any]) -> list[dict[str, float]]:
    """The loads of a fit's quadrant re-decisions, in order (``quadrant_loads``; an older
    record's final ``quadrant_load`` alone)."""
    loads = settings.get("quadrant_loads")
    if loads:
        return list(loads)
    last = settings.get("quadrant_load")
    return [] if last is None else [last]


def _step_sigma(before: IdentModel, after: IdentModel) -> float:
    """The largest change of a parameter between two fits of one model, in the standard
    deviation of the later fit (eq. 15; a removed parameter counts as 0): the step of the
    quadrant passes' rule (:func:`ident.quadrant_band.settled`); inf where a parameter with
    a changed value has no deviation."""
    step = 0.0
    for n in set(before.coef_) | set(after.coef_):
        delta = abs(after.coef_.get(n, 0.0) - before.coef_.get(n, 0.0))
        if delta == 0.0:
            continue
        sd = after.std_.get(n, 0.0) or before.std_.get(n, 0.0)
        step = max(step, delta / sd if sd > 0 else np.inf)
    return step


def _fitted(library: Library, name: str, fit: OneJointModel) -> IdentModel:
    """An :class:`~ident.models.IdentModel` holding the robot model's fit ``fit`` (by the
    single-joint names): the same public attributes (``coef_`` ... ``result_``,
    ``estimator_``), so ``predict``, ``rel_error_on``, the reports and the refinement read
    it as they read a single-joint fit; ``robot_`` is the fitted
    :class:`~ident.robot.estimate.RobotModel`."""
    m = IdentModel(library, name)
    m._set(fit.result)
    m.estimator_ = fit.estimator
    m.robot_ = fit.robot
    m.robot_names_ = fit.names
    return m


def _sign_check_shift(problem: OneJointProblem, m: IdentModel, q_s: float, eliminate: bool,
                      threshold_pct: float | None) -> dict[str, float] | None:
    """The paper model ``m``'s sign-check shift (:mod:`ident.robot.selection_shift`, as
    ``jointid fit --robot``): its record's parameters against the same fit on the rows before
    the sign check (:meth:`~ident.one_joint.OneJointProblem.unchecked_fit`). None when the
    check left no row out, or the model cannot be fitted on those rows (a diagnostic: never
    fatal)."""
    try:
        other = problem.unchecked_fit(q_s, eliminate=eliminate, threshold_pct=threshold_pct)
    except (DataError, np.linalg.LinAlgError):
        return None
    if other is None:
        return None
    return selection_shift(parameters_json(m),
                           dict(zip(other.result.names, other.result.chi.tolist(), strict=True)))


def _one_sign_load(d: Design) -> str | None:
    """What to say when the load keeps one sign on the paper design's rows (its quadrant,
    the model's or eq. 26's proxy, times sign(dq)): the motor and the generator rows are then
    one direction each and c_m, c_g and the offset (d_m, d_g) trade off (section III.B); the
    elimination would keep a combination under one name. None otherwise."""
    if "c_m" not in d.names or "c_g" not in d.names:
        return None
    # the model's quadrant as its columns carry it: c_m's column is P+ sign(dq), c_g's
    # P- sign(dq), so their difference is sign(P) sign(dq), the load's sign (never the
    # measured torque's proxy sign(tau dq) that Signals.sign_power falls back to)
    load = d.W[:, d.names.index("c_m")] - d.W[:, d.names.index("c_g")]
    pos = float(np.mean(load > 0))
    if min(pos, 1.0 - pos) >= THIN_QUADRANT:
        return None
    return (f"the load tau_out keeps one sign on {100 * max(pos, 1 - pos):.1f} % of the "
            "samples, so the motor and the generator rows are one direction each: c_m, c_g "
            "and the offset (and d_m, d_g) cannot be told apart, and their values are "
            "combinations of them, not the friction of each quadrant (section III.B: a "
            "trajectory across the position where the gravity torque changes sign, or a "
            "payload that reverses the load)")


def _split(
    data: Sequence[Experiment] | Signals, s: Signals, ref: np.ndarray | None
) -> tuple[list[Experiment], list[np.ndarray] | None]:
    """The experiments of ``data`` (concatenated signals: one per run of equal
    ``experiment``) and their references (``ref`` aligned with ``s``) cut to them."""
    if isinstance(data, Signals):
        cut = np.flatnonzero(np.diff(s.experiment) != 0) + 1
        bounds = list(zip(np.r_[0, cut], np.r_[cut, len(s)], strict=True))
        exps = [Experiment(f"experiment {int(s.experiment[a])}", s.t[a:b], s.q[a:b],
                           s.tau[a:b], float(s.payload_mass[a]), float(s.payload_arm[a]),
                           s.revolute) for a, b in bounds]
    else:
        exps = list(data)
        ends = np.cumsum([len(e) for e in exps])
        bounds = list(zip(np.r_[0, ends[:-1]], ends, strict=True))
    refs = None if ref is None else [ref[a:b] for a, b in bounds]
    return exps, refs


def _library(name: str, q_s: float, revolute: bool, payload: bool) -> Library:
    if name == "usual":
        return usual_model(revolute, payload=payload)
    if name == "paper":
        return new_model(q_s, revolute, payload=payload)
    raise DataError(f"model {name!r}: expected 'usual' or 'paper'")


def _combined_library(models: Sequence[str], qs0: float, revolute: bool,
                      payload: bool) -> Library:
    """The terms of every requested model, each once (q_s ``qs0``)."""
    terms: list[Term] = []
    seen: set[str] = set()
    for name in models:
        for t in _library(name, qs0, revolute, payload).terms():
            if not set(t.names()) & seen:
                terms.append(t)
                seen |= set(t.names())
    return Library(*terms)


def _other_designs(
    data: Sequence[Experiment] | Signals,
    sig: Signals,
    models: Sequence[str],
    names: Sequence[str],
    qs0: float,
    q_s: float,
    has_payload: bool,
    pre: dict[str, Any],
    first: RobotModel | None,
    band_nm: float = 0.0,
    fit_designs: dict[str, Design] | None = None,
) -> tuple[dict[str, Design], RobotSignals]:
    """The design of each model of ``names`` on other data than the fit's (validation
    files), with the fit's settled preprocessing (``pre``: cut-off, decimation, thresholds,
    torque delay, the sign check's ``load_model`` and ``quadrant_load``) and its load model
    ``first`` (the first usual fit deciding the rows and quadrants, requadranted by
    ``pre["quadrant_load"]`` as the fit was), built as the fit's designs are: the experiments
    through the robot chain (:class:`~ident.one_joint.OneJointProblem` with the fit's
    ``first``, as Table IV's problem), the design of every model in ``models`` on its
    full-rate signals (:meth:`~ident.one_joint.OneJointProblem.design`), the paper model at
    ``q_s`` from its products (:meth:`~ident.one_joint.OneJointProblem.paper_columns`) and
    its quadrant band ``band_nm`` [N m] (0: none) left out: the 1-dof regressor is evaluated
    once per run at full rate. A model's columns are in the order of its design in
    ``fit_designs`` (the fit's), when given (the paper model's design after the quadrants were
    decided again is its own library's, not the combined one's).

    Returns
    -------
    designs : dict of str to Design
    signals : RobotSignals
        The chain's signals; ``columns.full_columns.evaluations`` counts the full-rate
        evaluations of each run's regressor (its kept columns released).
    """
    exps, _ = _split(data, sig, None)
    load_model = pre.get("load_model")
    checked = load_model is not None and first is not None
    settled = {k: pre[k] for k in ("cutoff_hz", "decimation", "dq_min", "trim", "guard")}
    problem = OneJointProblem(
        exps, revolute=sig.revolute, has_payload=has_payload, references=None,
        paper="paper" in models, torque_delay=float(pre["torque_delay"]), **settled,
        tau_min=pre.get("tau_min"), sign_check=False, first=first if checked else None,
        first_checked=checked and pre.get("sign_check", True), model_quadrant=checked)
    if problem.model_quadrant and band_nm > 0:
        # the fit's band h and passes: the band's rows with its hysteresis (quadrant_band)
        problem.replay(_quadrant_loads(pre), band_nm)
    elif pre.get("quadrant_load") is not None and problem.model_quadrant:
        problem.requadrant(pre["quadrant_load"])  # the quadrants of the fit's final load

    def design(lib: Library) -> Design:
        return problem.design(lib, sig, tau_min=pre.get("tau_min"), load_model=load_model,
                              sign_check=pre.get("sign_check", True))

    full = design(_combined_library(models, qs0, sig.revolute, has_payload))
    out = {}
    for name in names:
        d = _part(full, name, has_payload, q_s, qs0,
                  lambda q: problem.paper_columns(q, load_model))[1]
        if fit_designs is not None and name in fit_designs and (
                fit_designs[name].names != d.names):  # the model's own library's order
            own = design(_combined_library([name], qs0, sig.revolute, has_payload))
            d = _part(own, name, has_payload, q_s, qs0,
                      lambda q: problem.paper_columns(q, load_model))[1]
        masks = problem.band_masks() if problem.model_quadrant else None
        if name == "paper" and band_nm > 0 and load_model is not None:
            d = d.select(dq_min=d.dq_min, tau_min=d.tau_min,
                         quadrant_band=band_nm if masks is None else masks)
        out[name] = d
    sig_v = problem.signals  # its counts kept; its full-rate signals and columns released
    if sig_v.columns.full_columns is not None:
        sig_v.columns.full_columns.release()
    return out, replace(sig_v, columns=replace(sig_v.columns, full=None))


def _part(d: Design, name: str, payload: bool, q: float, qs0: float,
          given: Callable[[float], Any] | None = None) -> tuple[Library, Design]:
    """The library of model ``name`` (q_s ``q``) and its columns of the combined design.

    At another q_s than the design's ``qs0`` the paper model's quadrant terms are formed
    again (appended, :meth:`~ident.preprocess.Design.with_term`): from ``given(q)`` when it
    gives their decimated columns (the robot chain's full-rate products at q,
    :meth:`~ident.one_joint.OneJointProblem.paper_columns`, when ``d`` is that problem's
    design), else evaluated on the design's full-rate signals."""
    lib = _library(name, q, d.signals.revolute, payload)
    keep = set(lib.names())
    sub = d.without([n for n in d.names if n not in keep])
    if name == "paper" and q != qs0:
        quad = [t for t in sub.library.terms() if isinstance(t, LoadDependent | QuadrantCoulomb)]
        sub = sub.without([n for t in quad for n in t.names()])
        cols = None if given is None else given(q)
        for t in lib.terms():
            if isinstance(t, LoadDependent | QuadrantCoulomb):
                sub = sub.with_term(t, decimated=cols)
    return lib, sub


@dataclass
class FitReport:
    """Everything :func:`fit_models` identified.

    Attributes
    ----------
    models : dict[str, IdentModel]
        Fitted models by name (``"usual"``, ``"paper"``): the robot model's fits by the
        single-joint names (``robot_``: the :class:`~ident.robot.estimate.RobotModel`;
        ``robot_names_``: robot name -> (single-joint name, sign)).
    designs : dict[str, Design]
        The identification system of each model.
    validation_designs : dict[str, Design]
        The cross-validation system of each model (empty without validation data).
    vmax : float
        Maximum |dq| of the identification samples [rad/s] (Table III bands).
    q_s : float
        q_s used by the paper model [rad/s].
    qs_scan : list of (q_s, rel_error)
        The scan, when q_s was scanned.
    table_iv : dict or None
        ``{"with_payloads": {model: err}, "without_payload": {model: err}}``.
    sources, validation_sources : list of str
        Input files.
    notes : list of str
        Remarks for the user (terms dropped because of the data, ...).
    has_payload : bool
        Whether the payload term was part of the models.
    settings : dict
        The preprocessing settled on the identification data (keyword arguments of
        :func:`ident.preprocess.build_design`, and ``quadrant_load`` when the quadrants were
        decided again), reused for validation data.
    qs_design : float
        q_s the combined design was built with (the q_s-dependent columns are rebuilt
        when ``q_s`` differs).
    robot_signals : dict[str, RobotSignals]
        The samples each model's robot fit read (the paper model: with its products formed
        at full rate), for :meth:`refit_found_terms`; not serialised.
    torque_delay_given : bool
        Whether ``settings["torque_delay"]`` was given (``torque_delay`` of
        :func:`fit_models`) or chosen (the JSON's ``preprocessing.torque_delay_given``).
    sign_check_shift : dict[str, float] or None
        When the sign check left rows out: per paper-model parameter, z = (its estimate on
        the rows before the check - the reported one) / its reported std
        (:func:`ident.robot.selection_shift.selection_shift`, the JSON's
        ``models.paper.sign_check_shift``); None otherwise.
    validation_signals : RobotSignals or None
        The robot chain's signals of the validation files (``validation_designs`` are built
        on them, :func:`_other_designs`): ``columns.full_columns.evaluations`` counts the
        full-rate evaluations of each validation run's 1-dof regressor (1: once); not
        serialised.
    first_fit : RobotModel or None
        The load model of the sign check and quadrants (the robot's first usual fit), which
        :meth:`designs_for` applies to other data; None without one.
    band_nm : float
        The paper model's quadrant band [N m] (the sign check skipped,
        :meth:`ident.one_joint.OneJointProblem.band`), 0 without one.
    paper_products : callable or None
        q_s [rad/s] -> the paper model's robot signals with the full-rate products formed at
        that q_s (:meth:`ident.one_joint.OneJointProblem.products`, its q_s-free part kept:
        only the E products are formed again), for :meth:`rescan_found_terms`; None without
        a paper fit; not serialised.
    position_splits : dict[str, dict or None]
        Per model with validation designs, its validation error split by the fit's position
        range (:func:`ident.results.position_split`, q in [rad] or [m]) as :func:`fit_models`
        computed it for its note; the JSON's ``validation_position_split`` reads it
        (computed on demand by :meth:`position_split` for a model without an entry).
    """

    models: dict[str, IdentModel]
    designs: dict[str, Design]
    validation_designs: dict[str, Design]
    vmax: float
    q_s: float
    revolute: bool
    qs_scan: list[tuple[float, float]] = field(default_factory=list)
    table_iv: dict[str, dict[str, float | None]] | None = None
    sources: list[str] = field(default_factory=list)
    validation_sources: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    has_payload: bool = False
    settings: dict[str, Any] = field(default_factory=dict, repr=False)
    qs_design: float = DEFAULT_QS
    robot_signals: dict[str, RobotSignals] = field(default_factory=dict, repr=False,
                                                   compare=False)
    torque_delay_given: bool = False
    sign_check_shift: dict[str, float] | None = None
    validation_signals: RobotSignals | None = field(default=None, repr=False, compare=False)
    first_fit: RobotModel | None = field(default=None, repr=False, compare=False)
    band_nm: float = 0.0
    paper_products: Callable[[float], RobotSignals] | None = field(default=None, repr=False,
                                                                   compare=False)
    position_splits: dict[str, dict[str, Any] | None] = field(default_factory=dict,
                                                              repr=False)

    def refit_found_terms(self, name: str, terms: Sequence[Term],
                          design: Design | None = None) -> dict[str, Any]:
        """The terms a refinement of model ``name`` found, refitted inside its robot model
        with every parameter (:func:`ident.one_joint.refit_found_terms`): the ``refit``
        record of the refinement (docs/fit-json.md), or ``{"error": why}``.

        ``design``: the refinement's final design (``Refinement.final_design``): the terms'
        columns are then its own (formed at full rate, filtered and decimated with the
        torque), so the refit is the refinement's final fit computed by the robot model;
        without it they are evaluated on the decimated states
        (:func:`ident.robot.design.joint_columns`, as the n-dof refit does)."""
        try:
            m, sig, columns, zcols = self._found_terms(name, terms, design)
        except DataError as exc:
            return {"error": str(exc)}
        return refit_found_terms(m.robot_, sig, terms, revolute=self.revolute,
                                 names=getattr(m, "robot_names_", None), columns=columns,
                                 instrument_columns=zcols)

    def rescan_found_terms(self, name: str, terms: Sequence[Term],
                           design: Design | None = None, *, n_grid: int = 13,
                           progress: Callable[[int, int, float, float], None] | None = None
                           ) -> QsScan:
        """q_s chosen again with the terms a refinement of the paper model found
        (:func:`ident.one_joint.rescan_found_terms`): at each q_s the refit of
        :meth:`refit_found_terms` (the terms' columns ``design``'s, as there) on the robot
        fit's full-rate products formed at that q_s (``paper_products``). The result's
        ``record`` is that refit at the chosen q_s, by the single-joint names.

        Raises
        ------
        DataError
            Not the paper model, no robot fit or products to rescan, a design not on the
            robot fit's rows, or the refit cannot be made (one line).
        """
        if name != "paper" or self.paper_products is None:
            raise DataError(f"{name} model: no paper model's products to rescan q_s with "
                            "(q_s is a parameter of the paper model)")
        m, _, columns, zcols = self._found_terms(name, terms, design)
        return rescan_found_terms(m.robot_, self.paper_products, terms, vmax=self.vmax,
                                  revolute=self.revolute,
                                  names=getattr(m, "robot_names_", None), columns=columns,
                                  instrument_columns=zcols, n_grid=n_grid, progress=progress)

    def _found_terms(self, name: str, terms: Sequence[Term], design: Design | None
                     ) -> tuple[IdentModel, RobotSignals, list[np.ndarray] | None,
                                list[np.ndarray] | None]:
        """Model ``name``, its robot fit's signals and the found terms' columns and IDIM-IV
        instruments from ``design`` (None without it) on the robot fit's rows, for
        :meth:`refit_found_terms` and :meth:`rescan_found_terms`.

        Raises
        ------
        DataError
            No robot model, a design not on its rows or without a term's column.
        """
        m = self.models[name]
        if getattr(m, "robot_", None) is None or name not in self.robot_signals:
            raise DataError(f"{name} model: no robot model to refit")
        sig = self.robot_signals[name]
        columns = zcols = None
        if design is not None:
            rows = np.flatnonzero(m.robot_.fitted_rows(sig)[:, 0])
            if rows.size != len(design) or not np.allclose(design.Y, sig.tau[rows, 0],
                                                           rtol=1e-9, atol=0.0):
                raise DataError(f"{name} model: the refinement's design is not on the robot "
                                "fit's rows")
            names = [n for t in terms for n in t.names()]
            missing = [n for n in names if n not in design.names]
            if missing:
                raise DataError(f"{name} model: the design has no column {missing[0]}")
            idx = [design.names.index(n) for n in names]
            X = np.zeros((sig.n, len(names)))
            X[rows] = design.W[:, idx]
            columns = [X]
            if design.Z is not None:  # IDIM-IV: the design's instruments of the terms
                Xz = np.zeros((sig.n, len(names)))
                Xz[rows] = design.Z[:, idx]
                zcols = [Xz]
        return m, sig, columns, zcols

    def designs_for(self, data: Sequence[Experiment] | Signals) -> dict[str, Design]:
        """The system of other data (e.g. validation files) for every fitted model, with the
        preprocessing settled on the identification data (same cut-off, decimation,
        thresholds, sign check, quadrants and quadrant band), as ``validation_designs``
        (:func:`_other_designs`).

        Parameters
        ----------
        data : list of Experiment or Signals
            Experiments to evaluate (their joint kind is taken as the fit's).
        """
        sig = _as_signals(data, self.revolute)
        return _other_designs(data, sig, list(self.models), list(self.models),
                              self.qs_design, self.q_s, self.has_payload, self.settings,
                              self.first_fit, self.band_nm, self.designs)[0]

    def errors(self, name: str) -> dict[str, float | None]:
        """Table III entries of one model: ``all``, ``low``, ``high``, ``validation``."""
        m, d = self.models[name], self.designs[name]
        rho = d.Y - m.predict(d)
        out: dict[str, float | None] = dict(band_errors(d.Y, rho, d.signals.dq, self.vmax))
        out["all"] = m.rel_error_
        vd = self.validation_designs.get(name)
        out["validation"] = m.rel_error_on(vd) if vd is not None else None
        return out

    def position_split(self, name: str) -> dict[str, Any] | None:
        """One model's validation error split by the fit's position range
        (:func:`ident.results.position_split`; q in [rad] or [m]), None without validation:
        the one :func:`fit_models` computed for its note (``position_splits``), else
        computed here."""
        if name in self.position_splits:
            return self.position_splits[name]
        vd = self.validation_designs.get(name)
        if vd is None:
            return None
        m = self.models[name]
        return position_split(self.designs[name].signals.q, vd.signals.q, vd.Y,
                              vd.Y - m.predict(vd))

    def to_json(self) -> dict[str, Any]:
        """The JSON record documented in ``docs/fit-json.md``."""
        any_design = next(iter(self.designs.values()))
        models: dict[str, Any] = {}
        for name, m in self.models.items():
            e = self.errors(name)
            rec: dict[str, Any] = {
                "description": m.library.describe(),
                "rel_error": json_float(e["all"]),
                "rel_error_low_velocity": json_float(e["low"]),
                "rel_error_high_velocity": json_float(e["high"]),
                "sigma_rho": json_float(m.sigma_rho_),
                "cond": json_float(m.cond_),
                "cond_raw": json_float(m.result_.cond_raw),
                "estimator": getattr(m, "estimator_", "ls"),
                "samples": int(m.result_.m),
                "parameters": parameters_json(m),
                "removed": removed_json(m),
            }
            if e["validation"] is not None:
                rec["validation_rel_error"] = json_float(e["validation"])
                split = self.position_split(name)
                if split is not None:
                    rec["validation_position_split"] = position_split_json(split)
            if name == "paper":
                rec["q_s"] = self.q_s
                if m.quadrant_changes_ is not None:  # the model quadrants decided again
                    rec["quadrant_passes"] = 1 + len(m.quadrant_changes_)
                    rec["converged"] = bool(m.converged_)
                    if not m.converged_:
                        rec["convergence"] = m.convergence_
                if self.sign_check_shift is not None:
                    rec["sign_check_shift"] = dict(self.sign_check_shift)
            models[name] = rec
        out: dict[str, Any] = {
            "format": FORMAT,
            "inputs": list(self.sources),
            "validation_inputs": list(self.validation_sources),
            "joint": "revolute" if self.revolute else "prismatic",
            "preprocessing": {**any_design.settings(),  # (and whether the delay was given)
                              "torque_delay_given": self.torque_delay_given},
            "vmax": json_float(self.vmax),
            "bands": {"low": [0.0, 0.10], "high": [0.35, 1.0]},
            "q_s": self.q_s,
            "models": models,
            "notes": list(self.notes),
        }
        if self.qs_scan:
            out["q_s_scan"] = [{"q_s": q, "rel_error": json_float(e)} for q, e in self.qs_scan]
        if self.table_iv is not None:
            out["table_iv"] = {
                k: {m: json_float(v) for m, v in d.items()} for k, d in self.table_iv.items()
            }
        return out

    def format_tables(self) -> str:
        """Tables I-IV as plain text."""
        parts = []
        for name, m in self.models.items():
            title = f"Identified values with the {name} model"
            if name == "paper":
                title += f" (q_s = {self.q_s:g})"
            parts.append(format_parameter_table(m, title))
        parts.append(format_error_table({n: self.errors(n) for n in self.models}))
        if self.table_iv is not None:
            parts.append(format_table_iv(self.table_iv))
        if self.qs_scan:
            parts.append(
                "q_s scan (paper model): " + ", ".join(f"{q:.4g}: {e:.4g}" for q, e in self.qs_scan)
            )
        parts.extend(f"note: {n}" for n in self.notes)
        return "\n\n".join(parts)


def _references(
    references: Sequence[Any] | np.ndarray | None,
    data: Sequence[Experiment] | Signals,
    s: Signals,
) -> np.ndarray | None:
    """The reference positions as one array aligned with ``s`` (see :func:`fit_models`)."""
    if references is None:
        return None
    if isinstance(references, str):
        if references != "auto":
            raise DataError(f"references {references!r}: expected arrays, 'auto' or None")
        if isinstance(data, Signals):
            return None
        found = [getattr(e, "q_ref", None) for e in data]
        if any(r is None for r in found):
            return None
        arrays = [np.asarray(r, dtype=float).ravel() for r in found]
        if not all(
            a.size == len(e) and np.all(np.isfinite(a)) for a, e in zip(arrays, data, strict=True)
        ):
            return None
        return np.concatenate(arrays)
    if isinstance(data, Signals) or isinstance(references, np.ndarray):
        parts = [references]
    else:
        parts = list(references)
        if len(parts) != len(data):
            raise DataError(
                f"references: {len(parts)} given for {len(data)} experiments (one per experiment)"
            )
    arrays = []
    for i, r in enumerate(parts):
        a = np.asarray(getattr(r, "q_ref", r), dtype=float).ravel()
        if not isinstance(data, Signals) and not isinstance(references, np.ndarray):
            e = data[i]
            if a.size != len(e):
                raise DataError(
                    f"references[{i}] ({e.source}): {a.size} samples, expected {len(e)}"
                )
        arrays.append(a)
    ref = np.concatenate(arrays)
    if ref.size != len(s):
        raise DataError(f"references: {ref.size} samples, expected {len(s)}")
    check_reference(ref, s, None if isinstance(data, Signals) else [e.source for e in data])
    return ref


def fit_models(
    data: Sequence[Experiment] | Signals,
    models: Sequence[str] = MODEL_NAMES,
    *,
    q_s: float | str = DEFAULT_QS,
    joint: str | bool | None = None,
    validation: Sequence[Experiment] | Signals | None = None,
    cutoff_hz: float | None = None,
    decimation: int | None = None,
    dq_min: float | None = None,
    tau_min: float | None = None,
    trim: int | None = None,
    guard: int | None = None,
    sign_check: bool = True,
    eliminate: bool = True,
    threshold_pct: float | None = None,
    table_iv: bool = True,
    references: Sequence[Any] | np.ndarray | str | None = "auto",
    torque_delay: float | str = "auto",
    payload: bool | None = None,
    like: FitReport | None = None,
    axis: str | None = None,
    **deprecated: Any,
) -> FitReport:
    """Identify the usual and/or the paper model on all experiments in one LS (eq. 36, 40).

    Parameters
    ----------
    data : list of Experiment or Signals
        Identification experiments (one per payload run).
    models : sequence of {"usual", "paper"}
        Models to fit.
    q_s : float, "scan" or "scan-joints"
        q_s [rad/s] of the paper model, or ``"scan"`` (``"scan-joints"``, the robot's per-joint
        scan, is the same on one joint) to pick the one that minimises the new
        model's residual norm (section III.D): the best of :func:`qs_grid`, then a bounded
        1-D search between its neighbours (every evaluated q_s is in ``qs_scan``).
    joint : {"revolute", "prismatic"} or None
        Overrides the joint kind of the data.
    validation : list of Experiment or Signals or None
        Files not used for the fit; their relative error is reported per model.
    cutoff_hz, decimation, dq_min, tau_min, trim, guard
        Preprocessing, see :func:`ident.preprocess.build_design`. The same settings (the
        cut-off and decimation found on the identification data) apply to validation data.
        ``dq_min`` defaults to :data:`DQ_MIN_FRACTION` of the maximum velocity; pass 0 to
        keep every sample.
    sign_check : bool
        When the paper model is fitted, estimate tau_out with a first fit of the usual model
        and leave out the samples where sign(tau) differs from sign(tau_out), where eq. 26's
        sign(P) is wrong (see ``load_model`` of :func:`ident.preprocess.build_design`).
        Both models then use these same samples. Needed when the runs cross zero load at
        low velocity (the example campaign crosses q = pi/2 at 0.03 rad/s). Skipped, with a
        note, when it would keep less than :data:`SIGN_CHECK_MIN_KEPT` of the samples (a
        horizontal axis without payload: tau_out ~ 0 at constant velocity).
    eliminate, threshold_pct
        Elimination of non-significant parameters, see :meth:`IdentModel.fit`.
    table_iv : bool
        Also identify on the runs without payload only (Table IV) when there are both.
    references : sequence or ndarray or "auto" or None
        The reference (planned) position of every identification sample, one array per
        experiment [rad or m] (or objects with a ``q_ref`` array, e.g.
        :class:`daq.protocol.reader.RunArrays`), or one concatenated array with ``Signals`` data.
        When given, every model is estimated by IDIM-IV with instruments built on the
        reference acceleration (see :mod:`ident.estimate` and ``reference`` of
        :func:`ident.preprocess.build_design`), and the default cut-off is at least
        f_s/8 and at least 125 Hz up to 0.4 f_s (:func:`ident.chain.iv_floor`, a warning
        where 0.4 f_s is below 125 Hz); this removes the closed-loop noise bias of OLS on
        the E_xp ddq columns.
        ``"auto"`` (default): the experiments' ``q_ref`` attributes when every experiment
        has one without NaN, else OLS. None: OLS.
    torque_delay : float, "auto" or None
        Instant of the torque samples after the position samples, in samples, in [0, 1)
        (:func:`ident.chain.check_torque_delay`), see :func:`ident.preprocess.build_design`.
        ``"auto"`` or None: half a cycle
        (:data:`ident.preprocess.TORQUE_DELAY`) when every experiment is a jointid MCAP log
        (``source`` ending in ``.mcap``: commands held over the next cycle), else 0 (files of
        unknown timing, processed like the MATLAB reference scripts).
    payload : bool or None
        Include the payload term (eq. 35, 42). None (default): when some run carries a
        payload (M_aw != 0).
    like : FitReport, optional
        A report of an earlier call on the same data with the same options but ``q_s`` (the
        demo's refit once q_s is adjusted): its settled preprocessing (cut-off, decimation,
        trim, guard, dq_min) and its sign check's load model are taken as they are for the
        designs instead of being found again (neither depends on q_s: the same values, one
        design build fewer; the robot's first usual fit, which decides the rows and
        quadrants of the fit, is made again on the settled preprocessing: the same numbers).
        Its ``sources`` must be this call's.
    axis : str, optional
        The axis of a multi-axis file the experiments are (e.g. ``"axis 3"``, or the mapped
        position's path ``"axis rec.act_pos_mot_deg[3]"``): named in the notes about it (the
        position split's, ``"validation, axis 3 (paper model): ..."``). None: not named.
    **deprecated
        ``qs``: the older spelling of ``q_s`` (:mod:`ident.vocab`, with a DeprecationWarning).

    Returns
    -------
    FitReport
    """
    q_s = renamed_keywords("fit_models", deprecated).get("q_s", q_s)
    models = list(dict.fromkeys(model_name(n) for n in models))  # "new": deprecated "paper"
    if not models:
        raise DataError("no model to fit")
    s = _as_signals(data, joint)
    sv = _as_signals(validation, joint) if validation is not None else None
    sources = [e.source for e in data] if not isinstance(data, Signals) else []
    vsources = (
        [e.source for e in validation]
        if validation is not None and not isinstance(validation, Signals)
        else []
    )
    ref = _references(references, data, s)
    given = check_torque_delay(torque_delay)  # None: "auto" (the record says which)
    delay_given = given is not None
    torque_delay = default_torque_delay(sources) if given is None else given
    has_payload = bool(np.any(s.payload_mass != 0)) if payload is None else bool(payload)
    notes: list[str] = []
    if not has_payload:
        notes.append(
            "no run carries a payload: the payload term (Ma_ratio / a_m, b_m...) is left out"
        )
    if not s.revolute:
        notes.append("prismatic joint: no gravity columns (MX, MY)")
    pre: dict[str, Any] = dict(
        decimation=decimation,
        cutoff_hz=cutoff_hz,
        dq_min=dq_min,
        tau_min=tau_min,
        trim=trim,
        guard=guard,
        dq_min_rel=DQ_MIN_FRACTION if dq_min is None else None,
        torque_delay=torque_delay,
    )
    qs0 = DEFAULT_QS if isinstance(q_s, str) else float(q_s)
    if not qs0 > 0:
        raise DataError(f"q_s must be positive [rad/s], got {qs0}")

    def part(d: Design, name: str, payload: bool, q: float = qs0,
             given: Callable[[float], Any] | None = None) -> tuple[Library, Design]:
        return _part(d, name, payload, q, qs0, given)

    if like is not None:
        if list(like.sources) != sources or like.revolute != s.revolute:
            raise DataError("fit_models: like= is a report on other data "
                            f"({', '.join(like.sources) or 'signals'})")
        # the settled preprocessing and the sign check's load model (independent of q_s)
        pre.update({k: v for k, v in like.settings.items()
                    if k in pre or k in ("load_model", "sign_check")})
        notes += [n for n in like.notes if n.startswith("sign check")]
    # the fit is the robot model's (ident.one_joint): the joint as a 1-dof robot, the
    # columns chain (which settles the cut-off, decimation and stiction threshold from the
    # data), the sign check of a first usual fit
    exps, refs = _split(data, s, ref)
    given = {k: pre[k] for k in ("cutoff_hz", "decimation", "dq_min", "trim", "guard")}
    problem = OneJointProblem(
        exps, revolute=s.revolute, has_payload=has_payload, references=refs,
        paper="paper" in models, torque_delay=float(torque_delay), **given,
        tau_min=tau_min,
        sign_check=sign_check and (like is None or "load_model" in like.settings))
    st = problem.settings
    band_note = iv_band_note(st.cutoff_hz) if refs is not None and cutoff_hz is None else None
    if band_note:  # the warning of ident.chain.resolve_settings, kept in the report's notes
        notes.append(band_note)
    pre.update(cutoff_hz=st.cutoff_hz, decimation=st.decimation, trim=st.trim,
               guard=st.guard, dq_min=st.dq_min, dq_min_rel=None)
    # the load that decided the paper model's quadrants when not the first usual fit's (the
    # sign check skipped: the paper fit's own, below); like= takes it as it is
    quadrant_load = None if like is None else like.settings.get("quadrant_load")
    if quadrant_load is not None and problem.model_quadrant:
        problem.replay(_quadrant_loads(like.settings))  # the passes of like='s fit, in order
    if like is None and sign_check and "paper" in models:
        if (problem.sign_checked or problem.model_quadrant) and problem.first is not None:
            # the same rows and quadrants in the design: the load model of the robot's first
            # usual fit (the check skipped: the quadrant only, every row kept)
            lib0 = usual_model(s.revolute, payload=has_payload)
            inner = Library(*[t for t in lib0.terms() if isinstance(t, RigidBody | Payload)])
            first = problem.load_values()
            pre["load_model"] = (inner, np.array([first.get(n, 0.0) for n in inner.names()]))
            if problem.model_quadrant:
                pre["sign_check"] = False
            elif problem.sign_kept < 1.0:
                notes.append(f"sign check: {100 * (1 - problem.sign_kept):.1f} % of the samples "
                             "left out of both models (sign(tau) != sign(tau_out) of a first "
                             "usual fit: there eq. 26's sign(tau dq) is not the quadrant)")
        notes.extend(problem.notes)
    # the single-joint design of both models on the chain's full-rate signals (no second
    # filtering): the paper model's P+/P- columns from the model quadrant
    # sign(tau_out_hat dq), not from tau, when the sign check applied
    full = problem.design(_combined_library(models, qs0, s.revolute, has_payload), s,
                          tau_min=tau_min, load_model=pre.get("load_model"),
                          sign_check=pre.get("sign_check", True))
    vmax = float(np.max(np.abs(full.signals.dq)))

    scan: list[tuple[float, float]] = []
    if isinstance(q_s, str):
        # ident.vocab's rule; "scan-joints" is "scan" on a joint (a 1-dof robot)
        if qs_value(q_s) not in QS_WORDS:
            raise DataError(f"q_s {q_s!r}: give a velocity as a number, not a string")
        if "paper" in models:
            # full model (no elimination): the residual as a function of q_s alone, eq. 42's
            # columns formed again at full rate for each q_s; the grid steps by 36 %, and the
            # b and d terms follow q_s closely (a 14 % error in q_s put b_m_MX 40 % off on
            # the quick demo): the minimum is refined between the grid neighbours, on log
            # q_s, to QS_XTOL (scan_qs, the robot's scan too)
            qs_val, scan = scan_qs(
                lambda q: problem.fit("paper", float(q), eliminate=False).result.rel_error,
                vmax)
        else:
            qs_val = DEFAULT_QS
    else:
        qs_val = qs0

    fitted: dict[str, IdentModel] = {}
    designs: dict[str, Design] = {}
    robot_signals: dict[str, RobotSignals] = {}
    vdesigns: dict[str, Design] = {}
    vsignals = None
    splits: dict[str, dict[str, Any] | None] = {}
    failed: list[str] = []
    one_sign = None
    shift = None  # the paper model's sign-check shift (ident.robot.selection_shift)
    def banded(d: Design) -> Design:
        """The paper model's design without its quadrant band's rows (the sign check
        skipped: :meth:`~ident.one_joint.OneJointProblem.band`), as its robot fit."""
        if problem.band() <= 0 or "load_model" not in pre:
            return d
        return d.select(dq_min=d.dq_min, tau_min=d.tau_min, quadrant_band=problem.band_masks())

    def products_at(q: float) -> Any:
        """The paper model's columns at q from the robot chain's products (the design's
        quadrant: ``full`` and the requadranted designs are built with ``load_model``)."""
        return problem.paper_columns(q, pre.get("load_model"))

    for name in models:
        lib, d = part(full, name, has_payload, qs_val, products_at)
        if name == "paper":
            one_sign = _one_sign_load(d)
            d = banded(d)
        try:
            m = _fitted(lib, name, problem.fit(name, qs_val, eliminate=eliminate,
                                               threshold_pct=threshold_pct))
        except DataError as exc:
            if name == "paper" and one_sign:
                exc = DataError(f"{exc}; {one_sign}")
            if len(models) == 1:
                raise exc from None
            # one of several models cannot be identified on these data: say so, keep the
            # others (the data are not bad, they do not excite that model; as jointid fit
            # --robot does)
            why = str(exc).removeprefix(f"{name} model: ")
            failed.append(f"{name} model: {why}")
            notes.append(f"{name} model: not fitted: {why}")
            continue
        _same_rows(name, m, d)
        fitted[name], designs[name] = m, d
        robot_signals[name] = problem.signals if name == "usual" else problem.products(qs_val)
        if m.cond_ > COND_WARN:
            notes.append(
                f"{name} model: condition number {m.cond_:.3g} (scaled columns): the data "
                "excite some parameters poorly; their deviations are large"
            )
        identifiable = [n for n, r in m.removed_ if not r.startswith("not significant")]
        if identifiable:
            notes.append(f"{name} model: not identifiable on these data: {', '.join(identifiable)}")
        if name == "paper":  # the estimate against the sign check's row choice
            shift = _sign_check_shift(problem, m, qs_val, eliminate, threshold_pct)
            if shift is not None and (note := shift_note(shift)):
                notes.append(note)

    if not fitted:
        raise DataError("; ".join(failed))
    if "paper" in fitted and like is None and problem.model_quadrant and "load_model" in pre:
        # the check skipped: the quadrants were decided by the first usual fit's load, which
        # on a joint whose friction exceeds its load can be far off (MX 3.35 for 2.0 on
        # tests/test_friction_dominated.py's joint); decide them again, and the band, by the
        # paper fit's own load until they settle (the robot path's model-quadrant passes)
        plib = _combined_library(["paper"], qs0, s.revolute, has_payload)
        record = QuadrantPasses(REQUADRANT_PASSES)
        loads: list[dict[str, float]] = []
        problem.band()  # its h, decided once by the first load (quadrant_band)
        for _ in range(record.redecisions):
            d, m = designs["paper"], fitted["paper"]
            own = paper_load_values(d.library, m.coef_)
            if own is None:
                break
            before, rows = problem.decision()
            cand = problem.loads_for(own)
            # rows moved: into another quadrant, or into or out of the band (RobotModel's count)
            changed = int(np.count_nonzero(rows & (before != problem.decision(cand)[0])))
            if not changed:  # a fixed point: the same rows and quadrants, the same fit
                record.record(0, int(rows.sum()), 0.0)
                break
            problem.requadrant(own, cand)
            quadrant_load = own
            loads.append(own)
            inner = pre["load_model"][0]
            values = problem.load_values()
            pre["load_model"] = (inner, np.array([values.get(n, 0.0) for n in inner.names()]))
            lib, d = part(problem.design(plib, s, tau_min=tau_min, load_model=pre["load_model"],
                                         sign_check=False), "paper", has_payload, qs_val,
                          products_at)
            d = banded(d)
            m = _fitted(lib, "paper", problem.fit("paper", qs_val, eliminate=eliminate,
                                                  threshold_pct=threshold_pct))
            _same_rows("paper", m, d)
            step = _step_sigma(fitted["paper"], m)
            fitted["paper"], designs["paper"] = m, d
            robot_signals["paper"] = problem.products(qs_val)
            if record.record(changed, int(rows.sum()), step):
                break
        m = fitted["paper"]
        m.converged_, m.convergence_ = record.converged, record.reason
        m.quadrant_changes_, m.quadrant_steps_ = record.changes, record.steps
        if loads:
            pre["quadrant_loads"] = loads
        if any(record.changes):  # (a re-decision that moved no row changes nothing)
            notes.append(f"paper model: the quadrants decided again by its own fitted load "
                         f"({len(record.changes)} time(s); rows moved, into another quadrant "
                         f"or across the band: {', '.join(map(str, record.changes))})")
        if not record.converged:
            notes.append(f"paper model: the quadrants did not settle: {record.reason}; the "
                         "estimate is the last pass's")
        if problem.band_nm > 0:
            notes.append(f"paper model: rows near zero load left out (the quadrant band, "
                         f"|tau_out_hat| < {problem.band_nm:.3g} {'N m' if s.revolute else 'N'}, "
                         f"{100 * SKIPPED_CHECK_BAND:g} % of the RMS load: "
                         f"{100 * (1 - problem.band_kept):.1f} % of the rows), where the "
                         "quadrant is uncertain and the joint can slide at zero load")
        elif problem.band_kept < 1.0:
            notes.append(f"paper model: no quadrant band (it would keep only "
                         f"{100 * problem.band_kept:.0f} % of the rows: the load near zero "
                         "over much of the data)")
    settings = {**pre, **({} if quadrant_load is None else {"quadrant_load": quadrant_load})}
    band_nm = problem.band() if "paper" in fitted and "load_model" in pre else 0.0
    if sv is not None:
        # the validation files through the robot chain, with the fit's settled settings, its
        # first fit's load and final quadrants: the regressor evaluated once per run
        vdesigns, vsignals = _other_designs(validation, sv, models, list(fitted), qs0,
                                            qs_val, has_payload, settings, problem.first,
                                            band_nm, designs)
        for name, vd in vdesigns.items():  # the report's JSON reads these (not again)
            splits[name] = position_split(designs[name].signals.q, vd.signals.q, vd.Y,
                                          vd.Y - fitted[name].predict(vd))
        notes.extend(position_split_notes(
            ((f"{n} model" if axis is None else f"{axis} ({n} model)", sp)
             for n, sp in splits.items()), vsources, s.revolute))
    if "paper" in designs and one_sign:
        notes.append(f"paper model: {one_sign}")
    t4 = None
    exp_ids = np.unique(s.experiment)
    no_payload_ids = np.unique(s.experiment[s.payload_mass == 0])
    if table_iv and has_payload and 0 < no_payload_ids.size < exp_ids.size:
        t4 = {"with_payloads": {}, "without_payload": {}}
        empty = [i for i, e in enumerate(exps) if float(e.payload_mass) == 0]
        try:
            # the same preprocessing, and the sign check and quadrants of the load model
            # of all the experiments
            p0 = OneJointProblem(
                [exps[i] for i in empty], revolute=s.revolute, has_payload=False,
                references=None if refs is None else [refs[i] for i in empty],
                paper="paper" in models, torque_delay=float(torque_delay),
                **{k: pre[k] for k in given},
                tau_min=tau_min, sign_check=False, first=problem.first,
                first_checked="load_model" in pre and pre.get("sign_check", True),
                model_quadrant="load_model" in pre, reuse=problem.reuse_for(empty))
            if quadrant_load is not None and p0.model_quadrant:
                p0.replay(_quadrant_loads(settings))  # the fit's passes, in order
        except DataError as exc:  # too few samples without payload
            notes.append(f"Table IV without payload: {exc}")
            p0 = None
        for name in fitted:
            t4["with_payloads"][name] = fitted[name].rel_error_
            try:
                t4["without_payload"][name] = (
                    p0.fit(name, qs_val, eliminate=eliminate,
                           threshold_pct=threshold_pct).result.rel_error
                    if p0 is not None else None
                )
            except DataError as exc:  # that model not identifiable without the payloads
                notes.append(f"Table IV without payload, {name} model: {exc}")
                t4["without_payload"][name] = None
    # the kept full-rate regressor served the fits: the report keeps no copy of it
    for held in (problem, p0 if t4 is not None else None):
        if held is not None and held.full_columns is not None:
            held.full_columns.release()
    return FitReport(
        models=fitted,
        designs=designs,
        validation_designs=vdesigns,
        vmax=vmax,
        q_s=qs_val,
        revolute=s.revolute,
        qs_scan=scan,
        table_iv=t4,
        sources=sources,
        validation_sources=vsources,
        notes=notes,
        has_payload=has_payload,
        settings=settings,
        qs_design=qs0,
        robot_signals=robot_signals,
        validation_signals=vsignals,
        first_fit=problem.first if "load_model" in pre else None,
        band_nm=band_nm,
        paper_products=problem.products if "paper" in fitted else None,
        torque_delay_given=delay_given,
        sign_check_shift=shift,
        position_splits=splits,
    )
