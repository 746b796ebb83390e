"""The Stribeck velocity q_s of the paper's friction model, defined once (issue 24).

A ground-floor module beside :mod:`trajectories.robot` (contract ``robot-floor``), kept out of
that package so the single-joint plant and fit do not import pinocchio for one exponential.

``E = exp(-|dq| / q_s)`` (paper eq. 29, 44) enters the load-dependent and quadrant dry
friction of the ``paper`` model; planning, simulation (:mod:`sim_drivers`) and identification
(:mod:`ident`) compute it with :func:`stribeck_exp` and take the default from
:data:`DEFAULT_Q_S`. (The simulators' per-step scalar loops inline the same expression with
``math.exp`` for speed; they say so where they do.)
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

#: Default Stribeck velocity q_s [rad/s or m/s]: the paper's a-priori 0.03 rad/s (section III.D).
DEFAULT_Q_S = 0.03


def stribeck_exp(dq: ArrayLike, q_s: ArrayLike) -> np.ndarray:
    """``exp(-|dq| / q_s)`` (eq. 29), elementwise with numpy broadcasting.

    Parameters
    ----------
    dq : array_like
        Joint velocity [rad/s or m/s].
    q_s : array_like
        Stribeck velocity q_s [rad/s or m/s], > 0 (not checked here: the callers validate it).

    Returns
    -------
    ndarray
        E in (0, 1], the shape of ``dq`` broadcast with ``q_s``.
    """
    return np.exp(-np.abs(dq) / q_s)
