"""Offline closed loop: the controller tracks, runs are reproducible, and the record is the
plant's truth (eq. 30 on the true states reproduces the applied torque)."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from daq.protocol.control import ControllerGains
from sim_drivers import SimError
from sim_drivers.offline import SimRun, simulate, simulate_payloads
from sim_drivers.plant import REGIME_SLIDING, inverse_torque, output_torque
from sim_drivers.plant_config import default_plant, load_plant

ROOT = Path(__file__).resolve().parents[1]
MA, LA = 3.4584, 1.277
#: Gains recommended for the default plant (J = 31 kg m^2): PD + rough feed-forward.
GAINS = ControllerGains(kp=20000.0, kd=1000.0, J_ff=31.0, MX_ff=21.1, Fc_ff=25.0, Fv_ff=40.0)


def sine_reference(duration=12.0, dt=0.001, offset=0.0):
    """Two sines (fast and slow): reversals, both power quadrants, low speed."""
    t = np.arange(0.0, duration, dt)
    w = 2 * np.pi * 0.2
    q = offset + 0.8 * np.sin(w * t) + 0.3 * np.sin(0.5 * w * t)
    dq = 0.8 * w * np.cos(w * t) + 0.15 * w * np.cos(0.5 * w * t)
    ddq = -0.8 * w * w * np.sin(w * t) - 0.075 * w * w * np.sin(0.5 * w * t)
    return SimpleNamespace(t=t, q=q, dq=dq, ddq=ddq)


@pytest.fixture(scope="module")
def run_rx():
    p = load_plant(ROOT / "examples" / "plant_rx130l.toml")
    return p, simulate(p, sine_reference(), GAINS, payload_mass=MA, payload_arm=LA, seed=3)


def test_closed_loop_tracks(run_rx):
    _, r = run_rx
    ref = sine_reference()
    err = (r.q_true - ref.q)[1000:]
    assert np.sqrt(np.mean(err**2)) < 0.005 and np.max(np.abs(err)) < 0.01
    assert isinstance(r, SimRun) and len(r) == ref.q.size and r.revolute
    assert r.payload_mass_kg == MA and r.payload_arm_m == LA


def test_record_is_the_plants_truth(run_rx):
    p, r = run_rx
    sliding = r.regime == REGIME_SLIDING
    assert sliding.mean() > 0.9 and r.stuck.sum() > 20  # it does stick at some reversals
    tau = inverse_torque(p, r.q_true, r.dq_true, r.ddq_true, MA, LA, r.t)
    np.testing.assert_allclose(tau[sliding], r.tau_applied[sliding], rtol=0, atol=1e-8)
    # without torque lag the applied torque is the reference plus the ripple noise
    np.testing.assert_allclose(r.tau_applied - r.tau_noise, r.tau_ref, rtol=0, atol=1e-9)
    assert np.std(r.tau_noise) == pytest.approx(p.drive.torque_noise_std_Nm, rel=0.05)
    # both power quadrants are visited (the paper model is identifiable)
    power = np.sign(output_torque(p, r.q_true, r.ddq_true, MA, LA) * r.dq_true)
    assert (power > 0).mean() > 0.2 and (power < 0).mean() > 0.2


def test_measurements_are_quantised_like_the_bus(run_rx):
    p, r = run_rx
    d = p.drive
    cpr = d.gear_ratio * d.encoder_counts_per_rev / (2 * np.pi)
    np.testing.assert_array_equal(r.counts, np.round(r.q_true * cpr).astype(np.int64))
    np.testing.assert_allclose(r.q, r.counts / cpr, rtol=0, atol=0)
    assert r.x.dtype == np.int16
    np.testing.assert_array_equal(r.tau_ref, r.x.astype(float) * d.torque_per_permille)
    np.testing.assert_array_equal(r.cycle, np.arange(len(r)))
    np.testing.assert_allclose(r.t, np.arange(len(r)) * 0.001)


def test_same_seed_same_arrays_other_seed_differs():
    p = default_plant()
    ref = sine_reference(duration=2.0)
    a = simulate(p, ref, GAINS, payload_mass=MA, payload_arm=LA, seed=11)
    b = simulate(p, ref, GAINS, payload_mass=MA, payload_arm=LA, seed=11)
    c = simulate(p, ref, GAINS, payload_mass=MA, payload_arm=LA, seed=12)
    for f in dataclasses.fields(SimRun):
        va, vb = getattr(a, f.name), getattr(b, f.name)
        if isinstance(va, np.ndarray):
            np.testing.assert_array_equal(va, vb, err_msg=f.name)
    assert not np.array_equal(a.tau_ref, c.tau_ref)


def test_torque_lag_record_balances_with_applied_not_reference():
    p = default_plant().with_effect("torque_lag", time_constant_s=0.003)
    r = simulate(p, sine_reference(duration=3.0), GAINS, payload_mass=0.0, payload_arm=LA)
    sliding = r.regime == REGIME_SLIDING
    tau = inverse_torque(p, r.q_true, r.dq_true, r.ddq_true, 0.0, LA, r.t)
    np.testing.assert_allclose(tau[sliding], r.tau_applied[sliding], rtol=0, atol=1e-8)
    lagged = r.tau_applied - r.tau_noise
    assert np.max(np.abs(lagged - r.tau_ref)) > 5.0  # the lag is visible against tau_ref
    # first-order lag, exact for a piecewise-constant command: y_k+1 = u_k + (y_k - u_k) e^-dt/T
    keep = np.exp(-0.001 / 0.003)
    np.testing.assert_allclose(lagged[1:], r.tau_ref[:-1] + (lagged[:-1] - r.tau_ref[:-1]) * keep,
                               rtol=0, atol=1e-9)


def test_campaign_plan_runs_through_the_simulator():
    trajectories_plan = pytest.importorskip("trajectories.plan")
    campaign_file = pytest.importorskip("trajectories.campaign_file")
    camp = campaign_file.load_campaign(ROOT / "examples" / "campaign.toml")
    ref = trajectories_plan.plan_campaign(camp).reference
    n = min(len(ref.t), 30000)  # the first 30 s: the slow band and the first trapezoids
    short = SimpleNamespace(t=ref.t[:n], q=ref.q[:n], dq=ref.dq[:n], ddq=ref.ddq[:n])
    p = default_plant()
    r = simulate(p, short, GAINS, payload_mass=6.970, payload_arm=LA)
    assert np.max(np.abs(r.q_true - short.q)) < 0.01
    low = (np.abs(r.dq_true) > 0) & (np.abs(r.dq_true) < 0.1)
    assert low.mean() > 0.2  # low-velocity samples, where E = exp(-|dq|/q_s) matters


def test_bad_reference_is_refused():
    p = default_plant()
    ref = sine_reference(duration=0.1)
    ref.t = ref.t.copy()
    ref.t[5] += 0.0004
    with pytest.raises(SimError, match=r"reference\.t: expected uniform sampling"):
        simulate(p, ref, GAINS)
    with pytest.raises(SimError, match=r"reference\.dq: expected finite values of shape \(100,\)"):
        simulate(p, SimpleNamespace(t=ref.t, q=ref.q, dq=ref.dq[:-1], ddq=ref.ddq), GAINS)
    with pytest.raises(SimError, match=r"reference: expected arrays"):
        simulate(p, SimpleNamespace(t=ref.t, q=ref.q), GAINS)
    nan = ref.ddq.copy()
    nan[3] = np.nan
    with pytest.raises(SimError, match=r"reference\.ddq: expected finite values"):
        simulate(p, SimpleNamespace(t=ref.t, q=ref.q, dq=ref.dq, ddq=nan), GAINS)
    with pytest.raises(SimError, match=r"reference\.t: expected the sample times"):
        simulate(p, SimpleNamespace(q=ref.q, dq=ref.dq, ddq=ref.ddq), GAINS)
    with pytest.raises(SimError, match=r"cycle_s: expected a number > 0"):
        simulate(p, ref, GAINS, cycle_s=0.0)


def _eq42_columns(q, dq, ddq, ma, la, power, q_s):
    """W_new of eq. 42, column by column, in the order of eq. 43."""
    g = 9.81
    pp, pm = (1 + power) / 2, (1 - power) / 2
    e = np.exp(-np.abs(dq) / q_s)
    pay = ma * la * (la * ddq + g * np.cos(q))
    load = [ddq, g * np.cos(q), g * np.sin(q), pay]
    cols = []
    for p, sb in ((pp, 1.0), (pm, -1.0)):
        for x in load:
            cols += [p * x, sb * p * e * x]
    s = np.sign(dq)
    cols += [pp * s, pp * e * s, pm * s, pm * e * s, dq, np.ones_like(q)]
    return np.column_stack(cols)


def test_truth_is_the_exact_least_squares_solution_of_eq42():
    """On the true states and applied torque of two payload runs, the LS solution of eq. 40-43
    is PlantParams.truth(): the truth mapping, the eq. 42 sign conventions and the simulator
    agree. The motion crosses q = pi/2, so that tau_out changes sign: otherwise
    P+ sign(dq) - P- sign(dq) = 1 and c_m, c_g, tau_off are not separable."""
    p = default_plant()
    ref = sine_reference(duration=6.0, offset=0.9)
    w_blocks, y_blocks = [], []
    runs = simulate_payloads(p, ref, GAINS, [(0.0, LA), SimpleNamespace(mass_kg=6.970, arm_m=LA)])
    assert [r.payload_mass_kg for r in runs] == [0.0, 6.970]
    assert not np.array_equal(runs[0].tau_noise, runs[1].tau_noise)  # seeds 0 and 1
    for r in runs:
        ma = r.payload_mass_kg
        keep = r.regime == REGIME_SLIDING
        power = np.sign(output_torque(p, r.q_true, r.ddq_true, ma, LA) * r.dq_true)
        assert (power[keep] * np.sign(r.dq_true[keep]) < 0).mean() > 0.05  # tau_out < 0 too
        w_blocks.append(_eq42_columns(r.q_true, r.dq_true, r.ddq_true, ma, LA, power,
                                      p.joint.q_s)[keep])
        y_blocks.append(r.tau_applied[keep])
    w, y = np.vstack(w_blocks), np.concatenate(y_blocks)
    scale = np.linalg.norm(w, axis=0)
    chi = np.linalg.lstsq(w / scale, y, rcond=None)[0] / scale
    truth = p.truth()
    np.testing.assert_allclose(chi, list(truth.values()), rtol=1e-6, atol=1e-6)
