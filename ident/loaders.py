"""Loading measured experiments: MCAP logs of ``jointid run``, CSV and MATLAB files.

This is the only module of :mod:`ident` that reads files. Each input file is one experiment
(one payload run); :func:`concat` stacks them into one :class:`~ident.signals.Signals`
(paper eq. 36-37), with derivatives left to :func:`ident.preprocess.build_design`.

Column mapping
--------------
The canonical variables are ``t`` [s], ``q`` [rad or m], ``tau`` [N m or N] and the optional
``payload_kg`` (M_aw [kg]) and ``payload_arm_m`` (L_a [m]). CSV files need a header row;
MATLAB ``.mat`` files (v5/v7, not v7.3) hold named variables. A mapping renames them::

    mapping = {"q": "qm", "tau": "vir"}      # canonical -> name in the file
    gain = "gtau"                            # tau = gain * column; a number or a variable name

Payload entries of the mapping may also be numbers (a constant for the whole file).
Irregular sampling is resampled onto a uniform grid (linear interpolation) with a
:class:`ResamplingWarning`.
"""

from __future__ import annotations

import csv
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import DataError
from .signals import Signals

__all__ = [
    "Experiment",
    "ResamplingWarning",
    "load_experiments",
    "load_experiment",
    "concat",
    "parse_mapping",
    "MIN_SAMPLES",
]

#: Fewest samples accepted in one experiment.
MIN_SAMPLES = 50
#: Relative spread of the sampling period above which a file is resampled.
IRREGULAR_TOL = 0.01

CANONICAL = ("t", "q", "tau", "payload_kg", "payload_arm_m")


class ResamplingWarning(UserWarning):
    """An experiment was irregularly sampled and has been resampled to a uniform grid."""


@dataclass(frozen=True)
class Experiment:
    """One experiment (input file), uniformly sampled.

    Attributes
    ----------
    source : str
        File it came from (or a label).
    t : ndarray, shape (n,)
        Time from the start of the run [s], uniform step ``dt``.
    q : ndarray, shape (n,)
        Joint position [rad or m].
    tau : ndarray, shape (n,)
        Motor torque from the current reference [N m or N] (eq. 7).
    payload_mass : float
        Weighed additional mass M_aw [kg].
    payload_arm : float
        Lever arm L_a [m].
    revolute : bool
        Joint kind.
    q_ref : ndarray, shape (n,), or None
        Reference (planned) position the controller tracked [rad or m], when the data carry it
        (MCAP logs of ``jointid run``; CSV/MAT column ``q_ref``). With it the fit uses
        instrumental variables (IDIM-IV), which removes the closed-loop noise bias of OLS.
    """

    source: str
    t: np.ndarray
    q: np.ndarray
    tau: np.ndarray
    payload_mass: float = 0.0
    payload_arm: float = 0.0
    revolute: bool = True
    q_ref: np.ndarray | None = None

    @property
    def dt(self) -> float:
        """Sampling period [s]."""
        return float((self.t[-1] - self.t[0]) / (len(self.t) - 1))

    def __len__(self) -> int:
        return int(self.t.shape[0])


def parse_mapping(items: Sequence[str] | str | None) -> dict[str, str | float]:
    """Parse ``"q=qm,tau=vir"`` or ``["q=qm", "tau=vir"]`` into a mapping.

    Values that parse as numbers become floats (payload constants).
    """
    if not items:
        return {}
    if isinstance(items, str):
        items = [items]
    out: dict[str, str | float] = {}
    for item in items:
        for part in item.split(","):
            part = part.strip()
            if not part:
                continue
            if "=" not in part:
                raise DataError(f"mapping entry {part!r}: expected KEY=NAME (e.g. q=qm)")
            k, v = (x.strip() for x in part.split("=", 1))
            if k not in CANONICAL:
                raise DataError(f"mapping key {k!r}: expected one of {', '.join(CANONICAL)}")
            try:
                out[k] = float(v)
            except ValueError:
                out[k] = v
    return out


def _joint_flag(joint: str | bool | None) -> bool | None:
    if joint is None or isinstance(joint, bool):
        return joint
    j = str(joint).lower()
    if j in ("revolute", "rotary", "r"):
        return True
    if j in ("prismatic", "linear", "p"):
        return False
    raise DataError(f"joint kind {joint!r}: expected 'revolute' or 'prismatic'")


