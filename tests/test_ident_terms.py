"""Regressor terms against hand-computed values of the paper's equations (eq. 26-44), and
W chi = tau on noise-free plant data (property test)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ident import DataError
from ident.models import (
    Coulomb,
    LoadDependent,
    Offset,
    Payload,
    QuadrantCoulomb,
    RigidBody,
    Viscous,
    new_model,
    usual_model,
)
from ident.signals import G, Signals


def sig(q, dq, ddq, tau, mass=0.0, arm=0.0, revolute=True) -> Signals:
    q = np.atleast_1d(np.asarray(q, float))
    n = q.size
    return Signals(
        t=np.arange(n) * 1e-3,
        q=q,
        dq=np.broadcast_to(np.asarray(dq, float), (n,)).copy(),
        ddq=np.broadcast_to(np.asarray(ddq, float), (n,)).copy(),
        tau=np.broadcast_to(np.asarray(tau, float), (n,)).copy(),
        payload_mass=np.full(n, float(mass)),
        payload_arm=np.full(n, float(arm)),
        experiment=np.zeros(n, int),
        revolute=revolute,
    )


def test_rigid_body_revolute_and_prismatic():
    s = sig([0.3, -1.0], [0.5, -0.2], [2.0, -3.0], [1.0, 1.0])
    w = RigidBody().columns(s)
    assert RigidBody().names() == ("J", "MX", "MY")
    np.testing.assert_allclose(w[0], [2.0, 9.81 * math.cos(0.3), 9.81 * math.sin(0.3)])
    np.testing.assert_allclose(w[1], [-3.0, 9.81 * math.cos(-1.0), 9.81 * math.sin(-1.0)])
    p = sig([0.3], [0.5], [2.0], [1.0], revolute=False)
    assert RigidBody(revolute=False).names() == ("J",)
    np.testing.assert_allclose(RigidBody(revolute=False).columns(p), [[2.0]])
    # undecided kind on prismatic data: gravity columns are zero (reported by the estimator)
    np.testing.assert_allclose(RigidBody().columns(p), [[2.0, 0.0, 0.0]])


def test_payload_eq35():
    s = sig([0.4], [0.1], [1.5], [0.0], mass=3.4584, arm=1.277)
    expect = 3.4584 * 1.277 * (1.277 * 1.5 + 9.81 * math.cos(0.4))
    np.testing.assert_allclose(Payload().columns(s), [[expect]])
    p = sig([0.4], [0.1], [1.5], [0.0], mass=2.0, arm=1.277, revolute=False)
    np.testing.assert_allclose(Payload().columns(p), [[3.0]])  # M_a ddq, no arm, no gravity


def test_friction_terms():
    s = sig([0.0, 0.0, 0.0], [-0.2, 0.0, 0.7], [0.0, 0.0, 0.0], [1.0, 1.0, 1.0])
    np.testing.assert_array_equal(Coulomb().columns(s)[:, 0], [-1.0, 0.0, 1.0])
    np.testing.assert_array_equal(Viscous().columns(s)[:, 0], [-0.2, 0.0, 0.7])
    np.testing.assert_array_equal(Offset().columns(s)[:, 0], [1.0, 1.0, 1.0])


def test_quadrant_coulomb_eq30():
    q_s = 0.03
    # motor (tau dq > 0), generator (tau dq < 0), and dq = 0 (P+ = P- = 1/2)
    s = sig([0.0] * 3, [0.02, 0.05, 0.0], [0.0] * 3, [10.0, -4.0, 3.0])
    w = QuadrantCoulomb(q_s).columns(s)
    e0, e1 = math.exp(-0.02 / q_s), math.exp(-0.05 / q_s)
    np.testing.assert_allclose(w[0], [1.0, e0, 0.0, 0.0])  # P+ sign, P+ E sign, P- ...
    np.testing.assert_allclose(w[1], [0.0, 0.0, 1.0, e1])
    np.testing.assert_allclose(w[2], [0.0, 0.0, 0.0, 0.0])  # sign(0) = 0
    assert QuadrantCoulomb(q_s).names() == ("c_m", "d_m", "c_g", "d_g")


def test_load_dependent_eq42_columns_and_names():
    q_s = 0.04
    inner = RigidBody() + Payload()
    term = LoadDependent(inner, q_s)
    assert term.names() == (
        "a_m_J", "b_m_J", "a_m_MX", "b_m_MX", "a_m_MY", "b_m_MY", "a_m", "b_m",
        "a_g_J", "b_g_J", "a_g_MX", "b_g_MX", "a_g_MY", "b_g_MY", "a_g", "b_g",
    )  # fmt: skip
    q, dq, ddq, m, la = 0.2, -0.03, 1.2, 6.97, 1.277
    wi = np.array([ddq, G * math.cos(q), G * math.sin(q), m * la * (la * ddq + G * math.cos(q))])
    e = math.exp(-abs(dq) / q_s)
    gen = term.columns(sig([q], [dq], [ddq], [5.0], mass=m, arm=la))[0]  # tau dq < 0
    np.testing.assert_allclose(gen[:8], 0.0)
    np.testing.assert_allclose(gen[8::2], wi)
    np.testing.assert_allclose(gen[9::2], -e * wi)  # -P- Exp W (eq. 25, generator)
    mot = term.columns(sig([q], [dq], [ddq], [-5.0], mass=m, arm=la))[0]
    np.testing.assert_allclose(mot[0:8:2], wi)
    np.testing.assert_allclose(mot[1:8:2], e * wi)
    np.testing.assert_allclose(mot[8:], 0.0)


def test_models_parameter_names_match_architecture():
    assert usual_model().names() == ("J", "MX", "MY", "Ma_ratio", "F_C", "F_V", "tau_off")
    names = new_model(0.03).names()
    assert names[-6:] == ("c_m", "d_m", "c_g", "d_g", "F_V", "tau_off")
    assert len(names) == 22
    assert new_model(0.03, revolute=False, payload=False).names() == (
        "a_m_J", "b_m_J", "a_g_J", "b_g_J", "c_m", "d_m", "c_g", "d_g", "F_V", "tau_off",
    )  # fmt: skip


def test_bad_qs_is_a_clear_error():
    with pytest.raises(DataError, match="q_s"):
        QuadrantCoulomb(0.0)
    with pytest.raises(DataError, match="q_s"):
        LoadDependent(RigidBody(), -1.0)


finite = st.floats(allow_nan=False, allow_infinity=False)


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    q_s=st.floats(0.005, 0.2),
    mass=st.sampled_from([0.0, 3.4584, 6.97]),
)
def test_w_chi_reproduces_plant_torque_exactly(seed, q_s, mass):
    """Noise-free samples of the plant's inverse model (eq. 30/34): W_new chi_truth = tau
    wherever sign(tau) = sign(tau_out) (eq. 26), and W_usual chi = tau for a plant whose
    friction is the usual one."""
    from dataclasses import replace

    from sim_drivers.plant import inverse_torque, output_torque
    from sim_drivers.plant_config import default_plant

    p = default_plant()
    p = replace(p, joint=replace(p.joint, q_s=q_s))
    rng = np.random.default_rng(seed)
    n = 400
    q = rng.uniform(-2, 2, n)
    dq = rng.normal(0, 0.5, n) * rng.choice([0.02, 1.0], n)
    ddq = rng.normal(0, 3, n)
    la = 1.277
    tau = inverse_torque(p, q, dq, ddq, mass, la)
    tau_out = output_torque(p, q, ddq, mass, la)
    s = sig(q, dq, ddq, tau, mass=mass, arm=la)
    lib = new_model(q_s, revolute=True)
    truth = p.truth()
    chi = np.array([truth[n] for n in lib.names()])
    ok = np.sign(tau) == np.sign(tau_out)
    assert ok.mean() > 0.5
    np.testing.assert_allclose((lib.columns(s) @ chi)[ok], tau[ok], rtol=1e-10, atol=1e-9)

    # the usual model: a plant with a_m = a_g = 1, b = 0, c_m = c_g, d = 0
    f = replace(p.friction, a_m=1.0, a_g=1.0, b_m=0.0, b_g=0.0, c_g=p.friction.c_m,
                d_m=0.0, d_g=0.0)  # fmt: skip
    pu = replace(p, friction=f)
    tau_u = inverse_torque(pu, q, dq, ddq, mass, la)
    b = pu.body
    chi_u = np.array([b.J, b.MX, b.MY, 1.0, f.c_m, f.F_V, f.tau_off])
    su = sig(q, dq, ddq, tau_u, mass=mass, arm=la)
    np.testing.assert_allclose(usual_model().columns(su) @ chi_u, tau_u, rtol=1e-10, atol=1e-9)
