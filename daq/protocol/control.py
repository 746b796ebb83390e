"""Joint position control law used in cyclic synchronous torque mode (pure, no I/O).

One law, :class:`PDLaw` (PD on the position error + velocity filter, with the feed-forward an
input), on a float (one joint) or on arrays (k,) (k joints). Its two uses:
:class:`PositionController` (one joint, feed-forward from :class:`ControllerGains`), which the
runner calls every cycle per drive and the offline simulator (``sim_drivers.offline``) uses as
its law, so that bus runs and offline runs share one control law; and the arm's
``sim_drivers.arm_offline.simulate_arm`` (feed-forward computed for the whole run).

    tau_ref = J_ff * ddq_ref + MX_ff * g * cos(q_ref) + MY_ff * g * sin(q_ref)
              + Fc_ff * sign(dq_ref) + Fv_ff * dq_ref
              + kp * (q_ref - q) + kd * (dq_ref - dq_est)

with ``dq_est`` the backward difference of the measured position [rad/s], low-passed by a
first-order filter of cut-off ``velocity_cutoff_hz``. Units: joint side, SI ([rad], [N m]).

A cycle without a new measurement (the drive's TPDO missing or late, ``fresh=False``) does
not feed the last position again as if the joint had stopped: the feedback part, ``kp * (q_ref
- q) + kd * (dq_ref - dq_est)``, is held at its value of the last fresh cycle while the
feed-forward follows the reference, and the next measurement's backward difference spans the
cycles since the last one. Fed the stale position, the PD term grew by ``kp * dq * cycle_s``
per missing cycle and the velocity estimate jumped between 0 and twice the speed: a torque
that chattered by tens of N m every cycle (``tests/test_stale_feedback.py``) and, on late
feedback over a loaded bus, a joint that ran away to the velocity limit. Held, the torque
cannot grow without a measurement however long the gap (the supervisor's
``tpdo_timeout_cycles`` bounds it).

Resuming after a gap of ``n`` cycles, the law's feedback is not applied at once: the joint ran
on the held torque meanwhile, and the law's first value after the gap differs from the held
one by about ``kp`` times the error the gap let grow (a 45-cycle gap: a 42 N m step on the
loaded joint against at most 3.5 N m of cycle-to-cycle change without gaps, 52 N m against
7.9 on the arm's shoulder; ``tests/test_gap_resume.py``). After a gap of at least
:data:`RESUME_MIN_GAP` cycles the applied feedback goes from the held value to the law's over
``N = min(n, ceil(resume_s / cycle_s))`` fresh cycles, linearly (``fb = held + k / N (law -
held)`` at the k-th fresh cycle), ``resume_s`` (default :data:`RESUME_S`, 20 ms) short against
the loop's own period (``2 pi sqrt(J / kp)``: 200 ms for 6 kg at 1 m under kp 6000), so the
correction comes a few ms later, not weaker. A shorter gap resumes at once, as before: its
step is within the cycle-to-cycle changes of a run without gaps (1 or 2 cycles: at most
2.5 N m on that joint), and a link that loses one or two answers in every few cycles
(``tests/test_stale_feedback.py``) keeps the law's own values. A gap inside the blend holds
the blended value; a short one lets the blend go on, a long one starts a new blend from
there (a blend lengthened by every gap inside it never ended on such a link: a joint losing
two TPDOs in three oscillated to the velocity limit). And the velocity
estimate after a gap is the drive's own velocity (0x606C, ``dq_meas``) when given: the
backward difference over the gap assumed the first fresh sample answers this cycle's SYNC,
which, late through a loaded bridge, it often does not. A cycle with no gap before it and no
blend under way computes exactly what it did before (the offline simulators, which never miss
a cycle, are unchanged bit for bit).

Late answers (``drive_velocity``). Through a loaded bridge at 1 ms many answers arrive after
the next SYNC; the master cannot tell an answer to an earlier SYNC from this one's (a TPDO
has no sequence number) and uses it as this cycle's, so the backward difference divides a
step of two or three cycles by one, or a zero step: velocity spikes that the kd term turns
into torque steps. With ``drive_velocity=True`` the filter's input is the drive's own
velocity (0x606C, ``dq_meas``) on every fresh cycle, the velocity at the time of the sample
whichever SYNC it answers. The runner sets it from ``[daq] velocity_source``, left out for
its paced clock (in lockstep every answer is this SYNC's, and the logs, the demo's among
them, are unchanged); in lockstep against a simulated drive answering late on 30 % of the
cycles it keeps the torque's change per cycle at 6.5 N m at most, against 80 N m with the
difference (``tests/test_late_answers.py``). Measured at 1 ms through
two bridge hops beside 4 busy loops (``benchmarks/bench_late_answers.py``, 10 s of a 0.1 rad
sine, 3 runs each; 21-50 % of the plan's cycles without an answer, the 99th percentile of the
answers' delay 2.4-5.4 ms): the torque's cycle-to-cycle change 0.78-1.0 N m std and 12-22 N m
at most, against 4.2-8.5 and 42-430 N m with the difference.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

G = 9.81  # [m/s^2] gravity used by the paper (section IV.A)
#: [s] longest blend from the held feedback to the law's after a gap (module docstring)
RESUME_S = 0.02
#: [cycles] shortest gap the feedback blends after; a shorter one resumes at once (and
#: continues a blend under way)
RESUME_MIN_GAP = 3


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


class PDLaw:
    """Stateful PD position loop around a given feed-forward; call :meth:`torque` once per
    cycle. Works on floats (one joint) or on arrays (k,) (k joints, element-wise).

    ``tau = ff + kp (q_ref - q) + kd (dq_ref - dq_est)`` [N m], with ``dq_est`` the backward
    difference of the measured position [rad/s] low-passed by a first-order filter
    (``alpha = wc / (1 + wc)``, ``wc = 2 pi f_c cycle_s``; 0 at the first cycle).

    Parameters
    ----------
    kp, kd : float or ndarray (k,)
        Proportional [N m/rad] and derivative [N m s/rad] gains.
    velocity_cutoff_hz : float
        Cut-off of the velocity-estimate low-pass [Hz].
    cycle_s : float
        Control cycle [s].
    resume_s : float
        Longest blend from the held feedback to the law's after a gap [s] (module
        docstring); 0: the law's value at once.
    drive_velocity : bool
        Filter the drive's own velocity (``dq_meas``, when given) instead of the backward
        difference of the position, on every fresh cycle (module docstring; the runner's
        paced clock).
    """

    __slots__ = ("kp", "kd", "dt", "_q_prev", "_dq_est", "_alpha", "_gap", "_fb",
                 "_resume_max", "_blend", "_blend_n", "_held", "drive_velocity")

    def __init__(self, kp: Any, kd: Any, velocity_cutoff_hz: float, cycle_s: float,
                 resume_s: float = RESUME_S, drive_velocity: bool = False) -> None:
        self.kp, self.kd = kp, kd
        self.drive_velocity = drive_velocity
        self.dt = cycle_s
        self._q_prev: Any = None
        self._dq_est: Any = 0.0
        self._gap = 0  # cycles since the last fresh measurement
        self._fb: Any = 0.0  # feedback torque applied at the last fresh cycle [N m]
        wc = 2.0 * math.pi * velocity_cutoff_hz * cycle_s
        self._alpha = wc / (1.0 + wc)
        self._resume_max = max(1, math.ceil(resume_s / cycle_s - 1e-9))
        self._blend = 0  # fresh cycles of the blend done (0: none under way)
        self._blend_n = 0  # its length [cycles]
        self._held: Any = 0.0  # the feedback held during the gap the blend starts from

    def reset(self) -> None:
        self._q_prev = None
        self._dq_est = 0.0
        self._gap = 0
        self._fb = 0.0
        self._blend = self._blend_n = 0
        self._held = 0.0

    def torque(self, ff: Any, q_ref: Any, dq_ref: Any, q_meas: Any, fresh: bool = True,
               dq_meas: Any = None) -> Any:
        """Return the torque reference [N m] for this cycle from the feed-forward ``ff``
        [N m], the reference ``q_ref, dq_ref`` [rad, rad/s] and the measured position
        ``q_meas`` [rad].

        ``fresh=False``: no new measurement this cycle (``q_meas`` is the last one, not
        used); the feedback torque of the last fresh cycle is held (module docstring), 0
        before the first fresh cycle. ``dq_meas``: the drive's own velocity [rad/s] of this
        measurement, or None; used only at the first fresh cycle after a gap. After a gap of
        :data:`RESUME_MIN_GAP` cycles or more the feedback blends from the held value to
        the law's (module docstring)."""
        if not fresh:  # the feedback of the last fresh cycle (none before the first one)
            self._gap += self._q_prev is not None
            return ff + self._fb
        gap = self._gap
        if self._q_prev is not None:
            if dq_meas is not None and self.drive_velocity:  # late samples: see module doc
                self._dq_est = self._dq_est + self._alpha * (dq_meas - self._dq_est)
            elif gap and dq_meas is not None:  # not a difference over a span it may not have
                self._dq_est = dq_meas
            else:
                raw = (q_meas - self._q_prev) / (self.dt * (gap + 1))
                self._dq_est = self._dq_est + self._alpha * (raw - self._dq_est)
        self._q_prev = q_meas
        p, d = self.kp * (q_ref - q_meas), self.kd * (dq_ref - self._dq_est)
        if gap:
            self._gap = 0
            if gap >= RESUME_MIN_GAP:  # resuming: blend from the feedback held in the gap
                self._held = self._fb
                self._blend, self._blend_n = 0, min(gap, self._resume_max)
        if self._blend_n:
            self._blend += 1
            if self._blend < self._blend_n:
                fb = self._held + (self._blend / self._blend_n) * (p + d - self._held)
                self._fb = fb
                return ff + fb
            self._blend_n = 0  # the blend's last cycle: the law's own value
        self._fb = p + d
        return ff + p + d  # this order: the runs before the hold, bit for bit


