"""``jointid fit --robot --q-s scan`` and ``RobotFit(q_s="scan")`` (issue 24): the paper
model's q_s chosen by the single joint's rule -- the grid of ``qs_grid`` on the fitted rows'
largest |dq|, then a bounded search on log q_s -- on the relative error of the n-dof paper
fit (every joint's rows, every parameter kept), one q_s shared by every joint; the final fit
at that q_s.

Data: the simulated 3-dof arm (sim_drivers.arm, truth q_s 0.03 rad/s on every joint) as a
user's logs (tests/test_robot_fit.py ``noisy_raw_runs``: true positions, applied torque plus
1 % noise), through the real columns chain; and the same arm written as robot CSVs through
the real command line.

Tolerance: the scanned q_s within a factor 1.5 of the truth. Measured on seeds 1-6 (script in
docs/robot-identification.md, 'q_s scan with --robot'): 0.0396, 0.0266, 0.0297, 0.0298, 0.0420,
0.0301 rad/s (worst +40 %); the residual's minimum is shallow (seed 1: 0.8576 % at the
scanned q_s, 0.863 % at the truth) and the fit's other model errors move it. A scan that
returned the grid's first point (0.0038) or last (0.15) is a factor 8 or 5 off.

``--q-s scan-joints`` / ``q_s="scan-joints"`` (one q_s per joint, ``ident.qs_scan.
scan_qs_joints``: coordinate sweeps on the same error over every joint's rows): the same arm
with a distinct true q_s per joint, 0.03 / 0.05 / 0.1 rad/s (``QS_DISTINCT``), each scanned
q_s within ``FACTOR_JOINTS`` = 1.8 of its joint's truth. Measured by
benchmarks/robot_qs_joints.py (``--qs 0.03 0.05 0.1``) on seeds 1-8: the worst ratio over the
joints was 1.73 (seed 5, j3 0.0578), 1.47 on the other seven seeds (seeds 1-2 checked here:
1.46, 1.45); the table is in docs/robot-identification.md, 'One q_s per joint'. The factor is
set below sqrt(0.1 / 0.03) = 1.83 so that a shared q_s cannot pass: whatever its value it is
off by at least that on j1 or j3 (the shared scan chose 0.0625, 0.0754 on seeds 1, 2).
"""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest
from robot_campaigns import ARM3, ARM3_CENTRE, ARM3_PAYLOADS, ROOT, arm_csvs, write_arm_csv
from test_robot_design import example_campaign_runs
from test_robot_fit import _simulate, noisy_raw_runs

from daq.app.cli import main
from ident import DataError
from ident.api import RobotFit
from ident.fitting import fit_models
from ident.preprocess import TORQUE_DELAY
from ident.qs_scan import qs_grid
from sim_drivers.arm import ArmEffects, ArmGains, ArmParams, Payload, model_reference, simulate_arm
from trajectories.robot import load_robot

RX130L = ROOT / "examples" / "robots" / "rx130l.toml"
FACTOR = 1.5  # tolerance on q_s / q_s_true (module doc)
QS_DISTINCT = (0.03, 0.05, 0.1)  # true q_s of j1, j2, j3 [rad/s] (module doc)
FACTOR_JOINTS = 1.8  # tolerance of the per-joint scan (module doc; < sqrt(0.1 / 0.03))


def _off(q: float, truth: float) -> float:
    """Factor between a scanned q_s and the truth (>= 1)."""
    return math.exp(abs(math.log(q / truth)))


@pytest.mark.parametrize("seed", [1, 2])
def test_scanned_qs_near_the_truth(seed):
    params, reg, _, runs = _simulate("arm3", seed=seed)
    truth = params.truth(None)
    q_true = {truth[f"qs{j}"] for j in reg.numbers}
    assert len(q_true) == 1
    q_true = q_true.pop()
    fit = RobotFit(reg.robot, model="paper", q_s="scan", consistency=False,
                   torque_delay=TORQUE_DELAY).fit(noisy_raw_runs(params, runs, seed))
    rec = fit.record_
    q = rec["q_s"]
    assert abs(math.log(q / q_true)) < math.log(FACTOR), (q, q_true)
    scan = [(d["q_s"], d["rel_error"]) for d in rec["q_s_scan"]]
    # the grid and a bounded search after it, the chosen q_s the smallest error evaluated
    assert len(scan) > qs_grid(1.0).size
    assert q == min((s for s in scan if s[1] is not None), key=lambda s: s[1])[0]
    assert [s[0] for s in scan] == sorted(s[0] for s in scan)
    # the final paper fit is at that q_s, on every joint
    # (its record's errors are those after the uncertainty step's pruning, not the scan's)
    np.testing.assert_array_equal(fit.models_["paper"].q_s_, q)
    assert any("q_s scan" in n for n in rec["notes"])


@pytest.fixture(scope="module")
def arm_files(tmp_path_factory):
    """Two payload runs (0 kg, 5 kg) of the simulated arm, as robot CSVs."""
    return arm_csvs(tmp_path_factory.mktemp("arm"), (None, Payload(5.0, [0.0, 0.0, 0.05])))


