"""A 7-axis fit through ``jointid fit --robot``, timed stage by stage (issue 22 item 7: "a
7-axis fit with the consistency report <= 10 s on 2 cores").

    python benchmarks/bench_robot7.py [--duration 10] [--repeat 1] [--models both usual]
                                      [--args "--cutoff 20"] [--before DIR]

``--before DIR``: the same fits also with the code of another checkout (e.g.
``git archive <commit> | tar -x -C DIR``), alternating with this one in the same run, so
both see the same machine load.

Data: the Franka Panda of example-robot-data (its seven arm joints moving, the fingers
locked) simulated by ``sim_drivers.arm_offline.simulate_arm`` (``ArmParams.from_robot``: the
paper's friction on every joint, torque ripple noise) for ``--duration`` s at 1 kHz, written
as a robot CSV (``ArmRun.columns``) with jittered time stamps: the values are taken at the
true instants t_i + u_i, u_i uniform in +-0.3 ms (q and q_ref interpolated, the torque
command held), and logged with those instants -- as the 7-axis log of issue 22.

Every fit runs in a fresh process, as the command line does (its imports included), with the
BLAS threads limited as the command line limits them (``daq.app.cli.limit_blas_threads``).
Stages (exclusive times: a stage's time excludes the stages called inside it):

- import: importing the command line (``daq.app.cli``);
- load: ``load_robot`` and ``load_robot_runs`` (CSV read, resampling of the jittered stamps);
- preprocess: the cut-off/decimation choice and the columns chain (filters, decimation)
  without the regressor evaluations;
- regressor: ``RobotRegressor.rigid_kpn`` and ``payload_torque`` at full rate;
- base: ``base_parameters`` (every call);
- usual fit / paper fit: ``RobotModel.fit`` (the sign check's first usual fit counted under
  usual);
- consistency: ``check_consistency`` (the LMI program, cvxpy's import on its first call);
- uncertainty: ``ident.robot.uncertainty.assess`` (the honest sigma: block jackknife, IV
  check, pruning of the paper model);
- other: the rest of ``fit_robot`` and the report (Table III, errors on all rows, text).

Columns "wall" (perf_counter) and "cpu" (process_time, this process's CPU time: on a loaded
machine it is what the run would take on a free core). Medians over ``--repeat``.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
STAGES = ("import", "load", "preprocess", "regressor", "base", "usual fit", "paper fit",
          "consistency", "uncertainty", "other")
PANDA_TOML = """[robot]
name = "panda7"
gravity = [0.0, 0.0, -9.81]            # [m/s^2]
urdf = "example-robot-data:panda"

[motion]
moving = ["panda_joint1", "panda_joint2", "panda_joint3", "panda_joint4", "panda_joint5",
          "panda_joint6", "panda_joint7"]
