"""Loading multi-axis experiments: MCAP logs, CSV and MATLAB files -> :class:`RobotSignals`.

(Past 600 lines: the one module of ident.robot that reads files, by format -- MCAP, CSV,
MAT -- and the states chain, the one chain (ident.chain) without columns.)

Each input file is one experiment (one payload run) of the k moving joints of a robot. The
axes of the file must match the moving joints of the robot file, in number and -- where the
file names its axes -- by name; otherwise a one-line :class:`~ident.robot.RobotIdentError`
names the file and the element.

Formats
-------
MCAP (``jointid run`` logs)
    One ``/joint/<i>/state`` channel per drive; axis i is moving joint i. The torque is
    ``tau_ref``, already joint-side [N m] (the drive chain of the log's ``drive<i>``
    metadata), so no drive gain is applied. A ``drive<i>`` record with a ``joint`` key names
    the axis (checked against the robot). Only the cycles where *every* drive was in
    OPERATION ENABLED are kept (longest common stretch). The ``/setpoint`` channel carries
    one reference, used as ``q_ref`` only for a one-axis log. Payload: metadata ``payload``
    ``mass_kg`` and optional ``com_m`` (JSON list, flange frame); a single-joint log's
    ``arm_m`` (lever arm, eq. 34-35) when there is no ``com_m`` (placed on a one-joint robot,
    refused on several).
CSV (header row)
    ``t, q1..qk, tau1..tauk`` (numbered in the robot's moving order) or named by joint
    ``q_<joint>, tau_<joint>``; optional ``q_ref*`` (IV instruments), ``dq*`` and ``ddq*``
    (taken as given -- already filtered -- when both are present for every axis) and the
    constant payload columns ``payload_mass_kg``, ``payload_com_x_m``, ``payload_com_y_m``,
    ``payload_com_z_m`` (flange frame) and ``payload_ixx_kgm2``, ``payload_ixy_kgm2``, ...
    ``payload_izz_kgm2`` (about the CoM, flange axes). The torque column times the joint's
    ``drive_gain`` is the joint-side torque.
MAT (v5/v7, and v7.3 through h5py)
    The ``--map`` paths of :func:`ident.loaders.resolve_path` with one array per signal,
    one row (or column) per axis: ``t=rec.time_cont, q=rec.act_pos_mot_deg,
    tau=rec.act_torque_abs_nm, q_ref=rec.ref_pos_deg``; or per-axis keys ``q1=...``.
    ``q_unit="deg"`` converts q and q_ref, the drive gains convert the torque (motor-side
    torque x gear ratio for the KUKA recordings). ``payload_kg=`` (a number or a path to a
    scalar) gives the file's payload mass (no CoM: ``--payload mass`` identifies the rest).

Preprocessing (the "states" chain)
----------------------------------
:func:`preprocess_runs` runs the one chain, :func:`ident.chain.run_chain` (the chain of
:func:`ident.preprocess.build_design` and :mod:`ident.robot.design`), with no column
builder: per experiment and per axis the zero-phase Butterworth low-pass of q (cut-off chosen
from the motion bandwidth by :func:`~ident.chain.choose_cutoff`, the largest over the axes),
central differences for dq and ddq, edge trimming, then decimation of the torque and the
states (MATLAB ``decimate``); the estimator builds the rigid-body regressor afterwards from
the decimated, already band-limited states, chunk by chunk (memory bounded on any log
length). Its own settings: the decimation r = floor(0.4 f_s / cut-off) by default (the
decimated states keep the motion's band, since the nonlinear columns are built after the
decimation; the columns chain uses round(f_s / cut-off)), no torque delay, and derivatives
given by the file taken as they are. The columns chain -- the regressor columns built at full
rate and decimated in parallel with the torque, the torque delay, the IV cut-off floor, the
guard -- is :mod:`ident.robot.design` (``jointid fit --robot``'s default).
"""

from __future__ import annotations

import json
import re
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from daq.protocol.reader import LogReadError, read_run

