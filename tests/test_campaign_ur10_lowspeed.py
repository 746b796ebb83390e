"""examples/campaign_ur10_lowspeed.toml: the UR10 demo campaign plus one multi-sine with given
coefficients that holds the shoulder pan at low speeds under a load of either sign (issue 25,
docs/monitoring.md "Low-speed campaign for the pan").

The checks are on the plan and the robot model's rigid-body torque (pinocchio), not on any
identification result: the segment must do what its comment says (pan velocity held at
+-0.5, 1, 2 q_s, the pan's output torque of both signs while it crawls), the rest of the file
must be the demo's, and the monitor bench's derived campaigns must keep the segment as it is.
"""

from __future__ import annotations

import importlib.util
import tomllib
from pathlib import Path

import numpy as np
import pinocchio as pin

from trajectories.campaign_file import load_campaign
from trajectories.multi import plan_robot_campaign
from trajectories.robot_model import robot_for_campaign

ROOT = Path(__file__).resolve().parents[1]
LOW = ROOT / "examples" / "campaign_ur10_lowspeed.toml"
DEMO = ROOT / "examples" / "campaign_ur10_demo.toml"
LEVELS = (0.015, -0.015, 0.03, -0.03, 0.06, -0.06)  # [rad/s], 2 s each, as the file says


def _given_multisine(raw: dict) -> int:
    """Index of the one segment that is a multi-sine with given coefficients."""
    idx = [i for i, s in enumerate(raw["segments"]) if s["kind"] == "multisine" and "a" in s]
    assert len(idx) == 1, idx
    return idx[0]


def test_lowspeed_campaign_is_the_demo_plus_one_segment():
    low, demo = (tomllib.loads(p.read_text()) for p in (LOW, DEMO))
    i = _given_multisine(low)
    segs = low.pop("segments")
    assert segs[:i] + segs[i + 1:] == demo.pop("segments")
    assert low.pop("name") != demo.pop("name")
    assert low == demo


def test_slow_segment_holds_the_pan_slow_under_a_load_of_either_sign():
    from sim_drivers.arm import ArmParams

    c = load_campaign(LOW)
    i = _given_multisine(tomllib.loads(LOW.read_text()))
    plan = plan_robot_campaign(c)
    (block,) = [f for f in plan.fourier if f.segment == i]
    assert block.periods == 1
    arm = ArmParams.from_robot(robot_for_campaign(c))
    data = arm.model.createData()
    step = c.segments[i].period_s / len(LEVELS)
    for k, level in enumerate(LEVELS):
        # the flat part of each level: its middle 1.2 s of the series (after the blend in)
        sel = (plan.t >= block.t0 + k * step + 0.4) & (plan.t < block.t0 + (k + 1) * step - 0.4)
        assert np.all(plan.segment[sel] == i)
        assert sel.sum() > 0.9 * 1.2 / c.cycle_s
        assert np.abs(plan.dq[sel, 0] / level - 1).max() < 0.03, (level, plan.dq[sel, 0])
        # the pan's output torque (links only; its own acceleration is about 0 here) takes
        # both signs beyond 1 N m on a fifth of the samples each (its dry friction: ~2 N m)
        tau = np.array([pin.rnea(arm.model, data, plan.q[r], plan.dq[r], plan.ddq[r])[0]
                        for r in np.flatnonzero(sel)])
        assert (tau > 1.0).mean() > 0.2 and (tau < -1.0).mean() > 0.2, (level, tau)
    # the joints other than the pan and the lift hold during the series
    rows = (plan.t >= block.t0) & (plan.t < block.t0 + block.duration_s)
    assert np.abs(plan.dq[rows, 2:]).max() == 0.0


def _bench():
    spec = importlib.util.spec_from_file_location(
        "bench_monitor", ROOT / "benchmarks" / "bench_monitor.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_monitor_bench_keeps_the_given_multisine(tmp_path):
    bm = _bench()
    bm.SOURCE["campaign"] = LOW
    # only the seeded multi-sine is varied: the plan parts are the demo's plus the segment
    other_s, period_s = bm._plan_parts()
    assert period_s == 10.0
    given = load_campaign(LOW).segments[_given_multisine(tomllib.loads(LOW.read_text()))]
    for name, only in (("calibrate", False), ("detect", True)):
        c = load_campaign(bm._campaign(tmp_path, name, seed=13, periods=2, multisine_only=only))
        kept = [s for s in c.segments if getattr(s, "a", None) is not None]
        seeded = [s for s in c.segments if type(s).__name__ == "MultisineSegment"
                  and s.a is None]
        assert [(s.seed, s.periods) for s in seeded] == [(13, 2)]
        assert kept == ([] if only else [given])
