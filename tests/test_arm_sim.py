"""The n-dof arm simulator: its record is its own truth (inverse model on the true states),
one joint is exactly the single-joint plant, stiction holds and releases at the band edges,
the closed loop tracks, payloads change the truth as eq. 34-35 say, runs are reproducible.

(Just past 600 lines: one simulator's acceptance -- forward/inverse consistency, stiction, every
undeclared effect -- kept in one file so the shared fixtures stay in one place.)
"""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from daq.protocol.control import ControllerGains
from sim_drivers import SimError
from sim_drivers.arm import (
    REGIME_REST,
    REGIME_SLIDING,
    ArmDrive,
    ArmEffects,
    ArmFriction,
    ArmGains,
    ArmParams,
    ArmParamsError,
    ArmPlant,
    Payload,
    friction_torque,
    inverse_arm_torque,
    model_reference,
    output_arm_torque,
    simulate_arm,
    simulate_arm_payloads,
    sine_reference,
)
from sim_drivers.offline import simulate
from sim_drivers.plant import REGIME_REST as PLANT_REST
from sim_drivers.plant import REGIME_SLIDING as PLANT_SLIDING
from sim_drivers.plant import REGIME_ZERO_LOAD as PLANT_ZERO_LOAD
from sim_drivers.plant import JointPlant
from sim_drivers.plant_config import default_plant
from sim_drivers.robots import example_robot_model, example_robot_urdf, ur10

G = 9.81


# --------------------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def ur3dof() -> ArmParams:
    return ArmParams.from_model(ur10(3))


@pytest.fixture(scope="module")
def ur6dof() -> ArmParams:
    return ArmParams.from_model(ur10(6))


PAYLOAD = Payload(3.0, [0.0, 0.05, 0.12], [0.01, 0.0, 0.0, 0.01, 0.0, 0.02])


@pytest.fixture(scope="module")
def run3(ur3dof):
    ref = model_reference(ur3dof.model, duration_s=6.0, seed=2)
    gains = ArmGains.for_params(ur3dof, payload=PAYLOAD)
    return ref, simulate_arm(ur3dof, ref, gains, payload=PAYLOAD, seed=5)


def pendulum(plant_params, ia: float = 10.0, mass: float = 30.0):
    """One-joint pinocchio model equivalent to the plant's body (J = Ia + ZZ, MX, MY): joint
    axis z, gravity along -y, so the holding torque is MX g cos q + MY g sin q (eq. 31)."""
    b = plant_params.body
    m = pin.Model()
    m.name = "pendulum"
    jid = m.addJoint(0, pin.JointModelRZ(), pin.SE3.Identity(), "j1")
    c = np.array([b.MX, -b.MY, 0.0]) / mass
    izz = b.J - ia - mass * (c @ c)
    assert izz > 0
    m.appendBodyToJoint(jid, pin.Inertia(mass, c, np.diag([1.0, 1.0, izz])), pin.SE3.Identity())
    f = plant_params.friction
    fr = ArmFriction(a_m=f.a_m, b_m=f.b_m, a_g=f.a_g, b_g=f.b_g, c_m=f.c_m, d_m=f.d_m,
                     c_g=f.c_g, d_g=f.d_g, F_V=f.F_V, tau_off=f.tau_off,
                     q_s=plant_params.joint.q_s)
    d = plant_params.drive
    drive = ArmDrive(d.gear_ratio, d.rated_torque_Nm, d.encoder_counts_per_rev,
                     d.torque_noise_std_Nm)
    return ArmParams(m, Ia=[ia], friction=fr, drive=drive,
                     effects=ArmEffects.from_plant_effects([plant_params.effects]),
                     gravity=[0.0, -G, 0.0])


def quiet_plant(effects=None):
    p = default_plant()
    p = dataclasses.replace(p, drive=dataclasses.replace(p.drive, torque_noise_std_Nm=0.0))
    if effects is not None:
        p = dataclasses.replace(p, effects=effects)
    return p


# --------------------------------------------------------------------------- truth
def test_regime_constants_are_the_plants():
    assert (REGIME_SLIDING, REGIME_REST) == (PLANT_SLIDING, PLANT_REST)
    from sim_drivers.arm import REGIME_ZERO_LOAD
    assert REGIME_ZERO_LOAD == PLANT_ZERO_LOAD