from .. import DataError
from ..chain import ChainSettings, RawExperiment, resolve_settings, run_chain
from ..loaders import (
    GAP_PERIODS,
    IRREGULAR_TOL,
    MAX_ABS_SIGNAL,
    MIN_SAMPLES,
    Q_UNITS,
    _longest_true_run,
    _read_csv,
    _read_mat,
    log_torque_delay,
    lost_cycle_breaks,
    resolve_path,
    uniform_grid,
)
from ..timing import align_to_torque
from . import RobotIdentError
from .signals import RobotPayloadData, RobotSignals

__all__ = [
    "RawRobotRun",
    "RobotPreprocessing",
    "check_periods",
    "load_robot_runs",
    "load_robot_signals",
    "chain_period",
    "preprocess_runs",
    "resolved_settings",
    "parse_robot_mapping",
]

_SIGNALS = ("t", "q", "tau", "q_ref", "dq", "ddq", "payload_kg")
_PAYLOAD_COLS = ("payload_mass_kg", "payload_com_x_m", "payload_com_y_m", "payload_com_z_m",
                 *(f"payload_i{a}_kgm2" for a in ("xx", "xy", "xz", "yy", "yz", "zz")))
_KEY_RE = re.compile(r"^(?P<sig>q_ref|ddq|dq|q|tau)(?P<idx>\d+)$")


@dataclass(frozen=True)
class RawRobotRun:
    """One experiment as read from its file (joint-side SI, uniformly sampled).

    Attributes
    ----------
    source : str
        File name.
    t : ndarray, shape (n,)
        Time from the start of the run [s].
    q, tau : ndarray, shape (n, k)
        Positions [rad or m] and joint-side torques [N m or N].
    q_ref : ndarray, shape (n, k), or None
        Reference trajectory, when the file carries it.
    dq, ddq : ndarray, shape (n, k), or None
        Derivatives given by the file (taken as is), else None.
    payload : RobotPayloadData
    """

    source: str
    t: np.ndarray
    q: np.ndarray
    tau: np.ndarray
    q_ref: np.ndarray | None = None
    dq: np.ndarray | None = None
    ddq: np.ndarray | None = None
    payload: RobotPayloadData = RobotPayloadData()

    @property
    def dt(self) -> float:
        """Sampling period [s]."""
        return float((self.t[-1] - self.t[0]) / (len(self.t) - 1))


@dataclass(frozen=True)
class RobotPreprocessing:
    """Settings of the per-axis filtering (see the module docstring).

    Attributes
    ----------
    cutoff_hz : float or None
        Butterworth cut-off on q [Hz]; None: the largest :func:`choose_cutoff` over the axes
        of the first experiment.
    decimation : int or None
        Decimation factor r; None: floor(0.4 f_s / cut-off) (the anti-alias band of the
        decimation, 0.8 (f_s/2)/r, stays at or above the cut-off), at least 1.
    trim : int or None
        Full-rate samples cut at both ends of each experiment; None: ceil(3 f_s / cut-off).
    """

    cutoff_hz: float | None = None
    decimation: int | None = None
    trim: int | None = None


def parse_robot_mapping(items: Sequence[str] | str | None) -> dict[str, str]:
    """Parse ``--map`` entries ``KEY=PATH`` (KEY: t, q, tau, q_ref, dq, ddq or q1, tau3...).

    Commas inside brackets belong to a path and do not separate entries.
    """
    if not items:
        return {}
    if isinstance(items, str):
        items = [items]
    out: dict[str, str] = {}
    for item in items:
        depth, cur, parts = 0, [], []
        for ch in item:
            depth += ch == "["
            depth -= ch == "]"
            if ch == "," and depth == 0:
                parts.append("".join(cur))
                cur = []
            else:
                cur.append(ch)
        parts.append("".join(cur))
        for part in (p.strip() for p in parts):
            if not part:
                continue
            if "=" not in part:
                raise RobotIdentError(f"--map entry {part!r}: expected KEY=PATH (e.g. q=rec.q)")
            k, v = (x.strip() for x in part.split("=", 1))
            if k not in _SIGNALS and not _KEY_RE.match(k):
                raise RobotIdentError(
                    f"--map key {k!r}: expected one of {', '.join(_SIGNALS)} or a per-axis "
                    "key such as q1, tau2, q_ref3"
                )
            out[k] = v
    return out


# -- reading --------------------------------------------------------------------------------


