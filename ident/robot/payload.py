"""Per-joint check of a fitted payload: does the model's payload torque fit the payload runs?

A payload whose torque is misplaced (a guessed centre of mass, ``--payload known``) or not in
the model (a ratio that cannot carry an offset CoM) leaves a residual on the experiments that
carry it and not on the others. :func:`payload_misfit` compares, per joint, the residual RMS
of the payload rows with that of the no-payload rows of the same fit:

* ``ratio`` = rms_payload / rms_none;
* ``p_value``: one-sided F test of equal residual variances, F = ratio^2 with
  (n_payload, n_none) degrees of freedom;
* ``misfit``: p_value < alpha / k (family-wise alpha over the k joints) **and**
  ratio > ``MISFIT_RATIO`` -- the effect-size floor: filtered, decimated residuals are
  correlated, so on large data the F test alone calls differences of a few per cent
  significant.

The residual noise is assumed the same with and without the payload (a torque sensor's or a
current loop's noise); a noise that grows with the load raises the ratio too, so a flagged
joint says "look here", the parameters' sigma say how well the payload is known.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import scipy.stats

from . import RobotIdentError
from .signals import RobotSignals

__all__ = ["payload_misfit", "format_misfit", "MISFIT_RATIO"]

#: Residual RMS of the payload rows / of the no-payload rows above which (and significant) a
#: joint's payload torque is called a misfit.
MISFIT_RATIO = 1.2


def payload_misfit(model: Any, signals: RobotSignals | Sequence[RobotSignals],
                   alpha: float = 0.01, ratio: float = MISFIT_RATIO,
                   ) -> dict[str, dict[str, float | int | bool]]:
    """Per joint: residual RMS on the payload and the no-payload rows (module doc).

    Parameters
    ----------
    model : RobotModel
        A fitted estimator (``residual``, ``joints_``).
    signals : RobotSignals or sequence
        Experiments with and without payload (``payloads[experiment].mass``); rows with a
        non-finite residual (left out of the fit) are ignored.
    alpha : float
        Family-wise significance level over the joints.
    ratio : float
        Effect-size floor on rms_payload / rms_none.

    Returns
    -------
    dict
        joint name -> ``rms_payload``, ``rms_none`` [N m], ``n_payload``, ``n_none``,
        ``ratio``, ``p_value``, ``misfit``.
    """
    items = [signals] if isinstance(signals, RobotSignals) else list(signals)
    joints = tuple(model.joints_)
    k = len(joints)
    rss = np.zeros((2, k))
    cnt = np.zeros((2, k), dtype=int)
    for sig in items:
        if not isinstance(sig, RobotSignals):
            raise RobotIdentError(f"payload_misfit: expected RobotSignals, got "
                                  f"{type(sig).__name__}")
        rho = model.residual(sig)
        loaded = np.array([pl.mass > 0 for pl in sig.payloads])[sig.experiment]
        ok = np.isfinite(rho)
        for s, rows in ((0, loaded), (1, ~loaded)):
            sel = ok & rows[:, None]
            rss[s] += (np.where(sel, rho, 0.0) ** 2).sum(0)
            cnt[s] += sel.sum(0)
    if not (cnt[0].any() and cnt[1].any()):
        raise RobotIdentError("payload_misfit: needs rows with and without a payload "
                              f"(payload rows {cnt[0].tolist()}, none {cnt[1].tolist()})")
    out: dict[str, dict[str, float | int | bool]] = {}
    for j, name in enumerate(joints):
        n1, n0 = int(cnt[0, j]), int(cnt[1, j])
        r1 = float(np.sqrt(rss[0, j] / max(n1, 1)))
        r0 = float(np.sqrt(rss[1, j] / max(n0, 1)))
        q = r1 / r0 if r0 > 0 else float("inf")
        pv = float(scipy.stats.f.sf(q * q, n1, n0)) if n1 and n0 and r0 > 0 else float("nan")
        out[name] = {"rms_payload": r1, "rms_none": r0, "n_payload": n1, "n_none": n0,
                     "ratio": q, "p_value": pv,
                     "misfit": bool(pv < alpha / k and q > ratio)}
    return out


def format_misfit(check: dict[str, dict[str, float | int | bool]]) -> str:
    """The table of :func:`payload_misfit`, one line per joint."""
    lines = [f"{'joint':<12}{'rms payload':>13}{'rms none':>11}{'ratio':>8}  misfit"]
    for name, c in check.items():
        lines.append(f"{name:<12}{c['rms_payload']:>13.4g}{c['rms_none']:>11.4g}"
                     f"{c['ratio']:>8.2f}  {'YES' if c['misfit'] else 'no'}")
    return "\n".join(lines)
