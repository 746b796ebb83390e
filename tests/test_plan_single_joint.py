"""A single joint planned as a robot with one moving joint: the plans of before, sample for sample.

The fingerprints in ``plan_single_joint_frozen.json`` were written by the single-joint planner
that ``trajectories.plan`` had before it was folded into the robot planner
(:func:`trajectories.multi.plan_robot_campaign`), with ``python
tests/test_plan_single_joint.py --freeze`` (run once, by that old code). Each holds the sample
count, the segment boundaries, the pieces, sums of q, dq, ddq and their values at 101 spread
samples: small enough to commit, and any change of a sample beyond rounding moves a sum or a
spread value. The cases: the example campaign (``jointid demo`` runs it), its quick form, the
small sine campaign of the daq tests, the campaign of the refinement tests and a prismatic
joint with several speeds, cycles, no dwell and an off-centre start; and two robot campaigns
(``robot3``, ``ur10_demo``: the former robot planner's plans, kept too).
"""

from __future__ import annotations

import json
import re
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from trajectories import SchemaError

ROOT = Path(__file__).resolve().parents[1]
FROZEN = Path(__file__).with_name("plan_single_joint_frozen.json")
N_SPREAD = 101
# rounding only: the phases' start times are sums of the same durations
RTOL, ATOL = 1e-12, 1e-12

_DAQ_SMALL = {
    "name": "small",
    "joint": {"kind": "revolute", "limits": {
        "position": [-1.0, 1.0], "max_velocity": 1.0, "max_acceleration": 4.0,
        "max_jerk": 40.0, "max_torque": 700.0}},
    "control": {"cycle_s": 0.001, "kp": 6000.0, "kd": 200.0,
                "feedforward": {"J": 30.0, "MX": 21.0}},
    "payloads": [{"mass_kg": 3.0 * k, "arm_m": 1.0} for k in range(3)],
    "segments": [{"kind": "sine", "amplitude": 0.3, "frequency_hz": 0.5,
                  "center": 0.0, "periods": 1}],
}
_PRISMATIC = {
    "name": "slide",
    "joint": {"kind": "prismatic", "start": 0.12, "limits": {
        "position": [-0.2, 0.3], "max_velocity": 0.4, "max_acceleration": 2.5,
        "max_jerk": 30.0, "max_torque": 900.0}},
    "control": {"cycle_s": 0.002, "kp": 5000.0, "kd": 100.0,
                "feedforward": {"J": 4.0, "Fc": 10.0, "Fv": 3.0}},
    "payloads": [{"mass_kg": 0.0, "arm_m": 0.0}, {"mass_kg": 2.5, "arm_m": 0.0}],
    "segments": [
        {"kind": "trapezoid", "speeds": [0.2, 0.6, 1.0], "range": [-0.15, 0.25],
         "dwell_s": 0.0, "cycles": 2},
        {"kind": "sine", "amplitude": 0.1, "frequency_hz": 0.5, "center": 0.05,
         "periods": 3},
        {"kind": "trapezoid", "speeds": [0.05], "range": [0.0, 0.1], "dwell_s": 0.25},
    ],
}


# robot campaigns (multi-sines as written), frozen from the former robot planner
_ROBOTS = {"robot3": "examples/campaign_robot3.toml",
           "ur10_demo": "examples/campaign_ur10_demo.toml"}
#: The UR10 demo campaign's shoulder-pan segment when the plans were frozen; the example now
#: moves the pan with two sines (docs/campaign-robot.md), the frozen plan is of this one.
_UR10_PAN_TRAPEZOID = {"kind": "trapezoid", "joint": "shoulder_pan_joint",
                       "speeds": [0.06, 0.3, 1.0], "range": [-0.6, 0.6], "dwell_s": 0.2}


def _robot_campaign(name: str):
    """The robot campaign ``name`` of ``_ROBOTS`` as it was when the plans were frozen."""
    import tomllib

    from trajectories.robot_campaign import campaign_from_dict

    path = ROOT / _ROBOTS[name]
    raw = tomllib.loads(path.read_text())
    if name == "ur10_demo":
        segs = raw["segments"]
        pan = [i for i, g in enumerate(segs)
               if g.get("joint") == "shoulder_pan_joint" and g["kind"] == "sine"]
        assert pan, "the UR10 demo campaign no longer moves the pan with sines"
        raw["segments"] = segs[:pan[0]] + [_UR10_PAN_TRAPEZOID] + segs[pan[-1] + 1:]
    return campaign_from_dict(raw, source=str(path))