def _check_gains(gains: Sequence[float] | None, k: int) -> np.ndarray:
    g = np.ones(k) if gains is None else np.asarray(gains, dtype=float).reshape(-1)
    if g.shape != (k,):
        raise RobotIdentError(f"drive gains: {g.size} values for {k} moving joints")
    return g


def _names(joints: Sequence[str]) -> str:
    return ", ".join(joints)


def _mcap_axes(path: Path) -> int:
    """Number of drives of a jointid log (``drive<i>`` metadata, else probing channels)."""
    first = read_run(path, axis=0)
    drives = [k for k in first.metadata if re.fullmatch(r"drive\d+", k)]
    if drives:
        return len(drives)
    n = 1
    while True:
        try:
            read_run(path, axis=n)
        except LogReadError:
            return n
        n += 1


def _json_vector(text: str | None, size: int, what: str, source: str) -> np.ndarray:
    if not text:
        return np.zeros(size)
    try:
        v = np.asarray(json.loads(text), dtype=float).reshape(size)
    except (ValueError, TypeError):
        raise RobotIdentError(f"{source}: metadata {what} {text!r}: expected a JSON list of "
                              f"{size} numbers") from None
    return v


def _load_mcap(path: Path, joints: Sequence[str]) -> RawRobotRun:
    k = len(joints)
    n_axes = _mcap_axes(path)
    if n_axes != k:
        raise RobotIdentError(
            f"{path}: the log has {n_axes} axes (/joint/0..{n_axes - 1}/state), the robot "
            f"moves {k} joints ({_names(joints)})"
        )
    runs = [read_run(path, axis=i) for i in range(k)]
    for i, (run, name) in enumerate(zip(runs, joints, strict=True)):
        logged = run.metadata.get(f"drive{i}", {}).get("joint")
        if logged and logged != name:
            raise RobotIdentError(
                f"{path}: metadata drive{i}.joint is {logged!r}, the robot's moving joint {i + 1} "
                f"is {name!r} (moving: {_names(joints)})"
            )
    cycles = runs[0].cycle
    for i, run in enumerate(runs[1:], start=1):
        if run.cycle.shape != cycles.shape or np.any(run.cycle != cycles):
            raise RobotIdentError(f"{path}: /joint/{i}/state does not cover the cycles of "
                                  "/joint/0/state (one state per drive and cycle expected)")
    valid = np.logical_and.reduce([r.valid for r in runs])
    keep = _longest_true_run(valid, lost_cycle_breaks(cycles))
    if keep.stop == keep.start:
        raise RobotIdentError(f"{path}: no cycle with every drive in OPERATION ENABLED")
    if np.count_nonzero(valid) > keep.stop - keep.start:
        warnings.warn(f"{path}: kept the longest stretch of cycles with every drive enabled "
                      f"({keep.stop - keep.start} cycles; a stop, missing TPDOs or lost "
                      "cycles separate the others, never interpolated across)", stacklevel=3)
    runs = [r.select(keep) for r in runs]
    q_ref = None
    if k == 1 and np.all(np.isfinite(runs[0].q_ref)):
        q_ref = runs[0].q_ref[:, None]
    meta = runs[0].metadata.get("payload", {})
    try:
        mass = float(meta.get("mass_kg", "nan"))
    except ValueError:
        raise RobotIdentError(f"{path}: metadata payload.mass_kg {meta.get('mass_kg')!r}: "
                              "expected a number [kg]") from None
    arm = None
    if meta.get("com_m") is None and meta.get("arm_m") is not None and np.isfinite(mass) \
            and mass > 0:
        # a single-joint log: lever arm L_a, placed on a one-joint robot by the estimator
        try:
            arm = float(meta["arm_m"])
        except ValueError:
            raise RobotIdentError(f"{path}: metadata payload.arm_m {meta['arm_m']!r}: "
                                  "expected a number [m]") from None
    payload = RobotPayloadData(
        mass=mass if np.isfinite(mass) else 0.0,
        com=_json_vector(meta.get("com_m"), 3, "payload.com_m", str(path)),
        inertia=_json_vector(meta.get("inertia_kgm2"), 6, "payload.inertia_kgm2", str(path)),
        arm_m=arm,
    )
    try:  # the log's torque timing (docs/log-format.md), completed by the chain's 0.5
        t, q, tau, q_ref = align_to_torque(
            runs[0].t, np.column_stack([r.q for r in runs]),
            np.column_stack([r.tau_ref for r in runs]), q_ref,
            log_torque_delay(runs[0].metadata, path), str(path))
    except DataError as exc:
        raise RobotIdentError(str(exc)) from None
    return _make_run(str(path), t, q, tau, q_ref=q_ref, payload=payload, joints=joints)


