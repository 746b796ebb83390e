"""The robot's adapter of the one chain (``chain="columns"``, ``jointid fit --robot``).

:func:`design_runs` runs :func:`ident.chain.run_chain` -- the chain
:func:`ident.preprocess.build_design` runs for one joint, with the same settings
(:func:`ident.chain.resolve_settings`) -- with the n-dof regressor as its column builder:

- the standard regressor ``RobotRegressor.rigid_kpn``, the known torque (payload, and the
  known rotors' Ia_j ddq_j with ``known_rotor_inertia``), sign(dq) and the filtered reference
  position are built at full rate on the filtered states (and, for IDIM-IV, the regressor
  and the known torque with the reference trajectory's acceleration), then filtered and
  decimated in parallel with the torque (Gautier's parallel filtering, paper section IV.B);
- per joint, the stiction area |dq_j| < dq_min (1 % of the largest full-rate |dq| by
  default) evaluated at full rate and dilated by the guard 3 r, plus the first and last
  guard samples, leave joint j's decimated rows out (:attr:`RobotColumns.keep`).

On a robot with one moving joint this is exactly the single-joint design (the RX130L joint 3
of the demo gives the single-joint ``jointid fit`` numbers, ``tests/test_robot_design.py``).
The estimator reads the decimated columns instead of evaluating the regressor on decimated
states (``chain="states"``, :func:`ident.robot.loaders.preprocess_runs`). The paper model
takes E_j and the quadrant on the decimated samples, unless :func:`products_columns` formed
eq. 42's quadrant and E products at full rate, as the single-joint chain does (P from a
first usual fit's tau_out_hat, after :func:`sign_checked`); ``RobotModel(model="paper",
form="products")`` then reads them (``RobotColumns.products``) and on a one-joint robot gives
the single-joint paper fit. Memory: the full-rate regressor of one experiment, k p (1 + IV)
floats per sample, refused above :data:`MAX_BYTES` (:func:`products_columns`: its own
bound, in its doc).

With ``keep_full`` the full-rate regressor and known torque the chain evaluated are kept
too, per run, up to :data:`MAX_BYTES` over all runs (:class:`FullRateColumns`, in
``RobotColumns.full_columns``): :func:`products_columns` then reads them instead of
evaluating the regressor on the same full-rate signals again (a run past the bound is
evaluated again: the same floats), :func:`full_rate_loads` hands them to the load model
(:meth:`FullRateColumns.signals`: ``RobotModel.load_torque`` reads them), and another chain
on some of the same runs and settings takes them (``design_runs(reuse=...)``): on the single
joint (:class:`ident.one_joint.OneJointProblem`) the regressor is evaluated once per run.

(Past 600 lines: the column builder, the sign check, the full-rate products and the kept
full-rate regressor they share read the same runs' full-rate signals, in the order a fit
calls them; :func:`joint_columns`, the n-dof refit's hook, could move out.)
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from trajectories.friction import DEFAULT_Q_S, quadrant_products, quadrant_weights, stribeck_exp

from ..chain import (
    ChainSettings,
    FullRate,
    RawExperiment,
    chain_blocks,
    decimate,
    decimation_index,
    filter_experiment,
    keep_rows,
    rejected,
    resolve_settings,
    run_chain,
    selection,
)
from . import RobotIdentError
from .base import base_parameters, placed_payload
from .loaders import RawRobotRun, chain_period
from .refine_joint import joint_term_columns
from .signals import FullRateProducts, ProductsTooLarge, RobotColumns, RobotSignals

__all__ = ["DesignSettings", "FullRateColumns", "FullRateSource", "ProductsTooLarge",
           "design_runs", "joint_columns",
           "resolve_design", "sign_checked", "full_rate_loads",
           "products_columns", "MAX_BYTES", "DQ_MIN_FRACTION"]

#: Default stiction-area threshold: samples with |dq| below this fraction of the largest
#: full-rate velocity (and their neighbours, the guard) are left out (section III.D,
#: eq. 26); the default of the single-joint fit too (:func:`ident.fitting.fit_models`).
DQ_MIN_FRACTION = 0.01

#: Largest full-rate regressor of one experiment the columns chain builds [bytes].
MAX_BYTES = 4 * 2**30

#: Load models whose full-rate products' q_s-free part a design's source keeps
#: (:meth:`FullRateSource.cache`).
SOURCE_CACHES = 4

class FullRateSource:
    """What built a design's columns (:func:`design_runs`: the runs, the regressor, the
    resolved settings), kept on them (``RobotColumns.source``) so that the bilinear paper
    model forms its quadrant and E products at FULL rate with its own load prediction and
    q_s (:meth:`products`), then decimated like the torque -- the measured torque is the
    decimation of the full-rate product, not the product of decimated factors
    (docs/refinement.md section 8.9). Holds references only (the runs' raw arrays)."""

    def __init__(self, runs: Sequence[RawRobotRun], regressor, settings: ChainSettings,
                 instruments: bool) -> None:
        self.runs = tuple(runs)
        self.regressor = regressor
        self.settings = settings
        self.instruments = bool(instruments)
        self._caches: dict = {}

    def cache(self, key: Any) -> tuple[dict, dict]:
        """For a load model and base (``key``), the :func:`products_columns` cache of its
        q_s-free part and a dict for the products formed (the caller's, by q_s); the last
        :data:`SOURCE_CACHES` keys are kept. Memory: about (5 + l_j) n_f floats per run and
        joint per key (:func:`products_columns`'s ``cache``)."""
        got = self._caches.pop(key, None)
        if got is None:
            got = ({}, {})
        self._caches[key] = got  # the most recent last
        while len(self._caches) > SOURCE_CACHES:
            self._caches.pop(next(iter(self._caches)))
        return got

    def band(self, signals: RobotSignals, load_torque: Callable[[RobotSignals], np.ndarray],
             h: np.ndarray) -> np.ndarray:
        """The decimated rows (n, k) bool of ``signals`` (this design's) whose full-rate
        sample's load (``load_torque``) lies outside the quadrant band, |tau_out_hat_j| >=
        ``h[j]`` [N m]: the n-dof paper model's quadrant band at full rate (not dilated by the
        guard: the products blend a neighbouring sample's quadrant as the torque does, and
        dilated the band left out 23 % of the rows of an accelerated joint,
        tests/test_robot_zero_load.py)."""
        h = np.asarray(h, dtype=float)
        out = np.ones(signals.tau.shape, dtype=bool)
        for i, (f, tau_out) in enumerate(full_rate_loads(signals, self.runs, self.settings,
                                                         load_torque)):
            rows = np.flatnonzero(signals.experiment == i)
            out[rows] = keep_rows(np.abs(tau_out) < h[None, :], 0,
                                  decimation_index(f.n, self.settings.decimation))
        return out

    def products(self, signals: RobotSignals, load_torque: Callable[[RobotSignals],
                                                                    np.ndarray],
                 q_s: np.ndarray, *, base=None, instruments: bool = False,
                 cache: dict | None = None) -> RobotSignals:
        """``signals`` (this design's, any ``keep``) carrying the products formed at full rate
        with ``load_torque`` deciding the quadrants and E at ``q_s`` [rad/s] per joint
        (:func:`products_columns`; ``cache``: its q_s-free part, for the same load).

        Raises
        ------
        ProductsTooLarge
            A run's full-rate rows past :data:`MAX_BYTES`.
        """
        return products_columns(signals, self.runs, self.regressor, self.settings,
                                load_torque, q_s, base=base, instruments=instruments,
                                cache=cache)


#: The resolved settings of :func:`design_runs`: the chain's (``dq_min`` None:
#: :data:`ident.fitting.DQ_MIN_FRACTION` of the largest full-rate |dq| of the
#: identification experiments).
DesignSettings = ChainSettings


def resolve_design(
    runs: Sequence[RawRobotRun],
    *,
    instruments: bool = False,
    **given: float | None,
) -> DesignSettings:
    """The settings :func:`design_runs` uses on ``runs``: :func:`ident.chain.resolve_settings`
    on the first run's axes and the common period (the defaults of
    :func:`ident.preprocess.build_design`; the cut-off, when not given, by
    :func:`ident.chain.axes_cutoff`).

    ``given``: ``cutoff_hz``, ``decimation``, ``trim``, ``guard``, ``torque_delay``,
    ``dq_min`` (None: chosen from the data). ``torque_delay`` None:
    :data:`~ident.preprocess.TORQUE_DELAY` when every run is a jointid MCAP log (commands held
    over the next cycle), else 0 (files of unknown timing).
    """
    if not runs:
        raise RobotIdentError("no experiment to preprocess")
    return resolve_settings(runs[0].q, chain_period(runs), instruments=instruments,
                            sources=[run.source for run in runs], error=RobotIdentError,
                            **given)  # type: ignore[arg-type]


def _known_torque(regressor, f: FullRate, acc: np.ndarray, pay) -> np.ndarray:
    """The known torques (n_f, k) [N m] at full rate: the (placed) payload's and the known
    rotors' Ia_j ddq_j (zero unless ``RobotRegressor(known_rotor_inertia=True)``), filtered
    with the columns."""
    k = f.q.shape[1]
    out = (np.asarray(regressor.payload_torque(f.q, f.dq, acc, pay), dtype=float)
           if pay.mass > 0 else np.zeros((f.n, k)))
    if np.any(getattr(regressor, "known_Ia", 0.0)):
        out = out + regressor.known_torque(acc)
    return out


class FullRateColumns:
    """Per run, the regressor's full-rate columns the chain evaluated (:func:`design_runs`
    with ``keep_full``), kept for what reads the same full-rate signals again: the load
    prediction of the sign check and of the quadrants (:meth:`signals`) and the full-rate
    products (:func:`products_columns`). A cache on the design (``RobotColumns.full_columns``),
    keyed on the run's index.

    Memory: per run, the standard regressor (k p floats per full-rate sample) and the known
    torque (k), twice with the instruments; runs are kept while the total stays within
    ``max_bytes`` (default :data:`MAX_BYTES`, the chain's bound on one run's regressor), the
    others are evaluated again where needed (the same floats).

    Attributes
    ----------
    max_bytes : int
        The bound [bytes].
    nbytes : int
        Kept [bytes].
    evaluations : dict of int to int
        Per run, how many times its regressor was evaluated at full rate (the chain's, and
        every evaluation again of a run not kept), counted by the functions of this module
        and by the callers that evaluate a run's regressor themselves (:meth:`count`).
    """

    def __init__(self, max_bytes: int = MAX_BYTES) -> None:
        self.max_bytes = int(max_bytes)
        self.nbytes = 0
        self.evaluations: dict[int, int] = {}
        self._runs: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray | None,
                                    np.ndarray | None]] = {}

    def count(self, i: int) -> None:
        """One more full-rate evaluation of run i's regressor."""
        self.evaluations[i] = self.evaluations.get(i, 0) + 1

    def keep(self, i: int, W: np.ndarray, known: np.ndarray, Wz: np.ndarray | None = None,
             knownz: np.ndarray | None = None) -> bool:
        """Keep run i's standard regressor W (k, p, n_f), known torque (n_f, k) [N m] and
        their instruments (reference acceleration) when they fit in the bound; whether
        kept."""
        need = sum(a.nbytes for a in (W, known, Wz, knownz) if a is not None)
        if i in self._runs or self.nbytes + need > self.max_bytes:
            return False
        self._runs[i] = (W, known, Wz, knownz)
        self.nbytes += need
        return True

    def release(self) -> None:
        """Drop the kept columns (the counts stay): a run read afterwards is evaluated
        again."""
        self._runs.clear()
        self.nbytes = 0

    def get(self, i: int, instruments: bool = False
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None] | None:
        """Run i's (W, known, Wz, knownz) when kept (with the instruments' when asked),
        else None."""
        got = self._runs.get(i)
        if got is None or (instruments and got[2] is None):
            return None
        return got

    def signals(self, i: int, full: RobotSignals) -> RobotSignals:
        """``full`` (run i's full-rate signals, as :func:`full_rate_loads` forms them)
        carrying run i's kept regressor, known torque and sign(dq) as its columns (every
        sample kept), so that a model reading ``RobotSignals.columns``
        (``RobotModel.load_torque``, ``predict``) predicts without evaluating the regressor
        again; ``full`` itself when run i is not kept."""
        got = self.get(i)
        if got is None or got[0].shape[2] != full.n:
            return full
        cols = RobotColumns(W=got[0], p=got[1], sign=np.sign(full.dq),
                            keep=np.broadcast_to(np.True_, (full.n, full.k)))
        return replace(full, columns=cols)


