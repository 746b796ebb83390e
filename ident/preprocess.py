"""The single joint's adapter of the chain: the decimated, selected system Y = W chi + rho.

:func:`build_design` runs :func:`ident.chain.run_chain` (the one chain from one joint to n:
torque delay, zero-phase low-pass of q, central differences, the columns at full rate, edge
trimming, parallel filtering and decimation of the torque and every column, selection; paper
section IV.B) with the column builder of an :class:`ident.terms.Library` (one axis), and packs
its result in a :class:`Design`:

- the columns W of the terms are built on :class:`~ident.signals.Signals` holding the
  filtered full-rate q, dq, ddq and the low-passed tau (for sign(P) = sign(tau dq), eq. 26);
- the selection adds, to the chain's stiction area |dq| < ``dq_min``, the small torques
  |tau| < ``tau_min`` and, with a ``load_model``, the samples where sign(tau) is not the
  load model's (:func:`ident.chain.rejected`: the rule of the robot fit's sign check too,
  :func:`ident.robot.design.sign_checked`);
- the instruments Z of the IDIM-IV estimator (:func:`ident.estimate.fit_instrumental`) are
  the same columns with the measured acceleration replaced by the reference trajectory's
  (``reference``: the planned position, processed exactly as q), filtered, decimated and
  selected like W (only the columns that differ are filtered twice).

The chain's functions (:func:`~ident.chain.lowpass`, :func:`~ident.chain.decimate`,
:func:`~ident.chain.choose_cutoff`, ...) are importable from here too. Pure numerics: no file
access.

(Past 600 lines: the :class:`Design` and its two builders, :func:`build_design` and
:func:`design_on_full_rate` (which now takes the robot chain's decimated columns), share the
private block assembly and selection; the ``Design`` class could move to a module of its own.)
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from . import DataError
from .chain import (
    BUTTER_ORDER,
    CUTOFF_FLOOR_IV,
    TORQUE_DELAY,
    ChainSettings,
    FullRate,
    RawExperiment,
    _antialias,
    _decimate_rows,
    _factors,
    chain_blocks,
    choose_cutoff,
    decimate,
    decimation_index,
    default_rates,
    default_torque_delay,
    diffcent,
    filter_chain,
    guarded_keep,
    lowpass,
    rejected,
    resolve_settings,
    selection,
    shift,
)
from .signals import Signals
from .terms import Library, Term

__all__ = [
    "Design",
    "build_design",
    "check_reference",
    "design_on_full_rate",
    "diffcent",
    "lowpass",
    "decimate",
    "choose_cutoff",
    "split_experiments",
    "shift",
    "BUTTER_ORDER",
    "TORQUE_DELAY",
    "CUTOFF_FLOOR_IV",
    "decimation_index",
    "default_rates",
    "default_torque_delay",
    "guarded_keep",
    "_antialias",
    "_decimate_rows",
    "_factors",
]


def split_experiments(s: Signals) -> list[slice]:
    """Contiguous blocks of equal ``experiment`` index, as slices."""
    e = np.asarray(s.experiment)
    if e.size == 0:
        return []
    cuts = np.flatnonzero(np.diff(e) != 0) + 1
    bounds = np.concatenate([[0], cuts, [e.size]])
    return [slice(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]


def _dt(t: np.ndarray) -> float:
    d = np.diff(t)
    if d.size == 0 or not np.all(d > 0):
        raise DataError("time must be strictly increasing within each experiment")
    return float(np.median(d))


@dataclass
class _Block:
    """One experiment: full-rate filtered signals, decimated rows, selection."""

    sub: Signals  # raw samples after edge trim
    full: Signals  # filtered q, dq, ddq; tau low-passed (for sign P); after edge trim
    index: np.ndarray  # indices kept by decimation (into full)
    dec: np.ndarray  # decimated rows (4 + b, m): tau, q, dq, ddq, then the design's columns
    mask: np.ndarray  # selection on the decimated samples
    zfull: Signals | None = None  # ``full`` with the reference acceleration (instruments)
    zdec: np.ndarray | None = None  # decimated instrument rows (b, m), same order as columns
    load: np.ndarray | None = None  # the load model's tau_out_hat at full rate [N m], or None


def _assemble(blocks: list[_Block], n_par: int, revolute: bool) -> tuple:
    """Y, W, decimated signals, Z (or None) from the blocks' decimated rows and masks."""
    ys, ws, zs, sigs = [], [], [], []
    for b in blocks:
        m = b.mask
        y = b.dec[0, m]
        ys.append(y)
        ws.append(b.dec[4:, m].T)
        if b.zdec is not None:
            zs.append(b.zdec[:, m].T)
        picked = b.sub.take(b.index[m])
        sigs.append(replace(picked, q=b.dec[1, m], dq=b.dec[2, m], ddq=b.dec[3, m], tau=y))
    Y = np.concatenate(ys)
    if Y.size <= n_par:
        raise DataError(
            f"{Y.size} samples left after selection for {n_par} parameters; "
            "lower dq_min/tau_min or the decimation"
        )
    dsig = Signals(
        t=np.concatenate([s.t for s in sigs]),
        q=np.concatenate([s.q for s in sigs]),
        dq=np.concatenate([s.dq for s in sigs]),
        ddq=np.concatenate([s.ddq for s in sigs]),
        tau=Y,
        payload_mass=np.concatenate([s.payload_mass for s in sigs]),
        payload_arm=np.concatenate([s.payload_arm for s in sigs]),
        experiment=np.concatenate([s.experiment for s in sigs]),
        revolute=revolute,
        # other variables (other joints' states) are picked at the kept instants, not
        # anti-alias filtered: slow signals, see Signals.extra
        extra=None if sigs[0].extra is None else {
            k: np.concatenate([s.extra[k] for s in sigs]) for k in sigs[0].extra},
    )
    Z = np.concatenate(zs, axis=0) if zs else None
    return Y, np.concatenate(ws, axis=0), dsig, Z


