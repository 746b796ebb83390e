"""Spring k (q - q_c): a linear position-dependent torque.
"""

from __future__ import annotations

import numpy as np

from ..signals import Signals
from ._base import Candidate, Context, Effect, register


class Spring(Effect):
    """Linear position-dependent torque k (q - q_c) (spring, cable, gravity-model error).

    The constant -k q_c merges with the offset τ_off, so only k is identified.

    Parameters
    ----------
    q_center : float
        Reference position q_c [rad or m] (conditioning only).
    """

    effect = "spring"
    variable = "position"

    def __init__(self, q_center: float = 0.0, tag: str = "") -> None:
        super().__init__(tag)
        self.q_center = float(q_center)

    def names(self) -> tuple[str, ...]:
        return (self._n("k_spring"),)

    def columns(self, s: Signals) -> np.ndarray:
        return (s.q - self.q_center)[:, None]

    def describe(self) -> str:
        return "spring k (q - q0)"


@register("spring", order=20)
def propose(ctx: Context) -> list[Candidate]:
    """A spring about the mean position, once."""
    if ctx.span > 0 and "spring" not in ctx.effects:
        return [ctx.candidate(Spring(float(np.mean(ctx.s.q))))]
    return []
