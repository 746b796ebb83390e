"""The [robot] campaign schema: the example, dispatch between formats, one-line errors."""

from __future__ import annotations

import copy
import math
import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import ur_model
from hypothesis import given, settings
from hypothesis import strategies as st

from trajectories import LimitError, SchemaError, TrajectoryError
from trajectories.campaign import MAX_PLAN_CYCLES, JointLimits
from trajectories.campaign_file import load_campaign
from trajectories.excitation import assess_robot_campaign, optimise_campaign, quality
from trajectories.multi import multisine_ratio, plan_robot_campaign
from trajectories.robot_campaign import (
    DriveSpec,
    MoveSegment,
    MultisineSegment,
    RobotCampaign,
    RobotPayload,
    TrapezoidSweep,
    campaign_from_dict,
)

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
ROBOT3 = EXAMPLES / "campaign_robot3.toml"
SINGLE = EXAMPLES / "campaign.toml"


def raw_robot3() -> dict:
    with ROBOT3.open("rb") as f:
        return tomllib.load(f)


# ----------------------------------------------------------------------------- the example
def test_example_robot_campaign_loads():
    c = campaign_from_dict(raw_robot3(), "campaign_robot3.toml")
    assert isinstance(c, RobotCampaign)
    assert c.robot_file == "robots/arm3.toml"
    assert c.moving == ("j1", "j2", "j3")
    assert c.start == (0.0, -1.2, 1.2)
    # one bus per joint: at 1 kHz one drive takes 39 % of a 1 Mbit/s bus (budget 60 %)
    assert [j.drive for j in c.joints] == [DriveSpec(1, "can0"), DriveSpec(2, "can1"),
                                          DriveSpec(3, "can2")]
    assert c.joints[1].limits == JointLimits((-2.4, -0.3), 1.2, 4.0, 40.0, 400.0)
    assert (c.joints[1].kp, c.joints[1].kd) == (15000.0, 600.0)
    assert c.cycle_s == 0.001
    assert c.payloads == (RobotPayload(0.0), RobotPayload(5.0, (0.0, 0.0, 0.08),
                                                          (0.015, 0.0, 0.0, 0.015, 0.0, 0.01)))
    kinds = [type(s) for s in c.segments]
    assert kinds == [TrapezoidSweep, TrapezoidSweep, TrapezoidSweep, MultisineSegment,
                     MoveSegment]
    sweep = c.segments[0]
    assert sweep.joint == "j2" and sweep.sweep == {"j3": (0.3, 2.5)}
    assert min(sweep.speeds) < 0.1  # the paper's low-velocity band
    ms = c.segments[3]
    assert ms.optimise and ms.a is None and ms.n_harmonics == 5
    assert ms.omega == pytest.approx(2 * math.pi / 10.0)


def test_example_robot_campaign_plans_within_limits_from_and_to_rest():
    c = campaign_from_dict(raw_robot3(), "campaign_robot3.toml")
    plan = plan_robot_campaign(c)
    assert plan.joint_names == c.moving and plan.limits == c.limits
    np.testing.assert_allclose(plan.q[0], c.start)
    np.testing.assert_allclose(plan.q[-1], c.start, atol=1e-9)
    assert np.abs(plan.dq[[0, -1]]).max() < 1e-9
    for j, lim in enumerate(c.limits):
        assert np.abs(plan.dq[:, j]).max() <= lim.max_velocity * (1 + 1e-9)
        assert lim.position[0] - 1e-9 <= plan.q[:, j].min()
        assert plan.q[:, j].max() <= lim.position[1] + 1e-9
    # each joint spends time in the low-velocity band and in the fast one
    shares = plan.band_shares()
    assert (shares[:, 0] > 0.2).all() and (shares[:, 2] > 0.02).all()
    text = str(plan.summary())
    assert "arm3-excitation" in text and "2 payload run(s)" in text
    assert "segments[3] (multisine)" in text and "0-10 % of vmax" in text