def test_record_is_the_arms_truth(ur3dof, run3):
    _, run = run3
    sl = run.sliding
    assert sl.mean() > 0.8 and run.stuck.sum() > 10
    tau = inverse_arm_torque(ur3dof, run.q_true, run.dq_true, run.ddq_true, PAYLOAD, run.t)
    scale = np.max(np.abs(run.tau_applied), axis=0)
    assert np.max(np.abs(tau - run.tau_applied)[sl]) < 1e-9 * max(1.0, scale.max())
    # applied = reference + ripple noise (no torque lag), the reference is what 0x6071 carries
    np.testing.assert_allclose(run.tau_applied - run.tau_noise, run.tau_ref, rtol=0, atol=1e-9)
    assert np.array_equal(run.tau_ref, run.x * ur3dof.drive.torque_per_permille)
    np.testing.assert_allclose(np.std(run.tau_noise, axis=0),
                               ur3dof.drive.torque_noise_std_Nm, rtol=0.1)
    # both power quadrants on every joint
    tau_out = output_arm_torque(ur3dof, run.q_true, run.dq_true, run.ddq_true, PAYLOAD)
    p = np.sign(tau_out * run.dq_true)
    for j in range(ur3dof.k):
        assert np.sum(p[sl[:, j], j] > 0) > 200 and np.sum(p[sl[:, j], j] < 0) > 200
    # the measured position is the encoder's quantisation of the true one
    cpr = ur3dof.drive.counts_per_rad
    assert np.max(np.abs(run.q - run.q_true)) <= 0.5 / cpr.min() + 1e-15


@settings(max_examples=8, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**31 - 1))
def test_forward_then_inverse_on_random_states(ur6dof, seed):
    """ABA of the friction's output torque, then RNEA + eq. 30: the applied torque, to 1e-9,
    in both quadrants on every joint (random states, torques around the load)."""
    rng = np.random.default_rng(seed)
    k = ur6dof.k
    plant = ArmPlant(ur6dof, 0.001)
    load_scale = ur6dof.drive.torque_noise_std_Nm * 100  # = L_j of from_model
    n = 40
    q = rng.uniform(-2, 2, (n, k))
    dq = rng.uniform(-1, 1, (n, k)) * rng.choice([1e-3, 1e-1, 1.0], (n, 1))
    g = np.array([pin.computeGeneralizedGravity(plant.model, plant.data, qi) for qi in q])
    tau = g + rng.normal(0, 0.5, (n, k)) * load_scale
    ddq = np.empty((n, k))
    reg = np.empty((n, k), dtype=int)
    for i in range(n):
        ddq[i], reg[i] = plant.acceleration(tau[i], q[i], dq[i])
    sl = reg == REGIME_SLIDING
    assert sl.mean() > 0.9
    back = inverse_arm_torque(ur6dof, q, dq, ddq)
    err = np.abs(back - tau)[sl]
    assert err.max() < 1e-9 * max(1.0, np.abs(tau).max())
    tau_out = output_arm_torque(ur6dof, q, dq, ddq)
    pw = np.where(sl, np.sign(tau_out * dq), 0.0)
    assert np.all((pw > 0).any(axis=0)) and np.all((pw < 0).any(axis=0))  # every joint


def test_prismatic_and_revolute_chain():
    """A vertical prismatic axis carrying a revolute one: gravity acts on the slide (its holding
    force is the carried weight), and the record is still the inverse model's truth."""
    m = pin.Model()
    m.name = "lift-and-turn"
    j1 = m.addJoint(0, pin.JointModelPZ(), pin.SE3.Identity(), "lift")
    m.appendBodyToJoint(j1, pin.Inertia(20.0, np.zeros(3), np.eye(3) * 0.5), pin.SE3.Identity())
    j2 = m.addJoint(j1, pin.JointModelRX(), pin.SE3(np.eye(3), np.array([0, 0, 0.3])), "turn")
    m.appendBodyToJoint(j2, pin.Inertia(5.0, np.array([0, 0.2, 0]), np.eye(3) * 0.05),
                        pin.SE3.Identity())
    m.lowerPositionLimit = np.array([-0.3, -1.5])
    m.upperPositionLimit = np.array([0.3, 1.5])
    m.velocityLimit = np.array([0.5, 2.0])
    p = ArmParams.from_model(m)
    plant = ArmPlant(p, 0.001)
    hold = pin.computeGeneralizedGravity(plant.model, plant.data, np.zeros(2))
    assert hold[0] == pytest.approx(25.0 * G)  # [N]: the slide carries both bodies
    ref = model_reference(m, duration_s=3.0, seed=1)
    run = simulate_arm(p, ref, ArmGains.for_params(p), seed=2)
    assert np.sqrt(np.mean((run.q_true - ref.q) ** 2)) < 3e-3
    tau = inverse_arm_torque(p, run.q_true, run.dq_true, run.ddq_true, None, run.t)
    assert run.sliding.mean() > 0.6  # (it starts and ends at rest)
    assert np.max(np.abs(tau - run.tau_applied)[run.sliding]) < 1e-9 * 1e3


