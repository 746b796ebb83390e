"""Friction that drifts with time while the gearbox warms up."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trajectories.friction import stribeck_exp
from trajectories.schema import Field

from ._base import Inputs, PlantEffect, register


@dataclass(frozen=True)
class WarmUp:
    """Friction that drifts with time while the gearbox warms up.

    The dry friction terms of eq. 30 (the c and d terms, not the load-dependent a, b terms) are
    scaled by ``1 + w exp(-t / T_w)``, t the time since the start of the run [s]; the effect's
    torque is therefore ``w exp(-t/T_w) [P+ (c_m + d_m E) + P- (c_g + d_g E)] sign(dq)``.

    Attributes: ``fraction`` w [-] (excess at t = 0), ``time_constant_s`` T_w [s].
    """

    enabled: bool = False
    fraction: float = 0.0
    time_constant_s: float = 60.0


def torque(p: WarmUp, x: Inputs) -> np.ndarray:
    f = x.params.friction
    dq = x.dq
    pw = np.sign(x.tau_out * dq)
    ex = stribeck_exp(dq, x.params.joint.q_s)
    dry = (0.5 * (1.0 + pw) * (f.c_m + f.d_m * ex)
           + 0.5 * (1.0 - pw) * (f.c_g + f.d_g * ex)) * np.sign(dq)
    w = p.fraction * np.exp(-np.asarray(x.t, dtype=float) / p.time_constant_s)
    return w * dry


register(PlantEffect(
    name="warm_up", order=30, params=WarmUp,
    formula="dry friction (c, d) x (1 + w exp(-t / T_w))",
    schema={
        "fraction": Field(float, gt=-1),
        "time_constant_s": Field(float, unit="s", gt=0),
    },
    torque=torque, module=__name__,
))