def _experiments(runs: Sequence[RawRobotRun], refs: bool) -> list[RawExperiment]:
    return [RawExperiment(run.source, run.q, run.tau, run.q_ref if refs else None)
            for run in runs]


def design_runs(
    runs: Sequence[RawRobotRun],
    regressor,
    settings: DesignSettings,
    *,
    instruments: bool = False,
    base=None,
    keep_full: bool = False,
    full_bytes: int = MAX_BYTES,
    reuse: Sequence[tuple[FullRate, np.ndarray | None, np.ndarray | None]] | None = None,
) -> tuple[RobotSignals, float]:
    """The chain with the n-dof regressor as column builder (module doc).

    Parameters
    ----------
    runs : sequence of RawRobotRun
        Experiments of the robot (same sampling period), axes in the regressor's order.
    regressor : RobotRegressor
        ``rigid_kpn``, ``payload_torque``, ``joints``, ``p``.
    settings : DesignSettings
        From :func:`resolve_design`.
    instruments : bool
        Also build the IDIM-IV columns (needs every run's ``q_ref``).
    base : BaseParameters or None
        Places a single-joint log's lever-arm payload (``arm_m``); default
        ``base_parameters(regressor)``.
    keep_full : bool
        Keep every run's full-rate signals in ``columns.full`` (read by :func:`sign_checked`,
        :func:`products_columns` and :func:`ident.preprocess.design_on_full_rate` instead of
        filtering the runs again), and its full-rate regressor and known torque in
        ``columns.full_columns`` within ``full_bytes`` (:class:`FullRateColumns`).
    full_bytes : int
        The bound of those kept columns over all runs [bytes] (default :data:`MAX_BYTES`).
    reuse : sequence or None
        Per run, (its full-rate signals as the chain filtered it with these ``settings``, its
        standard regressor W (k, p, n_f) or None, W with the reference's acceleration or
        None): what an earlier chain on the same runs and settings kept (e.g. Table IV's fit
        without payload on some runs of the fit, :func:`ident.fitting.fit_models`); the runs
        are then not filtered again, nor their regressor evaluated where given.

    Returns
    -------
    signals : RobotSignals
        Decimated t, q, dq, ddq (filtered), tau (raw torque decimated, the paper's Y),
        q_ref (filtered, decimated) when every run has one, and :class:`RobotColumns`.
    dq_min : float
        The stiction threshold used [rad/s].

    Raises
    ------
    RobotIdentError
        Too short experiments, missing references, a regressor too large for memory.
    """
    if not runs:
        raise RobotIdentError("no experiment to preprocess")
    joints = tuple(regressor.joints)
    k, p = len(joints), int(regressor.p)
    has_ref = all(run.q_ref is not None for run in runs)
    if instruments and not has_ref:
        missing = next(run.source for run in runs if run.q_ref is None)
        raise RobotIdentError(f"{missing}: no reference trajectory q_ref for the IDIM-IV "
                              "instruments")
    dt = chain_period(runs)

    def check(_: int, exp: RawExperiment) -> None:
        if exp.q.shape[1] != k:
            raise RobotIdentError(f"{exp.label}: {exp.q.shape[1]} axes, expected {k} "
                                  f"({', '.join(joints)})")
        need = (exp.q.shape[0] - 2 * settings.trim) * k * p * 8 * (2 if instruments else 1)
        if need > MAX_BYTES:
            raise RobotIdentError(f"{exp.label}: the full-rate regressor needs "
                                  f"{need / 2**30:.1f} GiB (more than {MAX_BYTES / 2**30:.0f});"
                                  " use the states chain (--chain states) or split the log")

    placed: dict = {}  # lever-arm payloads, placed (eq. 34-35)
    kept = FullRateColumns(full_bytes) if keep_full else None

    def columns(i: int, f: FullRate) -> tuple[list[np.ndarray], None]:
        run = runs[i]
        pay = placed_payload(run.payload, regressor, base, run.source, placed)

        def torque(acc: np.ndarray) -> np.ndarray:
            return _known_torque(regressor, f, acc, pay)

        given = (None, None) if reuse is None else reuse[i][1:]
        evaluated = given[0] is None or (instruments and given[1] is None)
        known = torque(f.ddq)
        W = (np.asarray(regressor.rigid_kpn(f.q, f.dq, f.ddq)) if given[0] is None
             else given[0])
        rows = [known.T, np.sign(f.dq).T, W.reshape(k * p, f.n)]
        if has_ref:
            rows.append(f.ref.T)  # type: ignore[union-attr]
        Wz = knownz = None
        if instruments:
            Wz = (np.asarray(regressor.rigid_kpn(f.q, f.dq, f.ref_ddq)) if given[1] is None
                  else given[1])
            knownz = torque(f.ref_ddq)  # type: ignore[arg-type]
            rows += [Wz.reshape(k * p, f.n), knownz.T]
        if kept is not None:
            if evaluated:
                kept.count(i)
            kept.keep(i, W, known, Wz, knownz)
        return rows, None

    if reuse is None:
        blocks, dq_min = run_chain(_experiments(runs, has_ref), dt, settings, columns,
                                   instruments=instruments, dq_min_rel=DQ_MIN_FRACTION,
                                   check=check, error=RobotIdentError)
    else:
        fulls = [f for f, _, _ in reuse]
        t = settings.trim
        if len(fulls) != len(runs) or any(
                f.keep != slice(t, run.q.shape[0] - t if t else run.q.shape[0])
                or (instruments and f.ref_ddq is None)
                for f, run in zip(fulls, runs, strict=False)):
            raise RobotIdentError("design_runs: reuse: expected each run's full-rate signals "
                                  "of these settings")
        dq_min = settings.dq_min  # as ident.chain.filter_chain resolves it
        if dq_min is None:
            dq_min = DQ_MIN_FRACTION * max(float(np.max(np.abs(f.dq))) for f in fulls)
        blocks = chain_blocks(fulls, settings, dq_min, columns)
    parts: dict[str, list[np.ndarray]] = {n: [] for n in (
        "t", "q", "dq", "ddq", "tau", "p", "sign", "keep", "W", "Wz", "pz", "ref", "e")}
    for i, (run, b) in enumerate(zip(runs, blocks, strict=True)):
        m = b.index.size
        for name, x in zip(("tau", "q", "dq", "ddq"), b.states(), strict=True):
            parts[name].append(x)
        cols = b.columns()
        parts["p"].append(cols[0].T)
        parts["sign"].append(cols[1].T)
        parts["W"].append(cols[2].reshape(k, p, m))
        if has_ref:
            parts["ref"].append(cols[3].T)
        if instruments:
            parts["Wz"].append(cols[4].reshape(k, p, m))
            parts["pz"].append(cols[5].T)
        parts["t"].append(run.t[b.full.keep][b.index])
        parts["e"].append(np.full(m, i))
        parts["keep"].append(b.keep)

    def cat(name: str, axis: int = 0) -> np.ndarray:
        return np.ascontiguousarray(np.concatenate(parts[name], axis=axis))

    columns_ = RobotColumns(W=cat("W", 2), p=cat("p"), sign=cat("sign"), keep=cat("keep"),
                            Wz=cat("Wz", 2) if instruments else None,
                            pz=cat("pz") if instruments else None,
                            full=tuple(b.full for b in blocks) if keep_full else None,
                            full_columns=kept,
                            source=FullRateSource(runs, regressor,
                                                  replace(settings, dq_min=float(dq_min)),
                                                  instruments))
    sig = RobotSignals(t=cat("t"), q=cat("q"), dq=cat("dq"), ddq=cat("ddq"), tau=cat("tau"),
                       joints=joints, experiment=cat("e"),
                       payloads=tuple(run.payload for run in runs),
                       q_ref=cat("ref") if has_ref else None,
                       source=", ".join(run.source for run in runs), columns=columns_,
                       sign=columns_.sign)  # (the states path's, without the columns)
    return sig, float(dq_min)  # type: ignore[arg-type]


