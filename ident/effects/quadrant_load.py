"""Load-dependent dry friction in the motor/generator quadrants (eq. 17-20, 26).
"""

from __future__ import annotations

import numpy as np

from ..signals import Signals
from ._base import Candidate, Context, Effect, Prediction, model_quadrant, register


class QuadrantLoad(Effect):
    """Load-dependent dry friction in the motor/generator quadrants (eq. 17-20, 26).

    Column sign(P) τ̂_out = sign(τ̂_out q̇) τ̂_out = |τ̂_out| sign(q̇) (model quadrant), with
    τ̂_out the load torque predicted by the declared rigid-body terms. Its coefficient alpha_P
    is the mean of the paper's alpha_m and alpha_g (their difference is absorbed by the
    rigid-body parameters).

    Parameters
    ----------
    tau_out : Prediction
        Load-torque predictor τ̂_out [N m].
    """

    effect = "quadrant_load"
    variable = "quadrant"

    def __init__(self, tau_out: Prediction, tag: str = "") -> None:
        super().__init__(tag)
        self.tau_out = tau_out

    def names(self) -> tuple[str, ...]:
        return (self._n("alpha_P"),)

    def columns(self, s: Signals) -> np.ndarray:
        return (model_quadrant(s, self.tau_out) * self.tau_out(s))[:, None]

    def describe(self) -> str:
        return "load-dependent dry friction alpha_P sign(P) tau_out"


@register("quadrant_load", order=80)
def propose(ctx: Context) -> list[Candidate]:
    """sign(P) τ̂_out, when the model has a rigid body and no load-dependent friction yet."""
    if ctx.tau_out is not None and not ctx.has("quadrant_load", "load_dependent"):
        return [ctx.candidate(QuadrantLoad(ctx.tau_out))]
    return []
