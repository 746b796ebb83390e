"""``jointid fit --robot --q-s scan-joints --refine``: after the found terms' n-dof refit,
one q_s per joint is scanned again with the kept terms (``refinement.q_s_rescan``,
:func:`ident.qs_scan.rescan_qs_joints`), as ``--q-s scan`` rescans its shared q_s
(tests/test_robot_qs_scan.py ``test_cli_refine_after_a_scan_scans_again_with_the_found_terms``).

Data: the simulated 3-dof arm with load-dependent friction, a distinct true q_s per joint
(0.03 / 0.05 / 0.1 rad/s, tests/test_robot_qs_scan.py ``QS_DISTINCT``) and a drag
F_VV dq|dq| on joint 3 that no declared model has; three payload runs as robot CSVs through
the command line. Asserted: the drag is found on joint 3, the rescan ran (no error), each
joint's rescanned q_s is one of its scanned points, the scan's error at the chosen vector is
the smallest of the grid's, and every joint's q_s lies within ``FACTOR_JOINTS`` (1.8, the
per-joint scan's tolerance, below sqrt(0.1 / 0.03) so that one shared q_s cannot pass) of
its truth; the record keeps the fit's q_s per joint, and the printed line says so. And
through :func:`ident.qs_scan.rescan_qs_joints` with the true drag column as the term, over
seeds 11-13: every rescanned q_s within ``FACTOR_JOINTS`` of its truth, joint 3's closer than
the fit's (which the drag pushed up).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from robot_campaigns import ARM3, ARM3_CENTRE, ARM3_PAYLOADS, write_arm_csv

from daq.app.cli import main
from ident.cli_robot import fit_files
from ident.qs_scan import model_at_qs_joints, rescan_qs_joints
from ident.robot import RobotIdentError
from ident.robot.refit import extra_name, model_at_qs, refit_robot
from sim_drivers.arm import ArmEffects, ArmGains, ArmParams, model_reference, simulate_arm
from tests.test_robot_refit import _TrueDrag
from trajectories.robot import load_robot

QS_DISTINCT = (0.03, 0.05, 0.1)  # true q_s of j1, j2, j3 [rad/s]
FACTOR_JOINTS = 1.8  # as tests/test_robot_qs_scan.py (module doc)
F_VV = 3.0  # [N m s^2/rad^2], joint 3's drag (tests/test_robot_qs_scan.py)


def _off(q: float, truth: float) -> float:
    return math.exp(abs(math.log(q / truth)))


def drag_runs(seed: int) -> list:
    """Three payload runs of 10 s of the arm (load-dependent friction, QS_DISTINCT, the drag
    F_VV on joint 3), simulated (also tests/test_drag_chain.py's)."""
    robot = load_robot(ARM3)
    c = ArmParams.from_robot(robot).friction.c_m
    params = ArmParams.from_robot(
        robot, dict(a_m=1.0, b_m=0.25, a_g=1.0, b_g=0.27, d_m=0.0, d_g=0.0, c_g=c,
                    q_s=list(QS_DISTINCT)),
        effects=ArmEffects.make(3, quadratic_viscous={2: {"F_VV": F_VV}}))
    np.testing.assert_array_equal(params.friction.q_s, QS_DISTINCT)
    ref = model_reference(params.model, center=ARM3_CENTRE, fraction=0.9, duration_s=10.0,
                          seed=seed)
    return [simulate_arm(params, ref, ArmGains.for_params(params, payload=p), payload=p,
                         seed=10 * seed + i) for i, p in enumerate(ARM3_PAYLOADS)]


def _files(tmp_path: Path, seed: int) -> list[Path]:
    """:func:`drag_runs` as robot CSVs."""
    return [write_arm_csv(r, tmp_path / f"p{i}.csv") for i, r in enumerate(drag_runs(seed))]


@pytest.mark.parametrize("seed", [11, 12, 13])
def test_rescan_joints_with_the_true_drag(tmp_path, seed):
    """The per-joint rescan with the true drag column as the found term (the refinement's
    own finding varies with the seed: on seeds 12, 13 it adds nothing on joint 3). Measured
    (2026-11-29, with the quadrant band's hysteresis): fit q_s off the truth by a factor
    1.47 / 2.04 / 1.78 on joint 3 (seeds 11, 12, 13), rescanned 1.13 / 1.06 / 1.18; every
    joint within 1.42 after the rescan; the refit's error 0.7140 -> 0.7112 %, 0.6994 ->
    0.6970 %, 0.9706 -> 0.9674 % (the fit's q_s -> the rescanned); F_VV 3.97 / 3.48 / 3.62
    against 3 (not asserted: +-0.16..0.28 at 2 sigma,
    0.25..0.31 with q_s counted as estimated, ``std_qs_``). Not the decimated states' drag
    column (on the true velocity: the same to 0.2 sigma) but the columns chain's paper model
    on decimated rows (E and the quadrants applied to decimated columns, +0.2..+0.85 at the
    true q_s), the sign check's selection on the measured torque, and q_s
    (docs/refinement.md section 8.9; on the states chain F_VV is within 2 ``std_qs_`` after
    the rescan: tests/test_drag_chain.py). With the paper model's products formed at full
    rate (``RobotModel(full_rate=True)``, opt-in) the rescanned q_s of j3 are 0.0913 /
    0.1123 / 0.119 and F_VV 3.43 / 2.83 / 2.56 (+3.3, -1.0, -2.6 ``std_qs_``): the bias of
    the decimated rows gone, q_s's and the sign check's not (docs/refinement.md 8.9)."""
    robot = load_robot(ARM3)
    out = fit_files(robot, _files(tmp_path, seed), model="paper", q_s="scan-joints",
                    prune=False, feasibility=False)
    est, sig = out["_estimators"]["paper"], out["_identification"]
    keep = est.fitted_rows(sig)
    vmax = [float(np.abs(sig.dq[keep[:, j], j]).max()) for j in range(sig.k)]
    terms = [(2, _TrueDrag())]
    res, rf = rescan_qs_joints(est, sig, terms, vmax=vmax, keep=keep)
    at_fit = refit_robot(est, sig, terms, keep=keep)
    joints = list(est.joints_)
    q = [res.q_s[j] for j in joints]
    i = rf.names_.index(extra_name(joints[2], "true_F_VV"))
    off = {j: _off(res.q_s[j], t) for j, t in zip(joints, QS_DISTINCT, strict=True)}
    off_fit = {j: _off(float(v), t) for j, v, t in zip(joints, est.q_s_, QS_DISTINCT,
                                                        strict=True)}
    print(f"\nseed {seed}: fit q_s {np.round(est.q_s_, 4).tolist()} (off {off_fit}), "
          f"rescanned {np.round(q, 4).tolist()} (off {off}); F_VV {rf.coef_[i]:.3f} ± "
          f"{2 * rf.std_[i]:.3f} (2σ; q_s estimated: ± {2 * rf.std_qs_[i]:.3f}; truth {F_VV}); "
          f"error at the fit's q_s "
          f"{at_fit.rel_error['after']['all']:.5%}, rescanned {rf.rel_error['after']['all']:.5%}"
          f" ({res.fits} refits, {res.sweeps} sweeps)")
    np.testing.assert_array_equal(rf.model.q_s_, q)  # the refit returned is at the scan's q_s
    # the scan's model at a q_s vector (one copy) is model_at_qs joint by joint, est untouched
    fit_qs = np.array(est.q_s_)
    chained = est
    for n, v in zip(joints, q, strict=True):
        chained = model_at_qs(chained, v, [n])
    np.testing.assert_array_equal(model_at_qs_joints(est, q).q_s_, chained.q_s_)
    np.testing.assert_array_equal(est.q_s_, fit_qs)
    with pytest.raises(RobotIdentError, match=rf"q_s of \['{joints[1]}'\] must be positive"):
        model_at_qs_joints(est, [q[0], -q[1], q[2]])
    assert rf.rel_error["after"]["all"] == pytest.approx(res.error["all"], rel=1e-12)
    assert max(off.values()) < FACTOR_JOINTS, off
    # the fit without the drag lets joint 3's Stribeck term take part of it (q_s too high:
    # 1.47, 2.04, 1.78 x the truth on seeds 11-13); with the drag the rescan comes closer
    assert off[joints[2]] < off_fit[joints[2]], (off, off_fit)


@pytest.mark.parametrize("seed", [11])
def test_cli_refine_after_scan_joints_scans_each_joint_again(tmp_path, capfd, seed):
    robot = load_robot(ARM3)
    files = _files(tmp_path, seed)
    out = tmp_path / "fit.json"
    code = main(["fit", "--robot", str(ARM3), *map(str, files), "--no-consistency",
                 "--model", "paper", "--q-s", "scan-joints", "--refine", "--max-steps", "1",
                 "--no-prune", "--json", str(out)])
    text, err = capfd.readouterr()
    assert code == 0, err
    rec = json.loads(out.read_text())
    ref_rec = rec["refinement"]
    added = {j: [a["named_effect"] or a["structure"] for a in r.get("added", [])]
             for j, r in ref_rec["joints"].items()}
    assert added[robot.moving[2]], added  # the drag, named or as a generic structure
    assert ref_rec["refit"].get("extras"), ref_rec["refit"]  # a term kept: a rescan to do
    rs = ref_rec["q_s_rescan"]
    assert "error" not in rs, rs
    assert rs["q_s_fit"] == rec["q_s"]  # the record's refit stays at the fit's q_s
    joints = list(robot.moving)
    assert list(rs["q_s"]) == joints
    for j in joints:
        assert rs["q_s"][j] in [d["q_s"] for d in rs["scan"][j]]
    grid = [d["rel_error"] for d in rs["scan"][joints[0]] if d["sweep"] == 0]
    assert rs["rel_error"] <= min(e for e in grid if e is not None) + 1e-12
    off = {j: _off(rs["q_s"][j], t) for j, t in zip(joints, QS_DISTINCT, strict=True)}
    print(f"\nadded {added}; fit q_s {rec['q_s']}, rescanned {rs['q_s']} ({rs['fits']} "
          f"refits, error {rs['rel_error']:.5%}), off {off}")
    assert max(off.values()) < FACTOR_JOINTS, off
    assert "q_s scanned again per joint with the kept terms" in text
