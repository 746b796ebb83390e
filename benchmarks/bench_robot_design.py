"""Preprocessing of a 6-joint log, time and peak memory against the full-rate sample count:
the single-joint chain on the n-dof regressor (``ident.robot.design``, ``--chain columns``,
the default of ``jointid fit --robot``) against the states chain (``preprocess_runs``).

    python benchmarks/bench_robot_design.py [--sizes 1e4 1e5 1e6] [--repeat 1]

Synthetic UR10 run at 1 kHz (sum of sines on every joint, white-noise torque), one experiment.
The columns chain builds the standard regressor (k x p = 6 x 66 columns) at full rate and
decimates it: its memory grows with the samples (MAX_BYTES refuses an experiment above
4 GiB; ~1.3e6 full-rate samples of this robot); the states chain decimates 4 k signals and
leaves the regressor to the estimator's chunks. Peak memory: tracemalloc's peak during one
call (inputs excluded). Same process, same data for both.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
import tracemalloc
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from ident.robot.design import design_runs, resolve_design  # noqa: E402
from ident.robot.loaders import RawRobotRun, RobotPreprocessing, preprocess_runs  # noqa: E402
from trajectories.robot import RobotRegressor, load_robot  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def _run(n: int, k: int, seed: int = 0) -> RawRobotRun:
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 1e-3
    w = 2 * np.pi * rng.uniform(0.1, 1.0, (3, k))
    a = rng.uniform(0.2, 0.6, (3, k))
    q = sum(a[i] * np.sin(np.outer(t, w[i]) + i) for i in range(3))
    return RawRobotRun("bench.csv", t, q, rng.normal(0, 1.0, (n, k)))


def _measure(fn) -> tuple[float, float]:
    tracemalloc.start()
    t0 = time.perf_counter()
    fn()
    dt = time.perf_counter() - t0
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return dt, peak / 2**20


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", nargs="+", type=float, default=[1e4, 1e5, 1e6])
    ap.add_argument("--repeat", type=int, default=1)
    args = ap.parse_args()
    robot = load_robot("example-robot-data:ur10")
    reg = RobotRegressor(robot)
    k = len(robot.moving)
    print(f"UR10, {k} joints, {reg.p} standard columns a joint row; cut-off 50 Hz, r = 20 "
          "(columns) / 8 (states)")
    print(f"{'samples':>9} {'columns [s]':>12} {'[MiB]':>8} {'states [s]':>11} {'[MiB]':>8} "
          f"{'time ratio':>11} {'mem ratio':>10}")
    for size in args.sizes:
        n = int(size)
        runs = [_run(n, k)]
        settings = resolve_design(runs, cutoff_hz=50.0)
        pre = RobotPreprocessing(50.0, None, None)
        tc, mc, ts, ms = [], [], [], []
        for _ in range(max(args.repeat, 1)):
            a, b = _measure(lambda runs=runs, settings=settings: design_runs(runs, reg,
                                                                              settings))
            tc.append(a)
            mc.append(b)
            a, b = _measure(lambda runs=runs, pre=pre: preprocess_runs(runs, robot.moving, pre))
            ts.append(a)
            ms.append(b)
        c, s = statistics.median(tc), statistics.median(ts)
        print(f"{n:>9d} {c:>12.2f} {max(mc):>8.0f} {s:>11.3f} {max(ms):>8.0f} "
              f"{c / s:>11.1f} {max(mc) / max(ms):>10.1f}")


if __name__ == "__main__":
    main()
