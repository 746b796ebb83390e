"""``jointid fit --robot ROBOT DATA... [--model usual|paper|both] [--method ls|wls|iv]
[--validate DATA...] [--refine [--max-steps N]] [--json FILE] [--report DIR]``: identify an
n-dof robot.

(Past 600 lines: the fit, its all-rows figures, the per-joint refinement on the fit's rows and
the report are one record built in one place; the printing follows the record.)

Every input file is one multi-axis experiment of the robot's moving joints
(:mod:`ident.robot.loaders`: MCAP logs of ``jointid run``, CSV ``t, q1..qk, tau1..tauk``,
MATLAB structs with one row per axis); all are preprocessed per axis like a single joint and
identified together (:class:`ident.robot.estimate.RobotModel`: base parameters of the rigid
body and rotor inertias, plus the usual or the paper friction on every joint). Prints the
base parameters with their standard deviations (eq. 15-16), the per-joint and global relative
errors on the fit data and on the ``--validate`` files -- on the fit's rows and on all rows,
with the share each leaves out -- optionally refines every joint on the fit's rows and refits
the found terms inside the n-dof model (:func:`refine_robot`), and writes the JSON record
(``docs/robot-data.md``). Outputs are written only once everything has been computed, so a
bad input leaves nothing behind. :func:`fit_files` is the command without the printing: the
Python API (:class:`ident.api.RobotFit`) calls it too, so both give the same numbers.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from trajectories.excitation import ZERO_LOAD_SHARE
from trajectories.friction import DEFAULT_Q_S
from trajectories.robot import Robot, RobotRegressor, base_parameters, load_robot

from . import DataError, IdentError
from .chain import check_torque_delay
from .cli import parse_qs, warnings_held
from .estimate import DEFAULT_THRESHOLD_PCT
from .fitting import DQ_MIN_FRACTION, SIGN_CHECK_MIN_KEPT
from .loaders import Q_UNITS, parse_mapping
from .qs_scan import qs_grid, rescan_qs, rescan_qs_joints, scan_qs, scan_qs_joints
from .refine_result import ONE_TRAJECTORY_NOTE
from .report import staged_folder, write_json
from .results import (
    DEFAULT_BANDS,
    json_float,
    position_split,
    position_split_json,
    position_split_notes,
)
from .robot.confounded import regroup_friction
from .robot.consistency import check_consistency
from .robot.consistent_fit import add_consistent, format_record
from .robot.design import design_runs, full_rate_loads, resolve_design, sign_checked
from .robot.estimate import QUADRANT_TOL, THIN_QUADRANT, RobotModel
from .robot.friction_bounds import torque_peak
from .robot.load_jitter import JITTER_SHARE, jitter_note, jitter_share
from .robot.loaders import (
    RawRobotRun,
    RobotPreprocessing,
    check_periods,
    load_robot_runs,
    preprocess_runs,
    resolved_settings,
)
from .robot.payload import format_misfit, payload_misfit
from .robot.plots import write_robot_report
from .robot.refine_joint import joint_coulomb, refine_joint
from .robot.refit_accept import ALL_REFUSED, accept_refit
from .robot.selection_shift import selection_shift, shift_note
from .robot.signals import RobotSignals
from .robot.soft_fit import QUADRANTS, load_signs, soft_record
from .robot.tables import format_table_iii, format_uncertainty, table_iii
from .robot.uncertainty import N_BLOCKS, assess, parameter_records
from .vocab import method_name, model_name, qs_value, refined_model

__all__ = ["run", "fit_robot", "fit_files", "load_runs", "public_record", "refine_robot",
           "format_report", "format_refinement", "format_refit", "FORMAT", "OLD_FORMATS",
           "MODELS"]

FORMAT = "jointid-robot-fit/2"
#: Older robot-fit formats still read (:func:`ident.vocab.upgrade_record`): /1 spelled ``qs``
#: where /2 has ``q_s``.
OLD_FORMATS = ("jointid-robot-fit/1",)
#: Preprocessing chains (``fit_robot(chain=...)``, ``--chain``).
CHAINS = ("columns", "states")
#: Payload treatments (``fit_robot(payload=...)``, ``--payload``).
PAYLOADS = ("known", "ratio", "mass")
#: ``--model`` -> the models fitted (``jointid fit --robot``, :class:`ident.api.RobotFit`).
MODELS = {"usual": ("usual",), "paper": ("paper",), "both": ("usual", "paper")}
#: Stages after the fit that read the paper model with hard quadrants: refused in one line
#: with ``--quadrants soft`` (a soft model's prediction is not theirs).
SOFT_REFUSED = {
    "refine": "jointid fit --robot: --refine is not available with --quadrants soft (the "
              "n-dof refit of the found terms uses hard quadrants)",
    "consistent": "jointid fit --robot: --consistent is not available with --quadrants soft "
                  "(the consistent estimate and the exported friction use hard quadrants)",
}
#: Options of the single-joint ``jointid fit`` that have no meaning with ``--robot``.
_SINGLE_ONLY = (("joint", "--joint", "the robot file gives the joint types"),
                ("gain", "--gain", "use drive_gain in the robot file's [joints.drive]"),
                ("tau_min", "--tau-min", "single-joint only"),
                ("threshold", "--threshold", "single-joint only"),
                ("no_eliminate", "--no-eliminate", "its pruning is turned off by --no-prune"))


def robot_gains(robot: Robot) -> list[float]:
    """Joint-side torque per unit of logged torque of each moving joint (robot file drives)."""
    out = []
    for n in robot.moving:
        d = robot.drives.get(n)
        g = None if d is None else (d.drive_gain or d.torque_constant)
        out.append(1.0 if g is None else float(g))
    return out


def load_runs(robot: Robot, data: Sequence[str | Path] | str | Path | Sequence[RawRobotRun],
              *, mapping: Mapping[str, str | float] | None = None,
              q_unit: str | None = None) -> list[RawRobotRun]:
    """The robot's experiment files read as ``jointid fit --robot`` reads them: the robot
    file's drive gains (:func:`robot_gains`), the ``--map`` entries and ``--q-unit``
    (:func:`~ident.robot.loaders.load_robot_runs`). Runs already read are returned as given."""
    items = [data] if isinstance(data, str | Path | RawRobotRun) else list(data)
    if items and all(isinstance(r, RawRobotRun) for r in items):
        return items  # type: ignore[return-value]
    if any(isinstance(r, RawRobotRun) for r in items):
        raise DataError("robot data: expected file paths or RawRobotRun objects, not a mix")
    _check_q_unit_kind(robot, q_unit)
    return load_robot_runs(items, robot.moving, gains=robot_gains(robot),  # type: ignore[arg-type]
                           mapping=mapping, q_unit=q_unit)


def _check_q_unit_kind(robot: Robot, q_unit: str | None) -> None:
    """Refuse a ``--q-unit`` of the wrong kind for a moving joint (an angle for a prismatic
    joint, a length for a revolute one), as the single-joint loader does: one unit scales
    every axis, so ``--q-unit mm`` on a revolute arm read degrees as millimetres and fitted
    on without a word. A unit that is no unit at all is left to the loader's message."""
    if q_unit is None or str(q_unit).strip().lower() not in Q_UNITS:
        return
    unit = str(q_unit).strip().lower()
    angle = Q_UNITS[unit][1]
    wrong = [j for j in robot.moving
             if (robot.types[robot.joint_names.index(j)] == "revolute") != angle]
    if wrong:
        raise DataError(
            f"--q-unit {unit}: {'an angle' if angle else 'a length'}, but moving joint(s) "
            f"{', '.join(wrong)} of the robot are {'prismatic' if angle else 'revolute'} "
            f"(expected {'mm or m' if angle else 'deg or rad'}; one unit converts every axis: "
            "with joints of both kinds give q in SI units and no --q-unit)")


def _check_ratio_separable(runs: Sequence[RawRobotRun]) -> None:
    """Refuse the payload ratio M_ae/M_aw (eq. 35) when every run carries the same payload:
    its torque is then a combination of the last link's columns in every run, the ratio not
    separable from them (the fit ended in 'parameters not identifiable (cond 2.9e+300)')."""
    seen = {(float(r.payload.mass), r.payload.arm_m,
             tuple(np.round(np.asarray(r.payload.com, dtype=float), 12))) for r in runs}
    if len(seen) == 1 and next(iter(seen))[0] > 0:
        mass = next(iter(seen))[0]
        raise DataError(
            f"payload ratio M_ae/M_aw (eq. 35): every run carries the same payload ({mass:g} "
            f"kg; {', '.join(str(r.source) for r in runs[:3])}"
            f"{' ...' if len(runs) > 3 else ''}), so it is not separable from the robot's "
            "parameters: give runs with another payload (or none), or --payload known")


def _check_validation_payloads(runs: Sequence[RawRobotRun],
                               validation: Sequence[RawRobotRun] | None) -> None:
    """``--payload mass`` identifies one parameter set per payload mass of the fit's runs: a
    validation run whose payload is none of them has no parameters to predict with. Refused
    before fitting, naming the file (the estimator's own error came after the fit and named
    neither the file nor the option)."""
    fitted = sorted({float(r.payload.mass) for r in runs} - {0.0})
    for r in validation or []:
        mass = float(r.payload.mass)
        if mass > 0 and mass not in fitted:
            raise DataError(
                f"{r.source}: payload of {mass:g} kg: with --payload mass a validation file "
                f"must carry one of the payloads the fit identifies "
                f"({', '.join(f'{m:g}' for m in fitted) or 'none'} kg) or none")


