"""Cycles per second of the n-dof arm simulator (UR10 with k = 1, 3, 6 moving joints).

Usage: ``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_arm.py [--seconds 10] [--reps 3]``

Each case runs the offline closed loop (:func:`sim_drivers.arm.simulate_arm`: controller +
drive quantisation + plant with 10 sub-steps + record) over a smooth multi-joint reference of
``--seconds`` simulated seconds at 1 kHz, with a 3 kg payload; the plant-only rows step
:class:`sim_drivers.arm.ArmPlant` with a torque sequence that keeps every joint sliding. Prints
medians (min-max) over repetitions, the ratio to real time, and the time of a 60 s run. The
target is a 60 s run of a 6-dof arm in well under a minute.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import time

import numpy as np

from sim_drivers.arm import ArmGains, ArmParams, ArmPlant, Payload, model_reference, simulate_arm
from sim_drivers.robots import ur10


def time_closed_loop(params: ArmParams, seconds: float, substeps: int) -> float:
    """Cycles per second of simulate_arm."""
    ref = model_reference(params.model, duration_s=seconds, seed=1)
    pay = Payload(3.0, [0.0, 0.0, 0.1])
    gains = ArmGains.for_params(params, payload=pay)
    t0 = time.perf_counter()
    run = simulate_arm(params, ref, gains, payload=pay, seed=1, substeps=substeps)
    return len(run) / (time.perf_counter() - t0)


def time_plant_sliding(params: ArmParams, cycles: int) -> float:
    """Cycles per second of ArmPlant.step with every joint sliding (no stiction solve):
    gravity off, a constant torque above the dry friction on every joint."""
    params = dataclasses.replace(params, gravity=np.zeros(3))
    plant = ArmPlant(params, 0.001, substeps=10, seed=1)
    q0 = np.full(params.k, 0.3)
    plant.reset(q0)
    plant.dq = np.full(params.k, 0.5)
    push = 2.0 * (params.friction.c_m + params.friction.d_m) + params.friction.F_V * 0.5
    taus = push + params.friction.tau_off
    t0 = time.perf_counter()
    for _ in range(cycles):
        plant.step(taus)
    el = time.perf_counter() - t0
    assert np.all(plant.dq > 0), "bench case left the sliding regime"
    return cycles / el


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--reps", type=int, default=3)
    a = ap.parse_args()
    rows = []
    for k in (1, 3, 6):
        params = ArmParams.from_model(ur10(k))
        rows.append((f"closed loop, k={k}, 10 sub", [time_closed_loop(params, a.seconds, 10)
                                                     for _ in range(a.reps)]))
        rows.append((f"plant step, k={k}, sliding, 10 sub",
                     [time_plant_sliding(params, 2000) for _ in range(a.reps)]))
    params = ArmParams.from_model(ur10(6))
    rows.append(("closed loop, k=6, 5 sub", [time_closed_loop(params, a.seconds, 5)
                                            for _ in range(a.reps)]))
    base = statistics.median(rows[0][1])
    print(f"{'case':36s} {'cycles/s':>9s} {'min':>7s} {'max':>7s} {'vs k=1':>7s} "
          f"{'x real time':>11s} {'60 s run [s]':>12s}")
    for name, r in rows:
        m = statistics.median(r)
        print(f"{name:36s} {m:9.0f} {min(r):7.0f} {max(r):7.0f} {m / base:7.2f} "
              f"{m / 1000.0:11.1f} {60000.0 / m:12.1f}")


if __name__ == "__main__":
    main()
