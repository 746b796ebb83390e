"""Reading measured runs: MCAP logs of ``jointid run``, CSV and MATLAB files, one reader.

(Past 600 lines: the one module of ident that reads files, by design -- one reader of three
formats for one joint and for n, sharing the column mapping, unit conversion, validation,
resampling and one-line error messages.)

This is the only module of :mod:`ident` that reads files. Each input file is one experiment
(one payload run) of the k moving joints of a robot: :func:`read_file` reads it into the one
data contract, :class:`RawRobotRun` (t, q and tau of shape (n, k), q_ref, payload). A joint
is a 1-dof robot: :func:`load_experiment` reads a file as a run of one unnamed joint and
views it as the single-joint :class:`Experiment` (which holds that run, ``Experiment.run``,
and reads its first axis); :func:`concat` stacks experiments into one
:class:`~ident.signals.Signals` (paper eq. 36-37), with derivatives left to
:func:`ident.preprocess.build_design`. The robot's loader (:mod:`ident.robot.loaders`) reads
the same files through :func:`read_file` with the robot's moving joints.

What differs between one joint and n is data: the names (``q``, ``tau``, ``q_ref`` for one
joint, or ``q1..qk`` numbered / ``q_<joint>`` named by joint, and per-axis ``--map`` keys
``q1=PATH``), the payload (a single-joint lever arm ``payload_arm_m`` / log ``arm_m``, or a
CoM in the flange frame), the gains (one expression, or the robot file's drive gains) and
the wording of a missing signal's error.

Column mapping
--------------
The canonical variables are ``t`` [s], ``q`` [rad or m], ``tau`` [N m or N] and the optional
``q_ref`` (IV instruments), ``payload_kg`` (M_aw [kg]) and ``payload_arm_m`` (L_a [m]). CSV
files need a header row; MATLAB ``.mat`` files (v5/v7 through scipy, v7.3 -- HDF5 -- through
h5py, read into the same structure) hold named variables. A mapping renames them::

    mapping = {"q": "qm", "tau": "vir"}      # canonical -> name in the file
    gain = "gtau"                            # tau = gain * column; a number or a variable name

Payload entries of the mapping may also be numbers (a constant for the whole file). The
``--map`` entries of one joint and of a robot (which adds ``dq``, ``ddq`` and the per-axis
keys ``q1``, ``tau3`` ...) are read by one parser, :func:`parse_mapping`.

Foreign MATLAB data keep their signals in structs, several axes in one 2-D array and
positions in degrees. A mapping value is then a *path* (see :func:`resolve_path`)::

    NAME[.FIELD...][ROW]        row ROW (0-based) of a 2-D array, e.g. rec.act_pos_mot_deg[2]
    NAME[.FIELD...][:, COL]     column COL (0-based) of a 2-D array (N x axes layouts)

A name that exists as such in the file (e.g. a CSV header ``q.motor``) is always taken
verbatim. The gain may be a number, a path to a scalar (``para.u[2]``) or a product of them
(``para.u[2]*0.5``). ``q_unit`` converts q and q_ref to SI (degrees to radians, mm to m).
Irregular time stamps are put on a uniform grid by :func:`uniform_grid`, with a
:class:`ResamplingWarning` saying which reading of the stamps it took and why.

MCAP logs
---------
One ``/joint/<i>/state`` channel per drive; the torque is ``tau_ref``, already joint-side
[N m]. Only the longest stretch of consecutive cycles with every read drive in OPERATION
ENABLED is kept (never interpolated across lost cycles), re-paired to the log's torque
timing (:func:`log_torque_delay`, :func:`ident.timing.align_to_torque`).
"""

from __future__ import annotations

import csv
import json
import math
import re
import tomllib
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import h5py
import numpy as np
import scipy.io

from daq.protocol.reader import RunArrays, read_run, read_runs
from trajectories.robot.file_kinds import TOML_FILE_KINDS, toml_file_kind
from trajectories.robot.payload import RobotPayloadData

from . import DataError
from .held_warnings import warnings_held
from .robot import RobotIdentError
from .signals import Signals
from .timebase import GAP_PERIODS, IRREGULAR_TOL, STEP_BAND, ResamplingWarning, uniform_grid
from .timing import align_to_torque

__all__ = [
    "SLOW_PERIOD_S",
    "SlowSamplingWarning",
    "RawRobotRun",
    "read_file",
    "Experiment",
    "make_experiment",
    "ResamplingWarning",
    "load_experiments",
    "load_experiment",
    "concat",
    "parse_mapping",
    "resolve_path",
    "uniform_grid",
    "Q_UNITS",
    "MIN_SAMPLES",
    "GAP_PERIODS",
    "MAX_ABS_SIGNAL",
    "STEP_BAND",
]

#: Fewest samples accepted in one experiment.
MIN_SAMPLES = 50
#: Sanity bound on |q|, |q_ref| [rad or m] and |tau| [N m or N] after unit conversion and gain:
#: no joint signal comes near it; values beyond are a wrong column, unit or gain (or garbage)
#: and would overflow the least-squares sums.
MAX_ABS_SIGNAL = 1e9

#: ``--map`` keys of one joint (``jointid fit``): its signals and payload constants.
CANONICAL = ("t", "q", "tau", "q_ref", "payload_kg", "payload_arm_m")
#: ``--map`` keys of a robot (``jointid fit --robot``): one joint's and the derivatives a file
#: may give (dq, ddq), besides the per-axis keys of :data:`AXIS_KEY_RE` (q1, tau3, ...).
ROBOT_KEYS = ("t", "q", "tau", "q_ref", "dq", "ddq", "payload_kg", "payload_arm_m")

#: Units accepted for q (and q_ref): factor to SI [rad or m] and whether the unit is an angle.
Q_UNITS: dict[str, tuple[float, bool]] = {
    "rad": (1.0, True),
    "deg": (np.pi / 180.0, True),
    "m": (1.0, False),
    "mm": (1e-3, False),
}

_PATH_RE = re.compile(
    r"^\s*(?P<names>[A-Za-z_]\w*(?:\s*\.\s*[A-Za-z_]\w*)*)\s*"
    r"(?:\[\s*(?:(?P<row>\d+)|:\s*,\s*(?P<col>\d+))\s*\])?\s*$"
)
#: A ``--map`` value that starts like a name is a name (``nan``, ``inf``), not a number.
_NAME_START = re.compile(r"^[A-Za-z_]")
#: Most names listed in an error message.
_MAX_LISTED = 40



class SlowSamplingWarning(UserWarning):
    """An experiment's sampling period exceeds :data:`SLOW_PERIOD_S` (e.g. a time column in
    milliseconds read as seconds)."""


#: Sampling period above which a recording is said to be too slow for dynamic
#: identification [s] (20 Hz; the project's data: 250 Hz to 1 kHz).
SLOW_PERIOD_S = 0.05


def parse_mapping(items: Sequence[str] | str | None, *,
                  robot: bool = False) -> dict[str, str | float]:
    """Parse ``--map`` entries ``"q=qm,tau=vir"`` or ``["q=qm", "tau=vir"]`` into a mapping:
    the one parser of a single joint's ``--map`` and a robot's.

    Values that parse as numbers become floats (payload constants; a signal refuses them
    when the file is read); a value that starts like a name (``nan``, ``inf``) stays a name.
    Commas inside brackets belong to a path (``q=rec.pos[:, 2]``) and do not separate entries.

    Parameters
    ----------
    items : str, sequence of str or None
        The ``--map`` arguments (each may hold several comma-separated entries).
    robot : bool
        The keys of a robot (:data:`ROBOT_KEYS` and the per-axis keys ``q1``, ``tau3`` ... of
        :data:`AXIS_KEY_RE`) and its error class; else one joint's (:data:`CANONICAL`).

    Raises
    ------
    DataError or RobotIdentError (``robot``)
        An entry without ``=`` or an unknown key: one line naming it and what was expected.
    """
    error = RobotIdentError if robot else DataError
    keys = ROBOT_KEYS if robot else CANONICAL
    out: dict[str, str | float] = {}
    for part in map_entries(items):
        if "=" not in part:
            raise error(f"--map entry {part!r}: expected KEY=PATH (e.g. q=rec.q)")
        k, v = (x.strip() for x in part.split("=", 1))
        if k not in keys and not (robot and AXIS_KEY_RE.match(k)):
            axis = " or a per-axis key such as q1, tau2, q_ref3" if robot else ""
            raise error(f"--map key {k!r}: expected one of {', '.join(keys)}{axis}")
        try:
            out[k] = v if _NAME_START.match(v) else float(v)
        except ValueError:
            out[k] = v
    return out


