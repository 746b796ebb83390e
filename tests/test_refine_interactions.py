"""Refinement on simulated data with effects nobody declared and that live in an interaction:
the interaction diagnosis and the library search (ident/interactions.py,
ident/library_search.py, ident/describe.py) must name the right variables, reach within 10 %
of the error of the true model structure fitted on the same data, lower the held-out error,
and add nothing to clean data.

The effects are not in the named list of the refinement; they vary in period, amplitude,
length and seed:

* position-dependent dry friction a F_C sin(2π q/P + φ) sign(q̇) (worn or eccentric
  transmission);
* a friction depending on two variables at once, κ |τ_out| q̇ (viscous friction growing with
  the load; three payloads so that the load is not a function of the position);
* a hysteresis that builds up after each reversal: a Dahl-like state z, dz/ds = (sign(q̇) - z)/L
  in the travelled distance s, torque F_h z;
* a dry friction with a localised bump along the position (no named form: described in words);
* two effects at once.

The effects are added to the logged torque (computed from the plant's true state): an
open-loop shortcut until the plant carries them as physics.
"""

from __future__ import annotations

import functools
import json

import numpy as np
import pytest
from test_refine_sim import SETTINGS, _campaign, _plan, _usual_plant

from daq.protocol.control import ControllerGains
from ident.effects import rigid_prediction
from ident.interaction_effects import LoadViscous, PositionDryFriction, ReversalHysteresis
from ident.models import IdentModel, usual_model
from ident.preprocess import build_design
from ident.refine import refine
from ident.refine_plots import plot_refinement
from ident.signals import Signals
from ident.terms import Term
from sim_drivers.offline import simulate
from sim_drivers.plant import output_torque

F_C = 18.0


def _dahl(q: np.ndarray, dq: np.ndarray, length: float) -> np.ndarray:
    """Friction state z in [-1, 1]: dz/ds = (sign(dq) - z) / L, s the travelled distance."""
    z = np.empty_like(q)
    zz = 0.0
    sg = np.sign(dq).tolist()
    ds = np.abs(np.diff(q, prepend=q[0]))
    decay = np.exp(-ds / length).tolist()
    for k, (s_k, e_k) in enumerate(zip(sg, decay, strict=True)):
        if s_k != 0:
            zz = s_k + (zz - s_k) * e_k
        z[k] = zz
    return z


def _effect_torque(kind: str, run, plant, **kw) -> np.ndarray:
    q, dq = run.q_true, run.dq_true
    if kind == "position_friction":
        return kw["a"] * F_C * np.sin(2 * np.pi * q / kw["P"] + kw["phi"]) * np.sign(dq)
    if kind == "load_viscous":
        tau_out = output_torque(plant, q, run.ddq_true, run.payload_mass_kg, run.payload_arm_m)
        return kw["k"] * np.abs(tau_out) * dq
    if kind == "hysteresis":
        return kw["F"] * _dahl(q, dq, kw["L"])
    if kind == "bump_friction":
        return kw["a"] * F_C * np.exp(-(((q - kw["q0"]) / kw["w"]) ** 2)) * np.sign(dq)
    raise KeyError(kind)


@functools.cache
def _run(seed: int, payload: int):
    plan = _plan()
    gains = ControllerGains(**_campaign().gains_kwargs())
    pl = plan.payloads[payload]
    p = _usual_plant()
    return p, simulate(p, plan.reference, gains, payload_mass=pl.mass_kg,
                       payload_arm=pl.arm_m, seed=seed + 10 * payload)


