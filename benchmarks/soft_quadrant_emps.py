"""The soft quadrant weight on real data: the EMPS benchmark (../shared/data/emps), the paper
friction's ten terms with hard or soft quadrants, relative error on the identification file and
the cross-test on DATA_EMPS_PULSES.mat (docs/robot-identification.md, after the arm3 table).
A design check; nothing in the product uses it yet.

Usage: ``python benchmarks/soft_quadrant_emps.py``

The reference script's chain (Butterworth order 4 at 100 Hz on q, zero phase, central
differences, decimation 10, every sample: ``jointid fit``'s EMPS settings in
tests/test_ident_emps.py); force = gtau * vir [N]; the load s = M ddq with M the published
95.1089 kg (the axis is horizontal: inertial load only), fixed, so that only the friction's
ten terms are fitted (linear least squares on the decimated rows). Soft quadrants as
benchmarks/soft_quadrant_arm3.py (P+ -> Phi(mu / sigma), P+ x -> Phi s + r, P- x ->
(1 - Phi) s - r, r = sigma phi(mu / sigma) sign(dq), mu = s sign(dq)), for a few given sigma
[N] and with sigma chosen by the identification file's residual (scipy ``least_squares``, one
variable, the ten terms solved for at each sigma); for q_s 0.005, 0.01, 0.02 m/s.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import scipy.io as sio
from scipy.optimize import least_squares
from scipy.signal import butter, filtfilt

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from soft_quadrant_common import paper_columns  # noqa: E402

from ident.chain import decimate  # noqa: E402

DATA = ROOT.parent / "shared" / "data" / "emps"
M = 95.1089  # [kg], Janot, Gautier & Brunot 2019
R = 10


def load(name: str):
    """(dq [m/s], ddq [m/s^2], force [N]) at full rate, the reference script's chain."""
    d = sio.loadmat(DATA / name)
    t = d["t"].ravel()
    q = d["qm"].ravel()
    tau = d["gtau"].item() * d["vir"].ravel()
    b, a = butter(4, 100 / (0.5 / float(np.median(np.diff(t)))))
    dq = np.gradient(filtfilt(b, a, q), t)
    return dq, np.gradient(dq, t), tau


def columns(dq, ddq, sigma: float | None, q_s: float) -> np.ndarray:
    """The ten paper columns (a_m, b_m, a_g, b_g, c_m, d_m, c_g, d_g, F_V, offset), decimated."""
    return decimate(paper_columns(M * ddq, dq, sigma, q_s), R)[0]


def main() -> None:
    if not DATA.is_dir():
        sys.exit(f"soft_quadrant_emps: {DATA} not found (the shared materials beside the repo)")
    tr, va = load("DATA_EMPS.mat"), load("DATA_EMPS_PULSES.mat")
    yt, yv = decimate(tr[2], R)[0], decimate(va[2], R)[0]
    for q_s in (0.005, 0.01, 0.02):
        def fit(sigma, q_s=q_s):
            th = np.linalg.lstsq(columns(tr[0], tr[1], sigma, q_s), yt, rcond=None)[0]
            e = np.linalg.norm(yt - columns(tr[0], tr[1], sigma, q_s) @ th) / np.linalg.norm(yt)
            ev = np.linalg.norm(yv - columns(va[0], va[1], sigma, q_s) @ th) / np.linalg.norm(yv)
            return th, e, ev

        def line(label, sigma, fit=fit):
            th, e, ev = fit(sigma)
            print(f"  {label:26s} rel. error {e:.4f}, cross-test {ev:.4f}; a_m {th[0]:.3f} "
                  f"a_g {th[2]:.3f} c_m {th[4]:.2f} c_g {th[6]:.2f} N")
        print(f"q_s {q_s} m/s")
        line("hard", None)
        for sigma in (5.0, 20.0, 50.0, 100.0):
            line(f"soft, sigma {sigma:g} N", sigma)
        sol = least_squares(lambda p, fit=fit: np.array([fit(p[0])[1]]), [20.0],
                            bounds=(0.1, 1e3))
        line(f"soft, sigma fitted {sol.x[0]:.2f} N", sol.x[0])


if __name__ == "__main__":
    main()
