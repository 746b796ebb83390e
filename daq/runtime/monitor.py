"""Torque monitoring in the cycle loop: the residual of an identified model (filtered, or a
generalized-momentum observer's), its thresholds, collision events, an optional safe stop,
and staged pushes on a simulated arm.

(Past 600 lines: the two residuals, the per-cycle check that logs them and the reader of
their log channels share the message layout; one module keeps it in one place.)

Every cycle of a run's ``run`` phase (approach, plan, settle) the engine
(:mod:`daq.runtime.engine`) hands :meth:`TorqueMonitor.step` the measured joint positions q
[rad], velocities dq [rad/s] (0x606C) and torques tau [N m] (torque actual 0x6077). The same
causal low-pass -- a second-order state-variable filter, natural frequency ``2 pi
cutoff_hz``, damping 1/sqrt(2) (Butterworth), discretised exactly (zero-order hold) -- gives
the filtered q, dq, its derivative ddq and the filtered tau; the residual is::

    r_j = tau_f,j - clip(tau_f,j, lo_j, hi_j),   (lo, hi) = predict(q_f, dq_f, ddq_f)

with ``predict`` the identified model (``ident.monitor.TorquePredictor.band``, built by the
application layer; this module only calls it): the predicted torque (lo = hi) while the joint
moves, the interval of its static friction near rest, where the sign of the velocity -- and
so the friction -- is not known (then r_j = 0 inside the interval). Filtering the measured
torque with the same filter keeps both sides delayed alike. A collision (an external force
on a link) moves the arm without passing through the drives' torque: r_j is then about
``-(J^T F)_j``.

The other residual, ``residual="observer"`` (:class:`ObserverResidual`,
:class:`MomentumObserver`): De Luca and Mattone's generalized-momentum observer on the
measured q, dq, tau themselves (no filter, no acceleration), ``r -> external torque`` through
a first-order low-pass of gain K_O [1/s]; the residual is ``-(r - clip(r, -w, w))`` with w
the low-passed bound of the static friction's share near rest (the same meaning as the band's
interval), so it is about ``-(J^T F)`` like the filtered one. :func:`residual_for` is the one
place that makes either; its velocity (dq_f, or the measured dq for the observer) sets the
regime.

Each joint's regime is its *moving time* ``moving_s``: how long [s] its filtered velocity has
kept its sign with ``|dq_f,j| >= v_rest_j`` (0 at rest, at a reversal and at breakaway; the
rest velocity of the model's band); with a stuck velocity ``v_stuck_j``, minus the time [s]
the *measured* |dq_j| has stayed at most v_stuck_j (held by static friction). The thresholds
may depend on it: ``edges_s`` cut it into bins (bin b: ``edges_s[b-1] <= moving_s <
edges_s[b]``) and each bin has its band, so the band can be wide right after a reversal or
a start and narrow while the joint moves steadily (``ident.monitor.Thresholds``: the
validation residual's statistics per bin). The bin is found by bisection over the few
edges: O(k) per cycle.

A joint's residual outside ``[lower_j, upper_j]`` of its current bin (``mean +- k sigma``
of a validation run) after the first ``warmup_s`` of the phase is a ``collision``
event on ``/events`` (one per crossing: the joint must come back inside before it counts
again), and with ``stop=True`` the run stops through the engine's stop sequence (quick stop,
disable: the same path as a limit). Without thresholds (``calibrate``) the residual is only
logged.

Every monitored cycle writes one ``/monitor/<k>/residual`` message per joint
(``jointid_msgs/msg/MonitorSample``, CDR, docs/log-format.md); :func:`read_monitor` reads
them back with the reference MCAP reader.

Staged pushes (simulated arm only): a :class:`PushSpec` ``t0_s`` after the start of the run
phase stages :func:`sim_drivers.arm_push.staged_push` on the arm (``push`` event, axis = the
pushed joint); the arm applies it from its next step.
"""

from __future__ import annotations

import json
import math
import struct
import time
from bisect import bisect_right
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import scipy.linalg