def fit_files(
    robot: Robot,
    inputs: Sequence[str | Path] | str | Path | Sequence[RawRobotRun],
    validate: Sequence[str | Path] | str | Path | Sequence[RawRobotRun] | None = None,
    *,
    model: str = "both",
    mapping: Mapping[str, str | float] | None = None,
    q_unit: str | None = None,
    cutoff: float | None = None,
    decimation: int | None = None,
    trim: int | None = None,
    torque_delay: float | str | None = None,
    consistent: bool = False,
    **options: Any,
) -> dict[str, Any]:
    """``jointid fit --robot`` without the printing: :func:`load_runs` then :func:`fit_robot`
    (and ``add_consistent`` with ``consistent``). The one chain the command line and the
    Python API (:class:`ident.api.RobotFit`) run, so their numbers are the same.

    Parameters
    ----------
    robot : Robot
    inputs, validate : paths or RawRobotRun objects
        Identification and cross-validation experiments (``validate`` may be None).
    model : {"usual", "paper", "both"}
        ``--model`` (:data:`MODELS`).
    mapping, q_unit
        ``--map`` entries (:func:`~ident.loaders.parse_mapping`, ``robot=True``), ``--q-unit``.
    cutoff, decimation, trim
        ``--cutoff`` [Hz], ``--decimation``, ``--trim`` (None: chosen from the data).
    torque_delay : float, "auto" or None
        ``--torque-delay``: instant of the torque samples after the position samples
        [samples], in [0, 1) (:class:`~ident.robot.loaders.RobotPreprocessing`); None or
        ``"auto"`` (the spelling of :func:`ident.fitting.fit_models`): half a sample when every
        run is a jointid MCAP log, else 0.
    consistent : bool
        ``--consistent``: also the physically consistent estimate of every model.
    **options
        The other keywords of :func:`fit_robot` (``method``, ``q_s``, ``dq_min``, ``chain``,
        ``payload``, ``known_rotor_inertia``, ``sign_check``, ``feasibility``,
        ``sigma_blocks``, ``prune``, ``progress``).
    """
    model = model_name(model, extra=("both",))  # "new": deprecated "paper" (ident.vocab)
    if consistent and options.get("quadrants") == "soft" and model != "usual":
        raise DataError(SOFT_REFUSED["consistent"])
    runs = load_runs(robot, inputs, mapping=mapping, q_unit=q_unit)
    val = load_runs(robot, validate, mapping=mapping, q_unit=q_unit) if validate else None
    pre = RobotPreprocessing(cutoff, decimation, trim, check_torque_delay(torque_delay))
    out = fit_robot(robot, runs, val, models=MODELS[model], preprocessing=pre, **options)
    # how the inputs were read (--map, --q-unit): export-model reads them again with these
    out["reading"] = {"map": None if mapping is None else dict(mapping), "q_unit": q_unit}
    if consistent:
        add_consistent(out)
    return out


def _check_args(args: argparse.Namespace) -> None:
    for attr, flag, hint in _SINGLE_ONLY:
        if getattr(args, attr, None) not in (None, False):
            raise DataError(f"{flag}: not used with --robot ({hint})")
    quadrants = getattr(args, "quadrants", None)
    if quadrants is not None and quadrants not in QUADRANTS:
        raise DataError(f"--quadrants: expected one of {', '.join(QUADRANTS)}, got "
                        f"{quadrants!r}")
    if quadrants == "soft" and getattr(args, "model", None) == "usual":
        raise DataError("--quadrants soft: a weight of the paper model's quadrants; the usual "
                        "model has none (use --model paper or both)")
    if quadrants == "soft":  # the stages after the fit treat the paper model as hard
        for attr, why in (("refine", SOFT_REFUSED["refine"]),
                          ("consistent", SOFT_REFUSED["consistent"])):
            if getattr(args, attr, False):
                raise DataError(why)
    if getattr(args, "axis", 0) not in (0, None):
        raise DataError("--axis: not used with --robot (every axis of the log is a moving joint)")


