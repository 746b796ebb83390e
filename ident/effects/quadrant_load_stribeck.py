"""Velocity dependence of the load-dependent dry friction (the b terms of eq. 24-25).
"""

from __future__ import annotations

import numpy as np

from trajectories.friction import stribeck_exp

from ..signals import Signals
from ._base import Candidate, Context, Effect, Prediction, model_quadrant, register
from ._scan import scan_log


class QuadrantLoadStribeck(Effect):
    """Velocity dependence of the load-dependent dry friction (the b terms of eq. 24-25):
    beta_P sign(P) τ̂_out exp(-|q̇|/q_s), added after :class:`QuadrantLoad`.

    Parameters
    ----------
    tau_out : Prediction
        Load-torque predictor τ̂_out [N m].
    q_s : float
        Stribeck velocity q_s [rad/s or m/s]; a hyper-parameter scanned on the residual.
    """

    effect = "quadrant_load_stribeck"
    variable = "quadrant"
    hyper_names = ("q_s",)

    def __init__(self, tau_out: Prediction, q_s: float, tag: str = "") -> None:
        super().__init__(tag)
        if not q_s > 0:
            raise ValueError(f"QuadrantLoadStribeck: q_s must be > 0, got {q_s}")
        self.tau_out, self.q_s = tau_out, float(q_s)

    def with_hyper(self, **values: float) -> QuadrantLoadStribeck:
        return QuadrantLoadStribeck(self.tau_out, values.get("q_s", self.q_s), self.tag)

    def names(self) -> tuple[str, ...]:
        return (self._n("beta_P"),)

    def columns(self, s: Signals) -> np.ndarray:
        e = stribeck_exp(s.dq, self.q_s)
        return (model_quadrant(s, self.tau_out) * self.tau_out(s) * e)[:, None]

    def describe(self) -> str:
        return (
            f"low-velocity load-dependent friction beta_P sign(P) tau_out exp(-|dq|/{self.q_s:.4g})"
        )


@register("quadrant_load_stribeck", order=100)
def propose(ctx: Context) -> list[Candidate]:
    """beta_P sign(P) τ̂_out exp(-|q̇|/q_s), q_s scanned, after a ``quadrant_load`` step."""
    tau_out, vmax = ctx.tau_out, ctx.vmax
    if (
        tau_out is not None
        and vmax > 0
        and "quadrant_load" in ctx.effects
        and "quadrant_load_stribeck" not in ctx.effects
    ):
        e, g = scan_log(
            ctx.cols, lambda q_s: QuadrantLoadStribeck(tau_out, q_s), vmax / 1000, vmax / 2
        )
        return [Candidate(e, g, 1)]
    return []