from daq import ConfigError
from daq.protocol.logformat import MONITOR_OBSERVER_GAIN, MONITOR_RESIDUALS
from daq.protocol.reader import read_topics
from sim_drivers.arm_push import staged_push

__all__ = ["DEFAULT_OBSERVER_GAIN", "MONITOR_SCHEMA", "RESIDUALS", "FilteredResidual",
           "MomentumObserver", "MonitorRecord", "ObserverResidual", "PushSpec", "SVFilter",
           "TorqueMonitor", "moving_seconds", "read_monitor", "residual_for"]

MONITOR_SCHEMA_NAME = "jointid_msgs/msg/MonitorSample"
MONITOR_SCHEMA = """\
int64 cycle
float64 t             # [s] campaign time of the cycle
float64 residual      # [N m] filtered measured torque minus the model's prediction
float64 lower         # [N m] lower threshold (-inf: none)
float64 upper         # [N m] upper threshold (+inf: none)
float64 tau_filtered  # [N m] measured torque (0x6077), low-passed
float64 tau_predicted # [N m] the model's torque at the filtered state (nearest in its
                      # interval near rest)
float64 moving_s      # [s] time the filtered velocity has kept its sign above the rest
                      # velocity (the regime of the thresholds); negative: minus the time
                      # the measured velocity has been within the stuck velocity
uint8 armed           # 1 when crossings count (after the warm-up)
"""
_SAMPLE = struct.Struct("<4sqdddddddB")
_FIELDS = [("head", "V4"), ("cycle", "<i8"), ("t", "<f8"), ("residual", "<f8"),
           ("lower", "<f8"), ("upper", "<f8"), ("tau_filtered", "<f8"), ("tau_predicted", "<f8")]
_SAMPLE_DTYPE = np.dtype([*_FIELDS, ("moving_s", "<f8"), ("armed", "u1")])
#: logs written before the moving time (61-byte messages): moving_s reads as NaN
_SAMPLE_DTYPE_1 = np.dtype([*_FIELDS, ("armed", "u1")])
_MAX_AXES = 64
_CDR_HEADER = b"\x00\x01\x00\x00"


class SVFilter:
    """Second-order state-variable low-pass of k signals: y'' = wn^2 (u - y) - 2 zeta wn y',
    discretised exactly for a input held over each cycle. State: y (filtered) and y'
    (its derivative)."""

    def __init__(self, cutoff_hz: float, cycle_s: float, k: int, zeta: float = 2 ** -0.5
                 ) -> None:
        if not 0 < cutoff_hz < 0.5 / cycle_s:
            raise ConfigError(f"monitor cutoff: expected 0 < cutoff_hz < {0.5 / cycle_s:g} "
                              f"(Nyquist), got {cutoff_hz}")
        wn = 2.0 * math.pi * cutoff_hz
        a = np.array([[0.0, 1.0, 0.0], [-wn * wn, -2.0 * zeta * wn, wn * wn],
                      [0.0, 0.0, 0.0]])
        e = scipy.linalg.expm(a * cycle_s)
        (self.a11, self.a12, self.b1), (self.a21, self.a22, self.b2) = (
            e[0].tolist(), e[1].tolist())
        self.k = k
        self.y = [0.0] * k
        self.dy = [0.0] * k

    def reset(self, u: Sequence[float]) -> None:
        """At rest on ``u`` (y = u, y' = 0)."""
        self.y = [float(x) for x in u]
        self.dy = [0.0] * self.k

    def update(self, u: Sequence[float]) -> None:
        """One cycle with input ``u`` (k values)."""
        a11, a12, b1, a21, a22, b2 = self.a11, self.a12, self.b1, self.a21, self.a22, self.b2
        y, dy = self.y, self.dy
        self.y = [a11 * y0 + a12 * d0 + b1 * x for y0, d0, x in zip(y, dy, u, strict=True)]
        self.dy = [a21 * y0 + a22 * d0 + b2 * x for y0, d0, x in zip(y, dy, u, strict=True)]