def fit_robot(
    robot: Robot,
    runs: list[RawRobotRun],
    validation: list[RawRobotRun] | None = None,
    *,
    models: tuple[str, ...] = ("usual", "paper"),
    method: str | None = None,
    q_s: float | str | Sequence[float] | Mapping[str, float] = DEFAULT_Q_S,
    dq_min: float | None = None,
    preprocessing: RobotPreprocessing | None = None,
    known_rotor_inertia: bool = False,
    chain: str = "columns",
    payload: str | None = None,
    sign_check: bool = True,
    feasibility: bool = True,
    sigma_blocks: int = N_BLOCKS,
    prune: bool = True,
    progress: Callable[[str], None] | None = None,
    quadrants: str = "hard",
    full_rate: bool = False,
) -> dict[str, Any]:
    """Preprocess, fit each model, cross-validate; the JSON record (no file written).

    Parameters
    ----------
    robot : Robot
    runs, validation : list of RawRobotRun
        Identification and cross-validation experiments (:func:`load_robot_runs`).
    models : tuple of {"usual", "paper"}
    method : {"ls", "wls", "iv"} or None
        None: "wls" (Gautier's practice for several joints: each joint's rows weighted by
        its residual deviation). On the KUKA recordings it cross-validates better than IV,
        whose instruments (the planned trajectory) are poor under the robot's own position
        loop and feed-forward (docs/robot-data.md).
    q_s : float, sequence or mapping of float, "scan" or "scan-joints"
        q_s of the paper model [rad/s] (one, one per joint, or by joint name), or ``"scan"``:
        the q_s whose paper fit (every
        parameter kept: before the uncertainty step's pruning) has the smallest relative error
        over every joint's rows (``rel_error_["all"]``), on the grid of
        :func:`ident.qs_scan.qs_grid` of the fitted rows' largest |dq| then a bounded search
        between the best point's neighbours (:func:`ident.qs_scan.scan_qs`, the single joint's
        rule); one q_s shared by every joint. The record's ``q_s`` is the chosen one and
        ``q_s_scan`` every evaluated ``{q_s, rel_error}``; or ``"scan-joints"``: one q_s per
        joint, each in turn with the others held, on the same error
        (:func:`ident.qs_scan.scan_qs_joints`), the record's ``q_s`` by joint name and
        ``q_s_scan_joints`` the scan (docs/robot-data.md). Without the paper model: the
        default, as for one joint.
    dq_min : float or None
        Stiction area |dq_j| < dq_min left out of joint j's rows [rad/s]; None: 1 % of the
        largest |dq| of the identification data.
    preprocessing : RobotPreprocessing or None
        Cut-off, decimation, trim, torque delay (None entries: chosen by the chain's rules;
        the record's ``preprocessing`` says the delay used, ``torque_delay`` [samples], and
        whether it was given, ``torque_delay_given``).
    known_rotor_inertia : bool
        Rotor inertias of the robot file known, not identified
        (:class:`~ident.robot.regressor.RobotRegressor`).
    chain : {"columns", "states"}
        ``"columns"``: the single-joint chain, regressor columns filtered and decimated in
        parallel with the torque (:mod:`ident.robot.design`); ``"states"``: the states
        decimated and the regressor built on them (:func:`preprocess_runs`).
    payload : {"known", "ratio", "mass"} or None
        The payload torque known, or scaled by an identified ratio M_ae/M_aw (eq. 35,
        ``RobotModel(payload_ratio=True)``), or only its mass known and its first moments
        and inertia at the flange identified (``RobotModel(payload_params=True)``; needs
        runs without payload; ``payload_misfit`` in each model's record); None: "ratio"
        when some run gives its payload as a single-joint lever arm (``arm_m``), as the
        single-joint fit does, else "known".
    sign_check : bool
        Columns chain with the paper model: leave out, for both models, the rows where
        sign(tau_j) != sign(tau_out_j) of a first usual fit (the single-joint ``sign_check``
        of :func:`ident.fitting.fit_models`; skipped with a note when it would keep fewer
        than :data:`ident.fitting.SIGN_CHECK_MIN_KEPT` of the rows).
    feasibility : bool
        Search a physically consistent standard set reproducing the base estimate
        (:func:`~ident.robot.consistency.check_consistency`, the slow part of the report:
        most of a 7-axis fit's time); False (``--no-consistency``): the sign checks only,
        ``feasible`` null.
    sigma_blocks : int
        Units of the jackknife of the honest sigma (:func:`ident.robot.uncertainty.assess`:
        jackknife over experiments or blocks, IDIM-IV check when the runs carry q_ref,
        per-joint errors-in-variables flag); 0 (``--sigma-blocks 0``): eq. 15 alone, no
        IV check (the pruning then judged on eq. 15).
    prune : bool
        Paper model: prune the friction parameters above the threshold (eq. 14-16) and refit;
        False (``--no-prune``): only flag them ``unidentified``.
    progress : callable or None
        Receives progress lines of the uncertainty assessment when it runs over 10 s.
    quadrants : {"hard", "soft"}
        ``--quadrants``: the paper model's quadrant weights (``RobotModel(quadrants=...)``;
        "soft": a load jitter sigma_j per joint fitted with the parameters, analytic sigma
        only, no pruning; :mod:`ident.robot.soft_fit`). The usual model is not affected.
    full_rate : bool
        ``--full-rate`` (opt-in): the paper model's quadrant and E products formed at full
        rate, then low-passed and decimated like the torque (``RobotModel(full_rate=True)``,
        docs/refinement.md section 8.9); the record's ``"full_rate"`` and each paper record's
        ``"full_rate_applied"`` (False, with a note, where the model falls back to the
        decimated columns: the states chain, ``payload`` ratio or mass, soft quadrants). The
        usual model is not affected.

    Returns
    -------
    dict
        The record of docs/robot-data.md, plus the fitted estimators under ``"_estimators"``,
        the identification and validation signals with the rows the fit leaves out as NaN
        torques under ``"_signals"`` and the identification signals as preprocessed (every
        decimated sample) under ``"_identification"`` (not serialised).
    """
    joints = robot.moving
    reg = RobotRegressor(robot, known_rotor_inertia=known_rotor_inertia)
    method = "wls" if method is None else method_name(method)  # "ols": deprecated "ls"
    if method == "iv" and any(r.q_ref is None for r in runs):
        raise DataError("--method iv: the inputs carry no reference trajectory q_ref (map one "
                        "with --map q_ref=PATH, or CSV columns q_ref1..q_refk)")
    if chain not in CHAINS:
        raise DataError(f"chain {chain!r}: expected one of {CHAINS}")
    if payload is None:
        payload = "ratio" if any(r.payload.arm_m is not None and r.payload.mass > 0
                                 for r in runs) else "known"
    if payload not in PAYLOADS:
        raise DataError(f"payload {payload!r}: expected one of {PAYLOADS}")
    if payload == "mass":
        _check_validation_payloads(runs, validation)
    if validation:
        # the settings resolved on the identification files are in samples (decimation,
        # trim, guard): a validation file at another rate was processed with other ones
        check_periods([*runs, *validation])
    pre = preprocessing or RobotPreprocessing()
    delay_given = pre.torque_delay is not None
    if quadrants not in QUADRANTS:
        raise DataError(f"--quadrants: expected one of {', '.join(QUADRANTS)}, got "
                        f"{quadrants!r}")
    notes: list[str] = []
    # base parameters the friction columns confound (a constant weight is an offset): regrouped
    # for every fit, with one line saying what and why (ident.robot.confounded); the paper
    # model, whose load must carry that weight, is not fitted then
    base = base_parameters(reg)  # the fits' own default, computed once here
    regrouping = regroup_friction(reg, base, joints=tuple(joints))
    refused: dict[str, str] = {}  # model -> why it is not fitted
    if regrouping is not None:
        base = regrouping.base
        notes.append(regrouping.note)
        if "paper" in models:  # its tau_out needs the weight the offset absorbs
            if models == ("paper",):
                raise DataError(regrouping.paper)
            models = tuple(m for m in models if m != "paper")
            refused["paper"] = regrouping.paper
    jitter = None  # (share, jitter) per joint of the paper model's warning (load_jitter)
    unchecked = None  # the rows before the sign check, when it left some out (selection_shift)
    if chain == "columns":
        design = resolve_design(runs, instruments=method == "iv", cutoff_hz=pre.cutoff_hz,
                                decimation=pre.decimation, trim=pre.trim,
                                torque_delay=pre.torque_delay, dq_min=dq_min)
        # the instruments' columns also for the IDIM-IV check of the honest sigma
        iv_cols = method == "iv" or (sigma_blocks > 0 and all(r.q_ref is not None for r in runs))
        # the sign check reads every run's full-rate signals and regressor again: kept from
        # the chain (design_runs(keep_full=True), the same floats), freed after it
        check = sign_check and "paper" in models
        sig, dq_min = design_runs(runs, reg, design, instruments=iv_cols, keep_full=check)
        if payload == "ratio":  # after the payloads were placed on the robot (design_runs)
            _check_ratio_separable(runs)
        design = replace(design, dq_min=dq_min)
        val = design_runs(validation, reg, design)[0] if validation else None
        settings: dict[str, Any] = design.as_dict()
        est_dq_min = 0.0  # the stiction area is in the columns' keep mask
        if check:
            # as the single-joint fit: a first usual fit estimates tau_out; rows where
            # sign(tau) != sign(tau_out) are left out of both models (and the validation)
            first = RobotModel(reg, model="usual", method=method, base=base,
                               payload_ratio=payload == "ratio",
                               payload_params=payload == "mass").fit(sig)
            loads = full_rate_loads(sig, runs, design, first.load_torque)
            before = sig
            sig, kept = sign_checked(sig, runs, design, first.load_torque,
                                     SIGN_CHECK_MIN_KEPT, loads=loads)
            if np.any(kept >= SIGN_CHECK_MIN_KEPT):  # the rows it chose: checked below
                unchecked = before
            # the rows within the closed loop's load jitter of the quadrant boundary (a
            # warning of the paper model's, below): the first fit's load, the checked rows
            jitter = jitter_share(sig, loads, design.decimation)
            del loads
            # the kept full-rate signals and regressor: not read after the check (the record
            # keeps the signals, which would keep them too)
            sig, before = _without_full(sig), _without_full(before)
            if unchecked is not None:
                unchecked = before
            if val is not None:
                # checked on the joints the identification data were checked on
                val = sign_checked(val, validation, design, first.load_torque,
                                   np.where(kept >= SIGN_CHECK_MIN_KEPT, 0.0, np.inf))[0]
            for j, f in zip(joints, kept, strict=True):
                if f >= SIGN_CHECK_MIN_KEPT:
                    notes.append(f"sign check, joint {j}: {100 * (1 - f):.1f} % of its rows "
                                 "left out (sign(tau) != sign(tau_out) of a first usual fit)")
                else:
                    notes.append(f"sign check skipped on joint {j}: it would keep only "
                                 f"{100 * f:.0f} % of its rows (tau_out near zero)")
    else:
        settings = resolved_settings(runs, pre)
        pre = RobotPreprocessing(settings["cutoff_hz"], int(settings["decimation"]),
                                 int(settings["trim"]), settings["torque_delay"])
        sig = preprocess_runs(runs, joints, pre)
        val = preprocess_runs(validation, joints, pre) if validation else None
        if dq_min is None:
            dq_min = DQ_MIN_FRACTION * float(np.max(np.abs(sig.dq)))
        est_dq_min = dq_min
        if payload == "ratio":
            _check_ratio_separable(runs)

    def model(name: str, at: float | None = None) -> RobotModel:
        # one joint: exactly the single-joint fit's rows (no quadrant band; the sign check
        # plays its part there); at: the q_s of a scan's fit
        return RobotModel(reg, model=name, method=method, q_s=q_s if at is None else at,
                          dq_min=est_dq_min,
                          base=base, payload_ratio=payload == "ratio",
                          payload_params=payload == "mass",
                          quadrant_band=0.0 if len(robot.moving) == 1 else 0.03,
                          quadrants=quadrants if name == "paper" else "hard",
                          full_rate=bool(full_rate) and name == "paper")

    val_all = val
    q_s, qs_record = _scan_qs(q_s, models, lambda q: model("paper", q), sig, notes)
    if val is not None:
        # the validation error is taken on the samples the fit would use (as the single-joint
        # validation design): joint j's torque in its stiction area is left out (NaN)
        val = selected(val, dq_min)
    raw_n = sum(r.t.size for r in runs)
    trimmed = max(raw_n - _raw_rows(sig, settings), 0)
    out: dict[str, Any] = {
        "format": FORMAT,
        "robot": {"name": robot.name, "source": robot.source, "moving": list(joints),
                  "numbers": list(robot.numbers),
                  # the file as an absolute path, for export-model run from another folder
                  **({"path": str(Path(robot.source).resolve())}
                     if Path(robot.source).is_file() else {})},
        "inputs": [r.source for r in runs],
        "validation_inputs": [r.source for r in validation or []],
        "preprocessing": {**settings, "torque_delay_given": delay_given,
                          "chain": chain, "dq_min": dq_min, "samples": sig.n,
                          "validation_samples": 0 if val is None else val.n,
                          # file edges where the filters are undefined: out of every figure
                          "edge_share": trimmed / raw_n if raw_n else 0.0},
        "method": method,
        "known_rotor_inertia": bool(known_rotor_inertia),
        "payload": payload,
        "q_s": q_s,
        **qs_record,
        "quadrants": quadrants,
        "full_rate": bool(full_rate),
        "notes": notes,
        "models": {},
        # the unit of dq_min in the printed summary: the moving joints' kinds
        "_dq_unit": _speed_unit(robot),
        "_estimators": {},
        "_consistency": {},
        "_signals": (selected(sig, dq_min), val),
        "_identification": sig,
        "_tau_peak": torque_peak(sig),  # the static friction's data bound [N m]
        "_validation_all": val_all,
        "_cycle_s": float(np.median(np.diff(runs[0].t))),
        "_keep": kept_rows(sig, est_dq_min),
    }
    # what the position-split notes of the fit said already (the files, each reason in full)
    said: set[str] = set()
    for name in models:
        try:
            est = model(name).fit(sig)
        except IdentError as exc:
            if len(models) == 1:
                raise
            # one of several models cannot be identified on these data: say so, keep the
            # others (the data are not bad, they do not excite that model)
            out["models"][name] = {"error": str(exc)}
            continue
        # honest sigma, errors-in-variables flags, the paper model pruned (refitted in place)
        unc = assess(est, sig, n_blocks=sigma_blocks, iv=sigma_blocks > 0,
                     prune=prune and name == "paper", progress=progress)
        rec: dict[str, Any] = {
            "parameters": parameter_records(est),
            "uncertainty": unc.to_json(),
            "n_base": int(est.n_base_),
            "rel_error": {k: float(v) for k, v in est.rel_error_.items()},
            # every decimated row (stiction area, guard, sign check, quadrant band included)
            "rel_error_all_rows": {k: float(v) for k, v in est.rel_error(sig).items()},
            "rows_left_out": _left_out(est.n_samples_, sig.n, joints),
            "sigma_joint": {j: float(s) for j, s in zip(joints, est.sigma_joint_, strict=True)},
            "samples": {j: int(n) for j, n in zip(joints, est.n_samples_, strict=True)},
        }
        if name == "paper":
            flag_unidentified(rec)
            if full_rate:
                rec["full_rate_applied"] = bool(est.full_rate_paper_)
                if not est.full_rate_paper_:
                    notes.append("--full-rate: the paper model's quadrant and E products were "
                                 "taken on the decimated columns (the full-rate products need "
                                 "the columns chain, a known payload and hard quadrants; "
                                 "docs/robot-identification.md)")
            if quadrants == "hard":  # soft: no quadrant band (ident.robot.soft_fit)
                rec["quadrant_band_share"] = {j: float(x) for j, x in
                                              zip(joints, est.band_share_, strict=True)}
            if jitter is not None:
                rec["quadrant_jitter_share"] = {j: float(x) for j, x in
                                                zip(joints, jitter[0], strict=True)}
                # its warning is the hard quadrants' (biased dry friction where the low-pass
                # blends both): the soft weight is that blend's model, no note (the share stays)
                notes.extend(jitter_note(j, x, h) for j, x, h in
                             zip(joints, *jitter, strict=True)
                             if x > JITTER_SHARE and quadrants == "hard")
            if unchecked is not None:  # the estimate against the sign check's row choice
                # (model(name): the same quadrants, soft refitted soft, like with like)
                try:
                    alt = model(name).fit(unchecked)
                    # columns dropped on those rows (held at 0): no estimate to compare with,
                    # as when that fit was refused
                    z = (None if getattr(alt, "dropped_evidence_", None)
                         else selection_shift(rec["parameters"], alt))
                except (IdentError, np.linalg.LinAlgError):  # a diagnostic: never fatal
                    z = None  # (not identifiable on those rows: nothing to compare)
                if z is not None:
                    rec["sign_check_shift"] = z
                    if note := shift_note(z):
                        notes.append(note)
            for j, x, h in zip(joints, est.band_share_, est.band_, strict=True):
                # soft quadrants: no band, every row carries both quadrants' weights
                if x > ZERO_LOAD_SHARE and quadrants == "hard":
                    notes.append(
                        f"paper model, {j}: {100 * x:.0f} % of its rows have a predicted load "
                        f"within the quadrant band (|tau_out| < {h:.3g}, "
                        f"{100 * float(est.quadrant_band):g} % of its RMS load): it moves at about "
                        "zero load (no gravity on it, cruising), where the quadrant is decided "
                        "by noise; its dry-friction terms may be biased beyond their sigma "
                        "(docs/robot-identification.md, 'quadrants blended by the low-pass'); "
                        "excite it with accelerated motion")
            if removed := [(n, v["removed"]) for n, v in rec["parameters"].items()
                           if v.get("removed")]:
                # zero or exactly dependent columns on these data (the rank rule of every
                # fit): held at 0 and reported with the refusal's evidence, not refused
                rec["removed"] = [{"name": n, "reason": why} for n, why in removed]
                rec["removed_evidence"] = list(getattr(est, "dropped_evidence_", []))
                by_why: dict[str, list[str]] = {}
                for n, why in removed:
                    by_why.setdefault(why, []).append(n)
                notes.append(
                    f"paper model: {', '.join(n for n, _ in removed)} removed before the fit "
                    "(not identifiable on these data, the rank rule of every fit: "
                    + "; ".join(f"{', '.join(ns)}: {why}" for why, ns in by_why.items())
                    + "): held at 0, the model fitted without them, as the single-joint fit "
                    "does; the refusal it replaces: "
                    + " | ".join(ev.removeprefix("paper model: ")
                                 for ev in rec["removed_evidence"]))
            if unc.pruned:
                notes.append(f"paper model: {', '.join(unc.pruned)} pruned (relative std "
                             f"above {DEFAULT_THRESHOLD_PCT:g} %, eq. 14-16): held at 0 and the "
                             "model refitted without them (not used to predict)")
            if rec["unidentified"]:
                notes.append(f"paper model: {', '.join(rec['unidentified'])} unidentified "
                             f"(relative std above {DEFAULT_THRESHOLD_PCT:g} %, eq. 14-16; "
                             "not prunable: base parameters, a_m, a_g" + (
                                 "" if prune else ", or --no-prune") + "): kept in the fit, "
                             "their values are not identified")
        if name == "paper":
            soft_record(est, rec, joints, notes)
            _settled(est, rec, out["_signals"][0], joints, notes)
            _one_signed_loads(est, rec, out["_signals"][0], joints, notes)
        expressions = getattr(est.base_, "expressions", None)
        if expressions:
            rec["base_expressions"] = list(expressions)
        if regrouping is not None:  # the fitted friction parameters that carry a weight
            rec["base_expressions"] = [*rec.get("base_expressions", []),
                                       *regrouping.base.friction_expressions]
            rec["friction_regrouped"] = regrouping.base.friction
        if payload == "mass":  # the payload's identifiable combinations, the per-joint check
            rec["payload_merged"] = bool(est.payload_merged_)
            if not est.payload_merged_:
                rec["payload_expressions"] = list(est.payload_base_.expressions)
                rec["payload_misfit"] = payload_misfit(est, out["_signals"][0])
        if val is not None:
            rec["validation_rel_error"] = {k: float(v) for k, v in est.rel_error(val).items()}
            _position_extrapolation(est, rec, out["_signals"][0], val, joints, name,
                                    out["validation_inputs"], notes, said,
                                    [robot.types[robot.joint_names.index(j)] == "revolute"
                                     for j in joints])
        if val is not None and val_all is not None:
            rec["validation_rel_error_all_rows"] = {
                k: float(v) for k, v in est.rel_error(val_all).items()}
            rec["validation_rows_left_out"] = _left_out(np.isfinite(val.tau).sum(0),
                                                        val_all.n, joints)
        cons = check_consistency(est, feasibility=feasibility, tau_peak=out["_tau_peak"])
        rec["consistency"] = {
            "ok": cons.ok,
            "checks": [{"check": c, "value": float(v), "std": float(sd), "status": st}
                       for c, v, sd, st in cons.checks],
            "feasible": cons.feasible, "d2": float(cons.d2), "d2_limit": float(cons.d2_limit),
            "unchecked": list(cons.unchecked),
        }
        out["_consistency"][name] = cons.format()
        out["models"][name] = rec
        out["_estimators"][name] = est
    for name, why in refused.items():
        out["models"][name] = {"error": why}
    if not out["_estimators"]:
        raise DataError("; ".join(f"{n} model: {r['error']}" for n, r in out["models"].items()))
    fit_sel = out["_signals"][0]
    # the selected rows' vmax (table_iii's default) for the all-rows table too: the same
    # velocity bands
    vmax = _vmax(fit_sel)
    out["table_iii"] = {"fit": table_iii(out["_estimators"], fit_sel, vmax=vmax),
                        "fit_all_rows": table_iii(out["_estimators"], sig, vmax=vmax,
                                                  clip=True)}
    out["rows_left_out"] = {"fit": band_left_out(fit_sel, sig, vmax)}
    if val is not None and val_all is not None:
        vv = _vmax(val)
        out["table_iii"]["validation"] = table_iii(out["_estimators"], val, vmax=vv)
        out["table_iii"]["validation_all_rows"] = table_iii(out["_estimators"], val_all,
                                                            vmax=vv, clip=True)
        out["rows_left_out"]["validation"] = band_left_out(val, val_all, vv)
    return out


