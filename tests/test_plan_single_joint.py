"""A single joint planned as a robot with one moving joint: the plans of before, sample for sample.

The fingerprints in ``plan_single_joint_frozen.json`` were written by the single-joint planner
that ``trajectories.plan`` had before it was folded into the robot planner
(:func:`trajectories.multi.plan_robot_campaign`), with ``python
tests/test_plan_single_joint.py --freeze`` (run once, by that old code). Each holds the sample
count, the segment boundaries, the pieces, sums of q, dq, ddq and their values at 101 spread
samples: small enough to commit, and any change of a sample beyond rounding moves a sum or a
spread value. The cases: the example campaign (``jointid demo`` runs it), its quick form, the
small sine campaign of the daq tests, the campaign of the refinement tests and a prismatic
joint with several speeds, cycles, no dwell and an off-centre start.
"""

from __future__ import annotations

import json
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

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
_REFINE = """
name = "refine-sim"
[joint]
kind = "revolute"
[joint.limits]
position = [-1.0, 2.4]
max_velocity = 1.2
max_acceleration = 4.0
max_jerk = 40.0
max_torque = 700.0
[control]
cycle_s = 0.001
kp = 20000.0
kd = 1000.0
[[payloads]]
mass_kg = 0.0
arm_m = 1.277
[[segments]]
kind = "trapezoid"
speeds = [0.03]
range = [1.0, 2.1]
dwell_s = 0.5
[[segments]]
kind = "trapezoid"
speeds = [0.08]
range = [-0.9, 2.3]
dwell_s = 0.5
[[segments]]
kind = "sine"
amplitude = 1.6
frequency_hz = 0.1
center = 0.7
periods = 2
"""
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


def _campaigns() -> dict:
    from trajectories.campaign import Campaign
    from trajectories.campaign_file import load_campaign

    example = load_campaign(ROOT / "examples" / "campaign.toml")
    return {
        "example": example,
        "example_quick": example.quick(),
        "daq_small": Campaign.from_dict(_DAQ_SMALL, "small.toml"),
        "refine": Campaign.from_dict(tomllib.loads(_REFINE), "refine.toml"),
        "prismatic": Campaign.from_dict(_PRISMATIC, "slide.toml"),
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
    from trajectories.plan import plan_campaign

    out = {name: fingerprint(plan_campaign(c).reference) for name, c in _campaigns().items()}
    FROZEN.write_text(json.dumps(out, indent=1) + "\n")
    print(f"wrote {FROZEN} ({FROZEN.stat().st_size} bytes)")


@pytest.fixture(scope="module")
def frozen() -> dict:
    return json.loads(FROZEN.read_text())


@pytest.fixture(scope="module")
def campaigns() -> dict:
    return _campaigns()


@pytest.mark.parametrize("name", ["example", "example_quick", "daq_small", "refine",
                                  "prismatic"])
def test_single_joint_plan_is_the_frozen_one(name, frozen, campaigns):
    from trajectories.plan import plan_campaign

    want = frozen[name]
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


if __name__ == "__main__":
    if sys.argv[1:] == ["--freeze"]:
        _freeze()
    else:
        raise SystemExit("usage: python tests/test_plan_single_joint.py --freeze")