def map_entries(items: Sequence[str] | str | None) -> list[str]:
    """The non-empty ``KEY=PATH`` entries of ``--map`` items (one joint's and a robot's):
    split on the commas that are not inside square brackets (``q=rec.pos[:, 2]``)."""
    if not items:
        return []
    if isinstance(items, str):
        items = [items]
    return [p.strip() for item in items for p in _split_top_commas(item) if p.strip()]


def _split_top_commas(text: str) -> list[str]:
    """Split on the commas that are not inside square brackets."""
    parts, depth, cur = [], 0, []
    for ch in text:
        if ch == "[":
            depth += 1
        elif ch == "]":
            depth = max(depth - 1, 0)
        if ch == "," and depth == 0:
            parts.append("".join(cur))
            cur = []
        else:
            cur.append(ch)
    parts.append("".join(cur))
    return parts


def _shape_str(shape: tuple[int, ...]) -> str:
    return " x ".join(str(n) for n in shape) if shape else "scalar"


def _fields(obj: object) -> list[str] | None:
    """Field names of a struct-like object (MAT struct or the file's top level), else None."""
    if isinstance(obj, Mapping):
        return [str(k) for k in obj]
    names = getattr(obj, "_fieldnames", None)
    return list(names) if names is not None else None


def _describe(obj: object) -> str:
    if _fields(obj) is not None:
        return "a struct"
    if isinstance(obj, str):
        return "text"
    a = np.asarray(obj)
    if a.dtype.kind == "O":
        return f"an array {_shape_str(a.shape)} of objects (struct array or cell)"
    if a.dtype.kind in "US":
        return "text"
    return f"an array {_shape_str(a.shape)} ({a.dtype})" if a.ndim else f"a number ({a.dtype})"


def _listing(names: Sequence[str]) -> str:
    names = sorted(names)
    if not names:
        return "none"
    more = len(names) - _MAX_LISTED
    return ", ".join(names[:_MAX_LISTED]) + (f", ... ({more} more)" if more > 0 else "")


def resolve_path(table: Mapping[str, object], spec: str, source: str = "") -> np.ndarray:
    """Resolve a mapping value in a loaded file to a numeric array.

    Parameters
    ----------
    table : mapping
        Top level of the file: CSV column name -> column, or MAT variable name -> value
        (``scipy.io.loadmat(..., squeeze_me=True, struct_as_record=False)``: structs are
        objects whose fields are attributes).
    spec : str
        A name present verbatim in ``table``, or a path ``NAME[.FIELD...]`` followed by an
        optional index: ``[ROW]`` takes row ROW of a 2-D array (one row per axis, e.g.
        ``rec.act_pos_mot_deg[2]`` for axis 3) or element ROW of a 1-D array
        (``para.u[2]``); ``[:, COL]`` takes column COL (N x axes layouts). Indices are
        0-based and non-negative.
    source : str
        File name for the error messages.

    Returns
    -------
    ndarray
        Float array, whatever its dimension (the caller checks it: signals must be 1-D,
        gains and payloads scalar or constant).

    Raises
    ------
    DataError
        Bad syntax, unknown variable or field (listing those available at that level), a
        field taken on something that is not a struct, index out of range (with the
        shape), or a non-numeric value.
    """
    where = f"{source}: " if source else ""
    if spec in table:
        obj: object = table[spec]
        names, row, col = [spec], None, None
    else:
        m = _PATH_RE.match(spec)
        if m is None:
            raise DataError(
                f"{where}{spec!r}: expected a name or a path NAME[.FIELD...], optionally "
                "followed by [ROW] or [:, COL] (0-based)"
            )
        names = [n.strip() for n in m["names"].split(".")]
        row = int(m["row"]) if m["row"] is not None else None
        col = int(m["col"]) if m["col"] is not None else None
        obj = table
        for i, name in enumerate(names):
            here = ".".join(names[:i])
            fields = _fields(obj)
            if fields is None:
                raise DataError(
                    f"{where}{spec!r}: {here!r} is {_describe(obj)}, not a struct "
                    f"(no field {name!r})"
                )
            if name not in fields:
                level = f"no field {name!r} in {here!r}" if here else f"no variable {name!r}"
                what = "fields" if here else "variables"
                raise DataError(f"{where}{spec!r}: {level} ({what}: {_listing(fields)})")
            obj = obj[name] if isinstance(obj, Mapping) else getattr(obj, name)
    label = ".".join(names)
    head = f"{where}{spec!r}" if label == spec else f"{where}{spec!r}: {label!r}"
    if _fields(obj) is not None:
        raise DataError(
            f"{head} is a struct, not numeric data (fields: {_listing(_fields(obj) or [])})"
        )
    a = np.asarray(obj)
    if a.dtype.kind not in "fiub":
        raise DataError(f"{head} is {_describe(obj)}, not numeric")
    if row is not None:
        if a.ndim == 0 or row >= a.shape[0]:
            raise DataError(
                f"{where}{spec!r}: row index {row} out of range for {label!r} of shape "
                f"{_shape_str(a.shape)}" + (f" (rows 0..{a.shape[0] - 1})" if a.ndim else "")
            )
        a = a[row]
    elif col is not None:
        if a.ndim != 2 or col >= a.shape[1]:
            detail = f" (columns 0..{a.shape[1] - 1})" if a.ndim == 2 else " (not 2-D)"
            raise DataError(
                f"{where}{spec!r}: column index {col} out of range for {label!r} of shape "
                f"{_shape_str(a.shape)}{detail}"
            )
        a = a[:, col]
    return np.asarray(a, dtype=float)


def _signal(table: Mapping[str, object], spec: str, key: str, source: str) -> np.ndarray:
    """Resolve ``spec`` to a 1-D signal (a N x 1 or 1 x N array counts as 1-D)."""
    a = resolve_path(table, spec, source)
    if a.ndim > 1 and sum(n > 1 for n in a.shape) <= 1:
        a = a.ravel()
    if a.ndim != 1:
        hint = (
            f"; pick one row with [ROW] or one column with [:, COL] (0-based), e.g. {spec}[0]"
            if a.ndim == 2
            else ""
        )
        raise DataError(
            f"{source}: {spec!r} for {key!r} is {_shape_str(a.shape)}, expected a 1-D signal{hint}"
        )
    return a


def _constant(table: Mapping[str, object], spec: str, what: str, source: str) -> float:
    """Resolve ``spec`` to one number (a scalar, or an array whose values are all equal)."""
    a = resolve_path(table, spec, source)
    if a.size == 0 or not np.all(a == a.flat[0]):
        hint = f" (pick one with an index, e.g. {spec}[0])" if _PATH_RE.match(spec + "[0]") else ""
        if what.startswith("payload"):  # not one value of it: the runs of two payloads
            hint = (" (one payload per run: split the file where the payload changes, one "
                    "file per payload)")
        raise DataError(
            f"{source}: {what} {spec!r} is {_shape_str(a.shape)} values that differ, "
            f"expected a scalar or a constant column{hint}"
        )
    return float(a.flat[0])


