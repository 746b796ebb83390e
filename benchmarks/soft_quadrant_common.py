"""The columns the soft-quadrant benchmarks fit (``soft_quadrant_arm3.py``,
``soft_quadrant_emps.py``): one joint's ten paper-model columns at full rate with the hard
quadrants of eq. 27-28 or their expectation under a Gaussian load jitter
(:func:`trajectories.friction.soft_quadrant_weights`)."""

from __future__ import annotations

import numpy as np

from trajectories.friction import quadrant_weights, soft_quadrant_weights, stribeck_exp


def paper_columns(s: np.ndarray, dq: np.ndarray, sigma: float | None,
                  q_s: float) -> np.ndarray:
    """Eq. 30's ten columns (a_m, b_m, a_g, b_g, c_m, d_m, c_g, d_g, F_V, offset), shape
    (n, 10), for the model's load s [N m] and velocity dq [rad/s] (n,): P+ s, P+ E s, P- s,
    -P- E s, P+ sign, P+ E sign, P- sign, P- E sign, dq, 1 with the hard weights (``sigma``
    None) or, with a jitter RMS ``sigma`` [N m], E[P+ x] = E[P+] s + r and E[P- x] = E[P-] s
    - r for the load products and E[P+-] for the Coulomb ones; E = exp(-|dq| / q_s)."""
    sg = np.sign(dq)
    e = stribeck_exp(dq, q_s)
    if sigma is None:
        pp, pm = quadrant_weights(s * dq)
        rr = np.zeros_like(s)
    else:
        pp, pm, rr = soft_quadrant_weights(s, dq, sigma)
    xp, xm = pp * s + rr, pm * s - rr
    return np.stack([xp, e * xp, xm, -e * xm, pp * sg, pp * e * sg, pm * sg, pm * e * sg,
                     dq, np.ones_like(dq)], axis=1)
