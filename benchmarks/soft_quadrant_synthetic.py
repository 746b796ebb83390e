"""The soft quadrant weight on synthetic data: does eq. 30 with the quadrant's expectation under
the load's jitter remove the blend's bias (docs/robot-identification.md, "Known limit:
quadrants blended by the low-pass")? A design check for the estimator, numpy only; nothing in
the product uses it yet.

Usage: ``python benchmarks/soft_quadrant_synthetic.py [--seeds 1 2 3]``

One joint at 1 kHz, 120 s: a smooth velocity dq and a smooth load s(t) (sums of sines below
1.5 Hz), and a jitter n(t) above 80 Hz (white noise high-passed, RMS sigma = 1 N m, as the
closed loop's reaction to the encoder steps on the simulated arm3's yaw: 1.0-1.6 N m above
the cut-off). The true load is x = s + n and the torque eq. 30 without Stribeck terms, its
quadrant the true one at full rate::

    tau = a_m P+ x + a_g P- x + c sign(dq) + F_V dq + noise,   P+ = [x dq > 0]

(a_m 1.25, a_g 0.80, c 0.7 N m, F_V 0.3 N m s/rad, noise 0.05 N m). The chain low-passes
(Butterworth order 4, 50 Hz, zero phase) and decimates by 10, leaving out |dq| <= 0.02. The
model knows s (what a load model on the low-passed states predicts: the jitter is not in
them), never x. Fits, each linear least squares with eq. 15's sigma, z = (estimate -
truth) / sigma:

- ``hard``: the columns P+(s) s, P-(s) s, sign(dq), dq -- the quadrant of the smooth load, as
  the product does today;
- ``soft, sigma given``: the expectation of P+ x under x = s + n, n ~ N(0, sigma^2), with
  mu = s sign(dq): E[P+ x] = sign(dq) (mu Phi(mu / sigma) + sigma phi(mu / sigma)), and
  E[P- x] = s - E[P+ x] (the rectified jitter is in it), for a few sigma;
- ``soft, sigma fitted``: the same with sigma a parameter of the model, fitted with the
  others by nonlinear least squares (scipy ``least_squares``), its sigma from the Jacobian.

No column reads the measured torque: sigma is a model parameter like q_s.
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import butter, filtfilt

from trajectories.friction import soft_quadrant_weights

FS, T = 1000.0, 120.0  # [Hz], [s]
TRUTH = np.array([1.25, 0.80, 0.7, 0.3])  # a_m, a_g, c [N m], F_V [N m s/rad]
SIGMA = 1.0  # jitter RMS [N m]


def simulate(seed: int):
    """(s, dq, tau) at full rate."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(FS * T)) / FS

    def smooth(n: int, f: float) -> np.ndarray:
        return sum(np.sin(2 * np.pi * rng.uniform(0.05, f) * t + rng.uniform(0, 6.3)) / (k + 1)
                   for k in range(n))
    dq = smooth(4, 0.3)
    dq /= np.abs(dq).max()  # [rad/s]
    s = 2.0 * smooth(5, 1.5)  # [N m]
    bh, ah = butter(4, 80 / (FS / 2), "high")
    n = filtfilt(bh, ah, rng.standard_normal(t.size))
    x = s + SIGMA * n / n.std()
    am, ag, c, fv = TRUTH
    pp = (x * dq > 0).astype(float)
    tau = (am * pp * x + ag * (1 - pp) * x + c * np.sign(dq) + fv * dq
           + 0.05 * rng.standard_normal(t.size))
    return s, dq, tau


def expected_plus(s: np.ndarray, dq: np.ndarray, sigma: float) -> np.ndarray:
    """E[P+ x] for x = s + n, n ~ N(0, sigma^2) [N m], shape (n,)
    (:func:`trajectories.friction.soft_quadrant_weights`)."""
    pp, _, r = soft_quadrant_weights(s, dq, sigma)
    return pp * s + r


def one_seed(seed: int) -> None:
    """Print the three fits' z on one seed's data."""
    b, aa = butter(4, 50 / (FS / 2))
    s, dq, tau = simulate(seed)
    idx = np.arange(0, s.size, 10)
    idx = idx[np.abs(dq[idx]) > 0.02]
    y = filtfilt(b, aa, tau)[idx]
    sg = np.sign(dq)

    def design(cols):
        return np.column_stack([filtfilt(b, aa, v)[idx] for v in cols])

    def linear(W):
        th, *_ = np.linalg.lstsq(W, y, rcond=None)
        r = y - W @ th
        sd = np.sqrt(np.diag(r @ r / (y.size - W.shape[1]) * np.linalg.inv(W.T @ W)))
        return th, sd, np.linalg.norm(r) / np.linalg.norm(y)

    print(f"seed {seed}: z of (a_m, a_g, c, F_V), relative error")
    P = (s * dq > 0).astype(float)
    th, sd, e = linear(design([P * s, (1 - P) * s, sg, dq]))
    print(f"  hard (quadrant of s)       {np.round((th - TRUTH) / sd, 1)}  {e:.5f}")
    for sigma in (0.5, 0.75, 1.0, 1.25, 1.5):
        ep = expected_plus(s, dq, sigma)
        th, sd, e = linear(design([ep, s - ep, sg, dq]))
        print(f"  soft, sigma {sigma:4.2f} given   {np.round((th - TRUTH) / sd, 1)}  {e:.5f}")

    def resid(p):
        ep = expected_plus(s, dq, p[4])
        return design([ep, s - ep, sg, dq]) @ p[:4] - y
    sol = least_squares(resid, np.array([1.0, 1.0, 0.5, 0.2, 0.5]), x_scale="jac",
                        bounds=([-np.inf] * 4 + [1e-2], np.inf))
    J = sol.jac
    sd = np.sqrt(np.diag(sol.fun @ sol.fun / (y.size - 5) * np.linalg.inv(J.T @ J)))
    z = (sol.x - np.r_[TRUTH, SIGMA]) / sd
    print(f"  soft, sigma fitted         {np.round(z[:4], 2)}  sigma {sol.x[4]:.4f} +- "
          f"{sd[4]:.4f} (truth {SIGMA:g}, z {z[4]:+.2f})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    for seed in ap.parse_args().seeds:
        one_seed(seed)


if __name__ == "__main__":
    main()