# --------------------------------------------------------------------------- one joint
def _compare_with_joint_plant(plant_params, n=8000):
    arm_params = pendulum(plant_params)
    jp = JointPlant(plant_params, 0.001, substeps=10)
    arm = ArmPlant(arm_params, 0.001, substeps=10)
    jp.reset(-1.0)
    arm.reset([-1.0])
    t = np.arange(n) * 0.001
    tau = 100 + 70 * np.sin(2 * np.pi * 0.4 * t) + 20 * np.sin(2 * np.pi * 2.3 * t)
    out = np.empty((n, 2, 3))
    regimes = np.empty((n, 2), dtype=int)
    for i in range(n):
        jp.step(tau[i])
        arm.step([tau[i]], [0.0])
        out[i, 0] = jp.q, jp.dq, jp.ddq_start
        out[i, 1] = arm.q[0], arm.dq[0], arm.ddq_start[0]
        regimes[i] = jp.regime_start, arm.regime_start[0]
    return out, regimes


def test_one_joint_is_the_joint_plant():
    out, regimes = _compare_with_joint_plant(quiet_plant())
    assert np.sum(regimes[:, 0] == PLANT_REST) > 300  # it sticks at the reversals
    assert np.ptp(out[:, 0, 0]) > 0.3
    assert np.array_equal(regimes[:, 0], regimes[:, 1])
    np.testing.assert_allclose(out[:, 1], out[:, 0], rtol=0, atol=1e-10)


def test_one_joint_with_every_effect_is_the_joint_plant():
    from sim_drivers.plant_config import (
        AsymmetricViscous,
        Effects,
        PositionRipple,
        QuadraticViscous,
        Spring,
        TorqueLag,
        WarmUp,
    )
    eff = Effects(
        position_ripple=PositionRipple(enabled=True, amplitude_Nm=6.0, period_rad=0.3,
                                       phase_rad=0.4),
        spring=Spring(enabled=True, stiffness_Nm_per_rad=20.0, rest_position_rad=-0.8),
        warm_up=WarmUp(enabled=True, fraction=0.3, time_constant_s=3.0),
        asymmetric_viscous=AsymmetricViscous(enabled=True, F_V_pos=46.0, F_V_neg=33.0),
        quadratic_viscous=QuadraticViscous(enabled=True, F_VV=8.0),
        torque_lag=TorqueLag(enabled=True, time_constant_s=0.003))
    out, regimes = _compare_with_joint_plant(quiet_plant(eff))
    assert np.sum(regimes[:, 0] == PLANT_REST) > 100
    assert np.array_equal(regimes[:, 0], regimes[:, 1])
    np.testing.assert_allclose(out[:, 1], out[:, 0], rtol=0, atol=1e-10)


def test_one_joint_closed_loop_is_the_offline_simulator():
    """simulate_arm on the equivalent pendulum, with the single-joint controller's
    feed-forward as an array, is sim_drivers.offline.simulate (noise off) sample for sample."""

    plant = quiet_plant()
    arm = pendulum(plant)
    t = np.arange(0.0, 4.0, 0.001)
    w = 2 * np.pi * 0.3
    q = -1.0 + 0.5 * np.sin(w * t)
    dq = 0.5 * w * np.cos(w * t)
    ddq = -0.5 * w * w * np.sin(w * t)
    g1 = ControllerGains(kp=20000.0, kd=1000.0, J_ff=31.0, MX_ff=21.1, MY_ff=-0.8, Fc_ff=25.0,
                         Fv_ff=40.0)
    single = simulate(plant, SimpleNamespace(t=t, q=q, dq=dq, ddq=ddq), g1, seed=0)
    ff = (31.0 * ddq + G * (21.1 * np.cos(q) - 0.8 * np.sin(q)))[:, None]
    ga = ArmGains(kp=[20000.0], kd=[1000.0], Fc_ff=[25.0], Fv_ff=[40.0])
    multi = simulate_arm(arm, SimpleNamespace(t=t, q=q[:, None], dq=dq[:, None],
                                              ddq=ddq[:, None]), ga, feedforward=ff)
    assert np.sum(single.stuck) > 5  # it sticks at the reversals
    assert np.array_equal(multi.x[:, 0], single.x) and np.array_equal(multi.counts[:, 0],
                                                                      single.counts)
    np.testing.assert_allclose(multi.q_true[:, 0], single.q_true, rtol=0, atol=1e-10)
    np.testing.assert_array_equal(multi.regime[:, 0], single.regime)


