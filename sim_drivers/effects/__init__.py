"""The plant's undeclared effects, one module each (paper-external physics the
identification models do not declare; all off unless enabled in the plant file).

Every module of this package whose name does not start with ``_`` is imported here and
registers a :class:`PlantEffect` (its ``[effects.<name>]`` table schema, its torque, its
forward-dynamics knobs), so that adding an effect is adding one file (docs/refinement.md,
"Adding an effect"). :func:`registry` lists them in plant-file order;
:mod:`sim_drivers.plant_config` and :mod:`sim_drivers.plant` loop over it.
"""

from __future__ import annotations

import importlib
import pkgutil

from ._base import Inputs, Knobs, PlantEffect, register, registry
from .asymmetric_viscous import AsymmetricViscous
from .position_ripple import PositionRipple
from .quadratic_viscous import QuadraticViscous
from .spring import Spring
from .torque_lag import TorqueLag
from .warm_up import WarmUp

#: Effect modules found in this package (every module not starting with ``_``), imported
#: here so that they register themselves.
EFFECT_MODULES: tuple[str, ...] = tuple(
    sorted(m.name for m in pkgutil.iter_modules(__path__) if not m.name.startswith("_"))
)
for _name in EFFECT_MODULES:
    importlib.import_module(f"{__name__}.{_name}")

__all__ = [
    "EFFECT_MODULES",
    "AsymmetricViscous",
    "Inputs",
    "Knobs",
    "PlantEffect",
    "PositionRipple",
    "QuadraticViscous",
    "Spring",
    "TorqueLag",
    "WarmUp",
    "register",
    "registry",
]