def _full_rate(cols: RobotColumns, i: int, exp: RawExperiment, dt: float,
               settings: DesignSettings, instruments: bool = False) -> FullRate:
    """Run i's full-rate signals: those the chain kept (``cols.full``, with the reference's
    acceleration when ``instruments``), else :func:`ident.chain.filter_experiment` again."""
    if cols.full is not None and i < len(cols.full):
        f = cols.full[i]
        if not instruments or f.ref_ddq is not None:
            return f
    return filter_experiment(exp, dt, settings, instruments=instruments, error=RobotIdentError)


def sign_checked(
    signals: RobotSignals,
    runs: Sequence[RawRobotRun],
    settings: DesignSettings,
    load_torque: Callable[[RobotSignals], np.ndarray],
    min_kept: float | np.ndarray = 0.0,
    *,
    loads: Sequence[tuple[FullRate, np.ndarray]] | None = None,
) -> tuple[RobotSignals, np.ndarray]:
    """Also leave out the rows where sign(tau_j) differs from sign(tau_out_hat_j), the
    paper's stiction-area rectangle (Fig. 2.b) where eq. 26's proxy sign(P) = sign(tau dq)
    is not sign(P_out): the single-joint ``load_model`` selection of
    :func:`ident.preprocess.build_design`, per joint -- the one rule of both,
    :func:`ident.chain.rejected`.

    Parameters
    ----------
    signals : RobotSignals
        :func:`design_runs`'s output for ``runs`` with ``settings`` (``dq_min`` resolved).
    runs, settings
        What built ``signals``.
    load_torque : callable
        RobotSignals -> tau_out_hat (n, k) [N m], e.g. ``RobotModel.load_torque`` of a first
        usual fit; evaluated at full rate on the filtered states of each run
        (:func:`ident.chain.filter_experiment`).
    min_kept : float or ndarray, shape (k,)
        A joint keeps its rows unchecked when the check would keep less than this fraction
        of them (tau_out near zero over much of the data: no load to compare with); per
        joint when an array (inf: never checked, e.g. validation data checked where the
        identification data were).
    loads : list or None
        :func:`full_rate_loads` of these arguments when the caller has them (not evaluated
        again).

    Returns
    -------
    signals : RobotSignals
        The same columns with the stricter ``keep`` (the low-passed torque's sign is
        compared, at full rate, dilated by the guard) on the checked joints.
    kept : ndarray, shape (k,)
        Per joint, the fraction of its previously kept rows the check keeps (applied where
        >= ``min_kept``).
    """
    cols = signals.columns
    if cols is None or settings.dq_min is None:
        raise RobotIdentError("sign_checked: expected design_runs signals and resolved "
                              "settings (dq_min)")
    keep = cols.keep.copy()
    if loads is None:
        loads = full_rate_loads(signals, runs, settings, load_torque)
    for i, (f, tau_out) in enumerate(loads):
        rows = np.flatnonzero(signals.experiment == i)
        keep[rows] = selection(f.dq, settings.dq_min, settings.guard,
                               decimation_index(f.n, settings.decimation),
                               rejected(f.tau_f, load=tau_out))
    before = cols.keep.sum(axis=0)
    kept = keep.sum(axis=0) / np.maximum(before, 1)
    skip = kept < np.broadcast_to(np.asarray(min_kept, dtype=float), kept.shape)
    keep[:, skip] = cols.keep[:, skip]
    return replace(signals, columns=replace(cols, keep=keep)), kept


