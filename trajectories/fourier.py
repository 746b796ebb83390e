"""Multi-sine (Fourier series) excitation: evaluation, rest projection, limit ratios, scaling.

``q_j(t) = q0_j + sum_l a_jl/(w l) sin(w l t) - b_jl/(w l) cos(w l t)``, l = 1..L
(Swevers et al. 1997; the parameterisation of FloBaRoID). Arrays: coefficients (k, L),
samples (n, k). Pure numerics.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from .campaign import JointLimits

__all__ = [
    "GRID_PER_HARMONIC",
    "default_coefficients",
    "fit_coefficients",
    "fourier_eval",
    "multisine_ratio",
    "rest_projection",
]

#: grid points per period of the highest harmonic used to bound a Fourier series' peaks;
#: the sampled peak of a sinusoid is then within 1 - cos(pi/64) = 0.12 % of the true peak
GRID_PER_HARMONIC = 64
_GRID_MARGIN = 1.002  # covers the 0.12 % under-estimate of the grid peaks


def fourier_eval(q0: np.ndarray, a: np.ndarray, b: np.ndarray, omega: float,
                 t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Evaluate the multi-sine of every joint and its first three derivatives.

    Parameters
    ----------
    q0 : ndarray, shape (k,)
        Offsets [rad].
    a, b : ndarray, shape (k, L)
        Coefficients [rad/s].
    omega : float
        Base angular frequency w [rad/s].
    t : ndarray, shape (n,)
        Time from the start of the series [s].

    Returns
    -------
    q, dq, ddq, dddq : ndarray, shape (n, k)
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    wl = omega * np.arange(1, a.shape[1] + 1, dtype=np.float64)  # (L,)
    ph = np.outer(np.asarray(t, dtype=np.float64), wl)  # (n, L)
    s, c = np.sin(ph), np.cos(ph)
    q = np.asarray(q0, dtype=np.float64) + s @ (a / wl).T - c @ (b / wl).T
    dq = c @ a.T + s @ b.T
    ddq = -s @ (a * wl).T + c @ (b * wl).T
    dddq = -c @ (a * wl**2).T - s @ (b * wl**2).T
    return q, dq, ddq, dddq


def rest_projection(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Project coefficients so that the series starts at rest: dq(0) = ddq(0) = 0.

    Removes from each row of ``a`` its mean (``sum_l a_jl = 0``) and from each row of ``b``
    its component along ``l`` (``sum_l l b_jl = 0``). Needs L >= 2 (with L = 1 the only
    series at rest is zero); returns the inputs unchanged when L = 1.
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if a.shape[1] < 2:
        return a.copy(), b.copy()
    ell = np.arange(1, a.shape[1] + 1, dtype=np.float64)
    a = a - a.mean(axis=1, keepdims=True)
    b = b - np.outer(b @ ell, ell) / (ell @ ell)
    return a, b


def _grid(omega: float, n_harm: int) -> np.ndarray:
    n = max(256, GRID_PER_HARMONIC * n_harm)
    return np.arange(n, dtype=np.float64) * (2.0 * math.pi / omega / n)


def multisine_ratio(a: np.ndarray, b: np.ndarray, q0: np.ndarray, omega: float,
                    limits: Sequence[JointLimits]) -> np.ndarray:
    """Per joint, the largest ratio of a peak to its limit over one period.

    Ratios of: position excursion above/below ``q0`` to the room up to the position limit,
    peak |dq| / max_velocity, |ddq| / max_acceleration, |dddq| / max_jerk, evaluated on a
    grid of ``GRID_PER_HARMONIC`` points per period of the highest harmonic (times
    ``1.002`` to cover the grid's under-estimate). A ratio <= 1 means within every limit.

    Returns
    -------
    ndarray, shape (k,)
    """
    return _ratios(a, b, q0, omega, limits).max(axis=1)


def _ratios(a, b, q0, omega, limits) -> np.ndarray:
    """(k, 4) ratios: position, velocity, acceleration, jerk."""
    a = np.asarray(a, dtype=np.float64)
    q, dq, ddq, dddq = fourier_eval(q0, a, b, omega, _grid(omega, a.shape[1]))
    out = np.zeros((a.shape[0], 4))
    for j, lim in enumerate(limits):
        lo, hi = lim.position
        up = (q[:, j].max() - q0[j]) / max(hi - q0[j], 1e-300)
        down = (q0[j] - q[:, j].min()) / max(q0[j] - lo, 1e-300)
        out[j] = (max(up, down, 0.0),
                  np.abs(dq[:, j]).max() / lim.max_velocity,
                  np.abs(ddq[:, j]).max() / lim.max_acceleration,
                  np.abs(dddq[:, j]).max() / lim.max_jerk)
    return out * _GRID_MARGIN


def fit_coefficients(a: np.ndarray, b: np.ndarray, q0: np.ndarray, omega: float,
                     limits: Sequence[JointLimits], fill: float = 0.8,
                     *, grow: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Scale each joint's coefficients so that its tightest limit ratio equals ``fill``.

    With ``grow=False`` coefficients are only shrunk (never enlarged). Scaling a joint's
    row scales its excursion, velocity, acceleration and jerk alike, so the result is within
    every limit whatever the input direction (rows of zeros stay zero).
    """
    a = np.array(a, dtype=np.float64)
    b = np.array(b, dtype=np.float64)
    r = multisine_ratio(a, b, np.asarray(q0, dtype=np.float64), omega, limits)
    scale = np.where(r > 0.0, fill / np.where(r > 0.0, r, 1.0), 1.0)
    if not grow:
        scale = np.minimum(scale, 1.0)
    return a * scale[:, None], b * scale[:, None]


def default_coefficients(limits: Sequence[JointLimits], q0: Sequence[float], omega: float,
                         harmonics: int, *, fill: float = 0.8, seed: int = 0
                         ) -> tuple[np.ndarray, np.ndarray]:
    """Seeded random multi-sine coefficients at rest at t = 0, scaled to ``fill``.

    Normal draws (``numpy.random.default_rng(seed)``) divided by ``l`` (lower harmonics
    carry more amplitude), :func:`rest_projection`, then :func:`fit_coefficients`.

    Returns
    -------
    a, b : ndarray, shape (k, harmonics) [rad/s]
    """
    rng = np.random.default_rng(seed)
    k = len(limits)
    ell = np.arange(1, harmonics + 1, dtype=np.float64)
    a = rng.standard_normal((k, harmonics)) / ell
    b = rng.standard_normal((k, harmonics)) / ell
    a, b = rest_projection(a, b)
    return fit_coefficients(a, b, np.asarray(q0, dtype=np.float64), omega, limits, fill)
