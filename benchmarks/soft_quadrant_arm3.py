"""The soft quadrant weight on the simulated arm3 at 1 kHz: one joint's paper friction fitted
with the expectation of its quadrants under the load's jitter, against the hard quadrants of
today's rule (docs/robot-identification.md, "The default cut-off on logs slower than 1 kHz";
benchmarks/soft_quadrant_synthetic.py is the same on synthetic data). A design check; nothing
in the product uses it yet.

Usage: ``python benchmarks/soft_quadrant_arm3.py [--seed 1] [--joint 1] [--theta usual]``

The logs are benchmarks/robot_paper_blend.py's (arm3, paper friction, three payload runs of
20 s, the drives' log at 1 kHz), through ``jointid fit --robot``'s chain (columns chain, the
sign check of a first usual WLS fit). To isolate the friction, the load is the simulator's
true theta on the chain's full-rate states, s = W theta + p (what a right load model
predicts: the closed loop's jitter above the cut-off is not in those states), and only the
joint's ten paper parameters are fitted on its decimated rows, by linear least squares with
eq. 15's sigma (z = (estimate - truth) / sigma, sum of z^2 over the ten). ``--theta usual``:
the load of the first usual fit's theta instead (what the product has before the paper fit).
Variants:

- ``hard``: eq. 30 with P+ = [s dq > 0] formed at full rate, then the chain's decimation
  (the full-rate products of ``products_columns`` with the true theta);
- ``soft sigma``: the expectation under x = s + n, n ~ N(0, sigma^2), mu = s sign(dq):
  P+ -> Phi(mu / sigma) on the Coulomb terms, P+ x -> Phi s + r, P- x -> (1 - Phi) s - r with
  r = sigma phi(mu / sigma) sign(dq) (the rectified jitter), E = exp(-|dq| / q_s) as it is;
  formed at full rate and decimated likewise, for a few given sigma [N m];
- ``soft, sigma fitted``: sigma one more parameter, fitted with the ten by nonlinear least
  squares (scipy ``least_squares``), the sigma of all eleven from its Jacobian.

No column reads the measured torque (sigma is a parameter of the model, as q_s).
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings
from dataclasses import replace
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "benchmarks"))

import numpy as np  # noqa: E402
from scipy.optimize import least_squares  # noqa: E402
from soft_quadrant_common import paper_columns  # noqa: E402
from test_robot_cutoff_band import logged, simulated  # noqa: E402

from ident.chain import decimate, decimation_index  # noqa: E402
from ident.fitting import SIGN_CHECK_MIN_KEPT  # noqa: E402
from ident.robot.base import base_parameters  # noqa: E402
from ident.robot.design import (  # noqa: E402
    design_runs,
    full_rate_loads,
    resolve_design,
    sign_checked,
)
from ident.robot.estimate import RobotModel  # noqa: E402
from ident.robot.paper import PAPER_BLOCK  # noqa: E402
from trajectories.friction import DEFAULT_Q_S  # noqa: E402


def joint_rows(seed: int, j: int, theta: str = "truth"):
    """Joint j's decimated torque rows y, per run its full-rate (dq, s) and kept-row mask,
    the decimation factor, and the truth of its ten paper parameters with their names."""
    params, reg, sim, truth = simulated("paper", seed, 20.0)
    runs = logged(params, sim, 1)
    base = base_parameters(reg)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        design = resolve_design(runs)
        sig, dq_min = design_runs(runs, reg, design)
    design = replace(design, dq_min=dq_min)
    first = RobotModel(reg, "usual", "wls", base=base).fit(sig)
    true_load = RobotModel(reg, "usual", "wls", base=base).fit(sig)
    true_load.coef_ = true_load.coef_.copy()
    true_load.coef_[:true_load.n_theta_] = first.truth_vector(truth)[:first.n_theta_]
    loads = full_rate_loads(sig, runs, design, (true_load if theta == "truth" else first)
                            .load_torque)
    sig, _ = sign_checked(sig, runs, design, first.load_torque, SIGN_CHECK_MIN_KEPT)
    names = [f"{p}{reg.numbers[j]}" for p in PAPER_BLOCK]
    ys, full = [], []
    for i, (f, x) in enumerate(loads):
        rows = np.flatnonzero(sig.experiment == i)
        assert decimation_index(f.n, design.decimation).size == rows.size
        keep = sig.columns.keep[rows, j]
        ys.append(sig.tau[rows, j][keep])
        full.append((f.dq[:, j], x[:, j], keep))
    return (np.concatenate(ys), full, design.decimation, names,
            np.array([truth[n] for n in names]))


def columns(full, r: int, sigma: float | None) -> np.ndarray:
    """The joint's ten paper columns (PAPER_BLOCK order) formed at full rate and decimated;
    hard quadrants with ``sigma`` None."""
    return np.concatenate([decimate(paper_columns(s, dq, sigma, DEFAULT_Q_S), r)[0][keep]
                           for dq, s, keep in full])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--joint", type=int, default=1, help="joint number (1 = the base yaw)")
    ap.add_argument("--theta", choices=("truth", "usual"), default="truth",
                    help="the load's theta: the simulator's or the first usual fit's")
    a = ap.parse_args()
    y, full, r, names, tv = joint_rows(a.seed, a.joint - 1, a.theta)

    def show(label: str, th: np.ndarray, sd: np.ndarray, e: float, extra: str = "") -> None:
        z = (th[:10] - tv) / sd[:10]
        top = np.argsort(-np.abs(z))[:3]
        print(f"{label:24s} sum z^2 {np.sum(z * z):7.1f} / 10  rel. error {e:.5f}  "
              + "  ".join(f"{names[i]} {z[i]:+.1f}" for i in top) + extra, flush=True)

    def linear(W: np.ndarray):
        th, *_ = np.linalg.lstsq(W, y, rcond=None)
        res = y - W @ th
        C = res @ res / (y.size - W.shape[1]) * np.linalg.inv(W.T @ W)
        return th, np.sqrt(np.diag(C)), np.linalg.norm(res) / np.linalg.norm(y)

    print(f"arm3, paper friction, seed {a.seed}, joint {a.joint}, 1 kHz, theta = {a.theta}, "
          f"{y.size} rows (chi^2 0.999 quantile for 10: 29.6)")
    show("hard", *linear(columns(full, r, None)))
    for sigma in (0.5, 1.0, 1.5, 2.0):
        show(f"soft sigma {sigma:g} N m", *linear(columns(full, r, sigma)))
    th0 = linear(columns(full, r, 1.0))[0]
    sol = least_squares(lambda p: columns(full, r, p[10]) @ p[:10] - y, np.r_[th0, 1.0],
                        x_scale="jac", bounds=([-np.inf] * 10 + [1e-3], np.inf),
                        diff_step=1e-4)
    Jm = sol.jac
    sd = np.sqrt(np.diag(sol.fun @ sol.fun / (y.size - 11) * np.linalg.inv(Jm.T @ Jm)))
    show("soft, sigma fitted", sol.x, sd, float(np.linalg.norm(sol.fun) / np.linalg.norm(y)),
         f"  sigma {sol.x[10]:.3f} +- {sd[10]:.3f} N m")


if __name__ == "__main__":
    main()