def _design(effects: tuple, seed: int = 0, payloads: int = 1):
    parts = []
    for i in range(payloads):
        p, r = _run(seed, i)
        tau = r.tau_ref.copy()
        for kind, kw in effects:
            tau = tau + _effect_torque(kind, r, p, **dict(kw))
        n = len(r)
        parts.append(dict(t=r.t, q=r.q, dq=np.zeros(n), ddq=np.zeros(n), tau=tau,
                          payload_mass=np.full(n, r.payload_mass_kg),
                          payload_arm=np.full(n, r.payload_arm_m),
                          experiment=np.full(n, i)))
    s = Signals(**{k: np.concatenate([x[k] for x in parts]) for k in parts[0]}, revolute=True)
    lib = usual_model(True, payload=payloads > 1)
    return build_design(lib, s, **SETTINGS), lib


def _true_terms(effects: tuple, d, lib) -> list[Term]:
    m0 = IdentModel(lib).fit(d, eliminate=False)
    out: list[Term] = []
    for kind, kw in effects:
        kw = dict(kw)
        if kind == "position_friction":
            out.append(PositionDryFriction(kw["P"]))
        elif kind == "load_viscous":
            out.append(LoadViscous(rigid_prediction(lib, m0.coef_)))
        elif kind == "hysteresis":
            out.append(ReversalHysteresis(kw["L"]))
        else:
            out.append(_Bump(kw["q0"], kw["w"]))
    return out


class _Bump(Term):
    """The true structure of the bump friction (known centre and width)."""

    effect = "bump"

    def __init__(self, q0: float, w: float) -> None:
        self.q0, self.w = q0, w

    def names(self):
        return ("bump",)

    def columns(self, s):
        return (np.exp(-(((s.q - self.q0) / self.w) ** 2)) * np.sign(s.dq))[:, None]


def _true_structure_error(effects: tuple, d, lib) -> float:
    terms = _true_terms(effects, d, lib)
    dd, full = d, lib
    for t in terms:
        dd, full = dd.with_term(t), full + t
    return IdentModel(full).fit(dd, eliminate=False).rel_error_


@functools.cache
def _refined(effects: tuple, seed: int = 0, payloads: int = 1):
    d, lib = _design(effects, seed, payloads)
    return refine(d, IdentModel(lib, "usual"), max_steps=4), d, lib


def _fz(**kw):
    return tuple(sorted(kw.items()))


POSITION_FRICTION = [  # (a, P [rad], phase, seed)
    (0.38, 1.57, 0.3, 0),
    (0.25, 0.8, 1.1, 1),
    (0.5, 0.45, -0.7, 2),
]


@pytest.mark.parametrize("a,P,phi,seed", POSITION_FRICTION)
def test_position_dependent_dry_friction(a, P, phi, seed):
    eff = (("position_friction", _fz(a=a, P=P, phi=phi)),)
    R, d, lib = _refined(eff, seed)
    assert R.steps, R.format_report()
    st = R.steps[0]
    assert set(st.variables) == {"position", "direction"}, R.format_report()
    assert st.named_effect == "position_periodic_dry_friction"
    par = st.parameters
    assert par["fcq_period"]["value"] == pytest.approx(P, rel=0.02)
    assert par["fcq_amplitude"]["value"] == pytest.approx(a * F_C, rel=0.10)
    assert "period" in st.structure and "% of F_C" in st.structure
    assert st.heldout_rel_error_after < st.heldout_rel_error_before
    assert R.rel_error_final <= 1.10 * _true_structure_error(eff, d, lib)


@pytest.mark.parametrize("k,seed", [(0.08, 0), (0.04, 1)])
def test_friction_depending_on_load_and_velocity(k, seed):
    eff = (("load_viscous", _fz(k=k)),)
    R, d, lib = _refined(eff, seed, 3)
    assert R.steps, R.format_report()
    st = R.steps[0]
    assert {"velocity", "load"} <= {v.replace("load_quadrant", "load") for v in st.variables}, (
        R.format_report())
    assert st.named_effect == "load_dependent_viscous"
    assert st.parameters["F_V_load"]["value"] == pytest.approx(k, rel=0.10)
    assert st.heldout_rel_error_after < st.heldout_rel_error_before
    assert R.rel_error_final <= 1.10 * _true_structure_error(eff, d, lib)


