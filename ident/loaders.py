"""Loading measured experiments: MCAP logs of ``jointid run``, CSV and MATLAB files.

(Past 600 lines: the one module of ident that reads files, by design -- three formats sharing
the column mapping, unit conversion and one-line error messages.)

This is the only module of :mod:`ident` that reads files. Each input file is one experiment
(one payload run); :func:`concat` stacks them into one :class:`~ident.signals.Signals`
(paper eq. 36-37), with derivatives left to :func:`ident.preprocess.build_design`.

Column mapping
--------------
The canonical variables are ``t`` [s], ``q`` [rad or m], ``tau`` [N m or N] and the optional
``payload_kg`` (M_aw [kg]) and ``payload_arm_m`` (L_a [m]). CSV files need a header row;
MATLAB ``.mat`` files (v5/v7 through scipy, v7.3 -- HDF5 -- through h5py, read into the same
structure) hold named variables. A mapping renames them::

    mapping = {"q": "qm", "tau": "vir"}      # canonical -> name in the file
    gain = "gtau"                            # tau = gain * column; a number or a variable name

Payload entries of the mapping may also be numbers (a constant for the whole file).

Foreign MATLAB data keep their signals in structs, several axes in one 2-D array and
positions in degrees. A mapping value is then a *path* (see :func:`resolve_path`)::

    NAME[.FIELD...][ROW]        row ROW (0-based) of a 2-D array, e.g. rec.act_pos_mot_deg[2]
    NAME[.FIELD...][:, COL]     column COL (0-based) of a 2-D array (N x axes layouts)

A name that exists as such in the file (e.g. a CSV header ``q.motor``) is always taken
verbatim. The gain may be a number, a path to a scalar (``para.u[2]``) or a product of them
(``para.u[2]*0.5``). ``q_unit`` converts q and q_ref to SI (degrees to radians, mm to m).
Irregular time stamps are put on a uniform grid by :func:`uniform_grid` (shared with the
robot loader, :mod:`ident.robot.loaders`), with a :class:`ResamplingWarning` saying which
reading of the stamps it took and why.

Length (~940 lines): the path language of ``--map``/``--gain`` (struct fields, row and
column indices) and its one-line error messages are most of it; it serves CSV, MAT and
MCAP inputs alike; the MATLAB v7.3 (HDF5) reader that feeds the same paths and the one
resampling of irregular stamps (:func:`uniform_grid`, also the robot loader's) are the rest.
"""

from __future__ import annotations

import csv
import re
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np
import scipy.io

from daq.protocol.reader import read_run

from . import DataError
from .signals import Signals
from .timing import align_to_torque

__all__ = [
    "Experiment",
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
]

#: Fewest samples accepted in one experiment.
MIN_SAMPLES = 50
#: Relative spread of the sampling period above which a file is resampled.
IRREGULAR_TOL = 0.01
#: A step of the time column longer than this many median periods is a gap in the recording
#: (samples lost, logger paused): refused, never interpolated across.
GAP_PERIODS = 5.0
#: Sanity bound on |q|, |q_ref| [rad or m] and |tau| [N m or N] after unit conversion and gain:
#: no joint signal comes near it; values beyond are a wrong column, unit or gain (or garbage)
#: and would overflow the least-squares sums.
MAX_ABS_SIGNAL = 1e9

