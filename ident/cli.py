"""``jointid fit INPUTS... [--model usual|paper|both] [--method ls|wls|iv]
[--joint revolute|prismatic] [--q-s VALUE|scan|scan-joints] [--validate FILES...] [--report DIR]
[--json FILE]``: identify the usual and the paper model (names: :mod:`ident.vocab`).
With ``--robot ROBOT`` the inputs are multi-axis runs of a robot (``ident.cli_robot``).

Every input file (MCAP log of ``jointid run``, CSV or MATLAB ``.mat``) is one experiment;
all are concatenated into one least-squares system (paper eq. 36). Prints Tables I-IV,
writes the JSON record (``docs/fit-json.md``) and the direct-validation plots (Fig. 4-5).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from trajectories.friction import DEFAULT_Q_S

from . import DataError
from .held_warnings import warnings_held  # also for cli_robot, cli_export_model
from .vocab import METHOD_ALIASES, METHOD_NAMES, method_name, model_name, qs_value

if TYPE_CHECKING:
    from .api import JointModel

# the fitting modules (scipy, matplotlib, pinocchio...) are imported by the functions that
# use them: `jointid --help` and `jointid fit --help` must not wait seconds for them

__all__ = ["register", "run"]


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``fit`` subcommand to the ``jointid`` parser."""
    p = subparsers.add_parser(
        "fit",
        help="identify the usual and the load/velocity-dependent friction model",
        description=(__doc__ or "").split("\n\n")[1] if __doc__ else None,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=(
            "examples:\n"
            "  jointid fit runs/*.mcap --json fit.json --report fit/\n"
            "  jointid fit DATA_EMPS.mat --joint prismatic --map q=qm,tau=vir --gain gtau \\\n"
            "      --cutoff 100 --decimation 10 --dq-min 0 --no-sign-check \\\n"
            "      --validate DATA_EMPS_PULSES.mat\n"
            "  jointid fit --robot examples/robots/kuka_kr300_r2500.toml kuka_A.mat \\\n"
            "      --q-unit deg --map 't=rec.time_cont,q=rec.act_pos_mot_deg' \\\n"
            "      --map 'tau=rec.act_torque_abs_nm,q_ref=rec.ref_pos_deg' --model both \\\n"
            "      --validate kuka_B.mat kuka_C.mat          (n-dof: docs/robot-data.md)\n"
            "  jointid fit kuka_A.mat --q-unit deg --gain 'para.u[2]' \\\n"
            "      --map 't=rec.time_cont,q=rec.act_pos_mot_deg[2]' \\\n"
            "      --map 'tau=rec.act_torque_abs_nm[2]' \\\n"
            "      --validate kuka_B.mat kuka_C.mat\n"
            "\n"
            "paths in --map/--gain (MAT structs, multi-axis arrays; docs/fit-json.md):\n"
            "  NAME[.FIELD...]           a variable or a struct field, e.g. rec.time_cont\n"
            "  NAME[.FIELD...][ROW]      row ROW of a 2-D array (one row per axis), 0-based:\n"
            "                            rec.act_pos_mot_deg[2] is axis 3; on a 1-D array, one\n"
            "                            element: para.u[2]\n"
            "  NAME[.FIELD...][:, COL]   column COL of an N x axes array, 0-based\n"
            "  a name present verbatim in the file (CSV header) is always taken as is;\n"
            "  quote paths in the shell ([ ] are glob characters)"
        ),
    )
    p.add_argument("inputs", nargs="+", type=Path, help="experiment files (.mcap, .csv, .mat)")
    p.add_argument(
        "--robot",
        type=Path,
        metavar="ROBOT",
        help="robot file (.toml MDH table or .urdf): the inputs are multi-axis runs of its "
        "moving joints, identified together (docs/robot-data.md)",
    )
    p.add_argument(
        "--model",
        choices=("usual", "paper", "both", "new"),
        default="both",
        help="model(s) to fit (default both): 'usual' (eq. 38-39), 'paper' (load- and "
        "velocity-dependent dry friction, eq. 42-43); 'new' is a deprecated alias of 'paper'",
    )
    p.add_argument(
        "--method",
        choices=(*METHOD_NAMES, *METHOD_ALIASES),  # METHOD_NAMES: ident.estimators' keys
        help="estimator: least squares, weighted per joint, or instrumental variables on the "
        "reference q_ref (default: wls with --robot; one joint: iv when every input carries "
        "q_ref, else ls, and wls is ls); 'ols' is a deprecated alias of 'ls'",
    )
    p.add_argument(
        "--known-rotor-inertia",
        action="store_true",
        help="--robot only: take the rotor inertias the robot file gives (rotor_inertia) as "
        "known instead of identifying Ia_j",
    )
    p.add_argument(
        "--chain",
        choices=("columns", "states"),
        help="--robot only: 'columns' (default) builds the regressor at full rate and decimates "
        "its columns with the torque, exactly the single-joint chain; 'states' decimates q, dq, "
        "ddq and builds the regressor on them (memory bounded on very long logs)",
    )
    p.add_argument(
        "--no-consistency",
        action="store_true",
        help="--robot only: skip the search for physically consistent standard parameters "
        "(the slow part of the consistency report; the sign checks are kept)",
    )
    p.add_argument(
        "--sigma-blocks",
        type=int,
        metavar="N",
        help="--robot only: units of the jackknife behind the honest standard deviations "
        "(experiments, or contiguous blocks of them; default 10) and the IDIM-IV check; 0: "
        "the robust eq. 15 alone (faster)",
    )
    p.add_argument(
        "--no-prune",
        action="store_true",
        help="--robot only: keep the paper model's friction parameters whose relative std "
        "exceeds 30 %% (flagged unidentified) instead of pruning them and refitting",
    )
    p.add_argument(
        "--full-rate",
        action="store_true",
        help="--robot only, columns chain: the paper model's quadrant and Stribeck products "
        "formed at full rate, then low-passed and decimated like the torque (less bias of a "
        "drag or Stribeck term near reversals; slower; docs/robot-identification.md)",
    )
    p.add_argument(
        "--quadrants",
        metavar="{hard,soft}",
        help="--robot only: the paper model's quadrant weights: hard (default, eq. 27-28) or "
        "soft (their expectation under a load jitter sigma per joint, fitted with the "
        "parameters; analytic std only, no pruning; not with --refine, --consistent or "
        "export-model; docs/robot-identification.md)",
    )
    p.add_argument(
        "--consistent",
        action="store_true",
        help="--robot only: also compute the physically consistent estimate of every model "
        "(LMI fit, docs/model-export.md) and store it in the JSON for `jointid export-model` "
        "(not with --quadrants soft)",
    )
    p.add_argument(
        "--payload",
        choices=("known", "ratio", "mass"),
        help="--robot only: the logged payload's torque is known, or scaled by an identified "
        "ratio M_ae/M_aw (eq. 35), or only its mass is known and its first moments and "
        "inertia are identified (needs runs without payload); default ratio for single-joint "
        "logs (payload lever arm), else known",
    )
    p.add_argument(
        "--joint",
        choices=("revolute", "prismatic"),
        help="joint kind (default: MCAP metadata; revolute for CSV/MAT)",
    )
    p.add_argument(
        "--q-s",
        "--qs",  # the older spelling, still accepted
        metavar="VALUE|scan|scan-joints",
        help="q_s of the paper model [rad/s], or 'scan' to minimise the residual (default "
        f"{DEFAULT_Q_S:g}; refused with --model usual, which has no q_s); with --robot "
        "'scan' chooses one q_s shared by every joint, 'scan-joints' one q_s per joint "
        "(coordinate sweeps; several times the fits of 'scan'); on one joint 'scan-joints' "
        "is 'scan'",
    )
    p.add_argument(
        "--validate",
        nargs="+",
        type=Path,
        metavar="FILE",
        default=[],
        help="files not used for the fit: cross-validation error per model",
    )
    p.add_argument("--report", type=Path, metavar="DIR", help="write tables and PNG plots here")
    p.add_argument("--json", type=Path, metavar="FILE", help="write the JSON record here")
    g = p.add_argument_group("foreign data (CSV/MAT)")
    g.add_argument(
        "--map",
        action="append",
        metavar="KEY=PATH[,...]",
        help="column/variable names or paths (see below): t=, q=, tau=, q_ref= (reference "
        "position: IDIM-IV), payload_kg=, payload_arm_m= (payload entries may be numbers)",
    )
    g.add_argument(
        "--gain",
        metavar="NUMBER|PATH[*...]",
        help="drive gain: tau = gain x column; a number, a scalar variable/path "
        "(para.u[2]) or a product of them (para.u[2]*1.5)",
    )
    g.add_argument(
        "--q-unit",
        choices=("rad", "deg", "m", "mm"),
        help="unit of q and q_ref in CSV/MAT files, converted to rad or m (default: already "
        "rad/m); deg/rad imply a revolute joint, m/mm a prismatic one",
    )
    g.add_argument("--axis", type=int, default=0, help="axis of a multi-axis MCAP log")
    g2 = p.add_argument_group("preprocessing and estimation")
    g2.add_argument("--cutoff", type=float, metavar="HZ", help="low-pass cut-off on q [Hz]")
    g2.add_argument("--decimation", type=int, metavar="R", help="decimation factor")
    g2.add_argument(
        "--dq-min",
        type=float,
        metavar="V",
        help="stiction area: drop |dq| below V [rad/s] (default 1 %% of max; 0 keeps all)",
    )
    g2.add_argument("--tau-min", type=float, metavar="T", help="drop |tau| below T [N m]")
    g2.add_argument("--trim", type=int, metavar="N", help="samples cut at both ends of each file")
    g2.add_argument(
        "--torque-delay",
        metavar="SAMPLES|auto",
        help="instant of the torque samples after the position samples, in samples of the "
        "log's period, in [0, 1): 0.5 for a command held over the cycle after its sample, "
        "0.125 for that hold of a 1 kHz drive logged at 250 Hz (default 'auto': 0.5 when "
        "every input is a jointid MCAP log, else 0)",
    )
    g2.add_argument(
        "--threshold",
        type=float,
        metavar="PCT",
        help="eliminate parameters with relative deviation above PCT %% (default 30)",
    )
    g2.add_argument("--no-eliminate", action="store_true", help="keep every identifiable parameter")
    g2.add_argument(
        "--no-sign-check",
        action="store_true",
        help="keep the samples where sign(tau) differs from the sign of tau_out estimated by "
        "a first usual fit (dropped by default when the paper model is fitted: eq. 26 fails there)",
    )
    g3 = p.add_argument_group("refinement")
    g3.add_argument(
        "--refine",
        action="store_true",
        help="add the effects the residual points to (ident.refine), on the paper model "
        "(or the only model fitted); with --robot: every joint on the refined model's rows, "
        "then the found terms refitted in the n-dof model (not with --quadrants soft)",
    )
    g3.add_argument("--max-steps", type=int, default=None, metavar="N",
                    help="refinement steps (default 5; with --refine only)")
    p.set_defaults(func=run)


