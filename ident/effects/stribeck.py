"""Stribeck velocity-dependent dry friction (eq. 22, 29), q_s scanned.
"""

from __future__ import annotations

import numpy as np

from trajectories.friction import stribeck_exp

from ..signals import Signals
from ._base import Candidate, Context, Effect, register
from ._scan import scan_log


class Stribeck(Effect):
    """Stribeck velocity-dependent dry friction F_S exp(-|q̇|/q_s) sign(q̇) (eq. 22, 29).

    Parameters
    ----------
    q_s : float
        Stribeck velocity q_s [rad/s or m/s]; a hyper-parameter scanned on the residual.
    """

    effect = "stribeck"
    variable = "velocity"
    hyper_names = ("q_s",)

    def __init__(self, q_s: float, tag: str = "") -> None:
        super().__init__(tag)
        if not q_s > 0:
            raise ValueError(f"Stribeck: q_s must be > 0, got {q_s}")
        self.q_s = float(q_s)

    def with_hyper(self, **values: float) -> Stribeck:
        return Stribeck(values.get("q_s", self.q_s), self.tag)

    def names(self) -> tuple[str, ...]:
        return (self._n("F_S"),)

    def columns(self, s: Signals) -> np.ndarray:
        return (stribeck_exp(s.dq, self.q_s) * s.direction)[:, None]

    def describe(self) -> str:
        return f"Stribeck F_S exp(-|dq|/{self.q_s:.4g}) sign(dq)"


@register("stribeck", order=60)
def propose(ctx: Context) -> list[Candidate]:
    """F_S exp(-|q̇|/q_s) sign(q̇), q_s over vmax/1000..vmax/2; not when the model already
    has an exponential dry friction (a Stribeck term or the paper model's quadrant terms)."""
    if ctx.vmax > 0 and not ctx.has("stribeck", "quadrant_coulomb"):
        e, g = scan_log(ctx.cols, Stribeck, ctx.vmax / 1000, ctx.vmax / 2)
        return [Candidate(e, g, 1)]
    return []