def _joint_flag(joint: str | bool | None) -> bool | None:
    if joint is None or isinstance(joint, bool):
        return joint
    j = str(joint).lower()
    if j in ("revolute", "rotary", "r"):
        return True
    if j in ("prismatic", "linear", "p"):
        return False
    raise DataError(f"joint kind {joint!r}: expected 'revolute' or 'prismatic'")


def _read_text(path: Path) -> str:
    """The text of a CSV file: UTF-8, with or without a byte-order mark; other encodings are
    refused in one line (the byte and where it is), never guessed."""
    raw = path.read_bytes()
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        bom = ", a UTF-16 byte-order mark" if raw[:2] in (b"\xff\xfe", b"\xfe\xff") else ""
        raise DataError(
            f"{path}: not UTF-8 text (byte 0x{raw[exc.start]:02x} at offset {exc.start}{bom}); "
            "save the CSV as UTF-8"
        ) from None


def _read_csv(path: Path) -> dict[str, np.ndarray]:
    text = _read_text(path)
    try:
        dialect = csv.Sniffer().sniff(text[:4096], delimiters=",;\t ")
        delim = dialect.delimiter
    except csv.Error:
        delim = ","
    lines = text.splitlines()
    header = next(csv.reader(lines[:1], delimiter=delim), None)
    if not header:
        raise DataError(f"{path}: empty CSV file, expected a header row (t,q,tau,...)")
    header = [h.strip() for h in header]
    try:
        float(header[0])
        raise DataError(f"{path}: first row is numeric, expected a header row (t,q,tau,...)")
    except ValueError:
        pass
    if not any(ln.strip() for ln in lines[1:]):
        raise DataError(
            f"{path}: no data rows after the header ({', '.join(header)}), expected one row "
            "per sample"
        )
    try:
        data = np.loadtxt(lines[1:], delimiter=delim, ndmin=2, dtype=float)
    except ValueError as exc:
        raise DataError(f"{path}: unreadable numeric data ({exc})") from None
    if data.shape[1] != len(header):
        raise DataError(f"{path}: {data.shape[1]} columns of data for {len(header)} header names")
    seen: dict[str, int] = {}
    for i, h in enumerate(header):
        if h and h in seen:  # the later column replaced the earlier one, in silence
            raise DataError(f"{path}: column {h!r} twice in the header (columns "
                            f"{seen[h] + 1} and {i + 1}), expected each name once")
        seen[h] = i
    return {h: data[:, i] for i, h in enumerate(header)}


def _read_mat(path: Path) -> dict[str, object]:
    """Top-level variables of a MAT file; structs stay objects (fields as attributes).

    v5/v7 files through ``scipy.io.loadmat(squeeze_me=True, struct_as_record=False)``;
    v7.3 files (HDF5, which scipy refuses) through h5py into the same structure
    (:func:`_read_mat_v73`)."""
    try:
        raw = scipy.io.loadmat(path, squeeze_me=True, struct_as_record=False)
    except NotImplementedError:  # scipy: "Please use HDF reader for matlab v7.3 files"
        return _read_mat_v73(path)
    except (ValueError, OSError, scipy.io.matlab.MatReadError) as exc:
        # MatReadError (not a ValueError): a file shorter than a MAT header, e.g. empty
        raise DataError(f"{path}: not a readable MAT file ({exc})"
                        + _looks_like(path)) from None
    return {k: v for k, v in raw.items() if not k.startswith("__")}


def _looks_like(path: Path) -> str:
    """What a file that is not a MAT file looks like, from its first bytes, as the tail of
    the refusal ("; it looks like a CSV text file: name it .csv"); "" when unknown."""
    try:
        with open(path, "rb") as f:
            head = f.read(4096)
    except OSError:
        return ""
    if not head:
        return "; the file is empty"
    if head.startswith(b"\x89MCAP"):
        return "; it looks like an MCAP log (jointid run): name it .mcap"
    if head.startswith(b"PK\x03\x04"):
        return "; it looks like a zip archive (an .xlsx workbook?): export it as CSV (.csv)"
    if b"\0" in head:
        return ""
    try:
        text = head.decode("utf-8")
    except UnicodeDecodeError as exc:  # cut inside a character at the 4096th byte
        if exc.start < len(head) - 3:
            return ""
        text = head[:exc.start].decode("utf-8")
    text = text.lstrip("\ufeff \t\r\n")
    if text[:1] in ("{", "["):
        return "; it looks like a JSON text file (a jointid record?), not a data file"
    line = text.split("\n", 1)[0]
    if any(d in line for d in ",;\t "):  # the delimiters _read_csv sniffs
        return "; it looks like a CSV text file: name it .csv"
    return "; it looks like a text file, not a MAT file" if text else ""


class _MatStruct:
    """A MATLAB struct of a v7.3 file, shaped like scipy's ``mat_struct`` (fields as
    attributes, their names in ``_fieldnames``)."""

    def __init__(self, fields: Mapping[str, object]) -> None:
        self._fieldnames = list(fields)
        for k, v in fields.items():
            setattr(self, k, v)


def _squeezed(a: np.ndarray) -> object:
    """``squeeze_me=True`` of scipy: unit dimensions dropped, a single element a scalar."""
    a = np.squeeze(a)
    return a.item() if a.ndim == 0 and a.dtype.kind != "O" else a


def _v73_value(node: h5py.Group | h5py.Dataset, f: h5py.File) -> object:
    """One variable of a v7.3 file as ``loadmat(squeeze_me=True, struct_as_record=False)``
    gives it. MATLAB writes arrays column-major, so HDF5 holds them transposed."""
    cls = node.attrs.get("MATLAB_class", b"")
    cls = cls.decode() if isinstance(cls, bytes) else str(cls)
    if isinstance(node, h5py.Group):  # a struct (1 x 1); object, table... are refused later
        return _MatStruct({k: _v73_value(node[k], f) for k in node})
    if node.attrs.get("MATLAB_empty", 0):
        return np.zeros(0)
    data = node[()]
    if isinstance(data, bytes | str):
        return data.decode() if isinstance(data, bytes) else data
    a = np.asarray(data).T
    if a.dtype == h5py.ref_dtype:  # cell array, or a field of a struct array
        out = np.empty(a.shape, dtype=object)
        for idx, ref in np.ndenumerate(a):
            out[idx] = _v73_value(f[ref], f)
        return _squeezed(out)
    if cls == "char":
        return "".join(chr(c) for c in a.ravel(order="F"))
    if cls == "logical":
        a = a.astype(bool)
    elif a.dtype.names and {"real", "imag"} <= set(a.dtype.names):
        a = a["real"] + 1j * a["imag"]
    return _squeezed(a)


def _read_mat_v73(path: Path) -> dict[str, object]:
    """Top-level variables of a MATLAB v7.3 file (HDF5 after a 512-byte MATLAB header)."""
    try:
        with h5py.File(path, "r") as f:
            return {k: _v73_value(f[k], f) for k in f if not k.startswith("#")}
    except (OSError, KeyError, ValueError, TypeError) as exc:
        raise DataError(f"{path}: not a readable MATLAB v7.3 (HDF5) file ({exc})") from None


# -- the one reader: a file -> RawRobotRun of the k moving joints of a robot ----------------

#: Per-axis keys and CSV columns: ``q1``, ``tau2``, ``q_ref3``, ``dq1``, ``ddq1``.
AXIS_KEY_RE = re.compile(r"^(?P<sig>q_ref|ddq|dq|q|tau)(?P<idx>\d+)$")
#: The robot CSV's constant payload columns: mass, CoM (flange frame), inertia about the CoM.
PAYLOAD_COLUMNS = ("payload_mass_kg", "payload_com_x_m", "payload_com_y_m", "payload_com_z_m",
                   *(f"payload_i{a}_kgm2" for a in ("xx", "xy", "xz", "yy", "yz", "zz")))


