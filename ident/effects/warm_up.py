"""Warm-up: a dry friction that decays with the time since the run start, T_w scanned.
"""

from __future__ import annotations

import numpy as np

from ..signals import Signals
from ._base import Candidate, Context, Effect, Setting, register
from ._scan import scan_log


class WarmUp(Effect):
    """Time drift of dry friction (warm-up): dF_C exp(-t/T_w) sign(q̇).

    With a plant friction F_C (1 + w exp(-t/T_w)) sign(q̇), dF_C_warm = w F_C.

    Parameters
    ----------
    T_w : float
        Warm-up time constant [s]; a hyper-parameter scanned on the residual.
    """

    effect = "warm_up"
    variable = "time"
    hyper_names = ("T_w",)

    def __init__(self, T_w: float, tag: str = "") -> None:
        super().__init__(tag)
        if not T_w > 0:
            raise ValueError(f"WarmUp: T_w must be > 0, got {T_w}")
        self.T_w = float(T_w)

    def with_hyper(self, **values: float) -> WarmUp:
        return WarmUp(values.get("T_w", self.T_w), self.tag)

    def names(self) -> tuple[str, ...]:
        return (self._n("dF_C_warm"),)

    def columns(self, s: Signals) -> np.ndarray:
        return (np.exp(-s.t / self.T_w) * s.direction)[:, None]

    def describe(self) -> str:
        return f"warm-up dF_C exp(-t/{self.T_w:.4g}) sign(dq)"

    def physical_range(self, parameters: dict[str, dict[str, float]],
                       setting: Setting) -> str | None:
        """A warm-up is slower than the excitation (T_w above the median time between
        reversals) and shorter than the run (T_w below the longest run): otherwise the term
        is a slow drift or follows the motion itself."""
        key = next((k for k in parameters if k.startswith("T_w")), None)
        if key is None:
            return None
        tw = parameters[key]["value"]
        if tw <= setting.excitation_s:
            return (f"T_w = {tw:.3g} s is not slower than the excitation (median "
                    f"{setting.excitation_s:.3g} s between reversals)")
        if tw >= setting.run_s:
            return f"T_w = {tw:.3g} s is not shorter than the run ({setting.run_s:.3g} s)"
        return None

    def extra_parameters(self, coef, names, cov, params):
        """w_warm = dF_C_warm / F_C, when the model has a Coulomb F_C."""
        if not coef.get("F_C"):
            return {}
        own = self.names()[0]
        return {
            "w_warm": {
                "value": float(coef[own] / coef["F_C"]),
                "std2": float(params[own]["std2"] / abs(coef["F_C"])),
            }
        }


@register("warm_up", order=70)
def propose(ctx: Context) -> list[Candidate]:
    """dF_C exp(-t/T_w) sign(q̇), T_w over tmax/300..tmax, once."""
    if ctx.tmax > 0 and "warm_up" not in ctx.effects:
        e, g = scan_log(ctx.cols, WarmUp, ctx.tmax / 300, ctx.tmax)
        return [Candidate(e, g, 1)]
    return []