def full_rate_loads(signals: RobotSignals, runs: Sequence[RawRobotRun],
                    settings: DesignSettings,
                    load_torque: Callable[[RobotSignals], np.ndarray],
                    ) -> list[tuple[FullRate, np.ndarray]]:
    """Per run of ``signals`` (:func:`design_runs`'s output for ``runs`` with ``settings``):
    its full-rate signals as the chain filtered them and ``load_torque`` on them,
    tau_out_hat (n_f, k) [N m] -- what :func:`sign_checked` compares with the torque and the
    single joint's quadrant band (:meth:`ident.one_joint.OneJointProblem.band`) reads. Where
    the chain kept a run's full-rate regressor (``design_runs(keep_full=True)``), the signals
    handed to ``load_torque`` carry it as their columns (:meth:`FullRateColumns.signals`:
    ``RobotModel.load_torque`` does not evaluate it again, the same floats)."""
    dt = chain_period(runs)
    out = []
    for i, exp in enumerate(_experiments(runs, False)):
        f = _full_rate(signals.columns, i, exp, dt, settings)
        full = RobotSignals(t=runs[i].t[f.keep], q=f.q, dq=f.dq, ddq=f.ddq, tau=f.tau_f,
                            joints=signals.joints, payloads=(runs[i].payload,),
                            source=exp.label)
        kept = signals.columns.full_columns
        if kept is not None:  # the chain's full-rate regressor, not evaluated again
            full = kept.signals(i, full)
        out.append((f, np.asarray(load_torque(full), dtype=float)))
    return out