@dataclass(frozen=True)
class RawRobotRun:
    """One experiment as read from its file (joint-side SI, uniformly sampled): the one data
    contract of every reader; a single-joint :class:`Experiment` is its view with k = 1.

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
        The file's payload; ``arm_m`` is the lever arm of a single-joint log or column.
    revolute : bool or None
        The joint kind of a one-axis reading of a log (``campaign.joint_kind``, revolute
        when absent); None: the file does not say (CSV, MAT, several axes). The run an
        :class:`Experiment` views holds the kind it resolved (``joint``, the log, ``q_unit``).
    """

    source: str
    t: np.ndarray
    q: np.ndarray
    tau: np.ndarray
    q_ref: np.ndarray | None = None
    dq: np.ndarray | None = None
    ddq: np.ndarray | None = None
    payload: RobotPayloadData = RobotPayloadData()
    revolute: bool | None = None

    @property
    def dt(self) -> float:
        """Sampling period [s]."""
        return float((self.t[-1] - self.t[0]) / (len(self.t) - 1))


@dataclass(frozen=True, init=False)
class Experiment:
    """One experiment (input file) of one joint, uniformly sampled, as the single-joint fit
    takes it: a view of the run of one joint (:class:`RawRobotRun`, k = 1) that holds the
    run and reads its first axis; no array is copied.

    ``Experiment(source, t, q, tau, payload_mass, payload_arm, revolute, q_ref)`` builds the
    run from 1-D arrays (the payload checked as by :func:`make_experiment`, the arrays taken
    as given); :meth:`of_run` views a run already read (:func:`load_experiment`).

    Attributes
    ----------
    run : RawRobotRun
        The run of one joint: arrays of shape (n, 1), its payload, ``revolute`` the joint kind.
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
        Lever arm L_a [m] (0 when the file gives none).
    revolute : bool
        Joint kind.
    q_ref : ndarray, shape (n,), or None
        Reference (planned) position the controller tracked [rad or m], when the data carry it
        (MCAP logs of ``jointid run``; CSV/MAT column ``q_ref``). With it the fit uses
        instrumental variables (IDIM-IV), which removes the closed-loop noise bias of OLS.
    """

    run: RawRobotRun

    def __init__(self, source: str, t: np.ndarray, q: np.ndarray, tau: np.ndarray,
                 payload_mass: float = 0.0, payload_arm: float = 0.0, revolute: bool = True,
                 q_ref: np.ndarray | None = None) -> None:
        def axis(a: np.ndarray | None) -> np.ndarray | None:
            return None if a is None else np.asarray(a)[:, None]

        run = RawRobotRun(source=source, t=t, q=axis(q), tau=axis(tau),  # type: ignore[arg-type]
                          q_ref=axis(q_ref), payload=_payload(source, payload_mass, payload_arm),
                          revolute=bool(revolute))
        object.__setattr__(self, "run", run)

    @classmethod
    def of_run(cls, run: RawRobotRun, revolute: bool | None = None) -> Experiment:
        """The view of a run of one joint (``run.q`` of shape (n, 1)); ``revolute`` (when
        given) is set on the run, else the run's own (revolute when it does not say).

        Raises
        ------
        DataError
            The run has more than one axis.
        """
        if run.q.ndim != 2 or run.q.shape[1] != 1:
            raise DataError(f"{run.source}: {run.q.shape[-1]} axes, an Experiment has one "
                            "(pick one with axis=)")
        rev = run.revolute if revolute is None else revolute
        self = object.__new__(cls)
        object.__setattr__(self, "run", replace(run, revolute=True if rev is None else
                                                bool(rev)))
        return self

    @property
    def source(self) -> str:
        return self.run.source

    @property
    def t(self) -> np.ndarray:
        return self.run.t

    @property
    def q(self) -> np.ndarray:
        return self.run.q[:, 0]

    @property
    def tau(self) -> np.ndarray:
        return self.run.tau[:, 0]

    @property
    def q_ref(self) -> np.ndarray | None:
        return None if self.run.q_ref is None else self.run.q_ref[:, 0]

    @property
    def payload_mass(self) -> float:
        return float(self.run.payload.mass)

    @property
    def payload_arm(self) -> float:
        arm = self.run.payload.arm_m
        return 0.0 if arm is None else float(arm)

    @property
    def revolute(self) -> bool:
        return bool(self.run.revolute)

    @property
    def dt(self) -> float:
        """Sampling period [s]."""
        return self.run.dt

    def __len__(self) -> int:
        return int(self.run.t.shape[0])


def _names(joints: Sequence[str]) -> str:
    return ", ".join(joints)


def _payload(source: str, mass: float, arm: float | None = None,
             com: Sequence[float] | None = None,
             inertia: Sequence[float] | None = None,
             mass_spec: object = None) -> RobotPayloadData:
    """The payload of one file, checked: a mass >= 0 [kg], a finite lever arm [m];
    ``mass_spec``: the ``--map`` text the mass came from, named in the message."""
    if not (np.isfinite(mass) and mass >= 0):
        what = f"{mass_spec!r}" if isinstance(mass_spec, str) else f"{mass!r}"
        got = f", got {mass}" if isinstance(mass_spec, str) else ""
        raise DataError(f"{source}: payload_kg {what}: expected a mass >= 0 [kg]{got}")
    if arm is not None and not np.isfinite(arm):
        raise DataError(f"{source}: payload_arm_m {arm!r}: expected a finite lever arm [m]")
    return RobotPayloadData(mass=float(mass), arm_m=None if arm is None else float(arm),
                            com=np.zeros(3) if com is None else com,
                            inertia=np.zeros(6) if inertia is None else inertia)


def _make_run(source: str, t: np.ndarray, q: np.ndarray, tau: np.ndarray, *,
              q_ref: np.ndarray | None = None, dq: np.ndarray | None = None,
              ddq: np.ndarray | None = None, payload: RobotPayloadData | None = None,
              joints: Sequence[str] | None = None,
              columns: Mapping[str, Sequence[str]] | None = None,
              first_row: int | None = None, revolute: bool | None = None) -> RawRobotRun:
    """Validate the arrays of one file (lengths, finite values within
    :data:`MAX_ABS_SIGNAL`, increasing time without gaps) and resample an irregular grid
    (:func:`uniform_grid`): the one check of every reader and of :func:`make_experiment`.

    ``joints`` (None: one unnamed joint) and ``columns`` (signal -> column name of each axis)
    name the culprit of a bad value; ``first_row`` is the file line of sample 0 (CSV: 2,
    after the header), if any.

    Raises
    ------
    DataError
        Different lengths, NaN/inf, values beyond :data:`MAX_ABS_SIGNAL`, non-increasing
        time, a gap longer than :data:`GAP_PERIODS` median periods, fewer than
        :data:`MIN_SAMPLES` samples.
    """
    t = np.asarray(t, dtype=float).reshape(-1)
    arrays = {"q": q, "tau": tau, "q_ref": q_ref, "dq": dq, "ddq": ddq}
    for name, a in arrays.items():
        if a is not None and a.shape[0] != t.size:
            raise DataError(f"{source}: {name} has {a.shape[0]} samples, t has {t.size}")
    if t.size < MIN_SAMPLES:
        raise DataError(f"{source}: {t.size} samples, need at least {MIN_SAMPLES}")

    def where(name: str, i: int, j: int | None) -> str:
        names = (columns or {}).get(name)
        if names:
            col = f"column {names[j or 0]!r}"
            if joints is None and names[j or 0] != name:  # one joint: the key it was for
                col += f" ({name})"
        elif j is None or joints is None:
            col = f"column {name!r}"
        else:
            col = f"{name} of axis {j + 1}"
        if j is not None and joints is not None and j < len(joints):
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
                           "; expected SI values [rad, m, N m or N] after --q-unit and the "
                           "gains: wrong column, unit or gain?"))
        for bad, what, hint in checks:
            if bad.any():
                i = int(np.argmax(bad.any(axis=1)))
                j = int(np.argmax(bad[i])) if name != "t" else None
                raise DataError(f"{source}: {int(bad.sum())} {what}, first at "
                                f"{where(name, i, j)}: {float(a2[i, j or 0]):.6g}{hint}")
    d = np.diff(t)
    if np.any(d <= 0):
        i = int(np.argmax(d <= 0))
        raise DataError(f"{source}: time is not strictly increasing at sample {i + 1} "
                        f"(t={t[i + 1]})")
    med = float(np.median(d))
    if np.max(d) > GAP_PERIODS * med:
        i = int(np.argmax(d > GAP_PERIODS * med))
        n_gaps = int(np.count_nonzero(d > GAP_PERIODS * med))
        raise DataError(
            f"{source}: gap in the recording at t={t[i]:.6g} s (next sample {d[i]:.6g} s later, "
            f"{d[i] / med:.0f} periods of {med:.6g} s; {n_gaps} gap(s) over {GAP_PERIODS:g} "
            "periods): split the file at the gap into separate experiments")
    if med > SLOW_PERIOD_S:
        # dynamic identification differentiates the positions twice: a few hertz cannot
        # carry it, and a time column in milliseconds read as seconds looks just like this
        warnings.warn(f"{source}: sampling period {med:.6g} s ({1 / med:.3g} Hz) is slow for "
                      "dynamic identification (accelerations from the positions need about "
                      "100 Hz or more); if the time column is in milliseconds, give it in "
                      "seconds", SlowSamplingWarning, stacklevel=5)
    t, arrays, _ = uniform_grid(t, arrays, source=source, stacklevel=5)
    return RawRobotRun(source=source, t=t - t[0], payload=payload or RobotPayloadData(),
                       revolute=revolute, **arrays)  # type: ignore[arg-type]


