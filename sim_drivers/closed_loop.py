"""The one offline closed loop, for one joint and for n: measure, control, quantise, step, record.

Each control cycle k does what the bus path does (``daq`` runner + simulated drives), minus
CANopen: the measured position comes from the encoder counts, a control law turns the
reference of cycle k and that measurement into a joint-side torque reference [N m], which is
quantised to the per-mille target torque (int16) that object 0x6071 would carry, and the plant
is stepped one cycle with the joint-side torque of that target, ``N rated_torque x / 1000``.

The single joint (:func:`sim_drivers.offline.simulate`, ``JointPlant``, the law of
``daq.protocol.control.PositionController``, Python scalars) and the arm
(:func:`sim_drivers.arm_offline.simulate_arm`, ``ArmPlant``, a vectorised PD + computed-torque
feed-forward, arrays of shape (k,)) run this same loop; they differ only in the plant, the
control law (a strategy: a callable ``law(k, q_measured) -> torque``), the rounding of the
counts and the quantiser they pass in. The reference reader and the cycle period are also
shared here, and the record both runs are (:class:`LoopRecord`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar

import numpy as np

from . import SimError
from .dynamics import REGIME_REST, REGIME_SLIDING

# law(k, q_measured) -> joint-side torque reference [N m]; q_measured [rad] is a float for the
# single joint, an array (k,) for the arm. A law may keep state (filters) between cycles.
ControlLaw = Callable[[int, Any], Any]

R = TypeVar("R", bound="LoopRecord")


class LoopPlant(Protocol):
    """What the loop needs of a plant (``JointPlant`` and ``ArmPlant`` both have it)."""

    cycle_s: float
    q: Any
    dq: Any
    ddq_start: Any
    tau_applied_start: Any
    tau_noise: Any
    regime_start: Any

    def step(self, tau_cmd: Any, *noise: Any) -> None: ...


@dataclass(frozen=True, eq=False)
class LoopRecord:
    """One offline run, one record per control cycle: arrays (n,) for one joint or (n, k) for
    k joints (``t`` and ``cycle`` are (n,) in both). The record of :func:`run_closed_loop` and
    the part that ``sim_drivers.offline.SimRun`` and ``sim_drivers.arm_offline.ArmRun`` share
    (each adds its own fields: the payload, the reference, ...).

    Record i holds the measurement the controller used at the start of cycle i and the command
    it sent for that cycle, like the MCAP reader's ``RunArrays``, plus the plant's truth.

    Attributes
    ----------
    t : ndarray, (n,)
        Time of the measurement, i * cycle_s [s].
    cycle : ndarray of int64, (n,)
        Cycle index i.
    counts : ndarray of int64
        Encoder readings [counts] (motor side, what 0x6064 carries).
    q : ndarray
        Measured joint positions from the counts [rad].
    x : ndarray of int16
        Target torques sent [per-mille of rated torque] (0x6071).
    tau_ref : ndarray
        Joint-side torque references of x, tau = g_f v_f (eq. 7) [N m]: what a master logs.
    tau_applied : ndarray
        Torque acting on the joints at the start of cycle i, after its command was applied
        (lagged command + ripple noise) [N m].
    tau_noise : ndarray
        Ripple-noise samples [N m].
    q_true, dq_true, ddq_true : ndarray
        True state at time t [rad, rad/s, rad/s^2]; ddq_true is the acceleration right after
        the command of cycle i is applied, so that the plant's inverse model
        (``inverse_torque`` / ``inverse_arm_torque``) gives ``tau_applied`` on the sliding
        entries.
    regime : ndarray of int8
        Plant regime at time t (``sim_drivers.dynamics.REGIME_*``): 0 sliding, 1 at rest,
        2 sliding with zero load.
    cycle_s : float
        Control cycle [s].
    """

    t: np.ndarray
    cycle: np.ndarray
    counts: np.ndarray
    q: np.ndarray
    x: np.ndarray
    tau_ref: np.ndarray
    tau_applied: np.ndarray
    tau_noise: np.ndarray
    q_true: np.ndarray
    dq_true: np.ndarray
    ddq_true: np.ndarray
    regime: np.ndarray
    cycle_s: float

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def stuck(self) -> np.ndarray:
        """Boolean mask of the entries where the joint is at rest (dq_true == 0)."""
        return self.regime == REGIME_REST

    @property
    def sliding(self) -> np.ndarray:
        """Boolean mask of the entries where the balance (eq. 30) holds exactly."""
        return self.regime == REGIME_SLIDING


def reference_arrays(reference: Any, joints: int | None = None
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The reference ``q, dq, ddq`` [rad, rad/s, rad/s^2] as float arrays, checked.

    Parameters
    ----------
    reference : object
        Anything with equal-length arrays ``q``, ``dq``, ``ddq``, one sample per cycle.
    joints : int, optional
        None: one joint, arrays of shape (n,). k: arrays of shape (n, k) (for k == 1, 1-D
        arrays are taken as one column).

    Raises
    ------
    SimError
        An array is missing, of the wrong shape or not finite, or there is no sample.
    """
    want = "(n,)" if joints is None else f"(n, {joints})"
    try:
        arrays = [np.asarray(getattr(reference, name), dtype=float)
                  for name in ("q", "dq", "ddq")]
    except AttributeError as exc:
        raise SimError(f"reference: expected arrays q, dq, ddq of shape {want} ({exc})"
                       ) from None
    if joints == 1:
        arrays = [a.reshape(-1, 1) if a.ndim == 1 else a for a in arrays]
    n = arrays[0].shape[0] if arrays[0].ndim else 0
    shape = (n,) if joints is None else (n, joints)
    for name, a in zip(("q", "dq", "ddq"), arrays, strict=True):
        if a.shape != shape or not np.all(np.isfinite(a)):
            raise SimError(f"reference.{name}: expected finite values of shape {shape}, got "
                           f"shape {a.shape}")
    if n < 1:
        raise SimError("reference: expected at least one sample")
    return arrays[0], arrays[1], arrays[2]