def check_qs_model(args: argparse.Namespace) -> None:
    """``--q-s`` is the paper model's (eq. 29): given with ``--model usual``, which has no
    q_s-dependent term, it would be ignored; refused in one line instead, by ``jointid fit``
    and ``jointid fit --robot`` alike (``args.model`` already resolved).

    Raises
    ------
    DataError
        ``--q-s`` (or ``--qs``) given and ``--model usual``.
    """
    if args.q_s is not None and args.model == "usual":
        raise DataError(f"--q-s {args.q_s}: q_s is the paper model's Stribeck velocity (eq. 29) "
                        "and --model usual has none; drop --q-s or fit --model paper or both")


def parse_qs(value: str | None) -> float | str:
    """``--q-s`` of ``jointid fit``, with or without ``--robot``: a finite velocity > 0
    [rad/s or m/s] or one of :data:`ident.vocab.QS_WORDS` ('scan', 'scan-joints'), one line
    naming the flag otherwise (:func:`ident.vocab.qs_value`); not given: ``DEFAULT_Q_S``."""
    if value is None:
        return DEFAULT_Q_S
    return qs_value(value, what="--q-s")


def estimator_from_args(args: argparse.Namespace) -> JointModel:
    """The :class:`~ident.api.JointModel` ``jointid fit`` runs for these arguments."""
    from .api import JointModel

    return JointModel(
        model=args.model,
        q_s=parse_qs(args.q_s),
        joint=args.joint,
        cutoff=args.cutoff,
        decimation=args.decimation,
        dq_min=args.dq_min,
        tau_min=args.tau_min,
        trim=args.trim,
        sign_check=not args.no_sign_check,
        eliminate=not args.no_eliminate,
        threshold=args.threshold,
        estimator="auto" if args.method is None else args.method,
        torque_delay=args.torque_delay,
    )


