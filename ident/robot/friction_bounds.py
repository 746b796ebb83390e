"""The physical bounds of the friction parameters, written once: the direct checks of
:func:`ident.robot.consistency.check_consistency` and the constraints the consistent estimate
(:func:`ident.robot.consistent_fit.fit_consistent`) puts on the friction.

They are the simulators' bounds (``sim_drivers.arm_params.ArmFriction``,
``sim_drivers.plant_config``): dissipative friction, eq. 17-25 of the paper, with the load
coefficients of eq. 25 (a_m + b_m E in the motor quadrant, a_g - b_g E in the generator one,
E = exp(-|dq| / q_s)). Every bound is an affine inequality ``g . x + h >= 0`` (or ``> 0``) on
one joint's parameters, so it is also one row of a convex program.

Two bounds read the data (:data:`PEAK_BOUNDS`, given the largest measured torque T_j of each
joint): the joint moved, so its motor overcame the static friction. At a start in the motor
quadrant (tau_out dq > 0, E = 1) the motor torque is |tau| = (a_m + b_m) |tau_out| + c_m + d_m
>= c_m + d_m (eq. 30 with the bounds above), hence c_m + d_m <= T_j; the usual model's
F_C <= T_j alike. A larger value is a term that compensates others on the fitted rows (e.g. a
Stribeck term of 1570 N m on a wrist whose torque never exceeds 950 N m), not the joint's
friction.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["FRICTION_BOUNDS", "PEAK_BOUNDS", "bound_rows", "met", "torque_peak"]

#: statement -> linear combination ((prefix, coefficient), ...) of a joint's parameters
#: (prefix + joint number is the parameter's name); ">" statements are strict.
FRICTION_BOUNDS: dict[str, tuple[tuple[str, float], ...]] = {
    "a_m > 0": (("a_m", 1.0),),
    "a_m + b_m > 0": (("a_m", 1.0), ("b_m", 1.0)),
    "a_g > 0": (("a_g", 1.0),),
    "a_g - b_g > 0": (("a_g", 1.0), ("b_g", -1.0)),
    # the stiction band widens with the load (eq. 21-23): at rest the motor quadrant's load
    # coefficient is at least the generator's (gauge-free: one payload scales both alike)
    "a_m + b_m - a_g + b_g >= 0": (("a_m", 1.0), ("b_m", 1.0), ("a_g", -1.0), ("b_g", 1.0)),
    "c_m >= 0": (("c_m", 1.0),),
    "c_g >= 0": (("c_g", 1.0),),
    "c_m + d_m >= 0": (("c_m", 1.0), ("d_m", 1.0)),
    "c_g + d_g >= 0": (("c_g", 1.0), ("d_g", 1.0)),
    "FV >= 0": (("FV", 1.0),),
    "FC >= 0": (("FC", 1.0),),
}

#: statement -> combination, with h = T_j, the joint's largest measured |tau| [N m] (module doc).
PEAK_BOUNDS: dict[str, tuple[tuple[str, float], ...]] = {
    "max|tau| - c_m - d_m >= 0": (("c_m", -1.0), ("d_m", -1.0)),
    "max|tau| - FC >= 0": (("FC", -1.0),),
}


def torque_peak(signals) -> np.ndarray:
    """The largest finite |tau| of each joint over ``signals`` (RobotSignals, or a sequence of
    them), shape (k,) [N m]: the T_j of :data:`PEAK_BOUNDS`."""
    parts = signals if isinstance(signals, list | tuple) else [signals]
    tau = np.abs(np.concatenate([np.asarray(s.tau, dtype=float) for s in parts], axis=0))
    return np.max(np.where(np.isfinite(tau), tau, 0.0), axis=0)


def bound_rows(names: Sequence[str], numbers: Sequence[int],
               tau_peak: Sequence[float] | None = None
               ) -> list[tuple[str, np.ndarray, float, bool]]:
    """The bounds that apply to a model's parameters.

    Parameters
    ----------
    names : sequence of str
        The model's parameter names (``RobotModel.names_``).
    numbers : sequence of int
        The joints' numbers (``RobotModel.numbers_``), the suffix of their parameters.
    tau_peak : sequence of float, shape (k,), optional
        Per joint (in ``numbers``' order) its largest measured |tau| [N m]
        (:func:`torque_peak`): adds :data:`PEAK_BOUNDS`.

    Returns
    -------
    list of (str, ndarray, float, bool)
        Per bound whose parameters all exist: ``"<statement> (joint j)"`` (with T_j for the
        data's bounds), the row g (len(names),) and h of ``g . x + h >= 0``, and whether it is
        strict (``>``).
    """
    index = {n: i for i, n in enumerate(names)}
    peaks = [None] * len(numbers) if tau_peak is None else [float(t) for t in tau_peak]
    if len(peaks) != len(numbers):
        raise ValueError(f"bound_rows: tau_peak has {len(peaks)} joints, expected "
                         f"{len(numbers)}")
    out = []
    for j, peak in zip(numbers, peaks, strict=True):
        tables = [(FRICTION_BOUNDS, 0.0, "")]
        if peak is not None:
            tables.append((PEAK_BOUNDS, peak, f", max|tau| = {peak:.4g}"))
        for table, h, tail in tables:
            for what, combo in table.items():
                cols = [f"{p}{j}" for p, _ in combo]
                if not all(c in index for c in cols):
                    continue
                g = np.zeros(len(names))
                for c, (_, w) in zip(cols, combo, strict=True):
                    g[index[c]] = w
                out.append((f"{what} (joint {j}{tail})", g, h, ">=" not in what))
    return out


def met(v: np.ndarray | float, strict: np.ndarray | bool) -> np.ndarray | bool:
    """Whether bounds with values ``v = g . x + h`` are met: v > 0 where strict, v >= 0 else."""
    return (v > 0) | (~np.asarray(strict) & (v == 0))