@dataclass
class Design:
    """The decimated, selected system Y = W chi + rho (eq. 11, 36).

    Attributes
    ----------
    Y : ndarray, shape (m,)
        Decimated motor torque [N m].
    W : ndarray, shape (m, b)
        Decimated regressor columns, in the order of ``names``.
    names : tuple[str, ...]
        Parameter name of each column.
    library : Library
        The terms that built the columns.
    signals : Signals
        Decimated and selected signals (q, dq, ddq from the filtered position, tau = Y, t,
        payload, experiment) for diagnosis and velocity bands.
    cutoff_hz, decimation, trim, dq_min, tau_min, guard, torque_delay
        The preprocessing settings used.
    Z : ndarray, shape (m, b) or None
        Instruments of the IDIM-IV estimator, column for column with ``W`` (built with the
        reference trajectory's acceleration), or None when no reference was given.
    """

    Y: np.ndarray
    W: np.ndarray
    names: tuple[str, ...]
    library: Library
    signals: Signals
    cutoff_hz: float
    decimation: int
    trim: int
    dq_min: float | None
    tau_min: float | None
    guard: int = 0
    torque_delay: float = 0.0
    Z: np.ndarray | None = field(default=None, repr=False)
    _blocks: list[_Block] = field(default_factory=list, repr=False)

    def __len__(self) -> int:
        return int(self.Y.shape[0])

    def settings(self) -> dict[str, float | int | None]:
        """The preprocessing settings, for reports."""
        return {
            "cutoff_hz": self.cutoff_hz,
            "decimation": self.decimation,
            "trim": self.trim,
            "dq_min": self.dq_min,
            "tau_min": self.tau_min,
            "guard": self.guard,
            "torque_delay": self.torque_delay,
            "instruments": "reference" if self.Z is not None else None,
            "samples": len(self),
        }

    def with_term(self, term: Term, *, states_only: bool = False,
                  decimated: Sequence[Mapping[str, tuple[np.ndarray, np.ndarray | None]]]
                  | None = None) -> Design:
        """A new design with ``term``'s columns appended.

        The columns are computed on the same full-rate filtered signals, filtered,
        decimated and selected exactly as the existing ones. With ``states_only`` (every
        refinement candidate) the term sees :meth:`Signals.states` views: its columns cannot
        read the measured torque (:class:`~ident.OutputLeakError` if it tries).

        ``decimated`` gives, per experiment, columns already evaluated, filtered and
        decimated by the same chain with the same quadrant, as in
        :func:`design_on_full_rate`: where every column of ``term`` is given, it is not
        evaluated (e.g. the paper model's columns at another q_s from the robot chain's
        full-rate products, :meth:`ident.one_joint.OneJointProblem.paper_columns`). Not with
        ``states_only`` (given columns may have read the torque).
        """
        new = tuple(term.names())
        clash = set(new) & set(self.names)
        if clash:
            raise DataError(f"parameters {sorted(clash)} are already in the design")
        if decimated is not None and (states_only or len(decimated) != len(self._blocks)):
            raise DataError("with_term: decimated columns are given per experiment of the "
                            f"design ({len(self._blocks)}), and not with states_only")
        blocks, cols, zcols = [], [], []
        for e, b in enumerate(self._blocks):
            given = None if decimated is None else decimated[e]
            if given is not None and all(n in given for n in new):
                rows, zdec = self._given_rows(e, b, new, given)
                if zdec is not None:
                    zcols.append(zdec[-len(new):, b.mask].T)
                blocks.append(replace(b, dec=np.concatenate([b.dec, rows], axis=0),
                                      zdec=zdec))
                cols.append(rows[:, b.mask].T)
                continue
            full = b.full.states() if states_only else b.full
            rows, _ = _decimate_rows(np.ascontiguousarray(term.columns(full).T), self.decimation)
            zdec = None
            if b.zfull is not None and b.zdec is not None:
                zrows = rows.copy()
                zfull = b.zfull.states() if states_only else b.zfull
                diff = _instrument_rows(term.columns(zfull).T, term.columns(full).T, 0)
                if diff:
                    zd, _ = _decimate_rows(np.stack([r for _, r in diff]), self.decimation)
                    for k, (i, _) in enumerate(diff):
                        zrows[i] = zd[k]
                zdec = np.concatenate([b.zdec, zrows], axis=0)
                zcols.append(zrows[:, b.mask].T)
            blocks.append(replace(b, dec=np.concatenate([b.dec, rows], axis=0), zdec=zdec))
            cols.append(rows[:, b.mask].T)
        Z = None
        if self.Z is not None and zcols:
            Z = np.concatenate([self.Z, np.concatenate(zcols, axis=0)], axis=1)
        return replace(
            self,
            W=np.concatenate([self.W, np.concatenate(cols, axis=0)], axis=1),
            Z=Z,
            names=self.names + new,
            library=Library(*self.library.terms(), term),
            _blocks=blocks,
        )

    @staticmethod
    def _given_rows(e: int, b: _Block, names: tuple[str, ...],
                    given: Mapping[str, tuple[np.ndarray, np.ndarray | None]]
                    ) -> tuple[np.ndarray, np.ndarray | None]:
        """Experiment e's decimated rows of ``names`` from ``given`` (:meth:`with_term`), and
        its instrument rows appended to ``b.zdec`` (the same row where no instrument row is
        given), or None without instruments."""
        m = b.index.size
        rows = np.empty((len(names), m))
        zrows = np.empty((len(names), m))
        for j, n in enumerate(names):
            w, z = given[n]
            if np.shape(w) != (m,) or (z is not None and np.shape(z) != (m,)):
                raise DataError(f"experiment {e}: the given column {n} has {np.size(w)} "
                                f"decimated samples, the chain {m}")
            rows[j] = w
            zrows[j] = w if z is None else z
        if b.zfull is None or b.zdec is None:
            return rows, None
        return rows, np.concatenate([b.zdec, zrows], axis=0)

    def reference_acceleration(self) -> np.ndarray | None:
        """The reference trajectory's acceleration on the design's rows, shape (m,)
        [rad/s^2 or m/s^2]: differentiated at full rate, then low-passed, decimated and
        selected as the columns are (what the IDIM-IV instruments read in place of the
        measured ``signals.ddq``); None without instruments."""
        if self.Z is None or any(b.zfull is None for b in self._blocks):
            return None
        out = []
        for b in self._blocks:
            rows, _ = _decimate_rows(np.asarray(b.zfull.ddq, dtype=float)[None, :],
                                     self.decimation)
            out.append(rows[0, b.mask])
        return np.concatenate(out) if out else np.zeros(0)

    def without(self, names: Iterable[str]) -> Design:
        """A new design without the given parameter columns.

        Terms that lose any of their columns leave ``library`` (their remaining columns
        stay in ``W``/``names``).
        """
        drop = set(names)
        unknown = drop - set(self.names)
        if unknown:
            raise DataError(f"parameters {sorted(unknown)} are not in the design")
        keep = [i for i, n in enumerate(self.names) if n not in drop]
        rows = [0, 1, 2, 3] + [4 + i for i in keep]
        terms = [t for t in self.library.terms() if not (set(t.names()) & drop)]
        return replace(
            self,
            W=self.W[:, keep],
            Z=self.Z[:, keep] if self.Z is not None else None,
            names=tuple(self.names[i] for i in keep),
            library=Library(*terms),
            _blocks=[
                replace(b, dec=b.dec[rows], zdec=b.zdec[keep] if b.zdec is not None else None)
                for b in self._blocks
            ],
        )

    def select(
        self,
        *,
        dq_min: float | None = None,
        tau_min: float | None = None,
        load_model: tuple[Term, np.ndarray] | None = None,
        quadrant_band: float | Sequence[np.ndarray] | None = None,
    ) -> Design:
        """The same design with another sample selection (see :func:`build_design`),
        without recomputing or re-filtering any column. ``quadrant_band`` = h [N m]: also
        leave out the rows within the guard of a full-rate sample whose |tau_out_hat| < h,
        tau_out_hat the prediction of the load model the design was built with; or, per
        experiment, the full-rate samples (n_f,) bool the band leaves out, decided with its
        hysteresis over the quadrant passes (:meth:`ident.one_joint.OneJointProblem.
        band_masks`, :mod:`ident.quadrant_band`)."""
        masks = None
        if quadrant_band is not None and not np.isscalar(quadrant_band):
            masks = list(quadrant_band)
            if len(masks) != len(self._blocks) or any(
                    np.shape(m) != (b.full.tau.size,) for m, b in zip(masks, self._blocks,
                                                                      strict=False)):
                raise DataError("quadrant_band: expected one full-rate mask (n_f,) per "
                                f"experiment ({len(self._blocks)})")
        elif quadrant_band is not None and any(b.load is None for b in self._blocks):
            raise DataError("quadrant_band: the design was built without a load model")
        blocks = []
        for i, b in enumerate(self._blocks):
            tau_out = None if load_model is None else _load_torque(b.full, load_model)
            band = (None if quadrant_band is None or masks is not None
                    else (b.load, float(quadrant_band)))  # type: ignore[arg-type]
            bad = rejected(b.full.tau, tau_min=tau_min, load=tau_out, band=band)
            if masks is not None:
                bad = masks[i] if bad is None else bad | masks[i]
            mask = selection(b.full.dq[:, None], dq_min, self.guard, b.index,
                             None if bad is None else bad[:, None])[:, 0]
            blocks.append(replace(b, mask=mask))
        Y, W, dsig, Z = _assemble(blocks, len(self.names), self.signals.revolute)
        return replace(
            self, Y=Y, W=W, Z=Z, signals=dsig, dq_min=dq_min, tau_min=tau_min, _blocks=blocks
        )


