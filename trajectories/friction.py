"""The Stribeck velocity q_s of the paper's friction model, defined once (issue 24).

A ground-floor module beside :mod:`trajectories.robot` (contract ``robot-floor``), kept out of
that package so the single-joint plant and fit do not import pinocchio for one exponential.

``E = exp(-|dq| / q_s)`` (paper eq. 29, 44) enters the load-dependent and quadrant dry
friction of the ``paper`` model; planning, simulation (:mod:`sim_drivers`) and identification
(:mod:`ident`) compute it with :func:`stribeck_exp` and take the default from
:data:`DEFAULT_Q_S`. (The simulators' per-step scalar loops inline the same expression with
``math.exp`` for speed; they say so where they do.) :func:`quadrant_weights` forms that
model's quadrant weights P+ and P- (eq. 27-28) and :func:`quadrant_products` its quadrant
friction columns (eq. 30, 42-44), for one joint and for n.
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


def quadrant_weights(power: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """The quadrant weights P+ = (1 + sign P) / 2 and P- = (1 - sign P) / 2 (eq. 27-28).

    The one place the paper model's weights are formed: the single-joint columns
    (:func:`ident.models.power_split`), the n-dof full-rate products
    (:mod:`ident.robot.design`), the n-dof moments, quadrant store, prediction and refit
    (:mod:`ident.robot.estimate`, :mod:`ident.robot.quadrants`, :mod:`ident.robot.refit`)
    and the exported model's predictor (:mod:`ident.robot.export_model`) call it.

    Parameters
    ----------
    power : array_like
        P or anything with its sign, per sample: the load power tau_out dq [W] (the model
        quadrant, from a load prediction) or the paper's proxy tau dq of eq. 26, or sign(P)
        itself [-]. Only its sign is read.

    Returns
    -------
    p_plus, p_minus : ndarray
        P+ and P- [-], the shape of ``power``: 1 and 0 in the motor quadrant (P > 0), 0 and 1
        in the generator quadrant (P < 0), both 0.5 where P = 0 (the sample counts half in
        each), NaN where P is NaN. P+ + P- = 1.
    """
    sp = np.sign(power)
    return 0.5 * (1.0 + sp), 0.5 * (1.0 - sp)


def soft_quadrant_weights(load: ArrayLike, dq: ArrayLike,
                          sigma: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The quadrant weights' expectation under a Gaussian jitter of the load (the soft
    quadrant weight; docs/robot-identification.md, "Known limit: quadrants blended by the
    low-pass"). Used by the soft fit's start (:mod:`ident.robot.soft_fit`) and the
    benchmarks ``soft_quadrant_*.py``.

    With the true load x = s + n, n ~ N(0, sigma^2), mu = s sign(dq) and the hard weights of
    :func:`quadrant_weights` on P = x dq: E[P+] = Phi(mu / sigma), E[P+ x] = E[P+] s + r and
    E[P- x] = E[P-] s - r, with r = sigma phi(mu / sigma) sign(dq) the rectified jitter a
    low-pass keeps (Phi, phi: the standard normal distribution and density).

    Parameters
    ----------
    load : array_like
        The model's load s [N m] (or [N]) per sample, tau_out_hat: never the measured torque.
    dq : array_like
        The velocity [rad/s] (or [m/s]), the shape of ``load``; only its sign is read.
    sigma : float
        The jitter's RMS [N m] (or [N]), > 0.

    Returns
    -------
    p_plus, p_minus, rect : ndarray
        E[P+], E[P-] = 1 - E[P+] [-] and r [N m], the shape of ``load``; 0.5, 0.5 and 0 where
        dq = 0 (as :func:`quadrant_weights` at P = 0). As sigma -> 0 they tend to the hard
        weights and 0 wherever s != 0.
    """
    sigma = float(sigma)
    if not (np.isfinite(sigma) and sigma > 0):
        raise ValueError(f"soft_quadrant_weights: sigma: expected a positive jitter RMS "
                         f"[N m], got {sigma!r}")
    from scipy.special import ndtr  # (here: the single-joint path imports this module)
    sg = np.sign(np.asarray(dq, dtype=float))
    z = np.asarray(load, dtype=float) * sg / sigma
    p_plus = ndtr(z)
    rect = sigma * np.exp(-0.5 * z * z) / np.sqrt(2.0 * np.pi) * sg
    return p_plus, 1.0 - p_plus, rect


def quadrant_products(
    x: np.ndarray,
    p_plus: np.ndarray,
    p_minus: np.ndarray,
    e: np.ndarray | None = None,
    *,
    load: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """The quadrant products of the paper model's friction columns (eq. 30, 42-44), one half.

    Without ``e`` the q_s-free half, ``(P+ x, P- x)``; with ``e`` the half that carries
    E = exp(-|dq| / q_s) (eq. 29), ``(P+ E x, -P- E x)`` for load columns (``load``:
    the b_m, b_g columns of eq. 42-43) or ``(P+ E x, P- E x)`` for x = sign(dq) (the d_m, d_g
    columns of eq. 30). The halves are apart so that a q_s scan forms (and filters) the
    q_s-free one once. One joint (:class:`ident.models.LoadDependent`,
    :class:`ident.models.QuadrantCoulomb`) and n joints (:func:`ident.robot.design.
    products_columns`) compute their columns here.

    Parameters
    ----------
    x : ndarray
        What the weights multiply: load columns W_in [N m per parameter unit] or sign(dq) [-],
        any shape that broadcasts with the weights (e.g. (n, c) with weights (n, 1), or
        (c, n) with weights (n,)).
    p_plus, p_minus : ndarray
        P+ = (1 + sign P) / 2 and P- = (1 - sign P) / 2 (eq. 27-28, 44) [-], per sample
        (:func:`quadrant_weights`).
    e : ndarray or None
        E per sample [-], the shape of ``p_plus``; None for the q_s-free half.
    load : bool
        With ``e``: the generator product negated (load columns) or not (sign columns).

    Returns
    -------
    tuple of ndarray
        The motor and generator products, each of the broadcast shape.
    """
    if e is None:
        return p_plus * x, p_minus * x
    pe, me = p_plus * e, p_minus * e
    return pe * x, (-me if load else me) * x