def _axis_columns(
    table: Mapping[str, object], joints: Sequence[str], path: Path
) -> dict[str, list[str] | None]:
    """CSV: the column name of each (signal, axis), numbered or named by joint."""
    cols = [str(c) for c in table]
    numbered: dict[str, dict[int, str]] = {}
    for c in cols:
        m = _KEY_RE.match(c)
        if m:
            numbered.setdefault(m["sig"], {})[int(m["idx"])] = c
    named_q = [c[2:] for c in cols if c.startswith("q_") and not c.startswith("q_ref")]
    k = len(joints)
    out: dict[str, list[str] | None] = {}
    if "q" in numbered:
        idx = sorted(numbered["q"])
        if idx != list(range(1, len(idx) + 1)):
            listed = ", ".join(numbered["q"][i] for i in idx)
            raise RobotIdentError(f"{path}: position columns {listed} are not numbered 1..k")
        if len(idx) != k:
            raise RobotIdentError(
                f"{path}: {len(idx)} axes in the file (q1..q{len(idx)}), the robot moves {k} "
                f"joints ({_names(joints)})"
            )
        for sig in ("q", "tau", "q_ref", "dq", "ddq"):
            have = numbered.get(sig, {})
            if not have:
                if sig == "tau":
                    raise RobotIdentError(f"{path}: no torque columns tau1..tau{k} "
                                          f"(columns: {', '.join(cols)})")
                out[sig] = None
                continue
            missing = [f"{sig}{i}" for i in range(1, k + 1) if i not in have]
            extra = [have[i] for i in sorted(have) if i > k]
            if missing or extra:
                what = f"missing {', '.join(missing)}" if missing else f"extra {', '.join(extra)}"
                raise RobotIdentError(f"{path}: column {what} (the robot moves {k} joints: "
                                      f"{_names(joints)})")
            out[sig] = [have[i] for i in range(1, k + 1)]
        return out
    if named_q:
        unknown = [n for n in named_q if n not in joints]
        if unknown:
            raise RobotIdentError(
                f"{path}: column q_{unknown[0]} names no moving joint of the robot "
                f"(moving: {_names(joints)})"
            )
        for sig in ("q", "tau", "q_ref", "dq", "ddq"):
            names = [f"{sig}_{j}" for j in joints]
            present = [n in table for n in names]
            if not any(present) and sig not in ("q", "tau"):
                out[sig] = None
                continue
            if not all(present):
                miss = names[present.index(False)]
                raise RobotIdentError(f"{path}: missing column {miss!r} (the robot moves "
                                      f"{_names(joints)})")
            out[sig] = names
        return out
    raise RobotIdentError(
        f"{path}: no position columns q1..q{k} or q_<joint> (columns: {', '.join(cols)})"
    )


def _load_csv(path: Path, joints: Sequence[str], gains: np.ndarray,
              q_scale: float) -> RawRobotRun:
    from_csv = _read_csv(path)
    table = {str(k): v for k, v in from_csv.items()}
    if "t" not in table:
        raise RobotIdentError(f"{path}: missing column 't' (columns: {', '.join(table)})")
    cols = _axis_columns(table, joints, path)

    def stack(sig: str) -> np.ndarray | None:
        names = cols.get(sig)
        return None if names is None else np.column_stack([table[c] for c in names])

    pay = [float(table[c][0]) if c in table else 0.0 for c in _PAYLOAD_COLS]
    for c in _PAYLOAD_COLS:
        if c in table and np.ptp(table[c]) > 0:
            raise RobotIdentError(f"{path}: column {c!r} varies, expected a constant "
                                  "(one payload per file)")
    dq, ddq = stack("dq"), stack("ddq")
    q_ref = stack("q_ref")
    return _make_run(
        str(path),
        table["t"],
        q_scale * stack("q"),  # type: ignore[operator]
        gains * stack("tau"),  # type: ignore[operator]
        q_ref=None if q_ref is None else q_scale * q_ref,
        dq=None if dq is None or ddq is None else q_scale * dq,
        ddq=None if dq is None or ddq is None else q_scale * ddq,
        payload=RobotPayloadData(mass=pay[0], com=pay[1:4], inertia=pay[4:10]),
        joints=joints,
        columns={sig: names for sig, names in cols.items() if names is not None},
        first_row=2,
    )


