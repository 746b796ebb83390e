"""The paper model's products form with eq. 42's products formed at FULL rate on the simulated
3-dof arm, against the simulator's truth: does reading a low-passed, fractional quadrant
P+ (``ident.robot.design.products_columns``) remove the blended-quadrant bias of the
bilinear fit (docs/robot-identification.md, "Known limit: quadrants blended by the
low-pass" and "The products form at full rate on arm3")?

Usage: ``python benchmarks/robot_paper_products.py [--seed 1] [--every 1] [--duration 20]``

The log is that of ``benchmarks/robot_paper_blend.py`` (arm3, paper friction on every joint,
three payload runs, the drives' log every ``--every``-th sample; the helpers of
tests/test_robot_cutoff_band.py). The rows are those of ``jointid fit --robot``'s defaults
(columns chain at the chosen cut-off and decimation, a first usual WLS fit, the sign check
with its 70 % rule, payload torque known, q_s 0.03 rad/s, quadrant band 3 %), then per
variant the paper model, WLS:

- ``bilinear``: the default form (theta shared, per-joint a, b, c, d), its quadrants
  re-decided by its own theta;
- ``products, decimated``: ``form="products"`` on the decimated columns (P and E of each
  decimated row, quadrants once by the first usual fit's theta);
- ``products, full rate``: ``form="products"`` on ``products_columns`` (P+ = the quadrant of
  the first usual fit's tau_out_hat at full rate, the products formed there, then low-passed
  and decimated by the chain's filter: a fractional P+ where the quadrant flips within the
  filter window);
- ``products, full rate, true load``: the same with the simulator's true load tau_out in
  place of tau_out_hat (what the true quadrants at full rate can do; a diagnostic);
- ``products, full rate, true states+load``: also the full-rate rows formed on the
  simulator's true q, dq, ddq instead of the chain's low-passed ones (an oracle: the
  load's jitter above the cut-off is in the products then); ``regime rows out``: the rows
  within the guard of a full-rate sample where the simulator's joint does not slide under
  eq. 30 (at rest or in its zero-load regime) left out on every joint, as the
  ``band: true load, regime`` variant of ``benchmarks/robot_paper_blend.py``;
  ``held torque``: and the torque the simulator applied over the cycle from each sample
  (the one its ddq_true belongs to) instead of the log's mean of the two held around it.

The sigma is eq. 15's (WLS) for every variant: the honest sigma of ``jointid fit --robot``
(:func:`ident.robot.uncertainty.assess`) refuses the products form, and nothing is pruned.
The truth in the products' parameterisation is ``RobotModel.truth_vector`` (for
``form="products"``: a_m, b_m, a_g, b_g of the joint times its true base parameters theta_i
of each load column and times 1 for its known payload torque, then c_m, d_m, c_g, d_g, FV,
OFF). Printed per variant: sum of z^2 = ((estimate - truth) / sigma)^2 over the free
parameters / their number (the chi^2 0.999 quantile for that number), per joint, the largest
|z| and the per-joint relative error (with the sum of z^2 of the Stribeck products b_m, b_g,
d_m, d_g apart: ``E``). Printed first, per run and joint: the quadrant flips
per second at full rate of the true load sign(tau_out dq), of the first usual fit's
sign(tau_out_hat dq) and of the true load low-passed (4th-order Butterworth at the cut-off,
zero phase), the share of full-rate samples where tau_out_hat's quadrant is not the true
load's, and the share of the joint's kept rows whose full-rate P+ is fractional (blended).
Printed last: how much torque that is not eq. 30 (the simulator's samples at rest or in its
zero-load regime) the chain's anti-alias filter carries into the rows away from them
(:func:`_leak`).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

import numpy as np  # noqa: E402
import scipy.stats  # noqa: E402
from scipy.ndimage import binary_dilation  # noqa: E402
from scipy.signal import butter, filtfilt  # noqa: E402
from test_robot_cutoff_band import logged, simulated  # noqa: E402
from test_robot_fit import PAYLOADS  # noqa: E402

from ident.chain import decimate, decimation_index, selection  # noqa: E402
from ident.fitting import SIGN_CHECK_MIN_KEPT  # noqa: E402
from ident.robot import RobotIdentError  # noqa: E402
from ident.robot.base import base_parameters  # noqa: E402
from ident.robot.design import (  # noqa: E402
    design_runs,
    full_rate_loads,
    products_columns,
    resolve_design,
    sign_checked,
)
from ident.robot.estimate import RobotModel  # noqa: E402
from ident.robot.signals import RobotPayloadData, RobotSignals  # noqa: E402
from sim_drivers.arm_plant import output_arm_torque  # noqa: E402
from trajectories.friction import DEFAULT_Q_S  # noqa: E402

#: ``jointid fit --robot``'s quadrant band on several joints (ident.cli_robot.fit_robot).
BAND = 0.03


def _flips(x: np.ndarray, dur_s: float) -> float:
    """Sign changes of x per second."""
    return float(np.sum(np.diff(np.sign(x)) != 0) / dur_s)


def _leak(reg, base, sim, truth, design, k: slice) -> None:
    """How much of the simulator's torque that is not eq. 30 (at rest, in the zero-load
    regime) the chain's anti-alias filter carries into rows away from those samples: the
    products form fitted on the true states at the log's rate with the applied torque on the
    sliding samples only (no filter; quadrants of the true theta: the model is exact there),
    e = tau_applied - its prediction on every sample (0 where the joint slides), then e
    through :func:`ident.chain.decimate`; printed per run and joint, in % of the torque's RMS:
    e's RMS, and the decimated e's RMS on the rows with |dq| > dq_min farther than 1, 2 and 4
    guards from any sample that does not slide."""
    sigs = []
    for r, p in zip(sim, PAYLOADS, strict=True):
        pay = RobotPayloadData() if p is None else RobotPayloadData(p.mass, p.com, p.inertia)
        sigs.append(RobotSignals(t=r.t[k], q=r.q_true[k], dq=r.dq_true[k], ddq=r.ddq_true[k],
                                 tau=r.tau_applied[k], joints=reg.joints, payloads=(pay,),
                                 source=f"sim payload {r.payload_mass_kg} kg"))
    sliding = [replace(s, tau=np.where(r.regime[k] == 0, s.tau, np.nan))
               for s, r in zip(sigs, sim, strict=True)]
    usual = RobotModel(reg, "usual", base=base).fit(sliding)
    exact = RobotModel(reg, "paper", "ls", base=base, form="products", quadrant_band=0.0,
                       quadrant_theta=usual.truth_vector(truth)[:usual.n_theta_]).fit(sliding)
    g = design.guard
    print(f"non-eq.-30 torque through the filter; per run and joint, % of the torque's RMS: "
          f"e on the sliding samples (the exact model: 0), e, decimated e farther than {g}, "
          f"{2 * g}, {4 * g} samples from a non-sliding one")
    for i, (s, r) in enumerate(zip(sigs, sim, strict=True)):
        e = s.tau - exact.predict(s)
        slide = r.regime[k] == 0
        de, idx = decimate(e, design.decimation)
        for j in range(reg.k):
            rms = np.sqrt(np.mean(s.tau[:, j] ** 2)) / 100
            bad = r.regime[k][:, j] != 0
            out = [np.sqrt(np.mean(e[slide[:, j], j] ** 2)) / rms,
                   np.sqrt(np.mean(e[:, j] ** 2)) / rms]
            for m in (1, 2, 4):
                far = (~binary_dilation(bad, iterations=m * g)[idx]
                       & (np.abs(s.dq[idx, j]) > design.dq_min))
                # (nan: no such row)
                out.append(np.sqrt(np.mean(de[far, j] ** 2)) / rms if far.any() else np.nan)
            print(f"  run {i} j{j + 1}: {out[0]:.1e} " + " ".join(f"{x:7.3f}" for x in out[1:]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--every", type=int, default=1, help="keep every n-th sample of 1 kHz")
    ap.add_argument("--duration", type=float, default=20.0, help="seconds per run")
    ap.add_argument("--no-bilinear", action="store_true", help="skip the bilinear fit")
    a = ap.parse_args()
    t0 = time.perf_counter()
    params, reg, sim, truth = simulated("paper", a.seed, a.duration)
    runs = logged(params, sim, a.every)
    assert all(r.payload.arm_m is None for r in runs)  # fit_robot's payload "known"
    k = slice(None, None, a.every)
    true_loads = [output_arm_torque(params, r.q_true, r.dq_true, r.ddq_true, p)[k]
                  for r, p in zip(sim, PAYLOADS, strict=True)]
    base = base_parameters(reg)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the cut-off at its lower bound (250 Hz): expected
        design = resolve_design(runs)
        sig, dq_min = design_runs(runs, reg, design)
    design = replace(design, dq_min=dq_min)
    first = RobotModel(reg, "usual", "wls", base=base).fit(sig)
    loads = full_rate_loads(sig, runs, design, first.load_torque)
    sig, kept = sign_checked(sig, runs, design, first.load_torque, SIGN_CHECK_MIN_KEPT,
                             loads=loads)
    fs = 1.0 / float(np.median(np.diff(runs[0].t)))
    cut = design.cutoff_hz
    print(f"arm3, paper friction, seed {a.seed}, {fs:.0f} Hz, {a.duration:g} s per run, "
          f"cut-off {cut:g} Hz, decimation {design.decimation}; sign check keeps "
          + " ".join(f"{x:.3f}" for x in kept) + f"  ({time.perf_counter() - t0:.0f} s)",
          flush=True)

    def true_load(full):
        """The simulator's tau_out on the full-rate samples ``full`` of run ``full.source``."""
        i = [r.source for r in runs].index(full.source)
        f = loads[i][0]
        return true_loads[i][f.keep]

    t1 = time.perf_counter()
    full = products_columns(sig, runs, reg, design, first.load_torque, DEFAULT_Q_S, base=base)
    print(f"products_columns: {time.perf_counter() - t1:.0f} s", flush=True)
    pp = full.columns.products.pplus
    b, aa = butter(4, cut / (0.5 * fs))
    print("per run and joint: quadrant flips per s at full rate, true load / tau_out_hat / "
          "low-passed true load; share of samples tau_out_hat's quadrant != the true's; "
          "share of kept rows with a fractional P+")
    for i, (f, x_hat) in enumerate(loads):
        x = true_loads[i][f.keep]
        dq_true = sim[i].dq_true[k][f.keep]
        dur = f.n / fs
        rows = np.flatnonzero(sig.experiment == i)
        for j in range(reg.k):
            lo = filtfilt(b, aa, x[:, j])
            wrong = np.mean(np.sign(x_hat[:, j] * f.dq[:, j]) != np.sign(x[:, j] * dq_true[:, j]))
            kr = rows[full.columns.keep[rows, j]]
            frac = np.mean((pp[kr, j] > 0.01) & (pp[kr, j] < 0.99))
            print(f"  run {i} j{j + 1}: {_flips(x[:, j] * dq_true[:, j], dur):6.1f} "
                  f"{_flips(x_hat[:, j] * f.dq[:, j], dur):6.1f} "
                  f"{_flips(lo * dq_true[:, j], dur):6.1f}   {wrong:.3f}   {frac:.3f}")


    def show(label: str, m: RobotModel, t_fit: float) -> None:
        tv = m.truth_vector(truth)
        free = ~np.isin(np.array(m.names_), list(m.fixed_))
        z = (m.coef_ - tv) / m.std_
        names = np.array(m.names_)
        z, names = z[free], names[free]
        per = [float(np.sum(z[np.char.endswith(names.astype(str), str(n))] ** 2))
               for n in reg.numbers]
        top = np.argsort(-np.abs(z))[:3]
        q = scipy.stats.chi2.ppf(0.999, z.size)
        # the Stribeck products (b_m, b_g, d_m, d_g: E = exp(-|dq| / q_s) columns) apart
        stribeck = np.array([n.split("_")[0][:1] in "bd" and not n.startswith("FV")
                             for n in names.astype(str)])
        print(f"{label:34s} {np.sum(z ** 2):6.0f} / {z.size:3d} ({q:3.0f})  "
              + " ".join(f"{v:5.0f}" for v in per)
              + f"  E {np.sum(z[stribeck] ** 2):5.0f} / {stribeck.sum()}  "
              + " ".join(f"{names[i]} {z[i]:+.1f}" for i in top) + "  "
              + " ".join(f"{100 * m.rel_error_[j]:.2f}%" for j in reg.joints)
              + f"  ({t_fit:.0f} s)", flush=True)

    def fit(label: str, signals, **kw) -> None:
        t = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                m = RobotModel(reg, "paper", "wls", q_s=DEFAULT_Q_S, base=base,
                               **kw).fit(signals)
            except RobotIdentError as exc:  # not identifiable on the rows left
                print(f"{label:34s} not fitted: {str(exc)[:150]}", flush=True)
                return
        show(label, m, time.perf_counter() - t)

    # the rows within the guard of a full-rate sample where the simulator's joint does not
    # slide under eq. 30 (at rest, or in its zero-load regime) left out, on every joint
    regime = sig.columns.keep.copy()
    for i, (f, _) in enumerate(loads):
        rows = np.flatnonzero(sig.experiment == i)
        regime[rows] &= selection(f.dq, design.dq_min, design.guard,
                                  decimation_index(f.n, design.decimation),
                                  sim[i].regime[k][f.keep] != 0)
    print("rows left out near the simulator's rest or zero-load regime per joint: "
          + " ".join(f"{1 - x:.3f}" for x in regime.sum(axis=0) / sig.columns.keep.sum(axis=0)))

    print(f"{'variant':34s} sum z^2 / n (chi2 .999)  per joint   of which b, d (E terms)  "
          "largest |z|   rel. error per joint", flush=True)

    def no_regime(x):
        return replace(x, columns=replace(x.columns, keep=regime))

    fit("products, full rate", full, form="products")
    fit("  the same, regime rows out", no_regime(full), form="products")
    del full
    fit("products, decimated", sig, form="products", quadrant_band=BAND)
    if not a.no_bilinear:
        fit("bilinear", sig, quadrant_band=BAND)
    t1 = time.perf_counter()
    true_q = products_columns(sig, runs, reg, design, true_load, DEFAULT_Q_S, base=base)
    print(f"products_columns (true load): {time.perf_counter() - t1:.0f} s", flush=True)
    fit("products, full rate, true load", true_q, form="products")
    del true_q
    # the oracle: the full-rate rows formed on the simulator's true states (not the chain's
    # low-passed ones) with the true load's quadrants, then filtered and decimated as above
    states = tuple(replace(f, q=r.q_true[k][f.keep], dq=r.dq_true[k][f.keep],
                           ddq=r.ddq_true[k][f.keep]) for (f, _), r in zip(loads, sim, strict=True))
    oracle = replace(sig, columns=replace(sig.columns, full=states))
    oracle = products_columns(oracle, runs, reg, design, true_load, DEFAULT_Q_S, base=base)
    fit("products, full rate, true states+load", oracle, form="products")
    fit("  the same, regime rows out", no_regime(oracle), form="products")
    # and the torque the simulator applied over the cycle from each sample (the one its
    # ddq_true is the acceleration of; the log's is the mean of the two held around the
    # sample), on the same rows
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        held = design_runs(logged(params, sim, a.every, held=True), reg, design)[0]
    held = replace(held, columns=replace(held.columns, keep=sig.columns.keep, full=states))
    held = products_columns(held, runs, reg, design, true_load, DEFAULT_Q_S, base=base)
    fit("  the same, held torque", no_regime(held), form="products")
    _leak(reg, base, sim, truth, design, k)
    print(f"total {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