def _read_csv(path: Path) -> dict[str, np.ndarray]:
    with path.open(newline="") as f:
        sample = f.read(4096)
        f.seek(0)
        try:
            dialect = csv.Sniffer().sniff(sample, delimiters=",;\t ")
            delim = dialect.delimiter
        except csv.Error:
            delim = ","
        header = next(csv.reader(f, delimiter=delim), None)
    if not header:
        raise DataError(f"{path}: empty CSV file, expected a header row (t,q,tau,...)")
    header = [h.strip() for h in header]
    try:
        float(header[0])
        raise DataError(f"{path}: first row is numeric, expected a header row (t,q,tau,...)")
    except ValueError:
        pass
    try:
        data = np.loadtxt(path, delimiter=delim, skiprows=1, ndmin=2, dtype=float)
    except ValueError as exc:
        raise DataError(f"{path}: unreadable numeric data ({exc})") from None
    if data.shape[1] != len(header):
        raise DataError(f"{path}: {data.shape[1]} columns of data for {len(header)} header names")
    return {h: data[:, i] for i, h in enumerate(header)}


def _read_mat(path: Path) -> dict[str, np.ndarray]:
    import scipy.io

    try:
        raw = scipy.io.loadmat(path, squeeze_me=False)
    except NotImplementedError:
        raise DataError(
            f"{path}: MATLAB v7.3 (HDF5) files are not supported; save with -v7"
        ) from None
    except (ValueError, OSError) as exc:
        raise DataError(f"{path}: not a readable MAT file ({exc})") from None
    out = {}
    for k, v in raw.items():
        if k.startswith("__") or not isinstance(v, np.ndarray) or v.dtype.kind not in "fiub":
            continue
        out[k] = np.asarray(v, dtype=float).ravel()
    return out


def _pick(
    table: Mapping[str, np.ndarray], key: str, mapping: Mapping[str, str | float], path: Path
) -> np.ndarray | float | None:
    name = mapping.get(key, key)
    if isinstance(name, float):
        return name
    if name in table:
        return table[name]
    if key in ("payload_kg", "payload_arm_m", "q_ref") and key not in mapping:
        return None
    avail = ", ".join(sorted(table)) or "none"
    raise DataError(f"{path}: missing column/variable {name!r} for {key!r} (found: {avail}; "
                    f"map one with --map {key}=NAME)")


def _gain_variable(table: Mapping[str, np.ndarray], gain: str, path: Path) -> float:
    if gain not in table:
        raise DataError(f"{path}: gain variable {gain!r} not found")
    gv = np.unique(table[gain])
    if gv.size != 1:
        raise DataError(f"{path}: gain variable {gain!r} is not a scalar or constant column")
    return float(gv[0])


def _from_table(
    table: Mapping[str, np.ndarray],
    path: Path,
    mapping: Mapping[str, str | float],
    gain: float | str | None,
    revolute: bool | None,
) -> Experiment:
    t = _pick(table, "t", mapping, path)
    q = _pick(table, "q", mapping, path)
    tau = _pick(table, "tau", mapping, path)
    if isinstance(t, float) or isinstance(q, float) or isinstance(tau, float):
        raise DataError(f"{path}: t, q and tau must be columns, not constants")
    g = 1.0
    if gain is not None:
        if isinstance(gain, str):
            try:
                g = float(gain)
            except ValueError:
                g = _gain_variable(table, gain, path)
        else:
            g = float(gain)
    consts = {}
    for key in ("payload_kg", "payload_arm_m"):
        v = _pick(table, key, mapping, path)
        if v is None:
            consts[key] = 0.0
        elif isinstance(v, float):
            consts[key] = v
        else:
            v = np.asarray(v, dtype=float)
            if v.size == 0 or not np.all(v == v.flat[0]):
                raise DataError(f"{path}: {key} must be constant within one file (one experiment)")
            consts[key] = float(v.flat[0])
    q_ref = _pick(table, "q_ref", mapping, path)
    if isinstance(q_ref, float):
        raise DataError(f"{path}: q_ref must be a column, not a constant")
    return make_experiment(
        str(path),
        t,
        q,
        g * np.asarray(tau, dtype=float),
        payload_mass=consts["payload_kg"],
        payload_arm=consts["payload_arm_m"],
        revolute=True if revolute is None else revolute,
        q_ref=q_ref,
    )