def _joint_structure(regressor, base) -> list[np.ndarray]:
    """Per joint, the indices into ``base.columns`` of the base parameters' standard columns
    that are not structurally zero in its row: probed at seeded random states, as
    ``RobotModel`` finds each joint's base columns."""
    k = len(regressor.joints)
    rng = np.random.default_rng(12345)
    m = 32
    q = rng.uniform(-np.pi, np.pi, (m, k))
    W = np.asarray(regressor.rigid_kpn(q, rng.normal(size=(m, k)), rng.normal(size=(m, k)),
                                       columns=base.columns))
    mag = np.abs(W).max(axis=2)  # (k, nb)
    tol = 1e-10 * max(float(mag.max()), 1e-300)
    return [np.flatnonzero(mag[j] > tol) for j in range(k)]


def _per_joint(q_s: float | Sequence[float] | Mapping[str, float],
               joints: tuple[str, ...]) -> np.ndarray:
    """q_s [rad/s] per joint from one value, one per joint or a mapping by joint name."""
    if isinstance(q_s, Mapping):
        missing = [j for j in joints if j not in q_s]
        if missing:
            raise RobotIdentError(f"products_columns: q_s has no value for joint(s) {missing}")
        q_s = [q_s[j] for j in joints]
    try:
        out = np.broadcast_to(np.asarray(q_s, dtype=float), (len(joints),)).copy()
    except ValueError:
        raise RobotIdentError(f"products_columns: q_s: expected one value or {len(joints)}, "
                              f"got {np.size(q_s)}") from None
    if not np.all(np.isfinite(out) & (out > 0)):
        raise RobotIdentError(f"products_columns: q_s: expected positive velocities [rad/s], "
                              f"got {out.tolist()}")
    return out