def _matrix(table: Mapping[str, object], spec: str, key: str, n: int | None, k: int,
            path: Path, joints: Sequence[str]) -> np.ndarray:
    """A mapped 2-D array as (n, k): rows or columns are axes."""
    try:
        a = resolve_path(table, spec, str(path))
    except ValueError as exc:  # DataError: already one line naming the file and path
        raise RobotIdentError(str(exc)) from None
    if a.ndim == 1 and k == 1:
        a = a[:, None]
    if a.ndim != 2:
        raise RobotIdentError(f"{path}: {spec!r} for {key!r} has shape {a.shape}, expected one "
                              f"row (or column) per axis ({k} x samples)")
    if n is not None and a.shape[1] == n and a.shape[0] != n:
        a = a.T
    elif n is None and a.shape[0] < a.shape[1]:
        a = a.T
    if n is not None and a.shape[0] != n:
        raise RobotIdentError(f"{path}: {spec!r} for {key!r} has shape {a.shape}, expected "
                              f"{n} samples (the length of t)")
    if a.shape[1] != k:
        raise RobotIdentError(
            f"{path}: {spec!r} has {a.shape[1]} axes, the robot moves {k} joints "
            f"({_names(joints)})"
        )
    return np.asarray(a, dtype=float)


def _load_mat(path: Path, joints: Sequence[str], gains: np.ndarray, q_scale: float,
              mapping: Mapping[str, str]) -> RawRobotRun:
    table = _read_mat(path)
    k = len(joints)

    def vector(spec: str, key: str) -> np.ndarray:
        try:
            a = resolve_path(table, spec, str(path))
        except ValueError as exc:
            raise RobotIdentError(str(exc)) from None
        if a.ndim > 1 and sum(s > 1 for s in a.shape) <= 1:
            a = a.ravel()
        if a.ndim != 1:
            raise RobotIdentError(f"{path}: {spec!r} for {key!r} has shape {a.shape}, "
                                  "expected one signal (pick one row with [ROW])")
        return a

    if "t" not in mapping and "t" not in table:
        raise RobotIdentError(f"{path}: no variable 't'; map the time with --map t=PATH "
                              f"(variables: {', '.join(sorted(table))})")
    t = vector(mapping.get("t", "t"), "t")

    def signal(sig: str, required: bool) -> np.ndarray | None:
        per_axis = [f"{sig}{i}" for i in range(1, k + 1)]
        if any(key in mapping for key in per_axis):
            miss = [key for key in per_axis if key not in mapping]
            if miss:
                raise RobotIdentError(f"{path}: --map gives {sig} per axis but not {miss[0]} "
                                      f"(the robot moves {k} joints: {_names(joints)})")
            extra = sorted(key for key in mapping if (m := _KEY_RE.match(key))
                           and m["sig"] == sig and int(m["idx"]) > k)
            if extra:
                raise RobotIdentError(f"{path}: --map {extra[0]}: the robot moves only {k} "
                                      f"joints ({_names(joints)})")
            return np.column_stack([vector(mapping[key], key) for key in per_axis])
        spec = mapping.get(sig)
        if spec is None:
            if sig in table:
                spec = sig
            elif required:
                raise RobotIdentError(
                    f"{path}: no mapping for {sig!r} (map it with --map {sig}=PATH, one row per "
                    f"axis, or {sig}1=PATH,...; variables: {', '.join(sorted(table))})"
                )
            else:
                return None
        return _matrix(table, spec, sig, t.size, k, path, joints)

    q = signal("q", True)
    tau = signal("tau", True)
    q_ref = signal("q_ref", False)
    payload = None
    if "payload_kg" in mapping:  # the payload's mass: a number or a path to a scalar
        spec = mapping["payload_kg"]
        try:
            mass = float(spec)
        except ValueError:
            mass = None
        if mass is None:
            try:
                a = np.asarray(resolve_path(table, spec, str(path)), dtype=float)
            except ValueError as exc:
                raise RobotIdentError(str(exc)) from None
            if a.size != 1:
                raise RobotIdentError(f"{path}: payload_kg {spec!r} has shape {a.shape}, "
                                      "expected one value [kg]")
            mass = float(a.ravel()[0])
        if not (np.isfinite(mass) and mass >= 0):
            raise RobotIdentError(f"{path}: payload_kg {spec!r}: expected a mass >= 0 [kg], "
                                  f"got {mass}")
        payload = RobotPayloadData(mass)
    dq, ddq = signal("dq", False), signal("ddq", False)
    both = dq is not None and ddq is not None
    return _make_run(
        str(path), t, q_scale * q, gains * tau,  # type: ignore[operator]
        q_ref=None if q_ref is None else q_scale * q_ref,
        dq=q_scale * dq if both else None,  # type: ignore[operator]
        ddq=q_scale * ddq if both else None,  # type: ignore[operator]
        joints=joints, payload=payload,
    )


