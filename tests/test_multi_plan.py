"""Multi-dof excitation plans: every joint's limits, rest at both ends, continuity, exact
multi-sines and trapezoid speeds; excitation quality and multi-sine optimisation on UR10."""

from __future__ import annotations

import math

import numpy as np
import pytest
import ur_model
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from trajectories import LimitError, TrajectoryError
from trajectories.campaign import JointLimits
from trajectories.excitation import (
    QUADRANTS,
    base_columns,
    condition_number,
    optimise_multisine,
    quadrant_shares,
    quality,
    random_states,
)
from trajectories.multi import (
    BANDS,
    band_shares,
    check_torques,
    default_coefficients,
    fit_coefficients,
    fourier_eval,
    multisine_ratio,
    plan_robot,
    rest_projection,
)
from trajectories.robot_campaign import (
    MoveSegment,
    MultisineSegment,
    RobotPayload,
    TrapezoidSweep,
)

HSET = settings(max_examples=40, deadline=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])


# ----------------------------------------------------------------------------- helpers
def assert_valid(plan, start) -> None:
    """Finite, (n, k) arrays, every joint's limits, continuity, rest at both ends at start."""
    n, k = plan.q.shape
    dt = plan.cycle_s
    assert plan.t.shape == (n,) and plan.segment.shape == (n,)
    for a in (plan.q, plan.dq, plan.ddq):
        assert a.shape == (n, k) and a.dtype == np.float64 and np.isfinite(a).all()
    np.testing.assert_allclose(plan.t, np.arange(n) * dt, rtol=0, atol=1e-9)
    for j, lim in enumerate(plan.limits):
        lo, hi = lim.position
        q, dq, ddq = plan.q[:, j], plan.dq[:, j], plan.ddq[:, j]
        assert q.min() >= lo - 1e-9 and q.max() <= hi + 1e-9
        assert np.abs(dq).max() <= lim.max_velocity * (1 + 1e-9)
        assert np.abs(ddq).max() <= lim.max_acceleration * (1 + 1e-9)
        if n < 2:  # nothing moves: one rest sample
            continue
        # continuity: increments bounded by the next derivative's limit over one cycle
        assert np.abs(np.diff(q)).max() <= lim.max_velocity * dt * (1 + 1e-6) + 1e-12
        assert np.abs(np.diff(dq)).max() <= lim.max_acceleration * dt * (1 + 1e-6) + 1e-12
        assert np.abs(np.diff(ddq)).max() <= lim.max_jerk * dt * (1 + 1e-6) + 1e-12
    for i in (0, -1):
        np.testing.assert_allclose(plan.q[i], start, atol=1e-9)
        assert np.abs(plan.dq[i]).max() < 1e-9 and np.abs(plan.ddq[i]).max() < 1e-9
    assert np.all(np.diff(plan.segment) >= 0)
    with pytest.raises(ValueError):
        plan.q[0, 0] = 1.0  # read-only


@st.composite
def limits_st(draw, k: int):
    out = []
    for _ in range(k):
        lo = draw(st.floats(-3.0, 0.0))
        span = draw(st.floats(0.5, 4.0))
        out.append(JointLimits((lo, lo + span), draw(st.floats(0.3, 3.0)),
                               draw(st.floats(1.0, 20.0)), draw(st.floats(5.0, 200.0)), 100.0))
    return tuple(out)