def test_single_joint_campaigns_load_as_a_robot_with_one_moving_joint():
    with SINGLE.open("rb") as f:
        raw = tomllib.load(f)
    c = campaign_from_dict(raw, str(SINGLE))
    assert isinstance(c, RobotCampaign)
    assert c == load_campaign(SINGLE) == RobotCampaign.from_dict(raw, str(SINGLE))
    assert c.plant == "joint" and c.moving == ("joint",) and c.joints[0].drive is None
    robot = campaign_from_dict(raw_robot3(), "arm.toml")
    assert robot.plant == "arm" and all(j.drive is not None for j in robot.joints)


def test_quick_is_for_one_moving_joint_of_trapezoids_and_sines():
    c = load_campaign(SINGLE)
    q = c.quick()
    assert q.name == f"{c.name} (quick)" and q.joints == c.joints and q.payloads == c.payloads
    assert [type(s) for s in q.segments] == [type(s) for s in c.segments]
    assert all(s.cycles == 1 and len(s.speeds) == 1 for s in q.segments
               if isinstance(s, TrapezoidSweep))
    assert plan_robot_campaign(q).run_duration_s < 0.3 * plan_robot_campaign(c).run_duration_s
    with pytest.raises(SchemaError, match=r"^arm\.toml: robot\.moving: expected one moving "
                       r"joint for a shortened campaign \(--quick\), got \['j1', 'j2', 'j3'\]$"):
        campaign_from_dict(raw_robot3(), "arm.toml").quick()
    one = replace(campaign_from_dict(raw_robot3(), "arm.toml"), joints=c.joints)
    with pytest.raises(SchemaError, match=r"^arm\.toml: segments\[3\]\.kind: expected "
                       r"'trapezoid' or 'sine' in a shortened campaign \(--quick\), "
                       r"got 'multisine'$"):
        one.quick()


def test_joint_and_robot_together_are_refused():
    raw = raw_robot3()
    raw["joint"] = {"kind": "revolute"}
    with pytest.raises(SchemaError, match=r"^arm\.toml: robot: expected either a \[joint\] "
                       r"or a \[robot\] table, not both$"):
        campaign_from_dict(raw, "arm.toml")
    with pytest.raises(SchemaError, match=r"^arm\.toml: <top level>: expected a table"):
        campaign_from_dict([], "arm.toml")


# ----------------------------------------------------------------------------- mistakes
def _set(raw: dict, path: str, value) -> None:
    keys = path.split(".")
    node = raw
    for k in keys[:-1]:
        node = node[int(k)] if isinstance(node, list) else node[k]
    last = keys[-1]
    if value is _DELETE:
        del node[last]
    elif isinstance(node, list):
        node[int(last)] = value
    else:
        node[last] = value


_DELETE = object()

