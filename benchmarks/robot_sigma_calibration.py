"""Calibration of the robot fit's standard deviations (eq. 15, ``RobotModel.std_``/``cov_``)
against the truth over noise seeds, and what makes them too small.

    OPENBLAS_NUM_THREADS=1 nice -n 10 python benchmarks/robot_sigma_calibration.py [--seeds 40]
        [--only "cols ls,states iv"] [--blocks 10]

Data: the simulated 3-dof arm of tests/test_robot_ratio_rotor.py (usual friction, 12 s,
payloads 0 / 5 / 10 kg declared at 0.8 times their truth, so the payload ratio is 1.25;
known rotor inertias; the true positions and the applied torque plus 1 % of each joint's load
as white noise at 1 kHz). One simulation; the seeds draw the torque noise only. Chains: the
columns chain (``design_runs``, the CLI's, with its settings: r = 20 for LS/WLS, r = 8 with
the instruments) and the states chain (``preprocess_runs``); IDIM-LS, WLS, IV. Parameters
compared: the base parameters and the ratio (16).

Per configuration it prints

* the mean Mahalanobis distance e^T C^-1 e of the estimate to the truth (chi-square(16): mean
  16, 99 % quantile 32.0) and how many seeds exceed the 99 % quantile, with C = eq. 15
  (``cov_``), ``robust_covariance(long_run=False)`` (per-joint residual variances) and
  ``robust_covariance()`` (also each joint's residual long-run variance);
* the noise-free fit's error in units of eq. 15 (the chain's deterministic bias: same data,
  no noise);
* tr(C^-1 S) / p, S the spread over seeds of the fit minus the noise-free fit (the noise's
  part, exact: the usual model is linear in the torque, the rows do not depend on it): the
  variance the covariance misses, 1 when calibrated;
* per parameter: mean z^2 and the shares outside 2 and 3 sigma for eq. 15, the jackknife, the
  robust one (``robust_covariance()``, its long-run factors as measured), the honest sigma of
  ``assess`` (max(robust, jackknife) with the long-run factors at least
  ``LONG_RUN_FLOOR`` = 1, raised to the IDIM-IV difference where |z_iv| > 4; no pruning)
  and, for comparison, the honest sigma before (max(eq. 15, jackknife) with the same raise:
  :func:`honest_before`);
* the filter factor 1 / (r var(decimate(white))) of the chain's decimation.

``--ur10 N``: instead, the 2-sigma coverage of ``benchmarks/sigma_coverage.py`` (UR10, paper
model, IDIM-WLS, friction-dominated wrists with drive noise in the motion: errors in
variables; seeds 100 to 100 + N - 1) for eq. 15, the honest sigma of ``assess``, the robust
covariance, and the honest sigma of ``assess`` before and after it took the robust one.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import numpy as np  # noqa: E402
import scipy.stats  # noqa: E402
from test_robot_fit import NOISE, PAYLOADS, _simulate  # noqa: E402
from test_robot_ratio_rotor import ROOT, SCALE  # noqa: E402

from ident.chain import decimate  # noqa: E402
from ident.preprocess import TORQUE_DELAY  # noqa: E402
from ident.robot.base import base_parameters  # noqa: E402
from ident.robot.design import design_runs, resolve_design  # noqa: E402
from ident.robot.estimate import RATIO, RobotModel  # noqa: E402
from ident.robot.loaders import RawRobotRun, RobotPreprocessing, preprocess_runs  # noqa: E402
from ident.robot.regressor import RobotRegressor  # noqa: E402
from ident.robot.signals import RobotPayloadData  # noqa: E402
from ident.robot.uncertainty import (  # noqa: E402
    Z_IV,
    assess,
    long_run_factor,
    robust_covariance,
)
from sim_drivers.arm import ArmParams  # noqa: E402
from trajectories.robot import load_robot  # noqa: E402

CONFIGS = [(ch, m) for ch in ("cols", "states") for m in ("ls", "wls", "iv")]


def setup():
    """(params, runs, known-rotor regressor, its base, truth, noise per joint [N m])."""
    robot = load_robot(ROOT / "examples" / "robots" / "arm3.toml")
    c = ArmParams.from_robot(robot).friction.c_m
    friction = dict(a_m=1.0, b_m=0.0, a_g=1.0, b_g=0.0, d_m=0.0, d_g=0.0, c_g=c)
    params, reg, _, runs = _simulate("arm3", friction, duration_s=12.0, seed=3)
    known = RobotRegressor(reg.robot, known_rotor_inertia=True)
    truth = params.truth(None)
    for j in reg.numbers:
        truth[f"FC{j}"] = truth[f"c_m{j}"]
    truth[RATIO] = 1.0 / SCALE
    noise = NOISE * params.drive.torque_noise_std_Nm / 0.01
    return params, runs, known, base_parameters(known), truth, noise


def raw_runs(runs, noise, seed: int, scale: float = 1.0) -> list[RawRobotRun]:
    """tests/test_robot_ratio_rotor.py's ``_raw`` with the noise times ``scale``."""
    rng = np.random.default_rng(seed)
    raw = []
    for r, p in zip(runs, PAYLOADS, strict=True):
        pay = RobotPayloadData() if p is None else RobotPayloadData(
            SCALE * p.mass, p.com, None if p.inertia is None else SCALE * np.asarray(p.inertia))
        tau = r.tau_applied + scale * rng.standard_normal(r.tau_applied.shape) * noise
        raw.append(RawRobotRun(f"payload {r.payload_mass_kg} kg", r.t, r.q_true, tau,
                               q_ref=r.q_ref, payload=pay))
    return raw


