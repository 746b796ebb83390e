"""Fit time and peak memory against sample count (both models), ``jointid fit``'s pipeline.

    python benchmarks/bench_fit.py [--sizes 1e4 1e5 1e6] [--repeat 3]

Synthetic data: three payload runs of a revolute joint whose torque follows the paper model
(eq. 30/34) exactly, plus noise, at 1 kHz. Each size is timed ``--repeat`` times in this
process (median reported); the peak memory is tracemalloc's peak of numpy allocations
during one fit. The growth must be linear: the table prints time and memory per sample.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
import tracemalloc

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from ident.fitting import fit_models  # noqa: E402
from ident.loaders import Experiment  # noqa: E402
from ident.signals import G  # noqa: E402
from trajectories.friction import DEFAULT_Q_S, stribeck_exp  # noqa: E402

TRUTH = dict(J=31.0, MX=21.1, MY=-0.8, a_m=1.06, b_m=0.2, c_m=21.0, d_m=8.0, a_g=0.93,
             b_g=0.2, c_g=16.0, d_g=6.0, F_V=40.0, tau_off=10.0)  # fmt: skip


def synthetic(
    n_total: int, seed: int = 0, dt: float = 1e-3, q_s: float = DEFAULT_Q_S
) -> list[Experiment]:
    """Three runs (0, 3.4584, 6.97 kg at 1.277 m) totalling ``n_total`` samples."""
    rng = np.random.default_rng(seed)
    out = []
    n = n_total // 3
    t = np.arange(n) * dt
    w = 2 * np.pi * np.array([0.05, 0.13, 0.37])
    a = np.array([0.9, 0.25, 0.05])
    q = (a[:, None] * np.sin(w[:, None] * t)).sum(0)
    dq = (a[:, None] * w[:, None] * np.cos(w[:, None] * t)).sum(0)
    ddq = -(a[:, None] * w[:, None] ** 2 * np.sin(w[:, None] * t)).sum(0)
    p = TRUTH
    for k, m in enumerate((0.0, 3.4584, 6.97)):
        la = 1.277
        tau_out = (p["J"] * ddq + p["MX"] * G * np.cos(q) + p["MY"] * G * np.sin(q)
                   + m * la * (la * ddq + G * np.cos(q)))  # fmt: skip
        e = stribeck_exp(dq, q_s)
        s = np.sign(tau_out * dq)
        pp, pm = 0.5 * (1 + s), 0.5 * (1 - s)
        tau = (pp * (p["a_m"] + p["b_m"] * e) * tau_out + pm * (p["a_g"] - p["b_g"] * e) * tau_out
               + (pp * (p["c_m"] + p["d_m"] * e) + pm * (p["c_g"] + p["d_g"] * e)) * np.sign(dq)
               + p["F_V"] * dq + p["tau_off"])  # fmt: skip
        tau = tau + rng.normal(0, 2.0, n)
        qm = np.round(q * 65190.0) / 65190.0  # encoder quantisation
        out.append(Experiment(f"run{k}", t, qm, tau, m, la, True))
    return out


def one_fit(exps: list[Experiment]) -> float:
    t0 = time.perf_counter()
    fit_models(exps, ("usual", "paper"), q_s=DEFAULT_Q_S, table_iv=False)
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", nargs="+", type=float, default=[1e4, 3e4, 1e5, 3e5, 1e6])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    rows = []
    for size in args.sizes:
        n = int(size)
        exps = synthetic(n)
        one_fit(exps)  # warm-up
        times = [one_fit(exps) for _ in range(args.repeat)]
        tracemalloc.start()
        one_fit(exps)
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        rows.append((n, statistics.median(times), min(times), max(times), peak / 2**20))
    print(f"{'samples':>10} {'median s':>9} {'min s':>7} {'max s':>7} {'us/sample':>9} "
          f"{'peak MiB':>9} {'B/sample':>9}")  # fmt: skip
    for n, med, lo, hi, mib in rows:
        print(f"{n:>10d} {med:>9.3f} {lo:>7.3f} {hi:>7.3f} {1e6 * med / n:>9.3f} "
              f"{mib:>9.1f} {mib * 2**20 / n:>9.0f}")  # fmt: skip
    if len(rows) >= 2:
        (n0, t0, *_, m0), (n1, t1, *_, m1) = rows[0], rows[-1]
        print(f"\nratio {n1 / n0:.0f}x samples: time x{t1 / t0:.1f}, peak memory x{m1 / m0:.1f}")


if __name__ == "__main__":
    main()
