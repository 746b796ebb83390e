"""First-order lag between commanded and applied torque (current-loop bandwidth).

Dynamic: not a term of the balance (``torque=None``); the plant's step filters the
commanded torque with ``d tau_applied / dt = (tau_cmd - tau_applied) / T_lag``.
"""

from __future__ import annotations

from dataclasses import dataclass

from trajectories.schema import Field

from ._base import PlantEffect, register


@dataclass(frozen=True)
class TorqueLag:
    """First-order lag between commanded and applied torque (current-loop bandwidth):
    ``d tau_applied / dt = (tau_cmd - tau_applied) / T_lag``. Attribute ``time_constant_s`` [s].
    """

    enabled: bool = False
    time_constant_s: float = 0.002


register(PlantEffect(
    name="torque_lag", order=60, params=TorqueLag,
    formula="d tau_applied / dt = (tau_cmd - tau_applied) / T_lag",
    schema={"time_constant_s": Field(float, unit="s", gt=0)},
    torque=None, module=__name__,
))