class PositionController(PDLaw):
    """Stateful PD + feed-forward position loop of one joint; call :meth:`update` once per
    cycle: the :class:`PDLaw` of ``gains`` around the model feed-forward of ``gains``.

    Parameters
    ----------
    gains : ControllerGains
    cycle_s : float
        Control cycle [s].
    revolute : bool
        Whether gravity feed-forward applies.
    drive_velocity : bool
        See :class:`PDLaw`.
    """

    __slots__ = ("g", "revolute")

    def __init__(self, gains: ControllerGains, cycle_s: float, revolute: bool = True,
                 drive_velocity: bool = False) -> None:
        super().__init__(gains.kp, gains.kd, gains.velocity_cutoff_hz, cycle_s,
                         drive_velocity=drive_velocity)
        self.g = gains
        self.revolute = revolute

    def update(self, q_ref: float, dq_ref: float, ddq_ref: float, q_meas: float,
               fresh: bool = True, dq_meas: float | None = None) -> float:
        """Return the torque reference [N m] for this cycle (``fresh``, ``dq_meas`` [rad/s]:
        see :meth:`PDLaw.torque`)."""
        g = self.g
        tau = g.J_ff * ddq_ref + g.Fv_ff * dq_ref
        if dq_ref > 0.0:
            tau += g.Fc_ff
        elif dq_ref < 0.0:
            tau -= g.Fc_ff
        if self.revolute and (g.MX_ff or g.MY_ff):
            tau += G * (g.MX_ff * math.cos(q_ref) + g.MY_ff * math.sin(q_ref))
        return self.torque(tau, q_ref, dq_ref, q_meas, fresh, dq_meas)