def _make_run(source: str, t: np.ndarray, q: np.ndarray, tau: np.ndarray, *,
              q_ref: np.ndarray | None = None, dq: np.ndarray | None = None,
              ddq: np.ndarray | None = None,
              payload: RobotPayloadData | None = None,
              joints: Sequence[str] = (),
              columns: Mapping[str, Sequence[str]] | None = None,
              first_row: int | None = None) -> RawRobotRun:
    """Validate the arrays of one file (lengths, finite values within
    :data:`~ident.loaders.MAX_ABS_SIGNAL`, increasing time without gaps) and resample an
    irregular grid (:func:`ident.loaders.uniform_grid`, as :func:`ident.loaders.make_experiment`).

    ``joints`` and ``columns`` (signal -> column name of each axis) name the culprit of a bad
    value; ``first_row`` is the file line of sample 0 (CSV: 2, after the header), if any."""
    t = np.asarray(t, dtype=float).reshape(-1)
    arrays = {"q": q, "tau": tau, "q_ref": q_ref, "dq": dq, "ddq": ddq}
    for name, a in arrays.items():
        if a is not None and a.shape[0] != t.size:
            raise RobotIdentError(f"{source}: {name} has {a.shape[0]} samples, t has {t.size}")
    if t.size < MIN_SAMPLES:
        raise RobotIdentError(f"{source}: {t.size} samples, need at least {MIN_SAMPLES}")

    def where(name: str, i: int, j: int | None) -> str:
        if j is None:
            col = f"column {name!r}"
        else:
            names = (columns or {}).get(name)
            col = f"column {names[j]!r}" if names else f"{name} of axis {j + 1}"
            if j < len(joints):
                col += f" (joint {joints[j]!r})"
        row = f"sample {i}" + (f", line {i + first_row}" if first_row is not None else "")
        return f"{col}, {row} (t={t[i]:.6g} s)" if np.isfinite(t[i]) else f"{col}, {row}"

    for name, a in (("t", t), *arrays.items()):
        if a is None:
            continue
        a2 = np.asarray(a, dtype=float).reshape(a.shape[0], -1)
        checks = [(~np.isfinite(a2), "NaN/inf values", "")]
        if name != "t":  # time may be an epoch stamp; the signals are SI
            checks.append((np.abs(a2) > MAX_ABS_SIGNAL, f"values beyond +-{MAX_ABS_SIGNAL:g}",
                           "; expected SI values after --q-unit and the drive gains"))
        for bad, what, hint in checks:
            if bad.any():
                i = int(np.argmax(bad.any(axis=1)))
                j = int(np.argmax(bad[i])) if name != "t" else None
                raise RobotIdentError(f"{source}: {int(bad.sum())} {what}, first at "
                                      f"{where(name, i, j)}: {float(a2[i, j or 0]):.6g}{hint}")
    d = np.diff(t)
    if np.any(d <= 0):
        i = int(np.argmax(d <= 0))
        raise RobotIdentError(f"{source}: time is not strictly increasing at sample {i + 1} "
                              f"(t={t[i + 1]})")
    med = float(np.median(d))
    if np.max(d) > GAP_PERIODS * med:
        i = int(np.argmax(d > GAP_PERIODS * med))
        raise RobotIdentError(
            f"{source}: gap in the recording at t={t[i]:.6g} s (next sample {d[i]:.6g} s later, "
            f"{d[i] / med:.0f} periods of {med:.6g} s): split the file at the gap into separate "
            "experiments")
    t, arrays, _ = uniform_grid(t, arrays, source=source, stacklevel=4)
    return RawRobotRun(source=source, t=t - t[0], payload=payload or RobotPayloadData(),
                       **arrays)  # type: ignore[arg-type]