def _campaigns() -> dict:
    """The single-joint cases, each a [joint] file read as a robot with one moving joint."""
    from trajectories.campaign_file import load_campaign
    from trajectories.robot_campaign import RobotCampaign

    example = load_campaign(ROOT / "examples" / "campaign.toml")
    return {
        "example": example,
        "example_quick": example.quick(),
        "daq_small": RobotCampaign.from_dict(_DAQ_SMALL, "small.toml"),
        # the campaign of tests/test_refine_sim.py: the example's slow trapezoids and sine,
        # one payload, no feed-forward
        "refine": replace(example, name="refine-sim", payloads=example.payloads[:1],
                          segments=tuple(example.segments[i] for i in (0, 1, 3)),
                          joints=(replace(example.joints[0], feedforward={}),)),
        "prismatic": RobotCampaign.from_dict(_PRISMATIC, "slide.toml"),
    }


def fingerprint(ref) -> dict:
    """What is compared: count, segments, pieces, sums and spread samples of one reference."""
    n = len(ref.t)
    idx = np.unique(np.linspace(0, n - 1, N_SPREAD).round().astype(int))
    seg = np.asarray(ref.segment)
    return {
        "n": n,
        "cycle_s": ref.cycle_s,
        "segment_names": list(ref.segment_names),
        "segment_starts": [0, *(int(i) + 1 for i in np.flatnonzero(seg[1:] != seg[:-1]))],
        "pieces": [[p.kind, p.segment, p.t0, p.t1] for p in ref.pieces],
        "index": idx.tolist(),
        **{f"{k}_at": np.asarray(getattr(ref, k))[idx].tolist() for k in ("q", "dq", "ddq")},
        **{f"{k}_sum": float(np.sum(getattr(ref, k))) for k in ("q", "dq", "ddq")},
        **{f"{k}_abs_sum": float(np.sum(np.abs(getattr(ref, k)))) for k in ("q", "dq", "ddq")},
    }


def _freeze() -> None:
    """Write the fingerprints with the planners of the checkout (done once, before the
    single-joint planner was folded into the robot one)."""
    from trajectories.multi import plan_robot_campaign
    from trajectories.plan import plan_campaign

    out = {name: fingerprint(plan_campaign(c).reference) for name, c in _campaigns().items()}
    # (the cases were Campaign objects of the [joint] format then)
    for name in _ROBOTS:
        out[name] = fingerprint(plan_robot_campaign(_robot_campaign(name)))
    FROZEN.write_text("{\n" + ",\n".join(f"{json.dumps(k)}: {json.dumps(v)}"
                                         for k, v in out.items()) + "\n}\n")
    print(f"wrote {FROZEN} ({FROZEN.stat().st_size} bytes)")


@pytest.fixture(scope="module")
def frozen() -> dict:
    return json.loads(FROZEN.read_text())


@pytest.fixture(scope="module")
def campaigns() -> dict:
    return _campaigns()


@pytest.mark.parametrize("name", ["example", "example_quick", "daq_small", "refine",
                                  "prismatic", "robot3", "ur10_demo"])
def test_single_joint_plan_is_the_frozen_one(name, frozen, campaigns):
    from trajectories.plan import plan_campaign

    want = frozen[name]
    if name in _ROBOTS:  # the robot plans of before are kept too
        from trajectories.multi import plan_robot_campaign

        got = fingerprint(plan_robot_campaign(_robot_campaign(name)))
    else:
        got = fingerprint(plan_campaign(campaigns[name]).reference)
    assert got["n"] == want["n"] and got["cycle_s"] == want["cycle_s"]
    assert got["segment_names"] == want["segment_names"]
    assert got["segment_starts"] == want["segment_starts"]
    assert [p[:2] for p in got["pieces"]] == [p[:2] for p in want["pieces"]]
    np.testing.assert_allclose([p[2:] for p in got["pieces"]],
                               [p[2:] for p in want["pieces"]], rtol=RTOL, atol=ATOL)
    assert got["index"] == want["index"]
    for k in ("q", "dq", "ddq"):
        np.testing.assert_allclose(got[f"{k}_at"], want[f"{k}_at"], rtol=RTOL, atol=ATOL,
                                   err_msg=f"{name}: {k}")
        # a sum of n samples of rounding-level differences: n * 1e-12 at most
        for s in ("sum", "abs_sum"):
            assert got[f"{k}_{s}"] == pytest.approx(want[f"{k}_{s}"], rel=RTOL,
                                                    abs=ATOL * want["n"]), f"{name}: {k}_{s}"