def make_experiment(
    source: str,
    t: np.ndarray,
    q: np.ndarray,
    tau: np.ndarray,
    *,
    payload_mass: float = 0.0,
    payload_arm: float = 0.0,
    revolute: bool = True,
    q_ref: np.ndarray | None = None,
) -> Experiment:
    """Validate arrays and build an :class:`Experiment` (resampling if irregular).

    Raises
    ------
    DataError
        Different lengths, NaN/inf, non-increasing time, fewer than :data:`MIN_SAMPLES`.
    """
    t = np.asarray(t, dtype=float).ravel()
    q = np.asarray(q, dtype=float).ravel()
    tau = np.asarray(tau, dtype=float).ravel()
    if not (t.shape == q.shape == tau.shape):
        raise DataError(
            f"{source}: t, q, tau have different lengths ({t.size}, {q.size}, {tau.size})"
        )
    if q_ref is not None:
        q_ref = np.asarray(q_ref, dtype=float).ravel()
        if q_ref.shape != t.shape:
            raise DataError(f"{source}: q_ref has {q_ref.size} samples, t has {t.size}")
    if t.size < MIN_SAMPLES:
        raise DataError(f"{source}: {t.size} samples, need at least {MIN_SAMPLES}")
    for name, a in (("t", t), ("q", q), ("tau", tau), ("q_ref", q_ref)):
        if a is None:
            continue
        bad = ~np.isfinite(a)
        if bad.any():
            raise DataError(
                f"{source}: {name} has {int(bad.sum())} NaN/inf values "
                f"(first at sample {int(np.argmax(bad))})"
            )
    d = np.diff(t)
    if np.any(d <= 0):
        k = int(np.argmax(d <= 0))
        raise DataError(
            f"{source}: time is not strictly increasing at sample {k + 1} (t={t[k + 1]})"
        )
    med = float(np.median(d))
    if np.max(np.abs(d - med)) > IRREGULAR_TOL * med:
        n = int(round((t[-1] - t[0]) / med)) + 1
        tu = t[0] + med * np.arange(n)
        tu = tu[tu <= t[-1] + 1e-12 * abs(t[-1])]
        warnings.warn(
            f"{source}: irregular sampling (period {d.min():.3g}..{d.max():.3g} s), "
            f"resampled to {tu.size} samples at {med:.6g} s",
            ResamplingWarning,
            stacklevel=3,
        )
        q = np.interp(tu, t, q)
        tau = np.interp(tu, t, tau)
        if q_ref is not None:
            q_ref = np.interp(tu, t, q_ref)
        t = tu
    return Experiment(
        source=source,
        t=t - t[0],
        q=q,
        tau=tau,
        payload_mass=float(payload_mass),
        payload_arm=float(payload_arm),
        revolute=bool(revolute),
        q_ref=q_ref,
    )


def _finite_or_zero(x: float | None) -> float:
    """Payload metadata: absent (None/NaN) means no payload."""
    try:
        v = float(x)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return 0.0
    return v if np.isfinite(v) else 0.0


def _longest_true_run(mask: np.ndarray) -> slice:
    """Slice of the longest contiguous stretch of True in a boolean array (empty if none)."""
    m = np.concatenate(([False], np.asarray(mask, dtype=bool), [False]))
    edges = np.flatnonzero(np.diff(m.astype(np.int8)))
    if edges.size == 0:
        return slice(0, 0)
    starts, stops = edges[0::2], edges[1::2]
    k = int(np.argmax(stops - starts))
    return slice(int(starts[k]), int(stops[k]))


def _load_mcap(path: Path, revolute: bool | None, axis: int) -> Experiment:
    """One MCAP run, restricted to the cycles an identification can use: the drive in
    OPERATION ENABLED with its TPDOs received (:attr:`daq.reader.RunArrays.valid`); during
    enable, quick stop and shutdown the drive ignores the torque reference."""
    try:
        from daq.reader import read_run
    except ImportError:
        raise DataError(f"{path}: MCAP support needs daq.reader, which is not installed") from None
    run = read_run(path, axis=axis)
    keep = _longest_true_run(run.valid)
    inner_dropped = int(np.count_nonzero(run.valid)) - (keep.stop - keep.start)
    if inner_dropped > 0:
        warnings.warn(f"{path}: kept the longest stretch of cycles with the drive enabled "
                      f"({keep.stop - keep.start} cycles); {inner_dropped} other enabled cycles "
                      "are separated from it by a stop or missing TPDOs", stacklevel=2)
    if keep.stop - keep.start == 0:
        raise DataError(f"{path}: no cycle with the drive in OPERATION ENABLED")
    run = run.select(np.arange(keep.start, keep.stop))
    rev = bool(run.revolute) if revolute is None else revolute
    return make_experiment(
        str(path),
        run.t,
        run.q,
        run.tau_ref,
        payload_mass=_finite_or_zero(run.payload_mass_kg),
        payload_arm=_finite_or_zero(run.payload_arm_m),
        revolute=rev,
        # logs without a /setpoint channel carry NaN: no reference, plain least squares
        q_ref=run.q_ref if np.all(np.isfinite(run.q_ref)) else None,
    )