def refine_robot(
    out: dict[str, Any],
    *,
    max_steps: int = 2,
    model: str | None = None,
    joints: Sequence[str] | None = None,
    progress: Callable[[str], None] | None = None,
    **kwargs: Any,
) -> dict[str, Any]:
    """Refine every moving joint of a :func:`fit_robot` result on the fit's own samples.

    Joint j's design is the identification data as the fit has them (every decimated row,
    the torque as Y, the fitted n-dof prediction as the declared column ``k_ndof``,
    :class:`~ident.robot.refine_joint.NdofPrediction`), selected by the rows the refined
    model's fit used (:meth:`~ident.robot.estimate.RobotModel.fitted_rows`: :func:`kept_rows`,
    and the paper model's quadrant band), the other joints' q and dq offered as variables,
    a zero-order hold
    named against the raw log's period (:func:`ident.robot.refine_joint.refine_joint`).
    With validation files, a step must lower their error too (their rows selected alike).
    Then every term found is refitted inside the n-dof model, every joint together
    (:func:`ident.robot.refit.refit_robot`: before/after per joint and for the robot, under
    ``"refit"``; ``{"error": ...}`` when it cannot be done, e.g. a term reading the
    acceleration under IDIM-IV without q_ref), and kept only if the refit does not worsen
    the held-out error (:func:`ident.robot.refit_accept.accept_refit`: the refused terms
    under ``"refit"["refused"]``, one line of reason each; every term refused: the refit
    without terms, the n-dof fit).

    Parameters
    ----------
    out : dict
        :func:`fit_robot`'s result (with its private ``_`` entries).
    max_steps : int
        Refinement steps per joint at most.
    model : {"usual", "paper"} or None
        The fitted n-dof model whose prediction is refined; None: the paper model when it was
        fitted, else the usual model (:func:`ident.vocab.refined_model`, the single joint's
        rule).
    joints : sequence of str, optional
        The moving joints to refine (default every one).
    progress : callable, optional
        Receives one line per step.
    **kwargs
        Passed to :func:`refine_joint` (``alpha``, ``min_gain``, ...).

    Returns
    -------
    dict
        The ``refinement`` record of docs/robot-data.md; the Refinement objects under
        ``"_refinements"`` (not serialised). Also stored in ``out["refinement"]``.
    """
    ests = out["_estimators"]
    # "new": deprecated "paper"; None: the paper model when fitted (ident.vocab, one rule
    # with the single joint's)
    model = refined_model(ests) if model is None else model_name(model)
    if model not in ests:
        raise DataError(f"refine: model {model!r} was not fitted ({', '.join(ests) or 'none'})")
    est = ests[model]
    if getattr(est, "quadrants", "hard") == "soft":
        raise DataError(f"refine: the {model} model was fitted with soft quadrants; "
                        + SOFT_REFUSED["refine"].split(": ", 1)[1])
    sig: RobotSignals = out["_identification"]
    # the refined model's own rows (the paper model's leave its quadrant band out too): its
    # residual where it was fitted, what its n-dof refit reads
    keep = est.fitted_rows(sig)
    pred = est.predict(sig)
    val_all: RobotSignals | None = out.get("_validation_all")
    validation = None
    if val_all is not None:
        validation = (val_all, est.predict(val_all), est.fitted_rows(val_all))
    types = dict(zip(out["robot"]["moving"], _revolute(out), strict=True))
    say = progress or (lambda _m: None)
    if joints is not None:
        unknown = sorted(set(joints) - set(sig.joints))
        if unknown:
            raise DataError(f"refine: joints {unknown} are not moving joints "
                            f"({', '.join(sig.joints)})")
    done: dict[str, Any] = {}
    refs = {}
    for j, joint in enumerate(sig.joints):
        if joints is not None and joint not in joints:
            continue
        rows = keep[:, j]
        say(f"joint {joint}: refining on {int(rows.sum())} of {sig.n} rows")
        vmax = float(np.abs(sig.dq[rows, j]).max(initial=0.0)) or None
        try:
            ref = refine_joint(sig, pred, j, revolute=types.get(joint, True), vmax=vmax,
                               max_steps=max_steps, coulomb=joint_coulomb(est, j), keep=keep,
                               cycle_s=out["_cycle_s"], validation=validation,
                               progress=lambda m, joint=joint: say(f"joint {joint}: {m}"),
                               **kwargs)
        except IdentError as exc:  # e.g. too few rows kept for this joint
            done[joint] = {"error": str(exc)}
            continue
        refs[joint] = ref
        js = ref.to_json()
        done[joint] = {
            "rows": int(rows.sum()),
            "rows_left_out": float(1.0 - rows.mean()) if sig.n else 0.0,
            "ndof_rel_error": out["models"][model]["rel_error"].get(joint),
            "fit": {"before": js["rel_error_initial"], "after": js["rel_error_final"]},
            "heldout": {"kind": js["heldout_kind"], "before": js["heldout_rel_error_initial"],
                        "after": js["heldout_rel_error_final"],
                        "one_trajectory": js["heldout_one_trajectory"]},
            "noise_floor": {"before": js["noise_floor_initial"], "after": js["noise_floor"]},
            "validation": None if js["validation_rel_error_initial"] is None else {
                "before": js["validation_rel_error_initial"],
                "after": js["validation_rel_error_final"]},
            "added": [{"named_effect": st["named_effect"], "structure": st["structure"],
                       "variables": st["variables"], "generic": st["generic"]}
                      for st in js["steps"]],
            "stop_reason": js["stop_reason"],
            "refinement": js,
        }
    rec = {"model": model, "max_steps": int(max_steps), "cycle_s": out["_cycle_s"],
           "rows": "the fit's rows (decimated samples, stiction area, guard and sign check "
                   "left out as in the fit)", "joints": done}
    # the found terms refitted inside the n-dof model, all joints together
    # (ident.robot.refit): before / after per joint and for the whole robot
    terms = [(sig.joints.index(joint), st.term) for joint, ref in refs.items()
             for st in ref.steps]
    if not terms:  # nothing to refit: the n-dof model is as it was fitted
        rec["refit"] = {"skipped": "no term found on any joint: the n-dof model is unchanged"}
    else:
        say(f"n-dof refit with {len(terms)} found term(s)")
        try:  # each term kept only if the refit's held-out error allows (refit_accept)
            fitted = accept_refit(est, sig, terms, prediction=pred, keep=keep,
                                  revolute=[types.get(jn, True) for jn in sig.joints],
                                  validation=validation, progress=say)
            rec["refit"] = fitted.to_json()
            out["_refit"] = fitted
        except IdentError as exc:
            rec["refit"] = {"error": str(exc)}
        else:
            rev = [types.get(jn, True) for jn in sig.joints]
            if out.get("q_s_scan") and model == "paper" and fitted.terms:
                rec["q_s_rescan"] = _rescan(est, sig, fitted.terms, pred, keep, rev, say)
            elif out.get("q_s_scan_joints") and model == "paper" and fitted.terms:
                rec["q_s_rescan"] = _rescan_joints(est, sig, fitted.terms, pred, keep, rev,
                                                   say)
    out["refinement"] = rec
    out["_refinements"] = refs
    return rec