# ----------------------------------------------------------------------------- one model
def test_a_joint_campaign_is_a_robot_with_one_moving_joint_without_loss(campaigns):
    from trajectories.robot_campaign import SineSegment, TrapezoidSweep

    r = campaigns["prismatic"]  # _PRISMATIC, read as a robot with one moving joint
    (j,) = r.joints
    assert r.robot_file == "" and r.moving == ("joint",)
    assert r.plant == "joint"
    assert (j.kind, j.limits.position, j.limits.max_velocity, j.limits.max_torque, j.kp, j.kd,
            j.key, j.drive) == ("prismatic", (-0.2, 0.3), 0.4, 900.0, 5000.0, 100.0,
                                "joint", None)
    assert dict(j.feedforward) == {"J": 4.0, "MX": 0.0, "MY": 0.0, "Fc": 10.0, "Fv": 3.0}
    assert r.start == (0.12,) and r.cycle_s == 0.002
    assert r.control.velocity_cutoff_hz == 100.0
    assert [(p.mass_kg, p.arm_m, p.com) for p in r.payloads] == [
        (0.0, 0.0, (0.0, 0.0, 0.0)), (2.5, 0.0, (0.0, 0.0, 0.0))]
    assert r.name == "slide" and r.source == "slide.toml" and r.daq == {}
    # the same segments: one trapezoid and one sine kind for both formats, of the only
    # moving joint ("")
    assert [type(s) for s in r.segments] == [TrapezoidSweep, SineSegment, TrapezoidSweep]
    assert {s.joint for s in r.segments} == {""} and not r.segments[0].sweep
    assert r.segments[0].speeds == (0.2, 0.6, 1.0) and r.segments[0].cycles == 2


def test_limit_and_torque_messages_name_the_joint_table(campaigns):
    """A [joint] campaign's errors name ``joint.limits.*`` (its file's keys), in one line."""
    from trajectories import LimitError
    from trajectories.multi import plan_robot_campaign
    from trajectories.robot_campaign import RobotPayload

    c = campaigns["daq_small"]
    heavy = replace(c, payloads=(RobotPayload(300.0, (1.0, 0.0, 0.0), arm_m=1.0),))
    with pytest.raises(LimitError, match=r"^payloads\[0\] \(300 kg at 1 m\): segments\[0\] "
                       r"\(sine\): torque [\d.-]+ N m at t = [\d.]+ s exceeds "
                       r"joint\.limits\.max_torque 700 N m$"):
        plan_robot_campaign(heavy)
    (j,) = c.joints
    slow = replace(c, joints=(replace(j, limits=replace(j.limits, max_velocity=0.5)),))
    with pytest.raises(LimitError, match=r"^segments\[0\] \(sine\): peak velocity 0\.9425 "
                       r"rad/s exceeds joint\.limits\.max_velocity 0\.5 rad/s$"):
        plan_robot_campaign(slow)


def test_the_joint_robot_regressor_is_the_feedforward_model():
    """The 1-dof robot built in memory for a [joint] campaign: its regressor with ZZ1 = J,
    MX1 = MX, MY1 = -MY, FC1, FV1 and its payload torque give the feed-forward torque
    estimate the planner checks (wherever the joint moves: the regressor's Coulomb column
    has a deadband)."""
    pytest.importorskip("pinocchio")
    from trajectories.multi import feedforward_dynamics, plan_robot_campaign
    from trajectories.robot_campaign import RobotCampaign
    from trajectories.robot_model import RobotDynamics, robot_for_campaign

    raw = json.loads(json.dumps(_DAQ_SMALL))
    raw["control"]["feedforward"] = {"J": 30.0, "MX": 21.0, "MY": -7.5, "Fc": 12.0, "Fv": 4.0}
    raw["segments"].append({"kind": "trapezoid", "speeds": [0.05, 0.6], "range": [-0.8, 0.9]})
    c = RobotCampaign.from_dict(raw, "ff.toml")
    robot = robot_for_campaign(c)
    assert robot.moving == ("joint",) and not robot.inertial and robot.source == "ff.toml"
    assert robot.limits["joint"].dq_max == 1.0 and robot.limits["joint"].tau_max == 700.0
    dyn = RobotDynamics(robot)
    plan = plan_robot_campaign(c)
    q, dq, ddq = plan.q[::7], plan.dq[::7], plan.ddq[::7]
    ff = c.joints[0].feedforward
    theta = dict.fromkeys(dyn.names, 0.0)
    theta.update(ZZ1=ff["J"], MX1=ff["MX"], MY1=-ff["MY"], FC1=ff["Fc"], FV1=ff["Fv"])
    w = dyn.regressor(q, dq, ddq) @ np.array([theta[n] for n in dyn.names])
    moving = np.abs(dq[:, 0]) > dyn.deadband[0]
    assert moving.sum() > 0.8 * len(q)
    for pay in c.payloads:
        tau = w + dyn.inverse_dynamics(q, dq, ddq, pay)[:, 0]
        want = feedforward_dynamics(c.joints)(q, dq, ddq, pay)[:, 0]
        np.testing.assert_allclose(tau[moving], want[moving], rtol=1e-12, atol=1e-9)
    # the base of the 1-dof robot: ZZ1 + Ia1, MX1, MY1 and the three friction columns
    assert np.linalg.matrix_rank(dyn.regressor(q, dq, ddq)) == 6


