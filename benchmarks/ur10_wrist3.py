"""Why wrist 3 of the simulated UR10 gets b_m6, d_m6 7 sigma off the truth on campaign seed 3.

docs/robot-identification.md, "Wrist 3 of the UR10 demo campaign: one row decides b_m6".
For each folder of UR10 logs (a monitor bench WORK folder, ``benchmarks/bench_monitor.py
--work WORK --campaign examples/campaign_ur10_demo.toml model``: its WORK/model_logs, or a
folder of ``jointid run`` MCAP logs of that campaign with another multi-sine seed), the paper
model is fitted as the bench does (``jointid fit --robot --model paper --no-prune``, hard
quadrants) and, for one joint (``--joint``, default wrist_3_joint), this prints:

- its ten paper parameters: value, the simulator's truth (``ArmParams.from_robot(robot)
  .truth()``), the honest std and its sides (robust eq. 15, block jackknife, the friction
  block's HC3 ``std_leverage``), z with the honest std and z with the rule before the HC3
  side, max(robust, jackknife);
- over every joint's free friction parameters: on how many the HC3 side raised the honest
  sigma, and the largest ratio honest / max(robust, jackknife);
- the same fit with the quadrants decided by the true theta (``quadrant_theta``): b_m, d_m,
  b_g, d_g and their z;
- the fit's rows of the joint: motor / generator quadrant (by the true load tau_out), the
  share of positive load, |dq| percentiles and the smallest |dq| / q_s, and how many rows per
  quadrant have E = exp(-|dq| / q_s) above 1e-2 and 1e-3 (the rows that carry b and d);
- the joint's friction block with theta held at the fit (the linear problem the HC3 side
  reads): the five rows of largest leverage h (E, load, residual / sigma_j, deleted residual
  e / (1 - h) / sigma_j) and b_m, d_m refitted without the largest;
- b_m, d_m held at 0 and the block refitted (theta held): the rise of the joint's residual
  sum of squares over the fit's, in sigma_j^2 (what the pruning's chi-square test reads);
- with validation logs: the joint's RMS of tau - tau_hat on the validation rows where it
  moves (|dq| >= 3 q_s, the monitor's rest band) for the fit, for the truth through the
  same estimator and for the fit with b_m, d_m held at 0 as above [N m].

Usage::

    OPENBLAS_NUM_THREADS=1 python benchmarks/ur10_wrist3.py LOGS [LOGS ...] \
        [--validation DIR] [--joint NAME]

``--validation`` default: the first WORK's calibrate/logs when present.
"""

from __future__ import annotations

import argparse
import copy
import os
import sys
import warnings
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from ident.cli_robot import fit_files  # noqa: E402
from ident.robot.estimate import RobotModel  # noqa: E402
from ident.robot.paper import PAPER_BLOCK  # noqa: E402
from sim_drivers.arm import ArmParams  # noqa: E402
from trajectories.friction import quadrant_weights, stribeck_exp  # noqa: E402
from trajectories.robot import load_robot  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
ROBOT = ROOT / "examples" / "robots" / "ur10.toml"
REST_QS = 3.0  # the monitor's rest band, in q_s


def logs_of(path: Path) -> list[Path]:
    """WORK/model_logs/*.mcap, else PATH/*.mcap."""
    d = path / "model_logs" if (path / "model_logs").is_dir() else path
    out = sorted(d.glob("*.mcap"))
    if not out:
        raise SystemExit(f"{path}: no *.mcap (nor model_logs/*.mcap)")
    return out


def gauged(est, truth: dict[str, float]) -> np.ndarray:
    """The truth on ``est.names_`` (the UR10's two payload runs fix the gauge: no scale)."""
    if est.fixed_:
        raise SystemExit(f"fixed parameters {list(est.fixed_)}: the truth needs the gauge")
    return est.truth_vector(truth)


