"""Quadratic (drag) viscous friction F_VV q̇|q̇|.
"""

from __future__ import annotations

import numpy as np

from ..signals import Signals
from ._base import Candidate, Context, Effect, register


class QuadraticViscous(Effect):
    """Nonlinear viscous friction F_VV q̇|q̇|."""

    effect = "quadratic_viscous"
    variable = "velocity"

    def names(self) -> tuple[str, ...]:
        return (self._n("F_VV"),)

    def columns(self, s: Signals) -> np.ndarray:
        return (s.dq * np.abs(s.dq))[:, None]

    def describe(self) -> str:
        return "quadratic viscous F_VV dq|dq|"


@register("quadratic_viscous", order=50)
def propose(ctx: Context) -> list[Candidate]:
    """The q̇|q̇| column, once."""
    if "quadratic_viscous" not in ctx.effects:
        return [ctx.candidate(QuadraticViscous())]
    return []