# -- MCAP logs of ``jointid run`` -------------------------------------------------------------


def _longest_true_run(mask: np.ndarray, breaks: np.ndarray | None = None) -> slice:
    """Slice of the longest contiguous stretch of True in a boolean array (empty if none).

    ``breaks`` (n - 1 booleans): True where sample i + 1 does not follow sample i (cycles
    lost between them, e.g. a damaged log chunk); a stretch never spans a break.
    """
    m = np.asarray(mask, dtype=bool)
    if m.size == 0 or not m.any():
        return slice(0, 0)
    prev = np.concatenate(([False], m[:-1]))
    start = m & ~prev
    if breaks is not None:
        start[1:] |= m[1:] & np.asarray(breaks, dtype=bool)
    starts = np.flatnonzero(start)
    label = np.cumsum(start)  # stretch number of every sample (0 before the first)
    lengths = np.bincount(label[m], minlength=starts.size + 1)[1:]
    k = int(np.argmax(lengths))
    return slice(int(starts[k]), int(starts[k] + lengths[k]))


def lost_cycle_breaks(cycle: np.ndarray) -> np.ndarray:
    """n - 1 booleans: True where the logged cycle numbers jump (cycles lost in between)."""
    return np.diff(np.asarray(cycle, dtype=np.int64)) != 1


def log_torque_delay(metadata: Mapping[str, Mapping[str, str]], path: Path | str) -> float:
    """The log's torque timing ``campaign.torque_delay_cycles`` [cycles] (docs/log-format.md),
    0.5 for logs written before jointid recorded it.

    Raises
    ------
    DataError
        A value that is not a number >= 0 (one line naming the file and the key).
    """
    text = metadata.get("campaign", {}).get("torque_delay_cycles")
    if text is None:
        return 0.5
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not np.isfinite(value) or value < 0:
        raise DataError(f"{path}: metadata campaign.torque_delay_cycles {text!r}: expected a "
                        "number >= 0 [cycles]")
    return value


def _mcap_axes(runs: Sequence[RunArrays]) -> int:
    """Number of drives of a jointid log: its ``drive<i>`` metadata, else the axes read
    (:func:`daq.protocol.reader.read_runs`: channels ``/joint/0..n-1/state``)."""
    drives = [k for k in runs[0].metadata if re.fullmatch(r"drive\d+", k)]
    return len(drives) if drives else len(runs)


def _meta_number(meta: Mapping[str, str], key: str, unit: str, path: Path) -> float:
    try:
        return float(meta.get(key, "nan"))
    except ValueError:
        raise DataError(f"{path}: metadata payload.{key} {meta.get(key)!r}: expected a number "
                        f"{unit}") from None


def _json_vector(text: str | None, size: int, what: str, source: str) -> np.ndarray:
    if not text:
        return np.zeros(size)
    try:
        v = np.asarray(json.loads(text), dtype=float).reshape(size)
    except (ValueError, TypeError):
        raise DataError(f"{source}: metadata {what} {text!r}: expected a JSON list of "
                        f"{size} numbers") from None
    return v


def _warn_unfinished(path: Path, result: Mapping[str, str]) -> None:
    """A warning naming the file when its run did not finish (``result.status`` other than
    ``done``: interrupted, stopped on a fault...): its samples end where the run was cut,
    which may leave a payload's excitation incomplete (a 14 s interrupted log of the quick
    campaign fitted tau_off = -130.8 N m against the plant's 10, in silence). A log without a
    result record (writer killed) is warned about by the reader (``truncated``)."""
    status = str(result.get("status", "")) if result else ""
    if status and status != "done":
        reason = str(result.get("reason", "")).strip()
        warnings.warn(f"{path}: the run did not finish ({status}"
                      + (f": {reason}" if reason else "")
                      + "): its excitation may be incomplete; fit it with care, or rerun "
                      "that payload (jointid run --resume)", stacklevel=4)