MISTAKES = [
    # (path to change, new value, key named in the message, expectation fragment)
    ("robot.joints.j2.limits.max_velocity", -1.0, "robot.joints.j2.limits.max_velocity",
     "a number > 0"),
    ("robot.joints.j2.limits.position", [1.0, -1.0], "robot.joints.j2.limits.position",
     "min < max"),
    ("robot.joints.j3.drive.node_id", 200, "robot.joints.j3.drive.node_id", "<= 127"),
    ("robot.joints.j3.drive", {"node_id": 2, "bus": "can1"}, "robot.joints.j3.drive.node_id",
     "a node ID not used by j2 on bus 'can1'"),
    ("robot.joints.j3.drive.speed", 3, "robot.joints.j3.drive.speed", "known keys"),
    ("robot.joints.j9", {"drive": {"node_id": 9}}, "robot.joints.j9", "robot.moving joints"),
    ("robot.joints.j1", _DELETE, "robot.joints.j1", "for every moving joint, it is missing"),
    ("robot.moving", ["j1", "j2", "j2"], "robot.moving", "distinct joint names"),
    ("robot.moving", [], "robot.moving", "a list of at least 1"),
    ("robot.file", 3, "robot.file", "a string"),
    ("robot.start", [0.0, -1.2], "robot.start", "3 positions"),
    ("robot.start", [0.0, 0.0, 1.2], "robot.start[1]", "within robot.joints.j2.limits"),
    ("robot.locked", {"j2": 0.0}, "robot.locked.j2", "not in robot.moving"),
    ("control.gains.j3", _DELETE, "control.gains.j3", "it is missing"),
    ("control.gains.j2.kp", 0.0, "control.gains.j2.kp", "a number > 0"),
    ("control.cycle_s", "1ms", "control.cycle_s", "a number"),
    ("payloads.1.com", [0.0, 0.1], "payloads[1].com", "a list of at least 3"),
    ("payloads.1.com", [0.0, 0.1, 0.2, 0.3], "payloads[1].com", "exactly 3 numbers"),
    ("payloads.1.inertia", [0.1] * 7, "payloads[1].inertia", "exactly 6 numbers"),
    ("payloads.0.mass_kg", -2.0, "payloads[0].mass_kg", ">= 0"),
    ("segments.0.kind", "spline", "segments[0].kind", "one of 'trapezoid'"),
    ("segments.0.joint", "j7", "segments[0].joint", "a moving joint"),
    ("segments.0.range", [-2.5, -0.4], "segments[0].range[0]",
     "within robot.joints.j2.limits.position"),
    ("segments.0.range", [-0.4, -2.3], "segments[0].range", "low < high"),
    ("segments.0.speeds", [0.5, 1.5], "segments[0].speeds[1]", "<= 1"),
    ("segments.0.sweep", {"j2": [-2.0, -1.0]}, "segments[0].sweep.j2", "another joint"),
    ("segments.0.sweep", {"j3": [0.3, 3.5]}, "segments[0].sweep.j3[1]",
     "within robot.joints.j3.limits.position"),
    ("segments.0.amplitude", 1.0, "segments[0].amplitude", "known keys"),
    ("segments.3.a", [[0.1, 0.1]] * 3, "segments[3].b", "both or neither"),
    ("segments.3.harmonics", 1, "segments[3].harmonics", ">= 2"),
    ("segments.3.center", [0.0, 0.0], "segments[3].center", "3 positions"),
    ("segments.3.period_s", 0, "segments[3].period_s", "a number > 0"),
    ("segments.3.fill", 1.2, "segments[3].fill", "<= 1"),
    ("segments.3.optimise", "yes", "segments[3].optimise", "a boolean"),
    ("segments.4.poses", [[0.0, -0.6]], "segments[4].poses", "poses of 3 positions"),
    ("segments.4.poses", [[0.0, -0.6, 0.5], [0.0, -0.6]], "segments[4].poses",
     "rows of different lengths"),
    ("segments.4.poses", [[0.0, -0.6, 3.0]], "segments[4].poses[0][2]",
     "within robot.joints.j3.limits.position"),
    ("name", "  ", "name", "a non-empty string"),
    ("extra", 1, "extra", "known keys"),
]


@pytest.mark.parametrize(("path", "value", "key", "expect"), MISTAKES,
                         ids=[f"{m[0]}={m[1]!r}"[:60] for m in MISTAKES])
def test_mistakes_give_one_line_naming_the_key(path, value, key, expect):
    raw = raw_robot3()
    _set(raw, path, value)
    with pytest.raises(SchemaError) as err:
        campaign_from_dict(raw, "arm.toml")
    msg = str(err.value)
    assert "\n" not in msg
    assert msg.startswith(f"arm.toml: {key}: "), msg
    assert expect in msg, msg
    assert isinstance(err.value, TrajectoryError) and isinstance(err.value, ValueError)


def test_explicit_coefficients_are_kept():
    raw = raw_robot3()
    raw["segments"][3].update(a=[[0.1, 0.0], [0.0, 0.1], [0.05, 0.05]],
                              b=[[0.0, 0.1], [0.1, 0.0], [0.0, 0.0]])
    c = campaign_from_dict(raw, "arm.toml")
    seg = c.segments[3]
    assert seg.a == ((0.1, 0.0), (0.0, 0.1), (0.05, 0.05)) and seg.n_harmonics == 2
    raw["segments"][3]["b"] = [[0.0, 0.1, 0.2]] * 3
    with pytest.raises(SchemaError, match=r"^arm\.toml: segments\[3\]\.b: expected the shape "
                       r"of a \(3 x 2\), got '3 x 3'$"):
        campaign_from_dict(raw, "arm.toml")


