"""Generic basis: hinge functions of one variable, for effects outside the named list.

Competes with the named effects in :mod:`ident.refine` (``generic=True`` candidates), and
is chosen only when it removes clearly more than every named one.
"""

from __future__ import annotations

import numpy as np

from ..signals import Signals
from ._base import (
    VARIABLES,
    Candidate,
    Context,
    Effect,
    Prediction,
    register,
    variable_values,
)

#: Continuous variables a generic basis may expand.
CONTINUOUS = ("position", "velocity", "acceleration", "load", "time")


class GenericBasis(Effect):
    """Generic basis expansion in one variable: hinge functions max(x - k_j, 0) at the
    ``n_knots - 2`` interior knots of a uniform grid over [lo, hi] (x clipped to [lo, hi]),
    optionally multiplied by sign(q̇). Used when the residual depends on a variable but no
    named effect fits.

    The hinges span the piecewise-linear functions of x *without* their constant and linear
    parts, which the declared model usually carries already (offset, viscous, Coulomb), so
    the basis is not collinear with it; each parameter is the change of slope at a knot.

    Parameters
    ----------
    variable : str
        One of :data:`VARIABLES` with a continuous range (position, velocity,
        acceleration, load, time).
    lo, hi : float
        Knot range in the variable's unit.
    n_knots : int
        Number of grid points (≥ 3), ends included.
    signed : bool
        Multiply the hinges by sign(q̇) (a friction-like effect).
    tau_out : Prediction, optional
        Load predictor for ``variable="load"``.
    """

    def __init__(
        self,
        variable: str,
        lo: float,
        hi: float,
        n_knots: int = 12,
        signed: bool = False,
        tau_out: Prediction | None = None,
        tag: str = "",
    ) -> None:
        super().__init__(tag)
        if variable not in VARIABLES:
            raise ValueError(f"GenericBasis: unknown variable {variable!r}")
        if not hi > lo or n_knots < 3:
            raise ValueError("GenericBasis: need hi > lo and n_knots >= 3")
        self.variable = variable
        self.effect = f"generic_{variable}" + ("_signed" if signed else "")
        self.lo, self.hi, self.n_knots, self.signed = float(lo), float(hi), int(n_knots), signed
        self.tau_out = tau_out

    @property
    def knots(self) -> np.ndarray:
        """Interior knots k_j, shape (n_knots - 2,), in the variable's unit."""
        return np.linspace(self.lo, self.hi, self.n_knots)[1:-1]

    def names(self) -> tuple[str, ...]:
        v = self.variable[:3]
        return tuple(
            self._n(f"g{'s' if self.signed else ''}_{v}_{k}") for k in range(1, self.n_knots - 1)
        )

    def columns(self, s: Signals) -> np.ndarray:
        x = np.clip(variable_values(self.variable, s, self.tau_out), self.lo, self.hi)
        H = np.maximum(x[:, None] - self.knots[None, :], 0.0)
        if self.signed:
            H = H * np.asarray(s.direction, dtype=float)[:, None]
        return H

    def describe(self) -> str:
        sg = " x sign(dq)" if self.signed else ""
        return (
            f"generic basis in {self.variable}{sg}: {self.n_knots - 2} hinge functions "
            f"on [{self.lo:.4g}, {self.hi:.4g}] (no named effect fitted)"
        )


@register("generic", order=1000)
def propose(ctx: Context) -> list[Candidate]:
    """Two bases (plain and × sign(q̇)) per significantly implicated continuous variable,
    over the 0.5-99.5 % range of the variable."""
    out: list[Candidate] = []
    for d in ctx.diag.significant:
        if d.variable not in CONTINUOUS:
            continue
        x = variable_values(d.variable, ctx.s, ctx.tau_out)
        lo, hi = np.quantile(x, [0.005, 0.995])
        if not hi > lo:
            continue
        for signed in (False, True):
            e = GenericBasis(
                d.variable, float(lo), float(hi), ctx.generic_knots, signed, ctx.tau_out
            )
            out.append(ctx.candidate(e, generic=True))
    return out
