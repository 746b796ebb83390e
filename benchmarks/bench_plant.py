"""Microseconds per JointPlant.step() and per offline closed-loop cycle.

Usage: ``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_plant.py [--cycles 20000] [--reps 7]``

Prints medians (and min-max) over repetitions. The target is <= 20 us per step at 1 kHz so that
a bus loop with CANopen still runs >= 5x real time.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time
from types import SimpleNamespace

import numpy as np

from daq.protocol.control import ControllerGains
from sim_drivers.offline import simulate
from sim_drivers.plant import JointPlant
from sim_drivers.plant_config import default_plant


def all_effects():
    p = default_plant()
    p = p.with_effect("position_ripple", amplitude_Nm=5.0, period_rad=0.3927, phase_rad=0.5)
    p = p.with_effect("spring", stiffness_Nm_per_rad=40.0, rest_position_rad=0.1)
    p = p.with_effect("warm_up", fraction=0.3, time_constant_s=60.0)
    p = p.with_effect("asymmetric_viscous", F_V_pos=45.0, F_V_neg=35.0)
    p = p.with_effect("quadratic_viscous", F_VV=10.0)
    return p.with_effect("torque_lag", time_constant_s=0.002)


def time_steps(params, cycles: int, substeps: int, torque) -> float:
    plant = JointPlant(params, 0.001, substeps=substeps, seed=1)
    plant.set_payload(3.4584, 1.277)
    plant.reset(0.3)
    taus = [torque(k) for k in range(cycles)]
    step = plant.step
    t0 = time.perf_counter()
    for tau in taus:
        step(tau)
    return (time.perf_counter() - t0) / cycles * 1e6


def time_offline(params, cycles: int) -> float:
    t = np.arange(cycles) * 0.001
    w = 2 * np.pi * 0.2
    ref = SimpleNamespace(t=t, q=0.8 * np.sin(w * t), dq=0.8 * w * np.cos(w * t),
                          ddq=-0.8 * w * w * np.sin(w * t))
    gains = ControllerGains(kp=20000.0, kd=1000.0, J_ff=31.0, MX_ff=21.1, Fc_ff=25.0, Fv_ff=40.0)
    t0 = time.perf_counter()
    simulate(params, ref, gains, payload_mass=3.4584, payload_arm=1.277)
    return (time.perf_counter() - t0) / cycles * 1e6


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cycles", type=int, default=20000)
    ap.add_argument("--reps", type=int, default=7)
    a = ap.parse_args()

    sliding = lambda k: 300.0 + 250.0 * math.sin(k * 0.002)  # noqa: E731  moves, reverses
    holding = lambda k: 250.0  # noqa: E731  inside the static band at q = 0.3: stuck
    cases = [
        ("step, no effect, sliding, 10 sub", default_plant(), 10, sliding),
        ("step, no effect, stuck, 10 sub", default_plant(), 10, holding),
        ("step, all effects, sliding, 10 sub", all_effects(), 10, sliding),
        ("step, no effect, sliding, 20 sub", default_plant(), 20, sliding),
    ]
    rows = []
    for name, params, sub, torque in cases:
        r = [time_steps(params, a.cycles, sub, torque) for _ in range(a.reps)]
        rows.append((name, r))
    for name, params in (("offline cycle (ctrl + plant + record)", default_plant()),
                         ("offline cycle, all effects", all_effects())):
        rows.append((name, [time_offline(params, a.cycles) for _ in range(a.reps)]))

    base = statistics.median(rows[0][1])
    print(f"{'case':42s} {'median us':>10s} {'min':>7s} {'max':>7s} {'ratio':>6s} "
          f"{'x real time':>11s}")
    for name, r in rows:
        m = statistics.median(r)
        print(f"{name:42s} {m:10.2f} {min(r):7.2f} {max(r):7.2f} {m / base:6.2f} "
              f"{1000.0 / m:11.0f}")


if __name__ == "__main__":
    main()
