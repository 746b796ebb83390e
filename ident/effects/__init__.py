"""Candidate effects: regressor terms the refinement loop may add to a declared model.

One module per effect, each holding its :class:`Effect` subclass (columns linear in its
parameters, nonlinear hyper-parameters such as a ripple period, a Stribeck velocity q_s or a
warm-up time constant), its hyper-parameter scan and its proposal function registered with
:func:`register` (see :mod:`ident.effects._base`). Every module of this package whose name
does not start with ``_`` is imported here, so that adding an effect is adding one file
(docs/refinement.md, "Adding an effect"); :func:`registry` lists them in candidate order.

==========================  ============  ==============================================
effect                      variable      columns (parameters)
==========================  ============  ==============================================
``position_ripple``         position      sin(2π q/P), cos(2π q/P)  (A, phase; P scanned)
``spring``                  position      q - q_c  (k_spring)
``position_smooth``         position      Legendre P_2..P_d of the scaled position
``directional_viscous``     direction     |q̇|/2  (dF_V = F_V+ - F_V-)
``quadratic_viscous``       velocity      q̇|q̇|  (F_VV)
``stribeck``                velocity      exp(-|q̇|/q_s) sign(q̇)  (F_S; q_s scanned, eq. 22)
``quadrant_load``           quadrant      sign(P) τ̂_out  (alpha_P, eq. 17-20, 26)
``quadrant_coulomb``        quadrant      sign(P) sign(q̇) / 2  (dF_Cq = c_m - c_g)
``quadrant_load_stribeck``  quadrant      sign(P) τ̂_out exp(-|q̇|/q_s)  (beta_P; eq. 24)
``warm_up``                 time          exp(-t/T_w) sign(q̇)  (dF_C_warm; T_w scanned)
``torque_lag``              acceleration  dτ̂/dt  (T_lag)
``generic_<variable>``      any           hinges max(x - k_j, 0) of the variable (× sign(q̇))
==========================  ============  ==============================================

``τ̂_out`` is the load torque predicted by the declared rigid-body terms with their current
coefficients (the terms whose ``variable`` is ``"model"``), see :class:`Prediction`; the
torque lag differentiates the whole current model prediction τ̂.
Nothing here touches files; everything is vectorised over samples.
"""

from __future__ import annotations

import importlib
import pkgutil

from ._base import (
    VARIABLES,
    Candidate,
    Context,
    Effect,
    Prediction,
    Registration,
    Setting,
    amplitude_phase,
    available_variables,
    model_prediction,
    model_quadrant,
    register,
    registry,
    rigid_prediction,
    unique_tag,
    variable_values,
)
from ._scan import Columns, Scorer, effective_n, refine_1d, scan_log
from .directional_viscous import DirectionalViscous
from .generic import CONTINUOUS, GenericBasis
from .position_ripple import PositionRipple
from .position_smooth import PositionSmooth
from .quadrant_coulomb import QuadrantCoulomb
from .quadrant_load import QuadrantLoad
from .quadrant_load_stribeck import QuadrantLoadStribeck
from .quadratic_viscous import QuadraticViscous
from .spring import Spring
from .stribeck import Stribeck
from .torque_lag import TorqueLag
from .warm_up import WarmUp

#: Effect modules found in this package (every module not starting with ``_``), imported
#: here so that their proposal functions register themselves.
EFFECT_MODULES: tuple[str, ...] = tuple(
    sorted(m.name for m in pkgutil.iter_modules(__path__) if not m.name.startswith("_"))
)
for _name in EFFECT_MODULES:
    importlib.import_module(f"{__name__}.{_name}")

__all__ = [
    "VARIABLES",
    "amplitude_phase",
    "CONTINUOUS",
    "EFFECT_MODULES",
    "Candidate",
    "Columns",
    "Context",
    "DirectionalViscous",
    "Effect",
    "Setting",
    "GenericBasis",
    "PositionRipple",
    "PositionSmooth",
    "Prediction",
    "QuadrantCoulomb",
    "QuadrantLoad",
    "QuadrantLoadStribeck",
    "QuadraticViscous",
    "Registration",
    "Scorer",
    "Spring",
    "Stribeck",
    "TorqueLag",
    "WarmUp",
    "effective_n",
    "refine_1d",
    "register",
    "registry",
    "rigid_prediction",
    "available_variables",
    "model_prediction",
    "model_quadrant",
    "scan_log",
    "unique_tag",
    "variable_values",
]