def load_experiment(
    path: str | Path,
    *,
    mapping: Mapping[str, str | float] | None = None,
    gain: float | str | None = None,
    joint: str | bool | None = None,
    axis: int = 0,
) -> Experiment:
    """Load one file (``.mcap``, ``.csv``, ``.mat``) as an :class:`Experiment`.

    Parameters
    ----------
    path : str or Path
        Input file.
    mapping : mapping or None
        Canonical name -> column/variable name (or a number for payload entries).
    gain : float, str or None
        Drive gain applied to the ``tau`` column (a number, or a scalar variable of a MAT
        file / a constant CSV column); ``None`` = 1. Ignored for MCAP (already N m).
    joint : {"revolute", "prismatic"} or bool or None
        Joint kind; ``None``: from the MCAP metadata, revolute for CSV/MAT.
    axis : int
        Axis of a multi-axis MCAP log.
    """
    p = Path(path)
    if not p.exists():
        raise DataError(f"{p}: no such file")
    rev = _joint_flag(joint)
    ext = p.suffix.lower()
    mapping = dict(mapping or {})
    if ext == ".mcap":
        return _load_mcap(p, rev, axis)
    if ext == ".csv" or ext == ".txt":
        return _from_table(_read_csv(p), p, mapping, gain, rev)
    if ext == ".mat":
        return _from_table(_read_mat(p), p, mapping, gain, rev)
    raise DataError(f"{p}: unknown file type {ext!r}, expected .mcap, .csv or .mat")


def load_experiments(
    paths: Sequence[str | Path] | str | Path,
    *,
    mapping: Mapping[str, str | float] | None = None,
    gain: float | str | None = None,
    joint: str | bool | None = None,
    axis: int = 0,
) -> list[Experiment]:
    """Load every file as one experiment (see :func:`load_experiment`).

    Raises
    ------
    DataError
        No file given, a bad file, or files mixing revolute and prismatic joints.
    """
    if isinstance(paths, str | Path):
        paths = [paths]
    if not paths:
        raise DataError("no input file given")
    exps = [load_experiment(p, mapping=mapping, gain=gain, joint=joint, axis=axis) for p in paths]
    kinds = {e.revolute for e in exps}
    if len(kinds) > 1:
        raise DataError("input files mix revolute and prismatic joints; pass --joint")
    return exps


def concat(experiments: Sequence[Experiment]) -> Signals:
    """Stack experiments into one :class:`Signals` (eq. 36-37).

    ``dq`` and ``ddq`` are left at zero: :func:`ident.preprocess.build_design` computes them
    per experiment from the filtered position. ``experiment`` holds each sample's index.
    """
    if not experiments:
        raise DataError("no experiment to concatenate")
    kinds = {e.revolute for e in experiments}
    if len(kinds) > 1:
        raise DataError("experiments mix revolute and prismatic joints")
    dts = np.array([e.dt for e in experiments])
    if np.max(np.abs(dts - dts[0])) > IRREGULAR_TOL * dts[0]:
        raise DataError(
            "experiments have different sampling periods "
            f"({', '.join(f'{e.source}: {e.dt:.6g} s' for e in experiments)})"
        )
    n = [len(e) for e in experiments]
    q = np.concatenate([e.q for e in experiments])
    return Signals(
        t=np.concatenate([e.t for e in experiments]),
        q=q,
        dq=np.zeros_like(q),
        ddq=np.zeros_like(q),
        tau=np.concatenate([e.tau for e in experiments]),
        payload_mass=np.repeat([e.payload_mass for e in experiments], n).astype(float),
        payload_arm=np.repeat([e.payload_arm for e in experiments], n).astype(float),
        experiment=np.repeat(np.arange(len(experiments)), n),
        revolute=experiments[0].revolute,
    )
