"""The joint plant: eq. 30 torque balance, undeclared effects, stiction, reversals, drive chain."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from sim_drivers.plant import (
    REGIME_REST,
    REGIME_SLIDING,
    JointPlant,
    effect_torques,
    inverse_torque,
    output_torque,
)
from sim_drivers.plant_config import G, default_plant, plant_from_dict

MA, LA = 3.4584, 1.277


def quiet(params):
    """The same plant without applied-torque noise."""
    return dataclasses.replace(
        params, drive=dataclasses.replace(params.drive, torque_noise_std_Nm=0.0))


def paper_eq30(p, q, dq, ddq, ma, la):
    """Eq. 30 with eq. 34 written out sample by sample from the paper, quadrant by quadrant."""
    f, b = p.friction, p.body
    out = []
    for qi, v, a in zip(q, dq, ddq, strict=True):
        tau_out = (b.J * a + b.MX * G * math.cos(qi) + b.MY * G * math.sin(qi)
                   + ma * la * (la * a + G * math.cos(qi)))
        e = math.exp(-abs(v) / p.joint.q_s)
        s = math.copysign(1.0, v)
        if tau_out * v > 0:  # motor quadrants 1 and 3
            tau = (f.a_m + f.b_m * e) * tau_out + (f.c_m + f.d_m * e) * s
        else:  # generator quadrants 2 and 4
            tau = (f.a_g - f.b_g * e) * tau_out + (f.c_g + f.d_g * e) * s
        out.append(tau + f.F_V * v + f.tau_off)
    return np.array(out)


def random_states(n=4000, seed=3):
    rng = np.random.default_rng(seed)
    q = rng.uniform(-2.5, 2.5, n)
    # low speed (inside the exponential's range) and high speed, both directions
    speed = np.where(rng.random(n) < 0.5, rng.uniform(1e-4, 0.1, n), rng.uniform(0.1, 1.5, n))
    dq = speed * rng.choice([-1.0, 1.0], n)
    ddq = rng.uniform(-8.0, 8.0, n)
    return q, dq, ddq


def test_inverse_torque_is_paper_eq30_on_random_states():
    p = default_plant()
    q, dq, ddq = random_states()
    tau = inverse_torque(p, q, dq, ddq, MA, LA)
    ref = paper_eq30(p, q, dq, ddq, MA, LA)
    np.testing.assert_allclose(tau, ref, rtol=0, atol=1e-9)
    tau_out = output_torque(p, q, ddq, MA, LA)
    power = np.sign(tau_out * dq)
    # every case was exercised: both quadrants, both directions, low and high speed
    for mask in (power > 0, power < 0, dq > 0, dq < 0, np.abs(dq) < 0.03, np.abs(dq) > 0.5):
        assert mask.sum() > 300


def test_forward_dynamics_inverts_eq30_on_random_states():
    """plant.acceleration(inverse_torque(state, ddq)) gives back ddq: the plant's torque
    balance is eq. 30 to numerical precision, in both quadrants and both directions."""
    p = quiet(default_plant())
    plant = JointPlant(p, 0.001)
    plant.set_payload(MA, LA)
    q, dq, ddq = random_states(seed=4)
    tau = inverse_torque(p, q, dq, ddq, MA, LA)
    back = np.empty_like(ddq)
    for i in range(q.size):
        back[i], regime = plant.acceleration(float(tau[i]), float(q[i]), float(dq[i]), 0.0)
        assert regime == REGIME_SLIDING
    np.testing.assert_allclose(back, ddq, rtol=0, atol=1e-9)


def test_prismatic_payload_adds_mass_and_no_gravity():
    raw = default_plant().as_dict()
    raw["joint"]["kind"] = "prismatic"
    raw["body"] = {"J": 12.0}
    p = plant_from_dict(raw)
    q = np.array([0.0, 1.0, 2.0])
    np.testing.assert_allclose(output_torque(p, q, 2.0, 3.0, 1.277), (12.0 + 3.0) * 2.0)
    assert "a_m_MX" not in p.truth() and p.truth()["a_m_J"] == pytest.approx(p.friction.a_m * 12)


EFFECTS = {
    "position_ripple": ({"amplitude_Nm": 5.0, "period_rad": 2 * math.pi / 16, "phase_rad": 0.7},
                        lambda q, dq, t, P, E, f: 5.0 * np.sin(16 * q + 0.7)),
    "spring": ({"stiffness_Nm_per_rad": 40.0, "rest_position_rad": 0.2},
               lambda q, dq, t, P, E, f: 40.0 * (q - 0.2)),
    "warm_up": ({"fraction": 0.5, "time_constant_s": 30.0},
                lambda q, dq, t, P, E, f: 0.5 * np.exp(-t / 30.0) * np.sign(dq)
                * np.where(P > 0, f.c_m + f.d_m * E, f.c_g + f.d_g * E)),
    "asymmetric_viscous": ({"F_V_pos": 50.0, "F_V_neg": 30.0},
                           lambda q, dq, t, P, E, f: np.where(dq > 0, 50.0 - f.F_V,
                                                              30.0 - f.F_V) * dq),
    "quadratic_viscous": ({"F_VV": 12.0}, lambda q, dq, t, P, E, f: 12.0 * dq * np.abs(dq)),
}


@pytest.mark.parametrize("name", sorted(EFFECTS))
def test_each_effect_changes_the_balance_exactly_by_its_formula(name):
    base = quiet(default_plant())
    values, formula = EFFECTS[name]
    p = base.with_effect(name, **values)
    assert p.effects.enabled() == (name,)
    q, dq, ddq = random_states(n=2000, seed=5)
    t = np.linspace(0.0, 90.0, q.size)
    tau_out = output_torque(p, q, ddq, MA, LA)
    power = np.sign(tau_out * dq)
    e = np.exp(-np.abs(dq) / p.joint.q_s)
    expected = formula(q, dq, t, power, e, p.friction)
    assert np.std(expected) > 0.5  # the effect is not trivially zero on these states
    diff = inverse_torque(p, q, dq, ddq, MA, LA, t) - inverse_torque(base, q, dq, ddq, MA, LA, t)
    np.testing.assert_allclose(diff, expected, rtol=0, atol=1e-9)
    np.testing.assert_allclose(effect_torques(p, q, dq, ddq, MA, LA, t)[name], expected,
                               rtol=0, atol=1e-9)
    # the forward dynamics carries the same effect: base torque + effect -> same ddq
    plant = JointPlant(p, 0.001)
    plant.set_payload(MA, LA)
    tau = inverse_torque(p, q, dq, ddq, MA, LA, t)
    for i in range(0, q.size, 7):
        a, _ = plant.acceleration(float(tau[i]), float(q[i]), float(dq[i]), float(t[i]))
        assert a == pytest.approx(ddq[i], abs=1e-9)


def test_effects_are_off_by_default():
    p = default_plant()
    assert p.effects.enabled() == ()
    assert effect_torques(p, [0.1], [0.2], [0.3]) == {}


def test_torque_lag_is_first_order():
    p = quiet(default_plant()).with_effect("torque_lag", time_constant_s=0.004)
    plant = JointPlant(p, 0.001)
    plant.reset(0.0)
    # hold the joint stuck (torque inside the static band) and watch the applied torque
    load = p.body.MX * G
    target = load + 5.0
    applied = []
    for _ in range(5):
        plant.step(target)
        applied.append(plant.tau_applied)
    expected = [target * (1.0 - math.exp(-0.001 * (k + 1) / 0.004)) for k in range(5)]
    np.testing.assert_allclose(applied, expected, rtol=1e-12)


def _band(p, q, ma=0.0, la=0.0):
    """Static band of eq. 21-23 at rest: (lower, upper) applied torque [N m]."""
    f = p.friction
    load = (p.body.MX + ma * la) * G * math.cos(q) + p.body.MY * G * math.sin(q)
    am1, ag1, dm1, dg1 = f.a_m + f.b_m, f.a_g - f.b_g, f.c_m + f.d_m, f.c_g + f.d_g
    if load > 0:
        lo, hi = ag1 * load - dg1, am1 * load + dm1
    else:
        lo, hi = am1 * load - dm1, ag1 * load + dg1
    return lo + f.tau_off, hi + f.tau_off


@pytest.mark.parametrize("q0, ma", [(0.3, 0.0), (0.3, 6.97), (2.6, 0.0), (-1.0, 3.4584)])
def test_stiction_holds_below_breakaway_and_releases_above(q0, ma):
    p = quiet(default_plant())
    lo, hi = _band(p, q0, ma, LA)
    assert hi - lo > 40.0  # the band is wide: it really holds the joint
    for tau, direction in ((hi - 0.01, 0), (lo + 0.01, 0), (hi + 0.5, 1), (lo - 0.5, -1)):
        plant = JointPlant(p, 0.001)
        plant.set_payload(ma, LA)
        plant.reset(q0)
        for _ in range(200):
            plant.step(tau)
        if direction == 0:
            assert plant.q == q0 and plant.dq == 0.0 and plant.regime == REGIME_REST
        else:
            assert np.sign(plant.dq) == direction and np.sign(plant.q - q0) == direction


def test_reversal_passes_through_rest_without_chattering():
    """A joint moving up with a torque that cannot hold it stops once, then reverses once;
    with a torque inside the static band it stops and stays stopped."""
    p = quiet(default_plant())
    q0 = 0.0
    lo, hi = _band(p, q0)
    for tau, reversals in ((0.5 * (lo + hi), 0), (lo - 30.0, 1)):
        plant = JointPlant(p, 0.001)
        plant.reset(q0)
        plant.dq = 0.5  # launched upwards
        signs = []
        for _ in range(1500):
            plant.step(tau)
            signs.append(np.sign(plant.dq))
        s = np.array(signs)
        nz = s[s != 0]
        changes = int(np.sum(nz[1:] != nz[:-1]))
        assert changes == reversals
        if reversals == 0:
            assert s[-1] == 0 and np.all(s[np.argmax(s == 0):] == 0)  # stuck for good
        else:
            assert s[-1] == -1


def test_integration_converges_with_substeps():
    p = quiet(default_plant())

    def run(sub):
        plant = JointPlant(p, 0.001, substeps=sub)
        plant.set_payload(MA, LA)
        plant.reset(0.2)
        for k in range(1500):  # through rest, breakaway and reversals
            plant.step(260.0 + 150.0 * math.sin(2 * math.pi * 1.0 * k * 0.001))
        return plant.q, plant.dq

    q10, dq10 = run(10)
    q40, dq40 = run(40)
    q400, dq400 = run(400)
    # 10 sub-steps are within 0.5 mrad of the converged answer after 1.5 s of stick-slip...
    assert abs(q10 - q400) < 5e-4 and abs(dq10 - dq400) < 2e-3
    # ...and the error shrinks with the sub-step (the scheme converges)
    assert abs(q40 - q400) < 0.5 * abs(q10 - q400)
    assert abs(q400 - 0.2) > 0.01  # it did move


def test_step_reports_a_consistent_balance():
    """After a step, (q, dq, ddq, t) and tau_applied satisfy the inverse model."""
    p = default_plant().with_effect("position_ripple", amplitude_Nm=5.0,
                                    period_rad=0.3927, phase_rad=0.1)
    plant = JointPlant(p, 0.001, seed=7)
    plant.set_payload(MA, LA)
    plant.reset(0.4)
    checked = 0
    for k in range(3000):
        plant.step(300.0 + 200.0 * math.sin(2 * math.pi * 0.5 * k * 0.001))
        if plant.regime == REGIME_SLIDING:
            tau = inverse_torque(p, plant.q, plant.dq, plant.ddq, MA, LA, plant.t)
            assert float(tau) == pytest.approx(plant.tau_applied, abs=1e-8)
            checked += 1
    assert checked > 2000


def test_noise_is_seeded_and_has_the_configured_std():
    p = default_plant()

    def noise(seed):
        plant = JointPlant(p, 0.001, seed=seed)
        plant.reset(0.0)
        out = []
        for _ in range(20000):
            plant.step(0.0)
            out.append(plant.tau_noise)
        return np.array(out)

    a, b, c = noise(1), noise(1), noise(2)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    assert np.std(a) == pytest.approx(p.drive.torque_noise_std_Nm, rel=0.03)
    assert abs(np.mean(a)) < 0.1


def test_drive_chain_conversions():
    p = default_plant()
    plant = JointPlant(p, 0.001)
    d = p.drive
    per_count = 2 * math.pi / (d.encoder_counts_per_rev * d.gear_ratio)
    assert plant.counts_to_rad(1) == pytest.approx(per_count)
    assert plant.rad_to_counts(1000.4 * per_count) == 1000
    assert plant.rad_to_counts(-1000.6 * per_count) == -1001
    plant.reset(0.123456)
    assert isinstance(plant.encoder_counts, int)
    assert abs(plant.counts_to_rad(plant.encoder_counts) - 0.123456) <= per_count / 2
    # x per-mille of rated torque -> joint side N * rated * x / 1000
    assert plant.torque_from_permille(100) == pytest.approx(d.gear_ratio * d.rated_torque_Nm * 0.1)
    assert plant.permille_from_torque(plant.torque_from_permille(-321)) == -321
    assert plant.permille_from_torque(1e9) == 32767 and plant.permille_from_torque(-1e9) == -32768
    assert d.g_f == pytest.approx(d.gear_ratio * d.amplifier_gain * d.torque_constant_Nm_per_A)
    assert plant.counts_per_rad == pytest.approx(1.0 / per_count)
    plant.step(plant.torque_from_permille(1000))  # rated torque -> rated current (K_t I = T_r)
    kt = d.torque_constant_Nm_per_A
    assert plant.motor_current_A == pytest.approx(
        d.rated_torque_Nm / kt + plant.tau_noise / (d.gear_ratio * kt))


def test_warm_up_clock_restarts_at_reset():
    p = quiet(default_plant()).with_effect("warm_up", fraction=1.0, time_constant_s=10.0)
    plant = JointPlant(p, 0.001)
    plant.reset(0.0, t0=100.0)
    a_new, _ = plant.acceleration(400.0, 0.0, 0.5, 100.0)
    plant.reset(0.0, t0=0.0)
    a_zero, _ = plant.acceleration(400.0, 0.0, 0.5, 0.0)
    assert a_new == a_zero
    a_late, _ = plant.acceleration(400.0, 0.0, 0.5, 100.0)
    assert a_late > a_zero  # less dry friction once warm


def test_ambiguous_quadrant_keeps_the_current_one():
    """With generator dry friction above the motor one, some torques are consistent with both
    quadrants (both satisfy eq. 30); the plant stays in the quadrant it was in."""
    raw = default_plant().as_dict()
    raw["friction"].update(c_m=10.0, d_m=0.0, c_g=40.0, d_g=0.0)
    p = quiet(plant_from_dict(raw))
    plant = JointPlant(p, 0.001)
    q, v = 0.0, 0.5
    grav = p.body.MX * G  # tau_out = grav + J ddq
    tau = p.friction.tau_off + p.friction.F_V * v + 25.0  # between s D_m = 10 and s D_g = 40
    results = {}
    for quad in (1, -1):
        plant._dyn.quad[0] = quad
        ddq, regime = plant.acceleration(tau, q, v, 0.0)
        assert regime == REGIME_SLIDING
        tau_out = grav + p.body.J * ddq
        assert np.sign(tau_out * v) == quad  # stayed in its quadrant
        assert float(inverse_torque(p, q, v, ddq)) == pytest.approx(tau, abs=1e-9)
        results[quad] = ddq
    assert results[1] != results[-1]
