"""Different dry friction in the motor and generator quadrants (c_m != c_g, eq. 25).
"""

from __future__ import annotations

import numpy as np

from ..signals import Signals
from ._base import Candidate, Context, Effect, Prediction, model_quadrant, register


class QuadrantCoulomb(Effect):
    """Different dry friction in the motor and generator quadrants (c_m != c_g, eq. 25):
    (dF_Cq / 2) sign(P) sign(q̇) = (dF_Cq / 2) sign(τ̂_out) for q̇ != 0, with dF_Cq = c_m - c_g
    and sign(P) the model quadrant sign(τ̂_out q̇) (:func:`~ident.effects.model_quadrant`).

    Parameters
    ----------
    tau_out : Prediction
        Load-torque predictor τ̂_out [N m].
    """

    effect = "quadrant_coulomb"
    variable = "quadrant"

    def __init__(self, tau_out: Prediction, tag: str = "") -> None:
        super().__init__(tag)
        self.tau_out = tau_out

    def names(self) -> tuple[str, ...]:
        return (self._n("dF_Cq"),)

    def columns(self, s: Signals) -> np.ndarray:
        return (0.5 * model_quadrant(s, self.tau_out) * s.direction)[:, None]

    def describe(self) -> str:
        return "quadrant dry friction (c_m - c_g) sign(P) sign(dq) / 2"


@register("quadrant_coulomb", order=90)
def propose(ctx: Context) -> list[Candidate]:
    """sign(P) sign(q̇)/2, when the model has no quadrant dry friction (the paper model has)."""
    if ctx.tau_out is not None and "quadrant_coulomb" not in ctx.effects:
        return [ctx.candidate(QuadrantCoulomb(ctx.tau_out))]
    return []