#: Options of ``jointid fit --robot`` refused without it: (attribute, flag, hint).
_ROBOT_ONLY = (
    ("known_rotor_inertia", "--known-rotor-inertia", " (one joint: J includes the rotor)"),
    ("chain", "--chain", ""),
    ("payload", "--payload", ""),
    ("no_consistency", "--no-consistency", ""),
    ("consistent", "--consistent", ""),
    ("sigma_blocks", "--sigma-blocks", ""),
    ("no_prune", "--no-prune", ""),
    ("quadrants", "--quadrants", ""),
    ("full_rate", "--full-rate", ""),
)


#: Numeric options of ``jointid fit``: (attribute, flag, lowest accepted, whether it may equal
#: it, what is expected). None (not given) always passes.
_NUMBERS = (
    ("cutoff", "--cutoff", 0.0, False, "a cut-off frequency > 0 [Hz]"),
    ("decimation", "--decimation", 1, True, "a decimation factor >= 1"),
    ("dq_min", "--dq-min", 0.0, True, "a velocity >= 0 [rad/s or m/s]"),
    ("tau_min", "--tau-min", 0.0, True, "a torque >= 0 [N m or N]"),
    ("trim", "--trim", 0, True, "a number of samples >= 0"),
    ("threshold", "--threshold", 0.0, False, "a percentage > 0"),
    ("max_steps", "--max-steps", 0, True, "a number of steps >= 0"),
    ("sigma_blocks", "--sigma-blocks", 0, True, "a number of jackknife units >= 0"),
    ("axis", "--axis", 0, True, "an axis index >= 0"),
)