def _rescan(est: Any, sig: RobotSignals, terms: Sequence[tuple[int, Any]], pred: np.ndarray,
            keep: np.ndarray, revolute: list[bool], say: Callable[[str], None]
            ) -> dict[str, Any]:
    """q_s scanned again with the kept found terms (:func:`ident.qs_scan.rescan_qs`: at each
    q_s the n-dof refit of the terms, one q_s for every joint), after a fit whose q_s was
    scanned with the declared model alone (``--q-s scan``), as ``jointid demo`` does for a
    joint. Informative: the record's refit stays at the fit's q_s. ``{"error": ...}`` when
    it cannot be done."""
    vmax = float(np.max(np.abs(sig.dq[keep]), initial=0.0))
    say(f"q_s scanned again with the {len(terms)} kept term(s)")
    try:
        rs = rescan_qs(est, sig, terms, vmax=vmax, revolute=revolute, prediction=pred,
                       keep=keep)
    except IdentError as exc:
        return {"error": str(exc)}
    return {"q_s": float(rs.q_s), "q_s_fit": float(est.q_s_[0]),
            "rel_error": json_float(rs.refit.rel_error["after"]["all"]),
            "scan": [{"q_s": q, "rel_error": json_float(e)} for q, e in rs.scan]}


def _rescan_joints(est: Any, sig: RobotSignals, terms: Sequence[tuple[int, Any]],
                   pred: np.ndarray, keep: np.ndarray, revolute: list[bool],
                   say: Callable[[str], None]) -> dict[str, Any]:
    """One q_s per joint scanned again with the kept found terms, after ``--q-s scan-joints``
    (:func:`ident.qs_scan.rescan_qs_joints`: at each q_s vector the n-dof refit of the terms;
    the grid of each joint on its kept rows' largest |dq|). Informative, as :func:`_rescan`:
    the record's refit stays at the fit's q_s. ``{"error": ...}`` when it cannot be done."""
    vmax = [float(np.abs(sig.dq[keep[:, j], j]).max(initial=0.0)) for j in range(sig.k)]
    say(f"q_s scanned again per joint with the {len(terms)} kept term(s)")
    try:
        res, rf = rescan_qs_joints(est, sig, terms, vmax=vmax, revolute=revolute,
                                   prediction=pred, keep=keep)
    except IdentError as exc:
        return {"error": str(exc)}
    return {"q_s": dict(res.q_s),
            "q_s_fit": {n: float(q) for n, q in zip(est.joints_, est.q_s_, strict=True)},
            "rel_error": json_float(rf.rel_error["after"]["all"]), "fits": res.fits,
            "converged": res.converged,
            "scan": {n: [{"q_s": q, "rel_error": json_float(e), "sweep": k} for q, e, k in pts]
                     for n, pts in res.scan.items()}}


def _revolute(out: dict[str, Any]) -> list[bool]:
    """Per moving joint, whether it is revolute (the fitted regressor's robot)."""
    est = next(iter(out["_estimators"].values()))
    robot = getattr(getattr(est, "regressor_", None), "robot", None)
    if robot is None:
        return [True] * len(out["robot"]["moving"])
    kind = dict(zip(robot.joint_names, robot.types, strict=True))
    return [kind.get(n, "revolute") == "revolute" for n in out["robot"]["moving"]]


def format_refinement(rec: dict[str, Any]) -> str:
    """The per-joint refinement table ``jointid fit --robot --refine`` prints."""
    lines = [f"refinement of the {rec['model']} model, joint by joint, on the fit's rows "
             f"(raw cycle {1e3 * rec['cycle_s']:.3g} ms; errors ||rho_j||/||tau_j|| [%])"]
    w = max(8, *(len(j) + 2 for j in rec["joints"]))
    lines.append(f"{'joint':<{w}}{'fit':>16}{'held-out':>18}{'noise floor':>18}  added")
    for joint, r in rec["joints"].items():
        if "error" in r:
            lines.append(f"{joint:<{w}}not refined: {r['error']}")
            continue

        def ba(d: dict[str, Any]) -> str:
            return f"{_pct(d['before']).strip()} -> {_pct(d['after']).strip()}"

        added = ", ".join(a["named_effect"] or a["structure"] for a in r["added"]) or "none"
        lines.append(f"{joint:<{w}}{ba(r['fit']):>16}{ba(r['heldout']):>18}"
                     f"{ba(r['noise_floor']):>18}  {added}")
        if r["validation"] is not None:
            lines.append(f"{'':<{w}}validation {ba(r['validation'])}")
    if any(r.get("heldout", {}).get("one_trajectory") and r.get("validation") is None
           for r in rec["joints"].values()):
        lines.append(ONE_TRAJECTORY_NOTE)
    if rec.get("refit"):
        lines.append("")
        lines += format_refit(rec["refit"], rec["model"])
    rs = rec.get("q_s_rescan")
    if rs and isinstance(rs.get("q_s"), dict):  # --q-s scan-joints: one q_s per joint
        lines.append("q_s scanned again per joint with the kept terms: " + ", ".join(
            f"{j} {rs['q_s_fit'][j]:.4g} -> {q:.4g}" for j, q in rs["q_s"].items())
            + f" rad/s ({rs['fits']} refits, error {_pct(rs['rel_error']).strip()} %; the "
            "refit above stays at the fit's q_s)")
    elif rs:
        lines.append(f"q_s scanned again with the kept terms: not done: {rs['error']}"
                     if "error" in rs else
                     f"q_s scanned again with the kept terms: {rs['q_s_fit']:.4g} -> "
                     f"{rs['q_s']:.4g} rad/s ({len(rs['scan'])} refits, error "
                     f"{_pct(rs['rel_error']).strip()} %; the refit above stays at "
                     f"{rs['q_s_fit']:.4g})")
    return "\n".join(lines)


