"""The physical bounds of the friction parameters, written once: the direct checks of
:func:`ident.robot.consistency.check_consistency` and the constraints the consistent estimate
(:func:`ident.robot.consistent_fit.fit_consistent`) puts on the friction.

They are the simulators' bounds (``sim_drivers.arm_params.ArmFriction``,
``sim_drivers.plant_config``): dissipative friction, eq. 17-25 of the paper, with the load
coefficients of eq. 25 (a_m + b_m E in the motor quadrant, a_g - b_g E in the generator one,
E = exp(-|dq| / q_s)). Every bound is a linear inequality ``g . x >= 0`` (or ``> 0``) on one
joint's parameters, so it is also one row of a convex program.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["FRICTION_BOUNDS", "bound_rows", "met"]

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


def bound_rows(names: Sequence[str], numbers: Sequence[int]
               ) -> list[tuple[str, np.ndarray, bool]]:
    """The bounds that apply to a model's parameters.

    Parameters
    ----------
    names : sequence of str
        The model's parameter names (``RobotModel.names_``).
    numbers : sequence of int
        The joints' numbers (``RobotModel.numbers_``), the suffix of their parameters.

    Returns
    -------
    list of (str, ndarray, bool)
        Per bound whose parameters all exist: ``"<statement> (joint j)"``, the row g (len(names),)
        of ``g . x >= 0``, and whether it is strict (``>``).
    """
    index = {n: i for i, n in enumerate(names)}
    out = []
    for j in numbers:
        for what, combo in FRICTION_BOUNDS.items():
            cols = [f"{p}{j}" for p, _ in combo]
            if not all(c in index for c in cols):
                continue
            g = np.zeros(len(names))
            for c, (_, w) in zip(cols, combo, strict=True):
                g[index[c]] = w
            out.append((f"{what} (joint {j})", g, ">=" not in what))
    return out


def met(v: np.ndarray | float, strict: np.ndarray | bool) -> np.ndarray | bool:
    """Whether bounds with values ``v = g . x`` are met: v > 0 where strict, v >= 0 else."""
    return (v > 0) | (~np.asarray(strict) & (v == 0))