def load_robot_runs(
    paths: Sequence[str | Path] | str | Path,
    joints: Sequence[str],
    *,
    gains: Sequence[float] | None = None,
    mapping: Mapping[str, str] | None = None,
    q_unit: str | None = None,
) -> list[RawRobotRun]:
    """Read every file as one multi-axis experiment (no filtering yet).

    Parameters
    ----------
    paths : path or sequence of paths
        ``.mcap``, ``.csv`` (``.txt``) or ``.mat`` files.
    joints : sequence of str
        The robot's moving joints, in order (the axes of each file).
    gains : sequence of float, shape (k,), or None
        Joint-side torque per unit of the logged torque of each axis (the robot file's
        ``drive_gain``; CSV and MAT only -- MCAP torques are already joint-side N m).
    mapping : mapping or None
        MAT/CSV ``--map`` entries (:func:`parse_robot_mapping`).
    q_unit : {"rad", "deg", "m", "mm"} or None
        Unit of q and q_ref in CSV/MAT files (converted to SI).

    Raises
    ------
    RobotIdentError
        Missing file, unknown type, axes that do not match ``joints``, bad mapping or values.
    """
    if isinstance(paths, str | Path):
        paths = [paths]
    if not paths:
        raise RobotIdentError("no input file given")
    joints = tuple(joints)
    if not joints:
        raise RobotIdentError("the robot has no moving joint")
    g = _check_gains(gains, len(joints))
    mapping = dict(mapping or {})
    scale = 1.0
    if q_unit is not None:
        if q_unit not in Q_UNITS:
            raise RobotIdentError(f"q unit {q_unit!r}: expected one of {', '.join(Q_UNITS)}")
        scale = Q_UNITS[q_unit][0]
    runs = []
    for p in map(Path, paths):
        if not p.exists():
            raise RobotIdentError(f"{p}: no such file")
        ext = p.suffix.lower()
        try:
            if ext == ".mcap":
                if scale != 1.0:
                    raise RobotIdentError(f"{p}: MCAP logs are SI; --q-unit does not apply")
                runs.append(_load_mcap(p, joints))
            elif ext in (".csv", ".txt"):
                runs.append(_load_csv(p, joints, g, scale))
            elif ext == ".mat":
                runs.append(_load_mat(p, joints, g, scale, mapping))
            else:
                raise RobotIdentError(f"{p}: unknown file type {ext!r}, expected .mcap, .csv "
                                      "or .mat")
        except LogReadError as exc:
            raise RobotIdentError(str(exc)) from None
        except RobotIdentError:
            raise
        except ValueError as exc:  # DataError of the shared readers: one line with the file
            raise RobotIdentError(str(exc)) from None
    return runs


# -- preprocessing --------------------------------------------------------------------------


def check_periods(runs: Sequence[RawRobotRun]) -> float:
    """The common sampling period of ``runs`` [s]; :class:`RobotIdentError` naming the first
    run whose period differs."""
    dt = runs[0].dt
    for r in runs[1:]:
        if abs(r.dt - dt) > IRREGULAR_TOL * dt:
            raise RobotIdentError(
                f"{r.source}: sampling period {r.dt:.6g} s differs from {runs[0].source} "
                f"({dt:.6g} s)"
            )
    return dt


def chain_period(runs: Sequence[RawRobotRun]) -> float:
    """The sampling period [s] the chain uses for every run: the median step of the first
    (as :func:`ident.preprocess.build_design`), after :func:`check_periods`."""
    check_periods(runs)
    return float(np.median(np.diff(runs[0].t)))


