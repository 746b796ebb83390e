"""A simulated n-dof arm on the bus: one :class:`~sim_drivers.arm.ArmPlant` behind n
simulated CiA 402 drives (one node id per joint), stepping together on SYNC.

Each drive is an ordinary :class:`~sim_drivers.drive.SimulatedDrive` (the same CiA 402 state
machine, PDO handling and watchdogs as for one joint); its plant is an :class:`ArmJoint`, a
one-joint view of the shared arm. The drives of a channel are on one
:class:`~sim_drivers.simbus.SimNetwork`; drives may be spread over several channels (buses,
each with its own SYNC from the master): the arm is stepped once per cycle, at the first
SYNC of the cycle on any of them (``_on_sync`` counts the SYNCs of each channel).

Timing (one SYNC, k = cycle index)
----------------------------------
1. :class:`ArmOnBus`'s SYNC handler -- subscribed before every drive's -- steps the arm once
   over the last cycle with the torques the drives commanded at SYNC k-1, when every joint
   was powered then (OPERATION ENABLED or QUICK STOP ACTIVE); otherwise the brakes hold the
   whole arm and it is not stepped (a simplification: no arm moves with one joint braked).
2. Each drive applies its latched RPDO, runs its control law (``ArmJoint.step`` only stores
   the torque for step 1 of the next SYNC), and answers its TPDOs from the arm's state at
   SYNC k.

So the position a TPDO carries at SYNC k results from the torques applied over the cycle
before it -- what a real drive samples at SYNC -- one cycle later than the single-joint
:class:`~sim_drivers.plant.JointPlant` drive, which steps on the torque it just received and
reports the position at the end of the coming cycle. ``torque actual`` (0x6077) is the torque
applied over that last cycle (command + ripple noise), as for ``JointPlant``.
"""

from __future__ import annotations

import logging
import math
import threading
from types import SimpleNamespace
from typing import Any

import numpy as np
import pinocchio as pin

from sim_drivers import SimError
from sim_drivers.arm import ArmParams, ArmPlant, Payload
from sim_drivers.arm_push import Push
from sim_drivers.drive import SimulatedDrive
from sim_drivers.faults import PLANT_FAULT
from sim_drivers.simbus import SimNetwork

logger = logging.getLogger(__name__)

__all__ = ["ArmJoint", "ArmOnBus", "TORQUE_DELAY_CYCLES"]

#: The timing of a log of the arm on the bus [cycles] (module docstring): the position of
#: SYNC k is the arm's at SYNC k; the torque a master computes from it is latched by the drive
#: at SYNC k+1 and applied by the arm's step over [k+1, k+2], whose middle is 1.5 cycles after
#: that position -- as on a drive whose synchronous RPDO is actuated at the next SYNC.
TORQUE_DELAY_CYCLES = 1.5

_INT16_MIN, _INT16_MAX = -32768, 32767


class ArmJoint:
    """Joint ``j`` of an :class:`ArmOnBus`, with the plant interface ``SimulatedDrive`` uses
    (``step``, ``q``, ``dq``, ``tau_applied``, ``encoder_counts``, scaling helpers).

    ``step(tau)`` [N m] stores the joint-side torque command for the arm's next step; the
    state attributes are the arm's at the last SYNC.
    """

    def __init__(self, arm: ArmOnBus, j: int, inertia: float) -> None:
        self.arm = arm
        self.j = j
        d = arm.params.drive
        self._per_mille = float(d.torque_per_permille[j])
        self._counts_per_rad = float(d.counts_per_rad[j])
        # what SimulatedDrive reads from ``plant.params``: rated torque and gear ratio (0x6076),
        # J [kg m^2] for its default CSP gains (the arm's M_jj at the start position)
        self.params = SimpleNamespace(drive=SimpleNamespace(
            rated_torque_Nm=float(d.rated_torque_Nm[j]), gear_ratio=float(d.gear_ratio[j])),
            J=float(inertia))
        self.tau_cmd = 0.0

    # -- state (the arm's at the last SYNC) -------------------------------------------------
    @property
    def q(self) -> float:
        return self.arm.q[self.j]

    @property
    def dq(self) -> float:
        return self.arm.dq[self.j]

    @property
    def tau_applied(self) -> float:
        return self.arm.tau_applied[self.j]

    @property
    def encoder_counts(self) -> int:
        return round(self.arm.q[self.j] * self._counts_per_rad)

    @property
    def counts_per_rad(self) -> float:
        return self._counts_per_rad

    # -- drive chain -------------------------------------------------------------------------
    def counts_to_rad(self, counts: int) -> float:
        return counts / self._counts_per_rad

    def rad_to_counts(self, q: float) -> int:
        return round(q * self._counts_per_rad)

    def torque_from_permille(self, x: int) -> float:
        """Joint-side torque [N m] of x per-mille of the rated torque."""
        return x * self._per_mille

    def permille_from_torque(self, tau: float) -> int:
        """Per-mille of rated torque of a joint-side torque [N m], rounded, int16-clipped."""
        x = round(tau / self._per_mille)
        return _INT16_MIN if x < _INT16_MIN else _INT16_MAX if x > _INT16_MAX else x

    # -- the drive's calls -------------------------------------------------------------------
    def step(self, tau_cmd: float) -> None:
        """The drive is powered this cycle and commands ``tau_cmd`` [N m] (applied by the
        arm's step at the next SYNC)."""
        self.tau_cmd = tau_cmd
        self.arm._cmd[self.j] = tau_cmd
        self.arm._powered[self.j] = True

    def set_payload(self, mass_kg: float, arm_m: float) -> None:
        """Mount a point mass of ``mass_kg`` [kg] at ``arm_m`` [m] along x of the flange
        (the single-joint runner's payload; :meth:`ArmOnBus.set_payload` takes any)."""
        self.arm.set_payload(Payload(mass_kg, [arm_m, 0.0, 0.0]) if mass_kg else None)