def check_numbers(args: argparse.Namespace) -> None:
    """Refuse non-finite or out-of-range numeric options in one line naming the flag.

    Raises
    ------
    DataError
        E.g. ``--cutoff 0``, ``--cutoff nan``, ``--decimation 0``, ``--dq-min -1``.
    """
    for attr, flag, low, inclusive, expected in _NUMBERS:
        v = getattr(args, attr, None)
        if v is None:
            continue
        ok = math.isfinite(v) and (v >= low if inclusive else v > low)
        if not ok:
            raise DataError(f"{flag} {v:g}: expected {expected}")


#: refinement steps at most when ``--refine`` is given without ``--max-steps``
DEFAULT_MAX_STEPS = 5


def check_refine_steps(args: argparse.Namespace) -> None:
    """``--max-steps`` without ``--refine`` would be ignored in silence: refused in one line;
    not given, it is :data:`DEFAULT_MAX_STEPS` (set on ``args``).

    Raises
    ------
    DataError
        ``--max-steps N`` given without ``--refine``.
    """
    if getattr(args, "max_steps", None) is None:
        args.max_steps = DEFAULT_MAX_STEPS
    elif not getattr(args, "refine", False):
        raise DataError(f"--max-steps {args.max_steps}: expected with --refine (the steps of "
                        f"the refinement, which runs only with --refine); add --refine or "
                        f"drop --max-steps")


def check_output(flag: str, path: Path | None, directory: bool) -> None:
    """Refuse an output path that cannot be written, before anything is fitted: the
    directory ``--report`` (or ``export-model -o``) names (created if absent) or the file
    ``--json`` names (its folder created if absent).

    Raises
    ------
    DataError
        One line naming the flag, the path and what is in the way.
    """
    if path is None:
        return
    try:
        _check_writable(flag, path, directory)
    except OSError as e:  # a folder on the way that cannot be read (no x permission)
        raise DataError(f"{flag} {path}: {e.strerror or e}"
                        + (f" ({e.filename})" if e.filename else "")) from None


