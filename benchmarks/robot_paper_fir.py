"""Is the shoulder's and elbow's Stribeck bias on the simulated arm the chain's anti-alias
filter leaking? The same fits with MATLAB's Chebyshev (zero phase, an IIR: its reach has no
end) and with the chain's compact-support FIR (``ChainSettings.antialias = "fir"``:
:func:`ident.chain.fir_antialias`, the guard at least its half-length)
(docs/robot-identification.md, after "The products form with eq. 42's products formed at
full rate").

Usage: ``python benchmarks/robot_paper_fir.py [--seed 1] [--no-fit] [--usual]``

The logs are benchmarks/robot_paper_blend.py's (arm3, paper friction, three payload runs of
20 s, the drives' log at 1 kHz). Three variants: ``cheby`` (the default: the Chebyshev, the
guard 3 r), ``cheby, FIR's guard`` (the Chebyshev with the FIR's guard, its half-length: the
same rows as the FIR, so that what differs from it is the filter's reach only) and ``fir``.
Printed per variant:

- ``per joint``: benchmarks/soft_quadrant_arm3.py's harness with hard quadrants: the
  columns chain and sign check of ``jointid fit --robot``, the load the simulator's true
  theta on the chain's full-rate states, only one joint's ten paper parameters fitted on its
  rows (linear least squares, eq. 15 sigma), sum of z^2 against the truth (0.999 quantile of
  chi^2 with 10 degrees of freedom: 29.6) and the largest |z|; ``+ truth band``: also the
  rows within the guard of a full-rate sample where the simulator's joint does not slide
  under eq. 30 (at rest, stuck, or in its zero-load regime) left out: with the FIR nothing of
  those samples reaches the rows kept, with the Chebyshev its tail does;
- ``default fit`` (unless ``--no-fit``): ``jointid fit --robot``'s defaults
  (tests/test_robot_paper_sigma.py's ``fit_default``) with the filter: sum of z^2 per joint
  over the unpruned parameters, the largest |z|, the parameters pruned, the sign check's
  notes, time; then the same not pruned (``prune=False``);
- ``--usual``: tests/test_robot_cutoff_band.py's criterion of the usual model (the usual
  friction law simulated, logs at 500 and 250 Hz, default cut-off; sum of z^2 under the
  0.999 quantile of chi^2 and every |z| < 4) with each filter.

``--atten A``: the FIR (both the chain's and the harness's) replaced by the same Kaiser design
with A dB at 1.2 (f_s/2)/r: shorter (half-length 77 samples at 30 dB for r = 20 against 188),
so a guard nearer 3 r: whether a compact support with fewer rows lost keeps the gain.

The FIR goes into ``fit_files`` by wrapping :func:`ident.chain.resolve_settings` where
:mod:`ident.robot.design` calls it (``antialias="fir"``); nothing else changes.
"""

from __future__ import annotations

import argparse
import functools
import os
import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "benchmarks"))

import numpy as np  # noqa: E402
import scipy.signal  # noqa: E402
import scipy.stats  # noqa: E402
from soft_quadrant_common import paper_columns  # noqa: E402
from test_robot_cutoff_band import logged, simulated, z_scores  # noqa: E402

import ident.chain as chain  # noqa: E402
import ident.cli_robot as cli_robot  # noqa: E402
import ident.robot.design as robot_design  # noqa: E402
from ident import DataError  # noqa: E402
from ident.chain import decimate, decimation_index, selection  # noqa: E402
from ident.fitting import SIGN_CHECK_MIN_KEPT  # noqa: E402
from ident.robot import RobotIdentError  # noqa: E402
from ident.robot.base import base_parameters  # noqa: E402
from ident.robot.design import design_runs, full_rate_loads, sign_checked  # noqa: E402
from ident.robot.estimate import RobotModel  # noqa: E402
from ident.robot.paper import PAPER_BLOCK  # noqa: E402
from trajectories.friction import DEFAULT_Q_S  # noqa: E402

#: (label, filter, guard): the Chebyshev with its guard (3 r), the Chebyshev with the FIR's
#: guard (its half-length: the same rows, so what differs is the filter's reach), the FIR
VARIANTS = (("cheby", "cheby", None), ("cheby, FIR's guard", "cheby", "fir"),
            ("fir", "fir", None))
FILTERS = ("cheby", "fir")


class _Antialias:
    """Within the block, :mod:`ident.robot.design` resolves its settings with the filter
    (and the guard: ``"fir"`` for the FIR's half-length)."""

    def __init__(self, name: str, guard: str | None = None) -> None:
        self.name, self.guard = name, guard

    def __enter__(self) -> None:
        def resolve(q0, dt, **given):
            if self.guard == "fir":
                r = chain.resolve_settings(q0, dt, **given).decimation
                given["guard"] = max(3 * r, chain.fir_half_length(r))
            return chain.resolve_settings(q0, dt, antialias=self.name, **given)
        robot_design.resolve_settings = resolve

    def __exit__(self, *exc) -> None:
        robot_design.resolve_settings = chain.resolve_settings