def format_refit(fit: dict[str, Any], model: str) -> list[str]:
    """The n-dof refit table of ``jointid fit --robot --refine`` (the found terms inside the
    n-dof model, :func:`ident.robot.refit.refit_robot`)."""
    if "error" in fit:
        return [f"n-dof refit with the found terms: not done: {fit['error']}"]
    if "skipped" in fit:
        return [f"n-dof refit: none ({fit['skipped']})"]
    lines = [f"n-dof refit of the {model} model with the found terms, every joint together "
             "(errors ||rho_j||/||tau_j|| [%], the n-dof fit -> the refit)"]
    joints = list(fit["rel_error"]["before"])
    w = max(8, *(len(j) + 2 for j in joints))

    def ba(d: dict[str, Any] | None, j: str) -> str:
        if d is None:
            return ""
        return f"{_pct(d['before'].get(j)).strip()} -> {_pct(d['after'].get(j)).strip()}"

    val = fit.get("validation_rel_error")
    lines.append(f"{'joint':<{w}}{'fit':>18}{'held-out':>18}{'noise floor':>18}"
                 + (f"{'validation':>18}" if val else ""))
    for j in joints:
        lines.append(f"{j:<{w}}{ba(fit['rel_error'], j):>18}"
                     f"{ba(fit['heldout_rel_error'], j):>18}{ba(fit['noise_floor'], j):>18}"
                     + (f"{ba(val, j):>18}" if val else ""))
    for x in fit["extras"]:
        pars = fit["parameters"]
        vals = ", ".join(
            f"{n} = {pars[x['joint'] + ':' + n]['value']:.4g} ± "
            f"{2 * (pars[x['joint'] + ':' + n]['std'] or math.nan):.2g}" for n in x["names"])
        flag = ("" if x.get("significant", True) else
                "  [not significant inside the n-dof model: Wald "
                f"{x['wald'] if x.get('wald') is None else format(x['wald'], '.3g')}]")
        # the term's derived values (a periodic form's amplitude, phase, period)
        derived = "".join(  # (not the coefficients again, e.g. a library basis's)
            f"; {n} = {v['value']:.4g}" + (f" ± {v['two_sigma']:.2g}" if v["two_sigma"] else "")
            for n, v in (x.get("parameters") or {}).items() if n not in x["names"])
        lines.append(f"  {x['joint']}: {x['effect']}: {vals}{derived} (± 2σ){flag}")
    refused = fit.get("refused") or []
    for r in refused:  # the held-out check of ident.robot.refit_accept
        lines.append(f"  {r['reason']}")
    if not fit["extras"]:
        lines.append(f"  ({ALL_REFUSED})" if refused else
                     "  (no term found: the refit is the n-dof fit)")
    if fit.get("unsettled"):
        lines.append("  note: the n-dof fit had not settled on " + ", ".join(
            f"{j} ({100 * s:.1f} % of its rows in another quadrant with its final values)"
            for j, s in fit["unsettled"].items())
            + ": 'before' is the model refitted on those quadrants without the terms, so "
            "before -> after is what the terms add")
    return lines


def _scan_qs(q_s: Any, models: tuple[str, ...],
             paper: Callable[[Any], RobotModel], sig: RobotSignals,
             notes: list[str]) -> tuple[Any, dict[str, Any]]:
    """``q_s="scan"`` or ``"scan-joints"`` of :func:`fit_robot` (:data:`ident.vocab.QS_WORDS`),
    and the record's entries of that scan.

    ``"scan"``: the q_s of the smallest relative error of the paper fit ``paper(q).fit(sig)``
    over every joint's rows (:func:`ident.qs_scan.scan_qs`; a fit that fails scores inf), one
    for every joint; ``q_s_scan`` every evaluated ``{q_s, rel_error}``. ``"scan-joints"``: one
    q_s per joint (:func:`ident.qs_scan.scan_qs_joints`: on the same error, each joint's q_s
    in turn with the others held), returned by joint name; ``q_s_scan_joints`` the scan. A
    number, sequence or mapping is returned as it is, with no scan; without the paper model,
    the default q_s. Notes say the scan's figures (one line per joint for ``scan-joints``).

    Raises
    ------
    DataError
        A string other than a number or those words, or the paper fit failing at every q_s.
    """
    if not isinstance(q_s, str):
        return q_s, {}
    q_s = qs_value(q_s)  # one rule and one message (ident.vocab)
    if not isinstance(q_s, str):
        return q_s, {}
    if "paper" not in models:  # the usual model has no q_s: ignored, as for one joint
        return DEFAULT_Q_S, {}
    t0 = time.perf_counter()
    vmax = _vmax(sig)
    if q_s == "scan-joints":
        return _scan_qs_joints(paper, sig, vmax, notes, t0)

    def score(q: float) -> float:
        try:
            return float(paper(q).fit(sig).rel_error_["all"])
        except (IdentError, np.linalg.LinAlgError):
            return math.inf

    top = float(vmax.max(initial=0.0))
    best, scan = scan_qs(score, top)
    notes.append(f"q_s scan (paper model, one q_s for every joint): {best:.4g} rad/s, the "
                 f"smallest relative error over every joint's rows of {len(scan)} paper fits "
                 f"(grid {qs_grid(top)[0]:.4g}..{qs_grid(top)[-1]:.4g} rad/s then a bounded "
                 f"search; {time.perf_counter() - t0:.1f} s)")
    return best, {"q_s_scan": [{"q_s": q, "rel_error": json_float(e)} for q, e in scan]}


def _scan_qs_joints(paper: Callable[[Any], RobotModel], sig: RobotSignals, vmax: np.ndarray,
                    notes: list[str], t0: float) -> tuple[dict[str, float], dict[str, Any]]:
    """``q_s="scan-joints"`` of :func:`_scan_qs`: :func:`ident.qs_scan.scan_qs_joints` on the
    paper fit's relative error over every joint's rows, each joint's grid on its own largest
    |dq|; the chosen q_s by joint, the record's ``q_s_scan_joints`` and one note per joint."""
    joints = sig.joints

    def score(q: np.ndarray) -> dict[str, float]:
        try:
            return dict(paper(q.tolist()).fit(sig).rel_error_)
        except (IdentError, np.linalg.LinAlgError):
            return {}  # every score inf

    if not np.all(vmax > 0):  # a joint that did not move: no grid of its own
        still = [j for j, v in zip(joints, vmax, strict=True) if not v > 0]
        raise DataError(f"--q-s scan-joints: joint(s) {', '.join(still)} have no fitted row "
                        "with |dq| > 0; give a q_s or use 'scan'")
    res = scan_qs_joints(score, vmax, joints)
    took = time.perf_counter() - t0
    notes.append(f"q_s scan per joint (paper model, 'scan-joints'): {res.fits} paper fits, "
                 f"the shared grid then {res.sweeps} coordinate sweep(s), "
                 f"{'converged' if res.converged else 'stopped at the sweep cap'} "
                 f"({took:.1f} s); error over every joint's rows "
                 f"{100 * res.error['all']:.3g} %")
    for j, v in zip(joints, vmax, strict=True):
        notes.append(f"q_s scan, joint {j}: {res.q_s[j]:.4g} rad/s, its rows' relative error "
                     f"{100 * res.error[j]:.3g} % ({len(res.scan[j])} points; grid "
                     f"{qs_grid(float(v))[0]:.4g}..{qs_grid(float(v))[-1]:.4g} rad/s)")
    return res.q_s, {"q_s_scan_joints": {
        "criterion": "all", "fits": res.fits, "sweeps": res.sweeps,
        "converged": res.converged, "rel_error": {n: json_float(e) for n, e in res.error.items()},
        "joints": {n: [{"q_s": q, "rel_error": json_float(e), "sweep": k} for q, e, k in pts]
                   for n, pts in res.scan.items()}}}


def _vmax(sel: RobotSignals) -> np.ndarray:
    """Per joint, max |dq| over the rows with a finite torque [rad/s]."""
    return np.array([float(np.abs(sel.dq[np.isfinite(sel.tau[:, j]), j]).max(initial=0.0))
                     for j in range(sel.k)])


def _raw_rows(sig: RobotSignals, settings: dict[str, Any]) -> int:
    """Full-rate samples the decimated rows of ``sig`` stand for (trimmed edges excluded)."""
    r = int(settings.get("decimation") or 1)
    return int(sig.n * r)


def _left_out(used: Any, n: int, joints: tuple[str, ...]) -> dict[str, float]:
    """Share of the n rows each joint's figure leaves out."""
    used = np.asarray(used, dtype=float)
    out = {j: float(1.0 - used[i] / n) if n else 0.0 for i, j in enumerate(joints)}
    out["all"] = float(1.0 - used.sum() / (n * len(joints))) if n else 0.0
    return out


def kept_rows(sig: RobotSignals, dq_min: float) -> np.ndarray:
    """The rows (n, k) the fit uses: the columns' keep mask (stiction area, guard, sign
    check), else |dq_j| > dq_min (the states chain)."""
    if sig.columns is not None:
        return np.asarray(sig.columns.keep, dtype=bool)
    return np.abs(sig.dq) > dq_min


