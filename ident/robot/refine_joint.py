"""Refinement of one joint of an n-dof fit, the other joints' states available.

Joint j's measured torque tau_j is the Y of a single-joint design whose declared model is the
n-dof fit's prediction tau_hat_j times a gain (:class:`NdofPrediction`, ~1) plus the usual
friction (F_C, F_V, tau_off; ~0, they take what the n-dof fit left in those shapes); its
residual is the n-dof fit's residual, and :func:`ident.refine.refine` looks for the effects
left in it (docs/refinement.md). The measured torque, not the residual, is the design's
torque so that the variables the refinement reads from it are not the residual itself:
sign(P) = sign(tau_j dq_j) (eq. 26) and the load tau_out, taken as the n-dof prediction
(:func:`ident.effects.rigid_prediction`: the declared "rigid body" is that column; it includes
joint j's fitted friction, a small bias of the load variable where friction is a large part
of the torque). With the residual as the torque, sign(residual dq) and a basis in the
"load" = residual fit the noise itself (a quadrant Coulomb or a load basis accepted on clean
data).

The other joints' positions and velocities ride along as :attr:`Signals.extra
<ident.signals.Signals.extra>`, named ``q<m>`` and ``dq<m>`` with m the joint's 1-based index
in ``RobotSignals.joints`` (the moving chain): they follow the design's row selection, the
interaction diagnosis and the library search expand them, and a selected group in them
becomes a term of joint j (a cross-joint effect: a cable or a bearing load following another
joint, ``sim_drivers.arm_effects`` "dry coupling").

The fit's own rows (``keep``): given the rows joint j's n-dof fit used (the columns chain's
:attr:`RobotColumns.keep <ident.robot.signals.RobotColumns.keep>`, stiction area, guard and
sign check applied), the design is the fit's samples as they are -- the decimated torque as Y,
the filtered and decimated states, no second filter, trim or decimation -- and its selection
is those rows (:func:`fit_rows_design`). Without ``keep`` the samples are filtered and
differentiated again by :func:`ident.preprocess.build_design` with decimation 1 (the states
chain). A zero-order hold is named against the raw log's period ``cycle_s`` (the design's own
period is the decimated one).

The direction on the fit's rows: when the n-dof signals carry the fit's Coulomb column
(``RobotSignals.sign``: sign(dq) formed at full rate and decimated with the torque, on both
chains), joint j's signals carry it as :attr:`Signals.sign <ident.signals.Signals.sign>`,
through the row selection, into the design's signals (the candidates' scoring) and into
:func:`joint_term_columns` (the n-dof refit's columns); the terms that read
:attr:`Signals.direction <ident.signals.Signals.direction>` -- the library's ``Coulomb``, the
paper model's ``QuadrantCoulomb`` and the candidate effects of :mod:`ident.effects` -- take it
instead of the sign of the decimated dq, a step where the decimated torque's dry friction is
a ramp (docs/robot-identification.md, "The direction on the fit's rows", for the figures).
Without ``keep`` (filtered again) the direction is that of the new dq.

The found term is fitted here on the n-dof fit's residual (two stages: the n-dof parameters
have already absorbed the part of its column in their span); :func:`joint_term_columns`
gives its columns on the robot's samples, from the states only, for the n-dof refit
(:mod:`ident.robot.refit`) that fits it together with every n-dof parameter.

Pure numerics (no file access).
"""

from __future__ import annotations

import warnings
from dataclasses import replace
from typing import Any

import numpy as np

from .. import DataError
from ..describe import CrossJointPeriodic, CrossJointPolynomial
from ..loaders import SlowSamplingWarning, concat, make_experiment
from ..models import Coulomb, IdentModel, Offset, Viscous
from ..preprocess import Design, _assemble, _Block, build_design
from ..refine import refine
from ..refine_result import Refinement
from ..signals import Signals
from ..terms import Library, Term
from .signals import RobotSignals

__all__ = ["NDOF_PREDICTION", "NdofPrediction", "fit_rows_design", "joint_coulomb",
           "joint_term_columns", "other_joint_names", "refine_joint"]

#: Key of the n-dof prediction in ``Signals.extra`` (not searched as an "other" variable).
NDOF_PREDICTION = "tau_hat"