#: the residuals :class:`TorqueMonitor` can check (:func:`residual_for`; the log format's)
RESIDUALS = MONITOR_RESIDUALS
#: default gain K_O [1/s] of the momentum observer (the log format's, where it is explained)
DEFAULT_OBSERVER_GAIN = MONITOR_OBSERVER_GAIN


class FilteredResidual:
    """The filtered residual (module docstring): ``predict(q_f, dq_f, ddq_f) -> (lo, hi)``
    [N m] the model's torque interval at the filtered state, ``cutoff_hz`` the filters'."""

    kind = "filtered"

    def __init__(self, predict: Callable[..., Any], k: int, cycle_s: float,
                 cutoff_hz: float) -> None:
        self.predict = predict
        self._fq = SVFilter(cutoff_hz, cycle_s, k)
        self._fdq = SVFilter(cutoff_hz, cycle_s, k)
        self._ftau = SVFilter(cutoff_hz, cycle_s, k)
        self._n = 0

    def step(self, q: Sequence[float], dq: Sequence[float], tau: Sequence[float]
             ) -> tuple[list[float], list[float], list[float], list[float]]:
        """One cycle of measured q [rad], dq [rad/s], tau [N m]: (residual, the torque it
        compares (tau_f), the model's torque nearest to it, the velocity of the regime
        (dq_f)) per joint."""
        if self._n == 0:
            self._fq.reset(q)
            self._fdq.reset(dq)
            self._ftau.reset(tau)
        else:
            self._fq.update(q)
            self._fdq.update(dq)
            self._ftau.update(tau)
        self._n += 1
        p_lo, p_hi = self.predict(self._fq.y, self._fdq.y, self._fdq.dy)
        tau_f = self._ftau.y
        r, pred = [], []
        for x, lo, hi in zip(tau_f, p_lo, p_hi, strict=True):
            pr = lo if x < lo else hi if x > hi else x
            pred.append(pr)
            r.append(x - pr)
        return r, tau_f, pred, self._fdq.y


class MomentumObserver:
    """De Luca and Mattone's generalized-momentum observer of k joints, one cycle at a time
    (docs/monitoring.md)::

        r(t) = K_O [ p(t) - p(t0) - integral_t0^t (beta + r) ds ],   p = M(q) dq,
        beta = tau_out + C(q, dq)^T dq - g(q)

    so dr/dt = K_O (tau_ext - r): r is the external torque (plus the model's error) through
    a first-order low-pass of time constant 1 / K_O. Discretised with the trapezoid rule on
    beta and r held over the cycle (pole 1 - K_O dt, hence 0 < K_O dt < 1)::

        s_k = s_(k-1) + dt (beta_(k-1) + beta_k) / 2 + dt r_(k-1),   r_k = K_O (p_k - s_k)

    Where beta is only known within +-w (the static friction near rest), the error it leaves
    in r is bounded by the same low-pass of w: :attr:`w`.
    """

    def __init__(self, gain: float, cycle_s: float, k: int) -> None:
        if not 0 < gain * cycle_s < 1:
            raise ConfigError(f"observer gain: expected 0 < K_O < {1 / cycle_s:g} 1/s (1 / "
                              f"cycle), got {gain}")
        self.gain, self.cycle_s, self.k = float(gain), float(cycle_s), k
        self.reset()

    def reset(self) -> None:
        """The next :meth:`update` starts the observer (r = 0 there)."""
        self.r = [0.0] * self.k  # [N m] the external torque's estimate
        self.w = [0.0] * self.k  # [N m] the bound of r's error from beta's interval
        self._s: list[float] | None = None
        self._beta = [0.0] * self.k
        self._hw = [0.0] * self.k

    def update(self, p: Sequence[float], beta: Sequence[float], half: Sequence[float]
               ) -> list[float]:
        """One cycle: momentum ``p`` [N m s], ``beta`` [N m] (class docstring) and the
        half-width of its interval ``half`` [N m]; returns r [N m] (also :attr:`r`)."""
        dt, kg = self.cycle_s, self.gain
        if self._s is None:
            self._s = [float(x) for x in p]
        else:
            h, a = 0.5 * dt, kg * dt
            self._s = [s + h * (b0 + b1) + dt * r for s, b0, b1, r in zip(
                self._s, self._beta, beta, self.r, strict=True)]
            self.w = [(1.0 - a) * w + a * 0.5 * (w0 + w1) for w, w0, w1 in zip(
                self.w, self._hw, half, strict=True)]
        self.r = [kg * (x - s) for x, s in zip(p, self._s, strict=True)]
        self._beta = [float(b) for b in beta]
        self._hw = [float(x) for x in half]
        return self.r