def _kaiser(r: int, atten: float) -> np.ndarray:
    """``--atten``: :func:`ident.chain.fir_antialias`'s design with another attenuation [dB]."""
    if r <= 1:
        return np.ones(1)
    numtaps, beta = scipy.signal.kaiserord(atten, 0.4 / r)
    numtaps += 1 - numtaps % 2
    return scipy.signal.firwin(numtaps, 1.0 / r, window=("kaiser", beta), scale=True)


def per_joint(params, reg, sim, truth, label: str, name: str, guard: str | None) -> None:
    """soft_quadrant_arm3.py's hard-quadrant harness with the filter ``name`` (and guard),
    each joint; then the same with the rows near the simulator's non-eq.-30 samples left
    out."""
    runs = logged(params, sim, 1)
    base = base_parameters(reg)
    t0 = time.perf_counter()
    with warnings.catch_warnings(), _Antialias(name, guard):
        warnings.simplefilter("ignore")
        design = robot_design.resolve_design(runs)
        sig, dq_min = design_runs(runs, reg, design)
    t_chain = time.perf_counter() - t0
    design = replace(design, dq_min=dq_min)
    first = RobotModel(reg, "usual", "wls", base=base).fit(sig)
    true_load = RobotModel(reg, "usual", "wls", base=base).fit(sig)
    true_load.coef_ = true_load.coef_.copy()
    true_load.coef_[:true_load.n_theta_] = first.truth_vector(truth)[:first.n_theta_]
    loads = full_rate_loads(sig, runs, design, true_load.load_torque)
    sig, _ = sign_checked(sig, runs, design, first.load_torque, SIGN_CHECK_MIN_KEPT)
    r = design.decimation
    print(f"  {label}: decimation {r}, guard {design.guard} samples "
          f"(FIR half-length {chain.fir_half_length(r)}), chain {t_chain:.1f} s; rows kept "
          "per joint "
          + " ".join(str(int(x)) for x in sig.columns.keep.sum(axis=0))
          + f" of {sig.n}", flush=True)
    for j in range(len(reg.numbers)):
        names = [f"{p}{reg.numbers[j]}" for p in PAPER_BLOCK]
        tv = np.array([truth[n] for n in names])
        for band in (False, True):
            ys, ws = [], []
            for i, (f, x) in enumerate(loads):
                rows = np.flatnonzero(sig.experiment == i)
                keep = sig.columns.keep[rows, j].copy()
                if band:
                    off = sim[i].regime[f.keep, j] != 0
                    keep &= selection(f.dq[:, j:j + 1], None, design.guard,
                                      decimation_index(f.n, r), off[:, None])[:, 0]
                ys.append(sig.tau[rows, j][keep])
                cols = paper_columns(x[:, j], f.dq[:, j], None, DEFAULT_Q_S)
                ws.append(decimate(cols, r, name)[0][keep])
            y, W = np.concatenate(ys), np.concatenate(ws)
            th, *_ = np.linalg.lstsq(W, y, rcond=None)
            res = y - W @ th
            if np.linalg.cond(W) > 1e8:  # a quadrant without rows left
                print(f"    joint {reg.numbers[j]}{' + truth band' if band else '':13s} "
                      f"{y.size:5d} rows  not identifiable (cond {np.linalg.cond(W):.1e})")
                continue
            sd = np.sqrt(np.diag(res @ res / (y.size - 10) * np.linalg.inv(W.T @ W)))
            z = (th - tv) / sd
            top = np.argsort(-np.abs(z))[:3]
            print(f"    joint {reg.numbers[j]}{' + truth band' if band else '':13s} "
                  f"{y.size:5d} rows  sum z^2 {np.sum(z * z):7.1f} / 10  rel. error "
                  f"{np.linalg.norm(res) / np.linalg.norm(y):.5f}  "
                  + "  ".join(f"{names[i]} {z[i]:+.1f}" for i in top), flush=True)


def fit(reg, exps, name: str, guard: str | None = None, **opts) -> tuple[dict | str, float]:
    """``fit_default`` (tests/test_robot_cutoff_band.py) with the filter ``name``, the guard
    and ``opts`` of ``fit_files``; seconds. The one-line error instead when it refuses."""
    t0 = time.perf_counter()
    with warnings.catch_warnings(), _Antialias(name, guard):
        warnings.simplefilter("ignore")
        try:
            out = cli_robot.fit_files(reg.robot, exps, model="both", feasibility=False,
                                      **opts)
        except (DataError, RobotIdentError) as exc:
            return str(exc), time.perf_counter() - t0
    return out, time.perf_counter() - t0