@pytest.mark.parametrize("F,L,seed", [(5.0, 0.1, 0), (3.0, 0.05, 1), (6.0, 0.25, 2)])
def test_hysteresis_building_up_after_each_reversal(F, L, seed):
    eff = (("hysteresis", _fz(F=F, L=L)),)
    R, d, lib = _refined(eff, seed)
    assert R.steps, R.format_report()
    st = R.steps[0]
    assert set(st.variables) == {"reversal", "direction"}, R.format_report()
    assert st.named_effect == "reversal_hysteresis"
    # z goes from -1 to +1 after a full reversal: the drop is about -2 F_h
    assert st.parameters["hysteresis_length"]["value"] == pytest.approx(L, rel=0.15)
    assert st.parameters["F_hyst"]["value"] == pytest.approx(-2 * F, rel=0.15)
    assert "reversal" in st.structure
    assert R.rel_error_final <= 1.10 * _true_structure_error(eff, d, lib)


def test_unnamed_structure_is_described_in_words():
    eff = (("bump_friction", _fz(a=0.4, q0=0.5, w=0.3)),)
    R, d, lib = _refined(eff, 3)
    assert R.steps, R.format_report()
    st = R.steps[0]
    assert set(st.variables) == {"position", "direction"}, R.format_report()
    assert st.named_effect is None and st.generic
    assert st.structure.startswith("dry friction varies with position")
    assert st.heldout_rel_error_after < 0.9 * st.heldout_rel_error_before
    assert R.rel_error_final <= 1.10 * _true_structure_error(eff, d, lib)


@pytest.mark.slow
def test_two_effects_at_once():
    eff = (("position_friction", _fz(a=0.3, P=0.8, phi=0.3)), ("load_viscous", _fz(k=0.06)))
    R, d, lib = _refined(eff, 4, 3)
    named = [st.named_effect for st in R.steps]
    assert "position_periodic_dry_friction" in named and "load_dependent_viscous" in named, (
        R.format_report())
    assert R.rel_error_final <= 1.10 * _true_structure_error(eff, d, lib)
    for st in R.steps:
        assert st.heldout_rel_error_after < st.heldout_rel_error_before


@pytest.mark.parametrize("seed,payloads", [(0, 1), (5, 1), (0, 3)])
def test_clean_data_get_nothing(seed, payloads):
    R, _d, _lib = _refined((), seed, payloads)
    assert R.steps == [], R.format_report()
    # the library was searched and every structure says why it was not taken
    assert R.library_tried and R.library_tried[0]["tried"]
    assert all(t["reason"] for t in R.library_tried[0]["tried"])


def test_json_and_report_show_variables_structure_and_heldout():
    eff = (("position_friction", _fz(a=0.38, P=1.57, phi=0.3)),)
    R, _d, _lib = _refined(eff, 0)
    js = json.loads(json.dumps(R.to_json()))
    st = js["steps"][0]
    assert st["variables"] == ["position", "direction"]
    assert st["named_effect"] == "position_periodic_dry_friction"
    assert "period" in st["structure"]
    assert st["heldout_rel_error_after"] < st["heldout_rel_error_before"]
    assert st["interactions"] and st["interactions"][0]["p_adjusted"] < 1e-3
    tried = js["library_tried"][0]["tried"]
    assert any(t["selected"] for t in tried)
    assert all(t["reason"] for t in tried)
    text = R.format_report()
    assert "held-out" in text and "position x direction" in text


def test_the_structure_of_a_library_step_is_plotted(tmp_path):
    eff = (("bump_friction", _fz(a=0.4, q0=0.5, w=0.3)),)
    R, _d, _lib = _refined(eff, 3)
    paths = plot_refinement(R, tmp_path)
    shape = tmp_path / "refine_step1_structure.png"
    assert shape in paths
    data = shape.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 5000