def test_run_columns_follow_the_multi_axis_layout(run3, tmp_path):
    _, run = run3
    cols = run.columns()
    assert list(cols) == ["t", "q1", "q2", "q3", "tau1", "tau2", "tau3", "q_ref1", "q_ref2",
                          "q_ref3"]
    run.to_csv(tmp_path / "run.csv")
    back = np.genfromtxt(tmp_path / "run.csv", delimiter=",", names=True)
    np.testing.assert_array_equal(back["tau2"], run.tau_ref[:, 1])
    np.testing.assert_array_equal(back["q3"], run.q[:, 2])


def test_effects_enter_the_inverse_model(ur3dof):
    eff = ArmEffects.make(3, position_ripple={0: {"amplitude_Nm": 2.0, "period_rad": 0.3}},
                          spring={1: {"stiffness_Nm_per_rad": 40.0, "rest_position_rad": -1.0}},
                          quadratic_viscous={2: {"F_VV": 3.0}},
                          asymmetric_viscous={1: {"F_V_pos": 15.0, "F_V_neg": 9.0}},
                          torque_lag={0: {"time_constant_s": 0.002}})
    params = dataclasses.replace(ur3dof, effects=eff)
    ref = model_reference(params.model, duration_s=3.0, seed=4)
    run = simulate_arm(params, ref, ArmGains.for_params(params), seed=1)
    sl = run.sliding
    tau = inverse_arm_torque(params, run.q_true, run.dq_true, run.ddq_true, None, run.t)
    assert np.max(np.abs(tau - run.tau_applied)[sl]) < 1e-8
    bare = inverse_arm_torque(params, run.q_true, run.dq_true, run.ddq_true, None, run.t,
                              effects=False)
    assert np.all(np.max(np.abs(bare - run.tau_applied)[sl].reshape(-1)) > 0.5)
    # the lagged joint's applied torque is not the reference plus noise; the others are
    d = run.tau_applied - run.tau_noise - run.tau_ref
    assert np.max(np.abs(d[:, 0])) > 1.0 and np.max(np.abs(d[:, 1:])) < 1e-9


def test_dry_coupling_follows_the_other_joints_position(ur3dof):
    """The cross-joint effect: joint 0's dry friction scaled by a sinusoid of q of joint 1 and
    joint 2's by a line in q of joint 0; the forward plant (sliding, stiction band) and the
    inverse model agree, and the difference with the effect off is exactly the scaled dry
    friction of the coupled joints (the others are untouched)."""
    eff = ArmEffects.make(3, dry_coupling={
        (0, 1): {"amplitude": 0.4, "period_rad": 1.7, "phase_rad": 0.3},
        (2, 0): {"slope_per_rad": 0.5, "rest_position_rad": 0.1}})
    assert eff.coupled().tolist() == [True, False, True]
    params = dataclasses.replace(ur3dof, effects=eff)
    ref = model_reference(params.model, duration_s=3.0, seed=6)
    run = simulate_arm(params, ref, ArmGains.for_params(params), seed=2)
    sl = run.sliding
    tau = inverse_arm_torque(params, run.q_true, run.dq_true, run.ddq_true, None, run.t)
    assert np.max(np.abs(tau - run.tau_applied)[sl]) < 1e-8
    off = dataclasses.replace(params, effects=ArmEffects.none(3))
    bare = inverse_arm_torque(off, run.q_true, run.dq_true, run.ddq_true, None, run.t)
    f, q, dq = params.friction, run.q_true, run.dq_true
    ex = np.exp(-np.abs(dq) / f.q_s)
    from_out = output_arm_torque(params, q, dq, run.ddq_true)
    p = np.sign(from_out * dq)
    dry = np.where(p > 0, f.c_m + f.d_m * ex, f.c_g + f.d_g * ex) * np.sign(dq)
    scale = np.ones_like(q)
    scale[:, 0] = 1 + 0.4 * np.sin(2 * np.pi * q[:, 1] / 1.7 + 0.3)
    scale[:, 2] = np.maximum(1 + 0.5 * (q[:, 0] - 0.1), 0.0)
    np.testing.assert_allclose((tau - bare)[sl], ((scale - 1) * dry)[sl], atol=1e-9)
    assert np.ptp((tau - bare)[:, 0]) > 0.3 * np.max(np.abs(dry[:, 0]))
    with pytest.raises(SimError, match="dry_coupling: joint pair"):
        ArmEffects.make(3, dry_coupling={(1, 1): {"amplitude": 0.1}})
    with pytest.raises(SimError, match="dry_coupling.gain: unknown key"):
        ArmEffects.make(3, dry_coupling={(0, 1): {"gain": 0.1}})


