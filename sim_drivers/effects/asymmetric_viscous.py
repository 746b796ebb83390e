"""Direction-dependent viscous friction: F_V_pos for dq > 0, F_V_neg for dq < 0."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from trajectories.schema import Field

from ._base import Inputs, PlantEffect, register


@dataclass(frozen=True)
class AsymmetricViscous:
    """Direction-dependent viscous friction: F_V is replaced by ``F_V_pos`` for dq > 0 and
    ``F_V_neg`` for dq < 0; the effect's torque is ``(F_V_pos - F_V) dq`` or ``(F_V_neg - F_V) dq``.

    Attributes: ``F_V_pos``, ``F_V_neg`` [N m s/rad].
    """

    enabled: bool = False
    F_V_pos: float = 0.0
    F_V_neg: float = 0.0


def torque(p: AsymmetricViscous, x: Inputs) -> np.ndarray:
    fv = x.params.friction.F_V
    dq = x.dq
    return np.where(dq > 0, (p.F_V_pos - fv) * dq, (p.F_V_neg - fv) * dq)


register(PlantEffect(
    name="asymmetric_viscous", order=40, params=AsymmetricViscous,
    formula="F_V -> F_V_pos (dq > 0), F_V_neg (dq < 0)",
    schema={
        "F_V_pos": Field(float, unit="N m s/rad", ge=0),
        "F_V_neg": Field(float, unit="N m s/rad", ge=0),
    },
    torque=torque, module=__name__,
))