def _check_writable(flag: str, path: Path, directory: bool) -> None:
    """:func:`check_output` of a given path (OSError where its folders cannot be read)."""
    if path.exists() and path.is_dir() != directory:
        what = "a file" if directory else "a directory"
        raise DataError(f"{flag} {path}: is {what}, expected "
                        f"{'a directory' if directory else 'a file name'}")
    folder = path if directory else path.parent
    anc = folder
    while not anc.exists() and anc != anc.parent:
        anc = anc.parent
    if anc.exists() and not anc.is_dir():
        raise DataError(f"{flag} {path}: {anc} is a file, not a directory")
    if not os.access(anc, os.W_OK | os.X_OK):
        raise DataError(f"{flag} {path}: {anc} is not writable")
    for name in REPORT_FILES if flag == "--report" and path.is_dir() else ():
        if (path / name).is_dir():
            raise DataError(f"{flag} {path}: {path / name} is a folder, expected a file "
                            "name (the report writes it)")


#: the files ``--report DIR`` always writes (besides the figures)
REPORT_FILES = ("tables.txt", "fit.json", "report.html")


def check_outputs(args: argparse.Namespace) -> None:
    """:func:`check_output` of ``--report`` (a directory) and ``--json`` (a file)."""
    check_output("--report", getattr(args, "report", None), True)
    check_output("--json", getattr(args, "json", None), False)
    js = getattr(args, "json", None)
    rep = getattr(args, "report", None)
    if js is not None and rep is not None and js.absolute() == rep.absolute():
        raise DataError(f"--json {js}: is the --report folder; expected a file name (the "
                        f"report holds the record as {rep / 'fit.json'})")
    if js is not None and js.is_file():  # `--json run.csv`: the record would replace the data
        for f in [*getattr(args, "inputs", []), *(getattr(args, "validate", None) or [])]:
            if Path(f).is_file() and os.path.samefile(js, f):
                raise DataError(f"--json {js}: is the input file {f}; expected a new file "
                                f"name (the JSON record would replace the data)")


def check_inputs_distinct(args: argparse.Namespace) -> None:
    """Refuse a file given twice among the inputs and ``--validate`` (``runs/*.mcap
    runs/a.mcap``): as an input twice it would count its samples twice in the fit, as an
    input and a validation file it would be cross-validated on the data it was fitted on.

    Raises
    ------
    DataError
        One line naming the file and its two places.
    """
    seen: list[tuple[Path, str]] = []
    for where, files in (("the inputs", getattr(args, "inputs", [])),
                         ("the --validate files", getattr(args, "validate", None) or [])):
        for f in map(Path, files):
            if not f.is_file():
                continue  # the loader names it
            for g, gwhere in seen:
                if os.path.samefile(f, g):
                    same = "" if str(f) == str(g) else f" (also as {g})"
                    places = (f"twice among {where}" if where == gwhere
                              else f"among {gwhere} and {where}")
                    raise DataError(f"{f}: given {places}{same}; expected each file once "
                                    "(fitted twice, or validated on the data it was fitted on)")
            seen.append((f, where))


def check_foreign_options(args: argparse.Namespace) -> None:
    """Refuse ``--map`` and ``--gain`` when every file (inputs and ``--validate``) is a
    jointid MCAP log: they apply to CSV and MAT files only, and were ignored in silence (an
    MCAP log has its own channels and joint-side torque [N m] or force [N]).

    Raises
    ------
    DataError
        One line naming the flags and the logs.
    """
    files = [str(f) for f in [*args.inputs, *(getattr(args, "validate", None) or [])]]
    if not files or not all(f.lower().endswith(".mcap") for f in files):
        return
    used = [flag for flag, v in (("--map", getattr(args, "map", None)),
                                 ("--gain", getattr(args, "gain", None))) if v]
    if used:
        logs = files[0] + (f" and {len(files) - 1} more" if len(files) > 1 else "")
        raise DataError(f"{' and '.join(used)}: apply to CSV and MAT files only; {logs}: "
                        "jointid MCAP log(s), with their own channels and joint-side torque")