@settings(max_examples=60, deadline=None)
@given(data=st.data())
def test_any_limit_set_to_a_non_positive_value_is_named(data):
    raw = raw_robot3()
    joint = data.draw(st.sampled_from(["j1", "j2", "j3"]))
    key = data.draw(st.sampled_from(["max_velocity", "max_acceleration", "max_jerk",
                                     "max_torque"]))
    value = data.draw(st.one_of(st.floats(max_value=0.0, allow_nan=False), st.just(True),
                                st.text(max_size=3)))
    raw["robot"]["joints"][joint]["limits"][key] = value
    with pytest.raises(SchemaError) as err:
        RobotCampaign.from_dict(copy.deepcopy(raw), "arm.toml")
    msg = str(err.value)
    assert msg.startswith(f"arm.toml: robot.joints.{joint}.limits.{key}: expected ")
    assert "\n" not in msg


@settings(max_examples=40, deadline=None)
@given(data=st.data())
def test_valid_limits_and_drives_round_trip(data):
    raw = raw_robot3()
    expect = {}
    ids = data.draw(st.lists(st.integers(1, 127), min_size=3, max_size=3, unique=True))
    for n, node in zip(("j1", "j2", "j3"), ids, strict=True):
        lo = data.draw(st.floats(-3.0, -0.01))
        hi = data.draw(st.floats(0.01, 3.0))
        vals = [data.draw(st.floats(1e-3, 1e3)) for _ in range(4)]
        bus = data.draw(st.sampled_from(["can0", "can1", "vcan0"]))
        raw["robot"]["joints"][n] = {"drive": {"node_id": node, "bus": bus},
                                     "limits": {"position": [lo, hi],
                                                "max_velocity": vals[0],
                                                "max_acceleration": vals[1],
                                                "max_jerk": vals[2], "max_torque": vals[3]}}
        expect[n] = (JointLimits((lo, hi), *vals), DriveSpec(node, bus))
    raw["robot"]["start"] = [0.0, 0.0, 0.0]
    # segments tied to the example's ranges are replaced by one that fits any range
    raw["segments"] = [{"kind": "move", "poses": [[0.0, 0.0, 0.0]]}]
    c = RobotCampaign.from_dict(raw, "arm.toml")
    for j in c.joints:
        assert (j.limits, j.drive) == expect[j.name]


# ----------------------------------------------------------------------------- with dynamics
def test_campaign_torque_check_and_multisine_optimisation_on_ur10_3dof():
    robot = ur_model.ur10(3)
    c = campaign_from_dict(raw_robot3(), "campaign_robot3.toml")
    # the example's 3 joints stand for UR10's shoulder pan, shoulder lift and elbow
    ms_only = replace(c, segments=(c.segments[3],))
    plan = plan_robot_campaign(ms_only, inverse_dynamics=robot.inverse_dynamics_payload)
    q_start = quality(plan, robot.regressor)
    opt, (res,) = optimise_campaign(ms_only, robot.regressor, max_evaluations=300)
    seg = opt.segments[0]
    assert seg.a is not None and np.allclose(seg.a, res.a) and seg.center == c.start
    assert multisine_ratio(res.a, res.b, res.q0, res.omega, c.limits).max() <= seg.fill + 1e-9
    plan_opt = plan_robot_campaign(opt, inverse_dynamics=robot.inverse_dynamics_payload)
    q_opt = quality(plan_opt, robot.regressor, base=q_start.base_columns)
    assert q_opt.cond < 0.9 * q_start.cond
    # a shoulder torque limit below the 5 kg run's peak is refused, naming payload and joint
    tight = list(c.joints)
    tight[1] = replace(tight[1], limits=replace(tight[1].limits, max_torque=20.0))
    with pytest.raises(LimitError, match=r"^payloads\[\d\] \(\d+ kg\): segments\[0\] "
                       r"\(multisine\): joint j2: torque .* exceeds "
                       r"robot\.joints\.j2\.limits\.max_torque 20 N m$"):
        plan_robot_campaign(replace(opt, joints=tuple(tight)),
                            inverse_dynamics=robot.inverse_dynamics_payload)


