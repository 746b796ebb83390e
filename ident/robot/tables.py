"""The paper's Table III per joint: relative error norms ||rho|| / ||tau|| of the usual and the
paper model over all samples, low velocities (0-10 % of the joint's maximum velocity) and high
velocities (35-100 %), as :func:`ident.results.band_errors` does for one joint.

:func:`format_table_iii` can set each figure on the fit's rows beside the same figure on all
rows (``jointid fit --robot``: stiction area, guard and sign check included) and the share of
the band's rows the first leaves out: a figure that leaves out the rows a model predicts worst
(the stiction area) is not the model's error on the data.

:func:`format_uncertainty` prints what :mod:`ident.robot.uncertainty` adds to a model's record:
how the honest sigma was obtained, the pruned parameters and the joints flagged for errors in
variables.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..results import DEFAULT_BANDS, band_errors
from . import RobotIdentError
from .signals import RobotSignals

__all__ = ["table_iii", "format_table_iii", "format_uncertainty"]


def _stack(signals: RobotSignals | Sequence[RobotSignals]) -> list[RobotSignals]:
    return [signals] if isinstance(signals, RobotSignals) else list(signals)


def table_iii(
    models: Mapping[str, Any],
    signals: RobotSignals | Sequence[RobotSignals],
    *,
    vmax: Sequence[float] | Mapping[str, float] | None = None,
    bands: Mapping[str, tuple[float, float]] = DEFAULT_BANDS,
    clip: bool = False,
) -> dict[str, dict[str, dict[str, float]]]:
    """Table III per joint.

    Parameters
    ----------
    models : mapping
        Model label (``"usual"``, ``"paper"``) -> fitted :class:`~ident.robot.estimate.RobotModel`.
    signals : RobotSignals or sequence
        Samples to evaluate (the identification data or validation runs); samples whose
        torque is not finite are ignored.
    vmax : sequence (k,) or mapping joint -> [rad/s], optional
        Maximum velocity of each joint; default max |dq_j| over the evaluated samples.
    bands : mapping
        Band name -> (low, high) fractions of vmax (default the paper's all/low/high).
    clip : bool
        Rows faster than vmax count as at vmax (in "all" and "high"), instead of in no band:
        the table of every row with the bands of the selected rows' vmax.

    Returns
    -------
    dict
        ``table[joint][model][band]`` = ||rho|| / ||tau|| (NaN for an empty band).
    """
    if not models:
        raise RobotIdentError("table_iii: no model given")
    sigs = _stack(signals)
    first = next(iter(models.values()))
    joints = tuple(first.joints_)
    taus = np.concatenate([s.tau for s in sigs])
    dqs = np.concatenate([s.dq for s in sigs])
    preds = {name: np.concatenate([m.predict(s) for s in sigs]) for name, m in models.items()}
    out: dict[str, dict[str, dict[str, float]]] = {}
    for j, joint in enumerate(joints):
        ok = np.isfinite(taus[:, j])
        for p in preds.values():
            ok &= np.isfinite(p[:, j])
        if isinstance(vmax, Mapping):
            vm = float(vmax[joint])
        elif vmax is not None:
            vm = float(np.asarray(vmax, dtype=float)[j])
        else:
            vm = float(np.abs(dqs[ok, j]).max(initial=0.0))
        dq = np.clip(dqs[ok, j], -vm, vm) if clip else dqs[ok, j]
        out[joint] = {name: band_errors(taus[ok, j], taus[ok, j] - p[ok, j], dq, vm, bands)
                      for name, p in preds.items()}
    return out


def format_table_iii(table: Mapping[str, Mapping[str, Mapping[str, float]]],
                     digits: int = 4, *,
                     all_rows: Mapping[str, Mapping[str, Mapping[str, float]]] | None = None,
                     left_out: Mapping[str, Mapping[str, float]] | None = None) -> str:
    """Plain-text Table III per joint: one row per (joint, band), one column per model.

    Parameters
    ----------
    table : mapping
        :func:`table_iii` on the rows a figure uses.
    digits : int
        Decimals of the relative errors.
    all_rows : mapping, optional
        :func:`table_iii` of the same models on every row: a column ``<model> all`` beside
        each model's.
    left_out : mapping, optional
        ``left_out[joint][band]``: share of the band's rows ``table`` leaves out (column
        ``out %``).
    """
    joints = list(table)
    if not joints:
        return ""
    models = list(table[joints[0]])
    bands = list(table[joints[0]][models[0]])
    head = ["joint", "samples"]
    for m in models:
        head += [m] + ([f"{m} all"] if all_rows is not None else [])
    if left_out is not None:
        head.append("out %")
    rows = [tuple(head)]
    for j in joints:
        for b in bands:
            row = [j, b]
            for m in models:
                row.append(f"{table[j][m][b]:.{digits}f}")
                if all_rows is not None:
                    row.append(f"{all_rows[j][m][b]:.{digits}f}")
            if left_out is not None:
                row.append(f"{100 * left_out[j][b]:.1f}")
            rows.append(tuple(row))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)) for r in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def format_uncertainty(block: Mapping[str, Any] | None) -> list[str]:
    """Lines for a model record's ``uncertainty`` block (:meth:`Uncertainty.to_json
    <ident.robot.uncertainty.Uncertainty.to_json>`): the method, the robust eq. 15 and its
    long-run factors, the pruned parameters and, per flagged joint, the errors-in-variables
    reason with its numbers."""
    if not block:
        return []
    reps = (f"{block['n_replicates']} jackknife replicates over {block['units']}"
            + (f", {block['n_failed']} not identifiable" if block["n_failed"] else "")
            if block["n_replicates"] else "no jackknife")
    iv = "IDIM-IV check made" if block["iv"] is not None else (
        f"no IDIM-IV check ({block['iv_note']})")
    lines = [f"std: honest sigma = {block['method']} ({reps}; {iv}); 'std eq15': eq. 15 alone"]
    if block.get("long_run_factor"):  # (records before the robust eq. 15 have no such key)
        lines.append("robust eq. 15 (JSON std_robust): " + block["robust"] + "; measured "
                     "long-run factors: "
                     + ", ".join(f"{j} {f:.3g}" for j, f in block["long_run_factor"].items()))
    if block["pruned"]:
        lines.append(f"pruned (relative std above {block['threshold_pct']:g} %, eq. 14-16; "
                     f"held at 0, the model refitted without them, not used to predict): "
                     f"{', '.join(block['pruned'])}")
    for joint, f in block["joints"].items():
        if f["errors_in_variables"]:
            lines.append(f"joint {joint}: {f['reason']}")
    return lines
