"""The paper model's jitter share per joint (:mod:`ident.robot.load_jitter`): the figures of
docs/robot-identification.md, "The jitter note".

Usage: ``python benchmarks/load_jitter_share.py [--seeds 1 2] [--duration 20]
[--single-joint-only]``

The simulated arm3 of tests/test_robot_cutoff_band.py (paper friction on every joint, three
payload runs of ``--duration`` s at 1 kHz, the drives' log) at 1 kHz, 500 Hz and 250 Hz (every
1st, 2nd, 4th sample), and the real KUKA recording A (../shared, when present), fitted by
``jointid fit --robot``'s defaults (:func:`ident.cli_robot.fit_files`, the honest sigma; no
feasibility search, which changes no parameter). Printed: the paper model's
``quadrant_jitter_share`` per joint [%] and the joints the note names, and the paper model's
``sign_check_shift`` (:mod:`ident.robot.selection_shift`): how many parameters move beyond
``SHIFT_Z`` sigma when the sign check's rows are kept, and the three largest. Then ``jointid fit``'s
defaults on single joints (the same rule): the example campaign, the friction-dominated joint
of tests/test_friction_dominated.py and the real EMPS (the note, or "not named").
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import sys
import tempfile
import warnings
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from test_robot_cutoff_band import logged, simulated  # noqa: E402

from ident.cli_robot import fit_files  # noqa: E402
from ident.robot.selection_shift import SHIFT_Z  # noqa: E402
from trajectories.robot import load_robot  # noqa: E402

KUKA = ROOT.parent / "shared" / "data" / "kuka_kr300_weigand2021"
KUKA_MAP = "t=rec.time_cont,q=rec.act_pos_mot_deg,tau=rec.act_torque_abs_nm,q_ref=rec.ref_pos_deg"


def _show(label: str, out: dict) -> None:
    share = out["models"]["paper"]["quadrant_jitter_share"]
    named = [n.split(":")[0].removeprefix("paper model, ") for n in out["notes"]
             if "jitter above the cut-off" in n]
    z = out["models"]["paper"].get("sign_check_shift") or {}
    top = sorted(z, key=lambda n: -abs(z[n]))[:3]
    big = sum(abs(v) > SHIFT_Z for v in z.values())
    print(f"{label:24s} " + "  ".join(f"{j} {100 * x:5.1f}" for j, x in share.items())
          + f"   named: {', '.join(named) or '-'}   sign-check shift: {big} beyond "
          f"{SHIFT_Z:g} (" + ", ".join(f"{n} {z[n]:+.1f}" for n in top) + ")", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--duration", type=float, default=20.0, help="seconds per run")
    ap.add_argument("--single-joint-only", action="store_true", help="only the single joints")
    a = ap.parse_args()
    warnings.simplefilter("ignore")
    for seed in a.seeds if not a.single_joint_only else ():
        params, reg, runs, _ = simulated("paper", seed, a.duration)
        for every in (1, 2, 4):
            out = fit_files(reg.robot, logged(params, runs, every), model="both",
                            feasibility=False)
            _show(f"arm3 seed {seed} {1000 // every} Hz", out)
    if a.single_joint_only:
        pass
    elif KUKA.is_dir():
        robot = load_robot(ROOT / "examples" / "robots" / "kuka_kr300_r2500.toml")
        out = fit_files(robot, [KUKA / "recorded_2020-10-21_FF_A_08ms.mat"], model="both",
                        mapping=dict(x.split("=", 1) for x in KUKA_MAP.split(",")),
                        q_unit="deg", feasibility=False)
        _show("KUKA recording A", out)
    else:
        print(f"{KUKA}: absent (KUKA skipped)")
    _single_joint()


def _single_joint() -> None:
    """``jointid fit``'s defaults on one joint (the same rule, :class:`ident.one_joint.
    OneJointProblem`): the example campaign (simulated), the friction-dominated joint of
    tests/test_friction_dominated.py, the real EMPS; printed: the note, or that none came."""
    from example_campaign import example_gains, payload_experiments, simulate_example_campaign
    from test_friction_dominated import friction_dominated

    from ident.fitting import fit_models

    plant, plan, _ = simulate_example_campaign()
    cases = {"example campaign": payload_experiments(plant, plan, example_gains(), 11,
                                                     name="p{i}.csv")}
    txt = (ROOT / "sim_drivers" / "data" / "plant_default.toml").read_text()
    with tempfile.TemporaryDirectory() as d:
        fplant, fplan, fgains = friction_dominated(txt, Path(d) / "plant.toml", "fd")
        cases["friction-dominated joint"] = payload_experiments(fplant, fplan, fgains, 1,
                                                                name="f{i}.csv")
    emps = ROOT.parent / "shared" / "data" / "emps" / "DATA_EMPS.mat"
    for label, exps in cases.items():
        rep = fit_models(exps, models=("usual", "paper"))
        _note(label, rep.notes)
    if emps.is_file():  # as tests/test_robot_load_jitter.py: the command line's defaults
        import json

        from daq.app.cli import main

        with tempfile.TemporaryDirectory() as d:
            out = Path(d) / "emps.json"
            with contextlib.redirect_stdout(io.StringIO()):  # the command's own tables
                main(["fit", str(emps), "--joint", "prismatic", "--map", "q=qm,tau=vir",
                      "--gain", "gtau", "--json", str(out)])
            notes = json.loads(out.read_text())["notes"]
        _note("EMPS (real)", notes)


def _note(label: str, notes: list[str]) -> None:
    named = [n for n in notes if "jitter above the cut-off" in n]
    print(f"{label:24s} " + (named[0][:70] if named else "not named"), flush=True)


if __name__ == "__main__":
    main()
