"""The torque's timing in a log: aligning the position samples with the torque they explain.

A torque command computed from the position of cycle k is held by the drive over some later
cycle; the motion it explains is that cycle's middle. ``d`` [cycles] is the delay from the
position's instant to that middle. The preprocessing chain interpolates q to t_k + d dt before
anything else (:func:`shift`, ``torque_delay``, :data:`ident.preprocess.TORQUE_DELAY` = 0.5 for
jointid logs). A log that says its own timing (MCAP metadata ``campaign.torque_delay_cycles``,
docs/log-format.md: 0.5 for the simulated single-joint drive, 1.5 for the simulated arm and
for drives whose synchronous RPDO is actuated at the next SYNC) is re-paired at load time by
:func:`align_to_torque` so that the chain's 0.5 completes it.
"""

from __future__ import annotations

import math

import numpy as np

from . import DataError

__all__ = ["CHAIN_DELAY", "align_to_torque", "shift"]

#: The delay [cycles] the chain applies to jointid's logs (``ident.preprocess.TORQUE_DELAY``).
CHAIN_DELAY = 0.5


def shift(x: np.ndarray, d: float) -> np.ndarray:
    """Samples of a smooth signal interpolated to t_k + d dt (cubic Lagrange, 4 points).

    Parameters
    ----------
    x : ndarray, shape (n,)
        Uniformly sampled signal (n >= 4).
    d : float
        Fraction of a sample, 0 <= d < 1 (0 returns ``x`` unchanged).

    Returns
    -------
    ndarray, shape (n,)
        x(t_k + d dt): exact for polynomials of degree <= 3; at d = 1/2 the weights are
        (-1, 9, 9, -1)/16, gain 0.99997 at 2 % of f_s and 0.996 at 10 %. The ends are
        extrapolated linearly (they are trimmed later).
    """
    x = np.asarray(x, dtype=float)
    if d == 0:
        return x
    if not 0 < d < 1:
        raise DataError(f"torque_delay must lie in [0, 1) samples, got {d}")
    if x.size < 4:
        raise DataError(f"{x.size} samples: too few to interpolate")
    p = np.concatenate([[2 * x[0] - x[1]], x, [2 * x[-1] - x[-2], 3 * x[-1] - 2 * x[-2]]])
    w = (
        -d * (d - 1) * (d - 2) / 6,
        (d + 1) * (d - 1) * (d - 2) / 2,
        -(d + 1) * d * (d - 2) / 2,
        (d + 1) * d * (d - 1) / 6,
    )
    n = x.size
    return w[0] * p[0:n] + w[1] * p[1 : n + 1] + w[2] * p[2 : n + 2] + w[3] * p[3 : n + 3]


def align_to_torque(t: np.ndarray, q: np.ndarray, tau: np.ndarray, q_ref: np.ndarray | None,
                    delay_cycles: float, source: str = "") -> tuple:
    """Re-pair a log's samples so that the chain's half-cycle completes its torque timing.

    Torque sample k is paired with q (and q_ref) taken ``e = delay_cycles - CHAIN_DELAY``
    cycles later: the integer part of e by dropping samples (the first or the last ones), the
    fraction by :func:`shift`. The torque and its time stamps are not touched.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Time stamps of the torque samples [s].
    q : ndarray, shape (n,) or (n, k)
        Positions [rad or m].
    tau : ndarray, shape (n,) or (n, k)
        Torques [N m].
    q_ref : ndarray or None
        The reference position, shaped like q, re-paired alike.
    delay_cycles : float
        The log's ``torque_delay_cycles`` [cycles], >= 0.
    source : str
        The file, for the message.

    Returns
    -------
    t, q, tau, q_ref
        n - |floor(e)| samples each (the same arrays when e = 0).

    Raises
    ------
    DataError
        A delay that is not a finite number >= 0, or too few samples left.
    """
    d = float(delay_cycles)
    if not math.isfinite(d) or d < 0:
        raise DataError(f"{source}: metadata campaign.torque_delay_cycles {delay_cycles!r}: "
                        "expected a number >= 0 [cycles]")
    e = d - CHAIN_DELAY
    if e == 0:
        return t, q, tau, q_ref
    whole = math.floor(e)
    frac = e - whole
    n = len(t)
    if n - abs(whole) < 4:
        raise DataError(f"{source}: {n} samples: too few to align with a torque delay of "
                        f"{d:g} cycles")

    def later(x: np.ndarray | None) -> np.ndarray | None:
        if x is None:
            return None
        x = np.asarray(x, dtype=float)
        if frac:
            x = (shift(x, frac) if x.ndim == 1
                 else np.column_stack([shift(x[:, j], frac) for j in range(x.shape[1])]))
        return x[whole:] if whole >= 0 else x[:whole]

    if whole >= 0:
        cut = slice(0, n - whole)
    else:
        cut = slice(-whole, n)
    return t[cut], later(q), np.asarray(tau)[cut], later(q_ref)
