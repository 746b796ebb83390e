"""The single-joint preprocessing chain on a robot's regressor (``chain="columns"``).

:func:`ident.preprocess.build_design` builds the regressor columns of one joint at full rate
on the filtered signals and filters and decimates them *in parallel* with the torque
(Gautier's parallel filtering, paper section IV.B); :func:`design_runs` does the same with
the n-dof regressor, per experiment, with the same functions and the same default settings:

0. q interpolated to the torque's instant (``torque_delay``; half a cycle for jointid's MCAP
   logs, :data:`ident.preprocess.TORQUE_DELAY`), every axis;
1. zero-phase Butterworth low-pass of q (cut-off: the largest
   :func:`~ident.preprocess.choose_cutoff` over the axes of the first experiment, at least
   :data:`~ident.preprocess.CUTOFF_FLOOR_IV` f_s with instruments), central differences for
   dq and ddq;
2. the standard regressor ``RobotRegressor.rigid_kpn``, the known torque (payload, and the
   known rotors' Ia_j ddq_j with ``known_rotor_inertia``) and
   sign(dq) at full rate (and, for IDIM-IV, the regressor and payload torque with the
   reference trajectory's acceleration);
3. edge trimming (max(ceil(3 f_s / cut-off), 2 r) samples);
4. decimation by r = round(f_s / cut-off) of the raw torque, the states and every column
   (MATLAB ``decimate``);
5. per joint, the stiction area |dq_j| < dq_min (1 % of the largest full-rate |dq| by
   default) evaluated at full rate and dilated by the guard 3 r, plus the first and last
   guard samples, leave joint j's decimated rows out (:attr:`RobotColumns.keep`).

On a robot with one moving joint this is exactly the single-joint design (the RX130L joint 3
of the demo gives the single-joint ``jointid fit`` numbers, ``tests/test_robot_design.py``).
The estimator reads the decimated columns instead of evaluating the regressor on decimated
states (``chain="states"``, :func:`ident.robot.loaders.preprocess_runs`); the paper model's
E_j and quadrant are still taken on the decimated samples. Memory: the full-rate regressor
of one experiment, k p (1 + IV) floats per sample, refused above :data:`MAX_BYTES`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..fitting import DQ_MIN_FRACTION
from ..preprocess import (
    CUTOFF_FLOOR_IV,
    _decimate_rows,
    choose_cutoff,
    decimation_index,
    default_rates,
    default_torque_delay,
    diffcent,
    guarded_keep,
    lowpass,
    shift,
)
from . import RobotIdentError
from .base import placed_payload
from .loaders import RawRobotRun, check_periods
from .refine_joint import joint_term_columns
from .signals import RobotColumns, RobotSignals

__all__ = ["DesignSettings", "design_runs", "joint_columns", "resolve_design", "sign_checked",
           "MAX_BYTES"]

#: Largest full-rate regressor of one experiment the columns chain builds [bytes].
MAX_BYTES = 4 * 2**30


@dataclass(frozen=True)
class DesignSettings:
    """Resolved settings of :func:`design_runs` (``None`` in :func:`resolve_design`'s
    arguments: chosen from the data as the module doc says).

    Attributes
    ----------
    cutoff_hz : float
        Butterworth cut-off on q [Hz].
    decimation : int
        Decimation factor r.
    trim : int
        Full-rate samples cut at both ends of each experiment.
    guard : int
        Full-rate samples around a rejected one that are rejected too.
    torque_delay : float
        Instant of the torque after the position sample [samples].
    dq_min : float or None
        Stiction threshold [rad/s]; None: :data:`ident.fitting.DQ_MIN_FRACTION` of the
        largest full-rate |dq| of the identification experiments.
    """

    cutoff_hz: float
    decimation: int
    trim: int
    guard: int
    torque_delay: float
    dq_min: float | None = None

    def as_dict(self) -> dict[str, float | int | None]:
        """The settings, for reports and JSON."""
        return {"cutoff_hz": self.cutoff_hz, "decimation": self.decimation, "trim": self.trim,
                "guard": self.guard, "torque_delay": self.torque_delay, "dq_min": self.dq_min}


def resolve_design(
    runs: Sequence[RawRobotRun],
    *,
    instruments: bool = False,
    cutoff_hz: float | None = None,
    decimation: int | None = None,
    trim: int | None = None,
    guard: int | None = None,
    torque_delay: float | None = None,
    dq_min: float | None = None,
) -> DesignSettings:
    """The settings :func:`design_runs` uses on ``runs`` (module doc; the defaults of
    :func:`ident.preprocess.build_design`).

    ``torque_delay`` None: :data:`~ident.preprocess.TORQUE_DELAY` when every run is a jointid
    MCAP log (commands held over the next cycle), else 0 (files of unknown timing).
    """
    if not runs:
        raise RobotIdentError("no experiment to preprocess")
    dt = _period(runs)
    fs = 1.0 / dt
    if cutoff_hz is None:
        floor = CUTOFF_FLOOR_IV if instruments else 0.05
        q0 = runs[0].q
        cutoff_hz = max(choose_cutoff(q0[:, j], dt, floor) for j in range(q0.shape[1]))
    cutoff_hz = float(cutoff_hz)
    if not 0 < cutoff_hz < fs / 2:
        raise RobotIdentError(f"cut-off {cutoff_hz:g} Hz: expected between 0 and the Nyquist "
                              f"frequency {fs / 2:g} Hz")
    r, trim, guard = default_rates(fs, cutoff_hz, decimation, trim, guard)
    if r < 1:
        raise RobotIdentError(f"decimation must be a positive integer, got {decimation}")
    if trim < 0:
        raise RobotIdentError(f"trim must be >= 0, got {trim}")
    if guard < 0:
        raise RobotIdentError(f"guard must be >= 0, got {guard}")
    if torque_delay is None:
        torque_delay = default_torque_delay(run.source for run in runs)
    torque_delay = float(torque_delay)
    if not 0 <= torque_delay < 1:
        raise RobotIdentError(f"torque_delay must lie in [0, 1) samples, got {torque_delay}")
    if dq_min is not None and not dq_min >= 0:
        raise RobotIdentError(f"dq_min must be >= 0 [rad/s], got {dq_min}")
    return DesignSettings(cutoff_hz, r, trim, guard, torque_delay,
                          None if dq_min is None else float(dq_min))


def _period(runs: Sequence[RawRobotRun]) -> float:
    """The sampling period [s] the chain uses for every run: the median step of the first
    (as :func:`ident.preprocess.build_design`), after checking that all runs share it."""
    check_periods(runs)
    return float(np.median(np.diff(runs[0].t)))


def _filtered(s: DesignSettings, q: np.ndarray, dt: float) -> np.ndarray:
    """q (n, k) interpolated to the torque instant and low-pass filtered, axis by axis with
    the single-joint calls (the same rounding: sign(dq) of a joint at rest is decided by it,
    so is the period: the single-joint chain's, :func:`_period`)."""
    fs = 1.0 / dt
    return np.column_stack([lowpass(shift(q[:, j], s.torque_delay), s.cutoff_hz, fs)
                            for j in range(q.shape[1])])


def _diff(x: np.ndarray, dt: float) -> np.ndarray:
    """:func:`~ident.preprocess.diffcent` axis by axis (see :func:`_filtered`)."""
    return np.column_stack([diffcent(x[:, j], dt) for j in range(x.shape[1])])


def _states(run: RawRobotRun, s: DesignSettings, dt: float) -> tuple:
    """Full-rate filtered q, dq, ddq (n_f, k) of a run after edge trimming, and the trim
    slice."""
    n = run.t.size
    if n - 2 * s.trim < max(4 * s.decimation, 10):
        raise RobotIdentError(f"{run.source}: {n} samples, too few after trimming {s.trim} "
                              f"at each end and decimating by {s.decimation}")
    q = _filtered(s, run.q, dt)
    dq = _diff(q, dt)
    keep = slice(s.trim, n - s.trim if s.trim else n)
    return q[keep], dq[keep], _diff(dq, dt)[keep], keep


def _keep(bad: np.ndarray, guard: int, index: np.ndarray) -> np.ndarray:
    """Rows kept (m, k) at the decimated samples ``index``, joint by joint
    (:func:`~ident.preprocess.guarded_keep` of each column of ``bad`` (n_f, k))."""
    return np.column_stack([guarded_keep(bad[:, j], guard, index)
                            for j in range(bad.shape[1])])


def design_runs(
    runs: Sequence[RawRobotRun],
    regressor,
    settings: DesignSettings,
    *,
    instruments: bool = False,
    base=None,
) -> tuple[RobotSignals, float]:
    """Filter, build the regressor at full rate, decimate in parallel, select (module doc).

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
    k, p, r = len(joints), int(regressor.p), settings.decimation
    has_ref = all(run.q_ref is not None for run in runs)
    if instruments and not has_ref:
        missing = next(run.source for run in runs if run.q_ref is None)
        raise RobotIdentError(f"{missing}: no reference trajectory q_ref for the IDIM-IV "
                              "instruments")
    states = []
    dt = _period(runs)
    for run in runs:
        if run.q.shape[1] != k:
            raise RobotIdentError(f"{run.source}: {run.q.shape[1]} axes, expected {k} "
                                  f"({', '.join(joints)})")
        need = (run.t.size - 2 * settings.trim) * k * p * 8 * (2 if instruments else 1)
        if need > MAX_BYTES:
            raise RobotIdentError(f"{run.source}: the full-rate regressor needs {need / 2**30:.1f}"
                                  f" GiB (more than {MAX_BYTES / 2**30:.0f}); use the states "
                                  "chain (--chain states) or split the log")
        states.append(_states(run, settings, dt))
    dq_min = settings.dq_min
    if dq_min is None:
        dq_min = DQ_MIN_FRACTION * max(float(np.max(np.abs(s[1]))) for s in states)
    placed: dict = {}  # lever-arm payloads, placed (eq. 34-35)
    parts: dict[str, list[np.ndarray]] = {n: [] for n in (
        "t", "q", "dq", "ddq", "tau", "p", "sign", "keep", "W", "Wz", "pz", "ref", "e")}
    for i, (run, (q, dq, ddq, keep)) in enumerate(zip(runs, states, strict=True)):
        nf = q.shape[0]
        pay = placed_payload(run.payload, regressor, base, run.source, placed)

        def torque(acc: np.ndarray, q=q, dq=dq, pay=pay) -> np.ndarray:
            # the known torques: the payload's and the known rotors' Ia_j ddq_j (zero unless
            # RobotRegressor(known_rotor_inertia=True)), filtered with the columns
            out = (np.asarray(regressor.payload_torque(q, dq, acc, pay), dtype=float)
                   if pay.mass > 0 else np.zeros((q.shape[0], k)))
            if np.any(getattr(regressor, "known_Ia", 0.0)):
                out = out + regressor.known_torque(acc)
            return out

        rows = [run.tau[keep].T, q.T, dq.T, ddq.T, torque(ddq).T, np.sign(dq).T]
        W = np.asarray(regressor.rigid_kpn(q, dq, ddq)).reshape(k * p, nf)
        rows.append(W)
        ref = None
        if has_ref:
            ref = _filtered(settings, run.q_ref, dt)  # type: ignore[arg-type]
            rows.append(ref[keep].T)
        if instruments:
            ddr = _diff(_diff(ref, dt), dt)[keep]  # type: ignore[arg-type]
            rows.append(np.asarray(regressor.rigid_kpn(q, dq, ddr)).reshape(k * p, nf))
            rows.append(torque(ddr).T)
        stack = np.ascontiguousarray(np.concatenate(rows, axis=0))
        del rows, W
        dec, index = _decimate_rows(stack, r)
        del stack
        m = index.size
        a = 0
        for name, size in (("tau", k), ("q", k), ("dq", k), ("ddq", k), ("p", k),
                           ("sign", k)):
            parts[name].append(dec[a:a + size].T)
            a += size
        parts["W"].append(dec[a:a + k * p].reshape(k, p, m))
        a += k * p
        if has_ref:
            parts["ref"].append(dec[a:a + k].T)
            a += k
        if instruments:
            parts["Wz"].append(dec[a:a + k * p].reshape(k, p, m))
            parts["pz"].append(dec[a + k * p:a + k * p + k].T)
        parts["t"].append(run.t[keep][index])
        parts["e"].append(np.full(m, i))
        parts["keep"].append(_keep(np.abs(dq) < dq_min, settings.guard, index))

    def cat(name: str, axis: int = 0) -> np.ndarray:
        return np.ascontiguousarray(np.concatenate(parts[name], axis=axis))

    columns = RobotColumns(W=cat("W", 2), p=cat("p"), sign=cat("sign"), keep=cat("keep"),
                           Wz=cat("Wz", 2) if instruments else None,
                           pz=cat("pz") if instruments else None)
    sig = RobotSignals(t=cat("t"), q=cat("q"), dq=cat("dq"), ddq=cat("ddq"), tau=cat("tau"),
                       joints=joints, experiment=cat("e"),
                       payloads=tuple(run.payload for run in runs),
                       q_ref=cat("ref") if has_ref else None,
                       source=", ".join(run.source for run in runs), columns=columns)
    return sig, float(dq_min)


def sign_checked(
    signals: RobotSignals,
    runs: Sequence[RawRobotRun],
    settings: DesignSettings,
    load_torque: Callable[[RobotSignals], np.ndarray],
    min_kept: float | np.ndarray = 0.0,
) -> tuple[RobotSignals, np.ndarray]:
    """Also leave out the rows where sign(tau_j) differs from sign(tau_out_hat_j), the
    paper's stiction-area rectangle (Fig. 2.b) where eq. 26's proxy sign(P) = sign(tau dq)
    is not sign(P_out): the single-joint ``load_model`` selection of
    :func:`ident.preprocess.build_design`, per joint.

    Parameters
    ----------
    signals : RobotSignals
        :func:`design_runs`'s output for ``runs`` with ``settings`` (``dq_min`` resolved).
    runs, settings
        What built ``signals``.
    load_torque : callable
        RobotSignals -> tau_out_hat (n, k) [N m], e.g. ``RobotModel.load_torque`` of a first
        usual fit; evaluated at full rate on the filtered states of each run.
    min_kept : float or ndarray, shape (k,)
        A joint keeps its rows unchecked when the check would keep less than this fraction
        of them (tau_out near zero over much of the data: no load to compare with); per
        joint when an array (inf: never checked, e.g. validation data checked where the
        identification data were).

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
    dt = _period(runs)
    keep = cols.keep.copy()
    for i, run in enumerate(runs):
        q, dq, ddq, trim = _states(run, settings, dt)
        tau_f = np.column_stack([lowpass(run.tau[:, j], settings.cutoff_hz, 1.0 / dt)
                                 for j in range(run.tau.shape[1])])[trim]
        full = RobotSignals(t=run.t[trim], q=q, dq=dq, ddq=ddq, tau=tau_f,
                            joints=signals.joints, payloads=(run.payload,),
                            source=run.source)
        tau_out = np.asarray(load_torque(full), dtype=float)
        bad = (np.abs(dq) < settings.dq_min) | (np.sign(tau_f) != np.sign(tau_out))
        rows = np.flatnonzero(signals.experiment == i)
        keep[rows] = _keep(bad, settings.guard, decimation_index(q.shape[0],
                                                                 settings.decimation))
    before = cols.keep.sum(axis=0)
    kept = keep.sum(axis=0) / np.maximum(before, 1)
    skip = kept < np.broadcast_to(np.asarray(min_kept, dtype=float), kept.shape)
    keep[:, skip] = cols.keep[:, skip]
    return replace(signals, columns=replace(cols, keep=keep)), kept


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
