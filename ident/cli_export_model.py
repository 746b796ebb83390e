"""``jointid export-model FIT.json [--robot ROBOT] [--model usual|paper] -o OUTDIR``: the
identified robot model as a URDF (physically consistent inertials) and a friction file
(docs/model-export.md).

FIT.json is the record of ``jointid fit --robot ... --json``. When its model carries a
``consistent`` block (:func:`ident.robot.consistent_fit.add_consistent`), that estimate is
exported as it is; otherwise the fit is made again from the record's inputs and settings
(the record has no covariance, which the consistent estimate needs), checked to give the
record's parameters, and the consistent estimate is computed. Everything is computed before a
file is written: a bad input leaves nothing behind; the files are written into a temporary
folder (beside or inside OUTDIR) moved in at the end (:func:`ident.report.staged_folder`), so
an interrupt leaves nothing half-written either.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from . import DataError
from .vocab import model_name, upgrade_record

if TYPE_CHECKING:
    from trajectories.robot import Robot

# the fitting modules (scipy, pinocchio...) are imported by the functions that use them:
# `jointid --help` must not wait seconds for them

__all__ = ["register", "run", "consistent_from_record", "soft_quadrants"]

#: Relative agreement asked of a refit with the record's parameters.
REFIT_RTOL = 1e-6


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``export-model`` subcommand to the ``jointid`` parser."""
    p = sub.add_parser(
        "export-model", help="write the identified robot as a URDF and a friction file",
        description="Write the identified robot model of FIT.json (jointid fit --robot ... "
        "--json) as OUTDIR/<robot>.urdf (physically consistent inertials), "
        "OUTDIR/friction.json (friction, rotor inertias, gravity) and OUTDIR/consistent.json "
        "(the consistent estimate and its cost); format: docs/model-export.md.")
    p.add_argument("fit", type=Path, metavar="FIT.json", help="record of jointid fit --robot")
    p.add_argument("--robot", help="robot file (default: the one FIT.json names)")
    p.add_argument("--model", choices=("usual", "paper", "new"),
                   help="model to export (default: paper when identified, else usual); 'new' "
                   "is a deprecated alias of 'paper'")
    p.add_argument("-o", "--output", type=Path, required=True, metavar="OUTDIR",
                   help="folder to write into (created)")
    p.add_argument("--map", action="append", metavar="KEY=PATH[,...]",
                   help="as jointid fit --map, when the inputs must be read again (CSV/MAT)")
    p.add_argument("--q-unit", choices=("rad", "deg", "m", "mm"),
                   help="as jointid fit --q-unit, when the inputs must be read again")
    p.set_defaults(func=run)


def read_fit_record(path: Path) -> dict[str, Any]:
    """A `jointid fit --robot --json` record (one line naming the file when it is not one)."""
    from .cli_robot import FORMAT, OLD_FORMATS

    try:
        rec = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as e:
        raise DataError(f"{path}: not JSON ({e.msg}, line {e.lineno})") from None
    except UnicodeDecodeError as e:  # a log, a MAT file...: not a text file at all
        raise DataError(f"{path}: not UTF-8 text (byte 0x{e.object[e.start]:02x} at offset "
                        f"{e.start}); expected the JSON record of jointid fit --robot ... "
                        "--json") from None
    if isinstance(rec, dict) and rec.get("format") in OLD_FORMATS:
        rec = upgrade_record(rec)  # older spellings ("qs", "new", "ols"): ident.vocab
    elif not isinstance(rec, dict) or rec.get("format") != FORMAT:
        got = rec.get("format") if isinstance(rec, dict) else type(rec).__name__
        raise DataError(f"{path}: format {got!r}: expected {FORMAT!r} (jointid fit --robot "
                        "... --json)")
    return rec


def _recorded_robot(robot: dict[str, Any]) -> str:
    """The robot file of a record: its absolute ``path`` (records since 2026-11-28) when that
    file exists, else the ``source`` as the fit was given it (relative to the fit's folder)."""
    path = robot.get("path")
    return path if path and Path(path).is_file() else robot["source"]


def consistent_from_record(path: Path, rec: dict[str, Any], robot: Robot, name: str,
                           mapping: Any = None, q_unit: str | None = None
                           ) -> tuple[dict[str, Any], dict[str, float]]:
    """The consistent estimate of model ``name`` of the record: its ``consistent`` block, or
    a refit of its inputs (checked against its parameters) and :func:`fit_consistent`.
    Returns (consistent record, parameters held fixed by the fit)."""
    from .cli_robot import fit_robot
    from .robot.consistent_fit import consistent_record, fit_consistent
    from .robot.loaders import RobotPreprocessing

    mrec = rec["models"][name]
    if "consistent" in mrec:
        return mrec["consistent"], {}
    pre = rec.get("preprocessing", {})
    try:
        runs = _read_inputs(path, rec, robot, name, mapping, q_unit)
        # the record's torque delay (absent from older records: the default, as then)
        settings = RobotPreprocessing(pre.get("cutoff_hz"), pre.get("decimation"),
                                      pre.get("trim"), pre.get("torque_delay"))
        fitted = tuple(n for n, r in rec["models"].items() if "error" not in r)
        out = fit_robot(robot, runs, None, models=fitted, method=rec["method"], q_s=rec["q_s"],
                        dq_min=pre.get("dq_min"), preprocessing=settings,
                        known_rotor_inertia=bool(rec.get("known_rotor_inertia", False)),
                        chain=pre.get("chain", "columns"), payload=rec.get("payload"),
                        feasibility=False)
    except KeyError as e:
        raise DataError(f"{path}: key {e.args[0]!r} missing (a record of jointid fit "
                        "--robot)") from None
    est = out["_estimators"].get(name)
    if est is None:
        raise DataError(f"{path}: the {name} model is not identified again from its inputs")
    want = np.array([v["value"] for v in mrec["parameters"].values()], dtype=float)
    if tuple(mrec["parameters"]) != tuple(est.names_) or not np.allclose(
            est.coef_, want, rtol=REFIT_RTOL, atol=REFIT_RTOL * np.abs(want).max()):
        raise DataError(f"{path}: the {name} model fitted again from its inputs "
                        f"{rec['inputs']} does not give its parameters (inputs changed, or "
                        "other --map/--q-unit)")
    cf = fit_consistent(est, out["_signals"][0], tau_peak=out["_tau_peak"])
    return consistent_record(est, cf), dict(est.fixed_)