class ArmOnBus:
    """One simulated arm behind ``len(node_ids)`` simulated drives on one channel.

    Parameters
    ----------
    params : ArmParams
        The arm (k moving joints).
    channel : str
        Virtual channel shared with the master.
    node_ids : sequence of int
        Node id of the drive of each joint, base to tip (k of them).
    channels : sequence of str, optional
        Channel of each joint's drive (k of them; default: all on ``channel``). Every
        channel must receive the master's SYNC every cycle.
    cycle_s : float
        SYNC period the arm is stepped with [s].
    eds : path, DriveOD or None
        The drives' EDS/DCF (default: the generic one).
    substeps : int
        Integration sub-steps of :class:`ArmPlant` per cycle.
    seed : int
        Ripple-noise seed.
    q0 : array_like, optional
        Start position [rad] (default zeros).
    dispatch : {"inline", "thread"}
        :class:`SimNetwork` delivery ("inline" for lockstep).
    clock : {"wall", "sync"} or None
        The drives' clock (:mod:`sim_drivers.drive`, "Clock"); ``"sync"`` also clocks each
        channel by its SYNCs (``SimNetwork(sync_cycle_s=cycle_s)``: heartbeats paced by
        SYNC), and needs ``"inline"``. None: ``"sync"`` with ``"inline"``, else ``"wall"``.
    payload : Payload, optional
    fault_injectors : mapping of node id to FaultInjector, optional
        Scripted misbehaviour of the drive of that node (:mod:`sim_drivers.faults`).
    drive_kwargs
        Passed to every :class:`SimulatedDrive` (``fault_injector`` per drive is not: use
        ``fault_injectors``).

    Attributes
    ----------
    plant : ArmPlant
    drives : list of SimulatedDrive
        One per joint, started.
    steps : int
        Arm steps taken (SYNCs with every joint powered the cycle before).
    """

    def __init__(self, params: ArmParams, channel: str, node_ids: Any, *, cycle_s: float,
                 eds: Any = None, substeps: int = 10, seed: int = 0, q0: Any = None,
                 dispatch: str = "inline", payload: Payload | None = None,
                 channels: Any = None, clock: str | None = None,
                 fault_injectors: Any = None, **drive_kwargs: Any) -> None:
        node_ids = [int(n) for n in node_ids]
        injectors = dict(fault_injectors or {})
        if stray := sorted(set(injectors) - set(node_ids)):
            raise SimError(f"ArmOnBus: fault injectors for nodes {stray}, which are not the "
                           f"arm's {node_ids}")
        if len(node_ids) != params.k:
            raise SimError(f"ArmOnBus: expected {params.k} node ids (one per moving joint), "
                           f"got {len(node_ids)}")
        chans = [channel] * params.k if channels is None else [str(c) for c in channels]
        if len(chans) != params.k:
            raise SimError(f"ArmOnBus: expected {params.k} channels (one per moving joint), "
                           f"got {len(chans)}")
        if clock is None:
            clock = "sync" if dispatch == "inline" else "wall"
        if clock == "sync" and dispatch != "inline":
            raise SimError(f"ArmOnBus: clock='sync' needs dispatch='inline', got {dispatch!r}")
        self.params = params
        self.cycle_s = float(cycle_s)
        self.substeps = int(substeps)
        self.seed = int(seed)
        self.payload = payload
        self.plant = ArmPlant(params, cycle_s, substeps=substeps, seed=seed, payload=payload)
        self.plant.reset(q0)
        k = params.k
        self._cmd = [0.0] * k
        self._powered = [False] * k
        self.steps = 0
        self._sync_state()
        self._lock = threading.Lock()
        self._cycle = 0  # SYNCs seen on the channel that saw most
        self.sims: dict[str, SimNetwork] = {}
        self._handlers: list[tuple[Any, Any]] = []
        self.drives: list[SimulatedDrive] = []
        try:
            for ch in dict.fromkeys(chans):
                sim = self.sims[ch] = SimNetwork(
                    ch, dispatch=dispatch, sync_cycle_s=cycle_s if clock == "sync" else None)
                counter = [0]

                def on_sync(can_id: int, data: bytes, timestamp: float,
                            counter: list[int] = counter) -> None:
                    self._on_sync_of(counter)

                # first in line on SYNC: step the arm before any drive answers (docstring)
                sim.network.subscribers.setdefault(0x80, []).insert(0, on_sync)
                self._handlers.append((sim.network, on_sync))
            self.sim = self.sims[chans[0]]
            p = self.plant
            m_diag = np.diag(pin.crba(p.model, p.data, p.q))
            for j, (nid, ch) in enumerate(zip(node_ids, chans, strict=True)):
                joint = ArmJoint(self, j, m_diag[j])
                net = self.sims[ch].network
                drive = SimulatedDrive(net, nid, joint, eds, cycle_s=cycle_s, clock=clock,
                                       fault_injector=injectors.get(nid), **drive_kwargs)
                self.sims[ch].add(drive)
                self.drives.append(drive)
        except Exception:
            self.close()
            raise

    def _sync_state(self) -> None:
        p = self.plant
        self.q = p.q.tolist()
        self.dq = p.dq.tolist()
        self.tau_applied = p.tau_applied.tolist()

    def _on_sync_of(self, counter: list[int]) -> None:
        """A SYNC on one channel: step the arm if it is the cycle's first SYNC (the first
        channel to see its n-th SYNC steps the arm for cycle n)."""
        with self._lock:
            counter[0] += 1
            if counter[0] <= self._cycle:
                return
            self._cycle = counter[0]
            self._on_sync(0x80, b"", 0.0)

    def _on_sync(self, can_id: int, data: bytes, timestamp: float) -> None:
        powered = self._powered
        if all(powered):
            try:
                self.plant.step(self._cmd)
                if not all(math.isfinite(x) for x in self.plant.q.tolist()):
                    raise SimError("arm state is not finite")
            except Exception:  # the arm failed: every drive faults, the bus thread lives on
                logger.exception("arm step failed after %d steps", self.steps)
                for d in self.drives:
                    with d._lock:
                        d.fault(PLANT_FAULT)
            else:
                self.steps += 1
                self._sync_state()
        for j in range(len(powered)):
            powered[j] = False

    def set_payload(self, payload: Payload | None) -> None:
        """Mount ``payload`` (None: none) on the flange; the arm keeps its state."""
        same = (payload is None and self.payload is None) or (
            payload is not None and self.payload is not None
            and payload.mass == self.payload.mass
            and np.array_equal(payload.com, self.payload.com)
            and np.array_equal(payload.inertia, self.payload.inertia)
            and payload.frame == self.payload.frame)
        if same:
            return
        old = self.plant
        plant = ArmPlant(self.params, self.cycle_s, substeps=self.substeps, seed=self.seed,
                         payload=payload)
        plant.reset(old.q, old.t0)
        plant.dq = old.dq.copy()
        plant.t = old.t
        plant.tau_applied = old.tau_applied.copy()
        plant._rng = old._rng  # one noise sequence over the campaign
        plant.pushes = list(old.pushes)
        self.plant, self.payload = plant, payload

    def push(self, push: Push) -> None:
        """Apply an external force (:mod:`sim_drivers.arm_push`; its ``t0_s`` on the arm's
        simulated time ``plant.t``) from the next arm step that reaches it."""
        with self._lock:
            self.plant.pushes.append(push)

    @property
    def node_ids(self) -> list[int]:
        return [d.node_id for d in self.drives]

    def close(self) -> None:
        """Stop the drives and shut the buses (idempotent)."""
        for net, handler in self._handlers:
            subs = net.subscribers.get(0x80, [])
            if handler in subs:
                subs.remove(handler)
        for sim in self.sims.values():
            sim.close()

    def __enter__(self) -> ArmOnBus:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