def test_assessment_is_what_jointid_plan_prints():
    robot = ur_model.ur10(3)
    c = campaign_from_dict(raw_robot3(), "campaign_robot3.toml")
    c = replace(c, segments=c.segments[3:])  # multi-sine and moves: quick
    a = assess_robot_campaign(c, regressor=robot.regressor,
                              inverse_dynamics=robot.inverse_dynamics_payload)
    assert a.optimised == () and a.campaign is c
    assert a.peak_torque.shape == (2, 3) and len(a.quadrants) == 2
    # the heavier payload loads the shoulder more; the quadrant shares are per payload
    assert a.peak_torque[1, 1] > a.peak_torque[0, 1]
    assert a.quality.cond == pytest.approx(quality(a.plan, robot.regressor).cond)
    text = str(a)
    assert text.count("quadrants of (dq, tau_out), payload") == 2
    assert f"{a.quality.cond:.4g}" in text and "peak |tau| [N m]" in text
    assert text.count("0-10 % of vmax") == 1  # bands printed once, with the plan
    with pytest.raises(TrajectoryError, match="needs the robot's regressor"):
        assess_robot_campaign(c, optimise=True)
    bare = assess_robot_campaign(c)  # no dynamics: the plan summary only
    assert bare.quality is None and bare.peak_torque is None and str(bare) == str(
        bare.plan.summary())


def test_a_joint_cruising_at_zero_load_is_named_by_the_plan():
    """The base yaw carries no gravity: its trapezoid alone cruises at zero output torque,
    where the paper model's quadrant is decided by noise; the plan names it. Multi-sines of
    every joint accelerate it all the time: no note."""
    robot = ur_model.ur10(3)
    c = campaign_from_dict(raw_robot3(), "campaign_robot3.toml")
    yaw = replace(c, segments=(c.segments[2],))
    assert isinstance(yaw.segments[0], TrapezoidSweep) and yaw.segments[0].joint == "j1"
    a = assess_robot_campaign(yaw, regressor=robot.regressor,
                              inverse_dynamics=robot.inverse_dynamics_payload)
    flagged = a.zero_load_joints()
    assert list(flagged) == ["j1"] and flagged["j1"] > 0.2
    assert "note: j1: " in str(a) and "at zero output torque" in str(a)
    ms = replace(c, segments=c.segments[3:4])
    b = assess_robot_campaign(ms, regressor=robot.regressor,
                              inverse_dynamics=robot.inverse_dynamics_payload)
    assert b.zero_load_joints() == {} and "note: " not in str(b)


def test_whole_plan_objective_predicts_the_plans_condition_number():
    """With the other segments as background, the optimiser's condition number is the one
    quality() gives for the planned campaign, before and after the optimisation."""
    robot = ur_model.ur10(3)
    c = campaign_from_dict(raw_robot3(), "campaign_robot3.toml")
    c = replace(c, segments=(c.segments[2], c.segments[3]))  # base yaw trapezoids + sine
    before = quality(plan_robot_campaign(c), robot.regressor)
    opt, (res,) = optimise_campaign(c, robot.regressor, max_evaluations=200,
                                    whole_plan=True)
    after = quality(plan_robot_campaign(opt), robot.regressor, base=before.base_columns)
    assert np.array_equal(res.base_columns, before.base_columns)
    assert res.cond_start == pytest.approx(before.cond, rel=0.05)
    assert res.cond_end == pytest.approx(after.cond, rel=0.05)
    assert after.cond < before.cond


@pytest.mark.parametrize(("segment", "key", "value"), [
    ({"kind": "multisine", "period_s": 10.0, "periods": 400}, "periods", 400),
    ({"kind": "sine", "joint": "j2", "amplitude": 0.2, "frequency_hz": 0.5, "center": -1.3,
      "periods": 2000}, "periods", 2000),
    ({"kind": "trapezoid", "joint": "j1", "speeds": [0.01], "range": [-1.0, 1.0],
      "cycles": 40}, "cycles", 40),
    ({"kind": "move", "poses": [[0.0, -1.2, 1.4]] * 20, "dwell_s": 200.0}, "poses", 20),
])
def test_a_plan_beyond_max_plan_cycles_is_refused_naming_its_longest_segment(segment, key,
                                                                             value):
    raw = raw_robot3()
    raw["segments"] = [raw["segments"][0], segment]
    with pytest.raises(SchemaError, match=rf"^arm\.toml: segments\[1\]\.{key}: expected a plan "
                       rf"of at most {MAX_PLAN_CYCLES} cycles per payload .*, got {value}$"):
        campaign_from_dict(raw, "arm.toml")