@st.composite
def robot_case(draw):
    """Random joints, limits, start pose and 1-3 segments of every kind (bounded durations)."""
    k = draw(st.integers(1, 4), label="k")
    limits = draw(limits_st(k), label="limits")
    names = tuple(f"j{i + 1}" for i in range(k))
    start = tuple(draw(st.floats(lim.position[0], lim.position[1])) for lim in limits)
    segments = []
    for _ in range(draw(st.integers(1, 3), label="n_segments")):
        kind = draw(st.sampled_from(["trapezoid", "multisine", "move"]))
        if kind == "trapezoid":
            jj = draw(st.integers(0, k - 1))
            lim = limits[jj]
            lo, hi = lim.position
            a = draw(st.floats(lo, hi - 0.3 * (hi - lo)))
            b = draw(st.floats(a + 0.1 * (hi - lo), hi))
            smin = min(1.0, (b - a) / (8.0 * lim.max_velocity))  # slowest move <= 8 s
            speeds = tuple(draw(st.lists(st.floats(smin, 1.0), min_size=1, max_size=3)))
            sweep = {}
            for s in range(k):
                if s != jj and draw(st.booleans()):
                    slo, shi = limits[s].position
                    x = draw(st.floats(slo, shi - 0.2 * (shi - slo)))
                    sweep[names[s]] = (x, draw(st.floats(x + 0.1 * (shi - slo), shi)))
            segments.append(TrapezoidSweep(names[jj], speeds, (a, b), sweep,
                                           draw(st.floats(0.05, 1.0)),
                                           draw(st.floats(0.0, 0.3)), draw(st.integers(1, 2))))
        elif kind == "multisine":
            center = tuple(draw(st.floats(lim.position[0] + 0.05 * (lim.position[1]
                                                                    - lim.position[0]),
                                          lim.position[1] - 0.05 * (lim.position[1]
                                                                    - lim.position[0])))
                           for lim in limits)
            segments.append(MultisineSegment(
                period_s=draw(st.floats(2.0, 12.0)), periods=draw(st.integers(1, 2)),
                center=center, harmonics=draw(st.integers(2, 6)),
                fill=draw(st.floats(0.1, 1.0)), seed=draw(st.integers(0, 1000))))
        else:
            poses = tuple(tuple(draw(st.floats(*lim.position)) for lim in limits)
                          for _ in range(draw(st.integers(1, 3))))
            segments.append(MoveSegment(poses, draw(st.floats(0.1, 1.0)),
                                        draw(st.floats(0.0, 0.5))))
    dt = draw(st.sampled_from([0.001, 0.002, 0.004]))
    return names, limits, start, tuple(segments), dt


# ----------------------------------------------------------------------------- properties
@HSET
@given(case=robot_case())
def test_multi_dof_plans_respect_every_limit_start_and_end_at_rest_and_are_continuous(case):
    names, limits, start, segments, dt = case
    plan = plan_robot(segments, names, limits, start, dt)
    assert_valid(plan, start)
    assert plan.segment_names[-1] == "return"
    assert len(plan.segment_names) == len(segments) + 1
    # deterministic: the same input gives the same samples
    again = plan_robot(segments, names, limits, start, dt)
    for a, b in ((plan.q, again.q), (plan.dq, again.dq), (plan.ddq, again.ddq)):
        np.testing.assert_array_equal(a, b)
    shares = plan.band_shares()
    assert shares.shape == (len(names), len(BANDS) - 1)
    moving = np.abs(plan.dq).max(axis=0) > 1e-3 * np.array([lim.max_velocity
                                                            for lim in limits])
    np.testing.assert_allclose(shares.sum(axis=1)[moving], 1.0)


@HSET
@given(case=robot_case())
def test_trapezoid_moves_cruise_at_exactly_the_requested_speed(case):
    names, limits, start, segments, dt = case
    plan = plan_robot(segments, names, limits, start, dt)
    for piece in plan.pieces:
        if piece.kind != "move":
            continue
        j = piece.joint
        sel = (plan.t >= piece.t0) & (plan.t <= piece.t1)
        peak = np.abs(plan.dq[sel, j]).max() / limits[j].max_velocity
        # never faster; as fast when the move is long enough to reach the cruise (sampled)
        assert peak <= piece.speed * (1 + 1e-9)
    seg = [s for s in segments if isinstance(s, TrapezoidSweep)]
    moves = [p for p in plan.pieces if p.kind == "move"]
    assert [p.speed for p in moves] == [v for s in seg for v in s.speeds
                                        for _ in range(2 * s.cycles)]


