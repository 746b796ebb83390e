"""Excitation plans: limits, rest at both ends, continuity, exact sines, the example's figures."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import ruckig
from daq.examples import path as example_path
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from trajectories import LimitError, SchemaError
from trajectories.campaign import (
    Joint,
    JointLimits,
    SineSegment,
    TrapezoidSweep,
    shorten_segments,
)
from trajectories.campaign_file import load_campaign
from trajectories.plan import (
    BANDS,
    POSITIONING_SPEED,
    plan_campaign,
    plan_segment,
)
from trajectories.robot_campaign import RobotCampaign, RobotControl, RobotJoint, RobotPayload
from trajectories.sampled import coverage

EXAMPLE = example_path("campaign.toml")

# ----------------------------------------------------------------------------- helpers
REL = 1e-9


def assert_valid(ref, joint: Joint) -> None:
    """No NaN, every limit, rest at both ends, continuity (bounded increments)."""
    lim = joint.limits
    dt = ref.cycle_s
    for a in (ref.t, ref.q, ref.dq, ref.ddq):
        assert a.dtype == np.float64 and a.shape == ref.t.shape
        assert np.isfinite(a).all()
    assert ref.segment.dtype == np.int32
    np.testing.assert_allclose(ref.t, np.arange(len(ref)) * dt, rtol=0, atol=1e-9)
    lo, hi = lim.position
    assert ref.q.min() >= lo - 1e-9 and ref.q.max() <= hi + 1e-9
    assert np.abs(ref.dq).max() <= lim.max_velocity * (1 + REL)
    assert np.abs(ref.ddq).max() <= lim.max_acceleration * (1 + REL)
    # jerk: the finite difference of a continuous piecewise-linear ddq is the mean jerk
    assert np.abs(np.diff(ref.ddq)).max() <= lim.max_jerk * dt * (1 + 1e-6) + 1e-12
    # continuity of q and dq (increments bounded by the next derivative's limit)
    assert np.abs(np.diff(ref.q)).max() <= lim.max_velocity * dt * (1 + 1e-6) + 1e-12
    assert np.abs(np.diff(ref.dq)).max() <= lim.max_acceleration * dt * (1 + 1e-6) + 1e-12
    # rest at both ends
    for k in (0, -1):
        assert abs(ref.dq[k]) < 1e-9 and abs(ref.ddq[k]) < 1e-9


limits_st = st.builds(
    lambda lo, span, v, a, j: JointLimits((lo, lo + span), v, a, j, 100.0),
    lo=st.floats(-3.0, 0.0),
    span=st.floats(0.3, 4.0),
    v=st.floats(0.1, 3.0),
    a=st.floats(0.5, 20.0),
    j=st.floats(2.0, 200.0),
)
cycle_st = st.sampled_from([0.001, 0.002, 0.005])
HSET = settings(max_examples=200, deadline=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])


# ----------------------------------------------------------------------------- properties
@HSET
@given(lim=limits_st, dt=cycle_st, data=st.data())
def test_trapezoid_segments_respect_limits(lim, dt, data):
    lo, hi = lim.position
    a = data.draw(st.floats(lo, hi - 0.2 * lim.span), label="range_lo")
    b = data.draw(st.floats(a + 0.1 * lim.span, hi), label="range_hi")
    # keep each run under ~40 s of samples: slowest cruise crosses the range in <= 15 s
    smin = min(1.0, (b - a) / (15.0 * lim.max_velocity))
    speeds = data.draw(st.lists(st.floats(smin, 1.0), min_size=1, max_size=3), label="speeds")
    dwell = data.draw(st.floats(0.0, 0.3), label="dwell")
    cycles = data.draw(st.integers(1, 2), label="cycles")
    start = data.draw(st.floats(lo, hi), label="start")
    joint = Joint("revolute", lim, start)
    seg = TrapezoidSweep("", tuple(speeds), (a, b), dwell_s=dwell, cycles=cycles)
    ref = plan_segment(seg, joint, dt, return_to_start=True)
    assert_valid(ref, joint)
    assert ref.q[0] == pytest.approx(start, abs=1e-12)
    assert ref.q[-1] == pytest.approx(start, abs=1e-9)
    # it does go across the range, at each requested cruise speed (when reachable)
    assert ref.q.min() <= a + 1e-6 and ref.q.max() >= b - 1e-6  # peaks fall between samples
    moves = [p for p in ref.pieces if p.kind == "move"]
    assert [p.speed for p in moves] == [s for s in speeds for _ in range(2 * cycles)]


@HSET
@given(lim=limits_st, dt=cycle_st, data=st.data())
def test_sine_segments_are_exact_between_blends(lim, dt, data):
    lo, hi = lim.position
    amp = data.draw(st.floats(0.02 * lim.span, 0.45 * lim.span), label="amplitude")
    center = data.draw(st.floats(lo + amp, hi - amp), label="center")
    w_max = min(lim.max_velocity / amp, math.sqrt(lim.max_acceleration / amp),
                (lim.max_jerk / amp) ** (1 / 3))
    w = w_max * data.draw(st.floats(0.2, 1.0), label="w_fraction")
    assume(w / (2 * math.pi) >= 0.05)  # at most 20 s per period
    periods = data.draw(st.integers(1, 2), label="periods")
    start = data.draw(st.floats(lo, hi), label="start")
    joint = Joint("revolute", lim, start)
    seg = SineSegment(amp, w / (2 * math.pi), center, periods)
    ref = plan_segment(seg, joint, dt, return_to_start=True)
    assert_valid(ref, joint)
    assert ref.q[-1] == pytest.approx(start, abs=1e-9)
    assert [p.kind for p in ref.pieces] == ["blend_in", "sine", "blend_out", "return"][
        : len(ref.pieces)]
    (sine,) = [p for p in ref.pieces if p.kind == "sine"]
    assert sine.t1 - sine.t0 == pytest.approx(periods / seg.frequency_hz, rel=1e-12)
    inside = (ref.t >= sine.t0) & (ref.t <= sine.t1)
    tau = ref.t[inside] - sine.t0
    np.testing.assert_allclose(ref.q[inside], center - amp * np.cos(w * tau), atol=1e-9)
    np.testing.assert_allclose(ref.dq[inside], amp * w * np.sin(w * tau), atol=1e-9)
    np.testing.assert_allclose(ref.ddq[inside], amp * w * w * np.cos(w * tau), atol=1e-9)


@HSET
@given(lim=limits_st, dt=cycle_st, data=st.data())
def test_mixed_campaigns_are_continuous_and_return_to_start(lim, dt, data):
    lo, hi = lim.position
    segments = []
    for _ in range(data.draw(st.integers(1, 3), label="n_segments")):
        if data.draw(st.booleans(), label="is_sine"):
            amp = data.draw(st.floats(0.05 * lim.span, 0.45 * lim.span), label="amplitude")
            center = data.draw(st.floats(lo + amp, hi - amp), label="center")
            w_max = min(lim.max_velocity / amp, math.sqrt(lim.max_acceleration / amp),
                        (lim.max_jerk / amp) ** (1 / 3))
            f = max(0.1, w_max * data.draw(st.floats(0.2, 1.0), label="w") / (2 * math.pi))
            assume(f <= w_max / (2 * math.pi))
            segments.append(SineSegment(amp, f, center, 1))
        else:
            a = data.draw(st.floats(lo, hi - 0.2 * lim.span), label="range_lo")
            b = data.draw(st.floats(a + 0.1 * lim.span, hi), label="range_hi")
            smin = min(1.0, (b - a) / (10.0 * lim.max_velocity))
            speed = data.draw(st.floats(smin, 1.0), label="speed")
            segments.append(TrapezoidSweep("", (speed,), (a, b), dwell_s=0.1))
    start = data.draw(st.floats(lo, hi), label="start")
    joint = RobotJoint("joint", "revolute", lim, None, 100.0, 1.0, table="joint")
    campaign = RobotCampaign("prop", "", (joint,), (start,), {}, RobotControl(dt),
                             (RobotPayload(0.0, (1.0, 0.0, 0.0), arm_m=1.0),), tuple(segments))
    plan = plan_campaign(campaign)
    ref = plan.reference
    assert_valid(ref, joint)
    assert ref.q[0] == pytest.approx(start, abs=1e-12)
    assert ref.q[-1] == pytest.approx(start, abs=1e-9)
    assert np.all(np.diff(ref.segment) >= 0)
    s = plan.summary()
    # the shares are of the moving samples (faster than MOVING_FRACTION of the velocity
    # limit); a plan that never exceeds it (e.g. a trapezoid at 0.001 of the limit, found by
    # hypothesis) has none, and its shares are all 0
    moving = s.moving_time_s[0] > 0
    assert sum(s.band_share[0]) == pytest.approx(1.0 if moving else 0.0)
    assert all(0 <= c <= 1 for c in s.band_coverage[0])


def test_cubic_evaluation_matches_ruckig_at_time():
    """The vectorised phase evaluation reproduces ruckig's own Trajectory.at_time."""
    lim = JointLimits((-1.0, 2.0), 1.5, 3.0, 25.0, 100.0)
    joint = Joint("revolute", lim, 0.2)
    ref = plan_segment(TrapezoidSweep("", (0.7,), (-0.5, 1.7), dwell_s=0.0), joint, 0.001)
    move = ref.pieces[0]  # positioning move 0.2 -> -0.5
    inp = ruckig.InputParameter(1)
    inp.current_position, inp.target_position = [0.2], [-0.5]
    inp.current_velocity = inp.current_acceleration = [0.0]
    inp.target_velocity = inp.target_acceleration = [0.0]
    inp.max_velocity = [POSITIONING_SPEED * 1.5]
    inp.max_acceleration, inp.max_jerk = [3.0], [25.0]
    traj = ruckig.Trajectory(1)
    ruckig.Ruckig(1).calculate(inp, traj)
    assert move.t1 - move.t0 == pytest.approx(traj.duration, rel=1e-12)
    idx = np.flatnonzero(ref.t <= move.t1)
    expected = np.array([[x[0] for x in traj.at_time(ref.t[k])] for k in idx])
    np.testing.assert_allclose(ref.q[idx], expected[:, 0], atol=1e-12)
    np.testing.assert_allclose(ref.dq[idx], expected[:, 1], atol=1e-12)
    np.testing.assert_allclose(ref.ddq[idx], expected[:, 2], atol=1e-12)


