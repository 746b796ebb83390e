"""Simulated joints for the refinement's acceptance over noise seeds (tests/test_refine_seeds.py,
benchmarks/bench_refine.py): every undeclared plant effect, position-dependent dry friction,
load-dependent viscous friction, two effects at once and a clean joint, each with the error
of its true structure fitted on the same data."""

from __future__ import annotations

import functools

import numpy as np
from test_refine_interactions import _effect_torque, _fz, _true_terms
from test_refine_sim import EFFECTS, SETTINGS, _campaign, _plan, _usual_plant

from daq.protocol.control import ControllerGains
from ident.effects import (
    DirectionalViscous,
    PositionRipple,
    Prediction,
    QuadraticViscous,
    Spring,
    TorqueLag,
    WarmUp,
)
from ident.models import IdentModel, usual_model
from ident.preprocess import build_design
from ident.refine import refine
from ident.signals import Signals
from sim_drivers.offline import simulate

#: case -> (plant effects, added torque effects, payload runs)
CASES = {
    "clean": ((), (), 1),
    **{e: ((e,), (), 1) for e in EFFECTS},
    "position_friction": ((), (("position_friction", _fz(a=0.4, P=0.8, phi=0.3)),), 1),
    "load_viscous": ((), (("load_viscous", _fz(k=0.06)),), 3),
    "two_effects": (("position_ripple",),
                    (("load_viscous", _fz(k=0.06)),), 3),
}


def _plant_term(effect: str, lib, d):
    truth = EFFECTS[effect]
    if effect == "position_ripple":
        return PositionRipple(truth["period_rad"])
    if effect == "spring":
        return Spring(truth["rest_position_rad"])
    if effect == "warm_up":
        return WarmUp(truth["time_constant_s"])
    if effect == "asymmetric_viscous":
        return DirectionalViscous()
    if effect == "quadratic_viscous":
        return QuadraticViscous()
    m0 = IdentModel(lib).fit(d, eliminate=False)
    return TorqueLag(Prediction(lib.terms(), m0.coef_array_))


@functools.cache
def case_design(case: str, seed: int):
    plant_effects, added, payloads = CASES[case]
    p = _usual_plant()
    for e in plant_effects:
        p = p.with_effect(e, **EFFECTS[e])
    plan = _plan()
    gains = ControllerGains(**_campaign().gains_kwargs())
    parts = []
    for i, pl in enumerate(plan.payloads[:payloads]):
        r = simulate(p, plan.reference, gains, payload_mass=pl.mass_kg, payload_arm=pl.arm_m,
                     seed=1000 * seed + i)
        tau = r.tau_ref.copy()
        for kind, kw in added:
            tau = tau + _effect_torque(kind, r, p, **dict(kw))
        n = len(r)
        parts.append(dict(t=r.t, q=r.q, dq=np.zeros(n), ddq=np.zeros(n), tau=tau,
                          payload_mass=np.full(n, r.payload_mass_kg),
                          payload_arm=np.full(n, r.payload_arm_m), experiment=np.full(n, i)))
    s = Signals(**{k: np.concatenate([x[k] for x in parts]) for k in parts[0]}, revolute=True)
    lib = usual_model(True, payload=payloads > 1)
    return build_design(lib, s, **SETTINGS), lib


def true_structure_error(case: str, seed: int) -> float:
    """Relative error of the declared model + the true effects' terms on the same samples."""
    d, lib = case_design(case, seed)
    plant_effects, added, _ = CASES[case]
    terms = [_plant_term(e, lib, d) for e in plant_effects] + _true_terms(added, d, lib)
    dd, full = d, lib
    for t in terms:
        dd, full = dd.with_term(t), full + t
    return IdentModel(full).fit(dd, eliminate=False).rel_error_


@functools.cache
def refined(case: str, seed: int):
    d, lib = case_design(case, seed)
    return refine(d, IdentModel(lib, "usual"), max_steps=4)
