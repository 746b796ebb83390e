"""Physically consistent estimate of a 6-dof fit: the convex LMI program
(``ident.robot.consistent_fit.fit_consistent``: Clarabel called directly, and the same
program built through cvxpy) against the former Cholesky-factor local search
(``check_consistency(method="cholesky")``), time and d^2.

    python benchmarks/bench_consistent_fit.py [--duration 20] [--repeat 3]

Data: the simulated UR10 (sim_drivers.arm, the paper's friction on every joint) with payload
runs of 0, 5 and 10 kg and 1 % torque noise; the usual model fitted by WLS, whose base set is
not realisable by physical links (the usual model is the wrong model of these data). Times:
the solve only (the fit and the error passes excluded), median of the repeats.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from ident.robot.consistency import check_consistency  # noqa: E402
from ident.robot.consistent_fit import fit_consistent  # noqa: E402
from ident.robot.estimate import RobotModel  # noqa: E402
from ident.robot.signals import RobotPayloadData, RobotSignals  # noqa: E402
from sim_drivers.arm import ArmGains, ArmParams, Payload, model_reference, simulate_arm  # noqa: E402
from trajectories.robot import RobotRegressor, base_parameters, load_robot  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
PAYLOADS = (None, Payload(5.0, [0.0, 0.0, 0.05]),
            Payload(10.0, [0.02, 0.0, 0.1], [0.02, 0.0, 0.0, 0.02, 0.0, 0.03]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration", type=float, default=20.0, help="seconds per run")
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    robot = load_robot(ROOT / "examples" / "robots" / "ur10.toml")
    params = ArmParams.from_robot(robot)
    ref = model_reference(params.model, center=[0.0, -1.9, 0.6, -1.0, 0.5, 0.0], fraction=0.9,
                          duration_s=a.duration, seed=1)
    reg = RobotRegressor(robot)
    rng = np.random.default_rng(0)
    sigs = []
    for i, p in enumerate(PAYLOADS):
        r = simulate_arm(params, ref, ArmGains.for_params(params, payload=p), payload=p,
                         seed=10 + i)
        tau = r.tau_applied + rng.standard_normal(r.tau_applied.shape) * (
            params.drive.torque_noise_std_Nm)
        pay = RobotPayloadData() if p is None else RobotPayloadData(p.mass, p.com, p.inertia)
        sigs.append(RobotSignals(t=r.t, q=r.q_true, dq=r.dq_true, ddq=r.ddq_true,
                                 tau=np.where(r.sliding, tau, np.nan), joints=reg.joints,
                                 payloads=(pay,)))
    est = RobotModel(reg, "usual", "wls", base=base_parameters(reg)).fit(sigs)
    lmi, via, chol, d_lmi, d_via, d_chol = [], [], [], 0.0, 0.0, 0.0
    for _ in range(a.repeat):
        fit = fit_consistent(est)
        lmi.append(fit.solve_s)
        d_lmi = fit.d2
        fit = fit_consistent(est, solver="cvxpy-clarabel")
        via.append(fit.solve_s)
        d_via = fit.d2
        t0 = time.perf_counter()
        d_chol = check_consistency(est, method="cholesky").d2
        chol.append(time.perf_counter() - t0)
    print(f"UR10, {a.duration:g} s x 3 runs, usual model (WLS), {est.n_base_} base parameters")
    print(f"LMI (Clarabel, direct): {statistics.median(lmi):.3f} s, d^2 = {d_lmi:.4g}")
    print(f"LMI (cvxpy + Clarabel): {statistics.median(via):.3f} s, d^2 = {d_via:.4g} "
          "(the first call includes cvxpy's import)")
    print(f"Cholesky-factor search: {statistics.median(chol):.3f} s, d^2 = {d_chol:.4g}")


if __name__ == "__main__":
    main()
