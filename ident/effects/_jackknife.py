"""Block jackknife of an effect found with a scanned hyper-parameter (a ripple's period):
the spread of its parameters when the whole estimation is redone without each unit of rows.

Why: the linearised 2σ of :func:`ident.refine._effect_parameters` (the hyper-parameter's
Jacobian column appended to the fit's regressor, eq. 15) assumes white residuals, all rows
behind the hyper-parameter and a least-squares fit. The refinement's scan chooses the
hyper-parameter's bracket on at most ~8000 of the decimated rows
(:attr:`ident.effects.Columns.fast`; a ripple's period is then searched on every row), the
filtered, decimated residual is autocorrelated, and an IDIM-IV fit's spread is not eq. 15's.

Each replicate leaves one unit out (:func:`ident.robot.uncertainty.jackknife_rows`: a run when
there are at least :data:`~ident.robot.uncertainty.N_BLOCKS` runs, else contiguous blocks of
each), refits the model without the term on the other rows (least squares or IDIM-IV, as the
fit: :func:`ident.refine_lsq.quick_residual`), scans the hyper-parameter again on that
residual (the effect's own scan), refits with the term's columns at the new value and maps
the coefficients to the physical parameters; the spread of the replicates is
:func:`ident.robot.uncertainty.jackknife_spread`'s (sqrt(U - 1) 1.4826 MAD). The caller keeps
the larger of the linearised and the jackknife 2σ per parameter (the robot fit's honest sigma,
docs/robot.md). Pure numerics.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np

from ..refine_lsq import quick_residual
from ..robot.uncertainty import jackknife_rows, jackknife_spread
from ._scan import Columns, Scorer, fast_rows

if TYPE_CHECKING:  # pragma: no cover
    from ..preprocess import Design
    from ._base import Effect

__all__ = ["MIN_REPLICATES", "hyper_jackknife"]

#: Fewest replicates that could be fitted for a jackknife spread (the robot's: 3).
MIN_REPLICATES = 3


def hyper_jackknife(
    term: Effect,
    design: Design,
    names: Sequence[str],
    rescan: Callable[[Columns], Effect],
    physical: Callable[[np.ndarray, Effect], np.ndarray],
) -> np.ndarray | None:
    """Jackknife standard deviations of a term's physical parameters (module doc).

    Parameters
    ----------
    term : Effect
        The fitted term (its columns in ``design``, hyper-parameters at the fit's values).
    design : Design
        The design holding the term's columns (rows, Y, instruments of the fit).
    names : sequence of str
        The fit's kept columns, in its order (the term's among them).
    rescan : callable
        ``rescan(cols) -> Effect``: the effect's hyper-parameter scan on a scorer of the
        replicate's rows, started at the fit's value.
    physical : callable
        ``physical(coef, effect) -> ndarray``: the physical parameters from the term's
        coefficients (in ``term.names()`` order) and the rescanned effect.

    Returns
    -------
    ndarray or None
        One standard deviation per physical parameter; None when the term's columns are not
        all kept or fewer than :data:`MIN_REPLICATES` replicates could be fitted.
    """

    tnames = list(term.names())
    names = list(names)
    if not set(tnames) <= set(names) or len(names) == len(tnames):
        return None
    col = [design.names.index(n) for n in names]
    pos = [names.index(n) for n in tnames]
    other = [i for i in range(len(names)) if i not in pos]
    W = design.W[:, col]
    Z = None if design.Z is None else design.Z[:, col]
    Y = design.Y
    s = design.signals.states()
    # the replicate's term columns: the design's (filtered at full rate) plus the change of
    # the states' columns from the fitted hyper-parameter to the rescanned one
    c0 = term.columns(s)
    groups = [np.flatnonzero(s.experiment == e) for e in np.unique(s.experiment)]
    units, _ = jackknife_rows(groups)
    full = fast_rows(len(Y))
    out = []
    for _, rows in units:
        keep = np.ones(len(Y), dtype=bool)
        keep[rows] = False
        sk = s.take(keep)
        Wk, Yk = W[keep], Y[keep]
        Zk = None if Z is None else Z[keep]
        base = quick_residual(Wk[:, other], Yk, None if Zk is None else Zk[:, other])
        if base is None:
            continue
        # the scan's subsample part reads the fit's own subsample (:attr:`Columns.fast`)
        # less the unit, not a new stride over the replicate's rows: which rows it reads is
        # part of the estimate, and a new subsample would make every replicate another
        # estimator (a ripple's final search reads every row of the replicate)
        sub = None if full is None else np.flatnonzero(np.isin(np.flatnonzero(keep), full))
        e = rescan(Columns(sk, Scorer(Wk[:, other], base[1]), fast_rows=sub))
        delta = e.columns(sk) - c0[keep]
        Wk = Wk.copy()
        Wk[:, pos] += delta
        if Zk is not None:
            Zk = Zk.copy()
            Zk[:, pos] += delta
        fit = quick_residual(Wk, Yk, Zk)
        if fit is None:
            continue
        x = np.asarray(physical(fit[0][pos], e), dtype=float)
        if np.all(np.isfinite(x)):
            out.append(x)
    if len(out) < MIN_REPLICATES:
        return None
    return jackknife_spread(np.asarray(out))