def _instrument_rows(zcols: np.ndarray, wcols: np.ndarray, offset: int) -> list:
    """``(offset + i, row)`` for the instrument rows that differ from the regressor's (those
    with the acceleration); the others are shared and decimated once."""
    return [
        (offset + i, np.ascontiguousarray(z))
        for i, (z, w) in enumerate(zip(zcols, wcols, strict=True))
        if not np.array_equal(z, w)
    ]


def _load_torque(full: Signals, load_model: tuple[Term, np.ndarray]) -> np.ndarray:
    """τ̂_out = W_out χ_out of a load model [N m], shape (n,)."""
    term, chi = load_model
    return term.columns(full) @ np.asarray(chi, dtype=float)


def build_design(
    library: Term,
    signals: Signals,
    *,
    decimation: int | None = None,
    cutoff_hz: float | None = None,
    tau_min: float | None = None,
    dq_min: float | None = None,
    trim: int | None = None,
    guard: int | None = None,
    load_model: tuple[Term, np.ndarray] | None = None,
    dq_min_rel: float | None = None,
    torque_delay: float = 0.0,
    reference: np.ndarray | None = None,
    sign_check: bool = True,
) -> Design:
    """Filter, differentiate, build W, decimate in parallel and select (see module doc).

    Parameters
    ----------
    library : Term
        Regressor terms (a :class:`~ident.terms.Library` or one term).
    signals : Signals
        Raw concatenated experiments (``dq``/``ddq`` are recomputed; see
        :func:`ident.loaders.concat`). All experiments share one sampling period.
    decimation : int or None
        Decimation factor r; default round(f_s / cut-off) (the EMPS script's rule:
        ``round(0.8 f_nyq / (2 f_dyn))`` with cut-off 5 f_dyn).
    cutoff_hz : float or None
        Butterworth cut-off on q [Hz]; default :func:`choose_cutoff` of the first experiment,
        at least f_s/20, or :func:`ident.chain.iv_floor` f_s with a ``reference``
        (f_s/8 and at least :data:`~ident.chain.CUTOFF_MIN_IV_HZ` up to 0.4 f_s).
    tau_min : float or None
        Drop decimated samples with |tau| below it [N m] (sign of P unreliable, eq. 26).
    dq_min : float or None
        Drop decimated samples with |dq| below it [rad/s] (stiction area, eq. 26).
    trim : int or None
        Full-rate samples cut at both ends of each experiment (filter edge effects);
        default ceil(3 f_s / cut-off), at least 2 r.
    guard : int or None
        The stiction and small-torque criteria are evaluated at full rate on the filtered
        dq and tau, and every sample within ``guard`` full-rate samples of a rejected one is
        rejected too, so that no kept decimated sample is smeared by the anti-alias filter
        with samples of the stiction area; default 3 r. The first and last ``guard``
        samples of each experiment (edge transients of the decimation filter) are dropped
        too.
    dq_min_rel : float or None
        Set ``dq_min`` to this fraction of the largest |dq| (filtered, full rate, all
        experiments); the resolved value is stored in ``Design.dq_min``.
    load_model : (Term, array) or None
        A model of the load torque, tau_out_hat = W_out chi_out (e.g. the rigid body and
        payload terms with the values of a first fit of the usual model). Samples where
        sign(tau) differs from sign(tau_out_hat) are dropped (with the guard): there the
        proxy sign(P) = sign(tau dq) of eq. 26 is not sign(P_out) (the friction exceeds
        the load, the paper's "stiction area" rectangle of Fig. 2.b). The quadrant of the
        paper model's columns is then sign(tau_out_hat dq) (the same on the kept rows).
    sign_check : bool
        With ``load_model``: drop those samples (default). False: keep them; the load model
        only decides the quadrant (where the sign check would keep too few samples: a joint
        whose friction exceeds its load over much of the motion, where eq. 26's sign(tau dq)
        is not the quadrant).
    torque_delay : float
        Instant the torque of sample k refers to, after the position sample, in samples
        (0 <= d < 1); q is interpolated there (step 0 of the module doc). 0 (default)
        leaves q as sampled; :data:`TORQUE_DELAY` for zero-order-held commands.
    reference : ndarray, shape (n,), or None
        Reference (planned) position of every sample [rad or m], concatenated like
        ``signals``. When given, the design carries the instruments ``Z`` of the IDIM-IV
        estimator: the same columns computed with the measured q and dq (sign(P) from the
        measured tau) and the acceleration of the reference, which is free of the
        applied-torque noise that the closed loop puts into the measured motion but not
        into the logged torque reference.

    Returns
    -------
    Design

    Raises
    ------
    DataError
        Too few samples left, bad settings.
    """
    lib = library if isinstance(library, Library) else Library(library)
    slices = split_experiments(signals)
    if not slices:
        raise DataError("no samples to identify from")
    dts = [_dt(signals.t[sl]) for sl in slices]
    dt = dts[0]
    if max(abs(d - dt) for d in dts) > 0.01 * dt:
        raise DataError("experiments have different sampling periods; resample them first")
    settings = resolve_settings(signals.q[slices[0]], dt, instruments=reference is not None,
                                cutoff_hz=cutoff_hz, decimation=decimation, trim=trim,
                                guard=guard, torque_delay=torque_delay, dq_min=dq_min)
    if reference is not None:
        reference = np.asarray(reference, dtype=float).ravel()
        if reference.shape != signals.q.shape:
            raise DataError(
                f"reference has {reference.size} samples, expected {signals.q.size} (one per "
                "position sample)"
            )
        check_reference(reference, signals)
    experiments = [
        RawExperiment(f"experiment {int(signals.experiment[sl.start])}", signals.q[sl, None],
                      signals.tau[sl, None], None if reference is None else reference[sl, None])
        for sl in slices
    ]
    fulls, dq_min = filter_chain(experiments, dt, settings, instruments=reference is not None,
                                 dq_min_rel=dq_min_rel)
    return design_on_full_rate(lib, signals, fulls, settings, dq_min, tau_min=tau_min,
                               load_model=load_model, sign_check=sign_check)


