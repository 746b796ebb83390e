"""Single-joint plant: this tree against a baseline commit, timed in the same run.

Usage: ``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_oneplant.py [--baseline b31155c]
[--reps 5] [--cycles 10000]``

The baseline's source is exported (``git archive``) to a temporary directory; each case runs
in a fresh subprocess, alternating baseline and this tree, so that both see the same machine
load. Prints the median microseconds per cycle of each and their ratio (this tree / baseline).
Cases: ``JointPlant.step`` sliding and stuck, with every effect, and the offline closed loop
(``simulate``: controller + plant + record) with and without effects; and the n-dof
``ArmPlant.step`` on a 3-joint UR10 (the same dynamics code since issue 24).
"""

from __future__ import annotations

import argparse
import io
import os
import statistics
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

CASE = r'''
import math, sys, time
from types import SimpleNamespace
import numpy as np
from daq.protocol.control import ControllerGains
from sim_drivers.offline import simulate
from sim_drivers.plant import JointPlant
from sim_drivers.plant_config import default_plant
case, n = sys.argv[1], int(sys.argv[2])
p = default_plant()
if "effects" in case:
    p = p.with_effect("position_ripple", amplitude_Nm=5.0, period_rad=0.3927, phase_rad=0.5)
    p = p.with_effect("spring", stiffness_Nm_per_rad=40.0, rest_position_rad=0.1)
    p = p.with_effect("warm_up", fraction=0.3, time_constant_s=60.0)
    p = p.with_effect("asymmetric_viscous", F_V_pos=45.0, F_V_neg=35.0)
    p = p.with_effect("quadratic_viscous", F_VV=10.0)
    p = p.with_effect("torque_lag", time_constant_s=0.002)
if case.startswith("arm"):
    from sim_drivers.arm import ArmParams, ArmPlant
    from sim_drivers.robots import ur10
    params = ArmParams.from_model(ur10(3))
    plant = ArmPlant(params, 0.001, substeps=10, seed=1)
    plant.reset([0.1, -1.0, 0.8])
    g = [float(x) for x in params.friction.tau_off]
    taus = [[g[0] + 400.0 * math.sin(k * 0.003), 900.0 * math.sin(k * 0.002) + 300.0,
             200.0 * math.sin(k * 0.004)] for k in range(n)]
    t0 = time.perf_counter()
    for x in taus:
        plant.step(x)
elif case.startswith("step"):
    jp = JointPlant(p, 0.001, substeps=10, seed=1)
    jp.set_payload(3.4584, 1.277)
    jp.reset(0.3)
    taus = ([250.0] * n if "stuck" in case
            else [300.0 + 250.0 * math.sin(k * 0.002) for k in range(n)])
    t0 = time.perf_counter()
    for x in taus:
        jp.step(x)
else:
    t = np.arange(n) * 0.001
    w = 2 * np.pi * 0.2
    ref = SimpleNamespace(t=t, q=0.8 * np.sin(w * t), dq=0.8 * w * np.cos(w * t),
                          ddq=-0.8 * w * w * np.sin(w * t))
    g = ControllerGains(kp=20000.0, kd=1000.0, J_ff=31.0, MX_ff=21.1, Fc_ff=25.0, Fv_ff=40.0)
    t0 = time.perf_counter()
    simulate(p, ref, g, payload_mass=3.4584, payload_arm=1.277)
print((time.perf_counter() - t0) / n * 1e6)
'''

CASES = ("step sliding", "step stuck", "step sliding effects", "offline", "offline effects",
         "arm step (UR10, 3 joints)")


def export(rev: str, dest: Path) -> None:
    data = subprocess.run(["git", "-C", str(ROOT), "archive", rev], check=True,
                          capture_output=True).stdout
    with tarfile.open(fileobj=io.BytesIO(data)) as tar:
        tar.extractall(dest, filter="data")


def run(tree: Path, case: str, cycles: int) -> float:
    env = dict(os.environ, PYTHONPATH=str(tree), OPENBLAS_NUM_THREADS="1")
    out = subprocess.run([sys.executable, "-c", CASE, case, str(cycles)], env=env, cwd=tree,
                         check=True, capture_output=True, text=True).stdout
    return float(out.split()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", default="b31155c")
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--cycles", type=int, default=10000)
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(tmp)
        export(a.baseline, base)
        print(f"{'case':24s} {'baseline us':>12s} {'this tree us':>13s} {'ratio':>6s}")
        for case in CASES:
            b, n = [], []
            for _ in range(a.reps):
                b.append(run(base, case, a.cycles))
                n.append(run(ROOT, case, a.cycles))
            mb, mn = statistics.median(b), statistics.median(n)
            print(f"{case:24s} {mb:12.2f} {mn:13.2f} {mn / mb:6.2f}")


if __name__ == "__main__":
    main()
