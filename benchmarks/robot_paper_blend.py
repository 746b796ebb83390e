"""Why the paper model of ``jointid fit --robot`` misses its sigma on the simulated 3-dof arm
(docs/robot-identification.md, "The default cut-off on logs slower than 1 kHz" and "Known
limit: quadrants blended by the low-pass"): the chi^2 against the truth per joint under
variants of the fit that each switch one suspect off.

Usage: ``python benchmarks/robot_paper_blend.py [--seed 1] [--every 1] [--duration 20]``

The log is that of ``benchmarks/bench_robot_cutoff_band.py`` (arm3, paper friction on every
joint, three payload runs, the drives' log every ``--every``-th sample; the helpers of
tests/test_robot_cutoff_band.py), fitted by :func:`ident.cli_robot.fit_files` with its
defaults (both models, WLS, columns chain, sign check, honest sigma, pruning; no feasibility
search). Printed first, per joint and run, from the simulator's truth: the true load
tau_out's RMS below and above the fit's cut-off (4th-order Butterworth, zero phase: a proxy of
the chain's low-pass), how often per second the true quadrant sign(tau_out dq) flips against
the low-passed load's, and the share of samples in the simulator's zero-load regime (sliding
with tau_out = 0, the dry friction anywhere between the quadrants'). Then, per variant, the
paper model's sum of z^2 = ((estimate - truth) / sigma)^2 over its unpruned parameters, per
joint, the number pruned, the largest |z| and the value +- sigma of the largest:

- ``default``: ``jointid fit --robot``'s defaults;
- ``no sign check``, ``no prune``, ``eq. 15 sigma`` (``sigma_blocks=0``): one step off;
- ``sign check on predicted tau``: the sign check compares the first usual fit's predicted
  torque tau_hat (not the measured, low-passed one) with its tau_out_hat: a selection on the
  states only;
- ``dq_min 0.05 rad/s``: the stiction area widened (the default is 1 % of the largest |dq|),
  so that E = exp(-|dq|/q_s) varies less within the rows kept;
- ``true-theta quadrants``: the paper model's quadrants decided by the simulator's true theta
  (``RobotModel(quadrant_theta=...)``) instead of the usual fit's and its own;
- ``band: true load, regime``: also leave out (for both models, as the sign check does) every
  decimated row within the guard of a full-rate sample where the simulator's joint does not
  slide under eq. 30 (at rest, or in its zero-load regime): what a band can do with the truth;
- ``band: k x torque above cut-off``: rows within the guard of a full-rate sample with
  |tau_out_hat| (the first usual fit's, as the sign check reads it) below k times the RMS of
  the joint's torque above the cut-off (tau - its low-pass: the closed loop's high-frequency
  load), k = 1 and 2;
- ``guard G r``: the guard around every rejected full-rate sample (and the trim) G = 6 and 12
  decimation factors instead of 3 (``ident.chain.default_rates`` wrapped): whether the
  anti-alias filter's reach beyond the guard (benchmarks/robot_paper_products.py) is the
  cause.

The band variants wrap :func:`ident.robot.design.sign_checked` where
:mod:`ident.cli_robot` calls it (diagnostic only; nothing in the product does this). The
products form on eq. 42's products formed at full rate (a low-passed, fractional quadrant) on
the same logs: ``benchmarks/robot_paper_products.py``.
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

import numpy as np  # noqa: E402
from scipy.signal import butter, filtfilt  # noqa: E402
from test_robot_cutoff_band import logged, simulated, z_scores  # noqa: E402
from test_robot_fit import PAYLOADS  # noqa: E402

import ident.chain as chain  # noqa: E402
import ident.cli_robot as cli_robot  # noqa: E402
from ident import DataError  # noqa: E402
from ident.chain import decimation_index, selection  # noqa: E402
from ident.robot.design import full_rate_loads, sign_checked  # noqa: E402
from sim_drivers.arm_plant import output_arm_torque  # noqa: E402


def _banded(reject, share: dict):
    """``sign_checked`` followed by leaving out, on every joint, the decimated rows within the
    guard of a full-rate sample ``reject(i, f, tau_out_hat)`` marks (n_f, k) bool; the share
    of each joint's rows this leaves out in ``share["left"]``."""
    def wrapped(sig, runs, design, load_torque, min_kept=0.0, **kw):
        out, kept = sign_checked(sig, runs, design, load_torque, min_kept, **kw)
        if not np.isscalar(min_kept):  # the validation data's call: left as it is
            return out, kept
        loads = full_rate_loads(sig, runs, design, load_torque)
        keep = out.columns.keep.copy()
        for i, (f, x) in enumerate(loads):
            rows = np.flatnonzero(sig.experiment == i)
            keep[rows] &= selection(f.dq, design.dq_min, design.guard,
                                    decimation_index(f.n, design.decimation),
                                    reject(i, f, x, loads))
        share["left"] = 1.0 - keep.sum(axis=0) / np.maximum(out.columns.keep.sum(axis=0), 1)
        return replace(out, columns=replace(out.columns, keep=keep)), kept
    return wrapped


