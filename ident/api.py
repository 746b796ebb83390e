"""Python API for notebooks and scripts: one estimator, scikit-learn style.

:class:`JointModel` identifies one joint with the paper's usual model (eq. 38-39) or its
load- and velocity-dependent friction model (eq. 42-43) and refines it with the effects its
residual points to (docs/refinement.md)::

    from ident.api import JointModel, load

    runs = load(["runs/rx130l_payload0.mcap", "runs/rx130l_payload1.mcap"])
    est = JointModel(model="paper", q_s=0.03).fit(runs)
    est.params_["a_m"], est.params_std_["a_m"], est.rel_error_   # or coef_ / coef_names_
    tau_hat = est.predict(other_runs)          # W χ̂ on the preprocessed samples
    est.score(other_runs)                      # 1 - ||ρ|| / ||Y||, higher is better
    refined = est.refine(max_steps=5)
    print(refined.refinement_.format_report())

Hyper-parameters are stored by ``__init__`` as given (``get_params``/``set_params``, so
scikit-learn's ``clone`` and grid search work on it); ``fit`` returns the estimator; fitted
attributes end in ``_``; ``coef_`` is an array aligned with ``coef_names_``. ``jointid fit``
is this estimator plus printing and files (:mod:`ident.cli`). Everything here is numerics on
loaded data, except :func:`load`, which wraps :func:`ident.loaders.load_experiments`.

:class:`RobotFit` (:mod:`ident.api_robot`) is ``jointid fit --robot`` as an estimator: the
same function reads the files and fits, so its record is the command line's JSON.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from . import DataError
from .api_robot import RobotFit
from .fitting import DEFAULT_Q_S, FitReport, fit_models
from .hyperparams import HyperParameters
from .loaders import Experiment, load_experiments
from .models import IdentModel
from .preprocess import Design
from .refine import Refinement, refine
from .signals import Signals
from .vocab import method_name, model_name, refined_model, renamed_keywords, warn_unused_qs

__all__ = ["JointModel", "RobotFit", "load"]

#: What :meth:`JointModel.fit`, :meth:`~JointModel.predict` and :meth:`~JointModel.score`
#: accept: experiments, file paths, or already concatenated signals.
Data = Sequence[Experiment] | Sequence[str | Path] | str | Path | Signals | Experiment


def load(
    paths: Sequence[str | Path] | str | Path,
    *,
    mapping: Mapping[str, str | float] | None = None,
    gain: float | str | None = None,
    joint: str | None = None,
    q_unit: str | None = None,
    axis: int = 0,
) -> list[Experiment]:
    """Load files as experiments (one per file): MCAP logs of ``jointid run``, CSV, MAT, each
    read by the one reader of one joint and n (:func:`ident.loaders.read_file`) as a run of
    one joint.

    Parameters
    ----------
    paths : path or sequence of paths
        The files.
    mapping : dict, optional
        Where the canonical signals are in CSV/MAT files, ``{"q": "qm", "tau": "vir"}``
        (keys ``t, q, tau, q_ref, payload_kg, payload_arm_m``; paths as in
        docs/fit-json.md, "Foreign data mapping"). Ignored for MCAP logs.
    gain : float or str, optional
        Drive gain: the torque used is ``gain × tau column`` (a number or a path to a
        scalar, e.g. ``"gtau"``).
    joint : {"revolute", "prismatic"}, optional
        Joint kind (default: MCAP metadata; revolute for CSV/MAT unless ``q_unit`` says).
    q_unit : {"rad", "deg", "m", "mm"}, optional
        Unit of q in CSV/MAT files, converted to [rad] or [m].
    axis : int
        Axis of a multi-axis MCAP log.

    Returns
    -------
    list of Experiment
        One per file; each holds ``t, q, tau`` arrays of shape (n,) [s, rad or m, N m or N].
    """
    return load_experiments(
        paths, mapping=mapping, gain=gain, joint=joint, axis=axis, q_unit=q_unit
    )


def _experiments(data: Data, joint: str | None) -> list[Experiment] | Signals:
    if isinstance(data, Signals):
        return data
    if isinstance(data, Experiment):
        return [data]
    if isinstance(data, str | Path):
        return load(data, joint=joint)
    items = list(data)
    if not items:
        raise DataError("no experiment given")
    if all(isinstance(x, Experiment) for x in items):
        return items
    if all(isinstance(x, str | Path) for x in items):
        return load(items, joint=joint)
    raise DataError(
        "data: expected Experiment objects, file paths or Signals "
        f"(got {sorted({type(x).__name__ for x in items})})"
    )


class JointModel(HyperParameters):
    """Identification of one joint, scikit-learn style (paper section II-IV).

    Parameters
    ----------
    model : {"paper", "usual", "both"}
        ``"usual"``: rigid body + payload + Coulomb + viscous + offset (eq. 38-39);
        ``"paper"``: load- and velocity-dependent dry friction (eq. 42-43); ``"both"``: fit
        both on the same samples (Tables III-IV compare them), the fitted attributes then
        describe the paper model.
    q_s : float or "scan"
        q_s of E_xp = exp(-|q̇|/q_s) (eq. 29) [rad/s or m/s], or ``"scan"`` to take the one
        minimising the paper model's residual (section III.D).
    joint : {"revolute", "prismatic"} or None
        Joint kind; None: the data's.
    payload : bool or None
        Include the payload term (eq. 35); None: when some run carries a payload.
    cutoff : float or None
        Butterworth cut-off on q [Hz] (None: from the data).
    decimation : int or None
        Decimation factor of the parallel filtering (None: from the data).
    dq_min : float or None
        Stiction area: samples with |q̇| below it [rad/s] are left out (None: 1 % of max).
    tau_min : float or None
        Samples with |τ| below it [N m] are left out.
    trim : int or None
        Samples cut at both ends of each experiment.
    estimator : {"auto", "ls", "wls", "iv"}
        The names of ``RobotFit(method=...)`` and ``--method`` (:mod:`ident.vocab`).
        ``"iv"``: IDIM-IV with instruments from the reference trajectory (every experiment
        must carry ``q_ref``); ``"ls"``: least squares (eq. 12); ``"wls"``: the same as
        ``"ls"`` for one joint (weighting each joint's rows by one constant changes neither
        the estimate nor its eq. 15 deviations), reported as ``"ls"``; ``"auto"``: IV when
        every experiment carries a reference, else LS. ``"ols"`` is a deprecated alias of
        ``"ls"``.
    eliminate : bool
        Remove non-significant parameters (relative deviation above ``threshold``, eq. 16).
    threshold : float or None
        Relative-deviation threshold [%] (None: 30).
    sign_check : bool
        Leave out the samples where sign(τ) differs from sign(τ̂_out) (eq. 26) when the new
        model is fitted.
    torque_delay : float, "auto" or None
        Instant of the torque samples after the position samples [samples], in [0, 1)
        (``--torque-delay``; ``torque_delay`` of :func:`ident.fitting.fit_models`); None or
        ``"auto"``: half a sample when every experiment is a jointid MCAP log, else 0.
    **deprecated
        ``qs=``: the older spelling of ``q_s`` (accepted with a DeprecationWarning,
        :mod:`ident.vocab`).

    Attributes
    ----------
    coef_ : ndarray, shape (n_params,)
        Identified parameters χ̂ (eq. 12) [SI units of each parameter], in the order of
        ``coef_names_``; eliminated parameters are absent.
    coef_names_ : ndarray of str, shape (n_params,)
        Their names (``docs/architecture.md``), e.g. ``"F_V"``. (Not ``feature_names_in_``:
        in scikit-learn that names the *input* columns.)
    std_ : ndarray, shape (n_params,)
        Standard deviations σ_χ̂ (eq. 15), aligned with ``coef_``; the paper's tables print 2σ.
    rel_std_pct_ : ndarray, shape (n_params,)
        Relative deviations 100 σ/|χ̂| [%] (eq. 16), aligned with ``coef_``.
    params_, params_std_ : dict[str, float]
        χ̂ and σ by name, e.g. ``params_["F_V"]`` (the dicts ``coef_`` and ``std_`` were
        before they became arrays).
    residual_ : ndarray, shape (n_samples_,)
        ρ = Y - W χ̂ on the identification samples [N m] (eq. 11).
    rel_error_ : float
        ‖ρ‖/‖Y‖ (Table III, first row).
    rel_error_bands_ : dict[str, float]
        ‖ρ‖/‖Y‖ overall (``all``), at low (``low``, ≤ 10 % of ``vmax_``) and high velocity
        (``high``, ≥ 35 %) (Table III).
    validation_rel_error_ : float or None
        ‖ρ‖/‖Y‖ on the ``validation`` data given to :meth:`fit`.
    n_samples_ : int
        Number of equations m (decimated, selected samples).
    q_s_ : float
        q_s used [rad/s].
    vmax_ : float
        max |q̇| of the identification samples [rad/s].
    estimator_ : {"ls", "iv"}
        The estimator used.
    model_ : IdentModel
        The fitted model (library of terms, covariance ``cov_``, ...).
    design_ : Design
        Y (shape (m,)) and W (shape (m, b)) of the identification samples.
    models_ : dict[str, IdentModel]
        Every fitted model by name (both with ``model="both"``).
    report_ : FitReport
        Tables I-IV (``format_tables()``) and the JSON record (``to_json()``); the fit's
        ``notes`` and the paper model's ``sign_check_shift`` (z per parameter against the
        rows before the sign check, :mod:`ident.robot.selection_shift`).
    refinement_ : Refinement
        Only on the estimator returned by :meth:`refine`.
    """

    def __init__(
        self,
        model: str = "paper",
        *,
        q_s: float | str = DEFAULT_Q_S,
        joint: str | None = None,
        payload: bool | None = None,
        cutoff: float | None = None,
        decimation: int | None = None,
        dq_min: float | None = None,
        tau_min: float | None = None,
        trim: int | None = None,
        estimator: str = "auto",
        eliminate: bool = True,
        threshold: float | None = None,
        sign_check: bool = True,
        torque_delay: float | str | None = None,
        **deprecated: Any,
    ) -> None:
        self.model = model
        self.q_s = renamed_keywords("JointModel", deprecated).get("q_s", q_s)
        self.joint = joint
        self.payload = payload
        self.cutoff = cutoff
        self.decimation = decimation
        self.dq_min = dq_min
        self.tau_min = tau_min
        self.trim = trim
        self.estimator = estimator
        self.eliminate = eliminate
        self.threshold = threshold
        self.sign_check = sign_check
        self.torque_delay = torque_delay

    def __sklearn_tags__(self) -> Any:
        """Estimator tags for scikit-learn >= 1.6 (its grid search asks for them): a
        regressor-like estimator of experiments, not of 2-D arrays, without targets ``y``
        (the torque is inside the data). Only scikit-learn calls this, so only then is it
        imported: jointid does not depend on it."""
        from sklearn.utils import InputTags, Tags, TargetTags

        return Tags(estimator_type=None, target_tags=TargetTags(required=False),
                    input_tags=InputTags(two_d_array=False), requires_fit=True)

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.get_params().items())
        return f"JointModel({args})"

    def _models(self) -> tuple[str, ...]:
        name = model_name(self.model, extra=("both",))  # "new": deprecated "paper"
        return ("usual", "paper") if name == "both" else (name,)

    def _references(self) -> str | None:
        # "ols": deprecated "ls"; "wls" of one joint is "ls" (one constant weight)
        method = method_name(self.estimator, extra=("auto",), what="estimator")
        return "auto" if method in ("auto", "iv") else None

    def fit(self, data: Data, validation: Data | None = None, *,
            axis: str | None = None) -> JointModel:
        """Identify the model on all experiments in one least-squares system (eq. 36, 40).

        Parameters
        ----------
        data : list of Experiment, list of paths, path, or Signals
            Identification experiments (one per payload run; paths are read with
            :func:`load` and default settings, use :func:`load` for CSV/MAT mappings).
        validation : same kinds, optional
            Data not used for the fit; ``validation_rel_error_`` and the JSON report
            their relative error, and :meth:`refine` uses them to accept a step.
        axis : str, optional
            The axis of a multi-axis file the data are (``jointid fit`` passes ``"axis N"``
            for ``--axis N`` of an MCAP log, or the mapped position's path): named in the
            report's notes about it (``axis`` of :func:`ident.fitting.fit_models`).

        Returns
        -------
        JointModel
            ``self``, fitted.
        """
        models = self._models()
        warn_unused_qs("JointModel", "paper" if len(models) > 1 else models[0], self.q_s,
                       DEFAULT_Q_S)
        exps = _experiments(data, self.joint)
        val = _experiments(validation, self.joint) if validation is not None else None
        report = fit_models(
            exps,
            models,
            q_s=self.q_s,
            joint=self.joint,
            validation=val,
            cutoff_hz=self.cutoff,
            decimation=self.decimation,
            dq_min=self.dq_min,
            tau_min=self.tau_min,
            trim=self.trim,
            sign_check=self.sign_check,
            eliminate=self.eliminate,
            threshold_pct=self.threshold,
            references=self._references(),
            payload=self.payload,
            torque_delay=self.torque_delay,
            axis=axis,
        )
        name = refined_model(report.models)
        if self.estimator == "iv" and report.models[name].estimator_ != "iv":
            raise DataError(
                "estimator='iv' needs the reference trajectory q_ref of every experiment "
                "(MCAP logs of jointid run, or a q_ref column); use 'auto' or 'ls'"
            )
        self.report_: FitReport = report
        self.models_ = dict(report.models)
        vd = report.validation_designs.get(name)
        self._set(name, report.models[name], report.designs[name], vd, ())
        return self

    def _set(
        self,
        name: str,
        model: IdentModel,
        design: Design,
        validation: Design | None,
        terms: tuple,
    ) -> None:
        self.name_ = name
        self.model_ = model
        self.design_ = design
        self._validation_design = validation
        self._terms = tuple(terms)
        names = list(model.coef_)
        self.coef_names_ = np.array(names, dtype=object)
        self.coef_ = np.array([model.coef_[n] for n in names], dtype=float)
        self.std_ = np.array([model.std_[n] for n in names], dtype=float)
        self.rel_std_pct_ = np.array([model.rel_std_pct_[n] for n in names], dtype=float)
        self.params_ = dict(model.coef_)
        self.params_std_ = dict(model.std_)
        self.residual_ = model.residual_
        self.rel_error_ = float(model.rel_error_)
        self.vmax_ = float(self.report_.vmax)
        self.rel_error_bands_ = model.rel_error_bands(design, self.vmax_)
        self.validation_rel_error_ = (
            model.rel_error_on(validation) if validation is not None else None
        )
        self.n_samples_ = int(design.Y.shape[0])
        self.q_s_ = float(self.report_.q_s)
        self.estimator_ = model.estimator_

    def _check_fitted(self) -> None:
        if not hasattr(self, "model_"):
            raise DataError("this JointModel is not fitted; call fit(experiments) first")

    # ------------------------------------------------------------------ use
    def transform(self, data: Data) -> Design:
        """The system of ``data`` for the fitted model: Y, shape (m,), and W, shape (m, b),
        with the fit's preprocessing (cut-off, decimation, thresholds, sign check) and
        the columns of every term added by :meth:`refine`."""
        self._check_fitted()
        exps = _experiments(data, self.joint)
        d = self.report_.designs_for(exps)[self.name_]
        for t in self._terms:
            d = d.with_term(t)
        return d

    def predict(self, data: Data) -> np.ndarray:
        """Predicted torque W χ̂ [N m] on the preprocessed samples of ``data``.

        Returns
        -------
        ndarray, shape (m,)
            Aligned with ``transform(data).Y`` (the measured, filtered and decimated τ).
        """
        d = self.transform(data)
        return self.model_.predict(d)

    def rel_error(self, data: Data) -> float:
        """‖Y - W χ̂‖/‖Y‖ on ``data`` (the paper's relative error norm, Table III)."""
        self._check_fitted()
        return self.model_.rel_error_on(self.transform(data))

    def score(self, data: Data) -> float:
        """1 - ‖Y - W χ̂‖/‖Y‖ on ``data``: higher is better (scikit-learn convention; 1 is
        a perfect prediction). :meth:`rel_error` gives the relative error itself."""
        return 1.0 - self.rel_error(data)

    def refine(
        self,
        validation: Data | None = None,
        *,
        max_steps: int = 5,
        progress: Callable[[str], None] | None = None,
        **options: Any,
    ) -> JointModel:
        """Add the effects the residual points to (:func:`ident.refine.refine`).

        Parameters
        ----------
        validation : data, optional
            A step is accepted only if it lowers their relative error; default: the
            validation data given to :meth:`fit` (if any).
        max_steps : int
            Maximum number of added effects.
        progress : callable, optional
            Receives one line per step.
        **options
            ``alpha``, ``min_gain``, ``max_tries``, ``generic_knots``, ``library`` of
            :func:`ident.refine.refine`.

        Returns
        -------
        JointModel
            A new fitted estimator (this one is unchanged) whose attributes describe the
            refined model, with ``refinement_`` (steps, report, JSON).
        """
        self._check_fitted()
        vd = self._validation_design
        if validation is not None:
            vd = self.transform(validation)
        ref = refine(
            self.design_,
            self.model_,
            validation=vd,
            max_steps=max_steps,
            vmax=self.vmax_,
            progress=progress,
            **options,
        )
        # the loop closed inside the robot model too: every term found so far (this
        # estimator's earlier refinements' and this one's) refitted in the fit's robot model
        ref.refit = self.report_.refit_found_terms(self.name_, self._terms + tuple(ref.terms),
                                                   ref.final_design)
        out = copy.copy(self)
        out._set(
            self.name_,
            ref.final_model,
            ref.final_design,
            ref.final_validation_design,
            self._terms + tuple(ref.terms),
        )
        out.refinement_: Refinement = ref
        return out

    def refinement_json(self) -> dict[str, Any]:
        """The ``refinement`` record of the fit JSON (docs/refinement.md), with ``model``."""
        if not hasattr(self, "refinement_"):
            raise DataError("no refinement: call refine() first")
        rec = self.refinement_.to_json()
        rec.setdefault("model", self.name_)
        return rec