def _axis_label(inputs: Sequence[Path | str], mapping: Mapping[str, Any], axis: int
                ) -> str | None:
    """The axis the single-joint fit reads from multi-axis files, for its notes: the mapped
    position's path when it picks a row or column (``"axis rec.act_pos_mot_deg[3]"``), or
    ``"axis N"`` (``--axis N``) for MCAP logs of more than one drive (their ``drive<i>``
    metadata; a log without it counts as several); None otherwise (a one-axis file)."""
    from daq.protocol.reader import LogReadError, read_metadata

    q = mapping.get("q")
    if isinstance(q, str) and "[" in q:
        return f"axis {q}"
    for p in inputs:
        if not str(p).lower().endswith(".mcap"):
            continue
        try:
            drives = sum(1 for k in read_metadata(p) if re.fullmatch(r"drive\d+", k))
        except (LogReadError, OSError):  # the loader has read it already; say the axis
            drives = 0
        if drives != 1:
            return f"axis {axis}"
    return None


def run(args: argparse.Namespace) -> int:
    """Execute ``jointid fit``; returns the exit code."""
    from . import cli_robot
    from .api import load
    from .chain import check_torque_delay
    from .loaders import parse_mapping
    from .plots import write_plots
    from .refine_plots import plot_refinement
    from .report import staged_folder, write_json, write_text_atomic
    from .report_build import build_report

    check_numbers(args)
    check_refine_steps(args)
    args.torque_delay = check_torque_delay(getattr(args, "torque_delay", None),
                                           "--torque-delay")
    check_outputs(args)
    check_inputs_distinct(args)
    check_foreign_options(args)
    # the one vocabulary (ident.vocab): "new" is a deprecated "paper", "ols" a deprecated "ls"
    args.model = model_name(args.model, extra=("both",))
    if args.method is not None:
        args.method = method_name(args.method, what="--method")
    check_qs_model(args)  # one rule for both paths, before any file is read
    if args.robot is not None:
        return cli_robot.run(args)
    for attr, flag, hint in _ROBOT_ONLY:
        if getattr(args, attr, None) not in (None, False):
            raise DataError(f"{flag}: applies to --robot fits only{hint}")
    parse_qs(args.q_s)  # refused before the files are read
    mapping = parse_mapping(args.map)
    gain: float | str | None = args.gain
    load_kw: dict[str, Any] = dict(
        mapping=mapping, gain=gain, joint=args.joint, axis=args.axis, q_unit=args.q_unit
    )
    with warnings_held():  # a refusal is its one line, without the warnings before it
        exps = load(args.inputs, **load_kw)
        val = load(args.validate, **load_kw) if args.validate else None
        est = estimator_from_args(args).fit(exps, validation=val,
                                            axis=_axis_label(args.inputs, mapping, args.axis))
    report = est.report_
    out = report.to_json()
    text = report.format_tables()
    print(text)
    ref = None
    if args.refine:
        refined = est.refine(
            max_steps=args.max_steps, progress=lambda msg: print(msg, file=sys.stderr)
        )
        ref = refined.refinement_
        print("\n" + ref.format_report())
        if ref.refit is not None:  # the found terms refitted inside the joint's robot model
            print("\n" + "\n".join(cli_robot.format_refit(ref.refit, refined.name_)))
        out["refinement"] = refined.refinement_json()
    if args.report is not None:
        # written whole or not at all: a temporary folder, moved in at the end
        with staged_folder(args.report) as tmp:
            (tmp / "tables.txt").write_text(text + "\n")
            files = write_plots(report, tmp)
            if ref is not None:
                files += plot_refinement(ref, tmp)
            out["figures"] = [str(args.report / f.name) for f in files]
            write_json(tmp / "fit.json", out)
            build_report(tmp, title="jointid fit report")
        print(f"\nreport: {args.report / 'report.html'} ({len(files)} figures, tables.txt, "
              "fit.json)")
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        write_text_atomic(args.json, json.dumps(out, indent=2) + "\n")
        print(f"json: {args.json}")
    return 0
