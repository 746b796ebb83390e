"""First-order lag between the torque reference and the applied torque.
"""

from __future__ import annotations

import numpy as np

from ..signals import Signals
from ._base import Candidate, Context, Effect, Prediction, Setting, model_prediction, register

#: Longest torque lag named a physical lag [s] (drive current loop, torque filter).
MAX_TORQUE_LAG_S = 0.02

#: ... or this many raw sampling periods on logs slower than 1 / (MAX_TORQUE_LAG_S / 3).
MAX_LAG_CYCLES = 3


def time_derivative(x: np.ndarray, s: Signals) -> np.ndarray:
    """dx/dt per experiment (central differences), shape (n,)."""
    out = np.empty_like(x)
    exp = s.experiment
    if len(x) < 2:
        return np.zeros_like(x)
    cuts = np.flatnonzero(np.diff(exp) != 0) + 1
    for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(x)], strict=True):
        if b - a >= 2:
            out[a:b] = np.gradient(x[a:b], s.t[a:b])
        else:
            out[a:b] = 0.0
    return out


class TorqueLag(Effect):
    """First-order lag between the torque reference and the applied torque.

    τ_ref ≈ τ_model + T_lag dτ_model/dt; the column is the time derivative of the current
    model prediction τ̂ (not of the measured torque, which would put noise in the regressor).
    Reported under the variable ``"acceleration"`` (the rate of change of the dynamics).

    Parameters
    ----------
    tau_model : Prediction
        Current model prediction τ̂ [N m].
    """

    effect = "torque_lag"
    variable = "acceleration"

    def __init__(self, tau_model: Prediction, tag: str = "") -> None:
        super().__init__(tag)
        self.tau_model = tau_model

    def names(self) -> tuple[str, ...]:
        return (self._n("T_lag"),)

    def columns(self, s: Signals) -> np.ndarray:
        return time_derivative(self.tau_model(s), s)[:, None]

    def describe(self) -> str:
        return "torque lag T_lag d(tau_model)/dt"

    def sigma_note(self) -> str | None:
        """The 2σ is the least-squares noise only (docs/refinement.md, section 6)."""
        return ("T_lag's 2σ covers the estimate's noise, not the lag model's own error: on "
                "the simulated friction-dominated joint a staged 5 ms lag reads 7.1 to 7.4 ms "
                "(benchmarks/refine_lag_noise.py; docs/refinement.md, section 6); take T_lag "
                "as its order of magnitude")

    def physical_range(self, parameters: dict[str, dict[str, float]],
                       setting: Setting) -> str | None:
        """A transmission or current loop lags by at most :data:`MAX_TORQUE_LAG_S` (or
        :data:`MAX_LAG_CYCLES` raw cycles on slow logs), and never leads: a longer lag is a
        controller's or a filter's dynamics, not the joint's."""
        key = next((k for k in parameters if k.startswith("T_lag")), None)
        if key is None:
            return None
        lag = parameters[key]["value"]
        cap = max(MAX_TORQUE_LAG_S, MAX_LAG_CYCLES * (setting.cycle_s or 0.0))
        if lag < 0:
            return f"T_lag = {1e3 * lag:.3g} ms < 0: the torque would lead the model"
        if lag > cap:
            return (f"T_lag = {1e3 * lag:.3g} ms > {1e3 * cap:.3g} ms, longer than a drive's "
                    "current loop or a transmission lags (a controller's or filter's dynamics)")
        return None


@register("torque_lag", order=110)
def propose(ctx: Context) -> list[Candidate]:
    """T_lag dτ̂/dt with τ̂ the whole current model prediction, once."""
    if "torque_lag" not in ctx.effects:
        return [ctx.candidate(TorqueLag(model_prediction(ctx.lib, ctx.coef)))]
    return []
