"""Smooth multi-joint excitation references for the arm simulator's tests and demos.

Per joint, a sum of sines (random phases, seeded) multiplied by a window that rises from 0 to
1 over ``ramp_s`` with a quintic smoothstep (zero velocity and acceleration at both ends) and
falls back at the end, so the reference starts and ends at rest at its centre; derivatives are
exact (product rule). Amplitudes are scaled so that each joint stays within the given range
and under the given velocity and acceleration bounds. Real multi-dof planning (Ruckig) is in
``trajectories``; this is only a test signal.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from . import SimError


@dataclass(frozen=True, eq=False)
class ArmReference:
    """A sampled reference: ``t`` (n,) [s], ``q, dq, ddq`` (n, k) [rad, rad/s, rad/s^2]."""

    t: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray


def _window(t: np.ndarray, duration: float, ramp: float) -> tuple[np.ndarray, ...]:
    """Quintic smoothstep window w, w', w'' (rise over [0, ramp], fall over the last ramp)."""
    w = np.ones_like(t)
    w1 = np.zeros_like(t)
    w2 = np.zeros_like(t)
    for sl, x, sgn in (
        (t < ramp, t / ramp, 1.0),
        (t > duration - ramp, (duration - t) / ramp, -1.0),
    ):
        xs = np.clip(x[sl], 0.0, 1.0)
        w[sl] = 10 * xs**3 - 15 * xs**4 + 6 * xs**5
        w1[sl] = sgn * (30 * xs**2 - 60 * xs**3 + 30 * xs**4) / ramp
        w2[sl] = (60 * xs - 180 * xs**2 + 120 * xs**3) / ramp**2
    return w, w1, w2


def sine_reference(
    center: Any,
    half_range: Any,
    *,
    duration_s: float = 10.0,
    cycle_s: float = 0.001,
    base_hz: float = 0.25,
    harmonics: int = 3,
    dq_max: Any = None,
    ddq_max: Any = None,
    ramp_s: float = 1.0,
    seed: int = 0,
) -> ArmReference:
    """Sum-of-sines reference per joint, entered and left at rest.

    Parameters
    ----------
    center : array_like, shape (k,)
        Centre of each joint's motion [rad]; the reference starts and ends there.
    half_range : array_like, shape (k,)
        Largest excursion from the centre [rad].
    duration_s, cycle_s : float
        Length [s] and sampling step [s].
    base_hz : float
        Fundamental frequency [Hz]; joint j uses harmonics (1..harmonics) of
        ``base_hz * (1 + 0.13 j)`` so that the joints are not in phase lock.
    harmonics : int
        Number of sines per joint; amplitude of harmonic h is proportional to 1/h.
    dq_max, ddq_max : array_like (k,), optional
        Velocity [rad/s] and acceleration [rad/s^2] bounds the amplitudes are scaled to.
    ramp_s : float
        Rise and fall time of the window [s].
    seed : int
        Seed of the phases.

    Returns
    -------
    ArmReference
    """
    center = np.atleast_1d(np.asarray(center, dtype=float))
    k = center.shape[0]
    half = np.broadcast_to(np.asarray(half_range, dtype=float), (k,))
    if not (duration_s > 2 * ramp_s > 0 and cycle_s > 0 and harmonics >= 1 and base_hz > 0):
        raise SimError("sine_reference: expected duration_s > 2 ramp_s > 0, cycle_s > 0, "
                       "base_hz > 0 and harmonics >= 1")
    n = int(round(duration_s / cycle_s)) + 1
    t = np.arange(n) * cycle_s
    w, w1, w2 = _window(t, t[-1], ramp_s)
    rng = np.random.default_rng(seed)
    q = np.empty((n, k))
    dq = np.empty((n, k))
    ddq = np.empty((n, k))
    for j in range(k):
        s = np.zeros(n)
        s1 = np.zeros(n)
        s2 = np.zeros(n)
        vel_bound = acc_bound = 0.0
        for h in range(1, harmonics + 1):
            om = 2 * math.pi * base_hz * (1 + 0.13 * j) * h
            ph = rng.uniform(0, 2 * math.pi)
            a = 1.0 / h
            s += a * np.sin(om * t + ph)
            s1 += a * om * np.cos(om * t + ph)
            s2 -= a * om * om * np.sin(om * t + ph)
            vel_bound += a * om
            acc_bound += a * om * om
        amp_bound = float(np.max(np.abs(s * w)))
        # bounds on the windowed signal's derivatives (window terms included)
        v_est = float(np.max(np.abs(w1 * s + w * s1)))
        a_est = float(np.max(np.abs(w2 * s + 2 * w1 * s1 + w * s2)))
        scale = half[j] / amp_bound
        if dq_max is not None:
            scale = min(scale, float(np.broadcast_to(dq_max, (k,))[j]) / v_est)
        if ddq_max is not None:
            scale = min(scale, float(np.broadcast_to(ddq_max, (k,))[j]) / a_est)
        q[:, j] = center[j] + scale * w * s
        dq[:, j] = scale * (w1 * s + w * s1)
        ddq[:, j] = scale * (w2 * s + 2 * w1 * s1 + w * s2)
    return ArmReference(t=t, q=q, dq=dq, ddq=ddq)


def model_reference(
    model: pin.Model,
    *,
    center: Any = None,
    fraction: float = 0.5,
    dq_fraction: float = 0.5,
    ddq_max: Any = 4.0,
    **kw: Any,
) -> ArmReference:
    """:func:`sine_reference` within a pinocchio model's joint limits.

    The centre defaults to the middle of each joint's position range (clipped to +-pi); the
    half range is ``fraction`` of the distance to the nearer limit (at most 1 rad); the
    velocity bound is ``dq_fraction`` of ``model.velocityLimit`` (1 rad/s where absent).
    Other keywords go to :func:`sine_reference`.
    """
    lo = np.maximum(np.where(np.isfinite(model.lowerPositionLimit),
                             model.lowerPositionLimit, -np.pi), -np.pi)
    hi = np.minimum(np.where(np.isfinite(model.upperPositionLimit),
                             model.upperPositionLimit, np.pi), np.pi)
    c = 0.5 * (lo + hi) if center is None else np.asarray(center, dtype=float)
    if np.any(c <= lo) or np.any(c >= hi):
        raise SimError(f"model_reference: centre {c} outside the joint limits")
    half = np.minimum(fraction * np.minimum(c - lo, hi - c), 1.0)
    vl = np.asarray(model.velocityLimit, dtype=float)
    vl = np.where((vl > 0) & np.isfinite(vl), vl, 1.0)
    return sine_reference(c, half, dq_max=dq_fraction * vl, ddq_max=ddq_max, **kw)