def _read_inputs(path: Path, rec: dict[str, Any], robot: Robot, name: str, mapping: Any,
                 q_unit: str | None) -> list[Any]:
    """The record's inputs read again (``load_robot_runs``), with ``jointid fit``'s ``--map``
    and ``--q-unit`` as the record keeps them (``"reading"``) unless given here. A record
    written before it kept them: a read failing without them says to give them to
    export-model (one line naming the record and the model)."""
    from . import IdentError
    from .cli_robot import robot_gains
    from .robot.loaders import load_robot_runs

    reading = rec.get("reading") or {}
    if mapping is None and q_unit is None and isinstance(reading, dict):
        mapping, q_unit = reading.get("map"), reading.get("q_unit")
    try:
        return load_robot_runs(rec["inputs"], robot.moving, gains=robot_gains(robot),
                               mapping=mapping, q_unit=q_unit)
    except IdentError as e:
        foreign = [f for f in rec["inputs"] if Path(f).suffix.lower() in (".csv", ".mat")]
        if (mapping is not None or q_unit is not None or not foreign
                or not all(Path(f).is_file() for f in rec["inputs"])):
            raise  # not a question of --map: the files are logs, or missing
        raise DataError(f"{path}: models.{name}: {e}; export-model reads the record's inputs "
                        "again and the record (written before jointid fit kept them) does not keep "
                        "jointid fit's --map and --q-unit: "
                        "give export-model the ones given to jointid fit") from None


def soft_quadrants(rec: dict[str, Any], name: str) -> bool:
    """Whether model ``name`` of the record was fitted with soft quadrant weights
    (``jointid fit --robot --quadrants soft``: its ``quadrants``, else the record's for the
    paper model)."""
    q = rec["models"][name].get("quadrants")
    if q is None and name == "paper":
        q = rec.get("quadrants")
    return q == "soft"


def run(args: argparse.Namespace) -> int:
    """Execute ``jointid export-model``; returns the exit code."""
    from trajectories.robot import load_robot

    from .cli import check_output, warnings_held
    from .loaders import parse_mapping
    from .report import staged_folder, write_json
    from .robot import RobotIdentError
    from .robot.consistent_fit import format_record
    from .robot.export_model import export_model

    check_output("-o", args.output, directory=True)  # a writable folder, before the refit
    rec = read_fit_record(args.fit)
    fitted = [n for n, r in rec.get("models", {}).items() if "error" not in r]
    name = model_name(args.model) if args.model else ("paper" if "paper" in fitted else "usual")
    if name not in fitted:
        raise DataError(f"{args.fit}: models.{name}: not identified in this record (it has "
                        f"{fitted or 'none'})")
    if soft_quadrants(rec, name):  # the friction file has no sigma_j: hard quadrants
        raise DataError(f"{args.fit}: model {name!r} was fitted with soft quadrants; "
                        "export-model writes hard-quadrant friction only")
    robot_file = args.robot or _recorded_robot(rec["robot"])
    robot = load_robot(robot_file)
    if list(robot.moving) != list(rec["robot"]["moving"]):
        raise DataError(f"{robot_file}: moving joints "
                        f"{list(robot.moving)}, the record's are {rec['robot']['moving']}")
    mapping = parse_mapping(args.map, robot=True) if args.map else None
    with warnings_held():  # a refusal is its one line, without the solver's warnings
        try:
            cons, fixed = consistent_from_record(args.fit, rec, robot, name, mapping,
                                                 args.q_unit)
        except RobotIdentError as e:  # the solver's refusal, named after the record's model
            if str(e).startswith(str(args.fit)):
                raise
            raise DataError(f"{args.fit}: models.{name}: {e}") from None
    if not cons.get("valid", False):
        left = cons.get("friction_bounds", {}).get("still_violated", [])
        raise DataError(f"{args.fit}: models.{name}.consistent: " + (
            f"friction bounds {', '.join(left)} still violated (on parameters held fixed)"
            if left else "a link is not physically valid") + "; nothing exported")
    with staged_folder(args.output) as tmp:  # written whole or not at all
        files = export_model(robot, cons, tmp, fixed)
        files.append(write_json(tmp / "consistent.json", cons))
    print(f"{name} model: " + format_record(cons))
    for f in files:
        print(f"wrote {args.output / f.name}")
    return 0