def _read_mcap(path: Path, joints: Sequence[str] | None, axis: int | None) -> RawRobotRun:
    """One run log: the axes of ``joints`` (every axis of the log, matched by number and by
    the ``drive<i>.joint`` names), or the one axis ``axis`` (``joints`` None), restricted to
    the cycles an identification can use: every drive read in OPERATION ENABLED with its
    TPDOs received (:attr:`daq.protocol.reader.RunArrays.valid`; during enable, quick stop
    and shutdown a drive ignores the torque reference), the longest stretch of consecutive
    cycles (never interpolated across lost ones), re-paired to the log's torque timing
    (:func:`ident.timing.align_to_torque`)."""
    if axis is not None:
        runs = [read_run(path, axis=axis)]
    else:
        joints = tuple(joints or ())
        k = len(joints)
        # every axis from one scan of the file (each warning of it said once); none of its
        # warnings before a refusal
        with warnings_held():
            runs = read_runs(path)
            n_axes = _mcap_axes(runs)
            if n_axes != k:
                raise DataError(
                    f"{path}: the log has {n_axes} axes (/joint/0..{n_axes - 1}/state), the "
                    f"robot moves {k} joints ({_names(joints)})"
                )
            if len(runs) < k:  # drive metadata for a channel missing: the reader names it
                runs = read_runs(path, range(k))
            runs = runs[:k]
            for i, (run, name) in enumerate(zip(runs, joints, strict=True)):
                logged = run.metadata.get(f"drive{i}", {}).get("joint")
                if logged and logged != name:
                    raise DataError(
                        f"{path}: metadata drive{i}.joint is {logged!r}, the robot's moving "
                        f"joint {i + 1} is {name!r} (moving: {_names(joints)})"
                    )
    _warn_unfinished(path, runs[0].metadata.get("result", {}))
    cycles = runs[0].cycle
    if cycles.size == 0:  # e.g. a log cut within its first chunk: not a drive-state matter
        cut = " (the log is cut short)" if getattr(runs[0], "truncated", False) else ""
        raise DataError(f"{path}: no cycle logged{cut}: expected a run log holding at least "
                        f"one complete chunk of /joint/0/state")
    for i, run in enumerate(runs[1:], start=1):
        if run.cycle.shape != cycles.shape or np.any(run.cycle != cycles):
            raise DataError(f"{path}: /joint/{i}/state does not cover the cycles of "
                            "/joint/0/state (one state per drive and cycle expected)")
    drive = "the drive" if len(runs) == 1 else "every drive"
    valid = np.logical_and.reduce([r.valid for r in runs])
    keep = _longest_true_run(valid, lost_cycle_breaks(cycles))
    if keep.stop == keep.start:
        raise DataError(f"{path}: no cycle with {drive} in OPERATION ENABLED")
    others = int(np.count_nonzero(valid)) - (keep.stop - keep.start)
    if others > 0:
        warnings.warn(
            f"{path}: kept the longest stretch of cycles with {drive} enabled "
            f"({keep.stop - keep.start} cycles); {others} other enabled cycles are separated "
            "from it by a stop, missing TPDOs or lost cycles (never interpolated across)",
            stacklevel=4,
        )
    runs = [r.select(keep) for r in runs]
    # logs without a /setpoint channel carry NaN: no reference, plain least squares; each
    # drive's /joint/<k>/setpoint is its own axis's reference (a robot campaign's too): q_ref
    # when every axis carries one on every kept cycle (IDIM-IV, the honest sigma's IV check)
    q_ref = None
    if all(np.all(np.isfinite(r.q_ref)) for r in runs):
        q_ref = np.column_stack([r.q_ref for r in runs])
    meta = runs[0].metadata.get("payload", {})
    mass = _meta_number(meta, "mass_kg", "[kg]", path)
    arm = None
    if meta.get("com_m") is None and meta.get("arm_m") is not None:
        # a single-joint log's lever arm L_a (eq. 34-35), placed on a one-joint robot
        arm = _meta_number(meta, "arm_m", "[m]", path)
        arm = arm if np.isfinite(arm) else None
    payload = _payload(str(path), mass if np.isfinite(mass) else 0.0, arm,
                       _json_vector(meta.get("com_m"), 3, "payload.com_m", str(path)),
                       _json_vector(meta.get("inertia_kgm2"), 6, "payload.inertia_kgm2",
                                    str(path)))
    t, q, tau, q_ref = align_to_torque(
        runs[0].t, np.column_stack([r.q for r in runs]),
        np.column_stack([r.tau_ref for r in runs]), q_ref,
        log_torque_delay(runs[0].metadata, path), str(path))
    return _make_run(str(path), t, q, tau, q_ref=q_ref, payload=payload, joints=joints,
                     revolute=bool(runs[0].revolute) if len(runs) == 1 else None)


# -- CSV and MAT files: named columns / variables ---------------------------------------------


def _axis_columns(
    table: Mapping[str, object], joints: Sequence[str] | None, path: Path
) -> dict[str, list[str] | None] | None:
    """CSV: the column name of each (signal, axis), numbered ``q1..qk`` or named by joint
    ``q_<joint>``; None when the file has neither (a single joint's ``q``, ``tau``)."""
    cols = [str(c) for c in table]
    numbered: dict[str, dict[int, str]] = {}
    for c in cols:
        m = AXIS_KEY_RE.match(c)
        if m:
            numbered.setdefault(m["sig"], {})[int(m["idx"])] = c
    named_q = ([] if joints is None else
               [c[2:] for c in cols if c.startswith("q_") and not c.startswith("q_ref")])
    k = 1 if joints is None else len(joints)
    names = ("joint",) if joints is None else joints
    out: dict[str, list[str] | None] = {}
    if "q" in numbered:
        idx = sorted(numbered["q"])
        if idx != list(range(1, len(idx) + 1)):
            listed = ", ".join(numbered["q"][i] for i in idx)
            raise DataError(f"{path}: position columns {listed} are not numbered 1..k")
        if len(idx) != k:
            raise DataError(
                f"{path}: {len(idx)} axes in the file (q1..q{len(idx)}), the robot moves {k} "
                f"joints ({_names(names)})"
            )
        for sig in ("q", "tau", "q_ref", "dq", "ddq"):
            have = numbered.get(sig, {})
            if not have:
                if sig == "tau":
                    raise DataError(f"{path}: no torque columns tau1..tau{k} "
                                    f"(columns: {', '.join(cols)})")
                out[sig] = None
                continue
            missing = [f"{sig}{i}" for i in range(1, k + 1) if i not in have]
            extra = [have[i] for i in sorted(have) if i > k]
            if missing or extra:
                what = f"missing {', '.join(missing)}" if missing else f"extra {', '.join(extra)}"
                raise DataError(f"{path}: column {what} (the robot moves {k} joints: "
                                f"{_names(names)})")
            out[sig] = [have[i] for i in range(1, k + 1)]
        return out
    if named_q and joints is not None:
        unknown = [n for n in named_q if n not in joints]
        if unknown:
            raise DataError(
                f"{path}: column q_{unknown[0]} names no moving joint of the robot "
                f"(moving: {_names(joints)})"
            )
        for sig in ("q", "tau", "q_ref", "dq", "ddq"):
            wanted = [f"{sig}_{j}" for j in joints]
            present = [n in table for n in wanted]
            if not any(present) and sig not in ("q", "tau"):
                out[sig] = None
                continue
            if not all(present):
                miss = wanted[present.index(False)]
                raise DataError(f"{path}: missing column {miss!r} (the robot moves "
                                f"{_names(joints)})")
            out[sig] = wanted
        return out
    return None


def _matrix(table: Mapping[str, object], spec: str, key: str, n: int, k: int,
            path: Path, joints: Sequence[str] | None) -> np.ndarray:
    """A mapped signal as (n, k): one 1-D signal for one joint, else a 2-D array whose rows
    or columns are the axes."""
    if k == 1 and joints is None:
        return _signal(table, spec, key, str(path))[:, None]
    names = ("joint",) if joints is None else joints
    a = resolve_path(table, spec, str(path))
    if a.ndim == 1 and k == 1:
        a = a[:, None]
    if a.ndim != 2:
        raise DataError(f"{path}: {spec!r} for {key!r} has shape {a.shape}, expected one "
                        f"row (or column) per axis ({k} x samples)")
    if a.shape[1] == n and a.shape[0] != n:
        a = a.T
    if a.shape[0] != n:
        raise DataError(f"{path}: {spec!r} for {key!r} has shape {a.shape}, expected "
                        f"{n} samples (the length of t)")
    if a.shape[1] != k:
        raise DataError(
            f"{path}: {spec!r} has {a.shape[1]} axes, the robot moves {k} joints "
            f"({_names(names)})"
        )
    return np.asarray(a, dtype=float)


def _missing(table: Mapping[str, object], key: str, path: Path,
             joints: Sequence[str] | None, csv_file: bool, k: int) -> DataError:
    """The one-line error of a required signal found neither mapped nor in the file."""
    listed = [str(c) for c in table]
    if joints is None:  # a single joint: canonical names, --map with paths
        return DataError(
            f"{path}: missing column/variable {key!r} for {key!r} (found: {_listing(listed)}; "
            f"map one with --map {key}=NAME or a path like rec.pos[2])"
        )
    if csv_file:
        if key == "t":
            return DataError(f"{path}: missing column 't' (columns: {', '.join(listed)})")
        if key == "tau":
            return DataError(f"{path}: no torque columns tau1..tau{k} "
                             f"(columns: {', '.join(listed)})")
        return DataError(f"{path}: no position columns q1..q{k} or q_<joint> "
                         f"(columns: {', '.join(listed)})")
    if key == "t":
        return DataError(f"{path}: no variable 't'; map the time with --map t=PATH "
                         f"(variables: {', '.join(sorted(listed))})")
    return DataError(
        f"{path}: no mapping for {key!r} (map it with --map {key}=PATH, one row per "
        f"axis, or {key}1=PATH,...; variables: {', '.join(sorted(listed))})"
    )