# ----------------------------------------------------------------------------- rejections
LIM = JointLimits((-1.2, 1.4), 1.2, 4.0, 40.0, 700.0)
JOINT = Joint("revolute", LIM, 0.1)


@pytest.mark.parametrize(
    ("seg", "limit"),
    [
        (SineSegment(1.0, 0.25, 0.1, 1), "joint.limits.max_velocity 1.2 rad/s"),
        (SineSegment(0.2, 0.8, 0.1, 1), "joint.limits.max_acceleration 4 rad/s^2"),
        (SineSegment(0.009, 3.2, 0.1, 1), "joint.limits.max_jerk 40 rad/s^3"),
        (SineSegment(0.5, 0.1, 1.0, 1), "joint.limits.position [-1.2, 1.4] rad"),
        (TrapezoidSweep("", (0.5,), (-1.3, 0.0)), "joint.limits.position [-1.2, 1.4] rad"),
    ],
)
def test_plans_beyond_a_limit_are_rejected_naming_segment_and_limit(seg, limit):
    with pytest.raises(LimitError) as err:
        plan_segment(seg, JOINT, 0.001, index=2)
    msg = str(err.value)
    assert msg.startswith(f"segments[2] ({seg.kind}): ")
    assert limit in msg and "\n" not in msg


def test_sine_peak_velocity_message():
    with pytest.raises(LimitError, match=r"^segments\[0\] \(sine\): peak velocity 1\.571 rad/s "
                       r"exceeds joint.limits.max_velocity 1\.2 rad/s$"):
        plan_segment(SineSegment(1.0, 0.25, 0.1, 1), JOINT, 0.001)


