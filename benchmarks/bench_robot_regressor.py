"""Time of the n-dof regressor (trajectories.robot.regressor) against pinocchio's, UR10 (6
joints).

Usage: ``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_robot_regressor.py [--reps 3]``

Rows: the full standard regressor (66 columns: 10 inertial + Ia per joint) for 10^4, 10^5
and 10^6 samples, built in blocks of ``--block`` samples into one reused (k, p, block) buffer
(what an estimator accumulating normal equations does); the base regressor only
(``columns=base.columns``); and ``pinocchio.computeJointTorqueRegressor`` in a Python loop
over samples (the reference the vectorised code must match), measured on 2 000 samples and
scaled. Prints medians (min-max) over repetitions and the speed-up over the pinocchio loop
measured in the same run. Target: 10^6 samples x 6 joints in about 1-2 s.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
import pinocchio as pin

from trajectories.robot import RobotRegressor, base_parameters, load_robot


def _states(n: int, k: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    return (rng.uniform(-3, 3, (n, k)), rng.normal(size=(n, k)), rng.normal(size=(n, k)))


def time_blocks(reg: RobotRegressor, n: int, block: int, columns=None) -> float:
    q, dq, ddq = _states(n, reg.k)
    width = reg.p if columns is None else len(columns)
    buf = np.empty((reg.k, width, min(block, n)))
    t0 = time.perf_counter()
    for s in reg.chunks(n, block):
        m = s.stop - s.start
        out = buf if m == buf.shape[2] else None
        reg.rigid_kpn(q[s], dq[s], ddq[s], out=out, columns=columns)
    return time.perf_counter() - t0


def time_pinocchio(reg: RobotRegressor, n: int) -> float:
    q, dq, ddq = _states(n, reg.k)
    model, data = reg.model, reg.model.createData()
    t0 = time.perf_counter()
    for t in range(n):
        pin.computeJointTorqueRegressor(model, data, q[t], dq[t], ddq[t])
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--block", type=int, default=50_000)
    args = ap.parse_args()
    reg = RobotRegressor(load_robot("example-robot-data:ur10"))
    base = base_parameters(reg)
    pin_per_sample = statistics.median(time_pinocchio(reg, 2000) for _ in range(args.reps)) / 2000
    print(f"UR10, k = {reg.k}, p = {reg.p} standard columns, p_b = {base.p_b} base columns, "
          f"block = {args.block}")
    print(f"{'case':<34}{'samples':>10}{'time [s]':>22}{'vs pinocchio loop':>20}")
    for label, cols in (("standard regressor", None), ("base regressor", base.columns)):
        for n in (10**4, 10**5, 10**6):
            ts = [time_blocks(reg, n, args.block, cols) for _ in range(args.reps)]
            med = statistics.median(ts)
            print(f"{label:<34}{n:>10}{med:>10.3f} ({min(ts):.3f}-{max(ts):.3f})"
                  f"{pin_per_sample * n / med:>19.0f}x")
    print(f"{'pinocchio loop (scaled)':<34}{10**6:>10}{pin_per_sample * 1e6:>10.3f}")


if __name__ == "__main__":
    main()