class NdofPrediction(Term):
    """The n-dof fit's prediction of the joint's torque, tau_hat_j [N m], times a gain
    ``k_ndof`` (1 when the n-dof fit is kept as it is); read from
    ``Signals.extra[NDOF_PREDICTION]``. Its effect is ``"rigid_body"``: the refinement takes
    it as the load prediction tau_out (module docstring)."""

    effect = "rigid_body"
    variable = "model"

    def names(self) -> tuple[str, ...]:
        return ("k_ndof",)

    def columns(self, s: Signals) -> np.ndarray:
        if s.extra is None or NDOF_PREDICTION not in s.extra:
            raise DataError(f"NdofPrediction: the signals have no extra[{NDOF_PREDICTION!r}]")
        return np.asarray(s.extra[NDOF_PREDICTION], dtype=float)[:, None]

    def describe(self) -> str:
        return "n-dof fit's prediction of the joint torque x k_ndof"


def other_joint_names(k: int, j: int) -> list[tuple[int, str, str]]:
    """``(m, "q<m+1>", "dq<m+1>")`` for every joint m != j of a k-joint robot."""
    return [(m, f"q{m + 1}", f"dq{m + 1}") for m in range(k) if m != j]


def refine_joint(
    sig: RobotSignals,
    prediction: np.ndarray,
    j: int,
    *,
    revolute: bool = True,
    vmax: float | None = None,
    dq_min: float | None = None,
    max_steps: int = 2,
    others: bool = True,
    torque: str = "measured",
    coulomb: float | None = None,
    keep: np.ndarray | None = None,
    cycle_s: float | None = None,
    validation: tuple[RobotSignals, np.ndarray, np.ndarray | None] | None = None,
    **kwargs,
) -> Refinement:
    """:func:`ident.refine.refine` on joint j of an n-dof fit (module docstring).

    Parameters
    ----------
    sig : RobotSignals
        The samples the n-dof fit used (n samples, k joints), uniform in time within each
        experiment (one experiment per payload run).
    prediction : ndarray, shape (n, k)
        The n-dof fit's torque prediction tau_hat [N m] (``RobotModel.predict``); joint j's
        column and ``sig.tau`` must be finite.
    j : int
        Joint index (0-based, column of ``sig``).
    revolute : bool
        Joint j is revolute.
    vmax : float, optional
        Joint j's maximum velocity for the velocity bands [rad/s].
    dq_min : float, optional
        Samples with |dq_j| below it are left out (as the n-dof fit did) [rad/s].
    max_steps : int
        Refinement steps at most.
    others : bool
        Give the other joints' q and dq to the refinement (``q<m>``, ``dq<m>``).
    torque : {"measured", "residual"}
        The design's torque: the measured tau_j with the prediction as declared column
        (module docstring), or the residual tau_j - tau_hat_j with the usual friction refitted
        on it (``jointid demo --robot`` so far; sign(P) and the load are then read from the
        residual itself).
    coulomb : float, optional
        Joint j's Coulomb friction of the n-dof fit [N m] (:func:`joint_coulomb`): the scale
        of "±x % of F_C" in the descriptions (the design's own F_C is a correction ~0).
    keep : ndarray of bool, shape (n, k), optional
        The rows the n-dof fit used (``RobotColumns.keep``, or |dq| > dq_min): the design is
        then the fit's samples as they are, selected by ``keep[:, j]``
        (:func:`fit_rows_design`; ``dq_min`` unused). None: the samples are filtered and
        differentiated again (module docstring).
    cycle_s : float, optional
        The raw log's sampling period [s], for the zero-order hold and the physical ranges
        (:func:`ident.refine.refine`); default the design's own (decimated) period.
    validation : (RobotSignals, ndarray, ndarray or None), optional
        Validation samples, the n-dof prediction on them and their kept rows (as ``sig``,
        ``prediction``, ``keep``): a step must lower their error too.
    **kwargs
        Passed to :func:`ident.refine.refine` (``alpha``, ``min_gain``, ``progress``, ...).

    Returns
    -------
    Refinement
        Relative errors are ||rho_j|| / ||tau_j||; the initial one is the n-dof fit's (up to
        the refitted gain and friction).

    Raises
    ------
    DataError
        Bad shapes or joint index, non-finite samples, too few samples.
    """
    y_lib = _joint_signals(sig, prediction, j, revolute=revolute, others=others,
                           torque=torque)
    s, names, lib = y_lib
    if keep is not None:
        design = fit_rows_design(lib, s, _joint_keep(keep, sig, j, "keep"))
    else:  # filtered again: the direction is that of the new dq (no decimated sign)
        design = build_design(lib, replace(s, sign=None), decimation=1, dq_min=dq_min)
    val = None
    if validation is not None:
        vsig, vpred, vkeep = validation
        vs, _, _ = _joint_signals(vsig, vpred, j, revolute=revolute, others=others,
                                  torque=torque)
        if vkeep is not None:
            val = fit_rows_design(lib, vs, _joint_keep(vkeep, vsig, j, "validation keep"))
        else:
            val = build_design(lib, replace(vs, sign=None), decimation=1, dq_min=dq_min)
    ref = refine(design, IdentModel(lib, "ndof" if torque == "measured" else "residual"),
                 max_steps=max_steps, vmax=vmax, others=names, validation=val,
                 reference=None if coulomb is None else {"F_C": float(coulomb)},
                 cycle_s=cycle_s, **kwargs)
    for st in ref.steps:
        if isinstance(st.term, CrossJointPeriodic | CrossJointPolynomial):
            # a pair the search selected, named by a one-variable form: the term's variables
            st.variables = (st.term.var,) + (() if st.term.modifier == "none"
                                             else (st.term.modifier,))
    return ref


