"""n-dof fit time and peak memory against sample count: UR10 (6 joints), usual and paper model.

    python benchmarks/bench_robot_fit.py [--sizes 1e4 1e5 1e6] [--repeat 1] [--chunk 20000]

Synthetic data: a sum-of-sines motion of the six joints at 1 kHz, three payload experiments,
torques from the paper's friction (eq. 30) on every joint through the vectorised regressor
(trajectories.robot.regressor) plus white noise. Timed: ``RobotModel.fit`` (regressor evaluation
in chunks, moments, Gauss-Newton) for the usual model, the paper model with the paper's quadrant
proxy (eq. 26, one data pass) and with model-decided quadrants: with the near-boundary rows
stored (ident.robot.quadrants; "passes" counts data passes, the start pass on every
stride-th row above 1e5 samples counted as one; "upd" store updates) and, for comparison in
the same run, as before these two: start on every row and a full pass at every re-decision
("paper/model-full"). Peak memory:
tracemalloc's peak of the allocations during one fit (the input arrays excluded), which must
stay bounded by the chunk size, not grow with the samples. Same process, same data for all.
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

from ident.robot import estimate  # noqa: E402
from ident.robot.estimate import RobotModel  # noqa: E402
from ident.robot.signals import RobotPayloadData, RobotSignals  # noqa: E402
from trajectories.friction import DEFAULT_Q_S, stribeck_exp  # noqa: E402
from trajectories.robot import RobotRegressor, base_parameters, load_robot  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
PAYLOADS = (RobotPayloadData(), RobotPayloadData(5.0, [0, 0, 0.05]),
            RobotPayloadData(10.0, [0.02, 0, 0.1], [0.02, 0, 0, 0.02, 0, 0.03]))
FRICTION = dict(a_m=1.05, b_m=0.25, a_g=0.92, b_g=0.27)


def synthetic(reg, base, n_total: int, seed: int = 0,
              q_s: float = DEFAULT_Q_S) -> list[RobotSignals]:
    rng = np.random.default_rng(seed)
    k = len(reg.joints)
    chi = base.values(reg.standard_values(Ia=np.full(k, 0.5)))
    n = n_total // len(PAYLOADS)
    t = np.arange(n) * 1e-3
    centre = np.array([0.0, -1.9, 0.6, -1.0, 0.5, 0.0])
    out = []
    for e, pay in enumerate(PAYLOADS):
        w = 2 * np.pi * rng.uniform(0.05, 0.4, (3, k))
        a = rng.uniform(0.2, 0.5, (3, k))
        ph = rng.uniform(0, 2 * np.pi, (3, k))
        arg = t[:, None, None] * w + ph
        q = centre + (a * np.sin(arg)).sum(1)
        dq = (a * w * np.cos(arg)).sum(1)
        ddq = -(a * w**2 * np.sin(arg)).sum(1)
        tau = np.empty((n, k))
        for s in range(0, n, 50000):
            sl = slice(s, s + 50000)
            tau_out = base.reduce(reg.rigid(q[sl], dq[sl], ddq[sl])) @ chi
            if pay.mass:
                tau_out += reg.payload_torque(q[sl], dq[sl], ddq[sl], pay)
            ex = stribeck_exp(dq[sl], q_s)
            p = np.sign(tau_out * dq[sl])
            f = FRICTION
            load = 0.03 * np.abs(tau_out).mean(0)  # friction ~ a few % of the load
            tau[sl] = (0.5 * (1 + p) * (f["a_m"] + f["b_m"] * ex) * tau_out
                       + 0.5 * (1 - p) * (f["a_g"] - f["b_g"] * ex) * tau_out
                       + (0.5 * (1 + p) * (1 + 0.4 * ex) + 0.5 * (1 - p) * (0.8 + 0.3 * ex))
                       * load * np.sign(dq[sl]) + 2 * load * dq[sl] + 0.3 * load)
        tau += 0.01 * np.abs(tau).mean(0) * rng.standard_normal(tau.shape)
        out.append(RobotSignals(t=t, q=q, dq=dq, ddq=ddq, tau=tau, joints=reg.joints,
                                payloads=(pay,), source=f"synthetic {e}"))
    return out


CASES = (("usual", dict(model="usual")),
         ("paper/measured", dict(model="paper", quadrant="measured")),
         ("paper/model", dict(model="paper", quadrant="model")),
         # the same fit with a full pass at every quadrant re-decision (no stored rows,
         # ident.robot.quadrants): the cost before the incremental updates
         ("paper/model-full", dict(model="paper", quadrant="model")))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", nargs="+", type=float, default=[1e4, 1e5, 1e6])
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--chunk", type=int, default=20000)
    args = ap.parse_args()
    robot = load_robot(ROOT / "examples" / "robots" / "ur10.toml")
    reg = RobotRegressor(robot)
    base = base_parameters(reg)
    rows = []
    for size in args.sizes:
        n = int(size)
        sigs = synthetic(reg, base, n)
        for label, kw in CASES:
            full = label.endswith("-full")

            def fit(kw=kw, sigs=sigs, full=full):
                keep = estimate.STORE_FRACTION, estimate.START_ROWS
                if full:  # the code before: start on every row, a pass per re-decision
                    estimate.STORE_FRACTION, estimate.START_ROWS = 0.0, 2**62
                try:
                    t0 = time.perf_counter()
                    m = RobotModel(reg, base=base, chunk_size=args.chunk, **kw).fit(sigs)
                    return time.perf_counter() - t0, m
                finally:
                    estimate.STORE_FRACTION, estimate.START_ROWS = keep
            times = [fit()[0] for _ in range(args.repeat)]
            tracemalloc.start()
            _, m = fit()
            _, peak = tracemalloc.get_traced_memory()
            tracemalloc.stop()
            rows.append((n, label, statistics.median(times), peak / 2**20, m.n_passes_,
                         m.n_store_updates_ if hasattr(m, "n_store_updates_") else 0,
                         m.rel_error_["all"]))
    print(f"UR10, 6 joints, {len(base.names)} base parameters, chunk {args.chunk} samples, "
          f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS')}")
    print(f"{'samples':>9} {'model':>17} {'fit s':>8} {'us/sample':>9} {'passes':>6} "
          f"{'upd':>4} {'peak MiB':>9} {'rel err':>8}")
    for n, label, t, mib, passes, upd, rel in rows:
        print(f"{n:>9d} {label:>17} {t:>8.2f} {1e6 * t / n:>9.2f} {passes:>6d} {upd:>4d} "
              f"{mib:>9.1f} {rel:>8.4f}")
    by = {}
    for n, label, t, mib, *_ in rows:
        by.setdefault(label, []).append((n, t, mib))
    for label, r in by.items():
        if len(r) >= 2:
            (n0, t0, m0), (n1, t1, m1) = r[0], r[-1]
            print(f"{label}: {n1 / n0:.0f}x samples -> time x{t1 / t0:.1f}, "
                  f"peak memory x{m1 / m0:.2f}")
    t = {(n, label): tt for n, label, tt, *_ in rows}
    for n in sorted({r[0] for r in rows}):
        u, pm, pf = t.get((n, "usual")), t.get((n, "paper/model")), t.get((n, "paper/model-full"))
        if u and pm and pf:
            print(f"{n} samples: paper/model / usual = {pm / u:.2f}, "
                  f"paper/model-full / usual = {pf / u:.2f}, stored rows save x{pf / pm:.2f}")


if __name__ == "__main__":
    main()
