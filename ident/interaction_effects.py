"""Named effects that live in an interaction of two variables.

They are not offered on their own by the refinement: the library search
(:mod:`ident.library_search`) finds the structure (variables and modifier), and
:mod:`ident.describe` replaces the selected basis by one of these when it explains the same
(fewer parameters, physical meaning, parameters with 2σ).

==================================  ==========  ===========================================
effect                              variable    columns (parameters)
==================================  ==========  ===========================================
``position_periodic_dry_friction``  position    [sin, cos](2π q/P) sign(q̇)  (amplitude,
                                                phase; P scanned) — eccentric or worn
                                                transmission
``reversal_hysteresis``             reversal    exp(-s/L) sign(q̇), s the distance since the
                                                last reversal (F_hyst; L scanned) — Dahl-like
                                                pre-sliding
``load_dependent_viscous``          load        |τ̂_out| q̇  (F_V_load)
==================================  ==========  ===========================================
"""

from __future__ import annotations

import math

import numpy as np

from trajectories.friction import stribeck_exp

from .effects import Effect, Prediction, amplitude_phase, model_quadrant
from .interactions import reversal_distance
from .signals import Signals


class PositionDryFriction(Effect):
    """Dry friction whose level varies periodically along the position:
    A sin(2π q/P + φ) sign(q̇) (eccentric or worn transmission).

    Parameters
    ----------
    period : float
        Period P [rad or m]; a hyper-parameter.
    """

    effect = "position_periodic_dry_friction"
    variable = "position"
    hyper_names = ("period",)

    def __init__(self, period: float, tag: str = "") -> None:
        super().__init__(tag)
        if not period > 0:
            raise ValueError(f"PositionDryFriction: period must be > 0, got {period}")
        self.period = float(period)

    def with_hyper(self, **values: float) -> PositionDryFriction:
        return PositionDryFriction(values.get("period", self.period), self.tag)

    def names(self) -> tuple[str, ...]:
        return (self._n("fcq_sin"), self._n("fcq_cos"))

    def columns(self, s: Signals) -> np.ndarray:
        th = (2 * np.pi / self.period) * s.q
        sg = s.direction
        return np.column_stack((np.sin(th) * sg, np.cos(th) * sg))

    def parameters(self, coef, cov):
        amp, amp2, phase, phase2 = amplitude_phase(coef, cov)
        sdp = math.sqrt(max(float(cov[2, 2]), 0.0)) if len(coef) > 2 else 0.0
        return {
            self._n("fcq_amplitude"): (amp, amp2),
            self._n("fcq_phase"): (phase, phase2),
            self._n("fcq_period"): (self.period, 2 * sdp),
        }

    def describe(self) -> str:
        return f"position-dependent dry friction A sin(2π q/{self.period:.6g} + φ) sign(dq)"


class ReversalHysteresis(Effect):
    """Dry friction that builds up after each reversal over a travelled distance L:
    F_hyst exp(-s/L) sign(q̇), s = distance since the last reversal (Dahl-like).

    Parameters
    ----------
    length : float
        L [rad or m]; a hyper-parameter.
    """

    effect = "reversal_hysteresis"
    variable = "reversal"
    hyper_names = ("length",)

    def __init__(self, length: float, tag: str = "") -> None:
        super().__init__(tag)
        if not length > 0:
            raise ValueError(f"ReversalHysteresis: length must be > 0, got {length}")
        self.length = float(length)

    def with_hyper(self, **values: float) -> ReversalHysteresis:
        return ReversalHysteresis(values.get("length", self.length), self.tag)

    def names(self) -> tuple[str, ...]:
        return (self._n("F_hyst"),)

    def columns(self, s: Signals) -> np.ndarray:
        return (np.exp(-reversal_distance(s) / self.length) * s.direction)[:, None]

    def parameters(self, coef, cov):
        sd = np.sqrt(np.clip(np.diag(cov), 0, None))
        out = {self._n("F_hyst"): (float(coef[0]), float(2 * sd[0]))}
        out[self._n("hysteresis_length")] = (
            self.length, float(2 * sd[1]) if len(coef) > 1 else 0.0)
        return out

    def describe(self) -> str:
        return f"reversal hysteresis F_hyst exp(-s/{self.length:.4g}) sign(dq)"


class LoadViscous(Effect):
    """Viscous friction growing with the load: F_V_load |τ̂_out| q̇.

    Parameters
    ----------
    tau_out : Prediction
        Load-torque predictor τ̂_out [N m].
    """

    effect = "load_dependent_viscous"
    variable = "load"

    def __init__(self, tau_out: Prediction, tag: str = "") -> None:
        super().__init__(tag)
        self.tau_out = tau_out

    def names(self) -> tuple[str, ...]:
        return (self._n("F_V_load"),)

    def columns(self, s: Signals) -> np.ndarray:
        return (np.abs(self.tau_out(s)) * s.dq)[:, None]

    def describe(self) -> str:
        return "load-dependent viscous F_V_load |tau_out| dq"


class LoadVelocityDryFriction(Effect):
    """The paper's load- and velocity-dependent dry friction in one term (eq. 24, 26):
    (alpha_P + beta_P exp(-|q̇|/q_s)) sign(P) τ̂_out — the load-dependent friction
    coefficient, larger at low velocity. It is what the library finds as "the load-dependent
    friction coefficient varies with velocity" (velocity x load_quadrant); the refinement
    otherwise reaches it in two steps (``quadrant_load`` then ``quadrant_load_stribeck``).

    Parameters
    ----------
    tau_out : Prediction
        Load-torque predictor τ̂_out [N m].
    q_s : float
        Stribeck velocity q_s [rad/s or m/s] (eq. 29); a hyper-parameter.
    """

    effect = "quadrant_load_velocity"
    variable = "quadrant"
    hyper_names = ("q_s",)

    def __init__(self, tau_out: Prediction, q_s: float, tag: str = "") -> None:
        super().__init__(tag)
        if not q_s > 0:
            raise ValueError(f"LoadVelocityDryFriction: q_s must be > 0, got {q_s}")
        self.tau_out, self.q_s = tau_out, float(q_s)

    def with_hyper(self, **values: float) -> LoadVelocityDryFriction:
        return LoadVelocityDryFriction(self.tau_out, values.get("q_s", self.q_s), self.tag)

    def names(self) -> tuple[str, ...]:
        return (self._n("alpha_P"), self._n("beta_P"))

    def columns(self, s: Signals) -> np.ndarray:
        c = model_quadrant(s, self.tau_out) * self.tau_out(s)
        return np.column_stack((c, c * stribeck_exp(s.dq, self.q_s)))

    def describe(self) -> str:
        return (f"load- and velocity-dependent dry friction (alpha_P + beta_P "
                f"exp(-|dq|/{self.q_s:.4g})) sign(P) tau_out")