class ObserverResidual:
    """The observer residual: ``terms(q, dq, tau) -> (p, beta, half)`` the model's
    momentum, rate and its interval at the measured sample (no filter, no acceleration),
    :class:`MomentumObserver` of gain K_O [1/s]; the residual is ``-(r - clip(r, -w, w))``
    (0 where the static friction could explain r; the sign of the filtered residual: about
    ``-(J^T F)`` under a push)."""

    kind = "observer"

    def __init__(self, terms: Callable[..., Any], k: int, cycle_s: float, gain: float
                 ) -> None:
        self.terms = terms
        self.observer = MomentumObserver(gain, cycle_s, k)

    def step(self, q: Sequence[float], dq: Sequence[float], tau: Sequence[float]
             ) -> tuple[list[float], list[float], list[float], list[float]]:
        """One cycle (as :meth:`FilteredResidual.step`): (residual, the measured torque,
        the measured torque minus the residual, the measured velocity)."""
        p, beta, half = self.terms(q, dq, tau)
        r = self.observer.update(p, beta, half)
        res, pred = [], []
        for x, h, t in zip(r, self.observer.w, tau, strict=True):
            c = -h if x < -h else h if x > h else x  # what the static friction can explain
            res.append(c - x)
            pred.append(float(t) - (c - x))
        return res, [float(t) for t in tau], pred, [float(v) for v in dq]


def residual_for(kind: str, model: Callable[..., Any], k: int, cycle_s: float, *,
                 cutoff_hz: float = 20.0, gain: float = DEFAULT_OBSERVER_GAIN
                 ) -> FilteredResidual | ObserverResidual:
    """The one place a residual is made: ``filtered`` (``model`` the band
    ``predict(q, dq, ddq) -> (lo, hi)``, ``cutoff_hz``) or ``observer`` (``model`` the
    observer's ``terms(q, dq, tau) -> (p, beta, half)``, ``gain`` K_O [1/s])."""
    if kind == "filtered":
        return FilteredResidual(model, k, cycle_s, cutoff_hz)
    if kind == "observer":
        return ObserverResidual(model, k, cycle_s, gain)
    raise ConfigError(f"monitor residual {kind!r}: expected one of {', '.join(RESIDUALS)}")


def _table(x: Sequence[Any] | None, k: int, nb: int, default: float) -> list[list[float]]:
    """Thresholds per joint and regime bin (k x nb): ``x`` one value per joint (every bin)
    or one row of nb per joint; None: ``default`` everywhere."""
    if x is None:
        return [[default] * nb for _ in range(k)]
    if len(x) != k:
        raise ConfigError(f"monitor: expected {k} thresholds (one per joint)")
    rows = [[float(v)] * nb if np.ndim(v) == 0 else [float(y) for y in v] for v in x]
    if any(len(r) != nb for r in rows):
        raise ConfigError(f"monitor: expected one threshold per regime bin ({nb}) of each "
                          "joint")
    return rows