# --------------------------------------------------------------------------- stiction
def _band(params, j, load):
    f = params.friction
    am1, ag1 = f.a_m[j] + f.b_m[j], f.a_g[j] - f.b_g[j]
    dm1, dg1 = f.c_m[j] + f.d_m[j], f.c_g[j] + f.d_g[j]
    if abs(load) < 1e-9:  # no load (vertical axis): the wider of the two dry bands
        return -max(dm1, dg1), max(dm1, dg1)
    if load > 0:
        return ag1 * load - dg1, am1 * load + dm1
    return am1 * load - dm1, ag1 * load + dg1


@pytest.mark.parametrize("j", [0, 1, 2])
def test_stiction_holds_inside_the_band_and_releases_outside(ur3dof, j):
    plant = ArmPlant(ur3dof, 0.001)
    q = np.array([0.3, -1.2, 1.0])
    hold = pin.computeGeneralizedGravity(plant.model, plant.data, q)
    off = ur3dof.friction.tau_off
    base = hold + off  # every joint inside its band (1 is between A_g1 and A_m1)
    lo, hi = _band(ur3dof, j, hold[j])
    eps = 1e-6 * (1 + abs(hi))
    for edge, direction in ((hi, 1.0), (lo, -1.0)):
        tau = base.copy()
        tau[j] = off[j] + edge - direction * eps
        ddq, reg = plant.acceleration(tau, q, np.zeros(3))
        assert np.all(ddq == 0) and np.all(reg == REGIME_REST)
        tau[j] = off[j] + edge + direction * eps
        ddq, reg = plant.acceleration(tau, q, np.zeros(3))
        assert ddq[j] * direction > 0 and np.all(np.delete(ddq, j) == 0)
        assert np.all(reg == REGIME_REST)


@settings(max_examples=10, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**31 - 1), j=st.integers(0, 5))
def test_stiction_band_edges_on_random_configurations(ur6dof, seed, j):
    """Six joints at rest at a random configuration, each held by its gravity torque: joint j
    stays stuck just inside either edge of its band and breaks away just outside it."""
    rng = np.random.default_rng(seed)
    plant = ArmPlant(ur6dof, 0.001)
    q = rng.uniform(-2.5, 2.5, 6)
    hold = pin.computeGeneralizedGravity(plant.model, plant.data, q)
    off = ur6dof.friction.tau_off
    lo, hi = _band(ur6dof, j, hold[j])
    for edge, direction in ((hi, 1.0), (lo, -1.0)):
        eps = 1e-7 * (1 + abs(edge))
        tau = hold + off
        tau[j] = off[j] + edge - direction * eps
        ddq, _ = plant.acceleration(tau, q, np.zeros(6))
        assert np.all(ddq == 0)
        tau[j] = off[j] + edge + direction * eps
        ddq, _ = plant.acceleration(tau, q, np.zeros(6))
        assert ddq[j] * direction > 0 and np.all(np.delete(ddq, j) == 0)


def test_stuck_joint_holds_the_load_of_the_moving_ones(ur3dof):
    """Joint 2 at rest while joints 1 and 3 slide: the constrained dynamics give it ddq = 0 and
    a holding torque (RNEA of the result) inside its band; the sliding joints obey eq. 30."""
    plant = ArmPlant(ur3dof, 0.001)
    q = np.array([0.2, -1.0, 1.3])
    dq = np.array([0.5, 0.0, -0.4])
    tau = pin.computeGeneralizedGravity(plant.model, plant.data, q) + np.array([20.0, 0, -5])
    ddq, reg = plant.acceleration(tau, q, dq)
    assert ddq[1] == 0 and reg[1] == REGIME_REST and np.all(reg[[0, 2]] == REGIME_SLIDING)
    tau_out = pin.rnea(plant.model, plant.data, q, dq, ddq)
    lo, hi = _band(ur3dof, 1, tau_out[1])
    assert lo <= tau[1] - ur3dof.friction.tau_off[1] <= hi
    back = friction_torque(ur3dof, q, dq, tau_out)
    np.testing.assert_allclose(back[[0, 2]], tau[[0, 2]], rtol=0, atol=1e-9)


