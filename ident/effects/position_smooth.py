"""Smooth position-dependent torque (gravity-model error): Legendre P_2..P_4.
"""

from __future__ import annotations

import numpy as np

from ..signals import Signals
from ._base import Candidate, Context, Effect, register


class PositionSmooth(Effect):
    """Smooth position-dependent torque: Legendre polynomials P_2..P_degree of the position
    scaled to [-1, 1] over [q_min, q_max] (the linear part is :class:`Spring`)."""

    effect = "position_smooth"
    variable = "position"

    def __init__(self, q_min: float, q_max: float, degree: int = 4, tag: str = "") -> None:
        super().__init__(tag)
        if not q_max > q_min:
            raise ValueError("PositionSmooth: q_max must exceed q_min")
        self.q_min, self.q_max, self.degree = float(q_min), float(q_max), int(degree)

    def names(self) -> tuple[str, ...]:
        return tuple(self._n(f"pos_P{k}") for k in range(2, self.degree + 1))

    def columns(self, s: Signals) -> np.ndarray:
        x = (2 * s.q - (self.q_max + self.q_min)) / (self.q_max - self.q_min)
        V = np.polynomial.legendre.legvander(x, self.degree)
        return V[:, 2:]

    def describe(self) -> str:
        return f"smooth position torque (Legendre degree 2..{self.degree})"


@register("position_smooth", order=30)
def propose(ctx: Context) -> list[Candidate]:
    """Legendre P_2..P_4 over the position range, once."""
    q = ctx.s.q
    if ctx.span > 0 and "position_smooth" not in ctx.effects:
        return [ctx.candidate(PositionSmooth(float(q.min()), float(q.max()), 4))]
    return []