def friction_block(est, sig, j: int):
    """Joint j's fitted rows with theta held: X (m, 10) over PAPER_BLOCK, tau, true-quadrant
    load and dq, E."""
    rows = est.fitted_rows(sig)[:, j]
    L = est.load_torque(sig)[rows, j]
    dq, y = sig.dq[rows, j], sig.tau[rows, j]
    sg = sig.columns.sign[rows, j] if sig.columns is not None else np.sign(dq)
    E = stribeck_exp(dq, est.q_s_[j])
    pp, pm = quadrant_weights(L * dq)
    X = np.stack([pp * L, pp * E * L, pm * L, -pm * E * L, pp * sg, pp * E * sg, pm * sg,
                  pm * E * sg, dq, np.ones_like(dq)], axis=1)
    return X, y, L, dq, E, rows


def report(path: Path, robot, val: list[Path], joint: str) -> None:
    params = ArmParams.from_robot(robot)
    truth = params.truth()
    j = list(robot.moving).index(joint)
    n = robot.numbers[j]
    names = [f"{p}{n}" for p in PAPER_BLOCK]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        out = fit_files(robot, logs_of(path), val or None, model="paper", feasibility=False,
                        prune=False)
    est = out["_estimators"]["paper"]
    rec = out["models"]["paper"]["parameters"]
    tv = dict(zip(est.names_, gauged(est, truth), strict=True))
    print(f"\n== {path}  ({joint}, q_s {est.q_s_[j]:g} rad/s)")
    print("  param      truth      value    honest   robust  jackknife  HC3    z    "
          "z before HC3")
    for nm in names:
        r = rec[nm]
        old = max(r["std_robust"] or 0.0, r["std_jackknife"] or 0.0)
        print(f"  {nm:<6} {tv[nm]:+9.4g} {r['value']:+10.4g} {r['std']:9.3g} "
              f"{r['std_robust'] or float('nan'):8.3g} {r['std_jackknife'] or float('nan'):9.3g} "
              f"{r['std_leverage'] or float('nan'):8.3g} "
              f"{(r['value'] - tv[nm]) / r['std']:+5.1f} {(r['value'] - tv[nm]) / old:+7.1f}")
    fr = [(nm, r["std"] / max(r["std_robust"] or 0.0, r["std_jackknife"] or 0.0))
          for nm, r in rec.items() if r["std_leverage"] is not None and r["std"] > 0]
    worst = max(fr, key=lambda t: t[1])
    print(f"  HC3 raised the honest sigma of {sum(v > 1 for _, v in fr)} of {len(fr)} friction "
          f"parameters; largest ratio {worst[1]:.1f} ({worst[0]}), median "
          f"{np.median([v for _, v in fr]):.2f}")
    p = est.get_params()
    p.update(quadrant_theta=gauged(est, truth)[:est.n_theta_])
    tq = RobotModel(**p).fit(out["_signals"][0])
    ix = list(tq.names_)
    print("  true-theta quadrants (eq. 15 std): " + "  ".join(
        f"{nm} {tq.coef_[ix.index(nm)]:+.3g} +- {tq.std_[ix.index(nm)]:.2g} "
        f"(z {(tq.coef_[ix.index(nm)] - tv[nm]) / tq.std_[ix.index(nm)]:+.1f})"
        for nm in names[1:8:2]))
    sig = out["_signals"][0]
    X, y, L, dq, E, _ = friction_block(est, sig, j)
    o = copy.copy(est)
    o.coef_ = gauged(est, truth)
    Lt = o.load_torque(sig)[est.fitted_rows(sig)[:, j], j]
    mot = Lt * dq > 0
    qs = est.q_s_[j]
    pct = np.percentile(np.abs(dq), [10, 50, 90]).round(3).tolist()
    print(f"  fit rows {y.size}: motor {mot.sum()}, generator {(~mot).sum()}; load > 0 in "
          f"{np.mean(Lt > 0):.0%}; |dq| 10/50/90 % {pct} rad/s, smallest "
          f"{np.abs(dq).min() / qs:.2f} q_s")
    for tag, m in (("motor", mot), ("generator", ~mot)):
        print(f"    {tag}: E > 1e-2 {(m & (E > 1e-2)).sum()} rows, E > 1e-3 "
              f"{(m & (E > 1e-3)).sum()} rows; largest E {E[m].max() if m.any() else 0:.3g}")
    G = X.T @ X
    Gi = np.linalg.pinv(G)
    b = Gi @ X.T @ y
    e = y - X @ b
    s = float(np.sqrt(e @ e / (y.size - X.shape[1])))
    h = np.einsum("ij,jk,ik->i", X, Gi, X)
    print(f"  friction block, theta held: b_m {b[1]:+.3g}, d_m {b[5]:+.3g} (the joint fit's "
          f"{rec[names[1]]['value']:+.3g}, {rec[names[5]]['value']:+.3g}); sigma_j {s:.4f} "
          "N m; largest leverages:")
    for i in np.argsort(-h)[:5]:
        print(f"    h {h[i]:.3f}  |dq| {abs(dq[i]) / qs:5.1f} q_s  E {E[i]:.1e}  load "
              f"{L[i]:+.3f} N m  {'motor' if mot[i] else 'gen.'}  residual {e[i] / s:+5.1f} "
              f"sigma_j, deleted {e[i] / (1 - h[i]) / s:+6.1f} sigma_j")
    keep = np.ones(y.size, bool)
    keep[int(np.argmax(h))] = False
    b1 = np.linalg.lstsq(X[keep], y[keep], rcond=None)[0]
    print(f"  without the largest-leverage row: b_m {b1[1]:+.3g}, d_m {b1[5]:+.3g}, b_g "
          f"{b1[3]:+.3g}, d_g {b1[7]:+.3g}")
    free = [0, 2, 3, 4, 6, 7, 8, 9]  # b_m, d_m held at 0
    bz = np.linalg.lstsq(X[:, free], y, rcond=None)[0]
    ez = y - X[:, free] @ bz
    zero = copy.copy(est)
    zero.coef_ = est.coef_.copy()
    ix = list(est.names_)
    for i, v in zip(free, bz, strict=True):
        zero.coef_[ix.index(names[i])] = v
    zero.coef_[ix.index(names[1])] = zero.coef_[ix.index(names[5])] = 0.0
    print(f"  b_m, d_m held at 0 (block refitted): residual sum of squares up by "
          f"{(ez @ ez - e @ e) / s ** 2:.1f} sigma_j^2")
    vs = out.get("_validation_all")
    if vs is not None:
        rms = []
        for m in (est, o, zero):
            r = vs.tau[:, j] - m.predict(vs)[:, j]
            ok = np.isfinite(r) & (np.abs(vs.dq[:, j]) >= REST_QS * qs)
            rms.append(float(np.sqrt(np.mean(r[ok] ** 2))))
        print(f"  validation RMS where it moves: fit {rms[0]:.4f} N m, truth {rms[1]:.4f} N m, "
              f"b_m, d_m held at 0 {rms[2]:.4f} N m")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("logs", type=Path, nargs="+")
    ap.add_argument("--validation", type=Path, default=None)
    ap.add_argument("--joint", default="wrist_3_joint")
    a = ap.parse_args()
    robot = load_robot(ROBOT)
    if a.joint not in robot.moving:
        raise SystemExit(f"--joint: expected one of {', '.join(robot.moving)}, got {a.joint!r}")
    vdir = a.validation or a.logs[0] / "calibrate" / "logs"
    val = sorted(vdir.glob("*.mcap")) if vdir.is_dir() else []
    if a.validation and not val:
        raise SystemExit(f"--validation {a.validation}: no *.mcap")
    for p in a.logs:
        report(p, robot, val, a.joint)
    sys.stdout.flush()


if __name__ == "__main__":
    main()