def flag_unidentified(rec: dict[str, Any],
                      threshold_pct: float = DEFAULT_THRESHOLD_PCT) -> list[str]:
    """Mark the parameters of a model record whose relative std exceeds the pruning
    threshold (eq. 14-16, :data:`ident.estimate.DEFAULT_THRESHOLD_PCT`) or is undefined
    (value 0) as ``"unidentified": true`` (pruned ones excepted); their names in
    ``rec["unidentified"]``."""
    bad = []
    for p, v in rec["parameters"].items():
        rs = v["rel_std_pct"]
        # a pruned parameter (held at 0) is removed from the model, not unidentified
        # nor one the rank rule removed before the fit (not excited on these data, at 0)
        v["unidentified"] = bool(not v.get("pruned") and not v.get("removed") and (
            rs is None or not math.isfinite(rs) or rs > threshold_pct))
        if v["unidentified"]:
            bad.append(p)
    rec["unidentified"] = bad
    rec["unidentified_threshold_pct"] = float(threshold_pct)
    return bad


def band_left_out(sel: RobotSignals, every: RobotSignals,
                  vmax: np.ndarray) -> dict[str, dict[str, float]]:
    """Per joint and Table III band, the share of ``every``'s rows that ``sel`` (torque NaN
    where left out) leaves out."""
    out: dict[str, dict[str, float]] = {}
    for j, joint in enumerate(every.joints):
        # rows faster than the selected rows' vmax count as at vmax (table_iii(clip=True))
        a = (np.minimum(np.abs(every.dq[:, j]) / vmax[j], 1.0) if vmax[j] > 0
             else np.zeros(every.n))
        ok = np.isfinite(sel.tau[:, j])
        row = {}
        for band, (lo, hi) in DEFAULT_BANDS.items():
            m = (a >= lo) & (a <= hi)
            row[band] = float(1.0 - ok[m].sum() / m.sum()) if m.any() else math.nan
        out[joint] = row
    return out


def _settled(est: RobotModel, rec: dict[str, Any], rows_sig: RobotSignals,
             joints: Sequence[str], notes: list[str]) -> None:
    """Whether the paper fit settled its quadrants: ``converged`` (``RobotModel.converged_``:
    false when its last Gauss-Newton stopped at its iteration limit or its quadrant passes at
    ``max_passes`` with rows still changing quadrant or crossing the quadrant band and the
    parameters still moving; then ``convergence``, the estimator's reason, and a note),
    ``quadrant_drift`` per joint (:meth:`RobotModel.quadrant_drift`) and, where a joint's
    drift exceeds ``QUADRANT_TOL``, ``rel_error_own_quadrants`` (the fitted parameters on
    their own quadrants, the same rows) and a note: its reported error is then not the error
    of its values.

    Soft quadrants (:mod:`ident.robot.soft_fit`): no hard quadrant to drift from (every row
    weighs both), so no ``quadrant_drift``; ``converged`` is the least-squares solver's, a
    note when it stopped at its evaluation limit."""
    rec["converged"] = bool(getattr(est, "converged_", True))
    if not rec["converged"]:
        rec["convergence"] = str(getattr(est, "convergence_", "") or "")
    if getattr(est, "quadrants", "hard") == "soft":
        if not rec["converged"]:
            notes.append("paper model (soft quadrants): the least-squares fit stopped at its "
                         "evaluation limit (20 x max_iter): its values are not a minimum of "
                         "its residual")
        return
    if not rec["converged"] and rec["convergence"]:
        notes.append(f"paper model: the fit did not converge: {rec['convergence']}; its "
                     "values are those of the last pass, not a settled estimate")
    drift = est.quadrant_drift(rows_sig)
    rec["quadrant_drift"] = {j: float(x) for j, x in zip(joints, drift, strict=True)}
    bad = [(j, x) for j, x in zip(joints, drift, strict=True) if x > QUADRANT_TOL]
    if not bad:
        return
    own = est.rel_error(replace(rows_sig, tau=np.where(est.fitted_rows(rows_sig), rows_sig.tau,
                                                       np.nan)))
    rec["rel_error_own_quadrants"] = {k: float(v) for k, v in own.items()}
    why = "" if rec["converged"] else " (not converged: above)"
    notes.append(
        f"paper model: the fit did not settle{why}: with its final values the model quadrant "
        "changes on " + ", ".join(f"{100 * x:.0f} % of {j}'s rows" for j, x in bad)
        + "; on the same rows their errors are then " + ", ".join(
            f"{j} {_pct(own[j]).strip()} %" for j, _ in bad)
        + " (reported: " + ", ".join(f"{_pct(rec['rel_error'][j]).strip()} %" for j, _ in bad)
        + "), so these joints' paper-model values are not a fit of their own quadrants")


def _one_signed_loads(est: RobotModel, rec: dict[str, Any], rows_sig: RobotSignals,
                      joints: Sequence[str], notes: list[str]) -> None:
    """Paper model: a joint whose load tau_out_hat keeps one sign on (all but
    :data:`~ident.robot.estimate.THIN_QUADRANT` of) its fitted rows has its quadrant set by
    the sign of dq alone, so P+ sign(dq), P- sign(dq) and 1 are dependent: c_m, c_g and the
    offset are not separable (only OFF - c_m and OFF + c_g, or their mirror, are). The
    estimator refuses it on decimated states (``--chain states``), but on the columns chain
    the low-passed sign(dq) near the reversals breaks the dependence by a hair: the fit went
    through, the pruning held one or two of them at 0 and the others took their place with a
    tight sigma (found by the identification sweep: arm3's elbow, c_g3 pruned and c_m3 27
    sigma from the simulator's value). Those not pruned are flagged ``unidentified``
    (``rec["unidentified"]``) with a note; ``rec["one_signed_load"]`` lists the joints.

    Soft quadrants: the rows of each sign are those the soft weight expects under the fitted
    load jitter (:func:`~ident.robot.soft_fit.load_signs`, sum of Phi(s / sigma_j)): a load
    within sigma_j of zero gives the joint both quadrants, and they separate the three."""
    try:
        load = est.load_torque(rows_sig)
        rows = est.fitted_rows(rows_sig)
    except IdentError:  # products form: no theta, no load to read
        return
    found = []
    for j, (joint, n) in enumerate(zip(joints, est.numbers_, strict=True)):
        pos, neg = load_signs(est, load[rows[:, j], j], j)
        if pos + neg == 0 or min(pos, neg) >= THIN_QUADRANT * (pos + neg):
            continue
        found.append(joint)
        names = [f"{p}{n}" for p in ("c_m", "c_g", "OFF")]
        pars = rec["parameters"]
        # (a column the rank rule removed before the fit is held at 0: neither)
        flagged = [p for p in names if p in pars and not pars[p].get("pruned")
                   and not pars[p].get("removed")]
        for p in flagged:
            pars[p]["unidentified"] = True
        pruned = [p for p in names if p in pars and pars[p].get("pruned")]
        notes.append(
            f"paper model, {joint}: its load tau_out_hat is {'> 0' if pos > neg else '< 0'} "
            f"on {100 * max(pos, neg) / (pos + neg):.1f} % of its fitted rows"
            + (f" (expected, load jitter sigma {float(est.quadrant_sigma_[j]):.3g} N m)"
               if getattr(est, "quadrants", "hard") == "soft" else "")
            + ", so its quadrant "
            f"is the sign of dq: {', '.join(names)} are not separable (a trajectory on which "
            "its load changes sign separates them)"
            + (f"; {', '.join(pruned)} pruned, " if pruned else "; ")
            + f"{', '.join(flagged)} flagged unidentified: their values are not the "
            "parameters")
    rec["unidentified"] = [p for p, v in rec["parameters"].items() if v.get("unidentified")]
    rec["one_signed_load"] = found


def _position_extrapolation(est: RobotModel, rec: dict[str, Any], rows_sig: RobotSignals,
                            val: RobotSignals, joints: Sequence[str], name: str,
                            files: Sequence[str], notes: list[str], said: set[str],
                            revolute: Sequence[bool]) -> None:
    """Each joint's validation error split by the fit's position range
    (:func:`ident.results.position_split`): ``rec["validation_position_split"]`` per joint,
    and a note for a joint with more than
    :data:`~ident.results.POSITION_OUTSIDE_SHARE` of its validation rows (those the
    cross-validation error uses) outside the positions of its fitted rows ([rad], [m] for a
    prismatic joint: ``revolute``, per joint). Only the positions decide the split; the
    headline validation error is unchanged. ``said``: what the fit's earlier notes said (the
    files named, the reasons explained; :func:`ident.results.position_split_notes`), updated
    here."""
    try:
        rows = est.fitted_rows(rows_sig)
    except IdentError:
        rows = np.isfinite(rows_sig.tau)
    rho = est.residual(val)
    kind = dict(zip(joints, revolute, strict=True))
    splits = {joint: position_split(rows_sig.q[rows[:, j], j], val.q[:, j], val.tau[:, j],
                                    rho[:, j]) for j, joint in enumerate(joints)}
    splits = {joint: sp for joint, sp in splits.items() if sp is not None}
    notes.extend(position_split_notes(((f"{joint} ({name} model)", sp)
                                       for joint, sp in splits.items()), files,
                                      [kind[joint] for joint in splits], said=said))
    rec["validation_position_split"] = {
        joint: position_split_json(sp)
        for joint, sp in splits.items()}