def build(runs, noise, known, chain: str, iv: bool, seed: int, scale: float = 1.0):
    raw = raw_runs(runs, noise, seed, scale)
    if chain == "cols":
        st = resolve_design(raw, torque_delay=TORQUE_DELAY, instruments=iv)
        return design_runs(raw, known, st, instruments=iv)[0], st
    return preprocess_runs(raw, known.joints, RobotPreprocessing(torque_delay=TORQUE_DELAY)), None


def fit(known, base, method: str, sig) -> RobotModel:
    kw = {}
    if sig.columns is None:
        kw["dq_min"] = 0.01 * float(np.max(np.abs(sig.dq)))
    return RobotModel(known, "usual", method, base=base, payload_ratio=True, **kw).fit(sig)


def filter_factor(r: int, n: int = 400_000) -> float:
    """1 / (r var(decimate(white, r))): white noise's variance at low frequency over the
    variance of one decimated row."""
    y, _ = decimate(np.random.default_rng(0).standard_normal(n), r)
    return 1.0 / (r * float(np.var(y[200:-200])))


def ur10_coverage(n_seeds: int) -> None:
    """The ``--ur10`` mode (module doc)."""
    from sigma_cases import friction_mask, gauged_truth, wrist_arm, wrist_signals
    params, reg, base = wrist_arm()
    tags = ("eq. 15", "honest before", "robust", "honest")
    hits = {t: np.zeros(4) for t in tags}
    hits3 = {t: np.zeros(4) for t in tags}
    for seed in range(100, 100 + n_seeds):
        t0 = time.time()
        sig = wrist_signals(params, reg, seed, 10.0)
        m = RobotModel(reg, "paper", "wls", base=base).fit(sig)
        u = assess(m, sig, n_blocks=10, iv=True, prune=False)
        rob = np.sqrt(np.diag(robust_covariance(m, sig)))
        err = np.abs(m.coef_ - gauged_truth(m, params))
        mask = friction_mask(m)
        wrist = mask & np.array([n[-1] in "456" for n in m.names_])
        sds = {"eq. 15": u.std_analytic, "honest before": honest_before(m, u), "robust": rob,
               "honest": u.std}
        for t, sd in sds.items():
            h = err <= 2 * sd
            hits[t] += [h[mask].sum(), mask.sum(), h[wrist].sum(), wrist.sum()]
            h3 = err <= 3 * sd
            hits3[t] += [h3[mask].sum(), mask.sum(), h3[wrist].sum(), wrist.sum()]
        print(f"seed {seed}: {time.time() - t0:.1f} s, long-run factor per joint "
              f"{np.round(long_run_factor(m, sig), 2)}", flush=True)
    print(f"\nshare of 2-sigma intervals containing the truth, {n_seeds} seeds (friction "
          f"parameters of the paper model; 95.4 % expected)")
    for t, h in hits.items():
        print(f"  {t:16s} all {h[0] / h[1]:6.1%}  wrists {h[2] / h[3]:6.1%}")
    print("3-sigma intervals (99.7 % expected)")
    for t, h in hits3.items():
        print(f"  {t:16s} all {h[0] / h[1]:6.1%}  wrists {h[2] / h[3]:6.1%}")


def honest_before(m: RobotModel, u) -> np.ndarray:
    """The honest sigma as ``assess`` gave it before the robust eq. 15 (unpruned fit):
    max(eq. 15, jackknife), raised to |chi - chi_iv| where |z_iv| > 4."""
    std = np.fmax(u.std_analytic, u.std_jackknife)
    if u.z_iv is None:
        return std
    d = m.coef_ - u.coef_iv
    with np.errstate(divide="ignore", invalid="ignore"):
        z = d / np.sqrt(u.std_iv ** 2 + std ** 2)
    return np.where(np.abs(np.nan_to_num(z)) > Z_IV, np.fmax(std, np.abs(d)), std)