def show_fit(reg, out: dict, truth: dict, model: str, dt: float) -> str:
    """Sum of z^2 (and per joint), pruned, the largest |z| (or why the model was refused)."""
    if "error" in out["models"][model]:
        return f"refused: {out['models'][model]['error'][:160]}"
    z, pruned = z_scores(out, model, truth)
    per = [sum(v * v for n, v in z.items() if n.endswith(str(j))) for j in reg.numbers]
    top = sorted(z, key=lambda n: -abs(z[n]))[:3]
    q = scipy.stats.chi2.ppf(0.999, len(z))
    return (f"sum z^2 {sum(v * v for v in z.values()):7.1f} / {len(z)} ({q:.0f}): "
            + " / ".join(f"{x:.0f}" for x in per) + f"  pruned {pruned}  "
            + "  ".join(f"{n} {z[n]:+.1f}" for n in top)
            + f"  {dt:.0f} s")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--no-fit", action="store_true", help="the per-joint harness only")
    ap.add_argument("--usual", action="store_true",
                    help="also the usual model's criterion at 500 and 250 Hz")
    ap.add_argument("--atten", type=float, default=None,
                    help="a shorter FIR: the Kaiser design's attenuation [dB] at 1.2 (f_s/2)/r "
                         "instead of the Chebyshev's there (same band edges)")
    a = ap.parse_args()
    if a.atten is not None:
        chain.fir_antialias = functools.lru_cache(maxsize=8)(
            functools.partial(_kaiser, atten=a.atten))
        print(f"FIR: Kaiser, {a.atten:g} dB from 1.2 (f_s/2)/r (half-length "
              f"{chain.fir_half_length(20)} samples for r = 20)")
    h = chain.fir_antialias(20)
    w, amp = scipy.signal.freqz(h, worN=np.pi * np.array([0.8, 1.2]) / 20)
    print(f"FIR for r = 20: {h.size} taps (half-length {(h.size - 1) // 2}), gain "
          f"{abs(amp[0]):.5f} at 0.8 (f_s/2)/r, {-20 * np.log10(abs(amp[1])):.1f} dB at 1.2 "
          f"(f_s/2)/r; the zero-phase Chebyshev "
          f"{-10 * np.log10(chain._cheby_zero_phase_gain(1.2 / 20, 20)):.1f} dB there")
    params, reg, sim, truth = simulated("paper", a.seed, 20.0)
    print(f"arm3, paper friction, seed {a.seed}, 1 kHz; per joint (theta at the truth, the "
          "joint's ten paper parameters, hard quadrants; chi^2 0.999 quantile for 10: 29.6)",
          flush=True)
    for label, name, guard in VARIANTS:
        per_joint(params, reg, sim, truth, label, name, guard)
    if not a.no_fit:
        exps = logged(params, sim, 1)
        print("default fit (jointid fit --robot's defaults), paper model: sum z^2 / n "
              "(0.999 quantile), joints 1 / 2 / 3", flush=True)
        for label, name, guard in VARIANTS:
            out, dt = fit(reg, exps, name, guard)
            if isinstance(out, str):
                print(f"  {label}: refused: {out}", flush=True)
                continue
            rec = out["models"]["paper"].get("parameters", {})
            print(f"  {label}: {show_fit(reg, out, truth, 'paper', dt)}  pruned: "
                  + " ".join(n for n, x in rec.items() if x["pruned"]), flush=True)
            for note in out["notes"]:
                if note.startswith("sign check"):
                    print(f"        {note}")
            out, dt = fit(reg, exps, name, guard, prune=False)
            if not isinstance(out, str):
                print(f"  {label}: {show_fit(reg, out, truth, 'paper', dt)}  (not pruned)",
                      flush=True)
    if a.usual:
        params, reg, sim, truth = simulated("usual", a.seed)
        print("usual friction simulated, usual model (criterion: sum z^2 under the 0.999 "
              "quantile, every |z| < 4)", flush=True)
        for every in (2, 4):
            exps = logged(params, sim, every)
            for name in FILTERS:
                out, dt = fit(reg, exps, name)
                if isinstance(out, str):
                    print(f"  {1000 // every} Hz {name:5s} refused: {out}", flush=True)
                    continue
                z, _ = z_scores(out, "usual", truth)
                chi2 = sum(v * v for v in z.values())
                ok = chi2 < scipy.stats.chi2.ppf(0.999, len(z)) and max(map(abs, z.values())) < 4
                print(f"  {1000 // every} Hz {name:5s} cut-off "
                      f"{out['preprocessing']['cutoff_hz']:g} Hz, guard "
                      f"{out['preprocessing']['guard']}: "
                      f"{show_fit(reg, out, truth, 'usual', dt)}  holds: {ok}", flush=True)


if __name__ == "__main__":
    main()
