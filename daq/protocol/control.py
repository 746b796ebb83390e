"""Joint position controller used in cyclic synchronous torque mode (pure, no I/O).

The runner computes the torque reference every cycle from the planned trajectory and the
measured encoder position; the offline simulator (``sim_drivers.offline``) uses the same
class so that bus runs and offline runs share one control law.

    tau_ref = J_ff * ddq_ref + MX_ff * g * cos(q_ref) + MY_ff * g * sin(q_ref)
              + Fc_ff * sign(dq_ref) + Fv_ff * dq_ref
              + kp * (q_ref - q) + kd * (dq_ref - dq_est)

with ``dq_est`` the backward difference of the measured position [rad/s], low-passed by a
first-order filter of cut-off ``velocity_cutoff_hz``. Units: joint side, SI ([rad], [N m]).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

G = 9.81  # [m/s^2] gravity used by the paper (section IV.A)


@dataclass(frozen=True)
class ControllerGains:
    """PD gains and model feed-forward of the position loop.

    Attributes
    ----------
    kp : float
        Proportional gain [N m/rad] (revolute) or [N/m] (prismatic).
    kd : float
        Derivative gain [N m s/rad] or [N s/m].
    J_ff, MX_ff, MY_ff, Fc_ff, Fv_ff : float
        Feed-forward model: inertia [kg m^2], first moments [kg m], Coulomb [N m],
        viscous [N m s/rad]. Gravity terms are used only for revolute joints.
    velocity_cutoff_hz : float
        Cut-off of the velocity-estimate low-pass [Hz].
    """

    kp: float = 4000.0
    kd: float = 150.0
    J_ff: float = 0.0
    MX_ff: float = 0.0
    MY_ff: float = 0.0
    Fc_ff: float = 0.0
    Fv_ff: float = 0.0
    velocity_cutoff_hz: float = 100.0


class PositionController:
    """Stateful PD + feed-forward position loop; call :meth:`update` once per cycle.

    Parameters
    ----------
    gains : ControllerGains
    cycle_s : float
        Control cycle [s].
    revolute : bool
        Whether gravity feed-forward applies.
    """

    __slots__ = ("g", "dt", "revolute", "_q_prev", "_dq_est", "_alpha")

    def __init__(self, gains: ControllerGains, cycle_s: float, revolute: bool = True) -> None:
        self.g = gains
        self.dt = cycle_s
        self.revolute = revolute
        self._q_prev: float | None = None
        self._dq_est = 0.0
        wc = 2.0 * math.pi * gains.velocity_cutoff_hz * cycle_s
        self._alpha = wc / (1.0 + wc)

    def reset(self) -> None:
        self._q_prev = None
        self._dq_est = 0.0

    def update(self, q_ref: float, dq_ref: float, ddq_ref: float, q_meas: float) -> float:
        """Return the torque reference [N m] for this cycle."""
        g = self.g
        if self._q_prev is not None:
            raw = (q_meas - self._q_prev) / self.dt
            self._dq_est += self._alpha * (raw - self._dq_est)
        self._q_prev = q_meas
        tau = g.J_ff * ddq_ref + g.Fv_ff * dq_ref
        if dq_ref > 0.0:
            tau += g.Fc_ff
        elif dq_ref < 0.0:
            tau -= g.Fc_ff
        if self.revolute and (g.MX_ff or g.MY_ff):
            tau += G * (g.MX_ff * math.cos(q_ref) + g.MY_ff * math.sin(q_ref))
        return tau + g.kp * (q_ref - q_meas) + g.kd * (dq_ref - self._dq_est)
