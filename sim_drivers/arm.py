"""Offline n-dof arm simulator: the ground truth of the multi-joint identification.

Forward dynamics with pinocchio's ABA (rotor inertias as armature), the load- and
velocity-dependent friction of Hamon, Gautier & Garrec (eq. 17-30) on every joint with
stiction and event detection, the undeclared effects of the plant-effect registry, per-joint drive
quantisation and noise, and a PD + feed-forward closed loop. The pieces:

* :mod:`sim_drivers.arm_params`    -- :class:`ArmParams` (truth, ``truth()`` by parameter name;
  ``from_model`` / ``from_robot`` make a plausible truth), :class:`ArmFriction`,
  :class:`ArmDrive`, :class:`Payload` (inertia about its CoM like the campaign payloads;
  ``Payload.coerce`` takes those)
* :mod:`sim_drivers.arm_effects`   -- :class:`ArmEffects` (undeclared effects, per joint)
* :mod:`sim_drivers.arm_plant`     -- :class:`ArmPlant` (forward model: the plant computation
  of :mod:`sim_drivers.dynamics`, shared with the single joint, on a pinocchio body),
  :func:`inverse_arm_torque` (inverse model)
* :mod:`sim_drivers.arm_offline`   -- :func:`simulate_arm` -> :class:`ArmRun`, :class:`ArmGains`,
  :func:`simulate_arm_payloads`
* :mod:`sim_drivers.arm_reference` -- smooth multi-joint test references
* :mod:`sim_drivers.arm_push`      -- :class:`Push`: an external force on a link for a time
* :mod:`sim_drivers.robots`        -- packaged robot models (UR10 from example-robot-data)

Example::

    from sim_drivers.arm import ArmParams, ArmGains, Payload, simulate_arm, model_reference
    from sim_drivers.robots import ur10
    params = ArmParams.from_model(ur10(3))
    ref = model_reference(params.model, duration_s=20.0)
    pay = Payload(5.0, com=[0.0, 0.0, 0.05], frame="tool0")   # 5 kg at the flange
    run = simulate_arm(params, ref, ArmGains.for_params(params, payload=pay), payload=pay)
    truth = params.truth(pay)                 # {"ZZ1": ..., "MX3": ..., "a_m2": ..., ...}
"""

from __future__ import annotations

from .arm_effects import ArmEffects
from .arm_offline import (
    ArmGains,
    ArmRun,
    feedforward_torque,
    simulate_arm,
    simulate_arm_payloads,
)
from .arm_params import (
    FRICTION_NAMES,
    STANDARD_NAMES,
    ArmDrive,
    ArmFriction,
    ArmParams,
    ArmParamsError,
    Payload,
)
from .arm_plant import (
    REGIME_REST,
    REGIME_SLIDING,
    REGIME_ZERO_LOAD,
    ArmPlant,
    friction_torque,
    inverse_arm_torque,
    output_arm_torque,
)
from .arm_push import Push, push_torque, staged_push
from .arm_reference import ArmReference, model_reference, sine_reference

__all__ = [
    "FRICTION_NAMES", "REGIME_REST", "REGIME_SLIDING", "REGIME_ZERO_LOAD", "STANDARD_NAMES",
    "ArmDrive", "ArmEffects", "ArmFriction", "ArmGains", "ArmParams", "ArmParamsError",
    "ArmPlant", "ArmReference", "ArmRun", "Payload", "Push", "feedforward_torque",
    "friction_torque", "inverse_arm_torque", "model_reference", "output_arm_torque",
    "push_torque", "simulate_arm", "simulate_arm_payloads", "sine_reference", "staged_push",
]