def _without_full(sig: RobotSignals) -> RobotSignals:
    """``sig`` without the full-rate signals the chain kept (``design_runs(keep_full=True)``)
    and with its kept full-rate regressor released (``full_columns`` then holds only its
    counts of evaluations)."""
    cols = sig.columns
    if cols is None or (cols.full is None and cols.full_columns is None):
        return sig
    if cols.full_columns is not None:
        cols.full_columns.release()
    return replace(sig, columns=replace(cols, full=None))


def selected(sig: RobotSignals, dq_min: float) -> RobotSignals:
    """``sig`` with the torque of joint j set to NaN where the estimator leaves joint j's
    rows out: the columns' keep mask (:mod:`ident.robot.design`), else |dq_j| <= dq_min
    (the stiction area; non-finite torques are ignored by ``RobotModel.rel_error``)."""
    if sig.columns is not None:
        return replace(sig, tau=np.where(sig.columns.keep, sig.tau, np.nan))
    return replace(sig, tau=np.where(np.abs(sig.dq) > dq_min, sig.tau, np.nan))


def _pct(x: float | None) -> str:
    if x is None or not math.isfinite(x):
        return "n/a"
    return f"{100 * x:6.2f}" if abs(x) < 1e4 else f"{100 * x:.2e}"


def format_report(out: dict[str, Any]) -> str:
    """The tables ``jointid fit --robot`` prints: parameters, then relative errors."""
    lines: list[str] = []
    r = out["robot"]
    pre = out["preprocessing"]
    lines.append(f"robot {r['name']} ({r['source']}): moving joints {', '.join(r['moving'])}")
    lines.append(f"preprocessing ({pre['chain']} chain): cut-off {pre['cutoff_hz']:g} Hz, "
                 f"decimation {pre['decimation']}, trim {pre['trim']}, "
                 f"{_delay_text(pre)}, dq_min "
                 f"{pre['dq_min']:.4g} {out.get('_dq_unit', 'rad/s')}, {pre['samples']} "
                 f"samples x {len(r['moving'])} joint{'s' if len(r['moving']) > 1 else ''}; "
                 f"method {out['method']}, payload {out['payload']}")
    lines.extend(f"note: {n}" for n in out.get("notes", []))
    fitted = {n: rec for n, rec in out["models"].items() if "error" not in rec}
    for name, rec in out["models"].items():
        lines.append("")
        if "error" in rec:
            lines.append(f"== {name} model: not identified: {rec['error']} ==")
            continue
        lines.append(f"== {name} model: {len(rec['parameters'])} parameters "
                     f"({rec['n_base']} base) ==")
        lines.append(f"{'parameter':<14}{'value':>14}{'std':>12}{'%std':>9}{'std eq15':>12}")
        for p, v in rec["parameters"].items():
            rs = v["rel_std_pct"]
            rs_s = "inf" if rs is None or not math.isfinite(rs) else f"{rs:.1f}"
            if v.get("pruned") or v.get("removed"):
                rs_s = "-"
            flag = ("  unidentified" if v.get("unidentified") else
                    "  pruned" if v.get("pruned") else
                    "  removed" if v.get("removed") else "")
            lines.append(f"{p:<14}{v['value']:>14.6g}{v['std']:>12.3g}{rs_s:>9}"
                         f"{v.get('std_analytic', v['std']):>12.3g}{flag}")
        lines.extend(format_uncertainty(rec.get("uncertainty")))
        if rec.get("unidentified"):
            lines.append(f"unidentified: relative std above {rec['unidentified_threshold_pct']:g}"
                         " % (eq. 14-16): values and the prediction where they act are not "
                         "identified")
        if rec.get("base_expressions"):
            lines.append("base parameters (standard parameters regrouped, ROBOT_FORMAT names):")
            lines.extend(f"  {e}" for e in rec["base_expressions"])
        if rec.get("payload_merged"):
            lines.append("payload: in every run, its first moments and inertia merged into the "
                         "last link's base parameters (its mass at the flange subtracted)")
        if rec.get("payload_misfit"):
            lines.append("payload (flange frame, about its origin; mass known): "
                         + "; ".join(rec["payload_expressions"]))
            lines.append("payload check, residual RMS on the payload vs no-payload runs:")
            lines.extend(f"  {ln}" for ln in format_misfit(rec["payload_misfit"]).splitlines())
    lines.append("")
    lines.append("relative error ||rho_j|| / ||tau_j|| [%]: on the fit's rows (out: share of "
                 "the rows left out) and on all rows (stiction area, guard, sign check "
                 f"included; file edges, {100 * pre.get('edge_share', 0.0):.1f} % of the "
                 "samples, out of both)")
    w = max(8, *(len(j) + 2 for j in r["moving"]))
    cv = bool(out["validation_inputs"])
    head = f"{'joint':<{w}}"
    for name in fitted:
        head += f"{name + ' fit':>12}{'out':>7}{name + ' all':>12}"
        if cv:
            head += f"{name + ' CV':>12}{'out':>7}{name + ' CV all':>14}"
    lines.append(head)
    for j in [*r["moving"], "all"]:
        row = f"{j:<{w}}"
        for rec in fitted.values():
            row += (f"{_pct(rec['rel_error'].get(j)):>12}"
                    f"{_pct(rec.get('rows_left_out', {}).get(j)):>7}"
                    f"{_pct(rec.get('rel_error_all_rows', {}).get(j)):>12}")
            if cv:
                row += (f"{_pct(rec['validation_rel_error'].get(j)):>12}"
                        f"{_pct(rec.get('validation_rows_left_out', {}).get(j)):>7}"
                        f"{_pct(rec.get('validation_rel_error_all_rows', {}).get(j)):>14}")
        lines.append(row)
    tables = out.get("table_iii", {})
    left = out.get("rows_left_out", {})
    for part in ("fit", "validation"):
        if part not in tables:
            continue
        lines.append("")
        what = "identification data" if part == "fit" else "validation files"
        lines.append(f"Table III per joint, ||rho|| / ||tau|| on the {what} "
                     "(low: |dq| <= 10 % of the joint's max, high: 35-100 %): the fit's rows, "
                     "all rows, and the share of the band's rows the first leaves out")
        lines.append(format_table_iii(tables[part], all_rows=tables.get(part + "_all_rows"),
                                      left_out=left.get(part)))
    if out.get("refinement"):
        lines.append("")
        lines.append(format_refinement(out["refinement"]))
    for name, text in out.get("_consistency", {}).items():
        lines.append("")
        lines.append(f"{name} model: " + text)
    for name, rec in fitted.items():
        if rec.get("consistent"):  # --consistent
            lines.append("")
            lines.append(f"{name} model: " + format_record(rec["consistent"]))
    return "\n".join(lines)


def _delay_text(pre: Mapping[str, Any]) -> str:
    """The summary's torque delay: its value [samples] and whether given or the default."""
    d = pre.get("torque_delay")
    if d is None:  # a record of before the torque delay was reported
        return "torque delay n/a"
    how = "given" if pre.get("torque_delay_given") else "default"
    return f"torque delay {d:g} sample ({how})"


def _speed_unit(robot: Robot) -> str:
    """Unit of a velocity threshold of the moving joints: rad/s, m/s (every joint prismatic:
    the EMPS axis) or both (one dq_min for joints of both kinds)."""
    kinds = {robot.types[robot.joint_names.index(j)] for j in robot.moving}
    if kinds == {"prismatic"}:
        return "m/s"
    return "rad/s" if kinds == {"revolute"} else "rad/s or m/s (one threshold, every joint)"


def public_record(out: dict[str, Any]) -> dict[str, Any]:
    """The JSON record of a :func:`fit_robot` result (its private ``_`` entries left out)."""
    return {k: v for k, v in out.items() if not k.startswith("_")}


def run(args: argparse.Namespace) -> int:
    """Execute ``jointid fit --robot``; returns the exit code."""
    _check_args(args)
    q_s = parse_qs(args.q_s)  # refused in one line before any file is read
    robot = load_robot(args.robot)
    with warnings_held():  # a refusal is its one line, without the warnings before it
        out = fit_files(robot, args.inputs, args.validate, model=args.model,
                        mapping=parse_mapping(args.map, robot=True), q_unit=args.q_unit,
                        cutoff=args.cutoff, decimation=args.decimation, trim=args.trim,
                        torque_delay=getattr(args, "torque_delay", None), method=args.method,
                        q_s=q_s, dq_min=args.dq_min,
                        known_rotor_inertia=args.known_rotor_inertia,
                        chain=args.chain or "columns", payload=args.payload,
                        feasibility=not getattr(args, "no_consistency", False),
                        consistent=getattr(args, "consistent", False),
                        sigma_blocks=N_BLOCKS if getattr(args, "sigma_blocks", None) is None
                        else args.sigma_blocks, prune=not getattr(args, "no_prune", False),
                        sign_check=not getattr(args, "no_sign_check", False),
                        quadrants=getattr(args, "quadrants", None) or "hard",
                        full_rate=bool(getattr(args, "full_rate", False)),
                        progress=lambda m: print(m, file=sys.stderr))
    if getattr(args, "refine", False):
        refine_robot(out, max_steps=args.max_steps,
                     progress=lambda m: print(m, file=sys.stderr))
    text = format_report(out)
    public = public_record(out)
    # everything computed: only now write files (a bad input leaves nothing behind)
    print(text)
    if args.report is not None:
        with staged_folder(args.report) as tmp:  # written whole or not at all
            figures = write_robot_report(tmp, out, text)
            public["figures"] = [str(args.report / f.name) for f in figures]
            write_json(tmp / "fit.json", public)
        print(f"\nreport: {args.report / 'report.html'} ({len(figures)} figures, tables.txt, "
              "fit.json)")
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        write_json(args.json, public)
        print(f"json: {args.json}")
    return 0