def _settings(runs: Sequence[RawRobotRun], pre: RobotPreprocessing) -> ChainSettings:
    """The chain's settings (:func:`ident.chain.resolve_settings`) with the states chain's
    decimation rule: r = floor(0.4 f_s / cut-off) when not given (the decimated states keep
    the motion's band), no torque delay."""
    if not runs:
        raise RobotIdentError("no experiment to preprocess")
    dt = chain_period(runs)
    s = resolve_settings(runs[0].q, dt, cutoff_hz=pre.cutoff_hz, decimation=pre.decimation,
                         trim=pre.trim, torque_delay=0.0, error=RobotIdentError)
    if pre.decimation is None:
        r = max(1, int(0.4 / dt / s.cutoff_hz + 1e-9))  # 1e-9: an exact ratio stays whole
        s = resolve_settings(runs[0].q, dt, cutoff_hz=s.cutoff_hz, decimation=r,
                             trim=pre.trim, torque_delay=0.0, error=RobotIdentError)
    return s


def preprocess_runs(
    runs: Sequence[RawRobotRun],
    joints: Sequence[str],
    preprocessing: RobotPreprocessing | None = None,
) -> RobotSignals:
    """The states chain: :func:`ident.chain.run_chain` with no columns; the states stacked.

    Parameters
    ----------
    runs : sequence of RawRobotRun
        Experiments of the same robot (same sampling period).
    joints : sequence of str
        Names of the k moving joints (column order).
    preprocessing : RobotPreprocessing or None
        Settings; None: all defaults.

    Returns
    -------
    RobotSignals
        ``experiment`` indexes ``runs``; ``payloads`` one per run; ``source`` the file names.
        The chosen cut-off, decimation and trim are returned by :func:`resolved_settings`.

    Raises
    ------
    RobotIdentError
        Different sampling periods, bad settings, an experiment too short for them.
    """
    settings = _settings(runs, preprocessing or RobotPreprocessing())
    has_ref = all(run.q_ref is not None for run in runs)
    exps = [RawExperiment(run.source, run.q, run.tau, run.q_ref if has_ref else None,
                          run.dq, run.ddq) for run in runs]
    blocks, _ = run_chain(exps, chain_period(runs), settings,
                          lambda _, f: ([f.ref.T] if has_ref else [], None),
                          error=RobotIdentError)
    states = [b.states() for b in blocks]

    def cat(i: int) -> np.ndarray:
        return np.ascontiguousarray(np.concatenate([s[i] for s in states]))

    return RobotSignals(
        t=np.concatenate([run.t[b.full.keep][b.index] for run, b in zip(runs, blocks,
                                                                         strict=True)]),
        q=cat(1),
        dq=cat(2),
        ddq=cat(3),
        tau=cat(0),
        joints=tuple(joints),
        experiment=np.concatenate([np.full(b.index.size, i) for i, b in enumerate(blocks)]),
        payloads=tuple(run.payload for run in runs),
        q_ref=(np.ascontiguousarray(np.concatenate([b.columns()[0].T for b in blocks]))
               if has_ref else None),
        source=", ".join(run.source for run in runs),
    )


def resolved_settings(runs: Sequence[RawRobotRun],
                      preprocessing: RobotPreprocessing | None = None) -> dict[str, float]:
    """The cut-off [Hz], decimation and trim :func:`preprocess_runs` uses for ``runs``."""
    s = _settings(runs, preprocessing or RobotPreprocessing())
    return {"cutoff_hz": s.cutoff_hz, "decimation": s.decimation, "trim": s.trim}


def load_robot_signals(
    paths: Sequence[str | Path] | str | Path,
    joints: Sequence[str],
    *,
    gains: Sequence[float] | None = None,
    mapping: Mapping[str, str] | None = None,
    q_unit: str | None = None,
    preprocessing: RobotPreprocessing | None = None,
) -> RobotSignals:
    """:func:`load_robot_runs` then :func:`preprocess_runs` (one call for notebooks)."""
    runs = load_robot_runs(paths, joints, gains=gains, mapping=mapping, q_unit=q_unit)
    return preprocess_runs(runs, joints, preprocessing)
