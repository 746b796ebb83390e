"""Direct-validation plots and the HTML report of an n-dof fit (``jointid fit --robot
--report DIR``), per joint in the style of the paper's Fig. 4-5.

Figures are built with :class:`matplotlib.figure.Figure` (no pyplot state);
:func:`write_robot_report` is the only function that writes files.
"""

from __future__ import annotations

import html
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from ..report import Section, html_table, write_html
from .signals import RobotSignals

__all__ = ["joint_validation", "write_robot_report"]


def joint_validation(est: Any, sig: RobotSignals, val: RobotSignals | None, j: int,
                     model: str) -> Figure:
    """Measured and predicted torque of joint ``j`` and the error, identification samples
    then validation samples (a vertical line between them; dotted lines between experiments).

    Parameters
    ----------
    est : RobotModel
        Fitted estimator (``predict(signals) -> (n, k)``).
    sig, val : RobotSignals
        Identification and (optional) validation signals.
    j : int
        Column of the joint (0-based, moving order).
    model : str
        Model name for the title.
    """
    parts = [sig] + ([val] if val is not None else [])
    y = np.concatenate([s.tau[:, j] for s in parts])
    yhat = np.concatenate([est.predict(s)[:, j] for s in parts])
    exp = np.concatenate([s.experiment + (1000 if i else 0) for i, s in enumerate(parts)])
    rho = y - yhat
    k = np.arange(y.size)
    joint = sig.joints[j]
    fig = Figure(figsize=(10, 4.8), layout="constrained")
    ax = fig.add_subplot(2, 1, 1)
    ax.plot(k, y, color="tab:blue", lw=1.2, label=r"measured $\tau$")
    ax.plot(k, yhat, "--", color="tab:red", lw=1.0, label=r"estimated $\hat\tau$")
    ax.set_ylabel("torque [N m]")
    ax.legend(loc="upper right", fontsize=8)
    ax.grid(alpha=0.3)

    def err(a: np.ndarray, b: np.ndarray) -> float:
        ok = np.isfinite(a) & np.isfinite(b)
        return float(np.linalg.norm(a[ok] - b[ok]) / max(np.linalg.norm(a[ok]), 1e-300))

    n0 = sig.n
    title = f"{model} model, joint {joint}: fit {err(y[:n0], yhat[:n0]):.4f}"
    if val is not None:
        title += f", cross-validation {err(y[n0:], yhat[n0:]):.4f}"
    ax.set_title(title + "  (||rho_j|| / ||tau_j||)")
    ax2 = fig.add_subplot(2, 1, 2, sharex=ax)
    ax2.plot(k, rho, color="k", lw=0.8)
    ax2.set_ylabel("error [N m]")
    ax2.set_xlabel("sample (decimated; identification, then validation)")
    ax2.grid(alpha=0.3)
    for b in np.flatnonzero(np.diff(exp) != 0) + 1:
        style = "-" if b == n0 else ":"
        ax.axvline(b, color="0.4", lw=0.8, ls=style)
        ax2.axvline(b, color="0.4", lw=0.8, ls=style)
    return fig


def write_robot_report(outdir: Path, out: Mapping[str, Any], text: str) -> list[Path]:
    """Write ``tables.txt``, the per-joint figures and ``report.html`` into ``outdir``
    (``fit.json`` is written by the caller).

    Parameters
    ----------
    outdir : Path
    out : mapping
        The record of :func:`ident.cli_robot.fit_robot` (with its ``_estimators`` and
        ``_signals``).
    text : str
        The printed tables.

    Returns
    -------
    list of Path
        The figures written.
    """
    outdir.mkdir(parents=True, exist_ok=True)
    (outdir / "tables.txt").write_text(text + "\n", encoding="utf-8")
    sig, val = out["_signals"]
    figures: list[Path] = []
    sections = []
    for name, est in out["_estimators"].items():
        rec = out["models"][name]
        sec = Section(f"{name} model")
        rows = []
        for j in [*sig.joints, "all"]:
            row = [j, f"{100 * rec['rel_error'][j]:.2f}"]
            if "validation_rel_error" in rec:
                row.append(f"{100 * rec['validation_rel_error'][j]:.2f}")
            rows.append(row)
        head = ["joint", "fit [%]"] + (["cross-validation [%]"] if val is not None else [])
        sec.raw(html_table(head, rows))
        for j, joint in enumerate(sig.joints):
            p = outdir / f"direct_validation_{name}_{joint}.png"
            joint_validation(est, sig, val, j, name).savefig(p, dpi=100)
            figures.append(p)
            sec.figure(p, f"{name} model, joint {joint}")
        sections.append(sec)
    for name, rec in out["models"].items():
        if "error" in rec:
            sections.append(Section(f"{name} model").para(f"not identified: {rec['error']}"))
    tables = Section("Parameters and errors").raw(f"<pre>{html.escape(text)}</pre>")
    r = out["robot"]
    write_html(outdir / "report.html", f"jointid fit --robot: {r['name']}",
               f"{r['source']}; moving {', '.join(r['moving'])}; inputs "
               f"{', '.join(out['inputs'])}", [*sections, tables])
    return figures