def cycle_period(reference: Any, cycle_s: float | None = None,
                 default: float | None = None) -> float:
    """The control cycle [s]: ``cycle_s`` when given, else the uniform sampling step of
    ``reference.t`` [s], else ``default``.

    Raises
    ------
    SimError
        ``cycle_s`` is not > 0; ``reference.t`` is missing (and no default), has fewer than 2
        samples or is not uniformly sampled (relative tolerance 1e-6).
    """
    if cycle_s is not None:
        if not cycle_s > 0:
            raise SimError(f"cycle_s: expected a number > 0 [s], got {cycle_s!r}")
        return cycle_s
    t = getattr(reference, "t", None)
    if t is None:
        if default is None:
            raise SimError("reference.t: expected the sample times [s] (or pass cycle_s)")
        return default
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or t.shape[0] < 2:
        raise SimError("reference.t: expected at least 2 samples to infer the cycle")
    dt = np.diff(t)
    c = float(np.median(dt))
    if not c > 0 or np.max(np.abs(dt - c)) > 1e-6 * c + 1e-12:
        raise SimError(f"reference.t: expected uniform sampling, got steps from "
                       f"{float(dt.min())!r} to {float(dt.max())!r} s")
    return c


def run_closed_loop(
    plant: LoopPlant,
    law: ControlLaw,
    quantise: Callable[[Any], Any],
    n: int,
    *,
    joints: int | None,
    counts_per_rad: float,
    torque_per_permille: float,
    rnd: Callable[[Any], Any] = round,
    noise: np.ndarray | None = None,
    record: Callable[..., R] = LoopRecord,  # type: ignore[assignment]
) -> R:
    """Run ``n`` control cycles of the closed loop on a plant that is already reset.

    Parameters
    ----------
    plant : LoopPlant
        ``JointPlant`` (``joints`` None) or ``ArmPlant`` (``joints`` = k).
    law : callable ``law(k, q_measured) -> torque``
        The control law of cycle k [N m], from the measured position [rad].
    quantise : callable
        Joint-side torque [N m] -> per-mille target torque (int16 range).
    n : int
        Number of cycles (the record's times are ``i plant.cycle_s`` [s]).
    joints : int or None
        None: scalar records (n,); k: records (n, k).
    counts_per_rad : float
        Encoder counts per joint radian (measured position = counts / counts_per_rad).
    torque_per_permille : float
        Joint-side torque of one per-mille of target torque [N m].
    rnd : callable
        Rounding of ``q counts_per_rad`` to counts (``round`` for a float, ``numpy.rint``
        for an array).
    noise : ndarray, optional
        Ripple-noise samples (n, k) [N m] passed to ``plant.step``; default: the plant draws
        its own.
    record : callable
        Makes the record from the keywords of the :class:`LoopRecord` fields: a subclass
        with its own fields given (e.g. a ``functools.partial`` of ``SimRun``).

    Returns
    -------
    LoopRecord
        What ``record`` makes.
    """
    shape = (n,) if joints is None else (n, joints)
    counts = np.empty(shape, dtype=np.int64)
    xs = np.empty(shape, dtype=np.int16)
    tau_applied = np.empty(shape)
    tau_noise = np.empty(shape)
    q_true = np.empty(shape)
    dq_true = np.empty(shape)
    ddq_true = np.empty(shape)
    regime = np.empty(shape, dtype=np.int8)
    cpr, per_mille, step = counts_per_rad, torque_per_permille, plant.step
    for k in range(n):
        c = rnd(plant.q * cpr)
        counts[k] = c
        q_true[k] = plant.q
        dq_true[k] = plant.dq
        x = quantise(law(k, c / cpr))
        xs[k] = x
        if noise is None:
            step(x * per_mille)
        else:
            step(x * per_mille, noise[k])
        ddq_true[k] = plant.ddq_start
        tau_applied[k] = plant.tau_applied_start
        tau_noise[k] = plant.tau_noise
        regime[k] = plant.regime_start
    cycle = np.arange(n, dtype=np.int64)
    cycle_s = plant.cycle_s
    return record(t=cycle * cycle_s, cycle=cycle, counts=counts, q=counts / cpr, x=xs,
                  tau_ref=xs.astype(float) * per_mille, tau_applied=tau_applied,
                  tau_noise=tau_noise, q_true=q_true, dq_true=dq_true, ddq_true=ddq_true,
                  regime=regime, cycle_s=float(cycle_s))


def per_payload(run_one: Callable[[Any, int], Any], payloads: Iterable[Any], seed: int
                ) -> list[Any]:
    """``run_one(payload, seed + i)`` for payload i: one run per payload with independent,
    reproducible noise, in the order of ``payloads`` (as a campaign does, paper IV.B)."""
    return [run_one(pay, seed + i) for i, pay in enumerate(payloads)]