def test_slow_trapezoid_reaches_its_cruise_speed_while_another_joint_sweeps():
    limits = (JointLimits((-2.4, -0.3), 1.2, 4.0, 40.0, 400.0),
              JointLimits((0.2, 2.6), 1.5, 5.0, 50.0, 200.0))
    seg = TrapezoidSweep("j1", (0.03, 0.08, 1.0), (-2.3, -0.4), {"j2": (0.3, 2.5)}, 0.3, 0.2)
    plan = plan_robot([seg], ("j1", "j2"), limits, (-1.2, 1.2), 0.001)
    assert_valid(plan, (-1.2, 1.2))
    moves = [p for p in plan.pieces if p.kind == "move"]
    assert [p.speed for p in moves] == [0.03, 0.03, 0.08, 0.08, 1.0, 1.0]
    sweeping = 0
    for p in moves:
        sel = (plan.t >= p.t0) & (plan.t <= p.t1)
        assert np.abs(plan.dq[sel, 0]).max() == pytest.approx(p.speed * 1.2, rel=1e-9)
        # the sweeping joint changes the gravity configuration during the slow moves (it
        # holds during the first move of every other speed, to shift the pairing)
        sweeping += p.speed < 0.1 and np.ptp(plan.q[sel, 1]) > 2.0
    assert sweeping == 3
    # joint 1 moves both ways under both ends of joint 2's sweep range (all 4 pairings)
    pairs = set()
    for p in moves:
        sel = (plan.t >= p.t0) & (plan.t <= p.t1)
        d1 = np.sign(plan.q[sel, 0][-1] - plan.q[sel, 0][0])
        d2 = np.sign(plan.q[sel, 1][-1] - plan.q[sel, 1][0])
        pairs.add((d1, d2))
    assert {(1, 1), (1, -1), (-1, 1), (-1, -1)} <= pairs
    assert plan.band_shares()[0, 0] > 0.5  # most moving time of j1 below 10 % of vmax


@settings(max_examples=30, deadline=None)
@given(k=st.integers(1, 5), n_harm=st.integers(2, 8), seed=st.integers(0, 10_000),
       period=st.floats(1.0, 20.0))
def test_default_multisine_starts_at_rest_and_fits_the_limits(k, n_harm, seed, period):
    limits = tuple(JointLimits((-1.0 - 0.1 * j, 1.5), 1.0 + j, 3.0, 30.0, 10.0)
                   for j in range(k))
    q0 = np.array([0.2] * k)
    w = 2 * math.pi / period
    a, b = default_coefficients(limits, q0, w, n_harm, fill=0.9, seed=seed)
    assert a.shape == b.shape == (k, n_harm)
    _, dq, ddq, _ = fourier_eval(q0, a, b, w, np.zeros(1))
    assert np.abs(dq).max() < 1e-12 and np.abs(ddq).max() < 1e-9
    np.testing.assert_allclose(multisine_ratio(a, b, q0, w, limits), 0.9, rtol=1e-9)
    # the projection is idempotent and keeps the projected series at rest
    a2, b2 = rest_projection(a, b)
    np.testing.assert_allclose(a2, a, atol=1e-15)
    np.testing.assert_allclose(b2, b, atol=1e-15)
    # the series is periodic: the state after one period equals the state at 0
    s0 = fourier_eval(q0, a, b, w, np.array([0.0, period]))
    for x in s0:
        np.testing.assert_allclose(x[0], x[1], atol=1e-9)


def test_fourier_derivatives_match_finite_differences():
    rng = np.random.default_rng(3)
    a, b = rng.standard_normal((2, 4)), rng.standard_normal((2, 4))
    q0 = np.array([0.1, -0.3])
    t = np.linspace(0.0, 5.0, 50_001)
    q, dq, ddq, dddq = fourier_eval(q0, a, b, 1.3, t)
    h = t[1] - t[0]
    np.testing.assert_allclose(np.gradient(q, h, axis=0)[1:-1], dq[1:-1], atol=1e-6)
    np.testing.assert_allclose(np.gradient(dq, h, axis=0)[1:-1], ddq[1:-1], atol=1e-5)
    np.testing.assert_allclose(np.gradient(ddq, h, axis=0)[1:-1], dddq[1:-1], atol=1e-4)


def test_multisine_is_exact_between_blends_and_blends_are_at_rest():
    limits = (JointLimits((-2.0, 2.0), 1.5, 5.0, 50.0, 1.0),
              JointLimits((-1.0, 1.0), 1.0, 4.0, 40.0, 1.0))
    seg = MultisineSegment(period_s=4.0, periods=2, harmonics=4, fill=1.0, seed=7)
    plan = plan_robot([seg], ("a", "b"), limits, (0.5, -0.2), 0.001)
    assert_valid(plan, (0.5, -0.2))
    (blk,) = plan.fourier
    # the default series starts and ends at rest: no blend out of it is needed
    assert [p.kind for p in plan.pieces] == ["blend_in", "multisine", "return"]
    sel = (plan.t >= blk.t0) & (plan.t <= blk.t0 + blk.duration_s)
    q, dq, ddq, _ = fourier_eval(blk.q0, blk.a, blk.b, blk.omega, plan.t[sel] - blk.t0)
    np.testing.assert_allclose(plan.q[sel], q, atol=1e-9)
    np.testing.assert_allclose(plan.dq[sel], dq, atol=1e-9)
    np.testing.assert_allclose(plan.ddq[sel], ddq, atol=1e-9)
    # fill = 1: each joint's binding limit is reached (to the grid margin), none exceeded
    np.testing.assert_allclose(multisine_ratio(blk.a, blk.b, blk.q0, blk.omega, limits), 1.0)