CANONICAL = ("t", "q", "tau", "q_ref", "payload_kg", "payload_arm_m")

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
#: Most names listed in an error message.
_MAX_LISTED = 40


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

    Values that parse as numbers become floats (payload constants). Commas inside brackets
    belong to a path (``q=rec.pos[:, 2]``) and do not separate entries.
    """
    if not items:
        return {}
    if isinstance(items, str):
        items = [items]
    out: dict[str, str | float] = {}
    for item in items:
        for part in _split_top_commas(item):
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
    except (ValueError, OSError) as exc:
        raise DataError(f"{path}: not a readable MAT file ({exc})") from None
    return {k: v for k, v in raw.items() if not k.startswith("__")}


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


def _pick(
    table: Mapping[str, object], key: str, mapping: Mapping[str, str | float], path: Path
) -> np.ndarray | float | None:
    """The mapped (or same-named) entry for ``key``: a float constant, a 1-D signal, or
    None when an optional key is neither mapped nor present."""
    name = mapping.get(key, key)
    if isinstance(name, float):
        return name
    if key not in mapping and name not in table:
        if key in ("payload_kg", "payload_arm_m", "q_ref"):
            return None
        avail = _listing([str(k) for k in table])
        raise DataError(
            f"{path}: missing column/variable {name!r} for {key!r} (found: {avail}; "
            f"map one with --map {key}=NAME or a path like rec.pos[2])"
        )
    if key in ("payload_kg", "payload_arm_m"):
        return _constant(table, name, key, str(path))
    return _signal(table, name, key, str(path))


def _gain_value(table: Mapping[str, object], gain: float | str, path: Path) -> float:
    """``gain``: a number, a path to a scalar/constant, or a product ``A*B*...`` of them."""
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


def _from_table(
    table: Mapping[str, object],
    path: Path,
    mapping: Mapping[str, str | float],
    gain: float | str | None,
    revolute: bool | None,
    q_scale: float = 1.0,
) -> Experiment:
    for key in ("t", "q", "tau", "q_ref"):
        if isinstance(mapping.get(key), float):
            raise DataError(f"{path}: {key} must be a column/variable, not a constant")
    t = _pick(table, "t", mapping, path)
    q = _pick(table, "q", mapping, path)
    tau = _pick(table, "tau", mapping, path)
    q_ref = _pick(table, "q_ref", mapping, path)
    g = 1.0 if gain is None else _gain_value(table, gain, path)
    consts = {}
    for key in ("payload_kg", "payload_arm_m"):
        v = _pick(table, key, mapping, path)
        consts[key] = 0.0 if v is None else float(v)  # type: ignore[arg-type]
    return make_experiment(
        str(path),
        t,  # type: ignore[arg-type]
        q_scale * np.asarray(q, dtype=float),
        g * np.asarray(tau, dtype=float),
        payload_mass=consts["payload_kg"],
        payload_arm=consts["payload_arm_m"],
        revolute=True if revolute is None else revolute,
        q_ref=None if q_ref is None else q_scale * np.asarray(q_ref, dtype=float),
        columns={k: str(mapping.get(k, k)) for k in ("t", "q", "tau", "q_ref")},
    )


def _hf_noise(x: np.ndarray, dt: float) -> float:
    """Noise of positions ``x`` (shape (n,) or (n, k)) in the complement of the excitation
    band: per axis, the median power of the Hann-windowed position spectrum above f_s/4
    (where the motion of an identification trajectory has no content), summed in log over
    the axes (a ratio between two gridings of the same axes is a product of per-axis ratios).
    """
    a = np.asarray(x, dtype=float).reshape(len(x), -1)
    n = a.shape[0]
    f = np.fft.rfftfreq(n, dt)
    upper = f > 0.25 / dt
    win = np.hanning(n)
    out = 0.0
    for col in a.T:
        c = col - np.polyval(np.polyfit(np.arange(n), col, 1), np.arange(n))
        p = np.abs(np.fft.rfft(c * win)) ** 2
        out += float(np.log(max(float(np.median(p[upper])), 1e-300)))
    return out


def uniform_grid(
    t: np.ndarray,
    arrays: Mapping[str, np.ndarray | None],
    *,
    source: str = "",
    judge: str = "q",
    warn: bool = True,
    stacklevel: int = 2,
) -> tuple[np.ndarray, dict[str, np.ndarray | None], str | None]:
    """Put samples with irregular time stamps on a uniform grid (the one resampling of the
    single-joint and the robot loaders, and of :func:`ident.preprocess.choose_cutoff`).

    Stamps whose steps stay within :data:`IRREGULAR_TOL` of their median are regular:
    returned as given. Otherwise two readings of the stamps are possible, and the data say
    which holds:

    * the values were taken at their stamps (irregular sampling instants): linear
      interpolation onto the grid of the median period;
    * the values were sampled uniformly and only the stamps jitter (a host clock stamping a
      drive's cycles): the values as they are, on the least-squares line through the stamps
      (t ≈ a + b k). Possible only when every stamp is within half a period of its slot
      (no sample lost).

    The reading whose positions (``arrays[judge]``) have less noise in the complement of the
    excitation band (:func:`_hf_noise`: position spectrum above f_s/4) is taken: interpolating
    values at the wrong instants adds q̇ × (stamp error) there, broadband noise that no
    cut-off chosen from the data survives. A :class:`ResamplingWarning` names the reading
    and the noise ratio that chose it.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Strictly increasing time stamps [s] (gaps refused by the callers beforehand).
    arrays : mapping of str to ndarray (shape (n,) or (n, k)) or None
        The signals sampled at ``t``; None entries are passed through.
    source : str
        Names the data in the warning.
    judge : str
        The key of the positions the readings are compared on.
    warn : bool
        Warn when the stamps are irregular.
    stacklevel : int
        Of the warning.

    Returns
    -------
    t : ndarray, shape (m,)
        Uniform time [s] (m = n for regular stamps and for the jitter reading).
    arrays : dict
        The signals on ``t``.
    note : str or None
        What was done (the warning's text), None for regular stamps.
    """
    t = np.asarray(t, dtype=float).reshape(-1)
    out: dict[str, np.ndarray | None] = dict(arrays)
    d = np.diff(t)
    med = float(np.median(d))
    if d.size == 0 or np.max(np.abs(d - med)) <= IRREGULAR_TOL * med:
        return t, out, None
    where = f"{source}: " if source else ""
    span = f"period {d.min():.3g}..{d.max():.3g} s"
    n = int(round((t[-1] - t[0]) / med)) + 1
    tu = t[0] + med * np.arange(n)
    tu = tu[tu <= t[-1] + 1e-12 * abs(t[-1])]

    def at_stamps(a: np.ndarray) -> np.ndarray:
        a = np.asarray(a, dtype=float)
        if a.ndim == 1:
            return np.interp(tu, t, a)
        return np.column_stack([np.interp(tu, t, a[:, j]) for j in range(a.shape[1])])

    k = np.arange(t.size, dtype=float)
    b, a0 = np.polyfit(k, t, 1)
    ti = a0 + b * k
    jitter_ok = b > 0 and float(np.max(np.abs(t - ti))) < 0.5 * b
    pos = arrays.get(judge)
    if jitter_ok and pos is not None and t.size >= 16:
        noise_stamps = _hf_noise(at_stamps(pos), med)
        noise_index = _hf_noise(np.asarray(pos, dtype=float), b)
        n_axes = int(np.asarray(pos).reshape(t.size, -1).shape[1])
        ratio = float(np.exp((noise_stamps - noise_index) / n_axes))  # per axis, geometric
        if ratio > 1.0:
            note = (f"{where}irregular time stamps ({span}) taken as jitter of uniformly "
                    f"sampled values, on a uniform grid of {t.size} samples at {b:.6g} s: "
                    f"resampled at the stamps, the positions' noise above f_s/4 is "
                    f"{ratio:.3g}x higher")
            if warn:
                warnings.warn(note, ResamplingWarning, stacklevel=stacklevel)
            return ti, out, note
        why = (f" (values taken at their stamps: their noise above f_s/4 is {1 / ratio:.3g}x "
               "lower than taken as uniformly sampled)")
    else:
        why = ("" if pos is None or t.size < 16 else
               " (values taken at their stamps: some stamp is more than half a period off "
               "a uniform grid)")
    for name, a in arrays.items():
        out[name] = None if a is None else at_stamps(a)
    note = f"{where}irregular sampling ({span}), resampled to {tu.size} samples at {med:.6g} s{why}"
    if warn:
        warnings.warn(note, ResamplingWarning, stacklevel=stacklevel)
    return tu, out, note


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
    """Validate arrays and build an :class:`Experiment` (resampling if irregular).

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
        :data:`MIN_SAMPLES`.
    """
    cols = dict(columns or {})
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
    if not (np.isfinite(payload_mass) and payload_mass >= 0):
        raise DataError(f"{source}: payload_kg {payload_mass!r}: expected a mass >= 0 [kg]")
    if not np.isfinite(payload_arm):
        raise DataError(f"{source}: payload_arm_m {payload_arm!r}: expected a finite lever "
                        "arm [m]")
    for name, a in (("t", t), ("q", q), ("tau", tau), ("q_ref", q_ref)):
        if a is None:
            continue
        col = cols.get(name, name)
        label = repr(name) if col == name else f"{col!r} ({name})"
        bad = ~np.isfinite(a)
        if bad.any():
            raise DataError(
                f"{source}: {label} has {int(bad.sum())} NaN/inf values "
                f"(first at sample {int(np.argmax(bad))})"
            )
        big = np.abs(a) > MAX_ABS_SIGNAL
        if name != "t" and big.any():
            k = int(np.argmax(big))
            raise DataError(
                f"{source}: {label} has {int(big.sum())} values beyond +-{MAX_ABS_SIGNAL:g} "
                f"(first {a[k]:.6g} at sample {k}); expected SI values [rad, m, N m or N] "
                "after --q-unit and --gain: wrong column, unit or gain?"
            )
    d = np.diff(t)
    if np.any(d <= 0):
        k = int(np.argmax(d <= 0))
        raise DataError(
            f"{source}: time is not strictly increasing at sample {k + 1} (t={t[k + 1]})"
        )
    med = float(np.median(d))
    if np.max(d) > GAP_PERIODS * med:
        k = int(np.argmax(d > GAP_PERIODS * med))
        n_gaps = int(np.count_nonzero(d > GAP_PERIODS * med))
        raise DataError(
            f"{source}: gap in the recording at t={t[k]:.6g} s (next sample {d[k]:.6g} s "
            f"later, {d[k] / med:.0f} periods of {med:.6g} s; {n_gaps} gap(s) over "
            f"{GAP_PERIODS:g} periods): split the file at the gap into separate experiments"
        )
    t, grid, _ = uniform_grid(t, {"q": q, "tau": tau, "q_ref": q_ref}, source=source,
                              stacklevel=4)
    q, tau, q_ref = grid["q"], grid["tau"], grid["q_ref"]
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


def _load_mcap(path: Path, revolute: bool | None, axis: int) -> Experiment:
    """One MCAP run, restricted to the cycles an identification can use: the drive in
    OPERATION ENABLED with its TPDOs received (:attr:`daq.protocol.reader.RunArrays.valid`);
    during enable, quick stop and shutdown the drive ignores the torque reference."""
    run = read_run(path, axis=axis)
    keep = _longest_true_run(run.valid, lost_cycle_breaks(run.cycle))
    inner_dropped = int(np.count_nonzero(run.valid)) - (keep.stop - keep.start)
    if inner_dropped > 0:
        warnings.warn(
            f"{path}: kept the longest stretch of cycles with the drive enabled "
            f"({keep.stop - keep.start} cycles); {inner_dropped} other enabled cycles "
            "are separated from it by a stop, missing TPDOs or lost cycles (never "
            "interpolated across)",
            stacklevel=2,
        )
    if keep.stop - keep.start == 0:
        raise DataError(f"{path}: no cycle with the drive in OPERATION ENABLED")
    run = run.select(keep)
    rev = bool(run.revolute) if revolute is None else revolute
    # logs without a /setpoint channel carry NaN: no reference, plain least squares
    q_ref = run.q_ref if np.all(np.isfinite(run.q_ref)) else None
    t, q, tau, q_ref = align_to_torque(run.t, run.q, run.tau_ref, q_ref,
                                       log_torque_delay(run.metadata, path), str(path))
    return make_experiment(
        str(path),
        t,
        q,
        tau,
        payload_mass=_finite_or_zero(run.payload_mass_kg),
        payload_arm=_finite_or_zero(run.payload_arm_m),
        revolute=rev,
        q_ref=q_ref,
    )


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
    """Load one file (``.mcap``, ``.csv``, ``.mat``) as an :class:`Experiment`.

    Parameters
    ----------
    path : str or Path
        Input file.
    mapping : mapping or None
        Canonical name (``t``, ``q``, ``tau``, ``q_ref``, ``payload_kg``, ``payload_arm_m``)
        -> column/variable name or path (:func:`resolve_path`: ``rec.act_pos_mot_deg[2]``,
        ``data[:, 1]``), or a number for payload entries.
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
    ext = p.suffix.lower()
    mapping = dict(mapping or {})
    scale, rev_u = _q_unit(q_unit, rev, str(p))
    if ext == ".mcap":
        if scale != 1.0:
            raise DataError(f"{p}: MCAP logs are in SI units; q unit {q_unit!r} does not apply")
        return _load_mcap(p, rev, axis)
    if ext == ".csv" or ext == ".txt":
        return _from_table(_read_csv(p), p, mapping, gain, rev_u, scale)
    if ext == ".mat":
        return _from_table(_read_mat(p), p, mapping, gain, rev_u, scale)
    raise DataError(f"{p}: unknown file type {ext!r}, expected .mcap, .csv or .mat")


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
