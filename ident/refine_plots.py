"""Plots of the residual diagnosis and of each refinement step (PNG files).

Figures are built with :class:`matplotlib.figure.Figure` and the Agg canvas (no pyplot
state, no display needed). This is the only module of the refinement that writes files.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from .describe import Description
from .diagnose import Diagnosis
from .effects import Prediction, rigid_prediction, variable_values
from .refine import Refinement, _unscaled
from .signals import Signals

UNITS = {
    "position": "q [rad or m]",
    "velocity": "dq [rad/s or m/s]",
    "direction": "sign(dq)",
    "acceleration": "ddq [rad/s² or m/s²]",
    "load": "τ_out [N m or N]",
    "quadrant": "sign(P)",
    "time": "t since run start [s]",
    "reversal": "distance since the last reversal [rad or m]",
}


def _save(fig: Figure, path: Path) -> Path:
    FigureCanvasAgg(fig)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path


def plot_residual_vs_variables(
    diag: Diagnosis,
    path: str | Path,
    *,
    residual: np.ndarray | None = None,
    signals: Signals | None = None,
    tau_out: Prediction | None = None,
    n_variables: int = 3,
    title: str = "",
) -> Path:
    """Residual against the leading variables of a diagnosis: binned means (line) over the
    samples (dots, when ``residual`` and ``signals`` are given).

    Parameters
    ----------
    diag : Diagnosis
        The diagnosis (its ranked table gives the variables and bin means).
    path : str or Path
        PNG file to write.
    residual : ndarray, shape (n,), optional
        Residual [N m] on ``signals``.
    signals : Signals, optional
        The samples of the residual.
    tau_out : Prediction, optional
        Load predictor for the ``load`` variable.
    n_variables : int
        Number of leading variables shown.
    title : str
        Figure title.

    Returns
    -------
    Path
        The written file.
    """
    rows = diag.table[:n_variables]
    fig = Figure(figsize=(4.2 * len(rows), 3.4))
    for i, d in enumerate(rows, 1):
        ax = fig.add_subplot(1, len(rows), i)
        if residual is not None and signals is not None:
            x = variable_values(d.variable, signals, tau_out)
            step = max(1, x.size // 4000)
            ax.plot(x[::step], residual[::step], ".", ms=1.5, alpha=0.3, color="0.5")
        ax.plot(d.centers, d.means, "o-", color="C3", ms=3, lw=1.2, label="bin mean")
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_xlabel(UNITS.get(d.variable, d.variable))
        ax.set_ylabel("residual [N m or N]")
        ax.set_title(f"{d.variable}: {100 * d.explained:.1f} %, p={d.p_value:.1e}", fontsize=9)
    if title:
        fig.suptitle(title, fontsize=10)
    return _save(fig, Path(path))


def plot_position_periodogram(diag: Diagnosis, path: str | Path, *, title: str = "") -> Path:
    """Periodogram of the residual against position (and time), peak marked.

    Parameters
    ----------
    diag : Diagnosis
        The diagnosis holding both periodograms.
    path : str or Path
        PNG file to write.
    title : str
        Figure title.
    """
    fig = Figure(figsize=(8.4, 3.4))
    for i, pg in enumerate((diag.position_periodogram, diag.time_periodogram), 1):
        ax = fig.add_subplot(1, 2, i)
        ax.semilogx(pg.periods, 100 * pg.power, lw=0.8)
        if np.isfinite(pg.peak_period):
            ax.axvline(pg.peak_period, color="C3", lw=0.8, ls="--")
        unit = "[rad or m]" if pg.against == "position" else "[s]"
        ax.set_xlabel(f"period in {pg.against} {unit}")
        ax.set_ylabel("share of residual variance [%]")
        ax.set_title(
            f"peak {pg.peak_period:.5g}: {100 * pg.peak_power:.2f} %, "
            f"false alarm {pg.false_alarm:.1e}",
            fontsize=9,
        )
    if title:
        fig.suptitle(title, fontsize=10)
    return _save(fig, Path(path))


def plot_structure(desc: Description, path: str | Path, *, title: str = "") -> Path:
    """The profile of a structure found by the library search (:mod:`ident.describe`): the
    fitted function of its variable (a curve) or of its two variables (a map), without the
    modifier (sign(q̇), sign(P), τ̂_out), with the sentence that describes it."""
    fig = Figure(figsize=(6.4, 3.6))
    ax = fig.add_subplot(1, 1, 1)
    parts = desc.group_key.split(" x ")
    if len(desc.grid) == 1:
        ax.plot(desc.grid[0], desc.profile, lw=1.0)
        ax.set_xlabel(UNITS.get(parts[0], parts[0]))
        ax.set_ylabel("[N m]" + (f" x {parts[1]}" if len(parts) > 1 else ""))
    elif len(desc.grid) == 2:
        im = ax.pcolormesh(desc.grid[0], desc.grid[1], desc.profile.T, shading="auto")
        fig.colorbar(im, ax=ax, label="[N m]")
        ax.set_xlabel(UNITS.get(parts[0], parts[0]))
        ax.set_ylabel(UNITS.get(parts[1], parts[1]))
    ax.set_title(desc.sentence if len(desc.sentence) < 95 else desc.sentence[:92] + "...",
                 fontsize=7)
    if title:
        fig.suptitle(title, fontsize=10)
    return _save(fig, Path(path))


def plot_refinement(ref: Refinement, outdir: str | Path, *, n_variables: int = 3) -> list[Path]:
    """All refinement figures: per step, the residual against the leading variables and the
    periodograms that led to it; then the same for the final residual.

    Parameters
    ----------
    ref : Refinement
        Outcome of :func:`ident.refine.refine`.
    outdir : str or Path
        Folder (created if needed).
    n_variables : int
        Leading variables per residual figure.

    Returns
    -------
    list of Path
        The PNG files written, in order.
    """
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for i, st in enumerate(ref.steps, 1):
        head = f"step {i}: added {st.effect} ({st.variable})"
        paths.append(plot_residual_vs_variables(
            st.diagnosis, out / f"refine_step{i}_residual.png", n_variables=n_variables,
            title=head))
        paths.append(plot_position_periodogram(
            st.diagnosis, out / f"refine_step{i}_periodogram.png", title=head))
        desc = st.library.description if st.library is not None else None
        if desc is not None and desc.group_key and " x ".join(st.variables) == desc.group_key:
            paths.append(plot_structure(desc, out / f"refine_step{i}_structure.png",
                                        title=head))
    s = _unscaled(ref.final_design)
    tau_out = rigid_prediction(ref.final_model.library, ref.final_model.coef_)
    paths.append(plot_residual_vs_variables(
        ref.final_diagnosis, out / "refine_final_residual.png",
        residual=ref.final_model.residual_, signals=s, tau_out=tau_out,
        n_variables=n_variables, title="remaining residual"))
    paths.append(plot_position_periodogram(
        ref.final_diagnosis, out / "refine_final_periodogram.png", title="remaining residual"))
    return paths
