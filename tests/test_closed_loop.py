"""The one offline closed loop (``sim_drivers.closed_loop``) on the real plants: the record
is what the loop measured, sent and stepped, for one joint (scalars) and for n (arrays), and
the shared reference reader and cycle period accept and refuse the same things for both."""

from __future__ import annotations

from functools import partial
from types import SimpleNamespace

import numpy as np
import pytest

from daq.protocol.control import ControllerGains, PDLaw, PositionController
from sim_drivers import SimError
from sim_drivers.arm import ArmGains, ArmParams, ArmPlant, ArmRun, simulate_arm, sine_reference
from sim_drivers.closed_loop import LoopRecord, cycle_period, reference_arrays, run_closed_loop
from sim_drivers.dynamics import REGIME_REST, REGIME_SLIDING
from sim_drivers.offline import SimRun, simulate
from sim_drivers.plant import JointPlant
from sim_drivers.plant_config import default_plant
from sim_drivers.robots import ur10


def test_cycle_period_from_argument_samples_or_default():
    t = np.arange(50) * 0.002
    ref = SimpleNamespace(t=t)
    assert cycle_period(ref) == pytest.approx(0.002, rel=1e-12)
    assert cycle_period(ref, 0.0005) == 0.0005
    assert cycle_period(SimpleNamespace(), default=0.001) == 0.001
    with pytest.raises(SimError, match=r"reference\.t: expected the sample times"):
        cycle_period(SimpleNamespace())
    with pytest.raises(SimError, match=r"reference\.t: expected at least 2 samples"):
        cycle_period(SimpleNamespace(t=t[:1]))
    with pytest.raises(SimError, match=r"reference\.t: expected uniform sampling"):
        cycle_period(SimpleNamespace(t=t ** 1.01))
    with pytest.raises(SimError, match=r"cycle_s: expected a number > 0"):
        cycle_period(ref, -0.001)


def test_reference_reader_shapes_for_one_joint_and_for_n():
    q = np.linspace(0.0, 1.0, 20)
    one = SimpleNamespace(q=q, dq=q, ddq=q)
    assert [a.shape for a in reference_arrays(one)] == [(20,)] * 3
    assert [a.shape for a in reference_arrays(one, 1)] == [(20, 1)] * 3
    three = SimpleNamespace(q=np.tile(q[:, None], 3), dq=np.zeros((20, 3)), ddq=np.zeros((20, 3)))
    assert [a.shape for a in reference_arrays(three, 3)] == [(20, 3)] * 3
    with pytest.raises(SimError, match=r"reference\.q: expected finite values of shape \(20,\)"):
        reference_arrays(three)
    with pytest.raises(SimError, match=r"reference\.q: expected .* shape \(20, 2\)"):
        reference_arrays(three, 2)
    with pytest.raises(SimError, match=r"reference: expected arrays q, dq, ddq"):
        reference_arrays(SimpleNamespace(q=q))
    with pytest.raises(SimError, match="at least one sample"):
        reference_arrays(SimpleNamespace(q=q[:0], dq=q[:0], ddq=q[:0]))


def test_one_joint_record_is_what_the_loop_measured_and_sent():
    """A law asking a torque beyond the int16 range is clipped by the quantiser; the counts
    are the rounded true position, the measurement the law saw is counts / cpr."""
    p = default_plant()
    plant = JointPlant(p, 0.001, seed=4)
    plant.reset(0.2)
    seen = []

    def law(k, q_measured):
        seen.append(q_measured)
        return 1e9 if k < 5 else -300.0

    cpr, pm = p.drive.counts_per_joint_rad, p.drive.torque_per_permille
    rec = run_closed_loop(plant, law, plant.permille_from_torque, 40, joints=None,
                          counts_per_rad=cpr, torque_per_permille=pm)
    assert rec.counts.shape == (40,) and rec.x.dtype == np.int16
    np.testing.assert_array_equal(rec.counts, np.rint(rec.q_true * cpr))
    np.testing.assert_array_equal(np.array(seen), rec.counts / cpr)
    assert np.all(rec.x[:5] == 32767)
    assert np.all(rec.x[5:] == round(-300.0 / pm))
    assert rec.q_true[0] == 0.2 and rec.dq_true[0] == 0.0
    assert np.any(rec.dq_true != 0.0)  # the torque moved the joint
    assert isinstance(rec, LoopRecord) and len(rec) == 40 and rec.cycle_s == 0.001
    np.testing.assert_array_equal(rec.q, rec.counts / cpr)
    np.testing.assert_array_equal(rec.tau_ref, rec.x * pm)
    np.testing.assert_array_equal(rec.t, np.arange(40) * 0.001)