def test_slow_joint_stops_exactly_and_sticks(ur3dof):
    """Event detection: a joint sliding slowly under a holding torque reaches dq = 0 inside the
    first sub-step, stops there exactly (no overshoot to a negative velocity) and sticks."""
    plant = ArmPlant(ur3dof, 0.001, substeps=2)
    q = np.array([0.3, -1.2, 1.0])
    plant.reset(q)
    v0 = 1e-4
    plant.dq = np.array([0.0, v0, 0.0])
    tau = pin.computeGeneralizedGravity(plant.model, plant.data, q) + ur3dof.friction.tau_off
    a0, reg0 = plant.acceleration(tau, q, plant.dq)
    assert a0[1] < 0 and -v0 / a0[1] < 0.0005 and reg0[1] == REGIME_SLIDING
    plant.step(tau, np.zeros(3))
    assert np.all(plant.dq == 0) and np.all(plant.regime == REGIME_REST)
    assert plant.q[1] == pytest.approx(q[1] + 0.5 * v0 * (-v0 / a0[1]), rel=1e-12, abs=1e-15)


# --------------------------------------------------------------------------- closed loop
def test_closed_loop_tracks_six_joints(ur6dof):
    ref = model_reference(ur6dof.model, duration_s=4.0, seed=3)
    run = simulate_arm(ur6dof, ref, ArmGains.for_params(ur6dof), seed=0)
    err = run.q_true - ref.q
    assert run.q.shape == (len(ref.t), 6) and run.k == 6
    assert np.all(np.sqrt(np.mean(err**2, axis=0)) < 3e-3)
    assert np.all(np.max(np.abs(err), axis=0) < 1e-2)
    # without feed-forward the same gains track worse
    run0 = simulate_arm(ur6dof, ref, ArmGains.for_params(ur6dof), seed=0, feedforward=None)
    err0 = run0.q_true - ref.q
    assert np.sqrt(np.mean(err0[:, 1] ** 2)) > 2 * np.sqrt(np.mean(err[:, 1] ** 2))


def test_runs_are_reproducible_by_seed(ur3dof):
    ref = model_reference(ur3dof.model, duration_s=1.5, ramp_s=0.5, seed=1)
    gains = ArmGains.for_params(ur3dof)
    a = simulate_arm(ur3dof, ref, gains, seed=7)
    b = simulate_arm(ur3dof, ref, gains, seed=7)
    c = simulate_arm(ur3dof, ref, gains, seed=8)
    for name in ("q", "tau_ref", "tau_applied", "q_true", "ddq_true", "regime"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert not np.array_equal(a.tau_noise, c.tau_noise)
    assert not np.array_equal(a.q_true, c.q_true)


# --------------------------------------------------------------------------- payload
def test_payload_changes_only_the_last_link_as_eq_34():
    p = pendulum(quiet_plant())
    ma, la = 3.4584, 1.277
    base = p.truth()
    withp = p.truth(Payload(ma, [la, 0.0, 0.0]))
    assert withp["M1"] == pytest.approx(base["M1"] + ma)
    assert withp["MX1"] == pytest.approx(base["MX1"] + ma * la)  # M_a L_a g cos q
    assert withp["ZZ1"] == pytest.approx(base["ZZ1"] + ma * la * la)  # M_a L_a^2 ddq
    assert withp["MY1"] == pytest.approx(base["MY1"])
    q, dq, ddq = np.array([[0.4]]), np.array([[0.3]]), np.array([[2.0]])
    tau_out = output_arm_torque(p, q, dq, ddq, Payload(ma, [la, 0, 0]))
    j_total = base["Ia1"] + base["ZZ1"]
    # gravity along -y: the plant's MY is -MY1 of the pinocchio frame (see pendulum())
    expected = (j_total * 2.0 + base["MX1"] * G * np.cos(0.4) - base["MY1"] * G * np.sin(0.4)
                + ma * la * (la * 2.0 + G * np.cos(0.4)))
    assert tau_out[0, 0] == pytest.approx(expected, rel=1e-12)


def test_payload_runs_need_more_torque(ur3dof):
    ref = model_reference(ur3dof.model, duration_s=2.5, ramp_s=0.5, seed=6)
    gains = ArmGains.for_params(ur3dof)
    runs = simulate_arm_payloads(ur3dof, ref, gains, [None, Payload(8.0, [0.0, 0.0, 0.1])],
                                 seed=3)
    assert [r.payload_mass_kg for r in runs] == [0.0, 8.0]
    assert not np.array_equal(runs[0].tau_noise, runs[1].tau_noise)
    # the shoulder lift holds the extra weight: its mean torque grows in magnitude
    assert np.abs(runs[1].tau_ref[:, 1]).mean() > np.abs(runs[0].tau_ref[:, 1]).mean() + 20
    for r in runs:
        tau = inverse_arm_torque(ur3dof, r.q_true, r.dq_true, r.ddq_true, r.payload, r.t)
        assert np.max(np.abs(tau - r.tau_applied)[r.sliding]) < 1e-9 * 1e3


def test_payload_on_a_named_frame(ur6dof):
    pay = Payload(2.0, [0.0, 0.0, 0.05], [0.002, 0, 0, 0.002, 0, 0.001], frame="tool0")
    base, withp = ur6dof.truth(), ur6dof.truth(pay)
    changed = {n for n in base if base[n] != withp[n]}
    assert changed and all(n.endswith("6") for n in changed)
    m = ur6dof.model
    fr = m.frames[m.getFrameId("tool0")]
    assert fr.parentJoint == 6
    expected = (m.inertias[6] + fr.placement.act(
        pin.Inertia.FromDynamicParameters(pay.dynamic_parameters()))).toDynamicParameters()
    got = [withp[n + "6"] for n in ("M", "MX", "MY", "MZ", "XX", "XY", "YY", "XZ", "YZ", "ZZ")]
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-12)
    with pytest.raises(ArmParamsError, match="no_such_frame"):
        ur6dof.truth(Payload(1.0, frame="no_such_frame"))


