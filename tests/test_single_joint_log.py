"""A single-joint campaign's log through the runtime: the logs of before, record for record.

The fingerprints in ``single_joint_log_frozen.json`` were written by the runtime that still
branched on the campaign's class (a ``[joint]`` file read into ``trajectories.campaign.Campaign``
and run by its own path), with ``python tests/test_single_joint_log.py --freeze`` (run once,
by that old code). Since then a ``[joint]`` file is read into a
:class:`~trajectories.robot_campaign.RobotCampaign` with one moving joint and runs through
the one runtime path; ident reads these logs with its single-joint loader, so their metadata
(payload mass and lever arm, joint kind, limits, gains, torque delay, drive scaling) and their
records must be the same. The case: two payloads, two drives on the one joint (each follows
the same plan, one ``/setpoint``), feed-forward gains, a simulated plant, lockstep clock
(deterministic). Each fingerprint holds every metadata record (without the wall time and the
software versions), the channels, and per axis the first 100 cycles of the state and setpoint
plus sums over the whole run.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from daq.protocol.reader import read_run
from daq.runtime.campaign_id import campaign_definition
from daq.runtime.runner import run_campaign
from sim_drivers.plant_config import default_plant
from trajectories.robot_campaign import campaign_from_dict

FROZEN = Path(__file__).with_name("single_joint_log_frozen.json")
#: Integer records compared exactly; floats to RTOL: the reference trajectory's sines differ
#: in their last bit between CPUs (1.5e-16 relative on 5 of 100 q_ref samples on an AMD EPYC
#: against the machine that froze them), and a change of the runtime would move far more.
INTEGER_FIELDS = ("cycle", "counts", "statusword", "flags", "segment")
RTOL = 1e-12
N_FIRST = 100
_VOLATILE = {("result", "wall_s")}
#: metadata written since the freeze, checked on their own: the campaign as loaded
#: (daq.runtime.campaign_id; a run folder holds the logs of one campaign), the velocity the
#: torque loop filtered ([daq] velocity_source; lockstep: the position's difference)
_ADDED = {("campaign", "definition"), ("campaign", "velocity_source")}

_RAW = {
    "name": "sj-log",
    "joint": {"kind": "revolute", "start": 0.05, "limits": {
        "position": [-1.0, 1.0], "max_velocity": 1.0, "max_acceleration": 4.0,
        "max_jerk": 40.0, "max_torque": 700.0}},
    "control": {"cycle_s": 0.002, "kp": 6000.0, "kd": 200.0,
                "feedforward": {"J": 30.0, "MX": 21.0, "Fc": 5.0}},
    "payloads": [{"mass_kg": 0.0, "arm_m": 1.0}, {"mass_kg": 3.5, "arm_m": 1.2}],
    "segments": [{"kind": "trapezoid", "speeds": [0.5], "range": [-0.2, 0.3], "dwell_s": 0.1},
                 {"kind": "sine", "amplitude": 0.3, "frequency_hz": 0.4, "center": 0.0,
                  "periods": 1}],
}


def _fingerprint(out_dir: Path, channel: str) -> dict:
    raw = {**_RAW, "daq": {"channel": channel, "drives": [{"node_id": 1}, {"node_id": 2}]}}
    campaign = campaign_from_dict(raw, "sj-log.toml")
    result = run_campaign(campaign, out_dir=out_dir, simulate=default_plant(), yes=True)
    assert result.ok, result.reason
    out: dict = {}
    for k, run in enumerate(result.runs):
        runs = [read_run(run.path, axis=a) for a in range(2)]
        assert runs[0].metadata["campaign"]["definition"] == campaign_definition(campaign)
        assert runs[0].metadata["campaign"]["velocity_source"] == "difference"
        md = {rec: {key: v for key, v in sorted(fields.items())
                    if (rec, key) not in _VOLATILE | _ADDED}
              for rec, fields in sorted(runs[0].metadata.items()) if rec != "software"}
        md["campaign"]["channel"] = md["campaign"]["channel"].replace(channel, "<ch>")
        md["campaign"]["bus"] = md["campaign"]["bus"].replace(channel, "<ch>")
        for rec in md.values():
            if "channel" in rec:
                rec["channel"] = rec["channel"].replace(channel, "<ch>")
        axes = []
        for a in runs:
            axes.append({
                "n": len(a),
                "first": {f: getattr(a, f)[:N_FIRST].tolist()
                          for f in ("cycle", "q", "dq", "counts", "tau_ref", "statusword",
                                    "flags", "q_ref", "dq_ref", "ddq_ref", "segment")},
                "sums": {f: float(np.nansum(getattr(a, f)))
                         for f in ("q", "dq", "tau_ref", "q_ref", "dq_ref", "ddq_ref")},
                # (the scale of the sums' tolerance, not frozen: a sum near 0 is a difference)
                "abs_sums": {f: float(np.nansum(np.abs(getattr(a, f))))
                             for f in ("q", "dq", "tau_ref", "q_ref", "dq_ref", "ddq_ref")},
                "payload": [a.payload_mass_kg, a.payload_arm_m, a.revolute],
            })
        out[f"payload{k}"] = {"metadata": md, "axes": axes}
    return out


def test_single_joint_log_is_the_frozen_one(tmp_path):
    want = json.loads(FROZEN.read_text())
    got = json.loads(json.dumps(_fingerprint(tmp_path, "sj_log_test")))
    assert got.keys() == want.keys()
    for k in want:
        assert got[k]["metadata"] == want[k]["metadata"], k
        for a, (g, w) in enumerate(zip(got[k]["axes"], want[k]["axes"], strict=True)):
            assert g["n"] == w["n"] and g["payload"] == w["payload"], (k, a)
            for f, v in w["first"].items():
                if f in INTEGER_FIELDS:
                    np.testing.assert_array_equal(g["first"][f], v, err_msg=f"{k} axis {a}: {f}")
                else:  # the last bits of libm differ between CPUs (module doc)
                    np.testing.assert_allclose(g["first"][f], v, rtol=RTOL, atol=0,
                                               err_msg=f"{k} axis {a}: {f}")
            for f, v in w["sums"].items():
                assert g["sums"][f] == pytest.approx(v, rel=0, abs=RTOL * g["abs_sums"][f]), (
                    k, a, f)


if __name__ == "__main__" and "--freeze" in sys.argv:
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        FROZEN.write_text(json.dumps(_fingerprint(Path(d), "sj_log_freeze")) + "\n")
    print(f"wrote {FROZEN} ({FROZEN.stat().st_size} bytes)")