def test_n_joint_record_uses_the_given_noise():
    params = ArmParams.from_model(ur10(3))
    plant = ArmPlant(params, 0.001, seed=1)
    plant.reset([0.1, -1.0, 0.8])
    noise = np.random.default_rng(2).standard_normal((30, 3))
    hold = np.asarray(params.friction.tau_off, dtype=float)
    drive = params.drive
    rec = run_closed_loop(plant, lambda k, q: hold, drive.quantise, 30, joints=3,
                          counts_per_rad=drive.counts_per_rad,
                          torque_per_permille=drive.torque_per_permille, rnd=np.rint,
                          noise=noise)
    assert rec.counts.shape == (30, 3) and rec.regime.shape == (30, 3)
    np.testing.assert_array_equal(rec.tau_noise, noise)
    np.testing.assert_array_equal(rec.x, np.tile(drive.quantise(hold), (30, 1)))
    np.testing.assert_array_equal(rec.counts, np.rint(rec.q_true * drive.counts_per_rad))


def test_the_pd_law_on_k_joints_is_k_single_joint_laws_bit_for_bit():
    """A joint is a 1-dof robot: PDLaw on arrays (k,) gives, element by element, what the
    single-joint PositionController gives with the same feed-forward (no gravity term)."""
    kp, kd = np.array([900.0, 20000.0, 3.5]), np.array([40.0, 1000.0, 0.7])
    rng = np.random.default_rng(3)
    ins = rng.standard_normal((50, 4, 3))  # ff, q_ref, dq_ref, q_meas per cycle
    arm = PDLaw(kp, kd, 80.0, 0.001)
    ones = [PositionController(ControllerGains(kp=kp[j], kd=kd[j], J_ff=1.0,
                                               velocity_cutoff_hz=80.0), 0.001, False)
            for j in range(3)]
    for ff, q_ref, dq_ref, q_meas in ins:
        tau = arm.torque(ff, q_ref, dq_ref, q_meas)
        assert tau.shape == (3,)
        # J_ff = 1, ddq_ref = ff, dq_ref * 0 friction: the controller's feed-forward is ff
        one = [c.update(q_ref[j], dq_ref[j], ff[j], q_meas[j]) for j, c in enumerate(ones)]
        np.testing.assert_array_equal(tau, one)
    arm.reset()
    ff, q_ref, dq_ref, q_meas = ins[0]
    np.testing.assert_array_equal(arm.torque(ff, q_ref, dq_ref, q_meas),
                                  ff + kp * (q_ref - q_meas) + kd * dq_ref)  # no velocity yet


def test_single_joint_and_arm_runs_are_one_record():
    p = default_plant()
    t = np.arange(0.0, 1.0, 0.001)
    ref = SimpleNamespace(t=t, q=0.3 * np.sin(t), dq=0.3 * np.cos(t), ddq=-0.3 * np.sin(t))
    one = simulate(p, ref, ControllerGains(kp=20000.0, kd=1000.0), payload_mass=1.5,
                   payload_arm=0.4)
    params = ArmParams.from_model(ur10(3))
    arm = simulate_arm(params, sine_reference(np.array([0.1, -1.0, 0.8]), 0.2,
                                              duration_s=2.5),
                       ArmGains.for_params(params), seed=2)
    for run, shape in ((one, (1000,)), (arm, (arm.t.shape[0], 3))):
        assert isinstance(run, LoopRecord) and run.q.shape == shape and run.t.ndim == 1
        np.testing.assert_array_equal(run.stuck, run.regime == REGIME_REST)
        np.testing.assert_array_equal(run.sliding, run.regime == REGIME_SLIDING)
        assert len(run) == run.t.shape[0]
    assert isinstance(one, SimRun) and (one.payload_mass_kg, one.payload_arm_m) == (1.5, 0.4)
    assert isinstance(arm, ArmRun) and arm.k == 3 and arm.q_ref.shape == arm.q.shape


def test_the_loop_makes_the_record_it_is_given():
    p = default_plant()
    plant = JointPlant(p, 0.002, seed=1)
    plant.reset(0.0)
    rec = run_closed_loop(plant, lambda k, q: 0.0, plant.permille_from_torque, 5, joints=None,
                          counts_per_rad=p.drive.counts_per_joint_rad,
                          torque_per_permille=p.drive.torque_per_permille,
                          record=partial(SimRun, payload_mass_kg=2.0, payload_arm_m=0.1,
                                         revolute=True))
    assert isinstance(rec, SimRun) and rec.payload_mass_kg == 2.0
    np.testing.assert_array_equal(rec.t, np.arange(5) * 0.002)
