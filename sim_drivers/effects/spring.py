"""Spring (balancer, cable) about a rest position: ``k (q - q0)``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trajectories.schema import Field

from ._base import Inputs, PlantEffect, register


@dataclass(frozen=True)
class Spring:
    """Spring (balancer, cable) about a rest position: ``k (q - q0)``.

    Attributes: ``stiffness_Nm_per_rad`` k [N m/rad], ``rest_position_rad`` q0 [rad].
    """

    enabled: bool = False
    stiffness_Nm_per_rad: float = 0.0
    rest_position_rad: float = 0.0


def torque(p: Spring, x: Inputs) -> np.ndarray:
    return p.stiffness_Nm_per_rad * (x.q - p.rest_position_rad)


register(PlantEffect(
    name="spring", order=20, params=Spring, formula="k (q - q0)",
    schema={
        "stiffness_Nm_per_rad": Field(float, unit="N m/rad"),
        "rest_position_rad": Field(float, unit="rad"),
    },
    torque=torque, module=__name__,
))
