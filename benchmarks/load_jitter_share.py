"""The paper model's jitter share per joint (:mod:`ident.robot.load_jitter`): the figures of
docs/robot-identification.md, "The jitter note".

Usage: ``python benchmarks/load_jitter_share.py [--seeds 1 2] [--duration 20]``

The simulated arm3 of tests/test_robot_cutoff_band.py (paper friction on every joint, three
payload runs of ``--duration`` s at 1 kHz, the drives' log) at 1 kHz, 500 Hz and 250 Hz (every
1st, 2nd, 4th sample), and the real KUKA recording A (../shared, when present), fitted by
``jointid fit --robot``'s defaults (:func:`ident.cli_robot.fit_files`, no jackknife, no
feasibility search: neither changes the share). Printed: the paper model's
``quadrant_jitter_share`` per joint [%] and the joints the note names.
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from test_robot_cutoff_band import logged, simulated  # noqa: E402

from ident.cli_robot import fit_files  # noqa: E402
from trajectories.robot import load_robot  # noqa: E402

KUKA = ROOT.parent / "shared" / "data" / "kuka_kr300_weigand2021"
KUKA_MAP = "t=rec.time_cont,q=rec.act_pos_mot_deg,tau=rec.act_torque_abs_nm,q_ref=rec.ref_pos_deg"


def _show(label: str, out: dict) -> None:
    share = out["models"]["paper"]["quadrant_jitter_share"]
    named = [n.split(":")[0].removeprefix("paper model, ") for n in out["notes"]
             if "jitter above the cut-off" in n]
    print(f"{label:24s} " + "  ".join(f"{j} {100 * x:5.1f}" for j, x in share.items())
          + f"   named: {', '.join(named) or '-'}", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--duration", type=float, default=20.0, help="seconds per run")
    a = ap.parse_args()
    warnings.simplefilter("ignore")
    for seed in a.seeds:
        params, reg, runs, _ = simulated("paper", seed, a.duration)
        for every in (1, 2, 4):
            out = fit_files(reg.robot, logged(params, runs, every), model="both",
                            sigma_blocks=0, feasibility=False)
            _show(f"arm3 seed {seed} {1000 // every} Hz", out)
    if KUKA.is_dir():
        robot = load_robot(ROOT / "examples" / "robots" / "kuka_kr300_r2500.toml")
        out = fit_files(robot, [KUKA / "recorded_2020-10-21_FF_A_08ms.mat"], model="both",
                        mapping=dict(x.split("=", 1) for x in KUKA_MAP.split(",")),
                        q_unit="deg", sigma_blocks=0, feasibility=False)
        _show("KUKA recording A", out)
    else:
        print(f"{KUKA}: absent (KUKA skipped)")


if __name__ == "__main__":
    main()