def _gain_value(table: Mapping[str, object], gain: float | str, path: Path) -> float:
    """``gain``: a number, a path to a scalar/constant, or a product ``A*B*...`` of them;
    refused (:class:`DataError` naming the file and the gain) unless finite and non-zero:
    a zero gain makes every torque 0 (the fit ran on, dividing by its norm)."""
    g = _gain_product(table, gain, path)
    if not (math.isfinite(g) and g != 0.0):
        raise DataError(f"{path}: gain {gain!r} is {g:g}: expected a finite, non-zero drive "
                        f"gain (tau = gain x column)")
    return g


def _gain_product(table: Mapping[str, object], gain: float | str, path: Path) -> float:
    """:func:`_gain_value` before its check."""
    if not isinstance(gain, str):
        return float(gain)
    g = 1.0
    for factor in gain.split("*"):
        f = factor.strip()
        if not f:
            raise DataError(f"{path}: gain {gain!r}: empty factor, expected NUMBER|NAME[*...]")
        try:
            g *= float(f)
        except ValueError:
            if f not in table and _PATH_RE.match(f) and "." not in f and "[" not in f:
                raise DataError(
                    f"{path}: gain variable {f!r} not found (variables: "
                    f"{_listing([str(k) for k in table])})"
                ) from None
            g *= _constant(table, f, "gain variable", str(path))
    return g


def _table_payload(table: Mapping[str, object], mapping: Mapping[str, str | float],
                   path: Path, one_value: bool) -> RobotPayloadData:
    """The file's payload: ``payload_kg`` / ``payload_arm_m`` mapped (a number or a path to a
    scalar or constant; ``one_value``: a scalar, the robot MAT rule) or same-named; the robot
    CSV's constant ``payload_mass_kg``, ``payload_com_*_m``, ``payload_i*_kgm2`` columns."""

    def constant(key: str) -> float | None:
        spec = mapping.get(key)
        if isinstance(spec, str):
            try:
                spec = float(spec)
            except ValueError:
                pass
        if isinstance(spec, float):
            return spec
        if spec is None:
            if key not in table:
                return None
            spec = key
        if one_value:
            a = resolve_path(table, spec, str(path))
            if a.size != 1:
                unit = "[kg]" if key == "payload_kg" else "[m]"
                raise DataError(f"{path}: {key} {spec!r} has shape {a.shape}, expected one "
                                f"value {unit}")
            return float(a.ravel()[0])
        return _constant(table, spec, key, str(path))

    mass, arm = constant("payload_kg"), constant("payload_arm_m")
    cols = [float(np.asarray(table[c]).flat[0]) if c in table else 0.0 for c in PAYLOAD_COLUMNS]
    for c in PAYLOAD_COLUMNS:
        if c in table and np.ptp(np.asarray(table[c], dtype=float)) > 0:
            raise DataError(f"{path}: column {c!r} varies, expected a constant "
                            "(one payload per file)")
    if mass is None:
        mass = cols[0]
    return _payload(str(path), mass, arm, cols[1:4], cols[4:10], mapping.get("payload_kg"))


def _read_table(path: Path, table: Mapping[str, object], joints: Sequence[str] | None,
                gains: Sequence[float | str] | None, q_scale: float,
                mapping: Mapping[str, str | float], csv_file: bool) -> RawRobotRun:
    """A CSV or MAT file: per signal (t, q, tau, q_ref, dq, ddq) the per-axis mapping keys
    (``q1=PATH``...), the mapped path (one row or column per axis), the numbered or named
    CSV columns (``q1``, ``q_<joint>``), else the same-named column or variable."""
    k = 1 if joints is None else len(joints)
    for key, spec in mapping.items():  # signals and per-axis keys: paths, never numbers
        if isinstance(spec, float) and (key in ("t", "q", "tau", "q_ref", "dq", "ddq")
                                        or AXIS_KEY_RE.match(key)):
            raise DataError(f"{path}: {key} must be a column/variable, not a constant")
    spec_t = mapping.get("t", "t")
    if "t" not in mapping and "t" not in table:
        raise _missing(table, "t", path, joints, csv_file, k)
    t = _signal(table, str(spec_t), "t", str(path))
    names = ("joint",) if joints is None else joints
    columns: dict[str, list[str]] = {}
    discovered = None  # the numbered / named CSV columns (a single joint's when q is absent)
    if csv_file and (joints is not None or ("q" not in mapping and "q" not in table)):
        try:
            discovered = _axis_columns(table, joints, path)
        except DataError:
            if joints is not None:
                raise
            raise _missing(table, "q", path, joints, csv_file, k) from None

    def signal(sig: str, required: bool) -> np.ndarray | None:
        per_axis = [f"{sig}{i}" for i in range(1, k + 1)]
        if any(key in mapping for key in per_axis):
            miss = [key for key in per_axis if key not in mapping]
            if miss:
                raise DataError(f"{path}: --map gives {sig} per axis but not {miss[0]} "
                                f"(the robot moves {k} joints: {_names(names)})")
            extra = sorted(key for key in mapping if (m := AXIS_KEY_RE.match(key))
                           and m["sig"] == sig and int(m["idx"]) > k)
            if extra:
                raise DataError(f"{path}: --map {extra[0]}: the robot moves only {k} "
                                f"joints ({_names(names)})")
            columns[sig] = [str(mapping[key]) for key in per_axis]
            return np.column_stack([_signal(table, str(mapping[key]), key, str(path))
                                    for key in per_axis])
        spec = mapping.get(sig)
        if spec is None and discovered is not None:
            cols = discovered[sig]
            if cols is None:
                return None
            columns[sig] = cols
            return np.column_stack([np.asarray(table[c], dtype=float) for c in cols])
        if spec is None:
            if sig not in table:
                if required:
                    raise _missing(table, sig, path, joints, csv_file, k)
                return None
            spec = sig
        if k == 1:
            columns[sig] = [str(spec)]
        return _matrix(table, str(spec), sig, t.size, k, path, joints)

    q = signal("q", True)
    tau = signal("tau", True)
    q_ref = signal("q_ref", False)
    g = np.ones(k) if gains is None else np.array([_gain_value(table, x, path) for x in gains])
    dq = ddq = None
    if joints is not None:  # derivatives given by the file (a robot's states chain)
        dq, ddq = signal("dq", False), signal("ddq", False)
        if dq is None or ddq is None:
            dq = ddq = None
    return _make_run(
        str(path), t, q_scale * q, g * tau,  # type: ignore[operator]
        q_ref=None if q_ref is None else q_scale * q_ref,
        dq=None if dq is None else q_scale * dq,
        ddq=None if ddq is None else q_scale * ddq,
        payload=_table_payload(table, mapping, path, joints is not None and not csv_file),
        joints=joints, columns=columns, first_row=2 if csv_file else None,
    )