def _cli(tmp_path, capfd, files, *options):
    out = tmp_path / f"fit{len(list(tmp_path.iterdir()))}.json"
    code = main(["fit", "--robot", str(ARM3), *map(str, files), "--no-consistency",
                 *options, "--json", str(out)])
    text, err = capfd.readouterr()
    assert code == 0, err
    return json.loads(out.read_text()), text


def test_cli_scan_records_the_scan_and_leaves_the_usual_model(tmp_path, capfd, arm_files):
    rec, text = _cli(tmp_path, capfd, arm_files, "--q-s", "scan")
    scan = rec["q_s_scan"]
    assert len(scan) > qs_grid(1.0).size and set(scan[0]) == {"q_s", "rel_error"}
    assert rec["q_s"] in [d["q_s"] for d in scan]
    assert "q_s scan (paper model, one q_s for every joint)" in text
    # the same fit as --q-s <the chosen value>, which has no scan; the usual model is the
    # default run's (it has no q_s)
    given, _ = _cli(tmp_path, capfd, arm_files, "--q-s", repr(rec["q_s"]))
    default, _ = _cli(tmp_path, capfd, arm_files)
    assert "q_s_scan" not in given
    for name, other in (("paper", given), ("usual", default)):
        assert rec["models"][name]["parameters"] == other["models"][name]["parameters"], name


@pytest.mark.parametrize("value", ["abc", "0", "-0.03", "nan", "scan-joint"])
def test_bad_qs_with_robot_is_one_line_before_reading(tmp_path, value):
    r = subprocess.run([sys.executable, "-m", "daq.app.cli", "fit", "--robot", "absent.toml",
                        "absent.csv", "--q-s", value],
                       cwd=tmp_path, capture_output=True, text=True, timeout=300)  # fmt: skip
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2, r.stderr
    assert len(lines) == 1, r.stderr
    assert f"--q-s '{value}'" in lines[0] and "'scan' or 'scan-joints'" in lines[0], lines[0]
    assert "single-joint only" not in lines[0]


def test_api_bad_qs_string_is_one_line(arm_files):
    with pytest.raises(DataError, match=r"^q_s 'scn': expected a number \[rad/s\], 'scan' or "
                                          r"'scan-joints'$"):
        RobotFit(ARM3, model="paper", q_s="scn", consistency=False).fit(arm_files)


def test_cli_refine_after_a_scan_scans_again_with_the_found_terms(tmp_path, capfd):
    """``--q-s scan --refine``: after the found terms' n-dof refit, q_s is scanned again with
    the kept terms (``refinement.q_s_rescan``, as ``jointid demo`` does for a joint). The arm
    of tests/test_qs_rescan.py (load-dependent friction, q_s 0.03 rad/s, a drag F_VV dq|dq|
    on joint 3 that no declared model has), three payload runs as robot CSVs through the
    command line. The rescan must be the smallest error of its own scan and land within
    FACTOR of the truth with the drag refitted."""
    robot = load_robot(ARM3)
    c = ArmParams.from_robot(robot).friction.c_m
    params = ArmParams.from_robot(
        robot, dict(a_m=1.0, b_m=0.25, a_g=1.0, b_g=0.27, d_m=0.0, d_g=0.0, c_g=c),
        effects=ArmEffects.make(3, quadratic_viscous={2: {"F_VV": 3.0}}))
    ref = model_reference(params.model, center=ARM3_CENTRE, fraction=0.9, duration_s=10.0,
                          seed=11)
    files = [write_arm_csv(simulate_arm(params, ref, ArmGains.for_params(params, payload=p),
                                        payload=p, seed=110 + i), tmp_path / f"p{i}.csv")
             for i, p in enumerate(ARM3_PAYLOADS)]
    q_true = float(params.friction.q_s[0])
    rec, text = _cli(tmp_path, capfd, files, "--model", "paper", "--q-s", "scan", "--refine",
                     "--max-steps", "1", "--no-prune")
    ref_rec = rec["refinement"]
    added = [a["named_effect"] for a in ref_rec["joints"][robot.moving[2]]["added"]]
    assert "quadratic_viscous" in added, ref_rec["joints"]
    rs = ref_rec["q_s_rescan"]
    assert "error" not in rs, rs
    scan = [(d["q_s"], d["rel_error"]) for d in rs["scan"] if d["rel_error"] is not None]
    assert rs["q_s"] == min(scan, key=lambda s: s[1])[0]
    assert rs["q_s_fit"] == rec["q_s"]
    assert abs(math.log(rs["q_s"] / q_true)) < math.log(FACTOR), (rs["q_s"], q_true)
    assert "q_s scanned again with the kept terms" in text


