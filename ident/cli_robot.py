"""``jointid fit --robot ROBOT DATA... [--model usual|paper|both] [--method ls|wls|iv]
[--validate DATA...] [--json FILE] [--report DIR]``: identify an n-dof robot.

Every input file is one multi-axis experiment of the robot's moving joints
(:mod:`ident.robot.loaders`: MCAP logs of ``jointid run``, CSV ``t, q1..qk, tau1..tauk``,
MATLAB structs with one row per axis); all are preprocessed per axis like a single joint and
identified together (:class:`ident.robot.estimate.RobotModel`: base parameters of the rigid
body and rotor inertias, plus the usual or the paper friction on every joint). Prints the
base parameters with their standard deviations (eq. 15-16), the per-joint and global relative
errors on the fit data and on the ``--validate`` files, and writes the JSON record
(``docs/robot-data.md``). Outputs are written only once everything has been computed, so a bad
input leaves nothing behind.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import replace
from typing import Any

import numpy as np

from trajectories.robot import Robot, load_robot

from . import DataError, IdentError
from .fitting import DQ_MIN_FRACTION, SIGN_CHECK_MIN_KEPT
from .report import write_json
from .robot.consistency import check_consistency
from .robot.design import design_runs, resolve_design, sign_checked
from .robot.estimate import RobotModel
from .robot.loaders import (
    RawRobotRun,
    RobotPreprocessing,
    load_robot_runs,
    parse_robot_mapping,
    preprocess_runs,
    resolved_settings,
)
from .robot.payload import format_misfit, payload_misfit
from .robot.plots import write_robot_report
from .robot.regressor import RobotRegressor
from .robot.signals import RobotSignals
from .robot.tables import format_table_iii, table_iii

__all__ = ["run", "fit_robot", "format_report", "FORMAT"]

FORMAT = "jointid-robot-fit/1"
#: Preprocessing chains (``fit_robot(chain=...)``, ``--chain``).
CHAINS = ("columns", "states")
#: Payload treatments (``fit_robot(payload=...)``, ``--payload``).
PAYLOADS = ("known", "ratio", "mass")
#: Options of the single-joint ``jointid fit`` that have no meaning with ``--robot``.
_SINGLE_ONLY = (("joint", "--joint", "the robot file gives the joint types"),
                ("gain", "--gain", "use drive_gain in the robot file's [joints.drive]"),
                ("refine", "--refine", "single-joint only"),
                ("tau_min", "--tau-min", "single-joint only"),
                ("threshold", "--threshold", "single-joint only"))


def _gains(robot: Robot) -> list[float]:
    """Joint-side torque per unit of logged torque of each moving joint (robot file drives)."""
    out = []
    for n in robot.moving:
        d = robot.drives.get(n)
        g = None if d is None else (d.drive_gain or d.torque_constant)
        out.append(1.0 if g is None else float(g))
    return out


def _qs(value: str) -> float:
    try:
        qs = float(value)
    except ValueError:
        raise DataError(f"--qs {value!r}: expected a number [rad/s] (the scan is single-joint "
                        "only)") from None
    if not qs > 0 or not math.isfinite(qs):
        raise DataError(f"--qs {value!r}: expected a number > 0 [rad/s]")
    return qs


def _check_args(args: argparse.Namespace) -> None:
    for attr, flag, hint in _SINGLE_ONLY:
        if getattr(args, attr, None) not in (None, False):
            raise DataError(f"{flag}: not used with --robot ({hint})")
    if getattr(args, "axis", 0) not in (0, None):
        raise DataError("--axis: not used with --robot (every axis of the log is a moving joint)")


def fit_robot(
    robot: Robot,
    runs: list[RawRobotRun],
    validation: list[RawRobotRun] | None = None,
    *,
    models: tuple[str, ...] = ("usual", "paper"),
    method: str | None = None,
    qs: float = 0.03,
    dq_min: float | None = None,
    preprocessing: RobotPreprocessing | None = None,
    known_rotor_inertia: bool = False,
    chain: str = "columns",
    payload: str | None = None,
    sign_check: bool = True,
    feasibility: bool = True,
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
    qs : float
        q_s of the paper model [rad/s].
    dq_min : float or None
        Stiction area |dq_j| < dq_min left out of joint j's rows [rad/s]; None: 1 % of the
        largest |dq| of the identification data.
    preprocessing : RobotPreprocessing or None
        Cut-off, decimation, trim (None entries: chosen by the chain's rules).
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
    if method is None:
        method = "wls"
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
    pre = preprocessing or RobotPreprocessing()
    notes: list[str] = []
    if chain == "columns":
        design = resolve_design(runs, instruments=method == "iv", cutoff_hz=pre.cutoff_hz,
                                decimation=pre.decimation, trim=pre.trim, dq_min=dq_min)
        sig, dq_min = design_runs(runs, reg, design, instruments=method == "iv")
        design = replace(design, dq_min=dq_min)
        val = design_runs(validation, reg, design)[0] if validation else None
        settings: dict[str, Any] = design.as_dict()
        est_dq_min = 0.0  # the stiction area is in the columns' keep mask
        if sign_check and "paper" in models:
            # as the single-joint fit: a first usual fit estimates tau_out; rows where
            # sign(tau) != sign(tau_out) are left out of both models (and the validation)
            first = RobotModel(reg, model="usual", method=method,
                               payload_ratio=payload == "ratio",
                               payload_params=payload == "mass").fit(sig)
            sig, kept = sign_checked(sig, runs, design, first.load_torque,
                                     SIGN_CHECK_MIN_KEPT)
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
                                 int(settings["trim"]))
        sig = preprocess_runs(runs, joints, pre)
        val = preprocess_runs(validation, joints, pre) if validation else None
        if dq_min is None:
            dq_min = DQ_MIN_FRACTION * float(np.max(np.abs(sig.dq)))
        est_dq_min = dq_min
    if val is not None:
        # the validation error is taken on the samples the fit would use (as the single-joint
        # validation design): joint j's torque in its stiction area is left out (NaN)
        val = selected(val, dq_min)
    out: dict[str, Any] = {
        "format": FORMAT,
        "robot": {"name": robot.name, "source": robot.source, "moving": list(joints),
                  "numbers": list(robot.numbers)},
        "inputs": [r.source for r in runs],
        "validation_inputs": [r.source for r in validation or []],
        "preprocessing": {**settings, "chain": chain, "dq_min": dq_min, "samples": sig.n,
                          "validation_samples": 0 if val is None else val.n},
        "method": method,
        "known_rotor_inertia": bool(known_rotor_inertia),
        "payload": payload,
        "qs": qs,
        "notes": notes,
        "models": {},
        "_estimators": {},
        "_consistency": {},
        "_signals": (selected(sig, dq_min), val),
        "_identification": sig,
    }
    for name in models:
        try:
            # one joint: exactly the single-joint fit's rows (no quadrant band; the sign
            # check plays its part there)
            est = RobotModel(reg, model=name, method=method, qs=qs, dq_min=est_dq_min,
                             payload_ratio=payload == "ratio",
                             payload_params=payload == "mass",
                             quadrant_band=0.0 if len(robot.moving) == 1 else 0.03).fit(sig)
        except IdentError as exc:
            if len(models) == 1:
                raise
            # one of several models cannot be identified on these data: say so, keep the
            # others (the data are not bad, they do not excite that model)
            out["models"][name] = {"error": str(exc)}
            continue
        rec: dict[str, Any] = {
            "parameters": {
                p: {"value": float(v), "std": float(s),
                    "rel_std_pct": float(100.0 * s / abs(v)) if v != 0 else None}
                for p, v, s in zip(est.names_, est.coef_, est.std_, strict=True)
            },
            "n_base": int(est.n_base_),
            "rel_error": {k: float(v) for k, v in est.rel_error_.items()},
            "sigma_joint": {j: float(s) for j, s in zip(joints, est.sigma_joint_, strict=True)},
            "samples": {j: int(n) for j, n in zip(joints, est.n_samples_, strict=True)},
        }
        expressions = getattr(est.base_, "expressions", None)
        if expressions:
            rec["base_expressions"] = list(expressions)
        if payload == "mass":  # the payload's identifiable combinations, the per-joint check
            rec["payload_merged"] = bool(est.payload_merged_)
            if not est.payload_merged_:
                rec["payload_expressions"] = list(est.payload_base_.expressions)
                rec["payload_misfit"] = payload_misfit(est, out["_signals"][0])
        if val is not None:
            rec["validation_rel_error"] = {k: float(v) for k, v in est.rel_error(val).items()}
        cons = check_consistency(est, feasibility=feasibility)
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
    if not out["_estimators"]:
        raise DataError("; ".join(f"{n} model: {r['error']}" for n, r in out["models"].items()))
    fit_sel = out["_signals"][0]
    out["table_iii"] = {"fit": table_iii(out["_estimators"], fit_sel)}
    if val is not None:
        out["table_iii"]["validation"] = table_iii(out["_estimators"], val)
    return out


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
                 f"decimation {pre['decimation']}, trim {pre['trim']}, dq_min "
                 f"{pre['dq_min']:.4g} rad/s, {pre['samples']} samples x {len(r['moving'])} "
                 f"joints; method {out['method']}, payload {out['payload']}")
    lines.extend(f"note: {n}" for n in out.get("notes", []))
    fitted = {n: rec for n, rec in out["models"].items() if "error" not in rec}
    for name, rec in out["models"].items():
        lines.append("")
        if "error" in rec:
            lines.append(f"== {name} model: not identified: {rec['error']} ==")
            continue
        lines.append(f"== {name} model: {len(rec['parameters'])} parameters "
                     f"({rec['n_base']} base) ==")
        lines.append(f"{'parameter':<14}{'value':>14}{'std':>12}{'%std':>9}")
        for p, v in rec["parameters"].items():
            rs = v["rel_std_pct"]
            rs_s = "inf" if rs is None or not math.isfinite(rs) else f"{rs:.1f}"
            lines.append(f"{p:<14}{v['value']:>14.6g}{v['std']:>12.3g}{rs_s:>9}")
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
    lines.append("relative error ||rho_j|| / ||tau_j|| [%]")
    w = max(8, *(len(j) + 2 for j in r["moving"]))
    head = f"{'joint':<{w}}"
    for name in fitted:
        head += f"{name + ' fit':>14}"
        if out["validation_inputs"]:
            head += f"{name + ' CV':>14}"
    lines.append(head)
    for j in [*r["moving"], "all"]:
        row = f"{j:<{w}}"
        for rec in fitted.values():
            row += f"{_pct(rec['rel_error'].get(j)):>14}"
            if out["validation_inputs"]:
                row += f"{_pct(rec['validation_rel_error'].get(j)):>14}"
        lines.append(row)
    for part, table in out.get("table_iii", {}).items():
        lines.append("")
        what = "identification data" if part == "fit" else "validation files"
        lines.append(f"Table III per joint, ||rho|| / ||tau|| on the {what} "
                     "(low: |dq| <= 10 % of the joint's max, high: 35-100 %)")
        lines.append(format_table_iii(table))
    for name, text in out.get("_consistency", {}).items():
        lines.append("")
        lines.append(f"{name} model: " + text)
    return "\n".join(lines)


def _public(out: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in out.items() if not k.startswith("_")}


def run(args: argparse.Namespace) -> int:
    """Execute ``jointid fit --robot``; returns the exit code."""
    _check_args(args)
    robot = load_robot(args.robot)
    models = {"usual": ("usual",), "new": ("paper",), "paper": ("paper",),
              "both": ("usual", "paper")}[args.model]
    qs = _qs(args.qs)
    mapping = parse_robot_mapping(args.map)
    kw: dict[str, Any] = dict(gains=_gains(robot), mapping=mapping, q_unit=args.q_unit)
    runs = load_robot_runs(args.inputs, robot.moving, **kw)
    val = load_robot_runs(args.validate, robot.moving, **kw) if args.validate else None
    pre = RobotPreprocessing(args.cutoff, args.decimation, args.trim)
    out = fit_robot(robot, runs, val, models=models, method=args.method, qs=qs,
                    dq_min=args.dq_min, preprocessing=pre,
                    known_rotor_inertia=args.known_rotor_inertia,
                    chain=args.chain or "columns", payload=args.payload,
                    feasibility=not getattr(args, "no_consistency", False))
    text = format_report(out)
    public = _public(out)
    # everything computed: only now write files (a bad input leaves nothing behind)
    print(text)
    if args.report is not None:
        figures = write_robot_report(args.report, out, text)
        public["figures"] = [str(f) for f in figures]
        write_json(args.report / "fit.json", public)
        print(f"\nreport: {args.report / 'report.html'} ({len(figures)} figures, tables.txt, "
              "fit.json)")
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        write_json(args.json, public)
        print(f"json: {args.json}")
    return 0