def read_file(
    path: str | Path,
    joints: Sequence[str] | None,
    *,
    gains: Sequence[float | str] | None = None,
    mapping: Mapping[str, str | float] | None = None,
    q_unit: str | None = None,
    axis: int | None = None,
) -> RawRobotRun:
    """Read one file (``.mcap``, ``.csv``/``.txt``, ``.mat``) as a run of the moving joints
    ``joints`` of a robot: the one reader of :mod:`ident` (single joint and robot alike).

    Parameters
    ----------
    path : str or Path
        Input file.
    joints : sequence of str or None
        The robot's moving joints, in order (the axes of the file); None: one unnamed joint
        (:func:`load_experiment`: canonical names ``q``, ``tau``..., axis ``axis`` of a log).
    gains : sequence of float or str, shape (k,), or None
        Joint-side torque per unit of the file's torque, per axis: a number or a path to a
        scalar of the file, or a product of them (``para.u[2]*0.5``); CSV and MAT only.
    mapping : mapping or None
        Signal or per-axis key (``t, q, tau, q_ref, dq, ddq, payload_kg, payload_arm_m``,
        ``q1``, ``tau2``...) -> path (:func:`resolve_path`); payload entries may be numbers.
    q_unit : {"rad", "deg", "m", "mm"} or None
        Unit of q, q_ref (and dq, ddq) of a CSV/MAT file; MCAP logs are SI.
    axis : int or None
        With ``joints`` None: the axis of an MCAP log to read.

    Raises
    ------
    DataError
        Missing file, unknown type, axes that do not match ``joints``, bad mapping or values
        (one line naming the file and the key, column or path).
    daq.protocol.reader.LogReadError
        An unreadable log.
    """
    p = Path(path)
    if not p.exists():
        raise DataError(f"{p}: no such file")
    if p.is_dir():  # `jointid fit logs/` for `jointid fit logs/*.mcap`
        raise DataError(f"{p}: a folder, expected a file (.mcap, .csv or .mat); give its "
                        f"files, e.g. {p / '*.mcap'}")
    scale = 1.0 if q_unit is None else Q_UNITS[str(q_unit).strip().lower()][0]
    ext = p.suffix.lower()
    if ext == ".mcap":
        if scale != 1.0:
            raise DataError(f"{p}: MCAP logs are in SI units; q unit {q_unit!r} does not apply")
        return _read_mcap(p, joints, (axis or 0) if joints is None else None)
    mapping = dict(mapping or {})
    if ext in (".csv", ".txt"):
        table: Mapping[str, object] = {str(k): v for k, v in _read_csv(p).items()}
        return _read_table(p, table, joints, gains, scale, mapping, True)
    if ext == ".mat":
        return _read_table(p, _read_mat(p), joints, gains, scale, mapping, False)
    raise DataError(f"{p}: unknown file type {ext!r}, expected .mcap, .csv or .mat"
                    + _other_kind_hint(p, ext))


def _other_kind_hint(p: Path, ext: str) -> str:
    """The tail of the unknown-file-type line when ``p`` is one of jointid's other files (a
    robot, campaign or plant file; :func:`trajectories.robot.file_kinds.toml_file_kind`):
    where it goes instead; "" otherwise."""
    if ext == ".urdf":
        return "; it looks like a robot file (URDF): jointid fit takes it as --robot"
    if ext != ".toml":
        return ""
    try:
        kind = toml_file_kind(tomllib.loads(p.read_text(encoding="utf-8")))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return ""
    if kind is None:
        return ""
    looks, where = TOML_FILE_KINDS[kind]
    return f"; it looks like {looks}: {where}"


# -- the single joint: a view of the run of a one-joint robot ---------------------------------


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
    columns: Mapping[str, str] | None = None,
) -> Experiment:
    """Validate arrays and build an :class:`Experiment` (resampling if irregular): the
    checks of every reader (:func:`_make_run`) on one joint.

    Parameters
    ----------
    columns : mapping or None
        Column/variable each signal (``t``, ``q``, ``tau``, ``q_ref``) came from, named in
        the error messages; default the signal's own name.

    Raises
    ------
    DataError
        Different lengths, NaN/inf, values beyond :data:`MAX_ABS_SIGNAL`, non-increasing
        time, a gap longer than :data:`GAP_PERIODS` median periods, fewer than
        :data:`MIN_SAMPLES`, a payload mass < 0 or a lever arm that is not finite.
    """

    def axis(a: np.ndarray | None) -> np.ndarray | None:
        return None if a is None else np.asarray(a, dtype=float).reshape(-1)[:, None]

    run = _make_run(source, t, axis(q), axis(tau), q_ref=axis(q_ref),  # type: ignore[arg-type]
                    payload=_payload(source, payload_mass, payload_arm),
                    columns={k: [v] for k, v in (columns or {}).items()})
    return Experiment.of_run(run, revolute)


def _q_unit(q_unit: str | None, rev: bool | None, source: str) -> tuple[float, bool | None]:
    """Scale factor to SI for ``q_unit`` and the joint kind it implies (checked against
    an explicit ``rev``)."""
    if q_unit is None:
        return 1.0, rev
    unit = str(q_unit).strip().lower()
    if unit not in Q_UNITS:
        raise DataError(f"{source}: q unit {q_unit!r}: expected one of {', '.join(Q_UNITS)}")
    scale, angle = Q_UNITS[unit]
    if rev is not None and rev != angle:
        kind = "revolute" if rev else "prismatic"
        raise DataError(
            f"{source}: q unit {unit!r} is {'an angle' if angle else 'a length'} "
            f"but the joint is {kind}"
        )
    return scale, angle


def load_experiment(
    path: str | Path,
    *,
    mapping: Mapping[str, str | float] | None = None,
    gain: float | str | None = None,
    joint: str | bool | None = None,
    axis: int = 0,
    q_unit: str | None = None,
) -> Experiment:
    """Load one file (``.mcap``, ``.csv``, ``.mat``) as an :class:`Experiment`: the file read
    as a run of one unnamed joint (:func:`read_file`), viewed with k = 1.

    Parameters
    ----------
    path : str or Path
        Input file.
    mapping : mapping or None
        Canonical name (``t``, ``q``, ``tau``, ``q_ref``, ``payload_kg``, ``payload_arm_m``)
        -> column/variable name or path (:func:`resolve_path`: ``rec.act_pos_mot_deg[2]``,
        ``data[:, 1]``), or a number for payload entries. Unmapped, a CSV file's ``q``,
        ``tau``, ``q_ref`` columns are taken, else its numbered ``q1``, ``tau1``, ``q_ref1``.
    gain : float, str or None
        Drive gain applied to the ``tau`` signal: a number, a scalar (or constant) variable
        or path (``para.u[2]``), or a product of them (``para.u[2]*0.5``); ``None`` = 1.
        Ignored for MCAP (already N m).
    joint : {"revolute", "prismatic"} or bool or None
        Joint kind; ``None``: from the MCAP metadata; for CSV/MAT from ``q_unit`` when given,
        else revolute.
    axis : int
        Axis of a multi-axis MCAP log.
    q_unit : {"rad", "deg", "m", "mm"} or None
        Unit of the q (and q_ref) signals of a CSV/MAT file, converted to [rad] or [m];
        ``None``: already SI. MCAP logs are SI: only ``None``, ``"rad"`` or ``"m"``.

    Raises
    ------
    DataError
        Missing or unreadable file, unknown type, bad mapping or path, unit contradicting
        the joint kind, invalid signals (see :func:`make_experiment`).
    """
    p = Path(path)
    if not p.exists():
        raise DataError(f"{p}: no such file")
    rev = _joint_flag(joint)
    _, rev_u = _q_unit(q_unit, rev, str(p))
    run = read_file(p, None, gains=None if gain is None else [gain], mapping=mapping,
                    q_unit=q_unit, axis=axis)
    if rev is not None and run.revolute is not None and rev != run.revolute:
        kinds = {True: "revolute", False: "prismatic"}
        raise DataError(f"{p}: the file says its joint is {kinds[bool(run.revolute)]}, the "
                        f"joint kind given (--joint) is {kinds[rev]}")
    if rev is None:
        rev = run.revolute if run.revolute is not None else rev_u
    return Experiment.of_run(run, True if rev is None else rev)


def load_experiments(
    paths: Sequence[str | Path] | str | Path,
    *,
    mapping: Mapping[str, str | float] | None = None,
    gain: float | str | None = None,
    joint: str | bool | None = None,
    axis: int = 0,
    q_unit: str | None = None,
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
    exps = [
        load_experiment(p, mapping=mapping, gain=gain, joint=joint, axis=axis, q_unit=q_unit)
        for p in paths
    ]
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