def _joint_keep(keep: np.ndarray, sig: RobotSignals, j: int, what: str) -> np.ndarray:
    keep = np.asarray(keep, dtype=bool)
    if keep.shape != sig.tau.shape:
        raise DataError(f"refine_joint: {what} has shape {keep.shape}, expected "
                        f"{sig.tau.shape} (samples, joints of {sig.source or 'the signals'})")
    return keep[:, j]


def _joint_signals(
    sig: RobotSignals,
    prediction: np.ndarray,
    j: int,
    *,
    revolute: bool,
    others: bool,
    torque: str,
) -> tuple[Signals, list[str], Library]:
    """Joint j's single-joint signals (experiments in order, the prediction and the other
    joints' states in ``extra``), the names of the other joints' variables, the library."""
    prediction = np.asarray(prediction, dtype=float)
    if prediction.shape != sig.tau.shape:
        raise DataError(f"refine_joint: prediction has shape {prediction.shape}, expected "
                        f"{sig.tau.shape} (samples, joints of {sig.source or 'the signals'})")
    if not 0 <= j < sig.k:
        raise DataError(f"refine_joint: joint index {j} not in 0..{sig.k - 1}")
    for what, a in (("torque", sig.tau[:, j]), ("prediction", prediction[:, j])):
        bad = ~np.isfinite(a)
        if bad.any():
            raise DataError(f"refine_joint: {what} of joint {sig.joints[j]} has "
                            f"{int(bad.sum())} non-finite samples (give the samples the fit "
                            "used, uniform in time)")
    if torque not in ("measured", "residual"):
        raise DataError(f"refine_joint: torque must be 'measured' or 'residual', got {torque!r}")
    y = sig.tau[:, j] if torque == "measured" else sig.tau[:, j] - prediction[:, j]
    exps, idx = [], []
    for e in np.unique(sig.experiment):
        m = np.flatnonzero(sig.experiment == e)
        dt = float(np.median(np.diff(sig.t[m])))  # the (decimated) period: uniform samples
        with warnings.catch_warnings():
            # the fit's decimated rows (0.08 s on the KUKA recordings): slow by design, the
            # loader's slow-sampling warning is about raw files and was false here
            warnings.simplefilter("ignore", SlowSamplingWarning)
            exps.append(make_experiment(f"{sig.joints[j]} run {e}", dt * np.arange(m.size),
                                        sig.q[m, j], y[m],
                                        payload_mass=float(sig.payloads[e].mass),
                                        payload_arm=float(sig.payloads[e].arm_m or 0.0),
                                        revolute=revolute))
        idx.append(m)
    order = np.concatenate(idx)
    extra = {NDOF_PREDICTION: prediction[order, j]}
    names: list[str] = []
    if others:
        for m, qn, dqn in other_joint_names(sig.k, j):
            extra[qn] = sig.q[order, m]
            extra[dqn] = sig.dq[order, m]
            names += [qn, dqn]
    # the states as the fit has them (concat leaves dq, ddq at zero: build_design recomputes
    # them; fit_rows_design reads them), and the fit's Coulomb column: sign(dq) formed at
    # full rate and decimated with the torque (RobotSignals.sign), the direction every
    # column reads (Signals.direction) -- the sign of the decimated dq is a step where the
    # decimated torque's dry friction is a ramp (module docstring)
    s = replace(concat(exps), dq=sig.dq[order, j], ddq=sig.ddq[order, j], extra=extra,
                sign=None if sig.sign is None else sig.sign[order, j])
    lib = Library(Coulomb(), Viscous(), Offset())
    if torque == "measured":
        lib = Library(NdofPrediction(), *lib.terms())
    return s, names, lib