@pytest.mark.parametrize("seed", [1, 2])
def test_scan_joints_recovers_each_joints_qs_where_a_shared_scan_cannot(seed):
    params, reg, _, runs = _simulate("arm3", {"q_s": np.array(QS_DISTINCT)}, seed=seed)
    np.testing.assert_array_equal(params.friction.q_s, QS_DISTINCT)
    raw = noisy_raw_runs(params, runs, seed)
    fits = {w: RobotFit(reg.robot, model="paper", q_s=w, consistency=False,
                        torque_delay=TORQUE_DELAY).fit(raw) for w in ("scan-joints", "scan")}
    rec = fits["scan-joints"].record_
    q = rec["q_s"]
    assert list(q) == list(reg.joints)
    off = {j: _off(q[j], t) for j, t in zip(reg.joints, QS_DISTINCT, strict=True)}
    assert max(off.values()) < FACTOR_JOINTS, (q, off)
    # the same assertion on the shared scan's q_s fails (module doc: it must)
    shared = fits["scan"].record_["q_s"]
    assert max(_off(shared, t) for t in QS_DISTINCT) >= FACTOR_JOINTS, shared
    # the final paper fit is at the chosen vector; each joint's q_s is one of its points,
    # the smallest score among its points of the last sweep it was searched in
    np.testing.assert_array_equal(fits["scan-joints"].models_["paper"].q_s_,
                                  [q[j] for j in reg.joints])
    sj = rec["q_s_scan_joints"]
    assert sj["criterion"] == "all" and sj["fits"] > qs_grid(1.0).size
    for j in reg.joints:
        pts = sj["joints"][j]
        assert {d["sweep"] for d in pts} >= {0, 1}
        assert sum(d["sweep"] == 0 for d in pts) == qs_grid(1.0).size  # the shared grid
        last = max(d["sweep"] for d in pts)
        mine = [d for d in pts if d["sweep"] == last and d["rel_error"] is not None]
        assert q[j] in [d["q_s"] for d in pts]
        assert min(d["rel_error"] for d in mine) <= min(
            d["rel_error"] for d in pts if d["q_s"] == q[j]) + 1e-15
    assert sum(n.startswith("q_s scan, joint ") for n in rec["notes"]) == len(reg.joints)


@pytest.fixture(scope="module")
def one_joint_runs():
    """The example campaign (the demo's RX130L joint 3, three payloads, seeds 11-13) as
    one-joint robot runs of examples/robots/rx130l.toml and as single-joint experiments."""
    exps, runs, robot, _ = example_campaign_runs()
    return robot, runs, exps


def test_one_joint_robot_per_joint_scan_is_the_shared_scan(one_joint_runs):
    """A 1-dof robot: the per-joint scan is the shared scan (the same fits, the same q_s,
    the same final paper parameters)."""
    robot, runs, _ = one_joint_runs
    recs = {w: RobotFit(robot, model="paper", q_s=w, consistency=False).fit(runs).record_
            for w in ("scan", "scan-joints")}
    shared, per = recs["scan"], recs["scan-joints"]
    (j,) = robot.moving
    assert per["q_s"] == {j: shared["q_s"]}
    pts = per["q_s_scan_joints"]["joints"][j]
    assert sorted((d["q_s"], d["rel_error"]) for d in pts) == [
        (d["q_s"], d["rel_error"]) for d in shared["q_s_scan"]]
    assert per["q_s_scan_joints"]["fits"] == len(shared["q_s_scan"])
    assert per["q_s_scan_joints"]["sweeps"] == 1 and per["q_s_scan_joints"]["converged"]
    assert per["models"]["paper"]["parameters"] == shared["models"]["paper"]["parameters"]


def test_one_joint_fit_takes_scan_joints_as_scan(one_joint_runs):
    """The single-joint fit (a joint is a 1-dof robot) takes the word as its scan."""
    _, _, exps = one_joint_runs
    a = fit_models(exps, models=("paper",), q_s="scan-joints")
    b = fit_models(exps, models=("paper",), q_s="scan")
    assert a.q_s == b.q_s and a.qs_scan == b.qs_scan


def test_cli_scan_joints_records_each_joint(tmp_path, capfd, arm_files):
    rec, text = _cli(tmp_path, capfd, arm_files, "--model", "paper", "--q-s", "scan-joints")
    joints = rec["robot"]["moving"]
    assert isinstance(rec["q_s"], dict) and list(rec["q_s"]) == joints
    assert "q_s_scan" not in rec
    sj = rec["q_s_scan_joints"]
    assert set(sj) == {"criterion", "fits", "sweeps", "converged", "rel_error", "joints"}
    assert list(sj["joints"]) == joints
    assert set(sj["joints"][joints[0]][0]) == {"q_s", "rel_error", "sweep"}
    assert "q_s scan per joint (paper model, 'scan-joints')" in text
    for j in joints:
        assert sum(line.startswith(f"note: q_s scan, joint {j}: {rec['q_s'][j]:.4g} rad/s")
                   for line in text.splitlines()) == 1, text
    # the same paper fit as the chosen q_s given per joint (no scan)
    given = RobotFit(ARM3, model="paper", q_s=rec["q_s"], consistency=False).fit(arm_files)
    assert "q_s_scan_joints" not in given.record_
    assert given.record_["models"]["paper"]["parameters"] == rec["models"]["paper"]["parameters"]