locked = { panda_finger_joint1 = 0.0, panda_finger_joint2 = 0.0 }   # [m]
"""
JITTER_S = 0.3e-3


def write_log(folder: Path, duration: float, seed: int = 1) -> tuple[Path, Path]:
    """The panda robot file and one simulated log with jittered stamps (module doc).

    (The imports here and in :func:`child` are inside the functions on purpose: the timed
    child process must import the command line itself, cold.)"""
    import numpy as np

    from sim_drivers.arm import ArmGains, ArmParams, model_reference, simulate_arm
    from trajectories.robot import load_robot

    toml = folder / "panda7.toml"
    toml.write_text(PANDA_TOML)
    robot = load_robot(toml)
    params = ArmParams.from_robot(robot)
    ref = model_reference(params.model, fraction=0.8, duration_s=duration, seed=seed)
    run = simulate_arm(params, ref, ArmGains.for_params(params), seed=seed + 2)
    cols = run.columns()
    tu = cols["t"]
    rng = np.random.default_rng(seed + 4)
    t = tu + rng.uniform(-JITTER_S, JITTER_S, tu.size)
    t[0], t[-1] = tu[0], tu[-1]
    held = np.clip(np.searchsorted(tu, t, side="right") - 1, 0, tu.size - 1)
    for name in list(cols):
        if name.startswith("q"):  # q1.., q_ref1..: the value at the true instant
            cols[name] = np.interp(t, tu, cols[name])
        elif name.startswith("tau"):  # the command in force at that instant
            cols[name] = cols[name][held]
    cols["t"] = t
    csv = folder / "panda7.csv"
    np.savetxt(csv, np.column_stack(list(cols.values())), delimiter=",",
               header=",".join(cols), comments="", fmt="%.17g")
    return toml, csv


class _Clock:
    """Exclusive wall and CPU time per stage of wrapped functions (nested calls: the inner
    stage's time is taken out of the outer's)."""

    def __init__(self) -> None:
        self.wall = dict.fromkeys(STAGES, 0.0)
        self.cpu = dict.fromkeys(STAGES, 0.0)
        self.stack: list[list] = []

    def wrap(self, owner, name: str, stage) -> None:
        fn = getattr(owner, name)

        def timed(*a, **kw):
            st = stage(*a, **kw) if callable(stage) else stage
            w0, c0 = time.perf_counter(), time.process_time()
            self.stack.append([0.0, 0.0])
            try:
                return fn(*a, **kw)
            finally:
                inner_w, inner_c = self.stack.pop()
                dw, dc = time.perf_counter() - w0, time.process_time() - c0
                self.wall[st] += dw - inner_w
                self.cpu[st] += dc - inner_c
                if self.stack:
                    self.stack[-1][0] += dw
                    self.stack[-1][1] += dc

        setattr(owner, name, timed)


def child(argv: list[str]) -> dict:
    """One command-line fit in this (fresh) process; the stage times as a dict."""
    w0, c0 = time.perf_counter(), time.process_time()
    import daq.app.cli as cli
    import ident.cli_robot as cr
    import ident.robot.design as design
    import ident.robot.estimate as estimate
    from ident.robot.regressor import RobotRegressor

    clock = _Clock()
    clock.wall["import"] = time.perf_counter() - w0
    clock.cpu["import"] = time.process_time() - c0
    clock.wrap(cr, "load_robot", "load")
    clock.wrap(cr, "load_robot_runs", "load")
    clock.wrap(cr, "resolve_design", "preprocess")
    clock.wrap(cr, "design_runs", "preprocess")
    clock.wrap(cr, "sign_checked", "preprocess")
    clock.wrap(RobotRegressor, "rigid_kpn", "regressor")
    clock.wrap(RobotRegressor, "payload_torque", "regressor")
    for mod in (design, estimate, cr):  # wherever the fit calls it
        if hasattr(mod, "base_parameters"):
            clock.wrap(mod, "base_parameters", "base")
    clock.wrap(estimate.RobotModel, "fit", lambda self, *a, **k: f"{self.model} fit")
    clock.wrap(cr, "check_consistency", "consistency")
    clock.wrap(cr, "assess", "uncertainty")
    devnull = open(os.devnull, "w")  # noqa: SIM115 -- the report text is not timed output
    keep, sys.stdout = sys.stdout, devnull
    try:
        code = cli.main(argv)
    finally:
        sys.stdout = keep
    if code != 0:
        raise SystemExit(f"bench_robot7: jointid {' '.join(argv)} exited with {code}")
    out = {"wall": clock.wall, "cpu": clock.cpu,
           "total_wall": time.perf_counter() - w0, "total_cpu": time.process_time() - c0}
    for key, tot in (("wall", "total_wall"), ("cpu", "total_cpu")):
        out[key]["other"] = out[tot] - sum(out[key].values())
    js = Path(argv[argv.index("--json") + 1])
    rec = json.loads(js.read_text())
    out["rel_error"] = {m: r.get("rel_error", {}).get("all") for m, r in rec["models"].items()}
    out["samples"] = rec["preprocessing"]["samples"]
    out["cutoff_hz"] = rec["preprocessing"]["cutoff_hz"]
    out["decimation"] = rec["preprocessing"]["decimation"]
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration", type=float, default=10.0, help="seconds of log at 1 kHz")
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--models", nargs="+", default=["both", "usual"],
                    help="--model values to time (the command line's default is both)")
    ap.add_argument("--args", default="--cutoff 20",
                    help="more options of jointid fit --robot (default --cutoff 20: on this "
                         "log the automatic cut-off stops at its 0.4 f_s bound, with a "
                         "warning, and the paper model is then refused as not identifiable)")
    ap.add_argument("--before", type=Path, default=None,
                    help="a checkout of the code before, timed in the same run")
    ap.add_argument("--child", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child is not None:
        print(json.dumps(child(a.child)))
        return
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        t0 = time.perf_counter()
        toml, csv = write_log(folder, a.duration)
        print(f"simulated {a.duration:g} s of the 7-axis panda at 1 kHz, stamps jittered "
              f"+-{1e3 * JITTER_S:g} ms ({time.perf_counter() - t0:.1f} s)")
        codes = {"": ROOT} if a.before is None else {"before ": a.before.resolve(),
                                                         "after ": ROOT}
        results: dict[str, list[dict]] = {}
        for model in a.models:
            argv = ["fit", "--robot", str(toml), str(csv), "--model", model,
                    "--json", str(folder / f"{model}.json"), *shlex.split(a.args)]
            for _ in range(a.repeat):
                for tag, code in codes.items():  # alternating: the same load for both
                    env = dict(os.environ, PYTHONPATH=str(code))
                    p = subprocess.run([sys.executable, __file__, "--child", *argv], env=env,
                                       capture_output=True, text=True, check=False)
                    if p.returncode != 0:
                        raise SystemExit((p.stderr.strip().splitlines() or ["failed"])[-1])
                    results.setdefault(f"{tag}{model}", []).append(
                        json.loads(p.stdout.strip().splitlines()[-1]))
    load = os.getloadavg()[0]
    first = next(iter(results.values()))[0]
    print(f"jointid fit --robot {' '.join(shlex.split(a.args))}: {first['samples']} decimated "
          f"samples (cut-off {first['cutoff_hz']:.4g} Hz, decimation {first['decimation']}); "
          f"{os.cpu_count()} cores, load average {load:.1f}; median of {a.repeat}; times [s]")
    for model in a.models:
        keys = [f"{tag}{model}" for tag in codes]
        print(f"--model {model}" + ("" if a.before is None else ": before / after"))
        print(f"{'stage':>12}" + "".join(f" {(t or 'time').strip() + ' wall':>11} "
                                         f"{(t or 'time').strip() + ' cpu':>11}"
                                         for t in codes))
        for st in (*STAGES, "total"):
            line = f"{st:>12}"
            for key in keys:
                runs = results[key]
                if st == "total":
                    w = statistics.median(r["total_wall"] for r in runs)
                    c = statistics.median(r["total_cpu"] for r in runs)
                else:
                    w = statistics.median(r["wall"][st] for r in runs)
                    c = statistics.median(r["cpu"][st] for r in runs)
                line += f" {w:>11.2f} {c:>11.2f}"
            print(line)
    for key, runs in results.items():
        errs = ", ".join(f"{m} {100 * e:.4f} %" for m, e in runs[0]["rel_error"].items()
                         if e is not None)
        print(f"{key}: relative error (fit rows) {errs}")


if __name__ == "__main__":
    main()
