"""Quadratic viscous (drag) term ``F_VV dq |dq|``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trajectories.schema import Field

from ._base import Inputs, PlantEffect, register


@dataclass(frozen=True)
class QuadraticViscous:
    """Quadratic viscous (drag) term ``F_VV dq |dq|``. Attribute ``F_VV`` [N m s^2/rad^2]."""

    enabled: bool = False
    F_VV: float = 0.0


def torque(p: QuadraticViscous, x: Inputs) -> np.ndarray:
    return p.F_VV * x.dq * np.abs(x.dq)


register(PlantEffect(
    name="quadratic_viscous", order=50, params=QuadraticViscous, formula="F_VV dq |dq|",
    schema={"F_VV": Field(float, unit="N m s^2/rad^2", ge=0)},
    torque=torque, module=__name__,
))