def _key(chain: str, method: str) -> tuple[str, bool]:
    return chain, chain == "cols" and method == "iv"


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=40)
    ap.add_argument("--only", default="", help='e.g. "cols ls,states iv"')
    ap.add_argument("--blocks", type=int, default=10, help="jackknife units (assess)")
    ap.add_argument("--ur10", type=int, default=0, metavar="N",
                    help="the UR10 coverage over N seeds instead (module doc)")
    a = ap.parse_args(argv)
    if a.ur10:
        ur10_coverage(a.ur10)
        return
    warnings.simplefilter("ignore", UserWarning)  # the cut-off's lower bound, every seed
    configs = [c for c in CONFIGS if not a.only or f"{c[0]} {c[1]}" in a.only.split(",")]
    t0 = time.time()
    params, runs, known, base, truth, noise = setup()
    print(f"simulated in {time.time() - t0:.1f} s; noise per joint {noise} N m")
    keys = sorted({_key(*c) for c in configs})
    e0, names = {}, None
    for key in keys:
        sig0, st = build(runs, noise, known, key[0], key[1], 0, scale=0.0)
        if st is not None:
            print(f"{key[0]} instruments={key[1]}: cut-off {st.cutoff_hz:g} Hz, r = "
                  f"{st.decimation}, filter factor {filter_factor(st.decimation):.3f}")
        for c in configs:
            if _key(*c) == key:
                m = fit(known, base, c[1], sig0)
                nb = m.n_base_ + 1
                names = m.names_[:nb]
                e0[c] = (m.coef_ - m.truth_vector(truth))[:nb]
    rec = {c: {k: [] for k in ("e", "eq15", "het", "rob", "jack", "honest", "old", "f")}
           for c in configs}
    for s in range(a.seeds):
        t1 = time.time()
        sigs = {key: build(runs, noise, known, key[0], key[1], s)[0] for key in keys}
        for c in configs:
            sig = sigs[_key(*c)]
            m = fit(known, base, c[1], sig)
            R = rec[c]
            R["e"].append((m.coef_ - m.truth_vector(truth))[:nb])
            R["eq15"].append(m.cov_[:nb, :nb])
            R["het"].append(robust_covariance(m, sig, long_run=False)[:nb, :nb])
            R["rob"].append(robust_covariance(m, sig)[:nb, :nb])
            R["f"].append(long_run_factor(m, sig))
            u = assess(m, sig, n_blocks=a.blocks, prune=False)
            R["jack"].append(np.asarray(u.std_jackknife)[:nb])
            R["honest"].append(np.asarray(u.std)[:nb])
            R["old"].append(honest_before(m, u)[:nb])
        print(f"seed {s}: {time.time() - t1:.1f} s", flush=True)
    q99 = scipy.stats.chi2.ppf(0.99, nb)
    print(f"\n{nb} parameters (base + ratio): chi-square mean {nb}, 99 % quantile {q99:.1f}; "
          f"{a.seeds} seeds; expected shares outside 2 / 3 sigma 4.6 % / 0.27 %")
    for c in configs:
        R = rec[c]
        E = np.array(R["e"])
        U = E - e0[c]
        S = U.T @ U / len(U)
        print(f"\n== {c[0]} {c[1]}")
        C15 = np.array(R["eq15"])
        b = e0[c]
        zb = b / np.sqrt(np.diag(C15.mean(0)))
        print(f"  noise-free fit: Mahalanobis {b @ np.linalg.solve(C15.mean(0), b):5.2f}, "
              f"max |z| {np.abs(zb).max():.2f} ({names[int(np.argmax(np.abs(zb)))]})")
        print(f"  long-run factor per joint {np.round(np.mean(R['f'], axis=0), 3)}")
        for tag, label in (("eq15", "eq. 15"), ("het", "per-joint sigma"),
                           ("rob", "robust")):
            Cs = np.array(R[tag])
            d = np.array([e @ np.linalg.solve(x, e) for e, x in zip(E, Cs, strict=True)])
            lam = float(np.trace(np.linalg.solve(Cs.mean(0), S)) / nb)
            print(f"  {label:16s} Mahalanobis mean {d.mean():6.2f}, > q99 {int((d > q99).sum()):2d}"
                  f"/{len(d)}; noise's variance / covariance {lam:.3f}")
        sds = {"eq. 15": np.sqrt(np.array([np.diag(x) for x in C15])),
               "jackknife": np.array(R["jack"]),
               "robust": np.sqrt(np.array([np.diag(x) for x in R["rob"]])),
               "honest before": np.array(R["old"]), "honest": np.array(R["honest"])}
        for tag, sd in sds.items():
            Z = E / sd
            print(f"  {tag:16s} per parameter: mean z^2 {np.mean(Z ** 2):5.2f}, outside 2 sigma "
                  f"{np.mean(np.abs(Z) > 2):5.1%}, 3 sigma {np.mean(np.abs(Z) > 3):5.1%}")


if __name__ == "__main__":
    main()