def test_torque_estimate_beyond_max_torque_is_rejected():
    c = load_campaign(EXAMPLE)
    payloads = (c.payloads[0], RobotPayload(80.0, (1.277, 0.0, 0.0), arm_m=1.277))
    heavy = replace(c, payloads=payloads)
    with pytest.raises(LimitError, match=r"^payloads\[1\] \(80 kg at 1.277 m\).*max_torque 700"):
        plan_campaign(heavy)


# ----------------------------------------------------------------------------- campaign plan
@pytest.fixture(scope="module")
def example_plan():
    return plan_campaign(load_campaign(EXAMPLE))


def test_example_plan_is_valid_and_starts_and_ends_at_start(example_plan):
    ref = example_plan.reference
    campaign = load_campaign(EXAMPLE)
    (joint,), (start,) = campaign.joints, campaign.start
    assert_valid(ref, joint)
    assert ref.q[0] == start == pytest.approx(0.7)
    assert ref.q[-1] == pytest.approx(start, abs=1e-9)
    assert ref.segment_names == ref.segments == (
        "segments[0] (trapezoid)", "segments[1] (trapezoid)", "segments[2] (trapezoid)",
        "segments[3] (sine)", "return")
    assert set(np.unique(ref.segment)) == {0, 1, 2, 3, 4}
    assert np.all(np.diff(ref.segment) >= 0)  # segments in order, contiguous
    # the plan of a [joint] campaign is that of a robot with one moving joint, "joint"
    assert example_plan.joint_names == ("joint",) and example_plan.limits == (joint.limits,)
    assert [(p.mass_kg, p.arm_m, p.com) for p in example_plan.payloads] == [
        (p.mass_kg, p.arm_m, (p.arm_m, 0.0, 0.0)) for p in campaign.payloads]
    with pytest.raises(ValueError):
        ref.q[0] = 1.0  # read-only


