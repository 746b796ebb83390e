"""Direct-validation plots in the style of the paper's Fig. 4-5 (matplotlib, Agg).

Figures are built with :class:`matplotlib.figure.Figure` directly (no pyplot state, no
display); :func:`write_plots` is the only function that writes files.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.figure import Figure

if TYPE_CHECKING:  # pragma: no cover
    from .fitting import FitReport
    from .models import IdentModel
    from .preprocess import Design

__all__ = ["direct_validation", "error_bands", "write_plots"]


def direct_validation(model: IdentModel, design: Design, title: str | None = None) -> Figure:
    """Measured tau against the prediction W chi_hat and the error, sample by sample
    (Fig. 4-5), with the experiment boundaries marked.

    Parameters
    ----------
    model : IdentModel
        A fitted model.
    design : Design
        Samples to show (identification or validation system).
    title : str or None
        Figure title; default names the model and its relative error.

    Returns
    -------
    matplotlib.figure.Figure
    """
    y = design.Y
    yhat = model.predict(design)
    rho = y - yhat
    k = np.arange(y.size)
    unit = "N m" if design.signals.revolute else "N"
    fig = Figure(figsize=(10, 4.8), layout="constrained")
    ax = fig.add_subplot(2, 1, 1)
    ax.plot(k, y, color="tab:blue", lw=1.2, label=r"measured $\tau$")
    ax.plot(k, yhat, "--", color="tab:red", lw=1.0, label=r"estimated $W\hat\chi$")
    ax.set_ylabel(f"torque [{unit}]" if unit == "N m" else f"force [{unit}]")
    ax.legend(loc="upper right", fontsize=8)
    ax.grid(alpha=0.3)
    err = float(np.linalg.norm(rho) / np.linalg.norm(y))
    ax.set_title(title or f"Direct validation, {model.name} model: ||rho||/||Y|| = {err:.4f}")
    ax2 = fig.add_subplot(2, 1, 2, sharex=ax)
    ax2.plot(k, rho, color="k", lw=0.8, label=r"error $\rho$")
    ax2.set_ylabel(f"error [{unit}]")
    ax2.set_xlabel("sample (decimated, experiments concatenated)")
    ax2.grid(alpha=0.3)
    exp = np.asarray(design.signals.experiment)
    for b in np.flatnonzero(np.diff(exp) != 0) + 1:
        ax.axvline(b, color="0.5", lw=0.8, ls=":")
        ax2.axvline(b, color="0.5", lw=0.8, ls=":")
    return fig


def error_bands(report: FitReport) -> Figure:
    """Residual against velocity for each model, with the Table III bands shaded."""
    names = list(report.models)
    fig = Figure(figsize=(5 * len(names), 3.6), layout="constrained")
    vmax = report.vmax
    first = None
    for i, name in enumerate(names):
        m, d = report.models[name], report.designs[name]
        rho = d.Y - m.predict(d)
        # one error scale for every model, so that the panels compare at a glance
        ax = fig.add_subplot(1, len(names), i + 1, sharey=first)
        first = first or ax
        ax.axvspan(-0.10 * vmax, 0.10 * vmax, color="tab:green", alpha=0.12, label="low (0-10 %)")
        for s in (-1, 1):
            ax.axvspan(
                s * 0.35 * vmax,
                s * vmax,
                color="tab:orange",
                alpha=0.10,
                label="high (35-100 %)" if s > 0 else None,
            )
        ax.plot(d.signals.dq, rho, ".", ms=1.5, color="k", alpha=0.5)
        rev = d.signals.revolute
        ax.set_xlabel("velocity [rad/s]" if rev else "velocity [m/s]")
        ax.set_ylabel("error [N m]" if rev else "error [N]")
        errs = report.errors(name)
        ax.set_title(f"{name} model: ||rho||/||Y|| = {errs['all']:.4f} "
                     f"(low {_f(errs.get('low'))}, high {_f(errs.get('high'))})", fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=7)
    return fig


def _f(x: float | None) -> str:
    return "-" if x is None or not np.isfinite(x) else f"{x:.4f}"


def write_plots(report: FitReport, outdir: str | Path) -> list[Path]:
    """Write the direct-validation figure of each model (and of the validation files,
    when given) and the residual-vs-velocity figure as PNG into ``outdir``.

    Returns
    -------
    list of Path
        The files written.
    """
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for name, m in report.models.items():
        fig = direct_validation(m, report.designs[name])
        p = out / f"direct_validation_{name}.png"
        fig.savefig(p, dpi=110)
        written.append(p)
        vd = report.validation_designs.get(name)
        if vd is not None:
            err = m.rel_error_on(vd)
            fig = direct_validation(
                m, vd, f"Cross validation, {name} model: ||rho||/||Y|| = {err:.4f}"
            )
            p = out / f"cross_validation_{name}.png"
            fig.savefig(p, dpi=110)
            written.append(p)
    p = out / "error_vs_velocity.png"
    error_bands(report).savefig(p, dpi=110)
    written.append(p)
    return written