def test_jointid_plan_assesses_a_joint_as_a_robot(capsys):
    """``jointid plan`` takes one path for both formats: a [joint] campaign also gets the
    condition number of its 1-dof robot's base regressor and the quadrant shares of the
    output torque (its feed-forward model without friction) per payload."""
    pytest.importorskip("pinocchio")
    from daq.app.cli import main

    assert main(["plan", str(ROOT / "examples" / "campaign.toml")]) == 0
    out = capsys.readouterr().out
    assert "(its [joint] table, no robot file): moving joint" in out
    m = re.search(r"excitation: condition number ([\d.]+) of the base regressor \(6 base "
                  r"columns", out)
    assert m and 1.0 < float(m.group(1)) < 1e3
    quads = re.findall(r"^joint\s+([\d.]+)%\s+([\d.]+)%\s+([\d.]+)%\s+([\d.]+)%", out, re.M)
    assert len(quads) == 3  # one row per payload
    for row in quads:  # the example moves both ways under both signs of gravity
        assert min(float(x) for x in row) > 10.0
    assert out.count("at 1.277 m") == 6  # the payloads, in the torque table and quadrants


# ----------------------------------------------------------------------------- robot sine
def test_a_robot_campaign_plays_an_exact_sine_of_one_joint():
    """The single-joint sine is a segment kind of every campaign: j2 plays it exactly between
    its blends while j1 and j3 hold."""
    from robot_campaigns import arm3_raw

    from trajectories.multi import plan_robot_campaign
    from trajectories.robot_campaign import RobotCampaign

    seg = {"kind": "sine", "joint": "j2", "amplitude": 0.5, "frequency_hz": 0.3,
           "center": -1.3, "periods": 2}
    c = RobotCampaign.from_dict(arm3_raw(segments=[seg]), "arm3-sine.toml")
    plan = plan_robot_campaign(c)
    (sine,) = [p for p in plan.pieces if p.kind == "sine"]
    assert sine.joint == 1 and sine.t1 - sine.t0 == pytest.approx(2 / 0.3, rel=1e-12)
    assert [p.kind for p in plan.pieces] == ["blend_in", "sine", "blend_out", "return"]
    inside = (plan.t >= sine.t0) & (plan.t <= sine.t1)
    w = 2 * np.pi * 0.3
    tau = plan.t[inside] - sine.t0
    np.testing.assert_allclose(plan.q[inside, 1], -1.3 - 0.5 * np.cos(w * tau), atol=1e-9)
    np.testing.assert_allclose(plan.dq[inside, 1], 0.5 * w * np.sin(w * tau), atol=1e-9)
    np.testing.assert_allclose(plan.q[:, [0, 2]], np.tile(c.start[::2], (len(plan), 1)),
                               atol=1e-12)
    assert np.all(plan.dq[:, [0, 2]] == 0.0)
    for key, value, msg in (("joint", "j9", "segments[0].joint: expected a moving joint"),
                            ("amplitude", 1.5, "segments[0].amplitude: expected center +/- "
                             "amplitude within robot.joints.j2.limits.position")):
        bad = arm3_raw(segments=[{**seg, key: value}])
        with pytest.raises(SchemaError, match=re.escape(msg)):
            RobotCampaign.from_dict(bad, "arm3-sine.toml")


if __name__ == "__main__":
    if sys.argv[1:] == ["--freeze"]:
        _freeze()
    else:
        raise SystemExit("usage: python tests/test_plan_single_joint.py --freeze")