def test_truth_names_follow_the_contract(ur3dof):
    tr = ur3dof.truth()
    for j in (1, 2, 3):
        for n in ("XX", "XY", "XZ", "YY", "YZ", "ZZ", "MX", "MY", "MZ", "M", "Ia", "a_m",
                  "b_m", "a_g", "b_g", "c_m", "d_m", "c_g", "d_g", "FV", "OFF", "qs"):
            assert f"{n}{j}" in tr
    assert len(tr) == 3 * 22
    relabelled = dataclasses.replace(ur3dof, joint_numbers=(2, 3, 4))
    assert relabelled.truth()["ZZ2"] == tr["ZZ1"]
    # the model's standard parameters about the joint origin (Khalil): M, MX = m c_x, ...
    inert = ur3dof.model.inertias[2]
    assert tr["M2"] == pytest.approx(inert.mass)
    assert tr["MX2"] == pytest.approx(inert.mass * inert.lever[0])
    assert tr["ZZ2"] == pytest.approx(inert.inertia[2, 2] + inert.mass
                                      * (inert.lever[0] ** 2 + inert.lever[1] ** 2))


def test_params_from_a_robot_description():
    """ROBOT_FORMAT's Robot (a stand-in built on the real UR10 until trajectories.robot lands):
    joints labelled by their index in the full chain, gear ratios and rotor inertias used."""
    full = ur10(6)
    names = tuple(full.names[1:])
    locked = {"shoulder_pan_joint": 0.0, "wrist_1_joint": -1.5, "wrist_2_joint": 0.0,
              "wrist_3_joint": 0.0}
    moving = ("shoulder_lift_joint", "elbow_joint")
    drives = {"shoulder_lift_joint": SimpleNamespace(gear_ratio=120.0, rotor_inertia=2e-4),
              "elbow_joint": None}
    robot = SimpleNamespace(name="ur10-2", joint_names=names, moving=moving, drives=drives,
                            reduced=lambda: example_robot_model("ur10", locked=locked))
    p = ArmParams.from_robot(robot)
    assert p.joint_numbers == (2, 3) and p.name == "ur10-2"
    tr = p.truth()
    assert tr["Ia2"] == pytest.approx(120.0**2 * 2e-4) and "ZZ3" in tr and "ZZ1" not in tr
    assert p.drive.gear_ratio.tolist() == [120.0, 100.0]


def test_payload_inertia_about_the_origin_is_huygens():
    p = Payload(2.0, [0.1, 0.0, 0.0], [0.01, 0, 0, 0.02, 0, 0.03])  # about the CoM (eq. 32)
    np.testing.assert_allclose(p.inertia_origin, [0.01, 0, 0, 0.02 + 0.02, 0, 0.03 + 0.02])
    point = Payload(2.0, [0.1, 0.2, 0.0])  # default inertia: a point mass
    np.testing.assert_allclose(point.inertia_origin, [0.08, -0.04, 0, 0.02, 0, 0.1])
    # a campaign payload (mass_kg, com, inertia about the CoM) is accepted as is
    campaign_like = SimpleNamespace(mass_kg=2.0, com=(0.1, 0.0, 0.0),
                                    inertia=(0.01, 0, 0, 0.02, 0, 0.03))
    np.testing.assert_array_equal(Payload.coerce(campaign_like).dynamic_parameters(),
                                  p.dynamic_parameters())
    with pytest.raises(ArmParamsError, match="expected a Payload"):
        Payload.coerce(3.0)