def check_reference(reference: np.ndarray, signals: Signals,
                    sources: Sequence[str] | None = None) -> None:
    """The reference positions (IDIM-IV), one per sample of ``signals``, must be finite.

    Raises
    ------
    DataError
        One line: how many values are NaN/inf and the experiment of the first (its
        ``sources`` name, e.g. the file, else its index).
    """
    bad = ~np.isfinite(reference)
    if bad.any():
        where = int(signals.experiment[int(np.argmax(bad))])
        name = (sources[where] if sources is not None and where < len(sources)
                else f"experiment {where}")
        raise DataError(f"references: {int(bad.sum())} NaN/inf values (first in {name}; the "
                        "log lacks setpoints for some cycles): give finite references or "
                        "references=None (least squares)")


def _check_extra(signals: Signals) -> None:
    """The extra signals (other joints' states, read by refinement terms) must be one finite
    value per position sample."""
    for k, v in (signals.extra or {}).items():
        if np.shape(v) != signals.q.shape or not np.all(np.isfinite(v)):
            raise DataError(f"signals.extra[{k!r}]: expected {signals.q.size} finite values "
                            "(one per position sample)")


def design_on_full_rate(
    library: Term,
    signals: Signals,
    fulls: Sequence[FullRate],
    settings: ChainSettings,
    dq_min: float | None,
    *,
    tau_min: float | None = None,
    load_model: tuple[Term, np.ndarray] | None = None,
    sign_check: bool = True,
    decimated: Sequence[Mapping[str, tuple[np.ndarray, np.ndarray | None]]] | None = None,
    loads: Sequence[np.ndarray] | None = None,
) -> Design:
    """The design of ``library`` on experiments already filtered at full rate: the second
    half of :func:`build_design` (columns, parallel decimation, selection;
    :func:`ident.chain.chain_blocks`).

    ``fulls`` are the chain's full-rate signals of each experiment of ``signals``
    (:func:`ident.chain.filter_chain` with ``settings``; e.g. those the robot chain of the
    same joint kept, :class:`ident.one_joint.OneJointProblem`): the design then equals
    :func:`build_design`'s with the same settings, without filtering the data again. With
    ``fulls`` carrying the reference's acceleration (``ref_ddq``) it has the IDIM-IV
    instruments. ``dq_min`` [rad/s] is the resolved stiction threshold; ``tau_min``,
    ``load_model``, ``sign_check`` as in :func:`build_design`.

    ``decimated`` gives, per experiment, columns already evaluated, filtered and decimated
    by the same chain: parameter name -> (its row over every decimated sample of the
    experiment, the instrument row or None). A term whose every column is given is not
    evaluated again (e.g. the rigid body, payload, Coulomb and viscous columns of the robot
    chain of the same joint, :meth:`ident.one_joint.OneJointProblem.design`: one evaluation
    of the 1-dof regressor feeds the robot fit and the design); the decimation filters each
    row on its own, so the rows are those the term would give.

    ``loads`` gives, per experiment, the ``load_model``'s prediction tau_out_hat at full rate
    [N m], shape (n_f,) (e.g. the robot fit's, :meth:`ident.one_joint.OneJointProblem.design`),
    instead of evaluating its terms; without it the load model is evaluated once per
    experiment. It decides the quadrant sign(tau_out_hat dq) and the sign check.

    Raises
    ------
    DataError
        ``fulls`` do not match the experiments of ``signals`` (or ``loads`` them);
        non-finite extra signals.
    """
    lib = library if isinstance(library, Library) else Library(library)
    _check_extra(signals)
    slices = split_experiments(signals)
    if len(fulls) != len(slices):
        raise DataError(f"{len(fulls)} full-rate experiments given for the {len(slices)} "
                        "experiments of the signals")
    if loads is not None and (load_model is None or len(loads) != len(fulls)
                              or any(np.shape(x) != (f.n,) for x, f in zip(loads, fulls,
                                                                           strict=False))):
        raise DataError("loads: expected one full-rate load prediction (n_f,) per experiment "
                        "of a load_model")
    for i, (sl, f) in enumerate(zip(slices, fulls, strict=True)):
        if len(range(sl.start, sl.stop)[f.keep]) != f.n:
            raise DataError(f"experiment {i}: {sl.stop - sl.start} samples, its full-rate "
                            f"signals keep {f.n} after the trim {f.keep}: not its chain")
    b = len(lib.names())
    made: list[tuple[Signals, Signals, Signals | None, list[int], np.ndarray | None]] = []
    given = [{} for _ in fulls] if decimated is None else list(decimated)
    if len(given) != len(fulls):
        raise DataError(f"{len(given)} experiments of decimated columns given for "
                        f"{len(fulls)}")
    # per experiment: the terms evaluated here (the others' rows are given) and their rows
    own: list[list[tuple[Term, slice]]] = [
        [(t, tsl) for t, tsl in lib.slices() if not all(n in g for n in t.names())]
        for g in given]

    def columns(i: int, f: FullRate) -> tuple[list[np.ndarray], np.ndarray | None]:
        """The library's columns of experiment i (and the instrument rows that differ)."""
        sl = slices[i]
        sub = signals.take(np.arange(sl.start, sl.stop)[f.keep])
        full = replace(sub, q=f.q[:, 0], dq=f.dq[:, 0], ddq=f.ddq[:, 0], tau=f.tau_f[:, 0])
        tau_out = None
        if load_model is not None:
            # the quadrant of eq. 27-28 from the model of the load, not from the measured
            # torque: the columns read no output (equal to eq. 26's proxy on the kept rows)
            tau_out = (_load_torque(full, load_model) if loads is None
                       else np.asarray(loads[i], dtype=float))
            full = replace(full, quadrant=np.sign(tau_out * full.dq))
        zfull = None if f.ref_ddq is None else replace(full, ddq=f.ref_ddq[:, 0])
        terms = own[i]
        cols = np.empty((sum(tsl.stop - tsl.start for _, tsl in terms), f.n))
        zrows: list[tuple[int, np.ndarray]] = []
        at = 0
        for term, tsl in terms:
            c = term.columns(full).T
            cols[at:at + c.shape[0]] = c
            if zfull is not None:
                zrows += _instrument_rows(term.columns(zfull).T, c, tsl.start)
            at += c.shape[0]
        made.append((sub, full, zfull, [j for j, _ in zrows], tau_out))
        rows = [cols, np.stack([r for _, r in zrows])] if zrows else [cols]
        bad = rejected(full.tau, tau_min=tau_min, load=tau_out if sign_check else None)
        return rows, None if bad is None else bad[:, None]

    chained = chain_blocks(fulls, settings, dq_min, columns)
    blocks: list[_Block] = []
    names = lib.names()
    for e, (c, (sub, full, zfull, zrows, load)) in enumerate(zip(chained, made, strict=True)):
        m = c.index.size
        dec = np.empty((4 + b, m))
        dec[:4] = c.dec[:4]
        at = 4
        for _, tsl in own[e]:  # the rows evaluated here, in the library's order
            dec[4 + tsl.start : 4 + tsl.stop] = c.dec[at : at + tsl.stop - tsl.start]
            at += tsl.stop - tsl.start
        zdec = None
        if zfull is not None:
            zdec = dec[4:].copy()
            for k, i in enumerate(zrows):
                zdec[i] = c.dec[at + k]
        for j, n in enumerate(names):  # the given rows
            if n not in given[e]:
                continue
            w, z = given[e][n]
            if np.shape(w) != (m,):
                raise DataError(f"experiment {e}: the given column {n} has {np.size(w)} "
                                f"decimated samples, the chain {m}")
            dec[4 + j] = w
            if zdec is not None:
                zdec[j] = w if z is None else z
        blocks.append(_Block(sub=sub, full=full, index=c.index, dec=dec, mask=c.keep[:, 0],
                             zfull=zfull, zdec=zdec, load=load))
    Y, W, dsig, Z = _assemble(blocks, b, signals.revolute)
    return Design(Y=Y, W=W, names=tuple(lib.names()), library=lib, signals=dsig, Z=Z,
                  cutoff_hz=settings.cutoff_hz, decimation=settings.decimation,
                  trim=settings.trim, dq_min=dq_min, tau_min=tau_min, guard=settings.guard,
                  torque_delay=settings.torque_delay, _blocks=blocks)
