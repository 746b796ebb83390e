"""Direction-dependent viscous friction (F_V+ != F_V-).
"""

from __future__ import annotations

import math

import numpy as np

from ..signals import Signals
from ._base import Candidate, Context, Effect, register


class DirectionalViscous(Effect):
    """Direction-dependent viscous friction F_V+ q̇ (q̇ > 0), F_V- q̇ (q̇ < 0).

    Added to a symmetric viscous term F_V q̇ through the column |q̇|/2, whose coefficient is
    dF_V = F_V+ - F_V-; the symmetric F_V then becomes (F_V+ + F_V-)/2.
    """

    effect = "directional_viscous"
    variable = "direction"

    def names(self) -> tuple[str, ...]:
        return (self._n("dF_V"),)

    def columns(self, s: Signals) -> np.ndarray:
        return (0.5 * np.abs(s.dq))[:, None]

    def describe(self) -> str:
        return "direction-dependent viscous (F_V+ - F_V-) |dq|/2"

    def extra_parameters(self, coef, names, cov, params):
        """F_V+ = F_V + dF_V/2 and F_V- = F_V - dF_V/2 with their 2σ, when the model has F_V."""
        out: dict[str, dict[str, float]] = {}
        if "F_V" not in coef:
            return out
        own = self.names()[0]
        i_fv, i_d = names.index("F_V"), names.index(own)
        fv, d = coef["F_V"], coef[own]
        for key, sgn in (("F_V_pos", 0.5), ("F_V_neg", -0.5)):
            g = np.zeros(cov.shape[0])
            g[i_fv], g[i_d] = 1.0, sgn
            out[key] = {
                "value": float(fv + sgn * d),
                "std2": float(2 * math.sqrt(max(g @ cov @ g, 0.0))),
            }
        return out


@register("directional_viscous", order=40)
def propose(ctx: Context) -> list[Candidate]:
    """The |q̇|/2 column, once."""
    if "directional_viscous" not in ctx.effects:
        return [ctx.candidate(DirectionalViscous())]
    return []
