"""The q_s scan of the paper model (section III.D): the grid, the bounded search, and the
rescan of a fitted model's q_s through its design (:func:`rescan_qs`), whose fast designs
(:class:`_QsDesigns`, :class:`_QsErrors`) rebuild only the columns that carry
E = exp(-|dq|/q_s) and must equal :func:`with_qs`'s, bit for bit (tests/test_qs_rescan.py).

Moved out of :mod:`ident.fitting` (which re-exports the public names: ``qs_grid``,
``with_qs``, ``rescan_qs``, ``QsScan``); :func:`ident.fitting.fit_models` scans q_s with
:func:`_scan` and :func:`qs_grid` on its own fits.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import scipy.optimize

from trajectories.friction import quadrant_products

from . import DataError
from .chain import _decimate_rows
from .models import IdentModel, LoadDependent, QuadrantCoulomb, exp_velocity, power_split
from .preprocess import Design
from .refine_lsq import quick_residual
from .signals import Signals
from .terms import Library, Term

__all__ = ["QsScan", "qs_grid", "rescan_qs", "with_qs", "QS_XTOL", "QS_SEARCH_EVALS",
           "QS_WORKERS"]

#: Resolution of the q_s scan after the grid, on log q_s (1 %).
QS_XTOL = 0.01


def qs_grid(vmax: float, n: int = 13) -> np.ndarray:
    """Candidate q_s for the scan [rad/s]: geometric, 0.5 %..20 % of the maximum velocity
    (the paper's 0.03-0.04 rad/s are 2.5-3.3 % of its 1.2 rad/s)."""
    return vmax * np.geomspace(0.005, 0.2, n)


def with_qs(design: Design, library: Library, q_s: float) -> tuple[Library, Design]:
    """The library and design with every q_s-dependent term (eq. 29: the load-dependent
    and quadrant dry-friction terms) rebuilt for velocity constant ``q_s`` [rad/s]; the other
    columns (rigid body, payload, refinement effects...) are kept as they are.

    Raises
    ------
    DataError
        The library has no q_s-dependent term.
    """
    quad = [t for t in library.terms() if isinstance(t, LoadDependent | QuadrantCoulomb)]
    if not quad:
        raise DataError("model has no q_s-dependent term (load-dependent or quadrant friction)")
    sub = design.without([n for t in quad for n in t.names() if n in design.names])
    terms: list[Term] = []
    for t in library.terms():
        if isinstance(t, LoadDependent):
            t = LoadDependent(t.inner, q_s, t.load)
            sub = sub.with_term(t)
        elif isinstance(t, QuadrantCoulomb):
            t = QuadrantCoulomb(q_s, t.load)
            sub = sub.with_term(t)
        terms.append(t)
    return Library(*terms), sub


def _e_columns(term: Term) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """Column indices of a q_s-dependent term that do not / do depend on q_s: the columns of
    :class:`~ident.models.LoadDependent` and :class:`~ident.models.QuadrantCoulomb` come in
    pairs (x, x E), E = exp(-|dq|/q_s) (eq. 29-30), so the odd ones carry E."""
    n = len(term.names())
    return tuple(range(0, n, 2)), tuple(range(1, n, 2))


class _Some(Term):
    """Columns ``index`` of ``term`` (its names and columns, in that order), the term's
    columns computed once per signals object (``Design.with_term`` asks twice for the
    regressor's columns when the design has instruments)."""

    def __init__(self, term: Term, index: Sequence[int]) -> None:
        self.term = term
        self.index = list(index)
        self._memo: dict[int, tuple[Signals, np.ndarray]] = {}

    def names(self) -> tuple[str, ...]:
        names = self.term.names()
        return tuple(names[i] for i in self.index)

    def columns(self, s: Signals) -> np.ndarray:
        hit = self._memo.get(id(s))
        if hit is None or hit[0] is not s:
            hit = self._memo[id(s)] = (s, self.term.columns(s))
        return hit[1][:, self.index]


class _EColumns(Term):
    """The E columns of a q_s term (:func:`_e_columns`), by the expressions of
    :class:`~ident.models.LoadDependent` and :class:`~ident.models.QuadrantCoulomb` (so the
    same floats; ``tests/test_qs_rescan.py`` checks it), with what does not depend on q_s
    (P+, P-, the inner columns or sign(dq)) kept in ``memo`` per signals object, for every
    q_s of a scan."""

    def __init__(self, term: LoadDependent | QuadrantCoulomb, memo: dict) -> None:
        self.term = term
        self.memo = memo

    def names(self) -> tuple[str, ...]:
        names = self.term.names()
        return tuple(names[i] for i in _e_columns(self.term)[1])

    def columns(self, s: Signals) -> np.ndarray:
        t = self.term
        hit = self.memo.get(id(s))
        if hit is None or hit[0] is not s:
            pp, pm = power_split(s, t.load)
            x = t.inner.columns(s) if isinstance(t, LoadDependent) else s.direction
            hit = self.memo[id(s)] = (s, pp, pm, x)
        _, pp, pm, x = hit
        e = exp_velocity(s, t.q_s)
        if isinstance(t, QuadrantCoulomb):
            return np.column_stack(quadrant_products(x, pp, pm, e, load=False))
        n, k = x.shape
        out = np.empty((n, 2 * k))
        out[:, :k], out[:, k:] = quadrant_products(x, pp[:, None], pm[:, None], e[:, None])
        return out


class _QsDesigns:
    """:func:`with_qs` for many q_s on one design, the same arrays bit for bit, faster: the
    design without the q_s-dependent terms and their columns that do not carry
    E = exp(-|dq|/q_s) are built once; each q_s filters and decimates only the columns with E
    (half of them), then the columns are put in :func:`with_qs`'s order. Filtering and
    decimation act on each column alone (``scipy.signal.sosfiltfilt`` row by row), so a
    column comes out the same whatever columns are built with it
    (``tests/test_qs_rescan.py`` checks the equality)."""

    def __init__(self, design: Design, library: Library) -> None:
        quad = [t for t in library.terms() if isinstance(t, LoadDependent | QuadrantCoulomb)]
        if not quad:
            raise DataError("model has no q_s-dependent term (load-dependent or quadrant "
                            "friction)")
        self.library = library
        self.quad = quad
        base = design.without([n for t in quad for n in t.names() if n in design.names])
        self.base_terms = base.library.terms()
        self.n_base = len(base.names)
        fixed = base
        for t in quad:
            fixed = fixed.with_term(_Some(t, _e_columns(t)[0]))
        self.fixed = fixed
        self.memo: list[dict] = [{} for _ in quad]

    def __call__(self, q_s: float) -> tuple[Library, Design]:
        terms: list[Term] = []
        new: list[Term] = []
        for t in self.library.terms():
            if isinstance(t, LoadDependent):
                t = LoadDependent(t.inner, q_s, t.load)
                new.append(t)
            elif isinstance(t, QuadrantCoulomb):
                t = QuadrantCoulomb(q_s, t.load)
                new.append(t)
            terms.append(t)
        d = self.fixed
        for t, memo in zip(new, self.memo, strict=True):
            d = d.with_term(_EColumns(t, memo))
        # columns now: base, the E-free columns of each term, then their E columns; with_qs
        # has base, then each term's columns in its own order
        nb = self.n_base
        starts_fixed, starts_e, at_f = [], [], nb
        for t in new:
            starts_fixed.append(at_f)
            at_f += len(_e_columns(t)[0])
        at_e = at_f
        for t in new:
            starts_e.append(at_e)
            at_e += len(_e_columns(t)[1])
        perm = list(range(nb))
        for t, f0, e0 in zip(new, starts_fixed, starts_e, strict=True):
            even, odd = _e_columns(t)
            col = [0] * (len(even) + len(odd))
            for k, i in enumerate(even):
                col[i] = f0 + k
            for k, i in enumerate(odd):
                col[i] = e0 + k
            perm += col
        rows = [0, 1, 2, 3] + [4 + i for i in perm]
        # the blocks' decimated rows (4 signal rows, then one per column) follow the columns,
        # as Design.without keeps them
        blocks = [replace(b, dec=b.dec[rows], zdec=None if b.zdec is None else b.zdec[perm])
                  for b in d._blocks]
        out = replace(
            d,
            W=np.ascontiguousarray(d.W[:, perm]),  # C order, as with_term's concatenation
            Z=None if d.Z is None else np.ascontiguousarray(d.Z[:, perm]),
            names=tuple(d.names[i] for i in perm),
            library=Library(*self.base_terms, *new),
            _blocks=blocks,
        )
        return Library(*terms), out


class _QsErrors:
    """The relative error of the full-model fit (no elimination) for one q_s, the same float
    as ``IdentModel(lq).fit(designs(q_s), eliminate=False).rel_error_`` of a
    :class:`_QsDesigns` (``tests/test_qs_rescan.py`` checks it), without building the
    design nor the fit's statistics: each block's E columns are filtered and decimated as
    :meth:`~ident.preprocess.Design.with_term` does (an instrument row only where it
    differs from the regressor's), put beside the fixed columns in the model's order, and
    :func:`ident.refine_lsq.quick_residual` gives the residual. None when that fit would
    drop a column (the caller then fits as usual)."""

    def __init__(self, designs: _QsDesigns, names: Sequence[str]) -> None:
        self.designs = designs
        fixed = designs.fixed
        self.Y = fixed.Y
        self.names = list(names)
        # where each model column comes from: a fixed column, or (term, E column)
        e_names = {}
        for i, t in enumerate(designs.quad):
            odd = _e_columns(t)[1]
            tn = t.names()
            for k, j in enumerate(odd):
                e_names[tn[j]] = (i, k)
        self.source = []
        for n in self.names:
            if n in e_names:
                self.source.append(("e", *e_names[n]))
            elif n in fixed.names:
                self.source.append(("f", fixed.names.index(n), 0))
            else:
                raise DataError(f"rescan_qs: no column for parameter {n}")
        self.zmemo: list[dict] = [{} for _ in designs.quad]

    def __call__(self, q_s: float) -> float | None:
        d = self.designs
        fixed = d.fixed
        new = [LoadDependent(t.inner, q_s, t.load) if isinstance(t, LoadDependent)
               else QuadrantCoulomb(q_s, t.load) for t in d.quad]
        wcols: list[list[np.ndarray]] = [[] for _ in new]
        zcols: list[list[np.ndarray]] = [[] for _ in new]
        with_z = fixed.Z is not None
        for b in fixed._blocks:
            for i, t in enumerate(new):
                term = _EColumns(t, d.memo[i])
                wc = term.columns(b.full)
                rows, _ = _decimate_rows(np.ascontiguousarray(wc.T), fixed.decimation)
                wcols[i].append(rows[:, b.mask].T)
                if with_z and b.zfull is not None and b.zdec is not None:
                    zc = _EColumns(t, self.zmemo[i]).columns(b.zfull)
                    zrows = rows.copy()
                    diff = [(k, np.ascontiguousarray(zc[:, k])) for k in range(zc.shape[1])
                            if not np.array_equal(zc[:, k], wc[:, k])]
                    if diff:
                        zd, _ = _decimate_rows(np.stack([r for _, r in diff]),
                                               fixed.decimation)
                        for j, (k, _) in enumerate(diff):
                            zrows[k] = zd[j]
                    zcols[i].append(zrows[:, b.mask].T)
        E = [np.concatenate(c, axis=0) for c in wcols]
        EZ = [np.concatenate(c, axis=0) for c in zcols] if with_z else None
        n, p = self.Y.shape[0], len(self.names)
        W = np.empty((n, p))
        Z = np.empty((n, p)) if with_z else None
        for j, (kind, a, k) in enumerate(self.source):
            if kind == "f":
                W[:, j] = fixed.W[:, a]
                if Z is not None:
                    Z[:, j] = fixed.Z[:, a]
            else:
                W[:, j] = E[a][:, k]
                if Z is not None and EZ is not None:
                    Z[:, j] = EZ[a][:, k]
        out = quick_residual(W, self.Y, Z)
        return None if out is None else out[2]


@dataclass
class QsScan:
    """Result of :func:`rescan_qs`.

    Attributes
    ----------
    q_s : float
        Velocity constant with the smallest residual [rad/s].
    model : IdentModel
        The model refitted with it (same estimator: IV when the design has instruments).
    design : Design
        The design with the q_s-dependent columns for ``q_s``.
    scan : list of (q_s, rel_error)
        Every evaluated q_s, sorted.
    """

    q_s: float
    model: IdentModel
    design: Design
    scan: list[tuple[float, float]]


#: Typical number of evaluations of the bounded search after the grid (for progress bars).
QS_SEARCH_EVALS = 10
#: Threads scoring the q_s grid of :func:`rescan_qs` (the VM has two cores).
QS_WORKERS = 2


def _scan(err: Any, grid: np.ndarray) -> None:
    """Evaluate ``err`` on ``grid``, then refine the minimum between its grid neighbours on
    log q_s (bounded 1-D search to :data:`QS_XTOL`)."""
    errs = [err(float(q)) for q in grid]
    k = int(np.argmin(errs))
    if 0 < k < grid.size - 1:
        scipy.optimize.minimize_scalar(
            lambda x: err(float(np.exp(x))),
            bounds=(float(np.log(grid[k - 1])), float(np.log(grid[k + 1]))),
            method="bounded",
            options={"xatol": QS_XTOL},
        )


def rescan_qs(
    design: Design,
    model: IdentModel,
    *,
    vmax: float,
    n_grid: int = 13,
    progress: Callable[[int, int, float, float], None] | None = None,
) -> QsScan:
    """Choose q_s again for a fitted model, e.g. after refinement added undeclared effects.

    :func:`fit_models` scans q_s (``q_s="scan"``) with the declared model only; an undeclared
    effect left in the residual then shifts the minimum (the quick demo's position ripple:
    q_s 0.038 instead of 0.030, the b terms of eq. 42 40-50 % off; with the ripple
    modelled the minimum is at 0.031). This repeats the scan (grid of :func:`qs_grid`, then a
    bounded search) with every term of ``model`` (the effects included), full model
    without elimination.

    Parameters
    ----------
    design : Design
        The design the model was fitted on (e.g. ``Refinement.final_design``).
    model : IdentModel
        The fitted model (e.g. ``Refinement.final_model``).
    vmax : float
        Maximum |dq| [rad/s] (``FitReport.vmax``), for the grid.
    n_grid : int
        Grid points.

    progress : callable, optional
        Called after each fit as ``progress(done, expected, q_s, rel_error)``; ``expected``
        is an estimate (the grid plus a typical bounded search).

    Returns
    -------
    QsScan
    """
    lib = model.library
    found: dict[float, tuple[IdentModel, Design]] = {}
    scan: list[tuple[float, float]] = []
    designs = _QsDesigns(design, lib)  # = with_qs(design, lib, q), faster
    quick = _QsErrors(designs, lib.names())  # the fit's error only, the same float

    def fit(q: float) -> tuple[IdentModel, Design]:
        lq, dq_ = designs(q)
        return IdentModel(lq, model.name).fit(dq_, eliminate=False), dq_

    grid = qs_grid(vmax, n_grid)
    ahead: dict[float, Future] = {}

    def err(q: float) -> float:
        f = ahead.pop(q, None)
        e = f.result() if f is not None else quick(q)
        if e is None:  # a column would be dropped: the fit decides which
            found[q] = fit(q)
            e = found[q][0].rel_error_
        scan.append((q, e))
        if progress is not None:
            progress(len(scan), n_grid + QS_SEARCH_EVALS, q, e)
        return e

    # the grid's errors are independent: two at a time (the filters and the factorisations
    # release the GIL), taken in grid order; the same floats as one at a time
    with ThreadPoolExecutor(max_workers=QS_WORKERS) as pool:
        ahead.update({float(q): pool.submit(quick, float(q)) for q in grid})
        try:
            _scan(err, grid)
        finally:
            for f in ahead.values():
                f.cancel()
    scan.sort()
    best = min(scan, key=lambda x: x[1])[0]
    m, d = found[best] if best in found else fit(best)
    return QsScan(q_s=best, model=m, design=d, scan=scan)