def _predicted_check(sig, runs, design, load_torque, min_kept=0.0, **_):
    """``sign_checked`` with the first usual fit's predicted torque tau_hat in place of the
    measured, low-passed one: rows where sign(tau_hat) != sign(tau_out_hat) left out (a
    selection on the states only, not on the output)."""
    first = load_torque.__self__  # the bound RobotModel.load_torque of the first usual fit
    cols = sig.columns
    keep = cols.keep.copy()
    pred = full_rate_loads(sig, runs, design, first.predict)
    for i, ((f, tau_hat), (_, tau_out)) in enumerate(
            zip(pred, full_rate_loads(sig, runs, design, load_torque), strict=True)):
        rows = np.flatnonzero(sig.experiment == i)
        keep[rows] = selection(f.dq, design.dq_min, design.guard,
                               decimation_index(f.n, design.decimation),
                               np.sign(tau_hat) != np.sign(tau_out))
    kept = keep.sum(axis=0) / np.maximum(cols.keep.sum(axis=0), 1)
    skip = kept < np.broadcast_to(np.asarray(min_kept, dtype=float), kept.shape)
    keep[:, skip] = cols.keep[:, skip]
    return replace(sig, columns=replace(cols, keep=keep)), kept


def _true_quadrants(truth):
    base = cli_robot.RobotModel

    class TrueQuadrants(base):
        def fit(self, signals):
            if self.model == "paper" and self.quadrant_theta is None:
                u = base(self.regressor, model="usual", method=self.method,
                         base=self.base).fit(signals)
                self.quadrant_theta = u.truth_vector(truth)[:u.n_theta_]
            return super().fit(signals)
    return TrueQuadrants


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--every", type=int, default=1, help="keep every n-th sample of 1 kHz")
    ap.add_argument("--duration", type=float, default=20.0, help="seconds per run")
    a = ap.parse_args()
    params, reg, runs, truth = simulated("paper", a.seed, a.duration)
    exps = logged(params, runs, a.every)
    loads = [output_arm_torque(params, r.q_true, r.dq_true, r.ddq_true, p)
             for r, p in zip(runs, PAYLOADS, strict=True)]
    k = slice(None, None, a.every)

    def fit(**opts):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                return cli_robot.fit_files(reg.robot, exps, model="both", feasibility=False,
                                           **opts)
            except DataError as exc:  # neither model identifiable on the rows left
                return {"models": {"paper": {"error": str(exc)}}}

    def show(label, out):
        if "error" in out["models"]["paper"]:
            print(f"{label:32s} not fitted: {out['models']['paper']['error'][:120]}")
            return
        z, pruned = z_scores(out, "paper", truth)
        per = [sum(v * v for n, v in z.items() if n.endswith(str(j))) for j in reg.numbers]
        top = sorted(z, key=lambda n: -abs(z[n]))[:4]
        rec = out["models"]["paper"]["parameters"][top[0]]
        print(f"{label:32s} {sum(v * v for v in z.values()):7.0f} / {len(z)}  "
              + " ".join(f"{x:6.0f}" for x in per) + f"  pruned {pruned:2d}  "
              + "  ".join(f"{n} {z[n]:+.1f}" for n in top)
              + f"  ({top[0]} {rec['value']:.4g} +- {rec['std']:.2g}, truth "
              f"{truth[top[0]]:.4g})", flush=True)

    out = fit()
    cut = float(out["preprocessing"]["cutoff_hz"])
    fs = 1.0 / float(np.median(np.diff(exps[0].t)))
    b, aa = butter(4, cut / (0.5 * fs))
    print(f"arm3, paper friction, seed {a.seed}, {fs:.0f} Hz, cut-off {cut:g} Hz; true load "
          "per run and joint: RMS below / above the cut-off [N m], quadrant flips per s "
          "(true / low-passed load), zero-load regime share")
    for i, (r, x) in enumerate(zip(runs, loads, strict=True)):
        for j in range(x.shape[1]):
            xj, dq = x[k, j], r.dq_true[k, j]
            lo = filtfilt(b, aa, xj)
            dur = xj.size / fs
            print(f"  run {i} j{j + 1}: {np.sqrt(np.mean(lo ** 2)):7.3f} "
                  f"{np.sqrt(np.mean((xj - lo) ** 2)):6.3f}  "
                  f"{np.sum(np.diff(np.sign(xj * dq)) != 0) / dur:6.1f} "
                  f"{np.sum(np.diff(np.sign(lo * dq)) != 0) / dur:5.1f}  "
                  f"{np.mean(r.regime[k, j] == 2):.3f}")
    print(f"{'variant':32s} sum z^2 / n   " + " ".join(f"{'j' + str(j):>6s}"
                                                       for j in reg.numbers))
    show("default", out)
    for note in out["notes"]:
        if note.startswith("sign check"):
            print(f"  {note}")
    print("  quadrant band share: " + ", ".join(
        f"{j} {x:.3f}" for j, x in out["models"]["paper"]["quadrant_band_share"].items()))
    show("no sign check", fit(sign_check=False))
    show("no prune", fit(prune=False))
    show("eq. 15 sigma (sigma_blocks 0)", fit(sigma_blocks=0))
    show("dq_min 0.05 rad/s", fit(dq_min=0.05))
    saved = cli_robot.RobotModel, cli_robot.sign_checked
    try:
        cli_robot.sign_checked = _predicted_check
        show("sign check on predicted tau", fit())
        cli_robot.sign_checked = saved[1]
        cli_robot.RobotModel = _true_quadrants(truth)
        show("true-theta quadrants", fit())
        cli_robot.RobotModel = saved[0]
        share: dict = {}
        cli_robot.sign_checked = _banded(
            lambda i, f, x, _: runs[i].regime[k][f.keep] != 0, share)
        show("band: true load, regime", fit())
        print("  rows left out per joint: " + " ".join(f"{x:.3f}" for x in share["left"]))
        for m in (1.0, 2.0):
            def hf(i, f, x, all_loads, m=m):
                hi = np.sqrt(np.mean(np.concatenate([g.tau - g.tau_f for g, _ in all_loads])
                                     ** 2, axis=0))
                return np.abs(x) < m * hi
            cli_robot.sign_checked = _banded(hf, share)
            show(f"band: {m:g} x torque above cut-off", fit())
            print("  rows left out per joint: " + " ".join(f"{x:.3f}" for x in share["left"]))
        cli_robot.sign_checked = saved[1]
        rates = chain.default_rates
        for g in (6, 12):
            def wider(fs, cutoff_hz, decimation=None, trim=None, guard=None, g=g):
                r, t, gd = rates(fs, cutoff_hz, decimation, trim, guard)
                return r, max(t, g * r), g * r if guard is None else gd
            chain.default_rates = wider
            try:
                show(f"guard {g} r", fit())
            finally:
                chain.default_rates = rates
    finally:
        cli_robot.RobotModel, cli_robot.sign_checked = saved


if __name__ == "__main__":
    main()