def test_example_meets_acceptance_figures(example_plan):
    s = example_plan.summary()
    assert 60.0 <= s.run_duration_s <= 210.0
    assert s.total_duration_s == pytest.approx(3 * s.run_duration_s)
    assert BANDS == (0.0, 0.1, 0.35, 1.0)
    (share,), (cov,), (peaks,) = s.band_share, s.band_coverage, s.peaks
    assert sum(share) == pytest.approx(1.0)
    assert share[0] >= 0.15
    assert min(cov) >= 0.80
    q_min, q_max, peak_dq, peak_ddq, peak_jerk = peaks
    assert peak_dq <= 1.2 * (1 + REL) and peak_ddq <= 4.0 * (1 + REL)
    assert peak_jerk <= 40.0 * (1 + 1e-6)
    assert q_min >= -1.0 and q_max <= 2.4
    # the range crosses pi/2, where gravity changes sign (motor and generator quadrants)
    assert q_min < math.pi / 2 < q_max
    tau = [row[0] for row in s.peak_torque]
    assert len(tau) == 3 and tau[0] < tau[1] < tau[2]
    # both directions in every band (motor and generator quadrants against gravity)
    ref = example_plan.reference
    speed = ref.dq / 1.2
    for lo, hi in zip(BANDS[:-1], BANDS[1:], strict=True):
        band = (np.abs(speed) > max(lo, 1e-3)) & (np.abs(speed) <= hi)
        assert (speed[band] > 0).sum() > 100 and (speed[band] < 0).sum() > 100
    table = s.format_table()
    assert "0-10 % of vmax" in table and "rx130l-joint3" in table
    assert f"{100 * share[0]:.1f}%" in table and f"{100 * cov[0]:.1f}%" in table
    assert "6.97 kg at 1.277 m" in table and f"{tau[2]:.4g} (700)" in table


def test_quick_campaign_is_short_with_slow_moves_both_ways():
    c = load_campaign(EXAMPLE)
    q = c.quick()
    plan = plan_campaign(q)
    ref = plan.reference
    assert_valid(ref, q.joints[0])
    assert ref.duration_s <= 0.3 * plan_campaign(c).reference.duration_s
    # the sine keeps the whole range covered (gravity and position effects stay visible)
    lo, hi = c.joints[0].limits.position
    assert ref.q.max() - ref.q.min() >= 0.8 * (hi - lo)
    slow = (np.abs(ref.dq) > 0.01 * 1.2) & (np.abs(ref.dq) < 0.1 * 1.2)
    assert (slow & (ref.dq > 0)).sum() * ref.cycle_s > 1.0
    assert (slow & (ref.dq < 0)).sum() * ref.cycle_s > 1.0
    assert q.payloads == c.payloads and q.control == c.control
    with pytest.raises(SchemaError, match="factor"):
        shorten_segments(c.segments, c.joints[0].limits, 0.0)


def test_coverage_is_the_union_of_visited_intervals():
    q = np.array([0.0, 0.5, 1.0, 0.8, 3.0, 3.5, 2.0])
    mask = np.array([True, True, True, True, False, True, True])
    # pairs in mask: [0,0.5], [0.5,1], [0.8,1], [2,3.5] -> union length 1 + 1.5
    assert coverage(q, mask) == pytest.approx(2.5)
    assert coverage(q, np.zeros(7, dtype=bool)) == 0.0