# --------------------------------------------------------------------------- inputs
def test_drive_quantisation_is_0x6071_per_mille():
    d = ArmDrive(gear_ratio=[100.0, 50.0], rated_torque_Nm=[5.0, 2.0],
                 encoder_counts_per_rev=[4096, 1000], torque_noise_std_Nm=0.0)
    np.testing.assert_allclose(d.torque_per_permille, [0.5, 0.1])
    np.testing.assert_allclose(d.counts_per_rad, [100 * 4096 / (2 * np.pi), 50e3 / (2 * np.pi)])
    x = d.quantise(np.array([[1.26, -0.26], [1e9, -1e9]]))
    assert x.dtype == np.int16 and x.tolist() == [[3, -3], [32767, -32768]]


def test_bad_parameters_are_named(ur3dof):
    f = ur3dof.friction
    with pytest.raises(ArmParamsError, match="a_g - b_g > 0.*joint index 2"):
        dataclasses.replace(f, b_g=np.array([0.2, 2.0, 0.2]))
    with pytest.raises(ArmParamsError, match="Ia: expected 3 values"):
        dataclasses.replace(ur3dof, Ia=[1.0, 2.0])
    with pytest.raises(ArmParamsError, match="friction: unknown key"):
        ArmParams.from_model(ur10(3), friction={"a_m": 1.0, "bogus": 2})
    partial = ArmParams.from_model(ur10(3), friction={"q_s": 0.05, "c_m": [1.0, 2.0, 3.0]})
    assert partial.truth()["qs2"] == 0.05 and partial.truth()["c_m3"] == 3.0
    assert partial.truth()["a_m1"] == ur3dof.truth()["a_m1"]
    with pytest.raises(ArmParamsError, match="Payload.mass"):
        Payload(-1.0)
    with pytest.raises(SimError, match="unknown effect 'wobble'"):
        ArmEffects.make(3, wobble={0: {}})


def test_bad_reference_is_named(ur3dof):
    ref = model_reference(ur3dof.model, duration_s=2.5)
    gains = ArmGains.for_params(ur3dof)
    bad = dataclasses.replace(ref, q=ref.q[:, :2])
    with pytest.raises(SimError, match=r"reference.q: expected .* shape \(\d+, 3\)"):
        simulate_arm(ur3dof, bad, gains)
    with pytest.raises(SimError, match="gains: expected 3 joints"):
        simulate_arm(ur3dof, ref, ArmGains(kp=[1.0], kd=[1.0]))
    with pytest.raises(SimError, match="feedforward"):
        simulate_arm(ur3dof, ref, gains, feedforward="magic")
    with pytest.raises(SimError, match="reference.t: expected uniform sampling"):
        simulate_arm(ur3dof, dataclasses.replace(ref, t=ref.t ** 1.01), gains)
    # without t the cycle is 1 ms
    short = SimpleNamespace(q=ref.q[:50], dq=ref.dq[:50], ddq=ref.ddq[:50])
    assert simulate_arm(ur3dof, short, gains).cycle_s == 0.001


def test_reference_is_smooth_within_limits_and_at_rest_at_the_ends(ur6dof):
    m = ur6dof.model
    ref = model_reference(m, duration_s=5.0, seed=9)
    assert np.all(ref.q >= m.lowerPositionLimit) and np.all(ref.q <= m.upperPositionLimit)
    assert np.all(np.abs(ref.dq) <= 0.5 * np.asarray(m.velocityLimit) + 1e-9)
    assert np.all(np.abs(ref.ddq) <= 4.0 + 1e-9)
    for a in (ref.dq, ref.ddq):
        assert np.allclose(a[[0, -1]], 0, atol=1e-12)
    np.testing.assert_allclose(ref.q[-1], ref.q[0], atol=1e-12)
    dt = ref.t[1] - ref.t[0]
    np.testing.assert_allclose(np.gradient(ref.q, dt, axis=0)[1:-1], ref.dq[1:-1], atol=1e-4)
    np.testing.assert_allclose(np.gradient(ref.dq, dt, axis=0)[1:-1], ref.ddq[1:-1], atol=5e-3)
    with pytest.raises(SimError):
        sine_reference([0.0], [0.1], duration_s=1.0, ramp_s=1.0)


def test_packaged_robot_locator():
    p = example_robot_urdf("ur10")
    assert p.is_file() and p.name == "ur10_robot.urdf"
    assert ur10(3).nv == 3 and ur10(6).nv == 6 and ur10(1).nv == 1
    with pytest.raises(SimError, match="example robot 'r2d2'"):
        example_robot_urdf("r2d2")
