"""The robot fit's q_s scans on the simulated 3-dof arm with a distinct true q_s per joint:
``q_s="scan"`` (one q_s shared by every joint), ``q_s="scan-joints"`` (one per joint,
:func:`ident.qs_scan.scan_qs_joints`) and the truth given, through
:func:`ident.cli_robot.fit_robot` (columns chain, paper model, no consistency search).

Data as tests/test_robot_fit.py's ``noisy_raw_runs``: examples/robots/arm3.toml with the
default ``ArmParams`` friction except ``q_s`` (``--qs``, default 0.02 / 0.03 / 0.06 rad/s), a
model multi-sine of 20 s about [0, -1.9, 0.6] (seed s) for each of 3 payloads (0, 5, 10 kg),
true positions, applied torque plus 1 % noise of each joint's load; a held-out run (another
multi-sine, seed 100 + s, no payload) as the validation file.

Prints per seed and per method: each joint's q_s, the fit's relative error per joint and
over every joint (the record's ``rel_error``: after the uncertainty step's pruning), the
held-out error, the number of paper fits of the scan, and the fit_robot wall time.
``--criterion joint`` scores each joint's q_s by its own rows' error instead of the error over
every joint's rows (the scan's ``criterion``, default "all"; set here by replacing the function
the fit calls, a measurement switch, not an option of the command).

Usage::

    OPENBLAS_NUM_THREADS=1 nice -n 10 python benchmarks/robot_qs_joints.py --seeds 1 2 3 4
"""

from __future__ import annotations

import argparse
import functools
import time
from pathlib import Path

import numpy as np

import ident.cli_robot as cli_robot
from ident.cli_robot import fit_robot
from ident.qs_scan import scan_qs_joints
from ident.robot.loaders import RawRobotRun, RobotPreprocessing
from ident.robot.signals import RobotPayloadData
from sim_drivers.arm import ArmGains, ArmParams, Payload, model_reference, simulate_arm
from trajectories.robot import load_robot

ROOT = Path(__file__).resolve().parents[1]
ARM3 = ROOT / "examples" / "robots" / "arm3.toml"
PAYLOADS = (None, Payload(5.0, [0.0, 0.0, 0.05]),
            Payload(10.0, [0.02, 0.0, 0.1], [0.02, 0.0, 0.0, 0.02, 0.0, 0.03]))
CENTRE = [0.0, -1.9, 0.6]
NOISE = 0.01


def _raw(params: ArmParams, seed: int, traj_seed: int, payloads: tuple, duration_s: float,
         tag: str) -> list[RawRobotRun]:
    ref = model_reference(params.model, center=CENTRE, fraction=0.9, duration_s=duration_s,
                          seed=traj_seed)
    rng = np.random.default_rng(seed)
    sd = NOISE * params.drive.torque_noise_std_Nm / 0.01
    out = []
    for i, p in enumerate(payloads):
        r = simulate_arm(params, ref, ArmGains.for_params(params, payload=p), payload=p,
                         seed=10 * traj_seed + i)
        pay = RobotPayloadData() if p is None else RobotPayloadData(p.mass, p.com, p.inertia)
        tau = r.tau_applied + rng.standard_normal(r.tau_applied.shape) * sd
        out.append(RawRobotRun(f"{tag} payload {r.payload_mass_kg} kg", r.t, r.q_true, tau,
                               q_ref=r.q_ref, payload=pay))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4])
    ap.add_argument("--qs", type=float, nargs=3, default=[0.02, 0.03, 0.06])
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--criterion", choices=("all", "joint"), default="all")
    ap.add_argument("--methods", nargs="+", default=["scan", "scan-joints", "truth"])
    a = ap.parse_args()
    if a.criterion != "all":
        cli_robot.scan_qs_joints = functools.partial(scan_qs_joints, criterion=a.criterion)
    robot = load_robot(ARM3)
    params = ArmParams.from_robot(robot, {"q_s": np.array(a.qs)})
    joints = robot.moving
    print(f"truth q_s {dict(zip(joints, a.qs, strict=True))} rad/s; criterion {a.criterion}")
    print("seed method       " + " ".join(f"{'q_s ' + j:>9}" for j in joints)
          + "  " + " ".join(f"{'fit ' + j:>8}" for j in joints) + "  fit all   CV all"
          + " " + " ".join(f"{'CV ' + j:>8}" for j in joints) + "  fits  sweeps    s")
    for seed in a.seeds:
        runs = _raw(params, seed, seed, PAYLOADS, a.duration, "fit")
        val = _raw(params, seed + 1000, 100 + seed, (None,), a.duration, "held-out")
        for m in a.methods:
            q_s = dict(zip(joints, a.qs, strict=True)) if m == "truth" else m
            t0 = time.perf_counter()
            rec = fit_robot(robot, runs, val, models=("paper",), q_s=q_s, feasibility=False,
                            preprocessing=RobotPreprocessing(torque_delay=0.5))
            dt = time.perf_counter() - t0
            qv = rec["q_s"]
            qj = [qv[j] for j in joints] if isinstance(qv, dict) else [qv] * len(joints)
            p = rec["models"]["paper"]
            err, cv = p["rel_error"], p["validation_rel_error"]
            if "q_s_scan" in rec:
                fits, sweeps = len(rec["q_s_scan"]), "-"
            elif "q_s_scan_joints" in rec:
                sj = rec["q_s_scan_joints"]
                fits, sweeps = sj["fits"], f"{sj['sweeps']}{'' if sj['converged'] else '!'}"
            else:
                fits, sweeps = 0, "-"
            print(f"{seed:4d} {m:12s} " + " ".join(f"{q:9.4f}" for q in qj) + "  "
                  + " ".join(f"{100 * err[j]:7.3f}%" for j in joints)
                  + f" {100 * err['all']:7.3f}% {100 * cv['all']:7.3f}% "
                  + " ".join(f"{100 * cv[j]:7.3f}%" for j in joints)
                  + f" {fits:5d} {sweeps:>7s} {dt:5.1f}", flush=True)


if __name__ == "__main__":
    main()
