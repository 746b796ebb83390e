"""Loading multi-axis experiments: MCAP logs, CSV and MATLAB files -> :class:`RobotSignals`.

Each input file is one experiment (one payload run) of the k moving joints of a robot, read
by the one reader of ident, :func:`ident.loaders.read_file` (the single joint's too: a joint
is a 1-dof robot), into :class:`~ident.loaders.RawRobotRun`. The axes of the file must match
the moving joints of the robot file, in number and -- where the file names its axes -- by
name; otherwise a one-line :class:`~ident.robot.RobotIdentError` names the file and the
element. A lever-arm payload (``arm_m``) without a mass is dropped here (it places nothing).

Formats
-------
MCAP (``jointid run`` logs)
    One ``/joint/<i>/state`` channel per drive; axis i is moving joint i. The torque is
    ``tau_ref``, already joint-side [N m] (the drive chain of the log's ``drive<i>``
    metadata), so no drive gain is applied. A ``drive<i>`` record with a ``joint`` key names
    the axis (checked against the robot). Only the cycles where *every* drive was in
    OPERATION ENABLED are kept (longest common stretch). The ``/setpoint`` channel carries
    one reference, used as ``q_ref`` only for a one-axis log. Payload: metadata ``payload``
    ``mass_kg`` and optional ``com_m`` (JSON list, flange frame); a single-joint log's
    ``arm_m`` (lever arm, eq. 34-35) when there is no ``com_m`` (placed on a one-joint robot,
    refused on several).
CSV (header row)
    ``t, q1..qk, tau1..tauk`` (numbered in the robot's moving order) or named by joint
    ``q_<joint>, tau_<joint>`` (one moving joint: also ``q, tau``); ``--map`` paths as for
    MAT; optional ``q_ref*`` (IV instruments), ``dq*`` and ``ddq*`` (taken as given --
    already filtered -- when both are present for every axis) and the
    constant payload columns ``payload_mass_kg``, ``payload_com_x_m``, ``payload_com_y_m``,
    ``payload_com_z_m`` (flange frame) and ``payload_ixx_kgm2``, ``payload_ixy_kgm2``, ...
    ``payload_izz_kgm2`` (about the CoM, flange axes), or ``payload_kg`` and
    ``payload_arm_m`` (a single joint's). The torque column times the joint's ``drive_gain``
    is the joint-side torque.
MAT (v5/v7, and v7.3 through h5py)
    The ``--map`` paths of :func:`ident.loaders.resolve_path` with one array per signal,
    one row (or column) per axis: ``t=rec.time_cont, q=rec.act_pos_mot_deg,
    tau=rec.act_torque_abs_nm, q_ref=rec.ref_pos_deg``; or per-axis keys ``q1=...``.
    ``q_unit="deg"`` converts q and q_ref, the drive gains convert the torque (motor-side
    torque x gear ratio for the KUKA recordings). ``payload_kg=`` (a number or a path to a
    scalar) gives the file's payload mass (no CoM: ``--payload mass`` identifies the rest).

Preprocessing (the "states" chain)
----------------------------------
:func:`preprocess_runs` runs the one chain, :func:`ident.chain.run_chain` (the chain of
:func:`ident.preprocess.build_design` and :mod:`ident.robot.design`), with no column
builder: per experiment and per axis the zero-phase Butterworth low-pass of q (cut-off chosen
from the motion bandwidth by :func:`~ident.chain.choose_cutoff`, the largest over the axes),
central differences for dq and ddq, edge trimming, then decimation of the torque and the
states (MATLAB ``decimate``); the estimator builds the rigid-body regressor afterwards from
the decimated, already band-limited states, chunk by chunk (memory bounded on any log
length). Its own settings: the decimation r = floor(0.4 f_s / cut-off) by default (the
decimated states keep the motion's band, since the nonlinear columns are built after the
decimation; the columns chain uses round(f_s / cut-off)), the columns chain's torque delay
(half a cycle for jointid logs), and derivatives given by the file taken as they are. The
columns chain -- the regressor columns built at full rate and decimated in parallel with the
torque, the IV cut-off floor, the guard -- is :mod:`ident.robot.design` (``jointid fit
--robot``'s default).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from daq.protocol.reader import LogReadError

from ..chain import ChainSettings, RawExperiment, resolve_settings, run_chain
from ..loaders import (
    IRREGULAR_TOL,
    Q_UNITS,
    RawRobotRun,
    read_file,
)
from . import RobotIdentError
from .signals import RobotPayloadData, RobotSignals

__all__ = [
    "RawRobotRun",
    "RobotPreprocessing",
    "check_periods",
    "load_robot_runs",
    "load_robot_signals",
    "chain_period",
    "preprocess_runs",
    "resolved_settings",
]


@dataclass(frozen=True)
class RobotPreprocessing:
    """Settings of the per-axis filtering (see the module docstring).

    Attributes
    ----------
    cutoff_hz : float or None
        Butterworth cut-off on q [Hz]; None: the largest :func:`choose_cutoff` over the axes
        of the first experiment.
    decimation : int or None
        Decimation factor r; None: floor(0.4 f_s / cut-off) (the anti-alias band of the
        decimation, 0.8 (f_s/2)/r, stays at or above the cut-off), at least 1.
    trim : int or None
        Full-rate samples cut at both ends of each experiment; None: ceil(3 f_s / cut-off).
    torque_delay : float or None
        Instant of the torque samples after the position samples [samples of the log's
        period], in [0, 1) (``--torque-delay``; the ``torque_delay`` of
        :func:`ident.fitting.fit_models`): e.g. 0.5 for a command held over the cycle after
        its sample, 0.125 for the same hold of a 1 kHz drive logged at 250 Hz. None:
        :func:`ident.chain.default_torque_delay` (half a sample when every run is a jointid
        MCAP log, else 0).
    """

    cutoff_hz: float | None = None
    decimation: int | None = None
    trim: int | None = None
    torque_delay: float | None = None


# -- reading --------------------------------------------------------------------------------


def _check_gains(gains: Sequence[float] | None, k: int) -> np.ndarray:
    g = np.ones(k) if gains is None else np.asarray(gains, dtype=float).reshape(-1)
    if g.shape != (k,):
        raise RobotIdentError(f"drive gains: {g.size} values for {k} moving joints")
    return g



def load_robot_runs(
    paths: Sequence[str | Path] | str | Path,
    joints: Sequence[str],
    *,
    gains: Sequence[float] | None = None,
    mapping: Mapping[str, str | float] | None = None,
    q_unit: str | None = None,
) -> list[RawRobotRun]:
    """Read every file as one multi-axis experiment (no filtering yet).

    Parameters
    ----------
    paths : path or sequence of paths
        ``.mcap``, ``.csv`` (``.txt``) or ``.mat`` files.
    joints : sequence of str
        The robot's moving joints, in order (the axes of each file).
    gains : sequence of float, shape (k,), or None
        Joint-side torque per unit of the logged torque of each axis (the robot file's
        ``drive_gain``; CSV and MAT only -- MCAP torques are already joint-side N m).
    mapping : mapping or None
        MAT/CSV ``--map`` entries (:func:`ident.loaders.parse_mapping` with ``robot=True``).
    q_unit : {"rad", "deg", "m", "mm"} or None
        Unit of q and q_ref in CSV/MAT files (converted to SI).

    Raises
    ------
    RobotIdentError
        Missing file, unknown type, axes that do not match ``joints``, bad mapping or values.
    """
    if isinstance(paths, str | Path):
        paths = [paths]
    if not paths:
        raise RobotIdentError("no input file given")
    joints = tuple(joints)
    if not joints:
        raise RobotIdentError("the robot has no moving joint")
    g = _check_gains(gains, len(joints))
    if q_unit is not None and q_unit not in Q_UNITS:
        raise RobotIdentError(f"q unit {q_unit!r}: expected one of {', '.join(Q_UNITS)}")
    runs = []
    for p in map(Path, paths):
        try:
            run = read_file(p, joints, gains=list(g), mapping=mapping, q_unit=q_unit)
        except LogReadError as exc:
            raise RobotIdentError(str(exc)) from None
        except ValueError as exc:  # DataError of the reader: one line naming the file
            raise RobotIdentError(str(exc)) from None
        pay = run.payload
        if pay.arm_m is not None and not pay.mass > 0:  # a lever arm without a mass: none
            run = replace(run, payload=RobotPayloadData(pay.mass, pay.com, pay.inertia))
        runs.append(run)
    return runs


# -- preprocessing --------------------------------------------------------------------------


def check_periods(runs: Sequence[RawRobotRun]) -> float:
    """The common sampling period of ``runs`` [s]; :class:`RobotIdentError` naming the first
    run whose period differs."""
    dt = runs[0].dt
    for r in runs[1:]:
        if abs(r.dt - dt) > IRREGULAR_TOL * dt:
            raise RobotIdentError(
                f"{r.source}: sampling period {r.dt:.6g} s differs from {runs[0].source} "
                f"({dt:.6g} s)"
            )
    return dt


def chain_period(runs: Sequence[RawRobotRun]) -> float:
    """The sampling period [s] the chain uses for every run: the median step of the first
    (as :func:`ident.preprocess.build_design`), after :func:`check_periods`."""
    check_periods(runs)
    return float(np.median(np.diff(runs[0].t)))


def _settings(runs: Sequence[RawRobotRun], pre: RobotPreprocessing) -> ChainSettings:
    """The chain's settings (:func:`ident.chain.resolve_settings`) with the states chain's
    decimation rule: r = floor(0.4 f_s / cut-off) when not given (the decimated states keep
    the motion's band); the torque delay of the columns chain (:func:`ident.chain.
    default_torque_delay`: half a cycle for jointid logs, whose hold the chain completes)
    unless ``pre`` gives one."""
    if not runs:
        raise RobotIdentError("no experiment to preprocess")
    dt = chain_period(runs)
    sources = [r.source for r in runs]
    s = resolve_settings(runs[0].q, dt, cutoff_hz=pre.cutoff_hz, decimation=pre.decimation,
                         trim=pre.trim, torque_delay=pre.torque_delay, sources=sources,
                         error=RobotIdentError)
    if pre.decimation is None:
        r = max(1, int(0.4 / dt / s.cutoff_hz + 1e-9))  # 1e-9: an exact ratio stays whole
        s = resolve_settings(runs[0].q, dt, cutoff_hz=s.cutoff_hz, decimation=r,
                             trim=pre.trim, torque_delay=pre.torque_delay, sources=sources,
                             error=RobotIdentError)
    return s


def preprocess_runs(
    runs: Sequence[RawRobotRun],
    joints: Sequence[str],
    preprocessing: RobotPreprocessing | None = None,
) -> RobotSignals:
    """The states chain: :func:`ident.chain.run_chain` with no columns; the states stacked.

    Parameters
    ----------
    runs : sequence of RawRobotRun
        Experiments of the same robot (same sampling period).
    joints : sequence of str
        Names of the k moving joints (column order).
    preprocessing : RobotPreprocessing or None
        Settings; None: all defaults.

    Returns
    -------
    RobotSignals
        ``experiment`` indexes ``runs``; ``payloads`` one per run; ``source`` the file names.
        The chosen cut-off, decimation and trim are returned by :func:`resolved_settings`.

    Raises
    ------
    RobotIdentError
        Different sampling periods, bad settings, an experiment too short for them.
    """
    settings = _settings(runs, preprocessing or RobotPreprocessing())
    has_ref = all(run.q_ref is not None for run in runs)
    exps = [RawExperiment(run.source, run.q, run.tau, run.q_ref if has_ref else None,
                          run.dq, run.ddq) for run in runs]
    # sign(dq) at full rate, decimated with the torque: the Coulomb column (RobotSignals.sign)
    blocks, _ = run_chain(exps, chain_period(runs), settings,
                          lambda _, f: (([f.ref.T] if has_ref else []) + [np.sign(f.dq).T],
                                        None),
                          error=RobotIdentError)
    states = [b.states() for b in blocks]

    def cat(i: int) -> np.ndarray:
        return np.ascontiguousarray(np.concatenate([s[i] for s in states]))

    return RobotSignals(
        t=np.concatenate([run.t[b.full.keep][b.index] for run, b in zip(runs, blocks,
                                                                         strict=True)]),
        q=cat(1),
        dq=cat(2),
        ddq=cat(3),
        tau=cat(0),
        joints=tuple(joints),
        experiment=np.concatenate([np.full(b.index.size, i) for i, b in enumerate(blocks)]),
        payloads=tuple(run.payload for run in runs),
        q_ref=(np.ascontiguousarray(np.concatenate([b.columns()[0].T for b in blocks]))
               if has_ref else None),
        source=", ".join(run.source for run in runs),
        sign=np.ascontiguousarray(np.concatenate([b.columns()[-1].T for b in blocks])),
    )


def resolved_settings(runs: Sequence[RawRobotRun],
                      preprocessing: RobotPreprocessing | None = None) -> dict[str, float]:
    """The cut-off [Hz], decimation, trim and torque delay [samples] :func:`preprocess_runs`
    uses for ``runs``."""
    s = _settings(runs, preprocessing or RobotPreprocessing())
    return {"cutoff_hz": s.cutoff_hz, "decimation": s.decimation, "trim": s.trim,
            "torque_delay": s.torque_delay}


def load_robot_signals(
    paths: Sequence[str | Path] | str | Path,
    joints: Sequence[str],
    *,
    gains: Sequence[float] | None = None,
    mapping: Mapping[str, str | float] | None = None,
    q_unit: str | None = None,
    preprocessing: RobotPreprocessing | None = None,
) -> RobotSignals:
    """:func:`load_robot_runs` then :func:`preprocess_runs` (one call for notebooks)."""
    runs = load_robot_runs(paths, joints, gains=gains, mapping=mapping, q_unit=q_unit)
    return preprocess_runs(runs, joints, preprocessing)