def joint_term_columns(sig: RobotSignals, prediction: np.ndarray, j: int, term: Term, *,
                       revolute: bool = True) -> np.ndarray:
    """Joint j's columns of a single-joint ``term`` (e.g. a step of :func:`refine_joint`) on
    every sample of ``sig``, in ``sig``'s row order, shape (n, c).

    The term sees what it saw in the refinement: joint j's signals of :func:`refine_joint`
    (``prediction[:, j]`` as ``extra["tau_hat"]``, the other joints' ``q<m>``, ``dq<m>``),
    experiment by experiment (as :func:`fit_rows_design`'s blocks), through
    :meth:`Signals.states <ident.signals.Signals.states>`: the columns are functions of the
    states and the n-dof model's prediction only, never of the measured torque
    (:class:`~ident.OutputLeakError` if the term tries).

    Raises
    ------
    DataError
        Bad shapes or joint index, non-finite samples, a term whose columns have another
        shape or non-finite values.
    """
    s, _, _ = _joint_signals(sig, prediction, j, revolute=revolute, others=True,
                             torque="measured")
    order = np.concatenate([np.flatnonzero(sig.experiment == e)
                            for e in np.unique(sig.experiment)])
    c = len(term.names())
    out = np.empty((sig.n, c))
    for e in np.unique(s.experiment):
        idx = np.flatnonzero(s.experiment == e)
        cols = np.asarray(term.columns(s.take(idx).states()), dtype=float)
        if cols.shape != (idx.size, c):
            raise DataError(f"{term.effect}: columns of shape {cols.shape} on joint "
                            f"{sig.joints[j]}, expected {(idx.size, c)}")
        out[order[idx]] = cols
    if not np.all(np.isfinite(out)):
        raise DataError(f"{term.effect}: non-finite columns on joint {sig.joints[j]}")
    return out


def fit_rows_design(lib: Library, s: Signals, keep: np.ndarray) -> Design:
    """The design of the samples ``s`` as they are (already filtered, differentiated and
    decimated: a fit's rows), selected by ``keep`` (n,).

    Every column, those added by the refinement too (:meth:`Design.with_term`), is evaluated
    on these samples with no further filtering or decimation (decimation 1, no trim, no
    guard): the states and torque are the n-dof fit's, so are the rows. When ``s`` carries
    the fit's direction (``s.sign``, module docstring) the design's signals carry it on the
    kept rows.

    Raises
    ------
    DataError
        ``keep`` of the wrong length, or too few rows kept for the library.
    """
    keep = np.asarray(keep, dtype=bool)
    if keep.shape != s.q.shape:
        raise DataError(f"fit_rows_design: keep has {keep.size} entries, expected {s.q.size}")
    b = len(lib.names())
    blocks = []
    for e in np.unique(s.experiment):
        idx = np.flatnonzero(s.experiment == e)
        sub = s.take(idx)
        stack = np.empty((4 + b, idx.size))
        stack[0], stack[1], stack[2], stack[3] = sub.tau, sub.q, sub.dq, sub.ddq
        for term, sl in lib.slices():
            stack[4 + sl.start:4 + sl.stop] = term.columns(sub).T
        blocks.append(_Block(sub=sub, full=sub, index=np.arange(idx.size), dec=stack,
                             mask=keep[idx]))
    Y, W, dsig, _ = _assemble(blocks, b, s.revolute)
    if s.sign is not None:  # the kept rows' direction (the refinement's scoring reads it)
        dsig = replace(dsig, sign=np.concatenate([bl.sub.sign[bl.mask] for bl in blocks]))
    return Design(Y=Y, W=W, names=tuple(lib.names()), library=lib, signals=dsig,
                  cutoff_hz=float("nan"), decimation=1, trim=0, dq_min=None, tau_min=None,
                  guard=0, torque_delay=0.0, _blocks=blocks)


def joint_coulomb(model: Any, j: int) -> float | None:
    """Joint j's Coulomb friction in a fitted n-dof model [N m]: ``FC<n>`` (usual) or
    ``c_m<n>`` (paper, motor quadrant at speed), n the joint's number; None if absent."""
    n = model.numbers_[j]
    for name in (f"FC{n}", f"c_m{n}"):
        if name in model.params_:
            return float(model.params_[name])
    return None
