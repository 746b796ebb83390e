"""Base of the plant's undeclared effects: the registry, the inputs of an effect's torque
and the knobs of the forward dynamics an effect sets.

An effect module (one file in ``sim_drivers/effects/``, see docs/refinement.md "Adding an
effect") defines the frozen dataclass of its plant-file table ``[effects.<name>]`` (field
``enabled`` plus its parameters, with their defaults), and registers a
:class:`PlantEffect` with its schema (keys, units, validation), its vectorised torque (the
inverse model, :func:`sim_drivers.plant.inverse_torque`, and the arm's) and, for an effect
the plant has no native form of, its forward-dynamics static torque (:class:`Knobs`, read by
:class:`sim_drivers.dynamics.ChainDynamics`)::

    register(PlantEffect(
        name="spring", order=20, params=Spring, formula="k (q - q0)",
        schema={"stiffness_Nm_per_rad": Field(float, unit="N m/rad"),
                "rest_position_rad": Field(float, unit="rad")},
        torque=lambda p, x: p.stiffness_Nm_per_rad * (x.q - p.rest_position_rad),
    ))

Pure numerics: no file, no bus. Joint side SI units as in :mod:`sim_drivers.plant`.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from trajectories.schema import Field

if TYPE_CHECKING:  # pragma: no cover
    from ..plant_config import PlantParams

__all__ = ["Inputs", "Knobs", "PlantEffect", "register", "registry"]


class Inputs:
    """States an effect's torque is evaluated at (arrays broadcast together).

    Attributes
    ----------
    params : PlantParams
        The whole plant (friction, joint...).
    q, dq : ndarray
        Position [rad] and velocity [rad/s] (float arrays).
    ddq, payload_mass, payload_arm, t : array_like
        Acceleration [rad/s^2], payload M_a [kg] and arm L_a [m], time since the run
        start [s], as given.
    tau_out : ndarray
        Output (load) torque of eq. 31/34 [N m], computed on first use.
    """

    def __init__(
        self,
        params: PlantParams,
        q: np.ndarray,
        dq: np.ndarray,
        ddq: Any,
        payload_mass: Any,
        payload_arm: Any,
        t: Any,
        output_torque: Callable[..., np.ndarray],
    ) -> None:
        self.params, self.q, self.dq, self.ddq = params, q, dq, ddq
        self.payload_mass, self.payload_arm, self.t = payload_mass, payload_arm, t
        self._output_torque = output_torque

    @functools.cached_property
    def tau_out(self) -> np.ndarray:
        return self._output_torque(self.params, self.q, self.ddq, self.payload_mass,
                                   self.payload_arm)


@dataclass
class Knobs:
    """What a registered effect WITHOUT a native form adds to the forward dynamics of the
    plant (:class:`sim_drivers.dynamics.ChainDynamics`, for the single joint and the arm).

    The six native effects (ripple, spring, warm-up, asymmetric and quadratic viscous, torque
    lag) have their forward form in ``ChainDynamics.accel`` and set no knob.

    Attributes
    ----------
    extra : list of callable
        Static torques ``f(q, dq, t) -> float`` [N m] (scalars; t since the run start),
        subtracted from the driving torque while sliding and at rest (dq = 0).
    """

    extra: list[Callable[[float, float, float], float]] = field(default_factory=list)


@dataclass(frozen=True)
class PlantEffect:
    """One undeclared effect of the plant.

    Attributes
    ----------
    name : str
        Table name in the plant file, ``[effects.<name>]``, and key of
        ``PlantParams.effects``.
    order : int
        Rank in the plant file's effects, ``Effects.enabled()`` and ``effect_torques``.
    params : type
        Frozen dataclass: ``enabled: bool = False`` then the parameters with defaults.
    schema : mapping of str to Field
        Each parameter's type, unit and bounds (required once ``enabled = true``).
    formula : str
        One line for the docs and the plant-file comment.
    torque : callable or None
        ``torque(p, x: Inputs) -> ndarray`` [N m], the effect's term of the inverse model
        (the one place its formula is written: the single joint and the arm call it; numpy
        broadcasting only, so that the arm can pass per-joint arrays (k,) as parameters and
        states of shape (..., k)); None for a dynamic effect (torque lag), which is not a
        term of the balance.
    configure : callable or None
        ``configure(p, knobs: Knobs, params)``: add the effect's static torque to
        ``knobs.extra`` (``params``: the joint's ``friction`` and ``joint.q_s``); None for the
        native effects, whose forward form is in ``ChainDynamics.accel``.
    truth : callable or None
        ``truth(p) -> dict`` of derived true values added to
        :meth:`~sim_drivers.plant_config.PlantParams.truth_effects`.
    """

    name: str
    order: int
    params: type
    schema: Mapping[str, Field]
    formula: str
    torque: Callable[[Any, Inputs], np.ndarray] | None
    configure: Callable[[Any, Knobs, Any], None] | None = None
    truth: Callable[[Any], dict[str, float]] | None = None
    module: str = ""


_REGISTRY: dict[str, PlantEffect] = {}


def register(effect: PlantEffect) -> PlantEffect:
    """Add an effect to the registry (called once at the bottom of its module)."""
    old = _REGISTRY.get(effect.name)
    if old is not None and old.module != effect.module:
        raise ValueError(f"plant effect {effect.name!r} registered twice")
    clash = [e.name for e in _REGISTRY.values() if e.order == effect.order
             and e.name != effect.name]
    if clash:
        raise ValueError(f"plant effect {effect.name!r}: order {effect.order} already used by "
                         f"{clash[0]!r}")
    _REGISTRY[effect.name] = effect
    return effect


def registry() -> list[PlantEffect]:
    """The registered effects, by increasing order."""
    return sorted(_REGISTRY.values(), key=lambda e: e.order)
