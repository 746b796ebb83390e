"""Python API of the n-dof fit: :class:`RobotFit`, ``jointid fit --robot`` as an estimator.

Re-exported by :mod:`ident.api`::

    from ident.api import RobotFit

    fit = RobotFit("examples/robots/arm3.toml").fit(["p0.csv", "p1.csv"], validation=["p2.csv"])
    fit.rel_error_["paper"]["j1"], fit.params_["paper"]["FV1"]
    print(fit.format_report())                  # the tables `jointid fit --robot` prints

:meth:`RobotFit.fit` calls :func:`ident.cli_robot.fit_files`, the function the command line
calls: the same reading (the robot file's drive gains, ``mapping`` and ``q_unit``), the same
chain (regressor columns filtered and decimated in parallel with the torque), cut-off,
decimation, guard, sign check and estimator (WLS by default), so ``record_`` is the JSON
record ``jointid fit --robot ... --json`` writes, number for number (tests/test_api_robot.py).
The lower-level pieces (:func:`ident.robot.loaders.load_robot_signals`, the "states" chain, and
:class:`ident.robot.estimate.RobotModel` on any RobotSignals) stay available for other chains;
their defaults are not the command line's.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from trajectories.friction import DEFAULT_Q_S
from trajectories.robot import Robot, load_robot

from . import DataError
from .cli_robot import (
    fit_files,
    format_report,
    public_record,
    refine_robot,
)
from .hyperparams import HyperParameters
from .loaders import parse_mapping
from .robot.estimate import RobotModel
from .robot.loaders import RawRobotRun
from .robot.signals import RobotSignals
from .robot.uncertainty import N_BLOCKS
from .vocab import QS_WORDS, model_name, qs_value, renamed_keywords, warn_unused_qs

__all__ = ["RobotFit"]

#: What :meth:`RobotFit.fit` accepts: file paths or runs read by
#: :func:`ident.cli_robot.load_runs`.
RobotData = Sequence[str | Path] | str | Path | Sequence[RawRobotRun]


def check_qs(q_s: Any) -> None:
    """Refuse a bad ``q_s`` of :class:`RobotFit` in one line, before any file is read: a
    number > 0 [rad/s] or one of :data:`ident.vocab.QS_WORDS` (:func:`ident.vocab.qs_value`,
    the rule of ``--q-s``), or a sequence or mapping (by joint name) of numbers > 0.

    Raises
    ------
    DataError
        Naming ``q_s`` (or the entry) and what is accepted.
    """
    if isinstance(q_s, Mapping):
        entries = [(f"q_s[{k!r}]", v) for k, v in q_s.items()]
    elif isinstance(q_s, Sequence) and not isinstance(q_s, str):
        entries = [(f"q_s[{i}]", v) for i, v in enumerate(q_s)]
    else:
        qs_value(q_s)
        return
    words = ", ".join(repr(w) for w in QS_WORDS)
    for what, v in entries:
        try:
            ok = not isinstance(v, bool) and math.isfinite(float(v)) and float(v) > 0
        except (TypeError, ValueError):
            ok = False
        if not ok:
            raise DataError(f"{what} {v!r}: expected a number > 0 [rad/s] per joint (q_s: a "
                            f"number, {words}, or one number per joint)")


class RobotFit(HyperParameters):
    """n-dof identification of a robot's moving joints, as ``jointid fit --robot``.

    Every hyper-parameter is the option of the same name of ``jointid fit --robot``
    (docs/robot-data.md), with the same default.

    Parameters
    ----------
    robot : str, Path or Robot
        Robot file (.toml MDH table or .urdf) or a loaded :class:`trajectories.robot.Robot`.
    model : {"both", "usual", "paper"}
        Models fitted (``--model``; "new" is accepted as a deprecated alias of "paper").
    method : {"ls", "wls", "iv"} or None
        Estimator (``--method``; None: "wls").
    q_s : float, sequence or mapping of float, "scan" or "scan-joints"
        q_s of the paper model [rad/s] (``--q-s``; one per joint as a sequence or a mapping
        by joint name), or ``"scan"``: one q_s shared by every joint, the paper fit's
        smallest relative error on the single joint's grid and bounded search
        (:func:`ident.cli_robot.fit_robot`; ``record_["q_s"]`` the chosen one,
        ``record_["q_s_scan"]`` the scan), or ``"scan-joints"``: one q_s per joint, each in
        turn on the same error with the others held
        (:func:`ident.qs_scan.scan_qs_joints`; ``record_["q_s"]`` by joint name,
        ``record_["q_s_scan_joints"]`` the scan). Ignored by the usual model.
    cutoff : float or None
        Butterworth cut-off on q [Hz] (``--cutoff``; None: chosen from the data).
    decimation, trim : int or None
        ``--decimation``, ``--trim`` (None: from the cut-off).
    torque_delay : float, "auto" or None
        Instant of the torque samples after the position samples [samples], in [0, 1)
        (``--torque-delay``, the ``torque_delay`` of :class:`~ident.api.JointModel`); None or
        ``"auto"``: half a sample when every run is a jointid MCAP log, else 0. The record's
        ``preprocessing`` has the delay used and ``torque_delay_given``.
    dq_min : float or None
        Stiction area [rad/s] (``--dq-min``; None: 1 % of the largest |dq|).
    mapping : mapping, sequence of "KEY=PATH" or None
        Where the signals are in CSV/MAT files (``--map``).
    q_unit : {"rad", "deg", "m", "mm"} or None
        Unit of q in CSV/MAT files (``--q-unit``).
    chain : {"columns", "states"}
        ``--chain``.
    payload : {"known", "ratio", "mass"} or None
        ``--payload``.
    known_rotor_inertia : bool
        ``--known-rotor-inertia``.
    consistency : bool
        Search a physically consistent standard set for the report (False:
        ``--no-consistency``).
    consistent : bool
        ``--consistent``: the physically consistent estimate of every model in the record.
    sigma_blocks : int
        ``--sigma-blocks``: jackknife units of the honest σ (0: the robust eq. 15 alone, no
        IV check; :mod:`ident.robot.uncertainty`).
    prune : bool
        Prune the paper model's friction parameters above the relative-σ threshold (False:
        ``--no-prune``).
    sign_check : bool
        Leave out the paper model's rows where sign(tau) != sign(tau_out) of a first usual fit
        (False: ``--no-sign-check``).
    quadrants : {"hard", "soft"}
        ``--quadrants``: the paper model's quadrant weights (``RobotModel(quadrants=...)``;
        "soft": a load jitter per joint fitted with the parameters, analytic σ only, no
        pruning; :mod:`ident.robot.soft_fit`).
    full_rate : bool
        ``--full-rate`` (opt-in): the paper model's quadrant and E products formed at full
        rate (``RobotModel(full_rate=True)``; docs/robot-identification.md, docs/refinement.md
        section 8.9).
    **deprecated
        ``qs=``: the older spelling of ``q_s`` (accepted with a DeprecationWarning,
        :mod:`ident.vocab`).

    Attributes
    ----------
    record_ : dict
        The JSON record ``jointid fit --robot --json`` writes (docs/robot-data.md).
    models_ : dict[str, RobotModel]
        The fitted estimators by model name ("usual", "paper").
    params_, params_std_ : dict[str, dict[str, float]]
        Per model, the parameters and their standard deviations by name: the record's
        ``std``, the honest one (max of the robust eq. 15 -- per-joint residual variances and
        long-run factors, ``std_robust`` -- and the jackknife, raised to the IDIM-IV
        difference; ``record_["models"][m]["parameters"][p]["std_analytic"]`` is eq. 15).
    coef_, std_ : dict[str, ndarray]
        Per model, the same as arrays aligned with ``coef_names_[model]``.
    coef_names_ : dict[str, ndarray of str]
    rel_error_ : dict[str, dict[str, float]]
        Per model, ||rho_j||/||tau_j|| per joint and ``"all"`` on the fit's rows.
    validation_rel_error_ : dict[str, dict[str, float]] or None
        The same on the validation files.
    settings_ : dict
        The preprocessing used (cut-off [Hz], decimation, trim, guard, dq_min [rad/s], ...).
    signals_ : RobotSignals
        The identification signals as the fit has them (every decimated row, with their
        regressor columns): the input of :class:`~ident.robot.estimate.RobotModel`.
    """

    def __init__(
        self,
        robot: str | Path | Robot,
        model: str = "both",
        *,
        method: str | None = None,
        q_s: float | str | Sequence[float] | Mapping[str, float] = DEFAULT_Q_S,
        cutoff: float | None = None,
        decimation: int | None = None,
        trim: int | None = None,
        torque_delay: float | str | None = None,
        dq_min: float | None = None,
        mapping: Mapping[str, str] | Sequence[str] | None = None,
        q_unit: str | None = None,
        chain: str = "columns",
        payload: str | None = None,
        known_rotor_inertia: bool = False,
        consistency: bool = True,
        consistent: bool = False,
        sigma_blocks: int = N_BLOCKS,
        prune: bool = True,
        sign_check: bool = True,
        quadrants: str = "hard",
        full_rate: bool = False,
        **deprecated: Any,
    ) -> None:
        q_s = renamed_keywords("RobotFit", deprecated).get("q_s", q_s)
        self.robot = robot
        self.model = model
        self.method = method
        self.q_s = q_s
        self.cutoff = cutoff
        self.decimation = decimation
        self.trim = trim
        self.torque_delay = torque_delay
        self.dq_min = dq_min
        self.mapping = mapping
        self.q_unit = q_unit
        self.chain = chain
        self.payload = payload
        self.known_rotor_inertia = known_rotor_inertia
        self.consistency = consistency
        self.consistent = consistent
        self.sigma_blocks = sigma_blocks
        self.prune = prune
        self.sign_check = sign_check
        self.quadrants = quadrants
        self.full_rate = full_rate

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.get_params().items())
        return f"RobotFit({args})"

    # -- fit --------------------------------------------------------------------------------
    def _robot(self) -> Robot:
        if isinstance(self.robot, Robot):
            return self.robot
        return load_robot(self.robot)

    def _mapping(self) -> dict[str, str | float]:
        m = self.mapping
        if isinstance(m, Mapping):
            m = [f"{k}={v}" for k, v in m.items()]
        return parse_mapping(m, robot=True)  # checks the keys as --map does

    def fit(self, data: RobotData, validation: RobotData | None = None) -> RobotFit:
        """Identify the robot on ``data`` (one multi-axis experiment per file or run).

        Parameters
        ----------
        data : path, sequence of paths, or sequence of RawRobotRun
            Identification experiments (``.mcap``, ``.csv``, ``.mat``).
        validation : same kinds, optional
            Cross-validation experiments (``--validate``).

        Returns
        -------
        RobotFit
            ``self``, fitted.
        """
        check_qs(self.q_s)  # refused in one line before any file is read
        warn_unused_qs("RobotFit", model_name(self.model, extra=("both",)), self.q_s,
                       DEFAULT_Q_S)
        out = fit_files(
            self._robot(), data, validation, model=self.model, mapping=self._mapping(),
            q_unit=self.q_unit, cutoff=self.cutoff, decimation=self.decimation, trim=self.trim,
            torque_delay=self.torque_delay, consistent=self.consistent, method=self.method,
            q_s=self.q_s, dq_min=self.dq_min,
            known_rotor_inertia=self.known_rotor_inertia, chain=self.chain,
            payload=self.payload, feasibility=self.consistency,
            sigma_blocks=self.sigma_blocks, prune=self.prune, sign_check=self.sign_check,
            quadrants=self.quadrants, full_rate=self.full_rate)
        self._set(out)
        return self

    def _set(self, out: dict[str, Any]) -> None:
        self._out = out
        self.record_ = public_record(out)
        self.models_: dict[str, RobotModel] = dict(out["_estimators"])
        fitted = {n: r for n, r in self.record_["models"].items() if "error" not in r}
        self.params_ = {n: {p: v["value"] for p, v in r["parameters"].items()}
                        for n, r in fitted.items()}
        self.params_std_ = {n: {p: v["std"] for p, v in r["parameters"].items()}
                            for n, r in fitted.items()}
        self.coef_names_ = {n: np.array(list(p), dtype=object) for n, p in self.params_.items()}
        self.coef_ = {n: np.array(list(p.values()), dtype=float)
                      for n, p in self.params_.items()}
        self.std_ = {n: np.array(list(p.values()), dtype=float)
                     for n, p in self.params_std_.items()}
        self.rel_error_ = {n: dict(r["rel_error"]) for n, r in fitted.items()}
        self.validation_rel_error_ = (
            {n: dict(r["validation_rel_error"]) for n, r in fitted.items()}
            if self.record_["validation_inputs"] else None)
        self.settings_ = dict(self.record_["preprocessing"])
        self.signals_: RobotSignals = out["_identification"]

    def _check_fitted(self) -> None:
        if not hasattr(self, "_out"):
            raise DataError("this RobotFit is not fitted; call fit(files) first")

    # -- use --------------------------------------------------------------------------------
    def format_report(self) -> str:
        """The tables ``jointid fit --robot`` prints for this fit."""
        self._check_fitted()
        return format_report(self._out)

    def refine(self, *, max_steps: int = 2, model: str | None = None,
               joints: Sequence[str] | None = None,
               progress: Callable[[str], None] | None = None,
               **options: Any) -> dict[str, Any]:
        """Refine every moving joint on the fit's rows (``--refine``,
        :func:`ident.cli_robot.refine_robot`); returns the ``refinement`` record, also in
        ``record_["refinement"]`` and in :meth:`format_report`."""
        self._check_fitted()
        rec = refine_robot(self._out, max_steps=max_steps, model=model, joints=joints,
                           progress=progress, **options)
        self.record_ = public_record(self._out)
        return rec