def test_given_coefficients_not_at_rest_are_blended_in_and_out_continuously():
    limits = (JointLimits((-2.0, 2.0), 1.5, 5.0, 50.0, 1.0),
              JointLimits((-2.0, 2.0), 1.5, 5.0, 50.0, 1.0))
    seg = MultisineSegment(period_s=6.0, periods=1, center=(0.0, 0.3),
                           a=((0.3, 0.1), (0.2, 0.0)), b=((0.1, 0.1), (0.0, 0.2)))
    plan = plan_robot([seg], ("a", "b"), limits, (0.0, 0.0), 0.001)
    assert_valid(plan, (0.0, 0.0))
    (blk,) = plan.fourier
    i0 = np.searchsorted(plan.t, blk.t0)
    assert np.abs(plan.dq[i0]).max() > 0.1  # the series is entered moving


# ----------------------------------------------------------------------------- rejections
LIM2 = (JointLimits((-1.0, 1.0), 1.0, 4.0, 40.0, 10.0),
        JointLimits((-1.0, 1.0), 1.0, 4.0, 40.0, 10.0))


@pytest.mark.parametrize(
    ("a", "limit"),
    [
        (((0.1, 0.0), (2.0, 0.0)), "robot.joints.j2.limits.max_velocity"),
        (((0.1, 0.0), (0.0, 0.9)), "robot.joints.j2.limits.max_acceleration"),
    ],
)
def test_multisine_beyond_a_limit_is_rejected_naming_segment_joint_and_limit(a, limit):
    seg = MultisineSegment(period_s=2.0, a=a, b=((0.0, 0.0), (0.0, 0.0)), center=(0.0, 0.0))
    with pytest.raises(LimitError) as err:
        plan_robot([MoveSegment(((0.1, 0.1),)), seg], ("j1", "j2"), LIM2, (0.0, 0.0), 0.001)
    msg = str(err.value)
    assert msg.startswith("segments[1] (multisine): joint j2: ") and limit in msg
    assert "\n" not in msg


def test_multisine_leaving_the_position_range_is_rejected():
    seg = MultisineSegment(period_s=20.0, a=((0.0, 0.0), (0.5, -0.5)),
                           b=((0.0, 0.0), (0.0, 0.0)), center=(0.0, 0.8))
    with pytest.raises(LimitError, match=r"^segments\[0\] \(multisine\): joint j2: position "
                       r"excursion .* robot\.joints\.j2\.limits\.position$"):
        plan_robot([seg], ("j1", "j2"), LIM2, (0.0, 0.0), 0.001)


def test_move_outside_the_position_range_is_rejected():
    with pytest.raises(LimitError, match=r"^segments\[0\] \(move\): joint j1: .*position"):
        plan_robot([MoveSegment(((1.2, 0.0),))], ("j1", "j2"), LIM2, (0.0, 0.0), 0.001)


def test_bad_inputs_raise_trajectory_errors():
    with pytest.raises(TrajectoryError, match="same length"):
        plan_robot([], ("j1",), LIM2, (0.0, 0.0), 0.001)
    seg = TrapezoidSweep("j9", (0.5,), (-0.5, 0.5))
    with pytest.raises(TrajectoryError, match=r"segments\[0\] \(trapezoid\): joint 'j9'"):
        plan_robot([seg], ("j1", "j2"), LIM2, (0.0, 0.0), 0.001)


def test_empty_plan_is_one_rest_sample():
    plan = plan_robot([], ("j1", "j2"), LIM2, (0.1, 0.2), 0.001)
    assert len(plan) == 1 and plan.q.tolist() == [[0.1, 0.2]]


# ----------------------------------------------------------------------------- UR10 dynamics


@pytest.fixture(scope="module", params=[3, 6], ids=["ur10-3dof", "ur10-6dof"])
def robot(request):
    return ur_model.ur10(request.param)


def _excitation(robot):
    names = robot.names
    return [
        TrapezoidSweep(names[1], (0.05, 0.3, 1.0), (-2.4, -0.7), {names[2]: (-2.0, 2.0)}),
        MultisineSegment(period_s=10.0, periods=1, harmonics=5, seed=2),
    ]