def moving_seconds(dq_f: Any, rest_velocity: Any, cycle_s: float, dq: Any = None,
                   stuck_velocity: Any = None) -> np.ndarray:
    """The regime [s] of :class:`TorqueMonitor` over a run, offline: (n, k) from the
    filtered velocities ``dq_f`` (n, k) [rad/s] of its cycles, ``rest_velocity`` per joint
    [rad/s] (the same per-cycle rule: 0 when the sign changed or ``|dq_f| < v_rest``, else
    one cycle more); with the measured velocities ``dq`` (n, k) [rad/s] and
    ``stuck_velocity`` per joint [rad/s], minus the time a joint has been stuck (``|dq| <=
    v_stuck`` this cycle and the ones before) where it is."""
    d = np.asarray(dq_f, float)
    vr = np.broadcast_to(np.asarray(rest_velocity, float), d.shape[1:])
    sg = np.sign(d).astype(int)
    prev = np.vstack([np.zeros((1, d.shape[1]), int), sg[:-1]])
    reset = (sg != prev) | (np.abs(d) < vr)
    idx = np.arange(d.shape[0])[:, None]
    last = np.maximum.accumulate(np.where(reset, idx, -1), axis=0)
    n = np.where(last >= 0, idx - last, idx + 1)  # never reset yet: counting from the start
    if dq is not None and stuck_velocity is not None:
        vs = np.broadcast_to(np.asarray(stuck_velocity, float), d.shape[1:])
        st = np.abs(np.asarray(dq, float)) <= vs
        free = np.maximum.accumulate(np.where(~st, idx, -1), axis=0)  # last cycle not stuck
        n = np.where(st, -(idx - free), n)
    return n * float(cycle_s)


@dataclass(frozen=True)
class PushSpec:
    """A push to stage on the simulated arm: ``force_N`` [N] on the link of moving joint
    ``joint`` (0-based) from ``t0_s`` [s] after the run phase starts, for ``duration_s``
    [s]; ``point`` (joint frame [m]) and ``direction`` (world) default as
    :func:`sim_drivers.arm_push.staged_push`."""

    joint: int
    force_N: float
    t0_s: float
    duration_s: float = 0.2
    point: tuple[float, float, float] | None = None
    direction: tuple[float, float, float] | None = None


@dataclass
class MonitorRecord:
    """What a monitored run did (one per payload run)."""

    index: int
    staged: list[tuple[int, PushSpec]] = field(default_factory=list)  # (cycle, push)
    detections: list[tuple[int, int, float]] = field(default_factory=list)  # cycle, joint, r
    cycles: int = 0
    armed_cycles: int = 0
    step_s_max: float = 0.0  # [s] longest step() (wall time)
    step_s_total: float = 0.0


def _none(payload: Any) -> None:
    """No model (the residual's check at construction)."""
    return None


