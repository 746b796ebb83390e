"""Position-periodic ripple (cogging, gear meshing): ``A sin(2 pi q / period + phase)``."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from trajectories.schema import Field

from ._base import Inputs, PlantEffect, register

_TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class PositionRipple:
    """Position-periodic ripple (cogging, gear meshing): ``A sin(2 pi q / period + phase)``.

    Attributes: ``amplitude_Nm`` A [N m], ``period_rad`` [rad], ``phase_rad`` [rad].
    """

    enabled: bool = False
    amplitude_Nm: float = 0.0
    period_rad: float = 2.0 * math.pi / 16.0
    phase_rad: float = 0.0


def torque(p: PositionRipple, x: Inputs) -> np.ndarray:
    return p.amplitude_Nm * np.sin(_TWO_PI * x.q / p.period_rad + p.phase_rad)



def truth(p: PositionRipple) -> dict[str, float]:
    """Linear coefficients: A sin(x + phase) = sin_Nm sin x + cos_Nm cos x."""
    return {"sin_Nm": p.amplitude_Nm * math.cos(p.phase_rad),
            "cos_Nm": p.amplitude_Nm * math.sin(p.phase_rad)}


register(PlantEffect(
    name="position_ripple", order=10, params=PositionRipple,
    formula="A sin(2 pi q / period + phase)",
    schema={
        "amplitude_Nm": Field(float, unit="N m"),
        "period_rad": Field(float, unit="rad", gt=0),
        "phase_rad": Field(float, unit="rad"),
    },
    torque=torque, truth=truth, module=__name__,
))