def test_torque_limits_are_checked_per_payload_and_joint(robot):
    plan = plan_robot(_excitation(robot), robot.names, robot.limits, robot.start, 0.002)
    payloads = (RobotPayload(0.0), RobotPayload(5.0, (0.0, 0.0, 0.1)))
    peaks = check_torques(plan, robot.inverse_dynamics_payload, payloads)
    assert peaks.shape == (2, len(robot.names))
    assert peaks[1, 1] > peaks[0, 1]  # the payload loads the shoulder
    # a shoulder torque limit below the peak of the heavier payload is reported
    tight = list(robot.limits)
    tight[1] = JointLimits(tight[1].position, tight[1].max_velocity, tight[1].max_acceleration,
                           tight[1].max_jerk, 0.5 * (peaks[0, 1] + peaks[1, 1]))
    plan2 = plan_robot(_excitation(robot), robot.names, tight, robot.start, 0.002)
    with pytest.raises(LimitError, match=rf"^payloads\[1\] \(5 kg\): segments\[\d\] .*joint "
                       rf"{robot.names[1]}: torque .* exceeds robot\.joints\.{robot.names[1]}"
                       r"\.limits\.max_torque"):
        check_torques(plan2, robot.inverse_dynamics_payload, payloads)


def test_base_columns_span_the_regressor_at_other_states(robot):
    base = base_columns(robot.regressor, robot.limits, seed=0)
    q, dq, ddq = random_states(robot.limits, 300, seed=99)
    w = robot.regressor(q, dq, ddq)
    s = np.linalg.svd(w, compute_uv=False)
    rank = int(np.sum(s > 1e-8 * s[0]))
    assert base.size == rank < w.shape[1]  # the full regressor is rank deficient
    assert np.isfinite(condition_number(w, base))
    # every column is a combination of the base columns (least-squares residual ~ 0)
    coef, *_ = np.linalg.lstsq(w[:, base], w, rcond=None)
    assert np.abs(w[:, base] @ coef - w).max() <= 1e-8 * np.abs(w).max()
    assert np.array_equal(base, base_columns(robot.regressor, robot.limits, seed=0))


def test_quality_of_a_plan(robot):
    plan = plan_robot(_excitation(robot), robot.names, robot.limits, robot.start, 0.002)
    qual = quality(plan, robot.regressor, inverse_dynamics=robot.inverse_dynamics,
                   max_samples=1500)
    assert qual.stride == math.ceil(len(plan) / 1500)
    # the condition number is the one of the base columns of the decimated plan
    sub = slice(None, None, qual.stride)
    w = robot.regressor(plan.q[sub], plan.dq[sub], plan.ddq[sub])
    s = np.linalg.svd(w[:, qual.base_columns], compute_uv=False)
    assert qual.cond == pytest.approx(s[0] / s[-1], rel=1e-9)
    assert 1.0 < qual.cond < 1e4
    np.testing.assert_allclose(qual.band_share, band_shares(plan.dq, plan.limits))
    assert qual.quadrant_share.shape == (len(robot.names), 4)
    # shoulder and elbow carry gravity: all four quadrants visited, shares sum to 1
    for j in (1, 2):
        assert qual.quadrant_share[j].sum() == pytest.approx(1.0, abs=1e-3)
        assert qual.quadrant_share[j].min() > 0.05
    text = str(qual)
    assert "condition number" in text and QUADRANTS[1] in text and robot.names[2] in text


def test_quadrant_shares_follow_the_power_sign():
    lim = (JointLimits((-1.0, 1.0), 1.0, 1.0, 1.0, 1.0),)
    dq = np.array([[0.5], [-0.5], [-0.5], [0.5], [0.0]])
    tau = np.array([[1.0], [1.0], [-1.0], [-1.0], [3.0]])
    np.testing.assert_allclose(quadrant_shares(dq, tau, lim), [[0.25, 0.25, 0.25, 0.25]])
    np.testing.assert_allclose(quadrant_shares(dq, dq * 2.0, lim), [[0.5, 0.0, 0.5, 0.0]])
    np.testing.assert_allclose(quadrant_shares(dq, -dq, lim), [[0.0, 0.5, 0.0, 0.5]])
    # torque at rounding level relative to the joint's peak counts in no quadrant
    tiny = np.array([[1e-12], [-1e-12], [5.0], [-1e-12], [0.0]])
    np.testing.assert_allclose(quadrant_shares(dq, tiny, lim), [[0.0, 0.25, 0.0, 0.0]])
    np.testing.assert_allclose(quadrant_shares(dq, tiny, lim, tau_rtol=0.0),
                               [[0.25, 0.25, 0.25, 0.25]])