class TorqueMonitor:
    """The per-cycle check (module docstring).

    Parameters
    ----------
    predictor_for : callable
        ``payload -> model`` for a run with that payload: for the filtered residual
        ``predict(q, dq, ddq) -> (lo, hi)`` (k values each) [N m], the torque interval of
        the identified model; for the observer ``terms(q, dq, tau) -> (p, beta, half)``
        (:class:`ObserverResidual`).
    joints : sequence of str
        Joint names (k), the drives' order.
    cycle_s : float
        Control cycle [s].
    lower, upper : sequence, optional
        Thresholds per joint [N m]: one value per joint, or per joint one value per regime
        bin (``len(edges_s) + 1``); None: calibration (log only).
    edges_s : sequence of float
        Edges of the regime bins on the moving time [s] (increasing; empty: one band).
    rest_velocity : float or sequence of float
        Per joint [rad/s]: below it the joint's moving time is 0 (the model's rest band).
    stuck_velocity : float or sequence of float, optional
        Per joint [rad/s]: while the measured |dq| is at most this, the joint is stuck and
        its regime is minus the time it has been (None: never stuck, the regime >= 0).
    cutoff_hz : float
        Cut-off of the filter [Hz] (filtered residual).
    residual : str
        ``filtered`` or ``observer`` (:func:`residual_for`).
    observer_gain : float
        The observer's gain K_O [1/s].
    warmup_s : float
        Crossings are not counted during the first ``warmup_s`` [s] of the run phase (the
        filter's start transient).
    stop : bool
        A crossing stops the run (quick stop, disable).
    persist_cycles : int
        A crossing counts when the residual has been outside its band for this many
        consecutive armed cycles (1: at once; the thresholds file's).
    pushes : sequence of PushSpec
        Pushes to stage on the simulated arm (needs :attr:`arm`).
    """

    def __init__(self, predictor_for: Callable[[Any], Callable[..., Sequence[float]]],
                 joints: Sequence[str], cycle_s: float, *,
                 lower: Sequence[Any] | None = None, upper: Sequence[Any] | None = None,
                 edges_s: Sequence[float] = (), rest_velocity: float | Sequence[float] = 0.0,
                 cutoff_hz: float = 20.0, warmup_s: float = 0.25, stop: bool = False,
                 pushes: Sequence[PushSpec] = (), residual: str = "filtered",
                 observer_gain: float = DEFAULT_OBSERVER_GAIN,
                 stuck_velocity: float | Sequence[float] | None = None,
                 persist_cycles: int = 1) -> None:
        self.predictor_for = predictor_for
        if isinstance(persist_cycles, bool) or int(persist_cycles) != persist_cycles or not (
                persist_cycles >= 1):
            raise ConfigError(f"monitor: persist_cycles: expected an integer >= 1, got "
                              f"{persist_cycles}")
        self.persist_cycles = int(persist_cycles)
        self.joints = list(joints)
        k = self.k = len(self.joints)
        self.cycle_s = float(cycle_s)
        if (lower is None) != (upper is None):
            raise ConfigError("monitor: give both thresholds (lower and upper) or neither")
        self.edges_s = [float(e) for e in edges_s]
        if any(b <= a for a, b in zip(self.edges_s, self.edges_s[1:], strict=False)):
            raise ConfigError(f"monitor: regime edges {self.edges_s}: expected increasing")
        nb = len(self.edges_s) + 1
        #: per joint, per regime bin [N m]
        self.lower = _table(lower, k, nb, -math.inf)
        self.upper = _table(upper, k, nb, math.inf)
        vr = rest_velocity if np.ndim(rest_velocity) else [rest_velocity] * k
        self.rest_velocity = [float(v) for v in vr]  # type: ignore[union-attr]
        if len(self.rest_velocity) != k:
            raise ConfigError(f"monitor: rest_velocity: expected {k} values (one per joint)")
        vs = (-1.0 if stuck_velocity is None else stuck_velocity)
        vs = vs if np.ndim(vs) else [vs] * k
        self.stuck_velocity = [float(v) for v in vs]  # type: ignore[union-attr]
        if len(self.stuck_velocity) != k:
            raise ConfigError(f"monitor: stuck_velocity: expected {k} values (one per joint)")
        self.cutoff_hz = float(cutoff_hz)
        self.warmup_cycles = int(round(warmup_s / self.cycle_s))
        self.stop = bool(stop)
        self.pushes = sorted(pushes, key=lambda p: p.t0_s)
        for p in self.pushes:
            if not 0 <= p.joint < k:
                raise ConfigError(f"push on joint index {p.joint}: expected 0..{k - 1}")
        self.arm: Any = None  # sim_drivers.arm_bus.ArmOnBus when simulated
        self.records: list[MonitorRecord] = []
        self.residual = residual
        self.observer_gain = float(observer_gain)
        residual_for(residual, _none, k, self.cycle_s, cutoff_hz=self.cutoff_hz,
                     gain=self.observer_gain)  # checks kind, cut-off and gain now
        self._log: Any = None
        self._channels: list[int] = []
        self._res: FilteredResidual | ObserverResidual | None = None
        #: the velocity of the regime at the last cycle [rad/s] (filtered: dq_f; observer: dq)
        self.velocity: list[float] = [0.0] * k
        self._n = 0
        self._disarmed_until = 0
        self._next_push = 0
        self._out = [False] * k
        self._moving = [0] * k  # cycles the filtered velocity kept its sign above v_rest
        self._sign = [0] * k
        self._stuck = [0] * k  # cycles the measured |dq| stayed at most v_stuck
        self._over = [0] * k  # consecutive armed cycles outside the band

    # -- per run ---------------------------------------------------------------------------
    def begin(self, index: int, payload: Any, log: Any) -> None:
        """A payload run starts: the model for its payload, the log's channels."""
        self._res = residual_for(self.residual, self.predictor_for(payload), self.k,
                                 self.cycle_s, cutoff_hz=self.cutoff_hz,
                                 gain=self.observer_gain)
        self._log = log
        self._channels = []
        w = getattr(log, "_w", None)
        if w is not None:
            sid = w.register_schema(MONITOR_SCHEMA_NAME, "ros2msg", MONITOR_SCHEMA.encode())
            self._channels = [w.register_channel(f"/monitor/{j}/residual", "cdr", sid)
                              for j in range(self.k)]
            w.add_metadata("monitor", {
                "joints": json.dumps(self.joints), "cutoff_hz": repr(self.cutoff_hz),
                "residual": self.residual, "observer_gain": repr(self.observer_gain)
                if self.residual == "observer" else "",
                "lower": json.dumps(self.lower), "upper": json.dumps(self.upper),
                "edges_s": json.dumps(self.edges_s),
                "rest_velocity": json.dumps(self.rest_velocity),
                "stuck_velocity": json.dumps(self.stuck_velocity),
                "warmup_cycles": str(self.warmup_cycles), "stop": str(self.stop).lower(),
                "persist_cycles": str(self.persist_cycles),
                "pushes": json.dumps([p.__dict__ for p in self.pushes])})
        self._n = 0
        self._disarmed_until = 0
        self._next_push = 0
        self._out = [False] * self.k
        self._moving = [0] * self.k
        self._sign = [0] * self.k
        self._stuck = [0] * self.k
        self._over = [0] * self.k
        self.records.append(MonitorRecord(index))

    def step(self, cycle: int, t: float, q: Sequence[float], dq: Sequence[float],
             tau: Sequence[float], log: Any, valid: bool = True) -> tuple[str, int]:
        """One run-phase cycle; returns (reason, joint) of a crossing that stops the run,
        else ("", -1). ``valid`` False: a drive's TPDO was missing (its values are the
        last ones): crossings are not counted from this cycle for another warm-up."""
        t_in = time.perf_counter()
        rec = self.records[-1]
        res, tau_f, pred_all, dq_f = self._res.step(q, dq, tau)  # type: ignore[union-attr]
        self.velocity = dq_f
        n = self._n
        self._n += 1
        if not valid:  # stale values in the filters: disarm for a warm-up
            self._disarmed_until = n + self.warmup_cycles
        rec.cycles += 1
        if self._next_push < len(self.pushes) and n * self.cycle_s >= self.pushes[
                self._next_push].t0_s:
            self._stage(cycle, t, log, rec)
        armed = n >= self.warmup_cycles and n >= self._disarmed_until
        rec.armed_cycles += armed
        lo, hi, out, over, persist = (self.lower, self.upper, self._out, self._over,
                                      self.persist_cycles)
        moving, sign, v_rest = self._moving, self._sign, self.rest_velocity
        stuck, v_stuck = self._stuck, self.stuck_velocity
        edges, cycle_s = self.edges_s, self.cycle_s
        chans = self._channels
        add = getattr(log, "_add", None) if chans else None
        ts = log.start_ns + cycle * log.cycle_ns if add is not None else 0
        now_ns = time.time_ns()
        stop_why, stop_joint = "", -1
        for j in range(self.k):
            v = dq_f[j]
            sg = 1 if v > 0.0 else -1 if v < 0.0 else 0
            moving[j] = 0 if sg != sign[j] or abs(v) < v_rest[j] else moving[j] + 1
            sign[j] = sg
            # stuck: the measured velocity at most v_stuck (static friction holds the joint);
            # logged as minus the time it has been stuck
            stuck[j] = stuck[j] + 1 if abs(dq[j]) <= v_stuck[j] else 0
            mv = -stuck[j] * cycle_s if stuck[j] else moving[j] * cycle_s
            b = bisect_right(edges, mv) if edges else 0
            lo_j, hi_j = lo[j][b], hi[j][b]
            x, pred, r = tau_f[j], pred_all[j], res[j]
            if add is not None:
                add(chans[j], ts, _SAMPLE.pack(_CDR_HEADER, cycle, t, r, lo_j, hi_j, x, pred,
                                               mv, armed), now_ns, cycle)
            if not armed:
                over[j] = 0
                continue
            over[j] = over[j] + 1 if r < lo_j or r > hi_j else 0
            crossed = over[j] >= persist
            if crossed and not out[j]:
                rec.detections.append((cycle, j, r))
                why = (f"{self.joints[j]}: torque residual {r:+.3f} N m outside "
                       f"[{lo_j:.3f}, {hi_j:.3f}] (collision?)")
                log.event(cycle, t, "collision", why, j)
                if self.stop and not stop_why:
                    stop_why, stop_joint = why, j
            out[j] = crossed
        dt = time.perf_counter() - t_in
        rec.step_s_total += dt
        rec.step_s_max = max(rec.step_s_max, dt)
        return stop_why, stop_joint

    def _stage(self, cycle: int, t: float, log: Any, rec: MonitorRecord) -> None:
        spec = self.pushes[self._next_push]
        self._next_push += 1
        arm = self.arm
        plant = arm.plant
        p = staged_push(plant.model, plant.q, spec.joint, spec.force_N, plant.t,
                        spec.duration_s, point=spec.point, direction=spec.direction)
        arm.push(p)
        rec.staged.append((cycle, spec))
        log.event(cycle, t, "push", f"{self.joints[spec.joint]}: {spec.force_N:g} N for "
                  f"{spec.duration_s:g} s at {list(p.point)} m (joint frame), force "
                  f"{[round(f, 3) for f in p.force]} N (world)", spec.joint)


