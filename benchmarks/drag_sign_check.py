"""F_VV of the drag arm (docs/refinement.md §8.9) with the sign check on the measured
low-passed torque (the default), on the first usual fit's PREDICTED total torque, or off.

Is cause 2 of §8.9 (the sign check selects rows on the measured torque) a selection on the
noise? If it were, comparing the load's sign with the model's own predicted torque instead
(no measured quantity in the selection) would bring the spread over seeds back to the
unchecked fit's.

usage: python benchmarks/drag_sign_check.py {true,rescan} {measured,model,off} SEED...

One JSON line per seed: the refit's F_VV with the true drag column (truth 3 N m s^2/rad^2),
its sigma (eq. 15) and ``std_qs_``, the fit's error and the share of rows kept.
"""
from __future__ import annotations

import dataclasses
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]

from robot_campaigns import ARM3, write_arm_csv  # noqa: E402
from test_qs_joints_refine import drag_runs  # noqa: E402
from test_robot_refit import _TrueDrag  # noqa: E402

import ident.cli_robot as cli_robot  # noqa: E402
from ident.qs_scan import rescan_qs_joints  # noqa: E402
from ident.robot.refit import extra_name, refit_robot  # noqa: E402
from ident.robot.signals import RobotSignals  # noqa: E402
from trajectories.robot import load_robot  # noqa: E402

TRUE_QS = [0.03, 0.05, 0.1]  # [rad/s] the arm's per-joint truth
_measured = cli_robot.sign_checked


def _model_checked(sig, runs, design, load_torque, min_kept=0.0, *, loads=None):
    """The sign check with the first usual fit's predicted torque in place of the measured
    one: sign(tau_hat) != sign(tau_out_hat) (both the model's)."""
    first = load_torque.__self__
    if loads is None:
        loads = cli_robot.full_rate_loads(sig, runs, design, load_torque)
    new = []
    for i, (f, tau_out) in enumerate(loads):
        full = RobotSignals(t=runs[i].t[f.keep], q=f.q, dq=f.dq, ddq=f.ddq, tau=f.tau_f,
                            joints=sig.joints, payloads=(runs[i].payload,), source="model")
        new.append((dataclasses.replace(f, tau_f=np.asarray(first.predict(full))), tau_out))
    return _measured(sig, runs, design, load_torque, min_kept, loads=new)


def main(mode: str, check: str, seeds: list[int]) -> None:
    if check == "model":
        cli_robot.sign_checked = _model_checked
    for seed in seeds:
        with tempfile.TemporaryDirectory() as d:
            files = [write_arm_csv(r, Path(d) / f"p{i}.csv")
                     for i, r in enumerate(drag_runs(seed))]
            w0 = time.time()
            out = cli_robot.fit_files(load_robot(ARM3), files, model="paper",
                                      q_s="scan-joints" if mode == "rescan" else TRUE_QS,
                                      prune=False, feasibility=False, sign_check=check != "off")
            est, sig = out["_estimators"]["paper"], out["_identification"]
            keep = est.fitted_rows(sig)
            if mode == "rescan":
                vmax = [float(np.abs(sig.dq[keep[:, j], j]).max()) for j in range(sig.k)]
                _, rf = rescan_qs_joints(est, sig, [(2, _TrueDrag())], vmax=vmax, keep=keep)
            else:
                rf = refit_robot(est, sig, [(2, _TrueDrag())], keep=keep)
            i = rf.names_.index(extra_name(est.joints_[2], "true_F_VV"))
            v, sd, sq = float(rf.coef_[i]), float(rf.std_[i]), float(rf.std_qs_[i])
            print(json.dumps(dict(seed=seed, mode=mode, check=check,
                                  q_s=np.round(rf.model.q_s_, 4).tolist(), F_VV=round(v, 3),
                                  std=round(sd, 3), std_qs=round(sq, 3),
                                  z=round((v - 3) / sd, 2), wall_s=round(time.time() - w0, 1),
                                  err=round(est.rel_error_["all"], 5),
                                  kept=round(float(keep.mean()), 4))), flush=True)


if __name__ == "__main__":
    if len(sys.argv) < 4 or sys.argv[1] not in ("true", "rescan") or sys.argv[2] not in (
            "measured", "model", "off"):
        sys.exit("usage: python benchmarks/drag_sign_check.py {true,rescan} "
                 "{measured,model,off} SEED...")
    main(sys.argv[1], sys.argv[2], [int(s) for s in sys.argv[3:]])
