"""Results in the paper's form: parameter tables (Tables I-II), relative error norms per
velocity band (Table III), with and without payload runs (Table IV), and JSON records.

Pure formatting and numerics; ``docs/fit-json.md`` documents the JSON layout.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any, Protocol

import numpy as np

__all__ = [
    "DEFAULT_BANDS",
    "band_errors",
    "json_float",
    "parameters_json",
    "removed_json",
    "format_parameter_table",
    "format_error_table",
    "format_table_iv",
    "POSITION_OUTSIDE_SHARE",
    "position_split",
    "position_split_note",
    "position_split_notes",
]

class IdentModel(Protocol):
    """What the tables read of a fitted model (:class:`ident.models.IdentModel`); a
    protocol, so that this module does not import :mod:`ident.models` (which imports it)."""

    name: str
    names_: tuple[str, ...]
    coef_: dict[str, float]
    std_: dict[str, float]
    rel_std_pct_: dict[str, float]
    removed_: list[tuple[str, str]]


#: Velocity bands of Table III, as fractions of the maximum velocity.
DEFAULT_BANDS: dict[str, tuple[float, float]] = {
    "all": (0.0, 1.0),
    "low": (0.0, 0.10),
    "high": (0.35, 1.0),
}


def band_errors(
    Y: np.ndarray,
    rho: np.ndarray,
    dq: np.ndarray,
    vmax: float | None = None,
    bands: Mapping[str, tuple[float, float]] = DEFAULT_BANDS,
) -> dict[str, float]:
    """Relative error norms ||rho_band|| / ||Y_band|| per velocity band (Table III).

    Parameters
    ----------
    Y, rho, dq : ndarray, shape (m,)
        Measurements [N m], residuals [N m] and velocities [rad/s] of the same samples.
    vmax : float or None
        Maximum velocity [rad/s]; default max |dq|.
    bands : mapping
        name -> (low, high) fractions of vmax; a sample is in a band when
        low vmax <= |dq| <= high vmax.

    Returns
    -------
    dict
        name -> relative error (NaN for an empty band).
    """
    a = np.abs(dq)
    vm = float(a.max(initial=0.0)) if vmax is None else float(vmax)
    out = {}
    for name, (lo, hi) in bands.items():
        sel = (a >= lo * vm) & (a <= hi * vm)
        ny = float(np.linalg.norm(Y[sel]))
        out[name] = float(np.linalg.norm(rho[sel]) / ny) if sel.any() and ny > 0 else float("nan")
    return out


def json_float(x: Any) -> float | None:
    """A float for JSON: NaN and infinities become ``None``."""
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


def parameters_json(model: IdentModel) -> dict[str, dict[str, float | None]]:
    """``{param: {"value", "std", "std2", "rel_std_pct"}}`` of a fitted model."""
    return {
        n: {
            "value": json_float(model.coef_[n]),
            "std": json_float(model.std_[n]),
            "std2": json_float(2 * model.std_[n]),
            "rel_std_pct": json_float(model.rel_std_pct_[n]),
        }
        for n in model.names_
    }


def removed_json(model: IdentModel) -> list[dict[str, str]]:
    """``[{"name", "reason"}]`` of the eliminated parameters."""
    return [{"name": n, "reason": r} for n, r in model.removed_]


def _fmt(x: float | None, digits: int = 4) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "-"
    return f"{x:.{digits}g}"


def format_parameter_table(model: IdentModel, title: str | None = None) -> str:
    """Table I/II: parameter, identified value, 2 x standard deviation, relative deviation."""
    rows = [("Parameter", "Identified value", "Std dev x 2", "Rel. dev. [%]")]
    for n in model.names_:
        rows.append(
            (
                n,
                _fmt(model.coef_[n], 6),
                _fmt(2 * model.std_[n], 3),
                _fmt(model.rel_std_pct_[n], 3),
            )
        )
    out = [title or f"Identified values with the {model.name} model"]
    out.append(_grid(rows))
    for n, r in model.removed_:
        out.append(f"  eliminated {n}: {r}")
    return "\n".join(out)


def format_error_table(errors: Mapping[str, Mapping[str, float | None]]) -> str:
    """Table III. ``errors[model] = {"all", "low", "high", optional "validation"}``."""
    names = list(errors)
    labels = [
        ("all", "All samples (all velocities)"),
        ("low", "Low velocities (0-10 % of max)"),
        ("high", "High velocities (35-100 % of max)"),
        ("validation", "Validation files"),
    ]
    rows = [("Measurements used", *[f"{n} model" for n in names])]
    for key, label in labels:
        if any(errors[n].get(key) is not None for n in names):
            rows.append((label, *[_fmt(errors[n].get(key)) for n in names]))
    return "Relative norm of errors ||rho||/||Y||\n" + _grid(rows)


def format_table_iv(table_iv: Mapping[str, Mapping[str, float | None]]) -> str:
    """Table IV: errors of the identification with and without payload runs."""
    found = {m for v in table_iv.values() for m in v}
    names = [n for n in ("usual", "paper") if n in found] + sorted(found - {"usual", "paper"})
    rows = [("Identification carried out", *[f"{n} model" for n in names])]
    for key, label in (
        ("with_payloads", "With payload variations"),
        ("without_payload", "Without payload"),
    ):
        if key in table_iv:
            rows.append((label, *[_fmt(table_iv[key].get(n)) for n in names]))
    return "Relative norm of errors for 2 identifications\n" + _grid(rows)


def _grid(rows: list[tuple[str, ...]]) -> str:
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    lines = []
    for k, r in enumerate(rows):
        lines.append(
            "  ".join(
                c.ljust(w) if i == 0 else c.rjust(w)
                for i, (c, w) in enumerate(zip(r, widths, strict=True))
            )
        )
        if k == 0:
            lines.append("  ".join("-" * w for w in widths))
    return "\n".join(lines)


#: Share of the validation rows outside the fit's position range above which a note says so:
#: from 10 % of the rows on, the rows the fit never saw are a part of the cross-validation
#: error that can decide it (a fit over a narrow range of q can carry gravity and friction
#: constants that are nearly collinear there, with large cancelling coefficients that do not
#: cancel elsewhere); below it, a few rows at the edge of the range are the ordinary case.
POSITION_OUTSIDE_SHARE = 0.10


def position_split(q_fit: np.ndarray, q_val: np.ndarray, y_val: np.ndarray,
                   rho_val: np.ndarray) -> dict[str, Any] | None:
    """The validation error split by position: rows inside the fit's range of q, and outside.

    Only the positions decide the split; the measured torque enters only the errors.

    Parameters
    ----------
    q_fit : ndarray, shape (n,)
        The joint's positions on the fit's rows [rad] or [m].
    q_val, y_val, rho_val : ndarray, shape (m,)
        The validation rows' positions (same unit), measured torque and residual [N m] or
        [N]; rows with a non-finite torque or residual are ignored.

    Returns
    -------
    dict or None
        ``q_fit_range`` [min, max] (unit of ``q_fit``), ``rows``, ``rows_outside``,
        ``share_outside`` (fraction), ``error_inside`` and ``error_outside`` (||rho||/||y||
        on those rows, None without rows); None when there are no fit or validation rows.
    """
    q_fit = np.asarray(q_fit, float)
    q_fit = q_fit[np.isfinite(q_fit)]
    ok = np.isfinite(q_val) & np.isfinite(y_val) & np.isfinite(rho_val)
    q, y, rho = np.asarray(q_val)[ok], np.asarray(y_val)[ok], np.asarray(rho_val)[ok]
    if q_fit.size == 0 or q.size == 0:
        return None
    lo, hi = float(q_fit.min()), float(q_fit.max())
    out = (q < lo) | (q > hi)

    def err(sel: np.ndarray) -> float | None:
        ny = float(np.linalg.norm(y[sel]))
        return float(np.linalg.norm(rho[sel]) / ny) if sel.any() and ny > 0 else None

    return {"q_fit_range": [lo, hi], "rows": int(q.size), "rows_outside": int(out.sum()),
            "share_outside": float(out.mean()), "error_inside": err(~out),
            "error_outside": err(out)}


#: The note blames position extrapolation only where the rows outside the fit's positions err
#: more than this many times the rows inside (or none is inside); otherwise it says the
#: positions do not explain the error (KUKA KR300, robot fit: A4 114 % outside, 169 % inside).
OUTSIDE_ERROR_RATIO = 2.0


def position_split_json(split: Mapping[str, Any]) -> dict[str, Any]:
    """:func:`position_split` with JSON floats (null for NaN): the record's
    ``validation_position_split`` (per model, per joint on the robot path)."""
    return {k: ([json_float(x) for x in v] if isinstance(v, list)
                else v if isinstance(v, int) else json_float(v)) for k, v in split.items()}


#: The reasons a position note gives: (short form, full explanation). The full one is said
#: once per report, in the first note that gives the reason (:func:`position_split_notes`);
#: the later notes give the short form.
_WHY = {
    "extrapolation": ("position extrapolation",
                      "position extrapolation: over a narrow range of q the gravity columns can "
                      "be nearly collinear with the friction constants, and what cancels on the "
                      "fit's rows need not elsewhere; the cross-validation error above includes "
                      "these rows"),
    "inside": ("about as large inside: not the positions",
               "inside the range the error is about as large: the positions alone do not "
               "explain the cross-validation error"),
}


def _reason(split: Mapping[str, Any]) -> str:
    """The key in :data:`_WHY` of a split's note: position extrapolation where the rows
    outside err more than :data:`OUTSIDE_ERROR_RATIO` times those inside (or one part has
    no rows), else the positions do not explain the error."""
    e_in, e_out = split["error_inside"], split["error_outside"]
    if e_in is None or e_out is None or e_out > OUTSIDE_ERROR_RATIO * e_in:
        return "extrapolation"
    return "inside"


def position_split_note(split: Mapping[str, Any] | None, what: str, files: str,
                        revolute: bool = True, explain: bool = True) -> str | None:
    """The note of :func:`position_split` when more than :data:`POSITION_OUTSIDE_SHARE` of
    the validation rows lie outside the fit's positions, else None. ``what``: e.g.
    ``"A1 (paper model)"``; ``files``: the validation files' names; q in [rad] with degrees
    for a revolute joint, in [m] with millimetres for a prismatic one; ``explain``: the
    reason in full (False: its short form, an earlier note of the report explained it)."""
    if split is None or split["share_outside"] <= POSITION_OUTSIDE_SHARE:
        return None
    lo, hi = split["q_fit_range"]
    rng = (f"q = {lo:.3g}..{hi:.3g} rad ({np.degrees(lo):.3g}..{np.degrees(hi):.3g} deg)"
           if revolute else f"q = {lo:.3g}..{hi:.3g} m ({1e3 * lo:.3g}..{1e3 * hi:.3g} mm)")
    share = 100 * split["share_outside"]

    def pct(x: float | None) -> str:
        return "-" if x is None else f"{100 * x:.3g} %"

    inside = (f", the {100 - share:.0f} % inside {pct(split['error_inside'])}"
              if split["rows_outside"] < split["rows"] else "")
    why = _WHY[_reason(split)][1 if explain else 0]
    return (f"validation, {what}: {share:.0f} % of the rows of {files} lie outside the fit's "
            f"positions {rng}: their error {pct(split['error_outside'])}{inside} ({why})")


def position_split_notes(splits: Iterable[tuple[str, Mapping[str, Any] | None]],
                         files: Sequence[str | Path], revolute: bool | Sequence[bool] = True,
                         *, said: set[str] | None = None) -> list[str]:
    """The notes of :func:`position_split_note` for the splits of one fit on the same
    validation files: the single-joint fit's models (:func:`ident.fitting.fit_models`, the
    subject naming the axis when known) or the robot fit's joints of one model
    (``ident.cli_robot``), one line each. The one place the files' names are joined
    (``", "``, names without their folders; "the validation data" without files), and said
    once per report: the first note names them, the next ones say "the same files"; each
    reason is explained in full once too (the first note giving it; the next ones give its
    short form, e.g. "(position extrapolation)").

    Parameters
    ----------
    splits : iterable of (str, dict or None)
        ``(what, split)``: the note's subject, e.g. ``"A1 (paper model)"``, and its
        :func:`position_split`.
    files : sequence of str or Path
        The validation files.
    revolute : bool or sequence of bool
        Joint kind (q in [rad] with degrees, else [m] with millimetres): one for every
        split, or one per split in the order given (a robot's joints).
    said : set of str, optional
        What earlier notes of the same report said, updated here: ``"files"`` once the
        files are named, and the reasons explained in full (keys of ``_WHY``). The robot
        fit passes one set through its models, so that each is said once per report.

    Returns
    -------
    list of str
        One note per split past :data:`POSITION_OUTSIDE_SHARE`, in the order given.
    """
    where = ", ".join(Path(f).name for f in files) or "the validation data"
    said = set() if said is None else said
    out: list[str] = []
    for i, (what, sp) in enumerate(splits):
        rev = bool(revolute if np.ndim(revolute) == 0 else revolute[i])
        why = None if sp is None else _reason(sp)
        n = position_split_note(sp, what, "the same files" if "files" in said else where,
                                rev, explain=why not in said)
        if n is not None:
            out.append(n)
            said.update(("files", why))
    return out