# --------------------------------------------------------------------------- reading back
@dataclass(frozen=True)
class MonitorLog:
    """``/monitor/<k>/residual`` of one run log, one column per joint (cycles aligned)."""

    cycle: np.ndarray
    t: np.ndarray
    residual: np.ndarray  # (n, k) [N m]
    lower: np.ndarray
    upper: np.ndarray
    tau_filtered: np.ndarray
    tau_predicted: np.ndarray
    moving_s: np.ndarray  # (n, k) [s] the regime (NaN: a log without it)
    armed: np.ndarray  # (n,) bool
    events: list[dict[str, Any]]
    metadata: dict[str, str]


def _decode(msgs: list[bytes]) -> np.ndarray:
    """The MonitorSample messages of one channel as a structured array (either layout)."""
    dt = _SAMPLE_DTYPE_1 if len(msgs[0]) == _SAMPLE_DTYPE_1.itemsize else _SAMPLE_DTYPE
    return np.frombuffer(b"".join(msgs), dt)


def read_monitor(path: str | Path) -> MonitorLog:
    """Read the monitor channels, the events and the ``monitor`` metadata of a run log
    (with the fast chunk scanner of :mod:`daq.protocol.reader`; the reference reader gives
    the same messages, tests/test_monitor.py).

    Raises
    ------
    ConfigError
        The log has no ``/monitor`` channel (not a monitored run).
    daq.protocol.reader.LogReadError
        Not a readable MCAP file.
    """
    topics = {f"/monitor/{j}/residual": j for j in range(_MAX_AXES)}
    scan = read_topics(path, set(topics))
    cols = {topics[t]: _decode(v) for t, v in scan.raw.items() if v}
    if not cols:
        raise ConfigError(f"{path}: no /monitor channel (not a jointid monitor run)")
    k = max(cols) + 1
    n = min(len(cols.get(j, ())) for j in range(k))
    rec = [np.sort(cols[j], order="cycle")[:n] for j in range(k)]

    def stack(name: str) -> np.ndarray:
        return np.stack([r[name] for r in rec], axis=1).astype(float)

    moving = (stack("moving_s") if "moving_s" in rec[0].dtype.names
              else np.full((n, k), np.nan))
    return MonitorLog(rec[0]["cycle"].astype(np.int64), rec[0]["t"].astype(float),
                      stack("residual"), stack("lower"), stack("upper"),
                      stack("tau_filtered"), stack("tau_predicted"), moving,
                      rec[0]["armed"].astype(bool),
                      sorted(scan.events, key=lambda e: e["cycle"]),
                      dict(scan.metadata.get("monitor", {})))