def test_optimiser_lowers_the_condition_number_within_the_limits(robot):
    k = len(robot.names)
    w = 2 * math.pi / 10.0
    res = optimise_multisine(robot.regressor, robot.limits, robot.start, 10.0, 4, fill=0.8,
                             seed=5, max_evaluations=150 * k)
    assert res.stopped in ("converged", "max_evaluations")
    assert res.n_evaluations <= 150 * k
    assert res.cond_end < 0.9 * res.cond_start
    assert (multisine_ratio(res.a, res.b, res.q0, w, robot.limits) <= 0.8 * (1 + 1e-9)).all()
    # starts at rest (projected coefficients), so it plans with rest-to-rest blends
    _, dq, ddq, _ = fourier_eval(res.q0, res.a, res.b, w, np.zeros(1))
    assert np.abs(dq).max() < 1e-9 and np.abs(ddq).max() < 1e-9
    seg = MultisineSegment(10.0, 1, tuple(res.q0), tuple(map(tuple, res.a)),
                           tuple(map(tuple, res.b)))
    plan = plan_robot([seg], robot.names, robot.limits, robot.start, 0.002)
    assert_valid(plan, robot.start)
    # the plan's multi-sine samples give the optimiser's condition number (denser grid)
    (blk,) = plan.fourier
    sel = (plan.t >= blk.t0) & (plan.t < blk.t0 + blk.duration_s)
    w_plan = robot.regressor(plan.q[sel][::5], plan.dq[sel][::5], plan.ddq[sel][::5])
    assert condition_number(w_plan, res.base_columns) == pytest.approx(res.cond_end, rel=0.05)
    # deterministic for a given seed and evaluation budget
    again = optimise_multisine(robot.regressor, robot.limits, robot.start, 10.0, 4, fill=0.8,
                               seed=5, max_evaluations=150 * k)
    np.testing.assert_array_equal(again.a, res.a)
    assert again.cond_end == res.cond_end



def test_decimated_condition_number_matches_the_full_rate_one(robot):
    """quality() builds the regressor on every stride-th sample: the prediction it makes for
    the full-rate log stays within a few per cent (acceptance asks 20 % against a run)."""
    seg = MultisineSegment(period_s=8.0, periods=1, harmonics=5, seed=4)
    plan = plan_robot([seg], robot.names, robot.limits, robot.start, 0.002)
    full = quality(plan, robot.regressor, max_samples=len(plan))
    assert full.stride == 1
    for m in (300, 1000):
        dec = quality(plan, robot.regressor, max_samples=m, base=full.base_columns)
        assert dec.stride > 1
        assert dec.cond == pytest.approx(full.cond, rel=0.05)


@settings(max_examples=60, deadline=None)
@given(data=st.data())
def test_given_coefficients_either_plan_within_limits_or_are_refused(data):
    """Explicit coefficients (not at rest): a plan is within limits, or a LimitError says
    why (e.g. the blend into a fast state would overshoot the position range)."""
    k = data.draw(st.integers(1, 3), label="k")
    limits = data.draw(limits_st(k), label="limits")
    n_harm = data.draw(st.integers(1, 4), label="L")
    rng = np.random.default_rng(data.draw(st.integers(0, 10_000), label="seed"))
    period = data.draw(st.floats(2.0, 10.0), label="period")
    center = np.array([0.5 * (lim.position[0] + lim.position[1]) for lim in limits])
    a, b = rng.standard_normal((2, k, n_harm))
    a, b = fit_coefficients(a, b, center, 2 * math.pi / period, limits,
                            data.draw(st.floats(0.05, 1.3), label="fill"))
    seg = MultisineSegment(period_s=period, center=tuple(center), a=tuple(map(tuple, a)),
                           b=tuple(map(tuple, b)))
    names = tuple(f"j{i}" for i in range(k))
    start = tuple(center)
    try:
        plan = plan_robot([seg], names, limits, start, 0.002)
    except LimitError as err:
        assert str(err).startswith("segments[0] (multisine): joint j")
        return
    assert_valid(plan, start)