def _products_fixed(exp: RawExperiment, i: int, run: RawRobotRun, cols: RobotColumns,
                    dt: float, settings: DesignSettings, instruments: bool, regressor, base,
                    bcols: np.ndarray, pos: list[np.ndarray], width: list[int],
                    rows: np.ndarray, load_torque: Callable[[RobotSignals], np.ndarray],
                    placed: dict) -> list[tuple]:
    """Run i's part of :func:`products_columns` that does not depend on q_s, per joint j:
    (dq_j, P+_j, P-_j, sign(dq_j), its load rows (l_j + 1, n_f), their instruments or None,
    and the decimated rows P+ w, P- w, P+ sign, P- sign, P+ (then P+ w_z, P- w_z)): what a
    q_s scan would otherwise form and filter again for every q_s."""
    k = len(pos)
    iv = 2 if instruments else 1
    held = sum(iv * (w - 5) // 4 + 4 for w in width)  # every joint's q_s-free rows
    need = (exp.q.shape[0] - 2 * settings.trim) * 8 * (
        iv * k * bcols.size + held + max(width) + (iv - 1) * (max(width) - 5) + 4 * k)
    if need > MAX_BYTES:
        raise ProductsTooLarge(f"{exp.label}: the full-rate products need "
                              f"{need / 2**30:.1f} GiB (more than "
                              f"{MAX_BYTES / 2**30:.0f}); split the log")
    f = _full_rate(cols, i, exp, dt, settings, instruments)
    r = settings.decimation
    if decimation_index(f.n, r).size != rows.size:
        raise RobotIdentError(f"{exp.label}: {rows.size} decimated samples in the "
                              f"signals, the settings give "
                              f"{decimation_index(f.n, r).size}: not design_runs' "
                              "output for these runs and settings")
    full = RobotSignals(t=run.t[f.keep], q=f.q, dq=f.dq, ddq=f.ddq, tau=f.tau_f,
                        joints=tuple(regressor.joints), payloads=(run.payload,),
                        source=exp.label)
    if cols.full_columns is not None:  # the chain's full-rate regressor, not evaluated again
        full = cols.full_columns.signals(i, full)
    tau_out = np.asarray(load_torque(full), dtype=float)
    if tau_out.shape != (f.n, k) or not np.all(np.isfinite(tau_out)):
        raise RobotIdentError(f"{exp.label}: load_torque gave {tau_out.shape} values "
                              f"(finite: {bool(np.all(np.isfinite(tau_out)))}), "
                              f"expected ({f.n}, {k}) finite [N m]")
    kept = None if cols.full_columns is None else cols.full_columns.get(i, instruments)
    at = pos  # joint j's load columns: W[j, at[j]]
    if kept is not None and kept[0].shape[2] == f.n:  # the chain's, not evaluated again
        W, known = kept[0], kept[1]  # standard columns: the base ones picked by index
        Wz, knownz = (kept[2], kept[3]) if instruments else (None, None)
        at = [bcols[c] for c in pos]
    else:
        if cols.full_columns is not None:
            cols.full_columns.count(i)
        pay = placed_payload(run.payload, regressor, base, run.source, placed)
        known = _known_torque(regressor, f, f.ddq, pay)
        W = np.asarray(regressor.rigid_kpn(f.q, f.dq, f.ddq, columns=bcols))
        Wz = knownz = None
        if instruments:
            Wz = np.asarray(regressor.rigid_kpn(f.q, f.dq, f.ref_ddq, columns=bcols))
            knownz = _known_torque(regressor, f, f.ref_ddq, pay)
    out = []
    for j in range(k):
        dq = f.dq[:, j]
        pp, pm = quadrant_weights(tau_out[:, j] * dq)  # P+, P- of eq. 27-28, 1/2 where P = 0
        sg = np.sign(dq)
        load = np.concatenate([W[j, at[j]], known[None, :, j]], axis=0)  # (l + 1, n_f)
        loadz = None
        parts = [*quadrant_products(load, pp, pm), np.stack([*quadrant_products(sg, pp, pm), pp])]
        if Wz is not None and knownz is not None:  # the instruments' load rows
            loadz = np.concatenate([Wz[j, at[j]], knownz[None, :, j]], axis=0)
            parts += [*quadrant_products(loadz, pp, pm)]
        # the chain's filter, row by row (the same floats as in one stack)
        fixed = decimate(np.concatenate(parts).T, r, settings.antialias)[0].T
        out.append((dq, pp, pm, sg, load, loadz, fixed))
    return out


def products_columns(
    signals: RobotSignals,
    runs: Sequence[RawRobotRun],
    regressor,
    settings: DesignSettings,
    load_torque: Callable[[RobotSignals], np.ndarray],
    q_s: float | Sequence[float] | Mapping[str, float] = DEFAULT_Q_S,
    *,
    base=None,
    instruments: bool = False,
    cache: dict | None = None,
) -> RobotSignals:
    """The paper model's eq. 42 columns of every joint formed at FULL rate, then low-passed and
    decimated like the other columns: what the single-joint chain does
    (:func:`ident.preprocess.build_design` with the ``load_model`` of a first usual fit).

    Per run, the chain's full-rate signals are those it kept (``keep_full``) or formed again
    (:func:`ident.chain.filter_experiment`, as :func:`sign_checked` does), and its full-rate
    regressor and known torque those it kept (``RobotColumns.full_columns``) or evaluated
    again; on them, per joint j, with the model
    quadrant P+_j = (1 + sign(tau_out_hat_j dq_j)) / 2 (eq. 27-28, 44; tau_out_hat from
    ``load_torque``), P-_j = 1 - P+_j and E_j = exp(-|dq_j| / q_s,j) (eq. 29): each load
    column w of the joint (its base parameters' standard columns, ``rigid_kpn`` at full rate,
    then its known torque p_j: payload and known rotors) gives P+ w, P+ E w, P- w, -P- E w
    (a_m, b_m, a_g, b_g; eq. 42-43), sign(dq_j) gives P+ sign, P+ E sign, P- sign, P- E sign
    (c_m, d_m, c_g, d_g; eq. 30) (:func:`trajectories.friction.quadrant_products`, as the
    single-joint terms), and P+ itself is kept for the quadrant counts. These rows
    are filtered and decimated by :func:`ident.chain.decimate`, the chain's own anti-alias
    filter and decimation (the same floats as in the chain's stack: the rows are filtered
    independently), so ``RobotModel(model="paper", form="products")`` reads them and gives,
    on a one-joint robot, the single-joint paper fit (tests/test_robot_design.py).

    With ``instruments`` the IDIM-IV instruments of these columns too, as the single-joint
    chain builds them: the load columns with the reference trajectory's acceleration (the
    regressor and the known torque on q, dq and the filtered reference's ddq), times the
    same P and E (decided on the measured states); the Coulomb columns, dq and 1 are their
    own instruments.

    Memory: at full rate, per run, the base regressor (k b floats per sample, b the base
    parameters; none when the chain kept the standard one), every joint's q_s-free rows (its
    load rows, dq, P+, P-, sign: sum_j (l_j + 1) + 4, the load rows twice with
    ``instruments``; kept across q_s with a ``cache``) and one joint's filtered rows (4 (l_j
    + 1) + 5), twice the load parts with ``instruments``; kept, per decimated sample, sum_j
    4 (l_j + 1) + 5 k floats (plus sum_j 4 (l_j + 1) with ``instruments``; l_j: joint j's
    base columns). Refused above :data:`MAX_BYTES` at full rate.

    Parameters
    ----------
    signals : RobotSignals
        :func:`design_runs`'s output for ``runs`` with ``settings`` (``dq_min`` resolved),
        possibly after :func:`sign_checked` (its ``keep`` is kept).
    runs, regressor, settings
        What built ``signals`` (``regressor``: ``rigid_kpn``, ``payload_torque``, ``joints``).
    load_torque : callable
        RobotSignals -> tau_out_hat (n, k) [N m] on full-rate signals, e.g.
        ``RobotModel.load_torque`` of the first usual fit (the one :func:`sign_checked`
        reads): it decides the quadrants.
    q_s : float, sequence or mapping
        q_s of E [rad/s]: one value, one per joint or by joint name; the products form's
        ``q_s`` must be the same.
    base : BaseParameters or None
        Whose columns are formed (default ``base_parameters(regressor)``); the products
        form's ``base`` must be the same (or have the same columns).
    instruments : bool
        Also form the IDIM-IV instruments (needs every run's ``q_ref``).
    cache : dict or None
        Keeps, per run, what does not depend on q_s (the load model's quadrants, the load
        rows at full rate, their decimated P+/P- products): pass the same dict for other q_s
        of the same signals, load model and settings (a q_s scan) and only the E products are
        formed and filtered again. Memory: about (2 + l_j) n_f floats per run and joint.

    Returns
    -------
    RobotSignals
        ``signals`` with ``columns.products`` (:class:`~ident.robot.signals.FullRateProducts`).

    Raises
    ------
    RobotIdentError
        Signals not from ``design_runs``, unresolved settings, runs that do not match the
        signals, a bad ``load_torque`` output, rows too large for memory; one line.
    """
    cols = signals.columns
    if cols is None or settings.dq_min is None:
        raise RobotIdentError("products_columns: expected design_runs signals and resolved "
                              "settings (dq_min)")
    joints = tuple(regressor.joints)
    if tuple(signals.joints) != joints:
        raise RobotIdentError(f"products_columns: signals of joints {signals.joints}, the "
                              f"regressor's are {joints}")
    k = len(joints)
    qs = _per_joint(q_s, joints)
    if base is None:
        base = base_parameters(regressor)
    bcols = np.asarray(base.columns, dtype=int)
    pos = _joint_structure(regressor, base)
    width = [4 * (c.size + 1) + 5 for c in pos]
    if int(signals.experiment.max(initial=-1)) >= len(runs):
        raise RobotIdentError(f"products_columns: the signals have "
                              f"{int(signals.experiment.max()) + 1} experiments, {len(runs)} "
                              "runs given")
    dt = chain_period(runs)
    r = settings.decimation
    n = signals.n
    if instruments:
        missing = next((run.source for run in runs if run.q_ref is None), None)
        if missing is not None:
            raise RobotIdentError(f"{missing}: no reference trajectory q_ref for the IDIM-IV "
                                  "instruments of the full-rate products")
    loads = [np.empty((4, c.size + 1, n)) for c in pos]
    loads_z = [np.empty((4, c.size + 1, n)) for c in pos] if instruments else None
    coulomb = np.empty((4, n, k))
    pplus = np.empty((n, k))
    placed: dict = {}
    for i, exp in enumerate(_experiments(runs, instruments)):
        rows = np.flatnonzero(signals.experiment == i)
        per_joint = None if cache is None else cache.get(i)
        if per_joint is None or len(per_joint) != k or per_joint[0][-1].shape[1] != rows.size:
            per_joint = _products_fixed(exp, i, runs[i], cols, dt, settings, instruments,
                                        regressor, base, bcols, pos, width, rows, load_torque,
                                        placed)
            if cache is not None:
                cache[i] = per_joint
        for j, (dq, pp, pm, sg, load, loadz, fixed) in enumerate(per_joint):
            # the q_s-dependent rows: E = exp(-|dq| / q_s) times the fixed ones
            e = stribeck_exp(dq, qs[j])
            parts = [*quadrant_products(load, pp, pm, e),
                     np.stack(quadrant_products(sg, pp, pm, e, load=False))]
            if loadz is not None:
                parts += [*quadrant_products(loadz, pp, pm, e)]
            dep = decimate(np.concatenate(parts).T, r, settings.antialias)[0].T
            del parts
            nl = pos[j].size + 1
            for block, src, at in ((0, fixed, 0), (1, dep, 0), (2, fixed, nl), (3, dep, nl)):
                loads[j][block, :, rows] = src[at:at + nl].T
            coulomb[0, rows, j], coulomb[2, rows, j] = fixed[2 * nl], fixed[2 * nl + 1]
            coulomb[1, rows, j], coulomb[3, rows, j] = dep[2 * nl], dep[2 * nl + 1]
            pplus[rows, j] = fixed[2 * nl + 2]
            if loads_z is not None:
                for block, src, at in ((0, fixed, 2 * nl + 3), (1, dep, 2 * nl + 2),
                                       (2, fixed, 3 * nl + 3), (3, dep, 3 * nl + 2)):
                    loads_z[j][block, :, rows] = src[at:at + nl].T
    products = FullRateProducts(loads=tuple(loads), coulomb=coulomb, pplus=pplus,
                                cols=tuple(bcols[c] for c in pos), q_s=qs,
                                loads_z=None if loads_z is None else tuple(loads_z))
    return replace(signals, columns=replace(cols, products=products))


def joint_columns(
    signals: RobotSignals,
    prediction: np.ndarray,
    terms: Sequence[tuple[int, Any]],
    revolute: Sequence[bool] | None = None,
) -> list[np.ndarray]:
    """Extra columns of each joint's rows of the stacked n-dof system (the hook of the
    n-dof refit, :mod:`ident.robot.refit`).

    Parameters
    ----------
    signals : RobotSignals
        The samples of the stacked system (n samples, k joints).
    prediction : ndarray, shape (n, k)
        The n-dof model's prediction tau_hat [N m] on them: the load variable of the terms
        (never the measured torque).
    terms : sequence of (int, Term)
        (joint index, single-joint ``ident.terms.Term``), e.g. the steps of
        :func:`ident.robot.refine_joint.refine_joint`.
    revolute : sequence of bool, optional
        Per joint, whether it is revolute (default all).

    Returns
    -------
    list of ndarray
        Per joint j, shape (n, c_j): the columns of its terms side by side, in the order
        given (c_j = 0 without a term), computed from the states only
        (:func:`~ident.robot.refine_joint.joint_term_columns`).
    """
    k = signals.k
    out = [[] for _ in range(k)]
    for j, term in terms:
        if not 0 <= int(j) < k:
            raise RobotIdentError(f"joint_columns: joint index {j} not in 0..{k - 1}")
        rev = True if revolute is None else bool(revolute[int(j)])
        out[int(j)].append(joint_term_columns(signals, prediction, int(j), term, revolute=rev))
    return [np.concatenate(c, axis=1) if c else np.zeros((signals.n, 0)) for c in out]
